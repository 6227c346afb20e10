"""Session 41: every point beyond 5 cm of bench_dirty --more's clean sessions, listed.

    python benchmarks/session41/far_points.py FIRST_SEED [SEEDS]

Per point: rig, session, method, time, error (mm) and its std_m, camera, the nearest
kick or bounce before it (velocity jumps > 1 m/s between truth samples) and the session's
end.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_dirty as B

from pslog.evaluation import errors_m
from pslog.fusion import CONFIRM_GAPS, FusionOptions
from pslog.simulation import SimulationOptions, simulate_labelled


def main() -> None:
    first = int(sys.argv[1])
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 4
    methods = ["typeA", "smooth", "filter"]
    confirm = CONFIRM_GAPS["kicks"]
    options = FusionOptions(confirm_gaps=confirm[0], confirm_every=confirm[1],
                            confirm_sides=confirm[2], confirm_breaks=confirm[3])
    points = dict.fromkeys(methods, 0)
    for rig in B.rigs() + B.more_rigs():
        runs = B.more_sessions(n, 8.0, first)
        for seed, (label, motion, duration, kicks) in enumerate(runs, start=first - 300):
            det, truth, _ = simulate_labelled(rig, motion, duration,
                                              SimulationOptions(noise_px=0.3, seed=seed))
            tracks = B._fused(det, rig, methods, options)
            if True:  # kicks and bounces from the truth: velocity jumps
                t = truth.time_ns / 1e9
                v = np.diff(truth.position_world, axis=0) / np.diff(t)[:, None]
                jump = np.linalg.norm(np.diff(v, axis=0), axis=1)
                kicks = t[1:-1][jump > 1.0]
            for m in methods:
                err = errors_m(tracks[m], truth)
                std = np.asarray(tracks[m].quality["std_m"])
                points[m] += int(np.isfinite(err).sum())
                for i in np.flatnonzero(err > B.MAX_ERROR_M):
                    ts = tracks[m].time_ns[i] / 1e9
                    before = kicks[kicks <= ts + 1e-9]
                    k = f"{(ts - before[-1]) * 1e3:6.1f} ms after a kick" if len(before) else \
                        "no kick before"
                    print(f"{rig.name:7s} {label:14s} {m:7s} t={ts:8.4f} s "
                          f"err {err[i] * 1e3:6.1f} mm (std {std[i] * 1e3:5.1f} mm, "
                          f"{err[i] / std[i]:4.1f} sigma) cam {tracks[m].camera[i]} {k}, "
                          f"{(t[-1] - ts) * 1e3:.0f} ms before the end",
                          flush=True)
    print("points scored:", points)


if __name__ == "__main__":
    main()
