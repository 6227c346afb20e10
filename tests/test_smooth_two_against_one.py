"""Two refined breaks of ``smooth`` less than ``_CLOSE_SPANS`` knot spacings apart are tested
against one break in their place (``trajectory._two_against_one``, session 45): the one's
best instant searched, both models' least costs on the same detections with the near breaks
in the model; the pair stays only where its second break gains more than
``break_threshold`` (25 σ²) over the one. Only where the one lies at neither break of the
pair (farther than the refine's first stage, h/16, from both): a one at one of them asks
whether the other break is needed, which the confirmation decides.

Session 44's held-out failure (``paper3`` rally-78502 of ``bench_dirty.py --more
--first-seed 78500`` with the faults): a kick at 5.5820 s between two kept breaks (5.5505
and 5.6000, a spacing of 37.56 ms), on neither; a point 54 mm off. The refine moves one
break at a time with its neighbour held, and each of the two explained part of the jump.
Here the same pattern is built on a rally of seed 79001 (``paper3``, 10 % of the
detections missed): at each kick alone (none other within 0.3 s) that the fit found, its
break replaced by two 1.3 spacings apart straddling it; the rally's own pairs of kicks 80
ms apart (1.9 spacings), each with its break, stay two."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from _stages import rally_arguments

from pslog.estimation import trajectory
from pslog.records import NS

SEED = 79001


@pytest.fixture(scope="module")
def arguments():
    """The arguments ``fit_trajectory`` gives ``_two_against_one`` on an 8-second rally of
    ``paper3`` with misses (a copy), and the rally's kicks (s since the fit's origin)."""
    (problem, *state), kicks = rally_arguments("_two_against_one", "paper3", SEED)
    return (problem, *state), kicks - problem.t0_ns / NS


def test_two_breaks_straddling_a_kick_become_one_on_it(arguments):
    (*state, spacing, breaks, options), kicks = arguments
    found = np.concatenate(breaks)
    # (the kicks the fit found: some lie where the ball is out of two cameras' view)
    alone = [k for k in kicks if np.sort(np.abs(kicks - k))[1] > 0.3
             and np.min(np.abs(found - k)) < 0.01]
    assert len(alone) >= 4
    for kick in alone:
        p = next(i for i, b in enumerate(breaks) if len(b) and np.min(np.abs(b - kick)) < 0.01)
        others = breaks[p][np.abs(breaks[p] - kick) > 0.02]
        for before in (0.3, 0.45, 0.6):  # spacings before the kick, the other 1.3 on
            pair = np.array([kick - before * spacing, kick + (1.3 - before) * spacing])
            placed = [np.sort(np.r_[others, pair]) if i == p else b
                      for i, b in enumerate(breaks)]
            out = trajectory._two_against_one(*state, spacing, placed, options)
            near = out[p][np.abs(out[p] - kick) < 2 * spacing]
            # one break, on the kick (the pair's nearer one was 0.3 spacings, 13 ms, off)
            assert len(near) == 1 and abs(near[0] - kick) < 0.003, (kick, before, near)
            np.testing.assert_array_equal(np.setdiff1d(out[p], near), others)
            for q, b in enumerate(out):
                if q != p:
                    np.testing.assert_array_equal(b, breaks[q])


def test_two_breaks_at_two_kicks_80_ms_apart_stay_two(arguments):
    (*state, spacing, breaks, options), kicks = arguments
    pairs = [(a, b) for a, b in itertools.pairwise(kicks)
             if b - a < trajectory._CLOSE_SPANS * spacing]
    assert len(pairs) >= 2  # (0.8471, 0.9271 and 1.5954, 1.6754 s: 1.9 spacings apart)
    found = np.concatenate(breaks)
    for pair in pairs:
        assert np.all(np.min(np.abs(found[:, None] - np.array(pair)[None, :]), axis=0) < 0.003)
    out = trajectory._two_against_one(*state, spacing, breaks, options)
    for a, b in zip(out, breaks, strict=True):
        np.testing.assert_array_equal(a, b)


def test_no_close_pair_no_work(arguments):
    # (the rule's only cost where no two breaks are close: their distances)
    (*state, spacing, breaks, options), _ = arguments
    apart = [b[np.r_[True, np.diff(b) > trajectory._CLOSE_SPANS * spacing]] if len(b) else b
             for b in breaks]
    assert trajectory._two_against_one(*state, spacing, apart, options) is apart


def test_a_pair_whose_one_is_one_of_them_is_left_to_the_confirmation(arguments):
    # a break on the kick and one 1.3 spacings after it (no jump there): the one break's
    # best instant is the first's, so the question is whether the second is needed, which
    # the confirmation answers (in context, with its neighbour held); this rule does not
    # decide it (held out, wide3 rally-72507 of 72500: a weak second kick 80 ms after the
    # first, its break 17.6 σ² in context: dropped here, a point 44 mm off)
    (*state, spacing, breaks, options), kicks = arguments
    found = np.concatenate(breaks)
    alone = [k for k in kicks if np.sort(np.abs(kicks - k))[1] > 0.3
             and np.min(np.abs(found - k)) < 0.01]
    for kick in alone:
        p = next(i for i, b in enumerate(breaks) if len(b) and np.min(np.abs(b - kick)) < 0.01)
        on = breaks[p][np.argmin(np.abs(breaks[p] - kick))]
        others = breaks[p][np.abs(breaks[p] - kick) > 0.02]
        placed = [np.sort(np.r_[others, on, on + 1.3 * spacing]) if i == p else b
                  for i, b in enumerate(breaks)]
        out = trajectory._two_against_one(*state, spacing, placed, options)
        np.testing.assert_array_equal(out[p], placed[p])


def test_a_region_without_detections_decides_nothing(arguments):
    # (_region_costs' region, a break's reach either side, holds no detection where the
    # piece's detections lie further apart than _WINDOW_SPANS spacings: a spacing under
    # max_gap_s / 10, 3 cameras at 100 fps or more, and an occlusion; None, as an
    # undetermined solve, not an IndexError out of the fit)
    (problem, control, sigma, r, w, J, spacing, breaks, _), _ = arguments
    X = problem.positions_known(control)
    t_obs = problem.t[problem.rows]
    # (the first piece's rows in time order, as _pieces_with_breaks gives them)
    here = np.argsort(t_obs[:len(problem.rows_of_piece[0])], kind="stable")
    t_here = t_obs[here]
    for lo, hi in ((t_here[-1] + 1.0, t_here[-1] + 2.0), (t_here[3], t_here[3])):
        assert trajectory._region_costs(
            problem, X, r, J, w, sigma, spacing, here, t_here, lo, hi, breaks[0],
            [(np.zeros(0), np.zeros(0)), (breaks[0][:1], np.zeros(0))]) is None
