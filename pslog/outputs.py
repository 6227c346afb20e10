"""Output files: never overwrite without ``force``, never leave a half-written replacement.

Every command that writes a file goes through :func:`check_output_path`; writers that may
replace an existing file write a sibling ``<name>.partial`` first and move it over the old
file only once it is complete (:func:`partial_path`), so a failed or killed run leaves the
previous output as it was.
"""

from __future__ import annotations

from pathlib import Path

from .errors import InputError, OutputExistsError


def check_output_path(path: str | Path, force: bool) -> Path:
    """``path`` as a :class:`~pathlib.Path` if a file may be written there.

    Raises
    ------
    InputError : ``path`` is a folder, or its folder does not exist
    OutputExistsError : ``path`` exists and ``force`` is false
    """
    path = Path(path)
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
