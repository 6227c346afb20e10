"""Work done in blocks to bound a 90-minute match's memory gives the same bits as all at
once: the gate's decisions (gating._decide_in_order, blocks of frames). (Type A's kink test
is a compiled per-point kernel with no (k,) temporaries: tests/test_kink_kernel.py.)"""

from __future__ import annotations

import numpy as np
from _rally import rally

from pslog import SimulationOptions, apply_timing, builtin_rig
from pslog.fusion import gating as G
from pslog.simulation import simulate_labelled


def _session(seed: int, **faults):
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion = rally(6.0, seed=seed, speed=4.0, kick_every_s=0.9)[0]
    det, _truth, _ = simulate_labelled(rig, motion, 6.0,
                                       SimulationOptions(noise_px=0.3, seed=seed, **faults))
    return det, rig


def test_gate_in_small_blocks_equals_large_ones(monkeypatch):
    """Dirty candidates (spurious blobs, a distractor): frames of several candidates, redone
    supports and decided blocks of every kind, cut at every 5 frames or not at all."""
    det, rig = _session(4, spurious_rate=0.3)
    assert np.max(np.bincount(det.cand_frame)) > 1
    whole = [G.gate(det, rig, causal=c, wait_s=w) for c, w in ((True, 0.0), (False, 0.0),
                                                               (True, 0.001))]
    monkeypatch.setattr(G, "_DECIDE_BLOCK", 5)
    for (c, w), g in zip(((True, 0.0), (False, 0.0), (True, 0.001)), whole, strict=True):
        small = G.gate(det, rig, causal=c, wait_s=w)
        assert small.reason.tobytes() == g.reason.tobytes()
        assert (g.reason >= 0).any()
