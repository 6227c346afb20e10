# ruff: noqa: E501
"""Session 48: free-running cameras, whose rig leaves the shutter offsets at 0, fused after
``pslog sync`` with the phases it measures (``--phases measure``, the default) against the
rig's zeros (``--phases keep``) and against the truth (the true offsets and clocks).

bench_dirty ``--more``'s rigs but ``paper2`` (paper3, lab3, lab4, wide3), its rallies and
faults (spurious blobs, a static object, a 0.5 s blackout), 0.3 px, ``MISSES`` of the frames
missed (half as many dropped). The shutters: ``typeA`` (the stagger) or ``random`` (each
camera's phase drawn uniformly in its period, per session). Every camera but the first has
its clock off by a uniform ±8 ms; the session's rig holds offsets 0 and clocks 0, and
``pslog.sync(estimate="offset")`` (the clocks have no drift or readout here) estimates the
clocks and measures the phases. Fused with typeA and filter as ``pslog fuse`` does.

Per rig and method: points beyond 5 cm, mean error (mm), points output, for the three rigs;
and the phases' error (measured − true, relative to the first camera, ms: largest |x|).
Usage: phases.py FIRST NSEEDS MISSES typeA|random"""
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, "benchmarks")
import bench_dirty as B

from pslog.api import sync
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.log.reader import Session
from pslog.rig import Rig
from pslog.simulation import SimulationOptions, simulate_labelled

METHODS = ["typeA", "filter"]


def main():
    first, nseeds, misses, shutters = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
    print(f"phases: seeds {first}..{first + nseeds - 1}, misses {misses:g}, shutters {shutters}, faults, 0.3 px")
    print("| rig | method | far > 5 cm: truth / phases measured / offsets 0 | mean mm: truth / measured / 0 | points: truth / measured / 0 |")
    print("|---|---|---|---|---|")
    total = {m: np.zeros(3, dtype=np.int64) for m in METHODS}
    worst_phase = 0.0
    start = time.perf_counter()
    for rig0 in B.rigs() + B.more_rigs()[1:]:
        acc = {m: [[0, 0, 0], [[], [], []], [0, 0, 0]] for m in METHODS}
        for k in range(nseeds):
            mseed = first + k
            seed = mseed - 300
            g = np.random.default_rng(mseed)
            if shutters == "random":
                offsets = [float(g.uniform(0, c.frame_period)) for c in rig0.cameras]
            else:
                offsets = [c.offset for c in rig0.cameras]
            true_rig = Rig(tuple(c.replace(offset=o) for c, o in zip(rig0.cameras, offsets, strict=True)), rig0.name)
            clocks = {c.name: float(g.uniform(-8e-3, 8e-3)) for c in rig0.cameras[1:]}
            motion, _ = B.dirty_rally(mseed, 8.0)
            det, truth, _ = simulate_labelled(true_rig, motion, 8.0, SimulationOptions(
                noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2,
                clock_offset_s=clocks, **B.faults(true_rig, seed, 8.0)))
            zero = Rig(tuple(c.replace(offset=0.0) for c in rig0.cameras), rig0.name)
            session = Session(Path(f"{rig0.name}-{mseed}"), zero, det, None, {}, "sync", {}, [], 0)
            outcome = sync(session, "offset")
            measured = np.array([c.offset for c in outcome.rig.cameras])
            periods = np.array([c.frame_period for c in rig0.cameras])
            rel_true = (np.array(offsets) - offsets[0]) % periods
            miss = (measured - rel_true + periods / 2) % periods - periods / 2
            worst_phase = max(worst_phase, float(np.max(np.abs(miss))))
            oracle = Rig(tuple(c.replace(clock_offset=clocks.get(c.name, 0.0)) for c in true_rig.cameras), rig0.name)
            for j, fuse_rig in enumerate((oracle, outcome.rig, outcome.result.rig)):
                tracks = B._fused(det, fuse_rig, METHODS, FusionOptions())
                for m in METHODS:
                    e = errors_m(tracks[m], truth)
                    acc[m][0][j] += int(np.sum(e > 0.05))
                    acc[m][1][j].append(e[np.isfinite(e)])
                    acc[m][2][j] += len(e)
        for m in METHODS:
            far, errs, pts = acc[m]
            means = [1e3 * np.mean(np.concatenate(x)) for x in errs]
            total[m] += np.array(far)
            print(f"| {rig0.name} | {m} | {' / '.join(map(str, far))} | {' / '.join(f'{x:.3f}' for x in means)} | {' / '.join(map(str, pts))} |", flush=True)
    for m in METHODS:
        print(f"all rigs, {m}: far truth / measured / 0 = {' / '.join(map(str, total[m]))}")
    print(f"largest phase error (measured − true, relative to the first camera): {worst_phase * 1e3:.3f} ms; {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
