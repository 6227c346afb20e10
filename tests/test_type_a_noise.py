"""typeA's covariance at the session's measured detection noise (pslog.fusion.pseudo:
measured_noise, type_a_noise, MeasuredNoiseStream; docs/methods.md, "Type A's covariance at
the measured noise"): it scales with the noise the detections show, not with the stated
``noise_px``; a point's noise uses only earlier detections, so the stream gives the batch's
bits; on a 1 px session the covariance is about honest where the stated 0.5 px was four
times too small."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from test_fusion_validity import dirty_session, streamed

from pslog import SimulationOptions, apply_timing, builtin_rig, simulate
from pslog.evaluation import _mahalanobis_sq, _offsets
from pslog.fusion import FusionOptions, fuse, prepare
from pslog.fusion.innovation import RAYLEIGH_MEDIAN
from pslog.fusion.pseudo import fuse_type_a, measured_noise, no_detection_limits
from pslog.fusion.stereo import (
    NOISE_EVERY_S,
    NOISE_FLOOR_PX,
    NOISE_MIN_COUNT,
    NOISE_WINDOW_S,
    detection_noise,
    recorded_residuals,
)
from pslog.motion import rally_motion
from pslog.records import NS, Observations, Track


def _session(noise_px: float, seed: int = 3, duration: float = 3.0, **faults):
    """paper3 (type A shutters) on the library's rally (``duration`` s) at ``noise_px`` of
    true noise: its best-scored detections and the truth."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, truth = simulate(rig, rally_motion(seed, duration), options=SimulationOptions(
        noise_px=noise_px, seed=seed, **faults))
    return rig, det.best(), truth


def _numpy_noise(prep, at_ns, max_gap_s, noise_px):
    """nearest's estimator in numpy (the reference both compiled users are held to): the
    residuals of stereo.recorded_residuals (the quadratic's Lagrange weights, in numpy),
    each checkpoint's window sorted, its middle element over Rayleigh's median."""
    res, weight = recorded_residuals(prep, max_gap_s)
    with np.errstate(invalid="ignore"):
        norm = np.hypot(res[:, 0], res[:, 1]) / np.sqrt(weight)
    fin = np.isfinite(norm)
    t_fin, v_fin = prep.obs.time_ns[fin], norm[fin]
    every, window = int(NOISE_EVERY_S * NS), int(NOISE_WINDOW_S * NS)
    out = np.empty(len(at_ns))
    for i, t in enumerate(at_ns):
        mark = t // every * every
        v = np.sort(v_fin[(t_fin >= mark - window) & (t_fin < mark)])
        out[i] = v[len(v) // 2] / RAYLEIGH_MEDIAN if len(v) >= NOISE_MIN_COUNT else noise_px
    return np.maximum(out, min(noise_px, NOISE_FLOOR_PX))


def _sigma(rig, obs, at_ns, noise_px, max_gap_s):
    return measured_noise(obs.time_ns, obs.camera, obs.uv, no_detection_limits(rig.cameras),
                          max_gap_s, at_ns, noise_px)


def test_covariance_scales_with_the_measured_noise_not_the_stated_one():
    # 1 px of true noise: whatever noise is stated, a point past the session's first window
    # has the covariance of the stated-noise kernel times (σ / stated)², σ the noise its
    # detections show: nearest's estimator (stereo.detection_noise; both held to a numpy
    # reference, _numpy_noise), about 1 px
    rig, obs, _ = _session(1.0)
    prep = prepare(obs, rig)
    from pslog.fusion._prepare import default_max_gap_s

    gap = default_max_gap_s(rig)
    for stated in (0.5, 2.0):
        track = fuse(obs, rig, "typeA", FusionOptions(noise_px=stated, confirm_gaps=False))
        # (the same points, the covariance at 0.5 px: the stated noise is also the tests'
        # least noise, which decides which points are made)
        kernel = fuse_type_a(prep, gap, stated, explain=False, cov_noise_px=0.5)[0]
        assert_array_equal(track.time_ns, kernel.time_ns)
        assert_array_equal(track.position_world, kernel.position_world)
        assert_array_equal(track.quality["snap_px"], kernel.quality["snap_px"])
        late = track.time_ns >= obs.time_ns[0] + int((NOISE_EVERY_S + NOISE_WINDOW_S) * NS)
        assert late.sum() > 100
        t = track.time_ns[late]
        sigma = detection_noise(prep, t, gap, stated)
        # (nearest's and type A's: the same compiled kernels, held to the numpy reference)
        assert_allclose(sigma, _numpy_noise(prep, t, gap, stated), rtol=1e-12)
        assert np.all((sigma > 0.8) & (sigma < 1.4)), (sigma.min(), sigma.max())
        assert_allclose(_sigma(rig, obs, t, stated, gap), sigma, rtol=1e-12)
        assert_allclose(track.quality["std_m"][late],
                        kernel.quality["std_m"][late] * sigma / 0.5, rtol=1e-10)
        assert_allclose(track.quality["cov_xy_m2"][late],
                        kernel.quality["cov_xy_m2"][late] * (sigma / 0.5) ** 2, rtol=1e-10)


def test_a_points_noise_uses_no_later_detection():
    # the detections after t* made 5 px noisy: the points before t* keep every bit of their
    # covariance (causal: a checkpoint's window ends at or before its points)
    rig, obs, _ = _session(0.3)
    cut = obs.time_ns[0] + int(1.6 * NS)
    uv = obs.uv.copy()
    later = obs.time_ns >= cut
    uv[later] += np.random.default_rng(1).normal(0.0, 5.0, (int(later.sum()), 2))
    noisy = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    options = FusionOptions(confirm_gaps=False)
    a, b = fuse(obs, rig, "typeA", options), fuse(noisy, rig, "typeA", options)
    before_a, before_b = a.time_ns < cut, b.time_ns < cut
    assert before_a.sum() > 80
    assert_array_equal(a.time_ns[before_a], b.time_ns[before_b])
    assert_array_equal(a.quality["std_m"][before_a], b.quality["std_m"][before_b])
    # (and the noise did reach the later points' covariance: the estimate follows it)
    assert np.median(b.quality["std_m"][~before_b]) > 5 * np.median(a.quality["std_m"][~before_a])


@pytest.mark.parametrize("noise_px", [0.5, 0.0])
def test_stream_equals_batch_with_misses_drops_outliers_and_a_pause(noise_px):
    # a dirty 1.5 s throw (30 % misses, 10 % drops, 5 % outliers, a lens), and a 5 s rally (30
    # % misses, 10 % drops) with the
    # detections of 1.6-3.0 s removed (every checkpoint's window empties: the latest
    # estimate held), pushed one by one through StreamFuser (MeasuredNoiseStream, which keeps
    # ~1.5 s of detections: halved, the checkpoints after the pause differ), long-gap points
    # withheld and confirmed (ConfirmedStream); noise_px 0: the covariance made at 1 px
    rig, obs, _ = dirty_session("typeA", 4)
    rig2, more, _ = _session(0.5, seed=4, duration=5.0, miss_rate=0.3,
                                   drop_rate=0.1)
    t0 = obs.time_ns[0]
    keep = (more.time_ns - more.time_ns[0] < int(1.6 * NS)) | (
        more.time_ns - more.time_ns[0] > int(3.0 * NS))
    obs2 = Observations(more.time_ns[keep], more.camera[keep], more.uv[keep],
                        more.frame_index[keep])
    options = FusionOptions(noise_px=noise_px)
    for r, o in ((rig, obs), (rig2, obs2)):
        batch = fuse(o, r, "typeA", options)
        assert len(batch) > 40
        joined = Track.concat(streamed(r, "typeA", o, options))
        assert_array_equal(joined.time_ns, batch.time_ns)
        assert_array_equal(joined.position_world, batch.position_world)
        for key, column in batch.quality.items():
            assert_array_equal(joined.quality[key], column, err_msg=key)
    assert t0 != obs2.time_ns[0]


def test_covariance_is_about_honest_at_one_pixel():
    # 1 px of true noise, the default stated 0.5 px: the stated noise made NEES ~3.7 and put
    # ~20 % of the truth inside 2σ (73.9 % if honest); the measured noise about 1 and 74 %
    rig, obs, truth = _session(1.0, seed=5)
    track = fuse(obs, rig, "typeA")
    d2 = _mahalanobis_sq(track, _offsets(track, truth))
    d2 = d2[np.isfinite(d2)]
    assert len(d2) > 100
    nees, inside = d2.mean() / 3, np.mean(d2 <= 4)
    assert 0.6 < nees < 1.5 and 0.6 < inside < 0.92, (nees, inside)
