"""The choice made again at a session's start competes a ``lone`` candidate as fully still
(docs/methods.md, "Candidates and gating", "A lone candidate competes as fully still": the
same term in ``_Decider.decide``'s re-choice and in the compiled ``_gate_kernel.choose``'s),
by hand: one frame of four candidates fed to the Python decider and, with the same columns,
track and camera history, to the compiled one. Two are supported by one camera and come
before the track can predict (their rows' times see two points of its window), so the first
pass keeps one of them; two later in the frame (earlier rows of a rolling shutter: the
window's three points) get the track's first prediction. Several one-support candidates no
track could tell apart: the re-choice rejects both and chooses between the two predicted
ones, which have one support each; the lone one (its pixel as still as a static object's,
kept because its camera's previous choice was there) has the smaller epipolar cost, but
competes as fully still."""

from __future__ import annotations

import numpy as np
import pytest

from pslog.fusion.gating import (
    EPIPOLAR,
    OUTSCORED,
    GatingOptions,
    _Columns,
    _Decider,
    _rig_constants,
)
from pslog.geometry import fundamental_matrices
from pslog.motion import G
from pslog.records import NS
from pslog.rig import apply_timing, builtin_rig

P0 = np.array([1.0, 1.5, 1.0])
V0 = np.array([2.0, -1.0, 1.5])
TRACK_S = (0.00, 0.04, 0.08)  # three points: the track predicts within 0.12 s of 0.00
# rows 0, 1 at 0.125 s (0.00 out of the window: two points, no prediction), rows 2, 3 at
# 0.115 s (three: the first prediction); all on the ball's path seen from cam1
TIMES = (0.125, 0.125, 0.115, 0.115)
UV = ((100.0, 100.0), (200.0, 100.0), (300.0, 300.0), (310.0, 300.0))
EPI_COST = (1.01, 1.02, 1.10, 1.40)
FRAME_NS = round(0.115 * NS)
# cam1 chose (300, 300) in its frame before: row 2 (lone, 4 px tolerance) is its pixel
BEFORE_NS = FRAME_NS - round(NS / 30)
LONE = (np.nan, np.nan, 4.0, np.nan)


def _ball(t_s: float) -> np.ndarray:
    return P0 + V0 * t_s + 0.5 * np.array([0.0, 0.0, -G]) * t_s * t_s


def _case():
    """The rig and the frame's candidates: points (4, 3) and unit rays (4, 3) from cam1."""
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    center = rig.cameras[0].center_world
    pts = np.array([_ball(t) for t in TIMES])
    rays = (pts - center) / np.linalg.norm(pts - center, axis=1)[:, None]
    return rig, pts, rays


def _decide(lone_term: bool = True) -> list[int]:
    """Each candidate's reason (-1 chosen) in the frame, by the Python decider;
    ``lone_term`` False: the lone candidate's stillness as its 3-D one (0), as the re-choice
    had it without the term."""
    rig, pts, rays = _case()
    decider = _Decider(rig, GatingOptions())
    for t in TRACK_S:
        decider.track.add(t, _ball(t))
    decider.picked[0] = (300.0, 300.0, BEFORE_NS)
    decider.last_frame[0] = BEFORE_NS
    cols = _Columns(
        rows=[[np.nan, 0.5]] * 4, available=[1] * 4, lag=[[0.0, 0.0]] * 4,
        n_support=[1] * 4, epi_cost=list(EPI_COST), t_s=list(TIMES),
        t_ns=[round(t * NS) for t in TIMES], rays=rays.tolist(), pts=pts.tolist(),
        front=[True] * 4, static=[False] * 4, stillness=[0.0] * 4,
        lone=list(LONE) if lone_term else [np.nan] * 4, uv=[list(x) for x in UV],
        camera=[0] * 4, unpointed=[False] * 4)
    reason = np.full(4, -1, dtype=np.int8)
    decider.decide([(0, 4)], cols, reason)
    return reason.tolist()


def _choose(lone_term: bool = True) -> list[int]:
    """The same frame decided by the compiled kernel (``_gate_kernel.choose``, what
    ``decide_frame`` calls on the columns it computes): a compiled stream gate's state with
    cam1's frame before (its choice at (300, 300)) and this one, the same track."""
    from pslog.fusion import _gate_kernel as gk

    rig, pts, rays = _case()
    options = GatingOptions()
    lags = [int(np.ceil(options.static_s * cam.fps)) for cam in rig.cameras]
    state = gk.GateState(rig, options, 0, round(3.5 * NS / 30), fundamental_matrices(
        rig.cameras), _rig_constants(rig), lags, G)
    # cam1's kept frames: the one before (one candidate, chosen) and this one (its key: its
    # first candidate's time, as insert_frame sets it)
    state.count[0], state.count[-1] = 2, 2
    state.fi[0, 0] = (BEFORE_NS, BEFORE_NS, 0, 1, 0)
    state.cf[0, 0, 0, :2] = (300.0, 300.0)
    state.fflag[0, 0, 0] = 1  # (decided, as a real earlier frame is)
    state.fi[0, 1] = (round(TIMES[0] * NS), FRAME_NS, 1, 4, -1)
    state.ct[0, 1, :4] = [round(t * NS) for t in TIMES]
    state.cf[0, 1, :4, :2] = UV
    state.cf[0, 1, :4, 2:5] = rays
    for i, t in enumerate(TRACK_S):
        state.trk[i] = (t, *_ball(t), 0.0)
    state.ist[:] = (len(TRACK_S), 0, 0, 0)  # (points, verified, tracked, vouched: none yet)
    reason = np.zeros(4, np.int64)
    gk.choose(0, 1, state.fi, state.fflag, state.ct, state.cf, state.trk, state.ist,
              state.centers, state.opt, np.zeros(4),
              np.array(LONE) if lone_term else np.full(4, np.nan), np.ones(4), np.ones(4),
              np.zeros(4), np.ones(4), np.ascontiguousarray(pts), np.array(EPI_COST),
              np.zeros(4), np.array([[np.nan, 0.5]] * 4), np.zeros((4, 2)), np.zeros(4),
              np.zeros(4), reason)
    assert state.fi[0, 1, 4] == reason.tolist().index(-1)  # (its choice, for the next frame)
    return reason.tolist()


def test_the_session_start_re_choice_competes_a_lone_candidate_as_fully_still():
    # the first pass kept row 0 (cost 1.01, no track cost); rows 0 and 1 are a guess: both
    # rejected; of rows 2 and 3, the lone row 2 costs 1.10 + 1 against row 3's 1.40
    assert _decide() == [EPIPOLAR, EPIPOLAR, OUTSCORED, -1]


def test_without_the_lone_term_the_re_choice_keeps_the_still_pixel():
    # (lone NaN: row 2 is an ordinary candidate, its 3-D stillness 0): row 2 wins
    assert _decide(lone_term=False) == [EPIPOLAR, EPIPOLAR, -1, OUTSCORED]


@pytest.mark.parametrize("lone_term", [True, False])
def test_the_compiled_re_choice_decides_as_the_python_one(lone_term):
    # the compiled twin of the two tests above: the same reasons (removing the term from
    # choose's re-choice fails the lone_term=True case)
    assert _choose(lone_term) == _decide(lone_term)
