"""Gating: choose the ball among each frame's candidates, before any fusion method runs.

Real detectors return more than the ball (a second orange object, a reflection, a shirt) and
miss it at times. Every method fuses :class:`~pslog.records.Observations` (one per frame);
this stage maps :class:`~pslog.records.Detections` (every candidate) to them, and records
every candidate it rejects with the reason (:class:`Rejections`). It is method-agnostic: the
registry's methods all fuse what it keeps (``pslog.fusion.fuse`` with ``gating=True``).

A candidate ``x`` of camera ``a`` at (corrected) time ``t`` is judged by three gates
(docs/methods.md, "Candidates and gating", has the equations and why these thresholds):

1. **Epipolar** (geometry of the rig, undistorted pixels, time-aware). For every other
   camera ``b``, its candidates of the frames nearest ``t`` are carried to ``t``: linearly
   interpolated between the frame before and the frame after (eq. (1) of the paper), or, in
   the causal form, extrapolated from the two latest frames at or before ``t``. Over every
   pair of candidates (one per frame), the distance of the carried point to ``x``'s
   epipolar line in ``b``, ``d_b = |l_b · [y(t), 1]|`` with ``l_b = F_ab x`` normalised, is
   compared with ``τ_b = epipolar_px + ½ A |t - t_0| |t - t_1|`` (the error a linear
   carry makes under an image acceleration of at most ``A``). ``b`` *supports* ``x`` when
   its best pair has ``d_b <= τ_b``. Of b's frames already decided, only the chosen candidate
   (and any only outscored) is carried, never one a gate rejected (:func:`_support_one`),
   once the stillness test can judge the frame (:func:`_can_judge`).
2. **Track** (ray-to-track distance). The points accepted so far (each candidate's rays
   crossed with its support's carried rays, least squares) over the last ``track_window_s``
   are fitted with a ballistic model (constant velocity plus gravity); the distance of
   ``x``'s viewing ray to the prediction ``p̂(t)`` must be at most ``track_m + Δv Δt``
   (``Δt``: time since the newest accepted point, ``Δv`` a kick's change of velocity).
3. **Motion model**. The point ``x`` makes with its support must lie in front of every
   camera that contributed, be reachable from the last accepted point at a ball's speed,
   ``|p - p_last| <= max_speed · Δt + track_m``, and not stand still: a point within
   ``static_m`` of its camera's earlier points over ``static_s`` is a static object (a second
   orange thing seen by every camera passes every epipolar test; it does not move); so is a
   pixel that stood still in its camera's image with its support coming and going, unless
   that camera's newest choice was there (it was following the ball: ``_static``'s ``lone``).

A candidate is accepted when the epipolar gate accepts it (some other camera supports it)
and the track and motion gates do not object, or when the track gate alone accepts it
firmly (its ray within ``track_alone_m`` of the prediction); one nothing can judge is kept
only in the session's first frames. Before the track first predicts, a choice one epipolar
line alone made while another camera denies it, or beside candidates that line refused (in
its frame, or at its pixel in its camera's frames of the last ``static_s``), is kept but
CONTESTED (:data:`CONTESTED`): in doubt, like a choice beside rejected ones, and so is its
camera's later choice at its pixel within ``static_s``. So is the session's first choice
when its camera's next two frames refuse what stands at its pixel (:func:`late_doubt`; the
stream waits for that verdict: :class:`StreamStart`). Offline (``smooth``), a choice made
before its camera could judge stillness is in doubt when its camera's next frames refuse
what stands at its pixel (:func:`unjudged_doubt`).
A candidate supported by two or more other cameras
whose rays meet (a point within ``track_m`` of each) is consistent in three views and is
accepted whatever the track says (that is how the track follows kicks and bounces); rays that
miss count as one support. Among a frame's accepted candidates the one with the most
supporting cameras, then the smallest cost (squared normalised residuals of the supporting
cameras, 1 for each other available camera, the track's, the stillness) is kept; the others
are rejected as ``outscored``. The detector's score is not used: a distractor may outscore
the ball. docs/methods.md has the whole rule.

Causality: :func:`gate` with ``causal=True`` decides a candidate at ``t`` from candidates at
or before ``t`` in (time, camera) order (plus ``wait_s`` for the methods that wait for the
tolerance) and from its own earlier decisions, so a causal method fed by it stays causal.
``causal=False`` (offline methods) also interpolates with the frame after ``t``.
"""

from __future__ import annotations

import functools
import itertools
import math
import sys
import threading
from bisect import bisect_left, bisect_right
from collections import deque
from dataclasses import dataclass
from itertools import pairwise
from typing import TYPE_CHECKING, Literal

import numpy as np

from ..errors import FusionError, InputError
from ..geometry import epipolar_lines, fundamental_matrices
from ..motion import MAX_BALL_SPEED_M_S, G
from ..records import NS, Detections, Observations
from ..rig import Rig
from ..timing import MAX_READOUT_TERM_NS, camera_parameters, true_times_ns
from ..timing import observations as timed_observations

if TYPE_CHECKING:
    from collections.abc import Callable

    from ._prepare import Prepared

#: Why a candidate was rejected (the ``reason`` codes of :class:`Rejections`).
REASONS = ("epipolar", "track", "motion", "outscored")
EPIPOLAR, TRACK, MOTION, OUTSCORED = range(4)
#: The ``reason`` code of a kept candidate whose choice is CONTESTED (-1: any other kept one):
#: chosen before the track first predicted, on fewer than two supports whose rays meet,
#: while another available camera denied it (its carried candidates off the line, or a
#: second support whose ray misses) or other candidates of its frame (or, within static_s,
#: one at its pixel in a frame of several of its camera: :func:`_refused_near`) were
#: refused: nothing but one epipolar line judged it (docs/methods.md, "A contested
#: start"). It is in doubt (:func:`doubt_variance`).
CONTESTED = -2
REASON_TEXT = {
    "epipolar": "no other camera's detections near that time lie near its epipolar line",
    "track": "its viewing ray passes too far from the track of the recent accepted points",
    "motion": "the point it makes is behind a camera, out of a ball's reach, or still (a "
              "static object: a ball slower than about 20 cm/s is not tracked)",
    "outscored": "another candidate of its frame fitted the gates better",
}


@dataclass(frozen=True)
class GatingOptions:
    """Thresholds of the gates (docs/methods.md explains each value).

    Attributes
    ----------
    epipolar_px : float, base epipolar distance accepted, pixels (detection noise of a few
        tenths of a pixel in two images, lens model residuals, a bounce between frames)
    accel_px_s2 : float, bound on the ball's image acceleration, pixels/s², for the error
        of carrying a candidate linearly to another time
    max_image_speed_px_s : float, pairs of candidates moving faster than this in an image
        are not one ball, pixels/s
    track_m : float, base ray-to-track distance accepted, metres
    track_jump_m_s : float, unmodelled change of velocity (a kick, a bounce) the track
        allowance grows with, per second since the newest accepted point, m/s
    track_window_s : float, accepted points older than this do not predict the track, s
    track_points : int, at most this many recent points fit the track (at least 3)
    max_speed_m_s : float, fastest ball, m/s
    loose_ratio : float, a candidate supported by one camera and within this many
        epipolar thresholds of every other camera gets twice the track allowance
    track_alone_m : float, a candidate no other camera confirms is still accepted when its
        ray passes this close to the track's prediction, metres (another camera that does not
        see the ball should not veto it)
    static_s, static_m : float, a candidate whose 3D point stays within ``static_m``
        metres of one of its camera's earlier candidates' in every frame of the last
        ``static_s`` seconds is a static object, not a ball in play (a ball slower than
        about 20 cm/s, 5 cm in 0.25 s, is not tracked)
    """

    epipolar_px: float = 8.0
    accel_px_s2: float = 6000.0
    max_image_speed_px_s: float = 1500.0
    track_m: float = 0.08
    track_jump_m_s: float = 6.0
    track_window_s: float = 0.12
    track_points: int = 6
    max_speed_m_s: float = MAX_BALL_SPEED_M_S
    loose_ratio: float = 2.0
    static_s: float = 0.25
    static_m: float = 0.05
    track_alone_m: float = 0.03

    def __post_init__(self) -> None:
        for name in ("epipolar_px", "accel_px_s2", "max_image_speed_px_s", "track_m",
                     "track_jump_m_s", "track_window_s", "max_speed_m_s", "loose_ratio", "static_s",
                     "static_m", "track_alone_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise FusionError(f"gating {name} must be a positive number, got {value!r}")
        if int(self.track_points) < 3:
            raise FusionError(f"gating track_points must be >= 3, got {self.track_points!r}")


@dataclass(frozen=True, eq=False)
class Rejections:
    """Every candidate the gating stage rejected, one row each, sorted by (time, camera).

    Attributes
    ----------
    frame_time_ns : (R,) int64, the candidate's frame's LOGGED time (as in the session)
    camera : (R,) int32, camera index in the rig
    frame_index : (R,) int64, the camera's frame counter
    uv : (R, 2) float64, the candidate's pixel, as detected (distorted)
    score : (R,) float64, the detector's score
    reason : (R,) int8, index into :data:`REASONS`
    """

    frame_time_ns: np.ndarray
    camera: np.ndarray
    frame_index: np.ndarray
    uv: np.ndarray
    score: np.ndarray
    reason: np.ndarray

    def __post_init__(self) -> None:
        for name, dtype in (("frame_time_ns", np.int64), ("camera", np.int32),
                            ("frame_index", np.int64), ("uv", np.float64),
                            ("score", np.float64), ("reason", np.int8)):
            value = np.ascontiguousarray(getattr(self, name), dtype=dtype)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        n = len(self.frame_time_ns)
        if self.uv.shape != (n, 2) or any(len(getattr(self, k)) != n for k in (
                "camera", "frame_index", "score", "reason")):
            raise ValueError("rejection columns differ in length")
        if n and (self.reason.min() < 0 or self.reason.max() >= len(REASONS)):
            raise ValueError("rejection reason out of range")

    def __len__(self) -> int:
        return len(self.frame_time_ns)

    def reason_names(self) -> list[str]:
        return [REASONS[r] for r in self.reason.tolist()]

    def counts(self) -> dict[str, int]:
        """Rejected candidates per reason (every reason, zeros included)."""
        found = np.bincount(self.reason, minlength=len(REASONS))
        return {name: int(found[i]) for i, name in enumerate(REASONS)}

    def frames_lost_to_epipolar(self, frame_keys: np.ndarray, per_frame: np.ndarray,
                                max_gap_s: float | None = None) -> int:
        """How many frames lost every candidate, one of them to the epipolar gate: the
        ball's own detections when the cameras' clocks are further apart than the gate
        allows (walk39), where a static object alone in a frame is rejected for ``motion``.

        With ``max_gap_s``, only those where another camera's frames with a candidate next
        before and after its logged time (within ``max_gap_s``, at least one) each held one
        not rejected for ``motion`` (something moving the gate could have paired it with):
        a frame whose ball no other camera saw then, the others holding a static object
        alone, lost no partner to the clocks
        (review39b: two cameras, the ball out of one's view for long stretches while a
        static object stays there lost a third of the frames on one clock).

        Parameters
        ----------
        frame_keys : (F,) int64, the session's frames' :func:`pslog.records.point_keys`
            (logged time, camera), unique
        per_frame : (F,) int, each frame's number of candidates
        max_gap_s : float, seconds (the gate's ``max_gap_s``); None: every such frame
        """
        from ..records import matching_rows, point_keys

        frame_keys, per_frame = np.asarray(frame_keys), np.asarray(per_frame)
        keys = point_keys(self.frame_time_ns, self.camera)
        frames, count = np.unique(keys, return_counts=True)
        rows, found = matching_rows(frames, frame_keys)
        lost = frames[found & (count == per_frame[rows])
                      & np.isin(frames, keys[self.reason == EPIPOLAR])]
        if max_gap_s is None or not len(lost):
            return len(lost)
        # each frame's candidates not rejected for motion (kept, or rejected otherwise)
        still, still_count = np.unique(keys[self.reason == MOTION], return_counts=True)
        rows, found = matching_rows(still, frame_keys)
        moving = per_frame.astype(np.int64)
        np.subtract.at(moving, rows[found], still_count[found])
        # (point_keys: time * 256 + camera)
        frame_time, frame_camera = frame_keys // 256, frame_keys % 256
        lost_time, lost_camera = lost // 256, lost % 256
        gap_ns = round(max_gap_s * NS)
        partnered = np.zeros(len(lost), dtype=bool)
        for cam in np.unique(frame_camera):
            mine = (frame_camera == cam) & (per_frame > 0)
            order = np.argsort(frame_time[mine], kind="stable")
            times, moves = frame_time[mine][order], (moving[mine] > 0)[order]
            other = np.flatnonzero(lost_camera != cam)
            if not len(times) or not len(other):
                continue
            t = lost_time[other]
            # its frames with a candidate next before (or at) and after each lost frame's
            # time, within the gap: the ones the gate pairs it with; each such one holding
            # something moving (a static object alone beside the ball missed: no partner)
            j = np.searchsorted(times, t, side="right")
            before = (j > 0) & (t - times[np.maximum(j - 1, 0)] <= gap_ns)
            after = (j < len(times)) & (times[np.minimum(j, len(times) - 1)] - t <= gap_ns)
            ok = ((~before | moves[np.maximum(j - 1, 0)])
                  & (~after | moves[np.minimum(j, len(times) - 1)]) & (before | after))
            partnered[other] |= ok
        return int(np.count_nonzero(partnered))

    @classmethod
    def empty(cls) -> Rejections:
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int64),
                   np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int8))

    @classmethod
    def from_rows(cls, rows) -> Rejections:
        """From ``(time_ns, camera, frame_index, u, v, score, reason name)`` tuples;
        ValueError on an unknown reason."""
        if not rows:
            return cls.empty()
        t, cam, idx, u, v, score, reason = zip(*rows, strict=True)
        unknown = sorted(set(reason) - set(REASONS))
        if unknown:
            raise ValueError(f"unknown rejection reason {unknown[0]!r} (have "
                             f"{', '.join(REASONS)})")
        code = {name: i for i, name in enumerate(REASONS)}
        return cls(np.array(t), np.array(cam), np.array(idx), np.column_stack([u, v]),
                   np.array(score), np.array([code[r] for r in reason]))


@dataclass(frozen=True, eq=False)
class Gated:
    """What :func:`gate` decided.

    Attributes
    ----------
    observations : Observations, the chosen candidate of every frame that kept one, at its
        corrected time (as :func:`pslog.timing.observations` makes them)
    rejections : Rejections
    chosen : (C,) bool over the detections' candidates, True for the kept ones
    reason : (C,) int8, the rejection reason of each candidate (< 0 for the kept ones:
        -1, or :data:`CONTESTED`)
    doubt_px2 : (n,) float64 over the observations, or None: the variance each choice adds
        for the chance it is wrong (:func:`choice_doubt`; None: no choice in doubt)
    """

    observations: Observations
    rejections: Rejections
    chosen: np.ndarray
    reason: np.ndarray
    doubt_px2: np.ndarray | None = None

    def kept(self, detections: Detections) -> Detections:
        """``detections`` with only the chosen candidates (every frame kept, at its LOGGED
        time; a frame whose candidates were all rejected holds none)."""
        return _chosen_candidates(detections, self.chosen)

    def rejected_frames(self, detections: Detections) -> int:
        """Frames that had candidates and kept none (rejected detections)."""
        had = detections.candidates_per_frame() > 0
        kept = np.zeros(detections.n_frames, dtype=bool)
        kept[detections.cand_frame[self.chosen]] = True
        return int(np.count_nonzero(had & ~kept))


@dataclass
class _Candidates:
    """Per-candidate geometry, columnar (C rows, the detections' candidate order)."""

    camera: np.ndarray       # (C,) int32
    time_ns: np.ndarray      # (C,) int64, corrected
    uv_und: np.ndarray       # (C, 2) undistorted pixels
    ray_dir: np.ndarray      # (C, 3) unit, world
    frame: np.ndarray        # (C,) the candidate's frame row


def _candidates(detections: Detections, rig: Rig) -> _Candidates:
    if tuple(detections.camera_names) != rig.names:
        raise FusionError(f"detections of cameras {', '.join(detections.camera_names)} do not "
                          f"match the rig's {', '.join(rig.names)} (names and order)")
    frame = detections.cand_frame
    camera = detections.frame_camera[frame]
    p = camera_parameters(rig)
    time_ns = true_times_ns(detections.frame_time_ns[frame], detections.cand_uv[:, 1],
                            p["height"][camera], p["clock_offset"][camera],
                            p["clock_drift_ppm"][camera], p["readout"][camera])
    uv_und = np.full((len(frame), 2), np.nan)
    ray_dir = np.full((len(frame), 3), np.nan)
    for i, cam in enumerate(rig.cameras):
        rows = np.flatnonzero(camera == i)
        if len(rows):
            uv_und[rows], ray_dir[rows] = _pixel_geometry(cam, detections.cand_uv[rows])
    return _Candidates(camera, time_ns, uv_und, ray_dir, frame)


def _pixel_geometry(cam, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undistorted pixels (n, 2) and unit world viewing rays (n, 3) of one camera's
    distorted pixels ``uv`` (n, 2); NaN for a pixel far outside the image (a damaged file).
    Elementwise (:func:`_from_normalized`): the stream's floats give the same bits."""
    uv_und = np.full((len(uv), 2), np.nan)
    ray_dir = np.full((len(uv), 3), np.nan)
    sane = np.all(np.abs(uv) <= 10 * max(cam.width, cam.height), axis=1)
    if sane.any():
        xy = cam.undistort_normalized(uv[sane])
        with np.errstate(invalid="ignore"):
            u, v, *d = _from_normalized(xy[:, 0], xy[:, 1], cam.K.tolist(), cam.R.tolist(),
                                        np.sqrt, np.maximum)
        uv_und[sane] = np.column_stack([u, v])
        ray_dir[sane] = np.column_stack(d)
    return uv_und, ray_dir


def _from_normalized(x, y, k, r, sqrt, maximum):
    """Undistorted pixel ``(u, v)`` (through ``K``) and unit world viewing ray
    ``(dx, dy, dz)`` (``Rᵀ [x, y, 1]``, scaled by its largest component first: a far-off
    pixel's ray would overflow) of ideal normalized coordinates; floats, or arrays
    elementwise, every sum in index order: the same bits (``k``, ``r``: nested lists;
    ``sqrt``, ``maximum``: math's and max, or numpy's)."""
    u = (k[0][0] * x + k[0][1] * y) + k[0][2]
    v = k[1][1] * y + k[1][2]
    s = maximum(maximum(abs(x), abs(y)), 1.0)
    cx, cy, cz = x / s, y / s, 1.0 / s
    dx = (cx * r[0][0] + cy * r[1][0]) + cz * r[2][0]
    dy = (cx * r[0][1] + cy * r[1][1]) + cz * r[2][1]
    dz = (cx * r[0][2] + cy * r[1][2]) + cz * r[2][2]
    size = sqrt((dx * dx + dy * dy) + dz * dz)
    return u, v, dx / size, dy / size, dz / size


def _epipolar_line(f, u, v, sqrt, maximum):
    """The epipolar line ``(a, b, c)``, ``a² + b² = 1``, of an undistorted pixel ``(u, v)``
    (``f``: F_ab as nested lists) as :func:`pslog.geometry.epipolar_lines` defines it;
    floats, or arrays elementwise, every sum in index order: the same bits."""
    a = (f[0][0] * u + f[0][1] * v) + f[0][2]
    b = (f[1][0] * u + f[1][1] * v) + f[1][2]
    c = (f[2][0] * u + f[2][1] * v) + f[2][2]
    big = maximum(abs(a), abs(b))  # (scaled first: the norm alone could overflow)
    a, b, c = a / big, b / big, c / big
    size = sqrt(a * a + b * b)
    return a / size, b / size, c / size


def epipolar_distance(F_ab: np.ndarray, uv_a: np.ndarray, uv_b: np.ndarray) -> np.ndarray:
    """Distance, pixels (n,), of undistorted pixels ``uv_b`` (n, 2) of camera b from the
    epipolar lines of ``uv_a`` (n, 2) of camera a (``F_ab``: ``x_bᵀ F_ab x_a = 0``, as
    :func:`pslog.geometry.fundamental_matrix`): ``|l · [u_b, v_b, 1]|`` with
    ``l = F_ab [u_a, v_a, 1]`` scaled to ``l_1² + l_2² = 1``. The gate's measure."""
    lines = epipolar_lines(F_ab, np.asarray(uv_a, dtype=np.float64))
    uv_b = np.asarray(uv_b, dtype=np.float64)
    return np.abs(lines[:, 0] * uv_b[:, 0] + lines[:, 1] * uv_b[:, 1] + lines[:, 2])


def _frame_table(c: _Candidates, n_cams: int):
    """Per camera: its frames with candidates, their times (the first, best candidate's
    corrected time) and a padded (frames, K) table of candidate rows (-1 padding)."""
    out = []
    k_max = 1
    if len(c.frame):
        k_max = int(np.max(np.unique(c.frame, return_counts=True)[1]))
    for i in range(n_cams):
        rows = np.flatnonzero(c.camera == i)
        frames, first, counts = np.unique(c.frame[rows], return_index=True, return_counts=True)
        first_rows = rows[first]
        times = c.time_ns[first_rows]
        order = np.lexsort((frames, times))
        frames, first_rows, counts, times = (frames[order], first_rows[order], counts[order],
                                             times[order])
        table = np.full((len(frames), k_max), -1, dtype=np.int64)
        for k in range(k_max):
            has = counts > k
            table[has, k] = first_rows[has] + k  # candidates of a frame are contiguous
        out.append((times, table))
    return out


def _support(c: _Candidates, rig: Rig, F: np.ndarray, tables, options: GatingOptions,
             max_gap_ns: int, causal: bool, wait_ns: int, only: np.ndarray | None = None,
             compiled: bool | None = None):
    """Epipolar support of every candidate by every other camera (``compiled``: by
    :func:`pslog.fusion._gate_kernel.support_all`, the same bits; None: where that module is
    loaded).

    Returns
    -------
    ratio : (C, m) float, best ``d_b / τ_b`` of camera b (NaN: b has no frame near; inf:
        frames but no plausible pair)
    carried : (C, m, 2) undistorted pixel of b's best pair carried to the candidate's time
    used : (C, m, 3) int, the positions in b's frame table of the frames the rule looked at
        (the two latest at or before the candidate's time and the first after; -1: none):
        this all-candidates support is the decided one (:func:`_support_one`) as long as
        none of them has been decided with a rejected candidate
    """
    n, m = len(c.camera), len(rig)
    ratio = np.full((n, m), np.nan)
    carried = np.full((n, m, 2), np.nan)
    used = np.full((n, m, 3), -1, dtype=np.int64)
    accel, vmax = options.accel_px_s2, options.max_image_speed_px_s
    # loaded (pslog fuse preloads it): the compiled rule, one candidate at a time in this
    # function's order of operations (the same bits, ~10 times faster); a light command
    # never waits for numba here
    if compiled is None:
        compiled = _kernels_ready()
    compiled = compiled and n > 0
    if compiled:
        from ._gate_kernel import support_all

        t_all = np.ascontiguousarray(c.time_ns, dtype=np.int64)
        uv_all = np.ascontiguousarray(c.uv_und, dtype=np.float64)
    for a in range(m):
        rows = np.flatnonzero((c.camera == a) if only is None else (c.camera == a) & only)
        if len(rows) == 0:
            continue
        t = c.time_ns[rows]
        for b in range(m):
            if b == a:
                continue
            times, table = tables[b]
            if len(times) == 0:
                continue
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                lines = np.column_stack(_epipolar_line(F[a, b].tolist(), c.uv_und[rows, 0],
                                                       c.uv_und[rows, 1], np.sqrt,
                                                       np.maximum))
            if compiled:
                support_all(rows, b, t_all, uv_all, np.ascontiguousarray(lines),
                            np.ascontiguousarray(times, dtype=np.int64),
                            np.ascontiguousarray(table, dtype=np.int64), causal,
                            wait_ns > 0 or b < a, wait_ns, max_gap_ns,
                            float(options.epipolar_px), float(vmax), float(0.5 * accel),
                            ratio, carried, used)
                continue
            if causal:
                # b's frames a causal choice at t may use: (time, camera) order, or up to
                # t + wait for the methods that wait for the tolerance
                limit = t + wait_ns
                side: Literal["left", "right"] = "right" if (wait_ns > 0 or b < a) else "left"
                last = np.searchsorted(times, limit, side=side) - 1
                i1, i0 = last, last - 1
                inext = np.full(len(rows), -1)
            else:
                last = np.searchsorted(times, t, side="right") - 1
                i1, i0 = last, last - 1
                inext = np.where(last + 1 < len(times), last + 1, -1)
            used[rows, b, 0], used[rows, b, 1], used[rows, b, 2] = i0, i1, inext
            best = np.full(len(rows), np.inf)
            best_uv = np.full((len(rows), 2), np.nan)
            near = np.zeros(len(rows), dtype=bool)
            # interpolation between the frames around t, else extrapolation from the two
            # latest at or before it
            for extrapolate, (first, second) in enumerate(((i1, inext), (i0, i1))):
                ok = (first >= 0) & (second >= 0)
                ok &= np.abs(t - times[np.maximum(first, 0)]) <= max_gap_ns
                ok &= np.abs(t - times[np.maximum(second, 0)]) <= max_gap_ns
                if extrapolate:  # only where no interpolation was possible
                    ok &= inext < 0
                near[ok] = True
                # (in blocks of candidates: each holds K² pairs, K the most candidates a
                # frame has, which a crowded session makes many: 50 a frame held GBs)
                every = np.flatnonzero(ok)
                block = max(1, _SUPPORT_PAIRS // max(1, table.shape[1] ** 2))
                for idx in (every[k:k + block] for k in range(0, len(every), block)):
                    _support_pairs(idx, first, second, table, t, c, lines, best, best_uv,
                                   vmax, accel, options)
            # a single nearby frame (the other camera missed the one before): its candidates
            # as they are, allowing the image motion a ball can make since
            single = ~near & (i1 >= 0)
            single &= np.abs(t - times[np.maximum(i1, 0)]) <= max_gap_ns
            every = np.flatnonzero(single)
            near[every] = True
            block = max(1, _SUPPORT_PAIRS // max(1, table.shape[1]))
            for idx in (every[k:k + block] for k in range(0, len(every), block)):
                r1 = table[i1[idx]]
                y = c.uv_und[np.maximum(r1, 0)]
                dt = np.abs(t[idx][:, None] - c.time_ns[np.maximum(r1, 0)]) / NS
                tau = options.epipolar_px + vmax * dt
                ln = lines[idx][:, None, :]
                d = np.abs(ln[..., 0] * y[..., 0] + ln[..., 1] * y[..., 1] + ln[..., 2])
                r = np.where((r1 >= 0) & np.isfinite(d), d / tau, np.inf)
                k = np.argmin(r, axis=1)
                best[idx] = r[np.arange(len(idx)), k]
                best_uv[idx] = y[np.arange(len(idx)), k]
            ratio[rows[near], b] = best[near]
            carried[rows, b] = best_uv
    return ratio, carried, used


#: False: :func:`_decide_in_order` foresees no frame that may be emptied (:func:`_emptied`),
#: so every one emptied makes the choice again (tests check the same choices come out)
FORESEE_EMPTIED = True

#: choices :func:`_decide_in_order` makes again for frames emptied that it did not foresee
#: before it foresees every frame (then the next pass is the last: a bound; on dirty
#: sessions it foresees them all in one pass, and with none foreseen (``FORESEE_EMPTIED``
#: False) two passes or three found them)
_MAX_PASSES = 3

#: frames that may be emptied (:func:`_emptied`) up to which :func:`_decide_pass` marks
#: the frames whose support used one span by span (beyond, over every frame at once)
_FEW_SPANS = 256

#: candidate pairs :func:`_support`'s numpy form holds at once (a block of candidates, each
#: with K² pairs of another camera's two frames; ~100 bytes a pair)
_SUPPORT_PAIRS = 1 << 20


def _support_pairs(idx, first, second, table, t, c: _Candidates, lines, best, best_uv, vmax,
                   accel, options: GatingOptions) -> None:
    """:func:`_support`'s interpolation (or extrapolation) between camera b's frames
    ``first[idx]`` and ``second[idx]`` for the candidates ``idx`` of camera a: lowers
    ``best[idx]`` to each one's best ratio, ``best_uv[idx]`` to that pair's carried pixel."""
    r0 = table[first[idx]]  # (k, K)
    r1 = table[second[idx]]
    valid = (r0[:, :, None] >= 0) & (r1[:, None, :] >= 0)
    y0 = c.uv_und[np.maximum(r0, 0)][:, :, None, :]
    y1 = c.uv_und[np.maximum(r1, 0)][:, None, :, :]
    t0 = c.time_ns[np.maximum(r0, 0)][:, :, None]
    t1 = c.time_ns[np.maximum(r1, 0)][:, None, :]
    span = (t1 - t0) / NS
    tt = t[idx][:, None, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(span != 0, (tt - t0) / NS / np.where(span != 0, span, 1), 0.0)
        y = y0 + w[..., None] * (y1 - y0)
        speed = np.linalg.norm(y1 - y0, axis=-1) / np.abs(span)
    valid &= (span > 0) & (speed <= vmax)
    tau = options.epipolar_px + 0.5 * accel * np.abs(tt - t0) / NS * np.abs(tt - t1) / NS
    ln = lines[idx][:, None, None, :]
    d = np.abs(ln[..., 0] * y[..., 0] + ln[..., 1] * y[..., 1] + ln[..., 2])
    r = np.where(valid & np.isfinite(d), d / tau, np.inf).reshape(len(idx), -1)
    k = np.argmin(r, axis=1)
    rk = r[np.arange(len(idx)), k]
    better = rk < best[idx]
    best[idx[better]] = rk[better]
    best_uv[idx[better]] = y.reshape(len(idx), -1, 2)[np.arange(len(idx)), k][better]


def _support_one(t: int, line, keys: list[int], usable, search, wait_ns: int, causal: bool,
                 gap_ns: int, options: GatingOptions):
    """:func:`_support`'s rule for one candidate (at corrected time ``t``, its epipolar
    ``line`` in camera b) and one other camera b, on floats, over the candidates of b's
    frames as decided so far (:func:`_supporting`): a frame decided with a chosen candidate
    supports with it (and any only outscored), not with those a gate rejected (a static
    object, a blob: no evidence for a later choice; carried with the ball's track they made
    a wrong point that entered the track); a frame not decided yet, or decided with none
    chosen, with every candidate (that the gate found no ball in it says nothing about which
    candidate is the ball; dropping them too made rejections self-sustaining: no support,
    so nothing chosen, so no support); nor a frame the stillness test cannot judge yet
    (:func:`_can_judge`: a static object may have been chosen and the ball rejected).
    The decisions are sequential, so this is computed when the candidate's frame is decided.

    ``keys``: b's frame times in frame-table order; ``usable(j)``: the candidates of b's
    frame ``j`` that may support, a list of (corrected time ns, undistorted u, v);
    ``search``: ``bisect_right`` (b's frames at ``t`` + wait count) or ``bisect_left``.
    Returns (ratio: NaN when b has no usable frame near ``t``, carried (u, v) or None).
    """
    epi, vmax = options.epipolar_px, options.max_image_speed_px_s
    half_accel = 0.5 * options.accel_px_s2
    l0, l1, l2 = line
    last = search(keys, t + (wait_ns if causal else 0)) - 1
    i1 = last
    while i1 >= 0 and not usable(i1):
        i1 -= 1
    i0 = i1 - 1
    while i0 >= 0 and not usable(i0):
        i0 -= 1
    inext = -1
    if not causal:
        inext = last + 1
        while inext < len(keys) and not usable(inext):
            inext += 1
        if inext == len(keys):
            inext = -1

    def near(j):
        return j >= 0 and abs(t - keys[j]) <= gap_ns

    pair = (i1, inext) if inext >= 0 else (i0, i1)
    if near(pair[0]) and near(pair[1]):
        # carried linearly between the two frames (interpolated or extrapolated)
        best, best_uv = math.inf, None
        later = usable(pair[1])
        for t0, u0, v0 in usable(pair[0]):
            for t1, u1, v1 in later:
                span = (t1 - t0) / NS
                if not span > 0:
                    continue
                w = (t - t0) / NS / span
                du, dv = u1 - u0, v1 - v0
                yu, yv = u0 + w * du, v0 + w * dv
                if not math.sqrt(du * du + dv * dv) / abs(span) <= vmax:
                    continue
                tau = epi + half_accel * abs(t - t0) / NS * abs(t - t1) / NS
                d = abs(l0 * yu + l1 * yv + l2)
                if math.isfinite(d) and d / tau < best:  # argmin: the first
                    best, best_uv = d / tau, (yu, yv)
        return best, best_uv
    if near(i1):  # a single nearby frame (no pair near), its candidates as they are
        best, best_uv = math.inf, None
        for t1, u1, v1 in usable(i1):
            tau = epi + vmax * (abs(t - t1) / NS)
            d = abs(l0 * u1 + l1 * v1 + l2)
            r = d / tau if math.isfinite(d) else math.inf
            if best_uv is None or r < best:
                best, best_uv = r, (u1, v1)
        return best, best_uv
    return math.nan, None


def _static(c: _Candidates, tables, rig: Rig, options: GatingOptions,
            points: np.ndarray, paired: np.ndarray | None = None,
            compiled: bool | None = None,
            held: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which candidates stood still in space: each one's 3D point (its ray crossed with its
    support's) within ``static_m`` of a candidate's point in each of its camera's earlier
    frames; or, for a candidate whose point rests on one other camera (``paired``), its
    pixel within ``static_m`` across its ray (:func:`_still_px`) of a candidate's pixel
    there, unless that support held in every one of those frames (:func:`_still_alone`)
    and no longer than a ball in flight can stay that still (:func:`_still_long`).
    (Still in one image is not enough in general: a ball moving along a camera's ray is.
    But one other camera fixes the point's depth by a single epipolar constraint, which a
    static object seen by this camera alone meets whenever the ball crosses its epipolar
    line: its points then run along its ray, however still it is, and with no third camera
    to deny them they make a track. Such a crossing ends; a ball moving along the ray is
    supported in every frame. Two or more supports whose rays meet fix the point in 3D,
    and the 3D test judges it.) Causal: only earlier frames of the same camera.

    Returns
    -------
    static : (C,) bool, still in three quarters of the frames of the last ``static_s`` (as
        many frames as the camera's rate gives, within 1.5 ``static_s``): a static object
        seen by several cameras (a second orange thing, a lamp), not a ball in play
    stillness : (C,) float in [0, 1], the share of those frames, back from the newest,
        it was still in (a candidate that has not moved yet is the less likely ball)
    lone : (C,) float, pixels: where the image test's verdict (:func:`_still_alone`) holds
        for a candidate whatever supports it (its pixel within its own ``f static_m / D``
        of one in every one of the ``static_s`` frames, its support not continuous), that
        tolerance; NaN elsewhere. A candidate without a point takes the tolerance of a point
        known at its pixel (:func:`_borrowed_tolerance`), and either image test's verdict
        (:func:`_still_alone`, :func:`_still_long`) makes it lone. Such a candidate is kept only
        where its camera's own previous frame chose a candidate within it
        (:meth:`_Decider.decide`: a ball arriving at a static object's pixel)

    ``compiled``: by :func:`pslog.fusion._gate_kernel.static_camera` (the same values);
    None: where that module is loaded. ``held`` (C,) bool: whether each candidate's support
    held (:func:`_held`; None: whether it has a point), what the image test's continuity
    (:func:`_still_alone`) counts of the earlier frames' still pixels.
    """
    static = np.zeros(len(c.camera), dtype=bool)
    stillness = np.zeros(len(c.camera))
    lone = np.full(len(c.camera), np.nan)
    # (C,) whether each candidate's support held (by default: whether it has a point)
    finite = np.isfinite(points).all(axis=-1) if held is None else np.asarray(held, dtype=bool)
    if compiled is None:
        compiled = _kernels_ready()
    if compiled and len(c.camera):
        from ._gate_kernel import static_camera

        pts = np.ascontiguousarray(points, dtype=np.float64)
        uv = np.ascontiguousarray(c.uv_und, dtype=np.float64)
        pair_of = (np.zeros(len(c.camera), dtype=bool) if paired is None
                   else np.ascontiguousarray(paired, dtype=bool))
        dz = np.ascontiguousarray(c.ray_dir[:, 2], dtype=np.float64)
        for b, (times, table) in enumerate(tables):
            cam = rig.cameras[b]
            long_lags = int(np.ceil(LONG_STILL * options.static_s * cam.fps))
            static_camera(np.ascontiguousarray(times, dtype=np.int64),
                          np.ascontiguousarray(table, dtype=np.int64), pts, uv, finite,
                          pair_of, dz, int(np.ceil(options.static_s * cam.fps)), long_lags,
                          1.5 * options.static_s * NS, 1.5 * LONG_STILL * options.static_s * NS,
                          min(float(cam.K[0, 0]), float(cam.K[1, 1])) * options.static_m,
                          np.ascontiguousarray(cam.center_world, dtype=np.float64),
                          long_lags / cam.fps,
                          float(options.static_m), LONG_STILL_C, G, static, stillness,
                          lone)
        return static, stillness, lone
    for b, (times, table) in enumerate(tables):
        lags = int(np.ceil(options.static_s * rig.cameras[b].fps))
        long_lags = int(np.ceil(LONG_STILL * options.static_s * rig.cameras[b].fps))
        run_long = np.zeros(table.shape)
        run = np.zeros(table.shape)
        p = points[np.maximum(table, 0)]  # (frames, K, 3)
        y = c.uv_und[np.maximum(table, 0)]  # (frames, K, 2)
        p_finite = finite[np.maximum(table, 0)]  # (frames, K)
        with np.errstate(invalid="ignore", divide="ignore"):
            tol = _still_px(rig.cameras[b], p[..., 0], p[..., 1], p[..., 2], options,
                            np.sqrt)
        # each candidate's own tolerance (NaN without a point): the long test's pair of
        # frames takes the smaller of the two (_still_long); the image test's counts are
        # made with it for every candidate (its verdict: static where paired, else lone)
        own = tol.copy()
        if paired is None:
            tol[:] = np.nan
        else:
            tol[~paired[np.maximum(table, 0)]] = np.nan
        # the image test's counts of a candidate without a point are made with the
        # tolerance of a point known at its pixel (:func:`_borrowed_tolerance`)
        own_px = _borrowed_tolerance(times, table, y, own, lags, options)
        # and its long test too, as a paired one's (its verdict: lone, not static)
        borrowed = np.isnan(own) & ~np.isnan(own_px)
        tol[borrowed] = own_px[borrowed]
        run_px = np.zeros(table.shape)
        held = np.zeros(table.shape)
        for lag in range(1, min(long_lags, len(times) - 1) + 1):
            prev = np.full(table.shape, -1)
            prev[lag:] = table[:-lag]
            if lag > lags:  # the long image test's frames only
                recent = np.zeros(len(times), dtype=bool)
                recent[lag:] = (times[lag:] - times[:-lag]
                                <= 1.5 * LONG_STILL * options.static_s * NS)
                yy = _lagged(y, lag, c.uv_und[0])  # c.uv_und[max(prev, 0)]
                with np.errstate(invalid="ignore"):
                    du = y[:, :, None, 0] - yy[:, None, :, 0]
                    dv = y[:, :, None, 1] - yy[:, None, :, 1]
                    d_px = np.sqrt(du * du + dv * dv)
                    run_long += recent[:, None] & _still_pair(
                        d_px, tol, _lagged(own, lag, own[0]), prev[:, None, :] >= 0)
                continue
            # the lag frames must lie within 1.5 static_s: missed frames do not count
            recent = np.zeros(len(times), dtype=bool)
            recent[lag:] = times[lag:] - times[:-lag] <= 1.5 * options.static_s * NS
            recent_long = np.zeros(len(times), dtype=bool)
            recent_long[lag:] = (times[lag:] - times[:-lag]
                                 <= 1.5 * LONG_STILL * options.static_s * NS)
            # points[max(prev, 0)] and c.uv_und[max(prev, 0)]: the frames' rows shifted
            pp = _lagged(p, lag, points[0])
            yy = _lagged(y, lag, c.uv_und[0])
            with np.errstate(invalid="ignore"):
                d = np.linalg.norm(p[:, :, None, :] - pp[:, None, :, :], axis=-1)
                du = y[:, :, None, 0] - yy[:, None, :, 0]
                dv = y[:, :, None, 1] - yy[:, None, :, 1]
                d_px = np.sqrt(du * du + dv * dv)
            valid = prev[:, None, :] >= 0
            d = np.where(valid & np.isfinite(d), d, np.inf).min(axis=2)
            with np.errstate(invalid="ignore"):
                # a still pixel there whose own support held too (its point, or _held's)
                near = valid & (d_px <= own_px[:, :, None])
            held += recent[:, None] & np.any(
                near & _lagged(p_finite, lag, finite[0])[:, None, :], axis=2)
            d_px_pair = d_px
            d_px = np.where(valid & np.isfinite(d_px), d_px, np.inf).min(axis=2)
            run += recent[:, None] & (d <= options.static_m)
            with np.errstate(invalid="ignore"):
                run_px += recent[:, None] & (d_px <= own_px)
                run_long += recent_long[:, None] & _still_pair(
                    d_px_pair, tol, _lagged(own, lag, own[0]), valid)
        ok = table >= 0
        stillness[table[ok]] = run[ok] / lags
        # still in most of them: one frame whose point a coincidence spoiled does not count;
        # across the ray, in every one of them (a static object's pixel is in every frame)
        dz = c.ray_dir[np.maximum(table, 0), 2]
        with np.errstate(invalid="ignore"):
            long = _still_long(run_long, dz, long_lags, rig.cameras[b].fps, options, np.sqrt)
        alone = _still_alone(run_px, held, lags)
        judged = ok & ~borrowed
        static[table[judged & ((run >= 0.75 * lags) | (alone & ~np.isnan(tol)) | long)]] = True
        lone_px = ok & (alone | (borrowed & long))
        lone[table[lone_px]] = own_px[lone_px]
    return static, stillness, lone


def _borrowed_tolerance(times, table, y, own, lags: int, options: GatingOptions):
    """(frames, K): each candidate's image tolerance for :func:`_static`'s image test
    (``own``, its :func:`_still_px`), and for one without a point (NaN there: the 3D and
    paired tests cannot judge it) the tolerance of a point known at its pixel: the smallest
    ``own`` of the candidates of its camera's newest frame within ``static_s`` (of the
    test's ``lags``, within 1.5 ``static_s``) that lie within their own tolerance of it;
    NaN where none does. A static object whose support comes and goes has no point in the
    frames where the rays do not meet (the ball seen by one other camera, kicked between
    its two frames: ``paper3``, ``bench_dirty.py --more --first-seed 72300``,
    ``rally-72307`` at 6.34 s; judged static in the frames before and after, the object
    was chosen there, and ``smooth`` made 8 points 4.3-4.9 m off at a ``std_m`` of 2-9 mm).
    Its pixel stands where its point stood, so the image tests judge it with that point's
    tolerance: :func:`_still_alone` (its support not continuous) and :func:`_still_long`
    (still longer than a ball in flight can be: the ball ran along the object's epipolar line
    for 0.3 s there, and a blob of the third camera, carried, supported it too), and either
    verdict makes it ``lone`` (kept only where its camera followed the ball to that pixel),
    not static: its depth is not known. ``times`` (frames,) ns, ``table`` (frames, K)
    candidate rows (-1 padding), ``y`` (frames, K, 2) undistorted pixels."""
    out = own.copy()
    need = np.isnan(own) & (table >= 0)
    for lag in range(1, min(lags, len(times) - 1) + 1):
        if not need.any():
            break
        recent = np.zeros(len(times), dtype=bool)
        recent[lag:] = times[lag:] - times[:-lag] <= 1.5 * options.static_s * NS
        prev = np.full(table.shape, -1)
        prev[lag:] = table[:-lag]
        yy = _lagged(y, lag, y[0])
        prev_own = _lagged(own, lag, own[0])[:, None, :]
        with np.errstate(invalid="ignore"):
            du = y[:, :, None, 0] - yy[:, None, :, 0]
            dv = y[:, :, None, 1] - yy[:, None, :, 1]
            d_px = np.sqrt(du * du + dv * dv)
            reach = (prev[:, None, :] >= 0) & (d_px <= prev_own)
        found = np.where(reach, prev_own, np.inf).min(axis=2)
        fill = need & recent[:, None] & (found < np.inf)
        out[fill] = found[fill]
        need &= ~fill
    return out



def _lagged(rows: np.ndarray, lag: int, fill) -> np.ndarray:
    """``rows`` (frames, ...) of a camera's frames ``lag`` frames back: row ``f`` is row
    ``f - lag``, the first ``lag`` rows ``fill`` (what gathering at a frame table shifted by
    ``lag``, -1 clipped to row 0, gives; those rows count for nothing)."""
    out = np.empty_like(rows)
    out[lag:] = rows[:-lag]
    out[:lag] = fill
    return out

def _still_pair(d_px, tol, tol_prev, valid):
    """The long image test's frame (:func:`_static`): (frames, K) whether some candidate of
    the earlier frame (``valid``, (frames, 1, K')) lies within the smaller tolerance of the
    pair: ``tol`` (frames, K) the candidate's own (:func:`_still_px`, NaN: no image test),
    ``tol_prev`` (frames, K') the earlier candidate's (NaN without a point: ``tol``), at
    pixel distance ``d_px`` (frames, K, K'). (A motion ``e`` across the ray at the earlier
    point's depth ``D'`` moves the image by ``f e / D'``: with the newest depth alone a ball
    coming towards the camera looked still while it moved ``static_m D' / D`` across its
    ray, more than ``_still_long``'s bound: a lob along a steep camera's ray.)"""
    pair = tol[:, :, None]
    prev = tol_prev[:, None, :]
    pair = np.where(prev < pair, prev, pair)  # Python's min(tol, tol_prev); NaN tol stays
    return np.any(valid & (d_px <= pair), axis=2)


def _still_alone(run_px, held, lags: int):
    """The image test's verdict (:func:`_static`; arrays elementwise or floats): still
    across its ray in every one of the ``lags`` frames (``run_px``), and its support not
    continuous there: held (a still pixel whose own support held: :func:`_held`) in fewer
    than all but one of them (``held``). A static object seen by one camera is supported
    only while the ball crosses its epipolar line in the other (a slow crossing lasted
    4-6 of 8 frames in ``bench_dirty.py --more``); a ball moving along its camera's ray
    is supported in every frame (its partner slides along that line), and is still in
    its image too; one frame whose point a coincidence spoiled does not count (a camera
    going blind made one ball point's rays miss: 8 ball detections lost on wide3)."""
    return (run_px >= lags) & (held < lags - 1)


#: The long image test's window, in ``static_s`` (:func:`_still_long`).
LONG_STILL = 2.0
#: ``min over v of max over s in [0, T] of |v s - g s² / 2|`` is ``LONG_STILL_C g T²``, the
#: least a ball under an acceleration ``g`` across its ray moves across it in ``T``:
#: ``(√2 - 1)² / 2`` (equal ripple at the turning point ``s = v/g`` and at ``s = T``).
LONG_STILL_C = (math.sqrt(2.0) - 1.0) ** 2 / 2.0


def _still_long(run_long, dz, frames: int, fps: float, options: GatingOptions, sqrt):
    """The long image test (:func:`_static`; arrays elementwise or floats): still across its
    ray in every one of the ``frames`` frames of the last ``LONG_STILL static_s``
    (``run_long``), longer than a ball in flight can be: gravity's component across the
    ray, ``g⊥ = G sqrt(1 - dz²)`` (``dz``: the ray's world z), moves it across the ray by
    at least ``LONG_STILL_C g⊥ T²`` in ``T = frames / fps``, whatever its velocity; beyond
    ``static_m`` it is not a ball moving along the ray, however continuous its support (a
    ball sliding along a static object's epipolar line in the other camera supported the
    object in every frame for 0.53 s: paper2, bench_dirty.py --more --first-seed 500,
    rally-501 at 5.55-6.08 s). Rays near vertical keep the
    exemption (a ball falling along them can stay that still; 14 degrees at 30 fps)."""
    t = frames / fps
    g_across = G * sqrt(1.0 - dz * dz)
    return (run_long >= frames) & (LONG_STILL_C * g_across * t * t > options.static_m)


def _still_px(cam, x, y, z, options: GatingOptions, sqrt):
    """The image distance, pixels, below which a candidate whose 3D point is ``(x, y, z)``
    (floats, or arrays elementwise: the same bits) moved less than ``static_m`` across its
    ray: ``min(f_x, f_y) static_m / D``, ``D`` the point's distance from the camera (a
    motion ``e`` across the ray moves the undistorted image by at least ``f e / D``); NaN
    without a point (nothing is still then)."""
    cx, cy, cz = cam.center_world.tolist()
    dx, dy, dz = x - cx, y - cy, z - cz
    depth = sqrt((dx * dx + dy * dy) + dz * dz)
    return min(float(cam.K[0, 0]), float(cam.K[1, 1])) * options.static_m / depth


def _paired(ratio: np.ndarray) -> np.ndarray:
    """(C,) bool: the candidates one other camera supports (its point's depth rests on a
    single epipolar constraint; :func:`_static`'s image test), from their support ratio
    (C, m)."""
    with np.errstate(invalid="ignore"):
        return np.count_nonzero(ratio <= 1.0, axis=1) == 1


def _held(c: _Candidates, rig: Rig, ratio: np.ndarray, carried: np.ndarray,
          points: np.ndarray, miss: np.ndarray, options: GatingOptions,
          constants=None) -> np.ndarray:
    """(C,) bool: whether each candidate's support held, what :func:`_still_alone` counts
    of the earlier frames (:func:`_static`): it has a point (``points`` (C, 3), NaN where
    its rays missed), or two or more supports' rays missed (``miss`` (C,) > ``track_m``)
    but one of them alone makes a point with its ray (within ``track_m``): two supports
    whose rays miss count as one ("The decision"), and that one held. A ball flying along
    its camera's ray, supported by its partner in every frame, lost that continuity in the
    frames where a blind camera's last ball or a blob, carried near its line, added a second
    support whose ray missed, and was taken for a static object (``bench_dirty.py --more
    --first-seed 52200``, ``paper3`` ``straight``: 8 of ``cam1``'s ball detections
    rejected as ``motion``). ``ratio`` (C, m), ``carried`` (C, m, 2): the support
    :func:`_points` took; each single-support point by :func:`_points` too (the bits of
    :func:`_held_one`)."""
    held = np.isfinite(points).all(axis=-1)
    with np.errstate(invalid="ignore"):
        rows = np.flatnonzero((np.count_nonzero(ratio <= 1.0, axis=1) >= 2)
                              & (miss > options.track_m))
    if len(rows):
        sub = _Candidates(c.camera[rows], c.time_ns[rows], c.uv_und[rows], c.ray_dir[rows],
                          c.frame[rows])
        for b in range(ratio.shape[1]):
            alone = np.full((len(rows), ratio.shape[1]), np.inf)
            alone[:, b] = ratio[rows, b]  # (a ratio above 1, or NaN: no point)
            p, _, m = _points(sub, rig, alone, carried[rows], constants)
            with np.errstate(invalid="ignore"):
                held[rows] |= np.isfinite(p).all(axis=-1) & (m <= options.track_m)
    return held


def _held_one(camera: int, ray_dir, ratio_row, carried_row, miss: float, point_ok: bool,
              options: GatingOptions, constants) -> bool:
    """:func:`_held` of one candidate on floats (the same bits): ``ray_dir`` (3,), its
    ``ratio`` (m,) and ``carried`` (m, 2) rows as lists, its all-supports point's ``miss``
    (:func:`_points_one`) and whether that point was kept (``point_ok``)."""
    if point_ok:
        return True
    if not (sum(1 for r in ratio_row if r <= 1.0) >= 2 and miss > options.track_m):
        return False
    for b, r in enumerate(ratio_row):
        if not r <= 1.0:
            continue
        alone = [math.inf] * len(ratio_row)
        alone[b] = r
        p, _, m = _points_one(camera, ray_dir, alone, carried_row, constants)
        if p is not None and m <= options.track_m:
            return True
    return False


def _rig_constants(rig: Rig):
    """Per camera, as nested Python floats: centre (3,), K⁻¹ (3, 3), R (3, 3) (for
    :func:`_points` and the stream's per-candidate form of it)."""
    return ([cam.center_world.tolist() for cam in rig.cameras],
            [np.linalg.inv(cam.K).tolist() for cam in rig.cameras],
            [cam.R.tolist() for cam in rig.cameras])


def _carried_ray(u, v, k_inv, r, sqrt):
    """Unit world direction ``Rᵀ K⁻¹ [u, v, 1]`` of undistorted pixels (floats, or arrays
    elementwise), every sum in index order, so that arrays and floats give the same bits
    (``sqrt``: :func:`math.sqrt` or :func:`numpy.sqrt`)."""
    cx = (k_inv[0][0] * u + k_inv[0][1] * v) + k_inv[0][2]
    cy = (k_inv[1][0] * u + k_inv[1][1] * v) + k_inv[1][2]
    cz = (k_inv[2][0] * u + k_inv[2][1] * v) + k_inv[2][2]
    x = (cx * r[0][0] + cy * r[1][0]) + cz * r[2][0]
    y = (cx * r[0][1] + cy * r[1][1]) + cz * r[2][1]
    z = (cx * r[0][2] + cy * r[1][2]) + cz * r[2][2]
    s = sqrt((x * x + y * y) + z * z)
    return x / s, y / s, z / s


def _normal_equations(rays):
    """The least-squares crossing's normal equations ``Σ w (I - d dᵀ) p = Σ w (I - d dᵀ) o``
    of rays ``(w, ox, oy, oz, dx, dy, dz)`` (w 1 for a ray used, 0 for none; floats, or
    arrays elementwise: the same bits), solved by cofactors. Returns (p (3,), det)."""
    a00 = a01 = a02 = a11 = a12 = a22 = b0 = b1 = b2 = 0.0
    for w, ox, oy, oz, dx, dy, dz in rays:
        p00, p11, p22 = (1.0 - dx * dx) * w, (1.0 - dy * dy) * w, (1.0 - dz * dz) * w
        p01, p02, p12 = (0.0 - dx * dy) * w, (0.0 - dx * dz) * w, (0.0 - dy * dz) * w
        a00, a01, a02 = a00 + p00, a01 + p01, a02 + p02
        a11, a12, a22 = a11 + p11, a12 + p12, a22 + p22
        b0 = b0 + ((p00 * ox + p01 * oy) + p02 * oz)
        b1 = b1 + ((p01 * ox + p11 * oy) + p12 * oz)
        b2 = b2 + ((p02 * ox + p12 * oy) + p22 * oz)
    c00, c01, c02 = a11 * a22 - a12 * a12, a02 * a12 - a01 * a22, a01 * a12 - a02 * a11
    c11, c12, c22 = a00 * a22 - a02 * a02, a01 * a02 - a00 * a12, a00 * a11 - a01 * a01
    det = (a00 * c00 + a01 * c01) + a02 * c02
    return ((c00 * b0 + c01 * b1) + c02 * b2, (c01 * b0 + c11 * b1) + c12 * b2,
            (c02 * b0 + c12 * b1) + c22 * b2), det


def _ray_offsets(p, rays):
    """Per ray: the point's distance along it (its depth, > 0 in front) and squared distance
    from it (floats or arrays: the same bits)."""
    out = []
    for _w, ox, oy, oz, dx, dy, dz in rays:
        fx, fy, fz = p[0] - ox, p[1] - oy, p[2] - oz
        along = (fx * dx + fy * dy) + fz * dz
        qx, qy, qz = fx - along * dx, fy - along * dy, fz - along * dz
        out.append((along, (qx * qx + qy * qy) + qz * qz))
    return out


#: A crossing whose normal equations' determinant is this small has parallel rays.
_MIN_DET = 1e-12


def _points(c: _Candidates, rig: Rig, ratio: np.ndarray, carried: np.ndarray, constants=None):
    """Each candidate's 3D point: its ray and its supporting cameras' carried rays crossed
    (least squares); NaN without support. Also whether it lies in front of every camera
    used, and the RMS distance of the point to those rays, metres (three or more rays that
    do not meet: the supports are not one ball). Elementwise, in the order of
    :func:`_points_one`, which gives the stream the same bits one candidate at a time;
    ``constants``: :func:`_rig_constants` of ``rig`` (computed when None)."""
    n = len(ratio)
    centers, k_inv, rot = constants or _rig_constants(rig)
    if n and _kernels_ready():
        # loaded (pslog fuse preloads it): the compiled form, one candidate at a time in
        # _points_one's order (the same bits); a light command never waits for numba here
        from ._gate_kernel import points_all

        points = np.empty((n, 3))
        in_front = np.empty(n, dtype=bool)
        miss = np.empty(n)
        points_all(c.camera, c.ray_dir, ratio, carried, np.array(centers, dtype=np.float64),
                   np.array(k_inv, dtype=np.float64), np.array(rot, dtype=np.float64),
                   points, in_front, miss)
        return points, in_front, miss
    return _points_arrays(c, ratio, carried, (centers, k_inv, rot))


def _points_arrays(c: _Candidates, ratio: np.ndarray, carried: np.ndarray, constants):
    """:func:`_points` in numpy, elementwise over the candidates."""
    n, m = ratio.shape
    centers, k_inv, rot = constants
    own = np.all(np.isfinite(c.ray_dir), axis=1)
    d = np.where(own[:, None], c.ray_dir, 0.0)
    o = np.where(own[:, None], np.array(centers)[c.camera], 0.0)
    rays = [(own * 1.0, o[:, 0], o[:, 1], o[:, 2], d[:, 0], d[:, 1], d[:, 2])]
    used = [own]
    supported = ratio <= 1.0
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for b in range(m):
            ok = supported[:, b]
            if not ok.any():
                continue
            dx, dy, dz = _carried_ray(carried[:, b, 0], carried[:, b, 1], k_inv[b], rot[b],
                                      np.sqrt)
            ok = ok & np.isfinite(dx) & np.isfinite(dy) & np.isfinite(dz)
            x, y, z = centers[b]
            rays.append((ok * 1.0, np.where(ok, x, 0.0), np.where(ok, y, 0.0),
                         np.where(ok, z, 0.0), np.where(ok, dx, 0.0), np.where(ok, dy, 0.0),
                         np.where(ok, dz, 0.0)))
            used.append(ok)
        n_rays = np.sum(used, axis=0)
        p, det = _normal_equations(rays)
        enough = n_rays >= 2
        solved = enough & (np.abs(det) > _MIN_DET)
        points = np.full((n, 3), np.nan)
        for i in range(3):
            points[solved, i] = (p[i] / det)[solved]
        front = solved.copy()
        total = np.zeros(n)
        for (along, sq), ok in zip(_ray_offsets(points.T, rays), used, strict=True):
            front &= (along > 0) | ~ok
            total = total + np.where(ok, sq, 0.0)
        in_front = np.where(enough, front, True)  # no point: nothing behind a camera
        miss = np.where(enough, np.sqrt(total / np.maximum(n_rays, 1)), np.nan)
    return points, in_front, miss


def _points_one(camera: int, ray_dir, ratio_row, carried_row, constants):
    """:func:`_points` of one candidate (``ray_dir`` (3,) floats; its ratio (m,) and
    carried (m, 2) rows as lists): the same arithmetic on floats, the same bits.
    Returns (point (3,) or None, in_front, miss or NaN)."""
    centers, k_inv, rot = constants
    rays = []
    if all(math.isfinite(x) for x in ray_dir):
        rays.append((1.0, *centers[camera], *ray_dir))
    for b, r in enumerate(ratio_row):
        if r <= 1.0:
            u, v = carried_row[b]
            dx, dy, dz = _carried_ray(u, v, k_inv[b], rot[b], _sqrt)
            if math.isfinite(dx) and math.isfinite(dy) and math.isfinite(dz):
                rays.append((1.0, *centers[b], dx, dy, dz))
    if len(rays) < 2:
        return None, True, math.nan
    p, det = _normal_equations(rays)
    if not abs(det) > _MIN_DET:
        return None, False, math.nan
    p = (p[0] / det, p[1] / det, p[2] / det)
    total = 0.0
    in_front = True
    for along, sq in _ray_offsets(p, rays):
        in_front = in_front and along > 0
        total = total + sq
    return p, in_front, math.sqrt(total / len(rays))


def _line_of(f, u: float, v: float):
    """:func:`_epipolar_line` on floats (NaN where the arrays' form gives NaN)."""
    a = (f[0][0] * u + f[0][1] * v) + f[0][2]
    b = (f[1][0] * u + f[1][1] * v) + f[1][2]
    if not max(abs(a), abs(b)) > 0 or not math.isfinite(a) or not math.isfinite(b):
        return math.nan, math.nan, math.nan
    return _epipolar_line(f, u, v, _sqrt, max)


def _ray_miss(p, center, ray) -> float:
    """Distance, metres, of the point ``p`` (3,) from the ray through ``center`` (3,) along
    the unit ``ray`` (3,): ``|(p - center) × ray|``, in floats."""
    ox, oy, oz = float(p[0]) - center[0], float(p[1]) - center[1], float(p[2]) - center[2]
    rx, ry, rz = ray
    cx, cy, cz = oy * rz - oz * ry, oz * rx - ox * rz, ox * ry - oy * rx
    return _sqrt((cx * cx + cy * cy) + cz * cz)


def _distance(p, q) -> float:
    """``|p - q|`` of two points (3,), metres, in floats."""
    dx, dy, dz = float(p[0]) - float(q[0]), float(p[1]) - float(q[1]), float(p[2]) - float(q[2])
    return _sqrt((dx * dx + dy * dy) + dz * dz)


def _clock_model(rig: Rig) -> list[tuple[float, float, float, float]]:
    """Per camera: (height, clock_offset, clock_drift_ppm, readout) as floats, for
    :func:`_true_time_ns`."""
    p = camera_parameters(rig)
    return list(zip(*(p[k].tolist() for k in ("height", "clock_offset", "clock_drift_ppm",
                                              "readout")), strict=True))


def _true_time_ns(logged: int, v: float, clock) -> int:
    """:func:`pslog.timing.true_times_ns` of one detection (``clock``: its camera's
    :func:`_clock_model` entry), in floats in the same order: the same nanosecond."""
    height, offset, drift, readout = clock
    term = readout * NS * v / height if readout != 0 else 0.0
    if not math.isfinite(term):
        raise InputError("a rolling-shutter time needs the detection's pixel row: got a "
                         "non-finite row")
    if abs(term) > MAX_READOUT_TERM_NS:
        raise InputError(f"a rolling-shutter time needs the detection's pixel row: got row "
                         f"{v:g}, far outside the image")
    return logged + round(offset * NS + drift * 1e-6 * float(logged) + term)


def _sqrt(x: float) -> float:
    """math.sqrt, NaN for a negative or NaN argument (as numpy's)."""
    return math.sqrt(x) if x >= 0 else math.nan


class _Track:
    """The recent accepted points and the ballistic prediction the track gate uses."""

    def __init__(self, options: GatingOptions) -> None:
        self.o = options
        self.t: list[float] = []
        self.p: list[np.ndarray] = []
        self.age: list[float] = []  # how long before its time a point was last observed, s

    def add(self, t_s: float, p: np.ndarray, age: float = 0.0) -> None:
        self.t.append(t_s)
        self.p.append(p)
        self.age.append(age)
        if len(self.t) > 4 * self.o.track_points:
            keep = self.o.track_points
            del self.t[:-keep], self.p[:-keep], self.age[:-keep]

    def extend(self, t_s: np.ndarray, p: np.ndarray, age: np.ndarray) -> None:
        """:meth:`add` of each point in turn (times ``t_s`` (k,) s, points ``p`` (k, 3),
        ages (k,) s): the same lists, without a Python step per point (only the newest
        survive)."""
        k, keep_at_most = len(t_s), self.o.track_points
        cap = 4 * keep_at_most
        if k == 0:
            return
        size = len(self.t) + k
        if size > cap:  # add() cut the lists to the newest track_points at cap + 1, and
            # again every 3 track_points + 1 additions after
            size = keep_at_most + (k - (cap + 1 - len(self.t))) % (3 * keep_at_most + 1)
        if size <= k:
            self.t = t_s[k - size:].tolist()
            self.p = [np.array(q) for q in p[k - size:].tolist()]
            self.age = age[k - size:].tolist()
        else:
            old = size - k
            self.t = self.t[len(self.t) - old:] + t_s.tolist()
            self.p = self.p[len(self.p) - old:] + [np.array(q) for q in p.tolist()]
            self.age = self.age[len(self.age) - old:] + age.tolist()

    def last(self):
        return (self.t[-1], self.p[-1]) if self.t else None

    def predict(self, t_s: float):
        """(p̂, allowance) at ``t_s`` from the points before it, or None."""
        o = self.o
        k = len(self.t)
        lo = k
        while lo > 0 and k - lo < o.track_points and t_s - self.t[lo - 1] <= o.track_window_s:
            lo -= 1
        if k - lo < 3:
            return None
        ts = [t - t_s for t in self.t[lo:]]
        # p(τ) = p0 + v τ + ½ g τ², τ = time - t, g = (0, 0, -G) (the world is z up; the
        # filter's default gravity): fit p0, v to the points less gravity
        ys = [(float(p[0]), float(p[1]), float(p[2]) + 0.5 * tau * tau * G)
              for tau, p in zip(ts, self.p[lo:], strict=True)]
        p0, rms = _line_fit(ts, ys)
        if rms > 0.5 * o.track_m and len(ts) > 3:  # a bounce in the window: the newest only
            p0, _ = _line_fit(ts[-3:], ys[-3:])
        # since the newest point was last observed: its own time (it may be later than t: a
        # rolling shutter), less its age (a point resting on one other camera's ray carried
        # from an earlier frame is that old: a kick after that frame spoils it)
        dt = abs(ts[-1]) + self.age[-1]
        return p0, o.track_m + o.track_jump_m_s * dt


def _line_fit(ts: list[float], ys: list[tuple]) -> tuple[list[float], float]:
    """Least-squares ``y ≈ p0 + v τ`` of points ``ys`` (3,) at ``ts`` (closed form, on
    floats): ``p0`` (3,) and the RMS residual, metres. All at one time: their mean."""
    n = len(ts)
    s1 = sum(ts)
    s2 = sum(t * t for t in ts)
    det = n * s2 - s1 * s1
    p0, v = [], []
    for axis in range(3):
        sy = sum(y[axis] for y in ys)
        if not det > 1e-18:
            p0.append(sy / n)
            v.append(0.0)
            continue
        sty = sum(t * y[axis] for t, y in zip(ts, ys, strict=True))
        p0.append((s2 * sy - s1 * sty) / det)
        v.append((n * sty - s1 * sy) / det)
    sq = sum((p0[a] + v[a] * t - y[a]) ** 2 for t, y in zip(ts, ys, strict=True)
             for a in range(3))
    return p0, math.sqrt(sq / n)


class _Columns:
    """Per candidate, as Python floats (the decision loop is sequential; numpy is slow on
    scalars), what :meth:`_Decider.decide` reads: made by :func:`_columns`."""

    __slots__ = ("available", "camera", "epi_cost", "front", "lag", "lone", "n_support", "pts",
                 "rays", "rows", "static", "stillness", "t_ns", "t_s", "unpointed", "uv")
    available: list[int]
    lag: list[list[float]]
    camera: list[int]
    epi_cost: list[float]
    front: list[bool]
    n_support: list[int]
    pts: list[list[float]]
    rays: list[list[float]]
    rows: list[list[float]]
    static: list[bool]
    stillness: list[float]
    lone: list[float]
    t_ns: list[int]
    t_s: list[float]
    unpointed: list[bool]
    uv: list[list[float]]

    def __init__(self, **columns) -> None:
        for k, v in columns.items():
            setattr(self, k, v)


def _columns(c: _Candidates, ratio, points, in_front, static=None, lag=None) -> _Columns:
    """:class:`_Columns` of the candidates ``c``: their support ``ratio`` (n, m), ``points``
    (n, 3), ``in_front`` (n,), ``static`` (:func:`_static`'s three values, or None: none
    static) and ``lag`` (n, m) s (:func:`_lags`; None: 0).
    Counted and summed with numpy in camera order, as the per-row Python sums did (the same
    bits: a sum of three non-negative floats from 0)."""
    n = len(c.camera)
    static, stillness, lone = (([False] * n, [0.0] * n, [math.nan] * n) if static is None else
                               (np.asarray(static[0]).tolist(), np.asarray(static[1]).tolist(),
                                np.asarray(static[2]).tolist()))
    ratio = np.asarray(ratio, dtype=np.float64).reshape(n, -1)
    points = np.asarray(points, dtype=np.float64).reshape(n, 3)
    with np.errstate(invalid="ignore"):
        supports = ratio <= 1.0
    supported = supports.sum(axis=1)
    # squared residuals of the supporting cameras, 1 for each other available one: a
    # camera that does not see the ball says nothing, however near a false candidate
    # (summed in camera order)
    with np.errstate(invalid="ignore", over="ignore"):
        squared = np.where(supports, ratio * ratio, 1.0)
    epi_cost = np.zeros(n)
    for b in range(ratio.shape[1]):
        epi_cost = epi_cost + squared[:, b]
    # two supporting cameras make three views only when the three rays meet (a point, not
    # NaN: within track_m): lines alone can agree by chance, two false or carried-across-a-
    # gap candidates near the epipolar lines of a random blob. Rays that miss count as one
    # support (the track gate then judges).
    # One support whose carried ray misses the candidate's by more than track_m (no point)
    # is no support either: the 3D geometry denies what the line allowed, and with no point
    # no stillness, reach or track test can judge it (paper3, rally seed 19 at 1 px: a lone
    # blob of a camera not seeing the ball, carried as it is across 22-56 ms, 21 cm from
    # the ray of a static object seen by cam2, "supported" it; chosen with no track to deny
    # it, smooth's points 2-3 m off).
    # It is not evidence against the candidate either: the support may be the ball carried
    # from a frame up to max_gap_s old while the ball moved (paper2 at 1 px: cam1 left the
    # view, cam0's ball carried 83-117 ms "supported" cam0's next balls with rays 29-40 cm
    # apart). Such a candidate (``unpointed``) is judged by the track alone, at the track's
    # own allowance; with no track it is rejected (:meth:`_Decider.decide`).
    no_point = ~np.isfinite(points[:, 0])
    unpointed = no_point & (supported == 1)
    n_support = np.where(no_point & (supported >= 2), 1, np.where(unpointed, 0, supported))
    lag = (np.zeros(ratio.shape) if lag is None
           else np.asarray(lag, dtype=np.float64).reshape(ratio.shape))
    return _Columns(rows=ratio.tolist(), available=np.isfinite(ratio).sum(axis=1).tolist(),
                    lag=lag.tolist(),
                    n_support=n_support.tolist(), epi_cost=epi_cost.tolist(),
                    t_s=(c.time_ns / NS).tolist(), t_ns=c.time_ns.tolist(),
                    rays=c.ray_dir.tolist(), pts=points.tolist(),
                    front=np.asarray(in_front).tolist(), static=static, stillness=stillness,
                    lone=lone, uv=c.uv_und.tolist(),
                    camera=np.asarray(c.camera).tolist(), unpointed=unpointed.tolist())


def _picked_there(before, adjacent: bool, key: int, uv, tol: float,
                  options: GatingOptions) -> bool:
    """Whether a camera was following what a ``lone`` candidate at ``uv`` (undistorted) is
    (:meth:`_Decider.decide`): its newest choice (``before``: undistorted (u, v) and its
    frame's time ns; None: none yet), among the frames the stillness test looks at (within
    1.5 ``static_s`` of this frame's time ``key`` ns), lies within ``tol`` pixels of it (it
    stood still there), or, made in the camera's frame before (``adjacent``), within
    ``tol + max_image_speed Δt`` (the ball the camera was following moved there: it passes
    over a static object's pixel)."""
    if before is None or not key - before[2] <= 1.5 * options.static_s * NS:
        return False
    du, dv = uv[0] - before[0], uv[1] - before[1]
    d = _sqrt(du * du + dv * dv)
    if adjacent:
        return d <= tol + options.max_image_speed_px_s * ((key - before[2]) / NS)
    return d <= tol


def _age(ratio_row, lag_row) -> float:
    """How long before its time a chosen candidate's point was last observed, s: resting on
    exactly one other camera (``ratio_row`` (m,): one ratio <= 1), the time since that
    camera's nearest frame its ray was carried from (``lag_row`` (m,) s, :func:`_lags`), as a
    kick after that frame spoils the carried ray and the point; with two or more supports
    whose rays meet the point is confirmed in three views at its own time: 0."""
    support = [lag for r, lag in zip(ratio_row, lag_row, strict=True) if r <= 1.0]
    return support[0] if len(support) == 1 else 0.0


def _lags(t: np.ndarray, tables, used: np.ndarray, compiled: bool = False) -> np.ndarray:
    """(n, m) s: for candidates at times ``t`` (n,) ns, the distance in time to the nearest
    frame of each camera that :func:`_support` looked at (``used`` (n, m, 3): the frame
    before, the latest at or before, the first after; -1 none), inf without one; exact
    integer nanoseconds divided once, as :meth:`StreamGate._support` does. ``compiled``:
    each camera's column by :func:`pslog.fusion._gate_kernel.lags_camera` (the same
    values, one pass)."""
    n, m = used.shape[:2]
    out = np.full((n, m), np.inf)
    for b, (times, _) in enumerate(tables):
        if len(times) == 0:
            continue
        if compiled:
            from ._gate_kernel import lags_camera

            lags_camera(np.ascontiguousarray(t, dtype=np.int64),
                        np.ascontiguousarray(times, dtype=np.int64),
                        np.ascontiguousarray(used, dtype=np.int64), b, NS, out)
            continue
        best = np.full(n, np.iinfo(np.int64).max)
        for slot in (1, 2):
            j = used[:, b, slot]
            gap = np.abs(t - times[np.maximum(j, 0)])
            best = np.where((j >= 0) & (gap < best), gap, best)
        has = best < np.iinfo(np.int64).max
        out[has, b] = best[has] / NS
    return out


class _Decider:
    """The sequential part of the gate: each frame's choice, in (time, camera) order, with
    the track and what the earlier choices taught (:func:`gate`; the stream keeps one)."""

    def __init__(self, rig: Rig, options: GatingOptions) -> None:
        self.rig, self.options = rig, options
        self.track = _Track(options)
        self.verified = False  # a candidate has passed a gate: from then on none passes unjudged
        # the track has predicted (three points in its window) for a candidate one camera
        # alone supports: from then on several such candidates are told apart by their cost
        self.tracked = False
        # the track's newest point was accepted where the track predicted, or on two
        # supports whose rays meet: not a lone pair's guess, so the ball's reach from it
        # holds after the track stops predicting (docs/methods.md, "A lone pair after the
        # track is lost")
        self.vouched = False
        self.centers = [cam.center_world.tolist() for cam in rig.cameras]
        # per camera: its newest choice, (undistorted u, v, its frame's time ns), None
        # before any, and its newest decided frame's time ns: a still pixel that is not the
        # one the camera itself was following is a static object's (the ``lone`` candidates)
        self.picked: list[tuple[float, float, int] | None] = [None] * len(rig)
        self.last_frame: list[int | None] = [None] * len(rig)
        # per camera, until the track first predicts: the candidates it rejected in its
        # frames of several candidates, (frame time ns, undistorted u, v), for
        # :func:`_refused_near` (a later choice there is still one line's guess)
        self.refused: list[list[tuple[int, float, float]]] = [[] for _ in rig.cameras]
        # the stillness rule's premise (docs/methods.md "Stillness"): the scene may hold
        # more than the ball, so a still candidate may be a second object (a static one).
        # Causal (the default): always so — before a second candidate a static object seen
        # alone from the start is not told from a ball at rest, and taking it for the ball
        # made false points until the ball came (session 29: typeA 540 -> 3,677 points on
        # such an object in 45 sessions); offline (_decide_in_order) it is the whole
        # session's: a frame of several candidates anywhere, else a still one is the ball
        self.several = True

    def run(self, c: _Candidates, frames, ratio, points, in_front, reason,
            static=None, lag=None) -> None:
        """Decide the frames ``[(lo, hi), ...]`` (candidate rows, in order): set ``reason``
        of every rejected row (``static``: :func:`_static`'s three values; ``lag``:
        :func:`_lags`)."""
        self.decide(frames, _columns(c, ratio, points, in_front, static, lag), reason)

    def decide(self, frames, cols: _Columns, reason) -> None:
        """:meth:`run` on the candidates' :func:`_columns` (made once for many frames)."""
        options, track = self.options, self.track
        rows, available, n_support, epi_cost = (cols.rows, cols.available, cols.n_support,
                                                cols.epi_cost)
        t_s, t_ns, rays, pts, front = cols.t_s, cols.t_ns, cols.rays, cols.pts, cols.front
        static, stillness, camera, unpointed = (cols.static, cols.stillness, cols.camera,
                                                cols.unpointed)
        lone, uv = cols.lone, cols.uv
        centers, picked = self.centers, self.picked
        for lo, hi in frames:
            best_key, best_row = None, -1
            # the track's prediction at each time (False: none)
            preds: dict[int, tuple | Literal[False]] = {}
            unverified = []
            untracked = []
            # this camera's newest choice (None: none yet), and whether it was its frame before
            before = picked[camera[lo]]
            adjacent = before is not None and before[2] == self.last_frame[camera[lo]]
            self.last_frame[camera[lo]] = t_ns[lo]
            for i in range(lo, hi):
                track_accepts = False
                if static[i] and self.several:  # a static object, whatever supports it (or
                    # no longer does); offline, in a session of one candidate a frame, a
                    # still one is the ball at rest
                    reason[i] = MOTION
                    continue
                if lone[i] == lone[i] and not _picked_there(before, adjacent, t_ns[lo], uv[i],
                                                            lone[i], options):
                    # a pixel as still as a static object's, whose support came and went,
                    # that this camera was not following: the ball did not arrive there out
                    # of nowhere (its camera blind or following it elsewhere); a static
                    # object that other cameras' rays happen to meet as the ball passes it
                    reason[i] = MOTION
                    continue
                if available[i] and n_support[i] == 0:
                    # no other camera confirms it (they may just not see the ball): the track
                    # gate alone may still accept it, if its ray passes close to the prediction
                    pred = preds.get(t_ns[i])
                    if pred is None:  # at the candidate's own time (a rolling shutter's row)
                        pred = preds[t_ns[i]] = track.predict(t_s[i]) or False
                    if pred and math.isfinite(rays[i][0]):
                        # (a single support whose carried ray made no point: the track's own
                        # allowance, as for a candidate one camera supports; _columns)
                        track_accepts = (_ray_miss(pred[0], centers[camera[i]], rays[i])
                                         <= (pred[1] if unpointed[i] else options.track_alone_m))
                    if not track_accepts:
                        reason[i] = EPIPOLAR
                        continue
                if not front[i]:
                    reason[i] = MOTION
                    continue
                # consistent in three views: supported by two cameras (how the track follows
                # kicks and bounces)
                strong = n_support[i] >= 2
                # supported by one and near the lines of every other (a kick or bounce spoils
                # carried points for a frame or two): the track gate, at twice the allowance
                # (not when two cameras support it and their rays miss: one of them carries
                # something other than the ball there, so "near every line" is no evidence;
                # lab3 in bench_dirty.py --more, rally-302 at 1.11 s: a blob near the lines
                # of a camera carried across 55 ms and of another, 68 cm off the track)
                loose = not strong and available[i] >= 2 and not (
                    n_support[i] == 1 and sum(r <= 1.0 for r in rows[i]) >= 2) and all(
                    r <= options.loose_ratio for r in rows[i] if math.isfinite(r))
                track_cost = 0.0
                if not strong:
                    pred = preds.get(t_ns[i])
                    if pred is None:  # at the candidate's own time (a rolling shutter's row)
                        pred = preds[t_ns[i]] = track.predict(t_s[i]) or False
                    last = track.last()
                    # (the reach from the newest point once the track can predict, or from
                    # a vouched newest point at any time since: else a first point may be a
                    # guess, and a guess must not veto the ball)
                    if (pred or self.vouched) and last is not None and math.isfinite(
                            pts[i][0]):
                        dt = abs(t_s[i] - last[0])
                        if _distance(pts[i], last[1]) > (
                                options.max_speed_m_s * dt + options.track_m):
                            reason[i] = MOTION
                            continue
                    if pred and math.isfinite(rays[i][0]):
                        miss = _ray_miss(pred[0], centers[camera[i]], rays[i])
                        if miss > (2.0 if loose else 1.0) * pred[1]:
                            reason[i] = TRACK
                            continue
                        track_cost = min((miss / pred[1]) ** 2, 4.0)
                    elif not available[i]:
                        if self.verified:  # nothing can confirm it: no other camera, no track
                            reason[i] = EPIPOLAR
                            continue
                        unverified.append(i)  # the session's first frames: nothing to judge by
                    if pred:
                        self.tracked = True
                    elif not self.tracked:
                        untracked.append(i)  # no track yet to tell it from another candidate
                # (a lone candidate, still in the image in every frame of static_s and
                # kept only because its camera followed the ball to it: stillness 1)
                key = (-n_support[i], epi_cost[i] + track_cost
                       + (1.0 if lone[i] == lone[i] else stillness[i]))
                if best_key is None or key < best_key:
                    best_key, best_row = key, i
            if best_row < 0:
                if hi - lo >= 2 and not self.tracked:
                    self._refused(camera[lo], t_ns[lo], uv, reason, lo, hi)
                continue
            if len(untracked) > 1 and best_row in untracked and n_support[best_row] < 2:
                # several candidates that one camera's epipolar line alone judges, before any
                # track could tell them apart (the session's start): keeping one would be a
                # guess, and a guess seeds the track (paper2 in
                # bench_dirty.py --more: a static object seen by one camera, chosen in the
                # first 0.03 s, made the ball unreachable; type A points 13-23 cm off)
                for i in untracked:
                    if n_support[i] < 2:
                        reason[i] = EPIPOLAR
                best_row = -1
                best_key = None
                for i in range(lo, hi):
                    if reason[i] < 0 and i not in unverified:
                        key = (-n_support[i], epi_cost[i]
                               + (1.0 if lone[i] == lone[i] else stillness[i]))
                        if best_key is None or key < best_key:
                            best_key, best_row = key, i
                if best_row < 0:
                    if not self.tracked:
                        self._refused(camera[lo], t_ns[lo], uv, reason, lo, hi)
                    continue
            if best_row in unverified and len(unverified) > 1:
                # several candidates nothing can tell apart (no other camera near, no track):
                # keeping one would be a guess
                for i in unverified:
                    reason[i] = EPIPOLAR
                best_row = -1
                for i in range(lo, hi):
                    if reason[i] < 0 and i not in unverified:
                        best_row = i
                if best_row < 0:
                    if not self.tracked:
                        self._refused(camera[lo], t_ns[lo], uv, reason, lo, hi)
                    continue
            for i in range(lo, hi):
                if i != best_row and reason[i] < 0:
                    reason[i] = OUTSCORED
            if best_row in untracked and (hi - lo >= 2 or _denied(rows[best_row]) or _refused_near(
                    self.refused[camera[lo]], t_ns[lo], uv[best_row], options)):
                # chosen on one support before the track could predict (the session's start:
                # nothing else can judge) while another camera denies it (paper3 in
                # bench_dirty.py --more --first-seed 1200 --misses 0.1: cam3's first frame
                # holds only the static object, on cam1's line, off cam2's; type A's first
                # point 4.1 m off), or among other candidates of its frame that the one line
                # refused (paper2, --first-seed 700: the object beside the refused ball,
                # type A 310 mm), or where its camera refused a candidate of a frame of
                # several within static_s (paper2@60, --first-seed 1700 --misses 0.1,
                # rally-1701: the object and the ball refused together at 0.008 s, the
                # object alone at 0.025 s, the ball missed, chosen on cam1's line: smooth
                # 0.5-0.8 m off): a guess, in doubt
                reason[best_row] = CONTESTED
            picked[camera[lo]] = (uv[best_row][0], uv[best_row][1], t_ns[lo])
            self.verified |= best_row not in unverified
            if hi - lo >= 2 and not self.tracked:
                self._refused(camera[lo], t_ns[lo], uv, reason, lo, hi)
            if math.isfinite(pts[best_row][0]):
                # (a candidate one camera supports had its prediction made above)
                self.vouched = n_support[best_row] >= 2 or bool(preds.get(t_ns[best_row]))
                track.add(t_s[best_row], np.array(pts[best_row]),
                          _age(rows[best_row], cols.lag[best_row]))

    def _refused(self, cam: int, key: int, uv, reason, lo: int, hi: int) -> None:
        """Note the candidates of camera ``cam``'s frame ``lo:hi`` (of several; frame time
        ``key`` ns) that were rejected, before the track first predicts
        (:func:`_refused_near`)."""
        window = self.options.static_s * NS
        kept = [r for r in self.refused[cam] if key - r[0] <= window]
        kept.extend((key, uv[i][0], uv[i][1]) for i in range(lo, hi) if reason[i] >= 0)
        self.refused[cam] = kept


def _refused_near(refused, key: int, uv, options: GatingOptions) -> bool:
    """Whether a camera rejected, in a frame of several candidates within ``static_s``
    before its frame at ``key`` ns (``refused``: :attr:`_Decider.refused` of the camera),
    a candidate within :data:`DOUBT_RADIUS_PX` of a choice at ``uv`` (undistorted): made
    before the track first predicts, that choice rests on one epipolar line as that
    rejected candidate did, and whatever stood there is still there
    (docs/methods.md, "A contested start")."""
    for t, u, v in refused:
        if 0 <= key - t <= options.static_s * NS:  # (earlier frames only, as the kernel's)
            du, dv = uv[0] - u, uv[1] - v
            if du * du + dv * dv <= DOUBT_RADIUS_PX * DOUBT_RADIUS_PX:
                return True
    return False


def _denied(ratios) -> bool:
    """Whether another available camera denies a choice that fewer than two supports whose
    rays meet made (``ratios``: its epipolar ratio per camera, NaN / inf: not available):
    one camera's candidates lie off its line (ratio above 1), or two supports' rays miss
    (two ratios within 1 that :func:`_columns` counts as one support)."""
    within = 0
    for r in ratios:
        if r <= 1.0:
            within += 1
        elif math.isfinite(r):
            return True
    return within >= 2


def gate(detections: Detections, rig: Rig, *, causal: bool = True, wait_s: float = 0.0,
         max_gap_s: float | None = None, options: GatingOptions | None = None,
         common: Callable[[], tuple] | None = None, doubt: bool | str = True) -> Gated:
    """Choose the ball among every frame's candidates (module docstring).

    Parameters
    ----------
    detections : Detections, every candidate (LOGGED times; corrected here by the rig's
        clock model, each candidate at its own row)
    rig : Rig, with the detections' cameras (names and order)
    causal : True: a choice at t uses nothing after t (+ ``wait_s``); False: offline
    wait_s : float, seconds a causal method waits for simultaneous detections (its
        tolerance, for ``sync``, ``typeB``, ``linear``; 0 for the others)
    max_gap_s : float, frames of other cameras further than this from t give no support
        (default: 3.5 frame periods of the slowest camera)
    options : GatingOptions
    common : ``common()`` gives :func:`gate_common` of ``detections`` and ``rig`` (the
        part of the work every form shares: several forms gating the same detections
        compute it once); None: computed here
    doubt : make :attr:`Gated.doubt_px2` (False: None, for methods that do not take it:
        the registry's ``Method.uses_doubt``; ``"start"``: only the start's, the contested
        choices and their camera's later choices at their pixel, ``Method.doubt``)

    Returns
    -------
    Gated: the observations every method fuses and the record of every rejection.
    """
    from ._prepare import default_max_gap_s

    options = options or GatingOptions()
    max_gap_ns = round((max_gap_s or default_max_gap_s(rig)) * NS)
    check_crowding(detections, rig)
    c, tables = common() if common is not None else gate_common(detections, rig)
    n = len(c.camera)
    reason = np.full(n, -1, dtype=np.int8)
    if n == 0:
        return _result(detections, rig, reason)
    _decided(c, rig, options, causal, round(wait_s * NS), max_gap_ns, reason, tables)
    return _result(detections, rig, reason, options, doubt)


#: most candidates a frame may hold for the gate (:func:`check_crowding`): it pairs each
#: candidate with every pair of another camera's frames around it, work that grows as the
#: square of a frame's candidates (hostile40, a rally of 8 s, one camera's frames of 1001
#: and 2001 candidates: 8.5 and 32.5 CPU s a pass; 20,834, 5 million in all, about an hour).
#: Detectors keep far fewer (``pslog record`` 5 by default, ``redetect`` at most 100).
MAX_FRAME_CANDIDATES = 1000


def check_crowding(detections: Detections, rig: Rig) -> None:
    """FusionError naming the first frame of the most candidates if it holds more than
    :data:`MAX_FRAME_CANDIDATES` (an imported CSV takes any number): gating it would take
    hours and look hung."""
    if detections.n_candidates == 0:
        return
    counts = np.bincount(detections.cand_frame, minlength=detections.n_frames)
    f = int(np.argmax(counts))
    if counts[f] > MAX_FRAME_CANDIDATES:
        from ..log.csvio import format_time

        raise FusionError(
            f"camera {rig.names[int(detections.frame_camera[f])]}'s frame "
            f"{int(detections.frame_index[f])} (t = {format_time(int(detections.frame_time_ns[f]))}"
            f" s) holds {int(counts[f])} candidates: the gate takes at most "
            f"{MAX_FRAME_CANDIDATES} a frame (its work grows as their square: hours); keep "
            f"each frame's best {MAX_FRAME_CANDIDATES} or fewer by score (or 'pslog fuse "
            f"--gating off': each frame's best-scored candidate alone)")


def gate_common(detections: Detections, rig: Rig) -> tuple:
    """What :func:`gate` computes whatever its form (causal or not, its wait and gap): the
    candidates' geometry (corrected times, undistorted pixels, viewing rays) and each
    camera's frame table; read only by the gate."""
    c = _candidates(detections, rig)
    return c, (_frame_table(c, len(rig)) if len(c.camera) else None)


def _decided(c: _Candidates, rig: Rig, options: GatingOptions, causal: bool, wait_ns: int,
             max_gap_ns: int, reason: np.ndarray, tables=None) -> np.ndarray:
    """:func:`gate`'s choice: sets ``reason`` (C,) of every rejected candidate; returns the
    epipolar support ratio (C, m) each candidate was decided with (``tables``: the frame
    tables of ``c``, made here when None). Decided by :func:`_decide_in_order` or, where
    :func:`_decide_compiled` says, by the compiled kernels over every frame at once (the
    same choices)."""
    n = len(c.camera)
    if tables is None:
        tables = _frame_table(c, len(rig))
    F = fundamental_matrices(rig.cameras)
    # frames in (time, camera) order of their best candidate; candidates contiguous per frame
    starts = np.flatnonzero(np.r_[True, c.frame[1:] != c.frame[:-1]])
    ends = np.r_[starts[1:], n]
    order = np.lexsort((c.camera[starts], c.time_ns[starts]))
    several = causal or bool(np.any(ends - starts >= 2))
    whole, python_s = _decide_compiled(c, starts, ends, tables, max_gap_ns)
    # (the kernels loaded for the whole-session choice where the Python decider's frames
    # would cost more than loading them: WHOLE_LOAD_S)
    compiled = _kernels(n, wait=whole and python_s >= WHOLE_LOAD_S)
    if whole and compiled and _sums_reproduced():
        # every frame decided by the compiled stream gate's steps in one call (the same
        # bits as the path below: tests/test_gate_whole.py)
        from ._gate_kernel import gate_session

        position = np.zeros(n, dtype=np.int64)  # a frame's first row -> its table row
        for _, table in tables:
            position[table[:, 0]] = np.arange(len(table))
        first = starts[order]
        return gate_session(c, tables, rig, options, wait_ns, max_gap_ns, F,
                            _rig_constants(rig),
                            [int(np.ceil(options.static_s * cam.fps)) for cam in rig.cameras],
                            G, causal, several, (c.camera[first], position[first]), reason)
    ratio, carried, used = _support(c, rig, F, tables, options, max_gap_ns, causal, wait_ns,
                                    compiled=compiled)
    constants = _rig_constants(rig)
    points, in_front, miss = _points(c, rig, ratio, carried, constants)
    points[miss > options.track_m] = np.nan  # rays that do not meet: no point to track
    static, stillness, lone = _static(c, tables, rig, options, points, _paired(ratio),
                                      compiled=compiled,
                                      held=_held(c, rig, ratio, carried, points, miss,
                                                 options, constants))
    _decide_in_order(c, rig, options, (starts, ends, order), tables, F,
                     (ratio, carried, used, _lags(c.time_ns, tables, used, compiled)),
                     (points, in_front), (static, stillness, lone), reason,
                     causal, wait_ns, max_gap_ns, constants)
    return ratio


#: None: :func:`_decide_compiled` decides by the session; True / False: always / never the
#: whole-session compiled choice (tests compare the two paths)
WHOLE_COMPILED: bool | None = None
#: frames the Python decider cannot take in arrays (:func:`_decide_compiled`), as a share
#: of all frames, from which the batch gate decides every frame by the compiled kernels
WHOLE_FROM_SHARE = 0.05
#: estimated CPU seconds of the Python decider's frames from which a gate whose compiled
#: kernels are not loaded yet loads them (or waits for ``pslog fuse``'s preload) for the
#: whole-session choice: numba's start and the kernels' cache, ~0.3-0.6 s
WHOLE_LOAD_S = 0.3
#: bytes of kept state (:class:`pslog.fusion._gate_kernel.GateState` holding every frame) up
#: to which the whole-session compiled choice is made; beyond, the Python decider
WHOLE_MAX_BYTES = 1 << 30
#: the Python decider's cost per frame, s (:func:`_decide_compiled`'s estimate): one
#: candidate that two other cameras support (taken in arrays), one candidate otherwise,
#: several candidates
_PYTHON_S = (1.1e-6, 12e-6, 150e-6)
#: the Python path's further cost per frame of several candidates, s: the frames whose
#: support used it are decided one by one (and redone where it was decided with a
#: rejected candidate, or offline emptied: :func:`_decide_pass`); the 90-minute session
#: with 0.1-0.5 % of frames given a blob (and 0-2 % of candidates dropped), 0.4-0.6 ms each
#: (``benchmarks/session46/review46_s90_blobs.py``)
_PYTHON_NEAR_S = 5e-4
#: the compiled whole-session choice's cost per frame, s, every step included (its support,
#: points and stillness too): the 90-minute session, clean or with blobs, 1.0-1.12 s for
#: 480,000 frames; where the Python path's estimate is more, the compiled one is taken
_COMPILED_S = 2.2e-6
#: the Python path's cost per candidate and candidate pair of its crowdest frames, s
#: (:func:`_decide_compiled`: candidates × k_max², k_max the most candidates a frame holds;
#: hostile40, 720 frames of a rally: 10, 20, 50 candidates a frame 0.53, 2.0, 30 CPU s and
#: 78 MB, 286 MB, 3.3 GB; the compiled kernels 0.3-1.3 s)
_PYTHON_PAIR_S = 3.4e-7
#: frames :func:`_decide_compiled` looks at, at most (evenly spaced: a share's estimate)
_WHOLE_SAMPLE = 20_000


def _decide_compiled(c: _Candidates, starts: np.ndarray, ends: np.ndarray, tables,
                     max_gap_ns: int) -> tuple[bool, float]:
    """Whether the batch gate should decide every frame by the compiled kernels in one call
    (:func:`pslog.fusion._gate_kernel.gate_session`) rather than by :func:`_decide_in_order`
    (the same choices: the same steps on the same bits; ``tests/test_gate_whole.py``), and
    the Python decider's estimated CPU seconds.

    The compiled kernels decide each frame whole: ~2.2 µs a frame (:data:`_COMPILED_S`, a
    90-minute match, three cameras, the geometry included). The Python path takes in arrays
    a frame of one candidate that two other cameras support (~1.1 µs), but decides any other
    in Python: ~12 µs a frame of one candidate (one other camera near: misses, drops, a
    two-camera rig), ~150 µs one of several (a static object, blobs) (:data:`_PYTHON_S`),
    and ~0.5 ms more for the frames around one of several (:data:`_PYTHON_NEAR_S`). So the
    compiled kernels where that estimate is the larger (a 90-minute match with a blob in
    0.2 % of its frames: 1.19 against 1.11 CPU s; 0.5 %: 1.94 against 1.10), and wherever
    at least :data:`WHOLE_FROM_SHARE` of the frames are not of the first kind (judged by the
    frames' times alone: one candidate, and a frame of two other cameras within the gate's gap;
    on up to :data:`_WHOLE_SAMPLE` evenly spaced frames), or where crowded frames would cost the
    Python path :data:`WHOLE_LOAD_S` or more (its support pairs each candidate with every pair
    of another camera's frames around it: :data:`_PYTHON_PAIR_S` a candidate and pair of the
    crowdest frame's candidates; 50 candidates a frame took 30 s and 3.3 GB there, 209 in one
    camera asked for 16 GiB), and the state holding every frame stays below
    :data:`WHOLE_MAX_BYTES`. Imports nothing (the caller loads the kernels only where they
    are worth it)."""
    n_frames = len(starts)
    if n_frames == 0:
        return False, 0.0
    # judged on every frame up to _WHOLE_SAMPLE of them, else on evenly spaced ones
    step = max(1, n_frames // _WHOLE_SAMPLE)
    first, last = starts[::step], ends[::step]
    several = last - first >= 2
    if len(tables) < 3:  # (no frame has two other cameras)
        simple = np.zeros(len(first), dtype=bool)
    else:
        t, camera = c.time_ns[first], c.camera[first]
        near = np.zeros(len(first), dtype=np.int64)
        for b, (times, _) in enumerate(tables):
            if len(times) == 0:
                continue
            at = np.searchsorted(times, t)
            gap = np.minimum(np.abs(t - times[np.maximum(at - 1, 0)]),
                             np.abs(times[np.minimum(at, len(times) - 1)] - t))
            near += (gap <= max_gap_ns) & (camera != b)
        simple = ~several & (near >= 2)
    shares = np.array([np.mean(simple), np.mean(~simple & ~several), np.mean(several)])
    h_max = max(len(times) for times, _ in tables)
    k_max = max(table.shape[1] for _, table in tables)
    # the numpy support pairs every candidate with each pair of another camera's frames
    # around it, k_max² candidate pairs (every frame table is k_max wide): sessions of
    # crowded frames cost that far more; from _KERNELS_FROM candidates the support is the
    # compiled kernels' anyway (a 90-minute match with one frame of two candidates keeps
    # the Python decider)
    crowd_s = (len(c.camera) * k_max**2 * _PYTHON_PAIR_S
               if k_max >= 2 and len(c.camera) < _KERNELS_FROM else 0.0)
    python_s = (float(n_frames * (shares @ np.array(_PYTHON_S))) + crowd_s
                + float(n_frames * shares[2]) * _PYTHON_NEAR_S)
    if WHOLE_COMPILED is not None:
        return WHOLE_COMPILED, python_s
    if _whole_bytes(len(tables), h_max, k_max, len(c.camera)) > WHOLE_MAX_BYTES:
        return False, python_s
    return bool(shares[1] + shares[2] >= WHOLE_FROM_SHARE or crowd_s >= WHOLE_LOAD_S
                or python_s >= n_frames * _COMPILED_S), python_s


def _whole_bytes(m: int, h_max: int, k_max: int, n: int) -> int:
    """Bytes the whole-session compiled choice holds for ``m`` cameras of at most ``h_max``
    frames of at most ``k_max`` candidates, ``n`` candidates in all
    (:func:`pslog.fusion._gate_kernel.gate_session`): per frame slot the state's ``fi`` (5
    int64) and ``fflag`` (2 int8); per candidate slot its ``ct`` (int64), ``cf`` (9 float64),
    ``csup`` (int8) and ``session_state``'s ``rows`` (int64); per candidate the decided ratio
    returned ((C, m) float64). (Review40: the estimate had the candidate slots alone, 61 %
    of the bytes of a two-camera session of one candidate a frame.)"""
    return m * h_max * (5 * 8 + 2) + m * h_max * k_max * (8 + 9 * 8 + 1 + 8) + n * m * 8


def _sums_reproduced() -> bool:
    """Whether the compiled kernels reproduce this Python's ``sum`` of floats (their
    module loaded: ``_gate_kernel.SUM_MODE``)."""
    from ._gate_kernel import SUM_MODE

    return SUM_MODE >= 0


#: candidates from which the batch gate loads its compiled kernels itself (numba's start,
#: ~0.5 s, then costs less than the numpy forms of _support and _static, ~2 µs a candidate
#: per form); below, they are used only where already loaded
_KERNELS_FROM = 200_000


def _kernels_ready() -> bool:
    """Whether :mod:`._gate_kernel` is loaded — or being loaded by ``pslog fuse``'s preload
    thread: then wait for it —, False where that import failed (numba cannot start: the
    numpy forms, not a traceback from the ``from ._gate_kernel import`` that follows)."""
    if "pslog.fusion._gate_kernel" not in sys.modules:
        return False
    try:
        import importlib

        importlib.import_module("pslog.fusion._gate_kernel")
    except Exception:
        return False
    return True


def _kernels(n: int, wait: bool = False) -> bool:
    """Whether the gate of ``n`` candidates runs :mod:`._gate_kernel`'s kernels (the same
    bits as the numpy forms): where that module is loaded (``pslog fuse`` preloads it on
    another thread; a gate that starts before that import is done waits for it here, at
    ``_KERNELS_FROM`` candidates or more, or where ``wait`` says the kernels are worth it,
    rather than burn the numpy forms' CPU meanwhile)."""
    if "pslog.fusion._gate_kernel" not in sys.modules and n < _KERNELS_FROM and not wait:
        return False
    try:  # loaded, being loaded by the preload (wait for it), or to be loaded here
        import importlib

        importlib.import_module("pslog.fusion._gate_kernel")
    except Exception:  # numba cannot start (here or in the preload): the numpy forms
        return False
    return True


#: frames decided by one :meth:`_Decider.decide` call at most (bounds the Python floats held)
_DECIDE_BLOCK = 8192


def _decide_in_order(c: _Candidates, rig: Rig, options: GatingOptions, frames, tables, F,
                     support, geometry, still, reason, causal: bool, wait_ns: int,
                     max_gap_ns: int, constants) -> None:
    """:class:`_Decider` over the frames in order, each frame's support as decided so far
    (:func:`_support_one`): the all-candidates support and points computed in arrays
    (``support``: :func:`_support`'s; ``geometry``: points, in_front) hold while no frame
    they used has been decided with a rejected candidate (or, offline, with every candidate
    rejected: :func:`_emptied`); a candidate whose support used one is recomputed on floats
    (the stream gate's arithmetic, the same bits). The stillness (``still``:
    :func:`_static`'s) stays the all-candidates one: whether an object stands still is a
    fact of the scene, whichever candidates were chosen (a static object the gate rejects
    must stay still to the test). Sets ``reason`` of every rejected row.

    ``frames``: ``(starts, ends, order)``, each frame's candidate rows ``starts[f]:ends[f]``
    (frames in row order) and the order to decide them in. Only a frame with several
    candidates can be decided with one rejected (:func:`_supporting`), and offline only a
    frame the gate does not take whole can be decided with none chosen, so only a frame
    whose support used such a frame may need its support redone; the others are decided in
    blocks (:meth:`_Decider.decide` over many frames), and a run of frames of one candidate
    that two other cameras support with meeting rays, neither static nor behind a camera
    (each one chosen, whatever the track says) only adds its points to the track. (A frame
    of that kind whose redone support rejects it after all: the choice is made again with
    it among those that may be emptied, :func:`_emptied`.)
    """
    ratio, carried, used, _ = support
    points, in_front = geometry
    static, _, lone = still
    starts, ends, order = frames
    m = len(rig)
    # candidates whose all-candidates support used a frame with several candidates
    several = [table[:, 1] >= 0 if table.shape[1] > 1 else np.zeros(len(table), dtype=bool)
               for _, table in tables]
    may_redo = np.zeros(len(c.camera), dtype=bool)
    for b in range(m):
        if several[b].any():
            u = used[:, b, :]
            may_redo |= np.any((u >= 0) & several[b][np.maximum(u, 0)], axis=1)
    lo_all, hi_all = starts[order], ends[order]
    single = (hi_all - lo_all) == 1
    with np.errstate(invalid="ignore"):
        strong = ((ratio <= 1.0).sum(axis=1) >= 2) & np.isfinite(points[:, 0])
    first = lo_all
    whole = (single & strong[first] & ~static[first] & np.isnan(lone[first])
             & in_front[first])
    position = np.zeros(len(c.camera), dtype=np.int64)  # a frame's first row -> table row
    for _, table in tables:
        position[table[:, 0]] = np.arange(len(table))
    frame_cam = c.camera[lo_all]  # each frame's camera, in the order
    frame_camera = frame_cam.tolist()
    frame_time = c.time_ns[lo_all]  # (sorted: the order is by time)
    redo_several = np.logical_or.reduceat(may_redo, starts)[order]
    # offline: the frames that may be decided with none chosen (_emptied), per camera's
    # frame table: all but those taken whole; more where a choice made again found one (a
    # frame taken whole that its redone support rejects: rare, no dirty test session has
    # one). Foreseeing those too (the frames near a frame of several candidates) made the
    # frames near them decided one by one: 90 minutes with 0.5 % of frames holding a blob,
    # 1.8 -> 2.7 CPU s, 1.95 s without them (review46)
    may_empty = []
    if not causal:
        left = np.flatnonzero(~whole)  # (few on a clean session)
        if not FORESEE_EMPTIED:
            left = left[:0]
        for b, (_, table) in enumerate(tables):
            empty = np.zeros(len(table), dtype=bool)
            empty[position[lo_all[left[frame_cam[left] == b]]]] = True
            may_empty.append(empty)
    saved: dict[int, tuple] = {}  # a redone row's array values, for a choice made again
    for passes in itertools.count(1):
        if passes > _MAX_PASSES:  # every frame foreseen: this pass is the last
            for empty in may_empty:
                empty[:] = True
        again = _decide_pass(c, rig, options, tables, F, support, geometry, still, reason,
                             causal, wait_ns, max_gap_ns, constants, may_empty, saved,
                             (lo_all, hi_all, single, whole, position, frame_camera,
                              frame_cam, frame_time, redo_several, order))
        if not again:
            return
        for b, js in enumerate(again):
            may_empty[b][sorted(js)] = True
        for i, (r, cu, p, ok) in saved.items():
            ratio[i], carried[i], points[i], in_front[i] = r, cu, p, ok
        saved.clear()
        reason[:] = -1


def _decide_pass(c: _Candidates, rig: Rig, options: GatingOptions, tables, F, support,
                 geometry, still, reason, causal: bool, wait_ns: int, max_gap_ns: int,
                 constants, may_empty, saved, layout) -> list[set[int]]:
    """One pass of :func:`_decide_in_order`'s choice over every frame. ``may_empty``: per
    camera, its frames that may be decided with none chosen (offline; empty list causal);
    ``saved``: gets each redone row's array values before its first redo. Returns, per
    camera, the frames emptied outside ``may_empty`` (a choice to make again), or an empty
    list."""
    ratio, carried, used, lag = support
    points, in_front = geometry
    static, stillness, lone = still
    (lo_all, hi_all, single, whole, position, frame_camera, frame_cam, frame_time,
     redo_several, order) = layout
    m = len(rig)
    decider = _Decider(rig, options)
    if not causal:
        # offline, the stillness rule's premise is the whole session's: a frame of several
        # candidates anywhere (before or after) says the scene holds more than the ball, so
        # a static object seen alone before the ball enters is one from the first frame
        # (docs/methods.md "Stillness"); the causal form always takes it (_Decider)
        decider.several = bool(np.any(hi_all - lo_all >= 2))
    redo_frame = redo_several
    if may_empty:
        # offline the support used b's frames last - 1, last, last + 1 (``used``; last the
        # latest at or before the candidate's time): a frame of one candidate at t used
        # b's frame j iff keys[j - 1] <= t < keys[j + 2], a span of the frames in time
        # order (a gather of ``used`` cost 25 ms at 90 minutes); a frame of several
        # candidates (times of their own) is decided by itself anyway: its turn checks
        n_frames = len(order)
        redo_frame = redo_several | ~single
        for b, (keys_b, _) in enumerate(tables):
            js = np.flatnonzero(may_empty[b])
            if len(js) == 0:
                continue
            since = np.where(js >= 1, keys_b[np.maximum(js - 1, 0)], np.iinfo(np.int64).min)
            until = np.where(js + 2 < len(keys_b),
                             keys_b[np.minimum(js + 2, len(keys_b) - 1)],
                             np.iinfo(np.int64).max)
            first = np.searchsorted(frame_time, since)
            stop = np.searchsorted(frame_time, until)
            if len(js) <= _FEW_SPANS:
                spans = np.concatenate([np.arange(f, e) for f, e in
                                        zip(first.tolist(), stop.tolist(), strict=True)])
            else:
                cover = np.cumsum(np.bincount(first, minlength=n_frames + 1)
                                  - np.bincount(stop, minlength=n_frames + 1))
                spans = np.flatnonzero(cover[:-1] > 0)
            redo_frame[spans[frame_cam[spans] != b]] = True
    simple = whole & ~redo_frame
    special = ~single | redo_frame
    # each frame's kind: 0 simple, 1 any other frame decided as it comes, 2 special
    kind = np.where(simple, 0, np.where(special, 2, 1))
    cuts = np.flatnonzero(np.r_[True, kind[1:] != kind[:-1], True])

    keys_cache: dict[int, list[int]] = {}

    def keys(b: int) -> list[int]:
        if b not in keys_cache:
            keys_cache[b] = tables[b][0].tolist()
        return keys_cache[b]

    # per camera: the candidates of a decided frame that may support (_supporting), where
    # they are not all its candidates; the frames so decided (spoiled); offline, the frames
    # decided with none chosen (emptied: _emptied), and those outside ``may_empty``
    kept_of: list[dict[int, list]] = [{} for _ in range(m)]
    spoiled: list[set[int]] = [set() for _ in range(m)]
    emptied: list[set[int]] = [set() for _ in range(m)]
    unforeseen: list[set[int]] = [set() for _ in range(m)]

    def usable_of(b: int, skip: bool = False):
        table, kept, gone = tables[b][1], kept_of[b], emptied[b]

        def usable(j: int) -> list:
            if skip and j in gone:
                return []
            got = kept.get(j)
            if got is None:
                got = [(int(c.time_ns[r]), *c.uv_und[r].tolist()) for r in table[j].tolist()
                       if r >= 0]
            return got
        return usable

    F_lists = F.tolist()
    lags = [int(np.ceil(options.static_s * cam.fps)) for cam in rig.cameras]  # as _static

    def judged(a: int, at: int) -> bool:
        return _can_judge(keys(a)[at], [keys(a)[at - lag] for lag in
                                        range(1, min(lags[a], at) + 1)], lags[a], options)

    def mark_emptied(k0: int, k1: int) -> None:
        """Offline: the frames k0:k1 of the order decided with none chosen (_emptied)."""
        if causal:
            return
        lo, hi = lo_all[k0:k1], hi_all[k0:k1]
        if k1 - k0 == 1:
            none = [0] if _emptied(reason[int(lo[0]):int(hi[0])].tolist()) else []
        else:  # (a block: frames of one candidate each)
            none = np.flatnonzero(reason[lo] >= 0).tolist()
        for k in none:
            a, at = frame_camera[k0 + k], int(position[lo[k]])
            if judged(a, at):
                emptied[a].add(at)
                if not may_empty[a][at]:
                    unforeseen[a].add(at)

    def decide_block(k0: int, k1: int) -> None:
        """Frames k0:k1 of the order by one decide() call on their candidates' columns."""
        lo, hi = lo_all[k0:k1], hi_all[k0:k1]
        sizes = hi - lo
        local_hi = np.cumsum(sizes)
        local_lo = local_hi - sizes
        rows = np.repeat(lo - local_lo, sizes) + np.arange(int(local_hi[-1]))
        sub = _Candidates(c.camera[rows], c.time_ns[rows], c.uv_und[rows], c.ray_dir[rows],
                          c.frame[rows])
        cols = _columns(sub, ratio[rows], points[rows], in_front[rows],
                        (static[rows], stillness[rows], lone[rows]), lag[rows])
        local = reason[rows]
        decider.decide(zip(local_lo.tolist(), local_hi.tolist(), strict=True), cols, local)
        reason[rows] = local

    for s, e in zip(cuts[:-1].tolist(), cuts[1:].tolist(), strict=True):
        if kind[s] == 0:  # each one chosen: its point joins the track
            rows = lo_all[s:e]
            decider.verified = True
            # (two supports whose rays meet: points of age 0, _age)
            decider.track.extend(c.time_ns[rows] / NS, points[rows], np.zeros(len(rows)))
            decider.vouched = decider.vouched or len(rows) > 0
            # each camera's choice in its newest frame of the run (_Decider.picked)
            seen: set[int] = set()
            for k in range(e - 1, s - 1, -1):
                b = frame_camera[k]
                if b not in seen:
                    seen.add(b)
                    u, v = c.uv_und[lo_all[k]].tolist()
                    decider.picked[b] = (u, v, int(c.time_ns[lo_all[k]]))
                    decider.last_frame[b] = int(c.time_ns[lo_all[k]])
                    if len(seen) == m:
                        break
            continue
        if kind[s] == 1:
            for k0 in range(s, e, _DECIDE_BLOCK):
                k1 = min(k0 + _DECIDE_BLOCK, e)
                decide_block(k0, k1)
                mark_emptied(k0, k1)
            continue
        for k in range(s, e):
            lo, hi = int(lo_all[k]), int(hi_all[k])
            a = int(c.camera[lo])
            redo = bool(redo_frame[k]) and any(
                j >= 0 and (j in spoiled[b] or j in emptied[b])
                for row in used[lo:hi].tolist() for b in range(m) if b != a for j in row[b])
            if redo:
                for i in range(lo, hi):
                    if i not in saved:
                        saved[i] = (ratio[i].copy(), carried[i].copy(), points[i].copy(),
                                    bool(in_front[i]))
                    t_i = int(c.time_ns[i])
                    und_i = c.uv_und[i].tolist()
                    for b in range(m):
                        if b == a or not keys(b):
                            continue
                        search = (bisect_right if (not causal or wait_ns > 0 or b < a)
                                  else bisect_left)
                        line = _line_of(F_lists[a][b], *und_i)
                        r, uv = _support_one(t_i, line, keys(b), usable_of(b), search, wait_ns,
                                             causal, max_gap_ns, options)
                        if any(j in emptied[b] and abs(t_i - keys(b)[j]) <= max_gap_ns
                               for j in used[i, b].tolist()):
                            # the better of the two carries (_emptied), where a frame
                            # emptied lies within the gap (as decide_at: one beyond it
                            # carried nothing, yet skipped it may turn the single frame
                            # before t into an extrapolation from two)
                            r2, uv2 = _support_one(t_i, line, keys(b), usable_of(b, True),
                                                   search, wait_ns, causal, max_gap_ns,
                                                   options)
                            if r2 < r:
                                r, uv = r2, uv2
                        ratio[i, b] = r
                        carried[i, b] = uv if uv is not None else (math.nan, math.nan)
                    p, ok, miss = _points_one(a, c.ray_dir[i].tolist(), ratio[i].tolist(),
                                              carried[i].tolist(), constants)
                    points[i] = p if p is not None and not miss > options.track_m else math.nan
                    in_front[i] = ok
            decide_block(k, k + 1)
            mark_emptied(k, k + 1)
            if hi - lo < 2:
                continue  # one candidate: every one may support (_supporting)
            kept = _supporting(reason[lo:hi].tolist())
            if kept is None:
                continue
            at = int(position[lo])
            if judged(a, at):
                spoiled[a].add(at)
                kept_of[a][at] = [(int(c.time_ns[i]), *c.uv_und[i].tolist())
                                  for i, ok in zip(range(lo, hi), kept, strict=True) if ok]
    return unforeseen if any(unforeseen) else []


def _supporting(reasons: list[int]) -> list[bool] | None:
    """Which candidates of a decided frame (their ``reason`` codes, -1 chosen) may support
    a later choice (:func:`_support_one`), or None when every one still may: with one
    chosen, it and those only outscored (they passed every gate; the frame's choice among
    them is no evidence against them), not those a gate rejected; with none chosen, all."""
    if all(r < 0 or r == OUTSCORED for r in reasons) or not any(r < 0 for r in reasons):
        return None
    return [r < 0 or r == OUTSCORED for r in reasons]


def _emptied(reasons: list[int]) -> bool:
    """Whether an offline choice decided a frame (its candidates' ``reason`` codes, -1
    chosen) with every candidate rejected: then, where the stillness test could judge it
    (:func:`_can_judge`), a later choice's support (:func:`_decide_in_order`, the compiled
    ``decide_at``) carries the better of two: with every candidate of the frame, as with
    any frame decided with none chosen (:func:`_supporting`: dropping them made rejections
    self-sustaining), and with the frame skipped, as the empty frame it is for the ball
    (the lower ratio; a skip that finds no frame near never wins). A camera that missed the
    ball in a frame that held only a static object or a blob otherwise carried that object
    into the next choice of the other cameras, and the ball there was rejected (``paper3``
    rally-79906, docs/methods.md "Held out (session 45"). The causal forms keep the one
    carry (the stream gate's, bit for bit)."""
    return not any(r < 0 for r in reasons)


def _can_judge(key: int, earlier: list[int], lags: int, options: GatingOptions) -> bool:
    """Whether the stillness test (:func:`_static`) can judge a frame's candidates: it calls a
    candidate static when still in ``0.75 lags`` of its camera's ``lags`` frames before it
    that lie within 1.5 ``static_s`` (``key``, ``earlier``: the frame's and those frames'
    times ns). With fewer (a camera's first ``static_s``, or after a blackout) no candidate
    can be static yet, so a static object seen by every camera passes every gate, may be
    chosen and seed the track, and the gates then reject the ball: such a frame's
    rejections are no evidence, and all its candidates keep supporting (:func:`_supporting`).
    """
    recent = sum(1 for k in earlier if key - k <= 1.5 * options.static_s * NS)
    return recent >= 0.75 * lags


def _stillness_one(key: int, pts, earlier, lags: int, options: GatingOptions,
                   uvs=None, paired=None, cam=None, dz=None):
    """:func:`_static`'s rule for one frame on floats (the same bits): ``pts`` its
    candidates' points (k, 3) as lists, ``earlier`` (frame time ns, points, undistorted
    pixels, whether each one's support held (:func:`_held`; None: whether it has a point))
    of its camera's frames before it, newest first (``lags`` of them for the 3D
    test and the image test; up to ``ceil(LONG_STILL static_s fps)`` for the long image
    test); ``uvs`` the frame's undistorted pixels (k, 2), ``paired`` (k,) bool (its point
    rests on one other camera), ``cam`` its Camera (the image tests; None: the 3D test
    alone), ``dz`` (k,) its candidates' rays' world z (the long test). Returns (static (k,)
    bool, stillness (k,), lone (k,): :func:`_static`'s three values)."""
    run = np.zeros(len(pts))
    run_px = np.zeros(len(pts))
    run_long = np.zeros(len(pts))
    held = np.zeros(len(pts))
    # each candidate's own tolerance (the image test's counts, whatever supports it), and
    # the paired ones' (the image test's static verdict and the long test)
    owns = [_still_px(cam, x, y, z, options, _sqrt)
            if cam is not None and math.isfinite(x) else math.nan for x, y, z in pts]
    tols = [own if cam is not None and paired[j] else math.nan
            for j, own in enumerate(owns)]
    # the image test's counts: a candidate without a point borrows the tolerance of one
    # known at its pixel (:func:`_borrowed_tolerance`)
    owns_px = list(owns)
    for j in range(len(pts) if cam is not None else 0):
        if owns[j] == owns[j]:
            continue
        u, v = uvs[j]
        for n, (prev_key, prev_points, prev_uvs, _) in enumerate(earlier, start=1):
            if n > lags:
                break
            if not key - prev_key <= 1.5 * options.static_s * NS:
                continue
            found = math.inf
            for (pu, pv), (px, py, pz) in zip(prev_uvs, prev_points, strict=True):
                if px == px and py == py and pz == pz:
                    own = _still_px(cam, px, py, pz, options, _sqrt)
                    du, dv = u - pu, v - pv
                    if _sqrt(du * du + dv * dv) <= own and own < found:
                        found = own
            if found < math.inf:
                owns_px[j] = found
                tols[j] = found  # (its long test too, as a paired one's: lone, not static)
                break
    borrowed = [owns[j] != owns[j] and owns_px[j] == owns_px[j] for j in range(len(pts))]
    # the candidates still across their ray in every frame so far (only they can pass the
    # long test, which asks for every one of its frames)
    alive = [t == t for t in tols]  # (an image test: not NaN)
    for n, (prev_key, prev_points, prev_uvs, prev_held) in enumerate(earlier, start=1):
        if n > lags and not any(alive):
            break  # (the long image test's frames: nothing left to test)
        recent = key - prev_key <= 1.5 * options.static_s * NS
        recent_long = key - prev_key <= 1.5 * LONG_STILL * options.static_s * NS
        if not (recent or recent_long):
            alive = [False] * len(pts)
            continue
        for j, (x, y, z) in enumerate(pts):
            if n > lags and not alive[j]:
                continue
            best_px = math.inf
            supported = False
            still_long = False
            if owns_px[j] == owns_px[j]:  # (an image test: not NaN)
                u, v = uvs[j]
                for i, ((pu, pv), (px, py, pz)) in enumerate(zip(prev_uvs, prev_points,
                                                                 strict=True)):
                    du, dv = u - pu, v - pv
                    d = _sqrt(du * du + dv * dv)
                    if d < best_px:
                        best_px = d
                    finite = px == px and py == py and pz == pz
                    if d <= owns_px[j] and (finite if prev_held is None else prev_held[i]):
                        supported = True
                    # _still_pair: the smaller of the two candidates' tolerances
                    pair = tols[j]
                    if finite:
                        own = _still_px(cam, px, py, pz, options, _sqrt)
                        if own < pair:
                            pair = own
                    if d <= pair:
                        still_long = True
            if recent_long and still_long:
                run_long[j] += 1.0
            else:
                alive[j] = False
            if n > lags or not recent:
                continue  # (the long image test's frames only)
            best = math.inf
            for px, py, pz in prev_points:
                dx, dy, dz_ = x - px, y - py, z - pz
                d = math.sqrt(dx * dx + dy * dy + dz_ * dz_)  # np.linalg.norm's order
                if d < best:  # NaN (no point) never is
                    best = d
            if supported:
                held[j] += 1.0
            if best <= options.static_m:
                run[j] += 1.0
            if best_px <= owns_px[j]:
                run_px[j] += 1.0
    alone = _still_alone(run_px, held, lags)
    static = ((run >= 0.75 * lags) | (alone & ~np.isnan(np.array(tols)))) & ~np.array(
        borrowed, dtype=bool)
    lone = np.where(alone, owns_px, math.nan)
    if cam is not None and dz is not None and any(alive):
        long_lags = int(np.ceil(LONG_STILL * options.static_s * cam.fps))
        for j in range(len(pts)):
            dz_j = float(dz[j])
            if alive[j] and dz_j * dz_j <= 1.0:  # (np.sqrt's NaN in _static: not static)
                long = bool(_still_long(run_long[j], dz_j, long_lags, cam.fps, options, _sqrt))
                if borrowed[j]:
                    if long:
                        lone[j] = owns_px[j]
                else:
                    static[j] |= long
    return static, run / lags, lone


def _result(detections: Detections, rig: Rig, reason: np.ndarray,
            options: GatingOptions | None = None, doubt: bool | str = True) -> Gated:
    chosen = reason < 0
    rej = ~chosen
    rows = detections.cand_frame[rej]
    rejections = Rejections(detections.frame_time_ns[rows], detections.frame_camera[rows],
                            detections.frame_index[rows], detections.cand_uv[rej],
                            detections.cand_score[rej], reason[rej])
    observations = timed_observations(_chosen_candidates(detections, chosen), rig)
    return Gated(observations, rejections, chosen, reason,
                 _observation_doubt(detections, rig, reason, observations,
                                    (options or GatingOptions()).static_s, doubt == "start",
                                    options)
                 if doubt else None)


#: A choice is in doubt when its camera rejected candidates this close to it (recorded
#: pixels), at least :data:`DOUBT_REJECTIONS` of them, in its own frame or in the frames of
#: the ``static_s`` before it: by the motion gate (a static object, mostly), or by any gate
#: in a frame of several candidates (a clean camera's frames hold one, the ball)
#: (:func:`choice_doubt`).
DOUBT_RADIUS_PX = 5.0
#: Rejections near a choice that put it in doubt: something stood there (one alone may be
#: the ball itself, slow in the image, that the motion gate refused once: a clean wide3
#: rally, 1.43 s).
DOUBT_REJECTIONS = 2
#: The chance that a choice in doubt is not the ball: the gate could not tell the two
#: hypotheses apart (the ball has come to the still object's pixel, or the object is seen
#: while the ball is elsewhere), so each is given half.
DOUBT_CHANCE = 0.5


def doubt_variance(u, v, width, height):
    """The variance per image axis (pixels²) a choice at recorded pixel ``(u, v)`` of a
    ``width`` x ``height`` camera adds when it is in doubt: with chance :data:`DOUBT_CHANCE`
    the ball is not there but anywhere in the image (nothing else is known), uniform, whose
    mean squared offset from ``(u, v)`` is ``(W² + H²)/12 + (u - W/2)² + (v - H/2)²``;
    half of it per axis (docs/methods.md, "A choice in doubt"). Arrays or Python floats,
    the same operations in the same order (the same bits in the batch and the stream)."""
    du = u - 0.5 * width
    dv = v - 0.5 * height
    return DOUBT_CHANCE * 0.5 * ((width * width + height * height) / 12.0 + du * du + dv * dv)


def choice_doubt(time_ns: np.ndarray, camera: np.ndarray, uv: np.ndarray,
                 still_time_ns: np.ndarray, still_camera: np.ndarray, still_uv: np.ndarray,
                 rig: Rig, static_s: float) -> np.ndarray:
    """The doubt of the gate's choices (k,): :func:`doubt_variance` (pixels² per axis)
    of each choice (LOGGED frame time ns, camera, recorded pixel) within
    :data:`DOUBT_RADIUS_PX` of at least :data:`DOUBT_REJECTIONS` candidates its camera
    rejected (``still_*``: their logged frame times, cameras, recorded pixels;
    :func:`doubt_source`) at frame times in ``[t - static_s, t]``; 0 for the others.
    Causal: only its camera's decisions up to its own frame."""
    out = np.zeros(len(time_ns))
    if not len(time_ns) or not len(still_time_ns):
        return out
    window = round(static_s * NS)
    width = np.array([float(c.width) for c in rig.cameras])
    height = np.array([float(c.height) for c in rig.cameras])
    for cam in np.unique(still_camera).tolist():
        s = np.flatnonzero(still_camera == cam)
        s = s[np.argsort(still_time_ns[s], kind="stable")]
        st, su = still_time_ns[s], still_uv[s]
        c = np.flatnonzero(camera == cam)
        if not len(c):
            continue
        lo = np.searchsorted(st, time_ns[c] - window, side="left")
        hi = np.searchsorted(st, time_ns[c], side="right")
        n = hi - lo
        if not n.any():
            continue
        which = np.repeat(np.arange(len(c)), n)
        j = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n) + np.repeat(lo, n)
        du = uv[c[which], 0] - su[j, 0]
        dv = uv[c[which], 1] - su[j, 1]
        with np.errstate(over="ignore"):  # (a pixel of 1e300 squared: inf, not close)
            close = which[du * du + dv * dv <= DOUBT_RADIUS_PX * DOUBT_RADIUS_PX]
        near = c[np.bincount(close, minlength=len(c)) >= DOUBT_REJECTIONS]
        out[near] = doubt_variance(uv[near, 0], uv[near, 1], width[cam], height[cam])
    return out


def doubt_source(reason, several):
    """Whether a rejected candidate (``reason`` its code, ``several``: its frame held more
    than one candidate) can put a choice beside it in doubt: rejected by the motion gate,
    or by any gate in a frame of several candidates. Arrays or Python values."""
    return (reason == MOTION) | ((reason >= 0) & several)


def late_doubt(detections: Detections, reason: np.ndarray, static_s: float) -> int:
    """The session's first choice, when a later verdict puts it in doubt: its candidate
    row, else -1 (docs/methods.md, "A contested start", "The first choice shown wrong
    later"). The first choice in (logged time, camera) order, not CONTESTED, whose
    camera's next two frames with candidates, both within ``static_s`` after it, each
    refused a candidate within :data:`DOUBT_RADIUS_PX` of it (recorded pixels) in a frame of
    several candidates, or chose one there CONTESTED: what stood at its pixel was still
    there and refused as a guess, so the first choice, one line's guess at a time nothing
    could judge, was one too. A clean camera's frames hold one candidate and no clean
    session has a contested choice: no clean first choice is so judged. The stream waits for
    the verdict before fusing (:class:`StreamStart`): the same bits."""
    chosen = np.flatnonzero(reason < 0)
    if not len(chosen):
        return -1
    f = detections.cand_frame[chosen]
    t = detections.frame_time_ns[f]
    at = np.flatnonzero(t == t.min())  # (the earliest; of those, the lowest camera)
    first = int(chosen[at[np.argmin(detections.frame_camera[f[at]])]])
    if reason[first] == CONTESTED:
        return -1
    f0 = int(detections.cand_frame[first])
    a, t0 = int(detections.frame_camera[f0]), int(detections.frame_time_ns[f0])
    u0, v0 = detections.cand_uv[first].tolist()
    end = t0 + round(static_s * NS)
    count = detections.candidates_per_frame()
    later = np.flatnonzero((detections.frame_camera == a) & (detections.frame_time_ns > t0)
                           & (detections.frame_time_ns <= end) & (count > 0))
    later = later[np.argsort(detections.frame_time_ns[later], kind="stable")][:2]
    if len(later) < 2:
        return -1
    starts = np.searchsorted(detections.cand_frame, later, side="left").tolist()
    for fr, lo in zip(later.tolist(), starts, strict=True):
        refused = False
        for i in range(lo, lo + int(count[fr])):
            u, v = detections.cand_uv[i].tolist()
            r = int(reason[i])
            if _refusal(r, int(count[fr]) >= 2, u - u0, v - v0):
                refused = True
        if not refused:
            return -1
    return first


def _camera_frames(detections: Detections, count: np.ndarray, n_cameras: int) -> list:
    """Each camera's frames with candidates in time order: ``[(frames (k,) int64, their
    LOGGED times (k,) int64 ns), ...]`` in rig order (``count``: candidates per frame)."""
    out = []
    for b in range(n_cameras):
        f = np.flatnonzero((detections.frame_camera == b) & (count > 0))
        f = f[np.argsort(detections.frame_time_ns[f], kind="stable")]
        out.append((f, detections.frame_time_ns[f]))
    return out


def unjudged_doubt(detections: Detections, rig: Rig, reason: np.ndarray, chosen: np.ndarray,
                   static_s: float) -> np.ndarray:
    """The doubt (:func:`doubt_variance`, else 0) of the chosen candidates ``chosen`` (rows)
    that the stillness test could not judge, shown wrong by their camera's frames after
    them: OFFLINE only (``smooth``'s ``doubt="start"``; docs/methods.md, "A static object
    at the start"). In a camera's first ``static_s`` (fewer than ``0.75 ceil(static_s
    fps)`` of its frames with candidates in the 1.5 ``static_s`` before, logged times:
    :func:`_can_judge`) no candidate can be static, so a static object seen by every
    camera is consistent in three views and passes every gate, and may outscore the ball.
    Such a choice is in doubt when at least :data:`DOUBT_REJECTIONS` candidates within
    :data:`DOUBT_RADIUS_PX` of it (recorded pixels) were rejected in frames of several
    candidates of its camera at logged times in ``[t, t + static_s]``: something stood at
    its pixel and was refused, as the ball beside it would not be. A clean camera's frames
    hold one candidate: no clean choice is so judged."""
    out = np.zeros(len(chosen))
    if not len(chosen):
        return out
    frame = detections.cand_frame
    count = detections.candidates_per_frame()
    source = np.flatnonzero((reason >= 0) & (count[frame] >= 2))
    if not len(source):
        return out
    # each camera's frames with candidates: how many lie in the 1.5 static_s before each
    unjudged_frame = np.zeros(detections.n_frames, dtype=bool)
    for cam, (f, t) in zip(rig.cameras, _camera_frames(detections, count, len(rig)),
                           strict=True):
        if not len(f):
            continue
        earlier = np.arange(len(f)) - np.searchsorted(
            t, t - 1.5 * static_s * NS, side="left")
        lags = int(np.ceil(static_s * cam.fps))
        unjudged_frame[f[earlier < 0.75 * lags]] = True
    rows = np.flatnonzero(unjudged_frame[frame[chosen]])
    if not len(rows):
        return out
    # (choice_doubt on negated times: its sources in [t, t + static_s])
    c = chosen[rows]
    out[rows] = choice_doubt(-detections.frame_time_ns[frame[c]], detections.frame_camera[frame[c]],
                             detections.cand_uv[c], -detections.frame_time_ns[frame[source]],
                             detections.frame_camera[frame[source]],
                             detections.cand_uv[source], rig, static_s)
    return out


def _stood(x: float, y: float, frames) -> bool:
    """Whether every one of ``frames`` (``(time ns, pixels)``, pixels ``[(u, v), ...]``)
    holds a candidate within :data:`DOUBT_RADIUS_PX` of ``(x, y)`` (recorded pixels):
    it stood there (:func:`unmoved`, :func:`_still_partner`; Python numbers, the same bits
    in the batch and the stream)."""
    radius2 = DOUBT_RADIUS_PX * DOUBT_RADIUS_PX
    return all(any((x - xj) * (x - xj) + (y - yj) * (y - yj) <= radius2 for xj, yj in px)
               for _, px in frames)


def unmoved(t: int, u: float, v: float, own, earlier, lags: int, static_s: float,
            speed_px_s: float, partner: Callable[[], bool] | None = None) -> bool:
    """Whether a choice of a camera (LOGGED frame time ``t`` ns, recorded pixel ``(u, v)``;
    ``own``: the recorded pixels of every candidate of its frame, ``[(u, v), ...]``) made
    before its camera could judge stillness stood still beside a candidate that moved as a
    ball does, or beside another still one (docs/methods.md, "An unmoved choice at the
    start"). ``earlier``: its camera's frames with candidates, ``(time ns, pixels)`` each in
    time order (any not before ``t`` are skipped); those within 1.5 ``static_s`` before it
    are the frames the stillness test looks at. True when they are fewer than ``0.75 lags``
    (:func:`_can_judge`'s count: the test cannot judge yet), at least one, every one of them
    holds a candidate within :data:`DOUBT_RADIUS_PX` of ``(u, v)`` (it stood there in every
    frame available), and its own frame holds another candidate that
    - moved (one of those frames holds none within :data:`DOUBT_RADIUS_PX` of it) within a
      ball's reach, ``speed_px_s`` times the time since, of a candidate of the newest of
      them (a ball in flight; a blob that comes from nowhere is not), or
    - stood too, while ``partner()`` says another camera holds a still candidate on the
      choice's epipolar line (:func:`_still_partner`: a still point in space chosen between
      two still things, a static object or a ball at rest).
    A clean camera's frames hold one candidate: never. Python numbers, the same operations
    in the batch (:func:`unmoved_doubt`) and the stream (:class:`StreamDoubt`)."""
    if len(own) < 2:
        return False
    span = 1.5 * static_s * NS
    recent = [e for e in earlier if t - span <= e[0] < t]
    if not recent or len(recent) >= 0.75 * lags:
        return False
    if not _stood(u, v, recent):
        return False
    # the newest of them that holds a candidate besides the choice's: a frame where the ball
    # was missed holds the still one alone, and the ball beside it then seemed to come from
    # nowhere (walk38: a webcam's 5 % misses, the object chosen with no doubt, the filter's
    # first points 0.93 m off)
    radius2 = DOUBT_RADIUS_PX * DOUBT_RADIUS_PX
    newest = next((e for e in reversed(recent)
                   if any((xj - u) * (xj - u) + (yj - v) * (yj - v) > radius2
                          for xj, yj in e[1])), recent[-1])
    reach = speed_px_s * ((t - newest[0]) / NS)
    reach2 = reach * reach
    still_too = False
    for x, y in own:
        if x == u and y == v:
            continue
        if _stood(x, y, recent):
            still_too = True
        elif any((x - xj) * (x - xj) + (y - yj) * (y - yj) <= reach2
                 for xj, yj in newest[1]):
            return True
    return still_too and partner is not None and partner()


def _still_partner(t: int, a: int, u: float, v: float, frames_of, rig: Rig, F_lists,
                   static_s: float, epipolar_px: float) -> bool:
    """Whether another camera ``b`` holds, in its newest frame with candidates before
    camera ``a``'s at LOGGED time ``t`` ((time, camera) order: the stream has it), a
    candidate that stood within :data:`DOUBT_RADIUS_PX` of a candidate of each of its
    other frames within 1.5 ``static_s`` before (at least one) and lies within
    ``epipolar_px`` of the epipolar line of ``(u, v)`` (recorded pixels, undistorted here):
    with it, a still point in space (:func:`unmoved`). ``frames_of(b)``: camera ``b``'s
    frames with candidates, ``(time ns, pixels)`` in time order (older or newer ones are
    skipped). Python numbers: the same bits in the batch and the stream."""
    span = 1.5 * static_s * NS
    ua, va = _pixel_geometry(rig.cameras[a], np.array([[u, v]]))[0][0].tolist()
    for b in range(len(rig.cameras)):
        if b == a:
            continue
        frames = [e for e in frames_of(b) if t - span <= e[0] and (e[0] < t or (
            e[0] == t and b < a))]
        if len(frames) < 2:
            continue
        la, lb, lc = _line_of(F_lists[a][b], ua, va)
        if math.isnan(la):
            continue
        for x, y in frames[-1][1]:
            if not _stood(x, y, frames[:-1]):
                continue
            xu, yu = _pixel_geometry(rig.cameras[b], np.array([[x, y]]))[0][0].tolist()
            if abs(la * xu + lb * yu + lc) <= epipolar_px:
                return True
    return False


def _frame_pixels(detections: Detections, lo: int, n: int) -> tuple:
    """The recorded pixels of a frame's ``n`` candidates from row ``lo``, ``((u, v), ...)``
    (Python floats, as :class:`StreamDoubt` keeps them)."""
    return tuple(tuple(x) for x in detections.cand_uv[lo:lo + n].tolist())


def unmoved_doubt(detections: Detections, rig: Rig, reason: np.ndarray, chosen: np.ndarray,
                  options: GatingOptions) -> np.ndarray:
    """The doubt (:func:`doubt_variance`, else 0) of the chosen candidates ``chosen`` (rows)
    that stood still beside a candidate that moved while their camera could not judge
    stillness (:func:`unmoved`): CAUSAL (their camera's frames up to their own). In a
    camera's first ``static_s`` a static object seen by every camera passes every gate and
    may be chosen over the ball with nothing rejected near it yet; a candidate that stood
    at its pixel in every frame so far is such an object or a ball at rest, which the
    stillness test rejects once it can judge anyway (docs/methods.md, "An unmoved choice
    at the start"). Only frames of several candidates: no clean choice is so judged."""
    out = np.zeros(len(chosen))
    if not len(chosen):
        return out
    static_s, epipolar_px = options.static_s, options.epipolar_px
    speed_px_s = options.max_image_speed_px_s
    frame = detections.cand_frame
    count = detections.candidates_per_frame()
    start = np.searchsorted(frame, np.arange(detections.n_frames), side="left")
    span = 1.5 * static_s * NS
    F_lists = fundamental_matrices(rig.cameras).tolist()
    # each camera's frames with candidates in time order (rows, times)
    order = _camera_frames(detections, count, len(rig))

    def frames_near(b: int, t: int) -> list:
        f, tb = order[b]
        lo = int(np.searchsorted(tb, t - span, side="left"))
        hi = int(np.searchsorted(tb, t, side="right"))
        return [(int(tb[i]), _frame_pixels(detections, int(start[f[i]]), int(count[f[i]])))
                for i in range(lo, hi)]

    for b, cam in enumerate(rig.cameras):
        f, t = order[b]
        if not len(f):
            continue
        first = np.searchsorted(t, t - span, side="left")
        lags = int(np.ceil(static_s * cam.fps))
        # (frames the test cannot judge, with an earlier frame: few, the camera's first
        # static_s and the frames after a spell without candidates)
        maybe = np.flatnonzero((np.arange(len(f)) - first < 0.75 * lags)
                               & (np.arange(len(f)) > first))
        if not len(maybe):
            continue
        rows = np.flatnonzero(np.isin(frame[chosen], f[maybe[count[f[maybe]] >= 2]]))
        if not len(rows):
            continue
        at = np.zeros(detections.n_frames, dtype=np.int64)
        at[f] = np.arange(len(f))
        for k in rows.tolist():
            i = int(at[frame[chosen[k]]])
            u, v = detections.cand_uv[chosen[k]].tolist()
            px = [_frame_pixels(detections, int(start[fr]), int(count[fr]))
                  for fr in f[int(first[i]):i + 1].tolist()]
            ti = int(t[i])
            partner = functools.partial(
                _still_partner, ti, b, u, v, functools.partial(frames_near, t=ti), rig,
                F_lists, static_s, epipolar_px)
            if unmoved(ti, u, v, px[-1],
                       list(zip(t[int(first[i]):i].tolist(), px[:-1], strict=True)), lags,
                       static_s, speed_px_s, partner):
                out[k] = doubt_variance(u, v, float(cam.width), float(cam.height))
    return out


def _refusal(reason: int, several: bool, du: float, dv: float) -> bool:
    """Whether a candidate of a camera's frame (``reason`` its code, ``several``: its frame
    held more than one) at ``(du, dv)`` recorded pixels from the camera's first choice
    speaks against that choice (:func:`late_doubt`): refused in a frame of several, or
    chosen CONTESTED, within :data:`DOUBT_RADIUS_PX`."""
    return ((reason >= 0 and several) or reason == CONTESTED) and (
        du * du + dv * dv <= DOUBT_RADIUS_PX * DOUBT_RADIUS_PX)


def _observation_doubt(detections: Detections, rig: Rig, reason: np.ndarray,
                       observations: Observations, static_s: float,
                       start: bool = False,
                       options: GatingOptions | None = None) -> np.ndarray | None:
    """:func:`choice_doubt` of the chosen candidates (``reason`` < 0), and the whole
    :func:`doubt_variance` of a :data:`CONTESTED` one, on the rows of ``observations`` (the
    chosen ones at their corrected times); None when none is in doubt. ``start``: the
    contested choices' only (no rejection a source: :func:`gate`'s ``doubt="start"``)."""
    frame = detections.cand_frame
    several = detections.candidates_per_frame()[frame] >= 2
    still = np.flatnonzero(np.zeros(len(reason), dtype=bool) if start
                           else doubt_source(reason, several))
    chosen = np.flatnonzero(reason < 0)
    # (the session's first choice shown wrong later counts as a contested one: late_doubt)
    late = late_doubt(detections, reason, static_s)
    contested = np.flatnonzero((reason[chosen] == CONTESTED) | (chosen == late))
    # (a choice made before its camera could judge stillness: offline, "start", beside
    # what its next frames refuse, unjudged_doubt; causal, one that has not moved in its
    # camera's frames so far, unmoved_doubt)
    unjudged = (unjudged_doubt(detections, rig, reason, chosen, static_s) if start
                else unmoved_doubt(detections, rig, reason, chosen,
                                   options or GatingOptions(static_s=static_s)))
    if not len(still) and not len(contested) and not unjudged.any():
        return None
    # (a contested choice is a source too, counted DOUBT_REJECTIONS times: a later choice
    # of its camera at its pixel is the same guess; StreamDoubt._row)
    still = np.concatenate([still, *[chosen[contested]] * DOUBT_REJECTIONS])
    doubt = choice_doubt(detections.frame_time_ns[frame[chosen]],
                         detections.frame_camera[frame[chosen]], detections.cand_uv[chosen],
                         detections.frame_time_ns[frame[still]],
                         detections.frame_camera[frame[still]], detections.cand_uv[still],
                         rig, static_s)
    if len(contested):  # (a contested choice: in doubt whatever was rejected near it)
        size = np.array([(float(c.width), float(c.height)) for c in rig.cameras])
        cam = detections.frame_camera[frame[chosen[contested]]]
        uv = detections.cand_uv[chosen[contested]]
        doubt[contested] = doubt_variance(uv[:, 0], uv[:, 1], size[cam, 0], size[cam, 1])
    doubt = np.maximum(doubt, unjudged)
    flagged = np.flatnonzero(doubt)
    if not len(flagged):
        return None
    out = np.zeros(len(observations))
    rows = chosen[flagged]
    # the observation of each (camera, frame index, pixel): few in doubt, found by frame index
    maybe = np.flatnonzero(np.isin(observations.frame_index, detections.frame_index[frame[rows]]))
    where: dict[tuple, list[int]] = {}
    for i in maybe.tolist():
        key = (int(observations.camera[i]), int(observations.frame_index[i]),
               *observations.uv[i].tolist())
        where.setdefault(key, []).append(i)
    for k, r in zip(flagged.tolist(), rows.tolist(), strict=True):
        f = frame[r]
        key = (int(detections.frame_camera[f]), int(detections.frame_index[f]),
               *detections.cand_uv[r].tolist())
        for i in where.get(key, []):
            out[i] = doubt[k]
    return out


def _chosen_candidates(detections: Detections, chosen: np.ndarray) -> Detections:
    """``detections`` with the candidates ``chosen`` (C,) bool only, every frame kept."""
    return Detections(detections.camera_names, detections.frame_time_ns,
                      detections.frame_camera, detections.frame_index,
                      detections.cand_frame[chosen], detections.cand_uv[chosen],
                      detections.cand_radius[chosen], detections.cand_score[chosen])


class _Frame:
    """One frame pushed to a :class:`StreamGate`: its candidates (best first) and what the
    gate computed of them once (corrected times, undistorted pixels, rays; once decided,
    their 3D points and rejection reasons)."""

    __slots__ = ("camera", "every", "held", "index", "key", "latest", "points", "ray_dir",
                 "reason", "support", "t", "time_ns", "uv", "uv_und")

    def __init__(self, t: int, camera: int, index: int, uv: np.ndarray, time_ns: list[int],
                 uv_und: np.ndarray, ray_dir: np.ndarray) -> None:
        self.t, self.camera, self.index, self.uv = t, camera, index, uv
        self.time_ns = time_ns  # corrected, per candidate
        self.uv_und, self.ray_dir = uv_und, ray_dir
        self.key = self.time_ns[0]  # the frame's time: its best candidate's (_frame_table)
        self.latest = max(time_ns)  # (a rolling shutter's lowest row: when it is ready)
        self.reason: np.ndarray | None = None
        self.points: list | None = None
        self.held: list[bool] = []  # per candidate, once decided: its support held (_held)
        # the candidates that may support another camera's choice, (t, u, v): every one
        # until the frame is decided, then the chosen one if any (:func:`_support_one`)
        self.every = [(t, u, v) for t, (u, v) in zip(time_ns, uv_und.tolist(), strict=True)]
        self.support = self.every


class _Held:
    """One frame pushed to a compiled :class:`StreamGate` (its state lives in
    :class:`pslog.fusion._gate_kernel.GateState`): what releasing it needs."""

    __slots__ = ("camera", "fid", "index", "key", "latest", "reason", "t", "uv")

    def __init__(self, t: int, camera: int, index: int, uv: np.ndarray, key: int, latest: int,
                 fid: int) -> None:
        self.t, self.camera, self.index, self.uv = t, camera, index, uv
        self.key, self.latest, self.fid = key, latest, fid  # (latest: of its corrected times)
        self.reason: list[int] | None = None


def stream_arrays(time_ns, camera, uv, frame_index, n_cameras: int, who: str):
    """The columns one stream push takes, checked: ``time_ns`` (n,) int64, ``camera`` (n,)
    int32 in ``[0, n_cameras)``, ``uv`` (n, 2) float64, ``frame_index`` (n,) int64 (zeros when
    None). A FusionError names the push (``who``) and what does not fit: the compiled kernels
    index their tables with these values and would read past them otherwise."""
    time_ns = _integer_column(time_ns, "time_ns", who)
    camera = _integer_column(camera, "camera", who)
    try:
        uv = np.asarray(uv, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise FusionError(f"{who}: uv must be (n, 2) pixels: {exc}") from None
    if uv.size % 2 or (uv.ndim > 1 and uv.shape[-1] != 2):
        raise FusionError(f"{who}: uv must be (n, 2) pixels, got shape {uv.shape}")
    uv = uv.reshape(-1, 2)
    frame_index = (np.zeros(len(time_ns), np.int64) if frame_index is None
                   else _integer_column(frame_index, "frame_index", who))
    if not len(time_ns) == len(camera) == len(uv) == len(frame_index):
        raise FusionError(f"{who}: time_ns, camera, uv and frame_index must have one row per "
                          f"detection, got {len(time_ns)}, {len(camera)}, {len(uv)} and "
                          f"{len(frame_index)} rows")
    if len(camera) == 1:  # (one detection per push, the live case: no numpy reductions)
        outside = not 0 <= int(camera[0]) < n_cameras
    else:
        outside = bool(len(camera)) and (camera.min() < 0 or camera.max() >= n_cameras)
    if outside:
        bad = camera[(camera < 0) | (camera >= n_cameras)][0]
        raise FusionError(f"{who}: camera index {bad} is not one of the rig's {n_cameras} "
                          f"cameras (0 to {n_cameras - 1})")
    return time_ns, camera.astype(np.int32), uv, frame_index


def _integer_column(values, name: str, who: str) -> np.ndarray:
    """``values`` as an (n,) int64 column, checked BEFORE the conversion (which would wrap
    2**32 + 1 or truncate 1.7 silently): integers within int64, or floats that are whole
    numbers within it."""
    if isinstance(values, np.ndarray) and values.dtype.kind == "i" and values.ndim == 1:
        return values if values.dtype == np.int64 else values.astype(np.int64)  # (fast path)
    try:
        array = np.atleast_1d(np.asarray(values))
    except (TypeError, ValueError) as exc:
        raise FusionError(f"{who}: {name} must be integers: {exc}") from None
    if array.dtype.kind == "u" and len(array) and array.max() > np.iinfo(np.int64).max:
        _bad_integer(array.max(), name, who)
    if array.dtype.kind in "iub":
        return array.astype(np.int64, copy=False)
    if array.dtype.kind == "f":
        whole = np.isfinite(array) & (array == np.round(array)) & (np.abs(array) < 2.0**63)
        if not whole.all():
            _bad_integer(array[~whole][0], name, who)
        return array.astype(np.int64)
    if array.dtype.kind == "O":  # Python ints too large for int64 land here
        try:
            return np.asarray([_python_int(v, name, who) for v in array.tolist()], np.int64)
        except OverflowError:
            pass
    raise FusionError(f"{who}: {name} must be integers, got {array.dtype} values "
                      f"such as {array.reshape(-1)[:1].tolist()}")


def _python_int(value, name: str, who: str) -> int:
    if not isinstance(value, int | np.integer) or not -2**63 <= int(value) < 2**63:
        _bad_integer(value, name, who)
    return int(value)


def _bad_integer(value, name: str, who: str):
    shown = value.item() if isinstance(value, np.generic) else value
    raise FusionError(f"{who}: {name} {shown!r} is not an integer within int64")


class StreamGate:
    """The causal gate of :func:`gate` for a stream: frames pushed as they arrive, each
    frame's candidates in one push, best first; each frame is decided once nothing still to
    come can change its choice, and the chosen candidates come out in the pushed (logged)
    order. The choices equal ``gate(detections, rig, causal=True, wait_s=...)`` on the whole
    session: the same arithmetic in the same order on the same history, bit for bit.

    Incremental: a frame's geometry (corrected times, undistorted pixels, rays) is computed
    once, when pushed; deciding it computes only its own candidates' epipolar support (the
    two latest frames of each other camera, :func:`_support`'s causal rule written per
    candidate), their 3D points (:func:`_points_one`), their stillness against the same
    camera's earlier frames' stored points (:func:`_static`'s rule) and the sequential
    choice (:class:`_Decider`). A frame's few candidates are computed on Python floats:
    every batch step is elementwise in an order floats reproduce (no matrix product or
    LAPACK call, whose bits depend on the array's size), so the bits are the batch's. Each
    camera's frames are kept in (corrected time, push) order, as :func:`_frame_table` orders
    them, for ``history`` seconds.

    ``compiled`` (default: when this Python's ``sum`` is one the kernels reproduce): the same
    steps run as compiled kernels over a state in preallocated arrays
    (:mod:`pslog.fusion._gate_kernel`, one call per frame pushed), the same bits; False keeps
    the Python form above. Cost per push at 3 × 30 fps, a few candidates per frame: ~13 µs
    compiled, ~100 µs in Python, on a warm core (``benchmarks/bench_live.py --direct 0``).

    Used by :class:`pslog.fusion.stream.StreamFuser` with ``candidates=True``.
    """

    def __init__(self, rig: Rig, wait_s: float = 0.0, max_gap_s: float | None = None,
                 options: GatingOptions | None = None, compiled: bool | None = None) -> None:
        from ._prepare import default_max_gap_s

        self.rig = rig
        self.options = options or GatingOptions()
        self.wait_ns = round(wait_s * NS)
        self.max_gap_ns = round((max_gap_s or default_max_gap_s(rig)) * NS)
        self.F = fundamental_matrices(rig.cameras)
        self.clock = camera_parameters(rig)
        self.corrected = any(cam.has_clock_correction for cam in rig.cameras)
        spread = float(np.sum(np.abs(self.clock["clock_offset"])) + np.max(self.clock["readout"]))
        # frames older than this (logged) reach no later choice: neither as support (at
        # most max_gap_s away) nor as a stillness reference (1.5 static_s)
        self.history_ns = round((2 * (max_gap_s or default_max_gap_s(rig)) + wait_s
                                 + 1.5 * LONG_STILL * self.options.static_s + 0.2
                                 + 2 * spread) * NS)
        self.decider = _Decider(rig, self.options)
        self.constants = _rig_constants(rig)
        self.camera_k = [cam.K.tolist() for cam in rig.cameras]
        self.camera_r = [cam.R.tolist() for cam in rig.cameras]
        self.distorted = [bool(np.any(cam.dist)) for cam in rig.cameras]
        self.F_lists = self.F.tolist()
        self.clock_model = _clock_model(rig)
        self.lags = [int(np.ceil(self.options.static_s * cam.fps)) for cam in rig.cameras]
        # per camera: its frames in (corrected time, push) order and their times
        self.keys: list[list[int]] = [[] for _ in rig.cameras]
        self.by_camera: list[list[_Frame]] = [[] for _ in rig.cameras]
        self.pending: list = []  # not decided yet, in pushed order (_Frame or _Held)
        self.unreleased: deque = deque()  # not returned yet, in pushed order
        self.last: tuple[int, int] = (np.iinfo(np.int64).min, -1)
        self.rejected: list[tuple] = []
        # the CONTESTED choices ((logged time, camera, u, v)): only before the track first
        # predicted, so a few per session at most
        self.contested: set[tuple] = set()
        self._one_time = np.zeros(1, np.int64)  # (_chosen's times of a frame of one)
        # the compiled form (pslog.fusion._gate_kernel: the same steps, the same bits, one
        # call per frame), unless this Python's sum() is one it does not reproduce
        self._state = None
        if compiled is not False:
            from . import _gate_kernel

            if _gate_kernel.SUM_MODE >= 0:
                self._state = _gate_kernel.GateState(rig, self.options, self.wait_ns,
                                                     self.max_gap_ns, self.F, self.constants,
                                                     self.lags, G)
            elif compiled:
                raise FusionError("the compiled stream gate cannot reproduce this Python's "
                                  "sum() of floats")

    @property
    def compiled(self) -> bool:
        """Whether the frames are decided by the compiled kernels (pslog.fusion._gate_kernel)."""
        return self._state is not None

    def push(self, time_ns, camera, uv, frame_index=None):
        """Add candidates (rows with equal ``(time, camera)`` are one frame's, best first;
        LOGGED times, in (time, camera) order, later than any pushed before). Returns the
        chosen candidates ready to fuse, ``(time_ns, camera, uv, frame_index)`` arrays in
        logged order."""
        time_ns, camera, uv, frame_index = stream_arrays(
            time_ns, camera, uv, frame_index, len(self.rig), "StreamGate.push")
        keys = list(zip(time_ns.tolist(), camera.tolist(), strict=True))
        if (self._state is not None and keys and keys[0] == keys[-1] and not self.pending
                and not self.corrected and not self.wait_ns):
            # one frame, decided as it comes (what _add then _step do, in one compiled call)
            if keys[0] <= self.last:
                raise FusionError("candidates must arrive in (time, camera) order of "
                                  "their logged times, each frame's in one push; got "
                                  f"t={keys[0][0]} ns after t={self.last[0]} ns")
            self.last = keys[0]
            return self._one(keys[0][0], keys[0][1], int(frame_index[0]), uv.copy())
        start = 0
        for i in range(1, len(keys) + 1):
            if i == len(keys) or keys[i] != keys[start]:
                if keys[start] <= self.last:
                    raise FusionError("candidates must arrive in (time, camera) order of "
                                      "their logged times, each frame's in one push; got "
                                      f"t={keys[start][0]} ns after t={self.last[0]} ns")
                self.last = keys[start]
                self._add(keys[start][0], keys[start][1], int(frame_index[start]),
                          uv[start:i].copy())
                start = i
        return self._step(final=False)

    def push_frame(self, t: int, cam: int, index: int, uv: np.ndarray):
        """:meth:`push` of one frame's candidates (Python integers, ``uv`` (k, 2) float64 of
        the caller's own; checked by the caller) when it is decided at once (compiled,
        nothing pending, no clock correction, no wait): the chosen candidates' pixels (c, 2)
        (the frame's time, camera and index are its own); None otherwise, nothing done (then
        :meth:`push` it)."""
        if self._state is None or self.pending or self.corrected or self.wait_ns:
            return None
        if (t, cam) <= self.last:
            raise FusionError("candidates must arrive in (time, camera) order of their logged "
                              f"times, each frame's in one push; got t={t} ns after "
                              f"t={self.last[0]} ns")
        self.last = (t, cam)
        return self._chosen(t, cam, index, uv)

    def _one(self, t: int, cam: int, index: int, uv: np.ndarray):
        """:meth:`push` of one frame that is decided at once (compiled; nothing pending)."""
        chosen = self._chosen(t, cam, index, uv)
        c = len(chosen)
        return (np.full(c, t, np.int64), np.full(c, cam, np.int32), chosen,
                np.full(c, index, np.int64))

    def _chosen(self, t: int, cam: int, index: int, uv: np.ndarray) -> np.ndarray:
        """The frame's chosen candidates' pixels, decided at once (compiled); the rejected
        ones recorded."""
        xy = None
        if self.distorted[cam]:  # the iterative undistortion, in numpy (row by row)
            xy = self._normalized(cam, uv)
        n = len(uv)
        assert self._state is not None  # (push calls it in the compiled form only)
        if n == 1:  # (the usual frame: its one time in an array of the gate's, copied in)
            times = self._one_time
            times[0] = t
        else:
            times = np.full(n, t, np.int64)
        reasons = self._state.push_decide(cam, t, times, uv, xy,
                                          self.last[0] - self.history_ns)
        chosen = []
        for k, r in enumerate(reasons):
            if r < 0:
                chosen.append(k)
                if r == CONTESTED:
                    self.contested.add((t, cam, *uv[k].tolist()))
            else:
                self.rejected.append((t, cam, index, *uv[k].tolist(), r))
        return uv[chosen] if len(chosen) != n else uv

    def _normalized(self, cam: int, uv: np.ndarray) -> np.ndarray:
        """Ideal normalized coordinates (k, 2) of a lensed camera's pixels ``uv`` (k, 2)
        (NaN where :func:`_pixel_geometry` gives none: far outside the image)."""
        camera = self.rig.cameras[cam]
        limit = 10 * max(camera.width, camera.height)
        sane = np.all(np.abs(uv) <= limit, axis=1)
        xy = np.full((len(uv), 2), np.nan)
        if sane.any():
            xy[sane] = camera.undistort_normalized(uv[sane])
        return xy

    def flush(self):
        """Decide and return every remaining frame (end of stream)."""
        return self._step(final=True)

    @property
    def rejections(self) -> Rejections:
        """Every candidate rejected so far."""
        return Rejections.from_rows([(t, c, f, u, v, 1.0, REASONS[r])
                                     for t, c, f, u, v, r in self.rejected])

    def _add(self, t: int, cam: int, index: int, uv: np.ndarray) -> None:
        # as _candidates: each candidate at its own row's corrected time (the logged one
        # without a clock model: its correction is 0 for any row)
        clock = self.clock_model[cam]
        time_ns = ([t] * len(uv) if not self.corrected else
                   [_true_time_ns(t, v, clock) for v in uv[:, 1].tolist()])
        if self._state is not None:
            xy = self._normalized(cam, uv) if self.distorted[cam] else None
            fid = self._state.insert(cam, t, np.array(time_ns, np.int64), uv, xy)
            held = _Held(t, cam, index, uv, time_ns[0], max(time_ns), fid)
            self.pending.append(held)
            self.unreleased.append(held)
            return
        frame = _Frame(t, cam, index, uv, time_ns, *self._geometry(cam, uv))
        at = bisect_right(self.keys[cam], frame.key)  # after equal times: push order
        self.keys[cam].insert(at, frame.key)
        self.by_camera[cam].insert(at, frame)
        self.pending.append(frame)
        self.unreleased.append(frame)

    def _geometry(self, cam: int, uv: np.ndarray):
        """:func:`_pixel_geometry` of one frame's candidates, on floats (the same bits)."""
        camera = self.rig.cameras[cam]
        k, r = self.camera_k[cam], self.camera_r[cam]
        limit = 10 * max(camera.width, camera.height)
        rows = uv.tolist()
        sane = [abs(u) <= limit and abs(v) <= limit for u, v in rows]
        if self.distorted[cam]:  # the iterative undistortion, in numpy (row by row)
            xy = iter(camera.undistort_normalized(uv[sane]).tolist() if any(sane) else [])
        else:  # Camera.normalized_from_pixels
            xy = iter([(((u - k[0][2]) - k[0][1] * ((v - k[1][2]) / k[1][1])) / k[0][0],
                        (v - k[1][2]) / k[1][1]) for (u, v), ok in zip(rows, sane, strict=True)
                       if ok])
        und, rays = [], []
        for ok in sane:
            x, y = next(xy) if ok else (math.nan, math.nan)
            if not (ok and math.isfinite(x) and math.isfinite(y)):  # (not undistorted)
                und.append((math.nan, math.nan))
                rays.append((math.nan, math.nan, math.nan))
                continue
            u, v, *d = _from_normalized(x, y, k, r, _sqrt, max)
            und.append((u, v))
            rays.append(tuple(d))
        return np.array(und), np.array(rays)

    def _step(self, final: bool):
        if self.pending:
            # gate()'s order: (time, camera), then push (frame) order
            todo = sorted(self.pending, key=lambda f: (f.key, f.camera))
            if not final:
                # the frames nothing still to come can change: every frame still to come is
                # later than ``bound``, and a candidate at t uses frames up to t + wait, so a
                # frame is ready once its LATEST candidate (a rolling shutter's lowest row)
                # is; decided in order, up to the first not ready
                bound = (min(_true_time_ns(self.last[0], 0.0, clock)
                             for clock in self.clock_model) if self.corrected
                         else self.last[0] if self.wait_ns else None)
                if bound is not None:
                    ready = 0
                    while ready < len(todo) and todo[ready].latest + self.wait_ns < bound:
                        ready += 1
                    todo = todo[:ready]
            if todo:
                for f in todo:
                    if self._state is not None:
                        f.reason = self._state.decide(f.fid, f.camera, len(f.uv))
                    else:
                        self._decide(f)
                self.pending = [f for f in self.pending if f.reason is None]
        out = []
        while self.unreleased and self.unreleased[0].reason is not None:
            f = self.unreleased.popleft()  # released in pushed order
            reasons = f.reason if isinstance(f.reason, list) else f.reason.tolist()
            for k, r in enumerate(reasons):  # (not None: above)
                if r < 0:
                    out.append((f.t, f.camera, f.uv[k], f.index))
                    if r == CONTESTED:
                        self.contested.add((f.t, f.camera, *f.uv[k].tolist()))
                else:
                    self.rejected.append((f.t, f.camera, f.index, *f.uv[k].tolist(), r))
        # keep the history a later choice can reach
        old = self.last[0] - self.history_ns
        if self._state is not None:
            self._state.trim(old)
        for keys, frames in zip(self.keys, self.by_camera, strict=True):
            drop = 0
            while drop < len(frames) and frames[drop].reason is not None and frames[drop].t < old:
                drop += 1
            if drop:
                del keys[:drop], frames[:drop]
        if not out:
            return (np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros((0, 2)),
                    np.zeros(0, np.int64))
        t, cam, uv, idx = zip(*out, strict=True)
        return (np.array(t, np.int64), np.array(cam, np.int32), np.array(uv),
                np.array(idx, np.int64))

    def _decide(self, f: _Frame) -> None:
        """Decide one frame: the steps of :func:`gate` on its candidates alone."""
        o = self.options
        k, a = len(f.uv), f.camera
        every, decided, differs, lag = self._support(f)
        c = _Candidates(np.full(k, a, np.int32), np.array(f.time_ns, np.int64), f.uv_und,
                        f.ray_dir, np.zeros(k, np.int64))
        # the points of the all-candidates support (what the stillness compares, as
        # gate()'s _static) and of the decided support (what the choice uses)
        f.points, chosen, front, f.held = [], [], [], []
        for j, (ray, r_row, c_row) in enumerate(zip(f.ray_dir.tolist(), every[0].tolist(),
                                                    every[1].tolist(), strict=True)):
            p, ok, miss = _points_one(a, ray, r_row, c_row, self.constants)
            pointed = p is not None and not miss > o.track_m  # as gate()
            f.points.append(p if pointed else (math.nan, math.nan, math.nan))
            # whether its support held (_held), for the later frames' image test
            f.held.append(_held_one(a, ray, r_row, c_row, miss, pointed, o, self.constants))
            if differs[j]:
                p, ok, miss = _points_one(a, ray, decided[0][j].tolist(),
                                          decided[1][j].tolist(), self.constants)
                chosen.append(p if p is not None and not miss > o.track_m
                              else (math.nan, math.nan, math.nan))
            else:
                chosen.append(f.points[-1])
            front.append(ok)
        ratio, points, in_front = decided[0], np.array(chosen), np.array(front)
        # _static's rule on this frame: still against each of the camera's lags frames before
        frames, at = self.by_camera[a], self.by_camera[a].index(f)
        lags = self.lags[a]
        long_lags = int(np.ceil(LONG_STILL * o.static_s * self.rig.cameras[a].fps))
        still = _stillness_one(f.key, f.points,
                               [(frames[at - lag].key, frames[at - lag].points,
                                 frames[at - lag].uv_und.tolist(), frames[at - lag].held)
                                for lag in range(1, min(long_lags, at) + 1)], lags, o,
                               f.uv_und.tolist(), _paired(every[0]).tolist(),
                               self.rig.cameras[a], f.ray_dir[:, 2])
        reason = np.full(k, -1, dtype=np.int8)
        self.decider.run(c, [(0, k)], ratio, points, in_front, reason, still, lag)
        f.reason = reason
        judged = _can_judge(f.key, [frames[at - lag].key for lag in range(1, min(lags, at) + 1)],
                            lags, o)
        kept = _supporting(reason.tolist()) if judged else None
        if kept is not None:
            f.support = [s for s, ok in zip(f.support, kept, strict=True) if ok]

    def _support(self, f: _Frame):
        """:func:`_support_one` (causal) of one frame's candidates and each other camera b:
        ``(ratio, carried)`` from every candidate of b's frames, and from its decided frames'
        chosen candidates (every candidate of the others), (k, m) and (k, m, 2) each, and
        which candidates' two supports were computed apart (k,) bool, and the time to each
        camera's latest frame a choice at t may use (:func:`_lags`), (k, m) s."""
        k, m, a = len(f.uv), len(self.rig), f.camera
        lag = np.full((k, m), np.inf)
        ratio = np.full((k, m), np.nan)
        carried = np.full((k, m, 2), np.nan)
        decided = [ratio.copy(), carried.copy()]
        differs = [False] * k
        for b in range(m):
            keys = self.keys[b]
            if b == a or not keys:
                continue
            frames = self.by_camera[b]

            def every(j, frames=frames):
                return frames[j].every

            def usable(j, frames=frames):
                return frames[j].support

            search = bisect_right if (self.wait_ns > 0 or b < a) else bisect_left
            for j, (t, (u, v)) in enumerate(zip(f.time_ns, f.uv_und.tolist(), strict=True)):
                latest = search(keys, t + self.wait_ns) - 1
                if latest >= 0:
                    lag[j, b] = abs(t - keys[latest]) / NS
                line = _line_of(self.F_lists[a][b], u, v)
                r, uv = _support_one(t, line, keys, every, search, self.wait_ns, True,
                                     self.max_gap_ns, self.options)
                ratio[j, b] = r
                if uv is not None:
                    carried[j, b] = uv
                # the frames a choice at t may reach (within max_gap_s): decided with a
                # rejected candidate, their chosen ones only
                last = search(keys, t + self.wait_ns)
                if any(frames[i].support is not frames[i].every for i in
                       range(bisect_left(keys, t - self.max_gap_ns), last)):
                    r, uv = _support_one(t, line, keys, usable, search, self.wait_ns, True,
                                         self.max_gap_ns, self.options)
                    differs[j] = True
                decided[0][j, b] = r
                if uv is not None:
                    decided[1][j, b] = uv
        return (ratio, carried), decided, differs, lag


class StreamDoubt:
    """:func:`choice_doubt` of a :class:`StreamGate`'s choices as they come out (the same
    bits as the batch's): each camera's candidates the gate rejected by the motion gate over
    the last ``static_s`` (LOGGED times), read from its record as it grows."""

    def __init__(self, gate: StreamGate) -> None:
        self.gate = gate
        self.read = 0  # rows of gate.rejected read
        # the pushed frames of several candidates ((logged time, camera)), in push order,
        # for as long as the gate may still decide them
        self.several: set[tuple[int, int]] = set()
        self.pushed: deque = deque()
        self.window = round(gate.options.static_s * NS)
        self.recent: list[deque] = [deque() for _ in gate.rig.cameras]
        self.size = [(float(c.width), float(c.height)) for c in gate.rig.cameras]
        # the session's first choice when a later verdict put it in doubt ((logged time,
        # camera, u, v): :class:`StreamStart`), treated as a CONTESTED one
        self.late: set[tuple] = set()
        # each camera's frames with candidates ((logged time, pixels)) over the 1.5
        # static_s the stillness test looks at (:func:`unmoved`), the newest frame of
        # several of any camera, and each camera's stillness lags
        self.span = 1.5 * gate.options.static_s * NS
        self.seen: list[deque] = [deque() for _ in gate.rig.cameras]
        self.newest_several: float = -math.inf
        self.lags = [math.ceil(gate.options.static_s * c.fps) for c in gate.rig.cameras]
        self.F_lists = fundamental_matrices(gate.rig.cameras).tolist()

    def frames(self, time_ns, camera) -> None:
        """Note the frames of a push (its rows, each frame's candidates together) before
        the gate decides them."""
        n = len(time_ns)
        if n < 2:
            return
        keys = list(zip(time_ns.tolist(), camera.tolist(), strict=True))
        for a, b in pairwise(keys):
            if a == b and a not in self.several:
                self.several.add(a)
                self.pushed.append(a)
                self.newest_several = max(self.newest_several, a[0])
        old = keys[-1][0] - self.gate.history_ns
        while self.pushed and self.pushed[0][0] < old:
            self.several.discard(self.pushed.popleft())

    def seen_frames(self, time_ns, camera, uv) -> None:
        """Note the frames of a push with their candidates' pixels (rows in (time, camera)
        order, each frame's candidates together; :func:`unmoved`), before the gate decides
        them."""
        n = len(time_ns)
        if not n:
            return
        t, c, p = time_ns.tolist(), camera.tolist(), uv.tolist()
        i = 0
        while i < n:
            j = i + 1
            while j < n and t[j] == t[i] and c[j] == c[i]:
                j += 1
            self.seen_frame(t[i], c[i], p[i:j])
            i = j

    def seen_frame(self, t: int, c: int, pixels: list) -> None:
        """Note one frame with candidates (logged time, camera, its candidates' recorded
        pixels, ``[[u, v], ...]``), forgetting what no choice can look back to."""
        seen = self.seen[c]
        seen.append((t, pixels))
        if len(pixels) >= 2:
            self.newest_several = max(self.newest_several, t)
        old = t - self.gate.history_ns - self.span
        while seen and seen[0][0] < old:
            seen.popleft()

    def of(self, time_ns: np.ndarray, camera: np.ndarray, uv: np.ndarray) -> np.ndarray | None:
        """The doubt (pixels² per axis) of chosen rows in logged order, None when none
        is in doubt."""
        self._read()
        if not len(time_ns) or not (self.gate.contested or self.late or any(self.recent)
                                    or self.newest_several >= int(time_ns.min())):
            return None
        out = None
        for i, (t, c) in enumerate(zip(time_ns.tolist(), camera.tolist(), strict=True)):
            u, v = uv[i].tolist()
            doubt = self._row(t, c, u, v)
            if doubt:
                if out is None:
                    out = np.zeros(len(time_ns))
                out[i] = doubt
        return out

    def of_one(self, t: int, c: int, u: float, v: float) -> float:
        """:meth:`of` of one chosen row (Python numbers: logged time, camera, pixel): its
        doubt, 0.0 when not in doubt (the same value, without its (1,) columns)."""
        self._read()
        return (self._row(t, c, u, v) if self.gate.contested or self.late or any(self.recent)
                or self.newest_several >= t else 0.0)

    def _read(self) -> None:
        """The gate's rejections since the last call, the doubt's sources among them noted
        (per camera, in logged order)."""
        rejected = self.gate.rejected
        if len(rejected) > self.read:
            for t, c, _, u, v, r in rejected[self.read:]:
                if doubt_source(r, (t, c) in self.several):
                    self.recent[c].append((t, u, v))
            self.read = len(rejected)

    def _row(self, t: int, c: int, u: float, v: float) -> float:
        """One chosen row's doubt (0.0: none), the sources older than the window forgotten
        (a camera's choices come in order); a CONTESTED choice is in doubt whatever lies
        near it."""
        near = self.recent[c]
        while near and near[0][0] < t - self.window:
            near.popleft()
        contested, late = self.gate.contested, self.late
        if (contested and (t, c, u, v) in contested) or (late and (t, c, u, v) in late):
            contested.discard((t, c, u, v))
            late.discard((t, c, u, v))
            # (a source of doubt for its camera's later choices, as DOUBT_REJECTIONS
            # rejections: _observation_doubt)
            near.extend([(t, u, v)] * DOUBT_REJECTIONS)
            return doubt_variance(u, v, *self.size[c])
        radius2 = DOUBT_RADIUS_PX * DOUBT_RADIUS_PX
        if sum(t - self.window <= tj <= t and (u - uj) * (u - uj) + (v - vj) * (v - vj)
               <= radius2 for tj, uj, vj in near) >= DOUBT_REJECTIONS:
            return doubt_variance(u, v, *self.size[c])
        # (still beside a candidate that moved, while its camera could not judge
        # stillness: unmoved_doubt; only in a frame of several)
        if self.newest_several >= t:
            # (the camera's frames before the choices to come: a later choice is not
            # earlier, and looks back 1.5 static_s at most)
            seen = self.seen[c]
            while seen and seen[0][0] < t - self.span:
                seen.popleft()
            after = 0  # (its own frame and any pushed after it)
            for e in reversed(seen):
                if e[0] < t:
                    break
                after += 1
            if len(seen) - after >= 0.75 * self.lags[c]:  # (the test judges: the usual)
                return 0.0
            own = next((e[1] for e in reversed(seen) if e[0] == t), ())
            options = self.gate.options
            if len(own) >= 2 and unmoved(
                    t, u, v, own, seen, self.lags[c], options.static_s,
                    options.max_image_speed_px_s, lambda: _still_partner(
                        t, c, u, v, lambda b: self.seen[b], self.gate.rig, self.F_lists,
                        options.static_s, options.epipolar_px)):
                return doubt_variance(u, v, *self.size[c])
        return 0.0


class StreamStart:
    """:func:`late_doubt` in a stream: the gate's chosen rows from the session's first
    choice on are held (not fused) until the verdict on that choice is known — its camera's
    next two frames with candidates decided, or one of them that does not speak against it
    (:func:`_refusal`), or every frame within ``static_s`` after it decided — then released
    together, the choice noted in doubt (:attr:`StreamDoubt.late`) when the verdict says
    so; from then on rows pass at once. The methods so fuse every row with the doubt the
    batch gives it, so the stream's points are the batch's, bit for bit; the cost is a
    latency of at most ``static_s`` on a session's first points (its first choice's camera's
    next two frame periods, or one on a clean session: its next frame holds one candidate).

    It reads a frame's verdict from the gate's records once the frame is decided:
    :class:`StreamGate` takes a frame's candidates in one push and decides them together
    (in that push, or a later one when it waits), so a decided frame read here is complete."""

    def __init__(self, gate: StreamGate, doubts: StreamDoubt) -> None:
        self.gate, self.doubts = gate, doubts
        self.window = round(gate.options.static_s * NS)
        self.first: tuple[int, int, float, float] | None = None  # (time, camera, u, v)
        self.read = 0  # rows of gate.rejected read
        self.frames: dict[int, bool] = {}  # the first choice's camera's frames after it
        self.held: list[tuple] = []  # (time_ns, camera, uv, frame_index) arrays
        self.done = False

    def rows(self, time_ns, camera, uv, frame_index, final: bool = False):
        """The gate's chosen rows of a push (``final``: its flush's) -> the rows to fuse
        now: none while the verdict is open, every held one with these once it is known."""
        if self.done:
            return time_ns, camera, uv, frame_index
        gate = self.gate
        if self.first is None:
            if not len(time_ns):  # (no choice yet: nothing to hold)
                self.read = len(gate.rejected)
                return time_ns, camera, uv, frame_index
            self.first = (int(time_ns[0]), int(camera[0]), *uv[0].tolist())
            self.read = 0  # (rejections before it lie before it: skipped below)
        t0, a, u0, v0 = self.first
        end = t0 + self.window
        frames = self.frames
        for t, c, _, u, v, r in gate.rejected[self.read:]:
            if c == a and t0 < t <= end:
                frames[t] = frames.get(t, False) or _refusal(
                    r, (t, c) in self.doubts.several, u - u0, v - v0)
        self.read = len(gate.rejected)
        contested = gate.contested
        for t, c, (u, v) in zip(time_ns.tolist(), camera.tolist(), uv.tolist(), strict=True):
            if c == a and t0 < t <= end:
                frames[t] = frames.get(t, False) or _refusal(
                    CONTESTED if (t, c, u, v) in contested else -1, False, u - u0, v - v0)
        self.held.append((time_ns, camera, uv, frame_index))
        later = sorted(frames)[:2]
        known = (final or (later and not frames[later[0]]) or len(later) == 2
                 or (gate.unreleased[0].t > end if gate.unreleased else gate.last[0] > end))
        if not known:
            n = 0
            return (np.zeros(n, np.int64), np.zeros(n, np.int32), np.zeros((n, 2)),
                    np.zeros(n, np.int64))
        if len(later) == 2 and all(frames[t] for t in later) and (
                self.first not in contested):
            self.doubts.late.add(self.first)
        self.done = True
        held, self.held, self.frames = self.held, [], {}
        return tuple(np.concatenate(column) for column in zip(*held, strict=True))


def gating_key(method: str, options) -> tuple[bool, float]:
    """(causal, wait_s) of the gate ``method`` needs (``options``: FusionOptions): the
    causal form for a causal method, waiting for the tolerance as the method does."""
    from . import METHODS

    m = METHODS[method]
    return m.causal, (options.tolerance_s if m.causal and m.waits_tolerance else 0.0)


def gate_for(detections: Detections, rig: Rig, method: str, options,
             common: Callable[[], tuple] | None = None,
             doubt: bool | str | None = None) -> Gated:
    """:func:`gate` in the form ``method`` needs (``options``: FusionOptions with
    ``max_gap_s`` set or None; ``common``: as :func:`gate`'s; ``doubt``: make the choices'
    doubt, None: if ``method`` takes it, ``Method.uses_doubt``)."""
    from . import METHODS

    causal, wait_s = gating_key(method, options)
    m = METHODS[method]
    return gate(detections, rig, causal=causal, wait_s=wait_s, max_gap_s=options.max_gap_s,
                common=common,
                doubt=(m.uses_doubt and m.doubt) if doubt is None else doubt)


def prepared_for(gated: Gated, rig: Rig) -> Prepared:
    """:func:`~pslog.fusion.prepare` of the gate's observations, with the doubt of its
    choices (:attr:`Gated.doubt_px2`) for the methods' covariance."""
    from dataclasses import replace

    from ._prepare import prepare

    prep = prepare(gated.observations, rig)
    return prep if gated.doubt_px2 is None else replace(prep, doubt_px2=gated.doubt_px2)


def fuse_detections(detections: Detections, rig: Rig, methods, options=None, *,
                    workers: int | None = None, gated: dict | None = None):
    """Fuse every method of ``methods`` from all the candidates of ``detections``, gated
    (:func:`gate`, in each method's form; once per form), or, with
    ``options.gating`` False, from each frame's best-scored candidate.

    ``workers``: threads fusing methods at once (:mod:`pslog.fusion._parallel`; the same
    tracks and errors as one after another); None: the usable cores, at most one per
    method; 1: in turn on the calling thread. ``gated``: a pass made before, as
    :func:`start_fusion`'s.

    Returns
    -------
    tracks : method -> Track, in the order of ``methods``
    rejections : method -> Rejections (empty ones without gating)
    """
    methods = list(methods)
    done = {m: (t, r) for m, t, r in start_fusion(detections, rig, methods, options,
                                                  workers=workers, gated=gated)}
    return ({m: done[m][0] for m in methods}, {m: done[m][1] for m in methods})


class FusionRun:
    """The methods of :func:`start_fusion`, fusing: iterate for ``(method, track,
    rejections)`` as each method ends (see :class:`pslog.fusion._parallel.MethodRun`:
    the tracks and errors of one method after another; with one worker in the asked
    order); :meth:`stop` keeps the methods not started from starting."""

    def __init__(self, methods: list[str], run, gating: bool) -> None:
        self.methods, self._run, self._gating = methods, run, gating

    def stop(self) -> None:
        self._run.stop()

    def __iter__(self):
        for i, out in self._run:
            method = self.methods[i]
            if self._gating:
                track, rejections = out
                del out
                yield method, track, rejections
            else:
                yield method, out, Rejections.empty()


#: the gating form :func:`pslog.fusion.default_methods` gates in when it gates (causal,
#: no wait: :func:`gating_key`'s for typeA, nearest and filter), and the key of the forms'
#: shared part in :func:`pregated`'s dict
_PREGATED_FORM = (True, 0.0)
_PREGATED_COMMON = "common"


def pregated(chosen: Gated, common: tuple, key: tuple = _PREGATED_FORM,
             doubt: bool | str = True) -> dict:
    """A gating pass made before the fusion (:func:`pslog.fusion.default_methods`' : by
    default the causal form without a wait, every choice's doubt made; ``key``: its form,
    :func:`gating_key`; ``doubt``: the doubt it was made with) and the forms' shared part
    (:func:`gate_common`), as :func:`start_fusion`'s ``gated`` takes them (a form's pass
    taken where its methods take that doubt)."""
    return {key: (chosen, doubt), _PREGATED_COMMON: common}


def start_fusion(detections: Detections, rig: Rig, methods, options=None, *,
                 workers: int | None = None, background: bool = False,
                 gated: dict | None = None) -> FusionRun:
    """:func:`fuse_detections` started (on threads, at once; ``workers=1``: each method
    as the iteration reaches it, unless ``background``: on one thread), its tracks
    delivered as each method ends: the caller writes them meanwhile (``pslog fuse``).

    ``gated``: :func:`pregated`'s dict of a pass made before (``default_methods(...,
    gated=)``, the same detections, rig and options): its form is not gated again where
    the methods take every choice's doubt in it, nor the forms' shared part made again
    (the same tracks, bit for bit: the same call; walk38's webcams, where that pass was
    the fusion's third, before it and on one thread). Emptied as it is used."""
    from . import METHODS, FusionOptions, check_method, fuse, prepare
    from ._parallel import MethodProgress, MethodRun, default_workers

    options = options or FusionOptions()
    methods = list(methods)
    for method in methods:
        check_method(method)
    workers = default_workers(len(methods)) if workers is None else workers
    # type A's confirm_breaks takes its kick instants from smooth's fit of the session:
    # made once, by smooth's fusion or type A's, whichever asks first (the other waits)
    from .breaks import fit_shared, shared_fit

    sharing = fit_shared(methods, rig, options)
    fit_of: list = []  # [SessionFit] when sharing, given smooth's input's maker
    made_input: dict = {}  # smooth's gated input when sharing (the fit's and smooth's)

    def share_fit(make_input) -> None:
        # (smooth's gated input, kept for smooth's own fusion, goes with the fit's last use)
        fit_of.append(shared_fit(methods, rig, options, make_input, made_input.clear))

    def fused_with_fit(method: str, observations, prep):
        fit = fit_of[0] if fit_of and method in ("smooth", "typeA") else None
        try:
            return fuse(observations, rig, method, options, prepared=prep, smooth_fit=fit)
        finally:
            if fit is not None:
                fit.release(method)  # (type A's already, once it had the breaks)

    if not options.gating:
        obs = timed_observations(detections, rig)
        prep = prepare(obs, rig) if len(rig) >= 2 else None
        if sharing:
            share_fit(lambda: prep)
        shown = MethodProgress(methods)
        return FusionRun(methods, MethodRun(
            methods, [None] * len(methods), lambda key, method: prep,
            lambda m, p: fused_with_fit(m, obs, p), workers,
            started=shown.started, finished=shown.finished, background=background),
            gating=False)

    # the forms' shared part (gate_common) once, by the first form to start, dropped once
    # every form has it (the forms gate at once, on threads: the others wait for it)
    smooth_key = gating_key("smooth", options)
    forms = len({gating_key(method, options) for method in methods}
                | ({smooth_key} if sharing else set()))
    lock = threading.Lock()
    shared: dict = {}

    given = {} if gated is None else gated
    if _PREGATED_COMMON in given:
        shared["value"] = given.pop(_PREGATED_COMMON)
        shared["left"] = forms

    def common() -> tuple:
        with lock:
            if "value" not in shared:
                shared["value"] = gate_common(detections, rig)
                shared["left"] = forms
            value = shared["value"]
            shared["left"] -= 1
            if shared["left"] == 0:
                shared["value"] = None  # (its arrays go with the last form's gate)
            return value

    # (the choices' doubt where a method of the form takes it in its covariance)
    # (a form's methods taking different doubts: every choice's, True, wins over "start")
    doubting: dict[tuple, bool | str] = {}
    for m in methods + (["smooth"] if sharing else []):
        if METHODS[m].uses_doubt:
            key = gating_key(m, options)
            doubting[key] = True if doubting.get(key) is True else METHODS[m].doubt

    def gated_input(key, method: str) -> tuple[Gated, Prepared | None]:  # once per form
        made = given.pop(key, None)
        if made is not None and made[1] == doubting.get(key, False):
            # (the pass before, the same call: see the docstring)
            gated = made[0]
            common()  # (its use of the shared part, counted as each form's is)
        else:
            gated = gate_for(detections, rig, method, options, common,
                             doubting.get(key, False))
        return gated, (prepared_for(gated, rig) if len(rig) >= 2 else None)

    input_lock = threading.Lock()

    def method_input(key, method: str) -> tuple[Gated, Prepared | None]:
        if not (sharing and key == smooth_key):
            return gated_input(key, method)
        with input_lock:  # smooth's input: also the shared fit's, made once
            if "value" not in made_input:
                made_input["value"] = gated_input(key, "smooth")
            return made_input["value"]

    if sharing:
        share_fit(lambda: method_input(smooth_key, "smooth")[1])

    def fused(method: str, shared: tuple[Gated, Prepared | None]):
        gated, prep = shared
        return fused_with_fit(method, gated.observations, prep), gated.rejections

    # the methods run at once on threads (pslog.fusion._parallel: same results, same errors)
    shown = MethodProgress(methods)
    return FusionRun(methods, MethodRun(
        methods, [gating_key(method, options) for method in methods], method_input, fused,
        workers, started=shown.started, finished=shown.finished, background=background),
        gating=True)


__all__ = [
    "REASONS",
    "REASON_TEXT",
    "FusionRun",
    "Gated",
    "GatingOptions",
    "Rejections",
    "StreamDoubt",
    "StreamGate",
    "StreamStart",
    "choice_doubt",
    "epipolar_distance",
    "fuse_detections",
    "gate",
    "gate_for",
    "gating_key",
    "pregated",
    "prepared_for",
    "start_fusion",
]
