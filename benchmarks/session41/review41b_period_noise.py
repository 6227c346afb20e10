"""review41b: motion_period at pixel noise 1-3 px, the noise given (a sync's noise_px):
turntables found, other motions not (seeds 69600-69699).

    python benchmarks/session41/review41b_period_noise.py"""
from __future__ import annotations

import sys
from pathlib import Path

from pslog.estimation.sync import motion_period
from pslog.fusion._prepare import default_max_gap_s
from pslog.motion import MOTIONS
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig

sys.path.insert(0, str(Path(__file__).parent))
from review41b_period import bouncing, rolling


def main() -> None:
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    seed = 69600
    motions = [MOTIONS["turntable"], MOTIONS["rally"], MOTIONS["spiral"], MOTIONS["straight"],
               rolling(20), rolling(5), bouncing(0.9)]
    for noise in (1.0, 1.5, 2.0, 3.0):
        for motion in motions:
            opts = SimulationOptions(noise_px=noise, miss_rate=0.1, seed=seed)
            _, _, ball = simulate_labelled(rig, motion, 20.0, opts)
            got = motion_period(ball.best(), true_rig(rig, opts), default_max_gap_s(rig),
                                noise)
            print(f"noise {noise} px {motion.name:12s} seed {seed}: {got}", flush=True)
            seed += 1


if __name__ == "__main__":
    main()
