"""``filter`` error per phase, and the floor of its process noise (issue 10, session 11).

Two tables, each with the filter as it is and with ``accel_psd`` = 0.01 m²/s³ on every rig
(the floor before session 11), on the same detections:

1. ``--rates``' sessions on the sparsest rig (``bench_filter.py``'s 2 cameras at 30 fps,
   60 detections/s; ``straight``, ``spiral``, ``turntable`` over their own duration and a
   4 s kicked rally of ``tests/_rally.py``; 0.3 px; ``--seeds``): ``filter`` and ``smooth``
   (offline: it sees the future) over ``typeA`` per session, and the filter's mean error,
   mm, per phase: the time since the track's start or the rally's latest bounce or kick,
   below 0.15 s, 0.15-0.4 s, after 0.4 s (points per phase in brackets).
2. A ball whose drag is not the model's (the golf ball's 0.0084 /m): the tests' rally
   generator with ``drag_per_m`` 0.0084, 0.015, 0.03, 0.05, two motion seeds x two noise
   seeds, 6 s, 0.3 px, on 2 and 3 cameras at 30 fps and 3 at 120 fps: ``filter / typeA``,
   mean (largest).

    python benchmarks/bench_filter_phases.py [--seeds 1 2 3] [--no-drag]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, before numpy loads

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from _rally import rally  # noqa: E402
from bench_filter import bench_rig  # noqa: E402

from pslog import SimulationOptions, get_motion, simulate  # noqa: E402
from pslog.evaluation import evaluate  # noqa: E402
from pslog.fusion import fuse  # noqa: E402
from pslog.fusion.filter import FilterOptions, fuse_filter  # noqa: E402

#: The floor of q before session 11, on every rig.
OLD = FilterOptions(accel_psd=0.01)
PHASES = ((0.0, 0.15), (0.15, 0.4), (0.4, np.inf))


def _errors_mm(track, truth) -> np.ndarray:
    return np.linalg.norm(track.position_world - truth.at(track.time_ns), axis=1) * 1e3


def _since_s(track, first_ns: int, events: np.ndarray) -> np.ndarray:
    """Seconds since the track's first detection or the latest event before each point."""
    t = track.time_ns / 1e9
    since = t - first_ns / 1e9
    if len(events):
        i = np.searchsorted(events, t, side="right") - 1
        last = np.where(i >= 0, events[np.clip(i, 0, None)], -np.inf)
        since = np.minimum(since, t - last)
    return since


def phases(seeds) -> None:
    rig = bench_rig(2)
    kicked, events = rally(4.0, seed=3)
    print("2 cameras at 30 fps, 0.3 px: filter and smooth / typeA; filter's error per phase, "
          "mm (points), now | with the 0.01 floor")
    head = "  ".join(f"{a:g}-{b:g} s" for a, b in PHASES)
    print(f"  {'motion':<10} {'seed':>4} {'typeA':>6} {'smooth':>6} {'filter':>6} {'0.01':>6}"
          f"   {head}")
    missed = {"now": 0, "0.01": 0}
    for name in ("straight", "spiral", "turntable", "rally"):
        motion = kicked if name == "rally" else get_motion(name)
        ev = np.asarray(events) if name == "rally" else np.zeros(0)
        duration = 4.0 if name == "rally" else motion.duration
        for seed in seeds:
            det, truth = simulate(rig, motion, duration, SimulationOptions(noise_px=0.3,
                                                                           seed=seed))
            obs = det.best()
            a = evaluate(fuse(obs, rig, "typeA"), truth).mean_mm
            s = evaluate(fuse(obs, rig, "smooth"), truth).mean_mm
            cells, ratios = [], []
            for key, options in (("now", None), ("0.01", OLD)):
                track = fuse_filter(obs, rig, options=options)
                err = _errors_mm(track, truth)
                since = _since_s(track, int(obs.time_ns[0]), ev)
                ratios.append(err.mean() / a)
                missed[key] += err.mean() / a > 0.5
                cells.append([(err[(since >= lo) & (since < hi)]) for lo, hi in PHASES])
            per = "  ".join(f"{now.mean():5.2f} | {old.mean():5.2f} ({len(now)})"
                            for now, old in zip(*cells, strict=True))
            print(f"  {name:<10} {seed:4d} {a:6.2f} {s / a:6.2f} {ratios[0]:6.2f} "
                  f"{ratios[1]:6.2f}   {per}", flush=True)
    n = 4 * len(seeds)
    print(f"  above half of typeA: {missed['now']} of {n} (with the 0.01 floor "
          f"{missed['0.01']})")


def drag() -> None:
    print("a ball whose drag is not the model's (0.0084 /m): filter / typeA, mean (largest) "
          "over 4 sessions, now | with the 0.01 floor")
    rigs = (("2 x 30 fps", bench_rig(2)), ("3 x 30 fps", bench_rig(3)),
            ("3 x 120 fps", bench_rig(3, fps=120.0)))
    for k in (0.0084, 0.015, 0.03, 0.05):
        cells = []
        for label, rig in rigs:
            r = {"now": [], "0.01": []}
            for motion_seed in (5, 6):
                motion, _ = rally(6.0, seed=motion_seed, drag_per_m=k)
                for seed in (1, 2):
                    det, truth = simulate(rig, motion, 6.0, SimulationOptions(noise_px=0.3,
                                                                              seed=seed))
                    obs = det.best()
                    a = evaluate(fuse(obs, rig, "typeA"), truth).mean_mm
                    for key, options in (("now", None), ("0.01", OLD)):
                        f = evaluate(fuse_filter(obs, rig, options=options), truth).mean_mm
                        r[key].append(f / a)
            cells.append(f"{label} {np.mean(r['now']):.3f} ({max(r['now']):.2f}) | "
                         f"{np.mean(r['0.01']):.3f} ({max(r['0.01']):.2f})")
        print(f"  drag {k:.4f} /m: " + ";  ".join(cells), flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--no-drag", action="store_true", help="the phase table only")
    args = parser.parse_args()
    phases(args.seeds)
    if not args.no_drag:
        drag()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
