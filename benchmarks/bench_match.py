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


def run(cmd: list[str]) -> None:
    """Run a preparation step (not timed)."""
    done = subprocess.run(cmd, capture_output=True, cwd=ROOT, env=_env(ROOT))
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({done.returncode}):\n{done.stderr.decode()}")


def run_peak(cmd: list[str], env: dict | None = None, timeout: float | None = None
             ) -> tuple[float, float, str, bool]:
    """``(seconds, peak MB, stdout, finished)`` of one process: wall time, and its own peak
    resident set (``os.wait4``); ``finished`` False when it ran past ``timeout`` (killed)."""
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
                return time.perf_counter() - t0, float("nan"), "", False
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
            s, peak, out, _ = run_peak([sys.executable, "-c", _FUSE_PHASES, str(session),
                                        str(fused_a)])
            steps = json.loads(out)
            row("fuse typeA steps", m, s, peak, "cpu s (peak MB): " + ", ".join(
                f"{k} {v[0]:.2f} ({v[1]})" for k, v in steps.items()))
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
        target = TARGETS.get(stage, "")
        print(f"  {stage:<22} {figures}   target {target}" if target
              else f"  {stage:<22} {figures}")
    if args.json is not None:
        args.json.write_text(json.dumps({"rows": rows, "targets": TARGETS}, indent=2))


if __name__ == "__main__":
    main()
