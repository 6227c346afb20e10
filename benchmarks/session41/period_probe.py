"""Session 41: motion_period on simulated sessions (false alarms and periods found).

    python benchmarks/session41/period_probe.py FIRST_SEED [N]

Every motion of pslog.motion on the built-in rigs and benchmarks/webcams3.toml, 0.3 px
noise, misses 0.1; the ball's own detections at the true clocks (the labelled ones), so the
detector alone is measured: period found (s) and CPU time.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from pslog.estimation.sync import motion_period
from pslog.fusion._prepare import default_max_gap_s
from pslog.motion import MOTIONS
from pslog.rig import builtin_rig, load_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig


def main() -> None:
    first = int(sys.argv[1])
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    rigs = {"paper3": builtin_rig("paper3"), "paper2": builtin_rig("paper2"),
            "webcams3": load_rig(Path(__file__).parents[1] / "webcams3.toml")}
    seed = first
    for name, rig in rigs.items():
        for motion in MOTIONS.values():
            for _ in range(n):
                for dur in (None, 30.0):
                    opts = SimulationOptions(noise_px=0.3, miss_rate=0.1, seed=seed)
                    seed += 1
                    _, _, ball = simulate_labelled(rig, motion, dur, opts)
                    obs = ball.best()
                    start = time.process_time()
                    period = motion_period(obs, true_rig(rig, opts),
                                           default_max_gap_s(rig))
                    cpu = time.process_time() - start
                    print(f"{name:9s} {motion.name:10s} {dur or motion.duration:6.1f} s "
                          f"seed {seed - 1}: period {period}  ({cpu:.3f} CPU s, "
                          f"{len(obs)} obs)", flush=True)


if __name__ == "__main__":
    main()
