"""When the refine of ``smooth``'s breaks brings two within a knot spacing, they merge into
one (``trajectory._one_per_span``) and the breaks are searched again from where the pass
left them — since session 29 only the two beside the one dropped (their search held it as a
neighbour) and those the pass moved by more than ``_REFINE_AGAIN`` spacings; every other
break keeps its instant (before, a single merge anywhere searched all of a session's breaks
again: a 90-minute match's 10,224 for its one merge, and a second search moves a break the
first left in place by a fraction of a microsecond)."""

from __future__ import annotations

import numpy as np
import pytest
from _stages import first_arguments

from pslog import SimulationOptions, apply_timing, builtin_rig, simulate
from pslog.estimation import trajectory
from pslog.motion import rally_motion
from pslog.timing import observations


@pytest.fixture(scope="module")
def refine_arguments():
    """The arguments ``fit_trajectory`` gives ``_refine_breaks`` on a 20-second rally (a
    copy: the fit goes on with its problem afterwards)."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    detections, _ = simulate(rig, rally_motion(seed=5, duration=20.0), 20.0,
                             SimulationOptions(noise_px=0.3, seed=3))
    return first_arguments("_refine_breaks", observations(detections, rig), rig)


def _moved(new: np.ndarray, old: np.ndarray) -> np.ndarray:
    """Each of ``new``'s instants' distance to the nearest of ``old``'s."""
    return np.min(np.abs(new[:, None] - old[None, :]), axis=1)


def test_after_a_merge_the_breaks_beside_it_and_those_moved_far_are_searched_again(
        refine_arguments):
    *state, spacing, breaks, options = refine_arguments
    p = int(np.argmax([len(b) for b in breaks]))
    assert len(breaks[p]) >= 20
    # a break added 1.35 spacings after one of the rally's (where there is no jump): its
    # refine moves it towards that jump, within a spacing of it, and one of the two goes
    for k in range(len(breaks[p]) // 4, len(breaks[p]) - 2):
        twin = [np.sort(np.r_[b, b[k] + 1.35 * spacing]) if i == p else b
                for i, b in enumerate(breaks)]
        first, dropped = trajectory._refine_pass(*state, spacing, twin, options, None)
        if len(dropped[p]):
            break
    assert len(dropped[p]) == 1 and len(first[p]) == len(breaks[p])
    assert not any(len(d) for i, d in enumerate(dropped) if i != p)
    out = trajectory._refine_breaks(*state, spacing, twin, options)
    # a whole second pass: from the first pass's instants, its neighbours held there
    second, _ = trajectory._refine_pass(*state, spacing, first, options, None)
    j = int(np.searchsorted(first[p], dropped[p][0]))
    beside = np.array([j - 1, j])
    moved = _moved(first[p], twin[p])
    # (h/32: _REFINE_AGAIN; here three breaks moved by 0.036-0.057 h, five by 0.022-0.030 h)
    far = np.setdiff1d(np.flatnonzero(moved > spacing / 32), beside)
    near = np.setdiff1d(np.flatnonzero(moved <= spacing / 32), beside)
    assert len(far) >= 2 and np.count_nonzero(moved[near] > spacing / 64) >= 3
    # those beside the dropped instant and those moved far: as the second pass finds them
    np.testing.assert_array_equal(out[p][beside], second[p][beside])
    assert not np.array_equal(out[p][beside], first[p][beside])  # (they moved)
    np.testing.assert_array_equal(out[p][far], second[p][far])
    assert not np.array_equal(out[p][far], first[p][far])
    # every other break: the first search's instant, which a second pass would move
    np.testing.assert_array_equal(out[p][near], first[p][near])
    assert not np.array_equal(second[p][near], first[p][near])
    for i, b in enumerate(out):
        if i != p:
            np.testing.assert_array_equal(b, first[i])


def test_without_a_merge_the_refine_is_one_pass(refine_arguments):
    *state, spacing, breaks, options = refine_arguments
    first, dropped = trajectory._refine_pass(*state, spacing, breaks, options, None)
    assert not any(len(d) for d in dropped)  # (this rally's breaks do not merge)
    out = trajectory._refine_breaks(*state, spacing, breaks, options)
    for a, b in zip(out, first, strict=True):
        np.testing.assert_array_equal(a, b)
