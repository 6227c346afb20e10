"""Columnar records that flow between pslog's layers: detections, observations, tracks, truth.

All times are integer nanoseconds on the session's common clock; positions are world metres
(z up); pixels are as detected (distorted) unless a name says ``undistorted``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

NS = 1_000_000_000  # nanoseconds per second
#: Largest frame index a session stores: the MCAP message sequence, a 32-bit count (4.3e9
#: frames are 4.5 years at 30 fps); CSV import and live datagrams refuse larger ones.
MAX_FRAME_INDEX = 2**32 - 1

#: Per-point quality columns a fusion method may fill (NaN where not applicable).
QUALITY_FIELDS = {
    "ray_miss_m": "distance between the rays crossed for this point, metres (N-view: RMS "
                  "distance of the point to its rays; type A: the larger of its past points' "
                  "ray distances BEFORE the epipolar snap, after which they would cross)",
    "snap_px": "distance the interpolated point moved to reach the epipolar line, pixels",
    "ray_shift_m": "distance the prediction moved onto the newest viewing ray (eq. 4), metres",
    "ray_angle_deg": "angle between the crossed rays (the largest pair; for type A the smaller "
                     "of its two past points), degrees: small means a poorly determined depth",
    "residual_max_px": "largest reprojection error of a contributing detection, pixels of the "
                       "recorded image (type A/B: the past points' before the epipolar snap, "
                       "and the newest detection's against the eq. (2) prediction)",
    "residual_mean_px": "mean reprojection error of the contributing detections, pixels",
    "camera_mask": "cameras whose detections made the point, bit c for camera c",
    "n_detections": "number of distinct detections that made the point",
    "gap_s": "largest time span bridged (interpolated, extrapolated or taken as "
             "simultaneous), seconds",
    "span_s": "the point's time minus the earliest capture time it uses, seconds (type A's "
              "point from the detections after it, --confirm-gaps jumps or breaks: minus the "
              "latest, negative)",
    "std_m": "position standard deviation, sqrt(trace of the covariance), metres (first order "
             "from the detections' pixel noise and, in a session from pslog sync, the "
             "uncertainty of its clock estimates; not the motion model's error, but "
             "nearest's includes the ball's motion between the shutters it pairs)",
    "std_x_m": "position standard deviation along x, metres (smooth, filter)",
    "std_y_m": "position standard deviation along y, metres (smooth, filter)",
    "std_z_m": "position standard deviation along z, metres (smooth, filter)",
    "residual_px": "the detection's reprojection residual, pixels (smooth; filter: after "
                   "its update)",
    "innovation_px": "distance of the detection from the predicted point's projection, "
                     "pixels (filter, before its update)",
    "nis": "normalised innovation squared the filter's gate tested (chi-square, 2 degrees of "
           "freedom when the filter is right)",
    "jump": "1 where the filter accepted a velocity jump (bounce, kick) at this detection",
    "rejected": "1 where the method rejected the point's detection, and the point is not "
                "its: filter, the detection failed the gate and the point is the "
                "prediction; smooth, its residual is beyond χ²₂'s 1 - 1e-4 quantile of the "
                "fit's noise and the point is the trajectory's (the other detections')",
    "init": "1 where the filter's track was (re)initialised at this detection",
    **{f"cov_{a}_m2": f"position covariance entry {a}, square metres"
       for a in ("xx", "yy", "zz", "xy", "xz", "yz")},
}


def _frozen(array, dtype, shape_tail: tuple[int, ...], name: str) -> np.ndarray:
    # (an array already of the dtype and contiguous, the usual case, is taken as it is:
    # ascontiguousarray would return it too, at several times the cost of the test)
    if not (type(array) is np.ndarray and array.dtype.type is dtype and array.dtype.isnative
            and array.flags.c_contiguous):
        array = np.ascontiguousarray(array, dtype=dtype)
    if array.shape[1:] != shape_tail:
        raise InputError(f"{name} must have shape (n, {', '.join(map(str, shape_tail))}) "
                         f"got {array.shape}" if shape_tail else
                         f"{name} must be one-dimensional, got shape {array.shape}")
    # a read-only view: the record cannot be changed through it, and the caller's own array
    # keeps its flags
    view = array.view()
    view.setflags(write=False)
    return view


@dataclass(frozen=True, eq=False)
class Observations:
    """One ball observation per row, sorted by ``(time_ns, camera)``; the input of fusion.

    Attributes
    ----------
    time_ns : (n,) int64, capture time
    camera : (n,) int32, camera index in the rig
    uv : (n, 2) float64, pixels as detected (distorted)
    frame_index : (n,) int64, the camera's frame counter
    """

    time_ns: np.ndarray
    camera: np.ndarray
    uv: np.ndarray
    frame_index: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "time_ns", _frozen(self.time_ns, np.int64, (), "time_ns"))
        object.__setattr__(self, "camera", _frozen(self.camera, np.int32, (), "camera"))
        object.__setattr__(self, "uv", _frozen(self.uv, np.float64, (2,), "uv"))
        object.__setattr__(self, "frame_index",
                           _frozen(self.frame_index, np.int64, (), "frame_index"))
        n = len(self.time_ns)
        if not (len(self.camera) == len(self.uv) == len(self.frame_index) == n):
            raise InputError("observation columns differ in length")
        if n > 1:
            step = np.diff(self.time_ns)
            order_ok = (step > 0) | ((step == 0) & (np.diff(self.camera) > 0))
            if not np.all(order_ok):
                raise InputError("observations must be sorted by (time, camera) without repeats")

    def __len__(self) -> int:
        return len(self.time_ns)

    @classmethod
    def from_unsorted(cls, time_ns, camera, uv, frame_index=None) -> Observations:
        """Sort rows by (time, camera)."""
        time_ns = np.asarray(time_ns, dtype=np.int64)
        camera = np.asarray(camera, dtype=np.int32)
        order = np.lexsort((camera, time_ns))
        if frame_index is None:
            frame_index = np.zeros(len(time_ns), dtype=np.int64)
        return cls(time_ns[order], camera[order], np.asarray(uv, dtype=np.float64)[order],
                   np.asarray(frame_index, dtype=np.int64)[order])

    def select(self, mask_or_index) -> Observations:
        return Observations(self.time_ns[mask_or_index], self.camera[mask_or_index],
                            self.uv[mask_or_index], self.frame_index[mask_or_index])


@dataclass(frozen=True, eq=False)
class Detections:
    """A session's per-frame detection results, columnar.

    Every captured frame has a row, with or without candidates; frames are sorted by
    ``(time_ns, camera)``. Candidates are grouped by frame, best (highest score) first.

    Attributes
    ----------
    camera_names : tuple of str, the rig's camera order
    frame_time_ns : (F,) int64, capture time of each frame
    frame_camera : (F,) int32, camera index
    frame_index : (F,) int64, the camera's frame counter
    cand_frame : (C,) int64, row of the candidate's frame in the frame arrays (non-decreasing)
    cand_uv : (C, 2) float64, pixels as detected (distorted)
    cand_radius : (C,) float64, apparent radius in pixels (NaN when unknown)
    cand_score : (C,) float64, detector confidence in [0, 1] (1 when unknown)
    """

    camera_names: tuple[str, ...]
    frame_time_ns: np.ndarray
    frame_camera: np.ndarray
    frame_index: np.ndarray
    cand_frame: np.ndarray
    cand_uv: np.ndarray
    cand_radius: np.ndarray
    cand_score: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "camera_names", tuple(self.camera_names))
        for name, dtype, tail in (
            ("frame_time_ns", np.int64, ()), ("frame_camera", np.int32, ()),
            ("frame_index", np.int64, ()), ("cand_frame", np.int64, ()),
            ("cand_uv", np.float64, (2,)), ("cand_radius", np.float64, ()),
            ("cand_score", np.float64, ()),
        ):
            object.__setattr__(self, name, _frozen(getattr(self, name), dtype, tail, name))
        n_frames, n_cand = len(self.frame_time_ns), len(self.cand_frame)
        if not (len(self.frame_camera) == len(self.frame_index) == n_frames):
            raise InputError("frame columns differ in length")
        if not (len(self.cand_uv) == len(self.cand_radius) == len(self.cand_score) == n_cand):
            raise InputError("candidate columns differ in length")
        if n_cand and (np.any(np.diff(self.cand_frame) < 0) or self.cand_frame[0] < 0
                       or self.cand_frame[-1] >= n_frames):
            raise InputError("cand_frame must be non-decreasing rows of the frame arrays")
        if n_frames and (self.frame_camera.min() < 0
                         or self.frame_camera.max() >= len(self.camera_names)):
            raise InputError("frame_camera out of range of camera_names")

    @property
    def n_frames(self) -> int:
        return len(self.frame_time_ns)

    @property
    def n_candidates(self) -> int:
        return len(self.cand_frame)

    def candidates_per_frame(self) -> np.ndarray:
        """(F,) int, number of candidates of each frame."""
        return np.bincount(self.cand_frame, minlength=self.n_frames)

    def best_mask(self) -> np.ndarray:
        """(C,) bool, True for the first (best) candidate of each frame."""
        first = np.ones(self.n_candidates, dtype=bool)
        first[1:] = self.cand_frame[1:] != self.cand_frame[:-1]
        return first

    def best(self) -> Observations:
        """The first (best) candidate of every frame that has one, as fusion input."""
        if self.n_candidates == 0:
            return Observations(np.zeros(0, np.int64), np.zeros(0, np.int32),
                                np.zeros((0, 2)), np.zeros(0, np.int64))
        first = self.best_mask()
        rows = self.cand_frame[first]
        return Observations(self.frame_time_ns[rows], self.frame_camera[rows],
                            self.cand_uv[first], self.frame_index[rows])

    @classmethod
    def from_frames(
        cls,
        camera_names: Sequence[str],
        frame_time_ns,
        frame_camera,
        frame_index,
        cand_frame,
        cand_uv,
        cand_radius=None,
        cand_score=None,
    ) -> Detections:
        """Build from unsorted frames; candidates refer to rows of the *given* frame order
        and are reordered by frame, then by descending score."""
        frame_time_ns = np.asarray(frame_time_ns, dtype=np.int64)
        frame_camera = np.asarray(frame_camera, dtype=np.int32)
        frame_index = np.asarray(frame_index, dtype=np.int64)
        cand_frame = np.asarray(cand_frame, dtype=np.int64)
        n_cand = len(cand_frame)
        cand_uv = np.asarray(cand_uv, dtype=np.float64).reshape(n_cand, 2)
        cand_radius = (np.full(n_cand, np.nan) if cand_radius is None
                       else np.asarray(cand_radius, dtype=np.float64))
        cand_score = (np.ones(n_cand) if cand_score is None
                      else np.asarray(cand_score, dtype=np.float64))
        if not (len(frame_camera) == len(frame_index) == len(frame_time_ns)):
            raise InputError("frame columns differ in length")
        # checked before remapping: a negative row would silently wrap to another frame
        if n_cand and (cand_frame.min() < 0 or cand_frame.max() >= len(frame_time_ns)):
            raise InputError("cand_frame must be rows of the frame arrays")
        order = np.lexsort((frame_camera, frame_time_ns))
        new_row = np.empty_like(order)
        new_row[order] = np.arange(len(order))
        cand_frame = new_row[cand_frame] if n_cand else cand_frame
        cand_order = np.lexsort((-cand_score, cand_frame))
        return cls(tuple(camera_names), frame_time_ns[order], frame_camera[order],
                   frame_index[order], cand_frame[cand_order], cand_uv[cand_order],
                   cand_radius[cand_order], cand_score[cand_order])

    @classmethod
    def from_observations(cls, camera_names: Sequence[str], obs: Observations,
                          score=None) -> Detections:
        """One frame with one candidate per observation (no empty frames)."""
        n = len(obs)
        return cls.from_frames(camera_names, obs.time_ns, obs.camera, obs.frame_index,
                               np.arange(n), obs.uv, None, score)


@dataclass(frozen=True, eq=False)
class Track:
    """A fused 3D trajectory: one point per output event, sorted by time.

    Attributes
    ----------
    method : str, fusion method name (``typeA``)
    time_ns : (n,) int64, the instant the point describes (a shutter time)
    position_world : (n, 3) float64, metres
    camera : (n,) int32, index of the camera whose shutter produced the point
    quality : mapping of name -> (n,) float64, per-point quality (see ``QUALITY_FIELDS``),
        NaN where not applicable
    dropped : mapping of reason -> count of the points the method made but dropped as
        geometrically invalid (``behind_camera``, ``outside_view``, ``parallel_rays``) or
        refused (``prediction_failed``, ``residual_failed``, ...); not kept by
        :meth:`select` (it describes the whole track). A stream's Track
        (:class:`~pslog.fusion.stream.StreamFuser`) counts the points dropped that became
        settled with its push: :meth:`concat` sums them to the batch's counts
    """

    method: str
    time_ns: np.ndarray
    position_world: np.ndarray
    camera: np.ndarray
    quality: Mapping[str, np.ndarray] = field(default_factory=dict)
    dropped: Mapping[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "time_ns", _frozen(self.time_ns, np.int64, (), "time_ns"))
        object.__setattr__(self, "position_world",
                           _frozen(self.position_world, np.float64, (3,), "position_world"))
        object.__setattr__(self, "camera", _frozen(self.camera, np.int32, (), "camera"))
        n = len(self.time_ns)
        quality = {k: _frozen(v, np.float64, (), k) for k, v in dict(self.quality).items()}
        if len(self.position_world) != n or len(self.camera) != n or any(
                len(v) != n for v in quality.values()):
            raise InputError(f"track {self.method!r}: columns differ in length")
        object.__setattr__(self, "quality", quality)
        object.__setattr__(self, "dropped",
                           {str(k): int(v) for k, v in dict(self.dropped).items()})

    def __len__(self) -> int:
        return len(self.time_ns)

    @classmethod
    def _of_frozen(cls, method: str, time_ns: np.ndarray, position_world: np.ndarray,
                   camera: np.ndarray, quality: dict[str, np.ndarray],
                   dropped: dict[str, int]) -> Track:
        """A Track of columns its maker has already made as :meth:`__post_init__` leaves
        them: read-only, C-contiguous, native int64 / float64 (n, 3) / int32 / float64,
        of one length; ``dropped`` str -> int. No check, no view: the streaming form of a
        method makes a Track per detection, and the checks cost more than its point
        (``tests/test_records.py`` compares with the checked constructor)."""
        track = object.__new__(cls)
        track.__dict__.update(method=method, time_ns=time_ns, position_world=position_world,
                              camera=camera, quality=quality, dropped=dropped)
        return track

    def select(self, mask_or_index) -> Track:
        return Track(self.method, self.time_ns[mask_or_index],
                     self.position_world[mask_or_index], self.camera[mask_or_index],
                     {k: v[mask_or_index] for k, v in self.quality.items()})

    @classmethod
    def concat(cls, parts: Sequence[Track]) -> Track:
        """One method's consecutive tracks (the outputs of a stream) as one: every column
        joined in order, ``dropped`` counts summed (empty parts' included), a quality column
        missing from a part NaN there. The quality columns are every part's, empty parts'
        too: parts that are all empty join to an empty track with the same columns (empty
        float64), so a writer downstream sees the same schema as with points. InputError on
        parts of different methods."""
        parts = list(parts)
        if not parts:
            raise InputError("no tracks to join")
        method = parts[0].method
        if any(p.method != method for p in parts):
            raise InputError(f"cannot join tracks of methods {sorted({p.method for p in parts})}")
        dropped: dict[str, int] = {}
        for p in parts:
            for k, n in p.dropped.items():
                dropped[k] = dropped.get(k, 0) + n
        full = [p for p in parts if len(p)]
        # (the columns of empty parts too: all-empty parts kept no column before session 31)
        keys = list(dict.fromkeys(k for p in parts for k in p.quality))
        if not full:
            return cls(method, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32),
                       {k: np.zeros(0) for k in keys}, dropped=dropped)
        quality = {k: np.concatenate([p.quality.get(k, np.full(len(p), np.nan)) for p in full])
                   for k in keys}
        return cls(method, np.concatenate([p.time_ns for p in full]),
                   np.concatenate([p.position_world for p in full]),
                   np.concatenate([p.camera for p in full]), quality, dropped=dropped)


def by_reason(counts: Mapping[str, int]) -> str:
    """``{reason: count}`` (e.g. ``Track.dropped``, the gate's rejections) in the commands'
    words: ``"contradicted 3, unconfirmed 2"``, in the mapping's order, zero counts left out;
    empty when there is none."""
    return ", ".join(f"{reason} {n}" for reason, n in counts.items() if n)


def point_keys(time_ns: np.ndarray, camera: np.ndarray) -> np.ndarray:
    """(n,) int64: each point's (or detection's) time and camera keyed as one integer
    (times < 2**55 ns, cameras < 256)."""
    return np.asarray(time_ns, dtype=np.int64) * 256 + np.asarray(camera, dtype=np.int64)


def matching_rows(keys: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each of ``keys`` (n,) the row of ``other`` (m,) with the same key (``other``'s
    keys unique; :func:`point_keys`) and whether there is one: ``(rows (n,) int64, found
    (n,) bool)``, ``rows`` meaningful where ``found``."""
    if not len(other):
        return np.zeros(len(keys), dtype=np.int64), np.zeros(len(keys), dtype=bool)
    order = np.argsort(other, kind="stable")
    at = np.minimum(np.searchsorted(other[order], keys), len(other) - 1)
    return order[at], other[order][at] == keys


@dataclass(frozen=True, eq=False)
class Truth:
    """Ground-truth ball positions of a simulated session.

    Attributes
    ----------
    time_ns : (n,) int64, strictly increasing
    position_world : (n, 3) float64, metres
    """

    time_ns: np.ndarray
    position_world: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "time_ns", _frozen(self.time_ns, np.int64, (), "time_ns"))
        object.__setattr__(self, "position_world",
                           _frozen(self.position_world, np.float64, (3,), "position_world"))
        if len(self.position_world) != len(self.time_ns):
            raise InputError("truth columns differ in length")
        if len(self.time_ns) > 1 and np.any(np.diff(self.time_ns) <= 0):
            raise InputError("truth times must be strictly increasing")

    def __len__(self) -> int:
        return len(self.time_ns)

    def at(self, time_ns: np.ndarray) -> np.ndarray:
        """Truth at ``time_ns`` (m,), linearly interpolated, shape (m, 3); NaN outside the
        sampled span. Exact at sampled times (the simulator samples every capture time)."""
        time_ns = np.asarray(time_ns, dtype=np.int64)
        if len(self.time_ns) == 0:
            return np.full((len(time_ns), 3), np.nan)
        inside = (time_ns >= self.time_ns[0]) & (time_ns <= self.time_ns[-1])
        every = bool(inside.all())
        t = time_ns if every else time_ns[inside]
        # (inside the span: hi within [0, n - 1])
        hi = np.searchsorted(self.time_ns, t, side="left")
        sampled = self.time_ns[hi] == t
        if sampled.all() and len(t):
            # every time a sample's (the simulator samples every capture time): the
            # interpolation below gives 0 * previous + 1 * sample, which is the sample
            # itself but where the sample is a zero (a negative zero after a positive
            # sample comes out positive) or the previous sample is not finite (NaN):
            # those rows are made by the interpolation itself, as before
            value = self.position_world[hi]
            redo = np.unique(np.flatnonzero(value.reshape(-1) == 0) // 3)
            if not np.isfinite(self.position_world).all():
                lo = np.maximum(hi - 1, 0)
                redo = np.union1d(redo, np.flatnonzero(
                    ~np.isfinite(self.position_world[lo]).all(axis=1)))
            if len(redo):
                value[redo] = self._interpolated(t[redo], hi[redo])
        else:
            value = self._interpolated(t, hi)
        if every:
            return value
        out = np.full((len(time_ns), 3), np.nan)
        out[inside] = value
        return out

    def _interpolated(self, t: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """The linear interpolation at times ``t`` within the span, ``hi`` the first sample
        at or after each."""
        lo = np.maximum(hi - 1, 0)
        t_lo, t_hi = self.time_ns[lo], self.time_ns[hi]
        span = (t_hi - t_lo).astype(np.float64)
        w = np.where(span > 0, (t - t_lo) / np.where(span > 0, span, 1.0), 1.0)
        return ((1 - w)[:, None] * self.position_world[lo]
                + w[:, None] * self.position_world[hi])
