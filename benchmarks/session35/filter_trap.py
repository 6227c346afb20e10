# ruff: noqa: E501
"""Issue 10 (session 35, found, not fixed): the filter locked in jumps. On ``paper2``
(two cameras, 30 fps, 0.3 px) ``turntable`` noise seed 46710, the filter accepts a velocity
jump at every other detection from the start: the jump absorbs the turn the ballistic pair
lacks, the whiteness statistic that raises ``q`` forgets its innovations at every jump
(docs/methods.md, "Process noise adaptation"), so ``q`` never rises, the turn model never
joins, and every point is withheld as ``unconfirmed`` (6 of 120 output). This scans
sessions for filters that output fewer than 80 % of their detections.

    PYTHONPATH=. python benchmarks/session35/filter_trap.py RIG MOTION FIRST COUNT
"""
from __future__ import annotations

import sys
from pathlib import Path

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
import bench_dirty as bd  # noqa: E402

from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.motion import get_motion  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def main():
    rig_name, motion_name, first, count = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    rig = {r.name: r for r in bd.rigs() + bd.more_rigs()}[rig_name]
    low = []
    for seed in range(first, first + count):
        det, _truth, _ = simulate_labelled(rig, get_motion(motion_name), None, SimulationOptions(noise_px=0.3, seed=seed))
        track = fuse_detections(det, rig, ["filter"], FusionOptions())[0]["filter"]
        n = len(det.best())
        if len(track) < 0.8 * n:
            low.append((seed, len(track), n, dict(track.dropped)))
    print(f"{rig_name} {motion_name} seeds {first}..{first + count - 1}: {len(low)} of {count} below 80 %: {low}")


if __name__ == "__main__":
    main()
