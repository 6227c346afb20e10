# ruff: noqa: E501
"""Issue 10 (session 37, scan37), measurement only (not a change): the stillness image
test's ``held`` (a frame where the candidate's support held: its point finite) counting
also a frame where two or more supports' rays missed (no point) but one support alone
made a point — "two supports whose rays miss count as one" (docs/methods.md, "The
decision") applied to ``_still_alone``'s continuity. Batch gates only (both forms, the
numpy and compiled ``_static`` alike take the ``finite`` column patched here); the stream
gates are not patched. Runs ``scan_heldout37.py scan`` or ``scan_motion37.py`` so.

    PYTHONPATH=. python benchmarks/session37/scan_held37.py heldout|motion ARGS...
"""
import inspect
import runpy
import sys
import textwrap

import numpy as np

import pslog.fusion.gating as G

_SRC = textwrap.dedent(inspect.getsource(G._static)).replace(
    "finite = np.isfinite(points).all(axis=-1)  # (C,) whether each candidate has a point",
    "finite = np.isfinite(points).all(axis=-1) | _HELD[0]")
assert "_HELD" in _SRC
_HELD = [None]
G._HELD = _HELD
exec(compile(_SRC, G.__file__, "exec"), G.__dict__)
_static_held = G._static
_points = G._points


def _points_held(c, rig, ratio, carried, constants=None):
    points, in_front, miss = _points(c, rig, ratio, carried, constants)
    options_track_m = G.GatingOptions().track_m
    held = np.zeros(len(ratio), dtype=bool)
    with np.errstate(invalid="ignore"):
        several = np.count_nonzero(ratio <= 1.0, axis=1) >= 2
    rows = np.flatnonzero(several & (miss > options_track_m))
    if len(rows):
        for b in range(ratio.shape[1]):
            alone = np.full_like(ratio[rows], np.inf)
            alone[:, b] = ratio[rows, b]
            sub = G._Candidates(**{k: getattr(c, k)[rows] for k in c.__dataclass_fields__}) if hasattr(c, "__dataclass_fields__") else None
            if sub is None:
                raise SystemExit("_Candidates is not a dataclass")
            p, _, m = _points(sub, rig, alone, carried[rows], constants)
            held[rows] |= np.isfinite(p).all(axis=1) & (m <= options_track_m)
    _HELD[0] = held
    return points, in_front, miss


G._points = _points_held

if __name__ == "__main__":
    what = sys.argv[1]
    sys.argv = [sys.argv[0], *sys.argv[2:]]
    runpy.run_path(f"benchmarks/session37/scan_{'heldout37' if what == 'heldout' else 'motion37'}.py", run_name="__main__")
