"""`smooth`'s Gauss–Newton normal equations in one compiled pass
(``_gauss_newton.linearised_normal_onto``): bit for bit the three passes it replaced —
``linear_target``, ``data_terms`` and ``points_normal_onto`` — on a real fit's
linearisation (a simulated rally's detections, their Jacobians at the first trajectory),
compiled and as its Python original, with the points in time order (the ring of control
points) and shuffled (every control point's sums kept)."""

from __future__ import annotations

import numpy as np
import pytest
from _rigs import ring_rig
from numpy.testing import assert_array_equal

from pslog.estimation import SmoothOptions, _kernels
from pslog.estimation import trajectory as T
from pslog.estimation._gauss_newton import linearised_normal_onto
from pslog.motion import get_motion
from pslog.simulation import SimulationOptions, simulate


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _linearised_case():
    """A 3-s rally's fit problem on three cameras, linearised at its first trajectory: the
    problem, positions X, residuals r, Jacobians J and Cauchy weights over σ²."""
    rig = ring_rig(3, "r3")
    detections, _ = simulate(rig, get_motion("rally"), 3.0,
                             SimulationOptions(noise_px=0.5, seed=12))
    obs = detections.best()
    options = SmoothOptions()
    usable = np.all(np.isfinite(obs.uv), axis=1)
    pieces = T.split_pieces(obs, usable, options.max_gap_s)
    t = (obs.time_ns - obs.time_ns[0]) / 1e9
    knots = [T._knots_with_breaks(t[p[0]], t[p[-1]] + 1e-9, 0.033, np.zeros(0))
             for p in pieces]
    problem = T._Problem(obs, rig, pieces, knots, options.prior)
    control = T._initial_control(problem, 1.0)
    X = problem.positions(control)
    r, J = problem.project(X)
    sigma = 1.4826 * T._abs_median(r)
    w = 1 / (1 + T._scaled_norms(r, sigma) / T._CAUCHY**2) / sigma**2
    return problem, X, r, J, w


def _three_passes(first, N, J, X, r, w, m, base_ab, base_rhs):
    target = _kernels.linear_target(J, X, r)
    upper, v = _kernels.data_terms(J, target, w)
    return _kernels.points_normal_onto(first, N, upper, v, m, base_ab, base_rhs)


@pytest.mark.parametrize("order", ["time", "shuffled"])
def test_one_pass_is_the_three_passes_bit_for_bit(order):
    """Every entry of the band and of the rhs (the corner no pair of control points reaches
    included) is the three passes' bit for bit, compiled and as the Python original, and
    the prior's band is left as it was. Fails if a target's, a quadratic form's or a sum's
    operations are reordered (run once: the target's products summed in index order,
    ``(J0 X0 + J1 X1) + J2 X2``, differ in the last bits)."""
    problem, X, r, J, w = _linearised_case()
    first, N = problem.points.first, problem.points.N
    assert len(first) > 200 and np.all(np.diff(first) >= 0)
    if order == "shuffled":
        perm = np.random.default_rng(3).permutation(len(first))
        first, N, X, r, J, w = (np.ascontiguousarray(a[perm]) for a in (first, N, X, r, J, w))
    base_ab, base_rhs = problem.prior_ab.copy(), problem.prior_rhs.copy()
    want_ab, want_rhs = _three_passes(first, N, J, X, r, w, problem.m, base_ab, base_rhs)
    for fn in (linearised_normal_onto, linearised_normal_onto.py_func):
        ab, rhs = fn(first, N, J, X, r, w, problem.m, base_ab, base_rhs)
        assert_array_equal(_bits(ab), _bits(want_ab))
        assert_array_equal(_bits(rhs), _bits(want_rhs))
    assert_array_equal(base_ab, problem.prior_ab)
    assert_array_equal(base_rhs, problem.prior_rhs)


def test_problem_method_is_the_normal_of_the_linear_target():
    """``_Problem.linearised_normal`` is ``_Problem.normal`` of ``_linear_target``'s targets
    (the form the Gauss–Newton steps used), bit for bit; with no detection, the prior's
    normal equations."""
    problem, X, r, J, w = _linearised_case()
    ab, rhs = problem.linearised_normal(J, X, r, w)
    want_ab, want_rhs = problem.normal(J, T._linear_target(J, X, r), w)
    assert_array_equal(_bits(ab), _bits(want_ab))
    assert_array_equal(_bits(rhs), _bits(want_rhs))
    first, N = problem.points.first[:0], problem.points.N[:0]
    none_ab, none_rhs = linearised_normal_onto(first, N, J[:0], X[:0], r[:0], w[:0],
                                               problem.m, problem.prior_ab, problem.prior_rhs)
    assert_array_equal(none_ab, problem.prior_ab)
    assert_array_equal(none_rhs, problem.prior_rhs)
