"""Live camera processes: capture, detect, send one detection datagram per frame over UDP.

As in the paper's system (processes 1-3 analyse each camera's images and send the results
to process 4), every camera of ``pslog live`` runs in its own process: it captures a frame
(a live camera, a video file paced by its timestamps, or a synthetic camera rendering the
rig in real time), detects the ball with the recorders' :class:`~recorders.detect.BallDetector`
and sends ONE detection datagram (:func:`pslog.live.protocol.encode_detections`) per frame to
the fuser's listen address, also when nothing was seen (k = 0 tells the fuser the camera is
alive). The datagram carries:

- ``sequence``: +1 per frame sent, per camera, continued across restarts of the process
  (the parent keeps the counter in shared memory), so a restarted camera is never taken for
  a duplicate of its earlier self;
- ``t_capture_ns``: the frame's capture time on the wall clock (Unix epoch ns, as the
  protocol wants): the session start ``t0`` read on the wall clock plus the frame's time on
  the session clock (ns since ``t0``, a reading of the host's ``CLOCK_MONOTONIC`` that every
  process shares, the clock the sources stamp frames with);
- ``t_sent_ns``: the wall clock read just before sending.

When the fuser's clock started earlier (its ``epoch_ns``), the session start is put a whole
number of seconds after it, so the logged times the fuser derives (``t_capture_ns -
epoch_ns``) keep the rig's shutter phases.

The parent side (:class:`LiveCameras`) starts the processes (all of them open their source
before the session clock starts, so none misses the start), watches them, and restarts one
that died after a back-off (1 s, doubling up to 30 s; a source that merely ended is not
restarted). A restarted synthetic camera or video file resumes at the current session time
(frames whose time has passed are skipped, as a camera would), so the fuser sees it come back.

Processes are spawned, not forked (see :meth:`recorders.record._Session.run`); they ignore
SIGINT and SIGTERM (the parent stops them) and exit on their own when the parent is gone.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from pslog.records import NS

from ._flag import ProcessFlag, settled
from .detect import HsvRange
from .record import _STOP_SIGNALS, _stop_signals_blocked, warm_camera

#: exit codes of a camera process (anything else, e.g. -9, is a death)
EXIT_DONE = 0  # the source ended or the duration was reached
EXIT_FAILED = 3  # the source failed to open or stopped delivering
EXIT_CRASHED = 4  # an unexpected error while capturing, detecting or sending
_OPEN_TIMEOUT_S = 60.0  # longest wait for every camera to open before the clock starts
_STOP_TIMEOUT_S = 5.0  # longest wait for a camera process to end once told to stop
_BACKOFF_S = (1.0, 30.0)  # first and longest wait before restarting a dead camera
_STABLE_S = 10.0  # a process that ran this long restarts after the first back-off again
_FIRST_FRAME_S = 5.0  # a camera is "starting" until its first datagram or this long after
# the session clock started

# shared per-camera counters (int64, written by the camera's process, read by the parent)
_SEQ, _FRAMES, _DETECTED, _SKIPPED, _SEND_ERRORS, _LAST_INDEX = range(6)
_COUNTERS = 6


@dataclass(frozen=True)
class SenderOptions:
    """What every camera process does with its frames.

    Attributes
    ----------
    hsv, max_candidates : ball detection (:class:`recorders.detect.BallDetector`)
    duration_ns : stop at this session time, ns (None: until the source ends or the stop)
    pace : send frames of a source that is not live (a video file) at their capture time on
        the session clock, skipping those already past, as a camera would
    """

    hsv: HsvRange = field(default_factory=HsvRange)
    max_candidates: int = 5
    duration_ns: int | None = None
    pace: bool = True


# ---- the camera process -------------------------------------------------------------------
def sender_main(name: str, spec, options: SenderOptions, address: tuple[str, int], t0,
                t0_wall, counters, start, stop, conn, parent_pid: int) -> None:
    """Body of one camera process: open the source, say ready, wait for the session clock
    to start (``t0``), then capture -> detect -> send a datagram until the source ends, the
    duration is reached, the parent says stop or is gone."""
    for sig in _STOP_SIGNALS:  # the parent stops us (see recorders.record.camera_main)
        signal.signal(sig, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)
    import socket

    import cv2

    from pslog.errors import PslogError
    from pslog.live.protocol import DetectionDatagram, encode_detections

    from .detect import BallDetector
    from .sources import SourceError, end_reason

    cv2.setNumThreads(1)  # one process per camera already uses the cores
    with contextlib.suppress(AttributeError):
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)

    def tell(*msg) -> None:
        with contextlib.suppress(OSError):
            conn.send(msg)

    def parent_gone() -> bool:
        return os.getppid() != parent_pid

    try:
        source = spec.open()
    except Exception as exc:  # any failure to open is reported, not raised
        tell("failed", str(exc) if isinstance(exc, PslogError) else f"{spec.describe()}: "
                                                                     f"{exc!r}")
        sys.exit(EXIT_FAILED)
    detector = BallDetector(options.hsv, options.max_candidates)
    warm_camera(detector, spec, None)  # before "ready": its first frames are not late
    tell("ready", source.clock)
    while not start.wait(0.2):
        if parent_gone() or stop.is_set():
            source.close()
            return
    t0_ns, wall_ns = settled(t0, stop), settled(t0_wall, stop)
    source.set_start(t0_ns)
    family = socket.AF_INET6 if ":" in address[0] else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_DGRAM)
    sequence = int(counters[_SEQ])
    reason, code = "stopped", EXIT_DONE
    try:
        while not stop.is_set():
            if parent_gone():
                return
            try:
                item = source.read()
            except SourceError as exc:
                tell("failed", str(exc))
                reason, code = "", EXIT_FAILED
                break
            if item is None:
                reason = end_reason(source)
                break
            index, time_ns, frame = item
            if options.duration_ns is not None and time_ns >= options.duration_ns:
                reason = "duration reached"
                break
            if options.pace and not source.live:
                # a file's frame leaves at its capture time; one already a frame late is
                # skipped, as a camera that fell behind would
                wait_ns = t0_ns + time_ns - time.monotonic_ns()
                if wait_ns < -_late_ns(spec):
                    continue  # counted as skipped by the next frame sent
                if wait_ns > 0:
                    time.sleep(wait_ns / NS)
            # frames the camera (or its earlier process) never sent: fell behind, or dead
            counters[_SKIPPED] += max(int(index) - int(counters[_LAST_INDEX]) - 1, 0)
            counters[_LAST_INDEX] = int(index)
            found = detector.detect(frame)
            sequence += 1
            data = encode_detections(DetectionDatagram(
                camera=name, sequence=sequence, frame_index=int(index),
                t_capture_ns=wall_ns + int(time_ns), t_sent_ns=time.time_ns(),
                uv=found.uv, radius=found.radius, score=found.score))
            try:
                sock.sendto(data, address)
            except OSError:  # nobody listening yet, a full buffer: the frame is lost
                counters[_SEND_ERRORS] += 1
            counters[_SEQ] = sequence
            counters[_FRAMES] += 1
            if len(found):
                counters[_DETECTED] += 1
        if reason:
            tell("done", reason)
    except Exception as exc:  # a bug or a bad frame: said in one line (the parent restarts
        # the camera), never a traceback on the terminal
        tell("failed", f"{spec.describe()}: {type(exc).__name__}: {exc}".splitlines()[0])
        code = EXIT_CRASHED
    finally:
        sock.close()
        with contextlib.suppress(Exception):
            source.close()
    sys.exit(code)


def _late_ns(spec) -> int:
    fps = getattr(spec, "fps", None) or 30.0
    return int(NS / fps)


# ---- the parent side -----------------------------------------------------------------------
@dataclass
class CameraProcess:
    """The parent's view of one camera: its current process and what it sent so far.

    Attributes
    ----------
    name : camera name (as the rig names it; the datagrams carry it)
    spec : the source spec (:mod:`recorders.sources`), opened in the process
    state : ``opening``, ``running``, ``waiting`` (dead, restarting after a back-off),
        ``done`` (the source ended), ``failed`` (never opened), ``stopped``
    restarts : how many times the process was restarted
    message : why it died, failed or ended
    """

    name: str
    spec: object
    counters: object = None
    process: object = None
    conn: object = None
    state: str = "opening"
    restarts: int = 0
    message: str = ""
    started_at: float = 0.0
    restart_at: float = 0.0
    backoff_s: float = _BACKOFF_S[0]
    opened: bool = False  # the source opened at least once

    @property
    def pid(self) -> int | None:
        return None if self.process is None else self.process.pid

    @property
    def frames(self) -> int:
        return int(self.counters[_FRAMES])

    @property
    def detected(self) -> int:
        return int(self.counters[_DETECTED])

    @property
    def skipped(self) -> int:
        return int(self.counters[_SKIPPED])

    @property
    def send_errors(self) -> int:
        return int(self.counters[_SEND_ERRORS])


class LiveCameras:
    """Start, watch and restart the camera processes of ``pslog live``.

    Parameters
    ----------
    specs : camera name -> source spec (:mod:`recorders.sources`)
    address : (host, port) the processes send their datagrams to
    options : SenderOptions
    say : prints one status message (the command prefixes and writes it to stderr)
    restart : restart a process that died (True), or leave the camera dead
    """

    def __init__(self, specs: Mapping[str, object], address: tuple[str, int],
                 options: SenderOptions | None = None, *,
                 say: Callable[[str], None] = print, restart: bool = True) -> None:
        self._ctx = mp.get_context("spawn")
        self.address = (str(address[0]), int(address[1]))
        self.options = options or SenderOptions()
        self.say = say
        self.restart = restart
        self.cameras = [CameraProcess(name, spec, self._ctx.Array(
            "q", [-1, 0, 0, 0, 0, -1], lock=False)) for name, spec in specs.items()]
        self._t0 = self._ctx.Value("q", 0, lock=False)
        self._t0_wall = self._ctx.Value("q", 0, lock=False)
        # lock-free: a camera killed while reading a multiprocessing.Event would hang the
        # others and this watcher (recorders._flag)
        self._start = ProcessFlag(self._ctx)
        self._stop = ProcessFlag(self._ctx)
        self.t0_ns: int | None = None  # session time 0 on the monotonic clock
        self.t0_wall_ns: int | None = None  # and on the wall clock
        self._started_at: float | None = None  # monotonic seconds when the clock started

    # ---- start --------------------------------------------------------------------------
    def _spawn(self, cam: CameraProcess) -> None:
        receive, send = self._ctx.Pipe(duplex=False)
        process = self._ctx.Process(
            target=sender_main, name=f"pslog-live-{cam.name}", daemon=True,
            args=(cam.name, cam.spec, self.options, self.address, self._t0, self._t0_wall,
                  cam.counters,
                  self._start, self._stop, send, os.getpid()))
        with _stop_signals_blocked():
            process.start()
        send.close()  # ours is the reading end only: EOF once the process is gone
        cam.process, cam.conn = process, receive
        cam.started_at = time.monotonic()
        again = f" (restart {cam.restarts})" if cam.restarts else ""
        self.say(f"{cam.name}: camera process {process.pid} started{again}: "
                 f"{cam.spec.describe()}")

    def start(self, stop_requested: Callable[[], bool] = lambda: False,
              epoch_ns: int | None = None) -> int:
        """Start every camera, wait until each has opened its source or failed (or the
        stop), then start the session clock. Returns ``t0_ns`` (``time.monotonic_ns()``
        at session time 0).

        ``epoch_ns``: the fuser's session start on the wall clock; session time 0 of the
        cameras is then the next whole second after it (so the cameras' shutter phases
        survive the fuser's ``t_capture_ns - epoch_ns``), up to a second from now."""
        for cam in self.cameras:
            self._spawn(cam)
        deadline = time.monotonic() + _OPEN_TIMEOUT_S
        while (any(c.state == "opening" for c in self.cameras) and not stop_requested()
               and time.monotonic() < deadline):
            self.poll(wait_s=0.05, restart=False)
        for cam in self.cameras:
            if cam.state == "opening" and not stop_requested():
                cam.state, cam.message = "failed", f"did not open within {_OPEN_TIMEOUT_S:g} s"
                self.say(f"error: {cam.name}: {cam.message}")
                self._end(cam)
        mono, wall = time.monotonic_ns(), time.time_ns()
        if epoch_ns is not None and wall >= epoch_ns:
            start_wall = epoch_ns + -(-(wall - epoch_ns) // NS) * NS
            mono, wall = mono + (start_wall - wall), start_wall
        self.t0_ns, self.t0_wall_ns = mono, wall
        self._t0.value, self._t0_wall.value = mono, wall
        self._start.set()
        self._started_at = time.monotonic()
        if stop_requested():
            return self.t0_ns  # stopped before the clock started: nothing to say
        running = sum(c.state == "running" for c in self.cameras)
        host, port = self.address
        self.say(f"session clock started: {running} camera process"
                 f"{'es' if running != 1 else ''} sending to udp://{host}:{port}")
        return self.t0_ns

    # ---- watch ----------------------------------------------------------------------------
    def poll(self, wait_s: float = 0.0, restart: bool | None = None) -> None:
        """Read the processes' messages, notice deaths, restart after the back-off."""
        restart = self.restart if restart is None else restart
        conns = [c.conn for c in self.cameras if c.conn is not None]
        if wait_s > 0 and conns:
            from multiprocessing.connection import wait
            wait(conns, timeout=wait_s)
        elif wait_s > 0:
            time.sleep(wait_s)
        now = time.monotonic()
        for cam in self.cameras:
            self._read(cam)
            p = cam.process
            if p is not None and cam.state in ("opening", "running") and not p.is_alive():
                p.join(0)
                self._read(cam)  # its last words
                self._died(cam, p.exitcode, now)
            if (cam.state == "waiting" and restart and now >= cam.restart_at
                    and not self._stop.is_set()):
                cam.restarts += 1
                cam.state = "opening"
                self._spawn(cam)

    def _read(self, cam: CameraProcess) -> None:
        while cam.conn is not None:
            try:
                if not cam.conn.poll():
                    return
                msg = cam.conn.recv()
            except (EOFError, OSError):
                cam.conn.close()
                cam.conn = None
                return
            kind = msg[0]
            if kind == "ready":
                cam.opened = True
                if cam.state == "opening":
                    cam.state = "running"
                    if cam.restarts:
                        self.say(f"{cam.name}: camera process {cam.pid} running again")
            elif kind in ("failed", "done"):
                cam.message = msg[1]

    def _died(self, cam: CameraProcess, exitcode: int | None, now: float) -> None:
        if self._stop.is_set():
            cam.state = "stopped"
            return
        if exitcode == EXIT_DONE:
            cam.state = "done"
            self.say(f"{cam.name}: camera process ended ({cam.message or 'end of source'})")
            return
        if exitcode in (EXIT_FAILED, EXIT_CRASHED):
            why = cam.message or "its source failed"
        elif exitcode is not None and exitcode < 0:
            try:
                why = f"killed by {signal.Signals(-exitcode).name}"
            except ValueError:
                why = f"killed by signal {-exitcode}"
        else:
            why = f"exit code {exitcode}"
        cam.message = why
        if not cam.opened and exitcode == EXIT_FAILED:
            cam.state = "failed"  # never opened: restarting would fail the same way
            self.say(f"error: {cam.name}: {why}")
            return
        if now - cam.started_at > _STABLE_S:
            cam.backoff_s = _BACKOFF_S[0]
        others = [c.name for c in self.cameras if c is not cam and c.state == "running"]
        keep = f"; {', '.join(others)} keep fusing" if others else ""
        if self.restart:
            cam.state = "waiting"
            cam.restart_at = now + cam.backoff_s
            self.say(f"warning: {cam.name}: camera process {cam.pid} died ({why}); "
                     f"restarting in {cam.backoff_s:g} s{keep}")
            cam.backoff_s = min(cam.backoff_s * 2, _BACKOFF_S[1])
        else:
            cam.state = "failed"
            self.say(f"warning: {cam.name}: camera process {cam.pid} died ({why}){keep}")

    @property
    def finished(self) -> bool:
        """Every camera ended for good (its source ended, or it never opened)."""
        return all(c.state in ("done", "failed", "stopped") for c in self.cameras)

    def starting(self, name: str) -> bool:
        """Whether camera ``name`` may still be starting (for a status line that has not
        heard it yet): its process opening its source, or the session clock not started or
        started less than :data:`_FIRST_FRAME_S` ago."""
        cam = next((c for c in self.cameras if c.name == name), None)
        if cam is None or cam.state in ("done", "failed", "stopped"):
            return False
        if cam.state == "opening" or self._started_at is None:
            return True
        return time.monotonic() - self._started_at < _FIRST_FRAME_S

    @property
    def opened_any(self) -> bool:
        return any(c.opened for c in self.cameras)

    @property
    def all_failed(self) -> bool:
        """Every camera failed to open its source (not: was stopped before it did)."""
        return all(c.state == "failed" and not c.opened for c in self.cameras)

    def pids(self) -> dict[str, int | None]:
        return {c.name: c.pid for c in self.cameras
                if c.process is not None and c.process.is_alive()}

    # ---- stop ---------------------------------------------------------------------------
    def stop(self) -> None:
        """Tell every process to stop, wait for them, kill the ones that do not end."""
        self._stop.set()
        self._start.set()  # a process still waiting for the start ends at once
        for cam in self.cameras:
            if cam.state == "opening":
                # not ready yet (importing, opening its source for seconds): it has sent
                # nothing, nothing is lost
                self._end(cam)
        deadline = time.monotonic() + _STOP_TIMEOUT_S
        for cam in self.cameras:
            p = cam.process
            if p is None or p.pid is None:
                continue
            p.join(max(deadline - time.monotonic(), 0.1))
            self._end(cam)
            self._read(cam)
            if cam.state in ("opening", "running", "waiting"):
                cam.state = "stopped"

    def _end(self, cam: CameraProcess) -> None:
        p = cam.process
        if p is not None and p.pid is not None and p.is_alive():
            p.kill()  # the processes ignore SIGTERM (the parent stops them)
            p.join(1.0)

    def summary(self) -> str:
        """One line per camera: frames sent, with a ball, skipped, restarts, state."""
        lines = []
        for cam in self.cameras:
            parts = [f"{cam.frames} frames sent", f"{cam.detected} with the ball"]
            if cam.skipped:
                parts.append(f"{cam.skipped} not sent (behind real time or no process)")
            if cam.send_errors:
                parts.append(f"{cam.send_errors} not sent")
            if cam.restarts:
                parts.append(f"{cam.restarts} restart{'s' if cam.restarts > 1 else ''}")
            state = cam.state + (f": {cam.message}" if cam.message else "")
            lines.append(f"  {cam.name}: {', '.join(parts)} ({state})")
        return "\n".join(lines)

    def run(self, stop: threading.Event, ready: threading.Event | None = None,
            *, when_finished: Callable[[], None] | None = None,
            started: Callable[[int], None] | None = None,
            epoch_ns: Callable[[], int | None] | None = None) -> None:
        """Thread body: wait until the fuser is ``ready``, start the cameras, watch them
        until ``stop``; ``when_finished`` is called once every camera has ended for good
        (the command then stops the fuser), ``started(t0_ns)`` when the clock starts;
        ``epoch_ns()`` gives the fuser's clock start once it is ready (see :meth:`start`)."""
        try:
            while ready is not None and not ready.wait(0.05):
                if stop.is_set():
                    return
            if stop.is_set():
                return
            t0 = self.start(stop.is_set, None if epoch_ns is None else epoch_ns())
            if started is not None:
                started(t0)
            duration_ns = self.options.duration_ns
            while not stop.is_set():
                self.poll(wait_s=0.1)
                # a live camera that stalls never reaches the duration by itself
                overdue = (duration_ns is not None
                           and time.monotonic_ns() - t0 > duration_ns + 2 * NS)
                if self.finished or overdue:
                    if when_finished is not None:
                        when_finished()
                    return
        finally:
            self.stop()


@dataclass(frozen=True)
class LoggedClockPosition:
    """The ball's position at a camera's LOGGED times, for a camera whose clock the rig
    corrects (``clock_offset``, ``clock_drift_ppm``, ``readout``, :mod:`pslog.timing`).

    A synthetic camera stamps frame ``k`` with its shutter time on the schedule (the logged
    time); what it sees is the ball at the TRUE time the fuser computes from that stamp,
    ``logged + clock_offset + drift * logged + readout * v / height``. The row ``v`` is the
    ball's own row in this camera, found by one fixed-point step (the ball moves a fraction
    of a pixel in that time). Picklable (module level), as camera processes need.

    The drift term is taken from the cameras' session start, which is a whole number of
    seconds ``k`` after the fuser's (:meth:`LiveCameras.start`): ``drift * k`` (50 ppm over
    5 s: 0.25 ms) is not rendered.
    """

    position: Callable
    camera: object

    def __call__(self, t_logged: np.ndarray) -> np.ndarray:
        from pslog.timing import true_times_s

        cam = self.camera
        t = np.asarray(t_logged, dtype=np.float64)
        no_row = np.zeros_like(t)
        first = true_times_s(t, no_row, cam.height, cam.clock_offset, cam.clock_drift_ppm,
                             0.0)
        if not cam.readout:
            return self.position(first)
        uv, _ = cam.project(np.atleast_2d(self.position(first)))
        v = np.nan_to_num(np.clip(uv[:, 1], 0.0, cam.height), nan=0.0).reshape(t.shape)
        return self.position(true_times_s(t, v, cam.height, cam.clock_offset,
                                          cam.clock_drift_ppm, cam.readout))


def synthetic_specs(rig, motion, duration_s: float, options=None) -> dict[str, object]:
    """Camera name -> a real-time rendering source of every camera of ``rig`` watching
    ``motion`` (:class:`recorders.sources.SyntheticSpec`); a camera whose clock the rig
    corrects sees the ball at the true times of its stamps (:class:`LoggedClockPosition`),
    so the fuser's corrections recover the motion."""
    from dataclasses import replace

    from .render import RenderOptions
    from .sources import SyntheticSpec

    options = options or RenderOptions()
    specs = {}
    for i, cam in enumerate(rig.cameras):
        seen = (replace(motion, position=LoggedClockPosition(motion.position, cam))
                if cam.has_clock_correction else motion)
        specs[cam.name] = SyntheticSpec(cam, i, seen, options, float(duration_s),
                                        realtime=True)
    return specs
