"""Session 37 (start37): ``bench_dirty.py --more --validity --first-seed 49100 --fps 60``,
``straight`` on ``paper3@60``: which of the ball's own detections the offline gate
(``smooth``'s) rejects, by camera, reason and time, with each fault and with them all.

    PYTHONPATH=. python benchmarks/session37/start_straight.py [RIG] [FIRST]
"""

from __future__ import annotations

import sys

import numpy as np

sys.path.insert(0, "benchmarks/session35")
sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import smooth_straight as s35

from pslog.fusion.gating import REASONS, gate
from pslog.records import NS
from pslog.simulation import SimulationOptions, ball_mask, simulate_labelled


def main() -> None:
    rigname = sys.argv[1] if len(sys.argv) > 1 else "paper3@60"
    first = int(sys.argv[2]) if len(sys.argv) > 2 else 49100
    rig, motion, duration, seed, f = s35.session(rigname, "straight", first)
    print(f"{rig.name} straight, bench seed {seed}: {f}")
    extras = {"object": {"distractors": f["distractors"]},
              "blackout+object": {"blackouts": f["blackouts"], "distractors": f["distractors"]},
              "faults": f}
    for kind, extra in extras.items():
        det, _, ball = simulate_labelled(rig, motion, duration, SimulationOptions(
            noise_px=0.3, seed=seed, **extra))
        is_ball = ball_mask(det, ball)
        for causal in (False, True):
            g = gate(det, rig, causal=causal)
            lost = np.flatnonzero(is_ball & (g.reason >= 0))
            cam = det.frame_camera[det.cand_frame[lost]]
            t = det.frame_time_ns[det.cand_frame[lost]] / NS
            print(f"  {kind} ({'causal' if causal else 'offline'}): ball candidates rejected "
                  f"{len(lost)} of {int(is_ball.sum())}")
            for b in np.unique(cam).tolist():
                m = cam == b
                reasons = {REASONS[r]: int(np.sum(g.reason[lost[m]] == r)) for r in
                           np.unique(g.reason[lost[m]]).tolist()}
                print(f"    {rig.names[b]}: {int(m.sum())} at {t[m].min():.3f}-{t[m].max():.3f} s,"
                      f" {reasons}")


if __name__ == "__main__":
    main()
