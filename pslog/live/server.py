"""The live fuser's UDP loop: receive detection datagrams, fuse, hand each point out at once.

:func:`serve` binds a UDP socket, feeds every datagram to a :class:`~pslog.live.fuser.
LiveFuser` the moment it is received, gives the points it makes to every sink before doing
anything else (no batching), then the accepted detections (recording, viewers), and writes a
status line each ``status_every_s`` (per camera live or silent, datagrams, points, drops).

Arrival times are the kernel's receive timestamps (``SO_TIMESTAMPNS``, wall clock) where the
system gives them, so the latency a point reports includes any time its datagram waited in
the socket's queue behind others; elsewhere the time ``recv`` returned. Latencies are measured
on the monotonic clock (:func:`arrival_monotonic`): a step or slew of the wall clock during
a run does not enter them.
"""

from __future__ import annotations

import contextlib
import gc
import select
import signal
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError, PslogError
from ..records import NS
from ..rig import Rig
from .fuser import _UNKNOWN_NAMES, CameraLiveState, LiveFuser, Rehearsal, warm_up
from .protocol import MAX_DETECTION_BYTES
from .sinks import Sink, resolve_udp

#: Linux: receive timestamps as a timespec (not exported by Python's socket module).
_SO_TIMESTAMPNS = 35
#: Linux's SO_RXQ_OVFL: each datagram comes with the socket's count of the datagrams its full
#: receive buffer dropped (a flood: the kernel discards them before the fuser can see them)
_SO_RXQ_OVFL = 40
#: Receive buffer asked of the kernel: bursts of thousands of datagrams wait there, not lost.
_RCVBUF = 8 << 20
#: Longest wait for a datagram before looking at the clock (status, duration, stop), seconds.
_POLL_S = 0.05
#: Latencies kept for the summary (the latest ones).
_KEEP_LATENCIES = 1 << 20


@dataclass
class LiveSummary:
    """What a :func:`serve` run did.

    Attributes
    ----------
    counters : the fuser's counters (:meth:`LiveFuser.counters`) at the end
    cameras : each camera's state at the end
    duration_s : seconds served
    interrupted : True when Ctrl-C (KeyboardInterrupt) ended it
    latency_ns : (n,) int64, each point's fusion latency, ns, on the monotonic clock: from
        its datagram's arrival (:func:`arrival_monotonic`) to the point handed to every sink
        (the last sink's ``emit`` returned); at most the last 2**20
    cpu_ns : (m,) int64, per datagram that made points: the CPU time the fuser's thread
        spent on it, from received to its points handed to every sink, ns (what the latency
        would be on an idle core; at most the last 2**20)
    wait_ns : (m,) int64, per datagram that made points: from its arrival to ``recv``
        returning it (queued behind others, or the thread waking up), monotonic ns
    handled_ns : (m,) int64, per datagram that made points: from ``recv`` returning it to
        its points handed to every sink, monotonic ns (its first point's latency is
        ``wait_ns + handled_ns``)
    epoch_ns : the session clock's zero (wall clock)
    address : the bound (host, port)
    rehearsals : datagrams of the rehearsal run (``serve``'s ``rehearse_s``)
    rehearsal_cpu_ns : the CPU time they took, ns
    rehearsal_overlaps : datagrams that arrived while a rehearsal ran (they waited for it)
    """

    counters: dict
    cameras: list
    duration_s: float
    interrupted: bool = False
    latency_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    cpu_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    wait_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    handled_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    epoch_ns: int = 0
    address: tuple = ("", 0)
    rehearsals: int = 0
    rehearsal_cpu_ns: int = 0
    rehearsal_overlaps: int = 0


def bind_udp(listen, *, what: str = "--listen address") -> socket.socket:
    """A UDP socket bound to ``listen`` (``udp://HOST:PORT``); a PslogError naming the
    address and the OS's reason when it cannot be bound (port in use, address not local)."""
    family, sockaddr = resolve_udp(listen, what)
    sock = socket.socket(family, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RCVBUF)
        sock.bind(sockaddr)
    except OSError as exc:
        sock.close()
        raise PslogError(f"cannot listen on udp://{sockaddr[0]}:{sockaddr[1]}: "
                         f"{exc.strerror or exc}") from None
    return sock


def format_status(fuser: LiveFuser, cameras: list[CameraLiveState], now_ns: int,
                  started_ns: int, starting: Callable[[str], bool] | None = None) -> str:
    """One status line: time served; per camera live or silent (for how long), its datagrams
    (``dg``) and the points of its shutters (``pt``); all datagrams and points; the non-zero
    drop counters. A camera never heard is ``starting`` while ``starting(name)`` says it may
    still be (its process starting up), else ``silent (never heard)``. ``now_ns`` and
    ``started_ns``: on the fuser's waits' clock (:attr:`LiveFuser.monotonic`, the cameras'
    ``last_seen_ns``)."""
    c = fuser.counters()
    parts = [f"live {(now_ns - started_ns) / NS:6.1f} s"]
    for cam in cameras:
        if cam.last_seen_ns is None:
            still = starting is not None and starting(cam.name)
            parts.append(f"{cam.name} " + ("starting" if still else "silent (never heard)"))
            continue
        state = ("live" if not cam.silent else
                 f"SILENT {(now_ns - cam.last_seen_ns) / NS:.1f} s")
        parts.append(f"{cam.name} {state} {cam.datagrams} dg {cam.points} pt")
    parts.append(f"datagrams {c['received']} points {c['points']}")
    drops = [f"{k} {c[k]}" for k in ("duplicate", "reordered", "late", "future", "truncated",
                                     "oversize", "foreign", "version", "malformed",
                                     "unknown_camera", "fusion_error", "lost",
                                     "overflow") if c[k]]
    parts.append("drops: " + (", ".join(drops) if drops else "none"))
    return " | ".join(parts)


def _overflow(ancdata) -> int | None:
    """The socket's count of datagrams dropped for want of room (``SO_RXQ_OVFL``), from a
    datagram's ancillary data (None: not there, nothing dropped yet)."""
    for level, kind, raw in ancdata:
        if level == socket.SOL_SOCKET and kind == _SO_RXQ_OVFL and len(raw) >= 4:
            return int(struct.unpack_from("@I", raw)[0])
    return None


def _arrival(ancdata, default: int) -> int:
    """A datagram's kernel arrival time (wall clock, ns) from its ancillary data, else
    ``default``."""
    for level, kind, raw in ancdata:
        if level == socket.SOL_SOCKET and kind == _SO_TIMESTAMPNS and len(raw) >= 16:
            sec, nsec = struct.unpack_from("@qq", raw)
            return sec * NS + nsec
    return default


def arrival_monotonic(arrival_ns: int, now_ns: int, now_mono_ns: int, floor_ns: int) -> int:
    """A datagram's arrival on the monotonic clock, ns.

    ``arrival_ns`` is the kernel's receive stamp (wall clock); ``now_ns`` and ``now_mono_ns``
    the wall and monotonic clocks read together when ``recv`` returned it. The time it
    waited, ``now_ns - arrival_ns``, is an interval of the wall clock (microseconds, unless
    it queued), so a slew of the wall clock changes it by its rate only (0.5 % of it), and a
    step does not enter unless it came while that datagram waited: that wait is then bounded
    to what it can have been, not negative and not before ``floor_ns`` (monotonic: the
    previous datagram's arrival, a socket's queue being in arrival order, or the start of
    the run). Latencies measured from it on the monotonic clock never mix two clocks.
    """
    return now_mono_ns - min(max(now_ns - arrival_ns, 0), max(now_mono_ns - floor_ns, 0))


def _readable(sock: socket.socket, wait_s: float) -> bool:
    """Whether a datagram is waiting in ``sock`` or comes within ``wait_s`` seconds."""
    wait_s = max(0.0, wait_s)
    if sock.fileno() < 1024:  # (select's range)
        return bool(select.select((sock,), (), (), wait_s)[0])
    poller = select.poll()
    poller.register(sock, select.POLLIN)
    return bool(poller.poll(int(wait_s * 1000)))


def _collect_due(sock: socket.socket) -> None:
    """The garbage collection Python's own trigger would have run by now, if any: when more
    container objects were made than ``gc.get_threshold()[0]`` since the latest one, the
    oldest generation whose count is over its threshold (as CPython's ``collect_generations``,
    without its rule that puts off a full collection until the objects that survived the
    younger ones are a quarter of the old generation's). :func:`serve` runs it after each
    datagram's points are out, with automatic collections off: at 3 x 30 fps a collection
    of the youngest generation (0.1-0.2 ms on a busy core) came inside 0.6 % of the
    datagrams, its whole length added to their latency (docs/live.md). Put off while a
    datagram is already waiting in ``sock``, up to 4 times the threshold (a fuser that never
    catches up still collects)."""
    c0, c1, c2 = gc.get_count()
    t0, t1, t2 = gc.get_threshold()
    if t0 <= 0 or c0 <= t0:  # (threshold 0: collection off, as gc.set_threshold(0) means)
        return
    if c0 <= 4 * t0 and _readable(sock, 0.0):
        return
    gc.collect(2 if c2 > t2 else 1 if c1 > t1 else 0)


def _linux_option(sock: socket.socket, option: int) -> bool:
    """Turn a Linux socket option (``SOL_SOCKET``) on; False where it cannot be (another
    system, or a kernel without it): the receive timestamps and the overflow count."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, option, 1)
    except OSError:
        return False
    return True


def serve(rig: Rig, listen, sinks: Sequence[Sink], *, method: str = "filter",
          duration_s: float | None = None, stop: threading.Event | None = None,
          status_every_s: float = 1.0, silent_after_s: float = 1.0,
          ready: threading.Event | None = None, late_s: float = 0.1, options=None,
          candidates: bool = True, epoch_ns: int | None = None,
          status_stream="stderr", sock: socket.socket | None = None,
          hold_s: float = 0.0, starting: Callable[[str], bool] | None = None,
          rehearse_s: float | None = 0.0005) -> LiveSummary:
    """Run the live fuser on ``listen`` until ``stop`` is set, ``duration_s`` passes or
    Ctrl-C.

    Parameters
    ----------
    rig : Rig, the cameras the datagrams name, with their clock corrections
    listen : ``udp://HOST:PORT`` (port 0: any free port; :attr:`LiveSummary.address`)
    sinks : the outputs (:class:`~pslog.live.sinks.Sink`), each given every point at once
    method : a causal fusion method (``filter``, ``typeA``, ...)
    duration_s : stop after this many seconds (None: until ``stop`` or Ctrl-C)
    stop : threading.Event ending the run when set (from another thread, a signal handler)
    status_every_s : period of the status line (``status_stream``, and each sink's
        ``status``), seconds
    silent_after_s : a camera without a datagram this long is reported silent, seconds
    ready : set once the socket is bound (start senders after it); its ``address``
        attribute is set to the bound ``(host, port)`` first, its ``epoch_ns`` to the
        session clock's zero (wall clock ns)
    late_s, options, candidates, epoch_ns, hold_s : as :class:`~pslog.live.fuser.LiveFuser`
        (``hold_s`` > 0: frames wait for the other cameras' to be fused in capture order)
    status_stream : where status lines go: a text stream, ``"stderr"`` (``sys.stderr`` when
        called) or None (nowhere)
    sock : an already bound UDP socket to use instead of binding ``listen``
    starting : camera name -> whether it may still be starting up (the status line then says
        ``starting`` rather than ``silent (never heard)``); None: never
    rehearse_s : while datagrams come at least 4 ms apart (3 x 30 fps: 11 ms), one datagram
        of a simulated rally goes through a fuser of its own
        (:class:`~pslog.live.fuser.Rehearsal`), to end this long before the next datagram
        can come (seconds): the method's code back in the core's caches, so that the real
        datagram costs nearer what it costs back to back, at the price of one rehearsal per
        datagram (none when a datagram is already waiting); None: none

    Raises
    ------
    PslogError (one line) when the address is malformed or cannot be bound (in use, not
    local) or the method cannot stream; the sinks are then aborted (``abort``, else
    ``close``): nothing was served, nothing is left behind. A sink's error (a full disk)
    stops the run and is raised after every sink is closed.

    Returns
    -------
    LiveSummary. At the end the fuser is flushed (its last points go to the sinks) and every
    sink is closed, also on Ctrl-C or an error; the first sink error is raised after all are
    closed.
    """
    try:
        if rehearse_s is not None and not 0 <= rehearse_s <= 1:
            raise InputError(f"rehearsal lead must be in [0, 1] seconds, got {rehearse_s!r}")
        if not status_every_s > 0:
            raise InputError(f"status period must be > 0 seconds, got {status_every_s!r}")
        if duration_s is not None and not duration_s >= 0:
            raise InputError(f"duration must be >= 0 seconds, got {duration_s!r}")
        # (its waits, the hold and a camera's silence, on the monotonic clock: each
        # datagram's arrival given on it, arrival_monotonic)
        fuser = LiveFuser(rig, method, late_s=late_s, options=options, candidates=candidates,
                          epoch_ns=epoch_ns, silent_after_s=silent_after_s, hold_s=hold_s,
                          monotonic=time.monotonic_ns)
        # the method's kernels loaded now, not behind the first datagrams (fuser.warm_up)
        warm_up(method, candidates=fuser.candidates, options=fuser.options)
        rehearsal = None if rehearse_s is None else Rehearsal(fuser, rehearse_s)
        if sock is None:
            sock = bind_udp(listen)
    except BaseException:
        # nothing was served: the sinks leave nothing behind (a new session file is removed)
        for s in sinks:
            with contextlib.suppress(Exception):
                (getattr(s, "abort", None) or s.close)()
        raise
    address = sock.getsockname()[:2]
    timestamps = _linux_option(sock, _SO_TIMESTAMPNS)
    overflow = _linux_option(sock, _SO_RXQ_OVFL)
    stop = stop or threading.Event()
    if status_stream == "stderr":
        status_stream = sys.stderr
    emitters = [s.emit for s in sinks]
    on_detections = [s.detections for s in sinks if hasattr(s, "detections")]
    on_dropped = [s.dropped for s in sinks if hasattr(s, "dropped")]
    on_status = [s.status for s in sinks if hasattr(s, "status")]
    on_event = [s.event for s in sinks if hasattr(s, "event")]
    fuser.keep = bool(on_detections or on_dropped)
    latencies = np.zeros(_KEEP_LATENCIES, np.int64)
    n_lat = 0
    cpu = np.zeros(_KEEP_LATENCIES, np.int64)
    waits = np.zeros(_KEEP_LATENCIES, np.int64)
    handled = np.zeros(_KEEP_LATENCIES, np.int64)
    n_cpu = 0
    thread_time = time.thread_time_ns
    mono = time.monotonic_ns
    interrupted = False
    clock = time.time_ns
    # (latencies on the monotonic clock: the earliest a datagram read in this run can have
    # arrived, then each one's arrival; arrival_monotonic)
    started_mono = floor = mono()
    # the run's length and the status period on the monotonic clock too: a step of the wall
    # clock neither ends a run early nor holds it (or its status lines) for as long
    deadline = None if duration_s is None else started_mono + int(duration_s * NS)
    period = int(status_every_s * NS)
    next_status = started_mono + period
    was_silent = {c.name: True for c in fuser.cameras(started_mono)}
    heard: set[str] = set()
    said_unknown = 0  # (fuser.unknown_cameras said so far)
    error: BaseException | None = None
    rehearsal_cpu = overlaps = 0
    rehearsed_until = 0  # (monotonic end of the latest rehearsal)

    def say(text: str) -> None:
        if status_stream is not None:
            with contextlib.suppress(OSError, ValueError):
                print(text, file=status_stream, flush=True)

    def hand_out(points) -> int:
        """Every sink given ``points``; their latencies noted (monotonic: from the arrival
        of the datagram that made each point, its ``arrival_mono_ns``: the fuser's, as
        :func:`arrival_monotonic` gave it, a held frame's too); returns when (monotonic)."""
        nonlocal n_lat
        for emit in emitters:
            emit(points)
        out = mono()
        for p in points:
            latencies[n_lat % _KEEP_LATENCIES] = out - p.arrival_mono_ns
            n_lat += 1
        return out

    def events(now: int, now_mono: int) -> None:
        nonlocal said_unknown
        while said_unknown < len(fuser.unknown_cameras):  # (once each: a misnamed camera)
            name = fuser.unknown_cameras[said_unknown]
            said_unknown += 1
            text = (f"camera {name!r} is not in the rig (it has {', '.join(rig.names)}):"
                    f" its datagrams are dropped (unknown_camera)"
                    + ("; further unknown names are counted, not named"
                       if said_unknown == _UNKNOWN_NAMES else ""))
            say(text)
            for ev in on_event:
                ev(now, text)
        for cam in fuser.cameras(now_mono):
            if cam.silent != was_silent[cam.name]:
                was_silent[cam.name] = cam.silent
                if cam.silent:
                    text = f"camera {cam.name} silent: no datagram for {silent_after_s:g} s"
                elif cam.name in heard:
                    text = f"camera {cam.name} live again"
                else:
                    text = f"camera {cam.name} live"
                    heard.add(cam.name)
                say(text)
                for ev in on_event:
                    ev(now, text)

    def pass_on() -> None:
        accepted, dropped = fuser.take()
        for d in accepted:
            for f in on_detections:
                f(d)
        for d, reason in dropped:
            for f in on_dropped:
                f(d, reason)

    def handle(data: bytes, ancdata, now: int, now_mono: int) -> None:
        nonlocal n_cpu, overlaps, floor
        cpu0 = thread_time()
        arrival = _arrival(ancdata, now)
        if len(ancdata) > timestamps:  # (the kernel adds the count once it dropped any)
            dropped = _overflow(ancdata)
            if dropped is not None:
                fuser.socket_overflow(dropped)
        floor = arrival_mono = arrival_monotonic(arrival, now, now_mono, floor)
        overlaps += arrival_mono < rehearsed_until
        points = fuser.feed(data, arrival, arrival_mono)
        if points:  # the points first: recording and viewers after
            out = hand_out(points)
            i = n_cpu % _KEEP_LATENCIES
            cpu[i] = thread_time() - cpu0
            waits[i] = now_mono - arrival_mono
            handled[i] = out - now_mono
            n_cpu += 1
        if fuser.keep:
            pass_on()
        if rehearsal is not None:  # (the next one's rehearsal planned: after the points)
            rehearsal.plan(fuser, now_mono)

    bufsize = max(MAX_DETECTION_BYTES + 1, 65536)  # larger ones are seen whole: oversize
    anc = (socket.CMSG_SPACE(16) if timestamps else 0) + (socket.CMSG_SPACE(4) if overflow
                                                           else 0)
    # Ctrl-C ends the run between two datagrams (not inside one: each one received is
    # fused): in the main thread with Python's own SIGINT handler, it sets ``stop`` instead
    restore_sigint = None
    if (threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
        def on_sigint(signum, frame) -> None:
            nonlocal interrupted
            interrupted = True
            stop.set()

        restore_sigint = signal.signal(signal.SIGINT, on_sigint)
    # everything loaded so far (modules, the rig, numpy) is moved out of the collector's
    # reach: a full collection then walks only what the run makes, not a pause of tens of ms
    gc.collect()
    gc.freeze()
    # and the collector runs between datagrams, never inside one (_collect_due): its
    # automatic runs (allocation-triggered) are off until the end; the user's setting back
    collecting = gc.isenabled()
    gc.disable()
    try:
        for s in sinks:
            if hasattr(s, "start"):
                s.start(fuser)
        if ready is not None:
            # the caller's Event carries where the server listens and its clock's zero
            ready.address = address  # type: ignore[attr-defined]
            ready.epoch_ns = fuser.epoch_ns  # type: ignore[attr-defined]
            ready.set()
        # with a hold, look at the clock often enough to release frames about on time
        poll_s = min(_POLL_S, hold_s / 4) if fuser.hold_ns else _POLL_S
        sock.settimeout(poll_s)
        recv = sock.recvmsg
        while not stop.is_set():
            if rehearsal is not None and rehearsal.due is not None:
                due = rehearsal.due  # (monotonic: Rehearsal.plan)
                wait = (due - mono()) / NS
                # a rehearsal due before the next look at the clock: a datagram awaited until
                # then (to the microsecond: a socket's own timeout counts whole ms), else it,
                # unless this thread woke up too late for it (by more than its lead: it
                # would end after the next datagram can come)
                if wait < poll_s:
                    rehearsal.due = None
                    if not _readable(sock, wait) and mono() - due <= rehearsal.lead_ns:
                        cpu0 = thread_time()
                        rehearsal.step()
                        rehearsed_until = mono()
                        rehearsal_cpu += thread_time() - cpu0
            try:
                data, ancdata, _, _ = recv(bufsize, anc)
            except TimeoutError:
                data = None
            now, now_mono = clock(), mono()  # (read together: arrival_monotonic)
            if data is not None:
                handle(data, ancdata, now, now_mono)
            if fuser.hold_ns and data is None:
                # nothing more in the socket: frames whose wait is over by the clock (while
                # datagrams come, each one's arrival time releases them: a fuser running
                # behind reads what is queued before it gives up waiting for it)
                points = fuser.poll(now_mono)
                if points:
                    hand_out(points)
                if fuser.keep:
                    pass_on()
            if collecting:  # (after the points, held ones too: in the wait for the next datagram)
                _collect_due(sock)
            # a camera silent or back: looked at between datagrams while one is silent
            if (data is None or now_mono >= next_status
                    or was_silent.get(fuser.last_camera, False)):
                events(now, now_mono)
            if now_mono >= next_status:
                next_status = now_mono + period
                # (time served and silences on the monotonic clock)
                text = format_status(fuser, fuser.cameras(now_mono), now_mono, started_mono,
                                     starting)
                say(text)
                counters = fuser.counters()
                for f in on_status:
                    f(text, counters)
            if deadline is not None and now_mono >= deadline:
                break
    except KeyboardInterrupt:
        interrupted = True
    except BaseException as exc:  # closed below, raised after
        error = exc
    try:
        # what had arrived before the stop (or Ctrl-C) is fused too: nothing received is
        # left unread
        if error is None:
            sock.setblocking(False)
            # only what arrived before the stop: a sender still sending faster than the
            # fuser would otherwise keep it draining forever (at most a full receive
            # buffer's worth where datagrams carry no arrival time)
            stopped = clock()
            left = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF) // 32 + 1
            while left > 0:
                left -= 1
                try:
                    data, ancdata, _, _ = sock.recvmsg(bufsize, anc)
                except (BlockingIOError, InterruptedError):
                    break
                now, now_mono = clock(), mono()
                if _arrival(ancdata, now) > stopped:
                    break
                handle(data, ancdata, now, now_mono)
    except KeyboardInterrupt:
        interrupted = True
    except BaseException as exc:  # closed below, raised after
        error = exc
    finally:
        # the last points, then every sink closed whatever happened
        try:
            points = fuser.flush()
            if points:
                hand_out(points)
            if fuser.keep:
                pass_on()
        except BaseException as exc:
            if error is None and not isinstance(exc, KeyboardInterrupt):
                error = exc
        gc.unfreeze()
        if collecting:
            gc.enable()
        if restore_sigint is not None:
            signal.signal(signal.SIGINT, restore_sigint)
        end = clock()
        counters = fuser.counters()
        end_mono = mono()
        final = format_status(fuser, fuser.cameras(end_mono), end_mono, started_mono,
                              starting)
        for ev in on_event:
            with contextlib.suppress(Exception):
                ev(end, "live fuser stopped: " + ", ".join(f"{k} {v}"
                                                         for k, v in counters.items()))
        for s in sinks:
            try:
                s.close()
            except BaseException as exc:
                if error is None:
                    error = exc
        sock.close()
    if error is not None:
        if isinstance(error, KeyboardInterrupt):
            interrupted = True
        else:
            raise error
    say(final)
    lat = latencies[:min(n_lat, _KEEP_LATENCIES)].copy()
    kept = min(n_cpu, _KEEP_LATENCIES)
    return LiveSummary(counters=counters, cameras=fuser.cameras(end_mono),
                       duration_s=(end_mono - started_mono) / NS, interrupted=interrupted,
                       latency_ns=lat, cpu_ns=cpu[:kept].copy(),
                       wait_ns=waits[:kept].copy(), handled_ns=handled[:kept].copy(),
                       epoch_ns=fuser.epoch_ns,
                       address=tuple(address),
                       rehearsals=0 if rehearsal is None else rehearsal.steps,
                       rehearsal_cpu_ns=rehearsal_cpu, rehearsal_overlaps=overlaps)
