"""A static object every camera sees, chosen at a session's start (docs/methods.md, "An
unmoved choice at the start"): session 36's new-user walkthrough, ``pslog simulate --rig
paper3 --seed 48001 --distractor 1.0,2.0,0.1`` (the spiral; the object at the paper's
default timing and at type-A timing). In a camera's first ``static_s`` the stillness test
cannot judge, so the object, consistent in three views, passes every gate; cam1 chose it at
33 ms with nothing rejected near it yet (doubt 0), and nearest's point there, 1.3-2.2 m
off, rested on it. A choice that stood at its pixel in every frame of its camera so far,
in a camera that has seen several candidates in a frame, is now in doubt (``unmoved``):
nearest's covariance holds it, type A withholds and the filter leaves it out; the ball's
own choices on a clean session are never so judged, and the streams equal the batch."""

from __future__ import annotations

import numpy as np
import pytest
from test_gating_late_doubt import _stream
from test_stream_gating import assert_same_track, push_frames

from pslog.evaluation import errors_m, mahalanobis_sq
from pslog.fusion import fuse
from pslog.fusion.gating import GatingOptions, gate, unmoved_doubt
from pslog.motion import Motion, ballistic_with_bounces, get_motion
from pslog.records import Track
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, ball_mask, simulate_labelled

OBJECT = (1.0, 2.0, 0.1)


def _assert_streams_equal_batch(rig, det, tracks) -> None:
    """Every causal method's stream (compiled and Python gate; per detection and per frame)
    gives the batch's track, bit for bit."""
    for method in ("typeA", "nearest", "filter"):
        for compiled in (True, False):
            for form in ("push", "push_frame"):
                fuser = _stream(rig, method, compiled)
                out = Track.concat([*push_frames(fuser, det, form), fuser.flush()])
                assert_same_track(out, tracks[method])


def _walkthrough(timing: str, distractor: bool = True):
    """The walkthrough's session (the CLI's simulation, 0 px noise, seed 48001), the
    paper's cameras at ``timing``: (rig, detections, truth, which candidates are the ball)."""
    rig = apply_timing(builtin_rig("paper3"), timing)
    motion = get_motion("spiral")
    det, truth, ball = simulate_labelled(rig, motion, motion.duration, SimulationOptions(
        seed=48001, distractors=((None, OBJECT),) if distractor else ()))
    return rig, det, truth, ball_mask(det, ball)


@pytest.mark.parametrize("timing", ["sync", "typeA"])
def test_the_object_chosen_unmoved_before_the_stillness_test_can_judge_is_in_doubt(timing):
    rig, det, truth, is_ball = _walkthrough(timing)
    cam1 = det.frame_camera[det.cand_frame] == 0
    t_ms = np.round(det.frame_time_ns[det.cand_frame] / 1e6)
    obj33 = np.flatnonzero(cam1 & (t_ms == 33) & ~is_ball)
    assert len(obj33) == 1
    g = gate(det, rig, causal=True)
    assert g.reason[obj33[0]] < 0  # (the object chosen over the ball beside it)
    chosen = np.flatnonzero(g.reason < 0)
    doubt = unmoved_doubt(det, rig, g.reason, chosen, GatingOptions())
    assert doubt[np.flatnonzero(chosen == obj33[0])[0]] > 0
    # (the object's own choices; the ball's only where it is as slow in its image, 3 px)
    row = np.flatnonzero((g.observations.camera == 0) & (np.round(
        g.observations.time_ns / 1e6) == 33))
    assert len(row) == 1 and g.doubt_px2 is not None and g.doubt_px2[row[0]] > 0
    tracks = {m: fuse(det, rig, m) for m in ("typeA", "nearest", "filter")}
    for m in ("typeA", "filter"):
        e = errors_m(tracks[m], truth)
        assert len(e) >= 80 and np.nanmax(e) < 0.05, m
    near = tracks["nearest"]
    err = errors_m(near, truth)
    far = np.flatnonzero(err > 0.05)
    # (the start's points on the object, metres off; cam1's object at 133 ms is the
    # regular doubt's, two refusals near it)
    start = far[(near.time_ns[far] < 0.1e9) & (err[far] > 0.3)]
    assert len(start) >= 3 and np.all(err[start] > 0.9)
    # stated: each within 3 sigma of the truth (a chi-square of 3 dof: 14.2 at 99.7 %);
    # without the rule cam1's point at 33 ms, 2.18 m off, had d2 166,233
    d2 = mahalanobis_sq(near, truth)
    assert np.all(d2[start] < 14.2)
    _assert_streams_equal_batch(rig, det, tracks)


def test_a_clean_start_has_no_unmoved_choice():
    """The same session without the object: one candidate a frame, nothing in doubt."""
    for timing in ("sync", "typeA"):
        rig, det, _, _ = _walkthrough(timing, distractor=False)
        g = gate(det, rig, causal=True)
        chosen = np.flatnonzero(g.reason < 0)
        assert not unmoved_doubt(det, rig, g.reason, chosen, GatingOptions()).any()
        assert g.doubt_px2 is None


def _at_rest_then_dropped():
    """The ball at rest at (1.0, 1.0, 0.8) m for 0.3 s, then dropped (bouncing), beside the
    walkthrough's object that every camera sees; paper3, type-A shutters, 0.3 px, seed 22,
    1 s: (rig, detections, truth)."""
    p0 = np.array([1.0, 1.0, 0.8])

    def position(t):
        t = np.asarray(t, dtype=np.float64)
        out = ballistic_with_bounces(p0, np.zeros(3), t - 0.3)
        out[t < 0.3] = p0
        return out

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, truth, _ = simulate_labelled(rig, Motion("rest-drop", 1.0, position), 1.0,
                                      SimulationOptions(noise_px=0.3, seed=22,
                                                        distractors=((None, OBJECT),)))
    return rig, det, truth


def test_a_still_point_chosen_between_two_still_candidates_is_in_doubt():
    """Two still things at the start, the ball at rest and the object: the stillness test
    cannot judge either before static_s, and the gate chose the object in cam3 and cam1
    (consistent in three views, as the ball). Without the still partner (another camera's
    still candidate on the choice's epipolar line: a still point in space beside another
    still candidate) type A's points at 56-78 ms and the filter's at 56-122 ms were 1.22 m
    off with std_m 6-76 mm; now those choices are in doubt, no point beyond 5 cm, and the
    streams equal the batch."""
    rig, det, truth = _at_rest_then_dropped()
    tracks = {m: fuse(det, rig, m) for m in ("typeA", "filter", "nearest")}
    for m in ("typeA", "filter"):
        e = errors_m(tracks[m], truth)
        assert len(e) >= 40 and np.nanmax(e) < 0.05, m
    _assert_streams_equal_batch(rig, det, tracks)


def test_a_slow_ball_beside_a_blob_from_nowhere_is_not_in_doubt():
    """The live tests' dirty rally (tests/_live.py: 20 % spurious blobs): cam3's ball at
    56 ms stood within DOUBT_RADIUS_PX of its 22 ms pixel (slow in that image, 4.4 px a
    frame) beside a blob 285 px from anything of cam3's frame before, beyond a ball's reach
    (max_image_speed_px_s x 33 ms = 50 px): a blob that comes from nowhere is no moving
    ball, so the choice is not in doubt (with any moved candidate counting, it was, and type
    A withheld the points resting on it)."""
    from _live import rally_session

    rig, det = rally_session(1.5)
    g = gate(det, rig, causal=True)
    chosen = np.flatnonzero(g.reason < 0)
    t_ms = np.round(det.frame_time_ns[det.cand_frame[chosen]] / 1e6)
    cam3 = det.frame_camera[det.cand_frame[chosen]] == 2
    assert np.count_nonzero(cam3 & (t_ms == 56)) == 1
    assert not unmoved_doubt(det, rig, g.reason, chosen, GatingOptions()).any()
