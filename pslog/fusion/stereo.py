"""Ordinary stereo: the paper's "synchronized" and "unsynchronized" rows of Table 1."""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from typing import NamedTuple, cast

import numpy as np

from ..errors import FusionError
from ..geometry import _FEW, _solve_rays, ray_angles, ray_depths, triangulate_rays
from ..records import NS, Observations, Track
from . import _prepare
from ._prepare import (
    BEHIND,
    MIN_RAY_ANGLE_DEG,
    OUTSIDE_VIEW,
    PARALLEL,
    Prepared,
    camera_mask,
    covariance,
    covariance_columns,
    default_max_gap_s,
    direction_jacobian,
    finite_difference_jacobians,
    finite_rows,
    invalid_points,
    latest_row_at_or_before,
    least_squares_pixel_jacobians,
    rays_only,
    reprojection_one,
)


def sync_groups(obs: Observations, n_cams: int, tolerance_s: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Group observations captured within ``tolerance_s`` of each other.

    A group starts at the earliest observation not yet grouped and takes every later one up
    to ``tolerance_s`` after it, so no group spans more than the tolerance. (Chaining
    neighbours within the tolerance instead would let evenly spaced shutters a little closer
    than the tolerance join one by one into a single "simultaneous" group of the whole
    session.)

    Returns
    -------
    group : (n,) int64, group id of each observation (groups in time order)
    n_cameras : (n_groups,) int64, distinct cameras in each group
    """
    time_ns = obs.time_ns
    tol_ns = round(tolerance_s * NS)
    n = len(time_ns)
    starts = np.zeros(n, dtype=bool)
    if n:
        # runs separated by more than the tolerance are groups unless they span more than
        # it (vectorized, the usual case); only those longer runs are split one by one
        starts[0] = True
        starts[1:] = np.diff(time_ns) > tol_ns
        run_start = np.flatnonzero(starts)
        run_end = np.r_[run_start[1:], n]  # exclusive
        long = time_ns[run_end - 1] - time_ns[run_start] > tol_ns
        for a, b in zip(run_start[long].tolist(), run_end[long].tolist(), strict=True):
            times = time_ns[a:b]
            i = 0
            while i < b - a:
                starts[a + i] = True
                i = int(np.searchsorted(times, times[i] + tol_ns, side="right"))
    group = np.cumsum(starts) - 1
    n_groups = int(group[-1]) + 1 if len(group) else 0
    seen = np.zeros((n_groups, n_cams), dtype=bool)
    seen[group, obs.camera] = True
    return group, seen.sum(axis=1)


def doubt_covariance(prep: Prepared, slot_rows: np.ndarray, jacobians: list[np.ndarray],
                     cov: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``cov`` (quality columns ``std_m``, ``cov_*_m2`` of k points) with the doubt of the
    gate's choices (:attr:`Prepared.doubt_px2`, ``d`` pixels² per axis of each detection,
    :func:`pslog.fusion.gating.choice_doubt`): a point made from detections in doubt gains

        Σ_s d_s (J_s L_s)(J_s L_s)ᵀ

    over its slots ``s`` (``J_s`` (3, 2) d(point)/d(undistorted pixel), ``L_s`` the recorded-
    to-undistorted pixel Jacobian): the first-order covariance of a pixel offset of
    variance ``d_s`` per axis (docs/methods.md, "A choice in doubt"). Points without a
    detection in doubt keep their columns (the same arrays' values). ``slot_rows`` (k, m)
    the detection of each slot (-1: unused), each slot a different detection."""
    doubt = cast(np.ndarray, prep.doubt_px2)
    per_slot = np.where(slot_rows >= 0, doubt[np.maximum(slot_rows, 0)], 0.0)
    hit = np.flatnonzero(np.any(per_slot > 0, axis=1))
    if not len(hit):
        return cov
    names = ("cov_xx_m2", "cov_yy_m2", "cov_zz_m2", "cov_xy_m2", "cov_xz_m2", "cov_yz_m2")
    six = np.stack([cov[name][hit] for name in names])
    first = np.array([0, 1, 2, 0, 0, 1])
    second = np.array([0, 1, 2, 1, 2, 2])
    for s in range(slot_rows.shape[1]):
        d = per_slot[hit, s]
        if not np.any(d > 0):
            continue
        L = prep.pixel_jacobians_t(np.maximum(slot_rows[hit, s], 0))
        JL = _prepare.times_pixel_jacobian(jacobians[s][:, :, hit], L)
        six += (JL[first, 0] * JL[second, 0] + JL[first, 1] * JL[second, 1]) * d
    out = {name: column.copy() for name, column in cov.items()}
    for name, column in _prepare.covariance_columns(six).items():
        out[name][hit] = column
    return out


def nview_points(prep: Prepared, rows: np.ndarray, noise_px: float | np.ndarray | None,
                 motion: list[SlotMotion] | None = None, compiled: bool = True,
                 breaks: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                 residuals_out: list[np.ndarray] | None = None,
                 excess: tuple[np.ndarray, float] | None = None):
    """N-view least-squares point of each row of detections, with its quality and validity.

    Parameters
    ----------
    rows : (k, m) int64, the detection of camera c for point i at ``rows[i, c]`` (-1: none)
    noise_px : float, (k,) float or None, standard deviation of the detections' pixel noise,
        pixels per axis (an array: each point's; None: no covariance columns)
    motion : list of :class:`SlotMotion` per camera slot, or None: how each slot's detection
        moved in its image between its shutter and the point's time (the shutters taken as
        simultaneous are not; :func:`slot_motion`): the covariance is then
        :func:`motion_covariance`'s (docs/methods.md, "nearest's uncertainty")
    compiled : the per-point arithmetic in :mod:`._stereo_kernel`'s compiled passes (from
        ``_FEW`` points and below 8 cameras, where the numpy forms are columns; the same
        bits), else with numpy
    breaks : with ``motion``, every detection's :func:`innovations` ``(ν², ν_r², c)``: the
        covariance then also holds the breaks of the image motion they show (a bounce, a
        kick; :func:`motion_covariance`)
    residuals_out : a list, or None: given, each camera's reprojection residuals (k,) of
        the points are appended to it (recorded pixels, :func:`reprojection_one`'s; NaN
        where the ray is not used or the point is behind the camera)
    excess : with ``motion`` and ``noise_px``, each point's time (k,) and ``max_gap_s``, or
        None: the detection noise's part of the covariance of the points whose own
        detections disagree beyond the noise and the slots' motion is multiplied by
        :func:`excess_factor` (``nearest``; docs/methods.md, "nearest's covariance where its
        detections disagree"; :func:`excess_noise`), the motion's, the breaks' and the
        doubt's terms as they are

    Returns
    -------
    points : (k, 3) metres (NaN where fewer than two usable rays)
    quality : dict of (k,) columns (see :data:`pslog.records.QUALITY_FIELDS`): ``ray_miss_m``,
        ``ray_angle_deg``, ``residual_max_px``, ``residual_mean_px``, ``camera_mask``,
        ``n_detections``, ``gap_s`` (spread of the capture times taken as simultaneous; also
        ``span_s``, the point being at the latest),
        ``std_m`` and the covariance ``cov_*_m2``
    flags : (k,) int64, why a point is invalid (:func:`invalid_points` bits, ``PARALLEL``
        below :data:`MIN_RAY_ANGLE_DEG`; 0: valid)
    used : (k, m) bool, the rays used
    """
    k, m = rows.shape
    r = np.maximum(rows, 0)
    # compiled (the column forms of triangulate_rays and ray_angles, which they take from
    # _FEW points and below 8 rays: the same bits), unless the finite differences are asked
    compiled = compiled and k >= _FEW and m < 8 and not _prepare.FINITE_DIFFERENCES
    uv = [] if compiled else [prep.uv_undistorted[r[:, c]] for c in range(m)]
    origins = np.broadcast_to(prep.centers, (k, m, 3))

    def directions(uvs):
        return np.stack([prep.rays_from_undistorted(c, uvs[c]) for c in range(m)], axis=1)

    turns = None
    if compiled:
        dirs, points, rms_miss, used, smallest_cos, residual, turns = _nview_compiled(
            prep, rows)
        with np.errstate(invalid="ignore"):
            angle = np.degrees(np.where(np.isfinite(smallest_cos),
                                        np.arccos(np.clip(smallest_cos, 0.0, 1.0)), np.nan))
    else:
        with np.errstate(invalid="ignore"):
            dirs = directions(uv)
        points, rms_miss, _ = triangulate_rays(origins, dirs, rows >= 0)
        used = (rows >= 0) & np.isfinite(dirs[..., 0]) & np.isfinite(dirs[..., 1]) \
            & np.isfinite(dirs[..., 2])
        angle = np.degrees(ray_angles(dirs, used))
    finite = finite_rows(points)
    flags = invalid_points(prep, points, used, finite)
    with np.errstate(invalid="ignore"):
        if compiled and dirs.flags.c_contiguous and _prepare.ray_depths_compiled():
            # (the same bits, one pass: einsum sums C-contiguous rays in the order the
            # kernel repeats; other strides in another)
            from . import _prepare_kernel

            depth = np.empty((k, m))
            _prepare_kernel.ray_depths_rows(points, _c(prep.centers, dtype=np.float64),
                                            dirs, depth)
        else:
            depth = ray_depths(points, origins, dirs)  # the ray parameters: > 0 in front
        behind = used[:, 0] & ~(depth[:, 0] > 0)
        for c in range(1, m):
            behind |= used[:, c] & ~(depth[:, c] > 0)
        flags[behind & finite] |= BEHIND
        flags[angle < MIN_RAY_ANGLE_DEG] |= PARALLEL  # (NaN: fewer than two rays)
    if not compiled:
        residual = [np.where(used[:, c], reprojection_one(prep, c, points, uv[c]), np.nan)
                    for c in range(m)]
    if residuals_out is not None:
        residuals_out.extend(residual)

    slot_rows = np.where(used, rows, -1)
    if noise_px is None:
        cov = None
    elif _prepare.FINITE_DIFFERENCES:
        def evaluate(uvs):
            with np.errstate(invalid="ignore"):
                return triangulate_rays(origins, directions(uvs), used)[0]

        jacobians = finite_difference_jacobians(evaluate, uv, slot_rows)
    else:
        with np.errstate(invalid="ignore"):
            jacobians = least_squares_pixel_jacobians(
                points, origins, dirs, used,
                [direction_jacobian(prep, c, uv[c]) for c in range(m)]
                if turns is None else list(turns))
    if noise_px is not None:
        if motion is None:
            cov = covariance(slot_rows, jacobians,
                             [prep.pixel_jacobians_t(r[:, c]) for c in range(m)], noise_px)
        else:
            cov = motion_covariance(prep, slot_rows, jacobians, motion, used, noise_px,
                                    compiled, breaks, None if breaks is None
                                    else pixels_per_metre_sq(prep, points))
        if prep.doubt_px2 is not None:
            cov = doubt_covariance(prep, slot_rows, jacobians, cov)
        if excess is not None and motion is not None:
            noise = np.broadcast_to(np.asarray(noise_px, dtype=np.float64), (k,))
            cov = excess_noise(prep, slot_rows, jacobians, motion, used, noise, excess_factor(
                prep, rows, used, points, excess[0], noise, excess[1], list(residual),
                compiled), cov)
    # (k,) columns, each reduction over the m cameras in numpy's order (the same bits)
    times = [prep.obs.time_ns[r[:, c]] for c in range(m)]
    t_max = np.maximum.reduce([np.where(used[:, c], times[c], np.iinfo(np.int64).min)
                               for c in range(m)])
    t_min = np.minimum.reduce([np.where(used[:, c], times[c], np.iinfo(np.int64).max)
                               for c in range(m)])
    n_used = used.sum(axis=1)
    if m < 8:  # numpy sums fewer than 8 terms in order
        residual_sum = np.where(used[:, 0] & ~np.isnan(residual[0]), residual[0], 0.0)
        for c in range(1, m):
            residual_sum += np.where(used[:, c] & ~np.isnan(residual[c]), residual[c], 0.0)
    else:
        residual_sum = np.nansum(np.where(used, np.stack(residual, 1), 0.0), axis=1)
    with np.errstate(invalid="ignore", all="ignore"):
        quality = {
            "ray_miss_m": rms_miss, "ray_angle_deg": angle,
            "residual_max_px": np.fmax.reduce(residual),
            "residual_mean_px": residual_sum / n_used,
            "camera_mask": camera_mask(used), "n_detections": n_used.astype(np.float64),
            "gap_s": np.where(n_used > 0, (t_max - t_min) / NS, np.nan),
            "span_s": np.where(n_used > 0, (t_max - t_min) / NS, np.nan),
            **(cov if cov is not None else {}),
        }
    return points, quality, flags, used


def _nview_compiled(prep: Prepared, rows: np.ndarray):
    """:func:`nview_points`' rays, points, ``rms_miss``, rays used, smallest |cosine|
    between two used rays, residuals (m, k) and direction Jacobians (m, 3, 2, k) by
    :mod:`._stereo_kernel`'s passes, numpy solving the normal equations between them."""
    from . import _stereo_kernel

    k, m = rows.shape
    rows = _c(rows, dtype=np.int64)
    uv = _c(prep.uv_undistorted, dtype=np.float64)
    centers = _c(prep.centers, dtype=np.float64)
    dirs, A, rhs = np.empty((k, m, 3)), np.empty((k, 3, 3)), np.empty((k, 3))
    n_rays = np.empty(k, dtype=np.int64)
    _stereo_kernel.nview_normal(rows, uv, _c(prep._cols("K_inv").T),
                                _c(prep._cols("R").T), centers, dirs, A,
                                rhs, n_rays)
    points = _solve_rays(A, rhs, n_rays, overwrite=True)
    del A, rhs
    cam = np.array([np.concatenate([np.ravel(c.K), np.ravel(c.R), np.ravel(c.t),
                                    np.ravel(c.dist)]) for c in prep.cameras],
                   dtype=np.float64).reshape(-1, 26)
    lens = np.array([bool(np.any(c.dist)) for c in prep.cameras], dtype=bool)
    rms_miss, smallest_cos = np.empty(k), np.empty(k)
    used = np.empty((k, m), dtype=bool)
    residual, turns = np.empty((m, k)), np.empty((m, 3, 2, k))
    _stereo_kernel.nview_after(rows, uv, points, dirs, centers, n_rays, cam, lens,
                               _c(prep._rt_k_inv_cols.T), rms_miss, used,
                               smallest_cos, residual, turns)
    return dirs, points, rms_miss, used, smallest_cos, list(residual), turns


def _with_motion(cov: dict[str, np.ndarray], jacobians: list[np.ndarray],
                 shift_px: list[np.ndarray], used: np.ndarray) -> dict[str, np.ndarray]:
    """``cov`` (quality columns) plus ``m mᵀ``, ``m = Σ_s J_s δ_s`` (3, k): the point's move
    when each slot's pixel is shifted by ``δ_s`` (``J_s`` component-major (3, 2, k))."""
    move = np.zeros((3, used.shape[0]))
    for s, (J, d) in enumerate(zip(jacobians, shift_px, strict=True)):
        ok = used[:, s] & np.all(np.isfinite(d), axis=1)
        move += np.where(ok, J[:, 0] * d[:, 0] + J[:, 1] * d[:, 1], 0.0)
    six = np.stack([cov[f"cov_{a}_m2"] for a in ("xx", "yy", "zz", "xy", "xz", "yz")])
    six = six + np.stack([move[0] * move[0], move[1] * move[1], move[2] * move[2],
                          move[0] * move[1], move[0] * move[2], move[1] * move[2]])
    return covariance_columns(six)


#: The image speed (pixels per second, per axis) taken as unknown for a slot whose camera has
#: no previous detection within ``max_gap_s`` (its first detection, or its first after a gap
#: or a blackout): its shift over the lag is a zero-mean guess of this size, not 0 (a ball at
#: 5 m/s seen from 3 m by a 600 px focal length: 1,000 px/s). See docs/methods.md,
#: "nearest's covariance at the true noise".
UNKNOWN_IMAGE_SPEED_PX_S = 1000.0


#: ``nearest``'s detection noise (:func:`detection_noise`): the residuals of the last
#: NOISE_WINDOW_S seconds before each checkpoint, checkpoints every NOISE_EVERY_S seconds
#: (of the session's clock), an estimate once NOISE_MIN_COUNT residuals are in its window,
#: and at least NOISE_FLOOR_PX (or the stated noise, if lower).
NOISE_WINDOW_S = 1.0
NOISE_EVERY_S = 0.25
NOISE_MIN_COUNT = 16
NOISE_FLOOR_PX = 0.1


def detection_noise(prep: Prepared, time_ns: np.ndarray, max_gap_s: float,
                    noise_px: float) -> np.ndarray:
    """The detection noise σ (pixels per axis, (k,)) of points at ``time_ns`` (k,), as the
    session's own detections show it, causally.

    Each detection with its camera's three previous ones (each within ``max_gap_s`` of the
    next) has a residual from the quadratic through those three, extrapolated to it with
    the Lagrange weights ``l`` (:func:`slot_motion`'s, ``L``, ``h``, ``g`` the intervals):
    ``r = ‖u - Σ l_j u_j‖ / √(1 + Σ l_j²)`` (recorded pixels: the noise is the detector's,
    in the image it saw; the lens is smooth over three frames), under the model the norm
    of a 2-D Gaussian of σ per axis (plus the ball's jerk, small between bounces), whose
    median is ``σ √(2 ln 2)`` (Rayleigh). A point at ``t`` takes the median of the residuals
    of the detections in ``[T - NOISE_WINDOW_S, T)`` (the upper median: the middle element),
    ``T`` the latest multiple of ``NOISE_EVERY_S`` at or before ``t`` (a selection over
    detections strictly before the point: causal; the stream keeps that history and so
    gives every point the batch's bits), divided by ``√(2 ln 2)``; ``noise_px`` while
    fewer than ``NOISE_MIN_COUNT`` residuals are in the window; never below
    ``min(noise_px, NOISE_FLOOR_PX)``. Robust: a bounce or kick spoils three or four
    residuals of a camera, a few percent of a window.

    Type A's estimator (:func:`pslog.fusion.pseudo.measured_noise`) is the same, with its
    own rules at a session's start and across pauses: both take the residuals and each
    window's median from the same compiled kernels (:func:`pslog.fusion.pseudo.
    residual_norms`, :func:`~pslog.fusion.pseudo.window_noise`; a detection the rig says is
    no detection — undistorted NaN — has no residual)."""
    from .pseudo import no_detection_limits, residual_norms, window_noise

    # recorded pixels: σ is the detector's noise where it acts, before the lens model
    # (the covariance maps it through L itself; undistorted residuals would carry L twice)
    obs = prep.obs
    t_fin, v_fin = residual_norms(obs.time_ns, obs.camera, obs.uv,
                                  no_detection_limits(prep.cameras), max_gap_s)
    every = int(NOISE_EVERY_S * NS)
    marks, inverse = np.unique(time_ns // every * every, return_inverse=True)
    est = window_noise(t_fin, v_fin, marks, NOISE_MIN_COUNT)
    sigma = np.where(np.isfinite(est), est, noise_px)[inverse]
    return np.maximum(sigma, min(noise_px, NOISE_FLOOR_PX))


#: :func:`refusal_noise` estimates σ from this quantile of the residual norms (the element
#: ``count // 4`` of a window, sorted), over Rayleigh's at it, ``√(-2 ln 0.75)``: the median's
#: breakdown (half the residuals) is not enough where a few false detections each spoil up to
#: four residuals of their camera (a session's first second with 5 of 21 detections false
#: made the median 127 px, and kept a 2.5 m sync point with a 120 px residual)
REFUSAL_NOISE_QUANTILE = 0.25
RAYLEIGH_QUARTILE = float(np.sqrt(-2.0 * np.log(1.0 - REFUSAL_NOISE_QUANTILE)))


def refusal_noise(prep: Prepared, time_ns: np.ndarray, max_gap_s: float,
                  noise_px: float | None, camera: np.ndarray | None = None,
                  compiled: bool = True) -> np.ndarray:
    """Each camera's detection noise σ_c (pixels per axis, (k, m); with ``camera`` (k,):
    (k,), each point's camera's) that ``sync``'s residual test and ``typeB`` / ``linear``'s
    prediction test assume at ``time_ns`` (k,): at least the least noise the tests state,
    ``floor = max(0.5 px, noise_px)`` (0.5 px when None), and the noise the camera's
    detections show, from the residuals type A's and ``nearest``'s estimators take (the
    detector's, in recorded pixels: each detection's residual from the quadratic through its
    camera's three previous ones, :func:`detection_noise`), each camera's own (one σ pooled
    over the cameras is the quiet cameras' where webcams mix: one camera 3 px noisier
    refused 41 % of the good sync points), and with their windows, robust to false
    detections for a test:

    - a checkpoint ``T`` (a multiple of ``NOISE_EVERY_S`` at or before the point) with
      ``NOISE_MIN_COUNT`` residuals in ``[T - NOISE_WINDOW_S, T)``: their lower quartile
      over Rayleigh's (:data:`REFUSAL_NOISE_QUANTILE`; the estimators of the covariances take
      the median);
    - else (a session's first second, or after a pause): the same quartile of the
      residuals in the ``NOISE_WINDOW_S`` before the point once ``NOISE_START_COUNT`` are
      there, at most ``NOISE_UNKNOWN_PX`` (2 px); before the camera has that many, the same
      over all cameras' residuals; before that (the first ~0.1 s, each camera's fourth
      detection making its first residual) the floor alone. Type A's
      covariance takes their sum of squares over 2n - 2, unbounded, and 2 px
      before any, where a larger σ is the safe side; for a test it is not: 5 false
      detections among a session's first 21 (30 % misses) spoiled 10 of its first 12
      residuals (a quartile of 87 px kept a 2.5 m sync point with a 120 px residual), and
      2 px at the first frame kept a 2.1 m point (a static object chosen there, 2.8 px
      from the ball's epipolar line). The cost: at 2 px of real noise against the stated
      0.5 px, 2 of 180 good sync points in the first 0.1 s refused.

    Causal, from the detections of the ``NOISE_EVERY_S + NOISE_WINDOW_S`` and three gaps
    before the point (type A's estimator reaches back across a pause to the latest
    checkpoint that had one; a window stream cannot). A stated noise below the detector's
    real one refused good points in numbers (docs/methods.md, "The N-view residual test");
    a larger one is never undercut.

    ``compiled``: the residuals of every camera in one compiled pass, made once per
    Prepared and ``max_gap_s`` (:func:`_refusal_residuals`), and each window's quartile by
    :func:`._stereo_kernel.window_quartiles`; else a pass per camera (and one over all) and
    a numpy partition per window (the reference: the same σ)."""
    from .innovation import DEFAULT_NOISE_PX
    from .pseudo import NOISE_START_COUNT, NOISE_UNKNOWN_PX, no_detection_limits, residual_norms

    floor = max(DEFAULT_NOISE_PX, 0.0 if noise_px is None else float(noise_px))
    time_ns = np.asarray(time_ns, dtype=np.int64)
    n_cams = len(prep.cameras)
    if not len(time_ns):
        return np.zeros(0) if camera is not None else np.zeros((0, n_cams))
    obs = prep.obs
    limits = no_detection_limits(prep.cameras)
    if compiled:
        t_all, v_all, c_all = _refusal_residuals(prep, max_gap_s)
    every = int(NOISE_EVERY_S * NS)
    marks, inverse = _unique_inverse(time_ns // every * every, compiled)
    ends, back = _unique_inverse(time_ns, compiled)
    # the start's pooled estimate (all cameras' residuals), for a camera with fewer than
    # NOISE_START_COUNT of its own in the window yet
    pooled: tuple[np.ndarray, np.ndarray] | None = None
    sigma = np.full((len(time_ns), n_cams), np.nan)
    for c in range(n_cams):
        if camera is not None and not np.any(camera == c):
            continue
        if compiled:  # (the rows of one pass over every camera's: the same residuals)
            mine = c_all == c
            t_fin, v_fin = t_all[mine], v_all[mine]
        else:
            own = np.flatnonzero(obs.camera == c)
            t_fin, v_fin = residual_norms(obs.time_ns[own], obs.camera[own], obs.uv[own],
                                          limits, max_gap_s)
        s = _window_quartiles(t_fin, v_fin, marks, NOISE_MIN_COUNT, compiled)[inverse]
        start = np.flatnonzero(np.isnan(s))
        if len(start):
            u, b = np.unique(back[start], return_inverse=True)
            s[start] = np.minimum(_window_quartiles(
                t_fin, v_fin, ends[u], NOISE_START_COUNT, compiled)[b], NOISE_UNKNOWN_PX)
            none = start[np.isnan(s[start])]
            if len(none):
                if pooled is None:
                    pooled = (t_all, v_all) if compiled else residual_norms(
                        obs.time_ns, obs.camera, obs.uv, limits, max_gap_s)
                u, b = np.unique(back[none], return_inverse=True)
                s[none] = np.minimum(_window_quartiles(  # (NaN: none yet: the floor)
                    *pooled, ends[u], NOISE_START_COUNT, compiled)[b], NOISE_UNKNOWN_PX)
        sigma[:, c] = s
    sigma = np.fmax(floor, sigma)
    if camera is None:
        return sigma
    return sigma[np.arange(len(time_ns)), np.asarray(camera, dtype=np.int64)]


def _unique_inverse(values: np.ndarray, fast: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(values, return_inverse=True)`` of (k,) int64 ``values``; with ``fast``,
    where they are sorted (the points' times: the usual case), from where they change
    instead of numpy's sort (the same arrays)."""
    if fast and len(values) and bool(np.all(values[1:] >= values[:-1])):
        change = np.empty(len(values), dtype=bool)
        change[0] = True
        np.not_equal(values[1:], values[:-1], out=change[1:])
        return values[change], np.cumsum(change) - 1
    return np.unique(values, return_inverse=True)


def _refusal_residuals(prep: Prepared, max_gap_s: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The times, norms and cameras (j,) of the finite residuals of every detection of
    ``prep`` (:func:`pslog.fusion.pseudo.residual_norms`' rows, with the camera of each:
    :func:`._stereo_kernel.residual_norms_cameras`), in row order; made once per Prepared
    and ``max_gap_s`` (``sync``'s residual test and ``typeB`` / ``linear``'s prediction
    test both take them; not to be written)."""
    from . import _stereo_kernel
    from .pseudo import no_detection_limits

    cache = prep.__dict__.setdefault("_refusal_residuals", {})
    if max_gap_s not in cache:
        obs = prep.obs
        limits = no_detection_limits(prep.cameras)
        n = len(obs)
        t_out, v_out, c_out = np.empty(n, np.int64), np.empty(n), np.empty(n, np.int64)
        j = _stereo_kernel.residual_norms_cameras(
            _c(obs.time_ns, dtype=np.int64), _c(obs.camera, dtype=np.int64),
            _c(obs.uv, dtype=np.float64), limits, len(limits), int(max_gap_s * NS), NS,
            t_out, v_out, c_out)
        cache[max_gap_s] = (t_out[:j], v_out[:j], c_out[:j])
    return cache[max_gap_s]


def _window_quartiles(t_fin: np.ndarray, v_fin: np.ndarray, ends_ns: np.ndarray,
                      min_count: int, compiled: bool = True) -> np.ndarray:
    """σ (k,) at each of the sorted, distinct ``ends_ns`` (k,): the element ``count // 4``
    of the residual norms ``v_fin`` at ``t_fin`` (sorted) in ``[end - NOISE_WINDOW_S, end)``,
    sorted, over :data:`RAYLEIGH_QUARTILE`; NaN where fewer than ``min_count`` (at least 1)
    are there (a selection: the same element whatever rows lie outside the window).
    ``compiled``: every window in one pass of :func:`._stereo_kernel.window_quartiles`
    (the same element), else a partition per window with numpy (the reference)."""
    if compiled:
        from . import _stereo_kernel

        out = np.empty(len(ends_ns))
        _stereo_kernel.window_quartiles(
            _c(t_fin, dtype=np.int64), _c(v_fin, dtype=np.float64),
            _c(ends_ns, dtype=np.int64), int(NOISE_WINDOW_S * NS), min_count,
            np.empty(len(t_fin)), out)
        return out / RAYLEIGH_QUARTILE
    lo = np.searchsorted(t_fin, ends_ns - int(NOISE_WINDOW_S * NS), side="left")
    hi = np.searchsorted(t_fin, ends_ns, side="left")
    out = np.full(len(ends_ns), np.nan)
    for j in np.flatnonzero(hi - lo >= min_count).tolist():
        window = v_fin[lo[j]:hi[j]]
        q = len(window) // 4
        out[j] = np.partition(window, q)[q]
    return out / RAYLEIGH_QUARTILE


def quadratic_residuals(prep: Prepared, uv: np.ndarray, max_gap_s: float,
                        compiled: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Each detection's residual from the quadratic through its camera's three previous
    detections (each within ``max_gap_s`` of the next), extrapolated to its time with the
    Lagrange weights ``l`` (:func:`slot_motion`'s, one step on): ``u - Σ l_j u_j`` (n, 2),
    in the pixels of ``uv`` (n, 2), and ``1 + Σ l_j²`` (n,), its variance over the
    detections' σ² per axis under the model; NaN where a detection has no three such
    previous ones. :func:`detection_noise` (recorded pixels) and :func:`innovations`
    (undistorted) take them. ``compiled``: each camera's in one pass
    (:func:`._stereo_kernel.quadratic_residuals_rows`, the same operations: the same bits),
    else with numpy columns (the reference)."""
    n = len(prep.obs)
    t_obs = prep.obs.time_ns
    out, weight = np.full((n, 2), np.nan), np.full(n, np.nan)
    if compiled:
        from . import _stereo_kernel

        t_c, uv_c = _time_ns_c(prep), _c(uv, dtype=np.float64)
        for rows in prep.per_camera:
            _stereo_kernel.quadratic_residuals_rows(_c(rows, dtype=np.int64), t_c, uv_c,
                                                    int(max_gap_s * NS) / NS, float(NS),
                                                    out, weight)
        return out, weight
    for rows in prep.per_camera:
        if len(rows) < 4:
            continue
        t = t_obs[rows]
        u = uv[rows]
        a, b, c = ((t[3:] - t[2:-1]) / NS, (t[2:-1] - t[1:-2]) / NS, (t[1:-2] - t[:-3]) / NS)
        gap = int(max_gap_s * NS) / NS  # (as slot_motion's)
        ok = (a > 0) & (b > 0) & (c > 0) & (a <= gap) & (b <= gap) & (c <= gap)
        with np.errstate(invalid="ignore", divide="ignore"):
            l1 = (a + b) * (a + b + c) / (b * (b + c))
            l2 = -a * (a + b + c) / (b * c)
            l3 = a * (a + b) / ((b + c) * c)
            res = u[3:] - (l1[:, None] * u[2:-1] + l2[:, None] * u[1:-2]
                           + l3[:, None] * u[:-3])
            w = 1 + l1**2 + l2**2 + l3**2
        out[rows[3:][ok]] = res[ok]
        weight[rows[3:][ok]] = w[ok]
    return out, weight


def recorded_residuals(prep: Prepared, max_gap_s: float, compiled: bool = True
                       ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`quadratic_residuals` in recorded pixels (a detection the rig says is no
    detection — undistorted NaN — has none)."""
    return quadratic_residuals(
        prep, np.where(np.isfinite(prep.uv_undistorted), prep.obs.uv, np.nan), max_gap_s,
        compiled)


#: ``nearest``'s test of a break in the image motion (a bounce, a kick): a detection's
#: residual from the quadratic through its camera's three previous ones
#: (:func:`innovations`) is a break where its squared length exceeds KINK_GATE times its
#: variance under the detections' noise (the χ² of 2 degrees of freedom at 99 %). See
#: docs/methods.md, "nearest at bounces and kicks".
KINK_GATE = 9.21
#: ... and the mean of ``e² / ν²`` over a break's time, ``e`` a partner's extrapolation
#: error, ``ν`` the largest residual among the point's detections (a velocity jump at a
#: uniformly distributed time between detections: 0.206, 0.198, 0.193 with 2, 3, 4 cameras
#: at even offsets): the share of the residual's square taken as each slot's variance.
KINK_SHARE = 0.2


def innovations(prep: Prepared, max_gap_s: float,
                recorded: tuple[np.ndarray, np.ndarray] | None = None, compiled: bool = True
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ν², ν_r², c)`` (n,) each: every detection's squared residual from the quadratic
    through its camera's three previous ones in undistorted pixels (its size, where the
    Jacobians act) and in recorded pixels (what is tested against the noise: σ is the
    detector's, in the image it saw; a lens stretches undistorted pixels toward the edges),
    and ``c = 1 + Σ l_j²``, the recorded residual's variance over σ² per axis if the image
    motion has no break (:func:`quadratic_residuals`; NaN: no three such previous
    detections). What :func:`motion_covariance`'s break term takes. ``recorded``:
    :func:`recorded_residuals`, if already made. ``compiled``: :func:`quadratic_residuals`'."""
    res, weight = quadratic_residuals(prep, prep.uv_undistorted, max_gap_s, compiled)
    rec, _ = recorded_residuals(prep, max_gap_s, compiled) if recorded is None else recorded
    return (_c(res[:, 0] * res[:, 0] + res[:, 1] * res[:, 1]),
            _c(rec[:, 0] * rec[:, 0] + rec[:, 1] * rec[:, 1]), _c(weight))


def pixels_per_metre_sq(prep: Prepared, points: np.ndarray) -> np.ndarray:
    """``(f_s / z_s)²`` (m, k): each camera's (undistorted) pixels per metre across its ray
    at each point, squared; ``f_s`` the mean of its focal lengths, ``z_s`` the point's depth
    along its optical axis (NaN where the point is NaN)."""
    out = np.empty((len(prep.cameras), len(points)))
    for s, cam in enumerate(prep.cameras):
        R = np.asarray(cam.R, dtype=np.float64)
        z = (points[:, 0] - prep.centers[s, 0]) * R[2, 0] \
            + (points[:, 1] - prep.centers[s, 1]) * R[2, 1] \
            + (points[:, 2] - prep.centers[s, 2]) * R[2, 2]
        f = 0.5 * (float(cam.K[0, 0]) + float(cam.K[1, 1]))
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = f / z
        out[s] = ratio * ratio
    return out


class SlotMotion(NamedTuple):
    """Where one camera slot's detection is off the ball's image at the point's time, and
    the detections that say so (:func:`slot_motion`); (k,) or (k, 2) per point."""

    shift: np.ndarray  # (k, 2) δ = u̇ (t - t_s), undistorted pixels (0: no velocity)
    accel: np.ndarray  # (k, 2) α = ½ ü (t - t_s)(t - t_s'), undistorted pixels (0: none)
    rows: np.ndarray  # (k, 3) the slot's detection and its camera's two previous (-1: none)
    linear: np.ndarray  # (k, 3) weights of those detections in the linear extrapolation
    quadratic: np.ndarray  # (k, 3) weights in the quadratic extrapolation
    lag: np.ndarray  # (k,) t - t_s, seconds


def slot_motion(prep: Prepared, rows: np.ndarray, time_ns: np.ndarray, max_gap_s: float,
                compiled: bool = True) -> list[SlotMotion]:
    """Per camera slot (slot c: a detection of camera c, as :func:`nearest_rows` gives
    them): the image motion between the slot's detection (at ``t_s``) and the
    point's time ``t``, from that detection and its camera's previous ones (each within
    ``max_gap_s`` of the next; causal: only detections at or before the slot's own).

    With ``L = t - t_s``, ``h = t_s - t_s'``, ``g = t_s' - t_s''`` (``s'``, ``s''`` the
    camera's previous two detections), the ball's undistorted image position at ``t`` is
    extrapolated from them with the weights ``w`` (Lagrange, through the detection times):

        linear (two detections):      w = (1 + ρ, -ρ, 0),  ρ = L / h
        quadratic (three):            w = ((L+h)(L+h+g) / (h(h+g)), -L(L+h+g) / (h g),
                                           L(L+h) / ((h+g) g))

    ``shift`` is the linear extrapolation's move ``δ = u̇ L``, ``u̇ = (u_s - u_s') / h``
    (unchanged since session 12), ``accel`` the quadratic's further move
    ``α = ½ ü L (L + h)``, ``ü = 2 ((u_s - u_s') / h - (u_s' - u_s'') / g) / (h + g)``
    (the backward difference is the velocity half a frame earlier, hence ``L + h``, not
    ``L``). A slot without a previous detection has ``w = (1, 0, 0)``.

    ``compiled``: every slot in one compiled pass (:func:`._stereo_kernel.slot_motion`,
    the same operations: the same bits), else with numpy per slot.
    """
    out = []
    max_gap_ns = int(max_gap_s * NS)
    if compiled:
        return _slot_motion_compiled(prep, rows, time_ns, max_gap_ns)
    t_obs = prep.obs.time_ns
    uv = prep.uv_undistorted
    k = rows.shape[0]
    for c in range(rows.shape[1]):
        row = rows[:, c]
        have = row >= 0
        r0 = np.maximum(row, 0)
        prev = np.where(have, latest_row_at_or_before(prep, c, r0 - 1), -1)
        p0 = np.maximum(prev, 0)
        dt = (t_obs[r0] - t_obs[p0]) / NS
        ok = have & (prev >= 0) & (dt > 0) & (dt <= max_gap_ns / NS)
        prev2 = np.where(ok, latest_row_at_or_before(prep, c, p0 - 1), -1)
        q0 = np.maximum(prev2, 0)
        g = (t_obs[p0] - t_obs[q0]) / NS
        ok2 = ok & (prev2 >= 0) & (g > 0) & (g <= max_gap_ns / NS)
        with np.errstate(invalid="ignore", divide="ignore"):
            vel = (uv[r0] - uv[p0]) / dt[:, None]
        lag = (time_ns - t_obs[r0]) / NS
        with np.errstate(invalid="ignore"):
            shift = np.where(ok[:, None], vel * lag[:, None], 0.0)
        h = np.where(ok, dt, 1.0)
        g = np.where(ok2, g, 1.0)
        L = np.where(ok, lag, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            acc = 2.0 * ((uv[r0] - uv[p0]) / h[:, None] - (uv[p0] - uv[q0]) / g[:, None]) \
                / (h + g)[:, None]
            accel = np.where(ok2[:, None], 0.5 * acc * (L * (L + h))[:, None], 0.0)
        rho = L / h
        linear = np.stack([1.0 + rho, -rho, np.zeros(k)], axis=1)
        quad = np.stack([(L + h) * (L + h + g) / (h * (h + g)), -L * (L + h + g) / (h * g),
                         L * (L + h) / ((h + g) * g)], axis=1)
        quad = np.where(ok2[:, None], quad, linear)
        out.append(SlotMotion(shift, accel,
                              np.stack([row, np.where(ok, prev, -1),
                                        np.where(ok2, prev2, -1)], axis=1), linear, quad,
                              np.where(have, lag, 0.0)))
    return out


def _slot_motion_compiled(prep: Prepared, rows: np.ndarray, time_ns: np.ndarray,
                          max_gap_ns: int) -> list[SlotMotion]:
    """:func:`slot_motion` by :func:`._stereo_kernel.slot_motion`."""
    from . import _stereo_kernel
    from .innovation import previous_next_rows

    k, m = rows.shape
    shift, accel = np.empty((m, k, 2)), np.empty((m, k, 2))
    mrows = np.empty((m, k, 3), dtype=np.int64)
    linear, quad, lag = np.empty((m, k, 3)), np.empty((m, k, 3)), np.empty((m, k))
    _stereo_kernel.slot_motion(
        _c(rows, dtype=np.int64), _c(time_ns, np.int64), _time_ns_c(prep),
        _c(prep.uv_undistorted, dtype=np.float64), previous_next_rows(prep)[0],
        max_gap_ns, max_gap_ns / NS, float(NS),
        shift, accel, mrows, linear, quad, lag)
    return [SlotMotion(shift[c], accel[c], mrows[c], linear[c], quad[c], lag[c])
            for c in range(m)]


def _c(a: np.ndarray, dtype=None) -> np.ndarray:
    """``a`` as a C-contiguous, writable array (of ``dtype``) for a compiled kernel: a copy
    if it is not one (numba compiles a read-only array, such as a column read from a file,
    as another signature: one signature per kernel, the one ``pslog.warm`` compiles)."""
    a = np.ascontiguousarray(a, dtype=dtype)
    return a if a.flags.writeable else a.copy()


def _time_ns_c(prep: Prepared) -> np.ndarray:
    """``_c(prep.obs.time_ns, dtype=np.int64)``, made once per Prepared (a column read from
    a file is read-only: copied once, not at each block's kernels: a 90-minute match's
    3.9 MB twice in each of its 29 blocks of ``nearest``); not to be written."""
    made = prep.__dict__.get("_time_ns_c")
    if made is None:
        made = prep.__dict__["_time_ns_c"] = _c(prep.obs.time_ns, dtype=np.int64)
    return made


def _stacked(parts: list[np.ndarray]) -> np.ndarray:
    """``np.stack(parts)``, without a copy when ``parts`` are the consecutive slices of one
    contiguous array (the compiled :func:`slot_motion`'s and Jacobians' blocks): that
    array."""
    base = parts[0].base if len(parts) else None
    if (isinstance(base, np.ndarray) and base.flags.c_contiguous
            and base.shape == (len(parts), *parts[0].shape) and base.dtype == parts[0].dtype
            and all(p.base is base and p.__array_interface__["data"][0]
                    == base[i].__array_interface__["data"][0] for i, p in enumerate(parts))):
        return base
    return np.stack(parts)


def motion_covariance(prep: Prepared, slot_rows: np.ndarray, jacobians: list[np.ndarray],
                      motion: list[SlotMotion], used: np.ndarray,
                      noise_px: float | np.ndarray, compiled: bool = True,
                      breaks: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                      ppm2: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """``nearest``'s covariance (quality columns): the point ``P`` is made from the slots'
    unshifted pixels ``u_s`` while the ball was at ``ū_s(t)``; to first order its error is
    ``Σ_s J_s (u_s - ū_s(t))``, and with ``ū_s(t)`` extrapolated from the slot's detection
    and its camera's previous ones (``Σ_j w_sj u_sj``, :func:`slot_motion`)

        P - P(t) = -(m + a) + Σ_s J_s Σ_j w_sj n_sj      (n: the detections' noise)

    ``m + a = Σ_s J_s (δ_s + α_s)`` the extrapolated move. Hence

        Σ = σ² Σ_s J_s (Σ_j w_sj² L_sj L_sjᵀ) J_sᵀ + Σ_s (v₀ (t - t_s))² J_s J_sᵀ [no u̇_s]
            + (m + a)(m + a)ᵀ

    (``L_sj`` the recorded-to-undistorted pixel Jacobian of detection ``sj``; a detection
    in two slots adds its weighted Jacobians first, :func:`covariance`; ``v₀``
    :data:`UNKNOWN_IMAGE_SPEED_PX_S` where the slot's camera has no previous detection).
    With ``breaks`` (every detection's :func:`innovations` ``(ν², ν_r², c)``) and ``ppm2``
    (:func:`pixels_per_metre_sq` (m, k)), a break of the image motion (a bounce, a kick)
    that a used slot's newest detection shows (``ν_r² > KINK_GATE σ² c``, recorded pixels)
    is taken as the ball's departure from the extrapolated path, in metres across that
    camera's ray, ``κ² = max KINK_SHARE ν² (1 - KINK_GATE σ² c / ν_r²) / ppm2_a``
    (undistorted pixels: its share beyond the noise), and every slot with a lag and a
    velocity is off by that much in its image: ``+ Σ_s κ² ppm2_s J_s J_sᵀ``
    (docs/methods.md, "nearest at bounces and kicks").
    ``slot_rows`` (k, m) the detections used (-1: none), ``jacobians`` (3, 2, k) per slot.
    ``compiled``: per point in one compiled pass (:func:`._stereo_kernel.motion_covariance`,
    the same operations: the same bits), else on numpy columns."""
    k, m = slot_rows.shape
    if compiled:
        from . import _stereo_kernel

        out = np.empty((7, k))
        lens = prep._uv_jacobian_cols
        _stereo_kernel.motion_covariance(
            _c(slot_rows, dtype=np.int64),
            _c(_stacked(jacobians), dtype=np.float64),
            _c(used, dtype=bool),
            _c(_stacked([d.rows for d in motion]), dtype=np.int64),
            _c(_stacked([d.quadratic for d in motion]), dtype=np.float64),
            _c(_stacked([d.lag for d in motion]), dtype=np.float64),
            _c(_stacked([d.shift for d in motion]), dtype=np.float64),
            _c(_stacked([d.accel for d in motion]), dtype=np.float64),
            np.zeros((4, 0)) if lens is None else lens,
            # noise_px ** 2 as numpy makes it (a column: its square; a float: Python's power)
            np.square(noise_px) if np.ndim(noise_px) else np.full(k, noise_px**2),
            UNKNOWN_IMAGE_SPEED_PX_S,
            *((np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((m, 0)))
              if breaks is None or ppm2 is None
              else (*breaks, _c(ppm2, dtype=np.float64))),
            KINK_GATE, KINK_SHARE, out)
        return {"std_m": out[0], **{f"cov_{a}_m2": out[1 + i] for i, a in
                                    enumerate(("xx", "yy", "zz", "xy", "xz", "yz"))}}
    cov = covariance(slot_rows, jacobians, _noise_factors(prep, motion, used), noise_px)
    # the unknown shift of a slot without image velocity, independent of every detection's
    # noise and of the other slots': Σ_s (v₀ L_s)² J_s J_sᵀ
    # and the break of the image motion a used slot's newest detection shows:
    # κ² (m², across that camera's ray), the largest; each slot with a lag and a velocity
    # off by κ² ppm2_s per axis in its image: Σ_s κ² ppm2_s J_s J_sᵀ
    kink = _break_size(motion, used, noise_px, breaks, ppm2)
    unknown = np.zeros((6, k))
    first, second = np.array([0, 1, 2, 0, 0, 1]), np.array([0, 1, 2, 1, 2, 2])
    for s in range(m):
        blind = used[:, s] & (motion[s].rows[:, 1] < 0) & (motion[s].lag > 0)
        kinked = used[:, s] & ~blind & (motion[s].lag > 0) & (kink > 0)
        if np.any(blind | kinked):
            with np.errstate(invalid="ignore"):
                f2 = np.where(blind, (motion[s].lag * UNKNOWN_IMAGE_SPEED_PX_S) ** 2,
                              np.where(kinked, kink * ppm2[s] if ppm2 is not None else 0.0,
                                       0.0))
            J = jacobians[s]
            unknown += f2 * (J[first, 0] * J[second, 0] + J[first, 1] * J[second, 1])
    if np.any(unknown):
        cov = covariance_columns(np.stack([cov[f"cov_{a}_m2"] for a in
                                           ("xx", "yy", "zz", "xy", "xz", "yz")]) + unknown)
    return _with_motion(cov, jacobians, [d.shift + d.accel for d in motion], used)


def _noise_factors(prep: Prepared, motion: list[SlotMotion], used: np.ndarray
                   ) -> list[np.ndarray]:
    """Each slot's (2, 2, k) Cholesky factor ``C_s`` of ``M_s = Σ_j w_sj² L_sj L_sjᵀ``: the
    detection noise's part of :func:`motion_covariance` is ``covariance`` of them."""
    # no detection is in two slots of a point (a slot's are its camera's), so the weighted
    # detections of slot s add up to J_s M_s J_sᵀ, M_s = Σ_j w_sj² L_sj L_sjᵀ (2 x 2), given
    # to covariance as its Cholesky factor C_s (C_s C_sᵀ = M_s): three slots, not nine
    k, m = used.shape
    factors = []
    for s in range(m):
        M = np.zeros((2, 2, k))
        for j in range(3):
            r = np.where(used[:, s], motion[s].rows[:, j], -1)
            w2 = np.where(r >= 0, motion[s].quadratic[:, j] ** 2, 0.0)
            L = prep.pixel_jacobians_t(np.maximum(r, 0))
            if L is None:
                M[0, 0] += w2
                M[1, 1] += w2
            else:  # L Lᵀ: (a, c) = Σ_b L[a, b] L[c, b]
                M[0, 0] += w2 * (L[0, 0] * L[0, 0] + L[0, 1] * L[0, 1])
                M[1, 1] += w2 * (L[1, 0] * L[1, 0] + L[1, 1] * L[1, 1])
                M[1, 0] += w2 * (L[1, 0] * L[0, 0] + L[1, 1] * L[0, 1])
        C = np.zeros((2, 2, k))
        C[0, 0] = np.sqrt(M[0, 0])
        with np.errstate(invalid="ignore", divide="ignore"):
            C[1, 0] = np.where(C[0, 0] > 0, M[1, 0] / C[0, 0], 0.0)
        C[1, 1] = np.sqrt(np.maximum(M[1, 1] - C[1, 0] * C[1, 0], 0.0))
        factors.append(C)
    return factors


def _break_size(motion: list[SlotMotion], used: np.ndarray, noise_px: float | np.ndarray,
                breaks: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
                ppm2: np.ndarray | None) -> np.ndarray:
    """κ² (k,) of :func:`motion_covariance` (numpy form): the largest ``KINK_SHARE ν²
    (1 - KINK_GATE σ² c / ν_r²) / ppm2_a`` over the used slots' newest detections whose
    ``ν_r² > KINK_GATE σ² c`` (0: no break shown, or no ``breaks``)."""
    k = used.shape[0]
    kink = np.zeros(k)
    if breaks is None or ppm2 is None:
        return kink
    nu2, nu2_rec, var = breaks
    s2 = np.square(noise_px) if np.ndim(noise_px) else np.full(k, noise_px**2)
    for a in range(used.shape[1]):
        r = np.where(used[:, a], motion[a].rows[:, 0], -1)
        rr = np.maximum(r, 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            excess = nu2_rec[rr] - KINK_GATE * s2 * var[rr]
            y = KINK_SHARE * (nu2[rr] * (excess / nu2_rec[rr])) / ppm2[a]
            kink = np.where((r >= 0) & (excess > 0) & (y > kink), y, kink)
    return kink


def triangulate_groups(prep: Prepared, group: np.ndarray, n_groups: int,
                       noise_px: float | None = 0.5, with_flags: bool = False,
                       with_rows: bool = False,
                       residuals_out: list[np.ndarray] | None = None):
    """N-view least-squares point of each group (one ray per camera; a camera seen twice in a
    group keeps its latest ray). Returns points (g, 3), quality {name: (g,)}
    (:func:`nview_points`), time_ns (g,) of the group's latest observation, camera (g,) of
    that observation, with ``with_flags`` the validity flags (g,) of :func:`nview_points`,
    and with ``with_rows`` the rows (g, m) and the rays used (g, m); ``residuals_out``:
    :func:`nview_points`'."""
    n_cams = len(prep.centers)
    rows = np.full((n_groups, n_cams), -1, dtype=np.int64)
    # the latest ray of a camera seen twice: the largest row (a fancy assignment with repeated
    # indices has no defined winner in numpy; a maximum has)
    np.maximum.at(rows, (group, prep.obs.camera), np.arange(len(group)))
    points, quality, flags, used = nview_points(prep, rows, noise_px,
                                                residuals_out=residuals_out)
    last = np.r_[np.flatnonzero(np.diff(group)), len(group) - 1]  # last row of each group
    out: tuple = (points, quality, prep.obs.time_ns[last], prep.obs.camera[last])
    if with_flags:
        out = (*out, flags)
    return (*out, rows, used) if with_rows else out


def residual_refused(prep: Prepared, rows: np.ndarray, used: np.ndarray, points: np.ndarray,
                     time_ns: np.ndarray, sigma: np.ndarray, max_gap_s: float,
                     residuals: list[np.ndarray] | None = None, every_step: bool = False,
                     compiled: bool = True) -> np.ndarray:
    """Which N-view points the reprojection residuals of their own detections contradict
    (docs/methods.md, "The N-view residual test").

    ``n`` rays (``n >= 2``) of a point seen at one instant give ``2n`` pixel coordinates for
    3 unknowns; under the model (the detections of one ball at one instant, Gaussian noise of
    ``σ_c`` per axis in camera ``c``'s recorded image: each camera its own, webcams mix) the
    weighted sum of the squared reprojection residuals ``d² = Σ_c r_c² / σ_c²`` at its
    minimum is χ² of ``2n - 3`` degrees of freedom. ``d²`` is taken at the better of the
    least-squares ray intersection ``points`` and one reprojection-weighted step from it
    (:func:`_weighted_points`): any point's ``d²`` is at least the minimum's, and the
    unweighted intersection's is up to ``¼(2 + q² + q⁻²)`` times it for two views (``q`` the
    ratio of the cameras' ``f / (z σ)``), which refuses *more* valid points (2.4 on
    webcams3: 0.3 % instead of 3.7·10⁻⁶; tens where one camera is 6 times noisier). The
    detections taken as simultaneous lie up to the tolerance apart: each slot's image moved
    by ``e_c = |u̇_c| (t - t_c)`` since its shutter, ``t`` the point's time (its latest
    detection), ``u̇_c`` from its camera's previous detection within ``max_gap_s``
    (:func:`slot_motion`'s ``shift``; without one, :data:`UNKNOWN_IMAGE_SPEED_PX_S`). A point
    is refused when

        ``√d² > √χ²_{2n-3}(1 - p) + √(Σ_c e_c² / σ_c²)``,   ``p = exp(-25/2)``

    the level of type A's 5σ innovation test (:data:`~.innovation.REFUSAL_PROBABILITY`;
    ``2n - 3`` is odd: ``4.63 σ`` for two views, ``5.29 σ`` for three, ``5.75 σ`` for
    four): a detection that is not the ball the others saw (a
    second orange object chosen in one camera) makes rays that miss by metres, a point
    anywhere along them. Causal: the point's own detections and their cameras' previous ones.

    Parameters
    ----------
    rows, used : (k, m) the detection of each camera slot (-1: none) and the rays used
    points : (k, 3) the N-view points, metres
    time_ns : (k,) each point's time (its latest detection's)
    sigma : (k, m) each camera's detection noise, pixels per axis (:func:`refusal_noise`)
    residuals : each camera's reprojection residuals (k,) of ``points`` where used, if
        already made (:func:`nview_points`' ``residuals_out``: the same bits), else None
    every_step : the weighted step's ``d²`` of every point (the reference), not only of
        those whose own ``d²`` exceeds the bound (the same decisions: ``min(d², d²_w)``
        cannot exceed it where ``d²`` does not)
    compiled : the sums ``d²``, ``Σ e_c² / σ_c²`` and the rays used point by point in one
        compiled pass (:func:`._stereo_kernel.residual_sums`, the same operations: the same
        bits), else with numpy (:func:`slot_motion`'s columns; the reference)

    Returns
    -------
    (k,) bool, True where the residuals exceed the bound (False where fewer than two rays)
    """
    from .innovation import chi2_threshold

    k, m = rows.shape
    d2, e2, n = _refusal_sums(prep, rows, used, points, time_ns, sigma, max_gap_s, residuals,
                              compiled)
    bound = np.full(k, np.inf)
    for count in np.unique(n[n >= 2]).tolist():
        at = n == count
        bound[at] = np.sqrt(chi2_threshold(2 * count - 3))
    with np.errstate(invalid="ignore"):
        limit = bound + np.sqrt(e2)
        # the weighted step's d² only where the intersection's own fails: elsewhere
        # √min(d², d²_w) <= √d² <= the bound already (the same decisions, a few points'
        # Gauss-Newton steps instead of every point's)
        doubt = np.arange(k) if every_step else np.flatnonzero((n >= 2)
                                                               & ~(np.sqrt(d2) <= limit))
        d2w = d2.copy()
        if len(doubt):
            weighted = _weighted_points(prep, rows, used, points, sigma,
                                        None if every_step else doubt)
            d2w[doubt] = 0.0
            part = d2w[doubt]
            for c in range(m):
                on = used[doubt, c]
                if not on.any():
                    continue
                var = sigma[doubt, c] * sigma[doubt, c]
                _add_r2(part, reprojection_one(
                    prep, c, weighted, prep.uv_undistorted[np.maximum(rows[doubt, c], 0)]),
                    on, var)
            d2w[doubt] = part
        return (n >= 2) & (np.sqrt(np.fmin(d2, d2w)) > limit)


def _add_r2(total: np.ndarray, r: np.ndarray, on: np.ndarray, var: np.ndarray) -> None:
    """``total += r² / var`` where ``on`` and ``r`` finite; inf where ``on`` and not."""
    total += np.where(on & np.isfinite(r), r * r / var, 0.0)
    total[on & ~np.isfinite(r)] = np.inf  # (behind a ray's camera: never kept)


def _refusal_sums(prep: Prepared, rows: np.ndarray, used: np.ndarray, points: np.ndarray,
                  time_ns: np.ndarray, sigma: np.ndarray, max_gap_s: float,
                  residuals: list[np.ndarray] | None, compiled: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`residual_refused`'s ``d²`` (k,) of ``points``, ``Σ_c e_c² / σ_c²`` (k,) and
    rays used (k,) int64 (its arguments'); ``compiled``: by
    :func:`._stereo_kernel.residual_sums`, else with numpy (the reference: the same bits)."""
    k, m = rows.shape
    d2, e2 = np.zeros(k), np.zeros(k)
    if compiled:
        from . import _stereo_kernel
        from .innovation import previous_next_rows

        if residuals is None:
            with np.errstate(invalid="ignore"):
                residuals = [np.where(used[:, c], reprojection_one(
                    prep, c, points, prep.uv_undistorted[np.maximum(rows[:, c], 0)]), np.nan)
                    for c in range(m)]
        n = np.empty(k, dtype=np.int64)
        max_gap_ns = int(max_gap_s * NS)  # (slot_motion's)
        _stereo_kernel.residual_sums(
            _c(rows, dtype=np.int64), _c(used, dtype=bool),
            _c(np.array(residuals, dtype=np.float64).reshape(m, k)),
            _c(sigma, dtype=np.float64), _c(time_ns, dtype=np.int64),
            _time_ns_c(prep), _c(prep.uv_undistorted, dtype=np.float64),
            previous_next_rows(prep)[0], _c(np.asarray(used.any(axis=0))), max_gap_ns / NS,
            float(NS), UNKNOWN_IMAGE_SPEED_PX_S, d2, e2, n)
    else:
        motion = slot_motion(prep, np.where(used, rows, -1), time_ns, max_gap_s, False)
        with np.errstate(invalid="ignore"):
            for c in range(m):
                on = used[:, c]
                if not on.any():
                    continue
                var = sigma[:, c] * sigma[:, c]  # (each camera's own noise: webcams mix)
                _add_r2(d2, reprojection_one(
                    prep, c, points, prep.uv_undistorted[np.maximum(rows[:, c], 0)])
                    if residuals is None else residuals[c], on, var)
                mo = motion[c]
                known = mo.rows[:, 1] >= 0
                shift2 = mo.shift[:, 0] ** 2 + mo.shift[:, 1] ** 2
                unknown = UNKNOWN_IMAGE_SPEED_PX_S * mo.lag
                e2 += np.where(on, np.where(known, shift2, unknown * unknown) / var, 0.0)
        n = used.sum(axis=1)
    return d2, e2, n


def _weighted_points(prep: Prepared, rows: np.ndarray, used: np.ndarray, points: np.ndarray,
                     sigma: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
    """The ray intersection (k, 3) weighted as the reprojection error is, for the residual
    test only: camera ``c``'s squared distance from its ray at ``(f_c / (z_c σ_c))²``
    (``f_c`` its focal length in pixels, ``z_c`` the depth of the unweighted point
    ``points`` in it, ``σ_c`` its noise): one Gauss-Newton step, from the unweighted point,
    towards the minimum of ``Σ_c r_c² / σ_c²`` (the unweighted intersection's ``d²`` over
    that minimum is ``¼(2 + q² + q⁻²)`` for two views, ``q`` the ratio of the cameras'
    ``f / (z σ)``: 2.4 at webcams3's worst depths, tens where one camera's noise is 6 times
    the other's). NaN where a depth is not positive or the system singular.

    ``at``: the points of these rows only ((j,) sorted; None: every row), each the bits it
    has among all the rows: the cameras taken are those any row uses (an unused slot
    enters a point's sums as ``0 · I``: + 0.0, whatever ray, finite or not, its clipped
    index would read), and the depths are the whole array's product (a one-row product is
    another BLAS call, other bits)."""
    k, m = rows.shape
    cameras = [c for c in range(m) if used[:, c].any()]
    if at is not None:
        with np.errstate(invalid="ignore", over="ignore"):
            depth = {c: ((points - prep.centers[c]) @ prep.cameras[c].R[2])[at]
                     for c in cameras}
        rows, used, points, sigma = rows[at], used[at], points[at], sigma[at]
        k = len(at)
    A = np.zeros((k, 3, 3))
    b = np.zeros((k, 3))
    eye = np.eye(3)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for c in cameras:
            on = used[:, c]
            cam = prep.cameras[c]
            z = (points - prep.centers[c]) @ cam.R[2] if at is None else depth[c]
            f = 0.5 * (cam.K[0, 0] + cam.K[1, 1])
            w = np.where(on, (f / (z * sigma[:, c])) ** 2, 0.0)
            # an unused slot's ray: none (zero, P = I, weight 0: + 0.0), not the row the
            # index -1 is clipped to (row 0's ray, NaN where that detection has none:
            # 0 · NaN made every point without this camera's ray NaN)
            d = np.where(on[:, None], prep.ray_dir[np.maximum(rows[:, c], 0)], 0.0)
            P = eye - d[:, :, None] * d[:, None, :]
            A += w[:, None, None] * P
            b += w[:, None] * (P @ prep.centers[c])
        bad = ~np.all(np.isfinite(A.reshape(k, 9)), axis=1) | (np.linalg.det(A) <= 0.0)
        A[bad] = eye
        out = np.linalg.solve(A, b[:, :, None])[:, :, 0]
    out[bad] = np.nan
    return out


def stereo_at_common_instants(
    prep: Prepared, tolerance_s: float, method: str, noise_px: float | None = 0.5,
    max_gap_s: float | None = None, shared: bool | None = None, *,
    drops: Drops | None = None,
) -> tuple[Track, np.ndarray]:
    """N-view points of every instant at which at least two cameras saw the ball.

    A point whose detections' reprojection residuals exceed what the noise and the
    tolerance explain (:func:`residual_refused`, at :func:`refusal_noise`'s σ; ``max_gap_s``:
    how far back a camera's previous detection gives its image speed, and the noise's
    residuals reach; None: 3.5 periods of the slowest camera) is dropped and counted in
    ``Track.dropped`` as ``residual_failed``, like a geometrically invalid one. ``shared``:
    whether the session has instants two cameras share (None: ``prep``'s; given by the
    callers that left detections without a ray out, :func:`rays_only_shared`'s, of the
    session as given: its methods' error is the session's, not the rays'). ``drops``: a
    list to which each dropped point's reason, time and camera are added (:data:`Drops`).

    Returns
    -------
    track : Track named ``method``, one valid point per such instant, with its quality
    alone : (n,) bool, the detections that had no simultaneous partner
        (``track.dropped``: the instants whose point was geometrically invalid or refused,
        whose detections are not ``alone`` either)
    """
    group, n_cameras = sync_groups(prep.obs, len(prep.centers), tolerance_s)
    if not (np.any(n_cameras >= 2) if shared is None else shared):
        from . import METHODS  # (the registry: fusion imports this module)

        # no shared instant, and every detection alone: what the registry says suits that
        # (was a hard-coded "nearest, typeA", which left out smooth and filter)
        suit = [name for name, m in METHODS.items() if m.suits(False, True)]
        raise FusionError(
            f"method {method} needs cameras with a common shutter instant (sync or typeB "
            f"timing), but no two cameras captured within {tolerance_s * 1e3:g} ms of each "
            f"other; methods that suit this session: {', '.join(suit)}")
    residuals: list[np.ndarray] = []
    points, quality, time_ns, camera, flags, rows, used = triangulate_groups(
        prep, group, len(n_cameras), noise_px, with_flags=True, with_rows=True,
        residuals_out=residuals)
    # made: two usable rays, so an invalid point (exactly parallel rays give none) is counted
    made = (n_cameras >= 2) & (quality["n_detections"] >= 2)
    keep = made & (flags == 0) & np.all(np.isfinite(points), axis=1)
    if max_gap_s is None:
        max_gap_s = default_max_gap_s(prep)
    at = np.flatnonzero(keep)
    refused = np.zeros(len(keep), dtype=bool)
    refused[at] = residual_refused(
        prep, rows[at], used[at], points[at], time_ns[at],
        refusal_noise(prep, time_ns[at], max_gap_s, noise_px), max_gap_s,
        [r[at] for r in residuals])
    keep &= ~refused
    n_refused = int(np.count_nonzero(refused))
    if drops is not None:
        note_dropped(drops, time_ns[made], camera[made], flags[made])
        note_dropped(drops, time_ns, camera, refused=(RESIDUAL_FAILED, refused))
    track = Track(method, time_ns[keep], points[keep], camera[keep],
                  {k: v[keep] for k, v in quality.items()})
    return (with_dropped(track, count_invalid(flags[made]),
                         {RESIDUAL_FAILED: n_refused} if n_refused else {}),
            n_cameras[group] == 1)


def rays_only_shared(prep: Prepared, tolerance_s: float) -> tuple[Prepared, bool | None]:
    """``sync``'s, ``typeB``'s and ``linear``'s session: ``prep`` without its detections
    that have no ray (:func:`~._prepare.rays_only`: a missing detection), and whether
    ``prep`` as given has shared instants where any was left out (None: none left out)."""
    out, kept = rays_only(prep)
    if kept is None:
        return prep, None
    return out, bool(np.any(sync_groups(prep.obs, len(prep.centers), tolerance_s)[1] >= 2))


#: Track.dropped's reason for an N-view point its detections' residuals contradict.
RESIDUAL_FAILED = "residual_failed"


def fuse_sync(prep: Prepared, tolerance_s: float = 1e-3, noise_px: float | None = 0.5,
              max_gap_s: float | None = None, *, drops: Drops | None = None) -> Track:
    """``sync``: N-view triangulation of detections captured within ``tolerance_s`` (the
    paper's "synchronized" row of Table 1: "general stereo vision with no time delay").

    One point per instant at which at least two cameras saw the ball, unless geometrically
    invalid (dropped and counted in ``Track.dropped``): the least-squares intersection of
    their viewing rays (:func:`~pslog.geometry.triangulate_rays`; with two rays, the midpoint
    of the common perpendicular, the paper's "crossing point" of section 2.2, step 3), every
    ray parameter positive, and unless its detections' reprojection residuals contradict it
    (:func:`residual_refused`: a detection that is not the ball the others saw; dropped and
    counted as ``residual_failed``). ``std_m`` / ``cov_*``: first order at ``noise_px`` per
    axis on each recorded pixel (``tests/test_fusion_validity.py``, hand-computed on a
    rectified pair). ``max_gap_s``, ``drops``: :func:`stereo_at_common_instants`'. A
    detection without a ray is a missing one (:func:`rays_only_shared`).
    """
    prep, shared = rays_only_shared(prep, tolerance_s)  # (no ray: a missing detection)
    if len(prep.obs) == 0:
        return _empty("sync")
    return stereo_at_common_instants(prep, tolerance_s, "sync", noise_px, max_gap_s,
                                     shared, drops=drops)[0]


def fuse_nearest(prep: Prepared, max_gap_s: float, noise_px: float | None = 0.5,
                 compiled: bool = True, *, drops: Drops | None = None) -> Track:
    """``nearest``: each detection triangulated with the latest detection of every other camera
    as if they were simultaneous (the paper's "unsynchronized" baseline). Geometrically
    invalid points are dropped and counted in ``Track.dropped``. ``noise_px``: the
    detections' noise until the session's own shows (:func:`detection_noise`), and an upper
    bound of its floor; None: no covariance. ``compiled``: the per-point arithmetic by
    :mod:`._stereo_kernel` (the same bits), else by the numpy forms (a reference). A
    detection without a ray is a missing one (:func:`~._prepare.rays_only`). ``drops``: as
    :func:`stereo_at_common_instants`'."""
    prep = rays_only(prep)[0]
    if len(prep.obs) == 0:
        return _empty("nearest")
    time_ns, camera = prep.obs.time_ns, prep.obs.camera
    rows, others = nearest_rows(prep, int(max_gap_s * NS), compiled)
    if compiled and len(rows) >= 2 * NEAREST_BLOCK_ROWS:
        blocked = _nearest_in_blocks(prep, rows, others, max_gap_s, noise_px, drops)
        if blocked is not None:
            return blocked
    # the other cameras' detections are older than the point: the ball moved since; and the
    # noise is the detections' own (docs/methods.md, "nearest's covariance at the true noise")
    if noise_px is None:
        points, quality, flags, _ = nview_points(prep, rows, None, compiled=compiled)
    else:
        recorded = recorded_residuals(prep, max_gap_s, compiled)
        sigma = detection_noise(prep, time_ns, max_gap_s, noise_px)
        points, quality, flags, _ = nview_points(
            prep, rows, sigma, slot_motion(prep, rows, time_ns, max_gap_s, compiled),
            compiled, innovations(prep, max_gap_s, recorded, compiled),
            excess=(time_ns, max_gap_s))
    kept = _NearestRows(len(rows))
    kept.add(time_ns, camera, others, points, quality, flags, drops)
    return kept.track()


def excess_factor(prep: Prepared, rows: np.ndarray, used: np.ndarray, points: np.ndarray,
                  time_ns: np.ndarray, sigma: np.ndarray, max_gap_s: float,
                  residuals: list[np.ndarray] | None, compiled: bool = True) -> np.ndarray:
    """``nearest``'s variance factor (k,) for the points its own detections contradict
    (docs/methods.md, "nearest's covariance where its detections disagree"): with
    :func:`residual_refused`'s sums on the point's slots (``d² = Σ_c r_c² / σ²``, the
    reprojection residuals of the unshifted detections, and ``Σ_c e_c² / σ²``, what the
    slots' image motion since their shutters explains), where

        ``√d² > √χ²_{2n-3}(1 - p) + √(Σ_c e_c² / σ²)``   (the residual test's bound)

    the factor is ``(√d² - √(Σ_c e_c² / σ²))² / (2n - 3)``: the residual beyond the
    motion's, per degree of freedom, as the unit variance (the a-posteriori variance factor
    of least squares: the detections are not one ball at one instant, and the point is
    located no better than their disagreement); 1 elsewhere. ``sigma`` (k,): each point's
    noise (:func:`detection_noise`, the same for every camera)."""
    from .innovation import chi2_threshold

    k, m = rows.shape
    sig = np.ascontiguousarray(np.broadcast_to(np.asarray(sigma, dtype=np.float64)[:, None],
                                               (k, m)))
    d2, e2, n = _refusal_sums(prep, rows, used, points, time_ns, sig, max_gap_s, residuals,
                              compiled)
    bound = np.full(k, np.inf)
    for count in range(2, m + 1):  # (the rays used: 0 to m; no np.unique's sort a block)
        at = n == count
        if at.any():
            bound[at] = np.sqrt(chi2_threshold(2 * count - 3))
    with np.errstate(invalid="ignore"):
        excess = np.sqrt(d2) - np.sqrt(e2)
        over = (n >= 2) & (np.sqrt(d2) > bound + np.sqrt(e2))
        return np.where(over, excess * excess / np.maximum(2 * n - 3, 1), 1.0)


def excess_noise(prep: Prepared, slot_rows: np.ndarray, jacobians: list[np.ndarray],
                 motion: list[SlotMotion], used: np.ndarray, noise_px: np.ndarray,
                 f: np.ndarray, cov: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``cov`` (:func:`motion_covariance`'s quality columns) with the detection noise's part
    ``Σ_n = σ² Σ_s J_s M_s J_sᵀ`` of the points where ``f`` (:func:`excess_factor`) > 1
    taken ``f`` times: ``Σ' = Σ + (f - 1) Σ_n`` (the motion's, the breaks' and the gate's
    doubt's terms are the model's, not the noise the residual measures); the same arrays
    where ``f`` scales none. ``noise_px`` (k,), ``slot_rows`` / ``used`` / ``jacobians`` /
    ``motion`` as :func:`motion_covariance`'s. Elementwise on the scaled points only (the
    same bits whatever rows are beside them)."""
    hit = np.flatnonzero(f > 1.0)
    if not len(hit):
        return cov
    part = [SlotMotion(*(np.take(column, hit, axis=0) for column in mo)) for mo in motion]
    noise = covariance(slot_rows[hit], [J[:, :, hit] for J in jacobians],
                       _noise_factors(prep, part, used[hit]), noise_px[hit])
    names = ("cov_xx_m2", "cov_yy_m2", "cov_zz_m2", "cov_xy_m2", "cov_xz_m2", "cov_yz_m2")
    # (f is infinite only where a used slot has no residual: behind its camera, a point
    # invalid_points flags and the track leaves out)
    with np.errstate(invalid="ignore"):
        six = (np.stack([cov[name][hit] for name in names])
               + (f[hit] - 1.0) * np.stack([noise[name] for name in names]))
    out = {name: column.copy() for name, column in cov.items()}
    for name, column in covariance_columns(six).items():
        out[name][hit] = column
    return out


class _NearestRows:
    """:func:`fuse_nearest`'s kept points (a point is made where its row has another
    camera's detection and at least two detections; kept where valid and finite), block by
    block of rows (:func:`_nearest_in_blocks`), each block's written in place into columns
    of the session's row count as it comes (``np.compress(..., out=)``): one copy of a kept
    row, where the blocks' kept rows joined at the end made two, both alive at the join
    (a 90-minute match: ``fuse_nearest``'s peak 194.5 -> 131.2 MB, docs/performance.md).
    The same values, dtypes and order: the same track."""

    def __init__(self, rows: int) -> None:
        self.rows, self.n = rows, 0
        self.columns: tuple | None = None  # time_ns, points, camera, {name: quality}
        self.flags: list[np.ndarray] = []

    def add(self, time_ns: np.ndarray, camera: np.ndarray, others: np.ndarray,
            points: np.ndarray, quality: dict[str, np.ndarray], flags: np.ndarray,
            drops: Drops | None = None) -> None:
        """A block's rows (every argument: the same rows, (k,) or (k, .)), its kept points
        written after the earlier blocks'; ``drops``: the dropped ones added (:data:`Drops`)."""
        made = (others >= 1) & (quality["n_detections"] >= 2)
        keep = made & (flags == 0) & np.all(np.isfinite(points), axis=1)
        if drops is not None:
            note_dropped(drops, time_ns[made], camera[made], flags[made])
        self.flags.append(flags[made])
        if self.columns is None:
            k = self.rows
            self.columns = (np.empty(k, time_ns.dtype), np.empty((k, 3), points.dtype),
                            np.empty(k, camera.dtype),
                            {name: np.empty(k, column.dtype) for name, column in quality.items()})
        lo, hi = self.n, self.n + int(np.count_nonzero(keep))
        time_out, points_out, camera_out, quality_out = self.columns
        np.compress(keep, time_ns, out=time_out[lo:hi])
        np.compress(keep, points, axis=0, out=points_out[lo:hi])
        np.compress(keep, camera, out=camera_out[lo:hi])
        for name, column in quality.items():
            np.compress(keep, column, out=quality_out[name][lo:hi])
        self.n = hi

    def track(self) -> Track:
        """The track of the blocks added, in row order, with the invalid points' counts."""
        n = self.n
        # (the first n rows: views; copied when most rows were left out, not to hold them)
        cut = (lambda a: a[:n]) if 2 * n >= self.rows else (lambda a: a[:n].copy())
        time_ns, points, camera, quality = cast(tuple, self.columns)
        track = Track("nearest", cut(time_ns), cut(points), cut(camera),
                      {name: cut(column) for name, column in quality.items()})
        return with_dropped(track, count_invalid(np.concatenate(self.flags)))


#: :func:`fuse_nearest` makes the points of a long session (from twice this many detections)
#: in blocks of at least this many rows: each block's temporaries (rays, normal equations,
#: Jacobians, slot motions: ~1 kB a row with three cameras) are a few MB, reused from the
#: heap by the next block and hot in the cache, instead of arrays of hundreds of MB that the
#: kernel zeroes page by page at their first write (a 90-minute match: ~0.6 of nearest's
#: 1.5 CPU s); only the kept points' columns are made at full length
NEAREST_BLOCK_ROWS = 16384


def _nearest_in_blocks(prep: Prepared, rows: np.ndarray, others: np.ndarray,
                       max_gap_s: float, noise_px: float | None, drops: Drops | None = None
                       ) -> Track | None:
    """:func:`fuse_nearest`'s compiled track, its points made block by block of rows: the
    same bits, as every column of a point is made from its own row of ``rows`` and the
    detections' (session-wide) columns by the same operations whatever the rows beside it.
    The row count of a block does choose a path in :func:`nview_points` (compiled from
    ``_FEW`` rows: every block has at least :data:`NEAREST_BLOCK_ROWS`) and in
    :func:`invalid_points` (compiled where each camera has 0 or at least 2 finite points,
    and where its probes, and :func:`ray_depths`' probes, say the compiled passes give
    numpy's bits): None, for the whole-array way, when a block would go another way than
    the whole array (``drops`` then unchanged)."""
    from ._prepare import ray_depths_compiled, view_flags_compiled

    if not (view_flags_compiled() and ray_depths_compiled()):
        return None
    time_ns, camera = prep.obs.time_ns, prep.obs.camera
    k = len(rows)
    max_gap_ns = int(max_gap_s * NS)
    if noise_px is not None:  # (session-wide: causal windows and per-detection columns)
        recorded = recorded_residuals(prep, max_gap_s)
        sigma = detection_noise(prep, time_ns, max_gap_s, noise_px)
        breaks = innovations(prep, max_gap_s, recorded)
        del recorded
    n_blocks = k // NEAREST_BLOCK_ROWS
    bounds = [k * i // n_blocks for i in range(n_blocks + 1)]
    time_c = _time_ns_c(prep)  # (the kernels' times: views of one writable copy)
    kept = _NearestRows(k)
    noted: Drops | None = None if drops is None else []
    for lo, hi in itertools.pairwise(bounds):
        block = rows[lo:hi]
        if noise_px is None:
            points, quality, flags, used = nview_points(prep, block, None)
        else:
            points, quality, flags, used = nview_points(
                prep, block, sigma[lo:hi],
                _slot_motion_compiled(prep, block, time_c[lo:hi], max_gap_ns), True, breaks,
                excess=(time_c[lo:hi], max_gap_s))
        finite = finite_rows(points)
        counts = np.count_nonzero(used & finite[:, None], axis=0)
        if not np.all((counts == 0) | (counts >= 2)):
            return None  # (invalid_points' numpy form for this block)
        kept.add(time_ns[lo:hi], camera[lo:hi], others[lo:hi], points, quality, flags, noted)
        del points, quality, flags, used, finite
    if drops is not None and noted is not None:
        drops.extend(noted)
    return kept.track()


def nearest_rows(prep: Prepared, max_gap_ns: int, compiled: bool = True
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``nearest``'s rows (n, m) int64: for each detection, the latest detection of every
    other camera at or before it (row order) within ``max_gap_ns``, and itself in its own
    camera's slot (-1: none); and the other cameras' detections found (n,). ``compiled``:
    in one pass (:func:`._stereo_kernel.nearest_rows`), else per camera with numpy (the
    same rows)."""
    n, n_cams = len(prep.obs), len(prep.centers)
    time_ns, camera = prep.obs.time_ns, prep.obs.camera
    rows = np.full((n, n_cams), -1, dtype=np.int64)
    if compiled:
        from . import _stereo_kernel

        others = np.empty(n, dtype=np.int64)
        _stereo_kernel.nearest_rows(_c(camera, dtype=np.int64), _time_ns_c(prep),
                                    max_gap_ns, rows, others)
        return rows, others
    events = np.arange(n)
    for d in range(n_cams):  # loop over cameras, vectorized over events
        latest = latest_row_at_or_before(prep, d, events)
        ok = (latest >= 0) & (camera != d)
        ok &= time_ns - prep.obs.time_ns[np.maximum(latest, 0)] <= max_gap_ns
        rows[ok, d] = latest[ok]
    others = (rows >= 0).sum(axis=1)
    rows[events, camera] = events
    return rows, others


#: The validity flags' reasons, as ``Track.dropped`` names them.
_INVALID_REASONS = (("behind_camera", BEHIND), ("outside_view", OUTSIDE_VIEW),
                    ("parallel_rays", PARALLEL))


def count_invalid(flags: np.ndarray) -> dict[str, int]:
    """{reason: number of points} of validity ``flags`` (a point may have several reasons)."""
    return {name: int(np.count_nonzero(flags & bit))
            for name, bit in _INVALID_REASONS if np.any(flags & bit)}


#: The points a method dropped, one entry per reason and call: ``(reason, time_ns (k,),
#: camera (k,))``, each point under each of its reasons (as ``Track.dropped`` counts it).
#: The window stream (:class:`~pslog.fusion.stream.StreamFuser`) re-fuses its window at
#: every push and counts only the drops that became settled, as it emits only such points.
Drops = list[tuple[str, np.ndarray, np.ndarray]]


def note_dropped(drops: Drops, time_ns: np.ndarray, camera: np.ndarray,
                 flags: np.ndarray | None = None,
                 refused: tuple[str, np.ndarray] | None = None) -> None:
    """Add to ``drops`` the points of ``time_ns`` / ``camera`` (k,) that validity ``flags``
    (k,) make invalid (:func:`count_invalid`'s reasons) or that ``refused`` = ``(reason,
    (k,) bool)`` refuses."""
    if flags is not None:
        for name, bit in _INVALID_REASONS:
            on = (flags & bit) != 0
            if np.any(on):
                drops.append((name, time_ns[on], camera[on]))
    if refused is not None and np.any(refused[1]):
        drops.append((refused[0], time_ns[refused[1]], camera[refused[1]]))


def with_dropped(track: Track, *counts: Mapping[str, int]) -> Track:
    """``track`` carrying the summed counts of the invalid points dropped from it."""
    total: dict[str, int] = {}
    for c in counts:
        for k, v in c.items():
            total[k] = total.get(k, 0) + v
    return Track(track.method, track.time_ns, track.position_world, track.camera,
                 track.quality, dropped=total)


def _empty(method: str) -> Track:
    return Track(method, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32), {})
