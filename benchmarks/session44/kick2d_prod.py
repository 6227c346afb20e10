"""Type A's ``--confirm-gaps kicks`` / ``breaks`` / ``jumps`` on bench_dirty ``--more``'s
rigs and sessions (docs/methods.md, "Kick instants from the images (session 44)"): per rig
and kind (clean, with the issue's faults), the points beyond 5 cm, the good points (within
5 cm under ``kicks``) each option leaves out, the mean error and the point count; every
far point of ``breaks`` and ``jumps`` listed with its nearest kick.

    PYTHONPATH=.:tests python benchmarks/session44/kick2d_prod.py FIRST [FPS|-] [MISSES]
        [SEEDS] [NOISE]
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_dirty as bd

from pslog.evaluation import errors_m
from pslog.fusion import CONFIRM_GAPS, FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled


def main() -> None:
    argv = sys.argv[1:]
    first = int(argv[0])
    fps = None if len(argv) < 2 or argv[1] == "-" else float(argv[1])
    misses = float(argv[2]) if len(argv) > 2 else 0.0
    n_seeds = int(argv[3]) if len(argv) > 3 else 3
    noise = float(argv[4]) if len(argv) > 4 else 0.3
    g = CONFIRM_GAPS["kicks"]
    kicks = FusionOptions(confirm_gaps=g[0], confirm_every=g[1], confirm_sides=g[2])
    options = {"kicks": kicks, "breaks": replace(kicks, confirm_breaks=True),
               "jumps": replace(kicks, confirm_breaks=True, break_source="image")}
    total: dict[tuple, list] = {}
    start = time.time()
    for rig0 in bd.rigs() + bd.more_rigs():
        rig = rig0 if fps is None else bd.at_rate(rig0, fps)
        runs = bd.more_sessions(n_seeds, 8.0, first)
        for seed, (label, motion, duration, jumps) in enumerate(runs, start=first - 300):
            span = motion.duration if duration is None else duration
            for kind, extra in (("clean", {}), ("faults", bd.faults(rig, seed, span))):
                det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                    noise_px=noise, seed=seed, miss_rate=misses, drop_rate=misses / 2,
                    **extra))
                tracks = {name: fuse_detections(det, rig, ["typeA"], o)[0]["typeA"]
                          for name, o in options.items()}
                base = tracks["kicks"]
                good = errors_m(base, truth) <= 0.05
                key = base.time_ns * 64 + base.camera
                for name, track in tracks.items():
                    err = errors_m(track, truth)
                    lost = ~np.isin(key, track.time_ns * 64 + track.camera) & good
                    row = total.setdefault((rig.name, kind, name), [0, 0, 0.0, 0])
                    row[0] += int(np.count_nonzero(err > 0.05))
                    row[1] += int(np.count_nonzero(lost))
                    row[2] += float(np.nansum(err))
                    row[3] += int(np.count_nonzero(np.isfinite(err)))
                    if name == "kicks":
                        continue
                    for i in np.flatnonzero(err > 0.05):
                        t = track.time_ns[i] / 1e9
                        near = ("" if jumps is None else
                                f" kick {1e3 * (jumps[np.argmin(np.abs(jumps - t))] - t):+.1f} ms")
                        print(f"  FAR {name} {rig.name} {label} {kind} t={t:.4f} "
                              f"err={1e3 * err[i]:.0f} mm "
                              f"std={1e3 * track.quality['std_m'][i]:.0f} mm{near}", flush=True)
    print(f"run {argv}: far (> 5 cm) / good points withheld / mean mm / points")
    for (rig_name, kind, name), (far, lost, err_sum, n) in total.items():
        print(f"{rig_name:10s} {kind:6s} {name:6s} {far:3d} {lost:5d} "
              f"{1000 * err_sum / max(n, 1):7.3f} {n}")
    print(f"({time.time() - start:.0f} s)")


if __name__ == "__main__":
    main()
