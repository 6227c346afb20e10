"""The gate's track restarts from three held-back points that make one ballistic arc
(``_Decider._confirmed``): at a session's start (and after the ball was lost) a candidate
one other camera supports waits for such an arc instead of seeding the track, and after a
kick bigger than the track's allowance the ball's detections stop being rejected after two.

Both cases are from ``benchmarks/bench_dirty.py --more`` (two cameras, ``paper2``)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from pslog import apply_timing, builtin_rig
from pslog.evaluation import errors_m
from pslog.fusion import fuse
from pslog.fusion.gating import REASONS, GatingOptions, _arc_rms, _Decider, gate
from pslog.motion import G
from pslog.simulation import SimulationOptions, simulate_labelled

sys.path.insert(0, str(Path(__file__).parent))
from _rally import rally


def _ball_rows(det, ball) -> np.ndarray:
    """(C,) bool: the candidates of ``det`` that are the ball (``ball``: the labels)."""
    label = {(int(ball.frame_camera[f]), int(ball.frame_time_ns[f])): ball.cand_uv[j]
             for j, f in enumerate(ball.cand_frame.tolist())}
    out = np.zeros(len(det.cand_frame), dtype=bool)
    for j, f in enumerate(det.cand_frame.tolist()):
        uv = label.get((int(det.frame_camera[f]), int(det.frame_time_ns[f])))
        out[j] = uv is not None and bool(np.all(uv == det.cand_uv[j]))
    return out


def test_arc_rms_by_hand():
    # three points on one ballistic arc: no residual; one moved 3 cm across: its share
    t = [0.0, 0.01, 0.02]
    p0, v = np.array([1.0, 2.0, 1.5]), np.array([3.0, -1.0, 2.0])
    pts = [p0 + v * s - np.array([0, 0, 0.5 * G * s * s]) for s in t]
    assert _arc_rms(t, pts) < 1e-12
    moved = [pts[0], pts[1] + np.array([0.0, 0.03, 0.0]), pts[2]]
    # a line through three equally spaced samples, the middle one e off: the fit moves by
    # e/3, residuals (-e/3, 2e/3, -e/3), their squares 6e²/9 summed, RMS over the 3 points
    assert abs(_arc_rms(t, moved) - 0.03 * np.sqrt(6 / 9 / 3)) < 1e-12
    # without gravity taken out, a free fall is no line: 3 points 0.1 s apart
    t = [0.0, 0.1, 0.2]
    fall = [np.array([0.0, 0.0, 2.0 - 0.5 * G * s * s]) for s in t]
    assert _arc_rms(t, fall) < 1e-12


def test_confirmed_needs_three_points_on_one_arc():
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    d = _Decider(rig, GatingOptions())
    v = np.array([2.0, 0.5, 1.0])
    arc = [(0.01 * k, (np.array([1.0, 1.0, 1.0]) + v * 0.01 * k
                       - np.array([0, 0, 0.5 * G * (0.01 * k) ** 2])).tolist()) for k in range(4)]
    off = (np.array(arc[1][1]) + np.array([0.0, 0.3, 0.0])).tolist()  # a false point 30 cm off
    assert not d._confirmed(arc[0][0], 0, arc[0][1])
    assert not d._confirmed(arc[1][0], 1, off)
    assert not d._confirmed(arc[2][0], 0, arc[2][1])  # two on the arc and one off: held
    assert d._confirmed(arc[3][0], 1, arc[3][1])  # the third on it: the track restarts
    assert d.track.t == [arc[0][0], arc[2][0]] and d.held == []
    # a held point older than the track's window no longer counts
    d = _Decider(rig, GatingOptions())
    assert not d._confirmed(0.0, 0, arc[0][1])
    assert not d._confirmed(0.2, 1, arc[1][1])
    assert not d._confirmed(0.21, 0, arc[2][1])


def test_the_first_frames_do_not_seed_the_track_with_a_false_pairing():
    """paper2, a static object seen by cam1 from the start: cam2's first ball detection,
    supported by cam1's single frame (distractor and ball), used to be kept with the point
    the distractor made; the motion gate then rejected cam1's ball and kept the distractor
    (0.033 s), and type A's first points were up to 24 cm off. Now the first candidates wait
    for three points on one arc: no false candidate is kept, and no type A point is 5 cm
    off."""
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    motion = rally(1.0, seed=300, speed=4.0, kick_every_s=0.9)[0]
    det, truth, ball = simulate_labelled(rig, motion, 0.6, SimulationOptions(
        noise_px=0.3, seed=0, distractors=(("cam1", (1.0, 1.5, 0.2)),)))
    g = gate(det, rig, causal=True)
    is_ball = _ball_rows(det, ball)
    assert not np.any(g.chosen & ~is_ball)
    held = ~g.chosen & is_ball
    # the ball's detections not kept: cam1's first frame (two candidates, nothing to judge
    # them by), then three held back until the fourth makes an arc with two of them (the
    # first, paired with the distractor, is off it)
    assert [REASONS[r] for r in g.reason[held]] == ["epipolar", "track", "track", "track"]
    assert det.frame_time_ns[det.cand_frame[held]].max() < 0.06e9
    err = errors_m(fuse(det, rig, "typeA"), truth)
    assert np.nanmax(err) < 0.05, np.nanmax(err)


def test_after_a_kick_the_track_restarts_from_the_ball():
    """paper2 (clean), a 6 m/s rally: after the kick at 2.772 s the track's allowance
    (``track_jump_m_s`` 6 m/s) grew slower than its prediction's miss, and the track gate
    rejected the ball's next five detections (each one well on the other camera's
    epipolar line), until the track's window emptied. Three of them on one arc restart it:
    no more than two in a row are rejected."""
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    motion = rally(3.2, seed=302, speed=6.0, kick_every_s=0.9)[0]
    det, _truth, ball = simulate_labelled(rig, motion, 3.2, SimulationOptions(
        noise_px=0.3, seed=2))
    g = gate(det, rig, causal=True)
    is_ball = _ball_rows(det, ball)
    # ball candidates in (time) order, and the longest run the track gate rejected
    order = np.argsort(det.frame_time_ns[det.cand_frame], kind="stable")
    track_rejected = (g.reason == REASONS.index("track"))[order][is_ball[order]]
    runs = np.diff(np.flatnonzero(np.r_[True, ~track_rejected, True])) - 1
    assert runs.max() <= 2, runs.max()
