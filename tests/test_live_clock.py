"""Live latencies on one clock: the kernel's receive stamps are wall clock, and a step of the
wall clock between a datagram's arrival and its point (an NTP step, a VM's clock set again
after a pause) must not become a "latency" of seconds (session 19 read 3-68 s in
``benchmarks/bench_live.py``). Over real UDP, with a fuser thread whose wall clock is 60 s
off the kernel's stamps: what every datagram queued across such a step sees."""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import pytest

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
