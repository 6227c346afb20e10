"""pslog: pseudo-stereo 3D ball tracking from cameras whose shutters are offset in time.

The core library (this package) holds geometry, rigs, records, the session log format,
simulation, fusion and evaluation; it never imports ``recorders`` or ``viewers``.
"""

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
from .rig import BUILTIN_RIGS, TIMING_PRESETS, Rig, apply_timing, builtin_rig, load_rig, resolve_rig, save_rig
from .simulate import SimulationOptions, capture_times, simulate

__all__ = [
    "BUILTIN_RIGS", "MOTIONS", "NS", "QUALITY_FIELDS", "TIMING_PRESETS", "Camera", "Detections",
    "FusionError", "InputError", "LogFormatError", "Motion", "Observations", "OutputExistsError",
    "PslogError", "Rig", "RigError", "SimulationOptions", "Track", "Truth", "apply_timing",
    "builtin_rig", "capture_times", "get_motion", "load_rig", "look_at", "resolve_rig",
    "save_rig", "simulate",
]
