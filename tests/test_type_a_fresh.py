"""Type A's points resting on a re-acquisition wait for the next camera (session 31).

A camera's first detection after a spell without one (blind, or the ball out of its view)
was chosen by the gate with no track of that camera behind it: only the other cameras'
epipolar lines and the 3D track, whose allowances (8 px, 8 cm and more) let a spurious blob
a dozen pixels from where the ball is but is not seen through. Type A's next two points
extrapolate eq. (2) from it. Such a point now waits for the next camera that can check it,
as a point across a long gap does (:mod:`pslog.fusion.confirm`, ``FRESH_ROWS``).

The session is ``benchmarks/bench_dirty.py --more --first-seed 16200``'s ``lab3``
``straight`` with its faults: ``lab3`` blind 0.70-1.20 s, a spurious blob of it at
1.0889 s 13.7 px from the ball's image chosen by the gate; type A's point at 1.1111 s
(``lab2``), whose ``P_{t-2}`` is the blob's, was 132 mm off with ``std_m`` 5.1 mm
(``benchmarks/session31/typea_far.py``)."""

from __future__ import annotations

import numpy as np
import pytest
from _rigs import lab3_rig
from numpy.testing import assert_array_equal
from test_stream_gating import push_frames
from test_stream_type_a import assert_same, pushed_one_by_one

import pslog.fusion.confirm as confirm
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions, fuse
from pslog.fusion.gating import gate_for
from pslog.fusion.stream import StreamFuser
from pslog.motion import get_motion
from pslog.records import NS, Track
from pslog.simulation import SimulationOptions, simulate_labelled

#: the blob (lab3's, a frame of the blackout) and the far point resting on it, s
BLOB_S, FAR_S = 1.0889, 1.1111


def _session(dirty: bool = True):
    """(rig, detections, truth, ball labels): bench_dirty's lab3 ``straight`` of
    --first-seed 16200 (simulation seed 15904), 0.3 px, with its faults or clean."""
    rig = lab3_rig()
    faults = dict(spurious_rate=0.05, distractors=(("lab2", (1.0, 1.5, 0.2)),),
                  blackouts=(("lab3", 0.7004626062886659, 0.5),)) if dirty else {}
    det, truth, ball = simulate_labelled(rig, get_motion("straight"), None,
                                         SimulationOptions(noise_px=0.3, seed=15904, **faults))
    return rig, det, truth, ball


def _near(t_ns: np.ndarray, at_s: float) -> np.ndarray:
    return np.abs(t_ns / NS - at_s) < 1e-3


def test_the_gate_chooses_the_blob_of_the_blind_camera():
    """The cause, as the session has it: lab3 is blind, its frame at 1.0889 s holds one
    spurious blob, and the causal gate (type A's) keeps it: no gate can tell it from the
    ball there (lab3's first detection since 0.70 s)."""
    rig, det, truth, ball = _session()
    gated = gate_for(det, rig, "typeA", FusionOptions())
    obs = gated.observations
    at = np.flatnonzero(_near(obs.time_ns, BLOB_S) & (obs.camera == 2))
    assert len(at) == 1
    j = int(at[0])
    # not the ball: the ball's frame there holds no candidate (the blackout)
    frame = np.flatnonzero((ball.frame_camera == 2) & (ball.frame_index == obs.frame_index[j]))
    assert len(frame) == 1 and not np.any(ball.cand_frame == frame[0])
    # ... though the ball is in view, 10-20 px from the blob
    i = int(np.searchsorted(truth.time_ns, obs.time_ns[j]))
    uv, front = rig.cameras[2].project(truth.position_world[i:i + 1])
    assert front[0] and 10.0 < np.linalg.norm(uv[0] - obs.uv[j]) < 20.0
    # lab3's previous detection is older than the longest gap bridged (a re-acquisition)
    earlier = obs.time_ns[(obs.camera == 2) & (obs.time_ns < obs.time_ns[j])]
    assert len(earlier) == 0 or obs.time_ns[j] - earlier[-1] > 0.12 * NS


def test_a_point_resting_on_a_re_acquisition_waits_and_is_contradicted(monkeypatch):
    """Before the rule: type A's point at 1.1111 s is > 10 cm off (its P_{t-2} the blob's);
    with it the point waits for the next camera, which contradicts it: no point beyond 5 cm
    near the blob, and the other points of the session are the ones made without the rule
    (a waiting point that is confirmed is the same point, later)."""
    rig, det, truth, _ = _session()
    monkeypatch.setattr(confirm, "FRESH_ROWS", False)
    before = fuse(det, rig, "typeA")
    far = errors_m(before, truth) > 0.05
    assert np.any(far & _near(before.time_ns, FAR_S))
    assert np.max(errors_m(before, truth)[_near(before.time_ns, FAR_S)]) > 0.10
    monkeypatch.setattr(confirm, "FRESH_ROWS", True)
    after = fuse(det, rig, "typeA")
    err = errors_m(after, truth)
    near_blob = (after.time_ns / NS > BLOB_S - 0.01) & (after.time_ns / NS < BLOB_S + 0.1)
    assert not np.any(err[near_blob] > 0.05)
    assert not np.any(_near(after.time_ns, FAR_S) & (after.camera == 1))
    assert after.dropped.get("contradicted", 0) > before.dropped.get("contradicted", 0)
    # every point kept is the same point (the rule only withholds)
    kept = np.isin(before.time_ns * 256 + before.camera, after.time_ns * 256 + after.camera)
    assert_array_equal(before.position_world[kept], after.position_world)
    assert int(np.count_nonzero(~kept)) <= 3  # (the far point, and at most two more)


def test_the_clean_session_loses_no_point():
    """Without the faults nothing re-acquires mid-session but at the start, where the
    waiting points are confirmed: the clean session's points are the same with and
    without the rule."""
    rig, det, _, _ = _session(dirty=False)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(confirm, "FRESH_ROWS", False)
        before = fuse(det, rig, "typeA")
    after = fuse(det, rig, "typeA")
    assert_array_equal(before.time_ns, after.time_ns)
    assert_array_equal(before.position_world, after.position_world)


def test_the_stream_waits_and_decides_as_the_batch_run():
    """StreamFuser (candidates gated as fuse gates them, a frame a push; and the gated
    detections one a push): the same points, columns and counts as the batch run."""
    rig, det, _, _ = _session()
    batch = fuse(det, rig, "typeA")
    fuser = StreamFuser(rig, "typeA", candidates=True)
    streamed = Track.concat([*push_frames(fuser, det), fuser.flush()])
    assert streamed.dropped == batch.dropped
    assert_array_equal(streamed.time_ns, batch.time_ns)
    assert_array_equal(streamed.position_world, batch.position_world)
    for key, column in batch.quality.items():
        assert_array_equal(streamed.quality[key], column, err_msg=key)
    obs = gate_for(det, rig, "typeA", FusionOptions()).observations
    assert_same(pushed_one_by_one(StreamFuser(rig, "typeA"), obs), fuse(obs, rig, "typeA"))
