"""``filter``: accuracy against typeA and smooth, and per-detection latency when streamed.

Targets (issue 10): ``filter`` never worse than ``typeA``; at 0.3 px at most half of
``typeA``'s mean error; at most 50 µs median per detection in the streaming form. ``smooth``
(offline, every point uses every detection) is the reference of what the detections allow.

Sessions (rigs of this benchmark, not the tests'): rallies of the tests' own generator
(``tests/_rally.py``: kicks, floor bounces, air drag), the library's ``rally`` (chip kicks
and floor bounces of a golf ball), ``throw`` and the non-ballistic ``spiral``, ``straight``
and ``turntable`` (no gravity, or a centripetal acceleration), and a ball rolling on the
floor with rolling friction, kicked along it (``roll``, of ``tests/test_filter.py``), seen by
cameras around a 3 x 2 m floor with type-A shutters: 3 cameras at 30 fps (two rallies, one
throw, the four non-ballistic motions), 2 and 4 cameras, 3 cameras at 60 fps, 3 cameras with lens
distortion; the turning motions (``spiral``, ``turntable``: the turn model) also on the built-in
``paper3`` (type-A shutters), 4 cameras and 3 distorting cameras; noise 0, 0.3 and 1 px.

Throughput: detections per second of the batch form (``fuse_filter``: one compiled loop over
the detections) on 2-minute 3-camera rallies (``--quick``: 30 s; the library's rally, as
``bench_match.py``'s 90-minute session, and the tests' kicked rally), CPU time, against the
pure-Python filter it replaced (``benchmarks/_filter_base.py``) in the same run; target: the
filter's quarter of issue 12's 8-second budget for every default method of a 90-minute
session (486,000 detections in 2 s).

Latency: every detection of a 3-camera rally, and of 10 s of ``turntable`` (where the turn
model is at work, alone once the other two left the model set), pushed one at a time, (a) into
:class:`pslog.fusion.filter.BallFilter` (the filter's own streaming form, which live mode
uses) and (b) through :class:`pslog.fusion.stream.StreamFuser` (order check and a Track per
push included); median and p99 per detection, in CPU time of this process (the target's
measure: the machine may be shared) and in wall-clock time. ``withheld``: the share of the
filter's points withheld (``Track.dropped``: an unconfirmed jump, or ``std_m`` above the bound);
the means are over the points output.

    python benchmarks/bench_filter.py [--seconds 20] [--minutes 2] [--quick]
    python benchmarks/bench_filter.py --rates [--seeds 1 2 3]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, before numpy loads

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _rally import rally  # noqa: E402
from test_filter import roll  # noqa: E402

from pslog import Camera, Rig, SimulationOptions, get_motion, look_at, simulate  # noqa: E402
from pslog.evaluation import evaluate  # noqa: E402
from pslog.fusion import fuse  # noqa: E402
from pslog.fusion.filter import BallFilter  # noqa: E402
from pslog.fusion.stream import StreamFuser  # noqa: E402
from pslog.rig import apply_timing, builtin_rig  # noqa: E402

METHODS = ("typeA", "smooth", "filter")
NOISES = (0.0, 0.3, 1.0)
TARGET_US = 50.0
#: issue 12: every default method of a 90-minute session (486,000 detections) in 8 s; the
#: filter's share, a quarter of it: 486,000 detections in 2 s
TARGET_RATE = 486_000 / 2.0


def bench_rig(n: int = 3, fps: float = 30.0, distortion: bool = False) -> Rig:
    """``n`` cameras around the 3 x 2 m floor, 2.4-3 m high, type-A shutters."""
    dist = np.array([-0.12, 0.03, 5e-4, -4e-4, 0.0]) if distortion else np.zeros(5)
    cams = []
    for i in range(n):
        angle = 2 * np.pi * i / n - 1.2
        eye = (1.5 + 3.4 * np.cos(angle), 1.0 + 3.0 * np.sin(angle), 2.4 + 0.2 * i)
        R, t = look_at(eye, (1.5, 1.0, 0.6))
        K = [[520.0 + 15 * i, 0.0, 399.5], [0.0, 520.0 + 15 * i, 299.5], [0.0, 0.0, 1.0]]
        cams.append(Camera(f"b{i + 1}", 800, 600, K, dist, R, t, fps, i / (n * fps)))
    return Rig(tuple(cams), f"bench{n}")


def sessions(seconds: float):
    """(label, rig, motion, duration) of every accuracy session."""
    fast, _ = rally(seconds, seed=3)
    slow, _ = rally(seconds, seed=7, speed=4.0, kick_every_s=0.7)
    throw = get_motion("throw")
    paper3 = apply_timing(builtin_rig("paper3"), "typeA")
    return [
        ("rally, 3 cams 30 fps", bench_rig(3), fast, seconds),
        ("slow rally, 3 cams", bench_rig(3), slow, seconds),
        ("library rally, 3 cams", bench_rig(3), get_motion("rally"), seconds),
        ("throw, 3 cams", bench_rig(3), throw, throw.duration),
        ("rally, 2 cams", bench_rig(2), fast, seconds),
        ("rally, 4 cams", bench_rig(4), fast, seconds),
        ("rally, 3 cams 60 fps", bench_rig(3, fps=60.0), fast, seconds),
        ("rally, 3 cams distorted", bench_rig(3, distortion=True), fast, seconds),
        # not ballistic (no gravity, or a centripetal acceleration): the process noise adapts
        ("spiral, 3 cams", bench_rig(3), get_motion("spiral"), None),
        ("straight, 3 cams", bench_rig(3), get_motion("straight"), None),
        ("turntable, 3 cams", bench_rig(3), get_motion("turntable"), None),
        ("roll (kicked), 3 cams", bench_rig(3), roll(seconds, seed=1), seconds),
        # turning (the turn model) on other rigs: the paper's, 4 cameras, lens distortion
        ("spiral, paper3", paper3, get_motion("spiral"), None),
        ("turntable, paper3", paper3, get_motion("turntable"), None),
        ("spiral, 4 cams", bench_rig(4), get_motion("spiral"), None),
        ("turntable, 4 cams", bench_rig(4), get_motion("turntable"), None),
        ("spiral, 3 cams distorted", bench_rig(3, distortion=True), get_motion("spiral"), None),
        ("turntable, 3 cams dist.", bench_rig(3, distortion=True), get_motion("turntable"),
         None),
    ]


def accuracy_table(seconds: float) -> bool:
    print(f"accuracy: mean 3D error, mm (ratios to typeA); {seconds:g} s rallies")
    print(f"  {'session':<25} {'noise':>5}  {'typeA':>7}  {'smooth':>7} {'(ratio)':>7}  "
          f"{'filter':>7} {'(ratio)':>7}  {'filter std/err':>14} {'withheld':>8}")
    ok = True
    for label, rig, motion, duration in sessions(seconds):
        for noise in NOISES:
            detections, truth = simulate(rig, motion, duration,
                                         SimulationOptions(noise_px=noise, seed=11))
            obs = detections.best()
            means, tracks = {}, {}
            for method in METHODS:
                tracks[method] = fuse(obs, rig, method)
                means[method] = evaluate(tracks[method], truth).mean_mm
            ratio = means["filter"] / means["typeA"]
            err = np.linalg.norm(tracks["filter"].position_world
                                 - truth.at(tracks["filter"].time_ns), axis=1)
            calib = np.nanmedian(tracks["filter"].quality["std_m"]) / np.nanmedian(err)
            target = ratio <= (0.5 if noise == 0.3 else 1.0)
            ok &= target
            dropped = sum(tracks["filter"].dropped.values())
            withheld = dropped / (dropped + len(tracks["filter"]))
            print(f"  {label:<25} {noise:5.1f}  {means['typeA']:7.3f}  {means['smooth']:7.3f} "
                  f"{means['smooth'] / means['typeA']:7.2f}  {means['filter']:7.3f} "
                  f"{ratio:7.2f}  {calib:14.2f} {100 * withheld:7.1f}%"
                  f"{'' if target else '  MISSED'}")
    return ok


def rate_rigs():
    """(name, rig at ``fps``) of the frame-rate grid: the built-in ``paper3``, the tests'
    3-camera lab rig (lens distortion), and this benchmark's 2- and 4-camera rigs."""
    from test_filter import lab_rig
    from test_filter_rates import rig_at

    paper3 = apply_timing(builtin_rig("paper3"), "typeA")
    return [("paper3", lambda fps: rig_at(paper3, *(fps,) * 3)),
            ("lab3", lambda fps: lab_rig(3, fps=fps)),
            ("2 cams", lambda fps: bench_rig(2, fps=fps)),
            ("4 cams", lambda fps: bench_rig(4, fps=fps))]


def rates_table(rates=(30.0, 60.0, 120.0, 240.0), seconds: float = 4.0,
                motions=("straight", "spiral", "turntable", "rally"),
                seeds=(11,)) -> bool:
    """``filter`` against ``typeA`` on every rig of :func:`rate_rigs` x frame rate x motion
    x noise (0, 0.3, 1 px) x noise seed (one session at 0 px, where the seeds give the same
    detections): mean error, mm, and the ratio; the targets (never worse; at 0.3 px at
    most half) per row, then per frame rate and noise the geometric mean and largest ratio
    and the sessions missing the target, by motion. The library's motions over their own
    duration, the tests' kicked rally over ``seconds``."""
    print(f"frame rates: mean 3D error, mm; {seconds:g} s sessions; noise seeds "
          f"{', '.join(map(str, seeds))}")
    print(f"  {'rig':<7} {'fps':>4} {'motion':<10} {'seed':>4} " + "  ".join(
        f"{'A ' + format(n, 'g'):>7} {'F':>7} {'F/A':>5}" for n in NOISES))
    ok = True
    kicked, _ = rally(seconds, seed=3)
    results = []  # (fps, noise, motion, ratio, met)
    for rig_name, make in rate_rigs():
        for fps in rates:
            rig = make(fps)
            for motion_name in motions:
                motion = kicked if motion_name == "rally" else get_motion(motion_name)
                duration = seconds if motion_name == "rally" else motion.duration
                for i, seed in enumerate(seeds):
                    cells = []
                    for noise in NOISES:
                        if noise == 0 and i:
                            cells.append(f"{'':7} {'':7} {'':5} ")
                            continue
                        detections, truth = simulate(rig, motion, duration, SimulationOptions(
                            noise_px=noise, seed=seed))
                        obs = detections.best()
                        a = evaluate(fuse(obs, rig, "typeA"), truth).mean_mm
                        f = evaluate(fuse(obs, rig, "filter"), truth).mean_mm
                        met = f / a <= (0.5 if noise == 0.3 else 1.0)
                        ok &= met
                        results.append((fps, noise, motion_name, f / a, met))
                        cells.append(f"{a:7.3f} {f:7.3f} {f / a:5.2f}{' ' if met else '!'}")
                    print(f"  {rig_name:<7} {fps:4g} {motion_name:<10} {seed:4d} "
                          + " ".join(cells), flush=True)
    print("  per rate and noise: filter / typeA, geometric mean (largest); sessions missing "
          "the target (0 and 1 px: worse than typeA; 0.3 px: above half of it), by motion")
    for fps in rates:
        for noise in NOISES:
            rows = [r for r in results if r[0] == fps and r[1] == noise]
            ratios = np.array([r[3] for r in rows])
            missed = [r[2] for r in rows if not r[4]]
            by_motion = ", ".join(f"{m} {missed.count(m)}" for m in motions if m in missed)
            print(f"  {fps:4g} fps {noise:3g} px: {np.exp(np.mean(np.log(ratios))):5.2f} "
                  f"({ratios.max():.2f}); missed {len(missed)} of {len(rows)}"
                  f"{' (' + by_motion + ')' if by_motion else ''}")
    return ok


_ROWS: list[dict] = []  # for --json


def latency(seconds: float, motion=None, name: str = "rally") -> bool:
    rig = bench_rig(3)
    if motion is None:
        motion, _ = rally(seconds, seed=3)
    detections, _ = simulate(rig, motion, seconds, SimulationOptions(noise_px=0.3, seed=5))
    obs = detections.best()
    rows = list(zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(), strict=True))
    ok = True
    print(f"  {name}:")
    for label in ("BallFilter.push", "StreamFuser.push"):
        wall, cpu = np.empty(len(rows)), np.empty(len(rows))
        if label == "BallFilter.push":
            flt = BallFilter(rig)

            def push(t, c, uv, flt=flt):
                flt.push(t, c, uv[0], uv[1])
        else:
            push = StreamFuser(rig, "filter").push
        for i, (t, c, uv) in enumerate(rows):
            start, start_cpu = time.perf_counter_ns(), time.process_time_ns()
            push(t, c, uv)
            cpu[i] = time.process_time_ns() - start_cpu
            wall[i] = time.perf_counter_ns() - start
        median = np.median(cpu) / 1e3
        met = median <= TARGET_US
        ok &= met
        _ROWS.append({"stage": f"filter {label} ({name})", "figure": median,
                      "unit": "µs/det CPU", "target": f"<= {TARGET_US:g}", "ok": bool(met),
                      "peer": None, "peer_figure": None, "better": "lower",
                      "note": f"{len(rows):,} detections, median"})
        print(f"  {label:<17} CPU median {median:6.1f} µs  p99 {np.percentile(cpu, 99) / 1e3:7.1f}"
              f" µs | wall median {np.median(wall) / 1e3:6.1f} µs  p99 "
              f"{np.percentile(wall, 99) / 1e3:7.1f} µs  ({len(rows):,} detections)"
              f"{'' if met else '  above the 50 µs target'}")
    return ok


def throughput(minutes: float) -> bool:
    """Detections per second of ``fuse_filter`` (the batch form: one compiled loop) on two
    ``minutes``-long 3-camera 30 fps sessions on ``paper3`` (type-A shutters): the library's
    ``rally`` at 0.5 px (the session of ``bench_match.py``'s 90-minute target: the track
    rarely restarts) and the tests' kicked rally at 0.3 px (hard kicks: restarts, whose window
    fits stay in Python, cost a larger share). CPU time of this process, best of 3 after a
    warm-up call (the first call's time, numba's compile or cache load, is printed apart);
    the pure-Python filter it replaced (``benchmarks/_filter_base.py``) on the same
    detections in the same run, alternating, as the peer. The target holds the library
    rally (the 90-minute session's kind); the kicked rally's row is informative."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import _filter_base

    from pslog.fusion.filter import fuse_filter

    seconds = 60.0 * minutes
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    kicked, _ = rally(seconds, seed=3)
    ok = True
    for name, motion, noise, held in (("library rally", get_motion("rally"), 0.5, True),
                                      ("kicked rally", kicked, 0.3, False)):
        detections, _ = simulate(rig, motion, seconds, SimulationOptions(noise_px=noise,
                                                                         seed=1))
        obs = detections.best()
        start = time.process_time()
        fuse_filter(obs.select(slice(0, 50)), rig)
        warm = time.process_time() - start
        best = {"compiled": np.inf, "pure Python": np.inf}
        inits = 0
        for _ in range(3):
            for label, fn in (("compiled", fuse_filter),
                              ("pure Python", _filter_base.fuse_filter)):
                start = time.process_time()
                track = fn(obs, rig)
                best[label] = min(best[label], time.process_time() - start)
                inits = int(np.sum(track.quality["init"]))
        rate, peer = len(obs) / best["compiled"], len(obs) / best["pure Python"]
        met = rate >= TARGET_RATE
        ok &= met or not held
        _ROWS.append({"stage": f"filter fuse_filter ({name})", "figure": rate,
                      "unit": "det/s CPU", "target": f">= {TARGET_RATE:,.0f}" if held else "-",
                      "ok": bool(met) if held else None,
                      "peer": "pure-Python filter (base)", "peer_figure": peer,
                      "better": "higher",
                      "note": f"{len(obs):,} detections, {minutes:g} min paper3, {inits} "
                              f"starts; first call {warm:.1f} s (compile or cache load)"})
        print(f"  {name:<14} {rate:>9,.0f} detections/s CPU ({best['compiled']:.3f} s for "
              f"{len(obs):,}, {inits} starts); pure-Python filter {peer:,.0f}/s "
              f"({best['pure Python']:.2f} s): x{rate / peer:.1f}; first call {warm:.2f} s"
              f"{'' if met or not held else '  below the target'}")
    return ok


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="rally length")
    parser.add_argument("--quick", action="store_true", help="latency only")
    parser.add_argument("--json", default=None, help="write the latency rows as JSON")
    parser.add_argument("--minutes", type=float, default=None,
                        help="session of the throughput figure (default 2, --quick 0.5)")
    parser.add_argument("--rates", action="store_true",
                        help="only the frame-rate grid (30-240 fps, 4 rigs, 4 motions)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[11],
                        help="noise seeds of the --rates grid (default 11)")
    args = parser.parse_args()
    if args.rates:
        return 0 if rates_table(seeds=tuple(args.seeds)) else 1
    print("throughput, batch (3 cameras, 30 fps):")
    rate_ok = throughput(args.minutes or (0.5 if args.quick else 2.0))
    print("latency per detection, streamed one at a time (3 cameras, 0.3 px):")
    fast = latency(max(args.seconds, 10.0))
    # the turn model (in the model set while the ball turns) costs more per detection
    fast &= latency(10.0, get_motion("turntable"), "turntable (the turn model at work)")
    accurate = True if args.quick else accuracy_table(args.seconds)
    print(f"targets: throughput {'met' if rate_ok else 'MISSED'}; latency "
          f"{'met' if fast else 'MISSED'}; accuracy {'met' if accurate else 'MISSED'}")
    if args.json:
        import json

        with open(args.json, "w") as f:
            json.dump({"rows": _ROWS}, f)
    return 0 if rate_ok and fast and accurate else 1


if __name__ == "__main__":
    raise SystemExit(main())
