"""Pseudo stereo, type A: a 3D point at every detection event (the paper's section 2.2).

For the newest event ``t`` (camera ``c``, time ``t_t``):

1. The two previous events ``t-1`` and ``t-2`` (any cameras, strictly earlier instants) are
   triangulated although no other camera saw the ball at their instants:

   - *step 1, eq. (1)*: a partner camera's 2D track is interpolated linearly to the event's
     capture time, between the partner's two detections that bracket it,
     ``u = (δ_a u_next + δ_b u_prev) / (δ_a + δ_b)`` with ``δ_a = t_j - t_prev`` and
     ``δ_b = t_next - t_j`` (the paper's ``δ12`` and ``δ23 + δ31`` for three cameras), in
     undistorted pixels (the paper models no lens distortion; in ideal pixels the image of a
     motion parallel to the image plane at constant speed is linear, so eq. (1) is exact);
   - *step 2*: the interpolated point is snapped to the nearest point of the epipolar line of
     the observed point in the partner's image;
   - *step 3*: the 3D point is the crossing point of the two viewing rays.

   The partner's bracketing detections must not come after the newest detection in
   (time, camera) order (causality, exact even for equal timestamps). Among the
   other cameras, the partner is the one with the shortest bracket; on a tie, the one whose
   bracket ends latest, which for the paper's three cameras is camera 1 (the camera of the
   newest frame), as in the paper.
2. *Eq. (2)*, linear prediction: ``P̂_t = P_{t-1} + (P_{t-1} - P_{t-2}) δ_pred / δ_prev`` with
   ``δ_pred = t_t - t_{t-1}`` and ``δ_prev = t_{t-1} - t_{t-2}``, the actual capture intervals.
   (The paper prints ``δ31 / δ12``, but the interval between ``t-2`` and ``t-1`` is ``δ23``;
   the printed form agrees with ours only for type A's evenly spaced shutters. We use the
   actual intervals so that unequal offsets and jitter are handled.) ``P_{t-2}`` is chosen so
   that ``δ_pred <= MAX_EXTRAPOLATION * δ_prev``: two nearly simultaneous past instants would
   otherwise turn eq. (2) into an extrapolation that multiplies their errors many times.
3. *Eqs. (3)-(4)*: the output ``P'_t`` is the point of the newest viewing ray
   ``l = k r + T`` nearest to ``P̂_t``.

Everything is vectorized over events; the only Python loops run over cameras and over
how many instants back a past point is looked for (at most ``2 * n_cameras``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FusionError
from ..geometry import (
    _dot,
    closest_points_on_lines,
    closest_points_on_rays,
    crossing_of_rays,
    epipolar_lines_cols,
    ray_depths,
)
from ..records import NS, Observations, Track
from . import _prepare
from ._prepare import (
    BEHIND,
    MIN_RAY_ANGLE_DEG,
    PARALLEL,
    Prepared,
    camera_mask,
    covariance,
    covariance_columns,
    direction_jacobian_along,
    dot_t,
    finite_difference_jacobians,
    finite_rows,
    invalid_points,
    merged_slots,
    reprojection_px,
    times_pixel_jacobian,
)
from .innovation import (
    NoiseEstimate,
    failed_counts,
    failed_predictions,
    innovation_factors,
    kinked_points,
)
from .stereo import count_invalid, with_dropped

#: Brackets whose lengths differ by less than this are ties (shutter offsets are rounded to ns).
_SPAN_TIE_NS = 1_000_000
#: Eq. (2) extrapolates at most this many times the interval between its two past points.
MAX_EXTRAPOLATION = 2.0


@dataclass(frozen=True, eq=False)
class PseudoStereoPoints:
    """Steps 1-3 of section 2.2 for a batch of past observations (k rows).

    Attributes
    ----------
    row : (k,) int64, the observed detection (global row)
    valid : (k,) bool, a partner bracket was found
    partner : (k,) int64, partner camera index (-1 if none)
    prev_row, next_row : (k,) int64, the partner's bracketing detections (rows)
    uv_interpolated : (k, 2) float64, eq. (1), undistorted pixels in the partner's image
    uv_snapped : (k, 2) float64, step 2, on the epipolar line, undistorted pixels
    snap_px : (k,) float64, distance moved by the snap, pixels
    points_world : (k, 3) float64, step 3, metres
    miss_m : (k,) float64, distance between the two crossed rays (≈ 0 after the snap), metres
    angle_rad : (k,) float64, angle between the two crossed rays, radians
    weight : (k,) float64, eq. (1)'s weight of the bracket's later detection
    miss_unsnapped_m : (k,) float64, distance between the observed ray and the ray of the
        interpolated point BEFORE the snap: the disagreement the snap hides, metres
    residual_obs_px, residual_partner_px : (k,) float64, reprojection errors, in the recorded
        images, of the crossing of those unsnapped rays: against the observed detection and
        against the interpolated point, pixels
    dir_obs, dir_partner : (k, 3) float64, unit directions of the observed and the snapped
        point's rays
    flags : (k,) int64, why the point is geometrically invalid (0: valid; bits of
        :mod:`pslog.fusion._prepare`: behind a camera or a ray parameter ``s, k <= 0``,
        outside a view, rays within :data:`MIN_RAY_ANGLE_DEG` of parallel); an invalid
        point is not ``valid``
    """

    row: np.ndarray
    valid: np.ndarray
    partner: np.ndarray
    prev_row: np.ndarray
    next_row: np.ndarray
    uv_interpolated: np.ndarray
    uv_snapped: np.ndarray
    snap_px: np.ndarray
    points_world: np.ndarray
    miss_m: np.ndarray
    angle_rad: np.ndarray
    weight: np.ndarray
    miss_unsnapped_m: np.ndarray
    residual_obs_px: np.ndarray
    residual_partner_px: np.ndarray
    dir_obs: np.ndarray
    dir_partner: np.ndarray
    flags: np.ndarray


def _pseudo_from_pixels(prep: Prepared, cam_obs: np.ndarray, partner: np.ndarray,
                        uv_obs: np.ndarray, uv_prev: np.ndarray, uv_next: np.ndarray,
                        weight: np.ndarray, dir_obs: np.ndarray | None = None):
    """Steps 1-3 from undistorted pixels (k, 2): the observed one and the partner's bracket.

    Returns uv_interpolated, uv_snapped, snap_px, dir_obs, dir_partner, points, miss, s, k
    (``s``, ``k``: the ray parameters of the crossing, > 0 in front of both cameras).
    ``dir_obs`` (k, 3): the observed pixels' rays if already known (the same bits)."""
    # eq. (1): linear interpolation of the partner's 2D track to the observation's time
    uv_interp = (1.0 - weight)[:, None] * uv_prev + weight[:, None] * uv_next
    # step 2: nearest point on the epipolar line of the observed point, in the partner image
    lines = epipolar_lines_cols(prep.fundamental_t(cam_obs, partner), uv_obs)
    uv_snapped, snap_px = closest_points_on_lines(lines, uv_interp)
    # step 3: crossing point of the observed ray and the snapped point's ray
    if dir_obs is None:
        dir_obs = prep.rays_from_undistorted(cam_obs, uv_obs)
    dir_partner = prep.rays_from_undistorted(partner, uv_snapped)
    points, miss, s, k = crossing_of_rays(prep.centers[cam_obs], dir_obs,
                                          prep.centers[partner], dir_partner)
    return uv_interp, uv_snapped, snap_px, dir_obs, dir_partner, points, miss, s, k


def pseudo_stereo_points(
    prep: Prepared, rows: np.ndarray, not_after_row: np.ndarray, max_gap_ns: int
) -> PseudoStereoPoints:
    """3D points of past observations ``rows`` (k,) from partner brackets that end at or before
    global row ``not_after_row`` (k,) — steps 1-3 of the paper's section 2.2."""
    obs, n_cams = prep.obs, len(prep.centers)
    time_ns = obs.time_ns
    t_row = np.take(time_ns, rows)
    cam_row = np.take(obs.camera, rows)
    n_rows = len(rows)
    best_span = np.full(n_rows, 2**62)  # "none yet", far from int64 overflow in the tie test
    best_end = np.full(n_rows, np.iinfo(np.int64).min)
    partner = np.full(n_rows, -1, dtype=np.int64)
    prev_row = np.zeros(n_rows, dtype=np.int64)
    next_row = np.zeros(n_rows, dtype=np.int64)
    for d in range(n_cams):  # loop over cameras, vectorized over rows
        prev, nxt = prep.row_brackets(d)
        prev, nxt = np.take(prev, rows), np.take(nxt, rows)
        ok = (prev >= 0) & (nxt >= 0) & (cam_row != d)
        end = np.take(time_ns, np.maximum(nxt, 0))
        span = end - np.take(time_ns, np.maximum(prev, 0))
        ok &= (nxt <= not_after_row) & (span <= max_gap_ns)
        better = ok & ((span < best_span - _SPAN_TIE_NS)
                       | ((span <= best_span + _SPAN_TIE_NS) & (end > best_end)))
        best_span = np.where(better, span, best_span)
        best_end = np.where(better, end, best_end)
        partner = np.where(better, d, partner)
        prev_row = np.where(better, prev, prev_row)
        next_row = np.where(better, nxt, next_row)
    valid = partner >= 0
    partner_idx = np.maximum(partner, 0)

    # eq. (1)'s weight from integer capture times: the same for any window of the session
    t_prev = np.take(time_ns, prev_row)
    span_ns = np.take(time_ns, next_row) - t_prev
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(span_ns > 0, (t_row - t_prev) / np.where(span_ns > 0, span_ns, 1), 0.0)
    uv_row = np.take(prep.uv_undistorted, rows, axis=0)
    with np.errstate(invalid="ignore"):
        uv_interp, uv_snapped, snap_px, dir_obs, dir_partner, points, miss, s, k = (
            _pseudo_from_pixels(prep, cam_row, partner_idx, uv_row,
                                np.take(prep.uv_undistorted, prev_row, axis=0),
                                np.take(prep.uv_undistorted, next_row, axis=0), w,
                                np.take(prep.observed_rays, rows, axis=0)))
        # both directions are unit vectors; a line has no sense, hence the absolute value
        cos_angle = np.abs(_dot(dir_obs[:, 0], dir_obs[:, 1], dir_obs[:, 2],
                                dir_partner[:, 0], dir_partner[:, 1], dir_partner[:, 2]))
        angle = np.arccos(np.minimum(cos_angle, 1.0))
        # the disagreement before the snap: the interpolated point's ray against the observed
        dir_interp = prep.rays_from_undistorted(partner_idx, uv_interp)
        unsnapped, miss_unsnapped, _, _ = crossing_of_rays(
            prep.centers[cam_row], dir_obs, prep.centers[partner_idx], dir_interp)
    residual_obs = reprojection_px(prep, unsnapped, cam_row, uv_row)
    residual_partner = reprojection_px(prep, unsnapped, partner_idx, uv_interp)
    used = np.empty((n_rows, n_cams), dtype=bool, order="F")  # (contiguous columns)
    for c in range(n_cams):
        np.equal(cam_row, c, out=used[:, c])
        used[:, c] |= partner_idx == c
    finite = finite_rows(points)
    flags = invalid_points(prep, points, used, finite)
    with np.errstate(invalid="ignore"):
        flags[finite & ~((s > 0) & (k > 0))] |= BEHIND
        flags[np.degrees(angle) < MIN_RAY_ANGLE_DEG] |= PARALLEL  # (NaN: no ray, no flag)
    flags[~valid] = 0  # no partner: no point, and nothing to say about its geometry
    valid &= finite & (flags == 0)
    return PseudoStereoPoints(rows, valid, partner, prev_row, next_row, uv_interp, uv_snapped,
                              snap_px, points, miss, angle, w, miss_unsnapped, residual_obs,
                              residual_partner, dir_obs, dir_partner, flags)


@dataclass(frozen=True, eq=False)
class TypeAConstruction:
    """How each type-A point was made (for viewers and diagnostics); k output points.

    Attributes
    ----------
    event_row : (k,) int64, the newest detection (global row of the observations)
    past : tuple (P_{t-1}, P_{t-2}) of :class:`PseudoStereoPoints`, each k rows
    predicted_world : (k, 3) float64, eq. (2) ``P̂_t``, metres
    points_world : (k, 3) float64, eq. (4) ``P'_t``, metres
    """

    event_row: np.ndarray
    past: tuple[PseudoStereoPoints, PseudoStereoPoints]
    predicted_world: np.ndarray
    points_world: np.ndarray


def fuse_type_a(prep: Prepared, max_gap_s: float, noise_px: float | None = 0.5,
                events: np.ndarray | None = None, seen: np.ndarray | None = None,
                noise: NoiseEstimate | None = None) -> tuple[Track, TypeAConstruction]:
    """``typeA``: a point at every detection with two earlier pseudo-stereo points.

    The two earlier points are those of the two latest earlier instants that can be
    triangulated causally — for the paper's evenly offset cameras, always ``t-1`` and ``t-2``.
    When one cannot (a missed detection, or a partner camera with a slower frame rate whose
    next frame is still to come), or when ``t-2`` is too close to ``t-1`` for eq. (2)
    (see ``MAX_EXTRAPOLATION``), the next earlier instant takes its place, up to
    ``2 * n_cameras`` instants back and within ``max_gap_s``. A geometrically invalid past
    point (behind a camera, outside a view, near-parallel rays) counts as not triangulated.
    An output point behind a camera that contributed to it (eq. (4)'s ``k <= 0``: the
    prediction behind the newest camera) or outside its view is dropped and counted in
    ``Track.dropped``; refused past points are counted there too (``past_<reason>``, each
    detection once). ``noise_px``: the detections' pixel noise behind ``std_m``.

    ``events`` (sorted global rows, optional): make only these rows' points (the others'
    are neither made nor counted); each point is the same, bit for bit, as in a run over
    every row (the arithmetic is elementwise), which :class:`TypeAStream` relies on.
    ``seen`` (n,) int64, optional: the past refusals already counted per row, updated in
    place; only refusals not in it are counted (a stream counts each detection once).
    ``noise``: the session's estimate of the detection noise for the tests of innovation.py,
    updated in place (a stream keeps one across its pushes; None: a new one).
    """
    obs = prep.obs
    time_ns = obs.time_ns
    n, max_gap_ns = len(obs), int(max_gap_s * NS)
    depth = 2 * len(prep.centers)
    # triangulate predecessors depth by depth, only for events still lacking two points
    first = np.full(n, -1, dtype=np.int64)  # depth of P_{t-1} (the later past point)
    second = np.full(n, -1, dtype=np.int64)  # depth of P_{t-2}
    t_first = np.zeros(n, dtype=np.int64)  # capture time of P_{t-1}
    computed: list[tuple[int, np.ndarray, PseudoStereoPoints]] = []  # (depth, events, points)
    # candidate: latest row of the k-th distinct instant before each event (-1: none within
    # max_gap_s), followed depth by depth only for the events still lacking two points
    before = np.arange(n)
    candidate = np.full(n, -1, dtype=np.int64)
    targets = before.copy() if events is None else np.asarray(events, dtype=np.int64)
    # depth 1's points made ahead with depth 0's: (events, points, offset)
    ahead: tuple[np.ndarray, PseudoStereoPoints, int] | None = None
    for k in range(depth):
        # (the other rows keep candidate -1, so only targets are ever needed)
        pending = targets[second[targets] < 0] if k else targets.copy()
        if len(pending) == 0:
            break
        b = np.take(prep.previous_instant, np.maximum(before[pending], 0))
        b = np.where(candidate[pending] < 0, -1, b) if k else b
        reachable = (b >= 0) & (time_ns[pending] - time_ns[np.maximum(b, 0)] <= max_gap_ns)
        before[pending] = b
        candidate[pending] = np.where(reachable, b, -1)
        # as P_{t-2}, a candidate must leave eq. (2) a bounded extrapolation
        # (only pending rows can be needed: the others have two points, or candidate -1)
        c_pending = candidate[pending]
        t_first_pending = t_first[pending]
        spaced = (first[pending] < 0) | (time_ns[pending] - t_first_pending <= MAX_EXTRAPOLATION * (
            t_first_pending - time_ns[np.maximum(c_pending, 0)]))
        need = pending[(c_pending >= 0) & spaced]
        if k == 0 and events is not None:
            # a few events (a stream): depth 1's candidates too, in the same call (each row's
            # point is its own, elementwise), for the usual P_{t-2} without a second call
            b1 = np.take(prep.previous_instant, np.maximum(b, 0))
            b1 = np.where(candidate[pending] < 0, -1, b1)
            ok1 = (b1 >= 0) & (time_ns[pending] - time_ns[np.maximum(b1, 0)] <= max_gap_ns)
            ahead_rows, ahead_candidates = pending[ok1], b1[ok1]
            both = pseudo_stereo_points(prep, np.concatenate([candidate[need],
                                                              ahead_candidates]),
                                        np.concatenate([need, ahead_rows]), max_gap_ns)
            points_k = _take(both, slice(0, len(need)))
            ahead = (ahead_rows, both, len(need))
        elif k == 1 and ahead is not None:
            points_k = _take(ahead[1], ahead[2] + np.searchsorted(ahead[0], need))
        else:
            points_k = pseudo_stereo_points(prep, candidate[need], need, max_gap_ns)
        computed.append((k, need, points_k))
        good = need[points_k.valid]
        is_first = first[good] < 0
        first[good[is_first]] = k
        t_first[good[is_first]] = time_ns[candidate[good[is_first]]]
        second[good[~is_first]] = k

    events = np.flatnonzero(second >= 0)
    if not computed:  # fewer than three instants: no point yet
        computed.append((0, events, pseudo_stereo_points(prep, events, events, max_gap_ns)))
    p1 = _gather(computed, events, first[events])
    p2 = _gather(computed, events, second[events])
    # past points refused as invalid (each detection once): the points they would have made
    # are missing, or made from earlier instants
    refused = np.zeros(n, dtype=np.int64)
    for _, _, points_k in computed:
        np.bitwise_or.at(refused, points_k.row, points_k.flags)
    del computed, points_k, ahead  # (only p1 and p2 from here on: their memory for what follows)
    j1, j2 = p1.row, p2.row

    # eq. (2): linear prediction with the actual capture intervals (integer nanoseconds:
    # the same ratio whatever the window of the session)
    # the detections behind each point: newest, P_{t-1}'s and P_{t-2}'s with their brackets
    columns = [events, j1, p1.prev_row, p1.next_row, j2, p2.prev_row, p2.next_row]
    times = [np.take(time_ns, column) for column in columns]  # (each gathered once)
    cams = [np.take(obs.camera, column) for column in columns]
    t_event, t1, t2 = times[0], times[1], times[4]
    origin = np.take(prep.ray_origin, events, axis=0)
    direction = np.take(prep.ray_dir, events, axis=0)
    ratio = (t_event - t1) / (t1 - t2)
    predicted = p1.points_world + ratio[:, None] * (p1.points_world - p2.points_world)
    # eqs. (3)-(4): nearest point on the newest viewing ray
    points = closest_points_on_rays(origin, direction, predicted)

    slots = np.stack(columns, 1)
    k = len(events)
    used = np.empty((k, len(prep.centers)), dtype=bool, order="F")  # (contiguous columns)
    for c in range(len(prep.centers)):
        np.equal(cams[0], c, out=used[:, c])
        for cam in cams[1:]:
            used[:, c] |= cam == c
    flags = invalid_points(prep, points, used)
    with np.errstate(invalid="ignore"):
        foot_depth = ray_depths(predicted, origin, direction)
    flags[~(foot_depth > 0)] |= BEHIND  # eq. (4)'s k: the foot behind the newest camera
    residual = [
        p1.residual_obs_px, p1.residual_partner_px, p2.residual_obs_px, p2.residual_partner_px,
        # the newest detection against the prediction, before eq. (4) moves it onto its ray
        reprojection_px(prep, predicted, cams[0], np.take(prep.uv_undistorted, events, axis=0))]
    # slots holding a detection no earlier slot holds
    if k == 1:  # (a stream's one point: in Python, the same count)
        n_distinct = np.array([len({int(c[0]) for c in columns})], dtype=np.int64)
    else:
        n_distinct = np.ones(k, dtype=np.int64)
        for s in range(1, len(columns)):
            repeated = columns[0] == columns[s]
            for t in range(1, s):
                repeated |= columns[t] == columns[s]
            n_distinct += ~repeated
    t_earliest = np.minimum.reduce(times)
    span1 = (times[3] - times[2]) / NS
    span2 = (times[6] - times[5]) / NS

    def evaluate(uv):
        """P'_t from the undistorted pixels of the seven slots (for the covariance)."""
        point1 = _pseudo_from_pixels(prep, obs.camera[j1], p1.partner, uv[1], uv[2], uv[3],
                                     p1.weight)[5]
        point2 = _pseudo_from_pixels(prep, obs.camera[j2], p2.partner, uv[4], uv[5], uv[6],
                                     p2.weight)[5]
        newest = prep.rays_from_undistorted(obs.camera[events], uv[0])
        return closest_points_on_rays(prep.ray_origin[events], newest,
                                      point1 + ratio[:, None] * (point1 - point2))

    with np.errstate(invalid="ignore"):
        if noise_px is None:
            cov = None
        elif _prepare.FINITE_DIFFERENCES:
            jacobians = finite_difference_jacobians(
                evaluate, [prep.uv_undistorted[slots[:, s]] for s in range(7)], slots)
            cov = covariance(slots, jacobians,
                             [prep.pixel_jacobians_t(slots[:, s]) for s in range(7)], noise_px)
        else:
            cov = _type_a_covariance(prep, events, predicted, ratio, p1, p2, cams[1], cams[4],
                                     slots, noise_px, origin, direction)
        quality = {
            "snap_px": np.maximum(p1.snap_px, p2.snap_px),
            # measured before the snap: after it the rays cross by construction
            "ray_miss_m": np.maximum(p1.miss_unsnapped_m, p2.miss_unsnapped_m),
            "ray_shift_m": _row_norms(points - predicted),
            "ray_angle_deg": np.degrees(np.minimum(p1.angle_rad, p2.angle_rad)),
            # (folds over the five columns in the order of np.max and np.mean over rows)
            "residual_max_px": np.maximum.reduce(residual),
            "residual_mean_px": _sum_in_order(residual) / len(residual),
            "camera_mask": camera_mask(used),
            "n_detections": n_distinct.astype(np.float64),
            "gap_s": np.maximum(np.maximum(span1, span2), (t_event - t2) / NS),
            "span_s": (t_event - t_earliest) / NS,
            **(cov if cov is not None else {}),
        }
    made = finite_rows(points)
    # the tests' detection noise: at least what the earlier points' innovations imply
    with np.errstate(invalid="ignore"):
        normalised = np.where(made & (flags == 0), residual[4], np.nan) / innovation_factors(
            events, j1, j2, time_ns)
    sigma = (NoiseEstimate() if noise is None else noise).sigmas(normalised, noise_px)
    # the newest detection contradicts eq. (2)'s prediction: the motion changed (innovation.py)
    failed = made & (flags == 0) & failed_predictions(prep, events, j1, j2, predicted,
                                                      residual[4], sigma)
    # a camera saw the motion change inside eq. (1)'s or eq. (2)'s interval (innovation.py)
    kinked = made & (flags == 0) & ~failed & kinked_points(prep, events, (p1, p2, predicted),
                                                           sigma, max_gap_ns)
    keep = made & (flags == 0) & ~failed & ~kinked
    track = Track("typeA", t_event, points, cams[0], quality)
    if not np.all(keep):  # (every point kept: the Track as it is)
        track = track.select(keep)
    if seen is not None:  # count only the reasons not counted before (each detection once)
        refused, seen[:] = refused & ~seen, seen | refused
    past = {f"past_{k}": v for k, v in count_invalid(refused).items()}
    track = with_dropped(track, count_invalid(flags[made]), past, failed_counts(failed, kinked))
    construction = TypeAConstruction(
        events[keep], (_select(p1, keep), _select(p2, keep)), predicted[keep], points[keep])
    return track, construction


def _row_norms(v: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(v, axis=1)`` of (k, 3) rows, on columns (the same bits)."""
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    out = x * x
    out += y * y
    out += z * z
    return np.sqrt(out, out=out)


def _sum_in_order(columns: list[np.ndarray]) -> np.ndarray:
    """Sum of (k,) columns from the first on: numpy's order over a short row (the same bits
    as ``np.sum(np.stack(columns, 1), axis=1)`` for fewer than 8 columns)."""
    out = columns[0] + columns[1]
    for c in columns[2:]:
        out += c
    return out


def _type_a_covariance(prep: Prepared, events: np.ndarray, predicted: np.ndarray,
                       ratio: np.ndarray, p1: PseudoStereoPoints, p2: PseudoStereoPoints,
                       cam1: np.ndarray, cam2: np.ndarray, slots: np.ndarray, noise_px: float,
                       origin: np.ndarray, direction: np.ndarray) -> dict[str, np.ndarray]:
    """:func:`covariance` of type A's points (its quality columns), with the analytic
    Jacobians of eqs. (1)-(4), component-major.

    Eq. (4), ``P' = T + r rᵀ (P̂ - T)`` for a unit r: ``d P'/d P̂ = r rᵀ``, so every past
    slot's Jacobian is ``r gᵀ`` with ``g = (scale rᵀ J)`` (2, k), ``scale`` eq. (2)'s
    ``1 + ratio`` or ``-ratio``; its share of the covariance is ``r rᵀ |g L|²``. A turn
    ``δr`` of the newest ray moves P' by ``((rᵀq) I + r qᵀ) δr`` with ``q = P̂ - T``."""
    r = direction.T.copy()  # (3, k); origin, direction: the events' rays (k, 3)
    q = (predicted - origin).T
    G = np.take(prep.observed_direction_jacobians, events, axis=2)
    newest = (r[0] * q[0] + r[1] * q[1] + r[2] * q[2]) * G
    newest += r[:, None] * dot_t(q, G)
    del G
    # eq. (2): P̂ = (1 + ratio) P_{t-1} - ratio P_{t-2}
    k = len(events)
    if k <= 8:  # a few points (a stream's): both past points' Jacobians in one call
        both = _pseudo_jacobians(prep, _stacked(p1, p2), np.concatenate([cam1, cam2]),
                                 np.concatenate([r, r], axis=1))
        J1, J2 = [J[..., :k] for J in both], [J[..., k:] for J in both]
    else:
        J1, J2 = _pseudo_jacobians(prep, p1, cam1, r), _pseudo_jacobians(prep, p2, cam2, r)
    # (scaled in place: J1 and J2 are this call's own, and a (2, k) copy each is memory)
    scale1, scale2 = 1 + ratio, -ratio
    for J in J1:
        J *= scale1
    for J in J2:
        J *= scale2
    # slot 0 (the newest detection) goes to ``newest``, never into g
    g: list[np.ndarray] = [np.empty(0), *J1, *J2]
    del J1, J2
    merges, taken = _merged_slots(slots)
    for s, t, same in merges:  # (usually for every event: whole columns, no masked copies)
        moved = g[t] if np.all(same) else np.where(same, g[t], 0.0)
        if s == 0:
            newest += r[:, None] * moved
        else:
            g[s] += moved
    along = np.zeros(len(events))  # Σ |g L|² of the past slots
    for s in range(1, slots.shape[1]):
        gl = times_pixel_jacobian(g[s], prep.pixel_jacobians_t(slots[:, s]))
        along += np.where(taken[:, s], 0.0, gl[0] * gl[0] + gl[1] * gl[1])
    cov = np.empty((6, len(events)))
    NL = times_pixel_jacobian(newest, prep.pixel_jacobians_t(slots[:, 0]))
    for e, (_, i, j) in enumerate(_prepare._SYM6):
        cov[e] = NL[i, 0] * NL[j, 0] + NL[i, 1] * NL[j, 1] + r[i] * r[j] * along
    return covariance_columns(cov * noise_px**2)


def _pseudo_jacobians(prep: Prepared, p: PseudoStereoPoints, cam_obs: np.ndarray,
                      r: np.ndarray) -> list[np.ndarray]:
    """``rᵀ d(P) / d(undistorted pixel)`` (2, k) of pseudo-stereo points ``p`` for their
    observed detection and the partner's bracket (prev, next): steps 1-3 differentiated, seen
    along directions ``r`` (3, k) (all eq. (4) keeps of them).

    The point is the crossing of the observed ray and the snapped point's ray, which meet
    (the snap puts the partner's point on the epipolar line): with ``P = T_j + s_j d_j`` on
    both, a turn ``δd_j`` of ray j moves it by ``s_j A⁻¹ δd_j``, ``A = Σ (I - d dᵀ)`` (the
    least-squares point's derivative, :func:`least_squares_pixel_jacobians`, with ``w = -s d``).
    The snapped point moves with the interpolated one by ``I - n nᵀ`` (along the epipolar
    line of normal ``n``) and with the observed pixel as it moves the line; eq. (1) weighs the
    bracket by ``1 - w`` and ``w``."""
    uv_obs = prep.uv_undistorted[p.row]
    partner = np.maximum(p.partner, 0)
    d1, d2 = p.dir_obs.T.copy(), p.dir_partner.T.copy()
    cos = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]
    scale = 0.5 / (1 - cos**2)
    r_d1 = (r[0] * d1[0] + r[1] * d1[1] + r[2] * d1[2]) * scale
    r_d2 = (r[0] * d2[0] + r[1] * d2[1] + r[2] * d2[2]) * scale

    # size rᵀ A⁻¹ G for A = 2 I - d1 d1ᵀ - d2 d2ᵀ (Woodbury: A⁻¹ = (I + D M⁻¹ Dᵀ) / 2
    # with D = [d1 d2], M = [[1, -c], [-c, 1]], c = d1·d2) is size wᵀ G with the one vector
    # w = A⁻¹ r = r / 2 + (r_d1 + c r_d2) d1 + (c r_d1 + r_d2) d2 (3, k), shared by both rays
    w = 0.5 * r
    w += (r_d1 + cos * r_d2) * d1
    w += (cos * r_d1 + r_d2) * d2

    P = p.points_world.T
    C1 = np.take(prep.centers.T, cam_obs, axis=1)
    C2 = np.take(prep.centers.T, partner, axis=1)
    s1 = (P[0] - C1[0]) * d1[0] + (P[1] - C1[1]) * d1[1] + (P[2] - C1[2]) * d1[2]
    s2 = (P[0] - C2[0]) * d2[0] + (P[1] - C2[1]) * d2[1] + (P[2] - C2[2]) * d2[2]
    J_obs = dot_t(w, np.take(prep.observed_direction_jacobians, p.row, axis=2))
    J_obs *= s1
    J_snapped = direction_jacobian_along(prep, partner, p.uv_snapped, w)
    J_snapped *= s2
    del C1, C2, d1, d2, w, s1, s2  # (k-long temporaries: the peak memory of a long session)
    # the snap u_s = u_i - s n onto the line l = F (u_o, v_o, 1) = (a, l3), n = a / |a|,
    # s = (a·u_i + l3) / |a|; a move of u_o changes l by F[:, :2] δ, which moves u_s by
    # -n ((u_sᵀ da + dl3) / |a|) - s (I - n nᵀ) da / |a|
    F = prep.fundamental_t(cam_obs, partner)  # (9, k), F[3 i + j]
    u, v = uv_obs[:, 0], uv_obs[:, 1]
    line = F[0::3] * u + F[1::3] * v + F[2::3]  # (3, k)
    size = np.sqrt(line[0] ** 2 + line[1] ** 2)
    normal = line[:2] / size
    ui = p.uv_interpolated
    signed = (line[0] * ui[:, 0] + line[1] * ui[:, 1] + line[2]) / size
    da = F.reshape(3, 3, -1)[:2, :2] / size  # (2, 2, k): d a / d u_o, over |a|
    dl3 = F[6:8] / size
    del F, line
    us = p.uv_snapped
    shift = us[:, 0] * da[0] + us[:, 1] * da[1] + dl3
    n_da = normal[0] * da[0] + normal[1] * da[1]  # nᵀ da
    moved_line = -normal[:, None] * shift - signed * (da - normal[:, None] * n_da)
    J_obs += J_snapped[0] * moved_line[0] + J_snapped[1] * moved_line[1]
    J_n = J_snapped[0] * normal[0] + J_snapped[1] * normal[1]
    J_interp = J_snapped - J_n * normal  # J (I - n nᵀ)
    return [J_obs, (1 - p.weight) * J_interp, p.weight * J_interp]


def _merged_slots(rows: np.ndarray) -> tuple[list[tuple[int, int, np.ndarray]], np.ndarray]:
    """:func:`~pslog.fusion._prepare.merged_slots`; for one point (a stream's), in Python
    (the same merges and mask, without a hundred calls on arrays of one element)."""
    if rows.shape[0] != 1:
        return merged_slots(rows)
    row = rows[0].tolist()
    taken = [False] * len(row)
    merges = []
    for s in range(len(row)):
        for t in range(s + 1, len(row)):
            if row[t] == row[s] and row[s] >= 0 and not taken[t] and not taken[s]:
                merges.append((s, t, np.ones(1, dtype=bool)))
                taken[t] = True
    return merges, np.array([taken])


def _gather(computed: list[tuple[int, np.ndarray, PseudoStereoPoints]], events: np.ndarray,
            depth: np.ndarray) -> PseudoStereoPoints:
    """Rows of the per-depth results: for each event, the entry computed at its ``depth``
    (every event has one: ``depth >= 0``, and its row is in that depth's sorted rows)."""
    fields = PseudoStereoPoints.__dataclass_fields__
    template = computed[0][2]
    mine = [depth == k for k, _, _ in computed]
    counts = [int(np.count_nonzero(m)) for m in mine]
    if not computed or sum(counts) == 0:
        return PseudoStereoPoints(**{f: np.zeros((len(events), *getattr(template, f).shape[1:]),
                                                 dtype=getattr(template, f).dtype)
                                     for f in fields})
    # the depth of most events first, as a take of all of them (the others' rows of it are
    # placeholders, each replaced below by its own depth's entry)
    base = int(np.argmax(counts))
    _, rows_b, points_b = computed[base]
    if counts[base] == len(events) and len(rows_b) == len(events):  # (the same rows)
        return points_b
    where = np.minimum(np.searchsorted(rows_b, events), len(rows_b) - 1)
    out = {f: np.take(getattr(points_b, f), where, axis=0) for f in fields}
    for i, (_, rows_k, points_k) in enumerate(computed):
        if i == base or counts[i] == 0:
            continue
        at = np.flatnonzero(mine[i])
        where = np.searchsorted(rows_k, events[at])  # rows_k is sorted
        for f in fields:
            out[f][at] = getattr(points_k, f)[where]
    return PseudoStereoPoints(**out)


def _stacked(a: PseudoStereoPoints, b: PseudoStereoPoints) -> PseudoStereoPoints:
    """The rows of ``a`` then those of ``b``."""
    return PseudoStereoPoints(*(np.concatenate([getattr(a, f), getattr(b, f)])
                                for f in a.__dataclass_fields__))


def _take(p: PseudoStereoPoints, index) -> PseudoStereoPoints:
    return PseudoStereoPoints(*(getattr(p, f)[index] for f in p.__dataclass_fields__))


def _select(p: PseudoStereoPoints, keep: np.ndarray) -> PseudoStereoPoints:
    if np.all(keep):  # (p is this call's own gather: nothing else holds its arrays)
        return p
    return PseudoStereoPoints(*(getattr(p, f)[keep] for f in p.__dataclass_fields__))


class TypeAStream:
    """``typeA``'s incremental form (the registry's ``streamer``): each detection pushed, in
    (time, camera) order, makes its point from the few recent rows it can reach.

    A type-A point reaches back at most two bridged gaps (a past instant within
    ``max_gap_s``, its partner's bracket within ``max_gap_s`` more), so only those rows are
    kept, each undistorted once when it arrives (as :func:`~pslog.fusion._prepare.prepare`
    does a session, per camera, row by row the same bits), and :func:`fuse_type_a` makes the
    new rows' points only. Its arithmetic is elementwise, so every point, quality column and
    covariance equals the batch run's bit for bit; ``Track.dropped`` counts each dropped point
    and each refused past detection once, as the batch run does.

    Parameters
    ----------
    rig : Rig
    options : FusionOptions
    """

    def __init__(self, rig, options) -> None:
        from ._prepare import default_max_gap_s, prepare

        self.rig = rig
        self._noise_px = options.noise_px
        self._max_gap_s = options.max_gap_s or default_max_gap_s(rig)
        # the history a new point can reach: two bridged gaps (and the stream's margin)
        self._history_ns = int((2 * self._max_gap_s + 2 * options.tolerance_s) * NS) + 1
        self._checked = False
        empty = Observations(np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros((0, 2)),
                             np.zeros(0, np.int64))
        # the per-camera parts of prepare, made once; their column caches warmed and shared
        self._template = template = prepare(empty, rig)
        template._cols("K_inv"), template._cols("R")
        self._shared = {"_columns": template.__dict__["_columns"], "_f_cols": template._f_cols,
                        "_rt_k_inv_cols": template._rt_k_inv_cols}
        self._time = np.zeros(0, np.int64)
        self._camera = np.zeros(0, np.int32)
        self._uv = np.zeros((0, 2))
        self._frame = np.zeros(0, np.int64)
        self._uv_und = np.zeros((0, 2))
        self._ray_dir = np.zeros((0, 3))
        self._jac = np.zeros((0, 2, 2))
        self._seen = np.zeros(0, np.int64)  # past refusals already counted, per row
        self._noise = NoiseEstimate()  # the detection noise the innovations imply, so far
        self._empty = fuse_type_a(template, self._max_gap_s, self._noise_px,
                                  noise=NoiseEstimate())[0]

    def push(self, time_ns, camera, uv, frame_index) -> Track:
        """Rows (n,) after every row pushed before; returns their points (possibly none)."""
        from ._prepare import _FAR_IMAGES, _undistortion_jacobian

        n_new = len(time_ns)
        if n_new == 0:
            return self._empty
        rig = self.rig
        if not self._checked:  # (prepare's check, at the first detection as before)
            from ..rig import check_baselines

            check_baselines(rig)
            self._checked = True
        camera = np.asarray(camera, dtype=np.int32)
        if camera.min() < 0 or camera.max() >= len(rig):
            raise FusionError(f"observation camera index {int(camera.max())} is not in the "
                              f"{len(rig)}-camera rig")
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        # undistortion, rays and Jacobians of the new rows: prepare's per-camera pass
        uv_und = np.empty_like(uv)
        ray_dir = np.empty((n_new, 3))
        jac = np.empty((n_new, 2, 2))
        for i in np.unique(camera).tolist():
            cam = rig.cameras[i]
            rows = np.flatnonzero(camera == i)
            uv_und[rows] = cam.undistort(uv[rows])
            ray_dir[rows] = cam.rays(uv[rows])[1]
            far = rows[~np.all(np.abs(uv[rows]) <= _FAR_IMAGES * max(cam.width, cam.height),
                               axis=1)]
            uv_und[far] = np.nan
            ray_dir[far] = np.nan
            jac[rows] = _undistortion_jacobian(cam, uv_und[rows])
        # the window: the rows a new point can reach, then the new ones
        time_ns = np.asarray(time_ns, dtype=np.int64)
        # (the history of the earliest new row: each new row's point is made)
        cut = int(np.searchsorted(self._time, time_ns[0] - self._history_ns, side="left"))
        self._time = np.concatenate([self._time[cut:], time_ns])
        self._camera = np.concatenate([self._camera[cut:], camera])
        self._uv = np.concatenate([self._uv[cut:], uv])
        self._frame = np.concatenate([self._frame[cut:], np.asarray(frame_index, np.int64)])
        self._uv_und = np.concatenate([self._uv_und[cut:], uv_und])
        self._ray_dir = np.concatenate([self._ray_dir[cut:], ray_dir])
        self._jac = np.concatenate([self._jac[cut:], jac])
        self._seen = np.concatenate([self._seen[cut:], np.zeros(n_new, np.int64)])
        obs = Observations(self._time, self._camera, self._uv, self._frame)
        t = self._template
        n = len(obs)
        prep = Prepared(
            obs=obs, t=(self._time - self._time[0]) / NS, uv_undistorted=self._uv_und,
            ray_origin=t.centers[self._camera], ray_dir=self._ray_dir, centers=t.centers,
            K_inv=t.K_inv, R=t.R, F=t.F,
            per_camera=[np.flatnonzero(self._camera == i) for i in range(len(rig))],
            cameras=t.cameras, uv_jacobian=self._jac, view_box=t.view_box)
        prep.__dict__.update(self._shared)
        return fuse_type_a(prep, self._max_gap_s, self._noise_px,
                           events=np.arange(n - n_new, n), seen=self._seen,
                           noise=self._noise)[0]
