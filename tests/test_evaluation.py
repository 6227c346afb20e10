"""``pslog eval``'s arithmetic made cheaper without a changed bit: the determinant's sign by
the cofactor expansion where it is certain (LAPACK's LU elsewhere), the truth interpolated
once per track for the accuracy and the quality."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from pslog.evaluation import (
    _positive_det,
    assess,
    covariance_columns,
    evaluate,
    mahalanobis_sq,
    summarise_quality,
)
from pslog.fusion import FusionOptions, fuse
from pslog.motion import get_motion
from pslog.records import NS, Track, Truth
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate


def _columns(cov: np.ndarray) -> tuple[np.ndarray, ...]:
    return tuple(np.ascontiguousarray(cov[:, i, j])
                 for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))


def _symmetric(rng, n: int, kind: str) -> np.ndarray:
    a = rng.normal(size=(n, 3, 3))
    if kind == "spd":
        return a @ a.transpose(0, 2, 1) + 0.1 * np.eye(3)
    if kind == "indefinite":
        return a + a.transpose(0, 2, 1)
    if kind == "negative":
        return -(a @ a.transpose(0, 2, 1) + 0.1 * np.eye(3))
    if kind == "singular":  # rank 2 (rounding leaves a tiny determinant of either sign)
        u, w = rng.normal(size=(n, 3, 1)), rng.normal(size=(n, 3, 1))
        return u @ u.transpose(0, 2, 1) + w @ w.transpose(0, 2, 1)
    if kind == "near-singular":
        return _symmetric(rng, n, "singular") + 1e-15 * np.eye(3)
    if kind == "mixed scales":  # a covariance in m² of axes known to 1e-5 m and to 10 m
        s = np.array([1e1, 1.0, 1e-5])
        return _symmetric(rng, n, "spd") * s[:, None] * s[None, :]
    raise ValueError(kind)


@pytest.mark.parametrize("scale", [1e-12, 1e-6, 1.0, 1e6, 1e-100, 1e100])
def test_the_determinant_sign_is_lapacks(scale):
    """Every kind of symmetric matrix, at every scale (near the ends of the double range
    too): ``_positive_det`` says ``np.linalg.det(cov) > 0`` for each."""
    rng = np.random.default_rng(int(-np.log10(scale)) % 97)
    kinds = ("spd", "indefinite", "negative", "singular", "near-singular", "mixed scales")
    cov = np.concatenate([_symmetric(rng, 400, k) for k in kinds]) * scale
    cov = np.concatenate([cov, np.zeros((1, 3, 3)), np.diag([1.0, -1.0, 1.0])[None] * scale])
    expected = np.linalg.det(cov) > 0
    assert 0.3 < expected.mean() < 0.8  # (both signs, many times)
    assert_array_equal(_positive_det(_columns(cov)), expected)


def _fused(method: str) -> tuple[Track, Truth]:
    """A fused throw whose truth stops before its last points (outside its span), with a
    missing and a singular covariance among its points."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    detections, truth = simulate(rig, get_motion("throw"), None,
                                 SimulationOptions(noise_px=0.5, seed=3))
    track = fuse(detections.best(), rig, method, FusionOptions(gating=False))
    keep = truth.time_ns < track.time_ns[-5]
    truth = Truth(truth.time_ns[keep], truth.position_world[keep])
    quality = {k: np.array(v) for k, v in track.quality.items()}
    first = "cov_xx_m2" if "cov_xx_m2" in quality else "std_x_m"
    quality[first][3] = np.nan
    quality[first][7] = 0.0
    return Track(track.method, track.time_ns, track.position_world, track.camera,
                 quality), truth


@pytest.mark.parametrize("block", [16384, 7])
@pytest.mark.parametrize("method", ["typeA", "filter"])
def test_eval_figures_equal_the_lu_reference(method, block, monkeypatch):
    """``mahalanobis_sq`` is LAPACK's determinant test and solve at every point (the
    reference, written as eval computed it before), in one block or many; ``assess`` is
    ``evaluate`` and ``summarise_quality``; NaN outside the truth's span, inf at the
    unusable covariances."""
    from pslog import evaluation

    monkeypatch.setattr(evaluation, "_BLOCK", block)
    track, truth = _fused(method)
    columns = covariance_columns(track)
    assert columns is not None
    cov = np.empty((len(track), 3, 3))
    for c, (i, j) in zip(columns, ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)),
                         strict=True):
        cov[:, i, j] = cov[:, j, i] = c
    err = track.position_world - truth.at(track.time_ns)
    reference = np.full(len(track), np.inf)
    ok = np.all(np.isfinite(cov), axis=(1, 2)) & np.all(np.isfinite(err), axis=1)
    rows = np.flatnonzero(ok)[np.linalg.det(cov[ok]) > 0]
    sol = np.linalg.solve(cov[rows], err[rows][..., None])[..., 0]
    reference[rows] = np.einsum("ni,ni->n", err[rows], sol)
    reference[~np.all(np.isfinite(err), axis=1)] = np.nan
    d2 = mahalanobis_sq(track, truth)
    assert_array_equal(d2, reference)
    assert np.isnan(d2[-3:]).all() and np.isinf(d2[[3, 7]]).all() and np.isfinite(d2).sum() > 50
    accuracy, quality = assess(track, truth)
    assert accuracy == evaluate(track, truth)
    assert repr(quality) == repr(summarise_quality(track, truth))  # (NaN: repr)
    inside = np.isfinite(err).all(axis=1)
    assert quality.within_2sigma == np.mean(reference[inside] <= 4.0)
    assert quality.nees == np.inf  # (the unusable covariances' points)
    none, alone = assess(track, None)
    assert none is None and repr(alone) == repr(summarise_quality(track, None))
    assert alone.n_points == len(track) and np.isnan(alone.nees)


def _interpolation(truth: Truth, time_ns: np.ndarray) -> np.ndarray:
    """The truth at ``time_ns`` as ``Truth.at`` always computed it (the reference)."""
    out = np.full((len(time_ns), 3), np.nan)
    inside = (time_ns >= truth.time_ns[0]) & (time_ns <= truth.time_ns[-1])
    t = time_ns[inside]
    hi = np.clip(np.searchsorted(truth.time_ns, t, side="left"), 0, len(truth) - 1)
    lo = np.maximum(hi - 1, 0)
    t_lo, t_hi = truth.time_ns[lo], truth.time_ns[hi]
    span = (t_hi - t_lo).astype(np.float64)
    w = np.where(span > 0, (t - t_lo) / np.where(span > 0, span, 1.0), 1.0)
    out[inside] = ((1 - w)[:, None] * truth.position_world[lo]
                   + w[:, None] * truth.position_world[hi])
    return out


def test_truth_at_its_own_samples_and_between_them():
    """At a sampled time the truth is that sample, between two the linear interpolation,
    outside the span NaN: bit for bit the interpolation, the sign of a zero too (a negative
    zero after a positive sample comes out positive: ``0 * previous + 1 * sample``) and a
    NaN where the previous sample has one (``0 * NaN``), whether every time asked is a
    sample's (the simulator's sessions) or not."""
    t = np.array([0, 10, 20, 30, 40], np.int64) * NS // 100
    p = np.array([[1.0, -0.0, 2.0], [3.0, 0.0, -1.0], [-0.0, 5.0, 0.5], [2.0, 2.0, 2.0],
                  [0.0, -0.0, 1.0]])
    mixed = np.array([0, 10, 20, 30, 40, 5, 25, -1, 41], np.int64) * NS // 100
    nan = np.zeros((5, 3), dtype=bool)
    nan[2, 1] = True  # (the next sample, [2, 2, 2], has no zero)
    for positions in (p, np.where(nan, np.nan, p)):
        truth = Truth(t, positions)
        for times in (t, t[::-1], t[1:3], mixed):
            got, expected = truth.at(times), _interpolation(truth, times)
            assert_array_equal(got, expected)
            assert_array_equal(np.signbit(got), np.signbit(expected))
    truth = Truth(t, p)
    assert_array_equal(truth.at(t), p)  # (numerically)
    assert not np.signbit(truth.at(t)[2, 0]) and np.signbit(truth.at(t)[0, 1])
    assert_array_equal(truth.at(mixed[5:7]), [(p[0] + p[1]) / 2, (p[2] + p[3]) / 2])
    assert np.isnan(truth.at(mixed[7:])).all()
    assert truth.at(np.zeros(0, np.int64)).shape == (0, 3)


def test_candidates_are_matched_by_camera_frame_and_pixel():
    """A rejected candidate is found among the session's by its camera, frame index and
    pixel (-0.0 equal to 0.0; a NaN pixel equal to nothing), whether the rejected ones are
    few (an integer test on the frame index first) or many: the same answer as searching
    every key."""
    from pslog.evaluation import _keys, _member, _search

    rng = np.random.default_rng(5)
    n = 4000
    camera = rng.integers(0, 3, n)
    frame = rng.integers(0, 300, n)
    uv = np.round(rng.uniform(0, 640, (n, 2)), 1)
    uv[:20, 0] = 0.0
    uv[20:30] = np.nan
    keys = _keys(camera, frame, uv)
    for size in (1, 7, 60, 3000):
        pick = rng.choice(n, size, replace=False)
        pick = np.r_[pick, np.arange(30)]  # (zeros and NaN pixels among them)
        cam, fr, px = camera[pick].copy(), frame[pick].copy(), uv[pick].copy()
        px[px == 0.0] = -0.0
        cam[:3] = (cam[:3] + 1) % 3  # the same frame and pixel of another camera
        of = _keys(cam, fr, px)
        found = _member(keys, of)
        assert_array_equal(found, _search(keys, of))
        assert not found[20:30].any() and found[pick[3:]][~np.isnan(px[3:, 0])].all()
