"""Recorders: capture sessions from cameras, video files or a rendered synthetic rig.

Public entry points:

- :func:`recorders.record.record` — record any rig from per-camera sources
  (:mod:`recorders.sources`)
- :func:`record_synthetic` — render a rig watching a simulated ball and record it
- :func:`redetect_session` — re-run ball detection over a session's recorded frames
- :class:`BallDetector`, :class:`HsvRange` — colour ball detection (:mod:`recorders.detect`)
- :class:`CameraRenderer`, :class:`RenderOptions` — the synthetic camera (:mod:`recorders.render`)
"""

from .detect import BallDetector, Candidates, HsvRange
from .record import RecordSummary, RecordWriteError, StopRequest
from .redetect import redetect_session
from .render import CameraRenderer, RenderOptions
from .synthetic import record_synthetic

__all__ = ["BallDetector", "CameraRenderer", "Candidates", "HsvRange", "RecordSummary",
           "RecordWriteError", "RenderOptions", "StopRequest", "record_synthetic",
           "redetect_session"]
