"""``pslog ARGS`` run in the test's own process, seen as :func:`promises.run_pslog` sees a
real process: the same :class:`promises.Run` (exit code, stdout, stderr), so the same promises
are asserted on it.

For the many cases whose process boundary is not what they test (a refused value, a refused
file: the check runs before anything is written), a real process only adds its start-up
(~0.4 CPU s each). What a real process would show is reproduced: argparse's exit 2
(``SystemExit``), an uncaught exception as its traceback on stderr and exit 1, and Python
warnings under the interpreter's default filters (``PYTHONWARNINGS`` unset, as
:func:`promises.run_pslog` runs), printed to stderr as the interpreter prints them. A hang
(an input read for ever) fails the test after ``timeout`` seconds (SIGALRM). Each family of
cases keeps at least one case run as a real process (what only a process shows: start-up,
output flushed at exit, warnings at shutdown).
"""

from __future__ import annotations

import contextlib
import io
import os
import signal
import sys
import traceback
import warnings
from pathlib import Path

from _exit import exit_status

from .promises import HANG_S, Run


class _Hang(BaseException):
    """Raised by the alarm: not an ``Exception``, so no handler of pslog's turns it into a
    one-line error."""


def _default_filters() -> None:
    """The interpreter's default warning filters (``python -W`` unset, not a debug build)."""
    warnings.resetwarnings()
    warnings.filterwarnings("default", category=DeprecationWarning, module="__main__")
    for category in (DeprecationWarning, PendingDeprecationWarning, ImportWarning,
                     ResourceWarning):
        warnings.filterwarnings("ignore", category=category)


def run_inprocess(*args, cwd=None, timeout: float = HANG_S) -> Run:
    """``pslog ARGS`` through :func:`pslog.cli.main` in this process (in ``cwd``)."""
    from pslog.cli import main

    argv = [str(a) for a in args]
    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()

    def hang(_signum, _frame):
        raise _Hang

    previous = signal.signal(signal.SIGALRM, hang)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    fds = _FdCapture()  # what C libraries write to fds 1 and 2 (OpenCV's, FFmpeg's warnings)
    try:
        with warnings.catch_warnings(record=True) as caught, \
                contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            _default_filters()
            if cwd is not None:
                os.chdir(Path(cwd))
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse: --help, a usage error
                code = exit_status(exc)
            except _Hang:
                raise
            except Exception:  # uncaught: the interpreter prints it and exits 1
                traceback.print_exc()
                code = 1
            for w in caught:
                print(warnings.formatwarning(w.message, w.category, w.filename, w.lineno,
                                             w.line), file=sys.stderr, end="")
    except _Hang:
        raise AssertionError(f"pslog {' '.join(argv)} hung for more than {timeout} s") from None
    finally:
        raw_out, raw_err = fds.close()
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
        os.chdir(here)
    return Run(tuple(argv), int(code), out.getvalue() + raw_out, err.getvalue() + raw_err)


class _FdCapture:
    """File descriptors 1 and 2 pointed at temporary files until :meth:`close`, which puts
    them back and returns what was written there (after Python's own streams' text: a C
    library's line and pslog's are not interleaved exactly as in a terminal)."""

    def __init__(self) -> None:
        import tempfile

        sys.stdout.flush()
        sys.stderr.flush()
        self.files = [tempfile.TemporaryFile(), tempfile.TemporaryFile()]
        self.saved = [os.dup(1), os.dup(2)]
        for fd, f in zip((1, 2), self.files, strict=True):
            os.dup2(f.fileno(), fd)

    def close(self) -> tuple[str, str]:
        texts = []
        for fd, f, saved in zip((1, 2), self.files, self.saved, strict=True):
            os.dup2(saved, fd)
            os.close(saved)
            f.seek(0)
            texts.append(f.read().decode(errors="replace"))
            f.close()
        return texts[0], texts[1]


def assert_refused(folder: Path, code: int, args, contains: str | tuple[str, ...] = (), *,
                   real: bool = False) -> str:
    """:func:`promises.assert_refused` run in-process, or as a real process with ``real``
    (a family's one real-process case)."""
    from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog

    before = fingerprint(folder)
    run = (run_pslog if real else run_inprocess)(*args, cwd=folder)
    line = assert_one_line_error(run, code, contains=contains)
    assert_untouched(before, folder)
    return line


def first_case(request, per: tuple[str, ...] = ()) -> bool:
    """Whether the test is the first case of its parametrized family: the one that runs as a
    real process (the others run in this process: the same promises, without ~0.4 CPU s of
    start-up each). ``per``: parameter names whose every value gets a first case of its own
    (e.g. each kind of output node once as a real process).

    Decided by the parameters' values (each equal to the first of its ``parametrize`` list),
    not by ``callspec.indices``: pytest 9 gives there the index of the whole combination for
    every name of a stacked family, so only one case of all was real."""
    params = request.node.callspec.params
    for mark in request.node.iter_markers("parametrize"):
        names, values = mark.args[0], mark.args[1]
        names = [n.strip() for n in names.split(",")] if isinstance(names, str) else list(names)
        if not values or any(n in per for n in names):
            continue
        first = values[0]
        first = first.values if hasattr(first, "values") and hasattr(first, "marks") else first
        first = tuple(first) if len(names) > 1 else (first,)
        if any(params[n] != v for n, v in zip(names, first, strict=True)):
            return False
    return True
