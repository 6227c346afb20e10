"""Per-camera recording counters, the live status line and the end-of-recording summary."""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field

from pslog.records import NS

_RATE_WINDOW_S = 2.0  # the status line's fps is measured over this many seconds


@dataclass
class CameraStatus:
    """Counters of one camera.

    Attributes
    ----------
    name : camera name
    source : what it records from (``video file clip.mp4``)
    state : ``opening``, ``recording``, ``stalled``, ``done``, ``failed``
    frames : frames written
    detections : frames with at least one ball candidate
    drops : frames lost (queue overflow, gaps in the timestamps, renders that fell behind)
    first_ns, last_ns : session times of the first and last frame, ns (None before any)
    message : why it failed or stopped, or how it ended
    clock : where its timestamps come from
    """

    name: str
    source: str
    state: str = "opening"
    frames: int = 0
    detections: int = 0
    drops: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    message: str = ""
    clock: str = ""
    _arrivals: deque = field(default_factory=deque, repr=False)

    def add_frame(self, time_ns: int, detected: bool, wall_s: float) -> None:
        self.frames += 1
        self.detections += bool(detected)
        if self.first_ns is None:
            self.first_ns = time_ns
        self.last_ns = time_ns if self.last_ns is None else max(self.last_ns, time_ns)
        self._arrivals.append(wall_s)
        while self._arrivals and wall_s - self._arrivals[0] > _RATE_WINDOW_S:
            self._arrivals.popleft()

    def rate(self, wall_s: float) -> float:
        """Frames per second written over the last couple of seconds (wall clock)."""
        while self._arrivals and wall_s - self._arrivals[0] > _RATE_WINDOW_S:
            self._arrivals.popleft()
        if len(self._arrivals) < 2:
            return 0.0
        span = max(wall_s - self._arrivals[0], 1e-9)
        return (len(self._arrivals) - 1) / span

    def fps_recorded(self) -> float:
        """Mean frame rate over the recorded span on the session clock."""
        if self.frames < 2 or self.first_ns is None or self.last_ns is None:
            return 0.0
        span = (self.last_ns - self.first_ns) / NS
        return (self.frames - 1) / span if span > 0 else 0.0


class StatusBoard:
    """All cameras' counters; formats the status line and the summary."""

    def __init__(self, cameras: list[CameraStatus]) -> None:
        self.cameras = cameras
        self.started = time.monotonic()
        #: monotonic seconds at the session start (the cameras started and ready), if any
        self.session_started: float | None = None

    def total_frames(self) -> int:
        return sum(c.frames for c in self.cameras)

    def line(self) -> str:
        """One line: per camera ``name frames fps det drops`` while it records (``started,
        no frame yet`` before its first frame), else its state."""
        now = time.monotonic()
        parts = []
        for c in self.cameras:
            if c.state == "recording" and c.frames == 0:  # started: not a rate of 0 fps
                parts.append(f"{c.name}: started, no frame yet")
            elif c.state in ("recording", "stalled"):
                tag = "" if c.state == "recording" else " STALLED"
                parts.append(f"{c.name}: {c.frames} fr {c.rate(now):4.1f} fps "
                             f"{c.detections} det {c.drops} drop{tag}")
            else:
                parts.append(f"{c.name}: {c.state} ({c.frames} fr)")
        return f"[{now - self.started:6.1f} s] " + " | ".join(parts)

    def summary(self) -> str:
        """Multi-line summary, one line per camera, then the totals."""
        lines = []
        for c in self.cameras:
            pct = 100.0 * c.detections / c.frames if c.frames else 0.0
            line = (f"  {c.name:<8} {c.frames:6d} frames  {c.fps_recorded():5.1f} fps  "
                    f"{c.detections:6d} with a candidate ({pct:5.1f} %)  {c.drops:4d} dropped  "
                    f"[{c.state}]")
            if c.message:
                line += f"  {c.message}"
            lines.append(line)
        total = self.total_frames()
        now = time.monotonic()
        wall = now - self.started
        if self.session_started is None:  # stopped before the cameras were ready
            lines.append(f"  total    {total:6d} frames; {wall:.1f} s wall time (the cameras "
                         f"were still starting)")
        else:
            # the rate over the recording itself: starting the camera processes (seconds:
            # imports, opening the sources) is not part of it
            # said apart from the session's own span: a --fast synthetic recording of a 3 s
            # motion took 4.8 s, and "270 frames in 4.8 s of recording" read as the session's
            run = now - self.session_started
            firsts = [c.first_ns for c in self.cameras if c.first_ns is not None]
            lasts = [c.last_ns for c in self.cameras if c.last_ns is not None]
            span = f"{(max(lasts) - min(firsts)) / NS:.3f} s" if firsts and lasts else "-"
            lines.append(f"  total    {total:6d} frames over {span} of session time, recorded "
                         f"in {run:.1f} s ({total / run if run > 0 else 0.0:.1f} frames/s, "
                         f"wall clock); {wall:.1f} s wall time with the cameras' start")
        return "\n".join(lines)
