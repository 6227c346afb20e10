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

import importlib

_WHERE = {"BallDetector": "detect", "Candidates": "detect", "HsvRange": "detect",
          "RecordSummary": "record", "RecordWriteError": "record", "StopRequest": "record",
          "redetect_session": "redetect", "CameraRenderer": "render",
          "RenderOptions": "render", "record_synthetic": "synthetic"}

__all__ = sorted(_WHERE, key=str.lower)


def __getattr__(name: str):
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'recorders' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))
