"""rerun views of pslog sessions (all rerun calls of pslog live in this package).

- :func:`build_recording` — a session (plus fused copies) as a rerun RecordingStream
- :func:`save_rrd` — the same, written to a .rrd file
- :func:`build_blueprint` — the default layout

See :mod:`viewers.recording` for the entity paths and timelines.
"""

from .blueprint import build_blueprint
from .data import FramesChoice, ViewData, load_view_data
from .recording import APPLICATION_ID, build_recording, log_view, new_stream, save_rrd

__all__ = ["APPLICATION_ID", "FramesChoice", "ViewData", "build_blueprint", "build_recording",
           "load_view_data", "log_view", "new_stream", "save_rrd"]
