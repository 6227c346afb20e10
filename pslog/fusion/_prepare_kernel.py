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

import numpy as np

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
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = (R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1],
                                                   R[1, 2], R[2, 0], R[2, 1], R[2, 2])
    for i in range(xy.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = _normalized_ray(
            xy[i, 0], xy[i, 1], r00, r01, r02, r10, r11, r12, r20, r21, r22)


@kernel(inline=True)
def _normalized_ray(x, y, r00, r01, r02, r10, r11, r12, r20, r21, r22):
    """:func:`rays_from_normalized` of one point (x, y) and rotation R (its nine entries,
    row-major): scalars only, so a caller's loop makes it without a compiled call or a view
    of R (each took and released a reference to its arrays)."""
    z = 1.0
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
    d0 = x * r00 + y * r10 + z * r20
    d1 = x * r01 + y * r11 + z * r21
    d2 = x * r02 + y * r12 + z * r22
    norm = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return d0 / norm, d1 / norm, d2 / norm


@kernel(inline=True)
def homogeneous(m, c, u, v):
    """``M (u, v, 1)`` (3 floats) for camera c's 3 x 3 matrix ``m[c]`` (row-major, 9
    entries): each row ``(m0 u + m1 v) + m2``, the order numpy's ``@`` of these columns
    gives (``K⁻¹`` in :meth:`Prepared.rays_t`, ``Rᵀ K⁻¹`` in ``direction_jacobian``)."""
    return (m[c, 0] * u + m[c, 1] * v + m[c, 2],
            m[c, 3] * u + m[c, 4] * v + m[c, 5],
            m[c, 6] * u + m[c, 7] * v + m[c, 8])


@kernel(inline=True)
def ray(ki, rr, c, u, v):
    """Unit world direction (3 floats) of undistorted pixel (u, v) of camera c:
    ``Rᵀ K⁻¹ (u, v, 1)`` normalised (:meth:`Prepared.rays_t`, operation for operation)."""
    x, y, z = homogeneous(ki, c, u, v)
    o0 = rr[c, 0] * x
    o1 = rr[c, 1] * x
    o2 = rr[c, 2] * x
    o0 += rr[c, 3] * y
    o1 += rr[c, 4] * y
    o2 += rr[c, 5] * y
    o0 += rr[c, 6] * z
    o1 += rr[c, 7] * z
    o2 += rr[c, 8] * z
    norm = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    return o0 / norm, o1 / norm, o2 / norm


@kernel(inline=True)
def _jacobian_column(rtki, c, j, size, d0, d1, d2):
    """Column ``j`` (pixel axis u or v) of :func:`direction_jacobian` (3 floats)."""
    m0 = rtki[c, j] / size
    m1 = rtki[c, 3 + j] / size
    m2 = rtki[c, 6 + j] / size
    dm = d0 * m0
    dm += d1 * m1
    dm += d2 * m2
    return m0 - d0 * dm, m1 - d1 * dm, m2 - d2 * dm


@kernel(inline=True)
def direction_jacobian(rtki, c, u, v):
    """d(unit world direction) / d(undistorted pixel) at pixel (u, v) of camera c:
    ``(I - d dᵀ) Rᵀ K⁻¹[:, :2] / |r|`` with ``r = Rᵀ K⁻¹ (u, v, 1)``, ``d = r / |r|``
    (``rtki`` (m, 9) ``Rᵀ K⁻¹`` row-major), as :func:`~pslog.fusion._prepare.
    direction_jacobian` forms it, operation for operation. Six floats: the u column's
    three components, then the v column's."""
    r0, r1, r2 = homogeneous(rtki, c, u, v)
    size = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    d0, d1, d2 = r0 / size, r1 / size, r2 / size
    a0, a1, a2 = _jacobian_column(rtki, c, 0, size, d0, d1, d2)
    b0, b1, b2 = _jacobian_column(rtki, c, 1, size, d0, d1, d2)
    return a0, a1, a2, b0, b1, b2


@kernel
def observed_rays_and_jacobians(camera, uv, ki, rr, rtki, rays, jac):
    """Each detection's ray at its own undistorted pixel and that ray's direction Jacobian,
    in one pass: :meth:`~pslog.fusion._prepare.Prepared.rays_t` and
    :func:`~pslog.fusion._prepare.direction_jacobian`, operation for operation (the same
    bits as those numpy columns).

    Parameters
    ----------
    camera : (n,) int, each detection's camera
    uv : (n, 2) float64, undistorted pixels
    ki, rr, rtki : (m, 9) float64, per camera ``K⁻¹``, ``R`` and ``Rᵀ K⁻¹``, row-major
    rays : (n, 3) float64, written: unit world directions ``Rᵀ K⁻¹ (u, v, 1)`` normalised
    jac : (3, 2, n) float64, written: d(unit direction) / d(pixel),
        ``(I - d dᵀ) Rᵀ K⁻¹[:, :2] / |r|`` with ``r = Rᵀ K⁻¹ (u, v, 1)``
    """
    for i in range(camera.shape[0]):
        c = camera[i]
        u, v = uv[i, 0], uv[i, 1]
        rays[i, 0], rays[i, 1], rays[i, 2] = ray(ki, rr, c, u, v)  # rays_t
        (jac[0, 0, i], jac[1, 0, i], jac[2, 0, i],
         jac[0, 1, i], jac[1, 1, i], jac[2, 1, i]) = direction_jacobian(rtki, c, u, v)


@kernel
def previous_next(camera, n_cameras, before, after):
    """Each row's previous and next row of the same camera (-1: none), in row order: two
    passes with the last row seen per camera (``before``, ``after`` (n,) int64, written)."""
    last = np.full(n_cameras, -1, dtype=np.int64)
    for r in range(camera.shape[0]):
        before[r] = last[camera[r]]
        last[camera[r]] = r
    last[:] = -1
    for r in range(camera.shape[0] - 1, -1, -1):
        after[r] = last[camera[r]]
        last[camera[r]] = r


@kernel
def lensless_rows(camera, uv, kk, far, R, ki, rr, rtki, uv_und, ray_dir, jac, jac_rows,
                  rays, dir_jac):
    """:func:`~pslog.fusion._prepare.prepare`'s per-detection columns of detections of
    cameras WITHOUT lens distortion, row by row, in one pass (a stream's new rows: numpy's
    fixed cost per call was most of a push). The same operations in the same order as
    :meth:`~pslog.camera.Camera.normalized_from_pixels`, ``pixels_from_normalized``,
    :func:`rays_from_normalized` and :func:`observed_rays_and_jacobians` (the same bits).

    Parameters
    ----------
    camera : (k,) int64; uv : (k, 2) float64, recorded pixels
    kk : (m, 9) float64, each camera's K, row-major; far : (m,) float64, the largest
        absolute pixel coordinate of a detection (``_FAR_IMAGES`` image sizes; beyond: no
        ray, NaN); R : (m, 3, 3) float64, rotations; ki, rr, rtki : (m, 9) as
        :func:`observed_rays_and_jacobians`
    uv_und (k, 2), ray_dir (k, 3), jac (k, 2, 2), jac_rows (k, 4), rays (k, 3),
    dir_jac (3, 2, k) : written (``jac``: the identity, as ``_undistortion_jacobian``
        without a lens); ``jac_rows`` of no rows: not written; ``rays`` of no rows: neither
        they nor ``dir_jac`` (a session's prepare leaves them to ``Prepared.observed_rays``)
    """
    for i in range(camera.shape[0]):
        c = camera[i]
        u, v = uv[i, 0], uv[i, 1]
        # normalized_from_pixels, then pixels_from_normalized (no lens: the ideal point)
        y = (v - kk[c, 5]) / kk[c, 4]
        x = (u - kk[c, 2] - kk[c, 1] * y) / kk[c, 0]
        # rays_from_normalized's arithmetic, inlined (no call, no view R[c] per row)
        d0, d1, d2 = _normalized_ray(x, y, R[c, 0, 0], R[c, 0, 1], R[c, 0, 2], R[c, 1, 0],
                                     R[c, 1, 1], R[c, 1, 2], R[c, 2, 0], R[c, 2, 1], R[c, 2, 2])
        if abs(u) <= far[c] and abs(v) <= far[c]:
            uv_und[i, 0] = kk[c, 0] * x + kk[c, 1] * y + kk[c, 2]
            uv_und[i, 1] = kk[c, 4] * y + kk[c, 5]
            ray_dir[i, 0], ray_dir[i, 1], ray_dir[i, 2] = d0, d1, d2
        else:  # far outside the image (or NaN): no detection, no ray
            uv_und[i, 0] = uv_und[i, 1] = np.nan
            ray_dir[i, 0] = ray_dir[i, 1] = ray_dir[i, 2] = np.nan
        jac[i, 0, 0], jac[i, 0, 1], jac[i, 1, 0], jac[i, 1, 1] = 1.0, 0.0, 0.0, 1.0
        if jac_rows.shape[0]:
            jac_rows[i, 0], jac_rows[i, 1], jac_rows[i, 2], jac_rows[i, 3] = 1.0, 0.0, 0.0, 1.0
    if rays.shape[0]:
        observed_rays_and_jacobians(camera, uv_und, ki, rr, rtki, rays, dir_jac)


@kernel
def normal_inverse(used, dirs, out):
    """The inverse of ``A = Σ_j (I - d_j d_jᵀ)`` over the rays each point uses, as
    :func:`pslog.fusion._prepare.least_squares_pixel_jacobians` forms it (the same
    operations in the same order: the same bits): ``used`` (k, m) bool, ``dirs`` (k, m, 3)
    unit directions; ``out`` (6, k) written, entries (0,0) (1,1) (2,2) (0,1) (0,2) (1,2)
    (NaN where ``|det A| <= 1e-12``)."""
    k, m = used.shape[0], used.shape[1]
    for p in range(k):
        n_used = 0.0
        for j in range(m):
            if used[p, j]:
                n_used += 1.0
        a, e, i_ = n_used, n_used, n_used
        b = c = f = 0.0
        for j in range(m):
            if used[p, j]:
                x, y, z = dirs[p, j, 0], dirs[p, j, 1], dirs[p, j, 2]
            else:
                x = y = z = 0.0
            a -= x * x
            e -= y * y
            i_ -= z * z
            b -= x * y
            c -= x * z
            f -= y * z
        co00, co01, co02 = e * i_ - f * f, c * f - b * i_, b * f - c * e
        co11, co12, co22 = a * i_ - c * c, c * b - a * f, a * e - b * b
        det = (a * co00 + b * co01) + c * co02
        inv_det = 1.0 / (det if abs(det) > 1e-12 else np.nan)
        out[0, p], out[1, p], out[2, p] = co00 * inv_det, co11 * inv_det, co22 * inv_det
        out[3, p], out[4, p], out[5, p] = co01 * inv_det, co02 * inv_det, co12 * inv_det


@kernel
def ray_pixel_jacobian(points, origin, direction, used, turn, inverse, out):
    """d(point) / d(undistorted pixel of one ray), component-major (3, 2, k), as
    :func:`pslog.fusion._prepare.least_squares_pixel_jacobians` forms it for that ray (the
    same bits; zero where the ray is not ``used`` (k,)): ``points`` (k, 3), ``origin``
    (k, 3) or (1, 3) (one origin for every point), ``direction`` (k, 3), ``turn`` (3, 2, k)
    d(unit direction) / d(pixel), ``inverse`` (6, k) :func:`normal_inverse`; ``out``
    (3, 2, k) written."""
    k = points.shape[0]
    one = origin.shape[0] == 1
    for p in range(k):
        if not used[p]:
            for r in range(3):
                out[r, 0, p] = 0.0
                out[r, 1, p] = 0.0
            continue
        o = 0 if one else p
        w0 = origin[o, 0] - points[p, 0]
        w1 = origin[o, 1] - points[p, 1]
        w2 = origin[o, 2] - points[p, 2]
        d0, d1, d2 = direction[p, 0], direction[p, 1], direction[p, 2]
        s = (d0 * w0 + d1 * w1) + d2 * w2
        i00, i11, i22 = inverse[0, p], inverse[1, p], inverse[2, p]
        i01, i02, i12 = inverse[3, p], inverse[4, p], inverse[5, p]
        for q in range(2):
            g0, g1, g2 = turn[0, q, p], turn[1, q, p], turn[2, q, p]
            dot = (w0 * g0 + w1 * g1) + w2 * g2
            n0 = s * g0 + d0 * dot
            n1 = s * g1 + d1 * dot
            n2 = s * g2 + d2 * dot
            out[0, q, p] = -((i00 * n0 + i01 * n1) + i02 * n2)
            out[1, q, p] = -((i01 * n0 + i11 * n1) + i12 * n2)
            out[2, q, p] = -((i02 * n0 + i12 * n1) + i22 * n2)


@kernel(inline=True, contract=True)
def _view_project(p0, p1, p2, cams, boxes, c):
    """Camera c's ``(x, y, z)`` of a point and its projection ``(u, v)``, as
    :func:`pslog.fusion._prepare.invalid_points`' numpy gets them (see :func:`view_flags`);
    ``u = v = 0`` at or behind the image plane (``z <= 1e-9``: not projected)."""
    acc = 0.0
    acc = acc + p0 * cams[c, 0]
    acc = acc + p1 * cams[c, 1]
    acc = acc + p2 * cams[c, 2]
    x = acc + cams[c, 9]
    acc = 0.0
    acc = acc + p0 * cams[c, 3]
    acc = acc + p1 * cams[c, 4]
    acc = acc + p2 * cams[c, 5]
    y = acc + cams[c, 10]
    acc = 0.0
    acc = acc + p0 * cams[c, 6]
    acc = acc + p1 * cams[c, 7]
    acc = acc + p2 * cams[c, 8]
    z = acc + cams[c, 11]
    if z <= 1e-9:
        return x, y, z, 0.0, 0.0
    nx, ny = x / z, y / z
    acc = 0.0
    acc = acc + nx * cams[c, 12]
    acc = acc + ny * cams[c, 13]
    u = acc + boxes[c, 4]
    acc = 0.0
    acc = acc + nx * cams[c, 14]
    acc = acc + ny * cams[c, 15]
    v = acc + boxes[c, 5]
    return x, y, z, u, v


@kernel(contract=True)
def view_flags(points, used, finite, cams, boxes, behind_bit, outside_bit, flags):
    """:func:`pslog.fusion._prepare.invalid_points`' flags in one pass, its numpy operations
    repeated operation for operation (the same bits): ``in_cam = points @ Rᵀ + t`` and the
    projection ``(x / z, y / z) @ K[:2, :2]ᵀ + K[:2, 2]`` of each camera c a point used,
    each product's entry summed as numpy's matmul gets it from OpenBLAS for these shapes
    (two rows or more): the terms in order from 0, each a fused multiply-add
    (``contract``: where the CPU has none, neither has the BLAS kernel), then the
    addition. ``points`` (k, 3), ``used`` (k, m) bool, ``finite`` (k,) bool, ``cams``
    (m, 16): R row-major (9), t (3), K[0, 0], K[0, 1], K[1, 0], K[1, 1]; ``boxes`` (m, 4)
    the view boxes with K[0, 2], K[1, 2] after them (m, 6); ``flags`` (k,) int64, or-ed.
    Used only where :func:`pslog.fusion._prepare.view_flags_compiled`'s probe found
    :func:`view_project` (the same arithmetic) giving numpy's bits."""
    k, m = used.shape[0], used.shape[1]
    for p in range(k):
        if not finite[p]:
            continue
        p0, p1, p2 = points[p, 0], points[p, 1], points[p, 2]
        bits = 0
        for c in range(m):
            if not used[p, c]:
                continue
            _, _, z, u, v = _view_project(p0, p1, p2, cams, boxes, c)
            if z <= 1e-9:
                bits |= behind_bit
                continue
            if not ((u >= boxes[c, 0]) & (u <= boxes[c, 2]) & (v >= boxes[c, 1])
                    & (v <= boxes[c, 3])):
                bits |= outside_bit
        flags[p] |= bits


@kernel(contract=True)
def view_project(points, cams, boxes, out):
    """:func:`view_flags`' arithmetic for every point and camera: ``out`` (k, m, 5) written
    with ``x, y, z, u, v`` (``u = v = 0`` where ``z <= 1e-9``) — what the probe
    :func:`pslog.fusion._prepare.view_flags_compiled` compares with numpy's products."""
    for p in range(points.shape[0]):
        for c in range(cams.shape[0]):
            x, y, z, u, v = _view_project(points[p, 0], points[p, 1], points[p, 2], cams,
                                          boxes, c)
            out[p, c, 0], out[p, c, 1], out[p, c, 2] = x, y, z
            out[p, c, 3], out[p, c, 4] = u, v


@kernel
def ray_depths_rows(points, centers, dirs, out):
    """:func:`pslog.geometry.ray_depths` of points (k, 3) along the rays (k, m, 3) from the
    cameras' centres (m, 3) (the origins broadcast over the points), operation for
    operation (the same bits): ``(p - o) · d / d · d``, each dot product summed as numpy's
    einsum sums three terms (first, last, then middle). ``out`` (k, m) written."""
    k, m = dirs.shape[0], dirs.shape[1]
    for p in range(k):
        for c in range(m):
            o0 = points[p, 0] - centers[c, 0]
            o1 = points[p, 1] - centers[c, 1]
            o2 = points[p, 2] - centers[c, 2]
            d0, d1, d2 = dirs[p, c, 0], dirs[p, c, 1], dirs[p, c, 2]
            out[p, c] = ((o0 * d0 + o2 * d2) + o1 * d1) / ((d0 * d0 + d2 * d2) + d1 * d1)
