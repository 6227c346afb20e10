"""Fusion throughput on one core: every method's figure, with the triangulation peers a user
would otherwise pick timed in the same run.

Printed, best of ``--repeat`` runs (CPU time of this process, one thread, after one untimed
warm-up call), on a ``--minutes`` session of three 30 fps cameras with 0.5 px noise
(``turntable`` motion):

- ``typeA``, ``nearest`` (type-A timing) and ``typeB``, ``linear``, ``sync`` (their timings):
  fused points per second, ``fuse()`` end to end (``prepare`` included: undistortion and the
  viewing ray of every detection, also printed alone as the baseline every method shares),
  quality columns and covariance included; and ``typeA``'s fusion alone on a prepared
  session (what the peers are timed on: given pixels, rays and cameras);
- ``smooth``, ``filter`` (type-A timing) and ``sync`` (synchronised timing): detections
  consumed per second (issue 12's figures for the timing and robustness methods);
- peers: OpenCV's ``cv2.triangulatePoints`` (DLT) on two synchronised views (camera 1 and
  2 at the same frames, undistorted pixels, the dehomogenisation included) and, if
  installed, aniposelib's ``CameraGroup.triangulate`` on three synchronised views
  (undistortion inside it, as it does), on as many instants as ``typeA`` makes points (a
  synchronised session three times as long: its first instants). They are timed together
  with ``typeA``: its ``fuse()``, cv2 and aniposelib called in turn, ``--repeat`` rounds
  after one untimed round, each side's best CPU time (so a busy moment of a loaded machine
  slows each side alike; ``typeA``'s row and the peers' rows are that run's).

``typeA`` runs compiled kernels (numba, cached on disk): the figures are warm (an untimed
call is made before the timed ones, for every row: the first call in a process also pays
for fresh memory). ``--compile`` also prints the first call's time in a fresh process
with an empty numba cache (the compile a new install pays once) and with the cache filled.

Issue 12's target: ``typeA`` at least 1,000,000 points/s and at least the faster peer. The
exit status is 1 if it is missed. Speed figures on a shared machine are noisy: compare the
ratios printed in one run, not figures of separate runs.

``--base REV`` also times ``fuse(..., method)`` for each of ``--methods`` (default
``typeA``; each on its timing's session, as above) under a git revision's ``pslog`` (``git
archive``, run in a child process) and this tree's, alternating, ``--rounds`` times each on
the same sessions (CPU time of each child, best of ``--repeat``): the paired figure a
shared machine allows.

    python benchmarks/bench_fusion.py [--minutes 10] [--repeat 3] [--quick] [--stream 10]
        [--json out.json] [--compile] [--base REV [--rounds 3] [--methods typeA,sync]]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, before numpy loads

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate  # noqa: E402
from pslog.fusion import fuse, prepare  # noqa: E402
from pslog.fusion.stream import StreamFuser  # noqa: E402

#: issue 12: typeA points per second on one core (and at least the faster peer's)
TARGET_TYPEA = 1_000_000


def best_of(repeat: int, fn) -> tuple[float, object]:
    """Best CPU seconds (this process) of ``repeat`` calls of ``fn`` after one untimed call,
    and its result."""
    result = fn()
    best = float("inf")
    for _ in range(repeat):
        start = time.process_time()
        result = fn()
        best = min(best, time.process_time() - start)
    return best, result


def alternating(repeat: int, *fns) -> list[float]:
    """Best CPU seconds (this process) of each of ``fns``, called in turn ``repeat`` times
    after one untimed round of the same turns (each side warm alike)."""
    for fn in fns:
        fn()
    best = [float("inf")] * len(fns)
    for _ in range(repeat):
        for i, fn in enumerate(fns):
            start = time.process_time()
            fn()
            best[i] = min(best[i], time.process_time() - start)
    return best


def session(timing: str, minutes: float):
    """(rig, observations) of a simulated session with this rig timing."""
    rig = apply_timing(builtin_rig("paper3"), timing)
    detections, _ = simulate(rig, get_motion("turntable"), minutes * 60,
                             SimulationOptions(noise_px=0.5, seed=0))
    return rig, detections.best()


def synchronised_views(rig, obs, cameras: tuple[int, ...]) -> np.ndarray:
    """(n_views, k, 2) recorded pixels of the frames every camera in ``cameras`` saw."""
    frames = [dict(zip(obs.frame_index[obs.camera == c].tolist(),
                       np.flatnonzero(obs.camera == c).tolist(), strict=True))
              for c in cameras]
    common = sorted(set.intersection(*(set(f) for f in frames)))
    return np.stack([obs.uv[[f[i] for i in common]] for f in frames])


def type_a_alone(rig, obs, repeat: int) -> tuple[float, int]:
    """Seconds and points of type A's fusion itself (``fuse_type_a``: its compiled pass, the
    innovation and kink tests, the Track) on a session prepared beforehand (a new
    preparation for each run, not timed: no cache of a previous run helps)."""
    from pslog.fusion import FusionOptions
    from pslog.fusion._prepare import default_max_gap_s
    from pslog.fusion.pseudo import fuse_type_a

    best, points = float("inf"), 0
    for _ in range(repeat):
        prep = prepare(obs, rig)
        start = time.process_time()
        track = fuse_type_a(prep, default_max_gap_s(rig), FusionOptions().noise_px,
                            explain=False)[0]
        best = min(best, time.process_time() - start)
        points = len(track)
    return best, points


def peer_opencv(rig, uv: np.ndarray):
    """cv2.triangulatePoints (DLT) on two views' undistorted pixels: a call to time."""
    import cv2

    cv2.setNumThreads(1)
    cams = rig.cameras[:2]
    ideal = [cam.undistort(uv[i]) for i, cam in enumerate(cams)]
    P = [cam.K @ np.hstack([cam.R, cam.t.reshape(3, 1)]) for cam in cams]
    a, b = (np.ascontiguousarray(x.T) for x in ideal)

    def run():
        X = cv2.triangulatePoints(P[0], P[1], a, b)
        return (X[:3] / X[3]).T

    return run


def peer_aniposelib(rig, uv: np.ndarray):
    """aniposelib's CameraGroup.triangulate on the views: a call to time, or None."""
    try:
        from aniposelib.cameras import Camera as ACamera
        from aniposelib.cameras import CameraGroup
    except ImportError:
        return None
    import cv2

    group = CameraGroup([ACamera(name=c.name, size=(c.width, c.height), matrix=c.K,
                                 dist=np.asarray(c.dist, dtype=np.float64),
                                 rvec=cv2.Rodrigues(c.R)[0].ravel(), tvec=c.t)
                         for c in rig.cameras[:len(uv)]])
    try:
        group.triangulate(uv[:, :10], undistort=True, progress=False)  # (numba compiles here)
    except ImportError:  # (aniposelib >= 0.6 imports jax here)
        return None
    return lambda: group.triangulate(uv, undistort=True, progress=False)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="session length")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="a 2-minute session, best of 2")
    parser.add_argument("--stream", type=float, default=0.0, metavar="SECONDS",
                        help="also time StreamFuser on a session this long (0: not)")
    parser.add_argument("--json", default=None, help="write the rows here as JSON")
    parser.add_argument("--compile", action="store_true",
                        help="also time typeA's first call with a cold and a warm numba cache")
    parser.add_argument("--base", default=None, metavar="REV",
                        help="also time typeA under this git revision, alternating (paired)")
    parser.add_argument("--rounds", type=int, default=3, help="alternations with --base")
    parser.add_argument("--methods", default="typeA",
                        help="with --base: the methods timed, comma-separated (of "
                             + ", ".join(PAIRED_TIMING) + ")")
    args = parser.parse_args()
    if args.base:
        methods = args.methods.split(",")
        unknown = sorted(set(methods) - set(PAIRED_TIMING))
        if unknown:
            parser.error(f"--methods: not timed here: {', '.join(unknown)}")
        paired(args.base, args.minutes if not args.quick else 2.0, args.repeat, args.rounds,
               methods)
        return 0
    if args.quick:
        args.minutes, args.repeat = 2.0, 2
    print(f"fusion benchmark: {args.minutes:g}-minute session, 3 cameras at 30 fps, "
          f"0.5 px noise, one core, best of {args.repeat}")
    rows = []

    def row(stage: str, timing: str, seconds: float, count: int, unit: str, note: str = ""):
        rate = count / seconds
        rows.append({"stage": stage, "timing": timing, "seconds": seconds, "count": count,
                     "rate": rate, "unit": unit, "note": note})
        print(f"  {stage:<26} {seconds * 1e3:9.1f} ms  {rate:>12,.0f} {unit:<13} {note}")

    sessions = {t: session(t, args.minutes) for t in ("typeA", "typeB", "sync")}
    # the peers' views: as many synchronised instants as type A makes points (a synchronised
    # session three times as long, its first instants), timed beside type A's fuse()
    rig_a, obs_a = sessions["typeA"]
    n_type_a = len(fuse(obs_a, rig_a, "typeA"))
    rig_s, obs_s = session("sync", 3 * args.minutes + 1 / 60)
    uv2 = synchronised_views(rig_s, obs_s, (0, 1))[:, :n_type_a]
    uv3 = synchronised_views(rig_s, obs_s, (0, 1, 2))[:, :n_type_a]
    peer_runs = {"cv2.triangulatePoints": (peer_opencv(rig_s, uv2), uv2.shape[1], "2 views")}
    anipose_run = peer_aniposelib(rig_s, uv3)
    if anipose_run is not None:
        peer_runs["aniposelib triangulate"] = (anipose_run, uv3.shape[1], "3 views")
    peer_seconds: dict[str, float] = {}
    for timing, methods in (("typeA", ("typeA", "nearest")),
                            ("typeB", ("typeB", "linear")), ("sync", ("sync",))):
        rig, obs = sessions[timing]
        print(f"\n{timing} timing, {len(obs):,} detections")
        base_s, _ = best_of(args.repeat, lambda obs=obs, rig=rig: prepare(obs, rig))
        row("baseline (prepare)", timing, base_s, len(obs), "detections/s")
        for method in methods:
            if method == "typeA":  # timed in turn with the peers (module docstring)
                times = alternating(args.repeat, lambda obs=obs, rig=rig: fuse(obs, rig, "typeA"),
                                    *(run for run, _, _ in peer_runs.values()))
                seconds, track = times[0], fuse(obs, rig, "typeA")
                peer_seconds.update(zip(peer_runs, times[1:], strict=True))
            else:
                seconds, track = best_of(args.repeat,
                                         lambda m=method, obs=obs, rig=rig: fuse(obs, rig, m))
            row(method, timing, seconds, len(track), "points/s",
                f"{seconds / base_s:5.1f}x baseline")
            if method == "sync":
                row("sync (detections)", timing, seconds, len(obs), "detections/s")
            if method == "typeA":
                seconds, count = type_a_alone(rig, obs, args.repeat)
                row("typeA, fusion alone", timing, seconds, count, "points/s",
                    "prepared session")

    rig, obs = sessions["typeA"]
    print(f"\ntiming and robustness methods (typeA timing, {len(obs):,} detections; "
          f"detections consumed per second)")
    for method in ("smooth", "filter"):
        seconds, _ = best_of(args.repeat, lambda m=method: fuse(obs, rig, m))
        row(method, "typeA", seconds, len(obs), "detections/s")

    print("\npeers, on a synchronised session's instants (as many as typeA's points), "
          "timed in turn with typeA")
    peers = {}
    for name, (_, n, views) in peer_runs.items():
        peers[name] = n / peer_seconds[name]
        row(name, "sync", peer_seconds[name], n, "points/s", views)
    if anipose_run is None:
        print("  aniposelib                 not usable (pip install '.[bench]')")

    type_a = next(r["rate"] for r in rows if r["stage"] == "typeA")
    best_peer = max(peers.values())
    ok = type_a >= TARGET_TYPEA and type_a >= best_peer
    print(f"\ntypeA {type_a:,.0f} points/s: target {TARGET_TYPEA:,}/s and the faster peer "
          f"({best_peer:,.0f}/s, ratio {type_a / best_peer:.2f}): {'met' if ok else 'MISSED'}")
    if args.stream > 0:
        stream(args.stream, args.repeat)
    if args.compile:
        compile_times()
    if args.json:  # the suite's rows (python -m benchmarks), with this bench's own columns
        best_name = max(peers, key=peers.get)
        suite = []
        for r in rows:
            is_type_a = r["stage"] == "typeA"
            suite.append({**r, "stage": f"fusion {r['stage']}", "figure": r["rate"],
                          "target": f">= {TARGET_TYPEA:,} and the faster peer"
                          if is_type_a else "",
                          "ok": ok if is_type_a else None,
                          "peer": best_name if is_type_a else None,
                          "peer_figure": best_peer if is_type_a else None, "better": "higher",
                          "note": f"{r['timing']} timing, {args.minutes:g}-min session, best "
                                  f"of {args.repeat}" + (f"; {r['note']}" if r["note"] else "")})
        with open(args.json, "w") as f:
            json.dump({"minutes": args.minutes, "rows": suite, "target_typeA": TARGET_TYPEA,
                       "met": ok}, f, indent=2)
    return 0 if ok else 1


_FIRST_CALL = """
import time
t0 = time.perf_counter()
from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import fuse
rig = apply_timing(builtin_rig("paper3"), "typeA")
obs = simulate(rig, get_motion("throw"), options=SimulationOptions(noise_px=0.5))[0].best()
t1 = time.perf_counter()
fuse(obs, rig, "typeA")
t2 = time.perf_counter()
fuse(obs, rig, "typeA")
t3 = time.perf_counter()
print(t2 - t1, t3 - t2)
"""


def compile_times() -> None:
    """typeA's first call in a fresh process: numba's cache empty (a temporary
    NUMBA_CACHE_DIR), then filled by that run; and a second call, for comparison."""
    import subprocess
    import sys
    import tempfile

    print("\ntypeA first call in a new process (a throw, 180 detections)")
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold cache (compiles)", "warm cache (loads)"):
            out = subprocess.run([sys.executable, "-c", _FIRST_CALL], env=env, check=True,
                                 capture_output=True, text=True).stdout.split()
            first, second = float(out[0]), float(out[1])
            print(f"  {label:<24} first call {first:7.2f} s, second {second * 1e3:7.2f} ms")


#: the session timing each method is timed on by ``--base`` (the main run's)
PAIRED_TIMING = {"typeA": "typeA", "nearest": "typeA", "typeB": "typeB", "linear": "typeB",
                 "sync": "sync"}

_PAIRED_CHILD = """
import sys, time
from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
import pslog
from pslog.fusion import fuse
minutes, repeat = float(sys.argv[1]), int(sys.argv[2])
assert pslog.__file__.startswith(sys.argv[3]), (pslog.__file__, sys.argv[3])
sessions = {}
for pair in sys.argv[4:]:
    method, timing = pair.split("=")
    if timing not in sessions:
        rig = apply_timing(builtin_rig("paper3"), timing)
        sessions[timing] = rig, simulate(rig, get_motion("turntable"), minutes * 60,
                                         SimulationOptions(noise_px=0.5, seed=0))[0].best()
    rig, obs = sessions[timing]
    points = len(fuse(obs, rig, method))
    best = float("inf")
    for _ in range(repeat):
        start = time.process_time()
        fuse(obs, rig, method)
        best = min(best, time.process_time() - start)
    print(method, best, points)
"""


def paired(base: str, minutes: float, repeat: int, rounds: int,
           methods: list[str] | None = None) -> None:
    """``fuse(..., method)`` for each of ``methods`` (default ``typeA``) under revision
    ``base`` and this tree, alternating in child processes on the same sessions: CPU
    seconds, best of ``repeat`` per child and method."""
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    methods = methods or ["typeA"]
    root = Path(__file__).resolve().parents[1]
    print(f"fuse() with {', '.join(methods)}, {minutes:g}-minute sessions, base {base} "
          f"against this tree, alternating {rounds} times (CPU time, best of {repeat} per "
          f"run); load average {', '.join(f'{x:.1f}' for x in os.getloadavg())}")
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(["git", "-C", str(root), "archive", base, "pslog"],
                                 check=True, capture_output=True).stdout
        # (the children run in an empty folder: ``python -c`` puts its working folder
        # first on sys.path, and a run inside the base's folder timed the base twice)
        base_tree, empty = Path(tmp) / "base", Path(tmp) / "run"
        base_tree.mkdir()
        empty.mkdir()
        subprocess.run(["tar", "-x", "-C", str(base_tree)], input=archive, check=True)
        figures: dict[tuple[str, str], list[float]] = {
            (label, m): [] for label in ("base", "now") for m in methods}
        pairs = [f"{m}={PAIRED_TIMING[m]}" for m in methods]
        for _ in range(rounds):
            for label, path in (("base", str(base_tree)), ("now", str(root))):
                env = dict(os.environ, PYTHONPATH=path)
                out = subprocess.run([sys.executable, "-c", _PAIRED_CHILD, str(minutes),
                                      str(repeat), path, *pairs], env=env, check=True,
                                     cwd=empty, capture_output=True, text=True).stdout
                for line in out.splitlines():
                    method, seconds, points = line.split()
                    rate = int(points) / float(seconds)
                    figures[label, method].append(rate)
                    print(f"  {label:<5} {method:<8} {float(seconds) * 1e3:8.2f} ms  "
                          f"{rate:>12,.0f} points/s")
    for m in methods:
        base_rates, now_rates = np.array(figures["base", m]), np.array(figures["now", m])
        print(f"{m}: best: base {base_rates.max():,.0f}, now {now_rates.max():,.0f} points/s "
              f"(x{now_rates.max() / base_rates.max():.2f}); median ratio of the rounds "
              f"x{float(np.median(now_rates / base_rates)):.2f}")
    print(f"load average at the end {', '.join(f'{x:.1f}' for x in os.getloadavg())}")


def stream(seconds: float, repeat: int) -> None:
    """Milliseconds per push of StreamFuser, every detection pushed alone."""
    print(f"\nstreamed, one detection per push ({seconds:g}-second session, best of {repeat})")
    for timing, methods in (("typeA", ("typeA", "nearest")),
                            ("typeB", ("typeB", "linear", "sync"))):
        rig, obs = session(timing, seconds / 60)
        for method in methods:
            def run(method=method, rig=rig, obs=obs):
                fuser = StreamFuser(rig, method)
                for i in range(len(obs)):
                    fuser.push(obs.time_ns[i:i + 1], obs.camera[i:i + 1], obs.uv[i:i + 1])
            push_s = best_of(repeat, run)[0] / len(obs)
            print(f"  {method:<20} {push_s * 1e3:9.2f} ms per push ({timing} timing)")


if __name__ == "__main__":
    raise SystemExit(main())
