"""The window streams' dropped counts (issue 10: stream output equals batch output exactly on
sessions with misses, drops and outliers). ``sync``, ``nearest``, ``typeB`` and ``linear``
stream by re-fusing a window of recent detections at every push (pslog/fusion/stream.py); a
window's dropped points include ones an earlier window already dropped, so the stream used
to report no counts at all (``{}`` where the batch counted ``prediction_failed`` and
``residual_failed``). It now counts each dropped point once, at the push that settles it
(as it emits a point): joined, the stream's ``Track.dropped`` is the batch's, reason by
reason, beside its points, bit for bit."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from _rally import rally
from test_fusion import observations
from test_fusion_validity import rectified_rig
from test_stream_gating import LENS, assert_same_track, push_frames
from test_stream_type_a import _behind_then_in_front, pushed_one_by_one

from pslog.fusion import FusionOptions, fuse
from pslog.fusion.stream import StreamFuser
from pslog.records import Detections, Observations, Track
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig

WINDOW_METHODS = ("sync", "nearest", "typeB", "linear")

#: Dirty rallies of :data:`DURATION_S` (a strong lens, 0.5 px noise, 30 % misses, 10 % dropped
#: frames, spurious blobs in 5 % of frames): (rig, timing, seed, clock offsets and rolling
#: shutters)
SESSIONS = {
    "paper3-typeB-2400": ("paper3", "typeB", 2400, False),
    "paper3-typeB-2401-clocks": ("paper3", "typeB", 2401, True),
    "paper3-sync-2402": ("paper3", "sync", 2402, False),
    "paper2-sync-2403": ("paper2", "sync", 2403, False),
}
#: the rallies' length: 3 s (it was 4 s; the stream re-fuses its window at every push, so its
#: cost grows with the pushes: 3 s keeps every bound below with the same seeds, and more
#: of the gated batches drop points, 6 of 16 against 2: what the gated test compares)
DURATION_S = 3.0


@functools.cache
def _session(name: str):
    """(rig, detections) of ``name``: made once per test process, read by each test (no
    test or stream writes into a session's arrays)."""
    rig_name, timing, seed, clocks = SESSIONS[name]
    rig = apply_timing(builtin_rig(rig_name), timing)
    rig = Rig(tuple(c.replace(dist=LENS) for c in rig.cameras), rig.name)
    # (an offset of a few ms would leave typeB timing few common instants: 0.3 ms)
    faults = ({"clock_offset_s": {rig.names[1]: 0.0003},
               "readout_s": dict.fromkeys(rig.names, 0.002)} if clocks else {})
    options = SimulationOptions(noise_px=0.5, seed=seed, miss_rate=0.3, drop_rate=0.1,
                                spurious_rate=0.05, **faults)
    det, _, _ = simulate_labelled(rig, rally(DURATION_S, seed=seed, speed=5.0)[0],
                                  DURATION_S, options)
    return true_rig(rig, options), det


def _with_outliers(obs: Observations, rig: Rig, seed: int) -> Observations:
    """``obs`` with 5 % of its detections moved to uniformly random pixels of their image
    (outliers no gate removed)."""
    rng = np.random.default_rng(seed)
    out = rng.random(len(obs)) < 0.05
    size = np.array([[c.width, c.height] for c in rig.cameras], np.float64)[obs.camera[out]]
    uv = obs.uv.copy()
    uv[out] = rng.random((int(out.sum()), 2)) * size
    return Observations(obs.time_ns, obs.camera, uv, obs.frame_index)


@functools.cache
def _logged(name: str) -> Observations:
    """``name``'s best candidates with its outliers (:func:`_with_outliers`), made once."""
    rig, det = _session(name)
    return _with_outliers(det.best(), rig, SESSIONS[name][2])


@functools.cache
def _batch(name: str, method: str, outliers: bool) -> Track:
    """``fuse`` of ``name``: its candidates through the gate, or (``outliers``) its
    :func:`_logged` detections without it; made once per test process, only read."""
    rig, det = _session(name)
    if not outliers:
        return fuse(det, rig, method)
    return fuse(Detections.from_observations(rig.names, _logged(name)), rig, method,
                FusionOptions(gating=False))


@pytest.mark.parametrize("method", WINDOW_METHODS)
@pytest.mark.parametrize("name", list(SESSIONS))
def test_window_stream_with_candidates_counts_what_the_gated_batch_drops(name, method):
    """Every frame's candidates pushed (``candidates=True``): the stream joined equals
    ``fuse(detections, rig, method)``, points, quality columns and every ``dropped`` count."""
    rig, det = _session(name)
    batch = _batch(name, method, outliers=False)
    fuser = StreamFuser(rig, method, candidates=True)
    joined = Track.concat([*push_frames(fuser, det), fuser.flush()])
    assert len(batch) >= 15
    assert_same_track(joined, batch)


@pytest.mark.parametrize("method", WINDOW_METHODS)
@pytest.mark.parametrize("name", list(SESSIONS))
def test_window_stream_of_detections_with_outliers_counts_what_the_batch_drops(name, method):
    """No gate: each frame's best candidate, with 5 % of the detections at random pixels,
    pushed one at a time at their logged times: the stream joined equals the batch of the
    same detections at their true times, counts included."""
    rig, _ = _session(name)
    batch = _batch(name, method, outliers=True)
    joined = Track.concat(pushed_one_by_one(StreamFuser(rig, method, FusionOptions(
        gating=False)), _logged(name)))
    assert len(batch) >= 15
    assert_same_track(joined, batch)


def test_the_sessions_drop_points_under_the_window_methods_reasons():
    """What makes the tests above bite: with the outliers, the batch drops points on every
    session, refused by the residual test (``sync``, and ``typeB``'s stereo points) and by
    the prediction test (``typeB``); with the gate, fewer (``typeB`` on three sessions; the
    gated sessions of tests/test_stream_gating.py: 5)."""
    gated = 0
    for name in SESSIONS:
        assert _batch(name, "sync", outliers=True).dropped.get("residual_failed", 0) >= 3
        dropped = _batch(name, "typeB", outliers=True).dropped
        assert dropped.get("residual_failed", 0) >= 3, (name, dropped)
        assert dropped.get("prediction_failed", 0) >= 1, (name, dropped)
        gated += sum(_batch(name, "typeB", outliers=False).dropped.values())
    assert gated >= 3


@pytest.mark.parametrize("method", WINDOW_METHODS)
def test_geometrically_invalid_points_are_counted_once_as_in_batch(method):
    """A static ball first at a negative disparity (its points cross behind both cameras:
    ``behind_camera``), then at a positive one, on a rectified pair: synchronous shutters
    (every method's points, and typeB / linear's stereo ones, invalid for 10 instants) and
    ``nearest`` on staggered ones. One detection a push, the counts are the batch's."""
    rig = rectified_rig() if method != "nearest" else rectified_rig(offsets=(0.0, 1 / 60))
    rows = _behind_then_in_front(40)
    if method != "nearest":  # (both cameras at each instant)
        rows = [(10 * (i // 2), c, u, v) for i, (_, c, u, v) in enumerate(rows)]
    obs = observations(rows)
    batch = fuse(obs, rig, method)
    assert batch.dropped.get("behind_camera", 0) >= 4 and len(batch) >= 4, batch.dropped
    assert_same_track(Track.concat(pushed_one_by_one(StreamFuser(rig, method), obs)), batch)


def test_each_drop_is_counted_at_the_push_that_settles_it():
    """A push's Track carries the drops settled with it, not its whole window's (which
    counts again the drops of the windows before): one frame a push, the counts come with
    the pushes that settle them, and their sum is the batch's."""
    rig, _ = _session("paper3-typeB-2400")
    parts = pushed_one_by_one(StreamFuser(rig, "typeB", FusionOptions(gating=False)),
                              _logged("paper3-typeB-2400"))
    batch = _batch("paper3-typeB-2400", "typeB", outliers=True)
    counted = [sum(p.dropped.values()) for p in parts]
    assert sum(counted) == sum(batch.dropped.values()) >= 5
    assert np.count_nonzero(counted) >= 3  # (spread over the pushes, not all at the end)
