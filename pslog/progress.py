"""Progress of a long command on standard error: rich's progress bar on a terminal, a plain
line every few seconds otherwise (a log file or CI shows that work goes on, without control
characters).

Used by every command that can run for more than a second on a long session::

    with Progress("fuse", total=len(methods) + 2, unit="steps") as progress:
        progress.step("reading the session")
        ...
        progress.step("typeA")

``PSLOG_PROGRESS`` chooses: ``auto`` (default: a bar on a terminal, lines otherwise), ``bar``,
``lines``, ``off``; ``PSLOG_PROGRESS_INTERVAL`` is the lines' period in seconds (default 5).
Results go to standard output and are never mixed with progress: a script that reads a
command's output reads the same with or without it.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import IO, Any

from .errors import InputError

#: the plain lines' period, seconds, when PSLOG_PROGRESS_INTERVAL is not set
DEFAULT_INTERVAL_S = 5.0
_MODES = ("auto", "bar", "lines", "off")


def progress_mode(stream: IO[str]) -> str:
    """``bar``, ``lines`` or ``off`` for this stream, by ``PSLOG_PROGRESS``."""
    mode = os.environ.get("PSLOG_PROGRESS", "auto").strip().lower() or "auto"
    if mode not in _MODES:
        raise InputError(f"PSLOG_PROGRESS={mode!r}: use one of {', '.join(_MODES)}")
    if mode == "auto":
        isatty = getattr(stream, "isatty", None)
        return "bar" if isatty is not None and isatty() else "lines"
    return mode


def _interval_s() -> float:
    text = os.environ.get("PSLOG_PROGRESS_INTERVAL", "")
    if not text.strip():
        return DEFAULT_INTERVAL_S
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (0.05 <= value <= 3600):
        raise InputError(f"PSLOG_PROGRESS_INTERVAL={text!r}: seconds between 0.05 and 3600")
    return value


def _count(value: float, unit: str) -> str:
    number = f"{value:,.0f}" if float(value).is_integer() else f"{value:,.1f}"
    return f"{number} {unit}".rstrip()


class Progress:
    """A command's progress: ``completed`` of ``total`` units (``total`` None: unknown).

    Parameters
    ----------
    command : the command's name, the lines' prefix (``pslog fuse: ...``)
    total : units of work in all, or None when unknown
    unit : what is counted (``steps``, ``frames``, ``detections``)
    stream : where progress goes (default standard error)
    """

    def __init__(self, command: str, total: float | None = None, unit: str = "steps", *,
                 stream: IO[str] | None = None) -> None:
        self.command = command
        self.total = total
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        self.mode = progress_mode(self.stream)
        self.interval_s = _interval_s() if self.mode == "lines" else DEFAULT_INTERVAL_S
        self.completed = 0.0
        self.what = ""
        self._start = time.monotonic()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._bar: Any = None
        self._task: Any = None

    # ---- context ----------------------------------------------------------------------
    def __enter__(self) -> Progress:
        self._start = time.monotonic()
        if self.mode == "bar":
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                SpinnerColumn,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )
            from rich.progress import Progress as RichProgress

            self._bar = RichProgress(
                SpinnerColumn(), TextColumn(f"pslog {self.command}"),
                TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                TextColumn(self.unit), TimeElapsedColumn(), TimeRemainingColumn(),
                # soft_wrap: a result line printed meanwhile keeps its own line breaks
                console=Console(file=self.stream, soft_wrap=True), transient=True,
                # a result printed meanwhile goes above the bar only when it shares the
                # terminal; piped standard output is never taken over
                redirect_stdout=bool(getattr(sys.stdout, "isatty", lambda: False)()),
                redirect_stderr=False)
            self._bar.start()
            self._task = self._bar.add_task(self.what, total=self.total)
        elif self.mode == "lines":
            self._thread = threading.Thread(target=self._lines, daemon=True,
                                            name=f"pslog-progress-{self.command}")
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop showing progress (the bar is removed from the terminal; no final line: the
        command prints its own result)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

    # ---- updates ------------------------------------------------------------------------
    def update(self, completed: float | None = None, *, advance: float = 0.0,
               what: str | None = None, total: float | None = None,
               unit: str | None = None) -> None:
        """Set ``completed`` (or add ``advance``), and optionally what is being done, the
        total (once known) and what is counted. Cheap: call it as often as convenient."""
        with self._lock:
            if unit is not None:
                self.unit = unit
            if completed is not None:
                self.completed = float(completed)
            self.completed += advance
            if what is not None:
                self.what = what
            if total is not None:
                self.total = total
        if self._bar is not None:
            self._bar.update(self._task, completed=self.completed, description=self.what,
                             total=self.total)

    def step(self, what: str) -> None:
        """Begin the next step, named ``what``: the steps before it are complete."""
        self.update(advance=1.0 if self.what else 0.0, what=what)

    def line(self) -> str:
        """The plain progress line: ``pslog fuse: 2/5 steps, smooth, 12.3 s``."""
        with self._lock:
            done, total, what = self.completed, self.total, self.what
        elapsed = time.monotonic() - self._start
        if total:
            count = (f"{_count(done, '')}/{_count(total, self.unit)} "
                     f"({100 * done / total:.0f} %)")
        elif done:
            count = _count(done, self.unit)
        else:  # nothing counted: say that work goes on
            count = "working"
        return f"pslog {self.command}: {count}{', ' + what if what else ''}, {elapsed:.1f} s"

    def _lines(self) -> None:
        while not self._stop.wait(self.interval_s):
            try:
                self.stream.write(self.line() + "\n")
                self.stream.flush()
            except (OSError, ValueError):  # a closed pipe or stream: progress is not worth a
                return  # failure of the command


#: the progress of the running command, which its stages report to (None: not shown)
_active: Progress | None = None


@contextmanager
def command_progress(command: str, total: float | None = None,
                     unit: str = "steps") -> Iterator[Progress]:
    """Show ``pslog COMMAND``'s progress while the block runs; inside it, :func:`step` and
    :func:`update` report to it (they do nothing outside such a block, so library code may
    call them freely)."""
    global _active
    with Progress(command, total, unit) as progress:
        _active = progress
        try:
            yield progress
        finally:
            _active = None


def step(what: str) -> None:
    """The running command begins its next step, ``what`` (nothing without a progress)."""
    if _active is not None:
        _active.step(what)


def update(completed: float | None = None, *, advance: float = 0.0, what: str | None = None,
           total: float | None = None, unit: str | None = None) -> None:
    """Report to the running command's progress (see :meth:`Progress.update`)."""
    if _active is not None:
        _active.update(completed, advance=advance, what=what, total=total, unit=unit)


def done() -> None:
    """The running command's work is over (it now waits, e.g. serves a viewer until Ctrl-C):
    stop showing progress."""
    global _active
    if _active is not None:
        _active.close()
        _active = None
