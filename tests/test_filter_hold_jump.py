"""``filter``: a held point withdrawn when the next camera's jump may lie before it
(``FilterOptions.hold_jump_p``; issue 10, session 31; docs/methods.md "A point held for the
next camera": "The jump's lag is a probability").

Session 31's held-out sweep (bench_dirty ``--more``'s sessions, first seeds 27000-27800):
10 of the 12 far points (> 5 cm) the filter output were the first detection 8-16 ms after a
kick along that camera's ray, held (NIS > 2) or not, whose next other camera's detection
made the jump but placed it after the held detection (lag 0), so session 29's rule (the
winner's lag) released it. The jump's hypotheses that place it before the held detection
passed too, with a posterior weight the rule now reads.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from _rally import dirty_rally

from pslog import SimulationOptions, apply_timing, builtin_rig
from pslog.evaluation import errors_m
from pslog.fusion import filter as FM
from pslog.fusion.filter import BallFilter, FilterOptions, fuse_filter
from pslog.simulation import simulate, true_rig
from pslog.timing import observations as corrected_observations


def _session():
    """bench_dirty --more's rally-27400 on paper2 (two type-A cameras, 30 fps), 0.3 px,
    clean: the kick at 5.340 s towards camera 1, whose next pixel (5.350 s, NIS 7.0) the
    filter put 60 mm off with std_m 5.3 mm before session 31."""
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    motion, _ = dirty_rally(27400)
    options = SimulationOptions(noise_px=0.3, seed=27100)
    detections, truth = simulate(rig, motion, 8.0, options)
    obs = corrected_observations(detections, true_rig(rig, options))
    return rig, obs, truth


def test_a_held_point_whose_jump_may_precede_it_is_withdrawn():
    rig, obs, truth = _session()
    before = fuse_filter(obs, rig, options=FilterOptions(hold_jump_p=None))
    after = fuse_filter(obs, rig)  # the default: 0.05
    err0, err = errors_m(before, truth), errors_m(after, truth)
    far = np.flatnonzero(err0 > 0.05)
    assert len(far) == 1 and abs(before.time_ns[far[0]] / 1e9 - 5.350) < 1e-3
    assert before.quality["nis"][far[0]] > 2.0  # held, then released by the winner's lag
    assert np.max(err) < 0.05
    # only held points are withdrawn, the rest bit-equal
    gone = set(zip(before.time_ns.tolist(), before.camera.tolist(), strict=True)) - set(
        zip(after.time_ns.tolist(), after.camera.tolist(), strict=True))
    assert after.dropped["held"] - before.dropped.get("held", 0) == len(gone) >= 1
    assert len(gone) <= 0.01 * len(before)
    keep = np.isin(before.time_ns * 8 + before.camera, after.time_ns * 8 + after.camera)
    np.testing.assert_array_equal(after.position_world, before.position_world[keep])


def test_each_lags_weight_is_the_mixtures():
    # at every accepted jump of the session the per-lag probabilities sum to 1, and the
    # winner's lag carries at least its own hypothesis's, the largest of at most 3 lags x
    # 3 shapes (the least score): 1/9
    rig, obs, _ = _session()
    flt = BallFilter(rig, replace(FilterOptions(), withhold=False))
    jumps = 0
    for i in range(len(obs.time_ns)):
        out = flt.push(int(obs.time_ns[i]), int(obs.camera[i]), float(obs.uv[i, 0]),
                       float(obs.uv[i, 1]))
        if out is None or out[1][8] != 1.0:
            continue
        w = flt._S[FM._SJLW:FM._SJLW + FM._HISTORY]
        jumps += 1
        assert abs(w.sum() - 1.0) < 1e-12 and np.all(w >= 0)
        assert w[int(flt._I[FM._IJLAG])] >= 1.0 / 9.0
    assert jumps >= 5
