"""Multi-view geometry on batches: epipolar lines, rays, triangulation.

Everything here is vectorized over the leading axis and free of per-point Python loops.
The pseudo-stereo method of Fujiyoshi et al. (``../shared/paper``) uses, in order:

- :func:`epipolar_lines` and :func:`closest_points_on_lines` — section 2.2, step 2: snap the
  interpolated point to the epipolar line of the observed one;
- :func:`triangulate_two_rays` — step 3: the 3D point as the "crossing point" of two viewing
  rays (midpoint of their common perpendicular);
- :func:`closest_points_on_rays` — eq. (4): the nearest point on a viewing ray (eq. (3)).

Image points given to :func:`fundamental_matrix`-based functions are *undistorted* pixels
(see :meth:`pslog.camera.Camera.undistort`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .camera import Camera

_PARALLEL_EPS = 1e-12
#: Below this many points the row-wise forms (fewer, larger numpy calls) are the faster; the
#: column forms give the same bits
_FEW = 64


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def fundamental_matrix(cam_a: Camera, cam_b: Camera) -> np.ndarray:
    """Fundamental matrix ``F`` (3, 3) with ``x_bᵀ F x_a = 0`` for undistorted pixels.

    Built from the relative pose: ``F = K_b⁻ᵀ [t_ba]ₓ R_ba K_a⁻¹`` where
    ``x_b = R_ba x_a + t_ba`` maps camera-a coordinates to camera-b coordinates.
    Scaled to unit Frobenius norm; zero for two cameras at the same centre.
    """
    R_ba = cam_b.R @ cam_a.R.T
    t_ba = cam_b.t - R_ba @ cam_a.t
    E = _skew(t_ba) @ R_ba
    F = np.linalg.inv(cam_b.K).T @ E @ np.linalg.inv(cam_a.K)
    norm = np.linalg.norm(F)
    # two cameras at one centre have no epipolar geometry: F is zero (and epipolar_lines
    # NaN), not 0/0 (see pslog.rig.check_baselines, which refuses such rigs for fusion)
    return F / norm if norm > 0 else F


def fundamental_matrices(cameras: Sequence[Camera]) -> np.ndarray:
    """``F[a, b]`` (m, m, 3, 3) for every ordered pair of ``cameras``, as
    :func:`fundamental_matrix` (``x_bᵀ F[a, b] x_a = 0``); zeros on the diagonal."""
    m = len(cameras)
    F = np.zeros((m, m, 3, 3))
    for a in range(m):
        for b in range(m):
            if a != b:
                F[a, b] = fundamental_matrix(cameras[a], cameras[b])
    return F


def epipolar_lines(F: np.ndarray, uv_a: np.ndarray) -> np.ndarray:
    """Epipolar lines in image b of undistorted pixels ``uv_a`` (n, 2) of image a.

    ``F`` is one fundamental matrix (3, 3) for all points, or one per point (n, 3, 3)
    (``x_bᵀ F x_a = 0``, as from :func:`fundamental_matrix`).

    Returns
    -------
    lines : array, shape (n, 3)
        ``(a, b, c)`` with ``a u + b v + c = 0`` and ``a² + b² = 1``, so that
        ``lines @ [u, v, 1]`` is a signed distance in pixels.
    """
    uv_a = np.asarray(uv_a, dtype=np.float64)
    homogeneous = np.hstack([uv_a, np.ones((len(uv_a), 1))])
    F = np.asarray(F, dtype=np.float64)
    # a pixel near the float range (1e300, from a damaged file) overflows to inf and its line
    # comes out NaN, as does any line of a zero F (two cameras at one centre): NaN is the
    # answer there, so these steps warn of nothing
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        lines = homogeneous @ F.T if F.ndim == 2 else np.einsum("nij,nj->ni", F, homogeneous)
        # scale by the larger of a, b before the norm, which would overflow on its own
        lines = lines / np.max(np.abs(lines[:, :2]), axis=1, keepdims=True)
        return lines / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)


def epipolar_lines_cols(F: np.ndarray, uv_a: np.ndarray) -> np.ndarray:
    """:func:`epipolar_lines` of one fundamental matrix per point given as (9, n) columns
    (entry ``3 i + j`` of ``F[i, j]``), on columns (numpy is slow on short rows), with
    the sums in the order of the row-wise form: the same bits. Returns lines (n, 3)."""
    u, v = uv_a[:, 0], uv_a[:, 1]
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        a = F[0] * u + F[2]
        a += F[1] * v
        b = F[3] * u + F[5]
        b += F[4] * v
        c = F[6] * u + F[8]
        c += F[7] * v
        big = np.maximum(np.abs(a), np.abs(b))
        a /= big
        b /= big
        c /= big
        size = np.sqrt(a * a + b * b)
        lines = np.empty((len(u), 3))
        np.divide(a, size, out=lines[:, 0])
        np.divide(b, size, out=lines[:, 1])
        np.divide(c, size, out=lines[:, 2])
    return lines


def closest_points_on_lines(lines: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal projection of 2D points onto 2D lines (the paper's section 2.2, step 2).

    Parameters
    ----------
    lines : array, shape (n, 3), normalized ``a² + b² = 1`` (as from :func:`epipolar_lines`)
    uv : array, shape (n, 2), pixels

    Returns
    -------
    uv_on_line : array, shape (n, 2), pixels
    distance : array, shape (n,), unsigned distance from ``uv`` to its line, pixels
    """
    uv = np.asarray(uv, dtype=np.float64)
    normal = lines[:, :2]
    signed = np.einsum("ij,ij->i", normal, uv) + lines[:, 2]
    return uv - signed[:, None] * normal, np.abs(signed)


def triangulate_two_rays(
    origin_a: np.ndarray, dir_a: np.ndarray, origin_b: np.ndarray, dir_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Crossing point of two 3D lines: the midpoint of their common perpendicular.

    The paper's section 2.2, step 3. Rays are ``origin + k * dir``; ``dir`` need not be unit.
    The crossing of two *lines* may lie behind a camera; :func:`crossing_of_rays` also gives
    the ray parameters to check that it does not.

    Parameters
    ----------
    origin_a, origin_b : array, shape (n, 3) or (3,), metres
    dir_a, dir_b : array, shape (n, 3)

    Returns
    -------
    points : array, shape (n, 3), metres; NaN where the rays are parallel
    miss : array, shape (n,), length of the common perpendicular (ray-to-ray distance), metres
    """
    points, miss, _, _ = crossing_of_rays(origin_a, dir_a, origin_b, dir_b)
    return points, miss


def crossing_of_rays(
    origin_a: np.ndarray, dir_a: np.ndarray, origin_b: np.ndarray, dir_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`triangulate_two_rays` with the parameters of the common perpendicular's feet.

    The feet are ``origin_a + s dir_a`` and ``origin_b + k dir_b``; a point in front of both
    cameras has ``s > 0`` and ``k > 0`` (with ``dir`` pointing out of the camera). A
    negative-disparity pair crosses *behind* the cameras, at negative ``s`` and ``k``, with
    a miss as small as any good pair's: only the signs tell.

    Returns
    -------
    points : (n, 3) metres, NaN where the rays are parallel
    miss : (n,) metres
    s, k : (n,) the ray parameters (units of ``|dir|``), NaN where parallel
    """
    dir_a = np.atleast_2d(np.asarray(dir_a, dtype=np.float64))
    dir_b = np.atleast_2d(np.asarray(dir_b, dtype=np.float64))
    origin_a = np.asarray(origin_a, dtype=np.float64)
    origin_b = np.asarray(origin_b, dtype=np.float64)
    # on (n,) columns, not rows of 3 (numpy is slow on short axes); dot products summed in
    # einsum's order, so that the bits are those of the row-wise form
    xa, ya, za = dir_a[:, 0], dir_a[:, 1], dir_a[:, 2]
    xb, yb, zb = dir_b[:, 0], dir_b[:, 1], dir_b[:, 2]
    w0 = origin_a - origin_b
    wx, wy, wz = w0[..., 0], w0[..., 1], w0[..., 2]
    a = _dot(xa, ya, za, xa, ya, za)
    b = _dot(xa, ya, za, xb, yb, zb)
    c = _dot(xb, yb, zb, xb, yb, zb)
    d = _dot(xa, ya, za, wx, wy, wz)
    e = _dot(xb, yb, zb, wx, wy, wz)
    denom = a * c - b * b
    parallel = denom <= _PARALLEL_EPS * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(parallel, np.nan, (b * e - c * d) / denom)
        k = np.where(parallel, np.nan, (a * e - b * d) / denom)
    points = np.empty((len(s), 3))
    miss = np.zeros(len(s))
    for i, (da, db) in enumerate(((xa, xb), (ya, yb), (za, zb))):
        foot_a = origin_a[..., i] + s * da
        foot_b = origin_b[..., i] + k * db
        points[:, i] = 0.5 * (foot_a + foot_b)
        foot_a -= foot_b
        foot_a *= foot_a
        miss += foot_a
    return points, np.sqrt(miss, out=miss), s, k


def _dot(x1, y1, z1, x2, y2, z2):
    """Row-wise dot products of 3-vectors given by their (n,) components, summed in the
    order of ``np.einsum("ij,ij->i", ...)`` (the first and last products first): the same
    bits."""
    out = x1 * x2
    out += z1 * z2
    out += y1 * y2
    return out


def ray_depths(points: np.ndarray, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Parameter along each ray of the foot of each point, in units of ``|direction|``:
    ``(p - o) · d / |d|²``; positive in front of the camera.

    Parameters
    ----------
    points : (n, 3), metres
    origins : (n, m, 3) or (n, 3), metres
    directions : (n, m, 3) or (n, 3)

    Returns
    -------
    (n, m) or (n,) float64
    """
    points = np.asarray(points, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    offsets = (points[:, None, :] if directions.ndim == 3 else points) - origins
    with np.errstate(invalid="ignore", divide="ignore"):
        return (np.einsum("...i,...i->...", offsets, directions)
                / np.einsum("...i,...i->...", directions, directions))


def triangulate_rays(
    origins: np.ndarray, directions: np.ndarray, valid: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares intersection of N rays per point (minimises summed squared distances).

    Parameters
    ----------
    origins : array, shape (n, m, 3), metres — m rays for each of n points
    directions : array, shape (n, m, 3)
    valid : array, shape (n, m), bool, optional — rays to use (default all)

    Returns
    -------
    points : array, shape (n, 3); NaN where fewer than two non-parallel rays are valid
    rms_miss : array, shape (n,), RMS distance from the point to its rays, metres
    n_rays : array, shape (n,), int, rays used
    """
    origins = np.asarray(origins, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    if valid is None:
        valid = np.ones(directions.shape[:2], dtype=bool)
    if directions.shape[1] >= 8 or len(directions) < _FEW:  # (numpy sums 8 or more terms
        return _triangulate_rays_rows(origins, directions, valid)  # pairwise)
    # on (n, m) component arrays, not (n, m, 3, 3) projectors (numpy is slow on short axes),
    # every sum in the order of the array form it replaces (einsum's: first and last terms
    # first; over rays: in order), so that the bits are the same
    d = [directions[..., c] for c in range(3)]
    o = [origins[..., c] for c in range(3)]
    valid = valid & np.isfinite(d[0]) & np.isfinite(d[1]) & np.isfinite(d[2])
    valid &= np.isfinite(o[0]) & np.isfinite(o[1]) & np.isfinite(o[2])
    norms = d[0] * d[0]
    norms += d[1] * d[1]
    norms += d[2] * d[2]
    np.sqrt(norms, out=norms)
    valid &= norms > 0
    scale = np.where(norms > 0, norms, 1.0)
    unit = [np.where(valid, dc / scale, 0.0) for dc in d]
    o = [np.where(valid, oc, 0.0) for oc in o]
    # sum_j (I - d_j d_jᵀ) p = sum_j (I - d_j d_jᵀ) o_j
    P = {}
    for i in range(3):
        for j in range(i, 3):
            P[i, j] = P[j, i] = ((1.0 if i == j else 0.0) - unit[i] * unit[j]) * valid
    n = valid.shape[0]
    A = np.empty((n, 3, 3))
    rhs = np.empty((n, 3))
    for i in range(3):
        for j in range(i, 3):
            A[:, i, j] = _sum_rays(P[i, j])
            if j != i:
                A[:, j, i] = A[:, i, j]
        rhs[:, i] = _sum_rays(_dot(P[i, 0], P[i, 1], P[i, 2], o[0], o[1], o[2]))
    n_rays = valid.sum(axis=1)
    points = _solve_rays(A, rhs, n_rays)
    offsets = [points[:, c, None] - o[c] for c in range(3)]
    along = _dot(offsets[0], offsets[1], offsets[2], unit[0], unit[1], unit[2])
    perp = [offsets[c] - along * unit[c] for c in range(3)]
    sq = np.where(valid, _dot(perp[0], perp[1], perp[2], perp[0], perp[1], perp[2]), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms_miss = np.sqrt(_sum_rays(sq) / n_rays)
    return points, rms_miss, n_rays


def _solve_rays(A: np.ndarray, rhs: np.ndarray, n_rays: np.ndarray,
                overwrite: bool = False) -> np.ndarray:
    """Points (n, 3) solving ``A p = rhs`` (n, 3, 3) where two rays or more and ``A`` is not
    singular (parallel rays); NaN elsewhere. ``overwrite``: ``A`` may be written (the
    caller drops it)."""
    det = np.linalg.det(A)
    ok = (n_rays >= 2) & (np.abs(det) > 1e-12)
    if not np.any(ok):
        return np.full((len(A), 3), np.nan)
    # every row solved at once, the others' matrices replaced by the identity (in a copy
    # unless ``overwrite``) rather than the ok rows gathered and scattered back (a match's
    # points have a row or two without a point); each matrix is solved on its own: the
    # ok rows' bits are those of solving them alone
    bad = ~ok
    if np.any(bad):
        A = A if overwrite else A.copy()
        A[bad] = np.eye(3)
    points = np.linalg.solve(A, rhs[..., None])[..., 0]
    points[bad] = np.nan
    return points


def _triangulate_rays_rows(origins, directions, valid):
    """:func:`triangulate_rays` on (n, m, 3, 3) projectors, for 8 rays or more."""
    valid = valid & np.all(np.isfinite(directions), axis=2) & np.all(np.isfinite(origins), axis=2)
    norms = np.linalg.norm(directions, axis=2, keepdims=True)
    valid = valid & (norms[..., 0] > 0)
    unit = np.where(valid[..., None], directions / np.where(norms > 0, norms, 1.0), 0.0)
    origins0 = np.where(valid[..., None], origins, 0.0)
    # sum_j (I - d_j d_jᵀ) p = sum_j (I - d_j d_jᵀ) o_j
    projector = np.eye(3) - unit[..., :, None] * unit[..., None, :]  # (n, m, 3, 3)
    projector = projector * valid[..., None, None]
    A = projector.sum(axis=1)
    rhs = np.einsum("nmij,nmj->ni", projector, origins0)
    n_rays = valid.sum(axis=1)
    points = _solve_rays(A, rhs, n_rays)
    offsets = points[:, None, :] - origins0
    perp = offsets - np.einsum("nmi,nmi->nm", offsets, unit)[..., None] * unit
    sq = np.where(valid, np.einsum("nmi,nmi->nm", perp, perp), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms_miss = np.sqrt(sq.sum(axis=1) / n_rays)
    return points, rms_miss, n_rays


def _sum_rays(x: np.ndarray) -> np.ndarray:
    """``x.sum(axis=1)`` of an (n, m) array, rays added in order (numpy's order for m < 8)."""
    if x.shape[1] >= 8:
        return x.sum(axis=1)
    out = x[:, 0].copy()
    for j in range(1, x.shape[1]):
        out += x[:, j]
    return out


def ray_angles(directions: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """Largest angle between any two valid rays of each point, radians.

    The conditioning of a triangulation: depth error grows like ``1 / sin(angle)``, so a
    small angle flags a point that looks consistent (small miss) but is poorly determined.

    Parameters
    ----------
    directions : (n, m, 3), ray directions (any length)
    valid : (n, m) bool, optional

    Returns
    -------
    (n,) float64 radians in [0, π/2] (rays are lines: their sense does not matter); NaN with
    fewer than two valid rays
    """
    directions = np.asarray(directions, dtype=np.float64)
    if valid is None:
        valid = np.ones(directions.shape[:2], dtype=bool)
    if directions.shape[1] >= 8 or len(directions) < _FEW:
        return _ray_angles_rows(directions, valid)
    # on (n, m) component arrays (the same bits as the row-wise form: einsum's order)
    d = [directions[..., c] for c in range(3)]
    norms = d[0] * d[0]
    norms += d[1] * d[1]
    norms += d[2] * d[2]
    np.sqrt(norms, out=norms)
    valid = valid & (norms > 0) & np.isfinite(d[0]) & np.isfinite(d[1]) & np.isfinite(d[2])
    scale = np.where(norms > 0, norms, 1.0)
    unit = [np.where(valid, dc / scale, 0.0) for dc in d]
    m = valid.shape[1]
    smallest_cos = np.full(len(valid), np.inf)
    for a in range(m):
        for b in range(a + 1, m):
            cos = np.abs(_dot(unit[0][:, a], unit[1][:, a], unit[2][:, a],
                              unit[0][:, b], unit[1][:, b], unit[2][:, b]))
            np.minimum(smallest_cos, np.where(valid[:, a] & valid[:, b], cos, np.inf),
                       out=smallest_cos)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(smallest_cos), np.arccos(np.clip(smallest_cos, 0.0, 1.0)),
                        np.nan)


def _ray_angles_rows(directions, valid):
    """:func:`ray_angles` on (n, m, m) cosines, for 8 rays or more."""
    norms = np.linalg.norm(directions, axis=2, keepdims=True)
    valid = valid & (norms[..., 0] > 0) & np.all(np.isfinite(directions), axis=2)
    unit = np.where(valid[..., None], directions / np.where(norms > 0, norms, 1.0), 0.0)
    cosines = np.abs(np.einsum("nai,nbi->nab", unit, unit))
    pair = valid[:, :, None] & valid[:, None, :] & ~np.eye(valid.shape[1], dtype=bool)
    smallest_cos = np.where(pair, cosines, np.inf).min(axis=(1, 2))
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(smallest_cos), np.arccos(np.clip(smallest_cos, 0.0, 1.0)),
                        np.nan)


def closest_points_on_rays(
    origins: np.ndarray, directions: np.ndarray, points: np.ndarray
) -> np.ndarray:
    """Nearest point on each ray to each point, eq. (4) of the paper.

    ``P' = ((P̂ - T) · r / |r|²) r + T`` for the ray ``l = k r + T`` of eq. (3).

    Parameters
    ----------
    origins : array, shape (n, 3) or (3,), the ray origins ``T``, metres
    directions : array, shape (n, 3), the ray directions ``r`` (any length)
    points : array, shape (n, 3), the predicted points ``P̂``, metres

    Returns
    -------
    array, shape (n, 3), metres
    """
    directions = np.asarray(directions, dtype=np.float64)
    offsets = np.asarray(points, dtype=np.float64) - origins
    x, y, z = directions[:, 0], directions[:, 1], directions[:, 2]
    k = _dot(offsets[:, 0], offsets[:, 1], offsets[:, 2], x, y, z) / _dot(x, y, z, x, y, z)
    return k[:, None] * directions + origins
