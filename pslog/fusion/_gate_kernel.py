"""The stream gate's per-frame work, compiled (:class:`pslog.fusion.gating.StreamGate`).

:class:`~pslog.fusion.gating.StreamGate` decides each frame as :func:`~pslog.fusion.gating.gate`
would, on Python floats in the batch's order of operations (bit for bit). Live, one frame
costs about 7,000 Python bytecodes and 500 allocations (its candidates' support by every
other camera, their 3D points, their stillness, the sequential choice with the track's
ballistic fit): ~0.1 ms on a warm core, ~0.4 ms on a core gone cold in the 11 ms between two
30 fps datagrams. This module holds the same steps as kernels (:func:`pslog._jit.kernel`)
over a state kept in preallocated arrays, one call per pushed frame: the same floating-point
operations in the same order on the same history, so the same bits and the same decisions
(``tests/test_gate_kernel.py`` compares it with the Python form, and the stream with the
batch gate). Each function names the Python one it mirrors in :mod:`pslog.fusion.gating`.

The batch gate (:func:`~pslog.fusion.gating.gate`) uses them too, where this module is
loaded (``pslog fuse`` preloads it), its numpy and Python forms otherwise: every candidate's
support, 3D point and stillness in arrays (:func:`support_all`, :func:`points_all`,
:func:`static_camera`: the numpy forms' bits), and, on a session whose frames the Python
decider would mostly decide one by one (a static object, blobs, misses, two cameras:
``gating._decide_compiled``), the whole sequential choice in one call (:func:`gate_frames`
over a :class:`GateState` holding every frame: :func:`decide_at` per frame, the stream's
steps, in the causal form or the offline one, ``opt[O_CAUSAL]``), the same choices as the
Python decider (``tests/test_gate_whole.py``).

Two of Python's float operations are not the compiled ones and are reproduced on purpose:

- ``x ** 2`` is C's ``pow(x, 2.0)`` in CPython, which differs from ``x * x`` in the last
  bit on ~0.1 % of values (glibc); the kernels call ``pow`` with an exponent read from the
  state (``two``), which the compiler cannot turn into a product;
- the built-in ``sum`` of floats is a plain running sum up to Python 3.11 and Neumaier's
  compensated sum from 3.12 (Neumaier 1974, "Rundungsfehleranalyse einiger Verfahren zur
  Summation endlicher Summen", ZAMM 54: 39-51): :data:`SUM_MODE` says which one this Python
  has (probed at import), and :func:`_sum_add` reproduces it; on a Python whose ``sum`` is
  neither, :data:`SUM_MODE` is -1 and the stream gate keeps its Python form.

State layout (``m`` cameras, ``H`` frames kept per camera, ``K`` candidates per frame; each
camera's frames in (key, push) order at rows ``0 .. count[c]-1``):

- ``fi`` (m, H, 4) int64: key (the first candidate's corrected time, ns), logged time ns,
  push id, number of candidates;
- ``fflag`` (m, H, 2) int8: decided, support narrowed (1: decided with a rejected candidate:
  only its chosen and outscored candidates still support, :func:`gating._supporting`; 2:
  offline, decided with every candidate rejected: it supports with every candidate or as
  an empty frame, the better, :func:`gating._emptied`);
- ``ct`` (m, H, K) int64 corrected times; ``cf`` (m, H, K, 9) float64: undistorted u, v,
  unit ray x, y, z, the all-candidates 3D point x, y, z, whether its support held (1.0, else
  0.0; NaN until decided: gating._held); ``csup`` (m, H, K) int8: may support;
- ``trk`` (4 P + 1, 5) float64: the track's points (time s, x, y, z, age s), ``ist`` int64:
  [points in the track, verified, tracked, next push id].
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel

#: rejection codes, as pslog.fusion.gating's (and its CONTESTED choice's)
_EPIPOLAR, _TRACK, _MOTION, _OUTSCORED = 0, 1, 2, 3
_CONTESTED = -2
#: gating.DOUBT_RADIUS_PX squared (undistorted pixels here, as gating._refused_near)
_DOUBT_RADIUS2 = 5.0 * 5.0
_NS = 1_000_000_000
_MIN_DET = 1e-12
_I64_MIN = int(np.iinfo(np.int64).min)
#: rows of ``opt`` (float64 options and constants, see :func:`options_array`)
(O_EPI, O_VMAX, O_HALF_ACCEL, O_TRACK_M, O_JUMP, O_WINDOW, O_MAX_SPEED, O_LOOSE, O_STATIC_S,
 O_STATIC_M, O_ALONE, O_G, O_TWO, O_TRACK_POINTS, O_WAIT, O_GAP, O_SUM, O_LONG_STILL,
 O_LONG_STILL_C, O_CAUSAL, O_SEVERAL) = range(21)
N_OPT = 21


def _python_sum_mode() -> int:
    """0: this Python's ``sum`` of floats is a plain running sum (<= 3.11); 1: Neumaier's
    compensated sum as CPython 3.12 adds it; -1: neither (the kernels are not used)."""
    probes = ([0.1] * 10, [1.0, 1e100, 1.0, -1e100], [-0.0], [1e308, 1e308, -1e308],
              [0.3, -0.1, 1e-17, 2.5e-16, -0.2], [math.inf, 1.0], [math.nan, 1.0])
    for mode in (0, 1):
        ok = True
        for p in probes:
            f, c = 0.0, 0.0
            for x in p:
                f, c = _sum_add.py_func(f, c, x, mode)  # uncompiled: import stays light
            mine, theirs = _sum_end.py_func(f, c, mode), sum(p)
            if not (mine == theirs or (mine != mine and theirs != theirs)) or (
                    math.copysign(1.0, mine) != math.copysign(1.0, theirs)):
                ok = False
        if ok:
            return mode
    return -1


@kernel
def _sum_add(f, c, x, mode):
    """One float added to a running ``sum`` (``f``, compensation ``c``) as this Python's
    built-in ``sum`` adds it (``mode``: :data:`SUM_MODE`)."""
    if mode == 0:
        return f + x, c
    t = f + x
    if abs(f) >= abs(x):
        c += (f - t) + x
    else:
        c += (x - t) + f
    return t, c


@kernel
def _sum_end(f, c, mode):
    if mode == 1 and c != 0.0 and math.isfinite(c):
        return f + c
    return f


#: how this Python's ``sum`` adds floats (:func:`_python_sum_mode`)
SUM_MODE = _python_sum_mode()


@kernel
def _pymax(a, b):
    """Python's ``max(a, b)``: ``b`` only when ``b > a`` (NaN as Python orders it)."""
    return b if b > a else a


@kernel
def _pymin(a, b):
    """Python's ``min(a, b)``."""
    return b if b < a else a


@kernel
def _sqrt(x):
    """gating._sqrt: NaN for a negative or NaN argument."""
    return math.sqrt(x) if x >= 0 else math.nan


@kernel
def _line_of(f, u, v):
    """gating._line_of (``f``: F_ab (3, 3))."""
    a = (f[0, 0] * u + f[0, 1] * v) + f[0, 2]
    b = (f[1, 0] * u + f[1, 1] * v) + f[1, 2]
    if not _pymax(abs(a), abs(b)) > 0 or not math.isfinite(a) or not math.isfinite(b):
        return math.nan, math.nan, math.nan
    c = (f[2, 0] * u + f[2, 1] * v) + f[2, 2]
    big = _pymax(abs(a), abs(b))
    a, b, c = a / big, b / big, c / big
    size = _sqrt(a * a + b * b)
    return a / size, b / size, c / size


@kernel
def _n_usable(csup, b, j, n, flag, mode):
    """How many candidates of camera b's frame j (``flag``: its ``fflag[b, j, 1]``) may
    support: all where ``mode`` is 0 (every candidate) or the frame is undecided or chosen
    from whole; a narrowed frame's (flag 1) chosen and outscored; an emptied frame's
    (flag 2, every candidate rejected offline) all in ``mode`` 1, none in ``mode`` 2 (it
    carries as the empty frame it is for the ball: gating._support_one's two carries)."""
    if mode == 0 or flag == 0:
        return n
    if flag == 2:
        return 0 if mode == 2 else n
    got = 0
    for q in range(n):
        if csup[b, j, q]:
            got += 1
    return got


@kernel
def support_one(t, l0, l1, l2, b, keys, fi, fflag, ct, cf, csup, right, mode, opt):
    """gating._support_one for one candidate at corrected time ``t`` (its epipolar line
    ``l`` in camera b) over b's kept frames (``keys``: their times): from every candidate
    (``mode`` 0) or as decided (:func:`_n_usable`: 1 with the frames decided with every
    candidate rejected, 2 without them). ``right``: bisect_right (else bisect_left). Causal where
    ``opt[O_CAUSAL]`` (the frames up to ``t`` + wait); else offline: the two usable frames
    around ``t`` (interpolated), extrapolated from the two before only where b has no usable
    frame after ``t`` (the batch gate's offline form, :func:`gate_frames`).
    Returns (ratio, carried u, carried v, found): ratio NaN when no frame is near."""
    epi, vmax, half_accel = opt[O_EPI], opt[O_VMAX], opt[O_HALF_ACCEL]
    wait, gap = np.int64(opt[O_WAIT]), np.int64(opt[O_GAP])
    causal = opt[O_CAUSAL] != 0.0
    target = t + wait if causal else t
    last = (np.searchsorted(keys, target, side="right") if right
            else np.searchsorted(keys, target, side="left")) - 1
    i1 = last
    while i1 >= 0 and _n_usable(csup, b, i1, fi[b, i1, 3], fflag[b, i1, 1],
                                mode) == 0:
        i1 -= 1
    i0 = i1 - 1
    while i0 >= 0 and _n_usable(csup, b, i0, fi[b, i0, 3], fflag[b, i0, 1],
                                mode) == 0:
        i0 -= 1
    inext = -1
    if not causal:
        inext = last + 1
        while inext < keys.shape[0] and _n_usable(csup, b, inext, fi[b, inext, 3],
                                                  fflag[b, inext, 1], mode) == 0:
            inext += 1
        if inext == keys.shape[0]:
            inext = -1
    # the pair: interpolated between i1 and inext, else extrapolated from i0 and i1
    p0, p1 = (i1, inext) if inext >= 0 else (i0, i1)
    near0 = p0 >= 0 and abs(t - keys[p0]) <= gap
    near1 = i1 >= 0 and abs(t - keys[i1]) <= gap
    near_p1 = p1 >= 0 and abs(t - keys[p1]) <= gap
    if near0 and near_p1:
        best, bu, bv, found = math.inf, math.nan, math.nan, False
        only0 = mode != 0 and fflag[b, p0, 1] == 1
        only1 = mode != 0 and fflag[b, p1, 1] == 1
        for q0 in range(fi[b, p0, 3]):
            if only0 and not csup[b, p0, q0]:
                continue
            t0, u0, v0 = ct[b, p0, q0], cf[b, p0, q0, 0], cf[b, p0, q0, 1]
            for q1 in range(fi[b, p1, 3]):
                if only1 and not csup[b, p1, q1]:
                    continue
                t1, u1, v1 = ct[b, p1, q1], cf[b, p1, q1, 0], cf[b, p1, q1, 1]
                span = (t1 - t0) / _NS
                if not span > 0:
                    continue
                w = (t - t0) / _NS / span
                du, dv = u1 - u0, v1 - v0
                yu, yv = u0 + w * du, v0 + w * dv
                if not math.sqrt(du * du + dv * dv) / abs(span) <= vmax:
                    continue
                tau = epi + half_accel * abs(t - t0) / _NS * abs(t - t1) / _NS
                d = abs(l0 * yu + l1 * yv + l2)
                if math.isfinite(d) and d / tau < best:  # argmin: the first
                    best, bu, bv, found = d / tau, yu, yv, True
        return best, bu, bv, found
    if near1:  # a single nearby frame, its candidates as they are
        best, bu, bv, found = math.inf, math.nan, math.nan, False
        only1 = mode != 0 and fflag[b, i1, 1] == 1
        for q1 in range(fi[b, i1, 3]):
            if only1 and not csup[b, i1, q1]:
                continue
            t1, u1, v1 = ct[b, i1, q1], cf[b, i1, q1, 0], cf[b, i1, q1, 1]
            tau = epi + vmax * (abs(t - t1) / _NS)
            d = abs(l0 * u1 + l1 * v1 + l2)
            r = d / tau if math.isfinite(d) else math.inf
            if not found or r < best:
                best, bu, bv, found = r, u1, v1, True
        return best, bu, bv, found
    return math.nan, math.nan, math.nan, False


@kernel
def _carried_ray(u, v, k_inv, r):
    """gating._carried_ray on floats (``k_inv``, ``r``: (3, 3))."""
    cx = (k_inv[0, 0] * u + k_inv[0, 1] * v) + k_inv[0, 2]
    cy = (k_inv[1, 0] * u + k_inv[1, 1] * v) + k_inv[1, 2]
    cz = (k_inv[2, 0] * u + k_inv[2, 1] * v) + k_inv[2, 2]
    x = (cx * r[0, 0] + cy * r[1, 0]) + cz * r[2, 0]
    y = (cx * r[0, 1] + cy * r[1, 1]) + cz * r[2, 1]
    z = (cx * r[0, 2] + cy * r[1, 2]) + cz * r[2, 2]
    s = _sqrt((x * x + y * y) + z * z)
    return x / s, y / s, z / s


@kernel
def points_one(a, ray, ratio, carried, centers, k_inv, rot, rays):
    """gating._points_one of one candidate of camera ``a`` (``ray`` (3,), its ``ratio``
    (m,) and ``carried`` (m, 2) rows; ``rays`` (m + 1, 6) scratch). Returns (solved, x, y, z,
    in_front, miss): solved False is gating's None (x, y, z NaN)."""
    n = 0
    if math.isfinite(ray[0]) and math.isfinite(ray[1]) and math.isfinite(ray[2]):
        rays[0, 0], rays[0, 1], rays[0, 2] = centers[a, 0], centers[a, 1], centers[a, 2]
        rays[0, 3], rays[0, 4], rays[0, 5] = ray[0], ray[1], ray[2]
        n = 1
    for b in range(len(ratio)):
        if ratio[b] <= 1.0:
            dx, dy, dz = _carried_ray(carried[b, 0], carried[b, 1], k_inv[b], rot[b])
            if math.isfinite(dx) and math.isfinite(dy) and math.isfinite(dz):
                rays[n, 0], rays[n, 1], rays[n, 2] = centers[b, 0], centers[b, 1], centers[b, 2]
                rays[n, 3], rays[n, 4], rays[n, 5] = dx, dy, dz
                n += 1
    if n < 2:
        return False, math.nan, math.nan, math.nan, True, math.nan
    # gating._normal_equations (w = 1.0 for every ray used: kept, x * 1.0 is x)
    a00 = a01 = a02 = a11 = a12 = a22 = b0 = b1 = b2 = 0.0
    for i in range(n):
        ox, oy, oz, dx, dy, dz = rays[i, 0], rays[i, 1], rays[i, 2], rays[i, 3], rays[i, 4], \
            rays[i, 5]
        p00, p11, p22 = (1.0 - dx * dx) * 1.0, (1.0 - dy * dy) * 1.0, (1.0 - dz * dz) * 1.0
        p01, p02, p12 = (0.0 - dx * dy) * 1.0, (0.0 - dx * dz) * 1.0, (0.0 - dy * dz) * 1.0
        a00, a01, a02 = a00 + p00, a01 + p01, a02 + p02
        a11, a12, a22 = a11 + p11, a12 + p12, a22 + p22
        b0 = b0 + ((p00 * ox + p01 * oy) + p02 * oz)
        b1 = b1 + ((p01 * ox + p11 * oy) + p12 * oz)
        b2 = b2 + ((p02 * ox + p12 * oy) + p22 * oz)
    c00, c01, c02 = a11 * a22 - a12 * a12, a02 * a12 - a01 * a22, a01 * a12 - a02 * a11
    c11, c12, c22 = a00 * a22 - a02 * a02, a01 * a02 - a00 * a12, a00 * a11 - a01 * a01
    det = (a00 * c00 + a01 * c01) + a02 * c02
    if not abs(det) > _MIN_DET:
        return False, math.nan, math.nan, math.nan, False, math.nan
    px = ((c00 * b0 + c01 * b1) + c02 * b2) / det
    py = ((c01 * b0 + c11 * b1) + c12 * b2) / det
    pz = ((c02 * b0 + c12 * b1) + c22 * b2) / det
    total = 0.0
    in_front = True
    for i in range(n):  # gating._ray_offsets
        fx, fy, fz = px - rays[i, 0], py - rays[i, 1], pz - rays[i, 2]
        dx, dy, dz = rays[i, 3], rays[i, 4], rays[i, 5]
        along = (fx * dx + fy * dy) + fz * dz
        qx, qy, qz = fx - along * dx, fy - along * dy, fz - along * dz
        in_front = in_front and along > 0
        total = total + ((qx * qx + qy * qy) + qz * qz)
    return True, px, py, pz, in_front, math.sqrt(total / n)



@kernel
def held_one(a, ray, ratio, carried, miss, track_m, centers, k_inv, rot, rays, r_one):
    """gating._held_one of a candidate of camera ``a`` without a point (``ray`` (3,), its
    ``ratio`` (m,) and ``carried`` (m, 2) rows, its all-supports point's ``miss``; ``rays``
    (m + 1, 6) and ``r_one`` (m,) scratch): two or more supports whose rays missed (more than
    ``track_m``), one of which alone makes a point with its ray within ``track_m``."""
    m = len(ratio)
    if not miss > track_m:
        return False
    n_sup = 0
    for b in range(m):
        if ratio[b] <= 1.0:
            n_sup += 1
    if n_sup < 2:
        return False
    for b in range(m):
        if not ratio[b] <= 1.0:
            continue
        for q in range(m):
            r_one[q] = math.inf
        r_one[b] = ratio[b]
        ok, _x, _y, _z, _front, miss_one = points_one(a, ray, r_one, carried, centers, k_inv,
                                                      rot, rays)
        if ok and miss_one <= track_m:
            return True
    return False


@kernel
def points_all(camera, ray_dir, ratio, carried, centers, k_inv, rot, points, in_front, miss):
    """gating._points of every candidate: :func:`points_one` of each row (``camera`` (C,),
    ``ray_dir`` (C, 3), ``ratio`` (C, m), ``carried`` (C, m, 2)), written into ``points``
    (C, 3), ``in_front`` (C,) bool and ``miss`` (C,): the numpy form's values, the same bits
    (its sums over unused rays add zeros; each candidate's arithmetic in its order)."""
    rays = np.empty((ratio.shape[1] + 1, 6))
    for i in range(len(camera)):
        _solved, x, y, z, front, ms = points_one(camera[i], ray_dir[i], ratio[i], carried[i],
                                                 centers, k_inv, rot, rays)
        points[i, 0], points[i, 1], points[i, 2] = x, y, z
        in_front[i] = front
        miss[i] = ms


@kernel
def _bisect(keys, x, right):
    """``bisect.bisect_right`` (``right``) or ``bisect_left`` of ``x`` in sorted ``keys``."""
    lo, hi = 0, len(keys)
    while lo < hi:
        mid = (lo + hi) // 2
        if keys[mid] < x or (right and keys[mid] == x):
            lo = mid + 1
        else:
            hi = mid
    return lo


@kernel
def support_all(rows, b, t_all, uv, lines, times, table, causal, right, wait_ns, gap_ns,
                epi, vmax, half_accel, ratio, carried, used):
    """gating._support's rule for the candidates ``rows`` of one camera a and one other
    camera b (its frame table: ``times`` (F,), ``table`` (F, K) candidate rows, -1
    padding), every candidate of b's frames supporting: writes ``ratio[rows, b]``,
    ``carried[rows, b]`` and ``used[rows, b]`` as the numpy form does, one candidate at a
    time in its order of operations (the same bits). ``t_all`` (C,) corrected times, ``uv``
    (C, 2) undistorted pixels, ``lines`` (len(rows), 3) each candidate's epipolar line in
    b; ``causal``: b's frames up to ``t + wait_ns`` (``right``: bisect_right, else left),
    else offline (interpolation between the frames around t where both are near);
    ``gap_ns``: frames further than this give no support; ``epi``, ``vmax``,
    ``half_accel``: GatingOptions' epipolar_px, max_image_speed_px_s, 0.5 accel_px_s2."""
    n_f, k_max = table.shape[0], table.shape[1]
    for i in range(len(rows)):
        r = rows[i]
        t = t_all[r]
        if causal:
            last = _bisect(times, t + wait_ns, right) - 1
            inext = -1
        else:
            last = _bisect(times, t, True) - 1
            inext = last + 1 if last + 1 < n_f else -1
        i1, i0 = last, last - 1
        used[r, b, 0], used[r, b, 1], used[r, b, 2] = i0, i1, inext
        l0, l1, l2 = lines[i, 0], lines[i, 1], lines[i, 2]
        best, bu, bv = math.inf, math.nan, math.nan
        near = False
        # interpolation between the frames around t, else extrapolation from the two
        # latest at or before it (only where no later frame exists)
        for extrapolate in range(2):
            if extrapolate == 0:
                first, second = i1, inext
            else:
                first, second = i0, i1
                if inext >= 0:
                    continue
            if first < 0 or second < 0:
                continue
            if not (abs(t - times[first]) <= gap_ns and abs(t - times[second]) <= gap_ns):
                continue
            near = True
            for q0 in range(k_max):  # numpy's argmin over (q0, q1): the first smallest
                r0 = table[first, q0]
                if r0 < 0:
                    continue
                t0, u0, v0 = t_all[r0], uv[r0, 0], uv[r0, 1]
                for q1 in range(k_max):
                    r1 = table[second, q1]
                    if r1 < 0:
                        continue
                    t1, u1, v1 = t_all[r1], uv[r1, 0], uv[r1, 1]
                    span = (t1 - t0) / _NS
                    if not span > 0:
                        continue
                    du, dv = u1 - u0, v1 - v0
                    if not math.sqrt(du * du + dv * dv) / abs(span) <= vmax:
                        continue
                    w = (t - t0) / _NS / span
                    yu, yv = u0 + w * du, v0 + w * dv
                    tau = epi + half_accel * abs(t - t0) / _NS * abs(t - t1) / _NS
                    d = abs(l0 * yu + l1 * yv + l2)
                    if math.isfinite(d) and d / tau < best:
                        best, bu, bv = d / tau, yu, yv
        # a single nearby frame (the other camera missed the one before): its candidates
        # as they are, allowing the image motion a ball can make since
        if not near and i1 >= 0 and abs(t - times[i1]) <= gap_ns:
            near = True
            for q1 in range(k_max):
                r1 = table[i1, q1]
                rr = r1 if r1 >= 0 else 0
                y0, y1 = uv[rr, 0], uv[rr, 1]
                tau = epi + vmax * (abs(t - t_all[rr]) / _NS)
                d = abs(l0 * y0 + l1 * y1 + l2)
                rv = d / tau if (r1 >= 0 and math.isfinite(d)) else math.inf
                if q1 == 0 or rv < best:  # argmin: the first smallest, 0 when all inf
                    best, bu, bv = rv, y0, y1
        if near:
            ratio[r, b] = best
        carried[r, b, 0], carried[r, b, 1] = bu, bv


@kernel
def static_camera(times, table, points, uv, finite, paired, dz, lags, long_lags, recent_ns,
                  recent_long_ns, focal_static, center, long_t, static_m, long_c, g,
                  static, stillness, lone):
    """gating._static for one camera's frames (``times`` (F,), ``table`` (F, K) candidate
    rows, -1 padding), every earlier frame's candidates counting: sets ``static`` and
    ``stillness`` of its candidates, one candidate at a time with _stillness_one's floats
    (the same decisions, the same stillness). ``points`` (C, 3), ``uv`` (C, 2) undistorted
    pixels, ``finite`` (C,) whether each one's support held (gating._held: has a point, or
    one of its supports whose rays missed makes one), ``paired`` (C,) its point rests on one
    other camera (the image tests), ``dz`` (C,) its ray's world z; ``lags`` and
    ``long_lags``: frames of the 3D / image test and of the long image test; ``recent_ns``,
    ``recent_long_ns``: how far back those frames may lie (1.5 static_s, 1.5 LONG_STILL
    static_s, ns); ``focal_static``: min(f_x, f_y) static_m (_still_px); ``center`` (3,)
    the camera's; ``long_t``: long_lags / fps; ``long_c``: LONG_STILL_C; ``g``: gravity.
    Sets ``lone`` (gating._static's third value) too: the image test counted with each
    candidate's own tolerance, whatever supports it (without a point: the tolerance of a
    point known at its pixel, gating._borrowed_tolerance; then the long test's verdict too)."""
    n_f, k_max = table.shape[0], table.shape[1]
    top = min(long_lags, n_f - 1)
    for f in range(n_f):
        for q in range(k_max):
            r = table[f, q]
            if r < 0:
                continue
            x, y, z = points[r, 0], points[r, 1], points[r, 2]
            u, v = uv[r, 0], uv[r, 1]
            # _still_px (NaN without a point), NaN too where the image test does not apply
            ex, ey, ez = x - center[0], y - center[1], z - center[2]
            dd = (ex * ex + ey * ey) + ez * ez
            own = focal_static / (math.sqrt(dd) if dd >= 0 else math.nan)
            tol = own if paired[r] else math.nan
            borrowed = False
            if not own == own:  # gating._borrowed_tolerance: a point known at its pixel
                for lag in range(1, lags + 1):
                    if f < lag:
                        break
                    if not times[f] - times[f - lag] <= recent_ns:
                        continue
                    found = math.inf
                    for q2 in range(k_max):
                        r2 = table[f - lag, q2]
                        if r2 < 0:
                            continue
                        px, py, pz = points[r2, 0], points[r2, 1], points[r2, 2]
                        if px == px and py == py and pz == pz:
                            fx, fy, fz = px - center[0], py - center[1], pz - center[2]
                            dd2 = (fx * fx + fy * fy) + fz * fz
                            own2 = focal_static / (math.sqrt(dd2) if dd2 >= 0 else math.nan)
                            du, dv = u - uv[r2, 0], v - uv[r2, 1]
                            if math.sqrt(du * du + dv * dv) <= own2 and own2 < found:
                                found = own2
                    if found < math.inf:
                        own = tol = found  # (its long test too: lone, not static)
                        borrowed = True
                        break
            run = run_px = held = run_long = 0.0
            for lag in range(1, top + 1):
                if f < lag:
                    break  # (no frame that far back: counts for nothing)
                gap = times[f] - times[f - lag]
                recent = gap <= recent_ns
                recent_long = gap <= recent_long_ns
                best = math.inf
                best_px = math.inf
                supported = False
                still_long = False
                for q2 in range(k_max):
                    r2 = table[f - lag, q2]
                    if r2 < 0:
                        continue
                    du, dv = u - uv[r2, 0], v - uv[r2, 1]
                    d_px = math.sqrt(du * du + dv * dv)
                    # _still_pair: the smaller of the two candidates' tolerances
                    px, py, pz = points[r2, 0], points[r2, 1], points[r2, 2]
                    fx, fy, fz = px - center[0], py - center[1], pz - center[2]
                    dd2 = (fx * fx + fy * fy) + fz * fz
                    own2 = focal_static / (math.sqrt(dd2) if dd2 >= 0 else math.nan)
                    pair = own2 if own2 < tol else tol
                    if d_px <= pair:
                        still_long = True
                    if lag <= lags:
                        if d_px <= own and finite[r2]:
                            supported = True
                        if d_px < best_px:  # (NaN never is)
                            best_px = d_px
                        ax, ay, az = x - px, y - py, z - pz
                        d = math.sqrt((ax * ax + ay * ay) + az * az)
                        if d < best:
                            best = d
                if recent_long and still_long:
                    run_long += 1.0
                if lag <= lags and recent:
                    if best <= static_m:
                        run += 1.0
                    if best_px <= own:
                        run_px += 1.0
                    if supported:
                        held += 1.0
            stillness[r] = run / lags
            alone = run_px >= lags and held < lags - 1  # gating._still_alone
            if alone:
                lone[r] = own
            dzr = dz[r]
            across = 1.0 - dzr * dzr
            g_across = g * (math.sqrt(across) if across >= 0 else math.nan)
            long = run_long >= long_lags and long_c * g_across * long_t * long_t > static_m
            if borrowed:
                if long:
                    lone[r] = own
            elif run >= 0.75 * lags or (alone and tol == tol) or long:
                static[r] = True


@kernel
def lags_camera(t, times, used, b, ns, out):
    """:func:`pslog.fusion.gating._lags`' column of camera ``b`` (the same values): for
    candidates at ``t`` (n,) ns, the distance to the nearer of the frames ``used[:, b, 1]``
    and ``used[:, b, 2]`` of b's frame times ``times`` (-1: none), integer nanoseconds
    divided once by ``ns``, into ``out[:, b]``; left as it is (inf) without one."""
    big = np.iinfo(np.int64).max
    for i in range(t.shape[0]):
        best = big
        for slot in range(1, 3):
            j = used[i, b, slot]
            gap = abs(t[i] - times[max(j, 0)])
            if j >= 0 and gap < best:
                best = gap
        if best < big:
            out[i, b] = best / ns


def _preload() -> None:
    """:func:`points_all` loaded from numba's cache (or compiled) now, in the signature of
    gating._points' call (int32 cameras, C-contiguous float64 rows): called by
    :func:`pslog._jit.preload` on its thread while the command reads its session, so that
    the batch gate's first call does not pay the load (~0.3 s on a busy machine)."""
    points_all(np.zeros(0, dtype=np.int32), np.zeros((0, 3)), np.zeros((0, 1)),
               np.zeros((0, 1, 2)), np.zeros((1, 3)), np.zeros((1, 3, 3)), np.zeros((1, 3, 3)),
               np.empty((0, 3)), np.empty(0, dtype=np.bool_), np.empty(0))
    # (and support_all, in the signature of gating._support's call)
    support_all(np.zeros(0, dtype=np.int64), 0, np.zeros(1, dtype=np.int64), np.zeros((1, 2)),
                np.zeros((0, 3)), np.zeros(1, dtype=np.int64), np.zeros((1, 1), dtype=np.int64),
                True, True, 0, 0, 1.0, 1.0, 1.0, np.zeros((1, 1)), np.zeros((1, 1, 2)),
                np.zeros((1, 1, 3), dtype=np.int64))
    # (and lags_camera, in the signature of gating._lags' call)
    lags_camera(np.zeros(0, dtype=np.int64), np.zeros(1, dtype=np.int64),
                np.zeros((0, 1, 3), dtype=np.int64), 0, 1, np.zeros((0, 1)))
    # (and static_camera, in the signature of gating._static's call)
    static_camera(np.zeros(1, dtype=np.int64), np.zeros((1, 1), dtype=np.int64),
                  np.zeros((1, 3)), np.zeros((1, 2)), np.zeros(1, dtype=np.bool_),
                  np.zeros(1, dtype=np.bool_), np.zeros(1), 1, 1, 1.0, 1.0, 1.0, np.zeros(3),
                  1.0, 1.0, 1.0, 1.0, np.zeros(1, dtype=np.bool_), np.zeros(1), np.zeros(1))

@kernel
def _line_fit(trk, lo, hi, t_s, opt, out):
    """gating._line_fit of the track's points ``lo:hi`` (times less ``t_s``, z less gravity,
    as _Track.predict makes them): ``out`` (3,) = p0; returns the RMS residual."""
    mode, g, two = np.int64(opt[O_SUM]), opt[O_G], opt[O_TWO]
    n = hi - lo
    s1, c1, s2, c2 = 0.0, 0.0, 0.0, 0.0
    for i in range(lo, hi):
        tau = trk[i, 0] - t_s
        s1, c1 = _sum_add(s1, c1, tau, mode)
        s2, c2 = _sum_add(s2, c2, tau * tau, mode)
    s1, s2 = _sum_end(s1, c1, mode), _sum_end(s2, c2, mode)
    det = n * s2 - s1 * s1
    v0 = v1 = v2 = 0.0
    for axis in range(3):
        sy, cy = 0.0, 0.0
        for i in range(lo, hi):
            tau = trk[i, 0] - t_s
            y = trk[i, 1 + axis] if axis < 2 else trk[i, 3] + 0.5 * tau * tau * g
            sy, cy = _sum_add(sy, cy, y, mode)
        sy = _sum_end(sy, cy, mode)
        if not det > 1e-18:
            out[axis] = sy / n
            v = 0.0
        else:
            sty, cty = 0.0, 0.0
            for i in range(lo, hi):
                tau = trk[i, 0] - t_s
                y = trk[i, 1 + axis] if axis < 2 else trk[i, 3] + 0.5 * tau * tau * g
                sty, cty = _sum_add(sty, cty, tau * y, mode)
            sty = _sum_end(sty, cty, mode)
            out[axis] = (s2 * sy - s1 * sty) / det
            v = (n * sty - s1 * sy) / det
        if axis == 0:
            v0 = v
        elif axis == 1:
            v1 = v
        else:
            v2 = v
    sq, cq = 0.0, 0.0
    for i in range(lo, hi):
        tau = trk[i, 0] - t_s
        for axis in range(3):
            y = trk[i, 1 + axis] if axis < 2 else trk[i, 3] + 0.5 * tau * tau * g
            v = v0 if axis == 0 else (v1 if axis == 1 else v2)
            sq, cq = _sum_add(sq, cq, math.pow(out[axis] + v * tau - y, two), mode)
    sq = _sum_end(sq, cq, mode)
    return math.sqrt(sq / n)


@kernel
def predict(trk, n_trk, t_s, opt, out):
    """gating._Track.predict at ``t_s``: False (None there), or True with ``out`` (4,) =
    p̂ (3,), allowance (m)."""
    points = np.int64(opt[O_TRACK_POINTS])
    lo = n_trk
    while lo > 0 and n_trk - lo < points and t_s - trk[lo - 1, 0] <= opt[O_WINDOW]:
        lo -= 1
    if n_trk - lo < 3:
        return False
    rms = _line_fit(trk, lo, n_trk, t_s, opt, out)
    if rms > 0.5 * opt[O_TRACK_M] and n_trk - lo > 3:  # a bounce in the window: newest only
        _line_fit(trk, n_trk - 3, n_trk, t_s, opt, out)
    dt = abs(trk[n_trk - 1, 0] - t_s) + trk[n_trk - 1, 4]
    out[3] = opt[O_TRACK_M] + opt[O_JUMP] * dt
    return True


@kernel
def _ray_miss(px, py, pz, center, rx, ry, rz):
    """gating._ray_miss."""
    ox, oy, oz = px - center[0], py - center[1], pz - center[2]
    cx, cy, cz = oy * rz - oz * ry, oz * rx - ox * rz, ox * ry - oy * rx
    return _sqrt((cx * cx + cy * cy) + cz * cz)


@kernel
def insert_frame(fi, fflag, ct, cf, csup, count, cam, t, k, times, uv, xy, distorted, kmat,
                 rot, limit):
    """Add one pushed frame to camera ``cam``'s kept frames, after those of equal key (push
    order), with its geometry (StreamGate._add, _geometry: ``uv`` (k, 2) distorted pixels;
    ``xy`` (k, 2) their ideal normalized coordinates when the camera is ``distorted``, NaN
    where not undistorted; ``times`` (k,) corrected ns). Returns its push id."""
    n = count[cam]
    key = times[0]
    at = n
    while at > 0 and fi[cam, at - 1, 0] > key:  # bisect_right
        at -= 1
    for j in range(n, at, -1):  # room at ``at``
        fi[cam, j] = fi[cam, j - 1]
        fflag[cam, j] = fflag[cam, j - 1]
        ct[cam, j] = ct[cam, j - 1]
        cf[cam, j] = cf[cam, j - 1]
        csup[cam, j] = csup[cam, j - 1]
    count[cam] = n + 1
    fid = count[-1]  # (the last slot of ``count``: the next push id)
    count[-1] = fid + 1
    fi[cam, at, 0], fi[cam, at, 1], fi[cam, at, 2], fi[cam, at, 3] = key, t, fid, k
    fi[cam, at, 4] = -1  # (its chosen candidate, once decided: decide_frame)
    fflag[cam, at, 0] = 0
    fflag[cam, at, 1] = 0
    k_ = kmat[cam]
    r = rot[cam]
    for j in range(k):
        ct[cam, at, j] = times[j]
        csup[cam, at, j] = 1
        u, v = uv[j, 0], uv[j, 1]
        ok = abs(u) <= limit and abs(v) <= limit
        if distorted:
            x, y = xy[j, 0], xy[j, 1]
        else:  # Camera.normalized_from_pixels
            y = (v - k_[1, 2]) / k_[1, 1]
            x = ((u - k_[0, 2]) - k_[0, 1] * y) / k_[0, 0]
        for q in range(9):
            cf[cam, at, j, q] = math.nan
        if not (ok and math.isfinite(x) and math.isfinite(y)):
            continue
        # gating._from_normalized
        cf[cam, at, j, 0] = (k_[0, 0] * x + k_[0, 1] * y) + k_[0, 2]
        cf[cam, at, j, 1] = k_[1, 1] * y + k_[1, 2]
        s = _pymax(_pymax(abs(x), abs(y)), 1.0)
        cx, cy, cz = x / s, y / s, 1.0 / s
        dx = (cx * r[0, 0] + cy * r[1, 0]) + cz * r[2, 0]
        dy = (cx * r[0, 1] + cy * r[1, 1]) + cz * r[2, 1]
        dz = (cx * r[0, 2] + cy * r[1, 2]) + cz * r[2, 2]
        size = _sqrt((dx * dx + dy * dy) + dz * dz)
        cf[cam, at, j, 2], cf[cam, at, j, 3], cf[cam, at, j, 4] = dx / size, dy / size, dz / size
    return fid


@kernel(inline=True)
def choose(a, at, fi, fflag, ct, cf, trk, ist, centers, opt, static, lone, avail, nsup,
           unpointed, front, chosen, epi, run, r_dec, lag, differs, pred, reason):
    """gating._Decider.decide of camera ``a``'s frame at row ``at`` of its kept frames (its
    ``k = fi[a, at, 3]`` candidates: corrected times ``ct[a, at]``, undistorted pixels and
    rays ``cf[a, at, :, :5]``), on its columns as :func:`decide_frame` computes them
    (gating._columns: ``static``, ``lone``, ``avail``, ``nsup``, ``unpointed``, ``front``
    (k,) float, ``chosen`` (k, 3) the decided points, ``epi`` the epipolar cost, ``run`` the
    3-D stillness, ``r_dec`` (k, m) the decided support ratio, ``lag`` (k, m) s) and the
    track (``trk``, ``ist``). ``differs`` (k,) and ``pred`` (4,): scratch. Sets ``reason``
    (k,) (-1 chosen, -2 contested), the track, the frame decided (``fflag[a, at, 0]``) and
    its chosen candidate (``fi[a, at, 4]``, -1 none); returns the time of its last
    candidate, s. Inlined into :func:`decide_frame` (its twenty arrays not referenced per
    call); called alone by ``tests/test_gating_rechoice_lone.py``."""
    m = r_dec.shape[1]
    k = fi[a, at, 3]
    key = fi[a, at, 0]
    recent_ns = 1.5 * opt[O_STATIC_S] * _NS
    verified, tracked = ist[1] != 0, ist[2] != 0
    vouched = ist[3] != 0  # gating._Decider.vouched
    n_trk = ist[0]
    loose_ratio = opt[O_LOOSE]
    for j in range(k):
        reason[j] = -1
    best_row = -1
    best_n, best_c = 0.0, 0.0
    # (unverified / untracked: marks in ``differs``, reused: 1 unverified, 2 untracked, 3 both)
    for j in range(k):
        differs[j] = 0.0
    n_unverified = n_untracked = 0
    t_s_frame = 0.0
    for i in range(k):
        t_s = ct[a, at, i] / _NS
        t_s_frame = t_s
        rx, ry, rz = cf[a, at, i, 2], cf[a, at, i, 3], cf[a, at, i, 4]
        if static[i] != 0.0 and opt[O_SEVERAL] != 0.0:  # (gating._Decider.several)
            reason[i] = _MOTION
            continue
        if lone[i] == lone[i]:  # gating._Decider.decide: kept where the camera followed it
            # (gating._picked_there: its newest choice, within 1.5 static_s; from its frame
            # before, within reach of a ball)
            there = False
            h = at - 1
            while h >= 0 and key - fi[a, h, 0] <= recent_ns:
                q = fi[a, h, 4]
                if q >= 0:
                    du = cf[a, at, i, 0] - cf[a, h, q, 0]
                    dv = cf[a, at, i, 1] - cf[a, h, q, 1]
                    d = _sqrt(du * du + dv * dv)
                    if h == at - 1:
                        there = d <= lone[i] + opt[O_VMAX] * ((key - fi[a, h, 0]) / _NS)
                    else:
                        there = d <= lone[i]
                    break
                h -= 1
            if not there:
                reason[i] = _MOTION
                continue
        if avail[i] != 0 and nsup[i] == 0:
            has_pred = predict(trk, n_trk, t_s, opt, pred)
            track_accepts = False
            if has_pred and math.isfinite(rx):
                track_accepts = (_ray_miss(pred[0], pred[1], pred[2], centers[a], rx, ry, rz)
                                 <= (pred[3] if unpointed[i] != 0.0 else opt[O_ALONE]))
            if not track_accepts:
                reason[i] = _EPIPOLAR
                continue
        if front[i] == 0.0:
            reason[i] = _MOTION
            continue
        strong = nsup[i] >= 2
        loose = False
        if not strong and avail[i] >= 2:
            n_le = 0
            all_loose = True
            for b in range(m):
                r = r_dec[i, b]
                if r <= 1.0:
                    n_le += 1
                if math.isfinite(r) and not r <= loose_ratio:
                    all_loose = False
            loose = not (nsup[i] == 1 and n_le >= 2) and all_loose
        track_cost = 0.0
        if not strong:
            has_pred = predict(trk, n_trk, t_s, opt, pred)
            if (has_pred or vouched) and n_trk > 0 and math.isfinite(chosen[i, 0]):
                dt = abs(t_s - trk[n_trk - 1, 0])
                dx = chosen[i, 0] - trk[n_trk - 1, 1]
                dy = chosen[i, 1] - trk[n_trk - 1, 2]
                dz = chosen[i, 2] - trk[n_trk - 1, 3]
                if _sqrt((dx * dx + dy * dy) + dz * dz) > (opt[O_MAX_SPEED] * dt
                                                           + opt[O_TRACK_M]):
                    reason[i] = _MOTION
                    continue
            if has_pred and math.isfinite(rx):
                miss = _ray_miss(pred[0], pred[1], pred[2], centers[a], rx, ry, rz)
                if miss > (2.0 if loose else 1.0) * pred[3]:
                    reason[i] = _TRACK
                    continue
                track_cost = _pymin(math.pow(miss / pred[3], opt[O_TWO]), 4.0)
            elif avail[i] == 0:
                if verified:
                    reason[i] = _EPIPOLAR
                    continue
                differs[i] += 1.0  # unverified
                n_unverified += 1
            if has_pred:
                tracked = True
            elif not tracked:
                differs[i] += 2.0  # untracked
                n_untracked += 1
        # (gating._Decider.decide: a lone candidate's stillness counts as 1)
        kn, kc = -nsup[i], (epi[i] + track_cost) + (1.0 if lone[i] == lone[i] else run[i])
        if best_row < 0 or kn < best_n or (kn == best_n and kc < best_c):
            best_row, best_n, best_c = i, kn, kc
    if best_row >= 0 and n_untracked > 1 and differs[best_row] >= 2.0 and nsup[best_row] < 2:
        for i in range(k):
            if differs[i] >= 2.0 and nsup[i] < 2:
                reason[i] = _EPIPOLAR
        best_row = -1
        for i in range(k):
            if reason[i] < 0 and not (differs[i] == 1.0 or differs[i] == 3.0):
                kn, kc = -nsup[i], epi[i] + (1.0 if lone[i] == lone[i] else run[i])
                if best_row < 0 or kn < best_n or (kn == best_n and kc < best_c):
                    best_row, best_n, best_c = i, kn, kc
    if best_row >= 0 and (differs[best_row] == 1.0 or differs[best_row] == 3.0) \
            and n_unverified > 1:
        for i in range(k):
            if differs[i] == 1.0 or differs[i] == 3.0:
                reason[i] = _EPIPOLAR
        best_row = -1
        for i in range(k):
            if reason[i] < 0 and not (differs[i] == 1.0 or differs[i] == 3.0):
                best_row = i
    if best_row >= 0:
        for i in range(k):
            if i != best_row and reason[i] < 0:
                reason[i] = _OUTSCORED
        if differs[best_row] >= 2.0:  # gating._Decider.decide: untracked and _denied,
            within = 0  # or a frame of several candidates
            denied = k >= 2
            for b in range(m):
                r = r_dec[best_row, b]
                if r <= 1.0:
                    within += 1
                elif math.isfinite(r):
                    denied = True
            if not (denied or within >= 2):
                # (gating._refused_near: a candidate this camera rejected in a frame of
                # several within static_s, within DOUBT_RADIUS_PX)
                window = opt[O_STATIC_S] * _NS
                h = at - 1
                while not denied and h >= 0 and key - fi[a, h, 0] <= window:
                    if fi[a, h, 3] >= 2 and fflag[a, h, 0] == 1:
                        for j in range(fi[a, h, 3]):
                            if j != fi[a, h, 4]:
                                du = cf[a, at, best_row, 0] - cf[a, h, j, 0]
                                dv = cf[a, at, best_row, 1] - cf[a, h, j, 1]
                                if du * du + dv * dv <= _DOUBT_RADIUS2:
                                    denied = True
                    h -= 1
            if denied or within >= 2:
                reason[best_row] = _CONTESTED
        if not (differs[best_row] == 1.0 or differs[best_row] == 3.0):
            verified = True
        if math.isfinite(chosen[best_row, 0]):  # _Track.add, with _age
            # (gating._Decider.vouched: predicted at its time, before it joins, or two
            # supports)
            vouched = nsup[best_row] >= 2 or predict(trk, n_trk, ct[a, at, best_row] / _NS,
                                                     opt, pred)
            n_one, age = 0, 0.0
            for b in range(m):
                if r_dec[best_row, b] <= 1.0:
                    n_one += 1
                    if n_one == 1:
                        age = lag[best_row, b]
            if n_one != 1:
                age = 0.0
            trk[n_trk, 0] = ct[a, at, best_row] / _NS
            trk[n_trk, 1] = chosen[best_row, 0]
            trk[n_trk, 2] = chosen[best_row, 1]
            trk[n_trk, 3] = chosen[best_row, 2]
            trk[n_trk, 4] = age
            n_trk += 1
            points = np.int64(opt[O_TRACK_POINTS])
            if n_trk > 4 * points:
                for i in range(points):
                    trk[i] = trk[n_trk - points + i]
                n_trk = points
    ist[0] = n_trk
    ist[1] = 1 if verified else 0
    ist[2] = 1 if tracked else 0
    ist[3] = 1 if vouched else 0
    fflag[a, at, 0] = 1
    fi[a, at, 4] = best_row  # (-1: none chosen)
    return t_s_frame


@kernel
def decide_frame(fid, a, fi, fflag, ct, cf, csup, count, trk, ist, F, centers, k_inv, rot,
                 still_f, lags, long_lags, long_t, opt, work, reason):
    """StreamGate._decide of camera ``a``'s frame of push id ``fid``: its candidates'
    support by every other camera from every candidate and from the decided ones
    (StreamGate._support), their points, their stillness (gating._stillness_one), the
    choice (gating._Decider.decide of one frame) and what later choices may use of it
    (gating._can_judge, gating._supporting). Sets ``reason`` (k,) (-1 chosen, -2 contested)
    and the state.
    ``lags``, ``long_lags`` (m,): per camera, the stillness test's frames and the long image
    test's (``ceil(LONG_STILL static_s fps)``); ``long_t`` (m,) s: ``long_lags / fps``
    (gating._still_long's ``T``). ``work``: float64 scratch of at least
    (k (7 m + 18) + 6 (m + 1) + 4 + m) values. Stores the chosen candidate (-1 none) in
    ``fi[a, at, 4]`` (gating._Decider.picked: the next frame of the camera reads it)."""
    at = count[a] - 1
    while at >= 0 and fi[a, at, 2] != fid:
        at -= 1
    if at < 0:  # (never from StreamGate: a pending frame is never trimmed)
        raise IndexError("decide_frame: camera has no kept frame of this push id")
    return decide_at(a, at, fi, fflag, ct, cf, csup, count, trk, ist, F, centers, k_inv, rot,
                     still_f, lags, long_lags, long_t, opt, work, reason)


@kernel
def decide_at(a, at, fi, fflag, ct, cf, csup, count, trk, ist, F, centers, k_inv, rot,
              still_f, lags, long_lags, long_t, opt, work, reason):
    """:func:`decide_frame` of camera ``a``'s kept frame at row ``at``; causal where
    ``opt[O_CAUSAL]``, else the batch gate's offline form (each candidate's support from b's
    frames around its time, gating._support_one; the lag to the nearer of the two,
    gating._lags), with the static verdict a rejection only where ``opt[O_SEVERAL]``
    (gating._Decider.several)."""
    m = len(lags)
    k = fi[a, at, 3]
    key = fi[a, at, 0]
    wait, gap = np.int64(opt[O_WAIT]), np.int64(opt[O_GAP])
    # scratch: every ratio (k, m), carried (k, m, 2); decided ratio, carried; lag (k, m);
    # chosen points (k, 3), front, stillness, static, tol, n_support, available, epi_cost
    off = 0
    r_every = work[off:off + k * m].reshape((k, m))
    off += k * m
    c_every = work[off:off + 2 * k * m].reshape((k, m, 2))
    off += 2 * k * m
    r_dec = work[off:off + k * m].reshape((k, m))
    off += k * m
    c_dec = work[off:off + 2 * k * m].reshape((k, m, 2))
    off += 2 * k * m
    lag = work[off:off + k * m].reshape((k, m))
    off += k * m
    chosen = work[off:off + 3 * k].reshape((k, 3))
    off += 3 * k
    front = work[off:off + k]
    off += k
    run = work[off:off + k]
    off += k
    run_px = work[off:off + k]
    off += k
    held = work[off:off + k]
    off += k
    tol = work[off:off + k]
    off += k
    static = work[off:off + k]
    off += k
    nsup = work[off:off + k]
    off += k
    avail = work[off:off + k]
    off += k
    epi = work[off:off + k]
    off += k
    differs = work[off:off + k]
    off += k
    run_long = work[off:off + k]
    off += k
    alive = work[off:off + k]
    off += k
    unpointed = work[off:off + k]
    off += k
    own_tol = work[off:off + k]  # each candidate's own _still_px (the image test's counts)
    off += k
    lone = work[off:off + k]  # gating._static's ``lone``
    off += k
    rays = work[off:off + 6 * (m + 1)].reshape((m + 1, 6))
    off += 6 * (m + 1)
    pred = work[off:off + 4]
    off += 4
    r_one = work[off:off + m]  # one support's ratio row (gating._held_one)
    r_every[:] = math.nan
    c_every[:] = math.nan
    r_dec[:] = math.nan
    c_dec[:] = math.nan
    lag[:] = math.inf
    differs[:] = 0.0
    # ---- StreamGate._support (offline: gating._support_one's form, gating._lags)
    causal = opt[O_CAUSAL] != 0.0
    for b in range(m):
        nb = count[b]
        if b == a or nb == 0:
            continue
        keys = fi[b, :nb, 0]
        right = (not causal) or wait > 0 or b < a
        for j in range(k):
            t = ct[a, at, j]
            u, v = cf[a, at, j, 0], cf[a, at, j, 1]
            target = t + wait if causal else t
            last = (np.searchsorted(keys, target, side="right") if right
                    else np.searchsorted(keys, target, side="left"))
            if causal:
                if last - 1 >= 0:
                    lag[j, b] = abs(t - keys[last - 1]) / _NS
            else:  # the nearer of the latest frame at or before t and the first after
                best_gap = np.int64(-1)
                if last - 1 >= 0:
                    best_gap = abs(t - keys[last - 1])
                if last < nb and (best_gap < 0 or abs(t - keys[last]) < best_gap):
                    best_gap = abs(t - keys[last])
                if best_gap >= 0:
                    lag[j, b] = best_gap / _NS
            l0, l1, l2 = _line_of(F[a, b], u, v)
            r, cu, cv, found = support_one(t, l0, l1, l2, b, keys, fi, fflag, ct, cf, csup,
                                           right, 0, opt)
            r_every[j, b] = r
            if found:
                c_every[j, b, 0], c_every[j, b, 1] = cu, cv
            first = np.searchsorted(keys, t - gap, side="left")
            # the frames the support may reach (offline: those after t within the gap too)
            reach = last if causal else np.searchsorted(keys, t + gap, side="right")
            narrowed = False
            emptied = False
            for i in range(first, reach):
                if fflag[b, i, 1] == 1:
                    narrowed = True
                elif fflag[b, i, 1] == 2:
                    emptied = True
            if narrowed or emptied:
                r, cu, cv, found = support_one(t, l0, l1, l2, b, keys, fi, fflag, ct, cf,
                                               csup, right, 1, opt)
                differs[j] = 1.0
            if emptied:  # the better of the two carries (gating._support_one)
                r2, cu2, cv2, found2 = support_one(t, l0, l1, l2, b, keys, fi, fflag, ct, cf,
                                                   csup, right, 2, opt)
                if r2 < r:
                    r, cu, cv, found = r2, cu2, cv2, found2
            r_dec[j, b] = r
            if found:
                c_dec[j, b, 0], c_dec[j, b, 1] = cu, cv
    # ---- the points: of the all-candidates support (the stillness's) and the decided one
    track_m = opt[O_TRACK_M]
    for j in range(k):
        ray = cf[a, at, j, 2:5]
        ok_p, x, y, z, ok, miss = points_one(a, ray, r_every[j], c_every[j], centers, k_inv,
                                             rot, rays)
        kept = ok_p and not miss > track_m
        if not kept:
            x = y = z = math.nan
        cf[a, at, j, 5], cf[a, at, j, 6], cf[a, at, j, 7] = x, y, z
        # whether its support held (the later frames' image test)
        hold = kept or held_one(a, ray, r_every[j], c_every[j], miss, track_m, centers, k_inv,
                                rot, rays, r_one)
        cf[a, at, j, 8] = 1.0 if hold else 0.0
        if differs[j] != 0.0:
            ok_p, x, y, z, ok, miss = points_one(a, ray, r_dec[j], c_dec[j], centers, k_inv,
                                                 rot, rays)
            if not (ok_p and not miss > track_m):
                x = y = z = math.nan
        chosen[j, 0], chosen[j, 1], chosen[j, 2] = x, y, z
        front[j] = 1.0 if ok else 0.0
    # ---- gating._stillness_one against the camera's frames before (newest first): lags of
    # them for the 3D and image tests, up to long_lags for the long image test
    static_s, static_m = opt[O_STATIC_S], opt[O_STATIC_M]
    la = lags[a]
    recent_ns = 1.5 * static_s * _NS
    recent_long_ns = 1.5 * opt[O_LONG_STILL] * static_s * _NS
    n_back = min(la, at)
    n_walk = min(long_lags[a], at)
    n_alive = 0
    for j in range(k):
        run[j] = 0.0
        run_px[j] = 0.0
        held[j] = 0.0
        run_long[j] = 0.0
        x = cf[a, at, j, 5]
        n_sup = 0
        for b in range(m):
            if r_every[j, b] <= 1.0:
                n_sup += 1
        if math.isfinite(x):  # gating._still_px
            dx = x - centers[a, 0]
            dy = cf[a, at, j, 6] - centers[a, 1]
            dz = cf[a, at, j, 7] - centers[a, 2]
            depth = _sqrt((dx * dx + dy * dy) + dz * dz)
            own_tol[j] = still_f[a] * static_m / depth
        else:
            own_tol[j] = math.nan
        # gating._paired: the image test's static verdict and the long test
        tol[j] = own_tol[j] if n_sup == 1 else math.nan
        # still across its ray in every frame so far (only those can pass the long test)
        alive[j] = 1.0 if tol[j] == tol[j] else 0.0
        if alive[j] != 0.0:
            n_alive += 1
        if not own_tol[j] == own_tol[j]:  # gating._borrowed_tolerance (the image test's)
            u, v = cf[a, at, j, 0], cf[a, at, j, 1]
            for lg in range(1, n_back + 1):
                h = at - lg
                if not key - fi[a, h, 0] <= recent_ns:
                    continue
                found = math.inf
                for q in range(fi[a, h, 3]):
                    px, py, pz = cf[a, h, q, 5], cf[a, h, q, 6], cf[a, h, q, 7]
                    if px == px and py == py and pz == pz:
                        dx, dy, dz = px - centers[a, 0], py - centers[a, 1], pz - centers[a, 2]
                        own = still_f[a] * static_m / _sqrt((dx * dx + dy * dy) + dz * dz)
                        du, dv = u - cf[a, h, q, 0], v - cf[a, h, q, 1]
                        if _sqrt(du * du + dv * dv) <= own and own < found:
                            found = own
                if found < math.inf:
                    own_tol[j] = tol[j] = found  # (its long test too: lone, not static)
                    alive[j] = 1.0
                    n_alive += 1
                    break
    for lg in range(1, n_walk + 1):
        if lg > la and n_alive == 0:
            break  # (the long image test's frames: nothing left to test)
        h = at - lg
        recent = key - fi[a, h, 0] <= recent_ns
        recent_long = key - fi[a, h, 0] <= recent_long_ns
        if not (recent or recent_long):
            for j in range(k):
                alive[j] = 0.0
            n_alive = 0
            continue
        nh = fi[a, h, 3]
        for j in range(k):
            if lg > la and alive[j] == 0.0:
                continue
            best_px = math.inf
            supported = False
            still_long = False
            if own_tol[j] == own_tol[j]:
                u, v = cf[a, at, j, 0], cf[a, at, j, 1]
                for q in range(nh):
                    du, dv = u - cf[a, h, q, 0], v - cf[a, h, q, 1]
                    d = _sqrt(du * du + dv * dv)
                    if d < best_px:
                        best_px = d
                    px, py, pz = cf[a, h, q, 5], cf[a, h, q, 6], cf[a, h, q, 7]
                    finite = px == px and py == py and pz == pz
                    if d <= own_tol[j] and cf[a, h, q, 8] == 1.0:  # (its support held)
                        supported = True
                    # gating._still_pair: the smaller of the two candidates' tolerances
                    pair = tol[j]
                    if finite:
                        dx = px - centers[a, 0]
                        dy = py - centers[a, 1]
                        dz = pz - centers[a, 2]
                        own = still_f[a] * static_m / _sqrt((dx * dx + dy * dy) + dz * dz)
                        if own < pair:
                            pair = own
                    if d <= pair:
                        still_long = True
            if recent_long and still_long:
                run_long[j] += 1.0
            elif alive[j] != 0.0:
                alive[j] = 0.0
                n_alive -= 1
            if lg > la or not recent:
                continue  # (the long image test's frames only)
            x, y, z = cf[a, at, j, 5], cf[a, at, j, 6], cf[a, at, j, 7]
            best = math.inf
            for q in range(nh):
                dx, dy, dz = x - cf[a, h, q, 5], y - cf[a, h, q, 6], z - cf[a, h, q, 7]
                d = math.sqrt(dx * dx + dy * dy + dz * dz)
                if d < best:
                    best = d
            if supported:
                held[j] += 1.0
            if best <= static_m:
                run[j] += 1.0
            if best_px <= own_tol[j]:
                run_px[j] += 1.0
    for j in range(k):
        alone = (run_px[j] >= la) and (held[j] < la - 1)  # gating._still_alone
        lone[j] = own_tol[j] if alone else math.nan
        # (a candidate without a point judged with a borrowed tolerance: lone, not static)
        borrowed = not cf[a, at, j, 5] == cf[a, at, j, 5] and own_tol[j] == own_tol[j]
        still = (run[j] >= 0.75 * la) or (alone and tol[j] == tol[j])
        # gating._still_long: longer than a ball in flight can stay still across its ray
        dz = cf[a, at, j, 4]
        if (borrowed or not still) and n_alive > 0 and alive[j] != 0.0 and dz * dz <= 1.0:
            t_long = long_t[a]
            g_across = opt[O_G] * _sqrt(1.0 - dz * dz)
            long = (run_long[j] >= long_lags[a]) and (
                opt[O_LONG_STILL_C] * g_across * t_long * t_long > static_m)
            if borrowed:
                if long:
                    lone[j] = own_tol[j]
            else:
                still = long
        static[j] = 1.0 if still and not borrowed else 0.0
        run[j] = run[j] / la  # the stillness
    # ---- gating._columns
    for j in range(k):
        supported = 0
        available = 0
        cost = 0.0
        for b in range(m):
            r = r_dec[j, b]
            if r <= 1.0:
                supported += 1
                cost = cost + r * r
            else:
                cost = cost + 1.0
            if math.isfinite(r):
                available += 1
        epi[j] = cost
        avail[j] = available
        no_point = not math.isfinite(chosen[j, 0])
        # (a single support whose carried ray makes no point: the track alone judges it,
        # at the track's own allowance: gating._columns's ``unpointed``)
        unpointed[j] = 1.0 if no_point and supported == 1 else 0.0
        if no_point and supported >= 2:
            nsup[j] = 1
        elif no_point and supported == 1:
            nsup[j] = 0
        else:
            nsup[j] = supported
    # ---- gating._Decider.decide, one frame
    t_s_frame = choose(a, at, fi, fflag, ct, cf, trk, ist, centers, opt, static, lone, avail,
                       nsup, unpointed, front, chosen, epi, run, r_dec, lag, differs, pred,
                       reason)
    # ---- gating._can_judge, gating._supporting: what later choices may use of it
    recent = 0
    for lg in range(1, n_back + 1):
        if key - fi[a, at - lg, 0] <= recent_ns:
            recent += 1
    if recent >= 0.75 * la:
        any_chosen = False
        all_kept = True
        for j in range(k):
            if reason[j] < 0:
                any_chosen = True
            elif reason[j] != _OUTSCORED:
                all_kept = False
        if any_chosen and not all_kept:
            fflag[a, at, 1] = 1
            for j in range(k):
                if not (reason[j] < 0 or reason[j] == _OUTSCORED):
                    csup[a, at, j] = 0
        elif not any_chosen and not causal:  # gating._emptied
            fflag[a, at, 1] = 2
    return t_s_frame


@kernel
def trim(fi, fflag, ct, cf, csup, count, old):
    """Forget each camera's oldest decided frames logged before ``old`` ns (no later choice
    reaches them: StreamGate._step)."""
    m = len(count) - 1
    for c in range(m):
        n = count[c]
        drop = 0
        while drop < n and fflag[c, drop, 0] != 0 and fi[c, drop, 1] < old:
            drop += 1
        if drop:
            for j in range(n - drop):
                fi[c, j] = fi[c, j + drop]
                fflag[c, j] = fflag[c, j + drop]
                ct[c, j] = ct[c, j + drop]
                cf[c, j] = cf[c, j + drop]
                csup[c, j] = csup[c, j + drop]
            count[c] = n - drop


@kernel
def push_frame(fi, fflag, ct, cf, csup, count, cam, t, k, times, uv, xy, distorted, kmat,
               limit, trk, ist, F, centers, k_inv, rot, still_f, lags, long_lags, long_t, opt,
               work, reason, old):
    """:func:`insert_frame`, :func:`decide_frame` and :func:`trim` in one call: a frame
    decided the moment it is pushed (no clock correction, no wait: nothing still to come
    can change its choice), as StreamGate._add then StreamGate._step do it."""
    fid = insert_frame(fi, fflag, ct, cf, csup, count, cam, t, k, times, uv, xy, distorted,
                       kmat, rot, limit)
    decide_frame(fid, cam, fi, fflag, ct, cf, csup, count, trk, ist, F, centers, k_inv, rot,
                 still_f, lags, long_lags, long_t, opt, work, reason)
    trim(fi, fflag, ct, cf, csup, count, old)
    return fid


@kernel
def gate_frames(cams, ats, rows, fi, fflag, ct, cf, csup, count, trk, ist, F, centers, k_inv,
                rot, still_f, lags, long_lags, long_t, opt, work, reason, out, ratio):
    """The batch gate's sequential choice (gating._decide_in_order) in one call: the kept
    frames ``(cams[n], ats[n])`` decided by :func:`decide_at` in that order (the batch's
    (time, camera) order; every frame of the session kept, none trimmed), each candidate's
    reason code written at its row of the session, ``out[rows[a, at, j]]`` (int8: -1
    chosen, -2 contested, else the rejection's code), and the support ratio it was decided
    with at ``ratio[rows[a, at, j]]`` (m,) (:meth:`GateState.decided_ratio`)."""
    m = ratio.shape[1]
    for n in range(cams.shape[0]):
        a, at = cams[n], ats[n]
        decide_at(a, at, fi, fflag, ct, cf, csup, count, trk, ist, F, centers, k_inv, rot,
                  still_f, lags, long_lags, long_t, opt, work, reason)
        k = fi[a, at, 3]
        for j in range(k):
            row = rows[a, at, j]
            out[row] = reason[j]
            for b in range(m):  # (decide_at's r_dec: work[3 k m:4 k m] as (k, m))
                ratio[row, b] = work[3 * k * m + j * m + b]


def options_array(options, wait_ns: int, max_gap_ns: int, gravity: float,
                  causal: bool = True, several: bool = True) -> np.ndarray:
    """The float64 ``opt`` row the kernels read (``O_*`` indices): the gate's options, the
    wait and max gap (ns: below 2**53, exact), gravity, the exponent 2.0, SUM_MODE, the
    long image test's constants (gating.LONG_STILL, gating.LONG_STILL_C), the form (1.0
    causal, 0.0 offline) and whether a static candidate is rejected (gating._Decider.several,
    1.0 always in the causal form)."""
    from .gating import LONG_STILL, LONG_STILL_C

    opt = np.zeros(N_OPT)
    opt[O_EPI], opt[O_VMAX] = options.epipolar_px, options.max_image_speed_px_s
    opt[O_HALF_ACCEL] = 0.5 * options.accel_px_s2  # (as _support_one computes it)
    opt[O_TRACK_M], opt[O_JUMP] = options.track_m, options.track_jump_m_s
    opt[O_WINDOW], opt[O_MAX_SPEED] = options.track_window_s, options.max_speed_m_s
    opt[O_LOOSE], opt[O_STATIC_S] = options.loose_ratio, options.static_s
    opt[O_STATIC_M], opt[O_ALONE] = options.static_m, options.track_alone_m
    opt[O_G], opt[O_TWO], opt[O_TRACK_POINTS] = gravity, 2.0, int(options.track_points)
    opt[O_WAIT], opt[O_GAP], opt[O_SUM] = wait_ns, max_gap_ns, SUM_MODE
    opt[O_LONG_STILL], opt[O_LONG_STILL_C] = LONG_STILL, LONG_STILL_C
    opt[O_CAUSAL], opt[O_SEVERAL] = float(causal), float(several)
    return opt


class GateState:
    """The compiled stream gate's state (module docstring) and its three steps: add a
    frame (:meth:`insert`), decide one (:meth:`decide`), forget old ones (:meth:`trim`).

    Parameters
    ----------
    rig : Rig; options : GatingOptions; wait_ns, max_gap_ns : int
    F : (m, m, 3, 3) fundamental matrices; constants : gating._rig_constants(rig)
    lags : per camera, the stillness test's frames (gating._static)
    gravity : float, m/s² (the track's model)
    """

    def __init__(self, rig, options, wait_ns: int, max_gap_ns: int, F, constants, lags,
                 gravity: float, frames: int = 64, candidates: int = 4) -> None:
        m = len(rig)
        self.m = m
        # per frame: key, logged time, push id, candidates, chosen candidate (-1 none)
        self.fi = np.zeros((m, frames, 5), np.int64)
        self.fflag = np.zeros((m, frames, 2), np.int8)
        self.ct = np.zeros((m, frames, candidates), np.int64)
        self.cf = np.full((m, frames, candidates, 9), np.nan)
        self.csup = np.zeros((m, frames, candidates), np.int8)
        self.count = np.zeros(m + 1, np.int64)  # frames per camera, then the next push id
        self.trk = np.zeros((4 * int(options.track_points) + 1, 5))
        self.ist = np.zeros(4, np.int64)
        self.F = np.ascontiguousarray(F, dtype=np.float64)
        centers, k_inv, rot = constants
        self.centers = np.array(centers, dtype=np.float64)
        self.k_inv = np.array(k_inv, dtype=np.float64)
        self.rot = np.array(rot, dtype=np.float64)
        self.kmat = np.array([cam.K for cam in rig.cameras], dtype=np.float64)
        # gating._still_px's factor (Python's min of the two focal lengths)
        self.still_f = np.array([min(float(cam.K[0, 0]), float(cam.K[1, 1]))
                                 for cam in rig.cameras])
        self.lags = np.array(lags, dtype=np.int64)
        # the long image test's frames and their span T = frames / fps (gating._stillness_one,
        # gating._still_long)
        from .gating import LONG_STILL

        long_lags = [int(np.ceil(LONG_STILL * options.static_s * cam.fps))
                     for cam in rig.cameras]
        self.long_lags = np.array(long_lags, dtype=np.int64)
        self.long_t = np.array([n / cam.fps for n, cam in zip(long_lags, rig.cameras,
                                                               strict=True)], dtype=np.float64)
        self.limit = np.array([10 * max(cam.width, cam.height) for cam in rig.cameras],
                              dtype=np.float64)
        self.opt = options_array(options, wait_ns, max_gap_ns, gravity)
        self.reason = np.zeros(candidates, np.int64)
        self.work = np.zeros(self._work_size(candidates))
        self.no_xy = np.zeros((candidates, 2))

    def _work_size(self, k: int) -> int:
        m = self.m
        return k * (7 * m + 19) + 6 * (m + 1) + 8 + m

    @property
    def frames(self) -> int:
        return self.fi.shape[1]

    @property
    def candidates(self) -> int:
        return self.ct.shape[2]

    def _grow(self, frames: int, candidates: int) -> None:
        """Room for ``frames`` frames per camera and ``candidates`` per frame (copied)."""
        m, h, k = self.m, self.frames, self.candidates
        new: dict[str, np.ndarray] = {"fi": np.zeros((m, frames, 5), np.int64),
                                      "fflag": np.zeros((m, frames, 2), np.int8),
                                      "ct": np.zeros((m, frames, candidates), np.int64),
                                      "cf": np.full((m, frames, candidates, 9), np.nan),
                                      "csup": np.zeros((m, frames, candidates), np.int8)}
        for name, a in new.items():
            old = getattr(self, name)
            if name in ("fi", "fflag"):  # (per frame: every column)
                a[:, :h] = old
            else:
                a[:, :h, :k] = old
            setattr(self, name, a)
        if candidates > k:
            self.reason = np.zeros(candidates, np.int64)
            self.work = np.zeros(self._work_size(candidates))
            self.no_xy = np.zeros((candidates, 2))

    def insert(self, cam: int, t: int, times: np.ndarray, uv: np.ndarray, xy) -> int:
        """Add a frame of camera ``cam`` logged at ``t`` ns: its candidates' corrected
        ``times`` (k,) ns, distorted pixels ``uv`` (k, 2) and, for a camera with a lens
        model, their ideal normalized coordinates ``xy`` (k, 2) (NaN: not undistorted; None
        without). Returns the frame's push id."""
        k = len(times)
        if int(self.count[cam]) >= self.frames or k > self.candidates:
            self._grow(2 * self.frames if int(self.count[cam]) >= self.frames else self.frames,
                       max(k, self.candidates))
        return insert_frame(self.fi, self.fflag, self.ct, self.cf, self.csup, self.count, cam,
                            t, k, times, uv, self.no_xy if xy is None else xy, xy is not None,
                            self.kmat, self.rot, self.limit[cam])

    def push_decide(self, cam: int, t: int, times: np.ndarray, uv: np.ndarray, xy,
                    old: int) -> list[int]:
        """:meth:`insert`, :meth:`decide` and :meth:`trim` (``old``) of a frame decided as
        it comes, in one compiled call; its candidates' reason codes (< 0 chosen: -1, or -2
        contested)."""
        k = len(times)
        if int(self.count[cam]) >= self.frames or k > self.candidates:
            self._grow(2 * self.frames if int(self.count[cam]) >= self.frames else self.frames,
                       max(k, self.candidates))
        push_frame(self.fi, self.fflag, self.ct, self.cf, self.csup, self.count, cam, t, k,
                   times, uv, self.no_xy if xy is None else xy, xy is not None, self.kmat,
                   self.limit[cam], self.trk, self.ist, self.F, self.centers, self.k_inv,
                   self.rot, self.still_f, self.lags, self.long_lags, self.long_t, self.opt,
                   self.work, self.reason, max(old, _I64_MIN))
        return self.reason[:k].tolist()

    def decide(self, fid: int, cam: int, k: int) -> list[int]:
        """Decide the frame of push id ``fid`` (camera ``cam``, ``k`` candidates): its
        candidates' reason codes (< 0 chosen: -1, or -2 contested)."""
        decide_frame(fid, cam, self.fi, self.fflag, self.ct, self.cf, self.csup, self.count,
                     self.trk, self.ist, self.F, self.centers, self.k_inv, self.rot,
                     self.still_f, self.lags, self.long_lags, self.long_t, self.opt, self.work,
                     self.reason)
        return self.reason[:k].tolist()

    def trim(self, old: int) -> None:
        """Forget the decided frames logged before ``old`` ns."""
        # (before any push the stream's newest time is int64's least: its history reaches
        # below what an int64 holds)
        trim(self.fi, self.fflag, self.ct, self.cf, self.csup, self.count, max(old, _I64_MIN))

    def decided_ratio(self, k: int) -> np.ndarray:
        """The epipolar support ratio (k, m) the last :meth:`decide` chose with (its
        candidates' support from the decided frames: gating._decided's ``ratio``), a copy."""
        m = self.m
        return self.work[3 * k * m:4 * k * m].reshape(k, m).copy()


def gate_session(c, tables, rig, options, wait_ns: int, max_gap_ns: int, F, constants,
                 lags, gravity: float, causal: bool, several: bool, frames,
                 reason) -> np.ndarray:
    """The batch gate's choice (gating._decided after its geometry) by :func:`gate_frames`:
    every frame of the session kept in a :class:`GateState` (each camera's in its frame
    table's order, gating._frame_table: ``tables``), decided in the batch's order
    (``frames``: ``(cameras, positions)`` (F,) of each frame, in that order). ``c``:
    gating._Candidates (corrected times, undistorted pixels, rays: the batch's own values,
    copied in); sets ``reason`` (C,) int8 of every candidate (-1 chosen, -2 contested) and
    returns the support ratio (C, m) each was decided with (gating._decided's)."""
    state, rows = session_state(c, tables, rig, options, wait_ns, max_gap_ns, F, constants,
                                lags, gravity, causal, several)
    m = len(rig)
    cams, ats = frames
    ratio = np.full((len(reason), m), np.nan)
    gate_frames(np.ascontiguousarray(cams, dtype=np.int64),
                np.ascontiguousarray(ats, dtype=np.int64), rows, state.fi, state.fflag,
                state.ct, state.cf, state.csup, state.count, state.trk, state.ist, state.F,
                state.centers, state.k_inv, state.rot, state.still_f, state.lags,
                state.long_lags, state.long_t, state.opt, state.work, state.reason, reason,
                ratio)
    return ratio


def session_state(c, tables, rig, options, wait_ns: int, max_gap_ns: int, F, constants, lags,
                  gravity: float, causal: bool, several: bool):
    """A :class:`GateState` holding every frame of the session (:func:`gate_session`'s
    arguments), none decided, and ``rows`` (m, H, K) int64: the session row of each kept
    candidate (-1 padding)."""
    m = len(rig)
    h_max = max(1, max(len(times) for times, _ in tables))
    k_max = max(1, max(table.shape[1] for _, table in tables))
    state = GateState(rig, options, wait_ns, max_gap_ns, F, constants, lags, gravity,
                      frames=h_max, candidates=k_max)
    state.opt = options_array(options, wait_ns, max_gap_ns, gravity, causal, several)
    rows = np.full((m, h_max, k_max), -1, np.int64)
    for b, (times, table) in enumerate(tables):
        h, k = table.shape
        if h == 0:
            continue
        valid = table >= 0
        r = table[valid]  # (the padding keeps the state's 0 and NaN; no (h, k) temporaries:
        # gating._whole_bytes counts the state alone)
        state.fi[b, :h, 0] = times
        state.fi[b, :h, 2] = np.arange(h)
        state.fi[b, :h, 3] = valid.sum(axis=1)
        state.fi[b, :h, 4] = -1
        state.ct[b, :h, :k][valid] = c.time_ns[r]
        state.cf[b, :h, :k, 0:2][valid] = c.uv_und[r]
        state.cf[b, :h, :k, 2:5][valid] = c.ray_dir[r]
        state.csup[b, :h, :k] = 1
        state.count[b] = h
        rows[b, :h, :k] = table
    return state, rows
