"""The choice made again at a session's start competes a ``lone`` candidate as fully still
(docs/methods.md, "Candidates and gating", "A lone candidate competes as fully still": the
same term in ``_Decider.decide``'s re-choice), by hand: one frame of four candidates fed to
the Python decider. Two are supported by one camera and come before the track can predict
(their rows' times see two points of its window), so the first pass keeps one of them; two
later in the frame (earlier rows of a rolling shutter: the window's three points) get the
track's first prediction. Several one-support candidates no track could tell apart: the
re-choice rejects both and chooses between the two predicted ones, which have one support
each; the lone one (its pixel as still as a static object's, kept because its camera's
previous choice was there) has the smaller epipolar cost, but competes as fully still."""

from __future__ import annotations

import numpy as np

from pslog.fusion.gating import EPIPOLAR, OUTSCORED, GatingOptions, _Columns, _Decider
from pslog.motion import G
from pslog.records import NS
from pslog.rig import apply_timing, builtin_rig

P0 = np.array([1.0, 1.5, 1.0])
V0 = np.array([2.0, -1.0, 1.5])


def _ball(t_s: float) -> np.ndarray:
    return P0 + V0 * t_s + 0.5 * np.array([0.0, 0.0, -G]) * t_s * t_s


def _decide(lone_term: bool = True) -> list[int]:
    """Each candidate's reason (-1 chosen) in the frame; ``lone_term`` False: the lone
    candidate's stillness as its 3-D one (0), as the re-choice had it without the term."""
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    options = GatingOptions()
    decider = _Decider(rig, options)
    for t in (0.00, 0.04, 0.08):  # three points: the track predicts within 0.12 s of 0.00
        decider.track.add(t, _ball(t))
    center = rig.cameras[0].center_world
    # rows 0, 1 at 0.125 s (0.00 out of the window: two points, no prediction), rows 2, 3 at
    # 0.115 s (three: the first prediction); all on the ball's path seen from cam1
    times = [0.125, 0.125, 0.115, 0.115]
    pts = [_ball(t) for t in times]
    rays = [(p - center) / np.linalg.norm(p - center) for p in pts]
    uv = [[100.0, 100.0], [200.0, 100.0], [300.0, 300.0], [310.0, 300.0]]
    frame_ns = round(0.115 * NS)
    # cam1 chose (300, 300) in its frame before: row 2 (lone, 4 px tolerance) is its pixel
    decider.picked[0] = (300.0, 300.0, frame_ns - round(NS / 30))
    decider.last_frame[0] = frame_ns - round(NS / 30)
    lone = [np.nan, np.nan, 4.0, np.nan]
    cols = _Columns(
        rows=[[np.nan, 0.5]] * 4, available=[1] * 4, lag=[[0.0, 0.0]] * 4,
        n_support=[1] * 4, epi_cost=[1.01, 1.02, 1.10, 1.40],
        t_s=times, t_ns=[round(t * NS) for t in times], rays=[r.tolist() for r in rays],
        pts=[p.tolist() for p in pts], front=[True] * 4, static=[False] * 4,
        stillness=[0.0] * 4, lone=lone if lone_term else [np.nan, np.nan, np.nan, np.nan],
        uv=uv, camera=[0] * 4, unpointed=[False] * 4)
    reason = np.full(4, -1, dtype=np.int8)
    decider.decide([(0, 4)], cols, reason)
    return reason.tolist()


def test_the_session_start_re_choice_competes_a_lone_candidate_as_fully_still():
    # the first pass kept row 0 (cost 1.01, no track cost); rows 0 and 1 are a guess: both
    # rejected; of rows 2 and 3, the lone row 2 costs 1.10 + 1 against row 3's 1.40
    assert _decide() == [EPIPOLAR, EPIPOLAR, OUTSCORED, -1]


def test_without_the_lone_term_the_re_choice_keeps_the_still_pixel():
    # (lone NaN: row 2 is an ordinary candidate, its 3-D stillness 0): row 2 wins
    assert _decide(lone_term=False) == [EPIPOLAR, EPIPOLAR, -1, OUTSCORED]
