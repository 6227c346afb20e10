"""Session 45: the two 120-second rallies with misses that ``smooth_equality.py`` fits
(``paper3`` and ``lab3``, 0.5 px, misses 0.2, drops 0.1, jitter 0.5 ms; its seeds 144 and
148), fused by ``smooth`` against the truth: mean / largest error, points beyond 5 cm, and
each error in an ``.npz`` (to compare two trees point by point); ``_two_against_one``'s
merges, where this tree has it.

    PYTHONPATH=.:tests python benchmarks/session45/twoone_rally120.py OUT_PREFIX
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fusion_equality import _lab_rig  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from twoone_match90 import trace_merges  # noqa: E402

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import fuse  # noqa: E402
from pslog.simulation import simulate_labelled  # noqa: E402


def main() -> None:
    prefix = sys.argv[1]
    merges = trace_merges()
    rigs = {"paper3": (apply_timing(builtin_rig("paper3"), "typeA"), 144),
            "lab3": (_lab_rig(), 148)}
    for name, (rig, seed) in rigs.items():
        merges.clear()
        det, truth, _ = simulate_labelled(rig, get_motion("rally"), duration=120.0,
                                          options=SimulationOptions(
                                              noise_px=0.5, seed=seed, miss_rate=0.2,
                                              drop_rate=0.1, jitter_s=0.0005))
        track = fuse(det, rig, "smooth")
        err = errors_m(track, truth)
        np.savez(f"{prefix}_{name}.npz", time=track.time_ns, camera=track.camera, err=err)
        print(f"{name}: mean {1e3 * np.nanmean(err):.4f} mm, max {1e3 * np.nanmax(err):.1f}, "
              f">5cm {int(np.sum(err > 0.05))}, points {int(np.sum(np.isfinite(err)))}")
        for t0_ns, gone, new in merges:
            print(f"    merged {(gone + t0_ns / 1e9).round(4)} -> "
                  f"{(new + t0_ns / 1e9).round(4)}")


if __name__ == "__main__":
    main()
