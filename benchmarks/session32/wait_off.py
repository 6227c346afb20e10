"""Run a benchmark script with type A's innovation wait off (``confirm.WAIT_SIGMAS = None``,
as before session 32): the 'before' of a before/after in one tree.

    PYTHONPATH=. python benchmarks/session32/wait_off.py benchmarks/bench_dirty.py --more ...
"""
from __future__ import annotations

import runpy
import sys

import pslog.fusion.confirm as confirm

confirm.WAIT_SIGMAS = None
script = sys.argv[1]
sys.argv = sys.argv[1:]
runpy.run_path(script, run_name="__main__")
