"""``benchmarks/bench_dirty.py`` with a held start's ``pb`` from ``PB`` (0: 80b8c27; -1: the
session-47 review). Usage: ``PYTHONPATH=.:tests:benchmarks python
benchmarks/session47/review47_bench_pb.py PB --more --methods filter ...``."""

import runpy
import sys
from pathlib import Path

import pslog.fusion.filter as FM

FM._START_PB = int(sys.argv[1])
bench = Path(__file__).resolve().parents[1] / "bench_dirty.py"
sys.argv = [str(bench), *sys.argv[2:]]
runpy.run_path(str(bench), run_name="__main__")
