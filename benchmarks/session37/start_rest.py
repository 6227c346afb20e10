"""Session 37 (start37): the cost of the unmoved-start doubt where the ball itself is at rest
at a session's start. A ball at rest at (1.0, 1.0, 0.8) m for REST seconds, then either
dropped from rest (bouncing) or kicked (3 m/s sideways, 2 m/s up), 2 s in all; paper3 and
paper2 (type-A shutters), 0.3 px; faults: none, spurious blobs in 5 % of frames, a static
object every camera sees at (1.0, 2.0, 0.1), both. Per method (nearest, typeA, filter):
points output, points beyond 5 cm, choices left out as doubt, nearest's NEES. Run with the
tree to measure on PYTHONPATH (before / after).

    python benchmarks/session37/start_rest.py [--seeds 50400 50401 50402]
"""

from __future__ import annotations

import argparse

import numpy as np

from pslog.evaluation import errors_m, mahalanobis_sq
from pslog.fusion import fuse
from pslog.motion import Motion, ballistic_with_bounces
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled

P0 = np.array([1.0, 1.0, 0.8])


def rest_then(rest: float, v0) -> Motion:
    def position(t):
        t = np.asarray(t, dtype=np.float64)
        out = ballistic_with_bounces(P0, np.asarray(v0, dtype=np.float64), t - rest)
        out[t < rest] = P0
        return out
    return Motion(f"rest{rest}", 2.0, position)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, nargs="+", default=[50400, 50401, 50402])
    args = parser.parse_args()
    faults = {"clean": {}, "blobs": {"spurious_rate": 0.05},
              "object": {"distractors": ((None, (1.0, 2.0, 0.1)),)},
              "both": {"spurious_rate": 0.05, "distractors": ((None, (1.0, 2.0, 0.1)),)}}
    total: dict = {}
    for rig_name in ("paper3", "paper2"):
        rig = apply_timing(builtin_rig(rig_name), "typeA")
        for rest in (0.1, 0.3, 0.6):
            for _kind, v0 in (("drop", (0.0, 0.0, 0.0)), ("kick", (3.0, 0.0, 2.0))):
                motion = rest_then(rest, v0)
                for fault, extra in faults.items():
                    for seed in args.seeds:
                        det, truth, _ = simulate_labelled(rig, motion, 2.0, SimulationOptions(
                            noise_px=0.3, seed=seed, **extra))
                        for m in ("nearest", "typeA", "filter"):
                            tr = fuse(det, rig, m)
                            e = errors_m(tr, truth)
                            d2 = mahalanobis_sq(tr, truth)
                            key = (rig_name, fault, m)
                            row = total.setdefault(key, [0, 0, 0, 0.0, 0])
                            row[0] += len(tr)
                            row[1] += int(np.sum(e > 0.05))
                            row[2] += int(tr.dropped.get("doubt", 0))
                            if d2 is not None:
                                row[3] += float(np.nansum(d2))
                                row[4] += int(np.sum(np.isfinite(d2)))
    print("| rig | faults | method | points | > 5 cm | left out as doubt | NEES |")
    print("|---|---|---|---|---|---|---|")
    for (rig_name, fault, m), (n, far, doubt, d2, n2) in total.items():
        nees = d2 / n2 / 3 if n2 else float("nan")
        print(f"| {rig_name} | {fault} | {m} | {n} | {far} | {doubt} | {nees:.2f} |")


if __name__ == "__main__":
    main()
