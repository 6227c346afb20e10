"""A static object whose support comes and goes, in the frames where it has no 3D point.

``paper3``, a rally whose ball leaves the field (``bench_dirty.py --more --first-seed 72300``,
``rally-72307``; held out, session 42): from 5.8 s on only ``cam1`` sees it, and the static
object ``cam2`` sees (the issue's second orange thing, at (1.0, 1.5, 0.2) m) lies on the
ball's epipolar line there, so ``cam1``'s ball supports it in every frame: a point along the
object's ray, 4-5 m from the ball. The image test calls it static in most frames (its pixel
still, its support not continuous: :func:`pslog.fusion.gating._still_alone`), but where the
ball is kicked between ``cam1``'s two frames around one of ``cam2``'s the carried rays miss,
the candidate has no point, no test judged it, and the offline gate chose it: ``smooth`` made
8 points 4.3-4.9 m off at a ``std_m`` of 2-9 mm. The image test now judges such a candidate
with the tolerance of the point known at its pixel in its camera's frames just before
(:func:`pslog.fusion.gating._borrowed_tolerance`), in each of the gate's four forms: the
numpy batch test, the compiled batch test, the compiled whole-session and stream decider and
the stream gate's Python one — the same choices in all of them.
"""
from __future__ import annotations

import numpy as np
import pytest
from _rally import dirty_rally, rally
from numpy.testing import assert_array_equal
from test_gate_whole import decided
from test_stream_gating import assert_same_track, push_frames

import pslog.fusion._gate_kernel  # noqa: F401  (loaded: the gate's compiled forms)
from pslog.evaluation import errors_m
from pslog.fusion import fuse, gating
from pslog.fusion.gating import StreamGate
from pslog.fusion.stream import StreamFuser
from pslog.motion import Motion
from pslog.records import Track
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, ball_mask, simulate_labelled, true_rig

RIG = apply_timing(builtin_rig("paper3"), "typeA")
OBJECT = (1.0, 1.5, 0.2)


@pytest.fixture(scope="module")
def session():
    """(detections, truth, ball labels): the held-out rally with spurious blobs in 5 % of the
    frames and the static object seen by ``cam2``."""
    motion = dirty_rally(72307)[0]
    options = SimulationOptions(noise_px=0.3, seed=72007, spurious_rate=0.05,
                                distractors=(("cam2", OBJECT),))
    return simulate_labelled(RIG, motion, 8.0, options)


def test_smooth_makes_no_point_on_the_object_while_one_camera_sees_the_ball(session):
    det, truth, ball = session
    track = fuse(det, RIG, "smooth")
    err = errors_m(track, truth)
    assert np.nanmax(err) < 0.05, np.nanmax(err)  # (before: 4.88 m, 8 points beyond 5 cm)
    assert len(track) >= 440  # (every frame of the clean session's 447 but the object's)
    # the offline gate chose none of the object's candidates while cam1 alone saw the ball
    gated = gating.gate(det, RIG, causal=False)
    t = det.frame_time_ns[det.cand_frame] / 1e9
    object_rows = ~ball_mask(det, ball) & (det.frame_camera[det.cand_frame] == 1)
    late = (t > 5.8) & (t < 6.7)
    assert np.count_nonzero(object_rows & late) >= 25
    assert not np.any(gated.chosen & object_rows & late)


@pytest.mark.parametrize("causal", [False, True], ids=["offline", "causal"])
def test_the_gates_forms_decide_alike(session, causal):
    det = session[0]
    reason, ratio = decided(det, RIG, False, causal)
    for whole, compiled in ((True, True), (False, False)):
        other, other_ratio = decided(det, RIG, whole, causal, compiled=compiled)
        assert_array_equal(other, reason)
        assert_array_equal(other_ratio, ratio)


@pytest.mark.parametrize("method", ["filter", "typeA"])
def test_the_stream_gate_decides_as_the_batch(session, method):
    det = session[0]
    batch = fuse(det, RIG, method)
    fuser = StreamFuser(RIG, method, candidates=True)
    assert_same_track(Track.concat([*push_frames(fuser, det), fuser.flush()]), batch)


def test_without_the_borrowed_tolerance_the_object_is_chosen(session, monkeypatch):
    """The rule's mutation: each candidate's own tolerance alone (NaN without a point), in
    the numpy batch test; the object is chosen again and ``smooth`` is metres off."""
    det, truth, _ = session
    monkeypatch.setattr(gating, "_kernels", lambda n, wait=False: False)
    monkeypatch.setattr(gating, "_borrowed_tolerance",
                        lambda times, table, y, own, lags, options: own)
    err = errors_m(fuse(det, RIG, "smooth"), truth)
    assert np.nanmax(err) > 1.0


def _rolling_to_rest(seed: int):
    """A ball rolling on ``paper3``'s floor, slowing to rest (1/e in 0.8 s), while ``cam2``
    then ``cam3`` black out (2.0 s, 2.5 s): ``cam1`` keeps seeing it at rest with its support
    coming and going; 25 % misses, 10 % drops, blobs (review42, held out)."""
    rng = np.random.default_rng(seed)
    start = np.array([0.5 + rng.uniform(0, 1), 0.5 + rng.uniform(0, 1), 0.11])
    velocity = np.array([rng.uniform(1, 2.5), rng.uniform(-0.5, 0.5), 0.0])

    def position(t):
        return start + (0.8 * (1 - np.exp(-np.asarray(t, float) / 0.8)))[:, None] * velocity

    options = SimulationOptions(noise_px=0.3, seed=seed, spurious_rate=0.1, miss_rate=0.25,
                                drop_rate=0.1, blackouts=(("cam2", 2.0, 4.0), ("cam3", 2.5, 4.0)))
    return simulate_labelled(RIG, Motion("slowing", 4.0, position), 4.0, options)[0], RIG


def _mixed_rates(seed: int):
    """``paper3`` at 60 and 120 fps with rolling shutters and a clock offset, two objects
    (``cam2``'s and one on the floor for ``cam1``), blobs, misses, drops (review42)."""
    rig = Rig(tuple(c.replace(fps=60.0 * (1 + i % 2), offset=i / 360.0)
                    for i, c in enumerate(RIG.cameras)), RIG.name)
    options = SimulationOptions(noise_px=0.3, seed=seed, spurious_rate=0.1, miss_rate=0.25,
                                drop_rate=0.1, distractors=(("cam2", OBJECT),
                                                            ("cam1", (2.0, 0.6, 0.11))),
                                clock_offset_s={"cam2": 0.004},
                                readout_s=dict.fromkeys(rig.names, 0.005))
    motion = rally(4.0, seed=seed, speed=4.0 + seed % 4, kick_every_s=0.7)[0]
    return simulate_labelled(rig, motion, 4.0, options)[0], true_rig(rig, options)


@pytest.mark.parametrize("make, seed", [(_rolling_to_rest, 73302), (_mixed_rates, 73301)],
                         ids=["rolling-to-rest", "60-120fps"])
def test_the_forms_decide_alike_where_many_candidates_borrow(make, seed, monkeypatch):
    """Sessions where dozens of candidates without a point borrow a tolerance (counted by the
    numpy form): the batch gate's three forms give the same reason codes and ratios, and the
    stream gate's Python form (``_stillness_one``) and compiled one reject as the batch."""
    det, rig = make(seed)
    borrowed = []

    def counted(times, table, y, own, lags, options):
        out = borrowed_tolerance(times, table, y, own, lags, options)
        borrowed.append(np.count_nonzero(np.isnan(own) & ~np.isnan(out) & (table >= 0)))
        return out

    borrowed_tolerance = gating._borrowed_tolerance
    monkeypatch.setattr(gating, "_borrowed_tolerance", counted)
    forms = [decided(det, rig, whole, causal, compiled=compiled)
             for whole, compiled in ((False, True), (True, True), (False, False))
             for causal in (False, True)]
    assert sum(borrowed) >= 20, borrowed
    for i, (reason, ratio) in enumerate(forms[2:], start=2):
        assert_array_equal(reason, forms[i % 2][0], err_msg=f"form {i}")
        assert_array_equal(ratio, forms[i % 2][1], err_msg=f"form {i}")
    batch = gating.gate(det, rig).rejections
    for compiled in (False, True):
        stream = StreamGate(rig, compiled=compiled)
        assert stream.compiled == compiled
        push_frames(stream, det)
        stream.flush()
        for name in ("frame_time_ns", "camera", "uv", "reason"):
            assert_array_equal(getattr(stream.rejections, name), getattr(batch, name))
