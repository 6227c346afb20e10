"""The compiled per-point kernels of the trajectory estimator (:mod:`pslog._jit`).

Each kernel is the loop its numpy caller ran over arrays of points, written once per point
with the same floating-point operations in the same order, so it returns the same bits
(no fastmath: no reassociation, no fused multiply-add). Imported by the estimator's functions
when they run, never at import time (``pslog --help`` does not load numba).
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel

_P = 3  # cubic


@kernel
def basis_in_span(knots: np.ndarray, j: np.ndarray, t: np.ndarray, n_derivatives: int
                  ) -> np.ndarray:
    """Values and derivatives (n, n_derivatives + 1, 4) of the four non-zero cubic B-splines
    at points ``t`` (n,) in spans ``j`` (n,) of ``knots``: Piegl & Tiller, *The NURBS Book*
    (2nd ed. 1997), algorithm A2.3 (``DersBasisFuns``), one point at a time
    (:func:`pslog.estimation.bspline._basis_in_span`)."""
    p = _P
    n = len(t)
    out = np.zeros((n, n_derivatives + 1, p + 1))
    ndu = np.zeros((p + 1, p + 1))
    left = np.zeros(p + 1)
    right = np.zeros(p + 1)
    a = np.zeros((2, p + 1))
    for i in range(n):
        ti = t[i]
        ji = j[i]
        ndu[:] = 0.0
        ndu[0, 0] = 1.0
        for r in range(1, p + 1):
            left[r] = ti - knots[ji + 1 - r]
            right[r] = knots[ji + r] - ti
            saved = 0.0
            for s in range(r):
                ndu[r, s] = right[s + 1] + left[r - s]  # a knot difference, > 0
                temp = ndu[s, r - 1] / ndu[r, s]
                ndu[s, r] = saved + right[s + 1] * temp
                saved = left[r - s] * temp
            ndu[r, r] = saved
        for r in range(p + 1):
            out[i, 0, r] = ndu[r, p]
        for r in range(p + 1):
            s1, s2 = 0, 1
            a[:] = 0.0
            a[0, 0] = 1.0
            for k in range(1, n_derivatives + 1):
                d = 0.0
                rk, pk = r - k, p - k
                if r >= k:
                    a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                    d = a[s2, 0] * ndu[rk, pk]
                j1 = 1 if rk >= -1 else -rk
                j2 = k - 1 if r - 1 <= pk else p - r
                for jj in range(j1, j2 + 1):
                    a[s2, jj] = (a[s1, jj] - a[s1, jj - 1]) / ndu[pk + 1, rk + jj]
                    d = d + a[s2, jj] * ndu[rk + jj, pk]
                if r <= pk:
                    a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                    d = d + a[s2, k] * ndu[r, pk]
                out[i, k, r] = d
                s1, s2 = s2, s1
        factor = 1.0
        for k in range(1, n_derivatives + 1):
            factor *= p - k + 1
            for r in range(p + 1):
                out[i, k, r] *= factor
    return out


@kernel
def window_normal(P: np.ndarray, prior_rhs: np.ndarray, first: np.ndarray, N: np.ndarray,
                  M: np.ndarray, v: np.ndarray, inside: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Dense normal equations of a batch of local windows (:class:`pslog.estimation._breaks.
    _Base`): ``H_b = P + Σ_w (N_w N_wᵀ) ⊗ M_w`` and ``rhs_b = prior_rhs + Σ_w N_w ⊗ v_w``, each
    detection's 12 x 12 block added at control points ``first .. first + 3`` (the sums the
    dense products of the basis matrix formed, one detection at a time, the prior first).

    Parameters
    ----------
    P : (n, n) float64, the prior's normal matrix (n = 3m); prior_rhs : (n,)
    first : (B, W) int64; N : (B, W, 4) float64, each detection's basis
    M : (B, W, 3, 3) float64, ``w JᵀJ``; v : (B, W, 3), ``w Jᵀ z``
    inside : (B, W) bool, the detections in each window (the rest add nothing)

    Returns
    -------
    H : (B, n, n); rhs : (B, n)
    """
    B, W = first.shape
    n = P.shape[0]
    H = np.empty((B, n, n))
    rhs = np.empty((B, n))
    for b in range(B):
        Hb = H[b]
        Hb[:, :] = P
        rb = rhs[b]
        rb[:] = 0.0
        for w in range(W):
            if not inside[b, w]:
                continue
            f3 = 3 * first[b, w]
            for a in range(4):
                na = N[b, w, a]
                for i in range(3):
                    rb[f3 + 3 * a + i] += na * v[b, w, i]
                for c in range(4):
                    nc = N[b, w, c]
                    for i in range(3):
                        for k in range(3):
                            # the upper triangle of M (w JᵀJ is symmetric only up to rounding)
                            mik = M[b, w, i, k] if i <= k else M[b, w, k, i]
                            Hb[f3 + 3 * a + i, f3 + 3 * c + k] += na * (mik * nc)
        for r in range(n):
            rb[r] += prior_rhs[r]
    return H, rhs
