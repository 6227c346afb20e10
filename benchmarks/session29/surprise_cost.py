# ruff: noqa: E501
"""Cost of ``FilterOptions.surprise_cov`` (session 29): paired and interleaved in one
process, off against on. Batch: ``fuse_filter`` on 2-minute sessions of bench_filter's
throughput (paper3, the library's rally at 0.5 px and the tests' kicked rally at 0.3 px),
CPU time, ROUNDS rounds alternating (median, min). Streaming: bench_filter's latency session
(3 cameras, the tests' kicked rally, 20 s), every detection pushed into ``BallFilter``, the
median CPU time per detection of each round, rounds alternating.
Usage: surprise_cost.py [ROUNDS]"""
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
from _rally import rally
from bench_filter import bench_rig

from pslog import SimulationOptions, get_motion, simulate
from pslog.fusion.filter import BallFilter, FilterOptions, fuse_filter
from pslog.rig import apply_timing, builtin_rig


def main():
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 7
    on, off = FilterOptions(), replace(FilterOptions(), surprise_cov=False)
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    kicked, _ = rally(120.0, seed=3)
    for name, motion, noise in (("library rally", get_motion("rally"), 0.5), ("kicked rally", kicked, 0.3)):
        obs = simulate(rig, motion, 120.0, SimulationOptions(noise_px=noise, seed=1))[0].best()
        fuse_filter(obs.select(slice(0, 50)), rig, options=on)
        times = {"off": [], "on": []}
        for _ in range(rounds):
            for label, opts in (("off", off), ("on", on)):
                start = time.process_time()
                fuse_filter(obs, rig, options=opts)
                times[label].append(time.process_time() - start)
        print(f"batch {name} ({len(obs):,} detections): " + ", ".join(
            f"{k} median {np.median(v):.3f} s (min {np.min(v):.3f})" for k, v in times.items()), flush=True)
    lrig = bench_rig(3)
    motion, _ = rally(20.0, seed=3)
    obs = simulate(lrig, motion, 20.0, SimulationOptions(noise_px=0.3, seed=5))[0].best()
    rows = list(zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(), strict=True))
    med = {"off": [], "on": []}
    for _ in range(rounds):
        for label, opts in (("off", off), ("on", on)):
            flt = BallFilter(lrig, opts)
            cpu = np.empty(len(rows))
            for i, (t, c, uv) in enumerate(rows):
                s = time.process_time_ns()
                flt.push(t, c, uv[0], uv[1])
                cpu[i] = time.process_time_ns() - s
            med[label].append(np.median(cpu) / 1e3)
    print(f"BallFilter.push ({len(rows):,} detections): " + ", ".join(
        f"{k} median of medians {np.median(v):.1f} µs ({np.min(v):.1f}-{np.max(v):.1f})" for k, v in med.items()))


if __name__ == "__main__":
    main()
