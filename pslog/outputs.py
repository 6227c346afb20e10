"""Output files: never overwrite without ``force``, never replace an input, never leave a
half-written replacement, and one-line errors for every operating-system fault.

Every command that writes a file goes through :func:`check_output_path`. Writers write a
sibling ``<name>.partial`` first and move it over the output only once it is complete
(:func:`partial_path`), so a failed or killed run leaves the previous output as it was.

Partial files left by a killed run (the next run meets them):

- a *derived* session (``simulate``, ``import``, ``fuse``, ``redetect``, ``recover``)
  can be made again from its inputs, and its MCAP says it is one, so its stale unfinished
  partial is removed with a one-line notice (:func:`clear_stale_partial`);
- a partial of :func:`replacing` or the .rrd writer (a CSV, JSON, TUM, Parquet, C3D, rig,
  ``recover`` or .rrd output: all made again from their inputs) is marked as pslog's by an
  *owner file* ``<name>.partial.pslog`` naming the partial's device and inode
  (:func:`claim_partial`): a killed run's partial that is still that very file is removed
  with a notice, the owner file with it;
- any other file of that name (a user's own ``notes.csv.partial``, a file put in place of a
  killed run's partial, a complete session) is never deleted: nothing proves pslog made it,
  so writing the output is refused, naming the file; an output named ``*.partial`` is
  refused;
- a partial that may hold a *recording* (``record --force`` killed while replacing a
  session: the only copy of what the cameras saw) is never deleted: writing over it is
  refused, naming it and how to salvage it.

:func:`partial_kind` tells them apart from the file itself (MCAP header and session metadata).
A partial that another pslog is writing right now is neither: every writer holds an exclusive
``flock`` on its partial while it writes (:func:`open_locked`), and a locked partial is left
alone. :func:`replacing` is the one way to write a replacement file.
"""

from __future__ import annotations

import errno
import io
import os
import stat
import struct
import sys
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO

from .errors import InputError, OutputExistsError, PslogError
from .inputs import file_kind

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None  # type: ignore[assignment]  # the usual optional-module idiom


class ClosedStdout(io.TextIOBase):
    """``sys.stdout`` of a command started with standard output closed (``>&-``, where
    Python sets it to None and every ``print`` vanishes: ``pslog eval F >&-`` printed nothing
    and exited 0). Its first write fails, as a full one does, so the CLI says it in one line
    and exits 1 once the command has run to its end (its files complete, kept); never a
    descriptor (1 may be a file the command opened since)."""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        raise OSError(errno.EBADF, "it is closed")

    def flush(self) -> None:
        pass  # nothing was written


def stdout_closed() -> bool:
    """True when standard output was closed as the process started (``>&-``): ``sys.stdout``
    is None, or the CLI's :class:`ClosedStdout` in its guard."""
    stream = sys.stdout
    return stream is None or isinstance(getattr(stream, "_stream", stream), ClosedStdout)


class WriteError(PslogError):
    """The operating system refused a write (full disk, read-only file system, size limit,
    permissions): ``cannot write <path>: <reason>``; ``reason`` holds the OS's words alone."""

    def __init__(self, message: str, reason: str = "") -> None:
        super().__init__(message)
        self.reason = reason or message


def os_reason(exc: BaseException) -> str:
    """The operating system's words for ``exc`` alone (``No space left on device``), without
    the file name and error number Python adds; any other exception's text or type name."""
    if isinstance(exc, WriteError):
        return exc.reason
    strerror = exc.strerror if isinstance(exc, OSError) else None
    return strerror or str(exc) or type(exc).__name__


def write_error(path: str | Path, exc: BaseException) -> WriteError:
    """The one-line error for ``exc`` met while writing ``path`` (the output the user named,
    not its ``.partial``)."""
    reason = os_reason(exc)
    return WriteError(f"cannot write {path}: {reason}", reason)


def same_file(a: str | Path, b: str | Path) -> bool:
    """True when ``a`` and ``b`` name one existing file, however spelled (``./``, ``..``,
    symbolic links, hard links)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


@contextmanager
def native_stderr(into: io.StringIO | None = None) -> Iterator[None]:
    """File descriptor 2 (where C and C++ code writes, not only ``sys.stderr``: FFmpeg,
    inside OpenCV's video reader, ``[mjpeg @ 0x...] No JPEG data found in image``, ``moov
    atom not found`` for a file that is no video) redirected while the block runs: to the
    null device (``into`` None: the command says what went wrong in its own words), or to a
    temporary file whose text is then appended to ``into`` (a batch task's captured
    output). ``sys.stderr`` is flushed first (nothing of pslog's own is lost); the whole
    process's descriptor: for a block no other thread writes in. With no descriptor left,
    nothing is redirected."""
    import tempfile

    sys.stderr.flush()
    try:
        target = open(os.devnull, "wb") if into is None else tempfile.TemporaryFile()
    except OSError:  # (no descriptor left: C's lines then stay)
        yield
        return
    with target:
        try:
            saved = os.dup(2)
        except OSError:
            yield
            return
        try:
            os.dup2(target.fileno(), 2)
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            if into is not None:
                target.seek(0)
                into.write(target.read().decode("utf-8", "replace"))


def _say_stderr(text: str) -> None:
    print(f"pslog: {text}", file=sys.stderr)


def not_a_folder(path: str | Path) -> str:
    """``"PATH is a regular file, not a folder"`` (its kind, :func:`pslog.inputs.file_kind`):
    the words for an output's folder that exists as something else."""
    return f"{path} is {file_kind(os.stat(path).st_mode)}, not a folder"


def check_output_path(path: str | Path, force: bool, inputs: Iterable[str | Path] = (), *,
                      say: Callable[[str], None] | None = None) -> Path:
    """``path`` as a :class:`~pathlib.Path` if a file may be written there.

    ``inputs`` are the files the command reads: an output that is one of them is refused,
    ``force`` or not (an output never replaces an input). A stale ``<path>.partial`` of a
    derived output is removed (``say`` tells the user; default: a line on stderr).

    Raises
    ------
    InputError : ``path`` is a folder or spelled as one (``out.mcap/``), its folder does
        not exist, or it or its ``.partial`` is one of ``inputs``
    OutputExistsError : ``path`` exists and ``force`` is false
    WriteError : the folder is not writable (read-only file system, permissions)
    PartialRecordingError : ``<path>.partial`` may hold an interrupted recording
    PartialBusyError : another process is writing ``<path>.partial``
    """
    inputs = [p for p in inputs if p is not None]
    spelled, path = os.fspath(path), Path(path)  # name files as the user wrote them
    if spelled == "-":
        # the usual spelling of standard output: never a file named "-" by surprise
        raise InputError("output '-': pslog writes files, not standard output; give a file "
                         "name (./- for a file named -)")
    if not path.name:
        # '.', '/', '': a folder by its spelling (and no name to give a .partial)
        raise InputError(f"{spelled} is a folder; give a file name")
    if os.path.basename(spelled) in ("", ".", ".."):
        # 'out.mcap/', 'out.mcap/.': a folder's spelling, which open() refuses (EISDIR);
        # pathlib drops the trailing '/', so a file out.mcap was written (session 32)
        raise InputError(f"{spelled} is spelled as a folder; give a file name")
    partial = partial_path(path)
    for source in inputs:
        if same_file(path, source):
            raise InputError(f"output {spelled} is the input {os.fspath(source)}; choose "
                             f"another file (an output never replaces an input)")
        if same_file(partial, source):
            # the partial is cleared before, and written over while, making the output
            raise InputError(f"output {spelled} is written via {partial}, which is an input "
                             f"({os.fspath(source)}); choose another name for the output")
    if path.name.endswith(".partial"):
        # the name pslog gives a file while writing it: a later run writing the output
        # without the suffix would take this one for its own stale partial
        raise InputError(f"output {spelled} ends in .partial, the name pslog gives files "
                         f"while it writes them; choose another name")
    try:
        st = os.lstat(path)
    except (OSError, ValueError):
        st = None  # missing (or unexaminable: the folder checks below say why)
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            # written through, a link could replace a device or another session; replaced,
            # the link would be lost: refused either way, --force or not
            raise InputError(f"output {spelled} is a symbolic link (to "
                             f"{os.readlink(path)}); give the file's real name or another "
                             f"name")
        if stat.S_ISDIR(st.st_mode):
            raise InputError(f"{path} is a folder; give a file name")
        if not stat.S_ISREG(st.st_mode):
            # a device, FIFO or socket is never replaced by a regular file, --force or not
            raise InputError(f"output {spelled} is {file_kind(st.st_mode)}, not a regular "
                             f"file; pslog writes only regular files")
        if not force:
            raise OutputExistsError(f"{path} exists; use --force to overwrite it")
        if locked_by_another(path):
            raise PartialBusyError(f"{spelled} is being written by another pslog (a recording "
                                   f"in progress?); wait for it to finish or choose another "
                                   f"output")
    folder = path.parent
    if not folder.is_dir():
        if folder.exists():
            raise InputError(f"output folder {not_a_folder(folder)}")
        raise InputError(f"output folder does not exist: {folder}")
    # fail before any long computation rather than after it; access() reports a read-only
    # file system (EROFS) even to root
    if not os.access(folder, os.W_OK | os.X_OK):
        reason = os.strerror(errno.EROFS if _read_only_fs(folder) else errno.EACCES)
        raise WriteError(f"cannot write {path}: {reason} (folder {folder} is not writable)")
    clear_stale_partial(path, say=say)
    return path


def locked_by_another(path: Path) -> bool:
    """True if another process holds the writer's lock on ``path`` (:func:`open_locked`):
    a session being recorded straight into ``path``."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NONBLOCK", 0))
    except OSError:
        return False  # unreadable: the write itself will say why
    try:
        return not _try_lock(fd)
    finally:
        os.close(fd)  # releases the lock taken to test


def _read_only_fs(folder: Path) -> bool:
    try:
        return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except (OSError, AttributeError):
        return False


def check_outputs(outputs: Iterable[str | Path], force: bool, inputs: Iterable[str | Path] = (),
                  *, say: Callable[[str], None] | None = None) -> list[Path]:
    """:func:`check_output_path` for each of a command's ``outputs``, which must also be
    distinct files (two options naming one file would write it twice)."""
    inputs = [p for p in inputs if p is not None]
    checked: list[Path] = []
    for out in outputs:
        for other in checked:
            if _same_name(Path(out), other):
                raise InputError(f"{out} is given as two outputs; give each its own file")
        checked.append(check_output_path(out, force, inputs, say=say))
    return checked


def _same_name(a: Path, b: Path) -> bool:
    return same_file(a, b) or os.path.realpath(a) == os.path.realpath(b)


def partial_path(path: Path) -> Path:
    """Where to write a file that will replace ``path`` once complete."""
    path = Path(path)
    return path.with_name(path.name + ".partial")


class PartialRecordingError(PslogError):
    """``<output>.partial`` may hold the only copy of an interrupted recording."""


class PartialBusyError(PslogError):
    """Another process is writing ``<output>.partial`` right now."""


# ---- stale partial files --------------------------------------------------------------

#: session metadata key (value ``"true"``) of an output made from inputs that still exist
#: (written by :class:`~pslog.log.SessionWriter` with ``on_error="discard"``)
DERIVED_KEY = "derived"
#: MCAP header ``library`` of ``pslog recover`` (which copies its input's metadata as is)
RECOVER_LIBRARY = "pslog recover"
_PEEK = 1 << 20


def partial_kind(path: str | Path) -> str:
    """What a ``.partial`` file left by a killed run holds, from its first bytes.

    Returns
    -------
    ``"empty"`` : nothing written yet (no complete record after the MCAP header)
    ``"derived"`` : an unfinished MCAP made from inputs that still exist: written by
        ``pslog recover`` or with the session metadata ``derived = "true"`` (``simulate``,
        ``import``, ``fuse``, ``redetect``)
    ``"complete"`` : a finished MCAP (closing magic in place): no killed run's partial
    ``"foreign"`` : no MCAP (a CSV or .rrd export's partial, or a user's file of that name:
        nothing in it proves that pslog wrote it)
    ``"recording"`` : any other MCAP, e.g. a recording; it may be the only copy of its data
    """
    from .log import _mcapio as io  # the MCAP record layout, read where it is defined

    with open(path, "rb") as f:
        head = f.read(_PEEK)
        if len(head) >= 2 * len(io.MAGIC) and head.startswith(io.MAGIC):
            f.seek(-len(io.MAGIC), os.SEEK_END)
            if f.read(len(io.MAGIC)) == io.MAGIC:
                return "complete"
    if not head:
        return "empty"
    if len(head) < len(io.MAGIC):
        return "empty" if io.MAGIC.startswith(head) else "foreign"
    if not head.startswith(io.MAGIC):
        return "foreign"  # pslog records only MCAP sessions
    try:
        pos = len(io.MAGIC)
        op, length = struct.unpack_from("<BQ", head, pos)
        if op != io.OP_HEADER or pos + 9 + length > len(head):
            return "recording"
        _profile, at = io._string(head, pos + 9)
        library, _ = io._string(head, at)
        if library == RECOVER_LIBRARY:
            return "derived"
        pos += 9 + length
        if pos + 9 > len(head):
            return "empty"
        op, length = struct.unpack_from("<BQ", head, pos)
        if pos + 9 + length > len(head):
            return "empty"  # the first record after the header never completed
        if op != io.OP_METADATA:
            return "recording"
        _name, at = io._string(head, pos + 9)
        meta, _ = io._string_map(head, at)
    except (struct.error, UnicodeDecodeError, ValueError):
        return "recording"
    return "derived" if meta.get(DERIVED_KEY) == "true" else "recording"



# ---- owner files: a killed run's partial recognised as pslog's own ----------------------

#: first line of an owner file (:func:`claim_partial`)
_OWNER_MAGIC = "pslog partial owner 1"


def owner_path(partial: Path) -> Path:
    """The owner file of ``partial`` (:func:`claim_partial`): ``<partial>.pslog``."""
    return partial.with_name(partial.name + ".pslog")


def claim_partial(partial: Path, fd: int) -> None:
    """Mark ``partial``, open on ``fd`` and locked by this process (:func:`open_locked`), as
    pslog's own: a small owner file ``<partial>.pslog`` names its device and inode (and,
    for people, this process and host). A run killed (SIGKILL, power cut) leaves both; the
    next run writing the same output finds the partial to be the very file a pslog writer
    created (same device and inode: not a user's file of that name, nor one put in its
    place: an inode is not reused while the partial holding it exists) and removes both
    (:func:`clear_stale_partial`). Only for partials of outputs made again from their
    inputs (never a recording's). An existing file of the owner's name is never written
    over: then the partial stays unmarked (after a kill, refused as before).

    The owner file appears whole or not at all (written under a temporary name, then linked
    to its own): a kill at any moment never leaves one that is empty or cut."""
    import socket

    owner = owner_path(partial)
    try:
        st = os.fstat(fd)
        text = (f"{_OWNER_MAGIC}\nfile {partial.name}\ndevice {st.st_dev}\ninode {st.st_ino}\n"
                f"pid {os.getpid()}\nhost {socket.gethostname()}\n").encode()
    except OSError:
        return
    cloexec = getattr(os, "O_CLOEXEC", 0)
    # written under a temporary name, then linked to the owner's name (a kill between the
    # two may leave the small temporary file, never a cut owner file)
    temporary = owner.with_name(f"{owner.name}.{os.getpid()}")
    try:
        out = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | cloexec, 0o644)
    except OSError:
        return
    try:
        os.write(out, text)
        os.close(out)
        out = -1
        os.link(temporary, owner)
    except OSError:
        pass
    finally:
        if out >= 0:
            os.close(out)
        with suppress(OSError):
            temporary.unlink()


def release_partial(partial: Path) -> None:
    """Remove ``partial``'s owner file once the partial is moved over its output or removed
    (:func:`claim_partial`); a missing one is no error."""
    with suppress(OSError):
        owner_path(partial).unlink()


def _owner(partial: Path) -> dict[str, str] | None:
    """The fields of ``partial``'s owner file if it is one pslog wrote, else None."""
    try:
        with open(owner_path(partial), "rb") as f:
            text = f.read(4096).decode("utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    lines = text.splitlines()
    if not lines or lines[0] != _OWNER_MAGIC:
        return None
    return dict(line.split(" ", 1) for line in lines[1:] if " " in line)


def owned_by_pslog(partial: Path) -> dict[str, str] | None:
    """The owner file's fields if ``partial`` is the very file a pslog writer created and
    marked (:func:`claim_partial`), else None."""
    owner = _owner(partial)
    if owner is None:
        return None
    try:
        st = os.lstat(partial)
    except OSError:
        return None
    if not stat.S_ISREG(st.st_mode):
        return None
    if (owner.get("file") != partial.name or owner.get("device") != str(st.st_dev)
            or owner.get("inode") != str(st.st_ino)):
        return None
    return owner


def _clear_stale_temporaries(partial: Path) -> None:
    """Owner files' temporaries (:func:`claim_partial`) of ``partial`` left by runs killed
    while marking it (``<partial>.pslog.<pid>``, pslog's by their contents, their process
    gone): removed."""
    import glob

    owner = owner_path(partial)
    for name in glob.glob(glob.escape(os.fspath(owner)) + ".*"):
        temporary = Path(name)
        pid = temporary.name.rsplit(".", 1)[1]
        if not pid.isdigit() or _alive(int(pid)):
            continue
        try:
            with open(temporary, "rb") as f:
                head = f.read(4096).decode("utf-8")
        except (OSError, UnicodeDecodeError):
            continue
        if head.startswith(f"{_OWNER_MAGIC}\nfile {partial.name}\n"):
            with suppress(OSError):
                temporary.unlink()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OSError, OverflowError):
        return True  # (another user's process: alive)
    return True


def _clear_stale_owner(partial: Path) -> None:
    """An owner file of pslog's whose partial is gone (a run killed between moving the
    partial and removing its owner file, or the partial deleted by hand): it marks nothing,
    removed (else it would keep the next partial of that name from being marked)."""
    if _owner(partial) is not None:
        release_partial(partial)


def _try_lock(fd: int) -> bool:
    """Take the exclusive advisory lock of an open file without waiting; False if another
    process holds it (a pslog writing that file now)."""
    if fcntl is None:  # no flock (Windows): no concurrent-run protection
        return True
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError:  # a file system without locks (ENOLCK, EOPNOTSUPP): write unprotected
        return True
    return True


def _busy(partial: Path) -> PartialBusyError:
    return PartialBusyError(f"another pslog is writing {partial}; wait for it to finish or "
                            f"choose another output")


def clear_stale_partial(path: str | Path, *, say: Callable[[str], None] | None = None) -> None:
    """Deal with ``<path>.partial`` left by an interrupted run before writing ``path``.

    A partial that a running pslog is writing (it holds the file's lock, see
    :func:`open_locked`) is left alone: :class:`PartialBusyError`. Only a file that pslog
    provably made is removed (``say`` is told): an empty one or an unfinished derived MCAP
    (:func:`partial_kind`). Any other is kept and refused with a
    :class:`PartialRecordingError` saying what it is: one that may hold a recording, a
    complete session, or a file that is no MCAP (a killed CSV or .rrd export's, or a
    user's own file of that name: nothing shows which, so it is never deleted).
    """
    partial = partial_path(Path(path))
    _clear_stale_temporaries(partial)
    if not partial.is_file():
        if not os.path.lexists(partial):
            _clear_stale_owner(partial)
        return
    try:
        f = open(partial, "rb")
    except FileNotFoundError:
        _clear_stale_owner(partial)
        return
    except OSError as exc:
        raise PartialRecordingError(f"{partial} exists (left by an interrupted run) and "
                                    f"cannot be read: {os_reason(exc)}; move it away") from None
    with f:  # the lock is held until the partial is gone (or kept)
        if not _try_lock(f.fileno()):
            raise _busy(partial)
        owner = owned_by_pslog(partial)
        try:
            kind = "owned" if owner is not None else partial_kind(partial)
        except OSError as exc:
            raise PartialRecordingError(f"{partial} exists (left by an interrupted run) and "
                                        f"cannot be read: {os_reason(exc)}; move it away"
                                        ) from None
        if kind == "recording":
            raise PartialRecordingError(
                f"{partial} exists: left by an interrupted recording, it may hold the only "
                f"copy of recorded data; salvage it into a new file with 'pslog recover "
                f"{partial} -o SAVED.mcap', or move it away, before writing {path}")
        if kind == "complete":
            raise PartialRecordingError(
                f"{partial} exists and is a complete session (not one pslog was writing); "
                f"rename it or move it away before writing {path}")
        if kind == "foreign":
            raise PartialRecordingError(
                f"{partial} exists (left by an interrupted run, or a file of yours): pslog "
                f"writes {path} via that name and cannot tell it made it; delete it or move "
                f"it away before writing {path}")
        try:
            partial.unlink()
        except FileNotFoundError:
            return
        except OSError as exc:
            raise write_error(partial, exc) from None
        if owner is not None:
            release_partial(partial)
    by = (f" (process {owner['pid']})" if owner is not None and owner.get("pid", "").isdigit()
          else "")
    (say or _say_stderr)(f"removed {partial} left by an interrupted run{by}")


# ---- writing ---------------------------------------------------------------------------

def open_locked(path: str | Path, mode: str = "wb", **open_kwargs) -> IO:
    """Open ``path`` to write from its start (created, emptied) holding an exclusive
    ``flock`` for as long as it stays open: while a writer holds it, no other pslog run
    takes the file for a stale partial (:func:`clear_stale_partial`) or writes it too.

    The lock is taken before the file is emptied, so a file another run is writing is left
    as it is. Every writer of a partial file opens it here (:func:`replacing`,
    :class:`~pslog.log.SessionWriter`, the .rrd writer).

    Raises
    ------
    PartialBusyError : another process holds the lock
    OSError : the file cannot be created or opened
    """
    if "w" not in mode:
        raise ValueError(f"open_locked writes: mode must contain 'w', got {mode!r}")
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o666)
    try:
        if not _try_lock(fd):
            raise _busy(Path(path))
        os.ftruncate(fd, 0)
        return os.fdopen(fd, mode, **open_kwargs)
    except BaseException:
        os.close(fd)
        raise


#: the open all_or_nothing blocks' lists of (file, partial, output) written complete
_STAGED: list[list[tuple[IO, Path, Path]]] = []
#: the open all_or_nothing blocks' lists of old outputs to remove once all moves are done
_OBSOLETE: list[list[Path]] = []


def remove_when_done(path: Path) -> None:
    """Remove ``path``, an old output of pslog's that the new outputs make obsolete (an
    earlier TUM export's ``<method>.tum`` for a method the new one lacks): inside
    :func:`all_or_nothing` only once every new file is in place (a failed run keeps it),
    else at once. A file already gone is no error."""
    if _OBSOLETE:
        _OBSOLETE[-1].append(Path(path))
        return
    try:
        Path(path).unlink()
    except FileNotFoundError:
        pass
    except OSError as exc:
        raise write_error(path, exc) from None


@contextmanager
def all_or_nothing() -> Iterator[None]:
    """A command with several outputs replaces all of them or none: inside the block, each
    file written with :func:`replacing` stays a complete ``.partial`` (its lock held) and is
    moved over its output only when the whole block has completed. On any error or signal
    (KeyboardInterrupt) every partial is removed and every old output stays as it was. The
    moves themselves run with SIGINT, SIGTERM and SIGHUP held back (acted on once all are
    done), so a signal never leaves some outputs new and some old. Nested blocks join the
    outermost."""
    if _STAGED:
        yield
        return
    staged: list[tuple[IO, Path, Path]] = []
    obsolete: list[Path] = []
    _STAGED.append(staged)
    _OBSOLETE.append(obsolete)
    moved = 0
    try:
        try:
            yield
        finally:
            _STAGED.remove(staged)
            _OBSOLETE.remove(obsolete)
        with signals_held():
            for _f, partial, path in staged:
                try:
                    partial.replace(path)
                except OSError as exc:
                    raise write_error(path, exc) from None
                moved += 1
                release_partial(partial)
            for old in obsolete:  # (remove_when_done)
                remove_when_done(old)
    except BaseException:
        for _f, partial, _path in staged[moved:]:
            with suppress(OSError):
                partial.unlink()
            release_partial(partial)
        raise
    finally:
        for f, _partial, _path in staged:
            with suppress(OSError):
                f.close()


@contextmanager
def signals_held() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP noted, not acted on, while the block runs; then the
    handlers that were there are called for those that came (in the main thread; elsewhere
    signals are not Python's to handle and the block simply runs)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    came: list[int] = []
    names = [getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)]
    previous = {sig: signal.signal(sig, lambda signum, _frame: came.append(signum))
                for sig in names}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    for signum in came:
        handler = previous[signum]
        if callable(handler):
            handler(signum, None)
        elif handler == signal.SIG_DFL:
            signal.raise_signal(signum)


@contextmanager
def replacing(path: str | Path, mode: str = "w", *, force: bool = False,
              inputs: Iterable[str | Path] = ()) -> Iterator[IO]:
    """Open a file to write in place of ``path`` (text mode writes UTF-8 with no newline
    translation): checked first (:func:`check_output_path`), written as ``<path>.partial``
    under the writer's lock (:func:`open_locked`), moved over ``path`` only when the
    ``with`` block completes. On any error the partial is removed, an old ``path`` stays,
    and an OS fault is a :class:`WriteError` naming ``path``."""
    path = check_output_path(path, force, inputs)
    partial = partial_path(path)
    text = {} if "b" in mode else {"newline": "", "encoding": "utf-8"}
    try:
        f = open_locked(partial, mode, **text)
    except OSError as exc:
        raise write_error(path, exc) from None
    claim_partial(partial, f.fileno())  # (made again from its inputs: a kill's is pslog's)
    staged = _STAGED[-1] if _STAGED else None
    try:
        try:
            yield f
            f.flush()
            if staged is not None:  # moved with the others at the end (all_or_nothing)
                staged.append((f, partial, path))
            else:
                # moved, or removed below, while the lock is held: another run never sees
                # a complete-looking partial that it could take for stale
                partial.replace(path)
                release_partial(partial)
        except OSError as exc:
            if exc.filename is not None and os.fsdecode(exc.filename) not in (
                    os.fspath(partial), os.fspath(path)):
                raise  # about another file (an input): not ours to name
            raise write_error(path, exc) from None
    except BaseException:
        with suppress(OSError):
            partial.unlink()
        release_partial(partial)
        with suppress(OSError):
            f.close()
        raise
    if staged is not None:
        return  # still open (its lock held) until all_or_nothing moves it
    try:
        f.close()
    except OSError as exc:
        raise write_error(path, exc) from None


#: OS error numbers that mean "this write cannot succeed here"
WRITE_ERRNOS = frozenset(e for e in (errno.ENOSPC, errno.EFBIG, errno.EROFS, errno.EACCES,
                                     errno.EPERM, getattr(errno, "EDQUOT", None), errno.EIO)
                         if e is not None)


def describe_os_error(exc: OSError, outputs: Iterable[str | Path] = (),
                      inputs: Iterable[str | Path] = ()) -> str:
    """One line for an OSError no writer translated: names the file (an output's
    ``.partial`` by the output's name) or, for a write fault without a file name, the
    command's outputs."""
    reason = os_reason(exc)
    out_paths = [Path(p) for p in outputs]
    name = exc.filename
    if name is not None:
        name = os.fsdecode(name) if isinstance(name, bytes) else str(name)
        for out in out_paths:
            if name in (str(out), str(partial_path(out))):
                return f"cannot write {out}: {reason}"
        return f"{name}: {reason}"
    if exc.errno in WRITE_ERRNOS and out_paths:
        return f"cannot write {' or '.join(map(str, out_paths))}: {reason}"
    in_names = [str(p) for p in inputs if os.path.exists(p)]  # not a built-in rig's name
    if in_names:  # a read fault without a file name: name what the command reads
        return f"cannot read {' or '.join(in_names)}: {reason}"
    return reason
