# ruff: noqa: E501
"""Issue 10 (session 36, trap36): how rare is session 35's jump trap? For each rig, motion
and held-out noise seed, the filter's output fraction (points / detections), its mean error
and typeA's; prints the sessions below 95 % output, and per (rig, motion) the counts below
80 % and between 80 and 95 %, and the filter/typeA geometric mean.

    PYTHONPATH=. python benchmarks/session36/scan.py --rigs paper2 --motions turntable,spiral \
        --first 48000 --count 300 [--noise 0.3] [--over "chained_jump_restart=False"]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
sys.path.insert(0, str(_ROOT / "benchmarks" / "session28"))
import bench_dirty as bd  # noqa: E402
from test_filter import swing  # noqa: E402
from twocam_per import filter_track, variants_of  # noqa: E402

from pslog.evaluation import _offsets  # noqa: E402
from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.motion import get_motion  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rigs", default="paper2")
    ap.add_argument("--motions", default="turntable,spiral,straight,swing")
    ap.add_argument("--first", type=int, default=48000)
    ap.add_argument("--count", type=int, default=300)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--over", default="", help="FilterOptions, twocam_per's syntax: key=value;key=value")
    a = ap.parse_args()
    over = variants_of("v:" + a.over)[0][1]
    rigs = {r.name: r for r in bd.rigs() + bd.more_rigs()}
    for rname in a.rigs.split(","):
        rig = rigs[rname]
        for mname in a.motions.split(","):
            motion = swing(1.0) if mname == "swing" else get_motion(mname)
            low, near, ratios, worst = 0, 0, [], []
            for seed in range(a.first, a.first + a.count):
                det, truth, _ = simulate_labelled(rig, motion, None, SimulationOptions(noise_px=a.noise, seed=seed))
                ta = fuse_detections(det, rig, ["typeA"], FusionOptions())[0]["typeA"]
                f = filter_track(det, rig, over)
                n = len(det.best())
                ef = np.nanmean(np.linalg.norm(_offsets(f, truth), axis=1)) if len(f) else np.nan
                ea = np.nanmean(np.linalg.norm(_offsets(ta, truth), axis=1))
                ratios.append(ef / ea)
                frac = len(f) / n
                if frac < 0.8:
                    low += 1
                elif frac < 0.95:
                    near += 1
                if frac < 0.95 or ef > ea:
                    worst.append(seed)
                    print(f"  {rname} {mname} {seed}: {len(f)}/{n} ({frac:.0%}) filter {1e3 * ef:.2f} mm typeA {1e3 * ea:.2f} ({ef / ea:.2f}) {dict(f.dropped)}", flush=True)
            r = np.array(ratios)
            ok = np.isfinite(r)
            print(f"{rname} {mname} seeds {a.first}..{a.first + a.count - 1}: <80 % {low}, 80-95 % {near}, "
                  f"filter/typeA gmean {np.exp(np.mean(np.log(r[ok]))):.3f} max {np.max(r[ok]):.2f} (>1: {int(np.sum(r[ok] > 1))})", flush=True)


if __name__ == "__main__":
    main()
