"""Real file-system faults for the fault suite: a tiny full tmpfs and a read-only bind mount.

Both need ``mount`` (root, or a user namespace); where the machine does not permit it the
test is skipped with the reason. As root, permission bits do not stop a write, so an
unwritable folder is made with a read-only mount, not ``chmod``.
"""

from __future__ import annotations

import contextlib
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


def fill(folder: Path) -> None:
    """Fill the file system of ``folder`` up to the last byte."""
    with contextlib.suppress(OSError), open(folder / "filler", "wb", buffering=0) as f:
        while True:
            f.write(b"\0" * 512)


@contextlib.contextmanager
def read_only(path: Path) -> Iterator[Path]:
    """The folder ``path`` (created) bind-mounted read-only onto itself."""
    path.mkdir(parents=True, exist_ok=True)
    _mount("--bind", str(path), str(path))
    try:
        _mount("-o", "remount,bind,ro", str(path))
        yield path
    finally:
        _umount(path)
