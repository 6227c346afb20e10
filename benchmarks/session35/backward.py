# ruff: noqa: E501
"""Issue 10 (session 35, measured, not built): type A run backward in time as a check of its
forward points. Each type A point lies on its newest detection's ray, its depth along that ray
from eq. (2)'s prediction out of the two previous points; just after an unseen kick that
depth follows the motion before the kick. Run on the time-reversed observations, the same
method predicts each detection's depth from the points *after* it: right just after a kick,
wrong just before. Both points lie on the same ray, so their distance is the disagreement
along it, where the forward error lies and the other cameras see it least. Per point: the
distance ``d = |P_f - P_b|`` over ``s = sqrt(std_f² + std_b²)``; printed: how the far
forward points (> 5 cm) and the good ones distribute over ``d`` and ``d / s``, on bench_dirty
``--more``'s sessions (clean), with ``--confirm-gaps kicks`` applied first (the points it
leaves).

    PYTHONPATH=. python benchmarks/session35/backward.py FIRST [--fps 60] [--misses 0.1]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, fuse  # noqa: E402
from pslog.records import Observations  # noqa: E402


def reversed_obs(obs: Observations, t0: int) -> Observations:
    t = t0 - obs.time_ns
    order = np.lexsort((obs.camera, t))
    return Observations(t[order], obs.camera[order], obs.uv[order], obs.frame_index[order])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    ap.add_argument("--seeds", type=int, default=3)
    a = ap.parse_args()
    from pslog.fusion.gating import gate_for
    from pslog.simulation import SimulationOptions, simulate_labelled
    kicks_opt = FusionOptions(confirm_every=True, confirm_sides=True)
    plain = FusionOptions(confirm_gaps=False)
    far_r, good_r, far_d, good_d = [], [], [], []
    for base in rigs() + more_rigs():
        rig = base if a.fps is None else at_rate(base, a.fps)
        for seed, (_label, motion, duration, _k) in enumerate(more_sessions(a.seeds, 8.0, a.first), start=a.first - 300):
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=seed, miss_rate=a.misses, drop_rate=a.misses / 2))
            obs = gate_for(det, rig, "typeA", FusionOptions()).observations
            fwd = fuse(obs, rig, "typeA", kicks_opt)
            t0 = int(obs.time_ns.max() + obs.time_ns.min())
            bwd = fuse(reversed_obs(obs, t0), rig, "typeA", plain)
            kb = dict(zip(zip((t0 - bwd.time_ns).tolist(), bwd.camera.tolist(), strict=True), range(len(bwd)), strict=True))
            idx = np.array([kb.get(k, -1) for k in zip(fwd.time_ns.tolist(), fwd.camera.tolist(), strict=True)])
            has = idx >= 0
            err = errors_m(fwd, truth)
            d = np.linalg.norm(fwd.position_world[has] - bwd.position_world[idx[has]], axis=1)
            s = np.hypot(fwd.quality["std_m"][has], bwd.quality["std_m"][idx[has]])
            far = err[has] > 0.05
            far_r += list(d[far] / s[far])
            far_d += list(d[far])
            good_r += list(d[~far] / s[~far])
            good_d += list(d[~far])
            missing = np.count_nonzero(~has & (err > 0.05))
            if missing:
                print(f"{rig.name} {_label}: {missing} far points without a backward point")
    far_r, good_r, far_d, good_d = map(np.asarray, (far_r, good_r, far_d, good_d))
    print(f"far {len(far_r)}: d mm {np.round(1e3 * np.sort(far_d), 0)}; d/s {np.round(np.sort(far_r), 1)}")
    for th in (3, 4, 5, 6, 8):
        print(f"d/s > {th}: far {np.sum(far_r > th)} of {len(far_r)}, good {np.sum(good_r > th)} of {len(good_r)} ({100 * np.mean(good_r > th):.2f} %)")
    for th in (0.02, 0.03, 0.04):
        print(f"d > {1e3 * th:.0f} mm: far {np.sum(far_d > th)}, good {np.sum(good_d > th)} ({100 * np.mean(good_d > th):.2f} %)")


if __name__ == "__main__":
    main()
