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


def _model_part(prep, kernel, sigma, rows):
    """Eq. (2)'s model term (k, 3, 3) of the kernel's points ``rows`` at the noise ``sigma``
    (k,), m², from the kernel's three model columns, written out: gravity's (h rᵀg)² plus,
    where the innovation's across-ray |u|² is beyond the χ²₂ 99 % of its noise σ² c
    (c = (factor D / f)²), half of it less 2 σ² c; along the unit ray from the point's
    camera to the point."""
    q = kernel.quality
    noise = sigma**2 * q["_model_m2_per_px2"][rows]
    across = q["_model_across_m2"][rows]
    v = q["_model_gravity_m2"][rows] + np.where(across > 9.21 * noise,
                                                0.5 * (across - 2 * noise), 0.0)
    ray = kernel.position_world[rows] - prep.centers[kernel.camera[rows]]
    r = ray / np.linalg.norm(ray, axis=1)[:, None]
    return v[:, None, None] * r[:, :, None] * r[:, None, :]


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
        # (the noise's part: the covariance less eq. (2)'s model term along the ray)
        model = _model_part(prep, kernel, sigma, late)
        noise_cov = track.quality["cov_xy_m2"][late] - model[:, 0, 1]
        assert_allclose(noise_cov, kernel.quality["cov_xy_m2"][late] * (sigma / 0.5) ** 2,
                        rtol=1e-9, atol=1e-9 * np.abs(noise_cov).max())
        trace = sum(track.quality[f"cov_{a}{a}_m2"][late] - model[:, i, i]
                    for i, a in enumerate("xyz"))
        assert_allclose(np.sqrt(trace), kernel.quality["std_m"][late] * sigma / 0.5,
                        rtol=1e-9)


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


def test_the_model_terms_of_a_parabola_in_closed_form():
    # a ball under gravity alone (the library's "fall", no noise) on paper3: for a motion of
    # constant acceleration a, eq. (2)'s prediction from the TRUE positions at t-1 and t-2
    # misses the truth at t by exactly -½ a δ_pred (δ_pred + δ_prev) (the remainder of linear
    # interpolation); the kernel's gravity column is that miss along the newest ray, squared,
    # here computed from the motion itself at each point's three times (not from h); and its
    # across-ray column is the prediction's offset across the ray less gravity's: the past
    # points' eq. (1) errors alone
    from pslog.fusion import type_a_explained
    from pslog.motion import get_motion

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, truth = simulate(rig, get_motion("fall"), options=SimulationOptions(noise_px=0.0))
    prep = prepare(det.best(), rig)
    from pslog.fusion._prepare import default_max_gap_s

    track, con = fuse_type_a(prep, default_max_gap_s(rig), 0.5, cov_noise_px=0.5)
    assert len(track) > 40
    t = prep.obs.time_ns
    t0, t1, t2 = t[con.event_row], t[con.past[0].row], t[con.past[1].row]
    rho = ((t0 - t1) / (t1 - t2))[:, None]
    miss = (1 + rho) * truth.at(t1) - rho * truth.at(t2) - truth.at(t0)
    ray = track.position_world - prep.centers[track.camera]
    r = ray / np.linalg.norm(ray, axis=1)[:, None]
    along = np.einsum("ij,ij->i", miss, r)
    assert np.median(np.abs(along)) > 1e-4  # (gravity's part is there: ~0.1-1 mm)
    assert_allclose(track.quality["_model_gravity_m2"], along**2, rtol=1e-6)
    # across: the prediction's offset across the (exact) newest ray less gravity's there,
    # i.e. across the ray, P̂ - X(t) less the parabola's own miss: the past points' errors
    off = con.predicted_world - truth.at(t0) - miss
    u = off - np.einsum("ij,ij->i", off, r)[:, None] * r
    assert_allclose(track.quality["_model_across_m2"], np.einsum("ij,ij->i", u, u),
                    rtol=1e-6, atol=1e-14)
    # the noise part's metres per pixel², c = (factor D / f)²: the innovation's noise factor
    # of ρ, the prediction's distance from the newest camera, that camera's larger focal
    factor = np.sqrt(1 + (1 + rho[:, 0]) ** 2 + rho[:, 0] ** 2)
    cam = prep.obs.camera[con.event_row]
    depth = np.linalg.norm(con.predicted_world - prep.centers[cam], axis=1)
    focal = np.array([max(c.K[0, 0], c.K[1, 1]) for c in rig.cameras])[cam]
    assert_allclose(track.quality["_model_m2_per_px2"], (factor * depth / focal) ** 2,
                    rtol=1e-9)
    # (and the registry's typeA leaves none of the kernel's model columns in its output)
    out = type_a_explained(prep, rig, FusionOptions(confirm_gaps=False))[0]
    assert not [k for k in out.quality if k.startswith("_")]


def test_the_model_term_lies_along_the_newest_ray_at_the_measured_noise():
    # the registry's covariance is the kernel's at the measured noise plus v r rᵀ, v the
    # model variance (gravity's (h rᵀg)², half |u|² beyond its noise), r the unit ray
    # from the point's camera to the point: every point, every column
    rig, obs, _ = _session(0.3, seed=6, duration=2.0)
    prep = prepare(obs, rig)
    from pslog.fusion._prepare import default_max_gap_s

    gap = default_max_gap_s(rig)
    track = fuse(obs, rig, "typeA", FusionOptions(confirm_gaps=False))
    kernel = fuse_type_a(prep, gap, 0.5, explain=False, cov_noise_px=0.5)[0]
    assert_array_equal(track.position_world, kernel.position_world)
    sigma = _sigma(rig, obs, track.time_ns, 0.5, gap)
    rows = np.arange(len(track))
    model = _model_part(prep, kernel, sigma, rows)
    assert np.median(model[:, 0, 0] + model[:, 1, 1] + model[:, 2, 2]) > 0
    f = (sigma / 0.5) ** 2
    for name, (a, b) in (("xx", (0, 0)), ("yy", (1, 1)), ("zz", (2, 2)), ("xy", (0, 1)),
                         ("xz", (0, 2)), ("yz", (1, 2))):
        expected = kernel.quality[f"cov_{name}_m2"] * f + model[:, a, b]
        assert_allclose(track.quality[f"cov_{name}_m2"], expected, rtol=1e-9,
                        atol=1e-12 * np.abs(expected).max(), err_msg=name)


def test_covariance_at_no_noise_is_no_longer_over_confident():
    # paper2 (two cameras) on a 4 s rally with no detection noise: the covariance held the
    # detection noise only (at its 0.1 px floor) and eq. (2)'s model error — gravity's
    # curvature over the three instants, the kicks — was not in it: the mean d² was 23.1
    # (NEES 7.7), its largest 1,798 (after a kick); with the model term 0.73 and 42. Without
    # noise the newest ray is exact and the error lies along it: an honest covariance's d²
    # is about χ²₁'s (mean 1, 95 % within 4), not χ²₃'s
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    det, truth = simulate(rig, rally_motion(7, 4.0), options=SimulationOptions(noise_px=0.0,
                                                                                seed=7))
    track = fuse(det.best(), rig, "typeA")
    d2 = _mahalanobis_sq(track, _offsets(track, truth))
    d2 = d2[np.isfinite(d2)]
    assert len(d2) > 150
    assert 0.1 < d2.mean() < 2.0, d2.mean()
    assert np.mean(d2 <= 4) > 0.9
    assert d2.max() < 100, d2.max()


def test_the_compiled_selection_is_the_sorted_element():
    """_pseudo_kernel._select (the checkpoints' upper median of type A's measured noise): the
    element ``np.sort(values[:count])[k]`` for every k, on random, sorted, reversed, tied and
    all-equal windows of the residuals' sizes (the same element as numpy's partition, so the
    same bits as the stream's np.sort)."""
    from pslog.fusion import _pseudo_kernel

    rng = np.random.default_rng(12)
    windows = [rng.rayleigh(0.5, 90), np.sort(rng.rayleigh(0.5, 64)),
               np.sort(rng.rayleigh(0.5, 64))[::-1].copy(), np.round(rng.rayleigh(0.5, 101), 1),
               np.full(17, 0.25), rng.rayleigh(0.5, 2), np.array([0.5]),
               np.concatenate([np.full(40, 1.0), np.full(40, 0.5), [0.0, 3.0]])]
    for values in windows:
        for count in sorted({len(values), max(1, len(values) - 3)}):
            expected = np.sort(values[:count])
            for k in range(count):
                scratch = values.copy()
                assert _pseudo_kernel._select(scratch, count, k) == expected[k]
                # (reordered in place, the same values)
                assert_array_equal(np.sort(scratch[:count]), expected)


def test_the_selection_near_a_hint_is_the_sorted_element_whatever_the_hint():
    """_pseudo_kernel._select_near (the checkpoints' and the tests' noise medians, looked for
    first near the previous one): the element ``np.sort(values[:count])[k]`` whatever the
    hint and band: inside the values, at a tie, beyond them on either side, of zero width,
    NaN (no band), on random, sorted, tied and all-equal windows; the band a few values."""
    from pslog.fusion import _pseudo_kernel

    rng = np.random.default_rng(13)
    windows = [rng.rayleigh(0.5, 256), np.sort(rng.rayleigh(0.5, 64)),
               np.round(rng.rayleigh(0.5, 101), 1), np.full(17, 0.25), np.array([0.5]),
               np.concatenate([np.full(40, 1.0), np.full(40, 0.5), [0.0, 3.0]])]
    for values in windows:
        count = len(values)
        expected = np.sort(values)
        half = count // 2
        hints = [(expected[half], 0.1 * expected[half]), (expected[half], 0.0),
                 (expected[0], 0.01), (expected[-1] + 1.0, 0.5), (-1.0, 0.5),
                 (expected[min(half + 3, count - 1)], 0.05), (np.nan, np.nan)]
        for hint, width in hints:
            for k in sorted({0, half, count - 1}):
                for fn in (_pseudo_kernel._select_near, _pseudo_kernel._select_near.py_func):
                    scratch, band = values.copy(), np.empty(count)
                    assert fn(scratch, count, k, hint, width, band) == expected[k], (
                        hint, width, k)
                    assert_array_equal(np.sort(scratch), expected)


def _start_points(prep, track, max_gap_s):
    """The residual norms (numpy reference: stereo.recorded_residuals) and which points of
    ``track`` come before any checkpoint's window holds NOISE_MIN_COUNT of them (the start)."""
    res, weight = recorded_residuals(prep, max_gap_s)
    with np.errstate(invalid="ignore"):
        norm = np.hypot(res[:, 0], res[:, 1]) / np.sqrt(weight)
    fin = np.isfinite(norm)
    t_fin, v_fin = prep.obs.time_ns[fin], norm[fin]
    every, window = int(NOISE_EVERY_S * NS), int(NOISE_WINDOW_S * NS)
    mark = track.time_ns // every * every
    counts = np.searchsorted(t_fin, mark) - np.searchsorted(t_fin, mark - window)
    return t_fin, v_fin, ~np.maximum.accumulate(counts >= NOISE_MIN_COUNT)


def test_the_start_takes_the_residuals_squares_over_2n_minus_2():
    # before any checkpoint has an estimate, a point's σ² is Σ r² / (2n - 2) of the n >= 4
    # residuals in the second before it (E[σ² / σ̂²] = 1: Σ r² / σ² is a χ² of 2n degrees of
    # freedom), without a floor at the stated noise (0.3 px of true noise, 0.5 stated);
    # before the fourth residual max(stated, 2 px). Then the start's points are about honest:
    # their NEES was 0.36-0.40 with the stated 0.5 px as a floor and Σ r² / 2n (held out:
    # docs/methods.md, "Type A's covariance at a session's start")
    from pslog.fusion._prepare import default_max_gap_s

    d2_start, below = [], 0
    for seed in range(6, 12):
        rig, obs, truth = _session(0.3, seed=seed, duration=1.0)
        prep = prepare(obs, rig)
        gap = default_max_gap_s(rig)
        track = fuse(obs, rig, "typeA", FusionOptions(confirm_gaps=False))
        t_fin, v_fin, start = _start_points(prep, track, gap)
        t = track.time_ns[start]
        window = int(NOISE_WINDOW_S * NS)
        lo, hi = np.searchsorted(t_fin, t - window), np.searchsorted(t_fin, t)
        n = hi - lo
        squares = np.array([np.sum(v_fin[a:b] ** 2) for a, b in zip(lo, hi, strict=True)])
        with np.errstate(invalid="ignore", divide="ignore"):
            want = np.where(n >= 4, np.sqrt(squares / (2 * n - 2)), 2.0)
        want = np.maximum(want, min(0.5, NOISE_FLOOR_PX))
        assert_allclose(_sigma(rig, obs, t, 0.5, gap), want, rtol=1e-12)
        measured = start & np.isin(track.time_ns, t[n >= 4])
        below += int(np.count_nonzero(want[n >= 4] < 0.5))
        d2_start.append(_mahalanobis_sq(track, _offsets(track, truth))[measured])
    d2 = np.concatenate(d2_start)
    d2 = d2[np.isfinite(d2)]
    assert len(d2) > 50 and below > 25, (len(d2), below)
    nees = d2.mean() / 3
    assert 0.7 < nees < 1.6, nees
