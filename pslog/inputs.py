"""Input files: one check for every file a command reads.

A special file (a device such as ``/dev/zero``, a FIFO, a socket) given where a file is
expected would be read for ever or block; a text input (a rig TOML, a CSV of points) far
larger than any real one would be read whole into memory. :func:`check_input_file` refuses
both with one line naming the path and what it is.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from .errors import InputError

#: Largest rig TOML read, bytes: a real rig is a few kilobytes (one table per camera).
MAX_RIG_BYTES = 1 << 20


def file_kind(mode: int) -> str:
    """What a ``stat`` mode names, in words: ``a character device``, ``a FIFO`` ..."""
    for test, words in ((stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a folder"),
                        (stat.S_ISLNK, "a symbolic link"), (stat.S_ISCHR, "a character device"),
                        (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a named pipe"),
                        (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return words
    return "not a regular file"


def binary_format(head: bytes, path: str | Path) -> str | None:
    """``"parquet"`` or ``"c3d"`` when a file's first bytes ``head`` (and, for C3D, whose
    magic is two bytes, its ``.c3d`` suffix) say it is one of the binary files ``pslog
    export`` writes, else None: the text readers name it instead of a byte that is no text.
    Parquet starts with ``PAR1``; C3D with its first parameter block's number (2-127) and
    the key 0x50."""
    if head.startswith(b"PAR1"):
        return "parquet"
    if (len(head) >= 2 and head[1] == 0x50 and 2 <= head[0] < 128
            and str(path).lower().endswith(".c3d")):
        return "c3d"
    return None


def not_there(path: str | Path) -> str | None:
    """Why ``path`` cannot be opened although something may be named so, or None if it can
    be examined or is simply missing (``Path.exists`` is False for both a missing file and
    a loop of symbolic links: "no such file" for a loop, or for a link whose target is gone,
    sends the user looking for a file that is there).

    Returns
    -------
    ``"cannot read P: a loop of symbolic links"``, ``"P is a symbolic link to T, which does
    not exist"``, ``"cannot read P: REASON"`` (another OS error), or None
    """
    try:
        os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            return f"{path} is a symbolic link to {os.readlink(path)}, which does not exist"
        return None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return f"cannot read {path}: a loop of symbolic links"
        return f"cannot read {path}: {exc.strerror or exc}"
    except ValueError:  # a NUL byte in the name: nothing can be named so
        return None
    return None


def special_file(path: str | Path) -> str | None:
    """What ``path`` is (``a character device``) if it exists and is neither a regular file
    nor a folder (links followed); None otherwise (a missing file is for the reader to report)."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    return file_kind(mode)


def check_input_file(path: str | Path, what: str = "", max_bytes: int | None = None) -> Path:
    """``path`` as a :class:`~pathlib.Path` if it is a regular file to read (links followed).

    Parameters
    ----------
    what : what the file is for the message (``"rig file"``); empty: nothing
    max_bytes : largest size accepted (text inputs read whole), None: any size

    Raises
    ------
    InputError : ``path`` is missing, a folder, a device, FIFO or socket, larger than
        ``max_bytes``, or cannot be examined
    """
    path = Path(path)
    label = f"{what} " if what else ""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise InputError(not_there(path) or (f"{label}not found: {path}" if what else
                                             f"no such file: {path}")) from None
    except OSError as exc:
        raise InputError(not_there(path) or f"cannot read {label}{path}: {exc.strerror or exc}"
                         ) from None
    except ValueError as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise InputError(f"cannot read {label}{path}: {reason}") from None
    if stat.S_ISDIR(st.st_mode):
        raise InputError(f"cannot read {label}{path}: it is a folder")
    if not stat.S_ISREG(st.st_mode):
        kind = file_kind(st.st_mode)
        raise InputError(f"{what} {path} is not a regular file ({kind})" if what
                         else f"not a regular file: {path} ({kind})")
    if max_bytes is not None and st.st_size > max_bytes:
        raise InputError(f"{label}{path} is {st.st_size} bytes: too large to be one (at most "
                         f"{max_bytes} bytes)")
    return path
