"""``filter`` at frame rates above 30 fps: its (re)initialisation window grows until its fit
pins the velocity (``init_span_s``), so the track starts at 60, 120 and 240 fps (it never
did: ``init_window`` detections spanned 10 ms at 3 x 240 fps), and nothing changes at 30 fps.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _rally import rally
from numpy.testing import assert_array_equal
from test_filter import FILTER_QUALITY, lab_rig, session

from pslog import Observations, Rig, SimulationOptions, builtin_rig, get_motion, simulate
from pslog.errors import FusionError
from pslog.evaluation import evaluate
from pslog.fusion import fuse
from pslog.fusion.filter import FilterOptions, fuse_filter
from pslog.fusion.stream import StreamFuser
from pslog.records import NS

#: The filter as it was: a window that never grows (no window spans less than a nanosecond).
NO_GROWTH = FilterOptions(init_span_s=1e-9)


def rig_at(base: Rig, *fps: float) -> Rig:
    """``base``'s cameras at these rates, shutters staggered by a third of the fastest
    period."""
    step = 1.0 / (len(fps) * max(fps))
    return Rig(tuple(c.replace(fps=f, offset=(i * step) % (1.0 / f))
                     for i, (c, f) in enumerate(zip(base.cameras, fps, strict=True))),
               f"{base.name}-{'-'.join(f'{f:g}' for f in fps)}")


def _start_s(track, obs) -> float:
    return (int(track.time_ns[0]) - int(obs.time_ns[0])) / NS


@pytest.mark.parametrize("rig, fps, motion", [
    ("paper3", (240.0,) * 3, "throw"), ("paper3", (60.0,) * 3, "throw"),
    ("lab", (240.0,) * 3, "rally"), ("paper3", (60.0,) * 3, "rally"),
    ("lab", (120.0,) * 3, "throw"), ("paper3", (60.0, 30.0, 60.0), "rally"),
    ("lab", (240.0, 240.0), "throw")])
def test_filter_starts_fast_and_beats_type_a_above_30_fps(rig, fps, motion):
    rig = rig_at(builtin_rig("paper3") if rig == "paper3" else lab_rig(len(fps)), *fps)
    if motion == "rally":
        m, _ = rally(2.0, seed=3, speed=5.0, kick_every_s=0.8)
        obs, truth = session(rig, m, 2.0, noise_px=0.3, seed=2)
    else:
        obs, truth = session(rig, get_motion(motion), 1.2, noise_px=0.3, seed=2)
    track = fuse(obs, rig, "filter")
    assert len(track) > 0, "no point at all"  # before the window grew: none from 60 fps on
    assert _start_s(track, obs) < 0.05  # measured 8 to 25 ms; 30 fps: 33 ms
    type_a = evaluate(fuse(obs, rig, "typeA"), truth)
    filt = evaluate(track, truth)
    # measured: 240 fps 0.22 (throw), 0.22 (rally); 120 fps 0.26; 60 fps 0.32; 30/60 0.33
    assert filt.mean_mm < 0.5 * type_a.mean_mm, (filt, type_a)
    # a point at (nearly) every detection after the start, but those withheld after a jump
    after = np.count_nonzero(obs.time_ns >= track.time_ns[0])
    assert len(track) + sum(track.dropped.values()) > 0.95 * after
    assert len(track) > 0.9 * after


def test_without_growth_no_point_at_240_fps():
    # the mechanism: the window of init_window detections (10 ms) fails on its velocity
    # (here bounded to 0.5 m/s: the default 1 m/s passes at 8 detections, 0.3 px, since a
    # window failing on its uncertainty alone is no longer cut to init_detections - 1,
    # where it never passed again: test_filter_start.py); growing, it passes at 14 ms
    rig = lab_rig(3, fps=240.0)
    obs, _ = session(rig, get_motion("throw"), 0.6, noise_px=0.3, seed=2)
    tight = FilterOptions(max_init_speed_std=0.5)
    assert len(fuse_filter(obs, rig, options=replace(tight, init_span_s=1e-9))) == 0
    track = fuse_filter(obs, rig, options=tight)
    assert len(track) > 0.9 * len(obs)
    assert _start_s(track, obs) < 0.03


def test_restart_after_a_gap_at_240_fps_is_fast():
    rig = lab_rig(3, fps=240.0)
    obs, _ = session(rig, get_motion("throw"), 1.2, noise_px=0.3, seed=5)
    gap = (obs.time_ns >= int(0.5 * NS)) & (obs.time_ns < int(0.6 * NS))  # > max_gap_s
    obs = obs.select(~gap)
    track = fuse(obs, rig, "filter")
    later = track.time_ns[track.time_ns >= int(0.6 * NS)]
    assert len(later) and (later[0] - int(0.6 * NS)) / NS < 0.05
    assert np.count_nonzero(track.quality["init"]) >= 2


@pytest.mark.parametrize("timing", ["staggered", "sync"])
def test_nothing_changes_at_30_fps(timing):
    # 3 cameras at 30 fps: init_detections span a frame period, the window never grows, the
    # points are bit-identical to a filter whose window cannot grow (the filter as it was)
    rig = lab_rig(3)
    if timing == "sync":
        rig = Rig(tuple(c.replace(offset=0.0) for c in rig.cameras), "lab3-sync")
    motion, _ = rally(5.0, seed=2, speed=6.0, kick_every_s=0.9)
    detections, _ = simulate(rig, motion, 5.0, SimulationOptions(
        noise_px=0.5, miss_rate=0.3, drop_rate=0.1, jitter_s=0.0005, seed=3))
    obs = detections.best()
    rng = np.random.default_rng(3)
    uv = obs.uv.copy()
    outlier = rng.random(len(uv)) < 0.05
    uv[outlier] = rng.uniform([0, 0], [800, 600], (int(outlier.sum()), 2))
    obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    ours, old = fuse_filter(obs, rig), fuse_filter(obs, rig, options=NO_GROWTH)
    assert np.count_nonzero(ours.quality["init"]) > 1
    assert_array_equal(ours.time_ns, old.time_ns)
    assert_array_equal(ours.position_world, old.position_world)
    for name in FILTER_QUALITY:
        assert_array_equal(ours.quality[name], old.quality[name])
    assert ours.dropped == old.dropped


def test_streaming_equals_batch_exactly_at_240_fps_with_misses_and_outliers():
    rig = lab_rig(3, fps=240.0)
    motion, _ = rally(1.5, seed=4, speed=5.0, kick_every_s=0.6)
    obs, _ = session(rig, motion, 1.5, noise_px=0.5, miss_rate=0.3, seed=4)
    uv = obs.uv.copy()
    rng = np.random.default_rng(1)
    spurious = rng.choice(len(uv), len(uv) // 20, replace=False)
    uv[spurious] = rng.uniform([0, 0], [800, 600], (len(spurious), 2))
    obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    batch = fuse(obs, rig, "filter")
    fuser = StreamFuser(rig, "filter")
    parts = [fuser.push(obs.time_ns[i], obs.camera[i], obs.uv[i], obs.frame_index[i])
             for i in range(len(obs))]
    parts.append(fuser.flush())
    assert len(batch) > 0.8 * len(obs) and np.count_nonzero(batch.quality["rejected"])
    assert_array_equal(np.concatenate([p.time_ns for p in parts]), batch.time_ns)
    assert_array_equal(np.concatenate([p.position_world for p in parts]), batch.position_world)
    for name in FILTER_QUALITY:
        assert_array_equal(np.concatenate([p.quality[name] for p in parts]),
                           batch.quality[name])


@pytest.mark.parametrize("changes, match", [
    (dict(init_max_window=7), "init_max_window"),
    (dict(init_span_s=0.0), "init_span_s"),
    (dict(init_span_s=float("nan")), "init_span_s"),
])
def test_bad_start_up_options_are_refused(changes, match):
    with pytest.raises(FusionError, match=match):
        FilterOptions(**changes)


def test_the_floor_of_q_is_a_velocity_variance_per_detection_interval():
    # q_min = accel_step_var · Σ fps (session 11): the same velocity variance q T added per
    # detection interval T = 1 / Σ fps on every rig; an explicit accel_psd replaces it
    from pslog.fusion.filter import BallFilter, accel_floor

    paper3 = builtin_rig("paper3")
    for fps, floor in (((30.0, 30.0), 0.001), ((60.0, 30.0, 60.0), 0.0025),
                       ((240.0,) * 3, 0.012)):
        rig = rig_at(Rig(paper3.cameras[:len(fps)], "p"), *fps)
        assert accel_floor(rig, FilterOptions()) == pytest.approx(floor, rel=1e-12)
        flt = BallFilter(rig)
        assert flt._q_min == flt._q == pytest.approx(floor, rel=1e-12)  # floor and start
        assert BallFilter(rig, FilterOptions(accel_psd=0.3))._q == 0.3
    with pytest.raises(FusionError, match="accel_step_var"):
        FilterOptions(accel_step_var=0.0)


@pytest.mark.parametrize("motion", ["straight", "turntable"])
def test_two_cameras_at_30_fps_reach_half_of_type_a(motion):
    # issue 10's 0.3 px target on the sparsest rig (60 detections/s), mean over four noise
    # seeds: measured 0.48 (straight) and 0.48 (turntable); 0.56 and 0.55 with the fixed
    # 0.01 m²/s³ floor of q before session 11
    rig = lab_rig(2)
    ratios = []
    for seed in (1, 2, 3, 4):
        obs, truth = session(rig, get_motion(motion), noise_px=0.3, seed=seed)
        ratios.append(evaluate(fuse(obs, rig, "filter"), truth).mean_mm
                      / evaluate(fuse(obs, rig, "typeA"), truth).mean_mm)
    assert np.mean(ratios) < 0.5, ratios


def test_the_turn_models_switch_is_an_acceleration_on_every_rig():
    # q_on = turn_on_accel2 / Σ fps (session 12): the q the adaptation settles at for a
    # missing acceleration a falls as a² T (an α-β filter's lag a T² / β with β ≈ the
    # tracking index sqrt(q T³) / σ); an explicit turn_on_psd replaces it
    from pslog.fusion.filter import _OTON, BallFilter, turn_on_threshold

    paper3 = builtin_rig("paper3")
    for fps, q_on in (((30.0,) * 3, 0.3), ((30.0, 30.0), 0.45), ((240.0, 240.0), 0.05625),
                      ((60.0, 30.0, 60.0), 0.18)):
        rig = rig_at(Rig(paper3.cameras[:len(fps)], "p"), *fps)
        assert turn_on_threshold(rig, FilterOptions()) == pytest.approx(q_on, rel=1e-12)
        assert BallFilter(rig)._opts[_OTON] == pytest.approx(q_on, rel=1e-12)
        assert BallFilter(rig, FilterOptions(turn_on_psd=0.2))._opts[_OTON] == 0.2
    for bad in (0.0, float("nan"), -1.0):
        with pytest.raises(FusionError, match="turn_on"):
            FilterOptions(turn_on_accel2=bad)
        with pytest.raises(FusionError, match="turn_on"):
            FilterOptions(turn_on_psd=bad)


def test_two_cameras_at_240_fps_give_the_turntable_to_the_turn_model():
    # bench_filter.py --rates: the 2-camera turntable at 240 fps was 0.52 of typeA (seed 2)
    # with the fixed q_on = 0.3 m²/s³, which q reaches at 240 fps only at an acceleration
    # sqrt(8) times 30 fps's; here (seeds 2 and 4 of test_filter.session) 0.29 and 0.31,
    # 0.54 and 0.50 with the fixed switch
    rig = lab_rig(2, fps=240.0)
    for seed in (2, 4):
        obs, truth = session(rig, get_motion("turntable"), noise_px=0.3, seed=seed)
        ratio = (evaluate(fuse(obs, rig, "filter"), truth).mean_mm
                 / evaluate(fuse(obs, rig, "typeA"), truth).mean_mm)
        assert ratio < 0.4, (seed, ratio)
