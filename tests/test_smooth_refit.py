"""``smooth``'s refit after a knot change is the next Gauss–Newton step, taken on the new
knots (``trajectory._refit_linearised``, session 23)."""

from __future__ import annotations

import numpy as np
from test_estimation import _rig

from pslog.estimation import MotionPrior, SmoothOptions
from pslog.estimation import trajectory as T
from pslog.motion import G, get_motion
from pslog.records import NS, Observations
from pslog.simulation import SimulationOptions, simulate

#: the throw's floor bounce (test_estimation: the root of z0 + vz s - g s²/2 = radius)
BOUNCE_S = (3.0 + np.sqrt(9.0 + 2 * G * (1.0 - 0.0215))) / G
SPACING = 0.03


def _throw(noise_px: float = 0.3, outliers: int = 0):
    rig = _rig(3)
    det, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(noise_px=noise_px,
                                                                         seed=5))
    obs = det.best()
    if outliers:
        uv = obs.uv.copy()
        bad = np.random.default_rng(3).choice(len(obs), outliers, replace=False)
        uv[bad] += 25.0
        obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    return obs, rig


def _fitted(obs, rig, breaks: np.ndarray, iterations: int = 4):
    """The problem on uniform knots with ``breaks`` (s since the first detection), fitted
    under the real prior: problem, control, σ, r, w, J."""
    t = (obs.time_ns - obs.time_ns[0]) / NS
    knots = [T._knots_with_breaks(t[0], t[-1] + 1e-9, SPACING, breaks)]
    problem = T._Problem(obs, rig, [np.arange(len(obs))], knots, MotionPrior())
    control = T._initial_control(problem, 1.0)
    return (problem, *T._Solver(problem, SmoothOptions()).run(control, 1.0, iterations))


def _robust_cost(problem, control, sigma):
    X = problem.positions(control)
    r, _ = problem.project(X)
    return T._Solver(problem, SmoothOptions()).cost(control, r, sigma)


def test_the_linearised_refit_is_a_fixed_point_of_a_converged_fit():
    """On the knots it was fitted on, a converged fit's refit gives it back (the step of a
    converged Gauss–Newton iteration is nil), outliers and their weights included: it solves
    the weighted linearised problem, not the positions (which the prior would pull) nor the
    unweighted one (which the outliers would)."""
    obs, rig = _throw(outliers=8)
    t0 = obs.time_ns[0] / NS
    problem, control, sigma, r, w, J = _fitted(obs, rig, np.array([BOUNCE_S - t0]), 12)
    assert np.sum(w < 0.05) >= 8  # the outliers carry (almost) no weight
    X = problem.positions(control)
    again = T._refit_linearised(problem, X, r, J, w, sigma)
    assert np.max(np.abs(again - control)) < 1e-6
    # the positions as measurements (the old refit) move it: the prior pulls them
    assert np.max(np.abs(T._refit_control(problem, X) - control)) > 1e-5
    # and without the weights the outliers pull it by far more
    flat = T._refit_linearised(problem, X, r, J, np.ones_like(w), sigma)
    assert np.max(np.abs(flat - control)) > 1e-4


def test_the_linearised_refit_fits_the_detections_after_a_break_is_inserted():
    """A fit without the bounce, then the bounce inserted: the refit is the Gauss–Newton step
    on the new knots, so it follows the detections through the bounce (a lower robust cost
    than the refit to the old, rounded positions, which cannot jump) and is within a small
    step of the converged fit with the break."""
    obs, rig = _throw()
    t0 = obs.time_ns[0] / NS
    problem, control, sigma, r, w, J = _fitted(obs, rig, np.zeros(0))
    X = problem.positions(control)
    t = (obs.time_ns - obs.time_ns[0]) / NS
    problem.set_knots([T._knots_with_breaks(t[0], t[-1] + 1e-9, SPACING,
                                            np.array([BOUNCE_S - t0]))], MotionPrior())
    step = T._refit_linearised(problem, X, r, J, w, sigma)
    positions = T._refit_control(problem, X)
    assert _robust_cost(problem, step, sigma) < 0.5 * _robust_cost(problem, positions, sigma)
    _, converged, *_ = _fitted(obs, rig, np.array([BOUNCE_S - t0]), 12)
    moved = np.linalg.norm(problem.positions(step) - problem.positions(converged), axis=1)
    before = np.linalg.norm(problem.positions(positions) - problem.positions(converged), axis=1)
    assert moved.max() < 0.2 * before.max()

