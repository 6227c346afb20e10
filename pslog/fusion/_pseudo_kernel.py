"""Type A's per-point kernels (the paper's section 2.2, eqs. (1)-(4)), compiled with numba.

:mod:`pslog.fusion.pseudo` used to compute type A on (k,) columns with numpy, ~200 small
array operations per batch; numpy's fixed cost per call dominated a stream's single point
and much of a session's. These kernels loop over points instead, doing for each exactly the
arithmetic of the former columns, in the same order (so the same bits, except for the
3 x 3 products numpy did with ``@``, whose summation order BLAS may choose: those are
written out here as ``p0 R[i, 0] + p1 R[i, 1] + p2 R[i, 2] + t_i``, and agree to the last
bit or two).

- :func:`pseudo_kernel`: steps 1-3 for past observations (the partner's bracket, eq. (1),
  the epipolar snap, the crossing of the two rays with its ray parameters ``s, k > 0``, and
  the quality of each: the rays' miss before the snap, ``snap_px``, the angle between the
  rays, the reprojection errors, the validity flags);
- :func:`event_kernel`: a type-A point from its two past points (eq. (2)'s linear
  prediction, eqs. (3)-(4)'s projection onto the newest ray with ``k > 0``, the quality
  columns and the closed-form covariance of :func:`pslog.fusion.pseudo._type_a_covariance`).

Imported lazily (numba compiles on first use; ``pslog --help`` never loads it). Camera
tables are per camera rows of 9 (a 3 x 3 matrix, row-major) or fewer values; see
:func:`camera_tables`.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import kernel
from ..motion import G as _G
from ._prepare_kernel import homogeneous as _homogeneous
from ._prepare_kernel import previous_next
from ._prepare_kernel import ray as _ray
from .innovation import DEFAULT_NOISE_PX as _DEFAULT_NOISE_PX
from .innovation import INNOVATION_SIGMAS as _INNOVATION_SIGMAS
from .innovation import KINK_SIGMAS as _KINK_SIGMAS
from .innovation import NOISE_EVERY as _NOISE_EVERY
from .innovation import NOISE_WINDOW as _NOISE_WINDOW
from .innovation import RAYLEIGH_MEDIAN as _RAYLEIGH_MEDIAN

#: geometry._PARALLEL_EPS: rays whose cross product is this small (relative) do not cross.
_PARALLEL_EPS = 1e-12
#: np.degrees' factor (numpy multiplies by 180 / pi, computed once in double precision).
_DEGREES = 180.0 / np.pi
#: The float columns of a past point in the kernels' tables ``ff[slot, i]`` (20 floats).
FLOATS = ("weight", "snap_px", "miss_m", "angle_rad", "miss_unsnapped_m", "residual_obs_px",
          "residual_partner_px", "points_world", "points_world", "points_world", "dir_obs",
          "dir_obs", "dir_obs", "dir_partner", "dir_partner", "dir_partner", "uv_interpolated",
          "uv_interpolated", "uv_snapped", "uv_snapped")
#: The int columns of a past point in ``fi[slot, i]``: its row, partner camera (-1: none),
#: the partner's bracket (prev, next rows), its validity flags and whether it is valid.
INTS = ("row", "partner", "prev_row", "next_row", "flags", "valid")
#: "No bracket end yet" in the partner choice (np.iinfo(np.int64).min).
_INT64_MIN = np.iinfo(np.int64).min


@kernel
def _max(x, y):
    """np.maximum of two floats (NaN propagates, the first NaN returned)."""
    if x != x:
        return x
    if y != y:
        return y
    return x if x >= y else y


@kernel
def _min(x, y):
    """np.minimum of two floats (NaN propagates)."""
    if x != x:
        return x
    if y != y:
        return y
    return x if x <= y else y


@kernel
def _dot3(a0, a1, a2, b0, b1, b2):
    """Dot product of (a0, a1, a2) and (b0, b1, b2) summed in np.einsum's order (x, then z,
    then y: geometry._dot)."""
    out = a0 * b0
    out += a2 * b2
    out += a1 * b1
    return out


@kernel(inline=True)
def _crossing(centers, ca, a0, a1, a2, cb, b0, b1, b2):
    """Step 3, the crossing of rays ``C_a + s a`` and ``C_b + k b`` (``C``: ``centers`` of
    cameras ``ca``, ``cb``): the midpoint of their common perpendicular; returns (miss, s, k,
    x, y, z), NaN s, k (and point) for parallel rays (:func:`pslog.geometry.crossing_of_rays`).
    (Scalars, not (3,) views: numba counts references to every view it makes, atomically, at
    a cost above this arithmetic's.)"""
    w0, w1, w2 = centers[ca, 0] - centers[cb, 0], centers[ca, 1] - centers[cb, 1], \
        centers[ca, 2] - centers[cb, 2]
    a = _dot3(a0, a1, a2, a0, a1, a2)
    b = _dot3(a0, a1, a2, b0, b1, b2)
    c = _dot3(b0, b1, b2, b0, b1, b2)
    d = a0 * w0
    d += a2 * w2
    d += a1 * w1
    e = b0 * w0
    e += b2 * w2
    e += b1 * w1
    denom = a * c - b * b
    if denom <= _PARALLEL_EPS * a * c:
        s = np.nan
        k = np.nan
    else:
        s = (b * e - c * d) / denom
        k = (a * e - b * d) / denom
    foot_a = centers[ca, 0] + s * a0
    foot_b = centers[cb, 0] + k * b0
    x = 0.5 * (foot_a + foot_b)
    gap = foot_a - foot_b
    miss = 0.0
    miss += gap * gap
    foot_a = centers[ca, 1] + s * a1
    foot_b = centers[cb, 1] + k * b1
    y = 0.5 * (foot_a + foot_b)
    gap = foot_a - foot_b
    miss += gap * gap
    foot_a = centers[ca, 2] + s * a2
    foot_b = centers[cb, 2] + k * b2
    z = 0.5 * (foot_a + foot_b)
    gap = foot_a - foot_b
    miss += gap * gap
    return math.sqrt(miss), s, k, x, y, z


@kernel(inline=True)
def _distorted(cam, c, x, y):
    """Pixels of ideal normalised (x, y) through camera c's lens (reprojection's
    ``_distorted_pixels``); ``cam[c]``: K (9), R (9), t (3), dist (5), box (4), lens flag."""
    k1, k2, p1, p2, k3 = cam[c, 21], cam[c, 22], cam[c, 23], cam[c, 24], cam[c, 25]
    r2 = x * x + y * y
    if cam[c, 30] == 0.0 and math.isfinite(r2 + r2):  # no lens: (x, y) exactly
        xd, yd = x, y
    else:
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return cam[c, 0] * xd + cam[c, 1] * yd + cam[c, 2], cam[c, 4] * yd + cam[c, 5]


@kernel(inline=True)
def _in_camera(cam, c, p0, p1, p2, i):
    """Coordinate i of world point (p0, p1, p2) in camera c's frame, ``R p + t``."""
    return p0 * cam[c, 9 + 3 * i] + p1 * cam[c, 10 + 3 * i] + p2 * cam[c, 11 + 3 * i] \
        + cam[c, 18 + i]


@kernel(inline=True)
def _reprojection(cam, c, p0, p1, p2, u_img, v_img):
    """Distance in camera c's recorded image between world point (p0, p1, p2)'s projection
    and the undistorted pixel (u_img, v_img), pixels; NaN behind the camera
    (reprojection_one)."""
    z = _in_camera(cam, c, p0, p1, p2, 2)
    in_front = z > 1e-12
    if not in_front:
        z = np.nan
    u, v = _distorted(cam, c, _in_camera(cam, c, p0, p1, p2, 0) / z,
                      _in_camera(cam, c, p0, p1, p2, 1) / z)
    y = (v_img - cam[c, 5]) / cam[c, 4]
    x = (u_img - cam[c, 2] - cam[c, 1] * y) / cam[c, 0]
    tu, tv = _distorted(cam, c, x, y)
    u -= tu
    v -= tv
    u *= u
    v *= v
    u += v
    return math.sqrt(u) if in_front else np.nan


@kernel(inline=True)
def _invalid(cam, c, p0, p1, p2):
    """:func:`~pslog.fusion._prepare.invalid_points`' bits for one contributing camera c
    and a finite point (p0, p1, p2): BEHIND (1) at or behind its image plane, OUTSIDE_VIEW
    (2) outside its view box."""
    x = _in_camera(cam, c, p0, p1, p2, 0)
    y = _in_camera(cam, c, p0, p1, p2, 1)
    z = _in_camera(cam, c, p0, p1, p2, 2)
    # (no branch: the inlined body one basic block, so numba's reference pruning drops its
    # reference to ``cam``, two atomic operations per call; behind, the projection is made
    # anyway, by 1 (never 0: the Python form does not raise), and not used)
    behind = np.float64(z <= 1e-9)
    depth = z * (1.0 - behind) + behind  # (in front: z * 1.0 + 0.0 == z, bit for bit)
    xn, yn = x / depth, y / depth
    u = xn * cam[c, 0] + yn * cam[c, 1] + cam[c, 2]
    v = xn * cam[c, 3] + yn * cam[c, 4] + cam[c, 5]
    inside = (u >= cam[c, 26]) & (u <= cam[c, 28]) & (v >= cam[c, 27]) & (v <= cam[c, 29])
    bits = np.int64(behind) + 2 * np.int64(1.0 - behind) * np.int64(not inside)
    return bits


@kernel(inline=True)
def _pseudo_one(r, not_after, max_gap_ns, time_ns, camera, prev_b, next_b, uv, observed_rays,
                centers, ki, rr, f9, cam, span_tie_ns, min_angle_deg, ff, fi, slot, i):
    """Steps 1-3 of the paper's section 2.2 for past observation ``r`` from a partner
    bracket ending at or before global row ``not_after``, into ``ff[slot, i]`` (floats,
    :data:`FLOATS`) and ``fi[slot, i]`` (ints, :data:`INTS`); returns (valid, flags).

    For row ``r`` (camera ``c``, time ``t_j``): the partner is the other camera whose bracket
    ``prev <= t_j <= next`` (``prev_b``, ``next_b``: (m, n) rows, -1 none) is shortest
    (ties within ``span_tie_ns``: the one ending latest), not after ``not_after`` and
    within ``max_gap_ns``. Then

    - eq. (1): ``u = (δ_a u_next + δ_b u_prev) / (δ_a + δ_b)``, ``δ_a = t_j - t_prev``,
      ``δ_b = t_next - t_j``, written ``(1 - w) u_prev + w u_next`` with
      ``w = δ_a / (δ_a + δ_b)`` from the integer times, in undistorted pixels;
    - step 2: the snap onto the epipolar line ``F (u_obs, v_obs, 1)`` of the observed point
      in the partner's image (``snap_px``: the distance moved);
    - step 3: the crossing of the two viewing rays, with its ray parameters ``s, k``
      (``s, k <= 0``: behind a camera, flagged BEHIND);
    - quality: the angle between the rays (PARALLEL below ``min_angle_deg``), the miss of the
      observed ray and the interpolated point's ray BEFORE the snap, and the reprojection
      errors of that unsnapped crossing in the observed and the partner's recorded images.

    ``cam`` (m, 31): per camera K (9), R (9), t (3), dist (5), view box (4), lens flag
    (:func:`camera_tables`); ``ki``, ``rr`` (m, 9): K⁻¹ and R; ``f9`` (m * m, 9): ``F[a, b]``
    at row ``a m + b``. A row without partner gets the arithmetic
    of camera 0 and rows 0 (as the former numpy columns did), not valid and no flags.
    """
    m = centers.shape[0]
    fi[slot, i, 0] = r
    t_row = time_ns[r]
    c = camera[r]
    best_span = np.int64(2**62)
    best_end = _INT64_MIN
    p = -1
    pv_best = 0
    nx_best = 0
    for d in range(m):
        pv = prev_b[d, r]
        nx = next_b[d, r]
        end = time_ns[max(nx, 0)]
        span = end - time_ns[max(pv, 0)]
        ok = (pv >= 0) and (nx >= 0) and (c != d) and (nx <= not_after) \
            and (span <= max_gap_ns)
        if ok and ((span < best_span - span_tie_ns)
                   or ((span <= best_span + span_tie_ns) and (end > best_end))):
            best_span = span
            best_end = end
            p = d
            pv_best = pv
            nx_best = nx
    fi[slot, i, 1] = p
    fi[slot, i, 2] = pv_best
    fi[slot, i, 3] = nx_best
    q = max(p, 0)
    # eq. (1)'s weight from integer capture times
    t_prev = time_ns[pv_best]
    span_ns = time_ns[nx_best] - t_prev
    w = (t_row - t_prev) / span_ns if span_ns > 0 else 0.0
    ff[slot, i, 0] = w
    # eq. (1): linear interpolation of the partner's 2D track to the observation's time
    ui0 = (1.0 - w) * uv[pv_best, 0] + w * uv[nx_best, 0]
    ui1 = (1.0 - w) * uv[pv_best, 1] + w * uv[nx_best, 1]
    ff[slot, i, 16] = ui0
    ff[slot, i, 17] = ui1
    # step 2: nearest point on the epipolar line of the observed point, partner image
    fr = c * m + q
    uo, vo = uv[r, 0], uv[r, 1]
    a = f9[fr, 0] * uo + f9[fr, 2]
    a += f9[fr, 1] * vo
    b = f9[fr, 3] * uo + f9[fr, 5]
    b += f9[fr, 4] * vo
    cl = f9[fr, 6] * uo + f9[fr, 8]
    cl += f9[fr, 7] * vo
    big = _max(abs(a), abs(b))
    a /= big
    b /= big
    cl /= big
    size = math.sqrt(a * a + b * b)
    n0, n1, n2 = a / size, b / size, cl / size
    signed = n0 * ui0 + n1 * ui1 + n2
    us0 = ui0 - signed * n0
    us1 = ui1 - signed * n1
    ff[slot, i, 18] = us0
    ff[slot, i, 19] = us1
    ff[slot, i, 1] = abs(signed)
    # step 3: crossing point of the observed ray and the snapped point's ray
    a0, a1, a2 = observed_rays[r, 0], observed_rays[r, 1], observed_rays[r, 2]
    ff[slot, i, 10] = a0
    ff[slot, i, 11] = a1
    ff[slot, i, 12] = a2
    b0, b1, b2 = _ray(ki, rr, q, us0, us1)
    ff[slot, i, 13] = b0
    ff[slot, i, 14] = b1
    ff[slot, i, 15] = b2
    miss, s, k, x0, x1, x2 = _crossing(centers, c, a0, a1, a2, q, b0, b1, b2)
    ff[slot, i, 2] = miss
    ff[slot, i, 7] = x0
    ff[slot, i, 8] = x1
    ff[slot, i, 9] = x2
    # both directions are unit vectors; a line has no sense, hence the absolute value
    ang = math.acos(_min(abs(_dot3(a0, a1, a2, b0, b1, b2)), 1.0))
    ff[slot, i, 3] = ang
    # the disagreement before the snap: the interpolated point's ray against the observed
    d0, d1, d2 = _ray(ki, rr, q, ui0, ui1)
    miss_u, _s, _k, y0, y1, y2 = _crossing(centers, c, a0, a1, a2, q, d0, d1, d2)
    ff[slot, i, 4] = miss_u
    ff[slot, i, 5] = _reprojection(cam, c, y0, y1, y2, uo, vo)
    ff[slot, i, 6] = _reprojection(cam, q, y0, y1, y2, ui0, ui1)
    # the flags without a branch (the inlined body then holds no reference to cam and fi:
    # numba prunes the pair of atomic operations of a straight block; in branches it kept
    # them, at every past point): the bits of the contributing cameras c and q (an OR, in
    # any order; c == q without partner), BEHIND (1) for a crossing behind a camera, then
    # PARALLEL (4, NaN: no ray, no flag); a point not finite has no camera bits, and a row
    # without partner no bits at all (no point, nothing to say about its geometry)
    finite = math.isfinite(x0) & math.isfinite(x1) & math.isfinite(x2)
    behind = not ((s > 0) & (k > 0))
    bits = (_invalid(cam, c, x0, x1, x2) | _invalid(cam, q, x0, x1, x2)
            | np.int64(behind)) * np.int64(finite)
    bits |= 4 * np.int64(ang * _DEGREES < min_angle_deg)
    bits *= np.int64(p >= 0)
    fi[slot, i, 4] = bits
    ok = (p >= 0) & finite & (bits == 0)
    fi[slot, i, 5] = ok
    return ok, bits


@kernel
def pseudo_kernel(rows, not_after, max_gap_ns, time_ns, camera, prev_b, next_b, uv,
                  observed_rays, centers, ki, rr, f9, cam, span_tie_ns, min_angle_deg, ff, fi):
    """:func:`_pseudo_one` for past observations ``rows`` (k,) and their ``not_after`` (k,)
    rows, into ``ff[0]`` (k, 20) and ``fi[0]`` (k, 6)."""
    for i in range(rows.shape[0]):
        _pseudo_one(rows[i], not_after[i], max_gap_ns, time_ns, camera, prev_b, next_b, uv,
                    observed_rays, centers, ki, rr, f9, cam, span_tie_ns, min_angle_deg,
                    ff, fi, 0, i)


@kernel(inline=True)
def _pixel_jacobian(jac4, lens, row, g0, g1):
    """``g L`` of a (2,) row vector g and the detection's d(undistorted) / d(recorded pixel)
    ``L`` (``jac4[row]``, (2, 2) row-major, NaN as 0); ``g`` itself without lens distortion
    (:func:`~pslog.fusion._prepare.times_pixel_jacobian` with None)."""
    if not lens:
        return g0, g1
    return (g0 * jac4[row, 0] + g1 * jac4[row, 2], g0 * jac4[row, 1] + g1 * jac4[row, 3])


@kernel
def type_a_kernel(targets, previous_instant, depth, max_extrapolation, max_gap_ns, time_ns,
                  camera, prev_b, next_b, uv, observed_rays, centers, ki, rr, f9, cam,
                  span_tie_ns, min_angle_deg, ray_dir, obs_jac, jac4, lens, rtki, ns,
                  noise_px, with_cov, ff, fi, refused, has, predicted, points, flags,
                  innovation, factor, model, quality, past_rows, past_points, decide, floor,
                  noise_values, noise_count, lens_table, row_before, row_after, bend_change,
                  bend_root, doubted, rows_out, counts, sigmas):
    """Type A's point at each detection of ``targets`` (k,), sorted global rows.

    The two past points: for each target, the latest rows of the 1st, 2nd, ... distinct
    instants before it (``previous_instant``), up to ``depth`` instants back and within
    ``max_gap_ns``, are triangulated by :func:`_pseudo_one` (steps 1-3, the partner's
    bracket ending at or before the target: causality) until two are valid: ``P_{t-1}``
    into ``ff[0, i]``, ``fi[0, i]`` and ``P_{t-2}`` into ``ff[1, i]``, ``fi[1, i]``;
    ``P_{t-2}`` only if eq. (2) stays a bounded extrapolation,
    ``δ_pred <= max_extrapolation δ_prev``. Every past point made ORs its flags into
    ``refused`` (n,) at its row. ``has`` (k,): both were found for the target; then its
    point is made, at place ``i`` of the outputs (the targets with a point, in order: the
    outputs' first ``made`` places, the number returned, are the points; no gather after):

    - eq. (2), linear prediction with the actual capture intervals (integer nanoseconds):
      ``P̂_t = P_{t-1} + (P_{t-1} - P_{t-2}) δ_pred / δ_prev``;
    - eqs. (3)-(4): ``P'_t = ((P̂_t - T) · r / |r|²) r + T``, the point of the newest viewing
      ray ``l = k r + T`` nearest to ``P̂_t``; its ``k <= 0`` (the foot behind the newest
      camera) and a point behind or outside a contributing camera are flagged (``flags``);
    - ``innovation``: the newest detection against the prediction (recorded pixels), and
      the prediction test's terms (:func:`pslog.fusion.innovation.failed_predictions`,
      its expressions in its order): ``factor`` ``√(1 + (1 + ρ)² + ρ²)`` (the innovation's
      noise in detection noises) and ``model`` the extrapolation error's bound, pixels;
    - ``quality`` (20, k): snap_px, ray_miss_m (before the snap), ray_shift_m,
      ray_angle_deg, residual_max_px, residual_mean_px, camera_mask, n_detections, gap_s,
      span_s, and (``with_cov``) std_m, cov_xx ... cov_yz m² with the closed-form Jacobians
      of eqs. (1)-(4): eq. (4), ``P' = T + r rᵀ (P̂ - T)``, gives each past slot ``r gᵀ``
      with ``g = scale rᵀ J`` (``scale``: eq. (2)'s ``1 + ratio`` or ``-ratio``), the newest
      ray's turn ``δr`` moves P' by ``((rᵀq) I + r qᵀ) δr``, ``q = P̂ - T``; a detection in
      several slots adds its slots' Jacobians (the earliest slot holds them); and
      (``with_cov``) eq. (2)'s model error's terms along the newest ray, which
      :func:`pslog.fusion.pseudo.with_measured_noise` adds at the measured noise: gravity's
      ``(h rᵀg)²``, the innovation's ``|u|²`` (the prediction's offset across the newest ray
      less gravity's, m²) and its noise per pixel² ``(factor D / f)²``.

    The other arguments are :func:`_pseudo_one`'s and: ``ray_dir`` (n, 3) the detections'
    rays, ``obs_jac`` (3, 2, n) their direction Jacobians, ``jac4`` (n, 4) their
    d(undistorted) / d(recorded pixel) (``lens`` False: the identity), ``rtki`` (m, 9)
    Rᵀ K⁻¹, ``ns`` nanoseconds per second, ``noise_px`` the detection noise (pixels).
    ``ff``, ``fi`` may have one place (``(2, 1, ·)``): a scratch row for each target, for
    callers that keep no construction; ``past_rows`` (2, k, 3) int64 (row, prev, next) and
    ``past_points`` (2, k, 3) float64 receive each point's two past points either way (what
    the kink test reads), 96 bytes a point instead of the tables' 416 (fresh memory's page
    faults were a quarter of a session's time). ``predicted``, and ``flags``,
    ``innovation``, ``factor``, ``model``, have k places or one (a scratch place), and
    ``past_rows``, ``past_points`` k places or one (``(2, 1, 3)``). ``rows_out`` (k,): each
    output place's target row.

    ``decide``: also the decisions :func:`pslog.fusion.pseudo.fuse_type_a` takes on each
    point made, in the same loop (the outputs' places then hold only the points kept):

    - the tests' noise ``σ`` (:meth:`pslog.fusion.innovation.NoiseEstimate.sigmas`, the same
      selections): ``max(floor, DEFAULT_NOISE_PX)`` until ``NOISE_EVERY`` innovations are
      taken, then ``max(floor, m / RAYLEIGH_MEDIAN)``, ``m`` the upper median of the last
      ``NOISE_WINDOW`` innovations before the latest multiple of ``NOISE_EVERY`` taken before
      the point; ``noise_values`` (L + k,) holds the estimate's last L innovations
      (``noise_count`` taken so far) and receives each finite, valid point's
      ``innovation / factor`` after them;
    - the prediction test (``innovation > INNOVATION_SIGMAS σ factor + model``), the kink
      test (:func:`_kinked`; ``row_before``, ``row_after`` (n,) each row's previous and next
      row of its camera, ``bend_change``, ``bend_root`` :func:`bend_rows`' tables,
      ``lens_table`` (m, 8)) and
      whether the point rests on a row in ``doubted`` ((n,) bool, or (0,): none);
    - ``counts`` (8,) int64, written: the finite points' flags BEHIND, OUTSIDE_VIEW,
      PARALLEL, then the points failed, kinked, in doubt, the innovations taken in all
      (``noise_count`` after), the points made; ``sigmas`` (k,) or (1,): each output
      place's σ (k places: the tests read them; one: a scratch place).

    Returns the number of output places written (the points made; ``decide``: kept).
    """
    m = centers.shape[0]
    slots = np.empty(7, dtype=np.int64)
    times = np.empty(7, dtype=np.int64)
    res = np.empty(5)
    jac = np.empty((2, 3, 2))  # (past point, slot obs/prev/next, pixel axis)
    g = np.empty((7, 2))
    newest = np.empty((3, 2))
    taken = np.zeros(7, dtype=np.bool_)
    nl = np.empty((3, 2))
    r = np.empty(3)
    q = np.empty(3)
    made = 0
    # (decide: the noise estimate's state, its checkpoint's median made once, bend tables)
    every = _NOISE_EVERY
    offset = noise_count - (noise_values.shape[0] - targets.shape[0])  # global index - place
    taken_n = noise_count
    median_at = np.int64(-1)
    median = np.nan  # (the previous checkpoint's median: the next one's hint)
    window = np.empty(_NOISE_WINDOW)
    band = np.empty(_NOISE_WINDOW)
    start_sigma = floor
    if _DEFAULT_NOISE_PX > start_sigma:  # (max(floor, DEFAULT_NOISE_PX), Python's)
        start_sigma = _DEFAULT_NOISE_PX
    tables = bend_change.shape[0] > 0
    focal_ok = _focal_ok(lens_table)
    any_doubt = doubted.shape[0] > 0
    if decide:
        for j in range(8):
            counts[j] = 0
    for target in range(targets.shape[0]):
        e = targets[target]
        i = made  # (the point's place in the outputs: the targets with a point, packed)
        pq = i if predicted.shape[0] > 1 else 0  # (k places, or a scratch place)
        pl = i if innovation.shape[0] > 1 else 0  # (flags, innovation, factor, model)
        pr = i if past_rows.shape[1] > 1 else 0
        # (the place in the tables: i, or 0 in tables of one place, a scratch row for
        # callers that keep no construction; past_rows/past_points keep what they need)
        at = i if ff.shape[1] > 1 else 0
        # the past points, instant by instant back from the target
        first = -1
        second = -1
        t_first = np.int64(0)
        before = e
        candidate = e
        for k in range(depth):
            b = previous_instant[max(before, 0)]
            if k > 0 and candidate < 0:
                b = -1
            reachable = (b >= 0) and (time_ns[e] - time_ns[max(b, 0)] <= max_gap_ns)
            before = b
            candidate = b if reachable else -1
            # as P_{t-2}, a candidate must leave eq. (2) a bounded extrapolation
            spaced = (first < 0) or (time_ns[e] - t_first <= max_extrapolation * (
                t_first - time_ns[max(candidate, 0)]))
            if candidate >= 0 and spaced:
                slot = 0 if first < 0 else 1
                ok, bits = _pseudo_one(candidate, e, max_gap_ns, time_ns, camera, prev_b,
                                       next_b, uv, observed_rays, centers, ki, rr, f9, cam,
                                       span_tie_ns, min_angle_deg, ff, fi, slot, at)
                refused[candidate] |= bits
                if ok:
                    if first < 0:
                        first = k
                        t_first = time_ns[candidate]
                    else:
                        second = k
                        break
            if candidate < 0:
                break  # (no earlier instant within max_gap_ns: none further back either)
        has[target] = second >= 0
        if second < 0:
            continue
        for pp in range(2):  # the past points' rows (row, bracket) and points, compact
            for j in range(3):
                past_rows[pp, pr, j] = fi[pp, at, j if j == 0 else j + 1]
                past_points[pp, pr, j] = ff[pp, at, 7 + j]
        slots[0], slots[1], slots[2], slots[3] = e, fi[0, at, 0], fi[0, at, 2], fi[0, at, 3]
        slots[4], slots[5], slots[6] = fi[1, at, 0], fi[1, at, 2], fi[1, at, 3]
        for s in range(7):
            times[s] = time_ns[slots[s]]
        t_event, t1, t2 = times[0], times[1], times[4]
        c0 = camera[e]
        # eq. (2): linear prediction with the actual capture intervals
        ratio = (t_event - t1) / (t1 - t2)
        for j in range(3):
            predicted[pq, j] = ff[0, at, 7 + j] + ratio * (ff[0, at, 7 + j] - ff[1, at, 7 + j])
        # eqs. (3)-(4): nearest point on the newest viewing ray
        d0, d1, d2 = ray_dir[e, 0], ray_dir[e, 1], ray_dir[e, 2]
        for j in range(3):
            q[j] = predicted[pq, j] - centers[c0, j]
        k_foot = _dot3(q[0], q[1], q[2], d0, d1, d2) / _dot3(d0, d1, d2, d0, d1, d2)
        pt0 = k_foot * d0 + centers[c0, 0]
        pt1 = k_foot * d1 + centers[c0, 1]
        pt2 = k_foot * d2 + centers[c0, 2]
        points[i, 0] = pt0
        points[i, 1] = pt1
        points[i, 2] = pt2
        bits = 0
        if math.isfinite(pt0) and math.isfinite(pt1) and math.isfinite(pt2):
            for cc in range(m):  # the cameras of the seven detections, in camera order
                for s in range(7):
                    if camera[slots[s]] == cc:
                        bits |= _invalid(cam, cc, pt0, pt1, pt2)
                        break
        if not (k_foot > 0):
            bits |= 1  # eq. (4)'s k: the foot behind the newest camera
        flags[pl] = bits
        res[0], res[1], res[2], res[3] = ff[0, at, 5], ff[0, at, 6], ff[1, at, 5], ff[1, at, 6]
        # the newest detection against the prediction, before eq. (4) moves it onto its ray
        res[4] = _reprojection(cam, c0, predicted[pq, 0], predicted[pq, 1], predicted[pq, 2],
                               uv[e, 0], uv[e, 1])
        innovation[pl] = res[4]
        # the prediction test's terms (innovation.failed_predictions, operation for
        # operation): the noise factor of ρ = δ_pred / δ_prev and the model's bound
        delta_pred = (t_event - t1) / ns
        delta_prev = (t1 - t2) / ns
        rho = delta_pred / delta_prev
        factor[pl] = math.sqrt(1.0 + (1.0 + rho) * (1.0 + rho) + rho * rho)
        distance = q[0] * q[0] + q[1] * q[1]  # (np.linalg.norm's order)
        distance += q[2] * q[2]
        distance = math.sqrt(distance)
        z_axis = q[0] * cam[c0, 15] + q[1] * cam[c0, 16]  # (np.sum's order; R[2]: the axis)
        z_axis += q[2] * cam[c0, 17]
        focal = _max(cam[c0, 0], cam[c0, 4])
        model[pl] = (0.5 * _G * delta_pred * (delta_pred + delta_prev) * focal * distance
                    / (z_axis * z_axis))
        # slots holding a detection no earlier slot holds
        n_distinct = 1
        for s in range(1, 7):
            repeated = False
            for t in range(s):
                if slots[t] == slots[s]:
                    repeated = True
            if not repeated:
                n_distinct += 1
        t_earliest = times[0]
        for s in range(1, 7):
            t_earliest = min(t_earliest, times[s])
        span1 = (times[3] - times[2]) / ns
        span2 = (times[6] - times[5]) / ns
        quality[0, i] = _max(ff[0, at, 1], ff[1, at, 1])
        # measured before the snap: after it the rays cross by construction
        quality[1, i] = _max(ff[0, at, 4], ff[1, at, 4])
        shift = (pt0 - predicted[pq, 0]) * (pt0 - predicted[pq, 0])
        shift += (pt1 - predicted[pq, 1]) * (pt1 - predicted[pq, 1])
        shift += (pt2 - predicted[pq, 2]) * (pt2 - predicted[pq, 2])
        quality[2, i] = math.sqrt(shift)
        quality[3, i] = _min(ff[0, at, 3], ff[1, at, 3]) * _DEGREES
        worst = res[0]
        total = res[0] + res[1]
        for s in range(1, 5):
            worst = _max(worst, res[s])
        for s in range(2, 5):
            total += res[s]
        quality[4, i] = worst
        quality[5, i] = total / 5
        mask = 0.0
        for cc in range(m):  # (sums of distinct powers of two: exact in any order)
            for s in range(7):
                if camera[slots[s]] == cc:
                    mask += 2.0**cc
                    break
        quality[6, i] = mask
        quality[7, i] = float(n_distinct)
        quality[8, i] = _max(_max(span1, span2), (t_event - t2) / ns)
        quality[9, i] = (t_event - t_earliest) / ns
        # eq. (2)'s model error along the newest ray (docs/methods.md, "Type A's model error
        # in its covariance"): under a constant acceleration a the prediction is off by
        # -½ a δ_pred (δ_pred + δ_prev) = -h a, which eq. (4) keeps along r: gravity's part
        # (h rᵀg)², and the innovation's across-ray offset u of P̂ less gravity's there
        # (|u|², the rest of the acceleration seen across; its noise part made at the
        # measured σ later: c σ², c = (factor D / f)², metres per pixel noise squared)
        h = 0.5 * delta_pred * (delta_pred + delta_prev)
        norm_r = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        ra0, ra1, ra2 = d0 / norm_r, d1 / norm_r, d2 / norm_r
        along_q = q[0] * ra0 + q[1] * ra1 + q[2] * ra2
        bias = -_G * h * ra2  # h rᵀg, g = (0, 0, -G): the world is z up
        # u = (q - (rᵀq) r) + h (g - (rᵀg) r)
        e0 = q[0] - along_q * ra0 - bias * ra0
        e1 = q[1] - along_q * ra1 - bias * ra1
        e2 = q[2] - along_q * ra2 - bias * ra2 - _G * h
        quality[17, i] = bias * bias
        quality[18, i] = e0 * e0 + e1 * e1 + e2 * e2
        spread = factor[pl] * distance / focal
        quality[19, i] = spread * spread
        rows_out[i] = e
        if decide:
            counts[7] += 1
            finite = math.isfinite(pt0) and math.isfinite(pt1) and math.isfinite(pt2)
            if finite:
                for j in range(3):
                    if bits & (1 << j):
                        counts[j] += 1
            good = finite and bits == 0
            # the tests' noise (NoiseEstimate.sigmas: its checkpoint's upper median, a
            # selection, the same element)
            sigma = start_sigma
            mark = taken_n // every * every
            if mark >= every:
                if mark != median_at:
                    lo = max(mark - _NOISE_WINDOW, 0) - offset
                    count = mark - offset - lo
                    for j in range(count):
                        window[j] = noise_values[lo + j]
                    median = _select_near(window, count, count // 2, median, 0.1 * median,
                                          band)
                    median_at = mark
                implied = median / _RAYLEIGH_MEDIAN
                sigma = floor if floor >= implied else implied  # (np.maximum, no NaN)
            sigmas[i if sigmas.shape[0] > 1 else 0] = sigma
            value = innovation[pl] / factor[pl]
            if good and value == value:  # (taken: after its own σ)
                noise_values[taken_n - offset] = value
                taken_n += 1
            failed = good and innovation[pl] > _INNOVATION_SIGMAS * (sigma * factor[pl]) \
                + model[pl]
            # the kink test (:func:`_kinked`, the same test, operation for operation),
            # written out here rather than inlined: numba binds an inlined helper's array
            # arguments to new variables and, across the helper's branches, kept their
            # reference counts (atomic calls; 62 more call sites in this kernel inlined:
            # 1.2x its time on bench_peers' session); the kernel's own arrays take none.
            # test_kink_kernel's fuse decisions against the columnar reference hold the two
            # forms together (the past points' part: the newest camera's part decides no
            # point of its sessions differently, in _kinked as here).
            kinked = False
            if good and not failed:
                row1, prev1, next1 = fi[0, at, 0], fi[0, at, 2], fi[0, at, 3]
                row2, prev2, next2 = fi[1, at, 0], fi[1, at, 2], fi[1, at, 3]
                x1, y1, z1 = ff[0, at, 7], ff[0, at, 8], ff[0, at, 9]
                x2, y2, z2 = ff[1, at, 7], ff[1, at, 8], ff[1, at, 9]
                speed = (math.sqrt((x1 - x2) * (x1 - x2) + (y1 - y2) * (y1 - y2)
                                   + (z1 - z2) * (z1 - z2))
                         / ((time_ns[row1] - time_ns[row2]) / ns))
                calm = speed >= 0.0
                for s in range(2):
                    prev = prev1 if s == 0 else prev2
                    nxt = next1 if s == 0 else next2
                    px = x1 if s == 0 else x2
                    py = y1 if s == 0 else y2
                    pz = z1 if s == 0 else z2
                    zero = row_before[prev] if prev >= 0 else -1  # (_kinked's ``first``)
                    mid = max(prev, 0)
                    quiet = _quiet(tables and prev >= 0 and row_before[mid] == zero
                                   and row_after[mid] == nxt,
                                   bend_change[mid] if tables else 0.0,
                                   bend_root[mid] if tables else 0.0, sigma,
                                   calm and focal_ok[camera[mid]])
                    if not quiet and _bent(zero, prev, nxt, e, t_event, max_gap_ns, px, py, pz,
                                           speed, sigma, time_ns, uv, camera, lens_table, ns):
                        later = row_after[nxt] if nxt >= 0 else -1
                        if (prev >= 0 and nxt >= 0 and later >= 0 and later <= e
                                and t_event - time_ns[prev] <= 2 * max_gap_ns):
                            quiet = _quiet(tables and row_before[nxt] == prev
                                           and row_after[nxt] == later,
                                           bend_change[nxt] if tables else 0.0,
                                           bend_root[nxt] if tables else 0.0, sigma,
                                           calm and focal_ok[camera[nxt]])
                            kinked = kinked or (not quiet and _bend(
                                prev, nxt, later, px, py, pz, speed, sigma, time_ns, uv, camera,
                                lens_table, ns))
                        else:
                            earlier = row_before[zero] if zero >= 0 else -1
                            mid = max(zero, 0)
                            quiet = _quiet(tables and zero >= 0 and row_before[mid] == earlier
                                           and row_after[mid] == prev,
                                           bend_change[mid] if tables else 0.0,
                                           bend_root[mid] if tables else 0.0, sigma,
                                           calm and focal_ok[camera[mid]])
                            kinked = kinked or not (not quiet and _bent(
                                earlier, zero, prev, e, t_event, max_gap_ns, px, py, pz, speed,
                                sigma, time_ns, uv, camera, lens_table, ns))
                if not kinked:  # the newest camera
                    mid = row_before[e]
                    zero = row_before[mid] if mid >= 0 else -1
                    hold = max(mid, 0)
                    quiet = _quiet(tables and mid >= 0 and row_before[hold] == zero
                                   and row_after[hold] == e,
                                   bend_change[hold] if tables else 0.0,
                                   bend_root[hold] if tables else 0.0, sigma,
                                   calm and focal_ok[camera[hold]])
                    if not quiet and _bent(zero, mid, e, e, t_event, max_gap_ns,
                                           predicted[pq, 0], predicted[pq, 1], predicted[pq, 2],
                                           speed, sigma, time_ns, uv, camera, lens_table, ns):
                        start = time_ns[hold]
                        earlier = row_before[zero] if zero >= 0 else -1
                        hold = max(zero, 0)
                        quiet = _quiet(tables and zero >= 0 and row_before[hold] == earlier
                                       and row_after[hold] == mid,
                                       bend_change[hold] if tables else 0.0,
                                       bend_root[hold] if tables else 0.0, sigma,
                                       calm and focal_ok[camera[hold]])
                        if not quiet and _bent(earlier, zero, mid, e, t_event, max_gap_ns,
                                               predicted[pq, 0], predicted[pq, 1],
                                               predicted[pq, 2], speed, sigma, time_ns, uv,
                                               camera, lens_table, ns):
                            start = time_ns[hold]
                        kinked = start >= time_ns[row2]
            keep = good and not failed and not kinked
            if failed:
                counts[3] += 1
            if kinked:
                counts[4] += 1
            if keep and any_doubt and _rests_on_doubt(
                    doubted, e, fi[0, at, 0], fi[0, at, 2], fi[0, at, 3], fi[1, at, 0],
                    fi[1, at, 2], fi[1, at, 3]):
                counts[5] += 1
                keep = False
            if not keep:
                continue
        made += 1
        if not with_cov:
            continue
        # the newest ray's turn: ((rᵀq) I + r qᵀ) G, G its direction's Jacobian
        r[0], r[1], r[2] = d0, d1, d2
        rq = r[0] * q[0] + r[1] * q[1] + r[2] * q[2]
        for a in range(2):
            qg = q[0] * obs_jac[0, a, e]
            qg += q[1] * obs_jac[1, a, e]
            qg += q[2] * obs_jac[2, a, e]
            for j in range(3):
                newest[j, a] = rq * obs_jac[j, a, e]
                newest[j, a] += r[j] * qg
        # the past points' Jacobians seen along r (steps 1-3 differentiated, for one point;
        # pslog.fusion.pseudo's former _pseudo_jacobians, operation for operation): with
        # P = T_j + s_j d_j on both rays (they meet after the snap), a turn δd_j of ray j
        # moves P by s_j A⁻¹ δd_j, A = Σ (I - d dᵀ); rᵀ A⁻¹ = wᵀ with
        # w = r / 2 + (r_d1 + c r_d2) d1 + (c r_d1 + r_d2) d2 (Woodbury). The snapped point
        # moves with the interpolated one by I - n nᵀ and with the observed pixel as it moves
        # the epipolar line; eq. (1) weighs the bracket by 1 - w and w.
        for pp in range(2):
            row = fi[pp, at, 0]
            cam_obs = camera[row]
            partner = max(fi[pp, at, 1], 0)
            w_eq1 = ff[pp, at, 0]
            a0, a1, a2 = ff[pp, at, 10], ff[pp, at, 11], ff[pp, at, 12]
            b0, b1, b2 = ff[pp, at, 13], ff[pp, at, 14], ff[pp, at, 15]
            cos = a0 * b0 + a1 * b1 + a2 * b2
            scale = 0.5 / (1 - cos * cos)
            r_d1 = (r[0] * a0 + r[1] * a1 + r[2] * a2) * scale
            r_d2 = (r[0] * b0 + r[1] * b1 + r[2] * b2) * scale
            f1 = r_d1 + cos * r_d2
            f2 = cos * r_d1 + r_d2
            w0 = 0.5 * r[0] + f1 * a0 + f2 * b0
            w1 = 0.5 * r[1] + f1 * a1 + f2 * b1
            w2 = 0.5 * r[2] + f1 * a2 + f2 * b2
            p0, p1, p2 = ff[pp, at, 7], ff[pp, at, 8], ff[pp, at, 9]
            s1 = ((p0 - centers[cam_obs, 0]) * a0 + (p1 - centers[cam_obs, 1]) * a1
                  + (p2 - centers[cam_obs, 2]) * a2)
            s2 = ((p0 - centers[partner, 0]) * b0 + (p1 - centers[partner, 1]) * b1
                  + (p2 - centers[partner, 2]) * b2)
            # J_obs = wᵀ G (G: the observed ray's direction Jacobian), times s1
            j_obs0 = w0 * obs_jac[0, 0, row]
            j_obs0 += w1 * obs_jac[1, 0, row]
            j_obs0 += w2 * obs_jac[2, 0, row]
            j_obs1 = w0 * obs_jac[0, 1, row]
            j_obs1 += w1 * obs_jac[1, 1, row]
            j_obs1 += w2 * obs_jac[2, 1, row]
            j_obs0 *= s1
            j_obs1 *= s1
            # J_snapped = wᵀ dd/duv of the partner's ray at the snapped pixel (direction_jacobian_
            # along), times s2
            us0, us1 = ff[pp, at, 18], ff[pp, at, 19]
            rv0, rv1, rv2 = _homogeneous(rtki, partner, us0, us1)
            norm2 = rv0 * rv0 + rv1 * rv1 + rv2 * rv2
            vm0 = w0 * rtki[partner, 0]
            vm0 += w1 * rtki[partner, 3]
            vm0 += w2 * rtki[partner, 6]
            vm1 = w0 * rtki[partner, 1]
            vm1 += w1 * rtki[partner, 4]
            vm1 += w2 * rtki[partner, 7]
            rm0 = rv0 * rtki[partner, 0]
            rm0 += rv1 * rtki[partner, 3]
            rm0 += rv2 * rtki[partner, 6]
            rm1 = rv0 * rtki[partner, 1]
            rm1 += rv1 * rtki[partner, 4]
            rm1 += rv2 * rtki[partner, 7]
            along = (w0 * rv0 + w1 * rv1 + w2 * rv2) / norm2
            rm0 *= along
            rm1 *= along
            vm0 -= rm0
            vm1 -= rm1
            root = math.sqrt(norm2)
            js0 = vm0 / root
            js1 = vm1 / root
            js0 *= s2
            js1 *= s2
            # the snap u_s = u_i - s n onto the line l = F (u_o, v_o, 1) = (a, l3), n = a / |a|,
            # s = (a·u_i + l3) / |a|; a move of u_o changes l by F[:, :2] δ, which moves u_s by
            # -n ((u_sᵀ da + dl3) / |a|) - s (I - n nᵀ) da / |a|
            fr = cam_obs * m + partner
            u, v = uv[row, 0], uv[row, 1]
            l0 = f9[fr, 0] * u + f9[fr, 1] * v + f9[fr, 2]
            l1 = f9[fr, 3] * u + f9[fr, 4] * v + f9[fr, 5]
            l2 = f9[fr, 6] * u + f9[fr, 7] * v + f9[fr, 8]
            size = math.sqrt(l0 * l0 + l1 * l1)
            nn0 = l0 / size
            nn1 = l1 / size
            signed = (l0 * ff[pp, at, 16] + l1 * ff[pp, at, 17] + l2) / size
            da00, da01 = f9[fr, 0] / size, f9[fr, 1] / size
            da10, da11 = f9[fr, 3] / size, f9[fr, 4] / size
            dl0, dl1 = f9[fr, 6] / size, f9[fr, 7] / size
            shift0 = us0 * da00 + us1 * da10 + dl0
            shift1 = us0 * da01 + us1 * da11 + dl1
            nda0 = nn0 * da00 + nn1 * da10
            nda1 = nn0 * da01 + nn1 * da11
            ml00 = -nn0 * shift0 - signed * (da00 - nn0 * nda0)
            ml01 = -nn0 * shift1 - signed * (da01 - nn0 * nda1)
            ml10 = -nn1 * shift0 - signed * (da10 - nn1 * nda0)
            ml11 = -nn1 * shift1 - signed * (da11 - nn1 * nda1)
            j_obs0 += js0 * ml00 + js1 * ml10
            j_obs1 += js0 * ml01 + js1 * ml11
            jn = js0 * nn0 + js1 * nn1
            ji0 = js0 - jn * nn0
            ji1 = js1 - jn * nn1
            jac[pp, 0, 0] = j_obs0
            jac[pp, 0, 1] = j_obs1
            jac[pp, 1, 0] = (1 - w_eq1) * ji0
            jac[pp, 1, 1] = (1 - w_eq1) * ji1
            jac[pp, 2, 0] = w_eq1 * ji0
            jac[pp, 2, 1] = w_eq1 * ji1
        scale1 = 1 + ratio
        scale2 = -ratio
        for s in range(3):
            for a in range(2):
                g[1 + s, a] = jac[0, s, a] * scale1
                g[4 + s, a] = jac[1, s, a] * scale2
        # a detection in several slots: its later slots' Jacobians into its first
        for s in range(7):
            taken[s] = False
        for s in range(7):
            if taken[s] or slots[s] < 0:
                continue
            for t in range(s + 1, 7):
                if slots[t] == slots[s] and not taken[t]:
                    taken[t] = True
                    if s == 0:
                        for j in range(3):
                            for a in range(2):
                                newest[j, a] += r[j] * g[t, a]
                    else:
                        g[s, 0] += g[t, 0]
                        g[s, 1] += g[t, 1]
        along = 0.0  # Σ |g L|² of the past slots
        for s in range(1, 7):
            gl0, gl1 = _pixel_jacobian(jac4, lens, slots[s], g[s, 0], g[s, 1])
            along += 0.0 if taken[s] else gl0 * gl0 + gl1 * gl1
        for j in range(3):
            nl[j, 0], nl[j, 1] = _pixel_jacobian(jac4, lens, e, newest[j, 0], newest[j, 1])
        var = noise_px**2
        for n in range(6):  # xx, yy, zz, xy, xz, yz
            a = n if n < 3 else (0 if n < 5 else 1)
            b = n if n < 3 else (1 if n == 3 else 2)
            quality[11 + n, i] = (nl[a, 0] * nl[b, 0] + nl[a, 1] * nl[b, 1]
                                  + r[a] * r[b] * along) * var
        quality[10, i] = math.sqrt(quality[11, i] + quality[12, i] + quality[13, i])
    if decide:
        counts[6] = taken_n
    return made


def camera_tables(prep):
    """The per-camera tables the kernels take: ``cam`` (m, 31), ``ki``, ``rr``, ``rtki``
    (m, 9), ``f9`` (m * m, 9) (see :func:`_pseudo_one`) and ``lens`` (bool: some camera has
    lens distortion), cached on ``prep``."""
    cache = prep.__dict__.get("_kernel_tables")
    if cache is not None:
        return cache
    m = len(prep.centers)
    cam = np.zeros((m, 31))
    for c, camera in enumerate(prep.cameras):
        cam[c, 0:9] = np.asarray(camera.K, np.float64).ravel()
        cam[c, 9:18] = np.asarray(camera.R, np.float64).ravel()
        cam[c, 18:21] = np.asarray(camera.t, np.float64).ravel()
        cam[c, 21:26] = np.asarray(camera.dist, np.float64).ravel()
        cam[c, 26:30] = prep.view_box[c]
        cam[c, 30] = 1.0 if np.any(camera.dist) else 0.0
    tables = (cam, np.ascontiguousarray(prep._cols("K_inv").T),
              np.ascontiguousarray(prep._cols("R").T),
              np.ascontiguousarray(prep._rt_k_inv_cols.T),
              np.ascontiguousarray(prep._f_cols.T), bool(np.any(cam[:, 30])))
    prep.__dict__["_kernel_tables"] = tables
    return tables


@kernel
def brackets_kernel(time_ns, camera, prev_b, next_b, previous_instant):
    """Each row's bracket in every camera and its previous instant, in two passes over the
    sorted rows: ``prev_b[d, r]`` the latest row of camera d at or before row r's time,
    ``next_b[d, r]`` the earliest at or after it (-1: none; the same row on an exact match:
    :func:`~pslog.fusion._prepare.bracket`), ``previous_instant[r]`` the latest row of the
    instant before r's (a strictly earlier time; -1: none)."""
    m = prev_b.shape[0]
    n = time_ns.shape[0]
    last = np.full(m, -1, dtype=np.int64)
    start = 0
    while start < n:  # instants (rows of one time) forwards
        end = start + 1
        while end < n and time_ns[end] == time_ns[start]:
            end += 1
        for r in range(start, end):
            last[camera[r]] = r
        for r in range(start, end):
            previous_instant[r] = start - 1
            for d in range(m):
                prev_b[d, r] = last[d]
        start = end
    last[:] = -1
    end = n
    while end > 0:  # instants backwards
        start = end - 1
        while start > 0 and time_ns[start - 1] == time_ns[end - 1]:
            start -= 1
        for r in range(end - 1, start - 1, -1):
            last[camera[r]] = r
        for r in range(start, end):
            for d in range(m):
                next_b[d, r] = last[d]
        end = start


# -- type A's kink test (pslog.fusion.innovation.kinked_points), point by point -----------

@kernel
def _bend(a, b, c, px, py, pz, speed, sigma, time_ns, uv, camera, lens, ns):
    """Whether one camera's 2D track bends at row ``b`` (rows ``a < b < c``) more than
    ballistic motion and the noise ``sigma`` (px) allow; ``px, py, pz`` a world point near
    the ball (metres, for its depth), ``speed`` m/s; ``lens`` (n_cameras, 8): fx, fy, cx,
    cy, R[2] (3), t[2]. The arithmetic of innovation._bends' former columns, in the same
    order (the same bits); its derivation is :func:`~pslog.fusion.innovation.kinked_points`'."""
    cam = camera[b]
    fx, fy, cx, cy = lens[cam, 0], lens[cam, 1], lens[cam, 2], lens[cam, 3]
    dt1 = (time_ns[b] - time_ns[a]) / ns
    dt2 = (time_ns[c] - time_ns[b]) / ns
    v1x, v1y = (uv[b, 0] - uv[a, 0]) / dt1, (uv[b, 1] - uv[a, 1]) / dt1
    v2x, v2y = (uv[c, 0] - uv[b, 0]) / dt2, (uv[c, 1] - uv[b, 1]) / dt2
    dx, dy = v2x - v1x, v2y - v1y
    change = math.sqrt(dx * dx + dy * dy)
    both = 1.0 / dt1 + 1.0 / dt2
    sigma_change = sigma * math.sqrt(1.0 / (dt1 * dt1) + both * both + 1.0 / (dt2 * dt2))
    noise_bound = _KINK_SIGMAS * sigma_change
    focal = _max(fx, fy)
    if change <= noise_bound and focal >= 0.0 and speed >= 0.0:
        # within the noise alone: the model's term below is >= 0 (or NaN) wherever the
        # test can fire (depth > 0; focal, speed >= 0), and IEEE addition of a non-negative
        # term never rounds below the other (fl(x + y) >= x), so the bend cannot exceed
        # the bound: the usual case (a smooth track), decided without the depth and three
        # square roots, the same decision as the full test's, bit for bit
        return False
    depth = lens[cam, 4] * px + lens[cam, 5] * py + lens[cam, 6] * pz + lens[cam, 7]
    ox, oy = (uv[b, 0] - cx) / focal, (uv[b, 1] - cy) / focal
    # d²u/dt² = f (a_xy - x a_z) / Z - 2 (Ż / Z) du/dt; |a| = g, |Ż| <= speed
    pixel_speed = _max(math.sqrt(v1x * v1x + v1y * v1y), math.sqrt(v2x * v2x + v2y * v2y))
    acceleration = (focal * _G * math.sqrt(1.0 + ox * ox + oy * oy)
                    + 2.0 * speed * pixel_speed) / depth
    bound = noise_bound + 0.5 * (dt1 + dt2) * acceleration
    return dt1 > 0 and dt2 > 0 and depth > 0 and change > bound


@kernel
def bend_rows(time_ns, uv, before, after, ns, change, root):
    """:func:`_bend`'s terms that depend on its triplet alone, for the triplet around each
    row ``b``, ``(before[b], b, after[b])`` (its camera's rows before and after it), made
    once per row instead of at every point whose kink test reads that triplet: ``change``
    ``|Δv|`` (px/s) and ``root`` ``√(1/δ1² + (1/δ1 + 1/δ2)² + 1/δ2²)`` (1/s), (n,) float64,
    written (NaN where the row has no triplet). The same IEEE operations on the same
    operands as :func:`_bend`'s (the same bits); a pair of consecutive rows' interval,
    velocity and inverse intervals are made once and read by the triplets on both sides."""
    n = time_ns.shape[0]
    pair = np.empty((n, 5))  # per row a and its camera's next row: δ, v (2), 1/δ, 1/δ²
    for a in range(n):
        b = after[a]
        if b < 0:
            continue
        dt = (time_ns[b] - time_ns[a]) / ns
        pair[a, 0] = dt
        pair[a, 1] = (uv[b, 0] - uv[a, 0]) / dt
        pair[a, 2] = (uv[b, 1] - uv[a, 1]) / dt
        pair[a, 3] = 1.0 / dt
        pair[a, 4] = 1.0 / (dt * dt)
    for b in range(n):
        a, c = before[b], after[b]
        if a < 0 or c < 0:
            change[b] = np.nan
            root[b] = np.nan
            continue
        dx, dy = pair[b, 1] - pair[a, 1], pair[b, 2] - pair[a, 2]
        change[b] = math.sqrt(dx * dx + dy * dy)
        both = pair[a, 3] + pair[b, 3]
        root[b] = math.sqrt(pair[a, 4] + both * both + pair[b, 4])


@kernel
def _bent(a, b, c, event, t_event, max_gap_ns, px, py, pz, speed, sigma, time_ns, uv,
          camera, lens, ns):
    """:func:`_bend` where the triplet is available (all three rows, none after the newest
    detection ``event``, ``a`` within ``2 max_gap`` of it); False elsewhere."""
    if a < 0 or b < 0 or c < 0 or c > event or t_event - time_ns[a] > 2 * max_gap_ns:
        return False
    return _bend(a, b, c, px, py, pz, speed, sigma, time_ns, uv, camera, lens, ns)


@kernel
def _quiet(held, change, root, sigma, calm):
    """Whether :func:`bend_rows`' tables decide a triplet within the noise: ``held`` (they
    hold it: its rows are the camera's consecutive rows around its middle one), ``change``
    and ``root`` its row's entries, ``calm`` (the camera's focal length and the speed are
    >= 0). :func:`_bend`'s usual case, its same decision (no bend) from the same bits,
    without its divisions; False where undecided (then :func:`_bent`). Scalars only: a
    compiled call takes a reference to each array it is given (two atomic operations)."""
    return held and calm and change <= _KINK_SIGMAS * (sigma * root)


@kernel(inline=True)
def _kinked(event, row1, prev1, next1, x1, y1, z1, row2, prev2, next2, x2, y2, z2, qx, qy, qz,
            sg, before, after, time_ns, uv, camera, lens, max_gap_ns, ns, tables, change, root,
            focal_ok):
    """One point's kink flag (:func:`kink_kernel`'s per-point test, which
    :func:`type_a_kernel` writes out in its loop, operation for operation: inlined there,
    its array arguments' reference counts were a sixth of that kernel's time): ``event`` its
    newest row, ``row``, ``prev``,
    ``next`` and ``(x, y, z)`` (metres) of ``P_{t-1}`` (1) and ``P_{t-2}`` (2), ``(qx, qy,
    qz)`` eq. (2)'s prediction, ``sg`` its noise (px), ``tables`` whether ``change`` and
    ``root`` hold :func:`bend_rows`' tables, ``focal_ok`` (m,) each camera's ``max(fx, fy)
    >= 0``; the other arguments :func:`kink_kernel`'s."""
    t_event = time_ns[event]
    speed = (math.sqrt((x1 - x2) * (x1 - x2) + (y1 - y2) * (y1 - y2) + (z1 - z2) * (z1 - z2))
             / ((time_ns[row1] - time_ns[row2]) / ns))
    calm = speed >= 0.0
    kinked = False
    for s in range(2):
        prev = prev1 if s == 0 else prev2
        nxt = next1 if s == 0 else next2
        px = x1 if s == 0 else x2
        py = y1 if s == 0 else y2
        pz = z1 if s == 0 else z2
        first = before[prev] if prev >= 0 else -1
        # a bend at prev: the change lies between prev and next if the triplet after
        # bends too, or (that one still to come) if the triplet before does not
        # (_quiet first: most triplets are decided by bend_rows' tables, no divisions)
        b = max(prev, 0)
        quiet = _quiet(tables and prev >= 0 and before[b] == first and after[b] == nxt,
                       change[b] if tables else 0.0, root[b] if tables else 0.0, sg,
                       calm and focal_ok[camera[b]])
        if not quiet and _bent(first, prev, nxt, event, t_event, max_gap_ns, px, py, pz,
                               speed, sg, time_ns, uv, camera, lens, ns):
            later = after[nxt] if nxt >= 0 else -1
            if (prev >= 0 and nxt >= 0 and later >= 0 and later <= event
                    and t_event - time_ns[prev] <= 2 * max_gap_ns):  # the one after: has
                quiet = _quiet(tables and before[nxt] == prev and after[nxt] == later,
                               change[nxt] if tables else 0.0,
                               root[nxt] if tables else 0.0, sg,
                               calm and focal_ok[camera[nxt]])
                kinked = kinked or (not quiet and _bend(
                    prev, nxt, later, px, py, pz, speed, sg, time_ns, uv, camera, lens,
                    ns))
            else:
                zero = before[first] if first >= 0 else -1
                b = max(first, 0)
                quiet = _quiet(tables and first >= 0 and before[b] == zero
                               and after[b] == prev, change[b] if tables else 0.0,
                               root[b] if tables else 0.0, sg,
                               calm and focal_ok[camera[b]])
                kinked = kinked or not (not quiet and _bent(
                    zero, first, prev, event, t_event, max_gap_ns, px, py, pz, speed, sg,
                    time_ns, uv, camera, lens, ns))
    # the newest camera: its last triplet bends at b, the change between b and the
    # newest detection (or between a and b, if the triplet before bends too); refused
    # when that interval lies inside eq. (2)'s span, from P_{t-2} on (before it, the
    # past points are already on the new motion)
    if not kinked:
        b = before[event]
        a = before[b] if b >= 0 else -1
        h = max(b, 0)
        quiet = _quiet(tables and b >= 0 and before[h] == a and after[h] == event,
                       change[h] if tables else 0.0, root[h] if tables else 0.0, sg,
                       calm and focal_ok[camera[h]])
        if not quiet and _bent(a, b, event, event, t_event, max_gap_ns, qx, qy, qz,
                               speed, sg, time_ns, uv, camera, lens, ns):
            start = time_ns[max(b, 0)]
            zero = before[a] if a >= 0 else -1
            h = max(a, 0)
            quiet = _quiet(tables and a >= 0 and before[h] == zero and after[h] == b,
                           change[h] if tables else 0.0, root[h] if tables else 0.0, sg,
                           calm and focal_ok[camera[h]])
            if not quiet and _bent(zero, a, b, event, t_event, max_gap_ns, qx, qy, qz,
                                   speed, sg, time_ns, uv, camera, lens, ns):
                start = time_ns[max(a, 0)]
            kinked = start >= time_ns[row2]
    return kinked


@kernel
def kink_kernel(events, rows1, prev1, next1, world1, rows2, prev2, next2, world2, predicted,
                sigma, before, after, time_ns, uv, camera, lens, max_gap_ns, ns, out,
                change, root):
    """Type A's kink flags, point by point (:func:`pslog.fusion.innovation.kinked_points`,
    whose docstring derives the test and names the triplets; :func:`_kinked` each point's).

    events (k,) int64, rows of the newest detections; rows/prev/next (k,) int64 and world
    (k, 3) metres of ``P_{t-1}`` (1) and ``P_{t-2}`` (2); predicted (k, 3) metres; sigma (k,)
    px; before/after (n,) int64, each row's previous/next row of its camera (-1: none);
    time_ns (n,) int64; uv (n, 2) undistorted px; camera (n,) int64; lens (n_cameras, 8);
    max_gap_ns int; ns the nanoseconds per second; out (k,) bool, written; change, root
    (n,) float64: :func:`bend_rows`' tables of these rows (or of no rows: each triplet's
    terms made where it is read, as a stream's one point does).
    """
    tables = change.shape[0] > 0
    focal_ok = _focal_ok(lens)
    for i in range(len(events)):
        out[i] = _kinked(events[i], rows1[i], prev1[i], next1[i], world1[i, 0], world1[i, 1],
                         world1[i, 2], rows2[i], prev2[i], next2[i], world2[i, 0],
                         world2[i, 1], world2[i, 2], predicted[i, 0], predicted[i, 1],
                         predicted[i, 2], sigma[i], before, after, time_ns, uv, camera, lens,
                         max_gap_ns, ns, tables, change, root, focal_ok)


@kernel(inline=True)
def _rests_on_doubt(doubted, event, row1, prev1, next1, row2, prev2, next2):
    """Whether a type-A point uses a detection whose gate choice is in doubt (``doubted``
    (n,) bool; docs/methods.md, "A choice in doubt"): its newest row ``event``, ``P_{t-1}``'s
    and ``P_{t-2}``'s observed rows and their partners' brackets (``prev``, ``next``; -1 is
    no row, not the last one)."""
    doubt = doubted[event]
    doubt = doubt or (row1 >= 0 and doubted[max(row1, 0)])
    doubt = doubt or (prev1 >= 0 and doubted[max(prev1, 0)])
    doubt = doubt or (next1 >= 0 and doubted[max(next1, 0)])
    doubt = doubt or (row2 >= 0 and doubted[max(row2, 0)])
    doubt = doubt or (prev2 >= 0 and doubted[max(prev2, 0)])
    return doubt or (next2 >= 0 and doubted[max(next2, 0)])


@kernel(inline=True)
def _focal_ok(lens):
    """(m,) bool: each camera's ``max(fx, fy) >= 0`` (:func:`_bend`'s condition), of
    ``lens`` (m, 8)."""
    m = lens.shape[0]
    focal_ok = np.empty(m, dtype=np.bool_)
    for cam in range(m):
        focal_ok[cam] = _max(lens[cam, 0], lens[cam, 1]) >= 0.0
    return focal_ok


@kernel(inline=True)
def _residual_norm(t0, t1, t2, t3, u0, v0, u1, v1, u2, v2, u3, v3, lim, gap, ns):
    """A row's residual (recorded pixel ``u0, v0`` at ``t0`` ns) from the quadratic through
    its camera's three previous rows (``u1, v1`` at ``t1`` the newest, then 2 and 3), per
    axis's σ; NaN where the intervals are not all in ``(0, gap]`` s or a pixel is NaN or
    beyond its camera's bound ``lim`` (prepare's "no detection"). Scalars, not the arrays and
    rows: inlined, an array argument's reference is kept across the early returns (atomic
    counts at every row: the residuals' pass took 2.1x as long)."""
    if not (abs(u0) <= lim and abs(v0) <= lim and abs(u1) <= lim and abs(v1) <= lim
            and abs(u2) <= lim and abs(v2) <= lim and abs(u3) <= lim and abs(v3) <= lim):
        return np.nan
    a = (t0 - t1) / ns
    b = (t1 - t2) / ns
    cc = (t2 - t3) / ns
    if not (a > 0 and b > 0 and cc > 0 and a <= gap and b <= gap and cc <= gap):
        return np.nan
    l1 = (a + b) * (a + b + cc) / (b * (b + cc))
    l2 = -a * (a + b + cc) / (b * cc)
    l3 = a * (a + b) / ((b + cc) * cc)
    e0 = u0 - (l1 * u1 + l2 * u2 + l3 * u3)
    e1 = v0 - (l1 * v1 + l2 * v2 + l3 * v3)
    w = 1 + l1 * l1 + l2 * l2 + l3 * l3
    return math.sqrt(e0 * e0 + e1 * e1) / math.sqrt(w)


@kernel(inline=True)
def _row_residual(time_ns, uv, limits, c, r, r1, r2, r3, gap, ns):
    """:func:`_residual_norm` of row ``r`` (camera ``c``) and its camera's three previous
    rows ``r1, r2, r3`` (``r3 < 0``: fewer, NaN), read from the arrays in one straight block
    (no branch: numba then drops the references it takes; a missing row reads row -1, not
    used)."""
    value = _residual_norm(time_ns[r], time_ns[r1], time_ns[r2], time_ns[r3], uv[r, 0],
                           uv[r, 1], uv[r1, 0], uv[r1, 1], uv[r2, 0], uv[r2, 1], uv[r3, 0],
                           uv[r3, 1], limits[c], gap, ns)
    return value if r3 >= 0 else np.nan


@kernel
def residual_norms_kernel(time_ns, camera, uv, limits, m, max_gap_ns, ns, t_out, v_out):
    """The finite residuals of the rows, in row order: each row's residual from the
    quadratic through its camera's three previous rows (each within ``max_gap_ns`` of the
    next), per axis's σ, ``‖u - Σ l_j u_j‖ / √(1 + Σ l_j²)`` with the Lagrange weights ``l``
    (:func:`pslog.fusion.stereo.quadratic_residuals`' arithmetic, row by row), its time
    into ``t_out`` and its value into ``v_out`` (n,) each; returns how many. ``time_ns``
    (n,) int64 sorted, ``camera`` (n,) of ``m`` cameras, ``uv`` (n, 2) recorded pixels,
    ``limits`` (m,) each camera's "no detection" bound (|u| or |v| beyond it), ``ns``
    nanoseconds per second. What :func:`pslog.fusion.pseudo.measured_noise` takes (type A's
    covariance)."""
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
            j += 1
    return j


@kernel(inline=True)
def _select(values, count, k):
    """The ``k``-th smallest of ``values[:count]`` (finite), reordering them in place: the
    element ``np.sort(values[:count])[k]``. Quickselect with Lomuto's partition written
    without a branch on the comparison (each element swapped with the boundary's, which
    moves by ``t < pivot``: in ``[store, j)`` are only elements not below the pivot, so the
    swap of two of them changes nothing): 1.2 µs for 270 random values instead of Hoare's
    3.5 µs, whose inner loops' exits the branch predictor misses at random data. A selection,
    no arithmetic: the same element whichever algorithm finds it."""
    lo = 0
    hi = count - 1
    while lo < hi:
        mid = (lo + hi) // 2
        pivot = values[mid]
        values[mid] = values[hi]
        values[hi] = pivot
        store = lo
        for j in range(lo, hi):
            t = values[j]
            values[j] = values[store]
            values[store] = t
            store += t < pivot
        values[hi] = values[store]
        values[store] = pivot
        if k == store:
            return pivot
        if store == lo and k > lo:
            # nothing below the pivot: its equals gathered after it (a window of equal
            # values, a ball at rest at integer pixels, would otherwise lose one element a
            # pass: quadratic, 29 µs instead of 0.6 for 270 equal values)
            e = lo + 1
            for j in range(lo + 1, hi + 1):
                t = values[j]
                if t == pivot:
                    values[j] = values[e]
                    values[e] = t
                    e += 1
            if k < e:
                return pivot
            lo = e
            continue
        if k < store:
            hi = store - 1
        else:
            lo = store + 1
    return values[k]


@kernel(inline=True)
def _select_near(values, count, k, hint, width, scratch):
    """:func:`_select`'s element (``np.sort(values[:count])[k]``), looked for first among the
    values within ``[hint - width, hint + width]``: one pass counts the values below that
    band and copies those in it into ``scratch`` (at least ``count`` places; without a
    branch on the comparisons); if the k-th lies in the band, it is the band's
    ``(k - below)``-th (every value below the band is smaller than every value in it, every
    value above larger), selected among a few; else :func:`_select` of all the values.
    The same element whatever the hint (NaN: no band, all the values): a sliding window's
    upper median moves little from one window to the next, so the previous one with a tenth
    of it either side holds the new one in ~15 % of the values (fewer to select among
    than the whole window). ``values`` is reordered only where the band does not hold the
    element."""
    low = hint - width
    high = hint + width
    below = 0
    m = 0
    for j in range(count):
        v = values[j]
        below += v < low
        scratch[m] = v
        m += (v >= low) & (v <= high)
    if below <= k and k < below + m:
        return _select(scratch, m, k - below)
    return _select(values, count, k)


@kernel(inline=True)
def _window_rows(time_ns, n, lo, hi, end, window_ns):
    """The rows ``[lo, hi)`` of the first ``n`` of ``time_ns`` (sorted) in ``[end -
    window_ns, end)``, from the previous window's ``lo, hi`` (the ends come in order: each
    bound only moves forward)."""
    while lo < n and time_ns[lo] < end - window_ns:
        lo += 1
    while hi < n and time_ns[hi] < end:
        hi += 1
    return lo, hi


@kernel
def checkpoint_noise_kernel(time_ns, camera, uv, limits, m, max_gap_ns, ns, every_ns,
                            window_ns, min_count, rayleigh, at_ns, out):
    """A session's checkpoint noise at each of the sorted ``at_ns`` (k,) (rows' times), in
    two passes over the rows: the residuals (:func:`residual_norms_kernel`), then each
    checkpoint of the rows' times (a multiple of ``every_ns``) in order, its window's upper
    median (``[T - window_ns, T)``, at least ``min_count`` residuals) over ``rayleigh``, or
    the latest earlier checkpoint's; into ``out`` (k,), NaN before any checkpoint has one.
    The arithmetic of :func:`pslog.fusion.pseudo.window_noise` (the same element divided by
    ``rayleigh``), which :class:`~pslog.fusion.pseudo.MeasuredNoiseStream` makes one
    checkpoint at a time."""
    n = time_ns.shape[0]
    t_fin = np.empty(n, dtype=np.int64)
    v_fin = np.empty(n)
    j = residual_norms_kernel(time_ns, camera, uv, limits, m, max_gap_ns, ns, t_fin, v_fin)
    scratch = np.empty(j)
    band = np.empty(j)
    lo = 0
    hi = 0
    p = 0
    k = at_ns.shape[0]
    latest = np.nan
    median = np.nan  # (the previous checkpoint's: the next one's hint)
    previous = np.iinfo(np.int64).min
    for r in range(n):
        mark = time_ns[r] // every_ns * every_ns
        if mark == previous:
            continue
        previous = mark
        lo, hi = _window_rows(t_fin, j, lo, hi, mark, window_ns)
        count = hi - lo
        if count >= min_count:
            for i in range(count):
                scratch[i] = v_fin[lo + i]
            median = _select_near(scratch, count, count // 2, median, 0.1 * median, band)
            latest = median / rayleigh
        while p < k and at_ns[p] // every_ns * every_ns <= mark:
            out[p] = latest
            p += 1
    while p < k:  # (no row at a point's time: not a caller's case)
        out[p] = np.nan
        p += 1


@kernel
def window_medians_kernel(time_ns, values, marks, window_ns, min_count, out):
    """For each of the sorted ``marks`` (k,) int64, the upper median (the middle element,
    sorted) of the ``values`` (n,) whose ``time_ns`` (n,) sorted lie in ``[mark -
    window_ns, mark)``, into ``out`` (k,); NaN where fewer than ``min_count`` are there.
    ``values`` finite. A selection, not arithmetic: the same element whichever rows around
    the window are given (a stream's history or the session)."""
    n = time_ns.shape[0]
    lo = 0
    hi = 0
    for j in range(marks.shape[0]):
        lo, hi = _window_rows(time_ns, n, lo, hi, marks[j], window_ns)
        count = hi - lo
        if count < min_count:
            out[j] = np.nan
            continue
        out[j] = np.sort(values[lo:hi])[count // 2]


@kernel
def window_mean_squares_kernel(time_ns, values, ends, window_ns, min_count, out):
    """For each of the sorted ``ends`` (k,) int64, the mean of the squares of the ``values``
    (n,) whose ``time_ns`` (n,) sorted lie in ``[end - window_ns, end)``, halved (a 2-D
    residual's norm over σ per axis: the unbiased estimate of σ²), summed in time order,
    into ``out`` (k,); NaN where fewer than ``min_count`` are there."""
    n = time_ns.shape[0]
    lo = 0
    hi = 0
    for j in range(ends.shape[0]):
        lo, hi = _window_rows(time_ns, n, lo, hi, ends[j], window_ns)
        count = hi - lo
        if count < min_count:
            out[j] = np.nan
            continue
        total = 0.0
        for i in range(lo, hi):
            total += values[i] * values[i]
        out[j] = total / (2 * count)


@kernel
def _fresh(r, time_ns, own_before, max_gap_ns):
    """Row ``r`` is its camera's first after a spell of more than ``max_gap_ns`` without a
    row (or its first at all): ``own_before`` (n,) each row's previous row of its camera."""
    own = own_before[r]
    return own < 0 or time_ns[r] - time_ns[own] > max_gap_ns


@kernel
def long_gap_kernel(time_ns, camera, m, previous, own_before, t_points, cam_points,
                    max_gap_ns, long_ns, fresh_rows, row, gap, long):
    """:func:`pslog.fusion.confirm.confirm_batch`'s first pass, point by point: each point's
    row (its time's first row, ``np.searchsorted(time_ns, t, "left")``, then up to ``m`` rows
    on until its camera's) into ``row`` (k,), the time since the previous instant (``gap``
    (k,) ns, -1: none; ``previous`` (n,): the last row of each row's previous instant,
    -1 none, :func:`~pslog.fusion.pseudo._all_brackets`), and whether it waits for
    confirmation (``long`` (k,)): that gap, or the previous instant's own, above
    ``long_ns``, or the previous instant's row of another camera while the point's camera
    has no row within ``max_gap_ns`` before it (``own_before`` (n,): each row's previous row
    of its camera, -1 none), or (``fresh_rows``, :data:`pslog.fusion.confirm.FRESH_ROWS`)
    the previous instant's row or its own previous instant's row is its camera's first
    after more than ``max_gap_ns`` without one (:func:`_fresh`: a re-acquisition). The numpy
    form's comparisons, without its (n,) and (k,) temporaries: the same rows and
    decisions."""
    n = time_ns.shape[0]
    lo = 0
    for i in range(t_points.shape[0]):
        t = t_points[i]
        # the first row at or after t: on from the previous point's (a Track's times are
        # sorted: one pass over the rows), by bisection after a point out of order
        if i > 0 and t < t_points[i - 1]:
            lo = 0
            hi = n
            while lo < hi:
                mid = (lo + hi) // 2
                if time_ns[mid] < t:
                    lo = mid + 1
                else:
                    hi = mid
        while lo < n and time_ns[lo] < t:
            lo += 1
        e = lo
        for _ in range(m):
            if e < n and camera[e] != cam_points[i]:
                e += 1
            else:
                break
        if e >= n:
            raise ValueError("a point's detection is not among the observations")
        row[i] = e
        p = previous[e]
        g = time_ns[e] - time_ns[p] if p >= 0 else np.int64(-1)
        gap[i] = g
        unbracketed = False
        gap_before = np.int64(-1)
        fresh = False
        if p >= 0:
            own = own_before[e]
            unbracketed = (camera[p] != camera[e]) and (
                own < 0 or time_ns[p] - time_ns[max(own, 0)] > max_gap_ns)
            pp = previous[p]
            gap_before = time_ns[p] - time_ns[pp] if pp >= 0 else np.int64(-1)
            # the two previous instants' rows (eq. (2)'s past points): either one its
            # camera's first row after a spell of max_gap_ns without one (a re-acquisition,
            # the gate's choice with no track of its own camera behind it)
            if fresh_rows:
                fresh = _fresh(p, time_ns, own_before, max_gap_ns) or (
                    pp >= 0 and _fresh(pp, time_ns, own_before, max_gap_ns))
        long[i] = (g > long_ns) or unbracketed or (gap_before > long_ns) or fresh


@kernel
def model_rescale_kernel(cov, sigma, cov_px, gravity, across, per_px2, points, camera,
                         centers, gate, out):
    """Type A's covariance at the measured noise with eq. (2)'s model term, point by point
    (:func:`pslog.fusion.pseudo.with_measured_noise`'s arithmetic, which
    ``MeasuredNoiseStream`` repeats on one point's floats, operation for operation):
    ``cov`` (6, k) the kernel's xx, yy, zz, xy, xz, yz made at ``cov_px``, ``sigma`` (k,)
    the points' noise, ``gravity``, ``across``, ``per_px2`` (k,) the kernel's model columns,
    ``points`` (k, 3), ``camera`` (k,), ``centers`` (m, 3), ``gate`` the innovation's χ²
    gate; into ``out`` (7, k): std_m, then the six columns."""
    for i in range(sigma.shape[0]):
        sg = sigma[i]
        f = sg / cov_px
        f = f * f
        noise = (sg * sg) * per_px2[i]
        c = camera[i]
        d0 = points[i, 0] - centers[c, 0]
        d1 = points[i, 1] - centers[c, 1]
        d2 = points[i, 2] - centers[c, 2]
        v = gravity[i] + (0.5 * (across[i] - 2.0 * noise) if across[i] > gate * noise else 0.0)
        w = v / (d0 * d0 + d1 * d1 + d2 * d2)
        xx = cov[0, i] * f + w * (d0 * d0)
        yy = cov[1, i] * f + w * (d1 * d1)
        zz = cov[2, i] * f + w * (d2 * d2)
        out[1, i] = xx
        out[2, i] = yy
        out[3, i] = zz
        out[4, i] = cov[3, i] * f + w * (d0 * d1)
        out[5, i] = cov[4, i] * f + w * (d0 * d2)
        out[6, i] = cov[5, i] * f + w * (d1 * d2)
        out[0, i] = math.sqrt(xx + yy + zz)


# -- a stream's one new point (pslog.fusion.pseudo.TypeAStream._push_one), in one call ---

@kernel
def one_point_kernel(depth, max_extrapolation, max_gap_ns, time_ns, camera, uv,
                     observed_rays, centers, ki, rr, f9, cam, span_tie_ns, min_angle_deg,
                     ray_dir, obs_jac, jac4, lens, rtki, ns, noise_px, with_cov, ff, fi,
                     refused, has, predicted, points, flags, innovation, factor, model,
                     quality, past_rows, past_points, camera64, lens_table, sigma,
                     innovation_sigmas, no_rows, kinked, decided):
    """The point of a window's newest row (its last) and the tests that decide it, as
    :class:`~pslog.fusion.pseudo.TypeAStream` makes them one row at a time: the brackets
    (:func:`brackets_kernel`), :func:`type_a_kernel` with that one target, and when its
    point is made, finite and valid and passes the prediction test (the innovation within
    ``innovation_sigmas σ factor + model``, ``σ`` = ``sigma[0]``, the noise estimate's for
    the next point), the kink test (:func:`kink_kernel`, each row's previous and next row of
    its camera from :func:`~pslog.fusion._prepare_kernel.previous_next`): the same calls on
    the same arrays as one after another (the same bits), without a call from Python for
    each, nor the arrays between them made in Python.

    The arguments are :func:`type_a_kernel`'s (without ``targets``, ``previous_instant``,
    ``prev_b``, ``next_b``: made here) and: ``camera64`` (n,) int64 the window's cameras;
    ``lens_table`` (m, 8) the cameras' lens rows (:func:`kink_kernel`'s ``lens``);
    ``sigma`` (1,) px; ``no_rows`` (0,) float64 (no bend tables); ``kinked`` (1,) bool,
    written (False unless tested); ``decided`` (4,) bool, written: the point made is
    finite, it is good (finite, no invalid flag), it failed the prediction test, it is
    kinked. Returns the number of points made (0 or 1).
    """
    n = time_ns.shape[0]
    m = centers.shape[0]
    prev_b = np.empty((m, n), dtype=np.int64)
    next_b = np.empty((m, n), dtype=np.int64)
    previous_instant = np.empty(n, dtype=np.int64)
    brackets_kernel(time_ns, camera, prev_b, next_b, previous_instant)
    target = np.empty(1, dtype=np.int64)
    target[0] = n - 1
    no_ints = np.empty(0, dtype=np.int64)
    made = type_a_kernel(
        target, previous_instant, depth, max_extrapolation, max_gap_ns, time_ns, camera,
        prev_b, next_b, uv, observed_rays, centers, ki, rr, f9, cam, span_tie_ns,
        min_angle_deg, ray_dir, obs_jac, jac4, lens, rtki, ns, noise_px, with_cov, ff, fi,
        refused, has, predicted, points, flags, innovation, factor, model, quality,
        past_rows, past_points, has.shape[0] < 0, 0.0, no_rows, np.int64(0), lens_table,
        no_ints, no_ints, no_rows, no_rows, np.zeros(0, dtype=np.bool_),
        np.empty(1, dtype=np.int64), np.zeros(8, dtype=np.int64), sigma)
    # (decide: False from a comparison, not a literal, whose type would be a second
    # signature of type_a_kernel; the decisions below, on the one point)
    kinked[0] = False
    decided[0] = decided[1] = decided[2] = decided[3] = False
    if made:
        finite = (math.isfinite(points[0, 0]) and math.isfinite(points[0, 1])
                  and math.isfinite(points[0, 2]))
        good = finite and flags[0] == 0
        failed = good and innovation[0] > innovation_sigmas * (sigma[0] * factor[0]) + model[0]
        if good and not failed:
            before = np.empty(n, dtype=np.int64)
            after = np.empty(n, dtype=np.int64)
            previous_next(camera64, m, before, after)
            kink_kernel(target, past_rows[0, :, 0], past_rows[0, :, 1], past_rows[0, :, 2],
                        past_points[0], past_rows[1, :, 0], past_rows[1, :, 1],
                        past_rows[1, :, 2], past_points[1], predicted, sigma, before, after,
                        time_ns, uv, camera64, lens_table, max_gap_ns, ns, kinked, no_rows,
                        no_rows)
        decided[0], decided[1], decided[2], decided[3] = finite, good, failed, kinked[0]
    return made


def _preload() -> None:
    """Type A's batch kernels loaded from numba's cache (or compiled) now, in the
    signatures ``pslog fuse``'s type A calls them with (the observations' columns
    read-only; C-contiguous arrays of its own; Python ints, floats and bools): called by
    :func:`pslog._jit.preload` on its thread while ``pslog fuse`` reads its session and
    gates it, so that type A's first calls do not pay the nine loads (~35 CPU ms, more
    wall where the compiler lock makes a load wait) on its way (session 44). Nothing
    runs: ``compile`` of a signature only loads it (tests/test_kernel_signatures.py: a
    type A fuse afterwards adds no signature)."""
    from numba import types

    f8, i8, b1 = types.float64, types.int64, types.boolean

    def a(dtype, ndim: int, readonly: bool = False):
        return types.Array(dtype, ndim, "C", readonly=readonly)

    iv, v, m, m3 = a(i8, 1), a(f8, 1), a(f8, 2), a(f8, 3)
    ro_t, ro_c, ro_uv = a(i8, 1, True), a(types.int32, 1, True), a(f8, 2, True)
    type_a_kernel.compile((
        iv, iv, i8, f8, i8, ro_t, ro_c, a(i8, 2), a(i8, 2), m, m, m, m, m, m, m, i8, f8, m,
        m3, m, b1, m, i8, f8, b1, m3, a(i8, 3), iv, a(b1, 1), m, m, iv, v, v, v, m,
        a(i8, 3), m3, b1, f8, v, i8, m, iv, iv, v, v, a(b1, 1), iv, iv, v))
    brackets_kernel.compile((ro_t, ro_c, a(i8, 2), a(i8, 2), iv))
    bend_rows.compile((ro_t, m, iv, iv, i8, v, v))
    previous_next.compile((iv, i8, iv, iv))
    long_gap_kernel.compile((ro_t, ro_c, i8, iv, iv, ro_t, ro_c, i8, f8, b1, iv, iv,
                             a(b1, 1)))
    checkpoint_noise_kernel.compile((ro_t, ro_c, ro_uv, v, i8, i8, i8, i8, i8, i8, f8, ro_t,
                                     v))
    residual_norms_kernel.compile((ro_t, iv, ro_uv, v, i8, i8, i8, iv, v))
    window_mean_squares_kernel.compile((iv, v, iv, i8, i8, v))
    model_rescale_kernel.compile((m, v, f8, a(f8, 1, True), a(f8, 1, True), a(f8, 1, True),
                                  a(f8, 2, True), iv, m, f8, m))
