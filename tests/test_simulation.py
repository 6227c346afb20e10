"""Tests of pslog.simulation: shutter schedules and simulated detections."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.camera import Camera, look_at
from pslog.errors import InputError, PslogError
from pslog.motion import Motion, get_motion
from pslog.records import NS
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, capture_times, simulate


def _paper3(timing: str = "typeA") -> Rig:
    return apply_timing(builtin_rig("paper3"), timing)


def _best_by_frame(det):
    """(F, 2) pixels of each frame's best candidate, NaN where it has none."""
    uv = np.full((det.n_frames, 2), np.nan)
    first = np.ones(det.n_candidates, dtype=bool)
    first[1:] = det.cand_frame[1:] != det.cand_frame[:-1]
    uv[det.cand_frame[first]] = det.cand_uv[first]
    return uv


def _projections(rig: Rig, camera: np.ndarray, positions: np.ndarray):
    """Noise-free pixels (n, 2) of ``positions`` in the camera of each row; visibility."""
    uv = np.full((len(camera), 2), np.nan)
    visible = np.zeros(len(camera), dtype=bool)
    for i, cam in enumerate(rig.cameras):
        rows = camera == i
        uv_cam, in_front = cam.project(positions[rows])
        uv[rows] = uv_cam
        visible[rows] = in_front & cam.in_image(uv_cam)
    return uv, visible


# ---- capture_times ------------------------------------------------------------------------

def test_capture_times_follow_offset_plus_k_over_fps():
    cams = builtin_rig("paper3").cameras
    rig = Rig((cams[0].replace(fps=30.0, offset=0.004), cams[1].replace(fps=25.0, offset=0.0),
               cams[2].replace(fps=60.0, offset=0.01)))
    time_s, camera, frame_index = capture_times(rig, 1.0)
    assert time_s.dtype == np.float64 and camera.dtype == np.int32
    assert frame_index.dtype == np.int64
    for i, cam in enumerate(rig.cameras):
        rows = camera == i
        k = frame_index[rows]
        assert_array_equal(k, np.arange(len(k)))  # every frame, from 0
        assert_allclose(time_s[rows], cam.offset + k / cam.fps, rtol=0, atol=1e-12)
        assert time_s[rows][-1] < 1.0 <= time_s[rows][-1] + 1 / cam.fps
    assert [np.sum(camera == i) for i in range(3)] == [30, 25, 60]
    # sorted by (time, camera)
    assert np.all((np.diff(time_s) > 0) | ((np.diff(time_s) == 0) & (np.diff(camera) > 0)))


def test_capture_times_type_a_paper3_gives_135_frames_in_1_5_s():
    time_s, camera, _ = capture_times(_paper3("typeA"), 1.5)
    assert len(time_s) == 135  # the paper's 135 points
    assert_array_equal(camera, np.tile([0, 1, 2], 45))  # round robin
    assert_allclose(np.diff(time_s), 1 / 90, rtol=0, atol=1e-12)  # 90 fps overall


def test_capture_times_sync_and_type_b():
    time_s, camera, _ = capture_times(_paper3("sync"), 0.1)
    assert_allclose(time_s, np.repeat([0.0, 1 / 30, 2 / 30], 3), rtol=0, atol=1e-15)
    assert_array_equal(camera, np.tile([0, 1, 2], 3))
    time_s, camera, _ = capture_times(_paper3("typeB"), 0.1)
    assert_allclose(time_s, [0, 0, 1 / 60, 1 / 30, 1 / 30, 1 / 20, 2 / 30, 2 / 30, 5 / 60],
                    rtol=0, atol=1e-15)
    assert_array_equal(camera, [0, 2, 1, 0, 2, 1, 0, 2, 1])


@pytest.mark.parametrize("duration", [0.0, -1.0, np.nan, np.inf])
def test_capture_times_rejects_bad_duration(duration):
    with pytest.raises(InputError, match="duration"):
        capture_times(_paper3(), duration)


# ---- simulate -----------------------------------------------------------------------------

@pytest.mark.parametrize("timing", ["sync", "typeA", "typeB"])
@pytest.mark.parametrize("motion_name", ["straight", "spiral", "fall", "turntable", "throw"])
def test_noise_free_detections_are_projections_of_truth(timing, motion_name):
    rig = _paper3(timing)
    motion = get_motion(motion_name)
    det, truth = simulate(rig, motion)
    time_s, camera, frame_index = capture_times(rig, motion.duration)
    # every scheduled frame is recorded, in order
    assert det.n_frames == len(time_s)
    assert_array_equal(det.frame_time_ns, np.round(time_s * NS).astype(np.int64))
    assert_array_equal(det.frame_camera, camera)
    assert_array_equal(det.frame_index, frame_index)
    assert det.camera_names == rig.names
    # truth is the motion at every capture instant
    assert_array_equal(truth.time_ns, np.unique(det.frame_time_ns))
    assert_allclose(truth.position_world, motion.position(truth.time_ns / NS), rtol=0, atol=0)
    # candidates are the projections of the truth at each frame's time
    positions = truth.at(det.frame_time_ns)
    expected, visible = _projections(rig, det.frame_camera, positions)
    assert_array_equal(det.candidates_per_frame(), visible.astype(int))
    assert_allclose(_best_by_frame(det)[visible], expected[visible], rtol=0, atol=1e-9)
    assert visible.mean() > 0.9  # the paper's motions stay in view (almost) all the time


def test_noise_std_close_to_requested():
    rig = _paper3()
    motion = get_motion("turntable")
    clean, _ = simulate(rig, motion, duration=10.0)
    noisy, _ = simulate(rig, motion, duration=10.0, options=SimulationOptions(noise_px=0.7,
                                                                               seed=3))
    assert_array_equal(noisy.cand_frame, clean.cand_frame)  # same frames detected
    error = noisy.cand_uv - clean.cand_uv
    assert len(error) == 900
    assert np.std(error, axis=0) == pytest.approx([0.7, 0.7], rel=0.08)
    assert np.abs(np.mean(error, axis=0)).max() < 0.1
    # reproducible with a seed, different with another
    again, _ = simulate(rig, motion, duration=10.0, options=SimulationOptions(noise_px=0.7,
                                                                               seed=3))
    assert_array_equal(again.cand_uv, noisy.cand_uv)
    other, _ = simulate(rig, motion, duration=10.0, options=SimulationOptions(noise_px=0.7,
                                                                               seed=4))
    assert not np.array_equal(other.cand_uv, noisy.cand_uv)


def test_drop_and_miss_rates():
    rig = _paper3()
    motion = get_motion("turntable")
    n_scheduled = len(capture_times(rig, 20.0)[0])
    assert n_scheduled == 1800
    det, truth = simulate(rig, motion, duration=20.0,
                          options=SimulationOptions(drop_rate=0.2, miss_rate=0.1, seed=1))
    kept = det.n_frames / n_scheduled
    assert kept == pytest.approx(0.8, abs=0.04)
    detected = det.n_candidates / det.n_frames  # the turntable is always in view
    assert detected == pytest.approx(0.9, abs=0.03)
    # dropped frames leave gaps in the frame counter; the recorded ones keep their index
    for i in range(3):
        k = det.frame_index[det.frame_camera == i]
        assert np.all(np.diff(k) >= 1) and np.any(np.diff(k) > 1)
    # truth only at recorded frames
    assert_array_equal(truth.time_ns, np.unique(det.frame_time_ns))
    # the surviving detections are still exact projections
    expected, _ = _projections(rig, det.frame_camera, truth.at(det.frame_time_ns))
    assert_allclose(det.cand_uv, expected[det.cand_frame], rtol=0, atol=1e-9)


def test_jitter_changes_times_and_truth_follows_them():
    rig = _paper3()
    motion = get_motion("spiral")
    nominal, _ = simulate(rig, motion)
    det, truth = simulate(rig, motion, options=SimulationOptions(jitter_s=0.5e-3, seed=2))
    assert det.n_frames == nominal.n_frames
    deviation = (np.sort(det.frame_time_ns) - nominal.frame_time_ns) / NS
    assert np.std(deviation) == pytest.approx(0.5e-3, rel=0.25)
    assert np.abs(deviation).max() < 5e-3
    # truth at the jittered times, and the detections match the truth at those times
    assert_array_equal(truth.time_ns, np.unique(det.frame_time_ns))
    assert_allclose(truth.position_world, motion.position(truth.time_ns / NS), rtol=0, atol=0)
    expected, visible = _projections(rig, det.frame_camera, truth.at(det.frame_time_ns))
    assert_allclose(_best_by_frame(det)[visible], expected[visible], rtol=0, atol=1e-9)
    # frames still sorted by (time, camera)
    assert np.all(np.diff(det.frame_time_ns) >= 0)


def _single_camera_rig() -> Rig:
    R, t = look_at((0.0, -3.0, 1.0), (0.0, 0.0, 1.0))
    K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])
    return Rig((Camera("side", 320, 240, K, np.zeros(5), R, t, fps=100.0),))


def test_frames_with_ball_outside_image_or_behind_have_no_candidate():
    # the ball moves along x through the view (x = 0 in the middle) and then behind the camera
    def position(t):
        x = np.where(t < 1.0, -4.0 + 8.0 * t, 0.0)
        y = np.where(t < 1.0, 0.0, -3.0 - 2.0 * (t - 1.0))  # behind the camera after 1 s
        return np.stack([x, y, np.full_like(t, 1.0)], axis=1)

    rig = _single_camera_rig()
    det, truth = simulate(rig, Motion("pass", 1.5, position),
                          options=SimulationOptions(noise_px=0.3, seed=0))
    assert det.n_frames == 150
    positions = truth.at(det.frame_time_ns)
    cam = rig.cameras[0]
    uv, in_front = cam.project(positions)
    visible = in_front & cam.in_image(uv)
    has_candidate = det.candidates_per_frame() == 1
    assert_array_equal(has_candidate, visible)
    assert 20 < visible.sum() < 60  # it really does leave the image on both sides...
    t = det.frame_time_ns / NS
    assert not np.any(has_candidate[t > 1.0])  # ...and nothing is seen from behind
    # the frames without a candidate are still recorded, as the format requires
    assert np.sum(~has_candidate) == 150 - visible.sum()


def test_default_duration_is_the_motion_duration():
    motion = get_motion("fall")
    det, _ = simulate(_paper3(), motion)
    assert det.frame_time_ns.max() < motion.duration * NS
    det_short, _ = simulate(_paper3(), motion, duration=0.2)
    assert det_short.frame_time_ns.max() < 0.2 * NS and det_short.n_frames == 18


@pytest.mark.parametrize("kwargs, name", [
    ({"noise_px": -1.0}, "noise_px"),
    ({"noise_px": np.nan}, "noise_px"),
    ({"jitter_s": -1e-3}, "jitter_s"),
    ({"jitter_s": np.inf}, "jitter_s"),
    ({"drop_rate": 1.0}, "drop_rate"),
    ({"drop_rate": -0.1}, "drop_rate"),
    ({"miss_rate": 1.5}, "miss_rate"),
    ({"miss_rate": np.nan}, "miss_rate"),
])
def test_simulation_options_validation(kwargs, name):
    with pytest.raises(InputError, match=name) as info:
        SimulationOptions(**kwargs)
    assert isinstance(info.value, PslogError)


def test_simulate_rejects_bad_duration():
    with pytest.raises(InputError, match="duration"):
        simulate(_paper3(), get_motion("straight"), duration=-1.0)


# ---- absurd values (issue 8) --------------------------------------------------------------
def test_absurd_simulation_values_are_refused_saying_why():
    from pslog.simulation import check_duration, check_exposure, check_simulation, shutter_times

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion = get_motion("straight")
    for options, why in ((SimulationOptions(jitter_s=1 / 60), "below half a frame period"),
                         (SimulationOptions(noise_px=1e6), "beyond the image size")):
        with pytest.raises(InputError, match=why):
            check_simulation(rig, options)
        with pytest.raises(InputError, match=why):
            simulate(rig, motion, options=options)
    check_simulation(rig, SimulationOptions(jitter_s=0.008, noise_px=640))
    with pytest.raises(InputError, match="frames"):
        check_duration(rig, 1e9)
    # the synthetic recorder's schedule: no 224 GB array attempted
    with pytest.raises(InputError, match="3e\\+10 frames of camera cam1"):
        shutter_times(rig.cameras[0], 1e9)
    with pytest.raises(InputError, match="frame period"):
        check_exposure(rig, 0.05)


# ---- clock faults (pslog.timing's model) ----------------------------------------------------

def _schedule_ns(rig: Rig, det) -> np.ndarray:
    """Nominal (true) top-row time of each frame of ``det``, ns, from the rig's schedule."""
    offset = np.array([c.offset for c in rig.cameras])[det.frame_camera]
    fps = np.array([c.fps for c in rig.cameras])[det.frame_camera]
    return np.round((offset + det.frame_index / fps) * NS).astype(np.int64)


def _check_truth_is_the_model(rig: Rig, options: SimulationOptions, motion_name="spiral"):
    """Noise-free: each detection's true time by the model (true parameters, detected row)
    is a truth sample, and the truth there projects onto the detection."""
    from pslog.simulation import true_rig
    from pslog.timing import observations

    motion = get_motion(motion_name)
    det, truth = simulate(rig, motion, options=options)
    obs = observations(det, true_rig(rig, options))
    at = np.searchsorted(truth.time_ns, obs.time_ns)
    nearest = np.minimum(np.abs(truth.time_ns[np.clip(at, 0, len(truth) - 1)] - obs.time_ns),
                         np.abs(truth.time_ns[np.clip(at - 1, 0, len(truth) - 1)] - obs.time_ns))
    assert nearest.max() <= 1  # ns: the model rounds its correction to the nanosecond
    assert_allclose(truth.position_world, motion.position(truth.time_ns / NS), rtol=0, atol=0)
    expected, visible = _projections(rig, obs.camera, motion.position(obs.time_ns / NS))
    assert visible.all()
    assert_allclose(obs.uv, expected, rtol=0, atol=1e-6)
    assert len(obs) >= 0.9 * det.n_frames  # the ball is seen nearly always
    return det, truth, obs


def test_clock_offset_fault_logs_times_off_by_the_offset():
    rig = _paper3()
    options = SimulationOptions(clock_offset_s={"cam2": 3.5e-3, "cam3": -2.25e-3})
    det, _, _ = _check_truth_is_the_model(rig, options)
    # true = logged + offset: logged = schedule - offset, exactly (hand-computed)
    shift = np.array([0, 3_500_000, -2_250_000])[det.frame_camera]
    assert_array_equal(det.frame_time_ns, _schedule_ns(rig, det) - shift)


def test_drift_fault_logs_times_on_the_drifting_clock():
    rig = _paper3()
    options = SimulationOptions(clock_drift_ppm={"cam3": 40.0})
    det, _, _ = _check_truth_is_the_model(rig, options)
    true = _schedule_ns(rig, det)
    expected = np.where(det.frame_camera == 2, true / (1 + 40e-6), true)
    assert np.abs(det.frame_time_ns - expected).max() <= 0.5 + 1e-6
    assert (true - det.frame_time_ns)[det.frame_camera == 2].max() > 40e-6 * 1.1 * NS


def test_readout_fault_captures_the_ball_at_its_row():
    rig = _paper3()
    options = SimulationOptions(readout_s={"cam1": 0.02, "cam2": 0.025, "cam3": 0.03})
    det, _, obs = _check_truth_is_the_model(rig, options, "throw")
    # the logged time is the top row's, on the schedule
    assert_array_equal(det.frame_time_ns, _schedule_ns(rig, det))
    # the ball's capture is later by readout * v / height (hand: 20 ms at the bottom row)
    best = det.best()
    delay = {(c, k): t for c, k, t in zip(obs.camera, obs.frame_index, obs.time_ns, strict=True)}
    for c, k, t, v in zip(best.camera, best.frame_index, best.time_ns, best.uv[:, 1],
                          strict=True):
        assert abs(delay[(c, k)] - t - [0.02, 0.025, 0.03][c] * v / 480 * NS) <= 1
    # and the ball moved: the fixed point mattered (a rolling shutter is not a delay of the
    # top row's position)
    nominal, _ = simulate(rig, get_motion("throw"))
    assert np.abs(nominal.best().uv - best.uv).max() > 1.0


def test_host_jitter_moves_only_the_stamps():
    rig = _paper3()
    clean, truth0 = simulate(rig, get_motion("spiral"), 3.0, SimulationOptions(seed=4))
    det, truth = simulate(rig, get_motion("spiral"), 3.0,
                          SimulationOptions(seed=4, host_jitter_s=1e-3))
    assert_array_equal(truth.time_ns, truth0.time_ns)  # the shutters kept their times
    a = np.lexsort((clean.frame_index, clean.frame_camera))
    b = np.lexsort((det.frame_index, det.frame_camera))
    assert_array_equal(det.frame_index[b], clean.frame_index[a])  # indices exact
    dev = (det.frame_time_ns[b] - clean.frame_time_ns[a]) / NS
    assert np.std(dev) == pytest.approx(1e-3, rel=0.15) and abs(np.mean(dev)) < 3e-4
    assert_array_equal(_best_by_frame(det)[b], _best_by_frame(clean)[a])


def test_every_fault_together_still_follows_the_model():
    rig = _paper3()
    options = SimulationOptions(clock_offset_s={"cam2": -4e-3}, clock_drift_ppm={"cam3": -25.0},
                                readout_s={"cam1": 0.01, "cam3": 0.02})
    _check_truth_is_the_model(rig, options, "throw")


@pytest.mark.parametrize("kwargs, message", [
    (dict(clock_offset_s={"cam9": 1e-3}), "clock_offset for unknown camera 'cam9'"),
    (dict(clock_offset_s={"cam1": 1e-3}), "'cam1' is the first of the rig and defines the "
                                          "session clock"),
    (dict(clock_drift_ppm={"cam1": 5.0}), "'cam1' is the first of the rig"),
    (dict(clock_drift_ppm={"cam2": 5000.0}), "clock_drift_ppm 5000 is beyond"),
    (dict(readout_s={"cam3": 0.04}), "readout 0.04 s must be in"),
    (dict(host_jitter_s=0.02), "host jitter 0.02 s must be below half a frame period"),
])
def test_bad_faults_are_refused_naming_the_camera(kwargs, message):
    with pytest.raises(InputError, match=message):
        simulate(_paper3(), get_motion("spiral"), options=SimulationOptions(**kwargs))


# ---- candidate faults: spurious blobs, distractors, blackouts ------------------------------

def test_dirty_session_keeps_the_clean_ball_and_labels_it():
    from pslog.simulation import ball_mask, simulate_labelled

    rig = _paper3()
    motion = get_motion("throw")
    clean, truth, _ = simulate_labelled(rig, motion, None, SimulationOptions(noise_px=0.5,
                                                                           seed=2))
    point = (1.0, 1.5, 0.2)
    options = SimulationOptions(noise_px=0.5, seed=2, spurious_rate=0.3,
                                distractors=(("cam2", point), (None, (1.5, 1.0, 0.0))),
                                blackouts=(("cam3", 0.3, 0.2),))
    dirty, truth2, ball = simulate_labelled(rig, motion, None, options)
    assert_array_equal(truth.position_world, truth2.position_world)
    assert_array_equal(dirty.frame_time_ns, clean.frame_time_ns)
    is_ball = ball_mask(dirty, ball)
    # the ball's candidates are the clean session's, less the blacked-out camera's
    cam = dirty.frame_camera[dirty.cand_frame]
    t = dirty.frame_time_ns[dirty.cand_frame]
    blind = (cam == 2) & (t >= 0.3e9) & (t < 0.5e9)
    assert not np.any(is_ball & blind)
    clean_t = clean.frame_time_ns[clean.cand_frame]
    clean_blind = (clean.frame_camera[clean.cand_frame] == 2) & (clean_t >= 0.3e9) & (
        clean_t < 0.5e9)
    assert clean_blind.sum() > 3
    assert_array_equal(np.sort(dirty.cand_uv[is_ball], axis=0),
                       np.sort(clean.cand_uv[~clean_blind], axis=0))
    # the named distractor: a candidate in every cam2 frame, at its projection (noise only)
    uv, _ = rig.cameras[1].project(np.array([point]))
    near = np.linalg.norm(dirty.cand_uv - uv, axis=1) < 5 * 0.5
    assert set(dirty.cand_frame[near & ~is_ball]) == set(np.flatnonzero(dirty.frame_camera == 1))
    # the unnamed one: in every camera that sees it (all three here)
    uv_all = np.array([c.project(np.array([[1.5, 1.0, 0.0]]))[0][0] for c in rig.cameras])
    near_all = np.linalg.norm(dirty.cand_uv - uv_all[cam], axis=1) < 2.5
    assert set(dirty.cand_frame[near_all & ~is_ball]) == set(range(dirty.n_frames))
    # spurious blobs in about 30 % of frames: the false candidates beyond the distractors
    spurious = (~is_ball).sum() - (dirty.frame_camera == 1).sum() - dirty.n_frames
    assert 0.2 * dirty.n_frames < spurious < 0.4 * dirty.n_frames
    # scores: ball in [0.5, 1], false ones within [0.2, 1]; best-first order kept
    assert np.all((dirty.cand_score[is_ball] >= 0.5) & (dirty.cand_score[is_ball] <= 1))
    assert np.all(dirty.cand_score[~is_ball] >= 0.2)
    assert np.all(clean.cand_score == 1.0)


def test_spurious_near_the_ball_stays_within_its_radius():
    from pslog.simulation import ball_mask, simulate_labelled

    rig = _paper3()
    options = SimulationOptions(seed=1, spurious_rate=0.5, spurious_radius_px=20.0)
    det, _, ball = simulate_labelled(rig, get_motion("spiral"), None, options)
    is_ball = ball_mask(det, ball)
    ball_uv = np.full((det.n_frames, 2), np.nan)
    ball_uv[det.cand_frame[is_ball]] = det.cand_uv[is_ball]
    offset = np.linalg.norm(det.cand_uv[~is_ball] - ball_uv[det.cand_frame[~is_ball]], axis=1)
    assert len(offset) > 20
    assert np.all((offset >= 5.0 - 1e-9) & (offset <= 20.0 + 1e-9))


@pytest.mark.parametrize("options, message", [
    ({"spurious_rate": 1.01}, "spurious_rate"),
    ({"spurious_radius_px": -1.0}, "spurious radius"),
    ({"distractors": (("cam1", (1.0, np.inf, 0.0)),)}, "three finite"),
    ({"blackouts": (("cam1", -1.0, 1.0),)}, "start must be"),
    ({"blackouts": (("cam1", 1.0, 0.0),)}, "duration must be"),
])
def test_candidate_fault_options_refuse_nonsense(options, message):
    with pytest.raises(InputError, match=message):
        SimulationOptions(**options)


def test_candidate_faults_refuse_cameras_and_points_out_of_the_rig():
    from pslog.simulation import check_candidate_faults

    rig = _paper3()
    with pytest.raises(InputError, match="unknown camera 'cam4'"):
        check_candidate_faults(rig, SimulationOptions(blackouts=(("cam4", 0.0, 1.0),)))
    with pytest.raises(InputError, match="not in camera cam1's view"):
        check_candidate_faults(rig, SimulationOptions(distractors=(("cam1", (0, 0, 10)),)))
    with pytest.raises(InputError, match="not in the view of any camera"):
        simulate(rig, get_motion("spiral"), None,
                 SimulationOptions(distractors=((None, (1.5, 1.0, 10.0)),)))


def test_simulate_rest_lays_the_ball_still_before_its_motion(tmp_path, cli, capsys):
    """``pslog simulate --rest S`` (session 37's walk: a robot-soccer ball lies still before
    it is kicked, and no motion started at rest): the truth stands at the motion's start for
    S seconds, then follows the motion shifted by S; the session lasts S longer; its source
    says so; 0 leaves the motion as it is; a bad value is exit 2."""
    from pslog.log import read_session
    from pslog.motion import at_rest_first

    rally = get_motion("rally")
    path = tmp_path / "rest.mcap"
    code, _out, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                         "rally", "--duration", "2", "--rest", "0.4", "--distractor",
                         "1,2,0.1", "--noise-px", "0.3", "--seed", 55010, "-o", path)
    assert code == 0, err
    session = read_session(path)
    t = session.truth.time_ns / NS
    assert 2.35 < t.max() <= 2.4
    still = t <= 0.4
    assert still.sum() >= 11
    assert_allclose(session.truth.position_world[still],
                    np.repeat(rally.position(np.zeros(1)), still.sum(), 0), atol=1e-12)
    assert_allclose(session.truth.position_world[~still], rally.position(t[~still] - 0.4),
                    atol=1e-12)
    assert session.metadata["simulate.rest_s"] == "0.4"
    assert at_rest_first(rally, 0.0) is rally
    assert at_rest_first(rally, 0.5).duration == rally.duration + 0.5
    for bad in ("-1", "nan", "1e9"):  # (argparse's refusals exit, usage_error's return)
        try:
            code, _, err = cli("simulate", "--rig", "paper3", "--rest", bad, "-o",
                               tmp_path / "bad.mcap")
        except SystemExit as exc:
            code, err = exc.code, capsys.readouterr().err
        assert code == 2 and "--rest" in err and err.count("\n") == 1, (bad, err)
    assert not (tmp_path / "bad.mcap").exists()
