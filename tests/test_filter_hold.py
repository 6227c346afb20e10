"""``filter``: the batch's hold for the next camera (``FilterOptions.hold_nis``; issue 10,
session 29; θ = 2 by default since session 30; docs/methods.md "A point held for the next
camera"; the stream's: tests/test_filter_hold_stream.py).

A plain update's output point whose NIS exceeds ``hold_nis`` waits for the next detection of
another camera: withdrawn (``Track.dropped["held"]``) if that detection made a jump placed
before it (the jump's lag reaches back to it) or that may be (since session 31, the jump's
hypotheses reaching back to it carry a posterior probability of at least ``hold_jump_p``:
tests/test_filter_hold_jump.py), was rejected, or the track was lost first (or none came);
else output. Since session 47 a start's point (``init``: ``hold_start``), a plain update's
after a gap of more than 1.5 staggers (``hold_gap``) and a rejected detection's (the
prediction: ``hold_rejected``) are held too; a start's and a rejected detection's are
withdrawn by a jump whose lag reaches back to them (the jump search reaches no further back
than a start: the session-47 review; a rejected detection is not among the lags: any jump
since the accepted detection before it). Checked against the rule written out in Python over
every point of the same detections streamed (``withhold=False``, each jump's lag read), and on
a flight kicked along a camera's ray, whose first point after the kick is 8.6 cm off.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from _rally import rally
from test_filter import lab_rig
from test_filter_jump_instant import kicked

from pslog.evaluation import errors_m
from pslog.fusion import filter as FM
from pslog.fusion.filter import BallFilter, FilterOptions, fuse_filter
from pslog.simulation import SimulationOptions, simulate, true_rig
from pslog.timing import observations as corrected_observations


def _withdrawn_by_rule(obs, rig, options, theta):
    """(time, camera) of the points the rule withdraws, from every point streamed."""
    flt = BallFilter(rig, replace(options, withhold=False))
    out = BallFilter(rig, options)  # the same state, its withholding: what is output
    rows = []
    for i in range(len(obs.time_ns)):
        t, c = int(obs.time_ns[i]), int(obs.camera[i])
        u, v = float(obs.uv[i, 0]), float(obs.uv[i, 1])
        p, shown = flt.push(t, c, u, v), out.push(t, c, u, v)
        if p is None:
            continue
        q = p[1]
        lag = int(flt._I[FM._IJLAG]) if q[8] == 1.0 else -1
        # (session 31) each lag's posterior probability at a jump
        w = flt._S[FM._SJLW:FM._SJLW + FM._HISTORY].copy()
        rows.append((t, c, q[6], q[7], q[8], q[9], q[10], (lag, w), shown is not None))
    p_min = 2.0 if options.hold_jump_p is None else options.hold_jump_p
    # (session 47) a plain point after a gap of more than hold_gap regular gaps of the rig (its
    # longest between consecutive frame instants: 1 / Σ fps here), a start's and a
    # rejected detection's are held too
    gap_max = (math.inf if options.hold_gap is None
               else options.hold_gap * FM.regular_gap_s(rig))
    gone = set()
    for i, (t, c, nis, gap, jump, rej, init, _, shown) in enumerate(rows):
        if not shown or jump:
            continue
        if rej:
            held = options.hold_rejected
        elif init:  # (its NIS and gap NaN)
            held = options.hold_start
        else:
            held = nis > theta or gap > gap_max
        if not held:
            continue
        # withdrawn unless another camera's point releases it; a start's and a rejected
        # detection's count begins one lower (FM._START_PB, -1: a jump reaching back to a
        # start withdraws it, the jump search reaching no further back; a rejected detection
        # is not among the jump's lags: any jump since the accepted detection before it)
        verdict, between = True, (FM._START_PB if init or rej else 0)
        for _t2, c2, _, _, jump2, rej2, init2, (lag2, w2), _ in rows[i + 1:]:
            if init2:
                break
            if c2 != c:
                # withdrawn by a jump placed before it, or that may be (hold_jump_p)
                verdict = bool(rej2) or bool(jump2 and (
                    lag2 >= between + 1 or w2[between + 1:].sum() >= p_min))
                break
            between += not rej2
        if verdict:
            gone.add((t, c))
    return gone


def _points(track):
    return set(zip(track.time_ns.tolist(), track.camera.tolist(), strict=True))


@pytest.mark.parametrize(("ncam", "misses", "spurious", "seed"),
                         [(3, 0.1, 0.0, 4), (2, 0.3, 0.15, 4), (3, 0.4, 0.15, 4),
                          (3, 0.4, 0.15, 9)])
def test_the_batch_withdraws_what_the_rule_says_and_nothing_else(ncam, misses, spurious, seed):
    # three cameras; many misses (one camera's detections in a row before another's: the
    # accepted ones counted against the jump's lag, the rejected ones not) and spurious blobs
    # ungated (the filter's rejections: another camera's withdraws a held point)
    rig = lab_rig(ncam)
    motion, _ = rally(6.0, seed=11, speed=5.0, kick_every_s=0.6)
    options = SimulationOptions(noise_px=0.3, seed=seed, miss_rate=misses,
                                spurious_rate=spurious)
    detections, _ = simulate(rig, motion, None, options)
    obs = corrected_observations(detections, true_rig(rig, options))
    default = fuse_filter(obs, rig, options=FilterOptions(hold_nis=None))
    rows = {k: i for i, k in enumerate(zip(default.time_ns.tolist(), default.camera.tolist(),
                                            strict=True))}
    for theta in (0.0, 2.0, 4.61):
        held = fuse_filter(obs, rig, options=FilterOptions(hold_nis=theta))
        gone = _points(default) - _points(held)
        assert _points(held) <= _points(default)
        assert gone == _withdrawn_by_rule(obs, rig, FilterOptions(hold_nis=None), theta)
        assert held.dropped.get("held", 0) == len(gone)
        # every point output is the default's, to the bit
        keep = [rows[k] for k in zip(held.time_ns.tolist(), held.camera.tolist(), strict=True)]
        np.testing.assert_array_equal(held.position_world, default.position_world[keep])
        for name, col in held.quality.items():
            np.testing.assert_array_equal(col, default.quality[name][keep])
        if theta == 0.0:
            assert gone  # the rally's kicks withdraw some
    # the default (session 30): θ = 2
    np.testing.assert_array_equal(fuse_filter(obs, rig).position_world,
                                  fuse_filter(obs, rig, options=FilterOptions(
                                      hold_nis=2.0)).position_world)


def test_the_first_point_after_a_kick_along_a_ray_is_withdrawn():
    # 8 m/s towards camera 2, 10.7 ms before its next pixel: a plain update at NIS < 2, 8.6
    # cm off, output by default; the next camera's detection is the jump, placed before it
    rig = lab_rig(3)
    options = SimulationOptions(noise_px=0.3, seed=0)
    at = 0.5115
    p_kick = kicked([0.0, 0.0, 0.0], at).position(np.array([at]))[0]
    toward = rig.cameras[2].center_world - p_kick
    motion = kicked(8.0 * toward / np.linalg.norm(toward), at)
    detections, truth = simulate(rig, motion, None, options)
    obs = corrected_observations(detections, true_rig(rig, options))
    default = fuse_filter(obs, rig, options=FilterOptions(hold_nis=None))
    held = fuse_filter(obs, rig, options=FilterOptions(hold_nis=0.0))
    err0, err = errors_m(default, truth), errors_m(held, truth)
    first = np.flatnonzero(default.time_ns / 1e9 > at)[0]
    assert default.camera[first] == 2 and err0[first] > 0.05
    assert default.quality["nis"][first] < 2.0
    assert np.max(err) < 0.05
    assert (int(default.time_ns[first]), 2) not in _points(held)
    assert 1 <= held.dropped["held"] <= 3
