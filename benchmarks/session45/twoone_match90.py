"""Session 45: ``smooth`` on bench_match's / smooth_equality's 90-minute ``paper3`` rally (0.5
px, seed 1) against the truth: mean error, points beyond 5 cm, and around each of
``_two_against_one``'s merges (where this tree has it) the mean error within 0.25 s; the
errors in an ``.npz`` to compare two trees point by point.

    PYTHONPATH=.:tests python benchmarks/session45/twoone_match90.py OUT_PREFIX [MINUTES]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402

import numpy as np  # noqa: E402

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate  # noqa: E402
from pslog.estimation import trajectory  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import fuse  # noqa: E402


def trace_merges() -> list:
    """Each merge ``trajectory._two_against_one`` makes from now on, as ``(the problem's t0
    ns, the breaks it removed, the ones it added)`` (s from t0), in the list returned (empty
    where this tree has no such rule)."""
    merges: list = []
    if hasattr(trajectory, "_two_against_one"):
        real = trajectory._two_against_one

        def traced(*args, **kwargs):
            out = real(*args, **kwargs)
            before, after = np.concatenate(args[7]), np.concatenate(out)
            if len(before) != len(after) or np.any(before != after):
                merges.append((args[0].t0_ns, np.setdiff1d(before, after),
                               np.setdiff1d(after, before)))
            return out

        trajectory._two_against_one = traced
    return merges


def main() -> None:
    prefix = sys.argv[1]
    minutes = float(sys.argv[2]) if len(sys.argv) > 2 else 90.0
    merges = trace_merges()
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, truth = simulate(rig, get_motion("rally"), 60 * minutes,
                          SimulationOptions(noise_px=0.5, seed=1))
    track = fuse(det, rig, "smooth")
    err = errors_m(track, truth)
    np.savez(f"{prefix}.npz", time=track.time_ns, err=err)
    print(f"{minutes:g} min: mean {1e3 * np.nanmean(err):.4f} mm, max "
          f"{1e3 * np.nanmax(err):.1f}, >5cm {int(np.sum(err > 0.05))}")
    t = track.time_ns / 1e9
    for t0_ns, gone, new in merges:
        at = new[0] + t0_ns / 1e9
        near = np.abs(t - at) < 0.25
        print(f"    merged {(gone + t0_ns / 1e9).round(4)} -> {(new + t0_ns / 1e9).round(4)}:"
              f" within 0.25 s mean {1e3 * np.nanmean(err[near]):.3f} mm, max "
              f"{1e3 * np.nanmax(err[near]):.1f}")


if __name__ == "__main__":
    main()
