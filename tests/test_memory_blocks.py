"""Work done in blocks to bound a 90-minute match's memory gives the same bits as all at
once: type A's kink test (innovation.kinked_points, blocks of events) and the gate's
decisions (gating._decide_in_order, blocks of frames)."""

from __future__ import annotations

import numpy as np
from _rally import rally

from pslog import SimulationOptions, apply_timing, builtin_rig
from pslog.fusion import FusionOptions, innovation
from pslog.fusion import gating as G
from pslog.fusion.gating import fuse_detections
from pslog.simulation import simulate_labelled


def _session(seed: int, **faults):
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion = rally(6.0, seed=seed, speed=4.0, kick_every_s=0.9)[0]
    det, _truth, _ = simulate_labelled(rig, motion, 6.0,
                                       SimulationOptions(noise_px=0.3, seed=seed, **faults))
    return det, rig


def _same(a, b) -> None:
    assert a.time_ns.tobytes() == b.time_ns.tobytes()
    assert a.position_world.tobytes() == b.position_world.tobytes()
    assert set(a.quality) == set(b.quality)
    for k in a.quality:
        assert a.quality[k].tobytes() == b.quality[k].tobytes(), k
    assert a.dropped == b.dropped


def test_kink_test_in_blocks_equals_all_at_once(monkeypatch):
    det, rig = _session(3)
    whole, _ = fuse_detections(det, rig, ["typeA"], FusionOptions())
    assert whole["typeA"].dropped.get("kink", 0) > 0  # the test refuses points here
    monkeypatch.setattr(innovation, "_KINK_BLOCK", 37)
    blocks, _ = fuse_detections(det, rig, ["typeA"], FusionOptions())
    _same(blocks["typeA"], whole["typeA"])


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
