"""Recorders: capture sessions from cameras, video files or a rendered synthetic rig.

Public entry points:

- :func:`recorders.record.record` — record any rig from per-camera sources
  (:mod:`recorders.sources`)
- :func:`record_synthetic` — render a rig watching a simulated ball and record it
- :func:`redetect_session` — re-run ball detection over a session's recorded frames
- :class:`BallDetector`, :class:`HsvRange` — colour ball detection (:mod:`recorders.detect`)
- :class:`CameraRenderer`, :class:`RenderOptions` — the synthetic camera (:mod:`recorders.render`)

The names are imported on first use (PEP 562): ``pslog redetect`` needs only the detector,
not the recorder, renderer and simulation (about 40 ms of imports).
"""

from __future__ import annotations

from pslog._lazy import lazy_names

_WHERE = {"BallDetector": "detect", "Candidates": "detect", "HsvRange": "detect",
          "RecordSummary": "record", "RecordWriteError": "record", "StopRequest": "record",
          "redetect_session": "redetect", "CameraRenderer": "render",
          "RenderOptions": "render", "record_synthetic": "synthetic"}

__all__ = sorted(_WHERE, key=str.lower)


__getattr__, __dir__ = lazy_names(__name__, _WHERE)
