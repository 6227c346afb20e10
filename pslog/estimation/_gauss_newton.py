"""The Gauss–Newton step's normal equations of ``smooth`` in one compiled pass
(:mod:`pslog._jit`).

A step's normal equations were three passes over every detection: the linearised targets
``z = J X - r`` (:func:`pslog.estimation._kernels.linear_target`, (n, 2)), each detection's
quadratic form ``w JᵀJ``, ``Jᵀ (w z)`` (:func:`pslog.estimation._kernels.data_terms`, (n, 6)
and (n, 3)) and their sums per control point onto the prior's band
(:func:`pslog.estimation._kernels.points_normal_onto`): at 90 minutes 40 MB of temporaries
written and read back at each of the fit's ~11 steps. :func:`linearised_normal_onto` forms
each detection's target and quadratic form where it adds them, with the same operations in
the same order as the three passes (the same bits: tests/test_smooth_gauss_newton.py), and
keeps no temporary beyond the ring of control-point sums.
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel
from ._kernels import _add_point, _fold_row, _ring


@kernel
def linearised_normal_onto(first: np.ndarray, N: np.ndarray, J: np.ndarray, X: np.ndarray,
                           r: np.ndarray, w: np.ndarray, m: int, base_ab: np.ndarray,
                           base_rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``points_normal_onto(first, N, *data_terms(J, linear_target(J, X, r), w), m,
    base_ab, base_rhs)`` in one pass: the normal equations (12, 3m) and rhs (3m,) of the
    prior's (``base_ab``, ``base_rhs``, left as they are) plus ``Σ_i w_i ‖J_i p(t_i) - z_i‖²``,
    ``z_i = J_i X_i - r_i`` the measurement linearised at the positions ``X`` (n, 3) with
    residuals ``r`` (n, 2) and Jacobians ``J`` (n, 2, 3); ``w`` (n,) the weights (over σ²).

    Each entry is what the three kernels give (the same operations, in their order): the
    target ``((J_a0 X_0 + J_a2 X_2) + J_a1 X_1) - r_a`` (numpy einsum's order), the upper
    triangle ``w (J_0a J_0b + J_1a J_1b)`` and ``v_d = J_0d (w z_0) + J_1d (w z_1)``, summed
    per control-point pair over the detections in order (a ring of 8 control points where
    ``first`` is non-decreasing, every control point's sums otherwise) and written once as
    the base's plus those sums."""
    ab = np.empty_like(base_ab)
    rhs = np.empty_like(base_rhs)
    # the band's corner (rows above the first columns: no pair of control points there)
    for i in range(ab.shape[0]):
        for j in range(min(12, ab.shape[1])):
            ab[i, j] = base_ab[i, j]
    n = len(first)
    if n == 0:
        ab[:, :] = base_ab
        rhs[:] = base_rhs
        return ab, rhs
    ordered, mask, blocks, rv = _ring(first, m)
    done = 0  # control points below this one are in ab and rhs
    for i in range(n):
        f = first[i]
        if ordered:
            while done < f:
                _fold_row(blocks, rv, done, done & mask, m, base_ab, base_rhs, ab, rhs)
                done += 1
        # linear_target's operations
        j00, j01, j02 = J[i, 0, 0], J[i, 0, 1], J[i, 0, 2]
        j10, j11, j12 = J[i, 1, 0], J[i, 1, 1], J[i, 1, 2]
        x0, x1, x2 = X[i, 0], X[i, 1], X[i, 2]
        z0 = ((j00 * x0 + j02 * x2) + j01 * x1) - r[i, 0]
        z1 = ((j10 * x0 + j12 * x2) + j11 * x1) - r[i, 1]
        # data_terms' operations
        wi = w[i]
        u0 = wi * (j00 * j00 + j10 * j10)
        u1 = wi * (j00 * j01 + j10 * j11)
        u2 = wi * (j00 * j02 + j10 * j12)
        u3 = wi * (j01 * j01 + j11 * j11)
        u4 = wi * (j01 * j02 + j11 * j12)
        u5 = wi * (j02 * j02 + j12 * j12)
        wz0 = wi * z0
        wz1 = wi * z1
        v0 = j00 * wz0 + j10 * wz1
        v1 = j01 * wz0 + j11 * wz1
        v2 = j02 * wz0 + j12 * wz1
        # points_normal_onto's sums
        _add_point(blocks, rv, f, mask, N[i, 0], N[i, 1], N[i, 2], N[i, 3], u0, u1, u2, u3,
                   u4, u5, v0, v1, v2)
    while done < m:
        _fold_row(blocks, rv, done, done & mask, m, base_ab, base_rhs, ab, rhs)
        done += 1
    return ab, rhs
