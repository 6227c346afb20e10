"""Session 45: `smooth` on `paper3` rally-78502 of ``bench_dirty.py --more --first-seed
78500`` alone (clean and with the faults), as bench_dirty builds it: the mean error, the
points beyond 5 cm, and the breaks the fit kept near the kicks.

    PYTHONPATH=.:tests python benchmarks/session45/twoone_78502.py [SEED] [MISSES] [RIG]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
import bench_dirty as bd  # noqa: E402
from _rally import dirty_rally  # noqa: E402

from pslog.estimation import trajectory  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def _traced() -> None:
    """Print what ``trajectory._two_against_one`` tests and changes (the breaks in s since
    the fit's first detection; the costs of the two models, σ²)."""
    two_against_one, region_costs = trajectory._two_against_one, trajectory._region_costs
    state = {"on": False}

    def costs(*args):
        out = region_costs(*args)
        if state["on"] and out is not None:
            pair, one = args[-1][1]
            print(f"    pair {pair[0]:.4f} {pair[1]:.4f} (apart {1e3 * (pair[1] - pair[0]):.1f}"
                  f" ms) against {one[0]:.4f}: the second gains {out[1] - out[0]:.1f}")
        return out

    def traced(*args, **kwargs):
        state["on"] = True
        try:
            out = two_against_one(*args, **kwargs)
        finally:
            state["on"] = False
        before, after = np.concatenate(args[7]), np.concatenate(out)
        print(f"    spacing {1e3 * args[6]:.2f} ms; gone {np.setdiff1d(before, after).round(4)},"
              f" new {np.setdiff1d(after, before).round(4)}")
        return out

    trajectory._two_against_one = traced
    trajectory._region_costs = costs


def main() -> None:
    if hasattr(trajectory, "_two_against_one"):
        _traced()
    seed_label = int(sys.argv[1]) if len(sys.argv) > 1 else 78502
    misses = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
    rig_name = sys.argv[3] if len(sys.argv) > 3 else "paper3"
    rig = next(r for r in bd.rigs() + bd.more_rigs() if r.name == rig_name)
    duration = 8.0
    motion, kicks = dirty_rally(seed_label, duration)
    seed = seed_label - 300  # bench_dirty's simulation seed of that rally
    fault = bd.faults(rig, seed, duration)
    options = FusionOptions(gating=True)
    for kind, extra in (("clean", {}), ("faults", fault)):
        det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
            noise_px=bd.TARGET_NOISE, seed=seed, miss_rate=misses, drop_rate=misses / 2,
            **extra))
        track = fuse_detections(det, rig, ["smooth"], options)[0]["smooth"]
        err = errors_m(track, truth)
        bad = np.flatnonzero(err > bd.MAX_ERROR_M)
        breaks = np.asarray(track.meta.get("breaks_s", [])) if hasattr(track, "meta") else []
        print(f"{rig_name} rally-{seed_label} {kind}: mean {1e3 * np.nanmean(err):.3f} mm, "
              f"max {1e3 * np.nanmax(err):.1f} mm, beyond 5 cm {len(bad)}"
              + "".join(f"\n    {track.time_ns[i] / 1e9:.4f} s {1e3 * err[i]:.1f} mm"
                        for i in bad))
        del breaks
    print("kicks:", " ".join(f"{k:.4f}" for k in kicks))


if __name__ == "__main__":
    main()
