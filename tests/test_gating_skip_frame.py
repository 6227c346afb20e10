"""The epipolar gate's pair that passes over a frame as if missed (docs/methods.md, "Gate 1",
and "Known limits": a false candidate alone in a frame where its camera missed the ball).

A frame where camera b missed the ball and saw nothing is not in b's frame table, so the
pair carried across it is the ball's; the same frame holding a spurious blob or b's static
object alone is, and paired with b's ball beside it, it moves faster in the image than
``max_image_speed_px_s``: b gave no plausible pair (ratio inf), supported nothing, yet counted
as available, and the ball was rejected. Where no pair of the two frames is plausible, the
gate now carries the pair that passes over one of them (``gating._skip_pairs``), in all four
forms: the numpy and compiled batch support (``_support``, ``_gate_kernel.support_all``), the
Python and compiled stream support (``_support_one``, ``_gate_kernel.support_one``; the
former is also the batch gate's decided support). Each session is ``bench_dirty.py --more``'s
own (its rally, its faults, its simulation seed, 10 % misses); each test fails without the
rule in its form.
"""

from __future__ import annotations

import numpy as np
import pytest
from _rally import rally
from _rigs import ring_rig
from numpy.testing import assert_array_equal
from test_gating import DISTRACTOR, _push_frames

from pslog.evaluation import errors_m
from pslog.fusion import fuse, gating
from pslog.fusion.gating import GatingOptions, StreamGate, gate
from pslog.geometry import fundamental_matrices
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, ball_mask, simulate_labelled


def _session(rig, rally_seed: int, distractor_cam: str, blind: tuple, clean: bool = False):
    """bench_dirty.py --more --first-seed <rally_seed> --misses 0.1's session of its first
    rally (simulation seed ``rally_seed - 300``; ``clean``: without the faults, the same
    ball detections)."""
    motion = rally(8.0, seed=rally_seed, speed=4.0 + rally_seed % 3, kick_every_s=0.9)[0]
    faults = {} if clean else {"spurious_rate": 0.05,
                               "distractors": ((distractor_cam, DISTRACTOR),),
                               "blackouts": (blind,)}
    options = SimulationOptions(noise_px=0.3, seed=rally_seed - 300, miss_rate=0.1,
                                drop_rate=0.05, **faults)
    return simulate_labelled(rig, motion, 8.0, options)


def _paper3(clean: bool = False):
    """paper3 rally-2600: cam3 sees the static object (the ball out of its view around 1 s),
    cam2 blind 2.0-2.5 s. cam2 missed the ball at 0.978 s, where a spurious blob lies alone."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    return rig, *_session(rig, 2600, "cam3", ("cam2", 2.0, 0.5), clean)


def _row(det, ball, camera: int, time_s: float) -> int:
    """The ball candidate of ``camera``'s frame at ``time_s``."""
    t = det.frame_time_ns[det.cand_frame] / 1e9
    cam = det.frame_camera[det.cand_frame]
    rows = np.flatnonzero((np.abs(t - time_s) < 1e-3) & (cam == camera) & ball_mask(det, ball))
    assert len(rows) == 1
    return int(rows[0])


@pytest.fixture(scope="module")
def paper3():
    return _paper3(), _paper3(clean=True)


@pytest.mark.parametrize("compiled", [False, True])
def test_batch_support_passes_over_the_blob_where_the_camera_missed_the_ball(paper3, compiled):
    """cam1's ball at 1.000 s against cam2: the causal pair (0.944 s ball, 0.978 s blob)
    moves at 2,571 px/s; passing over the blob carries cam2's balls of 0.911 and 0.944 s, as
    the clean session does, to the bit (ratio 0.81). Offline, (0.978 blob, 1.011 ball)
    is as fast; of the pairs passing over one frame, (blob, 1.044 s ball) is plausible
    (900 px/s) and 0.81 thresholds off by chance, its carried pixel 50 px from the ball's,
    (0.944, 1.011 s balls) 0.04, the clean session's: the better one is carried. The numpy
    form (``compiled`` False) and support_all each."""
    (rig, det, _truth, ball), (_, clean, _, clean_ball) = paper3
    F = fundamental_matrices(rig.cameras)
    gap = round(3.5e9 / 30)
    for causal in (True, False):
        got, want = [], []
        for d, b, out in ((det, ball, got), (clean, clean_ball, want)):
            c, tables = gating.gate_common(d, rig)
            ratio, carried, used = gating._support(c, rig, F, tables, GatingOptions(), gap,
                                                   causal, 0, compiled=compiled)
            row = _row(d, b, 0, 1.0)
            times = tables[1][0]
            out.append((ratio[row, 1], carried[row, 1], used, row, times, c, tables))
        (r, uv, used, row, times, c, tables), (r_clean, uv_clean, *_) = got[0], want[0]
        assert r <= 1.0 and r == r_clean and np.array_equal(uv, uv_clean), (causal, r)
        # the frames carried are the clean session's (slots 1 and 2: _lags), the blob's
        # frame among those looked at
        carried_at = np.round(times[used[row, 1, 1:3][used[row, 1, 1:3] >= 0]] / 1e6)
        assert carried_at.tolist() == ([944] if causal else [944, 1011])
        assert 978 in np.round(times[used[row, 1]] / 1e6).tolist()
        # a point resting on cam2 was last observed at the nearest frame carried: 0.944 s
        # causal (not the blob's 0.978 s), 1.011 s offline
        lag = gating._lags(c.time_ns, tables, used, compiled)
        assert abs(lag[row, 1] - (0.0556 if causal else 0.0111)) < 1e-3, lag[row, 1]


@pytest.mark.parametrize("compiled", [False, True])
def test_stream_gate_keeps_the_ball_beside_the_blob_where_the_camera_missed_it(paper3,
                                                                              compiled):
    """The same frame in the stream (``_support_one`` in Python, ``support_one``
    compiled): cam1's ball at 1.000 s is chosen (it was rejected, epipolar: cam2 available
    and supporting nothing, cam3 only its object, the ray 14 cm from the prediction 56 ms
    after a kick), the stream's choices are the batch gate's, and the filter's points after
    the kick are the clean session's (1.044 s: 69 mm off without the rule, 6 mm)."""
    (rig, det, truth, ball), _ = paper3
    row = _row(det, ball, 0, 1.0)
    stream = StreamGate(rig, compiled=compiled)
    assert stream.compiled == compiled
    _push_frames(stream, det)
    stream.flush()
    rejected = stream.rejections
    t = det.frame_time_ns[det.cand_frame[row]]
    assert not np.any((rejected.frame_time_ns == t) & (rejected.camera == 0)
                      & np.all(rejected.uv == det.cand_uv[row], axis=1))
    batch = gate(det, rig, causal=True)
    assert batch.chosen[row]
    for name in ("frame_time_ns", "camera", "frame_index", "uv", "reason"):
        assert_array_equal(getattr(rejected, name), getattr(batch.rejections, name))
    if compiled:
        track = fuse(det, rig, "filter")
        err = errors_m(track, truth)
        after = (track.time_ns > 1.005e9) & (track.time_ns < 1.1e9)
        assert after.sum() >= 5 and np.nanmax(err[after]) < 0.05, err[after]


def test_offline_decided_support_passes_over_the_object_where_the_camera_missed_the_ball():
    """wide3 at 60 fps, rally-2801 (``--first-seed 2800 --misses 0.1 --fps 60``): wide3-3
    sees the ball and its static object, and missed the ball at 7.528 s, where the object
    stands alone. Its frame of 7.511 s was decided with the object rejected, so it supports
    wide3-2's balls of 7.522 and 7.539 s with its ball alone (the decided support,
    ``_support_one`` offline, the batch gate's redo): ball and object are 487 px apart in
    17 ms, no plausible pair, and both balls were rejected; passing over 7.528 s pairs the
    balls of 7.511 and 7.544 s, as the clean session does. ``smooth`` then fits the kick at
    7.451 s with them: its points at 7.41-7.48 s within 10 mm (55 and 73 mm without)."""
    base = ring_rig(3, "wide3", f=330.0, dist=(-0.25, 0.05, 3e-4, -2e-4, 0.0), radius=2.4,
                    height=2.2)
    rig = Rig(tuple(c.replace(fps=60.0, offset=c.offset * c.fps / 60.0) for c in base.cameras),
              "wide3@60")
    det, truth, ball = _session(rig, 2801, "wide3-3", ("wide3-3", 2.1, 0.5))
    offline = gate(det, rig, causal=False)
    for time_s in (7.5222, 7.5389):
        assert offline.chosen[_row(det, ball, 1, time_s)], time_s
    track = fuse(det, rig, "smooth")
    err = errors_m(track, truth)
    near = (track.time_ns > 7.40e9) & (track.time_ns < 7.56e9)
    assert near.sum() >= 10 and np.nanmax(err[near]) < 0.01, err[near]


@pytest.mark.parametrize("compiled", [False, True])
def test_causal_support_passes_over_the_frame_before_the_latest(compiled):
    """paper2 (two cameras), the library's rally of ``--first-seed 4400 --misses 0.1 --seeds
    8`` (its ninth session): cam1 sees the static object; it missed the ball at 4.800 s,
    where the object stands alone, and its frames of 4.767 and 4.833 s hold the ball chosen
    and the object rejected. cam2's ball at 4.850 s: cam1's two latest frames are the
    object (4.800) and the ball (4.833), 1,660 px/s apart: no plausible pair; passing over
    the latest (4.767 s ball and 4.800 s object) carries the ball and the object, off the
    line; passing over the one before carries the two balls (4.767, 4.833 s) and supports
    it. With the latest frame alone passed over (session 23's rule) the ball, which the
    track alone had kept before, was rejected. The batch gate (its decided support:
    ``_support_one``) and the stream, ``compiled`` or not."""
    from pslog.motion import rally_motion

    rig = apply_timing(builtin_rig("paper2"), "typeA")
    options = SimulationOptions(noise_px=0.3, seed=4108, miss_rate=0.1, drop_rate=0.05,
                                spurious_rate=0.05, distractors=(("cam1", DISTRACTOR),),
                                blackouts=(("cam2", 2.8, 0.5),))
    det, _truth, ball = simulate_labelled(rig, rally_motion(4105, 8.0), 8.0, options)
    row = _row(det, ball, 1, 4.85)
    assert gate(det, rig, causal=True).chosen[row]
    stream = StreamGate(rig, compiled=compiled)
    assert stream.compiled == compiled
    _push_frames(stream, det)
    stream.flush()
    rejected = stream.rejections
    t = det.frame_time_ns[det.cand_frame[row]]
    assert not np.any((rejected.frame_time_ns == t) & (rejected.camera == 1))
