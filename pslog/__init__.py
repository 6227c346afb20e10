"""pslog: pseudo-stereo 3D ball tracking from cameras whose shutters are offset in time.

The core library (this package) holds geometry, rigs, records, the session log format,
simulation, fusion and evaluation; it never imports ``recorders`` or ``viewers``.

The public names below are re-exported lazily (PEP 562), so that ``import pslog.cli`` — and
with it ``pslog --help`` — does not load numpy.
"""

from __future__ import annotations

import importlib

#: as ``typing.TYPE_CHECKING`` (type checkers take the name as true) without importing
#: typing, which costs milliseconds before ``pslog`` can hold an early Ctrl-C (pslog.cli)
TYPE_CHECKING = False

_EXPORTS = {
    "api": ("FuseResult", "SyncOutcome", "evaluate", "fuse", "read_session", "sync"),
    "camera": ("Camera", "look_at"),
    "errors": ("FusionError", "InputError", "LogFormatError", "OutputExistsError", "PslogError",
               "RigError"),
    "motion": ("MOTIONS", "Motion", "get_motion"),
    "records": ("NS", "QUALITY_FIELDS", "Detections", "Observations", "Track", "Truth"),
    "rig": ("BUILTIN_RIGS", "TIMING_PRESETS", "Rig", "apply_timing", "builtin_rig", "load_rig",
            "resolve_rig", "save_rig"),
    "simulation": ("SimulationOptions", "capture_times", "simulate"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = [  # noqa: RUF022 (grouped by module, as _EXPORTS)
    "__version__",
    "FuseResult", "SyncOutcome", "evaluate", "fuse", "read_session", "sync",
    "Camera", "look_at",
    "FusionError", "InputError", "LogFormatError", "OutputExistsError", "PslogError", "RigError",
    "MOTIONS", "Motion", "get_motion",
    "NS", "QUALITY_FIELDS", "Detections", "Observations", "Track", "Truth",
    "BUILTIN_RIGS", "TIMING_PRESETS", "Rig", "apply_timing", "builtin_rig", "load_rig",
    "resolve_rig", "save_rig",
    "SimulationOptions", "capture_times", "simulate",
]


def package_version() -> str | None:
    """The installed pslog version, or None when running from an uninstalled source tree."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("pslog")
    except PackageNotFoundError:
        return None


def _source_version() -> str:
    """The version in the source tree's pyproject.toml (an uninstalled checkout)."""
    import re
    from pathlib import Path

    try:
        text = (Path(__file__).resolve().parent.parent / "pyproject.toml").read_text()
    except OSError:
        return "unknown"
    found = re.search(r'^version\s*=\s*"([^"]+)"', text, re.MULTILINE)
    return found.group(1) if found else "unknown"


def __getattr__(name: str):
    if name == "__version__":  # PEP 396's attribute, from the installed metadata
        value = package_version() or _source_version()
        globals()["__version__"] = value
        return value
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module 'pslog' has no attribute {name!r}")
    loaded = importlib.import_module(f".{module}", __name__)
    for exported in _EXPORTS[module]:  # bind the module's names together, once
        globals()[exported] = getattr(loaded, exported)
    return globals()[name]


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


if TYPE_CHECKING:  # for type checkers and IDEs
    __version__: str

    from .api import FuseResult, SyncOutcome, evaluate, fuse, read_session, sync
    from .camera import Camera, look_at
    from .errors import (
        FusionError,
        InputError,
        LogFormatError,
        OutputExistsError,
        PslogError,
        RigError,
    )
    from .motion import MOTIONS, Motion, get_motion
    from .records import NS, QUALITY_FIELDS, Detections, Observations, Track, Truth
    from .rig import (
        BUILTIN_RIGS,
        TIMING_PRESETS,
        Rig,
        apply_timing,
        builtin_rig,
        load_rig,
        resolve_rig,
        save_rig,
    )
    from .simulation import SimulationOptions, capture_times, simulate
