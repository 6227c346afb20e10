"""Shared helper of session 42's hostile probes: run ``pslog ARGS`` as a real process with a
timeout and classify what a user would see (ok, one-line error, traceback, hang, many lines)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

TREE = Path(__file__).resolve().parents[3]
ENV = {**os.environ, "PYTHONPATH": str(TREE), "PSLOG_PROGRESS": "off"}


def run(*args, timeout=60.0, cwd=None, stdin=subprocess.DEVNULL, env=None):
    """(outcome, code, stdout, stderr); outcome one of ok, ok-notes, error1, error2,
    TRACEBACK, HANG, MULTILINE, BADCODE."""
    argv = [sys.executable, "-m", "pslog.cli", *map(str, args)]
    try:
        done = subprocess.run(argv, capture_output=True, timeout=timeout, cwd=cwd,
                              env={**ENV, **(env or {})}, stdin=stdin,
                              errors="backslashreplace", text=True)
    except subprocess.TimeoutExpired:
        return "HANG", None, "", ""
    err = done.stderr
    lines = [x for x in err.splitlines() if x.strip()]
    if "Traceback" in err or "Traceback" in done.stdout or "Warning:" in err:
        kind = "TRACEBACK"
    elif done.returncode == 0:
        kind = "ok" if not lines else "ok-notes"
    elif done.returncode in (1, 2):
        kind = f"error{done.returncode}" if len(lines) == 1 else "MULTILINE"
    else:
        kind = "BADCODE"
    return kind, done.returncode, done.stdout, err
