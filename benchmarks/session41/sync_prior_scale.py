"""How much does ``pslog sync``'s σ rescale move its clocks' σ by scaling the motion prior too?
(session 41, review41)

``_solve_joint`` builds the Schur complement at the median-based σ_med, then multiplies the
whole of it by (σ_med/σ_cov)² (σ_cov: the dof-corrected RMS of the inliers). The data's
information scales so; the motion prior's should not. Here, densely (every Jacobian column by
central differences, as tests/test_hand_computed.py), the clocks' σ both ways.

    python benchmarks/session41/sync_prior_scale.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from test_hand_computed import dense_jacobian, dense_prior

from pslog import SimulationOptions, apply_timing, builtin_rig, simulate
from pslog.estimation import sync as S
from pslog.estimation.trajectory import SmoothOptions, _Solver
from pslog.motion import get_motion
from pslog.records import NS
from pslog.simulation import true_rig


def one(seed: int, motion: str, estimate=("offset", "readout")):
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    opts = SimulationOptions(noise_px=0.3, seed=seed, clock_offset_s={"cam2": 2e-3},
                             readout_s={"cam1": 20e-3, "cam2": 22e-3, "cam3": 18e-3})
    det, _ = simulate(rig, get_motion(motion), None, opts)
    truth = true_rig(rig, opts)
    obs = det.best()
    unknowns = [(c, p) for c in range(3) for p in estimate
                if not (c == 0 and p in ("offset", "drift"))]
    logged = obs.time_ns / NS
    params = S._Clocks(rig, unknowns, 0.5 * float(logged.min() + logged.max()))
    theta = params.to_internal(np.array([float(getattr(truth.cameras[c], S.RIG_KEY[p]))
                                         for c, p in unknowns]))
    options = SmoothOptions()
    problem, control, theta, sigma_cov, _, _, _, n_t = S._solve_joint(
        obs, rig, unknowns, theta, params, options)
    if n_t != len(params.reduced):
        return None  # breaks: their columns are not rebuilt here
    rows = problem.rows
    t0 = params.times(obs, theta)[rows[0]] - problem.t[rows[0]]
    dt = params.times_jacobian(logged[rows], obs.uv[rows, 1], obs.camera[rows]) @ params.M
    out = S._joint_step(problem, _Solver(problem, options), obs, params.reduced, theta,
                        params, control, sigma_cov, dt, t0)
    sigma_med, S_med = out[2], out[6]
    Jd, r0 = dense_jacobian(problem, params, obs, control, theta, t0)
    n = control.size
    s2 = np.sum(r0.reshape(-1, 2) ** 2, axis=1) / sigma_med**2
    ww = np.repeat(1 / (1 + s2 / S._CAUCHY**2), 2) / sigma_med**2
    Hd = Jd.T @ (ww[:, None] * Jd)
    P = np.zeros_like(Hd)
    P[:n, :n] = dense_prior(problem.prior_ab)
    k = (sigma_med / sigma_cov) ** 2
    coded = np.sqrt(np.diag(np.linalg.inv(k * (Hd + P))[n:, n:]))
    right = np.sqrt(np.diag(np.linalg.inv(k * Hd + P)[n:, n:]))
    return sigma_med, sigma_cov, coded, right, np.sqrt(np.diag(np.linalg.inv(S_med)))


def main():
    print("seed  σ_med  σ_cov  clocks' σ (ms): coded (prior scaled) / prior unscaled")
    for motion, seed in [(m, s) for m in ("spiral", "straight") for s in (67100, 67101, 67102)]:
        res = one(seed, motion)
        if res is None:
            print(f"{motion} {seed}: breaks in the fit, skipped")
            continue
        sm, sc, coded, right, _ = res
        print(f"{motion} {seed} {sm:.4f} {sc:.4f}  " + "  ".join(
            f"{a * 1e3:.4f}/{b * 1e3:.4f} ({(a / b - 1) * 100:+.2f} %)"
            for a, b in zip(coded, right, strict=True)))


if __name__ == "__main__":
    main()
