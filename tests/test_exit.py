"""tests/_exit.py, which the in-process and forking runners use for a command's
``SystemExit``, gives what the interpreter gives: the same exit status and stderr."""

from __future__ import annotations

import subprocess
import sys

import pytest
from _exit import exit_status


@pytest.mark.parametrize("code", [None, 0, 2, "pslog: error: a message", True, [1, 2]])
def test_exit_status_is_the_interpreters(code, capsys):
    real = subprocess.run([sys.executable, "-I", "-S", "-c", f"raise SystemExit({code!r})"],
                          capture_output=True, text=True, timeout=60)
    assert exit_status(SystemExit(code)) == real.returncode
    assert capsys.readouterr().err == real.stderr
