"""The real ``pslog`` command run in a process of its own, for the tests that exercise the
CLI end to end (its exit status, its standard output and error as a user sees them).

    from _cli import pslog, pslog_ok

``pslog(*args)`` returns the :class:`subprocess.CompletedProcess`; ``pslog_ok(*args)``
asserts exit 0 (showing the command's standard error otherwise) and returns its standard
output. (Each test file carried its own copy of these lines before session 41.)"""

from __future__ import annotations

import subprocess
import sys


def pslog(*args, timeout: float = 600, env: dict | None = None,
          input: str | None = None) -> subprocess.CompletedProcess:
    """``python -m pslog ARGS`` (each argument ``str``-ed: paths may be given as is)."""
    return subprocess.run([sys.executable, "-m", "pslog", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout, env=env,
                          input=input)


def pslog_ok(*args, timeout: float = 600, env: dict | None = None,
             input: str | None = None) -> str:
    """:func:`pslog`, exit 0 asserted; its standard output."""
    done = pslog(*args, timeout=timeout, env=env, input=input)
    assert done.returncode == 0, done.stderr
    return done.stdout
