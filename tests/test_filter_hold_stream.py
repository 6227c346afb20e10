"""``filter``: the hold for the next camera in the streaming form (``FusionOptions.
filter_hold_nis``; session 30, docs/methods.md "A point held for the next camera").

A held point stays pending across pushes until the detection that decides it arrives, every
later point waits behind it, and ``flush`` withdraws what is still held, as the batch does at
the session's end: the stream's Tracks joined are the batch's, bit for bit and count for
count, for any chunking, on dirty sessions (misses 30 %, drops 10 %, spurious blobs; with
candidates, a distractor, a blackout, clock offsets and rolling shutters). By hand: on a
flight kicked along a camera's ray, a held point that leaves one detection late and one that
the next camera's jump withdraws.
"""

from __future__ import annotations

import numpy as np
import pytest
from _rally import rally
from test_filter import lab_rig
from test_filter_jump_instant import kicked
from test_stream_gating import assert_same_track, dirty, push_frames

from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions, fuse
from pslog.fusion.filter import FilterOptions, fuse_filter
from pslog.fusion.stream import StreamFuser
from pslog.records import Observations, Track
from pslog.simulation import SimulationOptions, simulate, true_rig
from pslog.timing import observations as corrected_observations


def _dirty_observations(ncam: int, seed: int):
    """(rig, observations): a kicked rally, misses 30 %, drops 10 %, spurious blobs in 10 %
    of frames (ungated: the filter's own rejections)."""
    rig = lab_rig(ncam)
    motion, _ = rally(6.0, seed=20 + seed, speed=5.0, kick_every_s=0.6)
    options = SimulationOptions(noise_px=0.3, seed=seed, miss_rate=0.3, drop_rate=0.1,
                                spurious_rate=0.1)
    det, _ = simulate(rig, motion, None, options)
    return rig, corrected_observations(det, true_rig(rig, options))


def _streamed(fuser: StreamFuser, obs, chunking: str, rng) -> list[Track]:
    """Every push's Track and the flush's: one detection per push as Python numbers
    (``one``: the one-detection path), as one-row arrays (``rows``), in random chunks of 1
    to 40 (``random``), or all at once (``whole``)."""
    n, parts = len(obs.time_ns), []
    if chunking == "one":
        parts = [fuser.push(int(obs.time_ns[i]), int(obs.camera[i]), obs.uv[i].tolist())
                 for i in range(n)]
    elif chunking == "rows":
        parts = [fuser.push(obs.time_ns[i:i + 1], obs.camera[i:i + 1], obs.uv[i:i + 1])
                 for i in range(n)]
    elif chunking == "random":
        i = 0
        while i < n:
            k = int(rng.integers(1, 41))
            parts.append(fuser.push(obs.time_ns[i:i + k], obs.camera[i:i + k],
                                    obs.uv[i:i + k]))
            i += k
    else:
        parts = [fuser.push(obs.time_ns, obs.camera, obs.uv)]
    return [*parts, fuser.flush()]


@pytest.mark.parametrize(("ncam", "seed"), [(3, 1), (3, 4), (2, 3)])
@pytest.mark.parametrize("theta", [0.0, 2.0])
def test_the_stream_holds_as_the_batch_for_any_chunking(ncam, seed, theta):
    rig, obs = _dirty_observations(ncam, seed)
    batch = fuse_filter(obs, rig, options=FilterOptions(hold_nis=theta))
    assert batch.dropped.get("held", 0) >= 1  # (the hold withdraws points here)
    assert len(batch) >= 100
    rng = np.random.default_rng(seed)
    for chunking in ("one", "rows", "random", "whole"):
        fuser = StreamFuser(rig, "filter", FusionOptions(filter_hold_nis=theta))
        parts = _streamed(fuser, obs, chunking, rng)
        assert_same_track(Track.concat(parts), batch)
        if chunking == "one":
            # points left late: a push emits a held point of an earlier detection
            assert any(len(p) and p.time_ns[0] < obs.time_ns[i]
                       for i, p in enumerate(parts[:-1]))


@pytest.mark.parametrize("clocks", [False, True])
def test_the_stream_with_candidates_holds_as_the_gated_batch(clocks):
    """Every frame's candidates pushed (the gate, and with ``clocks`` the admission queue of
    corrected times): ``fuse(detections, rig, "filter")`` with the same hold."""
    rig, det = dirty("filter", clocks)
    options = FusionOptions(filter_hold_nis=0.0)
    batch = fuse(det, rig, "filter", options)
    assert batch.dropped.get("held", 0) >= 1
    fuser = StreamFuser(rig, "filter", options, candidates=True)
    assert_same_track(Track.concat([*push_frames(fuser, det), fuser.flush()]), batch)


def _kicked_along_a_ray():
    """A flight kicked 8 m/s towards camera 2, 10.7 ms before its next pixel
    (tests/test_filter_hold.py's): (rig, observations, truth, kick time s)."""
    rig = lab_rig(3)
    options = SimulationOptions(noise_px=0.3, seed=0)
    at = 0.5115
    p_kick = kicked([0.0, 0.0, 0.0], at).position(np.array([at]))[0]
    toward = rig.cameras[2].center_world - p_kick
    detections, truth = simulate(rig, kicked(8.0 * toward / np.linalg.norm(toward), at), None,
                                 options)
    return rig, corrected_observations(detections, true_rig(rig, options)), truth, at


def test_a_held_point_leaves_at_the_next_camera_or_is_withdrawn_by_its_jump():
    rig, obs, truth, at = _kicked_along_a_ray()
    pushes = [(int(obs.time_ns[i]), int(obs.camera[i]), obs.uv[i].tolist())
              for i in range(len(obs.time_ns))]
    free = StreamFuser(rig, "filter", FusionOptions(filter_hold_nis=None))
    at_once = [free.push(*p) for p in pushes]
    fuser = StreamFuser(rig, "filter", FusionOptions(filter_hold_nis=0.0))
    held = [fuser.push(*p) for p in pushes]
    held.append(fuser.flush())
    times = obs.time_ns.tolist()

    # withdrawn: camera 2's first point after the kick (8.6 cm off, a plain update: output
    # at once without the hold) waits, and the next camera's detection, the jump, placed
    # before it, withdraws it
    first = next(i for i, t in enumerate(times) if t / 1e9 > at and len(at_once[i]))
    assert obs.camera[first] == 2 and obs.camera[first + 1] != 2
    assert errors_m(at_once[first], truth)[0] > 0.05
    assert at_once[first].quality["jump"][0] == 0
    # (the next detection is the jump: its own point withheld until confirmed)
    assert not len(at_once[first + 1]) and at_once[first + 1].dropped == {"unconfirmed": 1}
    # pending: its push emits no point of its own (the one before it, which it released)
    assert times[first] not in held[first].time_ns.tolist() and not held[first].dropped
    assert held[first + 1].dropped == {"unconfirmed": 1, "held": 1}
    assert times[first] not in held[first + 1].time_ns.tolist()
    streamed = Track.concat(held)
    assert times[first] not in streamed.time_ns.tolist()
    assert np.max(errors_m(streamed, truth)) < 0.05

    # emitted: a plain point before the kick waits for the next camera's detection (a
    # plain update, no jump), which releases it: it leaves with that push, first, the
    # point made without the hold to the bit
    j = next(i for i in range(first) if len(at_once[i]) and len(at_once[i + 1])
             and at_once[i].quality["jump"][0] == 0 and at_once[i].quality["init"][0] == 0
             and at_once[i + 1].quality["jump"][0] == 0 and obs.camera[i + 1] != obs.camera[i])
    assert times[j] not in held[j].time_ns.tolist() and not held[j].dropped
    assert held[j + 1].time_ns.tolist() == [times[j]]  # (j + 1's own point held in turn)
    assert_same_track(held[j + 1], at_once[j])
    # every point not withdrawn leaves, in the batch's order
    assert_same_track(streamed, fuse_filter(obs, rig, options=FilterOptions(hold_nis=0.0)))

    # the stream ends with the kicked point held: flush withdraws it, as the batch does at
    # the end of its detections
    fuser = StreamFuser(rig, "filter", FusionOptions(filter_hold_nis=0.0))
    parts = [fuser.push(*p) for p in pushes[:first + 1]]
    end = fuser.flush()
    assert not len(end) and end.dropped == {"held": 1}
    k = first + 1
    cut = Observations(obs.time_ns[:k], obs.camera[:k], obs.uv[:k], obs.frame_index[:k])
    assert_same_track(Track.concat([*parts, end]),
                      fuse_filter(cut, rig, options=FilterOptions(hold_nis=0.0)))


def test_live_keeps_every_point_at_its_detection():
    """``pslog live``'s fuser turns the hold off (a point per shutter, at once)."""
    from pslog.live.fuser import LiveFuser

    rig = lab_rig(3)
    live = LiveFuser(rig, "filter")
    assert live.options.filter_hold_nis is None
    assert live.stream.incremental._hold is None


def test_fuse_filter_hold_option_holds_by_default_and_off_gives_the_live_points(tmp_path,
                                                                                   cli):
    """`pslog fuse --method filter` holds (``held`` counted; the track of
    ``FusionOptions()``); ``--filter-hold off`` gives every point at its detection, as
    ``pslog live`` emits them (``filter_hold_nis=None``)."""
    from pslog.log import SessionWriter, read_session

    # (rally seed 13: a point held and withdrawn; seed 7's held point came from a bounce
    # found as a jump, which the floor's predicted contact made a plain update, session 31)
    rig, det = dirty("filter", clocks=False, rally_seed=13)
    path = tmp_path / "dirty.mcap"
    with SessionWriter(path, rig, timing="typeA", source="test") as writer:
        writer.add_detections(det)
    tracks = {}
    for flag in ("on", "off"):
        out = tmp_path / f"fused-{flag}.mcap"
        code, _, err = cli("fuse", path, "--method", "filter", "--filter-hold", flag, "-o", out)
        assert code == 0, err
        tracks[flag] = read_session(out).tracks["filter"]
    held = fuse(det, rig, "filter")
    at_once = fuse(det, rig, "filter", FusionOptions(filter_hold_nis=None))
    assert held.dropped.get("held", 0) >= 1 and "held" not in at_once.dropped
    assert_same_track(tracks["on"], held, dropped=False)
    assert_same_track(tracks["off"], at_once, dropped=False)
