"""The ``pslog`` command line: a thin, lazily loaded dispatcher.

Each command lives in its own module ``pslog.cli.<module>`` exposing
``add_arguments(parser)`` and ``run(args) -> int``; only the chosen command's module is
imported, so ``pslog --help`` stays fast. Every :class:`~pslog.errors.PslogError` and every
unhandled OS fault (``OSError``) becomes a one-line ``pslog CMD: error: ...`` on stderr and
exit code 1.

Files: a command declares in ``add_arguments`` which options name its inputs and outputs
(:func:`pslog.cli._common.declare_files`); before ``run`` every declared output is checked
here, once for all commands: never an input in any spelling, not existing without
``--force``, a writable folder, a stale ``.partial`` of an interrupted run dealt with.
"""

from __future__ import annotations

import sys

#: SIGINT/SIGTERM/SIGHUPs that arrived while the ``pslog`` command was still loading
#: (see _hold_sigint)
_EARLY_SIGINT: list[int] = []


def _loaded_as_command() -> bool:
    """Whether this module is being loaded as the ``pslog`` command: the console script, or
    ``python -m pslog.cli`` (not imported by a program or a test)."""
    import os

    entry = os.path.basename(sys.argv[0]) if sys.argv else ""
    return (entry in ("pslog", "pslog.exe")
            or (entry == "-m" and "pslog.cli" in getattr(sys, "orig_argv", ())))


#: this process is the ``pslog`` command (:func:`_loaded_as_command`, told at import: under
#: ``python -m`` the entry's name is in ``sys.argv[0]`` only while the package loads)
_AS_COMMAND = _loaded_as_command()


def _hold_sigint():
    """When this module is loaded as the ``pslog`` command (console script or ``python -m
    pslog.cli``), note a Ctrl-C instead of raising KeyboardInterrupt until the command's
    ``run`` starts (:func:`_release_sigint`): raised during the imports of this module, of
    the command's module or of the C extensions its ``add_arguments`` loads, it would be a
    traceback (or an ImportError). The interpreter's own start-up before this point cannot
    be covered. Any other importer keeps Python's handler."""
    import _signal  # the C module, loaded at start-up; ``signal`` would build its enums first

    if not _AS_COMMAND or _signal.getsignal(_signal.SIGINT) is not _signal.default_int_handler:
        return None

    def note(signum, _frame) -> None:
        _EARLY_SIGINT.append(signum)

    # SIGTERM and SIGHUP too (unless ignored, as under nohup): their default action ended the
    # command silently while it loaded; noted, they are raised as Terminated once it runs
    for name in ("SIGTERM", "SIGHUP"):
        sig = getattr(_signal, name, None)
        if sig is not None and _signal.getsignal(sig) == _signal.SIG_DFL:
            _signal.signal(sig, note)
    return _signal.signal(_signal.SIGINT, note)


_SIGINT_HELD = _hold_sigint()

import argparse  # noqa: E402 (after the handler: the imports are the window it covers)
import importlib  # noqa: E402
import re  # noqa: E402

from pslog.errors import PslogError  # noqa: E402

#: command -> (module under pslog.cli, one-line help). Order is the order of ``--help``.
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("demo", "record a synthetic throw, fuse it with every method, show accuracy"),
    "simulate": ("simulate", "simulate a session of a rig watching a moving ball"),
    "record": ("record", "record a session from cameras, video files or a synthetic rig"),
    "import": ("import_csv", "build a session from a CSV of detections"),
    "export": ("export", "write a session's detections or tracks: CSV, TUM, JSONL, Parquet, C3D"),
    "info": ("info", "summarise a session: cameras, rates, shutter offsets, detections"),
    "calibrate": ("calibrate", "calibrate a camera from 3D-2D points or a chessboard"),
    "rig": ("rig", "list, show, check rigs; import/export anipose, Pose2Sim, OpenCV files"),
    "fuse": ("fuse", "fuse a session's detections into 3D tracks"),
    "sync": ("sync", "estimate every camera's clock from the ball's detections"),
    "eval": ("evaluate", "fused tracks: accuracy against ground truth, quality, points left out"),
    "paper": ("paper", "reproduce the paper's Tables 1 and 2"),
    "redetect": ("redetect", "re-run ball detection over a session's recorded frames"),
    "recover": ("recover", "salvage the complete records of a damaged session"),
    "view": ("view", "browse a session and its fused tracks in rerun"),
    "live": ("live", "fuse live: camera processes stream detections, points out at once"),
    "batch": ("batch", "re-sync, re-fuse, evaluate and render many sessions at once on Ray"),
}


#: commands that can run for more than a second on a long session: they show progress on
#: standard error (pslog.progress; record, live and batch show their own status lines)
PROGRESS_COMMANDS = frozenset({"simulate", "import", "export", "fuse", "sync", "eval", "paper",
                               "redetect", "recover", "view"})


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``pslog CMD: error: ... (see pslog CMD --help)``.

    A value starting with ``-`` and a digit is a value, not an option (``--hsv -5,22,...``,
    ``--distractor -2,1,0``): argparse < 3.13 took only ``-2`` or ``-2.5`` for negative
    numbers and said "expected one argument", not naming the value; 3.13's rule (a ``-``,
    then a digit or ``.`` and a digit) is taken over (no pslog option is like ``-1``)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")

    def _print_message(self, message, file=None):
        # argparse's own swallows a write's OSError: --help or --version into a full
        # standard output then said nothing and exited 0
        if not message:
            return
        file = sys.stderr if file is None else file
        try:
            file.write(message)
            file.flush()
        except OSError as err:
            if file is sys.stderr:  # nowhere left to say it
                return
            _drop_stdout(file)
            if isinstance(err, BrokenPipeError):  # the reader went away: nobody to tell
                self.exit(1)
            self.exit(1, f"{self.prog}: error: cannot write to standard output: "
                         f"{err.strerror or err}\n")


def _top_parser(commands: dict[str, tuple[str, str]]) -> argparse.ArgumentParser:
    from pslog import package_version

    pslog_version = package_version() or "unknown"
    width = max((len(n) for n in commands), default=0)
    lines = [f"  {name:<{width}}  {text}" for name, (_, text) in commands.items()]
    parser = _Parser(
        prog="pslog",
        description="Pseudo-stereo 3D ball tracking from cameras with offset shutters.",
        epilog="commands:\n" + "\n".join(lines) + "\n\nRun 'pslog COMMAND --help' for details.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        usage="pslog [-h] [--version] COMMAND ...",
    )
    parser.add_argument("--version", action="version", version=f"pslog {pslog_version}")
    return parser


def main(argv: list[str] | None = None) -> int:
    code: int | None = None  # (None: SystemExit or a bug's exception on its way out)
    try:
        code = _main(argv)
        return code
    except KeyboardInterrupt:  # Ctrl-C while a command's modules are still being imported
        print("pslog: interrupted", file=sys.stderr)
        code = 130
        return code
    finally:
        if _AS_COMMAND:
            _before_exit(code)


#: Daemon threads whose work runs outside the GIL (numba kernels compiled ``nogil``, numba's
#: compiler and cache loads): pslog.fusion._parallel's workers and pslog._jit's preload.
_NATIVE_THREADS = ("pslog-fuse-", "pslog-preload")
#: The session writer's pool threads (``concurrent.futures``, not daemons: the interpreter's
#: shutdown joins them). A SIGTERM or Ctrl-C raised in the main thread while it submitted
#: to such a pool can leave the pool's semaphore lock held (an exception raised by a signal
#: handler between a ``with`` block's ``__enter__`` and its body), and the worker, ending its
#: task, then waits for that lock forever while the shutdown joins it: ``pslog fuse`` said
#: "terminated (SIGTERM)" and never exited (session 36, once in a CI run).
_POOL_THREADS = ("pslog-encode", "pslog-zstd")


def _before_exit(code: int | None) -> None:
    """The ``pslog`` command's last step before the interpreter's shutdown: every object
    still alive moved to the collector's permanent generation (``gc.freeze``), so the
    shutdown's collections do not walk them: a default ``pslog fuse`` of a 90-minute match
    holds ~130,000 (numba's modules mostly), 0.3-0.4 CPU s of collections at exit, and its
    exit 0.1 s with them frozen (docs/performance.md). The process ends next: what a
    collection would have found is freed with it (files were closed by the command; atexit
    handlers run as before). Not done where :func:`main` is called by a program or a test,
    whose objects live on.

    A command that failed or was stopped (``code`` not 0: an error, Ctrl-C, SIGTERM) while
    one of its :data:`_NATIVE_THREADS` still runs (or, stopped by a signal, one of its
    :data:`_POOL_THREADS`) ends here, with ``os._exit(code)`` once
    its stdout and stderr are flushed: the interpreter's shutdown frees the objects such a
    thread's kernel is still reading and writing outside the GIL, and the process died of
    SIGSEGV instead of exiting 143 (``pslog fuse`` sent SIGTERM within 50 ms of its methods
    starting: 10 of 160 runs, and
    Ctrl-C 3 of 30, session 32). Nothing is lost by skipping the shutdown: the
    command has closed its files (its outputs were never written, or removed, on these
    paths), and a thread's unfinished work is what the exit abandons anyway. A command that
    succeeded has waited for its threads (``pslog fuse``'s methods) and ends as before."""
    import gc

    gc.freeze()
    if code is None or code == 0:
        return
    import threading

    signalled = code > 128  # (Ctrl-C 130, SIGTERM 143, SIGHUP 129: raised by a handler)
    if not any(thread.is_alive()
               and ((thread.daemon and thread.name.startswith(_NATIVE_THREADS))
                    or (signalled and thread.name.startswith(_POOL_THREADS)))
               for thread in threading.enumerate()):
        return
    import os

    for stream in (sys.stdout, sys.stderr):
        if stream is None:  # (started with that descriptor closed: '>&-')
            continue
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more to tell
            pass
    os._exit(code)


def _release_sigint() -> None:
    """Give SIGINT back to Python (see :func:`_hold_sigint`); a Ctrl-C that came while
    loading is raised now, where the command's KeyboardInterrupt handler catches it."""
    global _SIGINT_HELD
    if _SIGINT_HELD is not None:
        import signal

        # Python's own handler raises anywhere, importlib's code included (see _raising)
        signal.signal(signal.SIGINT, _raising(_keyboard_interrupt)
                      if _SIGINT_HELD is signal.default_int_handler else _SIGINT_HELD)
        _SIGINT_HELD = None
        # SIGTERM/SIGHUP's noting handlers were replaced by _termination_interrupts already
        for signum in _EARLY_SIGINT:
            if signum != signal.SIGINT:
                raise Terminated(signum)
        if _EARLY_SIGINT:
            raise KeyboardInterrupt


def _numba_warnings_in_one_line(name: str) -> None:
    """numba's warning about a NUMBA_* variable it cannot parse (``NUMBA_NUM_THREADS=abc``:
    nine lines on stderr, a traceback's text among them, as numba imports on any thread) as
    one line in pslog's words: numba goes on with its default; every other warning as
    Python shows it. Set once, before any thread starts."""
    import warnings

    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        text = str(message)
        if (category is RuntimeWarning and text.startswith("Environment variable 'NUMBA_")
                and "numba" in str(filename)):
            first = text.splitlines()[0].rstrip(".")
            print(f"pslog {name}: warning: numba: {first[0].lower()}{first[1:]}; numba takes "
                  f"its default instead", file=sys.stderr)
            return
        shown(message, category, filename, lineno, file, line)

    warnings.showwarning = show


def _main(argv: list[str] | None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    commands = COMMANDS
    if not argv or argv[0] not in commands:
        parser = _top_parser(commands)
        if argv and not argv[0].startswith("-"):
            parser.error(f"unknown command {argv[0]!r} (choose from {', '.join(commands)})")
        parser.parse_args(argv)  # --help / --version exit here
        parser.print_help()
        return 2
    name = argv[0]
    module_name, text = commands[name]
    module = importlib.import_module(f"pslog.cli.{module_name}")
    parser = _Parser(prog=f"pslog {name}", description=text)
    module.add_arguments(parser)
    args = parser.parse_args(argv[1:])
    early = getattr(module, "before_threads", None)
    if early is not None:  # a process-wide setting of the command, before any thread starts
        early()  # (the progress line's: pslog fuse's malloc arena)

    from ._common import empty_file_option

    empty = empty_file_option(parser, args)
    if empty is not None:
        parser.error(f"argument {empty}: empty file name")

    from pslog.outputs import describe_os_error

    from ._common import check_declared_files, declared_files, misnamed_session

    _ignore_file_size_signal()

    def say(text: str) -> None:
        print(f"pslog {name}: {text}", file=sys.stderr)

    _numba_warnings_in_one_line(name)

    real_stdout = sys.stdout  # None when started with standard output closed
    if real_stdout is not None:
        sys.stdout = _GuardedStdout(real_stdout)
    else:  # (``>&-``: a print vanished; now its first fails, said as a full stdout is)
        from pslog.outputs import ClosedStdout

        sys.stdout = _GuardedStdout(ClosedStdout())
    restore_termination = _termination_interrupts()
    try:
        _release_sigint()  # only now: a KeyboardInterrupt in a C extension's import (numpy,
        # cv2, while add_arguments loads them) surfaces as an ImportError traceback
        check_declared_files(args, say=say)
        # ('-o sim.csv': an MCAP that 'pslog import sim.csv' misreads) after the file checks,
        # as view --save and export check their names: an input, a folder or an existing
        # file named is said as such first (exit 1)
        misnamed = misnamed_session(parser, args)
        if misnamed is not None:
            parser.error(misnamed)
        if name in PROGRESS_COMMANDS:
            from pslog.progress import command_progress

            with command_progress(name):
                code = int(module.run(args) or 0)
        else:
            code = int(module.run(args) or 0)
        if sys.stdout is not None:  # a full stdout fails here, not at the interpreter's exit
            sys.stdout.flush()
        failed = sys.stdout.failed if isinstance(sys.stdout, _GuardedStdout) else None
        if failed is not None:
            # the command ran to its end (its outputs complete, kept): only its report is lost
            import os

            _drop_stdout(real_stdout)
            _, outputs, updates = declared_files(args)
            # (and a file the command updated in place: calibrate's rig; the folders and
            # files of its own a command names, `kept_outputs`: --tum's folder, batch's summary)
            kept_outputs = getattr(module, "kept_outputs", None)
            own = kept_outputs(args) if kept_outputs is not None else []
            made = [p for p in outputs + updates + own if os.path.exists(p)]
            kept = f"; {', '.join(made)} written complete" if made else ""
            print(f"pslog {name}: error: {failed}{kept}", file=sys.stderr)
            return 1
        return code
    except PslogError as exc:
        if isinstance(exc, StdoutError):
            _drop_stdout(real_stdout)
        print(f"pslog {name}: error: {exc}", file=sys.stderr)
        return 1
    except Terminated as exc:
        _close_abandoned_writers()
        print(f"pslog {name}: terminated ({exc.signal_name})", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        _close_abandoned_writers()
        print(f"pslog {name}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (``| head``): nobody to tell
        _drop_stdout(real_stdout)
        return 1
    except OSError as exc:  # an OS fault no writer translated: still one line
        inputs, outputs, updates = declared_files(args)
        print(f"pslog {name}: error: {describe_os_error(exc, outputs + updates, inputs)}",
              file=sys.stderr)
        return 1
    except Exception as exc:
        cause = _out_of_memory(exc)
        if cause is None:
            raise  # a bug: its traceback is what a report needs
        _close_abandoned_writers()
        print(f"pslog {name}: error: out of memory: {cause} (free memory, or process a "
              "shorter session)", file=sys.stderr)
        return 1
    finally:
        sys.stdout = real_stdout
        restore_termination()


def _out_of_memory(exc: BaseException) -> str | None:
    """What ran out, when ``exc`` or an exception it was raised from (``__cause__`` /
    ``__context__``: a module whose import failed half-way, a numba dispatcher's
    ``SystemError``) is a ``MemoryError`` or a thread that could not start (its stack is memory
    too, under ``ulimit -v`` or a container's limit); None otherwise."""
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, MemoryError):
            return str(current) or "an allocation failed"
        if isinstance(current, RuntimeError) and "can't start new thread" in str(current):
            return str(current)
        current = current.__cause__ or current.__context__
    return None


def _close_abandoned_writers() -> None:
    """After a Ctrl-C or SIGTERM: no ``.partial`` of a session writer left open (one the
    interrupt caught before its ``with`` block was entered); only if one was ever made."""
    writer = sys.modules.get("pslog.log.writer")
    if writer is not None:
        writer.close_abandoned()


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP (a closed terminal, a dropped ssh session), raised where a Ctrl-C
    would be: a command's interrupt handling (worker pools shut down, ``.partial`` outputs
    removed) runs for any; the exit code is 128 + the signal's number (143, 129)."""

    def __init__(self, signum: int = 15) -> None:
        super().__init__(signum)
        self.signum = int(signum)

    @property
    def signal_name(self) -> str:
        import signal

        return signal.Signals(self.signum).name


def _raising(make):
    """A signal handler raising ``make(signum)`` in the main thread where it was interrupted,
    unless that is importlib's own code: there an exception can land between a lock's
    acquisition and the ``try`` that releases it, or inside a weakref callback
    (``_get_module_lock``'s ``cb``), where Python prints and drops it — the interrupt was lost
    and the global import lock stayed taken, so every thread's next import waited for ever
    (``pslog fuse`` hung after a SIGTERM while its threads loaded modules). There the signal
    is sent again to the main thread 10 ms later, to be raised somewhere safe."""
    def handler(signum, frame):
        if frame is not None and frame.f_code.co_filename.startswith("<frozen importlib"):
            _deliver_later(signum)
            return
        raise make(signum)

    return handler


def _deliver_later(signum: int, delay_s: float = 0.01) -> None:
    import signal
    import threading

    timer = threading.Timer(delay_s, signal.pthread_kill,
                            (threading.main_thread().ident, signum))
    timer.daemon = True
    timer.start()


def _keyboard_interrupt(signum: int) -> KeyboardInterrupt:
    return KeyboardInterrupt()


def _termination_interrupts():
    """Make SIGTERM and SIGHUP raise :class:`Terminated` in the main thread while a command
    runs (a command that records installs its own stop handler over this one; a SIGHUP that
    is ignored, under ``nohup``, stays ignored); returns the function that puts the previous
    handlers back (callers of ``main()`` in-process)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    raise_terminated = _raising(Terminated)
    previous = {sig: signal.signal(sig, raise_terminated) for sig in (signal.SIGTERM,
                                                                       signal.SIGHUP)
                if signal.getsignal(sig) is not signal.SIG_IGN}

    def restore() -> None:
        for sig, old in previous.items():
            signal.signal(sig, old)

    return restore


class StdoutError(PslogError):
    """Standard output refused a write (full disk, closed): not the fault of any file."""


class _GuardedStdout:
    """``sys.stdout`` that outlives an OS fault of standard output (a full ``> /dev/full``):
    the first is noted in :attr:`failed` and everything after it dropped, so that every
    command runs to its end and keeps its complete outputs (never blamed, never removed half
    way, whenever it prints); the CLI then exits 1 with that one line.
    :class:`BrokenPipeError` (the reader went away) passes as it is."""

    def __init__(self, stream) -> None:
        self._stream = stream
        #: ``cannot write to standard output: <reason>`` once a write failed, else None
        self.failed: str | None = None

    def _guard(self, call, *args, dropped=None):
        if self.failed is not None:
            return dropped
        try:
            return call(*args)
        except BrokenPipeError:
            raise
        except OSError as exc:
            from pslog.outputs import os_reason

            self.failed = f"cannot write to standard output: {os_reason(exc)}"
            return dropped

    def write(self, text: str) -> int:
        return self._guard(self._stream.write, text, dropped=len(text))

    def writelines(self, lines) -> None:
        return self._guard(self._stream.writelines, lines)

    def flush(self) -> None:
        return self._guard(self._stream.flush)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def _drop_stdout(stream) -> None:
    """After standard output failed: point it at the null device, so that the interpreter's
    own flush at exit does not fail again with a second message (as Python's documentation
    on SIGPIPE recommends)."""
    import os

    try:
        fd = stream.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (a test's capture)
        return
    if fd != 1:
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    except OSError:
        pass


def _ignore_file_size_signal() -> None:
    """Ignore SIGXFSZ, so that a write beyond the file-size limit (``ulimit -f``) fails with
    EFBIG, which the writers report in one line, instead of killing the process."""
    import signal
    import threading

    if hasattr(signal, "SIGXFSZ") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


if __name__ == "__main__":
    sys.exit(main())
