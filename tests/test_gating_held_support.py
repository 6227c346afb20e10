"""A support whose ray misses, held: a ball along its camera's ray stays the ball.

``bench_dirty.py --more --validity --first-seed 52200`` (``paper3`` ``straight``, bench seed
51904: the static object on ``cam2``, ``cam3`` blind at 0.70-1.20 s, spurious blobs in 5 %
of frames): ``straight`` flies along ``cam1``'s ray, so ``cam1``'s pixel stands still and only
its support in every frame (``cam2``'s ball) tells it from a static object
(``_still_alone``). In the blackout ``cam3``'s last ball, carried, and one blob of ``cam3``
carried 45-111 ms lie near ``cam1``'s epipolar line: a second support whose ray misses, so
those frames had no point and read as frames where the support did not hold. The gate
took the ball for a static object: 8 of ``cam1``'s ball detections rejected as ``motion``
offline, 5 causally. Two supports whose rays miss count as one ("The decision"): a frame
where one of them alone makes a point is one where the support held
(pslog/fusion/gating.py ``_held``), in the batch gates (numpy and compiled) and in both
stream gates, which store the flag with each frame's point (stream = batch, bit for bit).
"""

from __future__ import annotations

import numpy as np
import pytest
from _rally import rally
from numpy.testing import assert_array_equal
from test_gating import DISTRACTOR
from test_stream_gating import assert_same_track, push_frames

from pslog.fusion import causal_methods, fuse, gating
from pslog.fusion.gating import GatingOptions, StreamGate, gate
from pslog.fusion.stream import StreamFuser
from pslog.geometry import fundamental_matrices
from pslog.motion import get_motion
from pslog.records import Track
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, ball_mask, simulate_labelled


def _straight(timing: str = "typeA", seed: int = 51904):
    """bench_dirty's ``--more --first-seed 52200`` ``paper3`` ``straight`` with its faults
    (at ``timing``: the case is typeA's; ``seed`` 51904 the case, others its neighbours):
    the rig, the detections, their ball mask."""
    rig = apply_timing(builtin_rig("paper3"), timing)
    motion = get_motion("straight")
    options = SimulationOptions(noise_px=0.3, seed=seed, spurious_rate=0.05,
                                distractors=(("cam2", DISTRACTOR),),
                                blackouts=(("cam3", 0.25 * motion.duration + 0.4, 0.5),))
    det, _truth, ball = simulate_labelled(rig, motion, None, options)
    return rig, det, ball_mask(det, ball)


def _dirty(timing: str = "typeA"):
    """A rally with misses (20 %), drops, blobs, the static object and a blackout."""
    rig = apply_timing(builtin_rig("paper3"), timing)
    options = SimulationOptions(noise_px=0.3, seed=38, miss_rate=0.2, drop_rate=0.1,
                                spurious_rate=0.1, distractors=(("cam1", DISTRACTOR),),
                                blackouts=(("cam2", 1.2, 0.5),))
    det, _truth, _ = simulate_labelled(rig, rally(3.0, seed=38, speed=5.0,
                                                  kick_every_s=0.9)[0], 3.0, options)
    return rig, det


def _same_in_the_stream(rig, det, g) -> None:
    """The stream gate's rejections, Python and compiled, are the causal gate ``g``'s."""
    for compiled in (False, True):
        stream = StreamGate(rig, 0.0, compiled=compiled)
        push_frames(stream, det)
        stream.flush()
        for column in ("reason", "frame_time_ns", "camera", "uv"):
            assert_array_equal(getattr(stream.rejections, column),
                               getattr(g.rejections, column), err_msg=f"{compiled=} {column}")


@pytest.mark.parametrize("causal", [True, False])
def test_a_ball_along_its_ray_whose_second_support_misses_stays_the_ball(causal):
    # (before: cam1's ball rejected as 'motion' at 0.867-0.933 and 1.067-1.200 s offline,
    # 5 times causally; none with the blackout alone)
    rig, det, is_ball = _straight()
    g = gate(det, rig, causal=causal)
    cam1 = det.frame_camera[det.cand_frame] == rig.names.index("cam1")
    assert np.count_nonzero(is_ball & cam1) > 30
    rejected = is_ball & ~g.chosen
    assert not np.any(rejected & cam1), det.frame_time_ns[det.cand_frame][rejected & cam1]
    assert not np.any(g.chosen & ~is_ball)  # (nor the object nor a blob chosen instead)
    if causal:
        _same_in_the_stream(rig, det, g)


def _held_flags(rig, det):
    """Per gate form (causal, then offline): the gate's candidates and tables, its options
    and constants, the candidates' support (``ratio``, ``carried``), their points (NaN
    where the rays miss by more than ``track_m``), ``miss`` and the held flags
    (``gating._held``), as ``gating._decided`` makes them."""
    c, tables = gating.gate_common(det, rig)
    F = fundamental_matrices(rig.cameras)
    options = GatingOptions()
    constants = gating._rig_constants(rig)
    for causal in (True, False):
        ratio, carried, _ = gating._support(c, rig, F, tables, options, round(3.5e9 / 30),
                                            causal, 0)
        points, _, miss = gating._points(c, rig, ratio, carried, constants)
        points[miss > options.track_m] = np.nan
        held = gating._held(c, rig, ratio, carried, points, miss, options, constants)
        yield causal, c, tables, options, constants, ratio, carried, points, miss, held


def test_held_counts_a_frame_whose_second_support_misses_but_one_alone_makes_a_point():
    """_held on the session: more than the points (the frames of the case), only where two
    or more supports' rays missed and one support's ray meets the candidate's; its float
    form (_held_one, the stream's) gives the same flags; _static's compiled and numpy forms
    take it alike, and it turns cam1's ball from lone to not lone there."""
    rig, det, _ = _straight()
    for causal, c, tables, options, constants, ratio, carried, points, miss, held in (
            _held_flags(rig, det)):
        finite = np.isfinite(points).all(axis=1)
        extra = held & ~finite
        assert np.all(held[finite])
        assert np.count_nonzero(extra) >= 3, causal
        with np.errstate(invalid="ignore"):
            assert np.all((ratio[extra] <= 1.0).sum(axis=1) >= 2)
        assert np.all(miss[extra] > options.track_m)
        one = [gating._held_one(int(c.camera[i]), c.ray_dir[i].tolist(), ratio[i].tolist(),
                                carried[i].tolist(), float(miss[i]), bool(finite[i]), options,
                                constants) for i in range(len(c.camera))]
        assert_array_equal(one, held)
        lone = []
        for flags in (None, held):
            want = gating._static(c, tables, rig, options, points, gating._paired(ratio),
                                  compiled=False, held=flags)
            got = gating._static(c, tables, rig, options, points, gating._paired(ratio),
                                 compiled=True, held=flags)
            for w, g in zip(want, got, strict=True):
                assert_array_equal(w.view(np.uint8), g.view(np.uint8))
            lone.append(np.isfinite(want[2]))
        # the ball along cam1's ray: lone without the rule (the rejections above), not with
        cam1 = c.camera == rig.names.index("cam1")
        in_blackout = (c.time_ns >= 0.85e9) & (c.time_ns <= 1.2e9)
        assert np.count_nonzero(lone[0] & cam1 & in_blackout) >= 5
        assert np.count_nonzero(lone[1] & cam1 & in_blackout) == 0


@pytest.mark.parametrize("method", causal_methods())
def test_every_causal_method_streams_the_batch_on_the_held_sessions(method):
    """Streaming every frame's candidates gives ``fuse(detections, rig, method)`` bit for
    bit, on the straight session (the rule at work) and on a dirty rally with misses,
    drops, blobs, the object and a blackout."""
    from pslog.fusion import METHODS

    timing = "typeB" if "shared" in METHODS[method].needs else "typeA"
    for rig, det in (_straight(timing)[:2], _dirty(timing)):
        batch = fuse(det, rig, method)
        assert len(batch) >= 8
        fuser = StreamFuser(rig, method, candidates=True)
        streamed = Track.concat([*push_frames(fuser, det), fuser.flush()])
        assert_same_track(streamed, batch)


def test_the_dirty_rallys_stream_gates_are_the_batch_gates():
    rig, det = _dirty()
    g = gate(det, rig, causal=True)
    assert np.count_nonzero(~g.chosen) >= 20
    _same_in_the_stream(rig, det, g)


@pytest.mark.parametrize("seed", [51902, 51907])
def test_each_gate_reads_the_held_flags_of_the_frames_it_compares(seed):
    """The held flags come from the very earlier frames whose pixels the image test compares
    (lag 1 .. static_s fps back): on these neighbours of the case the flags change from
    frame to frame where the count decides (held in all but one of the frames, or one
    fewer), so a form reading its neighbour frame's flags (an off-by-one: the compiled
    stream gate's ``cf[a, h + 1, q, 8]``, found in review) decides otherwise there. The
    stream gates (Python and compiled) are the causal gate, and _static's numpy and
    compiled forms agree, offline and causal."""
    rig, det, _ = _straight(seed=seed)
    _same_in_the_stream(rig, det, gate(det, rig, causal=True))
    for _causal, c, tables, options, _constants, ratio, _carried, points, _miss, held in (
            _held_flags(rig, det)):
        assert np.count_nonzero(held & ~np.isfinite(points).all(axis=1)) >= 1
        want = gating._static(c, tables, rig, options, points, gating._paired(ratio),
                              compiled=False, held=held)
        got = gating._static(c, tables, rig, options, points, gating._paired(ratio),
                             compiled=True, held=held)
        for w, g in zip(want, got, strict=True):
            assert_array_equal(w.view(np.uint8), g.view(np.uint8))


def test_held_is_one_support_whose_ray_meets_where_two_miss():
    """_held's equation on hand-made candidates of paper3's cam1 looking at X: held where the
    point is kept (both supports meet); where the supports' rays miss together, held only
    when one support alone makes a point within ``track_m`` with the candidate's ray (cam2
    at X, cam3 0.4 m off it), not when each one misses alone (cam2 and cam3 both 0.4 m
    off), nor for one support alone whose ray misses (no point: no support). The float
    form (_held_one, the stream's) and the compiled stream gate's (_gate_kernel.held_one)
    give the same flags."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    options = GatingOptions()
    x = np.array([1.0, 1.5, 0.5])

    def ray_of(b):
        return (x - rig.cameras[b].center_world) / np.linalg.norm(x - rig.cameras[b].center_world)

    def off(b):  # X moved 0.4 m along the common normal of cam1's ray and camera b's
        normal = np.cross(ray_of(0), ray_of(b))
        return x + 0.4 * normal / np.linalg.norm(normal)
    # per case: cam2's and cam3's carried points (None: no support); a point 0.4 m off
    # along the common normal: its ray passes 0.4 m from cam1's, the pair's miss 0.2 m
    cases = [(x, x), (x, off(2)), (off(1), off(2)), (off(1), None)]
    n = len(cases)
    ray = ray_of(0)
    ratio = np.full((n, 3), np.nan)
    carried = np.full((n, 3, 2), np.nan)
    for i, supports in enumerate(cases):
        for b, p in enumerate(supports, start=1):
            if p is not None:
                ratio[i, b] = 0.2
                carried[i, b] = rig.cameras[b].project(p[None])[0][0]
    c = gating._Candidates(np.zeros(n, np.int32), np.arange(n, dtype=np.int64),
                           np.tile(rig.cameras[0].project(x[None])[0], (n, 1)),
                           np.tile(ray, (n, 1)), np.arange(n))
    constants = gating._rig_constants(rig)
    import pslog.fusion._gate_kernel  # noqa: F401  (loaded: _points' compiled form)

    for compiled in (False, True):
        if not compiled:
            points, _, miss = gating._points_arrays(c, ratio, carried, constants)
        else:
            points, _, miss = gating._points(c, rig, ratio, carried, constants)
        assert miss[0] < 1e-6 and np.all(miss[1:] > options.track_m)  # (the cases' premise)
        points[miss > options.track_m] = np.nan
        held = gating._held(c, rig, ratio, carried, points, miss, options, constants)
        assert_array_equal(held, [True, True, False, False])
        one = [gating._held_one(0, ray.tolist(), ratio[i].tolist(), carried[i].tolist(),
                                float(miss[i]), bool(np.isfinite(points[i, 0])), options,
                                constants) for i in range(n)]
        assert_array_equal(one, held)
    # the compiled stream gate's (_gate_kernel.held_one, for a candidate without a point)
    from pslog.fusion import _gate_kernel as gk

    centers, k_inv, rot = (np.array(a, dtype=np.float64) for a in constants)
    got = [bool(np.isfinite(points[i, 0])) or gk.held_one(
        0, ray, ratio[i], carried[i], miss[i], options.track_m, centers, k_inv, rot,
        np.empty((4, 6)), np.empty(3)) for i in range(n)]
    assert_array_equal(got, held)
