"""A camera's projection to distorted pixels and its analytic Jacobian.

The model is :class:`pslog.camera.Camera`'s (OpenCV pinhole + plumb_bob):

    X_c = R X + t,   x = X_c / Z_c,   y = Y_c / Z_c,   r² = x² + y²
    x_d = x·ρ + 2 p1 x y + p2 (r² + 2x²),   y_d = y·ρ + p1 (r² + 2y²) + 2 p2 x y,
          ρ = 1 + k1 r² + k2 r⁴ + k3 r⁶
    u = fx x_d + s y_d + cx,   v = fy y_d + cy

and the Jacobian is the chain ``∂(u,v)/∂X = K₂ · ∂(x_d,y_d)/∂(x,y) · ∂(x,y)/∂X_c · R``.
"""

from __future__ import annotations

import numpy as np

from ..camera import Camera


def project_with_jacobian(camera: Camera, points_world: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Distorted pixels of world points and their derivative with respect to the points.

    Parameters
    ----------
    camera : Camera
    points_world : (n, 3) float64, metres

    Returns
    -------
    uv : (n, 2) float64, pixels, equal to ``camera.project(points_world)[0]``; NaN for a
        point at or behind the camera plane
    jacobian : (n, 2, 3) float64, ``∂(u, v) / ∂(x, y, z)_world``, pixels per metre
    """
    points_cam = points_world @ camera.R.T + camera.t
    z = points_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_z = np.where(z > 1e-12, 1.0 / z, np.nan)
    x, y = points_cam[:, 0] * inv_z, points_cam[:, 1] * inv_z
    k1, k2, p1, p2, k3 = camera.dist
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    d_radial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # dρ / d(r²)
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    K = camera.K
    uv = np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)

    # ∂(x_d, y_d) / ∂(x, y): the distortion's Jacobian (as in Camera.undistort_normalized)
    d00 = radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x
    d01 = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
    d11 = radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x
    # ∂(x, y) / ∂X: the perspective division's rows times R, (R₀ - x R₂) / Z and
    # (R₁ - y R₂) / Z
    R = camera.R
    px = inv_z[:, None] * (R[0] - x[:, None] * R[2])
    py = inv_z[:, None] * (R[1] - y[:, None] * R[2])
    # K₂ · ∂(x_d, y_d)/∂(x, y), then times the rows above
    a00 = K[0, 0] * d00 + K[0, 1] * d01
    a01 = K[0, 0] * d01 + K[0, 1] * d11
    a10 = K[1, 1] * d01
    a11 = K[1, 1] * d11
    jacobian = np.empty((len(x), 2, 3))
    jacobian[:, 0] = a00[:, None] * px + a01[:, None] * py
    jacobian[:, 1] = a10[:, None] * px + a11[:, None] * py
    return uv, jacobian


def stack_cameras(cameras, index: np.ndarray) -> dict[str, np.ndarray]:
    """Each point's camera parameters, for :func:`project_stacked`: ``R`` (n, 3, 3), ``t``
    (n, 3), ``K`` (n, 5) as ``fx, s, cx, fy, cy``, ``dist`` (n, 5); ``index`` (n,) the camera
    of each point."""
    R = np.array([c.R for c in cameras])[index]
    return {"R": R, "R0": R[:, 0], "R1": R[:, 1], "R2": R[:, 2],
            "t": np.array([c.t for c in cameras])[index],
            "K": np.array([[c.K[0, 0], c.K[0, 1], c.K[0, 2], c.K[1, 1], c.K[1, 2]]
                           for c in cameras])[index].T.copy(),
            "dist": np.array([c.dist for c in cameras])[index].T.copy()}


def project_stacked(params: dict[str, np.ndarray], points_world: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_with_jacobian` of points seen by different cameras in one pass
    (``params`` from :func:`stack_cameras`); the same formulas, per point."""
    points_cam = np.einsum("nij,nj->ni", params["R"], points_world) + params["t"]
    z = points_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_z = np.where(z > 1e-12, 1.0 / z, np.nan)
    x, y = points_cam[:, 0] * inv_z, points_cam[:, 1] * inv_z
    k1, k2, p1, p2, k3 = params["dist"]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    d_radial = k1 + r2 * (2 * k2 + 3 * k3 * r2)
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    fx, s, cx, fy, cy = params["K"]
    uv = np.stack([fx * xd + s * yd + cx, fy * yd + cy], axis=1)
    d00 = radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x
    d01 = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
    d11 = radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x
    R2 = params["R2"]
    px = inv_z[:, None] * (params["R0"] - x[:, None] * R2)
    py = inv_z[:, None] * (params["R1"] - y[:, None] * R2)
    a00 = fx * d00 + s * d01
    a01 = fx * d01 + s * d11
    a10 = fy * d01
    a11 = fy * d11
    jacobian = np.empty((len(x), 2, 3))
    jacobian[:, 0] = a00[:, None] * px + a01[:, None] * py
    jacobian[:, 1] = a10[:, None] * px + a11[:, None] * py
    return uv, jacobian
