"""Compiled per-detection arithmetic of :func:`pslog.fusion._prepare.prepare` (numba).

:meth:`pslog.camera.Camera.rays` builds its viewing rays with about fifteen numpy operations
on (n, 3) arrays (a stack, a row maximum, broadcast divisions), whose fixed and per-element
costs made it the largest part of ``prepare`` on a session without lens distortion. The
kernel here does, row by row, the same operations in the same order (so the same bits:
each is an IEEE operation on the same operands; no fastmath), from the normalised
coordinates ``prepare`` already has, so the lens is inverted once per detection instead of
twice. Imported lazily (numba compiles or loads on first use).
"""

from __future__ import annotations

import math

from .._jit import kernel


@kernel
def rays_from_normalized(xy, R, out):
    """Unit world directions of ideal normalised image coordinates, Camera.rays' arithmetic.

    Parameters
    ----------
    xy : (k, 2) float64, ideal (undistorted) normalised coordinates ``K⁻¹ (u, v, 1)``
        (:meth:`~pslog.camera.Camera.undistort_normalized`; NaN rows give NaN rays)
    R : (3, 3) float64, the camera's rotation world -> camera
    out : (k, 3) float64, written: ``Rᵀ (x, y, 1)`` after scaling by the largest absolute
        component (a far-off pixel's norm would overflow), then normalised to unit length
    """
    for i in range(xy.shape[0]):
        x, y, z = xy[i, 0], xy[i, 1], 1.0
        # np.max(np.abs(.)) of the row: NaN wins, as in numpy's maximum reduction
        big = abs(x)
        ay = abs(y)
        if not (big != big) and (ay != ay or ay > big):
            big = ay
        if not (big != big) and big < 1.0:
            big = 1.0
        x /= big
        y /= big
        z /= big
        # Rᵀ (x, y, z) written out as Camera.rays: x R[0] + y R[1] + z R[2], left to right
        d0 = x * R[0, 0] + y * R[1, 0] + z * R[2, 0]
        d1 = x * R[0, 1] + y * R[1, 1] + z * R[2, 1]
        d2 = x * R[0, 2] + y * R[1, 2] + z * R[2, 2]
        norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        out[i, 0] = d0 / norm
        out[i, 1] = d1 / norm
        out[i, 2] = d2 / norm
