"""The compiled gathers of the break test's local windows (:mod:`pslog._jit`).

:class:`pslog.estimation._breaks._Base` read each window's detections through numpy fancy
indexing and ``np.where`` (each detection's ``w JᵀJ`` and ``w J`` of the scan's terms, its
linearised target) and formed ``w Jᵀ z`` by an einsum and ``w ‖z‖²``: seven passes and six
(B, W, …) temporaries per block of windows. Here they are one loop over the windows'
detections, with the same operations in the same order (einsum's sum starts from +0: a
sum of -0 products is +0; the padding's entries as numpy's masked products give them), so
the same bits (tests/test_smooth_window.py).
"""

from __future__ import annotations

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
