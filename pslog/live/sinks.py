"""Outputs of the live fuser: point datagrams over UDP, JSON lines, a recorded session.

Every output implements :class:`Sink`; :func:`pslog.live.server.serve` hands each point to
every sink as soon as it is made, then the accepted detections (for recording and viewers).
"""

from __future__ import annotations

import json
import math
import queue
import socket
import sys
import threading
import time
from datetime import UTC, datetime
from typing import IO, Protocol, runtime_checkable

import numpy as np

from ..errors import InputError, PslogError
from ..records import Track
from ..rig import Rig
from .fuser import LiveFuser, LivePoint
from .protocol import DetectionDatagram


@runtime_checkable
class Sink(Protocol):
    """Every output of the live fuser.

    ``emit`` and ``close`` are required; :func:`~pslog.live.server.serve` calls the others
    only when a sink has them:

    - ``start(fuser)``: once, before the first datagram (the fuser's ``epoch_ns``, rig...);
    - ``detections(d)``: each accepted (fused) :class:`DetectionDatagram`, after its points;
    - ``dropped(d, reason)``: each valid datagram the fuser did not fuse (``duplicate``,
      ``reordered``, ``late``, ...);
    - ``status(text, counters)``: each status period, the status line and the counters;
    - ``event(time_ns, text)``: a change worth keeping (a camera silent or back; the final
      counters), ``time_ns`` on the wall clock.

    A sink never blocks the fuser for long: a slow one drops (and counts) what it cannot
    keep up with.
    """

    def emit(self, points: list[LivePoint]) -> None: ...

    def close(self) -> None: ...


def parse_udp_address(text, what: str = "address") -> tuple[str, int]:
    """``udp://HOST:PORT`` (or ``HOST:PORT``, or a ``(host, port)`` tuple) -> ``(host, port)``;
    InputError naming ``what`` and the value otherwise (IPv6 hosts in brackets:
    ``udp://[::1]:10006``)."""
    if isinstance(text, tuple):
        host, port = text
        return _checked(str(host), port, text, what)
    raw = str(text)
    rest = raw[len("udp://"):] if raw.startswith("udp://") else raw
    if "://" in rest:
        raise InputError(f"bad {what} {raw!r}: only udp://HOST:PORT is supported")
    if rest.startswith("["):
        host, sep, port = rest[1:].partition("]:")
    else:
        host, sep, port = rest.rpartition(":")
    if not sep or not host:
        raise InputError(f"bad {what} {raw!r}: expected udp://HOST:PORT")
    return _checked(host, port, raw, what)


def _checked(host: str, port, raw, what: str) -> tuple[str, int]:
    try:
        port = int(port)
    except (TypeError, ValueError):
        raise InputError(f"bad {what} {raw!r}: port {port!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise InputError(f"bad {what} {raw!r}: port {port} is not in 0..65535")
    return host, port


def resolve_udp(address, what: str = "address") -> tuple:
    """The socket address of ``address`` (:func:`parse_udp_address`), resolved; InputError
    naming it when the host is unknown. Returns ``(family, sockaddr)``."""
    host, port = parse_udp_address(address, what)
    try:
        info = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
    except (socket.gaierror, UnicodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise InputError(f"bad {what} udp://{host}:{port}: {reason}") from None
    family, _, _, _, sockaddr = info[0]
    return family, sockaddr


class UdpSink:
    """Each point as a point datagram (:mod:`pslog.live.protocol`) to ``destination``
    (``udp://HOST:PORT``), sequence +1 per point. A refused send (nothing listening, ICMP
    unreachable) is counted in :attr:`errors`, never stops the fuser."""

    def __init__(self, destination) -> None:
        family, sockaddr = resolve_udp(destination, "--out address")
        self.destination = sockaddr
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self.sock.connect(sockaddr)  # sends without a per-datagram address lookup
        except OSError as exc:
            self.sock.close()
            raise PslogError(f"cannot send to udp://{sockaddr[0]}:{sockaddr[1]}: "
                             f"{exc.strerror or exc}") from None
        self.sequence = 0
        self.sent = 0
        self.errors = 0

    def emit(self, points: list[LivePoint]) -> None:
        send = self.sock.send
        for p in points:
            self.sequence += 1
            try:
                send(p.to_datagram(self.sequence))
                self.sent += 1
            except OSError:
                self.errors += 1

    def close(self) -> None:
        self.sock.close()


class JsonlSink:
    """One JSON object per point and line (:meth:`LivePoint.to_json`), flushed per line, to
    ``stream`` (default stdout). A reader that went away (broken pipe) ends the output, not
    the fuser (counted in :attr:`errors`)."""

    def __init__(self, stream: IO[str] | None = None) -> None:
        self.stream = stream if stream is not None else sys.stdout
        self.lines = 0
        self.errors = 0
        self._broken = False
        # json.dumps(obj, allow_nan=False), without making an encoder per call (dumps does
        # for any non-default option)
        self._encode = json.JSONEncoder(allow_nan=False).encode

    def emit(self, points: list[LivePoint]) -> None:
        if self._broken:
            self.errors += len(points)
            return
        try:
            encode = self._encode
            for p in points:
                self.stream.write(encode(p.to_json()) + "\n")
                self.stream.flush()
                self.lines += 1
        except (BrokenPipeError, ValueError, OSError):
            self._broken = True
            self.errors += 1

    def close(self) -> None:
        if not self._broken:
            try:
                self.stream.flush()
            except (BrokenPipeError, ValueError, OSError):
                pass


#: Topic of a datagram the fuser did not fuse, by reason and camera: a
#: ``pslog.DetectionFrame`` as on ``/camera/<camera>/detections``.
def dropped_topic(reason: str, camera: str) -> str:
    return f"/live/dropped/{reason}/{camera}"


class RecordSink:
    """The live session as an MCAP session file (docs/log-format.md), re-fusable offline.

    - every FUSED frame, as a ``pslog.DetectionFrame`` on ``/camera/<cam>/detections`` (so
      ``pslog fuse`` of the file fuses exactly what the live fuser fused);
    - every valid datagram NOT fused (duplicate, reordered, late, ...) on
      ``/live/dropped/<reason>/<cam>`` (kept, but out of the fused topics);
    - the emitted points as the track ``/tracks/<method>`` (with the method's quality);
    - events: the session clock's zero on the wall clock, cameras going silent or back, the
      final counters.

    Times are on the session clock: the wall clock minus the fuser's ``epoch_ns``. As
    ``pslog record`` writes a recording (:class:`~pslog.log.writer.SessionWriter`,
    ``on_error="keep"``): a new file is written in place and flushed every
    ``flush_interval_s`` (a killed fuser loses at most that, ``pslog recover`` salvages the
    rest); an existing one (``force``) is replaced only once the new one is complete
    (``<path>.partial``, then renamed). :meth:`close` (also on Ctrl-C, through
    :func:`~pslog.live.server.serve`) finishes the file.

    Parameters
    ----------
    path : the session file; refused if it exists unless ``force``
    rig : the live rig (with its clock corrections: they travel with the session)
    method : the live fusion method (the track's name; also the metadata ``live_method``);
        default: the fuser's (``start``)
    epoch_ns : the session clock's zero; default: the fuser's (``start``)
    """

    def __init__(self, path, rig: Rig, method: str | None = None, *, force: bool = False,
                 epoch_ns: int | None = None, flush_interval_s: float = 0.5,
                 timing: str = "custom", source: str = "pslog live",
                 points_every_s: float = 0.25) -> None:
        from ..log.writer import SessionWriter

        self.rig = rig
        self.method = method
        self.epoch_ns = epoch_ns
        self.writer = SessionWriter(path, rig, force=force, timing=timing, source=source,
                                    metadata={"live_method": method} if method else None,
                                    flush_interval_s=flush_interval_s, on_error="keep")
        self.path = self.writer.path
        self._index = {name: i for i, name in enumerate(rig.names)}
        self._points: list[LivePoint] = []
        self._points_every_ns = int(points_every_s * 1e9)
        self._last_points = time.monotonic_ns()
        self.frames = 0
        self.dropped_frames = 0
        self.points = 0
        self._announced = False
        # the file is written by a thread of its own: a disk that stalls (or a flush of the
        # writer holding its lock) never delays the fuser; a write error is raised by the
        # next call (serve then stops and closes everything) and by close
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._work, daemon=True,
                                        name=f"pslog-live-record-{self.path.name}")
        self._thread.start()
        if epoch_ns is not None and method is not None:
            self._put(self._announce)

    # ---- the writing thread ---------------------------------------------------------------
    def _work(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            if self._error is not None:
                continue  # the file failed: what comes after is not written
            try:
                job[0](*job[1:])
            except BaseException as exc:
                self._error = exc

    def _put(self, *job) -> None:
        if self._error is not None:
            raise self._error
        self._jobs.put(job)

    def _stop_thread(self) -> None:
        if self._thread.is_alive():
            self._jobs.put(None)
            self._thread.join()

    def _announce(self) -> None:
        if self._announced or self.epoch_ns is None:
            return
        self._announced = True
        stamp = datetime.fromtimestamp(self.epoch_ns / 1e9, UTC).isoformat(timespec="microseconds")
        self.writer.add_event(0, f"live session: session time 0 is wall clock {self.epoch_ns} ns "
                                 f"({stamp}); method {self.method}")

    def _write_frame(self, d: DetectionDatagram) -> None:
        t = self._session(d.t_capture_ns)
        order = np.argsort(-d.score, kind="stable")  # best first, as the fuser took them
        self.writer.add_frame(self._index[d.camera], d.frame_index, t, d.uv[order],
                              d.radius[order], d.score[order])
        self._maybe_write_points()

    def _write_dropped(self, d: DetectionDatagram, reason: str) -> None:
        from ..log import _schemas as S

        t = max(self._session(d.t_capture_ns), 0)  # MCAP has no time before the zero
        w = self.writer
        msg = S.DetectionFrame(time_ns=t, camera=d.camera, frame_index=d.frame_index,
                               u=d.uv[:, 0].tolist(), v=d.uv[:, 1].tolist(),
                               radius=d.radius.tolist(), score=d.score.tolist())
        topic = dropped_topic(reason, d.camera)
        # the writer's own channel registry and buffer, under its lock (as add_frame)
        with w._lock:
            w._check_open()
            w._queue(w._channel(topic, S.DetectionFrame), t, msg.SerializeToString(),
                     d.frame_index)
            w._count(topic)

    def _add_points(self, points: list[LivePoint]) -> None:
        self._points.extend(points)
        self._maybe_write_points()

    def _maybe_write_points(self, force: bool = False) -> None:
        now = time.monotonic_ns()
        if self._points and (force or now - self._last_points >= self._points_every_ns):
            self._write_points()
            self._last_points = now

    def _write_points(self) -> None:
        points, self._points = self._points, []
        points = [p for p in points if p.session_ns >= 0]
        if not points:
            return
        keys: list[str] = []
        for p in points:
            keys.extend(k for k in p.quality if k not in keys)
        nan = math.nan
        track = Track(self.method or points[0].method,
                      np.array([p.session_ns for p in points], np.int64),
                      np.array([p.position_world for p in points]),
                      np.array([p.camera_index for p in points], np.int32),
                      {k: np.array([p.quality.get(k, nan) for p in points]) for k in keys})
        self.writer.add_track(track)
        self.points += len(points)

    def _write_event(self, time_ns: int, text: str) -> None:
        self.writer.add_event(max(self._session(time_ns), 0), text)

    def _session(self, wall_ns: int) -> int:
        return int(wall_ns) - (self.epoch_ns or 0)  # set by start(), before any frame

    # ---- the Sink interface (the fuser's thread) ------------------------------------------
    def start(self, fuser: LiveFuser) -> None:
        if self.epoch_ns is None:
            self.epoch_ns = fuser.epoch_ns
        if self.method is None:
            self.method = fuser.method
        self._put(self._announce)

    def _started(self) -> None:
        if self.epoch_ns is None:
            raise PslogError("RecordSink: no session clock (call start(fuser) or give epoch_ns)")

    def detections(self, d: DetectionDatagram) -> None:
        self._started()
        self._put(self._write_frame, d)
        self.frames += 1

    def dropped(self, d: DetectionDatagram, reason: str) -> None:
        self._started()
        self._put(self._write_dropped, d, reason)
        self.dropped_frames += 1

    def emit(self, points: list[LivePoint]) -> None:
        self._put(self._add_points, list(points))

    def status(self, text: str, counters: dict) -> None:
        self._put(self._maybe_write_points)

    def event(self, time_ns: int, text: str) -> None:
        self._started()
        self._put(self._write_event, time_ns, text)

    def close(self) -> None:
        """Write what is queued, finish the file; raises the first write error."""
        if self._error is None:
            self._jobs.put((self._maybe_write_points, True))
        self._stop_thread()
        try:
            self.writer.close()
        except BaseException as exc:
            if self._error is None:
                self._error = exc
        if self._error is not None:
            raise self._error

    def abort(self) -> None:
        """Nothing was served (the fuser could not start): leave nothing behind — a new file
        is removed, an existing one (``force``) stays as it was."""
        self._stop_thread()
        in_place = self.writer.target == self.writer.path
        self.writer.abort()
        if in_place and not self.frames and not self.dropped_frames:
            self.writer.path.unlink(missing_ok=True)
