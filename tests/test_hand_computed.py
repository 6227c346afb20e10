"""Estimators against cases derived independently of their code (session 41's review).

``pslog sync``'s covariance is the clocks' block of the inverse of the Schur complement
``S = C − Bᵀ A⁻¹ B`` of its bordered Gauss–Newton information (docs/timing.md, "Standard
deviations"). Here that information is built a second way, densely, with every Jacobian
column — the control points' and the clocks' (offset, drift, readout) — by central
differences of the reprojection residual itself, and the Schur complement and the clocks'
covariance compared with the code's. The code's clock columns are the analytic
``∂r/∂θ = ∂π/∂X · p'(τ) · ∂τ/∂θ``; a sign or a factor wrong in any of them, or in the
elimination, fails this.
"""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose
from test_estimation import _rig

from pslog.estimation import sync as S
from pslog.estimation.trajectory import SmoothOptions, _Solver
from pslog.motion import Motion
from pslog.records import NS
from pslog.simulation import SimulationOptions, simulate, true_rig


def _parabola() -> Motion:  # no bounce: the fit has no break, the problem is smooth
    return Motion("parabola", 2.0, lambda t: np.stack(
        [0.4 + 1.2 * t, 0.6 + 0.4 * np.sin(3 * t), 1.0 + 3.0 * t - 4.9 * t * t + 0.2 * t**3],
        axis=1))


def dense_prior(ab: np.ndarray) -> np.ndarray:
    """The symmetric matrix of an upper band ``ab`` (``ab[-1 - d, j]`` = ``A[j - d, j]``)."""
    n = ab.shape[1]
    A = np.zeros((n, n))
    for d in range(ab.shape[0]):
        j = np.arange(d, n)
        A[j - d, j] = ab[-1 - d, d:]
        A[j, j - d] = ab[-1 - d, d:]
    return A


#: central differences' steps of the clocks' columns: s, ppm, s
STEPS = {"offset": 1e-6, "drift": 1e-1, "readout": 1e-6}


def dense_jacobian(problem, params, obs, control: np.ndarray, theta: np.ndarray,
                   t0: float) -> tuple[np.ndarray, np.ndarray]:
    """The reprojection residual ``r0`` (m,) at ``(control, theta)`` and its Jacobian
    (m, n + q) by central differences: the n control-point coordinates (1 µm steps), then
    the q clock unknowns of ``params.reduced`` (:data:`STEPS`); ``problem``'s times are left
    at ``theta``'s. (benchmarks/session41/sync_prior_scale.py uses it too.)"""
    def residual(c_flat: np.ndarray, th: np.ndarray) -> np.ndarray:
        problem.set_times(params.times(obs, th) - t0)
        r, _ = problem.project(problem.positions(c_flat.reshape(-1, 3)))
        return r.reshape(-1)

    c0 = control.reshape(-1).copy()
    r0 = residual(c0, theta)
    n, q = len(c0), len(params.reduced)
    Jd = np.zeros((len(r0), n + q))
    for k in range(n):  # control points (m), central differences
        e = np.zeros(n)
        e[k] = 1e-6
        Jd[:, k] = (residual(c0 + e, theta) - residual(c0 - e, theta)) / 2e-6
    for j, (_, p) in enumerate(params.reduced):
        e = np.zeros(q)
        e[j] = STEPS[p]
        Jd[:, n + j] = (residual(c0, theta + e) - residual(c0, theta - e)) / (2 * STEPS[p])
    problem.set_times(params.times(obs, theta) - t0)
    return Jd, r0


def test_sync_information_is_the_schur_complement_of_the_dense_information_by_differences():
    rig = _rig(3, distortion=True)
    faults = dict(clock_offset_s={"c2": 2.1e-3, "c3": -1.3e-3},
                  clock_drift_ppm={"c2": 30.0, "c3": -20.0},
                  readout_s={"c1": 9e-3, "c2": 14e-3, "c3": 6e-3})
    opts = SimulationOptions(noise_px=0.3, seed=67010, **faults)
    detections, _ = simulate(rig, _parabola(), 1.2, opts)
    truth = true_rig(rig, opts)
    obs = detections.best()
    unknowns = [(c, p) for c in range(3) for p in ("offset", "drift", "readout")
                if not (c == 0 and p in ("offset", "drift"))]
    logged = obs.time_ns / NS
    params = S._Clocks(rig, unknowns, 0.5 * float(logged.min() + logged.max()))
    theta = params.to_internal(np.array([float(getattr(truth.cameras[c], S.RIG_KEY[p]))
                                         for c, p in unknowns]))
    options = SmoothOptions()
    problem, control, theta, *_ = S._solve_joint(obs, rig, unknowns, theta, params, options)
    rows = problem.rows
    first = rows[0]
    t0 = params.times(obs, theta)[first] - problem.t[first]
    # the code's information at (control, theta), at the σ its step uses
    dt = params.times_jacobian(logged[rows], obs.uv[rows, 1], obs.camera[rows]) @ params.M
    out = S._joint_step(problem, _Solver(problem, options), obs, params.reduced, theta,
                        params, control, 0.3, dt, t0)
    sigma, S_code = out[2], out[6]
    q = len(params.reduced)
    assert q == 7 and S_code.shape == (q, q)

    Jd, r0 = dense_jacobian(problem, params, obs, control, theta, t0)
    n = control.size
    # the robust weights at (control, theta), Cauchy at c = 3σ, as the step weighs
    s2 = np.sum(r0.reshape(-1, 2) ** 2, axis=1) / sigma**2
    ww = np.repeat(1 / (1 + s2 / S._CAUCHY**2), 2) / sigma**2
    H = Jd.T @ (ww[:, None] * Jd)
    H[:n, :n] += dense_prior(problem.prior_ab)  # the motion prior: control points only
    schur = H[n:, n:] - H[n:, :n] @ np.linalg.solve(H[:n, :n], H[:n, n:])
    scale = np.sqrt(np.outer(np.diag(schur), np.diag(schur)))
    assert_allclose(S_code / scale, schur / scale, atol=2e-5)
    # so the clocks' covariance is the clocks' block of the dense information's inverse
    assert_allclose(np.linalg.inv(S_code), np.linalg.inv(H)[n:, n:], rtol=1e-4)


def test_coarse_offset_scan_on_a_rectified_pair_is_the_middle_of_the_agreeing_stretch():
    """A rectified pair (same K and R, baseline along the image's x): the epipolar line of
    camera 2's pixel in camera 1 is its row. The ball's row falls at a constant rate
    ``v̇ = −f ż / Y`` in both, so at a trial offset g every detection of camera 2 lies
    ``|v̇| · |g − δ|`` from its line: all agree where that is within 6 px, none elsewhere. The
    scan's answer is the middle of the grid's points within ``6 / |v̇|`` of the true δ."""
    from pslog.camera import Camera, look_at
    from pslog.rig import Rig

    K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])
    cams = []
    for i, x in enumerate((0.0, 0.5)):
        R, t = look_at((x, 0.0, 1.0), (x, 5.0, 1.0))
        # camera 2's shutter 0.3 of a frame after camera 1's (not half: a half-frame phase
        # would make camera 1's two bracketing detections' weights symmetric)
        cams.append(Camera(f"c{i + 1}", 640, 480, K, np.zeros(5), R, t, 30.0, i * 0.01))
    rig = Rig(tuple(cams))
    # depth Y = 3 m; z rises 0.44 m/s: v̇ = −500 · 0.44 / 3 px/s; x swings fast (not still)
    ball = Motion("line", 5.0, lambda t: np.stack(
        [0.25 + 0.6 * np.sin(2 * np.pi * t), np.full_like(t, 3.0), 0.0 + 0.44 * t], axis=1))
    true_offset = 0.0437
    detections, _ = simulate(rig, ball, 5.0,
                             SimulationOptions(clock_offset_s={"c2": true_offset}))
    delta, notes = S.coarse_offsets(detections, rig, 1.0, 0.1)
    v_dot = 500 * 0.44 / 3.0
    step = S.COARSE_STEP / 30.0
    grid = np.arange(-1.0, 1.0 + step / 2, step)
    agree = grid[np.abs(grid - true_offset) * v_dot <= S.COARSE_TOL_PX]
    assert len(agree) == 20  # ±81.8 ms at 8.33 ms steps, by hand
    assert notes == [] and delta[0] == 0.0
    assert_allclose(delta[1], 0.5 * (agree[0] + agree[-1]), rtol=0, atol=1e-12)
    assert abs(delta[1] - true_offset) <= step / 2
