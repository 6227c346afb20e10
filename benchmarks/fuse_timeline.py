"""The timeline of one ``pslog fuse`` run, in process: when each step starts and ends, on
which thread, with how much of that thread's CPU, and how busy the process keeps the cores
meanwhile (where they sit idle, what is on the critical path at the end).

Each step below is wrapped (the same functions ``pslog fuse`` calls, called through: the
outputs are the command's own) and every thread's CPU is sampled from ``/proc/self/task``
every 20 ms (Linux). Printed:

- per step: calls, wall seconds summed over its calls, the CPU seconds of the threads that
  ran it (``time.thread_time``), its first start and last end (seconds from the start of
  the command, before its imports) and its threads' names;
- per thread (the sampler): CPU seconds and the span it was busy;
- per half second: the cores' use (1.0: both cores busy the whole half second) and the
  three busiest threads;
- the idle core-seconds (cores x wall - CPU): what a two-core run lost to waiting.

On a shared machine the other processes take cores too: compare two trees in alternation
(``PYTHONPATH=OTHER_TREE python benchmarks/fuse_timeline.py ...`` runs the other tree's
pslog with this script) and read the CPU columns before the wall ones.

Run: ``python benchmarks/fuse_timeline.py SESSION.mcap [pslog fuse options]`` (the output
goes to a temporary file unless ``-o`` is given), or ``--minutes M`` for a simulated
three-camera type-A rally of M minutes (benchmarks/bench_match.py's session).
"""

from __future__ import annotations

import functools
import itertools
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

T0 = time.perf_counter()
C0 = time.process_time()
#: (step, thread id, thread name, start s, end s, thread CPU s)
EVENTS: list[tuple[str, int, str, float, float, float]] = []
NAMES: dict[int, str] = {}
SAMPLES: list[tuple[float, dict[int, int]]] = []
TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def wrap(owner, attr: str, label=None) -> None:
    """Replace ``owner.attr`` by a call-through that records each call as an event."""
    fn = getattr(owner, attr)

    @functools.wraps(fn)
    def timed(*a, **k):
        w, c = time.perf_counter(), time.thread_time()
        try:
            return fn(*a, **k)
        finally:
            name = label(a, k) if callable(label) else (label or attr)
            me = threading.current_thread()
            EVENTS.append((name, threading.get_native_id(), me.name, w - T0,
                           time.perf_counter() - T0, time.thread_time() - c))

    setattr(owner, attr, timed)


def sampler(stop: threading.Event) -> None:
    """Every thread's user + system ticks, every 20 ms (this thread left out)."""
    me = threading.get_native_id()
    while not stop.is_set():
        now, ticks = time.perf_counter() - T0, {}
        for tid in os.listdir("/proc/self/task"):
            try:
                with open(f"/proc/self/task/{tid}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
                ticks[int(tid)] = int(fields[11]) + int(fields[12])
            except (OSError, IndexError, ValueError):
                pass  # (a thread that just ended)
        ticks.pop(me, None)
        SAMPLES.append((now, ticks))
        for thread in threading.enumerate():
            if thread.native_id is not None:
                NAMES.setdefault(thread.native_id, thread.name)
        time.sleep(0.02)


def instrument() -> None:
    """Wrap the steps of ``pslog fuse`` (what exists in the pslog imported: an older tree's
    missing step is left out)."""
    import dataclasses

    import pslog.cli.fuse  # noqa: F401
    import pslog.fusion as F
    import pslog.fusion.gating as G
    import pslog.log as L
    import pslog.log._chunks as CH
    import pslog.log.copy as CP
    import pslog.log.writer as W
    import pslog.timing as TM

    steps = [(L, "read_session", "read"), (TM, "observations", "observations"),
             (F, "default_methods", None), (G, "gate_common", None),
             (G, "gate", lambda a, k: "gate " + ("causal" if k.get("causal") else "offline")),
             (G, "prepared_for", "prepare"), (CP, "_copy_chunks", "copy session chunks"),
             (W.SessionWriter, "add_track", "write track"),
             (W.SessionWriter, "add_rejections", "write rejections"),
             (W.SessionWriter, "_close", "close"), (W, "_track_block", "encode track block"),
             (CH, "_pack", "compress chunk"), (CH, "write_attachment", "write table")]
    for owner, attr, label in steps:
        if hasattr(owner, attr):
            wrap(owner, attr, label)
    for name in list(F.METHODS):
        box = type("Box", (), {})()
        box.fn = F.METHODS[name].function
        wrap(box, "fn", "fuse " + name)
        F.METHODS[name] = dataclasses.replace(F.METHODS[name], function=box.fn)
    try:
        import pslog.estimation._breaks as B

        if hasattr(B, "_scan_block"):
            wrap(B, "_scan_block", "smooth break block")
    except ImportError:
        pass


def report(wall: float, cpu: float, code: int) -> None:
    import resource

    out = sys.__stdout__
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
    print(f"\nexit {code}; wall {wall:.2f} s, CPU {cpu:.2f} s, peak {peak} MB", file=out)
    steps: dict[str, list] = {}
    for name, _tid, thread, s, e, c in EVENTS:
        row = steps.setdefault(name, [0, 0.0, 0.0, s, e, set()])
        row[0] += 1
        row[1] += e - s
        row[2] += c
        row[3], row[4] = min(row[3], s), max(row[4], e)
        row[5].add(thread)
    print(f"{'step':<22} {'calls':>5} {'wall s':>7} {'CPU s':>7} {'start':>7} {'end':>7}  threads",
          file=out)
    for name, (n, w, c, s, e, threads) in sorted(steps.items(), key=lambda x: x[1][3]):
        print(f"{name:<22} {n:>5} {w:7.2f} {c:7.2f} {s:7.2f} {e:7.2f}  "
              f"{', '.join(sorted(threads))[:60]}", file=out)
    if len(SAMPLES) < 2:
        return
    first = SAMPLES[0][1]
    last: dict[int, int] = {}
    for _t, ticks in SAMPLES:
        for tid, v in ticks.items():
            last[tid] = max(last.get(tid, 0), v)

    def thread_name(tid: int) -> str:
        return NAMES.get(tid, f"thread {tid}")

    print("\nthreads (sampled CPU s, busy from - to):", file=out)
    for tid in sorted(last, key=lambda t: first.get(t, 0) - last[t]):
        used = (last[tid] - first.get(tid, 0)) / TICK
        if used >= 0.05:
            busy = [a[0] for a, b in itertools.pairwise(SAMPLES)
                    if b[1].get(tid, 0) > a[1].get(tid, 0)]
            print(f"  {thread_name(tid):<24} {used:6.2f}  {min(busy):6.2f} - {max(busy):6.2f}",
                  file=out)
    cores = 2
    print(f"\ncores' use per 0.5 s (1.0: {cores} cores busy), busiest threads:", file=out)
    end, k = SAMPLES[-1][0], 0
    while k * 0.5 < end:
        inside = [s for s in SAMPLES if k * 0.5 <= s[0] < (k + 1) * 0.5]
        k += 1
        if len(inside) < 2:
            continue
        (t0, a), (t1, b) = inside[0], inside[-1]
        per = {tid: (b.get(tid, last.get(tid, 0)) - a.get(tid, 0)) / TICK
               for tid in set(a) | set(b)}
        top = sorted(per.items(), key=lambda x: -x[1])[:3]
        print(f"  {(k - 1) * 0.5:5.1f} {sum(per.values()) / (t1 - t0) / cores:5.2f}  "
              + ", ".join(f"{thread_name(t)} {v / (t1 - t0):.2f}" for t, v in top if v > 0),
              file=out)
    total = (sum(last.values()) - sum(first.values())) / TICK
    print(f"idle core-seconds ({cores} cores x {end:.2f} s - {total:.2f} CPU s): "
          f"{cores * end - total:.2f}", file=out)


def main() -> int:
    args = sys.argv[1:]
    if not args or args[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    tmp = tempfile.TemporaryDirectory(prefix="fuse-timeline-")
    if args[0] == "--minutes":
        from pslog.cli import main as pslog_main

        session = Path(tmp.name) / "s.mcap"
        assert pslog_main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                           "rally", "--duration", str(float(args[1]) * 60), "--noise-px",
                           "0.5", "--seed", "1", "-o", str(session)]) == 0
        args = [str(session), *args[2:]]
    if "-o" not in args and "--output" not in args:
        args += ["-o", str(Path(tmp.name) / "fused.mcap"), "--force"]
    global T0, C0
    T0, C0 = time.perf_counter(), time.process_time()
    stop = threading.Event()
    threading.Thread(target=sampler, args=(stop,), name="timeline-sampler",
                     daemon=True).start()
    import pslog.cli

    instrument()
    os.environ["PSLOG_PROGRESS"] = "off"
    code = pslog.cli.main(["fuse", *args])
    wall, cpu = time.perf_counter() - T0, time.process_time() - C0
    stop.set()
    time.sleep(0.05)
    report(wall, cpu, code)
    tmp.cleanup()
    return code


if __name__ == "__main__":
    sys.exit(main())
