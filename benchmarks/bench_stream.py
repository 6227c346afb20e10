"""Streaming with candidates: per-push latency of ``StreamFuser(rig, method,
candidates=True)`` (live mode feeds each detection datagram, a frame's candidates, through
it) and of its gate alone, against a base revision in the same run.

Session: ``paper3`` (three 640 x 480 cameras at 30 fps, type-A shutters), a rally of the
tests' own generator (``tests/_rally.py``), 0.3 px noise, spurious blobs in 5 % of frames
and a static second object seen by one camera (1-2 candidates per frame); ``clocks``: the
same with clock offsets (4 and -6 ms) and 10 ms rolling shutters (every candidate at its own
corrected time; the gate waits to decide a frame until nothing still to come can precede
it). One push per frame, its candidates best first (``, best``: the frame's best candidate
only, through ``StreamFuser(rig, method)`` without candidates). Per push: CPU time of the
process (the measure on a shared machine) and wall time, median and p99; the first 30 pushes
(the track starting) are left out.

Targets (issue 11, live mode): each point out within 1 ms at p99; the gate well under
100 µs median per push for ``filter`` and ``typeA``.

The base revision's ``pslog`` (``git archive``, default ``0fce3cb``, before the incremental
gate) runs in a child process on the very same session, alternating with this tree's.

    python benchmarks/bench_stream.py [--seconds 10] [--base 0fce3cb] [--quick]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, before numpy loads

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DISTRACTOR = (1.0, 1.5, 0.2)  # on the floor, in view of every camera of paper3
SKIP = 30
#: (what, clock faults, candidates): without candidates each push is the frame's best one
CASES = (("gate", False, True), ("filter", False, True), ("typeA", False, True),
         ("typeA", False, False), ("gate", True, True), ("filter", True, True),
         ("typeA", True, True), ("typeA", True, False))


def frames(seconds: float, clocks: bool):
    """The rig and every frame's (times, cameras, uv, frame indices) push."""
    import numpy as np

    sys.path.insert(0, str(ROOT / "tests"))
    from _rally import rally

    from pslog import apply_timing, builtin_rig
    from pslog.simulation import SimulationOptions, simulate_labelled, true_rig

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    faults = ({"clock_offset_s": {"cam2": 0.004, "cam3": -0.006},
               "readout_s": dict.fromkeys(rig.names, 0.01)} if clocks else {})
    options = SimulationOptions(noise_px=0.3, seed=1, spurious_rate=0.05,
                                distractors=(("cam2", DISTRACTOR),), **faults)
    motion = rally(seconds, seed=100, speed=4.0, kick_every_s=0.9)[0]
    det, _, _ = simulate_labelled(rig, motion, seconds, options)
    starts = np.flatnonzero(np.r_[True, np.diff(det.cand_frame) != 0])
    ends = np.r_[starts[1:], det.n_candidates]
    out = []
    for lo, hi in zip(starts.tolist(), ends.tolist(), strict=True):
        f, n = int(det.cand_frame[lo]), hi - lo
        out.append((np.full(n, det.frame_time_ns[f]), np.full(n, det.frame_camera[f]),
                    det.cand_uv[lo:hi].copy(), np.full(n, det.frame_index[f])))
    return true_rig(rig, options), out, det.n_candidates


def measure(seconds: float) -> dict:
    """{case: (cpu median, cpu p99, wall median, wall p99) µs} of the pslog imported."""
    import numpy as np

    from pslog.fusion.gating import StreamGate
    from pslog.fusion.stream import StreamFuser

    results = {}
    for what, clocks, candidates in CASES:
        rig, pushes, _ = frames(seconds, clocks)
        push = (StreamGate(rig).push if what == "gate"
                else StreamFuser(rig, what, candidates=candidates).push)
        if not candidates:  # the frame's best candidate only (they come best first)
            pushes = [(t[:1], c[:1], uv[:1], f[:1]) for t, c, uv, f in pushes]
        wall, cpu = np.empty(len(pushes)), np.empty(len(pushes))
        for i, args in enumerate(pushes):
            start, start_cpu = time.perf_counter_ns(), time.process_time_ns()
            push(*args)
            cpu[i] = time.process_time_ns() - start_cpu
            wall[i] = time.perf_counter_ns() - start
        cpu, wall = cpu[SKIP:] / 1e3, wall[SKIP:] / 1e3
        results[f"{what}{', clocks' if clocks else ''}{'' if candidates else ', best'}"] = (
            float(np.median(cpu)), float(np.percentile(cpu, 99)), float(np.median(wall)),
            float(np.percentile(wall, 99)))
    return results


def run_child(pythonpath: str, seconds: float) -> dict:
    env = dict(os.environ, PYTHONPATH=pythonpath)
    done = subprocess.run([sys.executable, __file__, "--child", "--seconds", str(seconds)],
                          env=env, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="rally length")
    parser.add_argument("--base", default="0fce3cb", help="base revision (default 0fce3cb)")
    parser.add_argument("--repeats", type=int, default=2,
                        help="alternating runs of base and this tree (the best of each kept)")
    parser.add_argument("--quick", action="store_true", help="a 4 s rally, one run each")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(measure(args.seconds)))
        return 0
    seconds, repeats = (4.0, 1) if args.quick else (args.seconds, args.repeats)
    with tempfile.TemporaryDirectory() as base_dir:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.base, "pslog"],
                                 capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", base_dir], input=archive, check=True)
        runs: dict[str, list[dict]] = {"base": [], "now": []}
        for _ in range(repeats):
            runs["base"].append(run_child(base_dir, seconds))
            runs["now"].append(run_child(str(ROOT), seconds))
    _, pushes, n_candidates = frames(seconds, False)
    print(f"per push with candidates: paper3, {seconds:g} s rally, 0.3 px, spurious 5 % + a "
          f"distractor: {len(pushes)} pushes, {n_candidates} candidates; best of {repeats} "
          f"run(s); µs")
    head = (f"{'case':<22} | {'base ' + args.base:^31} | {'now':^31} | CPU median")
    print(head)
    print(f"{'':<22} | {'CPU median':>10} {'p99':>8} {'wall p99':>10} | "
          f"{'CPU median':>10} {'p99':>8} {'wall p99':>10} | speed-up")
    print("-" * len(head))
    for case in runs["now"][0]:
        b = [min(r[case][k] for r in runs["base"]) for k in range(4)]
        n = [min(r[case][k] for r in runs["now"]) for k in range(4)]
        print(f"{case:<22} | {b[0]:>10.1f} {b[1]:>8.1f} {b[3]:>10.1f} | {n[0]:>10.1f} "
              f"{n[1]:>8.1f} {n[3]:>10.1f} | {b[0] / n[0]:>6.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
