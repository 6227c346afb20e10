"""The trace of ``smooth``'s hat matrix from the covariance band (:mod:`pslog._jit`).

The fit's effective number of parameters (the trace of its hat matrix, Wahba 1983) was
``p_eff = Σ_i w_i tr(J_i Σ_X,i J_iᵀ) / σ²``: every detection's marginal covariance
``Σ_X,i`` (n, 3, 3) from the covariance band, then a pass over the detections
(:func:`pslog.estimation._kernels.hat_diagonal`). The same number is ``tr(H⁻¹ H_data)``
with ``H = H_data + P`` the information matrix (the data's normal equations plus the
prior's), that is ``3m - tr(H⁻¹ P)``: the band of ``H⁻¹`` (which the Takahashi recurrence
gives) against the prior's band ``P``, one pass over the ``3m`` unknowns instead of two over
the detections and a (n, 3, 3) array. The sums differ in order only: ~1e-14 relative.
Where the factor carries a diagonal load (:func:`pslog.estimation._normal.factor`: a
direction neither the detections nor the prior reach), ``H = H_data + P + λ I`` and the
trace is ``3m - tr(H⁻¹ P) - λ tr(H⁻¹)`` (:func:`hat_trace`): an unreached direction
counts ~0 parameters, as in the detections' sum, not 1.
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel


@kernel
def prior_trace(band: np.ndarray, prior_ab: np.ndarray) -> float:
    """``tr(Σ P)`` of the covariance band ``band`` (m, 4, 3, 3) (``band[i, k] = Σ_{i, i+k}``
    by control-point blocks, :func:`pslog.estimation._normal.covariance_band`) and a
    symmetric band ``prior_ab`` (kd + 1, 3m) in upper storage (``ab[kd + r - c, c] =
    P[r, c]``, kd <= 11) that couples control points at most 3 apart, as every spline term
    does (the band's entries of points 4 apart, which the covariance band does not hold,
    are zero): ``Σ_r Σ_rr P_rr + 2 Σ_{r < c} Σ_rc P_rc``, summed over the blocks in
    order."""
    m = band.shape[0]
    n = 3 * m
    kd = prior_ab.shape[0] - 1
    acc = 0.0
    for i in range(m):
        for k in range(4):
            for a in range(3):
                r = 3 * i + a
                for b in range(3):
                    c = 3 * (i + k) + b
                    if c < r or c >= n or c - r > kd:
                        continue
                    v = band[i, k, a, b] * prior_ab[kd - (c - r), c]
                    acc += v if c == r else 2.0 * v
    return acc


def hat_trace(band: np.ndarray, prior_ab: np.ndarray, load: float = 0.0) -> float:
    """``tr(H⁻¹ H_data)`` of ``H = H_data + P + load I`` from the covariance band ``band``
    (m, 4, 3, 3) of ``H⁻¹`` and the prior's band ``prior_ab`` (:func:`prior_trace`):
    ``3m - tr(H⁻¹ P) - load tr(H⁻¹)``."""
    p_eff = 3 * band.shape[0] - prior_trace(band, prior_ab)
    if load:
        p_eff -= load * float(np.trace(band[:, 0], axis1=1, axis2=2).sum())
    return float(p_eff)
