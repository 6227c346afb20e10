"""smooth throughput: detections per second fitted into one trajectory, on one core.

Target (issue 9): smooth >= 50,000 detections/s. The baseline, measured in the same run on
the same session, is ``typeA`` (the paper's method), so the ratio says what the continuous
trajectory costs beyond it. The session is a rally (kicks, floor bounces, air drag) seen by
three 30 fps cameras with 0.3 px noise, built by the tests' own rally generator. Both
methods are first run once on the session's first three seconds, so the timings are the fits'
own cost, not the one-time import of scipy and first-call setup of a fresh interpreter (about
0.2-0.5 s, paid once per process).

    python benchmarks/bench_smooth.py [--minutes 2] [--repeat 1]
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
from _rally import rally  # noqa: E402
from bench_fusion import best_of  # noqa: E402

from pslog import SimulationOptions, apply_timing, builtin_rig, simulate  # noqa: E402
from pslog.evaluation import evaluate  # noqa: E402
from pslog.fusion import fuse  # noqa: E402

TARGET = 50_000


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=2.0, help="session length")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--json", default=None, help="write the rows as JSON")
    args = parser.parse_args()
    duration = args.minutes * 60
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion, _ = rally(duration, seed=7, speed=4.0, kick_every_s=0.7)
    detections, truth = simulate(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=7))
    obs = detections.best()
    print(f"smooth benchmark: {args.minutes:g}-minute rally, 3 cameras at 30 fps, 0.3 px "
          f"noise, {len(obs):,} detections, best of {args.repeat}")
    warm = obs.select(obs.time_ns < obs.time_ns[0] + 3 * 10**9)
    for method in ("typeA", "smooth"):  # imports and first-call setup, outside the timings
        fuse(warm, rig, method)
    base_s, type_a = best_of(args.repeat, lambda: fuse(obs, rig, "typeA"))
    seconds, smooth = best_of(args.repeat, lambda: fuse(obs, rig, "smooth"))
    rate = len(obs) / seconds
    ok = rate >= TARGET
    for name, s, track in (("typeA (baseline)", base_s, type_a), ("smooth", seconds, smooth)):
        a = evaluate(track, truth)
        print(f"  {name:<17} {s * 1e3:9.1f} ms  {len(obs) / s:>10,.0f} detections/s  "
              f"mean {a.mean_mm:6.3f} mm  p95 {a.p95_mm:6.3f} mm  max {a.max_mm:7.3f} mm")
    print(f"  smooth / typeA time: {seconds / base_s:.1f}x; target {TARGET:,} detections/s: "
          f"{'met' if ok else 'MISSED'}")
    print(f"  smooth points: {len(smooth):,}, median std "
          f"{np.median(smooth.quality['std_m']) * 1e3:.2f} mm")
    if args.json:
        import json

        with open(args.json, "w") as f:
            json.dump({"rows": [{"stage": "smooth", "figure": rate, "unit": "det/s",
                                 "target": f">= {TARGET:,}", "ok": ok, "peer": None,
                                 "peer_figure": None, "better": "higher",
                                 "note": f"{args.minutes:g}-min rally; typeA same run "
                                         f"{len(obs) / base_s:,.0f} det/s"}]}, f)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
