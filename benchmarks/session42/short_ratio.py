"""Session 42: the filter's (and the others') dirty/clean ratio on short motions, per seed.

    python benchmarks/session42/short_ratio.py RIG MOTION FIRST_SEED SEEDS [METHODS]

bench_dirty --more's faults (spurious 5 %, the static object, a 0.5-s blackout) on one motion
of the library, seed by seed: the mean error clean / blackout alone / spurious+distractor
alone / all faults / without the blind camera (mm), the ratio and the data ratio.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_dirty as B

from pslog.evaluation import errors_m
from pslog.fusion import CONFIRM_GAPS, FusionOptions
from pslog.motion import get_motion
from pslog.simulation import SimulationOptions, simulate_labelled


def main() -> None:
    rig_name, motion_name = sys.argv[1], sys.argv[2]
    first, n = int(sys.argv[3]), int(sys.argv[4])
    methods = (sys.argv[5] if len(sys.argv) > 5 else "typeA,smooth,filter").split(",")
    rig = {r.name: r for r in B.rigs() + B.more_rigs()}[rig_name]
    c = CONFIRM_GAPS["kicks"]
    options = FusionOptions(confirm_gaps=c[0], confirm_every=c[1], confirm_sides=c[2],
                            confirm_breaks=c[3])
    motion = get_motion(motion_name)
    span = motion.duration
    ratios: dict[str, list] = {m: [] for m in methods}
    for seed in range(first, first + n):
        fault = B.faults(rig, seed, span)
        cam, start, length = fault["blackouts"][0]
        kinds = {"clean": {}, "blackout": {"blackouts": fault["blackouts"]},
                 "spurious": {k: v for k, v in fault.items() if k != "blackouts"},
                 "dirty": fault, "without": {"blackouts": ((cam, 0.0, span + 1.0),)}}
        errs = {}
        tracks = {}
        for kind, extra in kinds.items():
            det, truth, _ = simulate_labelled(rig, motion, None, SimulationOptions(
                noise_px=0.3, seed=seed, **extra))
            tracks[kind] = B._fused(det, rig, methods, options)
            errs[kind] = {m: errors_m(tracks[kind][m], truth) for m in methods}
        for m in methods:
            mean = {k: float(np.nanmean(errs[k][m])) * 1e3 for k in kinds}
            data = B._data_ratio(tracks, m, errs_for(errs, m), start, length)
            r = mean["dirty"] / mean["clean"]
            ratios[m].append((r, data))
            print(f"{seed} {m:7s} blind {cam} {start:.2f}s clean {mean['clean']:.3f} "
                  f"blackout {mean['blackout']:.3f} spurious {mean['spurious']:.3f} "
                  f"dirty {mean['dirty']:.3f} without {mean['without']:.3f} mm  "
                  f"ratio {r:.3f} data {data:.3f}", flush=True)
    for m in methods:
        r = np.array(ratios[m])
        print(f"{m}: ratio median {np.median(r[:, 0]):.3f} max {r[:, 0].max():.3f}; "
              f"> 1.2: {(r[:, 0] > 1.2).sum()} of {len(r)}; ratio - data median "
              f"{np.median(r[:, 0] - r[:, 1]):+.3f} max {np.max(r[:, 0] - r[:, 1]):+.3f}")


def errs_for(errs: dict, m: str) -> dict:
    return {k: v[m] for k, v in errs.items()}


if __name__ == "__main__":
    main()
