"""Session 42's hostile probes run ``pslog ARGS`` through session 41's helper
(``benchmarks/session41/hostile/_run.py``: a real process with a timeout, what a user would
see classified as ok, one-line error, traceback, hang or many lines)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

_path = Path(__file__).resolve().parents[2] / "session41" / "hostile" / "_run.py"
_spec = importlib.util.spec_from_file_location("_run_session41", _path)
assert _spec is not None and _spec.loader is not None
_module = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_module)

TREE, ENV, run = _module.TREE, _module.ENV, _module.run

__all__ = ["ENV", "TREE", "run"]
