"""Compiled per-point arithmetic of ``nearest`` (:mod:`pslog.fusion.stereo`), numba.

``fuse_nearest`` made its rows, each slot's image motion (:func:`~.stereo.slot_motion`) and
its covariance (:func:`~.stereo.motion_covariance`, :func:`~._prepare.covariance`,
:func:`~.stereo._with_motion`) with about a hundred numpy operations on (k,) columns, each
writing a temporary: ~5 µs per point of a 90-minute match. The kernels here loop over the
points instead and do, for each, exactly the arithmetic of those columns in the same order
(elementwise IEEE operations on the same operands, no fastmath: the same bits; ``x ** 2`` of
a float column is numpy's square, ``x * x``). :func:`nview_normal` and :func:`nview_after`
do the same for :func:`~.stereo.nview_points` (and so ``sync``, ``typeB``, ``linear``) from
``_FEW`` points and below 8 cameras, where triangulate_rays and ray_angles use their column
forms. Left to numpy, whose bits a loop need not reproduce: the 3 x 3 solves and
determinants (LAPACK), the arccos of the ray angle, ``invalid_points``' products (BLAS)
and ``ray_depths``' einsum. :func:`window_quartiles` is :func:`~.stereo.refusal_noise`'s
windowed selection (``sync``'s residual test and ``typeB`` / ``linear``'s prediction test),
:func:`residual_norms_cameras` the residuals it selects among, every camera's in one pass;
:func:`residual_sums` the residual test's sums (:func:`~.stereo.residual_refused`).
Imported lazily (numba loads them from its cache at the first
use; ``python -m pslog.warm`` compiles them).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel
from ._prepare_kernel import direction_jacobian as _direction_jacobian
from ._prepare_kernel import ray as _ray
from ._pseudo_kernel import _row_residual, _select, _window_rows


@kernel
def nearest_rows(camera, time_ns, max_gap_ns, rows, others):
    """``fuse_nearest``'s rows: for each detection ``e`` (in row order), the latest detection
    of every other camera at or before row ``e`` and within ``max_gap_ns`` of it, and ``e``
    itself in its own camera's slot (:func:`~._prepare.latest_row_at_or_before` per camera).

    ``camera`` (n,) int64, ``time_ns`` (n,) int64; ``rows`` (n, m) int64 written (-1: none),
    ``others`` (n,) int64 written: the other cameras' detections found."""
    n, m = rows.shape[0], rows.shape[1]
    last = np.full(m, -1, dtype=np.int64)
    for e in range(n):
        c = camera[e]
        last[c] = e
        found = 0
        for d in range(m):
            r = last[d]
            if d != c and r >= 0 and time_ns[e] - time_ns[r] <= max_gap_ns:
                rows[e, d] = r
                found += 1
            else:
                rows[e, d] = -1
        rows[e, c] = e
        others[e] = found


@kernel
def slot_motion(rows, time_ns, t_obs, uv, before, max_gap_ns, max_gap_s, ns, shift, accel,
                mrows, linear, quad, lag):
    """:func:`pslog.fusion.stereo.slot_motion` of every slot, operation for operation.

    ``rows`` (k, m) the slots' detections (-1: none), slot c's a detection of camera c (as
    :func:`nearest_rows` makes them), ``time_ns`` (k,) the points' times, ``t_obs`` (n,)
    int64 and ``uv`` (n, 2) the detections' times and undistorted pixels, ``before`` (n,)
    each row's previous row of its camera: a slot's camera's detections before its own,
    ``latest_row_at_or_before(prep, c, row - 1)``, are ``before[row]`` and
    ``before[before[row]]``; ``max_gap_ns`` int, ``max_gap_s`` its seconds
    (``max_gap_ns / NS``), ``ns`` float(NS).
    Written, per slot c: ``shift[c]``, ``accel[c]`` (k, 2), ``mrows[c]``, ``linear[c]``,
    ``quad[c]`` (k, 3), ``lag[c]`` (k,) (:class:`~pslog.fusion.stereo.SlotMotion`'s)."""
    k, m = rows.shape[0], rows.shape[1]
    for c in range(m):
        for p in range(k):
            row = rows[p, c]
            have = row >= 0
            r0 = max(row, 0)
            prev = before[r0] if have else -1
            p0 = max(prev, 0)
            dt = (t_obs[r0] - t_obs[p0]) / ns
            ok = have and prev >= 0 and dt > 0 and dt <= max_gap_s
            prev2 = before[p0] if ok else -1
            q0 = max(prev2, 0)
            g = (t_obs[p0] - t_obs[q0]) / ns
            ok2 = ok and prev2 >= 0 and g > 0 and g <= max_gap_s
            lg = (time_ns[p] - t_obs[r0]) / ns
            h = dt if ok else 1.0
            if not ok2:
                g = 1.0
            L = lg if ok else 0.0
            for a in range(2):
                du = uv[r0, a] - uv[p0, a]
                vel = du / dt
                shift[c, p, a] = vel * lg if ok else 0.0
                acc = 2.0 * (du / h - (uv[p0, a] - uv[q0, a]) / g) / (h + g)
                accel[c, p, a] = 0.5 * acc * (L * (L + h)) if ok2 else 0.0
            rho = L / h
            linear[c, p, 0] = 1.0 + rho
            linear[c, p, 1] = -rho
            linear[c, p, 2] = 0.0
            if ok2:
                quad[c, p, 0] = (L + h) * (L + h + g) / (h * (h + g))
                quad[c, p, 1] = -L * (L + h + g) / (h * g)
                quad[c, p, 2] = L * (L + h) / ((h + g) * g)
            else:
                quad[c, p, 0] = 1.0 + rho
                quad[c, p, 1] = -rho
                quad[c, p, 2] = 0.0
            mrows[c, p, 0] = row
            mrows[c, p, 1] = prev if ok else -1
            mrows[c, p, 2] = prev2 if ok2 else -1
            lag[c, p] = lg if have else 0.0


@kernel
def motion_covariance(slot_rows, jac, used, mrows, quad, lag, shift, accel, lens, s2,
                      unknown_speed, nu2, nu2_rec, nu_var, ppm2, gate, share, out):
    """:func:`pslog.fusion.stereo.motion_covariance` (with :func:`~._prepare.covariance` and
    :func:`~.stereo._with_motion`), operation for operation: the quality columns ``std_m``
    and ``cov_xx_m2`` ... ``cov_yz_m2`` into ``out`` (7, k).

    ``slot_rows`` (k, m) the detections used (-1: none), ``jac`` (m, 3, 2, k) each slot's
    d(point)/d(undistorted pixel), ``used`` (k, m) bool, ``mrows`` / ``quad`` (m, k, 3),
    ``lag`` (m, k), ``shift`` / ``accel`` (m, k, 2) the slots' motion (:func:`slot_motion`),
    ``lens`` (4, n) each detection's recorded-to-undistorted pixel Jacobian (NaN as 0; no
    rows: the identity, a rig without lens distortion), ``s2`` (k,) the noise variance per
    point (``noise_px ** 2``), ``unknown_speed`` :data:`~.stereo.UNKNOWN_IMAGE_SPEED_PX_S`;
    ``nu2``, ``nu2_rec``, ``nu_var`` (n,) every detection's :func:`~.stereo.innovations`, ``ppm2``
    (m, k) :func:`~.stereo.pixels_per_metre_sq` (no rows: no break term), ``gate``
    :data:`~.stereo.KINK_GATE`, ``share`` :data:`~.stereo.KINK_SHARE`."""
    k, m = slot_rows.shape[0], slot_rows.shape[1]
    has_lens = lens.shape[1] > 0
    # κ² per point, times KINK_SHARE (stereo._break_size): the largest break a used slot's
    # newest detection shows, in m² across that camera's ray (0: none)
    kink = np.zeros(k)
    if nu2.shape[0] > 0:
        for p in range(k):
            v = s2[p]
            for a in range(m):
                r = mrows[a, p, 0] if used[p, a] else -1
                if r >= 0:
                    excess = nu2_rec[r] - gate * v * nu_var[r]
                    y = share * (nu2[r] * (excess / nu2_rec[r])) / ppm2[a, p]
                    if excess > 0 and y > kink[p]:
                        kink[p] = y
    # the slots any of whose points is used without a merged duplicate (covariance's
    # ``if not np.any(use): continue``), and those with a blind or broken point
    # (motion_covariance's ``if np.any(blind | kinked)``): a skipped slot adds nothing,
    # not 0 * NaN
    any_use = np.zeros(m, dtype=np.bool_)
    any_blind = np.zeros(m, dtype=np.bool_)
    for p in range(k):
        for s in range(m):
            if slot_rows[p, s] >= 0 and not _taken(slot_rows, p, s):
                any_use[s] = True
            if used[p, s] and lag[s, p] > 0 and (mrows[s, p, 1] < 0 or kink[p] > 0):
                any_blind[s] = True
    for p in range(k):
        # the six distinct entries xx, yy, zz, xy, xz, yz
        c0 = c1 = c2 = c3 = c4 = c5 = 0.0
        for s in range(m):
            if not any_use[s]:
                continue
            # M_s = Σ_j w_sj² L_sj L_sjᵀ and its Cholesky factor C (motion_covariance)
            M00 = M11 = M10 = 0.0
            for j in range(3):
                r = mrows[s, p, j] if used[p, s] else -1
                w2 = quad[s, p, j] * quad[s, p, j] if r >= 0 else 0.0
                if not has_lens:
                    M00 += w2
                    M11 += w2
                else:
                    rr = max(r, 0)
                    L00, L01, L10, L11 = lens[0, rr], lens[1, rr], lens[2, rr], lens[3, rr]
                    M00 += w2 * (L00 * L00 + L01 * L01)
                    M11 += w2 * (L10 * L10 + L11 * L11)
                    M10 += w2 * (L10 * L00 + L11 * L01)
            C00 = math.sqrt(M00)
            C10 = M10 / C00 if C00 > 0 else 0.0
            diff = M11 - C10 * C10
            C11 = math.sqrt(diff if (diff != diff or diff >= 0.0) else 0.0)
            # covariance: slot s's Jacobian plus those of later slots holding its detection
            row = slot_rows[p, s]
            use = row >= 0 and not _taken(slot_rows, p, s)
            j00, j01 = jac[s, 0, 0, p], jac[s, 0, 1, p]
            j10, j11 = jac[s, 1, 0, p], jac[s, 1, 1, p]
            j20, j21 = jac[s, 2, 0, p], jac[s, 2, 1, p]
            if use:
                for t in range(s + 1, m):
                    if slot_rows[p, t] == row:
                        j00 += jac[t, 0, 0, p]
                        j01 += jac[t, 0, 1, p]
                        j10 += jac[t, 1, 0, p]
                        j11 += jac[t, 1, 1, p]
                        j20 += jac[t, 2, 0, p]
                        j21 += jac[t, 2, 1, p]
                # J C (times_pixel_jacobian: C[0, 1] = 0 written out)
                a0, a1 = j00 * C00 + j01 * C10, j00 * 0.0 + j01 * C11
                b0, b1 = j10 * C00 + j11 * C10, j10 * 0.0 + j11 * C11
                e0, e1 = j20 * C00 + j21 * C10, j20 * 0.0 + j21 * C11
            else:  # zero where not used
                a0 = a1 = b0 = b1 = e0 = e1 = 0.0
            c0 += a0 * a0 + a1 * a1
            c1 += b0 * b0 + b1 * b1
            c2 += e0 * e0 + e1 * e1
            c3 += a0 * b0 + a1 * b1
            c4 += a0 * e0 + a1 * e1
            c5 += b0 * e0 + b1 * e1
        v = s2[p]
        c0, c1, c2, c3, c4, c5 = c0 * v, c1 * v, c2 * v, c3 * v, c4 * v, c5 * v
        # the unknown shift of a slot without image velocity: Σ_s (v₀ L_s)² J_s J_sᵀ, and
        # the break's of one with: Σ_s κ² ppm2_s J_s J_sᵀ, summed apart, then added (a sum
        # of zeros where no slot is blind or broken: adding it changes no bit)
        u0 = u1 = u2 = u3 = u4 = u5 = 0.0
        for s in range(m):
            if not any_blind[s]:
                continue
            blind = used[p, s] and mrows[s, p, 1] < 0 and lag[s, p] > 0
            kinked = used[p, s] and not blind and lag[s, p] > 0 and kink[p] > 0
            f = lag[s, p] * unknown_speed
            if blind:
                f2 = f * f
            elif kinked:
                f2 = kink[p] * ppm2[s, p]
            else:
                f2 = 0.0
            j00, j01 = jac[s, 0, 0, p], jac[s, 0, 1, p]
            j10, j11 = jac[s, 1, 0, p], jac[s, 1, 1, p]
            j20, j21 = jac[s, 2, 0, p], jac[s, 2, 1, p]
            u0 += f2 * (j00 * j00 + j01 * j01)
            u1 += f2 * (j10 * j10 + j11 * j11)
            u2 += f2 * (j20 * j20 + j21 * j21)
            u3 += f2 * (j00 * j10 + j01 * j11)
            u4 += f2 * (j00 * j20 + j01 * j21)
            u5 += f2 * (j10 * j20 + j11 * j21)
        c0, c1, c2, c3, c4, c5 = c0 + u0, c1 + u1, c2 + u2, c3 + u3, c4 + u4, c5 + u5
        # _with_motion: plus m mᵀ, m = Σ_s J_s (δ_s + α_s)
        m0 = m1 = m2 = 0.0
        for s in range(m):
            d0 = shift[s, p, 0] + accel[s, p, 0]
            d1 = shift[s, p, 1] + accel[s, p, 1]
            if used[p, s] and math.isfinite(d0) and math.isfinite(d1):
                m0 += jac[s, 0, 0, p] * d0 + jac[s, 0, 1, p] * d1
                m1 += jac[s, 1, 0, p] * d0 + jac[s, 1, 1, p] * d1
                m2 += jac[s, 2, 0, p] * d0 + jac[s, 2, 1, p] * d1
            else:
                m0 += 0.0
                m1 += 0.0
                m2 += 0.0
        c0 = c0 + m0 * m0
        c1 = c1 + m1 * m1
        c2 = c2 + m2 * m2
        out[0, p] = math.sqrt(c0 + c1 + c2)
        out[1, p] = c0
        out[2, p] = c1
        out[3, p] = c2
        out[4, p] = c3 + m0 * m1
        out[5, p] = c4 + m0 * m2
        out[6, p] = c5 + m1 * m2


@kernel(inline=True)
def _taken(slot_rows, p, s):
    """Slot s of point p holds the detection of an earlier slot (merged into it:
    ``merged_slots``)."""
    for t in range(s):
        if slot_rows[p, t] == slot_rows[p, s]:
            return True
    return False


@kernel
def nview_normal(rows, uv, ki, rr, centers, dirs, A, rhs, n_rays):
    """The rays of each point's detections and the normal equations of their least-squares
    point, as :func:`pslog.fusion.stereo.nview_points` and the column form of
    :func:`pslog.geometry.triangulate_rays` make them (operation for operation: the same
    bits; numpy then solves them, :func:`pslog.geometry._solve_rays`).

    ``rows`` (k, m) each slot's detection (-1: none; its ray is then row 0's pixel's, not
    used), ``uv`` (n, 2) undistorted pixels, ``ki``, ``rr`` (m, 9) each camera's K⁻¹ and R
    row-major, ``centers`` (m, 3). Written: ``dirs`` (k, m, 3) unit directions,
    ``A`` (k, 3, 3) ``Σ_j (I - d_j d_jᵀ)``, ``rhs`` (k, 3) ``Σ_j (I - d_j d_jᵀ) o_j`` (sums
    over the valid rays in slot order, from the first slot's term), ``n_rays`` (k,)."""
    k, m = rows.shape[0], rows.shape[1]
    for p in range(k):
        a00 = a01 = a02 = a11 = a12 = a22 = b0 = b1 = b2 = 0.0
        count = 0
        for c in range(m):
            r0 = max(rows[p, c], 0)
            d0, d1, d2 = _ray(ki, rr, c, uv[r0, 0], uv[r0, 1])
            dirs[p, c, 0], dirs[p, c, 1], dirs[p, c, 2] = d0, d1, d2
            o0, o1, o2 = centers[c, 0], centers[c, 1], centers[c, 2]
            u0, u1, u2, w0, w1, w2, vf = _unit_ray(rows[p, c] >= 0, d0, d1, d2, o0, o1, o2)
            if vf > 0.0:
                count += 1
            p00 = (1.0 - u0 * u0) * vf
            p01 = (0.0 - u0 * u1) * vf
            p02 = (0.0 - u0 * u2) * vf
            p11 = (1.0 - u1 * u1) * vf
            p12 = (0.0 - u1 * u2) * vf
            p22 = (1.0 - u2 * u2) * vf
            # geometry._dot's order: first, last, then middle products
            t0 = p00 * w0 + p02 * w2
            t0 += p01 * w1
            t1 = p01 * w0 + p12 * w2
            t1 += p11 * w1
            t2 = p02 * w0 + p22 * w2
            t2 += p12 * w1
            if c == 0:
                a00, a01, a02, a11, a12, a22 = p00, p01, p02, p11, p12, p22
                b0, b1, b2 = t0, t1, t2
            else:
                a00 += p00
                a01 += p01
                a02 += p02
                a11 += p11
                a12 += p12
                a22 += p22
                b0 += t0
                b1 += t1
                b2 += t2
        A[p, 0, 0], A[p, 0, 1], A[p, 0, 2] = a00, a01, a02
        A[p, 1, 0], A[p, 1, 1], A[p, 1, 2] = a01, a11, a12
        A[p, 2, 0], A[p, 2, 1], A[p, 2, 2] = a02, a12, a22
        rhs[p, 0], rhs[p, 1], rhs[p, 2] = b0, b1, b2
        n_rays[p] = count


@kernel
def _unit_ray(valid, d0, d1, d2, o0, o1, o2):
    """triangulate_rays' column form for one ray: its unit direction and origin (zeros
    where not valid) and 1.0 / 0.0 for valid (a direction or an origin not finite, or a
    zero direction, is not)."""
    valid = valid and math.isfinite(d0) and math.isfinite(d1) and math.isfinite(d2) \
        and math.isfinite(o0) and math.isfinite(o1) and math.isfinite(o2)
    norm = d0 * d0
    norm += d1 * d1
    norm += d2 * d2
    norm = math.sqrt(norm)
    valid = valid and norm > 0
    scale = norm if norm > 0 else 1.0
    if valid:
        return d0 / scale, d1 / scale, d2 / scale, o0, o1, o2, 1.0
    return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0


@kernel
def _distorted(x, y, short, k1, k2, p1, p2, k3, k00, k01, k02, k11, k12):
    """``_prepare._distorted_pixels`` of a camera (K's entries ``k00`` ... ``k12``, lens
    ``k1, k2, p1, p2, k3``) at ideal normalised (x, y); ``short``: its lens-free form (no
    lens, and every r² of the column it is called on finite). Scalars only: compiled once,
    called without a reference to an array."""
    r2 = x * x + y * y
    if short:
        xd, yd = x, y
    else:
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return k00 * xd + k01 * yd + k02, k11 * yd + k12


@kernel(inline=True)
def _projected(cam, c, p0, p1, p2):
    """reprojection_one's ideal normalised coordinates of world point (p0, p1, p2) in
    camera c, and whether it is in front (else NaN)."""
    x = p0 * cam[c, 9] + p1 * cam[c, 10] + p2 * cam[c, 11] + cam[c, 18]
    y = p0 * cam[c, 12] + p1 * cam[c, 13] + p2 * cam[c, 14] + cam[c, 19]
    z = p0 * cam[c, 15] + p1 * cam[c, 16] + p2 * cam[c, 17] + cam[c, 20]
    in_front = z > 1e-12
    if not in_front:
        z = np.nan
    return x / z, y / z, in_front


@kernel(inline=True)
def _ideal(cam, c, u, v):
    """reprojection_one's ideal normalised coordinates of undistorted pixel (u, v)."""
    y = (v - cam[c, 5]) / cam[c, 4]
    x = (u - cam[c, 2] - cam[c, 1] * y) / cam[c, 0]
    return x, y


@kernel
def nview_after(rows, uv, points, dirs, centers, n_rays, cam, lens, rtki, rms_miss, used,
                smallest_cos, residual, turns):
    """What :func:`pslog.fusion.stereo.nview_points` makes of the solved points, operation
    for operation (the same bits): triangulate_rays' ``rms_miss`` (k,), the rays ``used``
    (k, m), the smallest |cosine| between two used rays (k,; inf with fewer than two:
    :func:`pslog.geometry.ray_angles`' column form before its arccos), each slot's
    reprojection error ``residual`` (m, k) (:func:`~._prepare.reprojection_one`, NaN where
    not used) and its direction Jacobian ``turns`` (m, 3, 2, k)
    (:func:`~._prepare.direction_jacobian`).

    ``cam`` (m, 26) per camera K (9), R (9), t (3), dist (5); ``lens`` (m,) bool, a camera
    with lens distortion; ``rtki`` (m, 9) Rᵀ K⁻¹ row-major; the rest as
    :func:`nview_normal`'s."""
    k, m = rows.shape[0], rows.shape[1]
    # _distorted_pixels takes the lens-free form for a whole column (a camera's slot) only
    # if every r² of it is finite: the projected points' and the detections' columns
    short_proj = np.empty(m, dtype=np.bool_)
    short_obs = np.empty(m, dtype=np.bool_)
    for c in range(m):
        short_proj[c] = not lens[c]
        short_obs[c] = not lens[c]
    for p in range(k):
        for c in range(m):
            if short_proj[c]:
                x, y, _f = _projected(cam, c, points[p, 0], points[p, 1], points[p, 2])
                r2 = x * x + y * y
                if not math.isfinite(r2 + r2):
                    short_proj[c] = False
            if short_obs[c]:
                r0 = max(rows[p, c], 0)
                x, y = _ideal(cam, c, uv[r0, 0], uv[r0, 1])
                r2 = x * x + y * y
                if not math.isfinite(r2 + r2):
                    short_obs[c] = False
    for p in range(k):
        q0, q1, q2 = points[p, 0], points[p, 1], points[p, 2]
        sq_sum = 0.0
        smallest = np.inf
        for c in range(m):
            r0 = max(rows[p, c], 0)
            d0, d1, d2 = dirs[p, c, 0], dirs[p, c, 1], dirs[p, c, 2]
            # triangulate_rays: the distance of the point to each valid ray
            u0, u1, u2, w0, w1, w2, vf = _unit_ray(rows[p, c] >= 0, d0, d1, d2,
                                                   centers[c, 0], centers[c, 1], centers[c, 2])
            f0, f1, f2 = q0 - w0, q1 - w1, q2 - w2
            along = f0 * u0 + f2 * u2
            along += f1 * u1
            e0, e1, e2 = f0 - along * u0, f1 - along * u1, f2 - along * u2
            sq = e0 * e0 + e2 * e2
            sq += e1 * e1
            if vf == 0.0:
                sq = 0.0
            sq_sum = sq if c == 0 else sq_sum + sq
            # the rays used: a detection with a finite direction
            use = rows[p, c] >= 0 and math.isfinite(d0) and math.isfinite(d1) \
                and math.isfinite(d2)
            used[p, c] = use
            # ray_angles: the unit directions of the used rays, every pair's |cosine|
            a0, a1, a2, _w0, _w1, _w2, va = _unit_ray(use, d0, d1, d2, 0.0, 0.0, 0.0)
            for b in range(c):
                b_use = used[p, b]
                g0, g1, g2, _w0, _w1, _w2, vb = _unit_ray(
                    b_use, dirs[p, b, 0], dirs[p, b, 1], dirs[p, b, 2], 0.0, 0.0, 0.0)
                cos = g0 * a0 + g2 * a2
                cos += g1 * a1
                cos = abs(cos)
                cand = cos if (va > 0.0 and vb > 0.0) else np.inf
                if cand != cand or smallest != smallest:
                    smallest = np.nan
                elif cand < smallest:
                    smallest = cand
            # reprojection_one, in the recorded image
            x, y, in_front = _projected(cam, c, q0, q1, q2)
            u, v = _distorted(x, y, short_proj[c], cam[c, 21], cam[c, 22], cam[c, 23],
                              cam[c, 24], cam[c, 25], cam[c, 0], cam[c, 1], cam[c, 2],
                              cam[c, 4], cam[c, 5])
            ix, iy = _ideal(cam, c, uv[r0, 0], uv[r0, 1])
            tu, tv = _distorted(ix, iy, short_obs[c], cam[c, 21], cam[c, 22], cam[c, 23],
                                cam[c, 24], cam[c, 25], cam[c, 0], cam[c, 1], cam[c, 2],
                                cam[c, 4], cam[c, 5])
            u -= tu
            v -= tv
            u *= u
            v *= v
            u += v
            residual[c, p] = math.sqrt(u) if (in_front and use) else np.nan
            # direction_jacobian at the detection's undistorted pixel
            (turns[c, 0, 0, p], turns[c, 1, 0, p], turns[c, 2, 0, p],
             turns[c, 0, 1, p], turns[c, 1, 1, p], turns[c, 2, 1, p]) = \
                _direction_jacobian(rtki, c, uv[r0, 0], uv[r0, 1])
        rms_miss[p] = math.sqrt(sq_sum / n_rays[p])
        smallest_cos[p] = smallest


@kernel
def window_quartiles(time_ns, values, ends, window_ns, min_count, scratch, out):
    """For each of the sorted, distinct ``ends`` (k,) int64, the element ``count // 4`` (the
    lower quartile, sorted) of the ``values`` (n,) whose ``time_ns`` (n,) sorted lie in
    ``[end - window_ns, end)``, into ``out`` (k,); NaN where fewer than ``min_count``
    (``count``) are there. ``values`` finite, ``scratch`` (n,) float64 (overwritten): each
    window is copied there and :func:`~._pseudo_kernel._select` reorders the copy. A
    selection, no arithmetic: the element ``np.partition(window, count // 4)`` gives
    (:func:`~.stereo._window_quartiles`' numpy form), found in one compiled pass instead of
    a Python loop of a partition per window."""
    n = time_ns.shape[0]
    lo = 0
    hi = 0
    for j in range(ends.shape[0]):
        lo, hi = _window_rows(time_ns, n, lo, hi, ends[j], window_ns)
        count = hi - lo
        if count < min_count:
            out[j] = np.nan
            continue
        for i in range(count):
            scratch[i] = values[lo + i]
        out[j] = _select(scratch, count, count // 4)


@kernel
def residual_norms_cameras(time_ns, camera, uv, limits, m, max_gap_ns, ns, t_out, v_out,
                           c_out):
    """:func:`~._pseudo_kernel.residual_norms_kernel` (the same inlined
    :func:`~._pseudo_kernel._row_residual`: the same bits), with each residual's camera
    into ``c_out`` (n,) int64 as well: a row's residual is made from its camera's rows
    alone, so one camera's are the rows of ``c_out == c``, the residuals a call on that
    camera's detections alone gives. Returns how many."""
    last = np.full((m, 3), -1, dtype=np.int64)  # each camera's three latest rows, newest first
    gap = max_gap_ns / ns
    j = 0
    for r in range(time_ns.shape[0]):
        c = camera[r]
        r1, r2, r3 = last[c, 0], last[c, 1], last[c, 2]
        last[c, 2], last[c, 1], last[c, 0] = r2, r1, r
        value = _row_residual(time_ns, uv, limits, c, r, r1, r2, r3, gap, ns)
        if value == value:
            t_out[j] = time_ns[r]
            v_out[j] = value
            c_out[j] = c
            j += 1
    return j


@kernel
def residual_sums(rows, used, residual, sigma, time_ns, t_obs, uv, before, active, max_gap_s,
                  ns, unknown_speed, d2, e2, n_used):
    """:func:`pslog.fusion.stereo.residual_refused`'s sums, point by point, operation for
    operation: ``d2`` (k,) ``Σ_c r_c² / σ_c²`` over the used slots (inf where a used slot's
    residual is not finite), ``e2`` (k,) ``Σ_c e_c² / σ_c²`` (``e_c`` the slot's image
    shift over its lag, :func:`slot_motion`'s ``shift``, or ``unknown_speed`` times the lag
    where the camera has no previous detection within ``max_gap_s``), ``n_used`` (k,) the
    used slots; in camera order, the cameras ``active`` (m,) bool (those any point uses).

    ``rows`` (k, m) each slot's detection (-1: none; slot c a detection of camera c),
    ``used`` (k, m) bool, ``residual`` (m, k) the reprojection residuals (recorded pixels;
    NaN: none), ``sigma`` (k, m) each camera's noise, ``time_ns`` (k,) the points' times,
    ``t_obs`` (n,) int64 and ``uv`` (n, 2) the detections' times and undistorted pixels,
    ``before`` (n,) each row's previous row of its camera, ``ns`` float(NS)."""
    k, m = rows.shape[0], rows.shape[1]
    for p in range(k):
        sd = 0.0
        se = 0.0
        count = 0
        for c in range(m):
            if not active[c]:
                continue
            on = used[p, c]
            if not on:
                continue  # (its terms: + 0.0)
            count += 1
            var = sigma[p, c] * sigma[p, c]
            r = residual[c, p]
            if math.isfinite(r):
                sd += r * r / var
            else:
                sd = np.inf
            # slot_motion's shift and lag of this slot (its arithmetic)
            row = rows[p, c]
            r0 = max(row, 0)
            prev = before[r0] if row >= 0 else -1
            p0 = max(prev, 0)
            dt = (t_obs[r0] - t_obs[p0]) / ns
            ok = row >= 0 and prev >= 0 and dt > 0 and dt <= max_gap_s
            lg = (time_ns[p] - t_obs[r0]) / ns
            if ok:
                s0 = (uv[r0, 0] - uv[p0, 0]) / dt * lg
                s1 = (uv[r0, 1] - uv[p0, 1]) / dt * lg
                se += (s0 * s0 + s1 * s1) / var
            else:
                lag = lg if row >= 0 else 0.0
                unknown = unknown_speed * lag
                se += unknown * unknown / var
        d2[p] = sd
        e2[p] = se
        n_used[p] = count


@kernel
def quadratic_residuals_rows(rows, time_ns, uv, gap, ns, out, weight):
    """:func:`~.stereo.quadratic_residuals` of one camera's detections: for each of its
    ``rows`` (k,) int64 (row order) from the fourth on, with ``a, b, c`` the intervals
    (seconds: ``time_ns`` (n,) int64 differences over ``ns``) to its three previous ones,
    all in ``(0, gap]``: ``u - Σ l_j u_j`` (``uv`` (n, 2)) into ``out[row]`` (n, 2) and
    ``1 + Σ l_j²`` into ``weight[row]`` (n,), its Lagrange weights' numpy expressions in
    their order (the same bits); the others' entries unchanged."""
    for i in range(3, rows.shape[0]):
        r, r1, r2, r3 = rows[i], rows[i - 1], rows[i - 2], rows[i - 3]
        a = (time_ns[r] - time_ns[r1]) / ns
        b = (time_ns[r1] - time_ns[r2]) / ns
        c = (time_ns[r2] - time_ns[r3]) / ns
        if not (a > 0 and b > 0 and c > 0 and a <= gap and b <= gap and c <= gap):
            continue
        l1 = (a + b) * (a + b + c) / (b * (b + c))
        l2 = -a * (a + b + c) / (b * c)
        l3 = a * (a + b) / ((b + c) * c)
        for x in range(2):
            out[r, x] = uv[r, x] - (l1 * uv[r1, x] + l2 * uv[r2, x] + l3 * uv[r3, x])
        weight[r] = 1 + l1 * l1 + l2 * l2 + l3 * l3
