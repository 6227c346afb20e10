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

from ..geometry import (
    closest_points_on_lines,
    closest_points_on_rays,
    epipolar_lines,
    triangulate_two_rays,
)
from ..records import NS, Track
from ._prepare import Prepared, bracket

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


def pseudo_stereo_points(
    prep: Prepared, rows: np.ndarray, not_after_row: np.ndarray, max_gap_ns: int
) -> PseudoStereoPoints:
    """3D points of past observations ``rows`` (k,) from partner brackets that end at or before
    global row ``not_after_row`` (k,) — steps 1-3 of the paper's section 2.2."""
    obs, n_cams = prep.obs, len(prep.centers)
    time_ns = obs.time_ns
    t_row = time_ns[rows]
    cam_row = obs.camera[rows]
    k = len(rows)
    best_span = np.full(k, 2**62)  # "none yet", far from int64 overflow in the tie test
    best_end = np.full(k, np.iinfo(np.int64).min)
    partner = np.full(k, -1, dtype=np.int64)
    prev_row = np.zeros(k, dtype=np.int64)
    next_row = np.zeros(k, dtype=np.int64)
    for d in range(n_cams):  # loop over cameras, vectorized over rows
        prev, nxt = bracket(prep, d, t_row)
        ok = (prev >= 0) & (nxt >= 0) & (cam_row != d)
        end = time_ns[np.maximum(nxt, 0)]
        span = end - time_ns[np.maximum(prev, 0)]
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

    # eq. (1): linear interpolation of the partner's 2D track to the observation's time
    t_prev, t_next = prep.t[prev_row], prep.t[next_row]
    span_s = t_next - t_prev
    w = np.where(span_s > 0, (prep.t[rows] - t_prev) / np.where(span_s > 0, span_s, 1.0), 0.0)
    uv_interp = ((1.0 - w)[:, None] * prep.uv_undistorted[prev_row]
                 + w[:, None] * prep.uv_undistorted[next_row])

    # step 2: nearest point on the epipolar line of the observed point, in the partner image
    lines = epipolar_lines(prep.F[cam_row, partner_idx], prep.uv_undistorted[rows])
    uv_snapped, snap_px = closest_points_on_lines(lines, uv_interp)

    # step 3: crossing point of the observed ray and the snapped point's ray
    dir_partner = prep.rays_from_undistorted(partner_idx, uv_snapped)
    points, miss = triangulate_two_rays(prep.ray_origin[rows], prep.ray_dir[rows],
                                        prep.centers[partner_idx], dir_partner)
    valid &= np.all(np.isfinite(points), axis=1)
    # both directions are unit vectors; a line has no sense, hence the absolute value
    cos_angle = np.abs(np.einsum("ij,ij->i", prep.ray_dir[rows], dir_partner))
    angle = np.arccos(np.minimum(cos_angle, 1.0))
    return PseudoStereoPoints(rows, valid, partner, prev_row, next_row, uv_interp, uv_snapped,
                              snap_px, points, miss, angle)


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


def fuse_type_a(prep: Prepared, max_gap_s: float) -> tuple[Track, TypeAConstruction]:
    """``typeA``: a point at every detection with two earlier pseudo-stereo points.

    The two earlier points are those of the two latest earlier instants that can be
    triangulated causally — for the paper's evenly offset cameras, always ``t-1`` and ``t-2``.
    When one cannot (a missed detection, or a partner camera with a slower frame rate whose
    next frame is still to come), or when ``t-2`` is too close to ``t-1`` for eq. (2)
    (see ``MAX_EXTRAPOLATION``), the next earlier instant takes its place, up to
    ``2 * n_cameras`` instants back and within ``max_gap_s``.
    """
    obs = prep.obs
    time_ns = obs.time_ns
    n, max_gap_ns = len(obs), int(max_gap_s * NS)
    depth = 2 * len(prep.centers)
    # predecessors[:, k]: latest row of the k-th distinct instant before each event
    predecessors = np.full((n, depth), -1, dtype=np.int64)
    before = np.arange(n)
    for k in range(depth):
        before = np.searchsorted(time_ns, time_ns[np.maximum(before, 0)], side="left") - 1
        before = np.where(predecessors[:, k - 1] < 0, -1, before) if k else before
        reachable = (before >= 0) & (time_ns - time_ns[np.maximum(before, 0)] <= max_gap_ns)
        predecessors[:, k] = np.where(reachable, before, -1)

    # triangulate predecessors depth by depth, only for events still lacking two points
    first = np.full(n, -1, dtype=np.int64)  # depth of P_{t-1} (the later past point)
    second = np.full(n, -1, dtype=np.int64)  # depth of P_{t-2}
    t_first = np.zeros(n, dtype=np.int64)  # capture time of P_{t-1}
    computed: list[tuple[int, np.ndarray, PseudoStereoPoints]] = []  # (depth, events, points)
    for k in range(depth):
        candidate = predecessors[:, k]
        # as P_{t-2}, a candidate must leave eq. (2) a bounded extrapolation
        spaced = (first < 0) | (time_ns - t_first <= MAX_EXTRAPOLATION * (
            t_first - time_ns[np.maximum(candidate, 0)]))
        need = np.flatnonzero((second < 0) & (candidate >= 0) & spaced)
        if len(need) == 0:
            continue
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
    j1, j2 = p1.row, p2.row

    # eq. (2): linear prediction with the actual capture intervals
    ratio = (prep.t[events] - prep.t[j1]) / (prep.t[j1] - prep.t[j2])
    predicted = p1.points_world + ratio[:, None] * (p1.points_world - p2.points_world)
    # eqs. (3)-(4): nearest point on the newest viewing ray
    points = closest_points_on_rays(prep.ray_origin[events], prep.ray_dir[events], predicted)

    keep = np.all(np.isfinite(points), axis=1)
    quality = {
        "snap_px": np.maximum(p1.snap_px, p2.snap_px),
        "ray_miss_m": np.maximum(p1.miss_m, p2.miss_m),
        "ray_shift_m": np.linalg.norm(points - predicted, axis=1),
        "ray_angle_deg": np.degrees(np.minimum(p1.angle_rad, p2.angle_rad)),
    }
    track = Track("typeA", time_ns[events], points, obs.camera[events], quality).select(keep)
    construction = TypeAConstruction(
        events[keep], (_select(p1, keep), _select(p2, keep)), predicted[keep], points[keep])
    return track, construction


def _gather(computed: list[tuple[int, np.ndarray, PseudoStereoPoints]], events: np.ndarray,
            depth: np.ndarray) -> PseudoStereoPoints:
    """Rows of the per-depth results: for each event, the entry computed at its ``depth``."""
    fields = PseudoStereoPoints.__dataclass_fields__
    template = computed[0][2]
    out = {f: np.zeros((len(events), *getattr(template, f).shape[1:]),
                       dtype=getattr(template, f).dtype) for f in fields}
    for k, rows_k, points_k in computed:
        mine = np.flatnonzero(depth == k)
        where = np.searchsorted(rows_k, events[mine])  # rows_k is sorted
        for f in fields:
            out[f][mine] = getattr(points_k, f)[where]
    return PseudoStereoPoints(**out)


def _select(p: PseudoStereoPoints, keep: np.ndarray) -> PseudoStereoPoints:
    return PseudoStereoPoints(*(getattr(p, f)[keep] for f in p.__dataclass_fields__))
