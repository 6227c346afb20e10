"""A match in seconds: ``pslog eval``, ``pslog fuse --method typeA``, ``pslog fuse`` (default
methods) and reading a session's detections, at 1, 10, 45 and 90 minutes of a three-camera
type-A rally (30 fps each: 486,000 detections at 90 minutes).

Each stage runs as its own ``pslog`` process (imports included, as a user meets it); printed:
seconds, seconds per minute of session (equal per-minute figures prove the stage linear),
peak memory (the process's maximum resident set), and the issue-12 target beside them.
Reading is timed three ways in the same run: ``read_session`` (the columnar tables), the
same without tables (the per-frame messages, as a file of an older pslog reads) and the
peer, the ``mcap`` package's ``iter_messages`` with protobuf decoding.
``pslog eval`` of the base commit (default ``0fce3cb``, before the linear reader) is timed in
the same run on the same fused files (a git worktree of it in the work folder, removed at the
end; ``--base-timeout`` caps its quadratic run), and its output compared with today's.

``fuse typeA steps`` splits ``pslog fuse --method typeA`` into its steps in one process (CPU
seconds and the peak resident set after each: imports, read, gate, prepare, the typeA fusion,
write); ``--fuse-base COMMIT`` times the fuse stages of that commit too, each right after
today's (paired runs: on a shared machine the CPU seconds are the steadier figure).

Run: ``python benchmarks/bench_match.py [--quick] [--minutes 1 10 45 90] [--dir DIR]
[--fuse-base COMMIT] [--json out.json]``. ``--quick``: 1 and 10 minutes. The sessions
(hundreds of MB at 90 minutes) live in a temporary folder unless ``--dir`` keeps them for
the next run.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: issue 12's targets at 90 minutes: (seconds, peak MB) or a rate
TARGETS = {
    "eval": "<= 3 s at 90 min",
    "fuse typeA": "<= 5 s, <= 1 GB at 90 min",
    "fuse default": "<= 8 s at 90 min",
    "read detections": ">= 2,000,000 det/s",
}

_READ = ("import sys, time; from pslog.log import read_session; t = time.perf_counter(); "
         "s = read_session(sys.argv[1]); dt = time.perf_counter() - t; "
         "print(s.detections.n_candidates, dt)")
#: the same without the columnar tables (as a file written before them reads): the messages
_READ_MESSAGES = ("import sys, time; from pslog.log import read_session; "
                  "from pslog.log.reader import _Finished; _Finished.use_tables = False; "
                  "t = time.perf_counter(); s = read_session(sys.argv[1]); "
                  "dt = time.perf_counter() - t; print(s.detections.n_candidates, dt)")
#: the peer: the mcap package's reader and protobuf, every detection message decoded
_READ_PEER = """
import sys, time
from mcap.reader import make_reader
from pslog.log._schemas import DetectionFrame
t = time.perf_counter()
n = 0
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    topics = [c.topic for c in reader.get_summary().channels.values()
              if c.topic.endswith("/detections")]
    for _s, _c, m in reader.iter_messages(topics=topics, log_time_order=False):
        n += len(DetectionFrame.FromString(m.data).u)
print(n, time.perf_counter() - t)
"""


#: ``pslog fuse --method typeA``'s steps in one process, as pslog.cli.fuse runs them: CPU
#: seconds of each (imports, reading, gating, preparing, the fusion itself, writing the fused
#: copy) and the peak resident set after each, printed as JSON: where the time goes
_FUSE_PHASES = """
import json, resource, sys, time
t0 = time.process_time()
out = {}
def mark(what):
    global t0
    t = time.process_time()
    out[what] = [round(t - t0, 3), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024]
    t0 = t
from pslog.fusion import FusionOptions, fuse, prepare
from pslog.fusion.gating import gate_for
from pslog.log import copy_session, read_session
mark("imports")
s = read_session(sys.argv[1])
rig, det = s.rig, s.detections
del s
mark("read")
options = FusionOptions()
gated = gate_for(det, rig, "typeA", options)
mark("gate")
prep = prepare(gated.observations, rig)
mark("prepare")
track = fuse(gated.observations, rig, "typeA", options, prepared=prep)
del prep
mark("typeA")
copy_session(sys.argv[1], sys.argv[2], tracks=[track], force=True,
             rejections={"typeA": gated.rejections})
mark("write")
print(json.dumps(out))
"""


#: ``pslog fuse`` with the default methods, in one process as the command runs them
#: (``pslog.cli.main``), timed by stage: wall seconds from the start of each stage to its end
#: and the CPU seconds of the thread that ran it (the methods run at once on threads, so the
#: stages overlap: their wall seconds do not add up to the total); the imports, the numba
#: cache loads (count, seconds), the total wall and CPU seconds and the peak resident set.
#: Printed as JSON: where the default methods' time goes
_FUSE_DEFAULT_PHASES = """
import dataclasses, json, os, resource, sys, threading, time
t_start, c_start = time.perf_counter(), time.process_time()
out, loads = {}, []
def wrap(name, fn):
    def timed(*a, **k):
        w, c = time.perf_counter(), time.thread_time()
        try:
            return fn(*a, **k)
        finally:
            label = name(a) if callable(name) else name
            wall, cpu = time.perf_counter() - w, time.thread_time() - c
            old = out.get(label, [0.0, 0.0])
            out[label] = [round(old[0] + wall, 3), round(old[1] + cpu, 3)]
    return timed
import pslog.cli, pslog.cli.fuse, pslog.fusion, pslog.fusion.gating, pslog.log, pslog.timing
out["imports"] = [round(time.perf_counter() - t_start, 3), round(time.process_time(), 3)]
F, G, L = pslog.fusion, pslog.fusion.gating, pslog.log
L.read_session = wrap("read", L.read_session)
L.copy_session = wrap("write", L.copy_session)
G.gate_for = wrap(lambda a: "gate " + ("causal" if G.gating_key(a[2], a[3])[0]
                                       else "offline"), G.gate_for)
F.prepare = wrap("prepare", F.prepare)
for m in list(F.METHODS):
    F.METHODS[m] = dataclasses.replace(F.METHODS[m],
                                       function=wrap(m, F.METHODS[m].function))
def watch_numba():  # the numba cache loads, once numba is imported (by a kernel module)
    from numba.core import caching
    load = caching.Cache.load_overload
    def timed(self, sig, ctx):
        w = time.perf_counter()
        try:
            return load(self, sig, ctx)
        finally:
            loads.append(time.perf_counter() - w)
    caching.Cache.load_overload = timed
import builtins
real_import = builtins.__import__
def spy(name, *a, **k):  # hook numba's cache once numba is imported (whole: not while its
    module = real_import(name, *a, **k)  # own modules import each other)
    numba = sys.modules.get("numba")
    if (numba is not None and "hooked" not in out
            and not getattr(numba.__spec__, "_initializing", False)):
        out["hooked"] = True
        watch_numba()
    return module
builtins.__import__ = spy
os.environ["PSLOG_PROGRESS"] = "off"
code = pslog.cli.main(["fuse", *sys.argv[1:]])
builtins.__import__ = real_import
out.pop("hooked", None)
out["numba loads"] = [len(loads), round(sum(loads), 3)]
out["total"] = [round(time.perf_counter() - t_start, 3), round(time.process_time() - c_start, 3)]
out["peak MB"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
print(json.dumps(out), file=sys.__stderr__)
sys.exit(code)
"""


def run(cmd: list[str]) -> None:
    """Run a preparation step (not timed)."""
    done = subprocess.run(cmd, capture_output=True, cwd=ROOT, env=_env(ROOT))
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr.decode()}")


def run_peak(cmd: list[str], env: dict | None = None, timeout: float | None = None,
             stderr: bool = False) -> tuple:
    """``(seconds, peak MB, stdout, finished)`` of one process: wall time, and its own peak
    resident set (``os.wait4``); ``finished`` False when it ran past ``timeout`` (killed);
    with ``stderr``, its standard error too (a fifth item)."""
    import signal

    t0 = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        # run outside the checkout: ``python -m`` puts the working folder first on sys.path
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, env=env or _env(ROOT),
                                cwd=tempfile.gettempdir())
        deadline = None if timeout is None else t0 + timeout
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if deadline is not None and time.perf_counter() > deadline:
                proc.send_signal(signal.SIGKILL)
                os.wait4(proc.pid, 0)
                proc.returncode = -9
                return (time.perf_counter() - t0, float("nan"), "", False) + (
                    ("",) if stderr else ())
            time.sleep(0.005)
        seconds = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n"
                             f"{err.read().decode()}")
        global _CPU, _SYS
        _CPU = usage.ru_utime + usage.ru_stime
        _SYS = usage.ru_stime
        if stderr:
            return (seconds, usage.ru_maxrss / 1024, out.read().decode(), True,
                    err.read().decode())
        return seconds, usage.ru_maxrss / 1024, out.read().decode(), True


#: CPU seconds (user + system) of the last process :func:`run_peak` ran: on a shared machine
#: the steadier figure of the two
_CPU = float("nan")
#: its system CPU seconds (page faults of fresh buffers, file writes)
_SYS = float("nan")


def _env(code: Path) -> dict:
    """The environment that runs the pslog of ``code`` (a checkout)."""
    return {**os.environ, "PYTHONPATH": str(code)}


def pslog(*args: str) -> list[str]:
    return [sys.executable, "-m", "pslog.cli", *args]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1 and 10 minutes only")
    parser.add_argument("--minutes", type=float, nargs="+", default=None)
    parser.add_argument("--dir", type=Path, default=None,
                        help="keep the sessions here (reused by the next run)")
    parser.add_argument("--base", default="0fce3cb",
                        help="commit whose eval is timed beside today's ('' to skip)")
    parser.add_argument("--base-timeout", type=float, default=300.0, metavar="S",
                        help="longest run of the base commit's eval, seconds")
    parser.add_argument("--fuse-base", default="", metavar="COMMIT",
                        help="also time the fuse stages of this commit, each right after "
                             "today's (paired: the machine may be shared)")
    parser.add_argument("--json", type=Path, default=None, help="write the rows as JSON")
    args = parser.parse_args()
    minutes = args.minutes or ([1, 10] if args.quick else [1, 10, 45, 90])

    tmp = None
    if args.dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="bench-match-")
        work = Path(tmp.name)
    else:
        work = args.dir
        work.mkdir(parents=True, exist_ok=True)

    def checkout(rev: str | None) -> Path | None:
        """A worktree of ``rev`` in the work folder (made once; None without a revision)."""
        if not rev:
            return None
        folder = work / f"base-{rev}"
        if not folder.exists():
            subprocess.run(["git", "worktree", "add", "--detach", "-f", str(folder), rev],
                           cwd=ROOT, check=True, capture_output=True)
        return folder

    base_dir = checkout(args.base)
    fuse_base_dir = checkout(args.fuse_base)
    rows = []

    def row(stage: str, m: float, seconds: float, peak: float, extra: str = "",
            finished: bool = True) -> None:
        cpu = _CPU if finished else float("nan")
        rows.append({"stage": stage, "minutes": m, "seconds": seconds if finished else None,
                     "cpu_seconds": cpu if finished else None,
                     "seconds_per_minute": seconds / m if finished else None,
                     "peak_mb": peak, "note": extra, "finished": finished})
        shown = f"{seconds:8.2f}" if finished else f"> {seconds:6.0f}"
        per = f"{seconds / m:8.3f}" if finished else f"{'-':>8}"
        cpu_shown = f"{cpu:8.2f} {cpu / m:8.3f}" if finished else f"{'-':>8} {'-':>8}"
        print(f"{stage:<22} {m:>5g} {shown} {per} {cpu_shown} {peak:>8.0f}  {extra}",
              flush=True)

    print(f"{'stage':<22} {'min':>5} {'seconds':>8} {'s/min':>8} {'cpu s':>8} {'cpu/min':>8} "
          f"{'peak MB':>8}  note")
    try:
        for m in minutes:
            session = work / f"s{m:g}.mcap"
            if not session.exists():
                run(pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                          "rally", "--duration", str(m * 60), "--noise-px", "0.5", "--seed",
                          "1", "-o", str(session)))
            fused, fused_a = work / f"f{m:g}.mcap", work / f"fA{m:g}.mcap"
            s, peak, out, _ = run_peak([sys.executable, "-c", _READ, str(session)])
            n, dt = out.split()
            row("read detections", m, s, peak,
                f"{int(n) / float(dt):,.0f} det/s in read_session ({float(dt):.2f} s)")
            for stage, code in (("read (messages)", _READ_MESSAGES),
                                ("read peer mcap+pb", _READ_PEER)):
                s, peak, out, _ = run_peak([sys.executable, "-c", code, str(session)])
                n, dt = out.split()
                row(stage, m, s, peak, f"{int(n) / float(dt):,.0f} det/s ({float(dt):.2f} s)")
            for label, env in (("", None), (f" @ {args.fuse_base}", fuse_base_dir)):
                if label and env is None:
                    continue
                env = None if env is None else _env(env)
                s, peak, _, _ = run_peak(pslog("fuse", str(session), "--method", "typeA",
                                               "-o", str(fused_a), "--force"), env=env)
                row("fuse typeA" + label, m, s, peak,
                    f"sys {_SYS:.2f} s of the cpu s; {fused_a.stat().st_size / 1e6:.0f} MB "
                    f"written")
                s, peak, _, _ = run_peak(pslog("fuse", str(session), "-o", str(fused),
                                               "--force"), env=env)
                row("fuse default" + label, m, s, peak)
                if not label:  # the same, the methods one after another (paired)
                    s, peak, _, _ = run_peak(pslog("fuse", str(session), "-o", str(fused),
                                                   "--force", "--workers", "1"), env=env)
                    row("fuse default 1 worker", m, s, peak)
            s, peak, out, _ = run_peak([sys.executable, "-c", _FUSE_PHASES, str(session),
                                        str(fused_a)])
            steps = json.loads(out)
            row("fuse typeA steps", m, s, peak, "cpu s (peak MB): " + ", ".join(
                f"{k} {v[0]:.2f} ({v[1]})" for k, v in steps.items()))
            s, peak, _, _, err = run_peak([sys.executable, "-c", _FUSE_DEFAULT_PHASES,
                                           str(session), "-o", str(fused), "--force"],
                                          stderr=True)
            steps = json.loads(err.strip().splitlines()[-1])
            total = steps.pop("total")
            peak_in = steps.pop("peak MB")
            n_loads, load_s = steps.pop("numba loads")
            row("fuse default steps", m, s, peak,
                "wall s (thread CPU s): " + ", ".join(
                    f"{k} {v[0]:.2f} ({v[1]:.2f})" for k, v in steps.items())
                + f"; {n_loads} numba cache loads {load_s:.2f} s; in process {total[0]:.2f} s "
                  f"wall, {total[1]:.2f} s CPU, peak {peak_in} MB")
            s, peak, new_out, _ = run_peak(pslog("eval", str(fused), "--json"))
            row("eval", m, s, peak)
            if base_dir is not None:
                env = _env(base_dir)
                s, peak, base_out, done = run_peak(pslog("eval", str(fused), "--json"),
                                                   env=env, timeout=args.base_timeout)
                same = ("output identical" if base_out == new_out else "OUTPUT DIFFERS") \
                    if done else "timed out"
                row(f"eval @ {args.base}", m, s, peak, same, finished=done)
            fused.unlink(missing_ok=True)
            fused_a.unlink(missing_ok=True)
            if args.dir is None:
                session.unlink(missing_ok=True)
    finally:
        if fuse_base_dir is not None and fuse_base_dir.exists():
            subprocess.run(["git", "worktree", "remove", "--force", str(fuse_base_dir)],
                           cwd=ROOT, capture_output=True)
            shutil.rmtree(fuse_base_dir, ignore_errors=True)
        if base_dir is not None and base_dir.exists():
            subprocess.run(["git", "worktree", "remove", "--force", str(base_dir)], cwd=ROOT,
                           capture_output=True)
            shutil.rmtree(base_dir, ignore_errors=True)
        if tmp is not None:
            tmp.cleanup()

    print("\nlinearity (CPU seconds per minute of session, smallest to largest; equal figures: "
          "linear) and targets:")
    for stage in dict.fromkeys(r["stage"] for r in rows):
        per = [r for r in rows if r["stage"] == stage and r["finished"]]
        figures = ", ".join(f"{r['minutes']:g} min {r['cpu_seconds'] / r['minutes']:.3f}"
                            for r in per)
        # the longest session's CPU seconds per minute over the shortest's but one (the
        # shortest carries the start-up, seconds that do not grow with the session): 1 for
        # a linear stage, about 90 / 10 for a quadratic one
        longer = [r for r in sorted(per, key=lambda r: r["minutes"]) if r["minutes"] >= 10]
        ratio = ""
        if len(longer) >= 2:
            a, b = longer[0], longer[-1]
            growth = (b["cpu_seconds"] / b["minutes"]) / (a["cpu_seconds"] / a["minutes"])
            ratio = f"; ratio {b['minutes']:g}/{a['minutes']:g} min {growth:.2f}"
        target = TARGETS.get(stage, "")
        print(f"  {stage:<22} {figures}{ratio}   target {target}" if target
              else f"  {stage:<22} {figures}{ratio}")
    if args.json is not None:
        args.json.write_text(json.dumps({"rows": rows, "targets": TARGETS}, indent=2))


if __name__ == "__main__":
    main()
