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

The arithmetic runs point by point in compiled kernels (:mod:`pslog.fusion._pseudo_kernel`,
numba): for each event, the search for its two past points, steps 1-3 for each candidate,
eqs. (2)-(4), the quality columns and the closed-form covariance, in one loop over the
events (a vectorised form spent most of its time in numpy's fixed cost per call: ~200 small
array operations per batch, the whole cost of a stream's single point). The innovation and
kink tests (:mod:`pslog.fusion.innovation`: the tests' noise estimate, the prediction test,
the kink test) and the doubt of the gate's choices decide each point in the same loop, which
writes only the points kept (no (k,) columns of predictions, innovations and past points
between the kernel and the tests: a call's fresh memory, whose page faults a process whose
heap glibc trims pays at every call, ~150 bytes a point less; docs/performance.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, Literal, cast, overload

import numpy as np

from ..errors import FusionError
from ..geometry import (
    closest_points_on_lines,
    closest_points_on_rays,
    crossing_of_rays,
    epipolar_lines_cols,
)
from ..records import NS, Observations, Track
from . import _prepare
from ._prepare import (
    MIN_RAY_ANGLE_DEG,
    Prepared,
    covariance,
    finite_difference_jacobians,
)
from .innovation import (
    DEFAULT_NOISE_PX,
    INNOVATION_SIGMAS,
    NoiseEstimate,
    previous_next_rows,
)
from .stereo import KINK_GATE, NOISE_FLOOR_PX, count_invalid

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
    global row ``not_after_row`` (k,) — steps 1-3 of the paper's section 2.2, point by point
    in the compiled :func:`~pslog.fusion._pseudo_kernel.pseudo_kernel` (eq. (1), the epipolar
    snap, the crossing with its ray parameters ``s, k > 0``, and the quality of each)."""
    from . import _pseudo_kernel

    rows = np.ascontiguousarray(rows, dtype=np.int64)
    not_after = np.ascontiguousarray(np.broadcast_to(not_after_row, rows.shape),
                                     dtype=np.int64)
    k = len(rows)
    prev_b, next_b, _ = _all_brackets(prep)
    cam, ki, rr, _, f9, _ = camera_tables(prep)
    ff = np.empty((1, k, len(_pseudo_kernel.FLOATS)))
    fi = np.empty((1, k, len(_pseudo_kernel.INTS)), dtype=np.int64)
    _pseudo_kernel.pseudo_kernel(
        rows, not_after, int(max_gap_ns), prep.obs.time_ns, prep.obs.camera, prev_b, next_b,
        prep.uv_undistorted, prep.observed_rays, prep.centers, ki, rr, f9, cam,
        _SPAN_TIE_NS, MIN_RAY_ANGLE_DEG, ff, fi)
    return _from_tables(ff[0], fi[0], None)


#: :func:`~pslog.fusion._pseudo_kernel.camera_tables` of the rigs met, keyed by what they are
#: made of (read by the kernels only, never written: shared by every ``Prepared`` of a rig)
_CAMERA_TABLES: dict[tuple, tuple] = {}


def camera_tables(prep: Prepared) -> tuple:
    """:func:`~pslog.fusion._pseudo_kernel.camera_tables` of ``prep``, made once per rig
    geometry (its cameras' K, R, t and lens, ``prep``'s K⁻¹, R, F and view boxes: the
    tables' every input; ~3 % of a 2-minute type-A ``fuse`` made them again at each call),
    and cached on ``prep`` as before."""
    from . import _pseudo_kernel

    cache = prep.__dict__.get("_kernel_tables")
    if cache is not None:
        return cache
    key = _prepare.array_key(prep.K_inv, prep.R, prep.F, prep.view_box,
                             *((c.K, c.R, c.t, c.dist) for c in prep.cameras))
    tables = _prepare.rig_cached(_CAMERA_TABLES, key, lambda: _pseudo_kernel.camera_tables(prep))
    prep.__dict__["_kernel_tables"] = tables
    return tables


def _from_tables(ff: np.ndarray, fi: np.ndarray, at: np.ndarray | None) -> PseudoStereoPoints:
    """The :class:`PseudoStereoPoints` of the kernels' tables of past points, ``ff`` (k, 20)
    and ``fi`` (k, 6) (:data:`~pslog.fusion._pseudo_kernel.FLOATS`, ``INTS``), rows ``at``
    (None: all); each field a view of the table's columns (no copies)."""
    if at is not None:
        ff, fi = ff[at], fi[at]
    return PseudoStereoPoints(
        row=fi[:, 0], valid=fi[:, 5] != 0, partner=fi[:, 1], prev_row=fi[:, 2],
        next_row=fi[:, 3], uv_interpolated=ff[:, 16:18], uv_snapped=ff[:, 18:20],
        snap_px=ff[:, 1], points_world=ff[:, 7:10], miss_m=ff[:, 2], angle_rad=ff[:, 3],
        weight=ff[:, 0], miss_unsnapped_m=ff[:, 4], residual_obs_px=ff[:, 5],
        residual_partner_px=ff[:, 6], dir_obs=ff[:, 10:13], dir_partner=ff[:, 13:16],
        flags=fi[:, 4])


def _all_brackets(prep: Prepared) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`Prepared.row_brackets` of every camera, stacked (prev and next, (m, n) int64),
    and :attr:`Prepared.previous_instant` (n,), by one compiled pass (made once)."""
    from . import _pseudo_kernel

    cache = prep.__dict__.get("_all_brackets")
    if cache is None:
        m, n = len(prep.centers), len(prep.obs)
        cache = (np.empty((m, n), dtype=np.int64), np.empty((m, n), dtype=np.int64),
                 np.empty(n, dtype=np.int64))
        _pseudo_kernel.brackets_kernel(prep.obs.time_ns, prep.obs.camera, *cache)
        prep.__dict__["_all_brackets"] = cache
    return cache


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

    def select(self, keep: np.ndarray) -> TypeAConstruction:
        """The rows ``keep`` ((k,) bool or int indices) of every field."""
        past = tuple(type(p)(**{f: getattr(p, f)[keep] for f in p.__dataclass_fields__})
                     for p in self.past)
        return TypeAConstruction(self.event_row[keep], cast(Any, past),
                                 self.predicted_world[keep], self.points_world[keep])

    def on_rows(self, rows: np.ndarray) -> TypeAConstruction:
        """The construction with every row field (``event_row``, the past points' ``row``,
        ``prev_row``, ``next_row``) mapped through ``rows`` (the rows of the observations a
        subset's row ``i`` is: ``rows[i]``; -1 stays -1)."""
        def mapped(r: np.ndarray) -> np.ndarray:
            return np.where(r >= 0, rows[np.maximum(r, 0)], r) if len(rows) else r

        past = tuple(replace(p, **{f: mapped(getattr(p, f)) for f in ("row", "prev_row",
                                                                       "next_row")})
                     for p in self.past)
        return TypeAConstruction(mapped(self.event_row), cast(Any, past),
                                 self.predicted_world, self.points_world)


@overload
def fuse_type_a(prep: Prepared, max_gap_s: float, noise_px: float | None = ...,
                events: np.ndarray | None = ..., seen: np.ndarray | None = ...,
                noise: NoiseEstimate | None = ...,
                explain: Literal[True] = ...,
                cov_noise_px: float | None = ...) -> tuple[Track, TypeAConstruction]: ...


@overload
def fuse_type_a(prep: Prepared, max_gap_s: float, noise_px: float | None = ...,
                events: np.ndarray | None = ..., seen: np.ndarray | None = ...,
                noise: NoiseEstimate | None = ...,
                *, explain: Literal[False],
                cov_noise_px: float | None = ...) -> tuple[Track, None]: ...


def fuse_type_a(prep: Prepared, max_gap_s: float, noise_px: float | None = 0.5,
                events: np.ndarray | None = None, seen: np.ndarray | None = None,
                noise: NoiseEstimate | None = None,
                explain: bool = True, cov_noise_px: float | None = None
                ) -> tuple[Track, TypeAConstruction | None]:
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
    ``explain``: also return how each point was made (False: None in its place, for callers
    that keep only the Track). ``cov_noise_px``: the noise the covariance is made with, if
    not ``noise_px`` (the tests' least noise); the registry's ``typeA`` makes it at
    :func:`covariance_noise_px` and rescales it to the measured noise (:func:`type_a_noise`).
    """
    return _fuse_type_a(prep, max_gap_s, noise_px, events, seen, noise, explain,
                        cov_noise_px, None)


def _fuse_type_a(prep: Prepared, max_gap_s: float, noise_px: float | None,
                 events: np.ndarray | None, seen: np.ndarray | None,
                 noise: NoiseEstimate | None, explain: bool, cov_noise_px: float | None,
                 table_out: list | None) -> tuple[Track, TypeAConstruction | None]:
    """:func:`fuse_type_a`; ``table_out`` (a list, or None): the quality table the Track's
    quality columns are rows of (``_QUALITY``'s order, writeable) appended to it, for
    :func:`with_measured_noise` to rescale the covariance in place (the registry's
    ``typeA``: a call's fresh memory ~100 bytes a point less)."""
    from . import _pseudo_kernel

    obs = prep.obs
    time_ns = obs.time_ns
    n, max_gap_ns = len(obs), int(max_gap_s * NS)
    targets = (np.arange(n) if events is None
               else np.ascontiguousarray(events, dtype=np.int64))
    k = len(targets)
    # per target, point by point (compiled): the two past points, up to 2 * n_cameras
    # instants back (steps 1-3), then eqs. (2)-(4), the quality columns and the covariance
    prev_b, next_b, previous_instant = _all_brackets(prep)
    # (lens: some camera has distortion; else the pixel Jacobians are the identity)
    cam, ki, rr, rtki, f9, lens = camera_tables(prep)
    # the past points' tables: each target's place, or (no construction kept) one scratch
    # place (the decisions below read them in the kernel's loop)
    tables = explain or (noise_px is not None and _prepare.FINITE_DIFFERENCES)
    places = k if tables else 1
    ff = np.empty((2, places, len(_pseudo_kernel.FLOATS)))
    fi = np.empty((2, places, len(_pseudo_kernel.INTS)), dtype=np.int64)
    # past points refused as invalid (each detection once): the points they would have made
    # are missing, or made from earlier instants
    refused = np.zeros(n, dtype=np.int64)
    has = np.empty(k, dtype=bool)
    # eq. (2)'s prediction (k places for the construction), and the tests' terms and the
    # past points' rows and points in one scratch place: the kernel decides each point in
    # its loop (a call's fresh memory ~150 bytes a point less: fewer page faults)
    predicted = np.empty((k if explain else 1, 3))
    flags, innovation = np.empty(1, dtype=np.int64), np.empty(1)
    factor, model = np.empty(1), np.empty(1)
    past_rows, past_points = np.empty((2, 1, 3), dtype=np.int64), np.empty((2, 1, 3))
    points, quality_table = np.empty((k, 3)), np.empty((len(_QUALITY), k))
    rows_out = np.empty(k, dtype=np.int64)
    with_cov = noise_px is not None and not _prepare.FINITE_DIFFERENCES
    # (the covariance's noise: the stated one unless told)
    var_px = (0.0 if noise_px is None else float(noise_px)) if cov_noise_px is None else float(
        cov_noise_px)
    # the decisions' inputs: the tests' noise estimate (its last innovations, then room for
    # this call's), each row's previous and next row of its camera and its triplet's bend
    # terms (innovation.kinked_points' tables), the rows in doubt
    noise = NoiseEstimate() if noise is None else noise
    tail = noise.tail
    noise_values = np.empty(len(tail) + k)
    noise_values[:len(tail)] = tail
    before, after = previous_next_rows(prep)
    change, root = np.empty(n if k else 0), np.empty(n if k else 0)
    if k:
        _pseudo_kernel.bend_rows(time_ns, prep.uv_undistorted, before, after, NS, change, root)
    doubted = (prep.doubt_px2 > 0 if prep.doubt_px2 is not None
               else np.zeros(0, dtype=bool))
    counts = np.empty(8, dtype=np.int64)
    kept = _pseudo_kernel.type_a_kernel(
        targets, previous_instant, 2 * len(prep.centers), MAX_EXTRAPOLATION, max_gap_ns,
        time_ns, obs.camera, prev_b, next_b, prep.uv_undistorted, prep.observed_rays,
        prep.centers, ki, rr, f9, cam, _SPAN_TIE_NS, MIN_RAY_ANGLE_DEG, prep.ray_dir,
        prep.observed_direction_jacobians, _jacobian_rows(prep) if lens else np.zeros((1, 4)),
        lens, rtki, NS, var_px, with_cov, ff, fi,
        refused, has, predicted, points, flags, innovation, factor, model, quality_table,
        past_rows, past_points, True, DEFAULT_NOISE_PX if noise_px is None else float(noise_px),
        noise_values, noise.count, prep.lens_rows, before, after, change, root, doubted,
        rows_out, counts, np.empty(1))
    noise.advance(noise_values, int(counts[6]))
    # the points kept (packed by the kernel: views, no gather): neither contradicting eq.
    # (2)'s prediction nor kinked (innovation.py) nor resting on a choice the gate put in
    # doubt (docs/methods.md, "A choice in doubt": type A's points)
    events = rows_out[:kept]
    if tables:
        p1, p2 = (_from_tables(ff[s, :kept], fi[s, :kept], None) for s in range(2))
    points, quality_table = points[:kept], quality_table[:, :kept]
    if table_out is not None and with_cov:  # (the finite differences' columns: not rows of it)
        table_out.append(quality_table)
    n_columns = len(_QUALITY) if with_cov else 10
    quality = dict(zip(_QUALITY[:n_columns], quality_table, strict=False))
    if noise_px is not None and _prepare.FINITE_DIFFERENCES:
        j1, j2 = p1.row, p2.row
        # the reference covariance: forward differences through the whole construction
        columns = [events, j1, p1.prev_row, p1.next_row, j2, p2.prev_row, p2.next_row]
        slots = np.stack(columns, 1)
        ratio = (time_ns[events] - time_ns[j1]) / (time_ns[j1] - time_ns[j2])

        def evaluate(uv):
            """P'_t from the undistorted pixels of the seven slots (for the covariance)."""
            point1 = _pseudo_from_pixels(prep, obs.camera[j1], p1.partner, uv[1], uv[2],
                                         uv[3], p1.weight)[5]
            point2 = _pseudo_from_pixels(prep, obs.camera[j2], p2.partner, uv[4], uv[5],
                                         uv[6], p2.weight)[5]
            newest = prep.rays_from_undistorted(obs.camera[events], uv[0])
            return closest_points_on_rays(prep.ray_origin[events], newest,
                                          point1 + ratio[:, None] * (point1 - point2))

        with np.errstate(invalid="ignore"):
            jacobians = finite_difference_jacobians(
                evaluate, [prep.uv_undistorted[slots[:, s]] for s in range(7)], slots)
            quality.update(covariance(slots, jacobians,
                                      [prep.pixel_jacobians_t(slots[:, s]) for s in range(7)],
                                      var_px))
            # (eq. (2)'s model terms: the kernel's, which need no Jacobian)
            quality.update(zip(_MODEL_COLUMNS, quality_table[len(_QUALITY) - 3:], strict=True))
    if seen is not None:  # count only the reasons not counted before (each detection once)
        refused, seen[:] = refused & ~seen, seen | refused
    # Track.dropped (stereo.with_dropped's sum, on the one Track made): the made points'
    # invalid flags, the past points refused (count_invalid's three scans only where some
    # flag is set: a stream's push has none), the tests' refusals, the points in doubt
    dropped = {reason: int(c) for reason, c in zip(
        ("behind_camera", "outside_view", "parallel_rays"), counts[:3].tolist(), strict=True)
        if c}
    if refused.any():
        dropped.update((f"past_{r}", c) for r, c in count_invalid(refused).items())
    for reason, c in zip(("prediction_failed", "kink", DOUBT), counts[3:6].tolist(),
                         strict=True):
        if c:
            dropped[reason] = c
    track = Track("typeA", np.take(time_ns, events), points, np.take(obs.camera, events),
                  quality, dropped)
    if not explain:
        return track, None
    construction = TypeAConstruction(events, (p1, p2), predicted[:kept], points)
    return track, construction


#: Track.dropped's reason for a point resting on a choice the gate put in doubt.
DOUBT = "doubt"


#: the kernel's terms of eq. (2)'s model error (``_pseudo_kernel.type_a_kernel``), which
#: :func:`with_measured_noise` adds to the covariance at the measured noise and drops
_MODEL_COLUMNS = ("_model_gravity_m2", "_model_across_m2", "_model_m2_per_px2")
_QUALITY = ("snap_px", "ray_miss_m", "ray_shift_m", "ray_angle_deg", "residual_max_px",
            "residual_mean_px", "camera_mask", "n_detections", "gap_s", "span_s", "std_m",
            "cov_xx_m2", "cov_yy_m2", "cov_zz_m2", "cov_xy_m2", "cov_xz_m2", "cov_yz_m2",
            *_MODEL_COLUMNS)


def _jacobian_rows(prep: Prepared) -> np.ndarray:
    """:attr:`Prepared.uv_jacobian` as (n, 4) rows, NaN as 0 (made once per Prepared)."""
    cache = prep.__dict__.get("_jacobian_rows")
    if cache is None:
        jac = cast(np.ndarray, prep.uv_jacobian)  # (set by prepare() and every Prepared made)
        cache = prep.__dict__["_jacobian_rows"] = np.ascontiguousarray(
            np.nan_to_num(jac).reshape(-1, 4))
    return cache


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
    cov_noise_px : float or None, the noise the covariance is made with (None: the stated
        ``options.noise_px``; :func:`fuse_type_a`'s)
    """

    def __init__(self, rig, options, cov_noise_px: float | None = None) -> None:
        from . import _pseudo_kernel
        from ._prepare import _FAR_IMAGES as _FAR_IMAGES_
        from ._prepare import default_max_gap_s, prepare

        self.rig = rig
        self._noise_px = options.noise_px
        # (the covariance's noise: the stated one unless told; fuse_type_a's cov_noise_px)
        self._cov_px = options.noise_px if cov_noise_px is None else cov_noise_px
        self._max_gap_s = options.max_gap_s or default_max_gap_s(rig)
        # the history a new point can reach: two bridged gaps (and the stream's margin)
        self._history_ns = int((2 * self._max_gap_s + 2 * options.tolerance_s) * NS) + 1
        self._checked = False
        # the gate's doubt of the rows of the next push (StreamFuser sets it; None: none)
        self.next_doubt: np.ndarray | None = None
        empty = Observations(np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros((0, 2)),
                             np.zeros(0, np.int64))
        # the per-camera parts of prepare, made once; their column caches warmed and shared
        self._template = template = prepare(empty, rig)
        template._cols("K_inv"), template._cols("R")
        # (K⁻¹, R, Rᵀ K⁻¹ rows: the compiled pass of each new row's ray and its Jacobian)
        self._ray_tables = (np.ascontiguousarray(template._cols("K_inv").T),
                            np.ascontiguousarray(template._cols("R").T),
                            np.ascontiguousarray(template._rt_k_inv_cols.T))
        self._shared = {"_columns": template.__dict__["_columns"], "_f_cols": template._f_cols,
                        "_rt_k_inv_cols": template._rt_k_inv_cols,
                        "_kernel_tables": camera_tables(template)}
        # the window's columns: views [lo:hi] of buffers that grow by doubling; a push writes
        # its rows after the window and moves the window to the front when the end is reached
        # (no concatenation of every column at every push). Each row's own-pixel ray, its
        # direction Jacobian and its pixel Jacobian's rows are made once, when it arrives
        # (as Prepared makes them for a session, elementwise)
        self._lo = self._hi = 0
        self._buffers = _StreamColumns(1024)  # (the window moved to the front rarely)
        self._noise = NoiseEstimate()  # the detection noise the innovations imply, so far
        self._empty = fuse_type_a(template, self._max_gap_s, self._noise_px,
                                  noise=NoiseEstimate())[0]
        # one new row (the usual push): the per-camera constants, made once (_push_one)
        self._max_gap_ns = int(self._max_gap_s * NS)
        self._tables = self._shared["_kernel_tables"]
        self._lens_table = template.lens_rows
        self._no_rows = np.empty(0)  # (kink_kernel without bend_rows' tables)
        # (the kernels of _push_one and push_one, held: no import at each push)
        from ._prepare_kernel import lensless_rows

        self._kernels = _pseudo_kernel
        self._lensless_rows = lensless_rows
        # cameras without lens distortion: their new rows in one compiled pass
        # (_prepare_kernel.lensless_rows; a lens's rows go through numpy as prepare does)
        self._lensless = [not np.any(c.dist) for c in rig.cameras]
        self._lensless_tables = (
            np.array([np.asarray(c.K, np.float64).ravel() for c in rig.cameras]),
            np.array([float(_FAR_IMAGES_ * max(c.width, c.height)) for c in rig.cameras]),
            np.ascontiguousarray([np.asarray(c.R, np.float64) for c in rig.cameras]),
            *self._ray_tables)
        # _push_one's scratch (what does not leave in its Track), made once
        self._scratch = (np.empty((2, 1, len(_pseudo_kernel.FLOATS))),
                         np.empty((2, 1, len(_pseudo_kernel.INTS)), dtype=np.int64),
                         np.empty((2, 1, 3), dtype=np.int64), np.empty((2, 1, 3)),
                         np.empty(1, dtype=bool), np.empty((1, 3)),
                         np.empty(1, dtype=np.int64), np.empty(1), np.empty(1), np.empty(1),
                         np.zeros(1, dtype=bool), np.empty(1), np.zeros(4, dtype=bool))
        if not all(self._lensless):
            # a lens's rows take _lens_rows' kernels, which pslog live's warm-up (a lensless
            # rig) does not run: one row of scratch loads (or compiles) them now, not at the
            # first datagram
            c = self._lensless.index(False)
            scratch = _StreamColumns(2)
            scratch.camera[:] = scratch.camera64[:] = c
            scratch.uv[:] = (rig.cameras[c].K[0, 2], rig.cameras[c].K[1, 2])
            self._lens_rows(scratch, 0, 1)

    def push(self, time_ns, camera, uv, frame_index) -> Track:
        """Rows (n,) after every row pushed before; returns their points (possibly none)."""
        from . import _prepare_kernel

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
        uv = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
        time_ns = np.asarray(time_ns, dtype=np.int64)
        # the window: the rows a new point can reach, then the new ones
        buf = self._buffers
        lo, hi = self._lo, self._hi
        # (the history of the earliest new row: each new row's point is made)
        lo += int(np.searchsorted(buf.time[lo:hi], time_ns[0] - self._history_ns, side="left"))
        if hi + n_new > buf.capacity:  # the window to the front (in a larger buffer if need be)
            buf = self._buffers = buf.moved(lo, hi, 2 * (hi - lo + n_new))
            lo, hi = 0, hi - lo
        end = hi + n_new
        buf.time[hi:end] = time_ns
        buf.camera[hi:end] = camera
        buf.uv[hi:end] = uv
        buf.frame[hi:end] = frame_index
        buf.seen[hi:end] = 0
        buf.doubt[hi:end] = 0.0 if self.next_doubt is None else self.next_doubt
        self.next_doubt = None
        # undistortion, rays and Jacobians of the new rows: prepare's per-camera pass, and
        # Prepared.observed_rays' and observed_direction_jacobians' compiled pass
        lensless = self._lensless
        camera64 = buf.camera64[hi:end]
        camera64[:] = camera
        if all(lensless[c] for c in camera.tolist()):  # (one compiled pass: the same bits)
            _prepare_kernel.lensless_rows(
                camera64, uv, *self._lensless_tables, buf.uv_und[hi:end],
                buf.ray_dir[hi:end], buf.jac[hi:end], buf.jac_rows[hi:end],
                buf.rays[hi:end], buf.dir_jac[:, :, hi:end])
        else:
            self._lens_rows(buf, hi, end)
        self._lo, self._hi = lo, end
        if n_new == 1:  # the usual push: its one point without a Prepared (_push_one)
            return self._push_one(lo, end)
        t = self._template
        window = slice(lo, end)
        self._time, self._camera = buf.time[window], buf.camera[window]
        obs = Observations(self._time, self._camera, buf.uv[window], buf.frame[window])
        n = len(obs)
        prep = Prepared(
            obs=obs, t=(self._time - self._time[0]) / NS, uv_undistorted=buf.uv_und[window],
            ray_dir=buf.ray_dir[window], centers=t.centers,
            K_inv=t.K_inv, R=t.R, F=t.F,
            per_camera=[np.flatnonzero(self._camera == i) for i in range(len(rig))],
            cameras=t.cameras, uv_jacobian=buf.jac[window], view_box=t.view_box,
            doubt_px2=buf.doubt[window] if buf.doubt[window].any() else None)
        prep.__dict__.update(self._shared)
        # (the direction Jacobians contiguous, as a batch run's: type_a_kernel's one
        # compiled signature, which pslog.warm compiles; the buffers' slice is strided)
        prep.__dict__.update(observed_rays=buf.rays[window],
                             observed_direction_jacobians=np.ascontiguousarray(
                                 buf.dir_jac[:, :, window]),
                             _jacobian_rows=buf.jac_rows[window])
        return fuse_type_a(prep, self._max_gap_s, self._noise_px,
                           events=np.arange(n - n_new, n), seen=buf.seen[window],
                           noise=self._noise, explain=False, cov_noise_px=self._cov_px)[0]

    def push_one(self, time_ns: int, camera: int, u: float, v: float) -> Track:
        """One detection (Python int, int, float, float; after every row pushed before, the
        camera the rig's: checked by the caller, :class:`~pslog.fusion.stream.StreamFuser`):
        the Track :meth:`push` gives for it, without push's conversions and checks of (n,)
        columns: its row written into the buffers (frame index 0: no point uses it) and
        :meth:`_push_one`. The first push and a lensed camera's rows take :meth:`push`."""
        if not self._checked or not self._lensless[camera]:
            return self.push(np.array([time_ns], np.int64), np.array([camera], np.int32),
                             np.array([[u, v]]), np.zeros(1, np.int64))
        buf = self._buffers
        lo, hi = self._lo, self._hi
        # (push's searchsorted, side left, of the window's sorted times)
        bound, times = time_ns - self._history_ns, buf.time
        while lo < hi and times[lo] < bound:
            lo += 1
        if hi + 1 > buf.capacity:  # the window to the front (in a larger buffer if need be)
            buf = self._buffers = buf.moved(lo, hi, 2 * (hi - lo + 1))
            lo, hi = 0, hi - lo
        end = hi + 1
        buf.time[hi] = time_ns
        buf.camera[hi] = buf.camera64[hi] = camera
        row = buf.uv[hi]
        row[0], row[1] = u, v
        buf.frame[hi] = buf.seen[hi] = 0
        buf.doubt[hi] = 0.0 if self.next_doubt is None else float(self.next_doubt[0])
        self.next_doubt = None
        self._lensless_rows(
            buf.camera64[hi:end], buf.uv[hi:end], *self._lensless_tables, buf.uv_und[hi:end],
            buf.ray_dir[hi:end], buf.jac[hi:end], buf.jac_rows[hi:end], buf.rays[hi:end],
            buf.dir_jac[:, :, hi:end])
        self._lo, self._hi = lo, end
        return self._push_one(lo, end)

    def _lens_rows(self, buf: _StreamColumns, hi: int, end: int) -> None:
        """prepare's per-camera pass (numpy: a lens's iterative undistortion) and
        Prepared.observed_rays' and observed_direction_jacobians' compiled pass, for the
        buffers' rows ``hi:end`` (their camera and recorded pixels already written)."""
        from . import _prepare_kernel
        from ._prepare import _FAR_IMAGES, _rays, _undistortion_jacobian

        camera, uv = buf.camera[hi:end], buf.uv[hi:end]
        n_new = end - hi
        uv_und = np.empty_like(uv)
        ray_dir = np.empty((n_new, 3))
        jac = np.empty((n_new, 2, 2))
        for i in sorted(set(camera.tolist())):
            cam = self.rig.cameras[i]
            rows = np.flatnonzero(camera == i)
            xy = cam.undistort_normalized(uv[rows])  # (the lens inverted once, as prepare)
            uv_und[rows] = cam.pixels_from_normalized(xy)
            ray_dir[rows] = _rays(cam, xy)
            far = rows[~np.all(np.abs(uv[rows]) <= _FAR_IMAGES * max(cam.width, cam.height),
                               axis=1)]
            uv_und[far] = np.nan
            ray_dir[far] = np.nan
            jac[rows] = _undistortion_jacobian(cam, uv_und[rows])
        buf.uv_und[hi:end] = uv_und
        buf.ray_dir[hi:end] = ray_dir
        buf.jac[hi:end] = jac
        _prepare_kernel.observed_rays_and_jacobians(
            buf.camera64[hi:end], np.ascontiguousarray(uv_und), *self._ray_tables,
            buf.rays[hi:end], buf.dir_jac[:, :, hi:end])
        buf.jac_rows[hi:end] = np.nan_to_num(jac).reshape(-1, 4)

    def _push_one(self, lo: int, end: int) -> Track:
        """The point of the window's newest row (rows ``lo:end`` of the buffers), as
        :func:`fuse_type_a` makes it with ``events`` that one row, ``seen`` and ``noise``
        the stream's, ``explain=False``: its compiled kernels on the window's columns, and
        the decisions that follow it (the prediction and kink tests, in the same compiled
        call: :func:`~pslog.fusion._pseudo_kernel.one_point_kernel`; the counts) on one
        point's scalars, each the same IEEE operation as the (1,) columns' (the same bits,
        the same Track: tests/test_stream_type_a.py) without a Prepared, an Observations
        and ~60 numpy calls on arrays of one element."""
        _pseudo_kernel = self._kernels
        buf = self._buffers
        # (the kernels' arguments of a batch run's types: read-only time and camera columns,
        # as Observations holds them, and contiguous direction Jacobians, a copy of the
        # buffers' strided slice: one compiled signature of brackets_kernel and
        # type_a_kernel for batch and stream, which pslog.warm compiles)
        time_ns, camera = buf.time_read[lo:end], buf.camera_read[lo:end]
        uv_und = buf.uv_und[lo:end]
        n = end - lo
        e = n - 1
        m = len(self.rig)
        cam, ki, rr, rtki, f9, lens = self._tables
        (ff, fi, past_rows, past_points, has, predicted, flags, innovation, factor, model,
         kinked_out, sigma, decided) = self._scratch
        refused = np.zeros(n, dtype=np.int64)
        points, quality_table = np.empty((1, 3)), np.empty((len(_QUALITY), 1))  # (returned)
        noise_px = self._noise_px
        with_cov = noise_px is not None and not _prepare.FINITE_DIFFERENCES
        # the σ NoiseEstimate.sigmas gives the next point (whatever its innovation: made
        # from the ones before), for the prediction and kink tests
        floor = DEFAULT_NOISE_PX if noise_px is None else float(noise_px)
        sigma[0] = self._noise.next_sigma(floor)
        # the brackets, type_a_kernel at the newest row and the decisions of fuse_type_a on
        # its one point (made: 1: finite, good, failed, kinked), or none (made: 0), in one
        # compiled call (one_point_kernel: the same calls one after another)
        made = _pseudo_kernel.one_point_kernel(
            2 * m, MAX_EXTRAPOLATION, self._max_gap_ns, time_ns, camera, uv_und,
            buf.rays[lo:end], self._template.centers, ki, rr, f9, cam, _SPAN_TIE_NS,
            MIN_RAY_ANGLE_DEG, buf.ray_dir[lo:end],
            np.ascontiguousarray(buf.dir_jac[:, :, lo:end]),
            buf.jac_rows[lo:end] if lens else np.zeros((1, 4)), lens, rtki, NS,
            0.0 if self._cov_px is None else float(self._cov_px), with_cov, ff, fi, refused, has,
            predicted, points, flags, innovation, factor, model, quality_table, past_rows,
            past_points, buf.camera64[lo:end], self._lens_table, sigma, INNOVATION_SIGMAS,
            self._no_rows, kinked_out, decided)
        bits = int(flags[0]) if made else 0
        finite, good, failed, kinked = decided.tolist()
        if made:  # (NoiseEstimate.sigmas of (innovation / factor,) or (NaN,): its one point)
            self._noise.take(float(innovation[0]) / float(factor[0]) if good else math.nan)
        keep = good and not failed and not kinked
        doubted = False
        if keep:  # (rests_on_doubt of the one point)
            doubt = buf.doubt
            doubted = doubt[lo + e] > 0
            if not doubted:  # (the rows of its past points: any in doubt)
                for r in past_rows[:, 0, :].ravel().tolist():
                    if r >= 0 and doubt[lo + r] > 0:
                        doubted = True
                        break
            keep = not doubted
        # Track.dropped: each detection's past refusals once (seen), the invalid point's
        # reasons, the tests' refusals, in fuse_type_a's order
        dropped: dict[str, int] = {}
        if made and finite and bits:
            dropped.update(count_invalid(flags))
        if refused.any():
            seen = buf.seen[lo:end]
            refused, seen[:] = refused & ~seen, seen | refused
            if refused.any():
                for reason, count in count_invalid(refused).items():
                    dropped[f"past_{reason}"] = dropped.get(f"past_{reason}", 0) + count
        if failed:
            dropped["prediction_failed"] = 1
        elif kinked:
            dropped["kink"] = 1
        elif doubted:
            dropped[DOUBT] = 1
        if not keep:
            if not dropped:
                return self._empty
            return _trusted_track(self._empty.time_ns, self._empty.position_world,
                                  self._empty.camera, dict(self._empty.quality), dropped)
        n_columns = len(_QUALITY) if with_cov else 10
        quality_table.flags.writeable = False
        # (the time and camera copied out of the buffers, which later pushes overwrite)
        return _trusted_track(time_ns[e:].copy(), points, camera[e:].copy(),
                              dict(zip(_QUALITY[:n_columns], quality_table, strict=False)),
                              dropped)


def _trusted_track(time_ns: np.ndarray, points: np.ndarray, camera: np.ndarray,
                   quality: dict, dropped: Mapping[str, int], shared: bool = False
                   ) -> Track:
    """A :class:`Track` of columns already of its dtypes and shapes (checked by whoever made
    them), without its constructor's checks: read-only views of them, as it keeps
    (``shared``: the columns are a Track's already, read-only: kept as they are)."""
    track = object.__new__(Track)
    columns = [time_ns, points, camera]
    if not shared:
        for i, column in enumerate(columns):
            view = column.view()
            view.flags.writeable = False
            columns[i] = view
    track.__dict__.update(method="typeA", time_ns=columns[0], position_world=columns[1],
                          camera=columns[2], quality=quality, dropped=dropped)
    return track


class _StreamColumns:
    """:class:`TypeAStream`'s per-row columns, ``capacity`` rows each (a window of them in
    use): times, cameras, recorded and undistorted pixels, frames, rays (recorded pixel's
    and undistorted pixel's), the undistortion Jacobians (as (2, 2) and as rows of 4), the
    rays' direction Jacobians (3, 2, capacity) and the past refusals counted per row."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.time = np.zeros(capacity, np.int64)
        self.camera = np.zeros(capacity, np.int32)
        # read-only views of them (their slices: the kernels' time and camera arguments)
        self.time_read, self.camera_read = self.time.view(), self.camera.view()
        self.time_read.flags.writeable = self.camera_read.flags.writeable = False
        self.camera64 = np.zeros(capacity, np.int64)  # (the kernels' int64 form of it)
        self.uv = np.zeros((capacity, 2))
        self.frame = np.zeros(capacity, np.int64)
        self.uv_und = np.zeros((capacity, 2))
        self.ray_dir = np.zeros((capacity, 3))
        self.jac = np.zeros((capacity, 2, 2))
        self.rays = np.zeros((capacity, 3))
        self.dir_jac = np.zeros((3, 2, capacity))
        self.jac_rows = np.zeros((capacity, 4))
        self.seen = np.zeros(capacity, np.int64)
        self.doubt = np.zeros(capacity)  # the gate's doubt of each row (0: none)

    def moved(self, lo: int, hi: int, capacity: int) -> _StreamColumns:
        """Rows [lo, hi) at the front of columns of at least ``capacity`` rows (these
        columns, if large enough)."""
        out = self if capacity <= self.capacity else _StreamColumns(capacity)
        k = hi - lo
        for name in ("time", "camera", "camera64", "uv", "frame", "uv_und", "ray_dir", "jac",
                     "rays", "jac_rows", "seen", "doubt"):
            column = getattr(self, name)
            getattr(out, name)[:k] = column[lo:hi].copy()  # (overlapping when in place)
        out.dir_jac[:, :, :k] = self.dir_jac[:, :, lo:hi].copy()
        return out


# ---------------------------------------------------------------------------------------
# type A's covariance at the session's measured detection noise (docs/methods.md, "Type A's
# covariance at the measured noise")

#: the covariance columns a point's noise scales
_COV_COLUMNS = ("cov_xx_m2", "cov_yy_m2", "cov_zz_m2", "cov_xy_m2", "cov_xz_m2", "cov_yz_m2")


def covariance_noise_px(noise_px: float | None) -> float:
    """The pixel noise type A's kernel makes the covariance with (``fuse_type_a``'s
    ``cov_noise_px``) before :func:`with_measured_noise` rescales it: the stated noise, or
    1 px where it is 0 (a covariance of zero noise cannot be rescaled)."""
    return float(noise_px) if noise_px else 1.0


def no_detection_limits(cameras) -> np.ndarray:
    """Each camera's bound (m,) beyond which a recorded pixel is no detection (prepare's
    ``_prepare._FAR_IMAGES`` image sizes: its undistorted pixel NaN)."""
    return np.array([float(_prepare._FAR_IMAGES * max(c.width, c.height)) for c in cameras])


#: type A's noise at a session's start, before any checkpoint's window holds
#: ``NOISE_MIN_COUNT`` residuals: Σ r² / (2n - 2) of the n residuals before the point's
#: own time once this many are there (:func:`measured_noise`)
NOISE_START_COUNT = 4
#: ... and before that (a session's first ~0.1 s: each camera's fourth detection makes its
#: first residual), at least this: nothing is measured yet, and the stated noise is what the
#: user left at the default as often as what the detector does (at 2 px of true noise the
#: stated 0.5 px made the first points' d² 16 times too large: docs/methods.md)
NOISE_UNKNOWN_PX = 2.0


def residual_norms(time_ns: np.ndarray, camera: np.ndarray, uv: np.ndarray,
                   limits: np.ndarray, max_gap_s: float) -> tuple[np.ndarray, np.ndarray]:
    """The times (j,) and norms (j,) of the finite residuals of the detections ``time_ns``
    (n,) sorted, ``camera`` (n,), ``uv`` (n, 2) recorded pixels (``limits``:
    :func:`no_detection_limits`) from the quadratic through each one's camera's three
    previous ones, per axis's σ (:func:`~pslog.fusion._pseudo_kernel.residual_norms_kernel`)."""
    from . import _pseudo_kernel

    n = len(time_ns)
    t_out, v_out = np.empty(n, np.int64), np.empty(n)
    j = _pseudo_kernel.residual_norms_kernel(
        np.ascontiguousarray(time_ns), np.ascontiguousarray(camera, dtype=np.int64),
        np.ascontiguousarray(uv), limits, len(limits), int(max_gap_s * NS), NS, t_out, v_out)
    return t_out[:j], v_out[:j]


def window_noise(t_fin: np.ndarray, v_fin: np.ndarray, ends_ns: np.ndarray, min_count: int
                 ) -> np.ndarray:
    """σ (k,) at each of the sorted ``ends_ns`` (k,): the upper median of the residual norms
    ``v_fin`` at ``t_fin`` (:func:`residual_norms`) in ``[end - NOISE_WINDOW_S, end)``
    over Rayleigh's median; NaN where fewer than ``min_count`` are there."""
    from . import _pseudo_kernel
    from .innovation import RAYLEIGH_MEDIAN
    from .stereo import NOISE_WINDOW_S

    est = np.empty(len(ends_ns))
    _pseudo_kernel.window_medians_kernel(t_fin, v_fin, np.ascontiguousarray(ends_ns),
                                         int(NOISE_WINDOW_S * NS), min_count, est)
    return est / RAYLEIGH_MEDIAN


def start_noise(t_fin: np.ndarray, v_fin: np.ndarray, at_ns: np.ndarray, noise_px: float
                ) -> np.ndarray:
    """σ (k,) of points at ``at_ns`` (k,) sorted before any checkpoint has an estimate:
    from the ``n`` residuals (per axis) in the window up to the point's own time once
    :data:`NOISE_START_COUNT` are there, ``σ̂² = Σ r² / (2n - 2)``, else the larger of
    ``noise_px`` and :data:`NOISE_UNKNOWN_PX`. The sum of squares, not the median: of a few
    residuals the median's ``E[σ² / σ̂²]`` is large (a checkpoint's window holds 16 or more),
    and an outlier makes it larger, not smaller; over ``2n - 2``, not ``2n``: ``Σ r² / σ²``
    is a χ² of 2n degrees of freedom, whose inverse's mean is ``1 / (2n - 2)``, so
    ``E[σ² / σ̂²] = 1`` and a point's NEES is 1 on average (over ``2n`` it was
    ``n / (n - 1)``: 4/3 at the fourth residual). No floor at ``noise_px`` (a checkpoint has
    none): the stated 0.5 px made the start's points at 0.3 px of true noise NEES 0.36-0.40
    (docs/methods.md, "Type A's covariance at a session's start")."""
    from . import _pseudo_kernel
    from .stereo import NOISE_WINDOW_S

    at_ns = np.ascontiguousarray(at_ns)
    window = int(NOISE_WINDOW_S * NS)
    est = np.empty(len(at_ns))  # (Σ r² / 2n: the kernel's window [t - window, t))
    _pseudo_kernel.window_mean_squares_kernel(t_fin, v_fin, at_ns, window, NOISE_START_COUNT,
                                              est)
    n = (np.searchsorted(t_fin, at_ns, "left")
         - np.searchsorted(t_fin, at_ns - window, "left")).astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):  # (n < NOISE_START_COUNT: NaN)
        est = est * (n / (n - 1.0))
    return np.where(np.isfinite(est), np.sqrt(est), max(noise_px, NOISE_UNKNOWN_PX))


def measured_noise(time_ns: np.ndarray, camera: np.ndarray, uv: np.ndarray, limits: np.ndarray,
                   max_gap_s: float, at_ns: np.ndarray, noise_px: float) -> np.ndarray:
    """The detection noise σ (pixels per axis, (k,)) of type-A points at ``at_ns`` (k,)
    sorted, from the detections ``time_ns`` (n,) sorted, ``camera`` (n,), ``uv`` (n, 2)
    recorded pixels (``limits``: :func:`no_detection_limits`), causally, with ``nearest``'s
    estimator (:func:`pslog.fusion.stereo.detection_noise`: its constants and floor) and
    two changes at the start and across pauses (docs/methods.md, "Type A's covariance at
    the measured noise"):

    - each detection's residual from the quadratic through its camera's three previous ones,
      per axis's σ (:func:`residual_norms`);
    - a checkpoint ``T`` (each detection's time down to a multiple of ``NOISE_EVERY_S``)
      has the median of the residuals in ``[T - NOISE_WINDOW_S, T)`` over Rayleigh's median
      if ``NOISE_MIN_COUNT`` are there, else the latest earlier checkpoint's (of any
      detection) that has one (a pause in the detections does not change the detector);
    - a point takes its checkpoint's; before any checkpoint has one (the session's start),
      :func:`start_noise` (``Σ r² / (2n - 2)`` of the ``n`` residuals before the point
      once ``NOISE_START_COUNT`` are there, else ``NOISE_UNKNOWN_PX``);
    - at least ``min(noise_px, NOISE_FLOOR_PX)``.

    A point uses only detections before its own time: :class:`MeasuredNoiseStream` gives it
    the same bits."""
    from . import _pseudo_kernel
    from .innovation import RAYLEIGH_MEDIAN
    from .stereo import NOISE_EVERY_S, NOISE_FLOOR_PX, NOISE_MIN_COUNT, NOISE_WINDOW_S

    time_ns = np.ascontiguousarray(time_ns)
    camera = np.ascontiguousarray(camera)  # (int32 or int64 as given: indices only)
    if camera.dtype.type not in (np.int32, np.int64):
        camera = camera.astype(np.int64)
    uv = np.ascontiguousarray(uv)
    at_ns = np.ascontiguousarray(at_ns, dtype=np.int64)
    sigma = np.empty(len(at_ns))
    _pseudo_kernel.checkpoint_noise_kernel(
        time_ns, camera, uv, limits, len(limits), int(max_gap_s * NS), NS,
        int(NOISE_EVERY_S * NS), int(NOISE_WINDOW_S * NS), NOISE_MIN_COUNT, RAYLEIGH_MEDIAN,
        at_ns, sigma)
    start = np.flatnonzero(np.isnan(sigma))  # (the session's first points)
    if len(start):
        # (the residuals of the rows up to the last of them: the same as of every row)
        end = int(np.searchsorted(time_ns, at_ns[start[-1]], side="right"))
        fin = residual_norms(time_ns[:end], camera[:end], uv[:end], limits, max_gap_s)
        sigma[start] = start_noise(*fin, at_ns[start], noise_px)
    return np.maximum(sigma, min(noise_px, NOISE_FLOOR_PX), out=sigma)  # (this call's own)


def without_model_columns(track: Track) -> Track:
    """``track`` without the kernel's model-error columns (:data:`_MODEL_COLUMNS`), which
    only :func:`with_measured_noise` reads (the same arrays otherwise)."""
    if _MODEL_COLUMNS[0] not in track.quality:
        return track
    quality = {k: v for k, v in track.quality.items() if k not in _MODEL_COLUMNS}
    return _trusted_track(track.time_ns, track.position_world, track.camera, quality,
                          dict(track.dropped), shared=True)


#: the innovation's part of type A's model error counts where ``|u|² / (σ² c)`` exceeds
#: this, the χ² of 2 degrees of freedom at 99 % (the same gate as ``nearest``'s break
#: test, ``stereo.KINK_GATE``): below it the noise explains it, and adding its excess over the
#: noise anyway (zero on average, but not once clipped at 0) made the 0.3 px sessions' NEES
#: 4-18 % lower
MODEL_GATE = KINK_GATE


def with_measured_noise(track: Track, sigma: np.ndarray, cov_noise_px: float,
                        centers: np.ndarray | None = None, table: np.ndarray | None = None
                        ) -> Track:
    """``track`` (type A's, its covariance made at ``cov_noise_px``) with the covariance of
    each point at its own noise ``sigma`` (k,): the columns times ``(σ / cov_noise_px)²``
    (the first-order covariance is the noise's variance times Jacobian products), plus
    eq. (2)'s model error along the newest ray where the kernel made its columns (which
    leave the track): ``v r rᵀ``, ``v = (h rᵀg)² + [|u|² > MODEL_GATE σ² c] ½ (|u|² - 2 σ²
    c)`` from the three columns (gravity's part, the innovation's across-ray offset less
    gravity's ``|u|²``, ``c = (factor D / f)²``), ``r`` the unit ray from the point's
    camera's centre in ``centers`` (m, 3) to the point
    (:func:`~pslog.fusion._pseudo_kernel.model_rescale_kernel`); ``std_m`` the root of the
    new diagonal's sum. Points and the other columns are the same arrays.

    ``table``: the quality table ``track``'s columns are rows of (``_fuse_type_a``'s
    ``table_out``; a Track no one else holds): ``std_m`` and the covariance are rescaled in
    place, in its rows (the kernel reads each point's six terms before it writes them: the
    same bits), where a copy of the six columns and seven new ones were fresh memory at every
    call (~100 bytes a point: page faults where glibc trims the heap; docs/performance.md)."""
    q = track.quality
    if not len(track) or "std_m" not in q:
        return without_model_columns(track)
    quality = {k: v for k, v in q.items() if k not in _MODEL_COLUMNS}
    if centers is not None and _MODEL_COLUMNS[0] in q:
        # (one compiled pass: the rescaling and v r rᵀ with r = ray / |ray|, v / |ray|²
        # times the ray's products; MeasuredNoiseStream the same operations on floats)
        from . import _pseudo_kernel

        if table is not None:  # (rows std_m, the six covariance columns: in place)
            std = _QUALITY.index("std_m")
            cov, out = table[std + 1:std + 7], table[std:std + 7]
            camera = track.camera  # (int32: no int64 copy)
        else:
            cov, out = np.stack([q[name] for name in _COV_COLUMNS]), np.empty((7, len(track)))
            camera = np.ascontiguousarray(track.camera, np.int64)
        _pseudo_kernel.model_rescale_kernel(
            cov, np.ascontiguousarray(sigma, np.float64),
            float(cov_noise_px), *(np.ascontiguousarray(q[name]) for name in _MODEL_COLUMNS),
            np.ascontiguousarray(track.position_world), camera,
            np.ascontiguousarray(centers, np.float64), MODEL_GATE, out)
        if table is None:
            quality["std_m"] = out[0]
            for name, column in zip(_COV_COLUMNS, out[1:], strict=True):
                quality[name] = column
    else:
        factor = sigma / cov_noise_px
        factor = factor * factor
        for name in _COV_COLUMNS:
            quality[name] = q[name] * factor
        quality["std_m"] = np.sqrt(quality["cov_xx_m2"] + quality["cov_yy_m2"]
                                   + quality["cov_zz_m2"])
    return _trusted_track(track.time_ns, track.position_world, track.camera, quality,
                          dict(track.dropped))


#: ``FusionOptions.max_std_m``'s default: the filter's (issue 10's "no output point further
#: than 5 cm from the truth" at 95 %: 5 cm / 1.96, ``pslog.fusion.filter.FilterOptions``)
MAX_STD_M = 0.05 / 1.96


def withhold_uncertain(track: Track, max_std_m: float | None) -> tuple[Track, np.ndarray | None]:
    """``track`` without the points whose ``std_m`` exceeds ``max_std_m`` (their covariance
    does not vouch for them within 5 cm at 95 %), counted in ``Track.dropped`` as
    ``uncertain`` (the filter's reason and rule, ``FilterOptions.max_std_m``), and the
    kept rows (None: every one; ``max_std_m`` None, no covariance or nothing above it)."""
    std = track.quality.get("std_m")
    if max_std_m is None or std is None or not len(track):
        return track, None
    keep = ~(std > max_std_m)  # (a NaN std_m is kept: no covariance to judge it by)
    n_out = len(keep) - int(np.count_nonzero(keep))
    if not n_out:
        return track, None
    dropped = dict(track.dropped)
    dropped["uncertain"] = dropped.get("uncertain", 0) + n_out
    return _trusted_track(track.time_ns[keep], track.position_world[keep], track.camera[keep],
                          {k: v[keep] for k, v in track.quality.items()}, dropped), keep


def type_a_noise(prep: Prepared, track: Track, max_gap_s: float, noise_px: float | None,
                 table: np.ndarray | None = None) -> Track:
    """``track`` (type A's from ``prep``, made with ``cov_noise_px =``
    :func:`covariance_noise_px`) with its covariance at the session's measured noise
    (:func:`measured_noise` over ``prep``'s detections); unchanged without covariance.
    ``table``: :func:`with_measured_noise`'s (rescaled in place)."""
    if noise_px is None or not len(track) or "std_m" not in track.quality:
        return without_model_columns(track)
    obs = prep.obs
    sigma = measured_noise(obs.time_ns, obs.camera, obs.uv, no_detection_limits(prep.cameras),
                           max_gap_s, track.time_ns, float(noise_px))
    return with_measured_noise(track, sigma, covariance_noise_px(noise_px), prep.centers,
                               table)


class MeasuredNoiseStream:
    """A type-A stream (:class:`TypeAStream`, or :class:`~pslog.fusion.confirm.
    ConfirmedStream` around one) whose points' covariance is at the measured noise, as
    :func:`type_a_noise` makes the batch's. Each checkpoint's σ is made when its first row
    arrives (every detection before the checkpoint is in then: rows arrive in time order)
    from the detections of the last ``NOISE_EVERY_S + NOISE_WINDOW_S + 3 max_gap_s`` (its
    window, and each residual's three previous detections), which it keeps; a point takes
    its checkpoint's σ when it is output (a withheld one later: the checkpoints of the
    points still withheld are kept); a point whose ``std_m`` then exceeds ``max_std_m`` is
    withheld (:func:`withhold_uncertain`). The same bits as the batch run."""

    def __init__(self, inner, rig, options) -> None:
        from ._prepare import default_max_gap_s
        from .stereo import NOISE_EVERY_S, NOISE_WINDOW_S

        self.inner = inner
        self._noise_px = options.noise_px
        self._cov_px = covariance_noise_px(options.noise_px)
        self._max_std = options.max_std_m  # (withhold_uncertain's bound, as the batch's)
        self._max_gap_s = options.max_gap_s or default_max_gap_s(rig)
        self._limits = no_detection_limits(rig.cameras)
        self._centers = np.array([c.center_world for c in rig.cameras])  # (prepare's)
        self._every_ns = int(NOISE_EVERY_S * NS)
        self._keep_ns = int((NOISE_EVERY_S + NOISE_WINDOW_S + 3 * self._max_gap_s
                             + options.tolerance_s) * NS) + 1
        self._time = np.zeros(256, np.int64)
        self._camera = np.zeros(256, np.int64)
        self._uv = np.zeros((256, 2))
        self._n = 0
        self._sigma: dict[int, float] = {}  # checkpoint ns -> σ (the recent ones)
        self._last_mark = np.iinfo(np.int64).min
        self._latest = math.nan  # the latest checkpoint's estimate (NaN: none yet)
        self._start: dict[int, float] = {}  # the session's start: time ns -> σ of its rows
        # a detection without a ray is a missing one (as the batch's rays_only): such rows
        # are kept from the inner stream and the noise's history (lensless cameras: beyond
        # the limits or NaN; a lens's: also where its undistortion folds over)
        self._cameras = rig.cameras
        self._lensless = [not np.any(c.dist) for c in rig.cameras]
        self._limit_list = self._limits.tolist()  # (Python floats: the one-row path's test)
        if hasattr(inner, "push_one"):
            self.push_one = self._push_one
        if hasattr(inner, "flush"):
            self.flush = self._flush

    def _log(self, time_ns: np.ndarray, camera: np.ndarray, uv: np.ndarray) -> None:
        """New rows into the kept history (the rows older than it dropped first when the
        buffers are full), the σ of each checkpoint they are the first rows of, and (at the
        session's start, no checkpoint's estimate yet) each new row's own."""
        k = len(time_ns)
        n = self._n
        first = int(time_ns[0])
        if first // self._every_ns * self._every_ns > self._last_mark or n + k > len(self._time):
            # (at each new checkpoint, and when full: the rows older than the history out)
            lo = int(np.searchsorted(self._time[:n], first - self._keep_ns))
            n -= lo
            size = max(len(self._time), 2 * (n + k))
            t, c, u = np.zeros(size, np.int64), np.zeros(size, np.int64), np.zeros((size, 2))
            t[:n], c[:n], u[:n] = (self._time[lo:lo + n], self._camera[lo:lo + n],
                                   self._uv[lo:lo + n])
            self._time, self._camera, self._uv = t, c, u
            self._prune(first)
        self._time[n:n + k] = time_ns
        self._camera[n:n + k] = camera
        self._uv[n:n + k] = np.asarray(uv, np.float64).reshape(-1, 2)
        self._n = n = n + k
        if self._noise_px is None:
            return
        from .stereo import NOISE_MIN_COUNT

        every = self._every_ns
        fin = None
        for mk in sorted({t // every * every for t in time_ns.tolist()}):
            if mk > self._last_mark:
                fin = fin or residual_norms(self._time[:n], self._camera[:n], self._uv[:n],
                                            self._limits, self._max_gap_s)
                est = window_noise(*fin, np.array([mk], np.int64), NOISE_MIN_COUNT)[0]
                if math.isfinite(est):
                    self._latest = est
                self._sigma[mk] = self._latest
                self._last_mark = mk
        # (the session's start, no checkpoint's estimate yet: each row's own)
        ends = [t for t in sorted(set(time_ns.tolist()))
                if math.isnan(self._sigma[t // every * every])]
        if ends:
            fin = fin or residual_norms(self._time[:n], self._camera[:n], self._uv[:n],
                                        self._limits, self._max_gap_s)
            at = np.array(ends, np.int64)
            for t, sg in zip(ends, start_noise(*fin, at, float(self._noise_px)).tolist(),
                             strict=True):
                self._start[t] = sg

    def _log_one(self, t: int, c: int, u: float, v: float) -> None:
        """:meth:`_log` of one row (Python scalars) where it only writes the row (a
        checkpoint already made, room left, past the session's start); else :meth:`_log`."""
        n = self._n
        if (t // self._every_ns * self._every_ns > self._last_mark or n >= len(self._time)
                or self._latest != self._latest):
            self._log(np.array([t], np.int64), np.array([c], np.int64), np.array([[u, v]]))
            return
        self._time[n] = t
        self._camera[n] = c
        row = self._uv[n]
        row[0], row[1] = u, v
        self._n = n + 1

    def _prune(self, newest: int) -> None:
        """The checkpoints no point can still take dropped (before the newest row's, and
        before the oldest point the inner stream withholds)."""
        oldest = newest
        queue = getattr(self.inner, "_queue", None)
        if queue:
            oldest = min(oldest, int(queue[0][0].time_ns[0]))
        cut = oldest // self._every_ns * self._every_ns
        for mk in [mk for mk in self._sigma if mk < cut]:
            del self._sigma[mk]
        for t in [t for t in self._start if t < cut]:
            del self._start[t]

    def _scaled(self, out: Track) -> Track:
        """``out`` with each point's covariance at its checkpoint's σ (at the session's
        start its own), at least the floor: :func:`type_a_noise`'s arithmetic (one point:
        the same IEEE operations on Python floats)."""
        n = len(out.time_ns)  # (len(out), without Track's Python __len__)
        if self._noise_px is None or not n or "std_m" not in out.quality:
            return without_model_columns(out)
        every = self._every_ns
        if n == 1:  # (the usual push: one point, no numpy call on (1,) columns)
            t = int(out.time_ns[0])
            sg = self._sigma[t // every * every]
            if sg != sg:
                sg = self._start[t]
            sg = max(float(sg), min(float(self._noise_px), NOISE_FLOOR_PX))
            f = sg / self._cov_px
            f = f * f
            q = out.quality
            # (_COV_COLUMNS' order; written out: no generator per point)
            xx, yy, zz = (float(q["cov_xx_m2"][0]) * f, float(q["cov_yy_m2"][0]) * f,
                          float(q["cov_zz_m2"][0]) * f)
            xy, xz, yz = (float(q["cov_xy_m2"][0]) * f, float(q["cov_xz_m2"][0]) * f,
                          float(q["cov_yz_m2"][0]) * f)
            if _MODEL_COLUMNS[0] in q:  # (with_measured_noise's model term, on floats)
                c = int(out.camera[0])
                p = out.position_world[0]
                d0 = float(p[0]) - float(self._centers[c, 0])
                d1 = float(p[1]) - float(self._centers[c, 1])
                d2 = float(p[2]) - float(self._centers[c, 2])
                gravity, across, per_px2 = (float(q["_model_gravity_m2"][0]),
                                            float(q["_model_across_m2"][0]),
                                            float(q["_model_m2_per_px2"][0]))
                noise = (sg * sg) * per_px2
                w = (gravity + (0.5 * (across - 2.0 * noise) if across > MODEL_GATE * noise
                                else 0.0)) / (d0 * d0 + d1 * d1 + d2 * d2)
                xx, yy, zz = xx + w * (d0 * d0), yy + w * (d1 * d1), zz + w * (d2 * d2)
                xy, xz, yz = xy + w * (d0 * d1), xz + w * (d0 * d2), yz + w * (d1 * d2)
            values = np.array([math.sqrt(xx + yy + zz), xx, yy, zz, xy, xz, yz])
            values.flags.writeable = False
            # (q's columns but the model's, in q's order: a copy less three, not a Python
            # loop over ~20 keys per point)
            quality = dict(q)
            for k in _MODEL_COLUMNS:
                quality.pop(k, None)
            quality.update(std_m=values[0:1], cov_xx_m2=values[1:2], cov_yy_m2=values[2:3],
                           cov_zz_m2=values[3:4], cov_xy_m2=values[4:5], cov_xz_m2=values[5:6],
                           cov_yz_m2=values[6:7])
            # (out's columns are a Track's already: read-only, shared as they are)
            track = _trusted_track(out.time_ns, out.position_world, out.camera, quality,
                                   out.dropped, shared=True)
            if self._max_std is not None and values[0] > self._max_std:
                return withhold_uncertain(track, self._max_std)[0]
            return track
        cache, start = self._sigma, self._start
        sigma = np.array([cache[t // every * every] for t in out.time_ns.tolist()])
        if np.isnan(sigma).any():
            sigma = np.array([start[t] if math.isnan(sg) else sg for t, sg in zip(
                out.time_ns.tolist(), sigma.tolist(), strict=True)])
        sigma = np.maximum(sigma, min(float(self._noise_px), NOISE_FLOOR_PX))
        return withhold_uncertain(with_measured_noise(out, sigma, self._cov_px, self._centers),
                                  self._max_std)[0]

    def _has_ray(self, camera: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """(n,) bool: the rows :func:`~._prepare.prepare` gives a ray (a finite one)."""
        limit = self._limits[camera]
        has = (np.abs(uv[:, 0]) <= limit) & (np.abs(uv[:, 1]) <= limit)
        for c in sorted(set(camera[has].tolist())):
            if not self._lensless[c]:
                rows = np.flatnonzero(has & (camera == c))
                with np.errstate(all="ignore"):
                    xy = self._cameras[c].undistort_normalized(uv[rows])
                has[rows] = np.isfinite(xy[:, 0]) & np.isfinite(xy[:, 1])
        return has

    def _one_has_ray(self, camera: int, u: float, v: float) -> bool:
        """:meth:`_has_ray` of one row (Python scalars; a lensless camera: two comparisons)."""
        limit = self._limit_list[camera]
        if not (abs(u) <= limit and abs(v) <= limit):  # (NaN: False)
            return False
        return self._lensless[camera] or bool(
            self._has_ray(np.array([camera]), np.array([[u, v]]))[0])

    def _nothing(self) -> Track:
        """The inner stream's answer to no row (a row without a ray: as if not pushed)."""
        return self._scaled(self.inner.push(np.zeros(0, np.int64), np.zeros(0, np.int32),
                                            np.zeros((0, 2)), np.zeros(0, np.int64)))

    def push(self, time_ns, camera, uv, frame_index) -> Track:
        """The inner stream's push, its points' covariance at the measured noise (a row
        without a ray: as if not pushed; a camera out of the rig: the inner stream's
        error)."""
        if len(time_ns) == 1:
            u, v = np.asarray(uv, np.float64).reshape(-1, 2)[0].tolist()
            c = int(camera[0])
            if 0 <= c < len(self._limit_list) and not self._one_has_ray(c, u, v):
                return self._nothing()
            self._log_one(int(time_ns[0]), c, u, v)
        elif len(time_ns):
            camera = np.asarray(camera)
            uv = np.asarray(uv, np.float64).reshape(-1, 2)
            if camera.min() >= 0 and camera.max() < len(self._limit_list):
                has = self._has_ray(camera, uv)
                if not has.all():
                    time_ns, camera, uv = np.asarray(time_ns)[has], camera[has], uv[has]
                    frame_index = np.asarray(frame_index)[has]
            if len(time_ns):
                self._log(np.asarray(time_ns, np.int64), camera, uv)
        return self._scaled(self.inner.push(time_ns, camera, uv, frame_index))

    def _push_one(self, time_ns: int, camera: int, u: float, v: float) -> Track:
        """The inner stream's ``push_one``, its point's covariance at the measured noise (a
        row without a ray: as if not pushed)."""
        if not self._one_has_ray(camera, u, v):
            return self._nothing()
        self._log_one(time_ns, camera, u, v)
        return self._scaled(self.inner.push_one(time_ns, camera, u, v))

    def _flush(self) -> Track:
        """The inner stream's ``flush`` (the points it still holds), at the measured noise."""
        return self._scaled(self.inner.flush())
