"""The continuous-time trajectory estimator behind ``smooth`` (pslog/estimation)."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from _rally import rally
from _rigs import lab3_rig
from numpy.testing import assert_allclose, assert_array_equal
from scipy.interpolate import BSpline

from pslog import builtin_rig
from pslog.camera import Camera, look_at
from pslog.errors import FusionError
from pslog.estimation import MotionPrior, SmoothOptions, fit_trajectory, project_with_jacobian
from pslog.estimation import trajectory as T
from pslog.estimation.bspline import basis, clamped_knots, n_control
from pslog.evaluation import evaluate
from pslog.fusion import FusionOptions, fuse
from pslog.motion import G, Motion, ballistic_with_bounces, get_motion
from pslog.records import NS, Observations
from pslog.rig import Rig, apply_timing
from pslog.simulation import SimulationOptions, simulate


def _rig(n: int = 3, distortion: bool = False, fps=(30.0,)) -> Rig:
    """Cameras around a 3 x 2 x 2 m volume (not the built-in rigs), shutters staggered."""
    cams = []
    dist = np.array([-0.21, 0.08, 4e-4, -6e-4, -0.01]) if distortion else np.zeros(5)
    for i in range(n):
        angle = 2 * np.pi * i / n + 0.4
        eye = (1.5 + 4.2 * np.cos(angle), 1.0 + 3.6 * np.sin(angle), 2.2 + 0.3 * i)
        R, t = look_at(eye, (1.5, 1.0, 0.8))
        rate = fps[i % len(fps)]
        cams.append(Camera(f"c{i + 1}", 800, 600, [[700.0 + 20 * i, 0.3, 401.0],
                                                   [0, 702.0 + 20 * i, 298.0], [0, 0, 1]],
                           dist, R, t, rate, (i / n / rate) % (1 / rate)))
    return Rig(tuple(cams))


# ---- B-spline basis ----------------------------------------------------------------------
def test_basis_and_derivatives_match_scipy_with_a_triple_knot():
    knots = clamped_knots(np.array([0.0, 0.1, 0.25, 0.3, 0.45, 0.6]), np.array([1, 3, 1, 1]))
    control = np.random.default_rng(0).normal(size=(n_control(knots), 3))
    t = np.linspace(0, 0.6, 997)
    first, values = basis(knots, t, 3)
    index = first[:, None] + np.arange(4)
    spline = BSpline(knots, control, 3)
    for d in range(4):
        ours = np.einsum("na,nad->nd", values[:, d], control[index])
        assert_allclose(ours, spline(t, nu=d), rtol=1e-10, atol=1e-9 * np.abs(ours).max())
    # C⁰ at the triple knot: the position is continuous, the velocity jumps
    left, right = (np.einsum("na,nad->nd", basis(knots, np.array([x]), 1)[1][:, 1],
                             control[basis(knots, np.array([x]), 1)[0][:, None] + np.arange(4)])
                   for x in (0.25 - 1e-9, 0.25))
    assert np.linalg.norm(left - right) > 1e-3


# ---- projection Jacobian -----------------------------------------------------------------
def test_projection_jacobian_matches_finite_differences_with_distortion_and_skew():
    rig = _rig(3, distortion=True)
    points = np.random.default_rng(1).uniform([0.3, 0.2, 0.1], [2.7, 1.8, 1.9], (50, 3))
    for cam in rig.cameras:
        uv, J = project_with_jacobian(cam, points)
        assert_allclose(uv, cam.project(points)[0], atol=1e-9)
        h = 1e-6
        for k in range(3):
            step = np.zeros(3)
            step[k] = h
            fd = (cam.project(points + step)[0] - cam.project(points - step)[0]) / (2 * h)
            assert_allclose(J[:, :, k], fd, rtol=1e-6, atol=1e-4)


def test_residual_jacobian_of_the_control_points_matches_finite_differences():
    rig = _rig(3, distortion=True)
    motion = Motion("throw", 1.0, lambda t: ballistic_with_bounces((0.4, 0.5, 1.2),
                                                                   (1.8, 0.6, 2.5), t))
    detections, _ = simulate(rig, motion, options=SimulationOptions(noise_px=0.5, seed=2))
    obs = detections.best()
    pieces = T.split_pieces(obs, np.ones(len(obs), bool), 0.12)
    t = (obs.time_ns - obs.time_ns[0]) / NS
    knots = [T._knots_with_breaks(t[p[0]], t[p[-1]] + 1e-9, 0.04, np.array([0.5]))
             for p in pieces]
    problem = T._Problem(obs, rig, pieces, knots, MotionPrior())
    control = np.random.default_rng(3).normal((1.5, 1.0, 1.0), 0.3, (problem.m, 3))
    r, J = problem.project(problem.positions(control))
    start, E, _ = problem.data_rows(J, np.zeros_like(r))
    dense = np.zeros((len(E), 3 * problem.m))
    for row, (s, e) in enumerate(zip(start, E, strict=True)):
        dense[row, s:s + 12] = e
    h = 1e-7
    for col in np.random.default_rng(4).choice(3 * problem.m, 25, replace=False):
        step = np.zeros(3 * problem.m)
        step[col] = h
        plus = problem.project(problem.positions(control + step.reshape(-1, 3)))[0]
        minus = problem.project(problem.positions(control - step.reshape(-1, 3)))[0]
        assert_allclose(dense[:, col], ((plus - minus) / (2 * h)).reshape(-1), rtol=1e-5,
                        atol=1e-3)


def test_prior_normal_equations_equal_the_integral_they_stand_for():
    prior = MotionPrior(sigma_accel=3.0, tau_s=0.3)
    knots = T._knots_with_breaks(0.0, 0.5, 0.045, np.array([0.21]))
    control = np.random.default_rng(5).normal(size=(n_control(knots), 3))
    problem = T._Problem.__new__(T._Problem)
    (problem.prior_ab, problem.prior_rhs, problem.prior_const,
     problem.prior_values) = T._prior_normal([knots], np.zeros(1, np.int64), n_control(knots),
                                             prior)
    # the integral by a fine midpoint rule, span by span (the triple knot's jump excluded)
    total = 0.0
    g = np.array(prior.gravity)
    spans = np.unique(knots)
    for lo, hi in itertools.pairwise(spans):
        t = lo + (np.arange(4000) + 0.5) / 4000 * (hi - lo)
        first, values = basis(knots, t, 3)
        index = first[:, None] + np.arange(4)
        acc = np.einsum("na,nad->nd", values[:, 2], control[index])
        jerk = np.einsum("na,nad->nd", values[:, 3], control[index])
        total += (hi - lo) * np.mean(np.sum((acc - g) ** 2, axis=1) / prior.q_accel
                                     + np.sum(jerk**2, axis=1) / prior.q_jerk)
    assert_allclose(T._prior_cost(problem, control), total, rtol=1e-6)
    # the Singer model's two spectral densities
    assert_allclose((prior.q_accel, prior.q_jerk), (2 * 9 * 0.3, 2 * 9 / 0.3))


# ---- hand-computable cases ---------------------------------------------------------------
def test_a_straight_line_at_constant_velocity_is_recovered_exactly_by_two_cameras():
    # with a zero-mean prior a line is in the prior's null space: nothing pulls it away
    rig = Rig(_rig(3).cameras[:2])
    line = Motion("line", 1.0, lambda t: np.array([0.3, 0.4, 0.6]) + t[:, None] * [2.1, 0.9, 1.0])
    detections, truth = simulate(rig, line)
    obs = detections.best()
    fit = fit_trajectory(obs, rig, SmoothOptions(prior=MotionPrior(gravity=(0.0, 0.0, 0.0))))
    assert fit.used.all()
    assert_allclose(fit.position, truth.at(obs.time_ns), atol=1e-7)
    assert len(fit.trajectory.breaks_s) == 0
    # and anywhere in between detections: the fitted line's velocity is the true one
    velocity, _ = fit.trajectory.evaluate(obs.time_ns[5:-5] + 1234567, derivative=1)
    assert_allclose(velocity, np.tile([2.1, 0.9, 1.0], (len(velocity), 1)), atol=1e-5)


def test_a_parabola_under_gravity_is_recovered_exactly_with_the_default_prior():
    rig = _rig(2)
    parabola = Motion("parabola", 0.7, lambda t: np.stack(
        [0.4 + 2.5 * t, 0.6 + 0.8 * t, 1.2 + 2.0 * t - 0.5 * G * t * t], axis=1))
    detections, truth = simulate(rig, parabola)
    obs = detections.best()
    fit = fit_trajectory(obs, rig)
    assert_allclose(fit.position, truth.at(obs.time_ns), atol=1e-8)
    accel, _ = fit.trajectory.evaluate(obs.time_ns, derivative=2)
    assert_allclose(accel, np.tile([0, 0, -G], (len(obs), 1)), atol=1e-5)


# ---- breaks, robustness, honesty ---------------------------------------------------------
def test_a_floor_bounce_is_found_at_its_instant_and_the_velocity_jumps_there():
    rig = _rig(3)
    motion = get_motion("throw")
    detections, truth = simulate(rig, motion)
    obs = detections.best()
    fit = fit_trajectory(obs, rig)
    # the throw reaches the floor at the root of z0 + vz s - g s²/2 = radius
    bounce = (3.0 + np.sqrt(9.0 + 2 * G * (1.0 - 0.0215))) / G
    breaks = fit.trajectory.breaks_s + obs.time_ns[0] / NS
    assert len(breaks) == 1 and abs(breaks[0] - bounce) < 1e-4
    err = np.linalg.norm(fit.position - truth.at(obs.time_ns), axis=1)
    assert err.max() < 1e-4  # 0.1 mm, noise-free, bounce included
    t_ns = np.array([round((breaks[0] - 2e-3) * NS), round((breaks[0] + 2e-3) * NS)])
    v, _ = fit.trajectory.evaluate(t_ns, derivative=1)
    assert v[0, 2] < -5 and v[1, 2] > 3  # falling, then rising


def test_gross_outliers_get_no_weight_and_do_not_move_the_track():
    rig = _rig(3)
    motion, _ = rally(3.0, seed=21, speed=4.0)
    detections, truth = simulate(rig, motion, 3.0, SimulationOptions(noise_px=0.3, seed=21))
    obs = detections.best()
    clean = fit_trajectory(obs, rig)
    uv = obs.uv.copy()
    bad = np.random.default_rng(7).choice(len(obs), 6, replace=False)
    uv[bad] += np.random.default_rng(8).choice([-1, 1], (6, 2)) * 40.0
    dirty = fit_trajectory(Observations(obs.time_ns, obs.camera, uv, obs.frame_index), rig)
    assert np.all(dirty.weight[bad] < 0.01) and np.median(dirty.weight) > 0.8
    both = clean.used & dirty.used
    shift = np.linalg.norm(dirty.position[both] - clean.position[both], axis=1)
    std = np.sqrt(np.trace(dirty.covariance[both], axis1=1, axis2=2))
    # a point loses its own detection's information, nothing more
    assert np.median(shift) < 2e-4 and np.all(shift < 2 * std)
    errors = [np.linalg.norm(f.position[both] - truth.at(obs.time_ns[both]), axis=1).mean()
              for f in (clean, dirty)]
    assert errors[1] < 1.1 * errors[0]


def test_the_standard_deviations_are_honest_on_many_seeds():
    """Over 24 seeds, the truth is inside ±2σ on about 95 % of the axes and points, and the
    Mahalanobis distance follows χ²(3)."""
    rig = _rig(3, distortion=True)
    inside, chi2, shares = [], [], []
    for seed in range(24):
        motion, _ = rally(1.5, seed=100 + seed, speed=4.0)
        detections, truth = simulate(rig, motion, 1.5,
                                     SimulationOptions(noise_px=0.3, seed=seed))
        obs = detections.best()
        fit = fit_trajectory(obs, rig)
        u = fit.used
        err = fit.position[u] - truth.at(obs.time_ns[u])
        sd = np.sqrt(np.einsum("nii->ni", fit.covariance[u]))
        inside.append(np.abs(err) < 2 * sd)
        d2 = np.einsum("ni,nij,nj->n", err, np.linalg.inv(fit.covariance[u]), err)
        chi2.append(d2 < 7.815)  # χ²(3) at 95 %
        shares.append(np.mean(np.abs(err) < 2 * sd))
    inside, chi2 = np.concatenate(inside), np.concatenate(chi2)
    assert 0.91 < inside.mean() < 0.985, inside.mean()
    assert 0.88 < chi2.mean() < 0.985, chi2.mean()
    assert np.median(shares) > 0.9


def test_noise_is_estimated_and_errors_stay_within_the_fit_on_mixed_rates_and_four_cameras():
    rig = _rig(4, distortion=True, fps=(30.0, 60.0))
    motion, _ = rally(4.0, seed=31, speed=4.5)
    detections, truth = simulate(rig, motion, 4.0, SimulationOptions(noise_px=0.4, seed=31,
                                                                     miss_rate=0.1))
    obs = detections.best()
    fit = fit_trajectory(obs, rig)
    assert abs(fit.trajectory.noise_px - 0.4) < 0.06
    err = np.linalg.norm(fit.position[fit.used] - truth.at(obs.time_ns[fit.used]), axis=1)
    type_a = evaluate(fuse(obs, rig, "typeA"), truth)
    assert err.mean() * 1e3 < type_a.mean_mm / 3, (err.mean(), type_a)


def test_one_camera_cannot_triangulate_and_says_so():
    rig = _rig(3)
    detections, _ = simulate(rig, get_motion("throw"))
    obs = detections.best()
    alone = obs.select(obs.camera == 0)
    with pytest.raises(FusionError, match="one camera cannot triangulate"):
        fit_trajectory(alone, rig)
    with pytest.raises(FusionError, match="one camera cannot triangulate"):
        fit_trajectory(obs, Rig(rig.cameras[:1]))
    assert len(fuse(alone, rig, "smooth")) == 0  # as a fusion method: no point, no error


def test_no_point_inside_a_gap_longer_than_the_bound():
    rig = _rig(3)
    motion, _ = rally(2.0, seed=41, speed=4.0)
    detections, _ = simulate(rig, motion, 2.0)
    obs = detections.best()
    t = obs.time_ns / NS
    gapped = obs.select((t < 0.8) | (t > 1.1))
    track = fuse(gapped, rig, "smooth", FusionOptions(rate_hz=500.0))
    inside = (track.time_ns / NS > 0.8 + 0.04) & (track.time_ns / NS < 1.1 - 0.04)
    assert len(track) > 500 and not inside.any()
    assert_allclose(np.diff(track.time_ns[track.time_ns / NS < 0.7]), NS / 500, atol=1)


def test_smooth_through_the_cli_with_a_rate(tmp_path, cli):
    from pslog.log import read_session

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    path = tmp_path / "s.mcap"
    assert cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
               "--noise-px", "0.3", "-o", path)[0] == 0
    code, _, err = cli("fuse", path, "--method", "smooth", "--method", "typeA", "--rate",
                         "250", "-o", tmp_path / "f.mcap")
    assert code == 0, err
    session = read_session(tmp_path / "f.mcap")
    smooth = session.tracks["smooth"]
    assert abs(evaluate(smooth, session.truth).rate_hz - 250) < 1
    assert {"std_m", "residual_px"} <= set(smooth.quality)
    assert np.all(smooth.quality["std_m"] > 0)
    assert evaluate(smooth, session.truth).mean_mm < evaluate(session.tracks["typeA"],
                                                              session.truth).mean_mm
    assert len(rig) == 3


@pytest.mark.parametrize("rate", ["1e-300", "0.0005", "2e6"])
def test_a_rate_outside_a_milli_to_a_megahertz_is_a_usage_error(tmp_path, cli, capsys, rate):
    """1e-300 Hz once made the grid's step inf ns: numpy warnings, then exit 0."""
    path = tmp_path / "s.mcap"
    assert cli("simulate", "--rig", "paper2", "--motion", "throw", "-o", path)[0] == 0
    with pytest.raises(SystemExit) as exit_:  # argparse's usage error, in-process
        cli("fuse", path, "--method", "smooth", "--rate", rate, "-o", tmp_path / "f.mcap")
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and "--rate" in err and "Warning" not in err, err
    assert not (tmp_path / "f.mcap").exists()
    with pytest.raises(FusionError, match="rate must be in"):
        FusionOptions(rate_hz=float(rate))


# ---- numeric kernels: each against its plain definition ------------------------------------
def _dense(ab: np.ndarray) -> np.ndarray:
    """The symmetric matrix of upper banded storage ``ab[11 + i - j, j] = A[i, j]``."""
    n = ab.shape[1]
    A = np.zeros((n, n))
    for d in range(12):
        i = np.arange(n - d)
        A[i, i + d] = ab[11 - d, d:]
        A[i + d, i] = ab[11 - d, d:]
    return A


def test_blocked_normal_equations_equal_the_row_by_row_sums():
    from pslog.estimation import _normal

    rng = np.random.default_rng(11)
    m, r = 40, 300
    first = rng.integers(0, m - 3, r)  # unsorted, repeated: the sums must not care
    N = rng.random((r, 4))
    J = rng.normal(size=(r, 2, 3)) * 300
    w = rng.random(r) + 0.1
    z = rng.normal(size=(r, 2)) * 20
    E = (N[:, None, :, None] * J[:, :, None, :]).reshape(-1, 12)  # the rows of data_rows
    ab0, rhs0 = _normal.accumulate(np.repeat(3 * first, 2), E, z.reshape(-1),
                                   np.repeat(w, 2), 3 * m)
    M = np.einsum("n,nai,naj->nij", w, J, J)
    v = np.einsum("n,nai,na->ni", w, J, z)
    ab1, rhs1 = _normal.accumulate_points(first, N, M, v, m)
    assert_allclose(ab1, ab0, rtol=0, atol=1e-12 * np.abs(ab0).max())
    assert_allclose(rhs1, rhs0, rtol=0, atol=1e-12 * np.abs(rhs0).max())
    # the upper-triangle form and adding onto given equations
    upper = M.reshape(r, 9)[:, [0, 1, 2, 4, 5, 8]]
    ab2, rhs2 = _normal.Points(first, N, m).normal(upper, v, ab0.copy(), rhs0.copy())
    assert_allclose(ab2, 2 * ab0, rtol=0, atol=1e-12 * np.abs(ab0).max())
    assert_allclose(rhs2, 2 * rhs0, rtol=0, atol=1e-12 * np.abs(rhs0).max())
    control = rng.normal(size=(m, 3))
    positions = np.einsum("na,nad->nd", N, control[first[:, None] + np.arange(4)])
    assert_allclose(_normal.Points(first, N, m).positions(control), positions, atol=1e-12)


@pytest.mark.parametrize("m", [5, 37, 400])
def test_the_chunked_covariance_band_is_the_band_of_the_dense_inverse(m):
    from pslog.estimation import _normal

    rng = np.random.default_rng(m)
    r = 8 * m
    first = rng.integers(0, m - 3, r)
    J = rng.normal(size=(r, 2, 3))
    ab, _ = _normal.accumulate_points(first, rng.random((r, 4)),
                                      np.einsum("nai,naj->nij", J, J), np.zeros((r, 3)), m)
    ab[11] += 1e-3
    U = _normal.factor(ab)
    band = _normal.covariance_band(U)
    cov = np.linalg.inv(_dense(ab))
    scale = np.abs(cov).max()  # (once: the loop's 1,600 asserts took 3 s recomputing it)
    for k in range(4):
        for i in range(m - k):
            assert_allclose(band[i, k], cov[3 * i:3 * i + 3, 3 * (i + k):3 * (i + k) + 3],
                            rtol=0, atol=1e-12 * scale)
    assert_allclose(band, _normal.covariance_band_sequential(U), rtol=0, atol=1e-13 * scale)


def test_the_three_new_b_splines_of_a_triple_knot_match_scipy():
    from pslog.estimation import _breaks

    a = np.array([0.25, 0.4, 0.5, 0.75])
    pieces = _breaks._new_splines(a)
    x = np.linspace(-1.0, 2.0, 601)[None, :].repeat(len(a), 0)
    for e, knots in enumerate(([-1, 0, "a", "a", "a"], [0, "a", "a", "a", 1],
                               ["a", "a", "a", 1, 2])):
        for d in range(4):
            ours = np.zeros_like(x)
            for lo, hi, c in pieces[e]:
                on = (x >= lo[:, None]) & (x < hi[:, None])
                ours = np.where(on, _breaks._horner(c, x, d), ours)
            for i, ai in enumerate(a):
                kn = [ai if k == "a" else k for k in knots]
                spline = BSpline.basis_element(kn, extrapolate=False)
                ref = np.nan_to_num(spline(x[i], nu=d))
                away = np.min(np.abs(x[i][:, None] - np.array(kn)[None]), axis=1) > 1e-9
                assert_allclose(ours[i][away], ref[away], atol=1e-9 * max(1, abs(ref).max()))


def test_the_break_gain_is_the_cost_decrease_of_the_dense_local_problem():
    """gᵀ S⁻¹ g equals, to rounding, the base cost minus the least cost with a triple knot at
    τ inserted into the base knots, both solved densely."""
    from pslog.estimation import _breaks

    rng = np.random.default_rng(4)
    h, prior = 0.03, MotionPrior()
    n = 80
    t = np.sort(rng.uniform(-0.25, 0.25, n))
    J = rng.normal(size=(n, 2, 3)) * 300
    z = rng.normal(size=(n, 2)) * 50
    w = rng.random(n) + 0.5
    centre = np.array([0.004])
    K = 7
    local = _breaks._local(K, h, prior, 1)
    index = np.flatnonzero(np.abs(t - centre[0]) < 5 * h)[None, :]
    base = _breaks._Base(local, t, J, z, w, index, np.ones_like(index, bool), centre, h)

    def dense_cost(knots):
        m = n_control(knots)
        ab, rhs, const, _ = T._prior_normal([knots], np.zeros(1, np.int64), m, prior)
        rows = index[0]
        first, values = basis(knots, t[rows], 0)
        D = np.zeros((len(rows), 2, 3 * m))
        for k, (f, nb) in enumerate(zip(first, values[:, 0], strict=True)):
            for a in range(4):
                D[k, :, 3 * (f + a):3 * (f + a) + 3] += nb[a] * J[rows[k]]
        D = D.reshape(-1, 3 * m)
        ww, zz = np.repeat(w[rows], 2), z[rows].reshape(-1)
        H = D.T @ (ww[:, None] * D) + _dense(ab)
        b = D.T @ (ww * zz) + rhs
        return ww @ (zz * zz) + const - b @ np.linalg.solve(H, b)

    grid = centre[0] + h * np.arange(-K, K + 1)
    plain = dense_cost(clamped_knots(grid))
    assert_allclose(base.cost[0], plain, rtol=1e-10)
    for frac in (0.25, 0.4, 0.61, 0.75):
        for span in (-2, 0, 1):
            tau = centre[0] + (span + frac) * h
            gain = _breaks._gains(base, np.array([0]), np.array([tau]), centre, prior)[0]
            points = np.sort(np.r_[grid, tau])
            mult = np.ones(len(points) - 2, np.int64)
            mult[np.searchsorted(points, tau) - 1] = 3
            assert_allclose(gain, plain - dense_cost(clamped_knots(points, mult)),
                            rtol=1e-7, atol=1e-6)


def test_the_basis_of_several_splines_at_once_equals_each_alone():
    from pslog.estimation.bspline import basis_pieces

    knots = [T._knots_with_breaks(0.0, 0.5, 0.04, np.array([0.21])),
             T._knots_with_breaks(0.9, 1.3, 0.05, np.zeros(0)),
             T._knots_with_breaks(2.0, 2.2, 0.03, np.array([2.1]))]
    rng = np.random.default_rng(9)
    t = [np.r_[k[0], rng.uniform(k[0], k[-1], 50), k[-1], 0.21, 2.1][:52 + (i != 1)]
         for i, k in enumerate(knots)]
    piece = np.concatenate([np.full(len(x), i) for i, x in enumerate(t)])
    first, values = basis_pieces(knots, piece, np.concatenate(t), 3)
    offset = np.cumsum([0] + [n_control(k) for k in knots])
    for i, k in enumerate(knots):
        f, v = basis(k, t[i], 3)
        sel = piece == i
        assert_array_equal(first[sel], f + offset[i])
        assert_allclose(values[sel], v, rtol=0, atol=1e-9)


def test_the_basis_of_several_splines_is_the_same_in_any_point_order():
    """Points of several splines interleaved (the clock estimator moves times) give, row for
    row, what they give grouped by spline."""
    from pslog.estimation.bspline import basis_pieces

    knots = [T._knots_with_breaks(0.0, 0.5, 0.04, np.array([0.21])),
             T._knots_with_breaks(0.9, 1.3, 0.05, np.zeros(0))]
    rng = np.random.default_rng(3)
    piece = np.repeat([0, 1], 40)
    t = np.where(piece == 0, rng.uniform(0.0, 0.5, 80), rng.uniform(0.9, 1.3, 80))
    grouped = basis_pieces(knots, piece, t, 2)
    order = rng.permutation(80)
    mixed = basis_pieces(knots, piece[order], t[order], 2)
    assert np.any(np.diff(piece[order]) < 0)
    assert_array_equal(mixed[0], grouped[0][order])
    assert_array_equal(mixed[1], grouped[1][order])


def test_a_run_starts_from_the_projection_it_remembers_only_for_that_design():
    """The projection a run ends with is reused for the same control points on the same
    design, and recomputed once the times (the design) change."""
    rig = _rig(2)
    det, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(noise_px=0.3, seed=1))
    obs = det.best()
    t = (obs.time_ns - obs.time_ns[0]) / NS
    rows = np.arange(len(obs))
    knots = [T._knots_with_breaks(t[0], t[-1] + 1e-9, 0.04, np.zeros(0))]
    problem = T._Problem(obs, rig, [rows], knots, MotionPrior())
    control = T._initial_control(problem, 1.0)
    control, _, r, _, J = T._Solver(problem, SmoothOptions()).run(control, 1.0, 2)
    _, r2, J2 = problem.project_control(control)
    assert r2 is r and J2 is J  # the remembered arrays
    assert problem.project_control(control.copy())[1] is not r  # another array: projected
    assert_array_equal(problem.project_control(control.copy())[1], r)
    problem.set_times(t + 1e-3)
    moved = problem.project_control(control)[1]
    assert moved is not r and not np.array_equal(moved, r)


def test_the_stacked_projection_equals_each_camera_alone():
    from pslog.estimation.projection import project_stacked, stack_cameras

    rig = _rig(3, distortion=True)
    rng = np.random.default_rng(12)
    points = rng.uniform([0.3, 0.2, 0.1], [2.7, 1.8, 1.9], (90, 3))
    index = rng.integers(0, 3, 90)
    uv, J = project_stacked(stack_cameras(rig.cameras, index), points)
    for i, cam in enumerate(rig.cameras):
        sel = index == i
        uv_i, J_i = project_with_jacobian(cam, points[sel])
        assert_allclose(uv[sel], uv_i, rtol=1e-14, atol=1e-9)
        assert_allclose(J[sel], J_i, rtol=1e-12, atol=1e-9)


def test_the_marginal_covariance_at_the_points_by_the_sparse_product_equals_the_sum():
    from pslog.estimation import _normal

    rng = np.random.default_rng(13)
    m, r = 30, 200
    first = rng.integers(0, m - 3, r)
    N = rng.random((r, 4))
    A = rng.normal(size=(3 * m, 3 * m))
    cov = A @ A.T  # any symmetric matrix: its band, as covariance_band returns it
    band = np.zeros((m, 4, 3, 3))
    for i in range(m):
        for k in range(4):
            if i + k < m:
                band[i, k] = cov[3 * i:3 * i + 3, 3 * (i + k):3 * (i + k) + 3]
    ours = _normal.Points(first, N, m).marginal(band)
    assert_allclose(ours, _normal.marginal(band, first, N), rtol=1e-12, atol=1e-12)
    index = 3 * (first[:, None] + np.arange(4))[:, :, None] + np.arange(3)  # (r, 4, 3)
    for i in range(0, r, 37):  # and the definition: Bᵀ Σ B with B the point's basis
        B = np.zeros((3 * m, 3))
        for a in range(4):
            B[index[i, a], np.arange(3)] = N[i, a]
        assert_allclose(ours[i], B.T @ cov @ B, rtol=1e-10)


def test_an_end_segment_too_few_detections_hold_gives_no_point(monkeypatch):
    # seed 3: a piece starts with one camera's detection just before a kick, the others after
    # it; that lone detection's position along its ray is not determined by anything
    # three cameras with lens distortion whose views the ball leaves and re-enters: a piece
    # of the trajectory can start one detection before a kick
    rig = lab3_rig(rise=0.2, focal_step=15.0, prefix="e", name="edge3")
    motion, _ = rally(15, seed=3)
    detections, truth = simulate(rig, motion, 15, SimulationOptions(noise_px=0.0, seed=11))
    obs = detections.best()
    fit = fit_trajectory(obs, rig)
    err = np.linalg.norm(fit.position - truth.at(obs.time_ns), axis=1)
    assert 1 <= fit.withheld <= 3
    assert np.nanmax(err) < 1e-3  # noise-free: every point given is right
    lone = ~fit.used & np.isin(np.arange(len(obs)), np.concatenate(fit.pieces))
    withheld = obs.time_ns[lone]
    track = fuse(obs, rig, "smooth", FusionOptions(rate_hz=200.0))
    # nor any grid point in the withheld segment (from its detection to the break)
    breaks = fit.trajectory.t0_ns + np.round(fit.trajectory.breaks_s * NS).astype(np.int64)
    for t in withheld:
        nxt = breaks[breaks > t].min(initial=t + NS) if np.any(breaks > t) else t
        prv = breaks[breaks <= t].max(initial=t - NS) if np.any(breaks <= t) else t
        assert not np.any((track.time_ns > t - 20_000_000) & (track.time_ns < nxt)
                          & (track.time_ns > prv)), t
    assert fuse(obs, rig, "smooth").dropped == {"underdetermined_end": fit.withheld}
    monkeypatch.setattr(T, "_END_DETECTIONS", 1)  # every end segment trusted: undetermined
    # the lone detection's point slides along its ray as far as the data's last digits take
    # it (0.70 m off before the break search's trials changed, 27 mm after; 14-137 mm with
    # the pixels moved by 1e-6-1e-4 px): two fits of pixels 1e-4 px apart move it by
    # millimetres, while every determined point keeps its place to 0.1 mm
    rng = np.random.default_rng(3)
    fits = [fit_trajectory(dataclasses.replace(obs, uv=obs.uv + rng.normal(
        scale=1e-4, size=obs.uv.shape)), rig) for _ in range(2)]
    moved = np.linalg.norm(fits[0].position - fits[1].position, axis=1)
    assert np.all(fits[0].used[lone]) and np.all(fits[1].used[lone])
    assert np.nanmax(moved[lone]) > 5e-3
    assert np.nanmax(moved[~lone]) < 1e-4
