"""The deletion test's per-detection terms in one compiled pass (:mod:`pslog._jit`).

:func:`pslog.estimation.trajectory.deletion_gain` formed ``J Σ`` (n, 2, 3) and ``J Σ Jᵀ``
(n, 2, 2) by two einsums and then its 2 x 2 inverse's quadratic form by eight elementwise
passes: ~0.05 CPU s a call at 90 minutes (486,000 detections), two calls a fit. Here each
detection's terms are formed where they are used, with the sums einsum makes (session 44):
``J Σ``'s three terms ``i`` in order, each from +0 (``((0 + p₀) + p₁) + p₂``), and
``(J Σ) Jᵀ``'s as numpy's einsum sums a contiguous axis of three on two SIMD lanes
(``j`` = 0 and 2 on one, ``j`` = 1 on the other, then the lanes added, the sum from +0),
then the same elementwise operations in the same order: the same bits, where
:func:`deletion_compiled`'s probe finds them (another numpy or CPU may sum otherwise:
numpy.s einsums then; tests/test_smooth_deletion_pass.py).
"""

from __future__ import annotations

import functools

import numpy as np

from .._jit import kernel


@kernel
def deletion_terms(J: np.ndarray, cov: np.ndarray, r: np.ndarray, w: np.ndarray,
                   scale_sigma2: float, sigma2: float) -> np.ndarray:
    """``T_i`` (n,) of :func:`pslog.estimation.trajectory.deletion_gain` for Jacobians ``J``
    (n, 2, 3), covariances ``cov`` (n, 3, 3), residuals ``r`` (n, 2) and weights ``w`` (n,),
    ``scale_sigma2 = scale · σ²`` and ``sigma2 = σ²`` as Python computes them."""
    n = J.shape[0]
    out = np.empty(n)
    JS = np.empty((2, 3))
    for q in range(n):
        for a in range(2):
            for j in range(3):
                acc = 0.0
                for i in range(3):
                    acc += J[q, a, i] * cov[q, i, j]
                JS[a, j] = acc
        f = w[q] / scale_sigma2
        P00 = (0.0 + ((0.0 + JS[0, 0] * J[q, 0, 0]) + JS[0, 2] * J[q, 0, 2])
               + (0.0 + JS[0, 1] * J[q, 0, 1])) * f
        P01 = (0.0 + ((0.0 + JS[0, 0] * J[q, 1, 0]) + JS[0, 2] * J[q, 1, 2])
               + (0.0 + JS[0, 1] * J[q, 1, 1])) * f
        P10 = (0.0 + ((0.0 + JS[1, 0] * J[q, 0, 0]) + JS[1, 2] * J[q, 0, 2])
               + (0.0 + JS[1, 1] * J[q, 0, 1])) * f
        P11 = (0.0 + ((0.0 + JS[1, 0] * J[q, 1, 0]) + JS[1, 2] * J[q, 1, 2])
               + (0.0 + JS[1, 1] * J[q, 1, 1])) * f
        a_ = 1.0 - P00
        d_ = 1.0 - P11
        b_ = -0.5 * (P01 + P10)
        x = r[q, 0]
        y = r[q, 1]
        quad = (d_ * x * x - 2 * b_ * x * y + a_ * y * y) / (a_ * d_ - b_ * b_)
        out[q] = w[q] * quad / sigma2
    return out


def deletion_numpy(J: np.ndarray, cov_X: np.ndarray, r: np.ndarray, w: np.ndarray,
                   sigma: float, scale: float = 1.0) -> np.ndarray:
    """:func:`deletion_terms` as numpy's einsums and elementwise passes (the form it
    repeats; :func:`pslog.estimation.trajectory.deletion_gain` before session 44)."""
    JS = np.einsum("nai,nij->naj", J, cov_X)
    P = np.einsum("naj,nbj->nab", JS, J) * (w / (scale * sigma**2))[:, None, None]
    a, d = 1.0 - P[:, 0, 0], 1.0 - P[:, 1, 1]
    b = -0.5 * (P[:, 0, 1] + P[:, 1, 0])  # (symmetric up to rounding)
    x, y = r[:, 0], r[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        quad = (d * x * x - 2 * b * x * y + a * y * y) / (a * d - b * b)
    return w * quad / sigma**2


def usable(J: np.ndarray, cov_X: np.ndarray, r: np.ndarray, w: np.ndarray) -> bool:
    """Whether the arguments have the layout :func:`deletion_terms` was checked on (C-
    contiguous float64 (n, 2, 3), (n, 3, 3), (n, 2), (n,)) and the probe passed."""
    n = len(J)
    return (all(isinstance(a, np.ndarray) and a.dtype == np.float64
                and a.flags.c_contiguous for a in (J, cov_X, r, w))
            and J.shape == (n, 2, 3) and cov_X.shape == (n, 3, 3) and r.shape == (n, 2)
            and w.shape == (n,) and deletion_compiled())


@functools.cache
def deletion_compiled() -> bool:
    """Whether :func:`deletion_terms` gives :func:`deletion_numpy`'s bits here: terms of
    several sizes and magnitudes, with signed zeros, infinities and NaNs among them,
    checked once per process (~ms)."""
    rng = np.random.default_rng(77044)
    for n in (1, 2, 3, 8, 31, 1000):
        J = rng.normal(size=(n, 2, 3)) * 10.0 ** rng.integers(-4, 5, (n, 1, 1))
        C = rng.normal(size=(n, 3, 3))
        C = np.ascontiguousarray(C @ np.swapaxes(C, 1, 2) * 10.0 ** rng.integers(
            -8, 0, (n, 1, 1)))
        r = rng.normal(size=(n, 2)) * 10.0 ** rng.integers(-2, 3, (n, 1))
        w = rng.uniform(0.0, 1.0, n)
        if n >= 8:
            J[::5] = -0.0
            J[1::7, 0] = 0.0
            C[2::6] = -0.0
            r[3::5] = 0.0
            w[4::9] = 0.0
            C[5::8, 0, 0] = np.inf
            r[6::8, 1] = np.nan
        for sigma, scale in ((0.7, 1.0), (0.31, 2.3)):
            with np.errstate(all="ignore"):
                want = deletion_numpy(J, C, r, w, sigma, scale)
            got = deletion_terms(J, C, r, w, scale * sigma**2, sigma**2)
            if not np.array_equal(want.view(np.int64), got.view(np.int64)):
                return False
    return True
