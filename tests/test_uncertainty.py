"""Honest per-point uncertainty: `smooth`'s covariance at the residuals' variance (not their
robust scale), `nearest`'s motion between the paired shutters, `smooth`'s `gap_s`."""

from __future__ import annotations

import numpy as np
from _rally import rally
from numpy.testing import assert_array_equal

from pslog.camera import Camera, look_at
from pslog.estimation import fit_trajectory
from pslog.estimation import trajectory as T
from pslog.evaluation import mahalanobis_sq, summarise_quality
from pslog.fusion import FusionOptions, fuse
from pslog.motion import Motion
from pslog.records import NS, Observations
from pslog.rig import Rig
from pslog.simulation import SimulationOptions, simulate


def _rig(n: int = 3) -> Rig:
    """Cameras around a 3 x 2 x 2 m volume with lens distortion, shutters staggered."""
    cams = []
    dist = np.array([-0.21, 0.08, 4e-4, -6e-4, -0.01])
    for i in range(n):
        angle = 2 * np.pi * i / n + 0.4
        eye = (1.5 + 4.2 * np.cos(angle), 1.0 + 3.6 * np.sin(angle), 2.2 + 0.3 * i)
        R, t = look_at(eye, (1.5, 1.0, 0.8))
        cams.append(Camera(f"c{i + 1}", 800, 600, [[700.0 + 20 * i, 0.3, 401.0],
                                                   [0, 702.0 + 20 * i, 298.0], [0, 0, 1]],
                           dist, R, t, 30.0, (i / n / 30.0) % (1 / 30.0)))
    return Rig(tuple(cams))


def _d2(fit, obs, truth) -> np.ndarray:
    """Each point's squared Mahalanobis distance from the truth."""
    u = fit.used
    err = fit.position[u] - truth.at(obs.time_ns[u])
    return np.einsum("ni,nij,nj->n", err, np.linalg.inv(fit.covariance[u]), err)


def test_smooth_covariance_is_honest_when_the_robust_scale_is_below_the_noise():
    """Scale-mixed noise (most detections 0.1 px, one in four 1 px): the median-based scale
    that weighs the fit is far below the noise's standard deviation, yet the Cauchy weights
    take the noisy detections' share out of the points: the covariance must follow the
    M-estimator's sandwich (Huber), not the residuals' plain variance (which would make it
    conservative, ~90 % inside 2σ), nor stay below the noise the points keep."""
    rig = _rig(3)
    inside, inside_plain = [], []
    for seed in range(3):
        motion, _ = rally(2.0, seed=60 + seed, speed=4.0)
        detections, truth = simulate(rig, motion, 2.0, SimulationOptions(noise_px=0.0,
                                                                         seed=seed))
        obs = detections.best()
        rng = np.random.default_rng(seed)
        scale = np.where(rng.random(len(obs)) < 0.25, 1.0, 0.1)
        uv = obs.uv + rng.normal(size=obs.uv.shape) * scale[:, None]
        obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
        fit, (r, w, sigma, p_eff) = _fit_and_final_residuals(obs, rig)
        assert fit.trajectory.noise_px < 0.5 * np.sqrt(np.mean(scale**2))
        k = T.variance_factor(r, w, sigma, p_eff)
        plain = np.sum(w * (r * r).sum(axis=1)) / (sigma**2 * (2 * len(r) - p_eff))
        d2 = _d2(fit, obs, truth)
        inside.append(np.mean(d2 <= 4))
        inside_plain.append(np.mean(d2 * k / max(plain, 1.0) <= 4))
    assert 0.66 < np.mean(inside) < 0.85, inside  # 0.739 if honest
    assert np.mean(inside_plain) > 0.87, inside_plain


def _fit_and_final_residuals(obs, rig):
    """The fit, and its final residuals, weights, robust σ and p_eff (as
    :func:`variance_factor` gets them), caught on their way in."""
    caught = {}
    original = T.variance_factor

    def spy(r, w, sigma, p_eff):
        caught["args"] = (r, w, sigma, p_eff)
        return original(r, w, sigma, p_eff)

    T.variance_factor = spy
    try:
        fit = fit_trajectory(obs, rig)
    finally:
        T.variance_factor = original
    return fit, caught["args"]


def test_variance_factor_is_hubers_sandwich_scale():
    """``k = [Σ w² ‖r‖² / (n_res - p_eff)] / σ² · mean(w) / mean(w²)²`` (Huber's sandwich with
    the radial Cauchy's ψ' averaged over a row's two directions, w²), at least 1."""
    rng = np.random.default_rng(3)
    r = rng.normal(size=(500, 2)) * 0.4
    w = rng.uniform(0.5, 1.0, 500)
    k = T.variance_factor(r, w, 0.2, 120.0)
    assert np.isclose(k, np.sum(w**2 * (r * r).sum(axis=1)) / (0.2**2 * (1000 - 120.0))
                      * np.mean(w) / np.mean(w**2) ** 2)
    assert T.variance_factor(r, w, 10.0, 120.0) == 1.0  # never below the fit's own
    r[0] = np.nan  # a point behind its camera: left out
    assert np.isfinite(T.variance_factor(r, w, 0.2, 120.0))


def _straight(t_s: float = 2.0) -> Motion:
    p0, v = np.array([0.4, 0.3, 0.6]), np.array([1.6, 0.9, 0.4])

    def position(t):
        t = np.asarray(t, dtype=np.float64)
        return p0 + t[..., None] * v

    return Motion("straight-test", t_s, position)


def test_nearest_covariance_holds_the_motion_between_the_paired_shutters():
    """Noise-free detections of a ball at constant velocity: nearest's whole error is the
    motion between the shutters it takes as simultaneous, and at no stated pixel noise its
    covariance is that term alone, ``m mᵀ``: ``‖m‖`` is the error's length."""
    rig = _rig(3)
    detections, truth = simulate(rig, _straight(), 1.0, SimulationOptions(noise_px=0.0))
    obs = detections.best()
    track = fuse(obs, rig, "nearest", FusionOptions(noise_px=0.0, gating=False))
    err = np.linalg.norm(track.position_world - truth.at(track.time_ns), axis=1)
    std = track.quality["std_m"]
    # (the first frames: a camera's first detection has no image velocity yet, term 0)
    moving = track.time_ns > obs.time_ns[0] + 0.06 * NS
    assert moving.mean() > 0.9 and np.all(err[moving] > 5e-3)
    # image velocity from two detections 1/30 s apart: exact up to the projection's curvature
    assert np.allclose(std[moving], err[moving], rtol=0.05), np.max(
        np.abs(std[moving] / err[moving] - 1))
    # with pixel noise stated, the truth is inside the 2σ ellipsoid nearly always
    noisy = fuse(obs, rig, "nearest", FusionOptions(noise_px=0.3, gating=False))
    d2 = mahalanobis_sq(noisy, truth)
    assert np.mean(d2 <= 4) > 0.9


def test_smooth_gap_is_the_longest_interval_between_fitted_detections_at_the_point():
    rig = _rig(3)
    motion, _ = rally(2.0, seed=8, speed=4.0)
    detections, truth = simulate(rig, motion, 2.0, SimulationOptions(noise_px=0.3, seed=8,
                                                                     miss_rate=0.2))
    obs = detections.best()
    track = fuse(obs, rig, "smooth", FusionOptions(gating=False))
    gap = track.quality["gap_s"]
    # the detections the fit kept (one it rejected, a 1.03 px noise tail beyond 4.29 σ, holds
    # nothing: the gap runs across it, the interval between its neighbours)
    kept = track.quality["rejected"] == 0
    assert np.count_nonzero(~kept) == 1
    t = np.unique(track.time_ns[kept])
    i = np.searchsorted(t, track.time_ns)
    exact = np.append(t, -1)[i] == track.time_ns
    assert_array_equal(exact, kept)
    before = np.where(i > 0, track.time_ns - t[np.maximum(i - 1, 0)], 0)
    j = np.where(exact, i + 1, i)  # the first kept detection after the point
    after = np.where(j < len(t), t[np.minimum(j, len(t) - 1)] - track.time_ns, 0)
    assert np.allclose(gap, np.where(exact, np.maximum(before, after), before + after) / NS)
    assert gap.max() > 1.5 / 90  # misses make longer gaps than the shutters' 1/90 s
    grid = fuse(obs, rig, "smooth", FusionOptions(gating=False, rate_hz=200.0))
    g = grid.quality["gap_s"]
    assert np.all(np.isfinite(g)) and g.max() <= gap.max() + 1e-12
    assert np.isfinite(summarise_quality(track, truth).gap_max_ms)


def _three_partner_detections(n_prev: int):
    """Two cameras of :func:`_rig` (lens distortion) watching a ball under gravity: camera
    c2's detections at uneven intervals (0.030 s, then 0.0325 s; ``n_prev`` of them before
    its last, at 0.0625 s), then camera c1's one detection 0.021 s later, the point."""
    rig = Rig(_rig(2).cameras)
    p0, v, g = np.array([1.2, 0.8, 1.1]), np.array([2.5, -1.5, 3.0]), np.array([0, 0, -9.81])
    times = [0.0, 0.030, 0.0625][2 - n_prev:]
    rows = [(t, 1) for t in times] + [(0.0835, 0)]
    t = np.array([r[0] for r in rows])
    cam = np.array([r[1] for r in rows], dtype=np.int32)
    uv = np.stack([rig.cameras[c].project((p0 + v * s + 0.5 * g * s**2)[None])[0][0]
                   for s, c in zip(t, cam, strict=True)])
    time_ns = np.round(t * NS).astype(np.int64)
    return rig, Observations(time_ns, cam, uv, np.arange(len(t), dtype=np.int64))


def _pair_point(prep, u_c, u_d):
    """The least-squares point of camera 0's undistorted pixel ``u_c`` and camera 1's."""
    from pslog.geometry import triangulate_rays

    dirs = np.stack([prep.rays_from_undistorted(0, u_c[None]),
                     prep.rays_from_undistorted(1, u_d[None])], axis=1)
    return triangulate_rays(prep.centers[None], dirs)[0][0]


def _pair_jacobian(prep, e: int, d: int, slot: int) -> np.ndarray:
    """d(point) / d(undistorted pixel of ``slot``) (3, 2) of rows ``e`` (camera 0) and ``d``
    (camera 1), by central differences."""
    uv = prep.uv_undistorted
    out = np.empty((3, 2))
    for axis in range(2):
        step = np.zeros(2)
        step[axis] = 1e-4
        hi, lo = [uv[e], uv[d]], [uv[e], uv[d]]
        hi[slot] = hi[slot] + step
        lo[slot] = lo[slot] - step
        out[:, axis] = (_pair_point(prep, *hi) - _pair_point(prep, *lo)) / 2e-4
    return out


def test_nearest_covariance_is_the_extrapolation_noise_and_the_extrapolated_move():
    """Hand-computed (docs/methods.md, "nearest's covariance at the true noise"): the point
    P is made of c1's detection u_c (lag 0) and c2's latest u_d (lag L = 0.021 s), while
    the ball was at ū_d(t) in c2's image. With ū_d(t) extrapolated through c2's last
    detections (Lagrange weights w_j: 1 for one detection, linear for two, quadratic for
    three, here by ``np.polyfit`` of unit vectors), P - P(t) = -J_d (ū_d(t) - u_d) +
    σ-noise: Σ = σ² (J_c L_c L_cᵀ J_cᵀ + J_d Σ_j w_j² L_j L_jᵀ J_dᵀ) + (m + a)(m + a)ᵀ,
    m + a = J_d (ū_d(t) - u_d); with one detection (no image velocity) the shift is
    unknown, (v₀ L)² J_d J_dᵀ instead. J by central differences of the triangulation.
    Fails if the velocity's noise or the acceleration is dropped, a weight is not squared,
    the sign of the cross term of u_d's own noise flips, or α takes L² for L (L + h)."""
    from pslog.fusion._prepare import prepare
    from pslog.fusion.stereo import UNKNOWN_IMAGE_SPEED_PX_S

    sigma = 0.4
    for n_prev in (0, 1, 2):
        rig, obs = _three_partner_detections(n_prev)
        prep = prepare(obs, rig)
        track = fuse(obs, rig, "nearest", FusionOptions(noise_px=sigma, gating=False))
        assert len(track) == 1 and track.time_ns[0] == obs.time_ns[-1]
        e, d = len(obs) - 1, len(obs) - 2  # the point's own row, its partner's
        uv = prep.uv_undistorted

        J_c, J_d = _pair_jacobian(prep, e, d, 0), _pair_jacobian(prep, e, d, 1)
        assert np.allclose(_pair_point(prep, uv[e], uv[d]), track.position_world[0], atol=1e-9)
        L_all = [prep.pixel_jacobians_t(np.array([r]))[..., 0] for r in range(len(obs))]
        t_s = obs.time_ns[:e] / NS
        lag = (obs.time_ns[e] - obs.time_ns[d]) / NS
        # Lagrange weights at the point's time through c2's detections (0 ... d)
        w = np.array([np.polyval(np.polyfit(t_s, np.eye(len(t_s))[j], len(t_s) - 1),
                                 obs.time_ns[e] / NS) for j in range(len(t_s))])
        assert np.isclose(w.sum(), 1.0)
        noise = J_c @ L_all[e] @ L_all[e].T @ J_c.T
        for j in range(len(t_s)):
            noise = noise + w[j] ** 2 * J_d @ L_all[j] @ L_all[j].T @ J_d.T
        expected = sigma**2 * noise
        if n_prev == 0:
            expected = expected + (UNKNOWN_IMAGE_SPEED_PX_S * lag) ** 2 * J_d @ J_d.T
        else:
            move = J_d @ (w @ uv[:e] - uv[d])
            expected = expected + np.outer(move, move)
        q = track.quality
        got = np.array([[q["cov_xx_m2"][0], q["cov_xy_m2"][0], q["cov_xz_m2"][0]],
                        [q["cov_xy_m2"][0], q["cov_yy_m2"][0], q["cov_yz_m2"][0]],
                        [q["cov_xz_m2"][0], q["cov_yz_m2"][0], q["cov_zz_m2"][0]]])
        np.testing.assert_allclose(got, expected, rtol=2e-6, atol=1e-14, err_msg=str(n_prev))
        # the terms are not small here: each weight differs from the old model's (1, 0, 0)
        # and the extrapolated move from the linear one by more than the tolerance
        assert n_prev == 0 or np.sum(w**2) > 1.5


def test_nearest_noise_is_the_noise_its_detections_show_causally():
    """``detection_noise``: the median residual of each camera's detection from the quadratic
    through its three previous ones, normalised by ``√(1 + Σ l²)`` and Rayleigh's
    ``√(2 ln 2)``, is the detections' σ (0.8 px here, 0.3 px in a second session); the
    stated noise until 16 residuals are in a point's window; at least min(stated, 0.1 px);
    and a point's σ does not change when the detections after it do (causal)."""
    from pslog.fusion._prepare import default_max_gap_s, prepare
    from pslog.fusion.stereo import NOISE_EVERY_S, detection_noise

    rig = _rig(3)
    gap = default_max_gap_s(rig)
    for sigma in (0.8, 0.3):
        detections, _ = simulate(rig, _straight(4.0), 4.0,
                                 SimulationOptions(noise_px=sigma, seed=3))
        obs = detections.best()
        prep = prepare(obs, rig)
        est = detection_noise(prep, obs.time_ns, gap, 0.5)
        t = (obs.time_ns - obs.time_ns[0]) / NS
        late = t > 1.5
        assert np.all(np.abs(est[late] / sigma - 1) < 0.3), (sigma, est[late].min(),
                                                           est[late].max())
        assert abs(np.median(est[late]) / sigma - 1) < 0.08, np.median(est[late])
        assert np.all(est[t < NOISE_EVERY_S] == 0.5)  # no residual before the first mark
        # causal: the first half's σ with the second half's detections moved far away
        half = len(obs) // 2
        uv = obs.uv.copy()
        uv[half:] += 40.0
        moved = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
        est2 = detection_noise(prepare(moved, rig), obs.time_ns, gap, 0.5)
        assert np.array_equal(est2[:half + 1], est[:half + 1])
        assert not np.array_equal(est2, est)
    # noise-free detections: the floor, min(stated, 0.1 px)
    detections, _ = simulate(rig, _straight(2.0), 2.0, SimulationOptions(noise_px=0.0))
    obs = detections.best()
    t = (obs.time_ns - obs.time_ns[0]) / NS
    for stated, floor in ((0.5, 0.1), (0.05, 0.05)):
        est = detection_noise(prepare(obs, rig), obs.time_ns, gap, stated)
        assert np.all(est[t > 1.5] == floor)
