"""``filter``'s start: the window is fitted by every model of the set (ballistic, supported,
coordinated turn), each model starts at its own fit with a probability from the fits'
likelihoods (docs/methods.md, "Loss and (re)initialisation"), and the supported model carries
no air drag (``supported_drag_per_m`` = 0): a ball on a line is no longer started on a
ballistic arc, and a turning ball's turn model starts with the window's turn rate.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_filter import lab_rig
from test_stream_type_a import assert_same, pushed_one_by_one

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.errors import FusionError
from pslog.evaluation import evaluate
from pslog.fusion import fuse
from pslog.fusion.filter import BallFilter, FilterOptions, fuse_filter
from pslog.fusion.stream import StreamFuser
from pslog.motion import Ball
from pslog.records import NS

#: The filter before session 8: the ballistic start alone, the golf ball's drag in both
#: models of the pair (bit for bit its points: benchmarks/filter_equality.py).
BEFORE = FilterOptions(start_models=False, supported_drag_per_m=Ball().drag_per_metre,
                       window_noise_prior=False)


def _detections(motion: str, noise: float = 0.0, fps: float = 30.0):
    rig = lab_rig(3, fps=fps)
    m = get_motion(motion)
    detections, truth = simulate(rig, m, m.duration, SimulationOptions(noise_px=noise, seed=2))
    return rig, detections.best(), truth


def _started(rig, obs, options=None) -> BallFilter:
    """The filter right after its first point (the start)."""
    flt = BallFilter(rig, options)
    for t, c, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(),
                            strict=True):
        if flt.push(t, c, u, v) is not None:
            return flt
    raise AssertionError("no start")


def test_start_carries_each_models_fit():
    # noise-free line (3 m/s, no gravity, no drag): the supported model's state (x - μ e)
    # is its exact fit, the ballistic one's (x + (1 - μ) e) carries gravity's curvature in
    # its velocity; a start's 4 detections over 44 ms tell them apart only by the noise
    # the start assumes (at the stated 0.5 px μ stayed near its prior; with the window's
    # own bound of its noise, session 10, it is at its bound 0.1), and the IMM's μ moves the
    # state to the supported fit as detections come
    rig, obs, truth = _detections("straight")
    flt = _started(rig, obs)
    t = flt.time_ns
    v_true = (truth.at(np.array([t + 1000])) - truth.at(np.array([t - 1000])))[0] / 2e-6
    x, e, mu = np.array(flt._x), np.array(flt._e), flt._mu
    assert 0.1 - 1e-12 <= mu <= 0.9
    np.testing.assert_allclose((x - mu * e)[3:], v_true, atol=1e-6)
    assert np.linalg.norm((x + (1 - mu) * e)[3:] - v_true) > 0.05
    before = _started(rig, obs, BEFORE)
    assert not np.any(before._e)  # one ballistic fit, the models' difference 0
    assert np.linalg.norm(np.array(before._x)[3:] - v_true) > 0.05


def test_noise_free_line_no_worse_than_type_a():
    # type A is exact on a constant velocity; the filter was 1.2-2.5 times its error
    # (a ballistic start, drag in the supported model); the same detections
    rig, obs, truth = _detections("straight")
    type_a = evaluate(fuse(obs, rig, "typeA"), truth).mean_mm
    now = evaluate(fuse_filter(obs, rig), truth).mean_mm
    before = evaluate(fuse_filter(obs, rig, options=BEFORE), truth).mean_mm
    assert before > 1.1 * type_a
    assert now <= type_a


def test_turn_model_starts_at_its_own_fit():
    # a turntable (45 rpm) at 30 fps: the turn model starts at its fit of the window, its
    # turn rate's variance below the prior's and correlated with the position (the fit's
    # covariance); before, it joined at the next detection at the pair's state, ω = 0 ± 6
    rig, obs, truth = _detections("turntable")
    flt = _started(rig, obs)
    Pt = np.array(flt._Pt).reshape(7, 7)
    assert 0.1 <= flt._nu < 0.2  # 4 detections: near the prior's odds
    assert flt._xt[6] != 0.0 and 0.0 < Pt[6, 6] < 6.0 ** 2
    assert np.any(np.abs(Pt[6, :3]) > 1e-6)
    assert _started(rig, obs, BEFORE)._nu == 0.0
    # its turn rate settles sooner: noise-free, the first 0.2 s decide the session's error
    assert (evaluate(fuse_filter(obs, rig), truth).mean_mm
            < 0.8 * evaluate(fuse_filter(obs, rig, options=BEFORE), truth).mean_mm)


def test_streaming_equals_batch_with_the_fitted_starts():
    rig, obs, _ = _detections("turntable", noise=0.3, fps=60.0)
    batch = fuse_filter(obs, rig)
    flt = BallFilter(rig)
    points = [flt.push(t, c, u, v) for t, c, (u, v) in
              zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(), strict=True)]
    stream = np.array([p[0] for p in points if p is not None])
    assert np.array_equal(stream, batch.position_world)


def test_negative_supported_drag_is_refused():
    with pytest.raises(FusionError, match="supported_drag_per_m"):
        FilterOptions(supported_drag_per_m=-0.1)


def test_turn_probability_is_its_bayes_factor_against_the_pair():
    # ν from the three fits by hand (docs/methods.md, "One fit per model"): the turn model's
    # Laplace Bayes factor against the supported model it nests, the pair's evidence
    # (ballistic and supported at the prior μ₀) divided out; windows of a turning ball
    import math

    rig, obs, _ = _detections("turntable", noise=0.3)
    flt = BallFilter(rig)
    rows = list(zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv[:, 0].tolist(),
                    obs.uv[:, 1].tolist(), strict=True))
    checked = inside = 0
    for start in range(0, len(rows) - 8, 3):
        window = rows[start:start + 8]
        fit, _mu, _e, turn = flt._fit_models(window)
        ballistic, supported = flt._fit(window), flt._fit(window, ballistic=False)
        if turn is None or not isinstance(supported, tuple):
            continue
        xt, Pt, nu = turn
        ss = {k: float(np.sum(f[2] ** 2)) for k, f in (("b", ballistic), ("s", supported))
              if isinstance(f, tuple)}
        rt = flt._turn_fit(window, supported[0], flt._window_var(8, (
            ballistic if ss.get("b", math.inf) <= ss["s"] else supported)[2]))[2]
        var = flt._window_var(8, fit[2])  # the noise from the best of the three fits
        log_b = (0.5 * (ss["s"] - float(rt @ rt)) / var
                 + 0.5 * math.log(Pt[48] / flt._turn_var) - 0.5 * xt[6] ** 2 / flt._turn_var)
        if "b" in ss:
            mu0 = flt._mu0
            log_b -= math.log(mu0 * math.exp(0.5 * (ss["s"] - ss["b"]) / var) + 1 - mu0)
        odds = 0.1 / 0.9 * math.exp(log_b)
        assert nu == pytest.approx(min(max(odds / (1 + odds), 0.1), 0.9), rel=1e-9)
        checked += 1
        inside += 0.1 < nu < 0.9
    assert checked >= 5 and inside >= 1, (checked, inside)


def test_two_camera_restart_keeps_a_window_that_failed_on_its_uncertainty():
    # paper2 (two cameras 30 fps), 1 px, 15 % misses, 5 % drops, cam1 blind 4-5 s: the track
    # was lost at 1.2 s and never started again (25 of 913 detections output): a window
    # whose fit failed on its position's uncertainty alone was cut down to init_detections
    # - 1 like one holding a break, so every later fit had 4 detections of 2 cameras at
    # 1 px (position std > 5 cm), failed again and was cut again
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    detections, _ = simulate(rig, get_motion("rally"), 20.0, SimulationOptions(
        noise_px=1.0, seed=5, miss_rate=0.15, drop_rate=0.05,
        blackouts=(("cam1", 4.0, 1.0),)))
    obs = detections.best()
    track = fuse(obs, rig, "filter")
    # measured: 501 points (typeA 757), 24-63 in every 2 s; before, 25 in the first 2 s
    assert len(track) > 0.5 * len(fuse(obs, rig, "typeA"))
    assert np.all(np.histogram(track.time_ns / NS, bins=np.arange(0.0, 20.1, 2.0))[0] > 10)
    assert np.count_nonzero(track.quality["init"]) >= 3
    assert_same(pushed_one_by_one(StreamFuser(rig, "filter"), obs), track)


def test_a_window_failing_on_its_uncertainty_alone_is_kept():
    # the mechanism, on one window: four detections of two cameras whose fit passes the
    # residual tests but not max_init_std_m; the window keeps them (a shorter one has
    # still less information), where it kept three
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    detections, _ = simulate(rig, get_motion("throw"), 1.0, SimulationOptions(seed=1))
    obs = detections.best()
    flt = BallFilter(rig, FilterOptions(max_init_std_m=1e-6))
    for t, c, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(),
                            strict=True):
        assert flt.push(t, c, u, v) is None  # no start can pass a 1 µm bound
    assert len(flt._window()) == FilterOptions().init_window
