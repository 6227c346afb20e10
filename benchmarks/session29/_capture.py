"""Session 29's measurement scripts (hold_lag, hold_run, surprise): the filter's own inputs
of a ``pslog fuse``-like run captured. Importing this module wraps
:func:`pslog.fusion.filter.fuse_filter` so that each call leaves its arguments ``(obs, rig,
max_gap_s, options, doubt)`` in ``cap["a"]``; ``orig`` is the unwrapped function, to fuse
them again with other options."""
from pslog.fusion import filter as FM

cap: dict = {}
orig = FM.fuse_filter


def capture(obs, rig, max_gap_s=None, options=None, doubt=None):
    cap["a"] = (obs, rig, max_gap_s, options, doubt)
    return orig(obs, rig, max_gap_s, options, doubt)


FM.fuse_filter = capture
