"""The trace of smooth's hat matrix as ``3m - tr(H⁻¹ P)`` from the covariance band
(``pslog.estimation._hat.prior_trace``): against the dense product's trace, and against the
detections' form it replaced (``Σ_i w_i tr(J_i Σ_X,i J_iᵀ) / σ²``) on a real fit."""

from __future__ import annotations

import numpy as np
import pytest
from test_smooth_initial import rally_problem

from pslog import SimulationOptions, apply_timing, builtin_rig
from pslog.estimation import _hat, _normal, trajectory


def _banded_spd(rng, m: int) -> tuple[np.ndarray, np.ndarray]:
    """A random symmetric positive definite matrix of 3m unknowns coupling control points
    at most 3 apart (as every spline term does: 11 super-diagonals, the entries of points 4
    apart zero): dense (n, n) and upper band (12, n)."""
    n = 3 * m
    A = np.zeros((n, n))
    for d in range(12):
        vals = rng.normal(size=n - d)
        A[np.arange(n - d), np.arange(d, n)] = vals
        A[np.arange(d, n), np.arange(n - d)] = vals
    point = np.arange(n) // 3
    A[np.abs(point[:, None] - point[None, :]) > 3] = 0.0
    A += np.eye(n) * (np.abs(A).sum(axis=1).max() + 1.0)  # diagonally dominant
    ab = np.zeros((12, n))
    for d in range(12):
        ab[11 - d, d:] = np.diagonal(A, d)
    return A, ab


@pytest.mark.parametrize("compiled", [True, False])
def test_prior_trace_is_the_trace_of_the_dense_product(compiled):
    """``tr(H⁻¹ P)`` of random banded matrices (the covariance band by the Takahashi
    recurrence; ``P`` any symmetric band, its upper-storage corner entries unused) equals
    the dense product's trace; a diagonal ``P`` gives the weighted sum of the variances."""
    rng = np.random.default_rng(5)
    m = 9
    H, h_ab = _banded_spd(rng, m)
    P, p_ab = _banded_spd(rng, m)
    for d in range(1, 12):  # the storage's corner, outside the matrix: never read
        p_ab[11 - d, :d] = 1e6
    band = _normal.covariance_band(_normal.factor(h_ab))
    fn = _hat.prior_trace if compiled else _hat.prior_trace.py_func
    want = np.trace(np.linalg.inv(H) @ P)
    assert fn(band, p_ab) == pytest.approx(want, rel=1e-12)
    diag = np.zeros_like(p_ab)
    diag[11] = np.arange(1.0, 3 * m + 1)
    assert fn(band, diag) == pytest.approx(
        float(np.diagonal(np.linalg.inv(H)) @ np.arange(1.0, 3 * m + 1)), rel=1e-12)


def test_p_eff_by_the_trace_is_the_hat_diagonal_sum_of_a_fit():
    """On a fit of a 2-second rally (paper3, 0.5 px): ``p_eff`` by the prior's trace and by
    the detections' hat diagonal agree to 1e-11 relative, and so do the degrees-of-freedom
    factors and covariance bands (the same factorisation)."""
    options = trajectory.SmoothOptions()
    problem = rally_problem(apply_timing(builtin_rig("paper3"), "typeA"), 3, 2.0,
                            SimulationOptions(noise_px=0.5, seed=4), options.prior)
    control = trajectory._initial_control(problem, 1.0)
    control, sigma, r, _, J = trajectory._Solver(problem, options).run(control, 1.0, 3)
    band_a, dof_a, p_a = trajectory._information(problem, control, sigma, r, J)
    band_b, dof_b, p_b = trajectory._information(problem, control, sigma, r, J, trace=True)
    assert 10 < p_a < 3 * problem.m
    assert p_b == pytest.approx(p_a, rel=1e-11)
    assert dof_b == pytest.approx(dof_a, rel=1e-12)
    np.testing.assert_array_equal(band_a, band_b)


def test_the_trace_under_factors_diagonal_load_counts_an_unreached_point_as_nothing():
    """A control point neither the detections nor the prior reach: factor loads the
    diagonal (H = H_data + P + λI) and the hat trace tr(H⁻¹ H_data), the detections' sum,
    counts its three directions ~0; 3m - tr(H⁻¹P) alone counts them 1 each (review, session
    19): hat_trace takes λ tr(H⁻¹) out. Hand case: diagonal H_data 2, P 1 on 5 points."""
    from pslog.estimation import _hat, _normal

    m = 6
    n = 3 * m
    h_data = np.r_[np.full(n - 3, 2.0), 0.0, 0.0, 0.0]
    prior = np.r_[np.full(n - 3, 1.0), 0.0, 0.0, 0.0]
    ab, prior_ab = np.zeros((12, n)), np.zeros((12, n))
    ab[11], prior_ab[11] = h_data + prior, prior
    loads: list[float] = []
    U = _normal.factor(ab, loads=loads)
    assert len(loads) == 1 and 0 < loads[0] < 1e-8
    band = _normal.covariance_band(U)
    data_sum = float(np.sum(np.diagonal(band[:, 0], axis1=1, axis2=2).ravel() * h_data))
    assert data_sum == pytest.approx(15 * 2 / 3, rel=1e-8)  # 2 / (2 + 1 + λ) on each of 15
    assert _hat.hat_trace(band, prior_ab, loads[0]) == pytest.approx(data_sum, rel=1e-6)
    assert _hat.hat_trace(band, prior_ab) == pytest.approx(data_sum + 3, rel=1e-6)
    # a positive definite band needs no load
    loads.clear()
    ab[11, -3:] = 1.0
    _normal.factor(ab, loads=loads)
    assert loads == []
