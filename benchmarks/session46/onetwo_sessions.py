"""Session 46: `smooth` with and without ``trajectory._one_against_two`` on ``bench_dirty.py
--more``'s sessions (every rig, clean / faults / blackout alone), paired in one process (the
rule off: it returns its input, main's fit), one line per fit that changes, then the totals:
fits changed, better / worse by the mean error, points beyond 5 cm, the screen's breaks.

    PYTHONPATH=.:tests python benchmarks/session46/onetwo_sessions.py FIRST_SEED [MISSES]
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

RULE = trajectory._one_against_two
COSTS = trajectory._region_costs
STATE = {"on": True, "changes": [], "tested": 0}


def _counted(*args):
    """``_region_costs``, counting the rule's searches (a break against its grid of pairs)."""
    if len(args[-1]) > 2:
        STATE["tested"] += 1
    return COSTS(*args)


def _switched(*args, **kwargs):
    """The rule, or its input (main's fit), recording what it changes."""
    if not STATE["on"]:
        return args[7]
    out = RULE(*args, **kwargs)
    before, after = np.concatenate(args[7]), np.concatenate(out)
    if len(before) != len(after) or np.any(before != after):
        t0 = args[0].t0_ns / 1e9
        STATE["changes"].append(f"{np.setdiff1d(before, after).round(4) + t0} -> "
                                f"{np.setdiff1d(after, before).round(4) + t0}")
    return out


def main() -> None:
    first = int(sys.argv[1])
    misses = float(sys.argv[2]) if len(sys.argv) > 2 else 0.0
    seeds = int(sys.argv[3]) if len(sys.argv) > 3 else 4
    fps = float(sys.argv[4]) if len(sys.argv) > 4 else None
    trajectory._one_against_two = _switched
    trajectory._region_costs = _counted
    runs = bd.more_sessions(seeds, 8.0, first)
    options = FusionOptions(gating=True)
    fits = changed = better = worse = 0
    far = [0, 0]
    means = [[], []]
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
                got = []
                for on in (False, True):
                    STATE["on"], STATE["changes"] = on, []
                    track = fuse_detections(det, rig, ["smooth"], options)[0]["smooth"]
                    err = errors_m(track, truth)
                    got.append((float(np.nanmean(err)), float(np.nanmax(err)),
                                int(np.sum(err > bd.MAX_ERROR_M))))
                fits += 1
                for k in (0, 1):
                    far[k] += got[k][2]
                    means[k].append(got[k][0])
                if got[0] != got[1]:
                    changed += 1
                    better += got[1][0] < got[0][0]
                    worse += got[1][0] > got[0][0]
                    print(f"{rig.name} {label} {kind}: mean {1e3 * got[0][0]:.4f} -> "
                          f"{1e3 * got[1][0]:.4f} mm, max {1e3 * got[0][1]:.1f} -> "
                          f"{1e3 * got[1][1]:.1f}, >5cm {got[0][2]} -> {got[1][2]}; "
                          + "; ".join(STATE["changes"]))
                    sys.stdout.flush()
    print(f"first {first} misses {misses} seeds {seeds} fps {fps}: {fits} fits, {changed} "
          f"changed ({better} better, {worse} worse); beyond 5 cm {far[0]} -> {far[1]}; "
          f"mean of means {1e3 * np.mean(means[0]):.4f} -> {1e3 * np.mean(means[1]):.4f} mm; "
          f"the rule's region solves (grids and polish stages) {STATE['tested']}")


if __name__ == "__main__":
    main()
