"""Real operating-system faults for the fault suite: a tiny full tmpfs, a read-only bind
mount, and a child process without one of root's capabilities.

Mounts need ``mount`` (root, or a user namespace); where the machine does not permit it the
test is skipped with the reason. As root, permission bits do not stop a write: an unwritable
folder is made with a read-only mount, or by running the child without CAP_DAC_OVERRIDE
(:func:`drop_capability`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest


def _mount(*args: str) -> None:
    if shutil.which("mount") is None:
        pytest.skip("no mount command on this machine")
    run = subprocess.run(["mount", *args], capture_output=True, text=True, timeout=30)
    if run.returncode != 0:
        pytest.skip(f"cannot mount here ({run.stderr.strip() or run.returncode}): "
                    f"mount {' '.join(args)}")


def _umount(path: Path) -> None:
    subprocess.run(["umount", "-l", str(path)], capture_output=True, timeout=30)


@contextlib.contextmanager
def small_tmpfs(path: Path, size: str = "64k") -> Iterator[Path]:
    """``path`` (created) as a tmpfs of ``size``: a disk that fills up at once."""
    path.mkdir(parents=True, exist_ok=True)
    _mount("-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path))
    try:
        yield path
    finally:
        _umount(path)


def fill(folder: Path, free: int = 0) -> None:
    """Fill the file system of ``folder`` until about ``free`` bytes are left (0: up to the
    last byte)."""
    filler = folder / "filler"
    with contextlib.suppress(OSError), open(filler, "wb", buffering=0) as f:
        while True:
            f.write(b"\0" * 512)
    if free:
        os.truncate(filler, max(0, filler.stat().st_size - free))


@contextlib.contextmanager
def read_only(path: Path) -> Iterator[Path]:
    """The folder ``path`` (created) bind-mounted read-only onto itself."""
    path.mkdir(parents=True, exist_ok=True)
    _mount("--bind", str(path), str(path))
    try:
        _mount("-o", "remount,bind,ro", str(path))
        if not os.statvfs(path).f_flag & os.ST_RDONLY:  # never test "read-only" on a
            pytest.skip(f"the bind mount of {path} stayed writable")  # writable mount
        yield path
    finally:
        _umount(path)


#: capability numbers (linux/capability.h) and prctl's PR_CAPBSET_DROP
CAP_DAC_OVERRIDE, CAP_NET_BIND_SERVICE = 1, 10
_PR_CAPBSET_DROP = 24


def drop_capability(cap: int):
    """A ``preexec_fn`` that drops capability ``cap`` from the child's bounding set before
    it execs, so that root then runs the command like an ordinary user in that respect
    (CAP_DAC_OVERRIDE: refused writes into a mode-555 folder; CAP_NET_BIND_SERVICE: refused
    ports below 1024)."""
    def preexec() -> None:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), f"prctl(PR_CAPBSET_DROP, {cap}) failed")
    return preexec
