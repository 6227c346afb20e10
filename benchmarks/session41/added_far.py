"""Session 41: the points beyond 5 cm that bench_dirty --more's faults add, explained.

    python benchmarks/session41/added_far.py FIRST_SEED SEEDS RIG [METHOD]

For each dirty session of RIG (bench_dirty's --more sessions and faults, 0.3 px) every point
of METHOD (typeA) beyond 5 cm whose clean twin is not: its time, error, camera, std, the
blackout and what the method's own detection there is (the ball or a false candidate) and
what it fused from (quality columns).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import bench_dirty as B

from pslog.evaluation import errors_m
from pslog.fusion import CONFIRM_GAPS, FusionOptions
from pslog.simulation import SimulationOptions, ball_mask, simulate_labelled


def main() -> None:
    first, n, rig_name = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    method = sys.argv[4] if len(sys.argv) > 4 else "typeA"
    rig = {r.name: r for r in B.rigs() + B.more_rigs()}[rig_name]
    c = CONFIRM_GAPS["kicks"]
    options = FusionOptions(confirm_gaps=c[0], confirm_every=c[1], confirm_sides=c[2],
                            confirm_breaks=c[3])
    runs = B.more_sessions(n, 8.0, first)
    for seed, (label, motion, duration, _kicks) in enumerate(runs, start=first - 300):
        span = motion.duration if duration is None else duration
        fault = B.faults(rig, seed, span)
        clean, truth, _ = simulate_labelled(rig, motion, duration,
                                            SimulationOptions(noise_px=0.3, seed=seed))
        dirty, _, ball = simulate_labelled(rig, motion, duration,
                                           SimulationOptions(noise_px=0.3, seed=seed, **fault))
        tc = B._fused(clean, rig, [method], options)[method]
        td = B._fused(dirty, rig, [method], options)[method]
        ec, ed = errors_m(tc, truth), errors_m(td, truth)
        bad = {(int(t), int(k)) for t, k in zip(tc.time_ns[ec > B.MAX_ERROR_M],
                                                tc.camera[ec > B.MAX_ERROR_M], strict=True)}
        is_ball = ball_mask(dirty, ball)
        for i in np.flatnonzero(ed > B.MAX_ERROR_M):
            key = (int(td.time_ns[i]), int(td.camera[i]))
            if key in bad:
                continue
            # the candidates of that camera's frame nearest the point's time
            cand_t = dirty.frame_time_ns[dirty.cand_frame]
            cand_c = dirty.frame_camera[dirty.cand_frame]
            near = np.flatnonzero((cand_c == key[1]) & (np.abs(cand_t - key[0]) < 2e6))
            what = [("ball" if is_ball[j] else "FALSE") + f"@{dirty.cand_uv[j].round(1)}"
                    for j in near]
            q = {k: float(td.quality[k][i]) for k in ("std_m", "gap_s", "ray_angle_deg",
                                                      "snap_px", "ray_miss_m")
                 if k in td.quality}
            print(f"{rig_name} {label} seed {seed} {method} t={key[0] / 1e9:.4f} "
                  f"err {ed[i] * 1e3:.1f} mm cam {key[1]} faults {fault} cands {what} "
                  f"q {q}", flush=True)


if __name__ == "__main__":
    main()
