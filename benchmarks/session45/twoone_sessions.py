"""Session 45: per session, `smooth`'s mean and largest error and its points beyond 5 cm on
``bench_dirty.py --more``'s sessions (every rig, clean / faults / blackout alone), one line
each, to diff two trees' outputs line by line (``_two_against_one``'s changes, where this
tree has it, printed under the session's line).

    PYTHONPATH=.:tests python benchmarks/session45/twoone_sessions.py FIRST_SEED [MISSES]
        [SEEDS] [FPS]
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

from pslog.estimation import trajectory  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

CHANGES: list[str] = []


def _traced() -> None:
    """Record each merge ``trajectory._two_against_one`` makes."""
    two_against_one, region_costs = trajectory._two_against_one, trajectory._region_costs
    gains: list[str] = []

    def costs(*args):
        out = region_costs(*args)
        if gains is not None and out is not None and len(args[-1]) == 2 and len(
                args[-1][1][0]) == 2:
            gains.append(f"{out[1] - out[0]:.1f}")
        return out

    def traced(*args, **kwargs):
        gains.clear()
        out = two_against_one(*args, **kwargs)
        before, after = np.concatenate(args[7]), np.concatenate(out)
        if len(before) != len(after) or np.any(before != after):
            CHANGES.append(f"    merged {np.setdiff1d(before, after).round(4)} -> "
                           f"{np.setdiff1d(after, before).round(4)} (h {1e3 * args[6]:.2f} ms;"
                           f" the pairs' second gains {', '.join(gains)})")
        return out

    trajectory._two_against_one = traced
    trajectory._region_costs = costs


def main() -> None:
    first = int(sys.argv[1])
    misses = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
    seeds = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    fps = float(sys.argv[4]) if len(sys.argv) > 4 else None
    if hasattr(trajectory, "_two_against_one"):
        _traced()
    runs = bd.more_sessions(seeds, 8.0, first)
    options = FusionOptions(gating=True)
    for rig in bd.rigs() + bd.more_rigs():
        if fps is not None:
            rig = bd.at_rate(rig, fps)
        for seed, (label, motion, duration, _) in enumerate(runs, start=first - 300):
            span = motion.duration if duration is None else duration
            fault = bd.faults(rig, seed, span)
            for kind, extra in (("clean", {}), ("faults", fault),
                                ("blackout", {"blackouts": fault["blackouts"]})):
                det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                    noise_px=bd.TARGET_NOISE, seed=seed, miss_rate=misses,
                    drop_rate=misses / 2, **extra))
                CHANGES.clear()
                track = fuse_detections(det, rig, ["smooth"], options)[0]["smooth"]
                err = errors_m(track, truth)
                print(f"{rig.name} {label} {kind}: mean {1e3 * np.nanmean(err):.4f} mm, max "
                      f"{1e3 * np.nanmax(err):.1f}, >5cm {int(np.sum(err > bd.MAX_ERROR_M))}")
                for line in CHANGES:
                    print(line)
                sys.stdout.flush()


if __name__ == "__main__":
    main()
