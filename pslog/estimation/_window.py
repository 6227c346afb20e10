"""The compiled gathers of the break test's local windows (:mod:`pslog._jit`).

:class:`pslog.estimation._breaks._Base` read each window's detections through numpy fancy
indexing and ``np.where`` (each detection's ``w JᵀJ`` and ``w J`` of the scan's terms, its
linearised target) and formed ``w Jᵀ z`` by an einsum and ``w ‖z‖²``: seven passes and six
(B, W, …) temporaries per block of windows. Here they are one loop over the windows'
detections, with the same operations in the same order (einsum's sum starts from +0: a
sum of -0 products is +0; the padding's entries as numpy's masked products give them), so
the same bits (tests/test_smooth_window.py). Since session 24 also the windows' ``M X₀``
(:func:`window_products`, where it gives numpy's matmul's bits).
"""

from __future__ import annotations

import functools

import numpy as np

from .._jit import kernel


@kernel
def window_terms(index: np.ndarray, inside: np.ndarray, at: np.ndarray, wJ: np.ndarray,
                 M: np.ndarray, z: np.ndarray, w: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each window detection's ``w JᵀJ`` (B, W, 3, 3), ``w Jᵀ z`` (B, W, 3) and ``w ‖z‖²``
    (B, W), zero where it is not ``inside`` its window (padding; ``w Jᵀ z`` and ``w ‖z‖²``
    there as ``0 · z``, numpy's masked products).

    Parameters
    ----------
    index : (B, W) int64, each window slot's detection; inside : (B, W) bool
    at : (n,) int64, a detection's row in ``wJ`` and ``M`` (:func:`pslog.estimation.
        _breaks.detection_terms`); wJ : (r, 2, 3) ``w J``; M : (r, 3, 3) ``w JᵀJ``
    z : (n, 2) the linearised targets; w : (n,) the weights
    """
    B, W = index.shape
    Mo = np.empty((B, W, 3, 3))
    v = np.empty((B, W, 3))
    wz = np.empty((B, W))
    for b in range(B):
        for q in range(W):
            i = index[b, q]
            z0 = z[i, 0]
            z1 = z[i, 1]
            zz = z0 * z0 + z1 * z1
            if inside[b, q]:
                row = at[i]
                for r in range(3):
                    for c in range(3):
                        Mo[b, q, r, c] = M[row, r, c]
                for k in range(3):
                    v[b, q, k] = (0.0 + wJ[row, 0, k] * z0) + wJ[row, 1, k] * z1
                wz[b, q] = w[i] * zz
            else:
                for r in range(3):
                    for c in range(3):
                        Mo[b, q, r, c] = 0.0
                for k in range(3):
                    v[b, q, k] = (0.0 + 0.0 * z0) + 0.0 * z1
                wz[b, q] = 0.0 * zz
    return Mo, v, wz


@kernel(contract=True)
def window_products(M: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``M X`` (B, W, 3) for ``M`` (B, W, 3, 3) and ``X`` (B, W, 3): each entry's three
    terms in order, the first a product, the next two fused multiply-adds (``contract``),
    a -0 sum made +0
    — the sums numpy's ``M @ X[..., None]`` gets from OpenBLAS on x86-64 with FMA, one
    BLAS call per 3 x 3 matrix (7,680 a block of the break scan's windows: 0.26 ms, this
    pass ~0.02). Used where :func:`products_compiled` finds the same bits."""
    B, W = X.shape[0], X.shape[1]
    out = np.empty((B, W, 3))
    for b in range(B):
        for q in range(W):
            x0 = X[b, q, 0]
            x1 = X[b, q, 1]
            x2 = X[b, q, 2]
            for i in range(3):
                acc = M[b, q, i, 0] * x0
                acc = acc + M[b, q, i, 1] * x1
                acc = acc + M[b, q, i, 2] * x2
                # BLAS's sums start from +0, so a sum of -0 products is +0 there
                out[b, q, i] = acc + 0.0
    return out


@functools.cache
def products_compiled() -> bool:
    """Whether :func:`window_products` gives numpy's ``M @ X[..., None]`` bits here (another
    BLAS, CPU or numpy may sum otherwise: numpy's matmul then). Probe products of several
    batch shapes and magnitudes, checked once per process (~ms)."""
    rng = np.random.default_rng(24)
    for B, W in ((1, 1), (2, 7), (128, 30), (257, 33)):
        M = rng.normal(size=(B, W, 3, 3)) * 10.0 ** rng.integers(-6, 7, (B, W, 1, 1))
        X = rng.normal(size=(B, W, 3)) * 10.0 ** rng.integers(-3, 4, (B, W, 1))
        M[:, ::4] = 0.0  # padding: signed zeros as numpy's
        want = (M @ X[..., None])[..., 0]
        if not np.array_equal(want.view(np.int64), window_products(M, X).view(np.int64)):
            return False
    return True
