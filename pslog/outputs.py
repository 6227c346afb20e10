"""Output files: never overwrite without ``force``, never leave a half-written replacement.

Every command that writes a file goes through :func:`check_output_path`; writers that may
replace an existing file write a sibling ``<name>.partial`` first and move it over the old
file only once it is complete (:func:`partial_path`), so a failed or killed run leaves the
previous output as it was.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from .errors import InputError, OutputExistsError


def same_file(a: str | Path, b: str | Path) -> bool:
    """True when ``a`` and ``b`` name one existing file, however spelled (``./``, ``..``,
    symbolic links, hard links)."""
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def check_output_path(path: str | Path, force: bool, inputs: Iterable[str | Path] = ()) -> Path:
    """``path`` as a :class:`~pathlib.Path` if a file may be written there.

    ``inputs`` are the files the command reads: an output that is one of them is refused,
    ``force`` or not (an output never replaces an input).

    Raises
    ------
    InputError : ``path`` is a folder, its folder does not exist, or it is one of ``inputs``
    OutputExistsError : ``path`` exists and ``force`` is false
    """
    path = Path(path)
    for source in inputs:
        if same_file(path, source):
            raise InputError(f"output {path} is the input {source}; choose another file "
                             f"(an output never replaces an input)")
    if path.is_dir():
        raise InputError(f"{path} is a folder; give a file name")
    if path.exists() and not force:
        raise OutputExistsError(f"{path} exists; use --force to overwrite it")
    if not path.parent.is_dir():
        raise InputError(f"output folder does not exist: {path.parent}")
    return path


def partial_path(path: Path) -> Path:
    """Where to write a file that will replace ``path`` once complete."""
    return path.with_name(path.name + ".partial")


@contextmanager
def replacing_text_file(path: str | Path, force: bool) -> Iterator[IO[str]]:
    """Open a text file to write in place of ``path``: it becomes ``path`` only when the
    ``with`` block completes; on an error the old file (if any) stays and nothing is left."""
    path = check_output_path(path, force)
    partial = partial_path(path)
    try:
        with open(partial, "w", newline="", encoding="utf-8") as f:
            yield f
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    partial.replace(path)
