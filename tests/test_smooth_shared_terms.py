"""The refine's and the confirmation's break scans share one linearisation's detection
terms (``trajectory._scan_terms``, session 44: each scan formed those of its windows'
detections, ~8 times the same at 90 minutes): the same breaks and gains, bit for bit, as
scans that form their own, on a rally of three pieces (a blackout among them) and
misses."""

from __future__ import annotations

import numpy as np
import pytest
from _rally import dirty_rally
from _stages import first_arguments
from numpy.testing import assert_array_equal

from pslog import apply_timing, builtin_rig
from pslog.estimation import _breaks, trajectory
from pslog.records import NS
from pslog.simulation import SimulationOptions, simulate

SEED = 77047


@pytest.fixture(scope="module")
def refine_arguments():
    """What ``fit_trajectory`` gives ``_refine_breaks`` on a 10-second ``paper3`` rally
    with 10 % misses and no detection between 4.0 and 4.6 s (three pieces)."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion, _ = dirty_rally(SEED)
    detections, _ = simulate(rig, motion, 10.0, SimulationOptions(
        noise_px=0.4, seed=SEED, miss_rate=0.1))
    obs = detections.best()
    t = (obs.time_ns - obs.time_ns[0]) / NS
    return first_arguments("_refine_breaks", obs.select((t < 4.0) | (t > 4.6)), rig)


def test_shared_terms_are_each_scans_own(refine_arguments):
    args = refine_arguments
    problem, control, sigma, r, w, J, spacing, breaks, options = args
    assert len(problem.rows_of_piece) >= 2 and sum(len(b) for b in breaks) >= 4
    terms = trajectory._scan_terms(J, w, sigma)
    # a detection's terms are the same whichever detections are formed with it
    at, wJ, M = _breaks.detection_terms(J, w / sigma**2, np.array([5, 400]),
                                        np.array([90, 560]))
    held = np.r_[5:90, 400:560]
    assert_array_equal(wJ[at[held]], terms[1][held])
    assert_array_equal(M[at[held]], terms[2][held])
    own = trajectory._refine_breaks(*args)
    shared = trajectory._refine_breaks(*args, terms)
    for a, b in zip(own, shared, strict=True):
        assert_array_equal(a, b)
    confirm = (problem, control, sigma, r, w, J, spacing, own, options)
    for a, b in zip(trajectory._confirmed_breaks(*confirm),
                    trajectory._confirmed_breaks(*confirm, terms), strict=True):
        assert_array_equal(a, b)
    # and the gains themselves, a later piece's breaks (its rows a slice that does not
    # start at the session's first)
    t_obs = problem.t[problem.rows]
    jobs = [job for job in trajectory._pieces_with_breaks(problem, t_obs, own)
            if job[0] > 0]
    assert jobs and jobs[0][1][0] > 0
    p, here, known, _, _, limits = jobs[0]
    target = trajectory._linear_target(J, problem.positions(control), r)
    job = [(p, here, known, np.stack([known, known], axis=1), limits)]
    scan = (job, t_obs, J, target, w / sigma**2, spacing, options)
    (_, want), = trajectory._scan_pieces(*scan, gains=True)
    (_, got), = trajectory._scan_pieces(*scan, gains=True, terms=terms)
    assert np.all(np.isfinite(want))
    assert_array_equal(got, want)
