"""Honest per-point uncertainty: `smooth`'s covariance at the residuals' variance (not their
robust scale), `nearest`'s motion between the paired shutters, `smooth`'s `gap_s`."""

from __future__ import annotations

import numpy as np
from _rally import rally

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
    t = np.unique(obs.time_ns)
    i = np.searchsorted(t, track.time_ns)
    assert np.all(t[i] == track.time_ns)
    before = np.where(i > 0, track.time_ns - t[np.maximum(i - 1, 0)], 0)
    after = np.where(i < len(t) - 1, t[np.minimum(i + 1, len(t) - 1)] - track.time_ns, 0)
    assert np.allclose(gap, np.maximum(before, after) / NS)
    assert gap.max() > 1.5 / 90  # misses make longer gaps than the shutters' 1/90 s
    grid = fuse(obs, rig, "smooth", FusionOptions(gating=False, rate_hz=200.0))
    g = grid.quality["gap_s"]
    assert np.all(np.isfinite(g)) and g.max() <= gap.max() + 1e-12
    assert np.isfinite(summarise_quality(track, truth).gap_max_ms)
