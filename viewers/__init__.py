"""rerun views of pslog sessions (all rerun calls of pslog live in this package).

- :func:`build_recording` — a session (plus fused copies) as a rerun RecordingStream
- :func:`save_rrd` — the same, written to a .rrd file
- :func:`open_sink` — a checked live sink: a viewer window, a served web viewer, a viewer
  running elsewhere (gRPC) or standard output (:mod:`viewers.sinks`)
- :func:`build_blueprint` — the default layout

See :mod:`viewers.recording` for the entity paths and timelines.
"""

from __future__ import annotations

from pslog._lazy import lazy_names

#: public name -> its submodule. Imported on first use (PEP 562): ``pslog view``'s argument
#: parsing (``--help``, a usage error) needs :mod:`viewers.sinks`' flags only, not rerun and
#: the session reader (over a CPU second of imports per process)
_WHERE = {"build_blueprint": "blueprint", "FramesChoice": "data", "ViewData": "data",
          "load_view_data": "data", "APPLICATION_ID": "recording",
          "build_recording": "recording", "log_view": "recording", "new_stream": "recording",
          "save_rrd": "recording", "Sink": "sinks", "open_sink": "sinks"}

__all__ = sorted(_WHERE)


__getattr__, __dir__ = lazy_names(__name__, _WHERE)
