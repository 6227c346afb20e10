"""Type A's offline confirmation, compiled with numba: :func:`pslog.fusion.confirm.sides_test`
and the first confirming camera's test (:func:`pslog.fusion.confirm._tests_numpy`) point by
point.

:func:`~pslog.fusion.confirm.sides_test` (numpy over the points, a loop over the cameras)
states the test; on a session it made ~100 column operations per camera, 4-5x type A's own
time (a 60-s 4-camera rally: 17 → 47 ms), too dear for ``pslog fuse``'s default. This
kernel loops over the points and cameras instead, doing for each exactly the arithmetic of
those columns, in the same order (so the same decisions, to the bit:
``tests/test_type_a_confirm_sides.py`` runs both). The module's switches
(``CONFIRM_SIGMAS``, ``SIDES_NEARER``, ``SIDES_PROVEN_M``) are arguments, read at each call,
not constants frozen at compile time. Session 44: the first confirming camera's search and
test in the same loop (numpy's search over every point at each row after them, its (k,)
gathers and ~60 column operations of ``residual_test`` were 0.5 of type A's ~1.2 CPU s at
90 minutes; ``tests/test_type_a_confirm_compiled.py`` runs both).

Imported lazily (numba compiles on first use).
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel
from ..motion import G as _G
from ..records import NS as _NS
from .confirm import _NO_COV_FACTOR2  # (the one value: the cache stamp covers confirm.py)

#: ``NS ** 2`` as numpy makes it from ``NS`` (an int) in a float expression
_NS2 = float(_NS ** 2)


@kernel
def _residual(rows, c, px, py, pz, has_cov, c0, c1, c2, c3, c4, c5, t_ns, prev_ns, next_ns,
              up0, up1, un0, un1, gap_s, span_s, sigma, stated, sigmas):
    """:func:`pslog.fusion.confirm.residual_test` for one point and camera ``c`` (``c0..c5``
    its covariance xx, yy, zz, xy, xz, yz): True when the camera contradicts the point (NaN:
    not)."""
    r5, r6, r7 = rows[c, 5], rows[c, 6], rows[c, 7]
    x = r5 * px + r6 * py + r7 * pz + rows[c, 14]
    y = rows[c, 8] * px + rows[c, 9] * py + rows[c, 10] * pz + rows[c, 15]
    z = rows[c, 11] * px + rows[c, 12] * py + rows[c, 13] * pz + rows[c, 16]
    fx, s, cx, fy, cy = rows[c, 0], rows[c, 1], rows[c, 2], rows[c, 3], rows[c, 4]
    t = float(t_ns)
    d_prev = (t - float(prev_ns)) / _NS
    d_next = (float(next_ns) - t) / _NS
    w = d_prev / (d_prev + d_next)
    u_i = (1.0 - w) * up0 + w * un0
    v_i = (1.0 - w) * up1 + w * un1
    u = (fx * x + s * y) / z + cx
    v = fy * y / z + cy
    du, dv = u - u_i, v - v_i
    res = math.sqrt(du * du + dv * dv)
    interp = sigma * sigma * ((1.0 - w) * (1.0 - w) + w * w)
    use_cov = has_cov and stated != 0.0
    if not use_cov:
        a = interp + sigma * sigma * _NO_COV_FACTOR2
        cc = a
        b = 0.0
    else:
        q = sigma / stated
        scale = q * q
        ju0 = (fx * rows[c, 5] + s * rows[c, 8]) / z - (fx * x + s * y) * rows[c, 11] / (z * z)
        ju1 = (fx * rows[c, 6] + s * rows[c, 9]) / z - (fx * x + s * y) * rows[c, 12] / (z * z)
        ju2 = (fx * rows[c, 7] + s * rows[c, 10]) / z - (fx * x + s * y) * rows[c, 13] / (z * z)
        jv0 = fy * rows[c, 8] / z - fy * y * rows[c, 11] / (z * z)
        jv1 = fy * rows[c, 9] / z - fy * y * rows[c, 12] / (z * z)
        jv2 = fy * rows[c, 10] / z - fy * y * rows[c, 13] / (z * z)
        cxx, cyy, czz = c0 * scale, c1 * scale, c2 * scale
        cxy, cxz, cyz = c3 * scale, c4 * scale, c5 * scale
        a = (ju0 * (cxx * ju0 + cxy * ju1 + cxz * ju2)
             + ju1 * (cxy * ju0 + cyy * ju1 + cyz * ju2)
             + ju2 * (cxz * ju0 + cyz * ju1 + czz * ju2)) + interp
        cc = (jv0 * (cxx * jv0 + cxy * jv1 + cxz * jv2)
              + jv1 * (cxy * jv0 + cyy * jv1 + cyz * jv2)
              + jv2 * (cxz * jv0 + cyz * jv1 + czz * jv2)) + interp
        b = (ju0 * (cxx * jv0 + cxy * jv1 + cxz * jv2)
             + ju1 * (cxy * jv0 + cyy * jv1 + cyz * jv2)
             + ju2 * (cxz * jv0 + cyz * jv1 + czz * jv2))
    half = 0.5 * (a - cc)
    sigma_r = math.sqrt(0.5 * (a + cc) + math.sqrt(half * half + b * b))
    if use_cov and not math.isfinite(sigma_r):  # tested as without a covariance
        sigma_r = math.sqrt(interp + sigma * sigma * _NO_COV_FACTOR2)
    dist = math.sqrt(x * x + y * y + z * z)
    per_m = max(fx, fy) * dist / (z * z)
    model = 0.5 * _G * (abs(d_prev * d_next) + gap_s * span_s) * per_m
    return res > sigmas * sigma_r + model


@kernel(inline=True)
def _after(rows_c, r, at_row, c):
    """``np.searchsorted(rows_c, r, side="right")`` (``rows_c`` sorted), found from camera
    ``c``'s last answer ``at_row[c]`` onward (and kept there): the points come in row order,
    so each camera's index only moves forward, a step or two a point (a binary search over
    a camera's rows where the rows went back)."""
    j = at_row[c]
    nc = rows_c.shape[0]
    if j > nc or (j > 0 and rows_c[j - 1] > r):
        j = np.searchsorted(rows_c, r, side="right")
    else:
        while j < nc and rows_c[j] <= r:
            j += 1
    at_row[c] = j
    return j


@kernel
def confirm_kernel(rows, time_ns, camera, uv, row, at, point, has_cov, cov, gap_s, span_s,
                   sigma, stated, max_gap_ns, by_camera, starts, sigmas, first, sides, nearer,
                   proven_m, first_bad, ok, bad, checked):
    """:func:`pslog.fusion.confirm.confirm_batch`'s tests of k points, compiled: with
    ``first``, the first confirming camera's interpolation (the confirming row found as
    ``confirm_batch``'s numpy search finds it, the test :func:`pslog.fusion.confirm.
    residual_test`'s) into ``first_bad`` and ``ok`` (k,) bool (``ok``: a confirming row
    found; ``first_bad`` False without one); with ``sides``, :func:`pslog.fusion.confirm.
    sides_test` into ``bad`` and ``checked`` (k,) bool. Each output written only where its
    test runs.

    The i-th point's values are at ``at[i]`` of the per-point arrays: ``row`` (its row in
    the observations), ``point`` (., 3), ``cov`` (six (.,) columns xx, yy, zz, xy, xz, yz;
    read only with ``has_cov``), ``gap_s``, ``span_s``, ``sigma`` (so the track's own
    columns are read without a gather). ``rows``, ``time_ns``, ``camera``, ``uv``,
    ``stated``, ``max_gap_ns`` as :func:`~pslog.fusion.confirm.sides_test`'s (``stated``
    the stated noise, 0: none); ``by_camera`` the rows of each camera in order, camera
    ``c``'s at ``by_camera[starts[c]:starts[c + 1]]``; ``sigmas``
    :data:`~pslog.fusion.confirm.CONFIRM_SIGMAS`, ``nearer``
    :data:`~pslog.fusion.confirm.SIDES_NEARER`, ``proven_m``
    :data:`~pslog.fusion.confirm.SIDES_PROVEN_M` (NaN: off)."""
    k = at.shape[0]
    m = rows.shape[0]
    n = time_ns.shape[0]
    c0 = c1 = c2 = c3 = c4 = c5 = 0.0
    at_row = np.zeros(m, dtype=np.int64)  # each camera's last index found (:func:`_after`)
    for i in range(k):
        pi = at[i]
        ei = row[pi]
        t = time_ns[ei]
        tt = float(t)
        px, py, pz = point[pi, 0], point[pi, 1], point[pi, 2]
        sg = sigma[pi]
        gs, ss = gap_s[pi], span_s[pi]
        if has_cov:
            c0, c1, c2 = cov[0][pi], cov[1][pi], cov[2][pi]
            c3, c4, c5 = cov[3][pi], cov[4][pi], cov[5][pi]
        ce = camera[ei]
        if first:
            # the confirming detection: the first later row of another camera that can
            # check the point (its camera's latest row before the point's within
            # max_gap_ns of it, both pixels finite), within max_gap_ns of the point
            found = False
            r = ei + 1
            b = -1
            cr = -1
            while r < n and time_ns[r] - t <= max_gap_ns:
                cr = camera[r]
                if cr != ce:
                    lo = starts[cr]
                    # (c's rows before the point's: searchsorted's index, side either: the
                    # point's row is another camera's)
                    j = _after(by_camera[lo:starts[cr + 1]], ei, at_row, cr)
                    if j >= 1:
                        b = by_camera[lo + j - 1]
                        if (t - time_ns[b] <= max_gap_ns and math.isfinite(uv[b, 0])
                                and math.isfinite(uv[b, 1]) and math.isfinite(uv[r, 0])
                                and math.isfinite(uv[r, 1])):
                            found = True
                            break
                r += 1
            ok[i] = found
            first_bad[i] = found and _residual(
                rows, cr, px, py, pz, has_cov, c0, c1, c2, c3, c4, c5, t, time_ns[b],
                time_ns[r], uv[b, 0], uv[b, 1], uv[r, 0], uv[r, 1], gs, ss, sg, stated,
                sigmas)
        if not sides:
            continue
        bad[i] = False
        checked[i] = False
        for c in range(m):
            lo, hi = starts[c], starts[c + 1]
            nc = hi - lo
            if nc == 0 or ce == c:
                continue
            rows_c = by_camera[lo:hi]
            j = _after(rows_c, ei, at_row, c)  # c's first row after the point's
            if j < 1 or j >= nc:
                continue
            p1, n1 = rows_c[j - 1], rows_c[j]
            if t - time_ns[p1] > max_gap_ns or time_ns[n1] - t > max_gap_ns:
                continue
            if not (math.isfinite(uv[p1, 0]) and math.isfinite(uv[p1, 1])
                    and math.isfinite(uv[n1, 0]) and math.isfinite(uv[n1, 1])):
                continue
            p2 = rows_c[max(j - 2, 0)]
            n2 = rows_c[min(j + 1, nc - 1)]
            full = (j >= 2 and j + 1 < nc and math.isfinite(uv[p2, 0])
                    and math.isfinite(uv[p2, 1]) and math.isfinite(uv[n2, 0])
                    and math.isfinite(uv[n2, 1])
                    and time_ns[p1] - time_ns[p2] <= max_gap_ns
                    and time_ns[n2] - time_ns[n1] <= max_gap_ns)
            x = rows[c, 5] * px + rows[c, 6] * py + rows[c, 7] * pz + rows[c, 14]
            y = rows[c, 8] * px + rows[c, 9] * py + rows[c, 10] * pz + rows[c, 15]
            zc = rows[c, 11] * px + rows[c, 12] * py + rows[c, 13] * pz + rows[c, 16]
            tp2, tp1 = float(time_ns[p2]), float(time_ns[p1])
            tn1, tn2 = float(time_ns[n1]), float(time_ns[n2])
            # the forward line's miss at n1: a jump inside [p1, n1] (or [p2, p1])
            wf = (tn1 - tp2) / (tp1 - tp2)
            miss = math.hypot((1 - wf) * uv[p2, 0] + wf * uv[p1, 0] - uv[n1, 0],
                              (1 - wf) * uv[p2, 1] + wf * uv[p1, 1] - uv[n1, 1])
            dist = math.sqrt(x * x + y * y + zc * zc)
            per_m = max(rows[c, 0], rows[c, 3]) * dist / (zc * zc)
            bound = (sigmas * sg * math.sqrt((1 - wf) * (1 - wf) + wf * wf + 1)
                     + 0.5 * _G * (tn1 - tp1) * (tn1 - tp2) / _NS2 * per_m)
            jump = full and miss > bound
            # the side: D(s) = f(s) - b(s), f through p2, p1 and b through n1, n2
            vf0 = (uv[p1, 0] - uv[p2, 0]) / (tp1 - tp2)
            vf1 = (uv[p1, 1] - uv[p2, 1]) / (tp1 - tp2)
            vb0 = (uv[n2, 0] - uv[n1, 0]) / (tn2 - tn1)
            vb1 = (uv[n2, 1] - uv[n1, 1]) / (tn2 - tn1)
            ft0 = uv[p1, 0] + vf0 * (tt - tp1)
            ft1 = uv[p1, 1] + vf1 * (tt - tp1)
            bt0 = uv[n1, 0] + vb0 * (tt - tn1)
            bt1 = uv[n1, 1] + vb1 * (tt - tn1)
            before = (ft0 - bt0) * (vf0 - vb0) + (ft1 - bt1) * (vf1 - vb1) > 0
            fx, sk, cx, fy, cy = rows[c, 0], rows[c, 1], rows[c, 2], rows[c, 3], rows[c, 4]
            u = (fx * x + sk * y) / zc + cx
            v = fy * y / zc + cy
            to_f = math.hypot(u - ft0, v - ft1)
            to_b = math.hypot(u - bt0, v - bt1)
            af = (tt - tp2) / (tp1 - tp2)
            ab = (tt - tn1) / (tn2 - tn1)
            sep_bound = (sigmas * sg * math.sqrt((1 - af) * (1 - af) + af * af
                                                 + (1 - ab) * (1 - ab) + ab * ab)
                         + 0.5 * _G * ((tt - tp1) * (tt - tp2) + (tn1 - tt) * (tn2 - tt))
                         / _NS2 * per_m)
            wrong = (jump and math.hypot(ft0 - bt0, ft1 - bt1) > sep_bound
                     and ((to_b > to_f) if before else (to_f > to_b)))
            if jump:
                ra, rb = (n1, n2) if before else (p2, p1)
            else:
                ra, rb = p1, n1
            verdict = _residual(rows, c, px, py, pz, has_cov, c0, c1, c2, c3, c4, c5, t,
                                time_ns[ra], time_ns[rb], uv[ra, 0], uv[ra, 1], uv[rb, 0],
                                uv[rb, 1], gs, ss, sg, stated, sigmas)
            if not math.isnan(proven_m):
                # the distance the camera proves: the residual less the reference's own
                # noise and model bound, over the pixels per metre across its ray
                ta, tb = float(time_ns[ra]), float(time_ns[rb])
                w = (tt - ta) / (tb - ta)
                ref0 = (1 - w) * uv[ra, 0] + w * uv[rb, 0]
                ref1 = (1 - w) * uv[ra, 1] + w * uv[rb, 1]
                excess = (math.hypot(u - ref0, v - ref1)
                          - sigmas * sg * math.sqrt((1 - w) * (1 - w) + w * w)
                          - 0.5 * _G * abs((tt - ta) * (tt - tb)) / _NS2 * per_m)
                verdict = verdict or excess > proven_m * per_m
            if verdict or (nearer and wrong):
                bad[i] = True
            checked[i] = True


def _preload() -> None:
    """:func:`confirm_kernel` (and :func:`_residual`) loaded from numba's cache (or
    compiled) now, in the one signature :func:`pslog.fusion.confirm._run_kernel` calls it
    in (every array read-only and C-contiguous, the cameras int32): called by
    :func:`pslog._jit.preload` on its thread while ``pslog fuse`` reads its session, so that
    type A's offline confirmation (the default) does not pay the load (~20 ms) on its way."""
    def ro(a):
        a.flags.writeable = False
        return a

    f, i = np.float64, np.int64
    confirm_kernel(ro(np.zeros((1, 17))), ro(np.zeros(0, dtype=i)),
                   ro(np.zeros(0, dtype=np.int32)), ro(np.zeros((0, 2))),
                   ro(np.zeros(0, dtype=i)), ro(np.zeros(0, dtype=i)), ro(np.zeros((0, 3))),
                   False, tuple(ro(np.zeros(0, dtype=f)) for _ in range(6)),
                   ro(np.zeros(0)), ro(np.zeros(0)), ro(np.zeros(0)), 0.0, 0,
                   ro(np.zeros(0, dtype=i)), ro(np.zeros(2, dtype=i)), 4.0, True, True, True,
                   np.nan, *(np.empty(0, dtype=np.bool_) for _ in range(4)))
