"""Record a session: one process per camera (capture, detect, JPEG-encode), one writer.

As in the paper's system, each camera has its own process that captures and analyses its
frames and sends the results, with the capture time, to the parent, which owns the only
:class:`pslog.log.SessionWriter`. Each camera has its own one-way pipe to the parent, whose
write end only that camera holds: a camera killed at any instant (SIGKILL, the OOM killer),
even in the middle of a message, gives the parent an end of file on that pipe alone -- its
complete messages are kept, the other cameras are not affected. (One shared
``multiprocessing.Queue`` was not safe: a camera killed while its feeder thread held the
queue's write lock blocked every other camera for ever, and a partial message left by a
killed camera blocked the parent's next read for ever.) The parent shows a live status line,
watches for cameras that fail or stall (logging the gap as an event while the others keep
recording) and finishes the file cleanly on Ctrl-C, SIGTERM or SIGHUP; the writer flushes
every 0.5 s, so a SIGKILL loses at most the last half second written (``pslog recover``
salvages the rest).

Worker -> parent messages (tuples, first item the kind):
``ready(cam, clock, live)``, ``failed(cam, text)``, ``frame(cam, index, time_ns, uv, radius,
score, jpeg)``, ``event(cam, time_ns, text)``, ``stopped(cam, text)``, ``done(cam, text)``.
"""

from __future__ import annotations

import collections
import contextlib
import multiprocessing as mp
import os
import pickle
import queue as queue_module
import signal
import struct
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Literal

import numpy as np

from pslog.errors import InputError, PslogError, RigError, shell_word
from pslog.outputs import WriteError, check_output_path, write_error
from pslog.records import NS, Truth
from pslog.rig import Rig, timing_label

from ._flag import ProcessFlag, settled
from .detect import BallDetector, HsvRange
from .status import CameraStatus, StatusBoard

_QUEUE_PER_CAMERA = 32  # frame messages waiting in a camera process (about 3 MB of JPEG)
_DRAIN = 64  # messages read after a wait before the loop's housekeeping
_OPEN_TIMEOUT_S = 60.0  # longest wait for every camera to open (spawning included)
_STOP_TIMEOUT_S = 10.0  # longest wait for cameras to finish after a stop request
_FIRST_FRAME_S = 5.0  # a live camera without a first frame this long after the start: said
_TTY_REFRESH_S = 0.25
_LOG_REFRESH_S = 5.0  # status line period when stderr is not a terminal


@dataclass(frozen=True)
class WorkerOptions:
    """What every camera process does with its frames."""

    hsv: HsvRange = field(default_factory=HsvRange)
    max_candidates: int = 5
    frames: bool = True
    jpeg_quality: int = 90
    duration_ns: int | None = None


@dataclass(frozen=True)
class RecordSummary:
    """The outcome of a recording.

    Attributes
    ----------
    output : the session file
    cameras : per-camera counters (frames, detections, drops, state, message)
    wall_s : wall-clock duration of the call, seconds (starting the camera processes included)
    interrupted : True when stopped by Ctrl-C / SIGTERM / SIGHUP
    events : (time_ns, text) logged as session events
    """

    output: Path
    cameras: tuple[CameraStatus, ...]
    wall_s: float
    interrupted: bool
    events: tuple[tuple[int, str], ...]
    text: str

    @property
    def n_frames(self) -> int:
        return sum(c.frames for c in self.cameras)

    @property
    def n_detections(self) -> int:
        return sum(c.detections for c in self.cameras)

    @property
    def failed(self) -> tuple[str, ...]:
        """Names of cameras that failed to open or stopped delivering."""
        return tuple(c.name for c in self.cameras if c.state == "failed")


def record(
    rig: Rig,
    sources: Mapping[str, object],
    output: str | Path,
    *,
    duration_s: float | None = None,
    frames: bool = True,
    jpeg_quality: int = 90,
    hsv: HsvRange | None = None,
    max_candidates: int = 5,
    force: bool = False,
    timing: str | None = None,
    source: str = "",
    metadata: Mapping[str, str] | None = None,
    truth: Truth | None = None,
    status: IO[str] | Literal["stderr"] | None = "stderr",
    stop_request: StopRequest | None = None,
    prefix: str = "",
) -> RecordSummary:
    """Record every camera of ``rig`` from its source into the session ``output``.

    Parameters
    ----------
    rig : the session's cameras (calibration and shutter offsets)
    sources : camera name -> source spec (:mod:`recorders.sources`); exactly the rig's cameras
    output : MCAP file to write; refused if it exists unless ``force``
    duration_s : stop each camera at this session time, seconds (None: until the sources end
        or Ctrl-C)
    frames : store the JPEG frames (False: detections only)
    jpeg_quality : 1..100
    hsv, max_candidates : ball detection settings (:class:`recorders.detect.BallDetector`)
    timing : shutter preset name for the metadata (default: inferred from the rig's offsets)
    source, metadata : free text and string key/values stored in the session metadata
    truth : ground truth to store (synthetic sessions)
    status : stream for the live status line, messages and summary (default: the current
        ``sys.stderr``; None: silent)
    prefix : put before the status line, each message and the summary's first line (``pslog
        record: ``, as every command's lines on stderr start); the summary's per-camera table
        below it is indented
    stop_request : the recording stops cleanly once this is set, also when it was set
        before the call. A caller that routes SIGINT and SIGTERM to it
        (:meth:`StopRequest.install`) before its own slow start-up passes it here; None:
        SIGINT and SIGTERM are routed to a new one for the duration of the call (main thread
        only)

    Raises
    ------
    RecordWriteError : the file could not be written (disk full, ...); the cameras were
        stopped and what was written is kept, the message says where

    Returns
    -------
    RecordSummary
    """
    if isinstance(status, str):
        status = sys.stderr
    names = list(sources)
    unknown = [n for n in names if n not in rig.names]
    if unknown:
        raise RigError(f"source for unknown camera {unknown[0]!r} "
                       f"(rig has {', '.join(rig.names)})")
    missing = [n for n in rig.names if n not in sources]
    if missing:
        raise InputError(f"no source for camera(s) {', '.join(missing)} of the rig "
                         f"(give --source NAME=... for every camera)")
    if not 1 <= int(jpeg_quality) <= 100:
        raise InputError(f"JPEG quality must be in 1..100, got {jpeg_quality!r}")
    if duration_s is not None and not (np.isfinite(duration_s) and duration_s > 0):
        raise InputError(f"duration must be > 0 seconds, got {duration_s!r}")
    output = check_output_path(output, force)
    options = WorkerOptions(hsv=hsv or HsvRange(), max_candidates=int(max_candidates),
                            frames=bool(frames), jpeg_quality=int(jpeg_quality),
                            duration_ns=None if duration_s is None else int(duration_s * NS))
    meta = {"detector_hsv": options.hsv.text(),
            "detector_max_candidates": str(options.max_candidates),
            "jpeg_quality": str(options.jpeg_quality) if frames else "none"}
    for name in rig.names:
        meta[f"source_{name}"] = sources[name].describe()
    meta.update({str(k): str(v) for k, v in dict(metadata or {}).items()})
    # Ctrl-C and SIGTERM only ask the recording to stop, from before the file is created to
    # after it is finished, so a signal at any moment ends in a clean stop, never a traceback
    if stop_request is None:
        stop_signal = StopRequest()
        restore = stop_signal.install()
    else:  # the caller routes the signals (and restores them)
        stop_signal, restore = stop_request, _nothing
    try:
        return _record(rig, sources, output, options, meta, timing=timing, source=source,
                       truth=truth, force=force, status=status, stop_signal=stop_signal,
                       prefix=prefix)
    finally:
        restore()


def _record(rig: Rig, sources: Mapping[str, object], output: Path, options: WorkerOptions,
            meta: dict[str, str], *, timing, source, truth, force, status,
            stop_signal: StopRequest, prefix: str = "") -> RecordSummary:
    from pslog.log import SessionWriter

    try:  # a writer that fails to start removes what it began
        writer = SessionWriter(output, rig, force=force, timing=timing or timing_label(rig),
                               source=source or "record", metadata=meta)
    except _WRITE_ERRORS as exc:  # an unwritable folder, a full disk: nothing recorded yet
        reason = _reason(exc, output)
        raise RecordWriteError(f"cannot write {output}: {reason}; nothing was recorded",
                               reason) from None
    # with --force over an old session the writer writes <output>.partial, moved over the
    # old session only once complete
    target = writer.target
    existed = target != output
    session = _Session(rig, sources, options, writer, status, stop_signal, prefix)
    try:
        if truth is not None:
            session.write(writer.add_truth, truth)
        summary = session.run()
    except BaseException as exc:
        _close_failed(writer, exc)
        raise
    if session.write_error is None:
        try:
            if summary.n_frames == 0:
                writer.abort()  # no camera delivered: keep any session this would replace
            else:
                writer.close()
        except (OSError, PslogError) as exc:
            session.write_error = exc
            _close_failed(writer, exc)
    else:
        _close_failed(writer, session.write_error)
    if session.write_error is not None:
        reason = _reason(session.write_error, output)
        kept = (f"what was written before is in {target}, unfinished (salvage it with: "
                f"pslog recover {shell_word(target)} -o fixed.mcap)" if target.exists() else
                "nothing was kept")
        if existed:
            kept += f"; the old {output} is untouched"
        raise RecordWriteError(f"cannot write {output}: {reason}; stopped the cameras; {kept}",
                               reason)
    if summary.n_frames == 0 and not existed:
        # stopped before the first frame, or no camera opened: a file of the calibration
        # alone is not a recording, and would only refuse the next run ("exists")
        output.unlink(missing_ok=True)
    return summary


#: what a writer raises when the OS refuses a write
_WRITE_ERRORS = (OSError, WriteError)


class RecordWriteError(WriteError):
    """The session file could not be written (disk full, file too large, I/O error)."""


def _close_failed(writer, exc: BaseException) -> None:
    """Close ``writer`` after a failure: it keeps what it wrote (and any old session it was
    to replace); a second error while closing (the disk is still full) is expected."""
    with contextlib.suppress(OSError, PslogError):
        writer.__exit__(type(exc), exc, exc.__traceback__)


class StopRequest:
    """A request to stop recording: which signal (SIGINT, SIGTERM) asked first, if any.

    :meth:`install` makes SIGINT and SIGTERM set it instead of interrupting the process, so a
    program can take over the signals before its slow imports and hand the request to
    :func:`record` (``stop_request=``), which honours a stop that came in before it started.
    """

    def __init__(self) -> None:
        self.event = threading.Event()
        self.name = ""

    def set(self, name: str) -> None:
        self.name = self.name or name
        self.event.set()

    def is_set(self) -> bool:
        return self.event.is_set()

    def install(self) -> Callable[[], None]:
        """Route SIGINT, SIGTERM and SIGHUP here; returns a function restoring the previous
        handlers (both a no-op outside the main thread, where Python allows no handler)."""
        if threading.current_thread() is not threading.main_thread():
            return _nothing

        def handler(signum, frame):
            self.set(signal.Signals(signum).name)

        # (a SIGHUP ignored, under nohup, stays ignored)
        previous = {sig: signal.signal(sig, handler) for sig in _STOP_SIGNALS
                    if not (sig == signal.SIGHUP and signal.getsignal(sig) is signal.SIG_IGN)}

        def restore() -> None:
            for sig, old in previous.items():
                signal.signal(sig, old)

        return restore


class _Session:
    """The parent side of one recording."""

    def __init__(self, rig: Rig, sources: Mapping[str, object], options: WorkerOptions,
                 writer, status: IO[str] | None, stop_signal: StopRequest | None = None,
                 prefix: str = "") -> None:
        self.rig = rig
        self.prefix = prefix  # before each line this session writes to ``status``
        self.stop_signal = stop_signal or StopRequest()
        self.write_error: BaseException | None = None  # the first failed write
        self.specs = [sources[name] for name in rig.names]
        self.options = options
        self.writer = writer
        self.status = status
        self.tty = bool(status is not None and getattr(status, "isatty", lambda: False)())
        self.board = StatusBoard([CameraStatus(c.name, s.describe())
                                  for c, s in zip(rig.cameras, self.specs, strict=True)])
        self.events: list[tuple[int, str]] = []
        self.live = [False] * len(rig)
        self.last_arrival = [0.0] * len(rig)
        self.started_at: float | None = None  # monotonic seconds at session time 0
        self._no_first_frame_said = [False] * len(rig)
        # why the recording ended before the sources did; ``stopped``: the cameras were
        # stopped (a signal, a write failure) rather than reaching an end or the duration
        self.stop_reason = ""
        self.stopped = False
        self._line_shown = False

    # ---- output -------------------------------------------------------------------------
    def _say(self, text: str) -> None:
        if self.status is None:
            return
        if self._line_shown and self.tty:
            self.status.write("\r\033[K")
            self._line_shown = False
        self.status.write(self.prefix + text + "\n")
        self.status.flush()

    def _show_line(self) -> None:
        if self.status is None:
            return
        if self.tty:
            self.status.write("\r\033[K" + self.prefix + self.board.line())
            self._line_shown = True
        else:
            self.status.write(self.prefix + self.board.line() + "\n")
        self.status.flush()

    def _event(self, time_ns: int, text: str, camera: int | None, level: str = "info") -> None:
        self.write(self.writer.add_event, int(time_ns), text, camera=camera, level=level)
        self.events.append((int(time_ns), text))

    def write(self, method, *args, **kwargs) -> bool:
        """Call a writer method; after the first OS failure (disk full, file too large) stop
        writing and remember it, so the recording ends cleanly and says what happened."""
        if self.write_error is not None:
            return False
        try:
            method(*args, **kwargs)
        except InputError:
            raise  # a wrong value, not a write fault
        except (OSError, PslogError) as exc:
            self.write_error = exc  # the writer's WriteError holds the OS's reason
            return False
        return True

    # ---- main loop ------------------------------------------------------------------------
    def run(self) -> RecordSummary:
        # spawn, not fork: a forked child hangs in OpenCV once the parent has used OpenCV's
        # thread pool (and the parent holds an open writer). As with any spawning code, a
        # script calling this must guard its top level with ``if __name__ == "__main__"``.
        ctx = mp.get_context("spawn")
        # one pipe per camera: the parent keeps only the reading ends (see the module text)
        pipes = [ctx.Pipe(duplex=False) for _ in self.specs]
        inbox = _Inbox([receive for receive, _send in pipes])
        # lock-free flags: a camera killed inside a multiprocessing.Event's is_set() would
        # leave its lock taken and hang every other camera and this loop (recorders._flag)
        start, stop = ProcessFlag(ctx), ProcessFlag(ctx)
        t0 = ctx.Value("q", 0, lock=False)
        procs = [ctx.Process(target=camera_main, name=f"pslog-{cam.name}",
                             args=(i, self.specs[i], self.options, pipes[i][1], start, stop,
                                   t0, os.getpid()), daemon=True)
                 for i, cam in enumerate(self.rig.cameras)]
        interrupted = self.stop_signal
        wall0 = time.monotonic()
        try:
            try:
                if not interrupted.is_set():
                    with _stop_signals_blocked():
                        for p, (_receive, send) in zip(procs, pipes, strict=True):
                            p.start()
                            send.close()  # the camera's alone: EOF here once it is gone
            finally:
                for _receive, send in pipes:
                    send.close()  # a camera not started: its pipe ends at once
            if not interrupted.is_set():
                self._wait_ready(inbox, procs, interrupted)
            t0.value = time.monotonic_ns()
            self.started_at = time.monotonic()
            if not interrupted.is_set():  # else the cameras were still starting
                self.board.session_started = self.started_at
            else:
                # stopped while the cameras were starting: the stop before the start, so a
                # camera released by the start finds it and reads no frame (set after, one
                # ready camera could deliver a frame first: a one-frame session kept)
                self.stop_reason, self.stopped = f"stopped by {interrupted.name}", True
                stop.set()
            start.set()
            if not interrupted.is_set():
                # relates the session clock to the host's monotonic clock (and UTC)
                self._event(0, f"recording started: session time 0 is host monotonic clock "
                               f"{t0.value} ns, {_utc_now()}", None)
            self._loop(inbox, procs, stop, interrupted, t0.value)
        finally:
            stop.set()
            start.set()
            if interrupted.is_set():
                self.stop_reason, self.stopped = f"stopped by {interrupted.name}", True
            self._finish(inbox, procs)
        if self._line_shown and self.tty and self.status is not None:
            self.status.write("\r\033[K")
        summary_text = self.board.summary()
        if self.status is not None:
            if self.write_error is not None:
                head = "recording stopped, the file could not be written"
            elif interrupted.is_set():
                head = f"recording stopped by {interrupted.name}: {self.writer.path}"
            elif self.board.total_frames() == 0:
                head = f"nothing recorded to {self.writer.path}: no camera delivered a frame"
            else:
                head = f"recorded: {self.writer.path}"
            self.status.write(f"{self.prefix}{head}\n{summary_text}\n")
            self.status.flush()
        return RecordSummary(Path(self.writer.path), tuple(self.board.cameras),
                             time.monotonic() - wall0, interrupted.is_set(),
                             tuple(self.events), summary_text)

    def _wait_ready(self, inbox: _Inbox, procs, interrupted: StopRequest) -> None:
        """Until every camera has opened or failed."""
        cams = self.board.cameras
        deadline = time.monotonic() + _OPEN_TIMEOUT_S
        while any(c.state == "opening" for c in cams) and not interrupted.is_set():
            if time.monotonic() > deadline:
                for i, c in enumerate(cams):
                    if c.state == "opening":
                        self._fail(i, 0, f"{c.source} did not open within {_OPEN_TIMEOUT_S:g} s")
                return
            msgs = inbox.get(timeout=0.1, limit=1)
            if not msgs:
                self._check_alive(procs, 0, inbox)
            for msg in msgs:
                self._handle(msg, 0)

    def _loop(self, inbox: _Inbox, procs, stop, interrupted: StopRequest,
              t0_ns: int) -> None:
        cams = self.board.cameras
        # a terminal's line at once (it is rewritten in place); a log's first line only after
        # a period, when it has counts to give (it was a line of zeros at the start: session 23)
        last_line = 0.0 if self.tty else time.monotonic()
        refresh = _TTY_REFRESH_S if self.tty else _LOG_REFRESH_S
        duration_ns = self.options.duration_ns
        stop_wall: float | None = None
        while True:
            active = [i for i, c in enumerate(cams) if c.state in ("recording", "stalled")]
            if not active:
                break
            if interrupted.is_set() and not stop.is_set():
                self._say(f"{interrupted.name}: stopping, finishing the session file ...")
                self.stop_reason, self.stopped = f"stopped by {interrupted.name}", True
                stop.set()
                self._event(max(time.monotonic_ns() - t0_ns, 0),
                            f"recording {self.stop_reason}", None)
            if self.write_error is not None and not stop.is_set():
                self._say(f"writing {self.writer.path} failed "
                          f"({_reason(self.write_error, self.writer.path)}): stopping the "
                          f"cameras ...")
                self.stop_reason = "stopped: the file could not be written"
                self.stopped = True
                stop.set()
            # the first message within 50 ms and what is already there, before housekeeping
            msgs = inbox.get(timeout=0.05, limit=1 + _DRAIN)
            now_ns = time.monotonic_ns() - t0_ns
            for msg in msgs:
                self._handle(msg, now_ns)
            if not stop.is_set():  # cameras that are finishing may pause
                self._check_stalls()
            self._check_alive(procs, now_ns, inbox)
            if (duration_ns is not None and any(self.live) and not stop.is_set()
                    and now_ns > duration_ns + 2 * NS):
                # a stalled live camera never reaches the duration by itself
                self.stop_reason = "duration reached"
                stop.set()
            if stop.is_set():
                stop_wall = stop_wall or time.monotonic()
                if time.monotonic() - stop_wall > _STOP_TIMEOUT_S:
                    for i in active:
                        self._fail(i, now_ns, "did not stop in time")
                    break
            wall = time.monotonic()
            if self.status is not None and wall - last_line >= refresh:
                self._show_line()
                last_line = wall

    def _handle(self, msg: tuple, now_ns: int) -> None:
        kind, cam = msg[0], msg[1]
        c = self.board.cameras[cam]
        if kind == "frame":
            _, _, index, time_ns, uv, radius, score, jpeg = msg
            if not self.write(self.writer.add_frame, cam, index, time_ns, uv, radius, score,
                              image=jpeg):
                return  # the file cannot be written: the frame is not recorded
            period_ns = NS / self.rig.cameras[cam].fps
            if c.last_ns is not None and time_ns - c.last_ns > 1.5 * period_ns:
                c.drops += round((time_ns - c.last_ns) / period_ns) - 1
            if c.state == "stalled":
                gap = (time.monotonic() - self.last_arrival[cam])
                self._event(time_ns, f"camera {c.name} delivering again after {gap:.1f} s",
                            cam)
                self._say(f"{c.name}: delivering frames again after {gap:.1f} s")
                c.state = "recording"
            c.add_frame(time_ns, len(uv) > 0, time.monotonic())
            self.last_arrival[cam] = time.monotonic()
        elif kind == "ready":
            _, _, clock, live = msg
            c.state, c.clock = "recording", clock
            self.live[cam] = bool(live)
            self.last_arrival[cam] = time.monotonic()
        elif kind == "event":
            _, _, time_ns, text = msg
            if text.startswith("timestamps:"):
                c.clock = text.split(":", 1)[1].strip()
            self._event(time_ns, f"camera {c.name} {text}", cam)
        elif kind in ("failed", "stopped"):
            self._fail(cam, c.last_ns + 1 if c.last_ns is not None else max(now_ns, 0), msg[2])
        elif kind == "done":
            # a camera told to stop by a signal or a write failure was stopped; one that
            # reached its end or the duration is done
            c.state = "stopped" if self.stopped else "done"
            c.message = self.stop_reason if c.state == "stopped" else msg[2]

    def _fail(self, cam: int, time_ns: int, text: str) -> None:
        c = self.board.cameras[cam]
        if c.state in ("failed", "done", "stopped"):
            return
        c.state, c.message = "failed", text
        self._event(time_ns, f"camera {c.name} failed: {text}", cam, level="error")
        # only cameras that opened record; ones still opening may fail too
        rest = [o.state for o in self.board.cameras if o is not c]
        if "recording" in rest or "stalled" in rest:
            others = "; the other cameras keep recording"
        elif "opening" in rest:
            others = "; the other cameras are still opening"
        else:
            others = ""
        self._say(f"error: {c.name}: {text}{others}")

    def _check_stalls(self) -> None:
        now = time.monotonic()
        for i, c in enumerate(self.board.cameras):
            if c.state != "recording" or not self.live[i]:
                continue
            if c.last_ns is None:
                # not a stall: a camera's first frame may come late (its source starting);
                # said once after a while, neither a state nor an event
                since = now - (self.started_at if self.started_at is not None else now)
                if since > _FIRST_FRAME_S and not self._no_first_frame_said[i]:
                    self._no_first_frame_said[i] = True
                    self._say(f"warning: {c.name}: no frame yet, {since:.1f} s after the start")
                continue
            limit = max(1.0, 10.0 / self.rig.cameras[i].fps)
            if now - self.last_arrival[i] > limit:
                c.state = "stalled"
                # just after its last frame: before the "delivering again" of its next one
                self._event(c.last_ns + 1, f"camera {c.name} stopped delivering frames", i,
                            level="warning")
                self._say(f"warning: {c.name}: no frame for {now - self.last_arrival[i]:.1f} s")

    def _check_alive(self, procs, now_ns: int, inbox: _Inbox) -> None:
        for i, (p, c) in enumerate(zip(procs, self.board.cameras, strict=True)):
            if c.state in ("opening", "recording", "stalled") and not p.is_alive():
                # its last messages are read once its pipe ended; give them a moment anyway
                if p.exitcode is not None and (inbox.ended(i) or time.monotonic() - getattr(
                        p, "_pslog_seen_dead", time.monotonic()) > 1.0):
                    self._fail(i, c.last_ns + 1 if c.last_ns is not None else max(now_ns, 0),
                               f"camera process died (exit code {p.exitcode})")
                elif not hasattr(p, "_pslog_seen_dead"):
                    p._pslog_seen_dead = time.monotonic()

    def _finish(self, inbox: _Inbox, procs) -> None:
        """Collect the last messages and reap the camera processes."""
        deadline = time.monotonic() + _STOP_TIMEOUT_S
        cams = self.board.cameras
        for p, c in zip(procs, cams, strict=True):
            if c.state == "opening" and p.pid is not None and p.is_alive():
                # stopped before it said "ready": it holds no frame, and may be importing or
                # opening its source for many seconds yet
                p.kill()
        try:
            while time.monotonic() < deadline and (
                    any(p.is_alive() for p in procs) or not inbox.all_ended()):
                for msg in inbox.get(timeout=0.05, limit=1 + _DRAIN):
                    self._handle(msg, 0)
        except PslogError:
            pass  # writer closed or broken: only reap
        for p in procs:
            if p.pid is None:
                continue  # never started (stopped before the start)
            p.join(timeout=1.0)
            if p.is_alive():
                p.kill()  # cameras ignore SIGTERM (the parent stops them)
                p.join(timeout=1.0)
        for i, c in enumerate(cams):
            if c.state in ("opening", "recording", "stalled"):
                if self.stopped:
                    c.state, c.message = "stopped", self.stop_reason
                elif self.stop_reason:
                    c.state, c.message = "done", c.message or self.stop_reason
                else:
                    self._fail(i, (c.last_ns or 0) + 1, "ended without reporting")
        inbox.close()


#: a message on a camera's pipe: its pickle's length (8 bytes, big-endian), then the pickle
_LENGTH = struct.Struct("!Q")
_READ_BYTES = 1 << 20  # the most read from one pipe at a time


class _Inbox:
    """The parent's reading ends of the cameras' pipes (one per camera, by index).

    A pipe whose camera is gone ends (EOF): after all of that camera's complete messages, also
    when it was killed in the middle of writing one (the partial message is dropped). Only the
    camera holds the write end, so the end comes however the camera died. The pipes are read
    without blocking and messages rebuilt here (:data:`_LENGTH` framing, written by
    :class:`_Outbox`): a camera stopped in the middle of a message (SIGSTOP, a debugger, a
    frozen cgroup) holds back only its own messages, never the parent, whose Ctrl-C still
    stops the recording."""

    def __init__(self, conns) -> None:
        self._conns = list(conns)  # None once ended
        for conn in self._conns:
            os.set_blocking(conn.fileno(), False)
        self._buffers = [bytearray() for _ in self._conns]
        self._ready: list[collections.deque] = [collections.deque() for _ in self._conns]
        self._turn = 0

    def ended(self, cam: int) -> bool:
        return self._conns[cam] is None and not self._ready[cam]

    def all_ended(self) -> bool:
        return all(self.ended(cam) for cam in range(len(self._conns)))

    def get(self, timeout: float, limit: int) -> list[tuple]:
        """Up to ``limit`` messages: waits up to ``timeout`` seconds for the first, then takes
        what is already there, a message per camera in turn."""
        from multiprocessing.connection import wait

        open_conns = [c for c in self._conns if c is not None]
        if not any(self._ready):
            if not open_conns:
                time.sleep(timeout)
                return []
            ready = wait(open_conns, timeout=timeout)
        else:
            ready = wait(open_conns, timeout=0) if open_conns else []
        for conn in ready:
            self._read(self._conns.index(conn))
        msgs: list[tuple] = []
        n = len(self._conns)
        while len(msgs) < limit and any(self._ready):
            cam = self._turn
            self._turn = (self._turn + 1) % n
            if self._ready[cam]:
                msgs.append(self._ready[cam].popleft())
        return msgs

    def _read(self, cam: int) -> None:
        """What camera ``cam``'s pipe holds now, into whole messages (the rest kept)."""
        conn = self._conns[cam]
        buffer = self._buffers[cam]
        ended = False
        while True:
            try:
                data = os.read(conn.fileno(), _READ_BYTES)
            except BlockingIOError:
                break
            except OSError:  # the camera is gone
                ended = True
                break
            if not data:
                ended = True
                break
            buffer += data
            if len(data) < _READ_BYTES:
                break
        at = 0
        while len(buffer) - at >= _LENGTH.size:
            (length,) = _LENGTH.unpack_from(buffer, at)
            if len(buffer) - at - _LENGTH.size < length:
                break
            start = at + _LENGTH.size
            self._ready[cam].append(pickle.loads(buffer[start:start + length]))
            at = start + length
        del buffer[:at]
        if ended:  # a partial message of a camera killed mid-write is dropped
            self._conns[cam] = None
            buffer.clear()
            conn.close()

    def close(self) -> None:
        for conn in self._conns:
            if conn is not None:
                conn.close()
        self._conns = [None] * len(self._conns)
        for ready in self._ready:
            ready.clear()


def jpeg_params(quality: int) -> list[int]:
    """``cv2.imencode`` parameters of stored frames: the quality and full-resolution colour
    (4:4:4). The default 4:2:0 halves the colour resolution, which smears a ball a few
    pixels across into the background: on the paper3 rig's 2..3 px balls a quarter of the
    stored frames then lose their detection and centroids are twice as noisy."""
    import cv2

    return [cv2.IMWRITE_JPEG_QUALITY, int(quality),
            cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]


_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)  # HUP: a closed terminal


def _nothing() -> None:
    pass


@contextlib.contextmanager
def _stop_signals_blocked():
    """Start camera processes inside this block: SIGINT and SIGTERM are blocked in the
    calling thread, and a child inherits that mask (through ``exec`` too). So Ctrl-C (sent to
    the whole foreground process group) or SIGTERM to the group stays pending in a camera
    that is still importing, until :func:`camera_main` ignores these signals (which discards
    it there): the parent stops the cameras. The parent's handlers stay in place meanwhile:
    its other threads take such a signal, or it waits for the end of the block, never lost.

    multiprocessing's resource tracker is started first: the first ``Process.start()`` starts
    it otherwise, and its start UNBLOCKS these signals in the calling thread (Python's
    ``resource_tracker.ensure_running``), so the cameras started after it got a Ctrl-C while
    importing (a KeyboardInterrupt traceback). The shared ``multiprocessing.Queue`` used to
    start it earlier by chance (its lock registers with the tracker). The tracker ignores
    only SIGINT and SIGTERM: it is started with SIGHUP blocked (a mask survives ``exec``),
    else a SIGHUP to the group (a closed terminal) killed it, and the next camera's start
    printed multiprocessing's "resource_tracker: process died unexpectedly" warning."""
    from multiprocessing import resource_tracker

    hup = signal.pthread_sigmask(signal.SIG_BLOCK, (signal.SIGHUP,))
    try:
        resource_tracker.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, hup)
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _reason(exc: BaseException, path: str | Path) -> str:
    """The operating system's reason (``No space left on device``) behind a write failure."""
    if isinstance(exc, WriteError):
        return exc.reason
    return write_error(path, exc).reason if isinstance(exc, OSError) else str(exc)


def _utc_now() -> str:
    from datetime import UTC, datetime

    return datetime.now(UTC).isoformat(timespec="milliseconds")


# ---- the camera process -------------------------------------------------------------------
def camera_main(cam: int, spec, options: WorkerOptions, conn, start, stop, t0,
                parent_pid: int) -> None:
    """Body of one camera process: open, wait for the start, then capture -> detect ->
    encode -> send until the source ends, the duration is reached or the parent says stop.

    ``conn`` is the write end of this camera's own pipe to the parent."""
    import cv2

    # Ctrl-C and SIGTERM to the process group reach the parent too, which stops us. They
    # were blocked from the start (see _stop_signals_blocked); ignoring them discards one
    # that came meanwhile, then they can be unblocked
    for sig in _STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)
    cv2.setNumThreads(1)  # one process per camera already uses the cores
    with contextlib.suppress(AttributeError):  # our own message says what failed
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)

    def parent_gone() -> bool:
        return os.getppid() != parent_pid

    outbox = _Outbox(conn, parent_gone)

    def send(msg, block: bool = True) -> bool:
        return outbox.put(msg, block=block,
                          give_up=lambda: stop.is_set() and msg[0] == "frame")

    try:
        _camera_body(cam, spec, options, start, stop, t0, send, parent_gone)
    finally:
        outbox.close()


def _camera_body(cam: int, spec, options: WorkerOptions, start, stop, t0,
                 send: Callable[..., bool], parent_gone: Callable[[], bool]) -> None:
    import cv2

    from .sources import SourceError, end_reason

    try:
        source = spec.open()
    except Exception as exc:  # any failure to open is reported, not raised
        text = str(exc) if isinstance(exc, PslogError) else f"{spec.describe()}: {exc!r}"
        send(("failed", cam, text))
        return
    detector = BallDetector(options.hsv, options.max_candidates)
    params = jpeg_params(options.jpeg_quality)
    # what the first frame would do lazily (about 0.3 s), done before "ready": a live
    # source's first frames would otherwise be late and skipped
    warm_camera(detector, spec, params if options.frames else None)
    send(("ready", cam, source.clock, source.live))
    while not start.wait(0.2):
        if parent_gone():
            return
    if stop.is_set():
        send(("done", cam, "stopped before the start"))
        return
    source.set_start(settled(t0, stop))
    clock = ""
    reason = "stopped by user"
    try:
        while not stop.is_set():
            try:
                item = source.read()
            except SourceError as exc:
                send(("stopped", cam, str(exc)))
                return
            if item is None:
                reason = end_reason(source)
                break
            index, time_ns, frame = item
            if options.duration_ns is not None and time_ns >= options.duration_ns:
                reason = "duration reached"
                break
            if source.clock != clock:
                clock = source.clock
                send(("event", cam, time_ns, f"timestamps: {clock}"))
            found = detector.detect(frame)
            jpeg = None
            if options.frames:
                ok, buf = cv2.imencode(".jpg", frame, params)
                jpeg = buf.tobytes() if ok else None
            msg = ("frame", cam, index, time_ns, found.uv, found.radius, found.score, jpeg)
            send(msg, block=not source.live)  # a live source cannot wait: drop instead
            if parent_gone():
                return
        send(("done", cam, reason))
    finally:
        source.close()


def frame_size(spec) -> tuple[int, int]:
    """(width, height) of the frames a source spec delivers (640 x 480 when it does not say:
    only the warm-up uses it)."""
    camera = getattr(spec, "camera", None)
    width = getattr(spec, "width", None) or getattr(camera, "width", None) or 640
    height = getattr(spec, "height", None) or getattr(camera, "height", None) or 480
    return int(width), int(height)


def warm_camera(detector: BallDetector, spec, jpeg: list[int] | None) -> None:
    """The detector (:meth:`BallDetector.warm`) and the JPEG encoder (``jpeg``: its
    parameters, None for none) warmed for the spec's frame size."""
    import cv2

    width, height = frame_size(spec)
    frame = detector.warm(width, height)
    if jpeg is not None:
        cv2.imencode(".jpg", frame, jpeg)


def _write_all(fd: int, data: bytes) -> None:
    """All of ``data`` into the blocking file ``fd`` (a pipe's write takes what fits)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


class _Outbox:
    """A camera process's sending end: a bounded local queue and a thread writing its
    messages into the camera's pipe, so the capture loop never waits in a pipe write (a live
    source drops a frame instead when the parent is behind)."""

    def __init__(self, conn, parent_gone: Callable[[], bool]) -> None:
        self._conn = conn
        self._parent_gone = parent_gone
        self._queue: queue_module.Queue = queue_module.Queue(maxsize=_QUEUE_PER_CAMERA)
        self._broken = False  # the parent's end is closed: nothing can be sent any more
        self._thread = threading.Thread(target=self._run, name="pslog-sender", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            msg = self._queue.get()
            if msg is None:
                return
            data = pickle.dumps(msg, protocol=pickle.HIGHEST_PROTOCOL)
            try:
                _write_all(self._conn.fileno(), _LENGTH.pack(len(data)) + data)
            except OSError:  # the parent is gone (its reading end closed)
                self._broken = True
                return

    def put(self, msg: tuple, block: bool, give_up: Callable[[], bool]) -> bool:
        """Queue ``msg``; without ``block`` drop it when the queue is full. A blocking put
        gives up when the parent is gone or ``give_up()``. Returns whether it was queued."""
        while not self._broken:
            try:
                if not block:
                    self._queue.put_nowait(msg)
                else:
                    self._queue.put(msg, timeout=0.5)
                return True
            except queue_module.Full:
                if not block or self._parent_gone() or give_up():
                    return False
        return False

    def close(self) -> None:
        """Send what is queued (while the parent is there to read it), then end."""
        while not self._broken and self._thread.is_alive():
            try:
                self._queue.put(None, timeout=0.2)
                break
            except queue_module.Full:
                if self._parent_gone():
                    return
        while self._thread.is_alive():
            self._thread.join(0.2)
            if self._parent_gone():
                return
        self._conn.close()
