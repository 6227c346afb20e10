"""Argument helpers shared by the CLI commands (no heavy imports at module level)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--force", action="store_true", help="overwrite existing output files")


def add_rig(parser: argparse.ArgumentParser, required: bool = True, help_extra: str = "") -> None:
    parser.add_argument(
        "--rig", required=required, metavar="RIG",
        help="built-in rig name (paper3, paper2) or rig TOML file ('pslog rig show paper3 "
             "> rig.toml' writes one to edit)" + help_extra)


def check_output(path: str | Path, force: bool, inputs=()) -> Path:
    """Refuse a folder, a missing parent folder, one of the ``inputs`` (always), or an
    existing file unless ``force``."""
    from pslog.outputs import check_output_path

    return check_output_path(path, force, inputs)


def _float_arg(text: str, ok, requirement: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not ok(value) or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be {requirement}, got {text!r}")
    return value


def positive_float(text: str) -> float:
    return _float_arg(text, lambda v: v > 0, "a positive number")


def nonnegative_float(text: str) -> float:
    return _float_arg(text, lambda v: v >= 0, "a number >= 0")


def seed(text: str) -> int:
    """A random seed: a whole number >= 0 (numpy's generators take no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return value


def fraction(text: str) -> float:
    value = nonnegative_float(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text!r}")
    return value


def installed_command(name: str) -> str:
    """How to start ``name`` (``rerun``, ``pslog``), installed beside this Python, from this
    shell: the bare name when it is on PATH (e.g. the virtual environment is active), else
    its path (``.venv/bin/rerun`` after ``bash run.sh demo``, which does not activate it)."""
    import os
    import shutil
    import sys

    ours = Path(sys.executable).parent / (name + (".exe" if os.name == "nt" else ""))
    if not ours.exists():
        return name
    found = shutil.which(name)
    if found is not None and os.path.samefile(found, ours):
        return name
    try:
        path = os.path.relpath(ours)
    except ValueError:  # another drive on Windows
        return str(ours)
    if path.startswith(os.pardir):
        return str(ours)
    return path if os.sep in path else os.path.join(os.curdir, path)
