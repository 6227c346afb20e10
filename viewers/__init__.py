"""rerun views of pslog sessions (all rerun calls of pslog live in this package).

- :func:`build_recording` — a session (plus fused copies) as a rerun RecordingStream
- :func:`save_rrd` — the same, written to a .rrd file
- :func:`open_sink` — a checked live sink: a viewer window, a served web viewer, a viewer
  running elsewhere (gRPC) or standard output (:mod:`viewers.sinks`)
- :func:`build_blueprint` — the default layout

See :mod:`viewers.recording` for the entity paths and timelines.
"""

from .blueprint import build_blueprint
from .data import FramesChoice, ViewData, load_view_data
from .recording import APPLICATION_ID, build_recording, log_view, new_stream, save_rrd
from .sinks import Sink, open_sink

__all__ = ["APPLICATION_ID", "FramesChoice", "Sink", "ViewData", "build_blueprint",
           "build_recording", "load_view_data", "log_view", "new_stream", "open_sink",
           "save_rrd"]
