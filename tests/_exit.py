"""What the interpreter does with an uncaught ``SystemExit``, for the tests that run a
``pslog`` command's ``main`` in a process of their own making (tests/faults/_inprocess.py,
test_readme's forking runner): imports nothing, so that it can be loaded by path into a
command's process without importing anything there."""

from __future__ import annotations

import sys


def exit_status(exc: SystemExit) -> int:
    """The process's exit status for ``exc``, as the interpreter gives it: ``None`` 0, an
    integer itself, anything else (argparse's and ``sys.exit("message")``'s) printed on
    stderr and 1."""
    code = exc.code
    if code is None:
        return 0
    if isinstance(code, int):
        return code
    print(code, file=sys.stderr)
    return 1
