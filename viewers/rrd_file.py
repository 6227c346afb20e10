"""Write a rerun recording to a .rrd file safely: OS errors become one clear error, never a hang.

rerun's own file sink (``RecordingStream.save``, rerun-sdk 0.41) writes from a background
thread that reports a failed write (a full disk, an I/O error) only as a log line on stderr;
the stream's flush then never completes and ``disconnect`` hangs for ever. So pslog gives
rerun a named pipe instead of the file and copies the bytes to the file itself: rerun never
sees a failing write, and pslog sees the ``OSError`` (with its path and reason), keeps
draining the pipe so rerun finishes normally, deletes the partial file and raises one
:class:`~pslog.errors.PslogError`. The file is written as ``<name>.partial`` and moved over
``path`` only once complete, so an old .rrd stays until a new one is whole.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sys
import tempfile
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

import rerun as rr

from pslog.outputs import (
    WriteError,
    check_output_path,
    claim_partial,
    open_locked,
    os_reason,
    partial_path,
    release_partial,
    write_error,
)

#: longest wait for rerun to hand over its last bytes after logging, seconds; only a hang
#: (never seen with the pipe) reaches it: the data has streamed out while it was logged
FLUSH_TIMEOUT_S = 60.0
_PIPE_READ = 1 << 20


class RrdWriteError(WriteError):
    """A .rrd file could not be written (folder not writable, disk full, I/O error)."""


def _rrd_error(path: Path, exc: OSError) -> RrdWriteError:
    error = write_error(path, exc)
    return RrdWriteError(str(error), error.reason)


def _remove(path: Path) -> None:
    """Remove the partial ``path`` and its owner file (:func:`pslog.outputs.claim_partial`)."""
    # a read-only file system refuses even to unlink a file that is not there
    with contextlib.suppress(OSError):
        path.unlink(missing_ok=True)
    release_partial(path)


class _Pump:
    """A named pipe that rerun writes to and a thread that copies it to a destination.

    Whatever goes wrong on pslog's side (the destination cannot be written, even reading the
    pipe fails), the pipe is drained to its end: rerun must never block on it or meet a
    broken pipe, which would make its flush and ``disconnect`` hang. Subclasses say where
    the bytes go (:meth:`_write`) and what a failure undoes (:meth:`_fail`), then call
    :meth:`_start`.
    """

    def __init__(self) -> None:
        self.error: OSError | None = None
        self.reading: int | None = None  # the descriptor the pump reads (for tests)
        self._dir = tempfile.mkdtemp(prefix="pslog-rrd-")
        try:
            self.fifo = os.path.join(self._dir, "stream.rrd")
            os.mkfifo(self.fifo, 0o600)
            # a second reader, held from the start: it drains the pipe if reading the first
            # one fails, and lets unblock() open the pipe at any moment
            self._spare = os.open(self.fifo, os.O_RDONLY | os.O_NONBLOCK)
        except OSError:
            self.cleanup()
            raise

    def _start(self) -> None:
        self._thread = threading.Thread(target=self._pump, name="pslog-rrd-writer",
                                        daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        try:
            try:
                with open(self.fifo, "rb", buffering=0) as src:
                    self.reading = src.fileno()
                    self._copy(src.fileno())
            except OSError as exc:  # reading the pipe failed: the output is lost, drain
                self._fail(exc)
                os.set_blocking(self._spare, True)
                with contextlib.suppress(OSError):  # nothing left to drain with
                    while os.read(self._spare, _PIPE_READ):
                        pass
        finally:
            os.close(self._spare)  # the last reader: only now could rerun meet EPIPE
        if self.error is None:
            try:
                self._flush()
            except OSError as exc:
                self._fail(exc)

    def _copy(self, fd: int) -> None:
        while chunk := os.read(fd, _PIPE_READ):
            if self.error is None:
                try:
                    self._write(chunk)
                except OSError as exc:
                    self._fail(exc)
            # after a failure keep draining, so that rerun never blocks

    def _write(self, chunk: bytes) -> None:
        raise NotImplementedError

    def _flush(self) -> None:
        pass

    def _fail(self, exc: OSError) -> None:
        self.error = self.error or exc

    def close(self) -> None:
        """Release the destination."""

    def unblock(self) -> None:
        """Let the pump's ``open`` return when rerun never opened the pipe."""
        with contextlib.suppress(OSError):
            fd = os.open(self.fifo, os.O_WRONLY | os.O_NONBLOCK)
            os.close(fd)

    def join(self, timeout: float) -> bool:
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def cleanup(self) -> None:
        shutil.rmtree(self._dir, ignore_errors=True)


class _PipeToFile(_Pump):
    """A :class:`_Pump` into the file ``partial`` (locked while open), removed on failure."""

    def __init__(self, partial: Path, path: Path) -> None:
        super().__init__()
        self.partial, self.path = partial, path
        try:
            # locked while open: no other pslog run takes it for a stale partial; closed
            # only after it has been moved over ``path`` or removed (close())
            self._out = open_locked(partial, "wb")
            claim_partial(partial, self._out.fileno())  # (a kill's partial: pslog's own)
        except BaseException:  # OSError, or PartialBusyError: another run writes it
            os.close(self._spare)
            self.cleanup()
            raise
        self._start()

    def _write(self, chunk: bytes) -> None:
        self._out.write(chunk)

    def _flush(self) -> None:
        self._out.flush()

    def _fail(self, exc: OSError) -> None:
        super()._fail(exc)
        _remove(self.partial)  # before the lock goes with close()
        self.close()

    def close(self) -> None:
        """Close the partial file (releasing its lock)."""
        with contextlib.suppress(OSError):
            self._out.close()


class _PipeToFd(_Pump):
    """A :class:`_Pump` into an open file descriptor (standard output): a reader that went
    away (EPIPE), a full device (ENOSPC) or a closed descriptor (EBADF) stops the copy, never
    rerun."""

    def __init__(self, fd: int) -> None:
        super().__init__()
        self._fd = fd
        self._start()

    def _write(self, chunk: bytes) -> None:
        view = memoryview(chunk)
        while view:
            view = view[os.write(self._fd, view):]


def _finish(rec: rr.RecordingStream, pipe: _Pump) -> None:
    """End ``rec``'s stream into ``pipe`` in every case, so rerun's writer thread finishes;
    a stuck stream becomes ``pipe.error``."""
    try:
        rec.flush(timeout_sec=FLUSH_TIMEOUT_S)
    except RuntimeError as exc:  # rerun's flush timeout
        pipe.error = pipe.error or OSError(0, f"rerun did not finish writing ({exc})")
    rec.disconnect()  # writes the footer and closes the pipe
    if not pipe.join(FLUSH_TIMEOUT_S):
        pipe.error = pipe.error or OSError(0, "rerun did not close its stream")


@contextlib.contextmanager
def _streamed(rec: rr.RecordingStream, pipe: _Pump) -> Iterator[None]:
    """``rec`` saved into ``pipe``'s named pipe for the ``with`` block, its stream ended in
    every case (:func:`_finish`)."""
    try:
        rec.save(pipe.fifo)
    except BaseException:
        pipe.unblock()
        raise
    try:
        yield
    finally:
        _finish(rec, pipe)


class StdoutWriteError(WriteError):
    """The recording could not be written to standard output (full device, closed)."""


def _stdout_error(reason: str) -> StdoutWriteError:
    return StdoutWriteError(f"cannot write to standard output: {reason}", reason)


@contextlib.contextmanager
def rrd_stdout(rec: rr.RecordingStream) -> Iterator[None]:
    """Stream ``rec`` to standard output while the ``with`` block logs into it.

    rerun's own ``stdout()`` sink meets a failing write (a reader that closed the pipe, a full
    device, a closed descriptor) with colour-coded log lines and a flush that never ends; here
    rerun writes into a named pipe and pslog copies it to standard output, so a failure is an
    ``OSError`` pslog sees while rerun finishes normally.

    Raises
    ------
    BrokenPipeError : the reader of standard output went away (the CLI exits 1 quietly, as
        on any broken pipe)
    StdoutWriteError : any other failed write; the message names standard output and the
        operating system's reason
    """
    from pslog.outputs import stdout_closed

    if stdout_closed():  # closed when Python started: descriptor 1 may be another file
        raise StdoutWriteError("cannot write to standard output: it is closed",
                               "Bad file descriptor")
    try:
        sys.stdout.flush()
        fd = os.dup(sys.stdout.fileno())
    except (OSError, ValueError) as exc:
        raise _stdout_error(os_reason(exc)) from None
    try:
        try:
            pipe = _PipeToFd(fd)
        except OSError as exc:
            raise _stdout_error(os_reason(exc)) from None
        try:
            with _streamed(rec, pipe):
                yield
            if isinstance(pipe.error, BrokenPipeError):
                raise BrokenPipeError(pipe.error.errno, pipe.error.strerror)
            if pipe.error is not None:
                raise _stdout_error(os_reason(pipe.error))
        finally:
            pipe.cleanup()
    finally:
        with contextlib.suppress(OSError):
            os.close(fd)


@contextlib.contextmanager
def rrd_file(rec: rr.RecordingStream, path: str | Path, *, force: bool = False,
             inputs: Iterable[str | Path] = ()) -> Iterator[Path]:
    """Stream ``rec`` to the .rrd ``path`` while the ``with`` block logs into it.

    ``path`` is checked first (:func:`pslog.outputs.check_output_path`: an input is refused,
    an existing file needs ``force``). On leaving the block the stream is flushed (at most
    :data:`FLUSH_TIMEOUT_S`), disconnected (which writes the file's footer) and the complete
    file moved over ``path``. On any error the partial file is removed and an old ``path``
    kept.

    Raises
    ------
    RrdWriteError : the file could not be written; the message names the path and the
        operating system's reason
    """
    path = check_output_path(path, force, inputs)
    partial = partial_path(path)
    if not hasattr(os, "mkfifo"):  # no named pipes (Windows): rerun writes the file itself
        rec.save(partial)
        try:
            yield path
            rec.flush(timeout_sec=FLUSH_TIMEOUT_S)
            rec.disconnect()
        except BaseException:
            _remove(partial)
            raise
        partial.replace(path)
        release_partial(partial)
        return
    try:
        pipe = _PipeToFile(partial, path)
    except OSError as exc:
        _remove(partial)
        raise _rrd_error(path, exc) from None
    try:
        with _streamed(rec, pipe):
            yield path
        if pipe.error is not None:
            raise _rrd_error(path, pipe.error)
        partial.replace(path)
        release_partial(partial)
    except BaseException:
        _remove(partial)
        raise
    finally:
        pipe.close()
        pipe.cleanup()
