"""Live latencies on one clock: the kernel's receive stamps are wall clock, and a step of the
wall clock between a datagram's arrival and its point (an NTP step, a VM's clock set again
after a pause) must not become a "latency" of seconds (session 19 read 3-68 s in
``benchmarks/bench_live.py``). Over real UDP, with a fuser thread whose wall clock is 60 s
off the kernel's stamps: what every datagram queued across such a step sees."""

from __future__ import annotations

import io
import socket
import struct
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

from pslog.live.protocol import encode_detections
from pslog.live.server import arrival_monotonic
from pslog.records import NS

ROOT = Path(__file__).resolve().parent.parent


def test_arrival_on_the_monotonic_clock():
    """The wait (wall now - stamp) moved onto the monotonic clock read with it; a wait the
    wall clock makes negative is none, one longer than possible (before the floor: the
    previous datagram's arrival, or the run's start) stops at the floor."""
    mono, wall = 5_000_000_000, 1_764_470_000_000_000_000
    # queued 300 µs: arrived 300 µs before now on the monotonic clock
    assert arrival_monotonic(wall - 300_000, wall, mono, mono - NS) == mono - 300_000
    # a wall clock stepped 60 s forward while it waited: at most since the floor (2 ms)
    assert arrival_monotonic(wall - 60 * NS, wall, mono, mono - 2_000_000) == mono - 2_000_000
    # stepped back: it cannot have arrived after now
    assert arrival_monotonic(wall + 60 * NS, wall, mono, mono - 2_000_000) == mono
    # a floor after now (never expected) gives now, not a time to come
    assert arrival_monotonic(wall - 300_000, wall, mono, mono + 1) == mono


@pytest.mark.parametrize("step_s", [60.0, -60.0])
def test_bench_latency_is_not_moved_by_a_wall_clock_step(monkeypatch, step_s):
    """bench_live's run (a sender process, serve in a thread, a robot process, real UDP
    datagrams) with the fuser thread's wall clock ``step_s`` off the kernel's receive stamps
    (the main thread's and the processes' as they are): every point's fusion latency is
    between 0 and the run's own length on the monotonic clock, not 60 s nor negative (as
    it was when the bench read time.time_ns() against the kernel's stamps)."""
    sys.path.insert(0, str(ROOT))
    from benchmarks import bench_live

    rig, frames = bench_live.session(30.0, 0.4)
    real, main = time.time_ns, threading.main_thread()

    def stepped() -> int:  # (the sender and robot are forked from the main thread: real)
        return real() + (int(step_s * NS) if threading.current_thread() is not main else 0)

    monkeypatch.setattr(time, "time_ns", stepped)
    t0 = time.monotonic_ns()
    r = bench_live.run(rig, frames, "typeA", False, rehearse_s=None)
    took_ms = (time.monotonic_ns() - t0) / 1e6
    assert r["lost"] == 0 and r["points"] > 20
    assert 0 <= r["fusion_min"] <= r["fusion_p99"] <= r["fusion_max"] <= took_ms
    assert 0 <= r["wait_med"] <= r["wait_p99"] <= took_ms


def test_serve_runs_its_duration_and_status_period_on_the_monotonic_clock(monkeypatch):
    """serve(duration_s=0.5, status every 0.1 s) whose thread's wall clock steps 60 s back
    once it is ready: it still ends after its 0.5 s and writes its status lines meanwhile
    (on the wall clock it ran 60.5 s and wrote none until then)."""
    import io

    from pslog.live.server import serve
    from pslog.rig import apply_timing, builtin_rig

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    ready, stop = threading.Event(), threading.Event()
    real, main = time.time_ns, threading.main_thread()

    def stepped() -> int:
        back = ready.is_set() and threading.current_thread() is not main
        return real() - (60 * NS if back else 0)

    monkeypatch.setattr(time, "time_ns", stepped)
    status, result = io.StringIO(), {}

    def run() -> None:
        result["summary"] = serve(rig, "udp://127.0.0.1:0", [], method="typeA", stop=stop,
                                  ready=ready, status_stream=status, status_every_s=0.1,
                                  duration_s=0.5, rehearse_s=None)

    server = threading.Thread(target=run)
    server.start()
    assert ready.wait(300)
    server.join(30)  # (a guard: 60 times the run's length)
    held = server.is_alive()
    stop.set()
    server.join()
    assert not held
    lines = status.getvalue().splitlines()
    assert len(lines) >= 2 and lines[-1].startswith("live ")  # (the last: the final one)
    assert 0.5 <= result["summary"].duration_s


class _SteppedSocket:
    """A bound UDP socket as ``serve`` sees it through a wall clock that steps by
    ``step_ns``: the kernel's receive stamp (SO_TIMESTAMPNS, wall clock) of every datagram
    received after the step moved by it, as the kernel's own stamps would be. The step comes
    at the real wall-clock instant ``at`` (set by the test), or, with ``at_datagram`` k, while
    the k-th datagram (from 0) waited in the socket: its own stamp is from before the step,
    every later one's after (:attr:`stepped` says when, for the thread's clock)."""

    def __init__(self, sock, step_ns: int, at_datagram: int | None = None) -> None:
        self.sock, self.step_ns, self.at_datagram = sock, step_ns, at_datagram
        self.at: int | None = None  # (real wall ns of the step, when set by the test)
        self.stepped = False
        self.received = 0
        self._real = time.time_ns

    def recvmsg(self, *args):
        from pslog.live.server import _SO_TIMESTAMPNS

        data, ancdata, flags, address = self.sock.recvmsg(*args)
        k, self.received = self.received, self.received + 1
        out = []
        for level, kind, raw in ancdata:
            if kind == _SO_TIMESTAMPNS and len(raw) >= 16:
                sec, nsec = struct.unpack_from("@qq", raw)
                stamp = sec * NS + nsec
                if self.stepped or (self.at is not None and stamp >= self.at):
                    stamp += self.step_ns
                raw = struct.pack("@qq", *divmod(stamp, NS)) + raw[16:]
            out.append((level, kind, raw))
        if k == self.at_datagram:
            self.stepped = True  # (after its stamp: it waited across the step)
        return data, out, flags, address

    def __getattr__(self, name):
        return getattr(self.sock, name)


def _step_thread_clock(monkeypatch, sock: _SteppedSocket, server_thread) -> None:
    """time.time_ns of the server's thread stepped with ``sock`` (the others' real)."""
    real = time.time_ns

    def stepped() -> int:
        now = real()
        if threading.current_thread() is server_thread() and (
                sock.stepped or (sock.at is not None and now >= sock.at)):
            return now + sock.step_ns
        return now

    monkeypatch.setattr(time, "time_ns", stepped)


@contextmanager
def _serving(monkeypatch, sock: _SteppedSocket, rig, sinks, stop: threading.Event, **options):
    """``serve(rig, "", sinks, sock=sock, stop=stop, **options)`` on a thread whose wall
    clock steps with ``sock`` (:func:`_step_thread_clock`); yields ``(ready, result)`` once
    it is ready (``ready.address``: where to send; ``result["summary"]``: its summary once
    it ended), then stops it and waits for it."""
    from pslog.live.server import serve

    ready, result = threading.Event(), {}

    def run() -> None:
        result["summary"] = serve(rig, "", sinks, stop=stop, ready=ready, sock=sock, **options)

    server = threading.Thread(target=run)
    _step_thread_clock(monkeypatch, sock, lambda: server)
    server.start()
    try:
        assert ready.wait(300)
        yield ready, result
    finally:
        stop.set()
        server.join()


def _wait_until(predicate, what: str, timeout_s: float = 60.0) -> None:
    deadline = time.monotonic() + timeout_s  # (a hang guard, not a timing)
    while not predicate():
        assert time.monotonic() < deadline, f"never {what}"
        time.sleep(0.005)


class _Collector:
    """A sink noting each point and whether the run had been told to stop when it came."""

    def __init__(self, stop: threading.Event) -> None:
        self.stop, self.fuser = stop, None
        self.points: list = []  # (LivePoint, the run told to stop before it)
        self.events: list[str] = []

    def start(self, fuser) -> None:
        self.fuser = fuser

    def emit(self, points) -> None:
        self.points += [(p, self.stop.is_set()) for p in points]

    def event(self, t, text) -> None:
        self.events.append(text)

    def close(self) -> None:
        pass


def test_hold_and_silence_are_not_fooled_by_a_wall_clock_stepped_back(monkeypatch):
    """serve with a hold over real UDP: cam3 stops sending, then the fuser host's wall
    clock (its thread's clock and the kernel's receive stamps) steps 60 s back, then cam1
    and cam2 send the next 0.3 s of frames, 0.4 s after cam3's last (its silence is 0.3 s).
    cam3 is silent and not waited for: the frames after it are fused while the run goes on,
    and the run ends with cam3 silent. On the wall clock cam3's last datagram came 60 s
    after the others: it looked live, every later frame waited for it (the 10-s hold) and
    came out only when the run was stopped, cam3 still live."""
    from pslog.live.server import bind_udp
    from tests._live import frames, rally_session

    rig, det = rally_session(0.6, spurious_rate=0.0, miss_rate=0.0)
    epoch = time.time_ns() - 120 * NS  # (the frames' capture times: in the past)
    cut = epoch + int(0.3 * NS)
    sent = [(d, encode_detections(d))
            for d in frames(det, rig, epoch) if d.camera != "cam3" or d.t_capture_ns < cut]
    before = [b for d, b in sent if d.t_capture_ns < cut]
    after = [b for d, b in sent if d.t_capture_ns >= cut]
    sock = _SteppedSocket(bind_udp("udp://127.0.0.1:0"), -60 * NS)
    stop = threading.Event()
    sink, status = _Collector(stop), io.StringIO()
    with _serving(monkeypatch, sock, rig, [sink], stop, method="typeA", candidates=False,
                  hold_s=10.0, silent_after_s=0.3, rehearse_s=None, epoch_ns=epoch,
                  status_stream=status, status_every_s=60.0) as (ready, result):
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for b in before:
            tx.sendto(b, ready.address)  # type: ignore[attr-defined]
        _wait_until(lambda: sink.fuser.counters()["received"] == len(before), "received")
        sock.at = time.time_ns()  # the step: every later stamp and clock reading 60 s back
        time.sleep(0.4)  # (cam3's silence: 0.3 s)
        for b in after:
            tx.sendto(b, ready.address)  # type: ignore[attr-defined]
        tx.close()
        _wait_until(lambda: sink.fuser.counters()["received"] == len(sent), "received")
    summary = result["summary"]
    assert summary.counters["fused"] == len(sent)
    later = [p for p, stopped in sink.points if p.t_capture_ns >= cut]
    on_time = [p for p, stopped in sink.points if p.t_capture_ns >= cut and not stopped]
    # every frame after cam3's last but the last one or two (waiting for the other live
    # camera's next frame when the run stopped)
    assert len(later) >= len(after) - 2 and len(on_time) >= len(later) - 2
    # cam3 silent at the end, its last datagram (monotonic) a step's sleep before the
    # others' (whether cam1 and cam2 still count as live at the end depends on how long
    # the shutdown took after their last datagram: not asserted)
    cam1, cam2, cam3 = summary.cameras
    assert cam3.silent
    assert cam3.last_seen_ns < min(cam1.last_seen_ns, cam2.last_seen_ns) - 0.3e9
    assert "cam3 SILENT" in status.getvalue().splitlines()[-1]


def test_a_datagram_queued_across_a_clock_step_is_bounded_by_the_previous_arrival(
        monkeypatch):
    """serve over real UDP, no datagram for 1 s, then a burst of datagrams; the wall clock
    steps 60 s forward while the 21st of them waits in the socket (its kernel stamp from
    before, every later one's and the thread's clock after). That datagram's wait cannot
    be told from the two clocks (60 s on the wall clock): it is bounded by the previous
    datagram's arrival, so no latency of the run exceeds the burst's own length (measured
    around it on the monotonic clock). Bounded by the run's start instead, it would read
    the second of silence before the burst (a persistent offset between the stamps and the
    thread's clock, as in the bench test above, does not tell the two bounds apart: a
    one-time step does)."""
    from pslog.live.server import bind_udp
    from tests._live import frames, rally_session

    rig, det = rally_session(0.4, spurious_rate=0.0, miss_rate=0.0)
    epoch = time.time_ns() - 10 * NS  # (the frames' capture times: in the past)
    sent = frames(det, rig, epoch)[:30]
    data = [encode_detections(d) for d in sent]
    sock = _SteppedSocket(bind_udp("udp://127.0.0.1:0"), 60 * NS, at_datagram=20)
    stop = threading.Event()
    sink = _Collector(stop)
    with _serving(monkeypatch, sock, rig, [sink], stop, method="typeA", candidates=False,
                  rehearse_s=None, epoch_ns=epoch, status_stream=None) as (ready, result):
        time.sleep(1.0)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        burst = time.monotonic_ns()
        for b in data:
            tx.sendto(b, ready.address)  # type: ignore[attr-defined]
        tx.close()
        _wait_until(lambda: sink.fuser.counters()["received"] == len(data), "received")
        took = time.monotonic_ns() - burst
    summary = result["summary"]
    assert sock.stepped and summary.counters["received"] == len(data)
    # (the datagram that waited across the step made a point: its latency is among them)
    assert any(p.t_capture_ns == sent[20].t_capture_ns for p, _ in sink.points)
    # (1 ms: the stamps' conversion between the two clocks, microseconds)
    assert 0 <= summary.latency_ns.min() and summary.latency_ns.max() <= took + 1_000_000
    assert summary.wait_ns.max() <= took + 1_000_000


@pytest.mark.parametrize("step_s", [60.0, -60.0])
def test_a_held_frame_reports_its_own_monotonic_arrival_across_a_wall_clock_step(
        monkeypatch, step_s):
    """serve with a hold over real UDP: a burst of frames 1 s after the start, the last of
    them held for the other cameras' next frames; then the fuser host's wall clock (its
    thread's clock and the kernel's receive stamps) steps ``step_s``, and 0.3 s later the
    next frames come and release them. Each held frame's point carries the monotonic
    arrival of its own datagram (LivePoint.arrival_mono_ns): its latency (the point's own,
    LivePoint.latency_s, and serve's, LiveSummary.latency_ns) is its wait, at least the
    0.3 s and at most the burst's length. Converted from its wall-clock stamp when the point
    came out (as before), it was the time since the run's start (stepped forward: the
    stamp 60 s old, bounded by the start) or none (stepped back), and the point's own
    latency_s 60 s or negative."""
    from pslog.live.server import bind_udp
    from tests._live import frames, rally_session

    rig, det = rally_session(0.4, spurious_rate=0.0, miss_rate=0.0)
    epoch = time.time_ns() - 120 * NS  # (in the past: a step back makes nothing `future`)
    sent = frames(det, rig, epoch)
    cut = sent[len(sent) // 2].t_capture_ns
    before = [encode_detections(d) for d in sent if d.t_capture_ns < cut]
    after = [encode_detections(d) for d in sent if d.t_capture_ns >= cut]
    sock = _SteppedSocket(bind_udp("udp://127.0.0.1:0"), int(step_s * NS))
    stop, stepped = threading.Event(), threading.Event()
    sink = _Collector(stepped)  # (each point: made after the step or not)
    start = sink.start

    def started(fuser) -> None:  # (the fuser's wall clock, t_emit_ns: the thread's, stepped)
        fuser.clock = time.time_ns
        start(fuser)

    sink.start = started  # type: ignore[method-assign]
    with _serving(monkeypatch, sock, rig, [sink], stop, method="typeA", candidates=False,
                  hold_s=10.0, silent_after_s=5.0, rehearse_s=None, epoch_ns=epoch,
                  status_stream=None) as (ready, result):
        time.sleep(1.0)  # (the run's start well before the burst)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        burst = time.monotonic_ns()
        for b in before:
            tx.sendto(b, ready.address)  # type: ignore[attr-defined]
        _wait_until(lambda: sink.fuser.counters()["received"] == len(before), "received")
        # every point the burst makes without waiting, out before the step (else, on a
        # loaded machine, one made just after it passes for a held frame's: CI, once)
        held_from = -1
        while held_from != sink.fuser.counters()["points"]:
            held_from = sink.fuser.counters()["points"]
            time.sleep(0.2)
        stepped.set()
        sock.at = time.time_ns()  # the step: every later stamp and clock reading moved
        time.sleep(0.3)
        for b in after:
            tx.sendto(b, ready.address)  # type: ignore[attr-defined]
        tx.close()
        _wait_until(lambda: sink.fuser.counters()["received"] == len(sent), "received")
        took = time.monotonic_ns() - burst
    summary = result["summary"]
    assert summary.counters["fused"] == len(sent)
    held = [p for p, late in sink.points if late and p.t_capture_ns < cut]
    assert len(held) >= 1 and len(sink.points) > held_from  # (the last frames, held)
    for p in held:
        assert 0.3 <= p.latency_s <= took / NS
    lat = summary.latency_ns
    assert 0 <= lat.min() and lat.max() <= took
    assert (lat >= 0.3 * NS).sum() >= len(held)


def test_serve_keeps_rehearsing_across_a_wall_clock_step(monkeypatch):
    """serve over real UDP, 40 datagrams paced at their capture times (3 x 30 fps, 11 ms
    apart), the fuser host's wall clock (its thread's clock and the kernel's receive
    stamps) stepped 60 s forward while the 6th waits: the rehearsals (planned and waited
    for on the monotonic clock) go on before the datagrams after the step. Planned on the
    wall clock, every one after the step was due 60 s in the past (the delays 60 s longer
    than the least one for 16 datagrams of each camera, more than each sends after it) and
    none ran."""
    from pslog.live import fuser as live_fuser
    from pslog.live.server import bind_udp
    from tests._live import frames, rally_session

    rig, det = rally_session(0.6, spurious_rate=0.0, miss_rate=0.0)
    sock = _SteppedSocket(bind_udp("udp://127.0.0.1:0"), 60 * NS, at_datagram=5)
    after: list[bool] = []  # per rehearsal run: after the step
    step = live_fuser.Rehearsal.step

    def noted(rehearsal) -> None:  # (the rehearsal itself, noted when it ran)
        step(rehearsal)
        after.append(sock.stepped)

    monkeypatch.setattr(live_fuser.Rehearsal, "step", noted)
    with _serving(monkeypatch, sock, rig, [], threading.Event(), method="typeA",
                  candidates=False, rehearse_s=0.004, status_stream=None) as (ready, result):
        sent = frames(det, rig, ready.epoch_ns)[:40]  # type: ignore[attr-defined]
        start = time.monotonic_ns() + 20_000_000
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for d in sent:  # (their capture times' spacing, from 20 ms on)
                due = start + d.t_capture_ns - sent[0].t_capture_ns
                time.sleep(max(0.0, (due - time.monotonic_ns()) / NS))
                tx.sendto(encode_detections(d), ready.address)  # type: ignore[attr-defined]
        _wait_until(lambda: sock.received == len(sent), "received")
        time.sleep(0.05)
    summary = result["summary"]
    assert sock.stepped and summary.counters["fused"] == len(sent)
    # (one before most of the 34 datagrams after the step: 20-25 at load 9, 8 at load 11,
    # skipped when the thread woke later than the lead; planned on the wall clock, none)
    assert summary.rehearsals == len(after) and sum(after) >= 3
