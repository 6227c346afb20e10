"""Compiled per-point arithmetic of ``nearest`` (:mod:`pslog.fusion.stereo`), numba.

``fuse_nearest`` made its rows, each slot's image motion (:func:`~.stereo.slot_motion`) and
its covariance (:func:`~.stereo.motion_covariance`, :func:`~._prepare.covariance`,
:func:`~.stereo._with_motion`) with about a hundred numpy operations on (k,) columns, each
writing a temporary: ~5 µs per point of a 90-minute match. The kernels here loop over the
points instead and do, for each, exactly the arithmetic of those columns in the same order
(elementwise IEEE operations on the same operands, no fastmath: the same bits; ``x ** 2`` of
a float column is numpy's square, ``x * x``). Imported lazily (numba loads them from its
cache at the first use; ``python -m pslog.warm`` compiles them).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel


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


@kernel(inline=True)
def _latest_before(cam_rows, cam_start, before, camera, c, row):
    """The latest row of camera ``c`` strictly before global row ``row`` (-1: none):
    ``latest_row_at_or_before(prep, c, row - 1)``. ``before`` (n,): each row's previous row
    of its own camera (one lookup when ``row`` is camera c's); otherwise a binary search of
    ``cam_rows[cam_start[c]:cam_start[c + 1]]``, camera c's rows in order."""
    if camera[row] == c:
        return before[row]
    lo, hi = cam_start[c], cam_start[c + 1]
    # searchsorted(rows, row - 1, side="right") - 1
    a, b = lo, hi
    while a < b:
        mid = (a + b) // 2
        if cam_rows[mid] <= row - 1:
            a = mid + 1
        else:
            b = mid
    return cam_rows[a - 1] if a > lo else -1


@kernel
def slot_motion(rows, time_ns, t_obs, uv, camera, before, cam_rows, cam_start, max_gap_ns,
                max_gap_s, ns, shift, accel, mrows, linear, quad, lag):
    """:func:`pslog.fusion.stereo.slot_motion` of every slot, operation for operation.

    ``rows`` (k, m) the slots' detections (-1: none), ``time_ns`` (k,) the points' times,
    ``t_obs`` (n,) int64 and ``uv`` (n, 2) the detections' times and undistorted pixels,
    ``camera`` (n,) int64, ``before`` (n,) each row's previous row of its camera, ``cam_rows``
    / ``cam_start`` every camera's rows in order (concatenated, (m + 1,) starts),
    ``max_gap_ns`` int, ``max_gap_s`` its seconds (``max_gap_ns / NS``), ``ns`` float(NS).
    Written, per slot c: ``shift[c]``, ``accel[c]`` (k, 2), ``mrows[c]``, ``linear[c]``,
    ``quad[c]`` (k, 3), ``lag[c]`` (k,) (:class:`~pslog.fusion.stereo.SlotMotion`'s)."""
    k, m = rows.shape[0], rows.shape[1]
    for c in range(m):
        for p in range(k):
            row = rows[p, c]
            have = row >= 0
            r0 = max(row, 0)
            prev = _latest_before(cam_rows, cam_start, before, camera, c, r0) if have else -1
            p0 = max(prev, 0)
            dt = (t_obs[r0] - t_obs[p0]) / ns
            ok = have and prev >= 0 and dt > 0 and dt <= max_gap_s
            prev2 = _latest_before(cam_rows, cam_start, before, camera, c, p0) if ok else -1
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
                      unknown_speed, out):
    """:func:`pslog.fusion.stereo.motion_covariance` (with :func:`~._prepare.covariance` and
    :func:`~.stereo._with_motion`), operation for operation: the quality columns ``std_m``
    and ``cov_xx_m2`` ... ``cov_yz_m2`` into ``out`` (7, k).

    ``slot_rows`` (k, m) the detections used (-1: none), ``jac`` (m, 3, 2, k) each slot's
    d(point)/d(undistorted pixel), ``used`` (k, m) bool, ``mrows`` / ``quad`` (m, k, 3),
    ``lag`` (m, k), ``shift`` / ``accel`` (m, k, 2) the slots' motion (:func:`slot_motion`),
    ``lens`` (4, n) each detection's recorded-to-undistorted pixel Jacobian (NaN as 0; no
    rows: the identity, a rig without lens distortion), ``s2`` (k,) the noise variance per
    point (``noise_px ** 2``), ``unknown_speed`` :data:`~.stereo.UNKNOWN_IMAGE_SPEED_PX_S`."""
    k, m = slot_rows.shape[0], slot_rows.shape[1]
    has_lens = lens.shape[1] > 0
    first = (0, 1, 2, 0, 0, 1)
    second = (0, 1, 2, 1, 2, 2)
    # the slots any of whose points is used without a merged duplicate (covariance's
    # ``if not np.any(use): continue``), and those with a blind point (motion_covariance's
    # ``if np.any(blind)``): a skipped slot adds nothing, not 0 * NaN
    any_use = np.zeros(m, dtype=np.bool_)
    any_blind = np.zeros(m, dtype=np.bool_)
    for p in range(k):
        for s in range(m):
            if slot_rows[p, s] >= 0:
                taken = False
                for t in range(s):  # merged into an earlier slot (merged_slots)
                    if slot_rows[p, t] == slot_rows[p, s]:
                        taken = True
                if not taken:
                    any_use[s] = True
            if used[p, s] and mrows[s, p, 1] < 0 and lag[s, p] > 0:
                any_blind[s] = True
    merged = np.empty((3, 2))
    cov = np.empty(6)
    unknown = np.empty(6)
    JL = np.empty((3, 2))
    for p in range(k):
        for e in range(6):
            cov[e] = 0.0
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
            taken = False
            for t in range(s):
                if row >= 0 and slot_rows[p, t] == row:
                    taken = True
            for i in range(3):
                merged[i, 0] = jac[s, i, 0, p]
                merged[i, 1] = jac[s, i, 1, p]
            if row >= 0 and not taken:
                for t in range(s + 1, m):
                    if slot_rows[p, t] == row:
                        for i in range(3):
                            merged[i, 0] += jac[t, i, 0, p]
                            merged[i, 1] += jac[t, i, 1, p]
            use = row >= 0 and not taken
            # J C (times_pixel_jacobian: C[0, 1] = 0 written out), zero where not used
            for i in range(3):
                if use:
                    JL[i, 0] = merged[i, 0] * C00 + merged[i, 1] * C10
                    JL[i, 1] = merged[i, 0] * 0.0 + merged[i, 1] * C11
                else:
                    JL[i, 0] = 0.0
                    JL[i, 1] = 0.0
            for e in range(6):
                a, b = first[e], second[e]
                cov[e] += JL[a, 0] * JL[b, 0] + JL[a, 1] * JL[b, 1]
        for e in range(6):
            cov[e] = cov[e] * s2[p]
        # the unknown shift of a slot without image velocity: Σ_s (v₀ L_s)² J_s J_sᵀ, summed
        # apart, then added (a sum of zeros where no slot is blind: adding it changes no bit)
        for e in range(6):
            unknown[e] = 0.0
        for s in range(m):
            if not any_blind[s]:
                continue
            blind = used[p, s] and mrows[s, p, 1] < 0 and lag[s, p] > 0
            f = lag[s, p] * unknown_speed
            f2 = f * f if blind else 0.0
            for e in range(6):
                a, b = first[e], second[e]
                unknown[e] += f2 * (jac[s, a, 0, p] * jac[s, b, 0, p]
                                    + jac[s, a, 1, p] * jac[s, b, 1, p])
        for e in range(6):
            cov[e] += unknown[e]
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
        c0 = cov[0] + m0 * m0
        c1 = cov[1] + m1 * m1
        c2 = cov[2] + m2 * m2
        out[0, p] = math.sqrt(c0 + c1 + c2)
        out[1, p] = c0
        out[2, p] = c1
        out[3, p] = c2
        out[4, p] = cov[3] + m0 * m1
        out[5, p] = cov[4] + m0 * m2
        out[6, p] = cov[5] + m1 * m2
