"""The compiled passes of ``smooth``'s first (DLT) trajectory (:mod:`pslog._jit`).

:func:`pslog.estimation.trajectory._initial_control` solves the linear form of the
projection twice; its numpy form gathered every detection's camera rotation, translation and
focal lengths ((n, 3, 3), (n, 3), (n, 2)), formed the linear rows ``A`` (n, 2, 3) and
``a0`` (n, 2), then per pass the scaled Jacobian ``J`` (n, 2, 3) and target (n, 2), and after
the solve the depths and residuals through two einsums: ~15 passes over a session's
detections and ~100 MB of temporaries at 90 minutes. Here each pass is one loop over the
detections, reading its camera's parameters by index, with the same floating-point
operations in the same order (einsum's three products added ``(p0 + p2) + p1``, as its
sum-of-products loop adds them), so the same bits (tests/test_smooth_initial.py compares
them with the numpy form, :func:`pslog.estimation.trajectory._initial_control_numpy`).
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel


@kernel(inline=True)
def _clamp_depth(d: float) -> float:
    """``np.maximum(d, 1e-3)`` (NaN stays NaN)."""
    return d if (d >= 1e-3 or d != d) else 1e-3


@kernel
def dlt_terms(camera: np.ndarray, R: np.ndarray, t: np.ndarray, f: np.ndarray,
              xy: np.ndarray, depth: np.ndarray, w: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Each detection's quadratic form ``w ‖J X - z‖²`` of the DLT's linear rows, as
    :func:`pslog.estimation._kernels.data_terms` gives it for ``J = A · f / depth``,
    ``z = -(a0 · f / depth)`` with ``A_a = R_a - xy_a R_2`` and ``a0_a = t_a - xy_a t_2``
    (rows ``a`` = 0, 1 of the camera's rotation and translation; the depth clamped at 1 mm).

    Parameters
    ----------
    camera : (n,) int64; R : (C, 3, 3); t : (C, 3); f : (C, 2) ``fx, fy``
    xy : (n, 2) undistorted normalised coordinates; depth : (n,) metres; w : (n,) weights

    Returns
    -------
    upper : (n, 6) the upper triangle of ``w JᵀJ`` (00, 01, 02, 11, 12, 22); v : (n, 3)
    ``Jᵀ (w z)``
    """
    n = len(camera)
    upper = np.empty((n, 6))
    v = np.empty((n, 3))
    J = np.empty((2, 3))
    z = np.empty(2)
    for i in range(n):
        c = camera[i]
        d = _clamp_depth(depth[i])
        for a in range(2):
            s = f[c, a] / d
            x = xy[i, a]
            for j in range(3):
                J[a, j] = (R[c, a, j] - x * R[c, 2, j]) * s
            z[a] = -((t[c, a] - x * t[c, 2]) * s)
        wi = w[i]
        q = 0
        for a in range(3):
            for b in range(a, 3):
                upper[i, q] = wi * (J[0, a] * J[0, b] + J[1, a] * J[1, b])
                q += 1
        v0 = wi * z[0]
        v1 = wi * z[1]
        for k in range(3):
            v[i, k] = J[0, k] * v0 + J[1, k] * v1
    return upper, v


@kernel
def dlt_residuals(camera: np.ndarray, R: np.ndarray, t: np.ndarray, f: np.ndarray,
                  xy: np.ndarray, depth: np.ndarray, X: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The residuals ``J X - z`` (n, 2) of the linear rows of :func:`dlt_terms` (made at
    ``depth``) at positions ``X`` (n, 3), and the positions' depths in their cameras
    ``R_2 · X + t_2`` (n,), clamped at 1 mm."""
    n = len(camera)
    r = np.empty((n, 2))
    out = np.empty(n)
    for i in range(n):
        c = camera[i]
        d = _clamp_depth(depth[i])
        X0, X1, X2 = X[i, 0], X[i, 1], X[i, 2]
        for a in range(2):
            s = f[c, a] / d
            x = xy[i, a]
            p0 = ((R[c, a, 0] - x * R[c, 2, 0]) * s) * X0
            p1 = ((R[c, a, 1] - x * R[c, 2, 1]) * s) * X1
            p2 = ((R[c, a, 2] - x * R[c, 2, 2]) * s) * X2
            r[i, a] = ((p0 + p2) + p1) + (t[c, a] - x * t[c, 2]) * s
        out[i] = _clamp_depth(((R[c, 2, 0] * X0 + R[c, 2, 2] * X2) + R[c, 2, 1] * X1)
                              + t[c, 2])
    return r, out
