"""What a view shows: a session, the tracks chosen from it (and from fused copies), the
type-A construction, and the time window.

Nothing here calls rerun; :mod:`viewers.recording` turns a :class:`ViewData` into a recording.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pslog.errors import InputError
from pslog.fusion import (
    METHODS,
    FusionOptions,
    Prepared,
    TypeAConstruction,
    for_session,
    fuse_all,
    type_a_explained,
    type_a_prepared,
)
from pslog.log import Session, read_session
from pslog.records import NS, Detections, Observations, Track
from pslog.timing import observations as timed_observations

if TYPE_CHECKING:
    from pslog.fusion.gating import Rejections

#: The method fused on the fly when a session has no stored track (it shows the paper's
#: Figure 2 construction).
DEFAULT_METHOD = "typeA"
#: A window bound this far out means "no bound".
UNBOUNDED_NS = np.iinfo(np.int64).max // 4


class ViewOptionError(InputError):
    """A view option's value that does not fit the sessions read (a method neither stored
    nor known, a window holding no frame): ``pslog view`` reports it as a command-line
    error (exit 2, ``usage_error``), as ``fuse``/``eval`` report an unknown ``--method``.
    (A known method the session's timing cannot support is a fault of the data, not of
    the command line: :class:`pslog.errors.FusionError`, exit 1, as ``fuse`` gives.)

    Attributes
    ----------
    option : the option's name (``--method``, ``--start``, ``--end`` or ``--start/--end``)
    """

    def __init__(self, option: str, message: str):
        super().__init__(message)
        self.option = option


@dataclass(frozen=True)
class FramesChoice:
    """Which recorded images to show: ``every`` = 0 for none, 1 for all, N for every N-th
    frame of each camera (frame index a multiple of N)."""

    every: int

    #: largest N of ``every:N``: far beyond any recording's frame count, small enough to be
    #: an ordinary integer (``every:99999999999999999999999`` is a typo, not a choice)
    MAX_EVERY = 1_000_000_000

    @classmethod
    def parse(cls, text: str) -> FramesChoice:
        """``all``, ``none`` or ``every:N`` (N a whole number, 1 <= N <= :data:`MAX_EVERY`)."""
        text = str(text).strip()
        if text == "all":
            return cls(1)
        if text == "none":
            return cls(0)
        match = re.fullmatch(r"every:(\d+)", text)
        if match and 0 < int(match.group(1)) <= cls.MAX_EVERY:
            return cls(int(match.group(1)))
        raise InputError(f"frames must be 'all', 'none' or 'every:N' with 1 <= N <= "
                         f"{cls.MAX_EVERY}, got {text!r}")


@dataclass(frozen=True)
class DetailChoice:
    """Where a recording holds every frame's overlays, and how thin it is elsewhere.

    A long session (a 90-minute match: 486,000 detections) logged in full makes a .rrd of
    half a gigabyte. Inside the detail range every frame keeps its ray, epipolar lines and
    Figure 2 construction, and the plots every point; beyond it those overlays are kept for
    one frame in ``every`` (of the slowest camera) and the plots are reduced to the first,
    last, smallest and largest value of each ``every``-frame bucket (M4 aggregation, Jugel
    et al., "M4: A Visualization-Oriented Time Series Data Aggregation", PVLDB 7(10), 2014:
    the drawn line keeps its extremes). Detections, tracks, truth and images stay complete.

    Attributes
    ----------
    start_s : seconds after the session's first frame; None: the shown range's start
    length_s : seconds of full detail from ``start_s``; None: everything (``all``)
    every : thinning factor beyond the range (>= 1)
    """

    start_s: float | None
    length_s: float | None
    every: int = 10

    #: the default: the first ten minutes shown in full detail, the rest thinned tenfold —
    #: a 10-minute session is unchanged, a 90-minute match stays light
    DEFAULT = "600"
    DEFAULT_EVERY = 10

    @classmethod
    def parse(cls, text: str, every: int = DEFAULT_EVERY) -> DetailChoice:
        """``all`` (no thinning), ``S`` (the first S seconds shown) or ``A:B`` (seconds
        after the session's first frame); ``every`` the thinning factor beyond it."""
        text = str(text).strip()
        if (isinstance(every, bool) or not isinstance(every, int) or every < 1
                or every > FramesChoice.MAX_EVERY):  # (10**23: a traceback, its bucket's ns)
            raise InputError(f"the thinning factor must be a whole number from 1 to "
                             f"{FramesChoice.MAX_EVERY}, got {every!r}")
        if text == "all":
            return cls(None, None, every)
        try:
            if ":" in text:
                a, b = (float(x) for x in text.split(":"))
                if np.isfinite(a) and np.isfinite(b) and 0 <= a < b:
                    return cls(a, b - a, every)
            else:
                length = float(text)
                if np.isfinite(length) and length >= 0:
                    return cls(None, length, every)
        except ValueError:
            pass
        raise InputError(f"detail must be 'all', seconds S >= 0 (the first S seconds shown) "
                         f"or A:B with 0 <= A < B seconds, got {text!r}")

    def range_ns(self, first_ns: int, window_ns: tuple[int, int]) -> tuple[int, int]:
        """The full-detail range (lo, hi), int ns on the session clock, given the session's
        first frame time and the shown window."""
        if self.length_s is None:
            return -UNBOUNDED_NS, UNBOUNDED_NS
        lo = min(first_ns + _ns_within_bounds(self.start_s), UNBOUNDED_NS) if (
            self.start_s is not None) else max(window_ns[0], first_ns)
        return lo, min(lo + _ns_within_bounds(self.length_s), UNBOUNDED_NS)


def _ns_within_bounds(seconds: float) -> int:
    """``seconds`` (finite, >= 0) as int ns, at most :data:`UNBOUNDED_NS`: a --detail of
    1e300 s is everything from its start (its ns, 1e309, is a float infinity that no int
    holds)."""
    return UNBOUNDED_NS if seconds * NS >= UNBOUNDED_NS else round(seconds * NS)


@dataclass(frozen=True, eq=False)
class ViewData:
    """Everything a recording is built from.

    Attributes
    ----------
    session : the first session file, read without images
    paths : the session files, first one first
    observations : each frame's detection, sorted by (time, camera): the candidate the
        gating of the first shown track stored with its rejections chose
        (:func:`chosen_observations`; a frame whose every candidate it rejected: none), else
        the best-scored one (fusion input without gating)
    tracks : display name -> Track, in display order
    construction : type-A construction behind the ``typeA`` track, or None
    window_ns : (lo, hi), int nanoseconds on the session clock; rows outside are left out
    notes : human-readable remarks (tracks fused on the fly, renamed duplicates)
    rejections : display name -> :class:`pslog.fusion.gating.Rejections` stored beside a
        shown track (``pslog fuse`` with gating), in display order
    detail_ns : (lo, hi), int ns: the full-detail range (see :class:`DetailChoice`)
    every : thinning factor beyond ``detail_ns`` (1: none)
    thin : True for the copy the per-frame overlays are drawn from (:meth:`thinned`): its
        :meth:`in_window` also leaves out the thinned frames
    construction_observations : the observations ``construction``'s rows index (the gated
        ones type A fused: not ``observations`` where the gate kept another candidate or
        none), or None without a construction
    """

    session: Session
    paths: tuple[Path, ...]
    observations: Observations
    tracks: dict[str, Track]
    construction: TypeAConstruction | None
    window_ns: tuple[int, int]
    notes: list[str] = field(default_factory=list)
    rejections: dict = field(default_factory=dict)
    detail_ns: tuple[int, int] = (-UNBOUNDED_NS, UNBOUNDED_NS)
    every: int = 1
    thin: bool = False
    construction_observations: Observations | None = None

    @property
    def first_ns(self) -> int:
        """The session's first frame time, int ns (0 without frames)."""
        t = self.session.detections.frame_time_ns
        return int(t.min()) if len(t) else 0

    @cached_property
    def ball_frames(self) -> tuple[list[list[dict]], np.ndarray]:
        """``(spots, moving)``: per camera the static spots of
        :func:`pslog.log.info.static_candidates` (a second orange object in view, a
        candidate in every frame; or the ball at rest) and (F,) bool, the frames with a
        candidate off every spot (:func:`pslog.log.info.moving_frames`): the frames the
        ball was detected in, as ``pslog info``'s "moving" rate counts them."""
        from pslog.log.info import moving_frames, static_candidates

        spots, static = static_candidates(self.session.detections)
        return spots, moving_frames(self.session.detections, static)

    @property
    def bucket_ns(self) -> tuple[int, int]:
        """``(bucket, period)`` int ns: beyond the detail range one frame period (of the
        slowest camera) is kept in each bucket of ``every`` periods, so every camera keeps
        one frame in ``every``."""
        fps = min((c.fps for c in self.session.rig.cameras), default=30.0)
        period = max(1, round(NS / fps))
        # (at most 2**62 ns, 146 years: an int64 still; a longer bucket keeps the same frames)
        return min(self.every * period, 2**62), period

    def in_detail(self, time_ns: np.ndarray) -> np.ndarray:
        """Mask (n,) of times within the full-detail range."""
        lo, hi = self.detail_ns
        return (time_ns >= lo) & (time_ns < hi)

    def on_grid(self, time_ns: np.ndarray) -> np.ndarray:
        """Mask (n,) of the times kept beyond the detail range (one frame in ``every``)."""
        bucket, period = self.bucket_ns
        return (np.asarray(time_ns, dtype=np.int64) - self.first_ns) % bucket < period

    def in_window(self, time_ns: np.ndarray) -> np.ndarray:
        """Mask (n,) of times within the window (and, for the :meth:`thinned` copy, within
        the detail range or on the thinning grid)."""
        lo, hi = self.window_ns
        mask = (time_ns >= lo) & (time_ns < hi)
        if self.thin:
            mask &= self.in_detail(time_ns) | self.on_grid(time_ns)
        return mask

    @property
    def thinned_anywhere(self) -> bool:
        """True when some shown time lies beyond the detail range (and ``every`` > 1)."""
        return self.every > 1 and (self.window_ns[0] < self.detail_ns[0]
                                   or self.window_ns[1] > self.detail_ns[1])

    def thinned(self) -> ViewData:
        """This view for the per-frame overlays (rays, epipolar lines, Figure 2): one frame
        in ``every`` beyond the detail range; itself when nothing is thinned."""
        return replace(self, thin=True) if self.thinned_anywhere else self


def parse_methods(text: str | Sequence[str] | None) -> list[str] | None:
    """``"typeA,sync"`` or ``["typeA", "sync"]`` -> a list without repeats; None stays None."""
    if text is None:
        return None
    parts = text.split(",") if isinstance(text, str) else list(text)
    methods = list(dict.fromkeys(p.strip() for p in parts if p.strip()))
    if not methods:
        raise InputError(f"no method named in {text!r}")
    return methods


def _safe_name(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", text)


def _with_left_out(track: Track, left_out) -> Track:
    """A stored ``track`` with its method's left-out counts (the session's ``left_out``,
    what ``pslog fuse`` wrote and ``pslog eval`` lists) as its ``dropped``, as a track fused
    on the fly has them: the summary panel counts them alike."""
    return replace(track, dropped=dict(left_out)) if left_out and not track.dropped else track


def load_view_data(session_paths: str | Path | Sequence[str | Path], *,
                   methods: str | Sequence[str] | None = None, start: float | None = None,
                   end: float | None = None, detail: str | DetailChoice = "all") -> ViewData:
    """Read the sessions and choose the tracks to show.

    Parameters
    ----------
    session_paths : the session MCAP, then optionally fused copies of it (``pslog fuse``
        output) whose tracks are added; a method name already taken gets the file's stem
        appended (``typeA_fused2``)
    methods : tracks to show, by name; a fusion method no file holds is fused on the fly.
        None: every stored track, or ``typeA`` fused on the fly when there is none
    start, end : seconds from the session's first frame; rows outside ``[start, end)`` are
        left out (fusion still sees every detection, so the first points keep their history)
    detail : a :class:`DetailChoice` or its text (``all``, ``S`` or ``A:B``): where the
        per-frame overlays and the plots keep every frame (default ``all``: everywhere;
        ``pslog view`` defaults to :attr:`DetailChoice.DEFAULT`)

    Raises
    ------
    LogFormatError for unreadable files, InputError for a bad window or sessions of
    different rigs (:class:`ViewOptionError`, an InputError, for an unknown method or a
    window holding no frame: checked before any fusing), FusionError when fusing fails.
    """
    paths = ((Path(session_paths),) if isinstance(session_paths, (str, Path))
             else tuple(Path(p) for p in session_paths))
    if not paths:
        raise InputError("no session file given")
    from pslog.errors import shell_word
    from pslog.outputs import same_file
    from pslog.timing import CLOCK_STD_KEY

    for i, path in enumerate(paths):  # (its tracks would be shown twice, renamed)
        for earlier in paths[:i]:
            if same_file(path, earlier):
                spelled = "" if str(path) == str(earlier) else f" (as {earlier} and {path})"
                raise InputError(f"{path} is given twice{spelled}: give each session file "
                                 f"once")
    session = read_session(paths[0])
    tracks: dict[str, Track] = {m: _with_left_out(t, session.left_out.get(m))
                                for m, t in session.tracks.items()}
    rejections = dict(session.rejections)
    notes: list[str] = []
    for path in paths[1:]:
        other = read_session(path)
        if other.rig.names != session.rig.names:
            raise InputError(f"{path}: cameras {', '.join(other.rig.names)} differ from "
                             f"{paths[0]}'s ({', '.join(session.rig.names)})")
        if not other.tracks:  # (a session, or a synced copy: its rig is not the one shown)
            notes.append(f"{path}: holds no fused track, so nothing of it is shown (the files "
                         f"after the first add their tracks; to view it as the session: "
                         f"'pslog view {shell_word(path)}')")
            continue
        synced = (other.metadata or {}).get(CLOCK_STD_KEY) and not (
            session.metadata or {}).get(CLOCK_STD_KEY)
        if not np.array_equal(other.detections.frame_time_ns, session.detections.frame_time_ns):
            mine, its = session.detections, other.detections
            if synced and np.array_equal(*(
                    np.sort(d.frame_camera.astype(np.int64) << 40 | d.frame_index)
                    for d in (its, mine))):  # (times regularized: frames reordered)
                # (the same frames at other times: a synced copy's regularized host stamps,
                # fused; "may come from another session" sent walk40 looking for one)
                notes.append(f"{path}: the same frames as {paths[0]}'s at other times (host "
                             f"stamps 'pslog sync' regularized): its tracks are shown beside "
                             f"{paths[0]}'s logged times and clocks; 'pslog view "
                             f"{shell_word(path)}' shows it with the ones it was fused with")
            else:
                notes.append(f"{path}: its frames are not {paths[0]}'s, so its tracks may "
                             f"come from another session")
        elif synced:
            # (walk42: the session beside its synced copy's fused file, as the README's
            # "session, then fused copies of it" reads; the rays, epipolar lines and type A's
            # Figure 2 constructions were drawn on the session's unsynced clocks, 907 of
            # 2,804 typeA points explained, without a word)
            notes.append(f"{path}: fused from a synced copy of {paths[0]} (clocks 'pslog "
                         f"sync' estimated): its tracks are shown beside {paths[0]}'s logged "
                         f"clocks (rays, epipolar lines and typeA's constructions on those); "
                         f"'pslog view {shell_word(path)}' shows it with the clocks it was "
                         f"fused with")
        for name, track in other.tracks.items():
            if name in tracks:
                new = f"{name}_{_safe_name(path.stem)}"
                notes.append(f"{path}: track {name!r} shown as {new!r}")
                if name in other.rejections:
                    rejections[new] = other.rejections[name]
                name = new
            elif name in other.rejections:
                rejections[name] = other.rejections[name]
            tracks[name] = _with_left_out(track, other.left_out.get(track.method))

    observations = timed_observations(session.detections, session.rig)
    wanted = parse_methods(methods)
    if wanted is None:
        wanted = list(tracks) or ([DEFAULT_METHOD] if len(session.rig) >= 2
                                  and len(observations) else [])
    missing = [m for m in wanted if m not in tracks]
    unknown = [m for m in missing if m not in METHODS]
    if unknown:
        have = sorted(set(tracks) | set(METHODS))
        raise ViewOptionError("--method", f"unknown method {unknown[0]!r} (stored or known: "
                                          f"{', '.join(have)})")
    # the window checked before any track is fused on the fly (its error comes out at once)
    first = int(session.detections.frame_time_ns.min()) if session.detections.n_frames else 0
    lo = -np.inf if start is None else float(start)
    hi = np.inf if end is None else float(end)
    if not (np.isfinite(lo) or start is None) or not (np.isfinite(hi) or end is None):
        raise InputError(f"start and end must be finite seconds, got {start!r}, {end!r}")
    if lo >= hi:
        raise InputError(f"start ({start} s) must be before end ({end} s)")
    # (beyond UNBOUNDED_NS from the session's start, a bound is no bound: 1e308 s is inf ns)
    window = (first + round(min(lo * NS, UNBOUNDED_NS)) if start is not None
              else -UNBOUNDED_NS,
              first + round(min(hi * NS, UNBOUNDED_NS)) if end is not None else UNBOUNDED_NS)
    frame_times = session.detections.frame_time_ns
    span = (frame_times.max() - first) / NS if len(frame_times) else 0.0  # s, for messages
    if (start is not None or end is not None) and not np.any(
            (frame_times >= window[0]) & (frame_times < window[1])):
        bounds = " and ".join(([f"--start {start} s"] if start is not None else [])
                              + ([f"--end {end} s"] if end is not None else []))
        where = "between" if start is not None and end is not None else (
            "from" if start is not None else "before")
        option = "/".join(o for o, v in (("--start", start), ("--end", end)) if v is not None)
        raise ViewOptionError(option, f"no frame {where} {bounds}; the session spans 0 to "
                                      f"{span:.3f} s")
    construction = construction_obs = None
    if missing:
        # as 'pslog fuse' does: each frame's ball chosen among its candidates (gating)
        if "typeA" in missing and len(session.rig) >= 2 and len(observations):
            # one gating and one type-A pass give the track and its Figure 2 construction
            # (what fuse_all and explain_type_a would each compute again, bit for bit)
            # (and its gating's rejections, as a stored track has them: the images draw the
            # ball the gate chose, not the best-scored candidate; walk38)
            (tracks["typeA"], construction, construction_obs,
             rejections["typeA"]) = _type_a_with_construction(session)
        rest = [m for m in missing if m != "typeA" or "typeA" not in tracks]
        if rest:
            tracks.update(fuse_all(session.detections, session.rig, rest,
                                   for_session(FusionOptions(), session.metadata,
                                               session.rig)))
        notes.append(f"fused on the fly: {', '.join(missing)}")
        empty = [m for m in missing if not len(tracks[m])]
        if empty:
            # say why nothing is shown for them ('pslog fuse' would refuse)
            seen = [session.rig.names[c] for c in np.unique(observations.camera)]
            why = (f"fusing needs at least two cameras; the rig has {len(session.rig)}"
                   if len(session.rig) < 2 else
                   "the session has no detection" if not seen else
                   f"only camera {seen[0]} has detections; fusing needs at least two "
                   f"cameras" if len(seen) == 1 else
                   "no point could be fused (run 'pslog fuse' to see why)")
            notes.append(f"no track from {', '.join(empty)}: {why}")
    shown = {m: tracks[m] for m in wanted}

    if (construction is None and "typeA" in shown and len(session.rig) >= 2
            and len(observations)):
        construction_obs, prep = _type_a_prepared(session)
        # (a stored track: as pslog fuse made it, the points resting on a choice the gate
        # made in doubt left out; every paper point explained, then those the track holds
        # kept: the file does not say which --confirm-gaps left the others out)
        every = type_a_explained(prep, session.rig, replace(
            for_session(FusionOptions(), session.metadata, session.rig),
            confirm_gaps=False, confirm_every=False, confirm_sides=False,
            confirm_breaks=False))[1]
        stored = shown["typeA"]
        rows = every.event_row
        # (a point made from the detections after it, --confirm-gaps breaks: span_s < 0,
        # has no forward construction: not explained by the one it replaced)
        forward = ~(stored.quality["span_s"] < 0) if "span_s" in stored.quality else slice(None)
        construction = every.select(np.isin(
            construction_obs.time_ns[rows] * 256 + construction_obs.camera[rows],
            stored.time_ns[forward] * 256 + stored.camera[forward]))

    choice = detail if isinstance(detail, DetailChoice) else DetailChoice.parse(detail)
    detail_ns = choice.range_ns(first, window)
    if choice.length_s is not None and choice.every > 1 and not np.any(
            (frame_times >= max(detail_ns[0], window[0]))
            & (frame_times < min(detail_ns[1], window[1]))):
        # a full-detail range past the session's end (or outside --start/--end) is no error
        # (the tracks are all there), but the user meant to see some frames in full: say why
        # none is
        lo_s = choice.start_s if choice.start_s is not None else (detail_ns[0] - first) / NS
        hi_s = lo_s + choice.length_s  # the seconds given (detail_ns is bounded)
        notes.append(f"the full-detail range {lo_s:g} to {hi_s:g} s holds no frame shown "
                     f"(the session spans 0 to {span:.3f} s): every frame's overlays are "
                     f"thinned to one in {choice.every}")
    shown_rejections = {m: rejections[m] for m in shown if m in rejections}
    if shown_rejections:
        # each frame's detection as the gating of the track whose rejections the images draw
        # chose it (its ray, epipolar lines, crop; the tracks' points matched to it), not the
        # best-scored candidate: walk38, a static orange object outscored the ball, and 370
        # of a webcam's 599 rays were drawn to the object, the ball's point beside them
        observations = chosen_observations(session, next(iter(shown_rejections.values())))
    return ViewData(session, paths, observations, shown, construction, window, notes,
                    shown_rejections, detail_ns=detail_ns, every=choice.every,
                    construction_observations=construction_obs)


def rejected_candidates(detections: Detections, rejections) -> np.ndarray:
    """(C,) bool over ``detections``' candidates: those ``rejections`` (a
    :class:`pslog.fusion.gating.Rejections` stored with a track) holds, by camera, frame
    and pixel (the same float values: the gate stores the candidate's pixel)."""
    rows = detections.cand_frame
    held = _candidate_keys(rejections.camera, rejections.frame_index, rejections.uv)
    return np.isin(_candidate_keys(detections.frame_camera[rows],
                                   detections.frame_index[rows], detections.cand_uv), held)


def _candidate_keys(camera: np.ndarray, frame_index: np.ndarray, uv: np.ndarray
                    ) -> np.ndarray:
    """(n,) opaque keys, equal where (camera, frame index, u, v) are: each row's four values
    as 32 bytes (``uv + 0.0``: -0.0 and 0.0 one key, as they compare equal)."""
    packed = np.empty(len(camera), dtype=[("c", "<i8"), ("f", "<i8"), ("u", "<f8"),
                                          ("v", "<f8")])
    packed["c"], packed["f"] = camera, frame_index
    packed["u"], packed["v"] = uv[:, 0] + 0.0, uv[:, 1] + 0.0
    return packed.view("V32")


def chosen_observations(session: Session, rejections) -> Observations:
    """The session's observations as a gating chose them: each frame's candidate that
    ``rejections`` does not hold (a frame whose every candidate it holds: none), at its
    corrected time, sorted by (time, camera) (:func:`pslog.timing.observations`)."""
    det = session.detections
    chosen = ~rejected_candidates(det, rejections)
    kept = Detections(det.camera_names, det.frame_time_ns, det.frame_camera, det.frame_index,
                      det.cand_frame[chosen], det.cand_uv[chosen], det.cand_radius[chosen],
                      det.cand_score[chosen])
    return timed_observations(kept, session.rig)


def _type_a_prepared(session: Session) -> tuple[Observations, Prepared]:
    """The observations type A fuses from the session's detections (default options),
    which its construction's rows index, and their preparation with the gate's doubt
    (:func:`pslog.fusion.type_a_prepared`)."""
    return type_a_prepared(session.detections, session.rig)


def _type_a_with_construction(session: Session
                              ) -> tuple[Track, TypeAConstruction, Observations, Rejections]:
    """``typeA`` fused from the session's detections as :func:`pslog.fusion.fuse_all`
    fuses it (gated, default options), its construction as
    :func:`pslog.fusion.explain_type_a` explains it, from one gating and one pass, the
    observations both rest on and the gating's rejections (as ``pslog fuse`` stores them)."""
    from pslog.fusion import check_tolerance
    from pslog.fusion.gating import gate_for, prepared_for

    rig = session.rig
    options = for_session(FusionOptions(), session.metadata, rig)
    check_tolerance(rig, options.tolerance_s)
    # (with the long-gap confirmation, as pslog fuse: the points it drops are not shown;
    # gated as _type_a_prepared gates, its rejections kept)
    gated = gate_for(session.detections, rig, "typeA", FusionOptions())
    obs, prep = gated.observations, prepared_for(gated, rig)
    track, construction = type_a_explained(prep, rig, options)
    if options.clock_covariance is not None and len(track):
        # (as pslog fuse: the synced clocks' uncertainty in the covariance; points unchanged)
        from pslog.fusion import type_a_with_kicks_of
        from pslog.fusion._prepare import default_max_gap_s
        from pslog.fusion.clock import with_clock_covariance

        resolved = replace(options, max_gap_s=options.max_gap_s or default_max_gap_s(rig))
        # (the images' kick instants taken once, as pslog fuse takes them)
        track = with_clock_covariance(
            track, "typeA", prep, rig, resolved,
            type_a_with_kicks_of(prep, rig, resolved)
            if resolved.confirm_breaks and resolved.break_source == "image" else None)
    return track, construction, obs, gated.rejections
