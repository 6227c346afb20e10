"""Issue 10 (session 36): ``bench_dirty.py ARGS`` with ``smooth``'s re-admission of the
start's choices in doubt that the fit made without them predicts (``pslog.fusion.smooth.
_confirmed``), or, with ``S36_NOREADMIT=1``, without it (every choice in doubt left out, as
before session 36). ``python benchmarks/session36/straight_bench.py --more --validity
--methods smooth --first-seed 49000 [--fps 60] [--misses 0.1]``.

Run from the repository root (PYTHONPATH=.)."""
import os
import runpy
import sys

import numpy as np

import pslog.fusion.smooth as S

if os.environ.get("S36_NOREADMIT") == "1":
    S._confirmed = lambda trajectory, obs, rows, rig: np.zeros(len(rows), dtype=bool)

if __name__ == "__main__":
    sys.argv = ["benchmarks/bench_dirty.py", *sys.argv[1:]]
    runpy.run_path("benchmarks/bench_dirty.py", run_name="__main__")
