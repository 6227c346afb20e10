"""review46: the Python decider and the compiled one, offline, on many dirty sessions (random
rigs, lenses, rolling shutters, short gaps; ``FORESEE_EMPTIED`` False too): one line a
session, then "bad N", the sessions where they differ (reason codes or decided ratios).

    python review46_deciders.py FIRST_SEED END_SEED
"""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from _rigs import ring_rig
from test_gate_whole import LENS, decided, session

import pslog.fusion._gate_kernel  # noqa: F401
from pslog.fusion import gating
from pslog.rig import Rig, apply_timing, builtin_rig


def config(seed: int):
    rng = np.random.default_rng(seed)
    if seed % 4 == 3:
        fps = float(rng.choice([60.0, 120.0]))
        rig = Rig(tuple(c.replace(fps=fps, offset=i / 400.0)
                        for i, c in enumerate(ring_rig(4, "ring4").cameras)), "ring4")
    else:
        rig = apply_timing(builtin_rig("paper2" if seed % 4 == 2 else "paper3"), "typeA")
    if rng.random() < 0.5:
        rig = Rig(tuple(c.replace(dist=LENS) for c in rig.cameras), rig.name)
    faults: dict = {}
    if rng.random() < 0.6:
        readout = float(rng.uniform(0.005, 0.9 / max(c.fps for c in rig.cameras)))
        faults = {"clock_offset_s": {rig.names[-1]: float(rng.uniform(-0.01, 0.01))},
                  "readout_s": dict.fromkeys(rig.names, readout)}
    gap = {"max_gap_s": float(rng.uniform(0.01, 0.05))} if rng.random() < 0.25 else {}
    if rng.random() < 0.5:
        faults |= {"spurious_rate": float(rng.uniform(0.05, 0.4)),
                   "miss_rate": float(rng.uniform(0.1, 0.5))}
    return rig, faults, gap


def same(a, b) -> bool:
    return np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1], equal_nan=True)


bad = 0
for seed in range(int(sys.argv[1]), int(sys.argv[2])):
    rig, faults, gap = config(seed)
    det, rig = session(seed, rig, duration=3.0, **faults)
    python = decided(det, rig, False, False, **gap)
    whole = decided(det, rig, True, False, **gap)
    gating.FORESEE_EMPTIED = False
    unforeseen = decided(det, rig, False, False, **gap)
    gating.FORESEE_EMPTIED = True
    ok = same(python, whole) and same(python, unforeseen)
    bad += not ok
    print(seed, rig.name, sorted(faults), gap, "rejected", int(np.sum(python[0] >= 0)),
          "OK" if ok else "DIFFERENT", flush=True)
print("bad", bad)
