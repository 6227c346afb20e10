"""Type A's points with a large innovation wait for the next camera (session 32).

Eq. (2) predicts across a kick the newest camera cannot see along its ray; the innovation
test (:mod:`pslog.fusion.innovation`) refuses a point whose prediction misses the newest
detection by more than ``5 σ_r + e_model``. Below that, a point whose innovation across the
newest ray (gravity's part taken out) exceeds ``WAIT_SIGMAS = 3`` standard deviations now
waits for the next camera's detection, as a long-gap point does (:mod:`pslog.fusion.confirm`),
and is dropped when that camera contradicts it.

The session is the tests' own rally (``tests/_rally.py``, seed 300; paper3, type-A shutters,
0.3 px, clean): a kick at 4.8235 s, and cam1's point at 4.8333 s (10 ms later) was 56.5 mm
off with the rule off (its normalised innovation 3-5 σ: not refused, nothing else waited).
"""

from __future__ import annotations

import numpy as np
import pytest
from _rally import dirty_rally
from numpy.testing import assert_array_equal
from test_stream_type_a import assert_same, pushed_one_by_one

import pslog.fusion.confirm as confirm
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions, fuse
from pslog.fusion._prepare import default_max_gap_s, prepare, rays_only
from pslog.fusion.pseudo import _fuse_type_a, covariance_noise_px
from pslog.fusion.stream import StreamFuser
from pslog.records import NS
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

#: the far point's time (s) and the kick before it
FAR_S, KICK_S = 4.8333, 4.8235


def _session(seed: int = 300, miss_rate: float = 0.0):
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion, kicks = dirty_rally(seed)
    det, truth = simulate(rig, motion, 8.0, SimulationOptions(
        noise_px=0.3, seed=seed, miss_rate=miss_rate, drop_rate=miss_rate / 2))[:2]
    return rig, det, truth, np.asarray(kicks)


def _near(t_ns: np.ndarray, at_s: float) -> np.ndarray:
    return np.abs(t_ns / NS - at_s) < 1e-3


def test_the_point_after_the_kick_waits_and_is_contradicted(monkeypatch):
    """Rule off: one point beyond 5 cm, 10 ms after a kick. Rule on (the default): none;
    the points kept are the rule-off points to the bit, at most three are left out (each
    contradicted by the next camera), and no point goes unconfirmed for it."""
    rig, det, truth, kicks = _session()
    default = confirm.WAIT_SIGMAS
    monkeypatch.setattr(confirm, "WAIT_SIGMAS", None)
    before = fuse(det, rig, "typeA")
    err = errors_m(before, truth)
    far = err > 0.05
    assert far.sum() == 1 and _near(before.time_ns[far], FAR_S).all()
    assert 0.05 < err[far][0] < 0.07
    assert 0 < FAR_S - kicks[kicks <= FAR_S].max() < 0.02
    monkeypatch.setattr(confirm, "WAIT_SIGMAS", default)
    after = fuse(det, rig, "typeA")
    assert np.all(errors_m(after, truth) <= 0.05)
    keep = np.isin(before.time_ns * 8 + before.camera, after.time_ns * 8 + after.camera)
    assert not keep[far].any()
    assert_array_equal(after.time_ns, before.time_ns[keep])
    assert_array_equal(after.position_world, before.position_world[keep])
    for name, column in after.quality.items():
        assert_array_equal(column, before.quality[name][keep], err_msg=name)
    lost = len(before) - len(after)
    assert 1 <= lost <= 3, lost
    assert (after.dropped["contradicted"] - before.dropped.get("contradicted", 0)) == lost
    assert after.dropped.get("unconfirmed", 0) == before.dropped.get("unconfirmed", 0)


def test_the_far_point_is_below_refusal_and_above_the_wait():
    """The far point's innovation across its ray, gravity's part out, in σ of the test's
    noise: above WAIT_SIGMAS (3), below the refusal's 5 (the kernel kept it); and the
    session's points that wait for it are few (under 1 %)."""
    rig, det, truth, _ = _session()
    options = FusionOptions()
    prep = rays_only(prepare(det.best(), rig))[0]
    made = _fuse_type_a(prep, default_max_gap_s(rig), options.noise_px, None, None, None,
                        False, covariance_noise_px(options.noise_px), None)[0]
    q = made.quality
    sigma = confirm.confirm_noise(q["snap_px"], options.noise_px)
    nu = np.sqrt(q["_model_across_m2"] / (sigma * sigma * q["_model_m2_per_px2"]))
    at = _near(made.time_ns, FAR_S) & (errors_m(made, truth) > 0.05)
    assert at.sum() == 1
    assert 3.0 < nu[at][0] < 5.0
    waits = confirm.innovation_waits(q["_model_across_m2"], q["_model_m2_per_px2"], sigma)
    assert waits[at][0]
    assert 1 <= waits.sum() <= 0.01 * len(made)


def test_the_rule_is_the_threshold_elementwise():
    """|u|² > k² σ² c, exactly at the boundary, one point as many (the same bits)."""
    sigma = np.array([0.5, 0.5, 0.7, np.nan])
    per = np.array([1e-6, 1e-6, 4e-6, 1e-6])
    k2 = confirm.WAIT_SIGMAS ** 2
    across = np.array([k2 * 0.25 * 1e-6, np.nextafter(k2 * 0.25 * 1e-6, 1.0),
                       0.9 * k2 * 0.49 * 4e-6, 1.0])
    out = confirm.innovation_waits(across, per, sigma)
    assert out.tolist() == [False, True, False, False]
    for i in range(4):
        assert confirm.innovation_waits(across[i:i + 1], per[i:i + 1], sigma[i:i + 1])[0] == out[i]


@pytest.mark.parametrize("seed, miss_rate", [(300, 0.0), (301, 0.3), (302, 0.1)])
def test_the_stream_waits_and_decides_as_the_batch_run(seed, miss_rate):
    """StreamFuser, one detection a push: the same points, columns and counts as the batch
    run (the waiting points output with the confirming detection's push), on the kick
    session and on rallies with misses and drops."""
    rig, det, _, _ = _session(seed, miss_rate)
    obs = det.best()
    batch = fuse(obs, rig, "typeA")
    assert batch.dropped.get("contradicted", 0) >= 1
    assert_same(pushed_one_by_one(StreamFuser(rig, "typeA"), obs), batch)


def test_the_stream_leaves_out_the_far_point():
    """The stream, not only the batch run, holds the far point and drops it."""
    rig, det, truth, _ = _session()
    fuser = StreamFuser(rig, "typeA")
    parts = pushed_one_by_one(fuser, det.best())
    from pslog.records import Track

    joined = Track.concat(parts)
    assert np.all(errors_m(joined, truth) <= 0.05)
