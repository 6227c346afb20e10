"""What a view shows: a session, the tracks chosen from it (and from fused copies), the
type-A construction, and the time window.

Nothing here calls rerun; :mod:`viewers.recording` turns a :class:`ViewData` into a recording.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pslog.errors import InputError
from pslog.fusion import METHODS, TypeAConstruction, explain_type_a, fuse_all
from pslog.log import Session, read_session
from pslog.records import NS, Observations, Track
from pslog.timing import observations as timed_observations

#: The method fused on the fly when a session has no stored track (it shows the paper's
#: Figure 2 construction).
DEFAULT_METHOD = "typeA"
#: A window bound this far out means "no bound".
UNBOUNDED_NS = np.iinfo(np.int64).max // 4


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


@dataclass(frozen=True, eq=False)
class ViewData:
    """Everything a recording is built from.

    Attributes
    ----------
    session : the first session file, read without images
    paths : the session files, first one first
    observations : the best candidate of every frame (fusion input), sorted by (time, camera)
    tracks : display name -> Track, in display order
    construction : type-A construction behind the ``typeA`` track, or None
    window_ns : (lo, hi), int nanoseconds on the session clock; rows outside are left out
    notes : human-readable remarks (tracks fused on the fly, renamed duplicates)
    rejections : display name -> :class:`pslog.fusion.gating.Rejections` stored beside a
        shown track (``pslog fuse`` with gating), in display order
    """

    session: Session
    paths: tuple[Path, ...]
    observations: Observations
    tracks: dict[str, Track]
    construction: TypeAConstruction | None
    window_ns: tuple[int, int]
    notes: list[str] = field(default_factory=list)
    rejections: dict = field(default_factory=dict)

    def in_window(self, time_ns: np.ndarray) -> np.ndarray:
        """Mask (n,) of times within the window."""
        lo, hi = self.window_ns
        return (time_ns >= lo) & (time_ns < hi)


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


def load_view_data(session_paths: str | Path | Sequence[str | Path], *,
                   methods: str | Sequence[str] | None = None, start: float | None = None,
                   end: float | None = None) -> ViewData:
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

    Raises
    ------
    LogFormatError for unreadable files, InputError for a bad window, an unknown method or
    sessions of different rigs, FusionError when fusing fails.
    """
    paths = ((Path(session_paths),) if isinstance(session_paths, (str, Path))
             else tuple(Path(p) for p in session_paths))
    if not paths:
        raise InputError("no session file given")
    session = read_session(paths[0])
    tracks: dict[str, Track] = dict(session.tracks)
    rejections = dict(session.rejections)
    notes: list[str] = []
    for path in paths[1:]:
        other = read_session(path)
        if other.rig.names != session.rig.names:
            raise InputError(f"{path}: cameras {', '.join(other.rig.names)} differ from "
                             f"{paths[0]}'s ({', '.join(session.rig.names)})")
        if not np.array_equal(other.detections.frame_time_ns, session.detections.frame_time_ns):
            notes.append(f"{path}: its frames are not {paths[0]}'s, so its tracks may come "
                         f"from another session")
        for name, track in other.tracks.items():
            if name in tracks:
                new = f"{name}_{_safe_name(path.stem)}"
                notes.append(f"{path}: track {name!r} shown as {new!r}")
                if name in other.rejections:
                    rejections[new] = other.rejections[name]
                name = new
            elif name in other.rejections:
                rejections[name] = other.rejections[name]
            tracks[name] = track

    observations = timed_observations(session.detections, session.rig)
    wanted = parse_methods(methods)
    if wanted is None:
        wanted = list(tracks) or ([DEFAULT_METHOD] if len(session.rig) >= 2
                                  and len(observations) else [])
    missing = [m for m in wanted if m not in tracks]
    unknown = [m for m in missing if m not in METHODS]
    if unknown:
        have = sorted(set(tracks) | set(METHODS))
        raise InputError(f"unknown method {unknown[0]!r} (stored or fusable: {', '.join(have)})")
    if missing:
        # as 'pslog fuse' does: each frame's ball chosen among its candidates (gating)
        tracks.update(fuse_all(session.detections, session.rig, missing))
        notes.append(f"fused on the fly: {', '.join(missing)}")
    shown = {m: tracks[m] for m in wanted}

    construction = None
    if "typeA" in shown and len(session.rig) >= 2 and len(observations):
        construction = explain_type_a(session.detections, session.rig)

    first = int(session.detections.frame_time_ns.min()) if session.detections.n_frames else 0
    lo = -np.inf if start is None else float(start)
    hi = np.inf if end is None else float(end)
    if not (np.isfinite(lo) or start is None) or not (np.isfinite(hi) or end is None):
        raise InputError(f"start and end must be finite seconds, got {start!r}, {end!r}")
    if lo >= hi:
        raise InputError(f"start ({start} s) must be before end ({end} s)")
    window = (first + round(lo * NS) if start is not None else -UNBOUNDED_NS,
              first + round(hi * NS) if end is not None else UNBOUNDED_NS)
    frame_times = session.detections.frame_time_ns
    if (start is not None or end is not None) and not np.any(
            (frame_times >= window[0]) & (frame_times < window[1])):
        span = (frame_times.max() - first) / NS if len(frame_times) else 0.0
        raise InputError(f"no frame between --start {start} s and --end {end} s; the session "
                         f"spans 0 to {span:.3f} s")
    return ViewData(session, paths, observations, shown, construction, window, notes,
                    {m: rejections[m] for m in shown if m in rejections})
