"""The three promises every fault case asserts (issue 8), shared by the fault-injection suite.

1. one line on stderr and no traceback;
2. the right exit code (1 for a fault, 2 for a malformed command line);
3. no input changed and no partial output left behind.

Commands run as a real process (``python -m pslog.cli``), so what a user sees on the terminal
(uncaught tracebacks, warnings, output of child processes) is what the test sees.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

#: longest a faulty command may go without progress (no CPU time used) before the suite
#: calls it a hang, seconds: a hang guard, not a time limit (a loaded machine slows a command
#: down, it does not stop it: the same command takes 30 s at load 20 that takes 3 idle)
HANG_S = 60.0
#: a command that keeps using CPU is still called hung after this many times its guard
STUCK_TIMES = 3


@dataclass(frozen=True)
class Run:
    args: tuple[str, ...]
    code: int
    stdout: str
    stderr: str
    #: seconds the command's main thread spent blocked (asleep, waiting on a socket...),
    #: neither on a core nor waiting for one, as last seen while it ran (``_procs.blocked_s``,
    #: every 0.5 s; None: never seen, it ended within 0.5 s): a length the machine's load
    #: does not stretch
    blocked_s: float | None = None


def run_pslog(*args, cwd=None, timeout: float = HANG_S, env=None, preexec_fn=None,
              stdin=subprocess.DEVNULL) -> Run:
    """Run ``pslog ARGS...`` as a separate process; a hang fails the test: ``timeout``
    seconds in which it and its child processes used no CPU (blocked: on a lock, a pipe, a
    wait), or :data:`STUCK_TIMES` times ``timeout`` in all."""
    from _procs import blocked_s, cpu_s

    argv = [str(a) for a in args]
    full_env = {**os.environ, **(env or {})}
    if env and "PYTHONPATH" in env:  # (before this tree's: tests/conftest.py), not instead
        full_env["PYTHONPATH"] = os.pathsep.join(
            p for p in (env["PYTHONPATH"], os.environ.get("PYTHONPATH")) if p)
    full_env.pop("PYTHONWARNINGS", None)
    proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", *argv], cwd=cwd, env=full_env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=stdin, preexec_fn=preexec_fn)
    start = last = time.monotonic()
    used = 0.0
    blocked = None
    with proc:
        while True:
            try:
                out, err = proc.communicate(timeout=0.5)  # (retried: no output lost)
                break
            except subprocess.TimeoutExpired:
                now, cpu = time.monotonic(), cpu_s(proc.pid)
                seen = blocked_s(proc.pid)
                blocked = blocked if seen is None else seen
                if cpu > used + 0.02:
                    last, used = now, cpu
                if now - last > timeout or now - start > STUCK_TIMES * timeout:
                    proc.kill()
                    proc.communicate()
                    raise AssertionError(
                        f"pslog {' '.join(argv)} hung: {now - last:.0f} s without using CPU, "
                        f"{now - start:.0f} s in all") from None
    return Run(tuple(argv), proc.returncode, out, err, blocked)


def assert_one_line_error(run: Run, code: int = 1, *, contains: str | tuple[str, ...] = ()) -> str:
    """Promises 1 and 2: exit ``code``, exactly one non-empty line on stderr, no traceback or
    Python warning anywhere; returns the line. ``contains``: text(s) the line must hold."""
    where = f"pslog {' '.join(run.args)}"
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    for stream in (run.stderr, run.stdout):
        assert "Traceback" not in stream, f"{where}: traceback\n{stream}"
        assert "Warning:" not in stream, f"{where}: Python warning\n{stream}"
    assert run.code == code, f"{where}: exit {run.code}, wanted {code}\nstderr: {run.stderr}"
    assert len(lines) == 1, f"{where}: {len(lines)} lines on stderr, wanted 1:\n{run.stderr}"
    line = lines[0]
    assert line.startswith("pslog"), f"{where}: error line does not name pslog: {line}"
    for text in (contains,) if isinstance(contains, str) else contains:
        assert text in line, f"{where}: {text!r} not in {line!r}"
    return line


def fingerprint(*paths) -> dict[str, tuple[int, str]]:
    """``path -> (size, sha256)`` of files, or every file below a folder (for promise 3)."""
    out: dict[str, tuple[int, str]] = {}
    for path in map(Path, paths):
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
        for f in files:
            if f.exists():
                data = f.read_bytes()
                out[str(f)] = (len(data), hashlib.sha256(data).hexdigest())
    return out


def assert_untouched(before: dict[str, tuple[int, str]], *paths) -> None:
    """Promise 3: the files fingerprinted in ``before`` are byte-identical and no file was
    added (no partial output) below ``paths`` (the same paths given to :func:`fingerprint`)."""
    after = fingerprint(*paths)
    added = sorted(set(after) - set(before))
    changed = sorted(p for p in before if after.get(p) != before[p])
    assert not added, f"left behind: {added}"
    assert not changed, f"changed or removed: {changed}"


def assert_refused(folder: Path, code: int, args, contains: str | tuple[str, ...] = ()) -> str:
    """All three promises for ``pslog ARGS`` run in ``folder``: one line, exit ``code``,
    nothing below ``folder`` changed or added; returns the error line."""
    before = fingerprint(folder)
    line = assert_one_line_error(run_pslog(*args, cwd=folder), code, contains=contains)
    assert_untouched(before, folder)
    return line
