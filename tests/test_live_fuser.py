"""The live fuser alone, fed datagram bytes: its points equal the offline fusion of what it
fused, every bad datagram is counted and dropped without changing a point, silent cameras."""

from __future__ import annotations

import gc
import json
import math
import socket
import threading
import time
import weakref
from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from pslog.fusion import FusionOptions, fuse
from pslog.live.fuser import COUNTERS, LiveFuser, LivePoint
from pslog.live.protocol import (
    FLAG_INIT,
    DetectionDatagram,
    PointDatagram,
    decode_detections,
    decode_point,
    encode_detections,
    encode_point,
)
from pslog.live.server import _collect_due
from pslog.records import NS
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, true_rig
from pslog.timing import camera_parameters, true_times_ns
from tests._live import EPOCH, datagrams, frames, rally_session, subset

#: what `pslog live` fuses as: the filter's points at their detection (no hold for the next
#: camera: `pslog fuse --filter-hold off`)
LIVE = FusionOptions(filter_hold_nis=None)


class Clock:
    """A wall clock the test sets (t_emit and the predictions become exact)."""

    def __init__(self, t: int = EPOCH) -> None:
        self.t = t

    def __call__(self) -> int:
        return self.t


def _run(fuser: LiveFuser, data: list[bytes], arrival: list[int] | None = None):
    points = []
    for i, d in enumerate(data):
        points += fuser.feed(d, EPOCH if arrival is None else arrival[i])
    return points + fuser.flush()


def _assert_same(points, track) -> None:
    assert len(points) == len(track) > 0
    np.testing.assert_array_equal([p.t_capture_ns - EPOCH for p in points], track.time_ns)
    np.testing.assert_array_equal([p.camera_index for p in points], track.camera)
    got = np.array([p.position_world for p in points])
    assert np.abs(got - track.position_world).max() <= 1e-9


@pytest.fixture(scope="module")
def session():
    return rally_session(1.5)


@pytest.mark.parametrize("method", ["filter", "typeA"])
@pytest.mark.parametrize("candidates", [True, False])
def test_points_equal_offline_fusion(session, method, candidates):
    """Fed a session's frames in order, the fuser emits the points `pslog fuse` makes of the
    session (all candidates gated; or each frame's best with --gating off)."""
    rig, det = session
    fuser = LiveFuser(rig, method, candidates=candidates, epoch_ns=EPOCH)
    points = _run(fuser, datagrams(det, rig))
    # (live outputs typeA's long-gap points at once: pslog.fusion.confirm off; the filter's
    # at their detection: no hold for the next camera)
    _assert_same(points, fuse(det, rig, method, FusionOptions(
        gating=candidates, confirm_gaps=False, filter_hold_nis=None)))
    c = fuser.counters()
    assert c["received"] == c["fused"] == det.n_frames and c["points"] == len(points)
    assert sum(c[k] for k in COUNTERS if k not in ("received", "fused", "points")) == 0


def test_clock_corrections_are_applied_live():
    """The rig's clock_offset, drift and rolling-shutter readout correct the times live as
    offline: points at the TRUE times, equal to fuse() with the same rig."""
    opts = dict(clock_offset_s={"cam2": 0.004, "cam3": -0.006}, clock_drift_ppm={"cam2": 40.0},
                readout_s={"cam1": 0.012, "cam3": 0.008})
    rig, det = rally_session(1.2, **opts)
    rig = true_rig(rig, SimulationOptions(**opts))
    data = datagrams(det, rig)
    arrival = [EPOCH + 1000 * (i + 1) for i in range(len(data))]
    # each frame's top-row TRUE time (numpy's true_times_ns) and its datagram's arrival
    cp = camera_parameters(rig)
    tops: dict[int, list] = {c: [] for c in range(len(rig))}
    logged = []
    for b, a in zip(data, arrival, strict=True):
        d = decode_detections(b)
        c = rig.names.index(d.camera)
        top = int(true_times_ns(d.t_capture_ns - EPOCH, 0.0, cp["height"][c],
                                cp["clock_offset"][c], cp["clock_drift_ppm"][c],
                                cp["readout"][c]))
        logged.append((d.t_capture_ns - EPOCH, c, top))
        if len(d):
            tops[c].append((top, a))
    for method in ("filter", "typeA"):
        fuser = LiveFuser(rig, method, epoch_ns=EPOCH)
        # the fuser's own top-row time (in floats): numpy's, to the nanosecond
        assert [fuser._true_time_ns(t, 0.0, fuser._clock_model[c]) for t, c, _ in logged] \
            == [top for _, _, top in logged]
        points = _run(fuser, data, arrival)
        offline = fuse(det, rig, method)
        _assert_same(points, offline)
        # each point's arrival: its camera's latest frame whose top row is at or before it
        for p in points:
            before = [a for top, a in tops[p.camera_index] if top <= p.t_capture_ns - EPOCH]
            assert p.arrival_ns == (before[-1] if before else p.t_emit_ns)
        # and not the uncorrected times
        assert not np.array_equal(offline.time_ns, fuse(det, rig.__class__(
            tuple(c.replace(clock_offset=0.0, clock_drift_ppm=0.0, readout=0.0)
                  for c in rig.cameras), rig.name), method).time_ns)


def _bad_variants(good: bytes, camera_count: int) -> dict[str, bytes]:
    return {
        "truncated": good[:50],
        "oversize": good[:4] + good[4:5] + bytes(3000),
        "foreign": b"\x00" * 40,
        "version": good[:4] + b"\x09" + good[5:],
        "malformed": good[:72] + np.float64(np.nan).tobytes() + good[80:]
        if len(good) > 72 else good[:6] + b"\x05\x00" + good[8:],
    }


def test_bad_datagrams_are_counted_and_change_nothing(session):
    """Interleaved with a session: a copy of every 7th datagram (duplicate), a frame sent
    after a newer one (reordered), one 0.5 s old (late), a frame from before the session's
    start, an unknown camera, and truncated / oversize / foreign / wrong-version / malformed
    bytes. Each is counted under its reason, and the points are those of the clean stream
    without the frames dropped."""
    rig, det = session
    clean = frames(det, rig)
    data, kept = [], np.ones(len(clean), bool)
    expect = dict.fromkeys(COUNTERS, 0)
    for i, d in enumerate(clean):
        raw = encode_detections(d)
        if i == 40:  # hold this frame back: sent after the next one (reordered)
            held = raw
            kept[i] = False
            continue
        data.append(raw)
        if i == 41:
            data.append(held)
            expect["reordered"] += 1
        if i % 7 == 3:
            data.append(raw)
            expect["duplicate"] += 1
        if i == 100:  # a frame 0.5 s older than the newest: late
            old = clean[100 - 45]  # (with a candidate: a frame without one fuses nothing)
            data.append(encode_detections(DetectionDatagram(
                old.camera, old.sequence, 99_999, old.t_capture_ns - 1, 0, [[320.0, 240.0]])))
            expect["late"] += 1
            expect["lost"] += 0
        if i == 120:  # before the session clock's zero
            data.append(encode_detections(DetectionDatagram(d.camera, 1, 1, EPOCH - 5, 0)))
            expect["late"] += 1
        if i == 60:
            data.append(encode_detections(DetectionDatagram("cam9", 1, 1, d.t_capture_ns + 1, 0,
                                                            d.uv)))
            expect["unknown_camera"] += 1
        if i % 25 == 5:
            for reason, bad in _bad_variants(raw, len(rig)).items():
                data.append(bad)
                expect[reason] += 1
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH, late_s=0.1)
    points = _run(fuser, data)
    c = fuser.counters()
    for reason in ("duplicate", "reordered", "late", "unknown_camera", "truncated", "oversize",
                   "foreign", "version", "malformed"):
        assert c[reason] == expect[reason] > 0, reason
    assert c["fused"] == kept.sum() and c["received"] == len(data)
    # no frame was lost on the way: the out-of-order frame 40 came (its gap is not counted)
    assert c["lost"] == 0
    _assert_same(points, fuse(subset(det, kept), rig, "filter", LIVE))
    # what was dropped is kept, with its reason, for a recorder
    reasons = sorted(r for _, r in fuser.dropped)
    assert reasons.count("duplicate") == expect["duplicate"]
    assert reasons.count("late") == 2 and reasons.count("reordered") == 1
    assert len(fuser.accepted) == kept.sum()


def test_rolling_shutter_row_outside_the_image_is_malformed():
    """A row that no rolling shutter read out would correct the time backwards: refused,
    the fuser keeps going."""
    rig, det = rally_session(0.6, readout_s={"cam1": 0.01})
    rig = true_rig(rig, SimulationOptions(readout_s={"cam1": 0.01}))
    clean = frames(det, rig)
    fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH)
    first = clean[0]
    bad = DetectionDatagram(first.camera, 99, 0, first.t_capture_ns + 1, 0, [[100.0, -40.0]])
    points = _run(fuser, [encode_detections(bad)] + [encode_detections(d) for d in clean])
    assert fuser.counters()["malformed"] == 1
    _assert_same(points, fuse(det, rig, "typeA"))


def test_silent_camera_and_its_return(session):
    """cam2 sends nothing for 0.4 s: the status says silent, the other cameras keep making
    points, and when it is back its frames are fused again (equal to offline fusion of the
    frames sent)."""
    rig, det = session
    clean = frames(det, rig)
    t = det.frame_time_ns
    gap = (det.frame_camera == 1) & (t > 0.5 * NS) & (t < 0.9 * NS)
    clock = Clock()
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH, silent_after_s=0.2, clock=clock)
    points, silent_seen, during = [], False, []
    for d, skip in zip(clean, gap, strict=True):
        clock.t = d.t_capture_ns
        states = {c.name: c for c in fuser.cameras()}
        if states["cam2"].silent and states["cam2"].frames:  # heard, then silent
            silent_seen = True
            assert not states["cam1"].silent and not states["cam3"].silent
        if skip:
            continue
        new = fuser.feed(encode_detections(d), d.t_capture_ns)
        if 0.75 * NS < d.t_capture_ns - EPOCH < 0.9 * NS:
            during += new
        points += new
    points += fuser.flush()
    assert silent_seen
    assert during and {p.camera for p in during} <= {"cam1", "cam3"}
    after = [p for p in points if p.t_capture_ns - EPOCH > 1.0 * NS]
    assert "cam2" in {p.camera for p in after}
    assert not {c.name: c for c in fuser.cameras()}["cam2"].silent
    _assert_same(points, fuse(subset(det, ~gap), rig, "filter", LIVE))
    # the frames it never sent show as a gap in its sequence
    assert fuser.counters()["lost"] == gap.sum()


def test_sequence_gaps_are_counted_lost(session):
    rig, det = session
    clean = frames(det, rig)
    skip = {10, 11, 12, 50}
    fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH)
    _run(fuser, [encode_detections(d) for i, d in enumerate(clean) if i not in skip])
    assert fuser.counters()["lost"] == 4
    assert sum(c.lost for c in fuser.cameras()) == 4


def test_forged_sequence_numbers_before_any_fused_frame_are_not_counted_lost(session):
    """Datagrams dropped before a frame of their camera was fused (captured before the
    session's start) once counted any jump of their sequence numbers as lost frames (the
    hostile sweep saw ``lost 23930939241261424455``)."""
    rig, det = session
    d = frames(det, rig)[0]
    fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH)
    for seq in (1, 2**62, 2**63 + 5, 3):
        forged = DetectionDatagram(d.camera, seq, d.frame_index, EPOCH - 1_000_000,
                                   d.t_sent_ns, d.uv, d.radius, d.score)
        fuser.feed(encode_detections(forged), EPOCH)
    assert fuser.counters()["late"] == 4
    assert fuser.counters()["lost"] == 0


def test_restarted_sender_is_not_a_duplicate(session):
    """A sender that restarts its sequence at 1 sends new capture times: fused, not dropped."""
    rig, det = session
    clean = frames(det, rig)
    half = len(clean) // 2
    renumbered = clean[:half] + [DetectionDatagram(d.camera, d.sequence - clean[half].sequence
                                                   + 1, d.frame_index, d.t_capture_ns,
                                                   d.t_sent_ns, d.uv, d.radius, d.score)
                                 if d.camera == clean[half].camera else d
                                 for d in clean[half:]]
    fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH)
    _run(fuser, [encode_detections(d) for d in renumbered])
    c = fuser.counters()
    assert c["duplicate"] == 0 and c["fused"] == len(clean)


def test_predicted_state_and_point_outputs(session):
    """filter: the state predicted to the emit time is the filter's own prediction;
    typeA: constant velocity from its last two points. The datagram and JSON carry them."""
    rig, det = session
    clean = frames(det, rig)
    clock = Clock()
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH, clock=clock)
    flt = fuser.stream.incremental.filter
    last = None
    for d in clean:
        clock.t = d.t_capture_ns + 3_000_000  # made 3 ms after capture
        for p in fuser.feed(encode_detections(d), d.t_capture_ns + 1_000_000):
            last = p
            pos, vel, _ = flt.predict(clock.t - EPOCH)
            np.testing.assert_array_equal(p.predicted_position, pos)
            np.testing.assert_array_equal(p.predicted_velocity, vel)
            assert p.t_emit_ns == clock.t and p.latency_s == pytest.approx(2e-3)
            assert np.all(np.isfinite(p.cov_world)) and p.cov_world[0, 0] > 0
    assert last is not None
    # the velocity is the ball's (a few m/s), the prediction 3 ms ahead of the point
    assert 0.5 < np.linalg.norm(last.predicted_velocity) < 30
    ahead = last.predicted_position - last.position_world
    assert np.linalg.norm(ahead) < 0.2
    q = decode_point(last.to_datagram(7))
    assert q.sequence == 7 and q.camera == last.camera and q.method == "filter"
    assert q.position == tuple(last.position_world)
    assert q.predicted_velocity == tuple(last.predicted_velocity)
    assert q.covariance[0] == last.cov_world[0, 0] and q.covariance[1] == last.cov_world[0, 1]
    assert (q.t_capture_ns, q.t_emit_ns, q.t_arrival_ns) == (
        last.t_capture_ns, last.t_emit_ns, last.arrival_ns)
    j = json.loads(json.dumps(last.to_json(), allow_nan=False))
    assert j["t"] == pytest.approx(last.t_capture_ns / NS) and j["method"] == "filter"
    assert (j["x"], j["y"], j["z"]) == tuple(last.position_world)
    assert j["latency_s"] == pytest.approx(2e-3) and j["camera"] == last.camera

    clock = Clock()
    fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH, clock=clock)
    previous = None
    checked = 0
    for d in clean:
        clock.t = d.t_capture_ns + 2_000_000
        for p in fuser.feed(encode_detections(d), d.t_capture_ns):
            assert np.all(np.isnan(p.cov_world)) or np.all(np.isfinite(p.cov_world))
            if previous is not None and 0 < p.t_capture_ns - previous.t_capture_ns < 0.1 * NS:
                v = (p.position_world - previous.position_world) / (
                    (p.t_capture_ns - previous.t_capture_ns) / NS)
                np.testing.assert_allclose(p.predicted_velocity, v, rtol=1e-12)
                np.testing.assert_allclose(p.predicted_position,
                                           p.position_world + v * 2e-3, rtol=1e-12)
                checked += 1
            previous = p
    assert checked > 50
    first = LiveFuser(rig, "typeA", epoch_ns=EPOCH)
    for d in clean:
        out = first.feed(encode_detections(d), d.t_capture_ns)
        if out:  # the first point has no previous one: no velocity
            assert all(math.isnan(v) for v in out[0].predicted_velocity)
            assert out[0].to_json()["velocity"] == [None, None, None]
            break


def test_flags_mark_a_track_start(session):
    rig, det = session
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    points = _run(fuser, datagrams(det, rig))
    assert points[0].flags & FLAG_INIT
    assert any(p.flags == 0 for p in points)


def test_bad_settings_are_one_line_errors(session):
    from pslog.errors import PslogError

    rig, _ = session
    for kwargs in (dict(method="smooth"), dict(method="nope"), dict(late_s=-1),
                   dict(silent_after_s=0)):
        with pytest.raises(PslogError) as info:
            LiveFuser(rig, **kwargs)
        assert "\n" not in str(info.value)


# ---- the rehearsal (serve's keep-warm between datagrams far apart) --------------------------
def _fields(p: LivePoint) -> tuple:
    """Every field of a point: its datagram's bytes, its JSON, its quality columns."""
    return (p.to_datagram(1), json.dumps(p.to_json()), p.t_emit_ns, p.arrival_ns,
            tuple(p.quality), np.array(list(p.quality.values())).tobytes())


@pytest.mark.parametrize("method", ["filter", "typeA"])
def test_a_rehearsal_before_every_datagram_changes_no_point(session, method):
    """A Rehearsal runs datagrams of warm_up's rally through a fuser of its own: the real
    fuser's points, with rehearsals (the rally replayed, later) before each of its
    datagrams, are those of a fuser without one, every field and counter."""
    from pslog.live.fuser import Rehearsal

    rig, det = session
    data = datagrams(det, rig)
    plain = LiveFuser(rig, method, epoch_ns=EPOCH, clock=Clock(EPOCH + 7))
    want = _run(plain, data)
    fuser = LiveFuser(rig, method, epoch_ns=EPOCH, clock=Clock(EPOCH + 7))
    rehearsal = Rehearsal(fuser)
    got = []
    for d in data:
        rehearsal.step()
        rehearsal.step()
        got += fuser.feed(d, EPOCH)
    got += fuser.flush()
    assert rehearsal.steps > len(rehearsal._frames)  # (replayed)
    # the replayed rally fused as the first time (its frames later, none dropped)
    c = rehearsal._shadow.counters()
    assert c["fused"] == rehearsal.steps and c["points"] > rehearsal.steps // 2
    assert [_fields(p) for p in got] == [_fields(p) for p in want]
    assert fuser.counters() == plain.counters()


def test_the_rehearsal_is_due_a_lead_before_the_next_frame_can_come(session):
    """plan(): each live camera's next frame is due a frame period after its latest fused
    one, at the earliest with the least delay (arrival - capture) of its latest datagrams;
    the rehearsal is the lead before the earliest camera's. None when the datagrams come
    closer than min_gap_s, and a silent camera is not waited for."""
    from pslog.live.fuser import Rehearsal

    rig, det = session
    fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH, clock=Clock())
    rehearsal = Rehearsal(fuser, lead_s=0.001)
    period = [round(NS / c.fps) for c in rig.cameras]
    delays = [3_000_000, 1_000_000, 2_500_000, 4_000_000, 1_500_000, 2_000_000, 1_200_000]
    seen: dict[int, list[int]] = {}
    last: dict[int, int] = {}
    for i, d in enumerate(frames(det, rig)[:7]):
        arrival = d.t_capture_ns + delays[i]
        fuser.feed(encode_detections(d), arrival)
        cam = fuser._index[d.camera]
        seen.setdefault(cam, []).append(delays[i])
        last[cam] = d.t_capture_ns
        rehearsal.plan(fuser, arrival)
        want = min(last[c] + period[c] + min(seen[c]) for c in last) - 1_000_000
        assert rehearsal.due == want - rehearsal.duration_ns
        if i == 3:  # (it starts the longest of the latest rehearsals' wall times earlier)
            rehearsal.step()
        assert (rehearsal.duration_ns > 0) == (i >= 4)
    # one rehearsal preempted for 50 ms: the next ones start at most 2 ms earlier (else
    # due before the datagram it is for, none would run, and the 50 ms would stay)
    rehearsal._durations.append(50_000_000)
    rehearsal.plan(fuser, arrival)
    assert rehearsal.due == want - 2_000_000 > arrival
    # a camera silent (nothing for silent_after_s): not waited for
    now = arrival + fuser.silent_after_ns + 1
    rehearsal.plan(fuser, now)
    assert rehearsal.due is None  # (every camera silent by then)
    # 3 x 240 fps: datagrams 1.4 ms apart, closer than min_gap_s: no rehearsal
    paper = builtin_rig("paper3")
    fast = apply_timing(Rig(tuple(c.replace(fps=240.0) for c in paper.cameras), "fast"),
                        "typeA")
    fuser = LiveFuser(fast, "typeA", epoch_ns=EPOCH, clock=Clock())
    rehearsal = Rehearsal(fuser)
    t0 = EPOCH + 10 * NS
    for k in range(6):
        t = t0 + k * round(NS / 720)
        fuser.feed(encode_detections(DetectionDatagram(
            fast.names[k % 3], k // 3 + 1, k // 3, t, t, [[320.0, 240.0]])), t)
        rehearsal.plan(fuser, t)
        assert (rehearsal.due is None) == (k > 0)  # (one camera heard: its own period)


@pytest.mark.parametrize("step_s", [60.0, -60.0])
def test_the_rehearsal_is_planned_on_the_monotonic_clock(session, step_s):
    """plan() on the fuser's waits' clock (monotonic, as serve gives it): with the fuser's
    wall clock stepping ``step_s`` after the 5th datagram (its wall-clock arrivals moved;
    the senders' capture times and the monotonic arrivals not), every rehearsal is due at
    the instant it is without the step, on the monotonic clock, within a frame period after
    the datagram it was planned after. Planned on the wall clock, a step forward made every
    delay after it 60 s longer than the least one: each rehearsal due 60 s in the past (none
    run) for the next 16 datagrams of each camera."""
    from pslog.live.fuser import Rehearsal

    rig, det = session
    sent = frames(det, rig)[:30]
    mono0 = 5 * NS
    delays = [3_000_000, 1_000_000, 2_500_000, 4_000_000, 1_500_000, 2_000_000, 1_200_000]
    arrivals = [mono0 + d.t_capture_ns - EPOCH + delays[i % 7] for i, d in enumerate(sent)]

    def plans(step_ns: int) -> list:
        now = [mono0]
        # (the frames captured 120 s before their wall-clock arrival: stepped back 60 s,
        # none is `future`)
        fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH, clock=Clock(), monotonic=lambda: now[0])
        rehearsal = Rehearsal(fuser, lead_s=0.001)
        due = []
        for i, d in enumerate(sent):
            now[0] = arrivals[i]
            wall = d.t_capture_ns + 120 * NS + delays[i % 7] + (step_ns if i >= 5 else 0)
            fuser.feed(encode_detections(d), wall, arrivals[i])
            rehearsal.plan(fuser, arrivals[i])
            due.append(rehearsal.due)
        assert fuser.counters()["fused"] == len(sent)
        return due

    plain = plans(0)
    assert plans(int(step_s * NS)) == plain
    # each due on the monotonic clock, after the datagram it was planned after and within a
    # frame period of it (the next camera's frame, 1/90 s later, with its least delay)
    assert all(a < due < a + NS // 30 for a, due in zip(arrivals, plain, strict=True))


def test_serve_rehearses_between_paced_datagrams_and_fuses_the_same_points(session):
    """Over real UDP, datagrams sent at their capture times (3 x 30 fps): serve rehearses
    between them (LiveSummary.rehearsals) and the robot gets the points a LiveFuser fed the
    same datagrams makes, bit for bit (times on the session clock, cameras, positions,
    covariances, residuals, masks, flags; predictions at emit aside: the wall clock's)."""
    import socket
    import threading
    import time

    from pslog.live.protocol import decode_point
    from pslog.live.server import serve
    from pslog.live.sinks import UdpSink

    rig, det = session
    keys = ("camera_index", "position", "covariance", "residual_px", "camera_mask", "flags")

    def run(rehearse_s):
        rx = _robot_socket()
        ready, stop = threading.Event(), threading.Event()

        def send():
            assert ready.wait(30)
            sent = frames(det, rig, ready.epoch_ns)[:40]
            start = time.time_ns() + 20_000_000 - sent[0].t_capture_ns
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
                for d in sent:  # (at their capture times, 20 ms later: 11 ms apart)
                    time.sleep(max(0.0, (start + d.t_capture_ns - time.time_ns()) / 1e9))
                    tx.sendto(encode_detections(d), ready.address)
            time.sleep(0.05)
            stop.set()

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        summary = serve(rig, "udp://127.0.0.1:0", [UdpSink(rx.getsockname())],
                        method="typeA", stop=stop, ready=ready, status_stream=None,
                        duration_s=30, rehearse_s=rehearse_s)
        sender.join(30)
        return summary, _received_points(rx), ready.epoch_ns

    def row(p, epoch):
        return [p.t_capture_ns - epoch] + [np.asarray(getattr(p, k)).tobytes() for k in keys]

    summary, got, epoch = run(0.004)
    fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH, clock=Clock())
    want = [decode_point(p.to_datagram(1)) for d in datagrams(det, rig)[:40]
            for p in fuser.feed(d, EPOCH)]
    assert summary.rehearsals > 0
    assert summary.counters["received"] == summary.counters["fused"] == 40  # (its own only)
    assert len(got) == summary.counters["points"] > 15
    assert [row(p, epoch) for p in got] == [row(p, EPOCH) for p in want]


# ---- over real UDP, recorded: the session re-fused offline gives the live points ----------
def _serve_session(rig, det, path, method, faults=True, interrupt=False, candidates=True):
    """Send ``det``'s frames (with a duplicate, a reordered and a late frame when
    ``faults``) over real UDP to serve() recording to ``path`` (``candidates``: serve's);
    returns (summary, points received by a robot's socket, epoch)."""
    import os
    import signal
    import socket
    import threading

    from pslog.live.server import serve
    from pslog.live.sinks import RecordSink, UdpSink

    rx = _robot_socket()
    ready, stop = threading.Event(), threading.Event()

    def send():
        assert ready.wait(30)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        clean = frames(det, rig, ready.epoch_ns)
        for i, d in enumerate(clean):
            if faults and i == 30:
                continue  # held back: sent after the next one
            tx.sendto(encode_detections(d), ready.address)
            if faults and i == 31:
                tx.sendto(encode_detections(clean[30]), ready.address)  # reordered
            if faults and i % 9 == 4:
                tx.sendto(encode_detections(d), ready.address)  # duplicate
            if faults and i == 50:
                old = clean[5]
                tx.sendto(encode_detections(DetectionDatagram(
                    old.camera, old.sequence, 77, old.t_capture_ns + 1, 0, [[320.0, 240.0]])),
                    ready.address)
            if i % 4 == 0:
                time.sleep(0.002)
        tx.close()
        time.sleep(0.1)
        if interrupt:
            os.kill(os.getpid(), signal.SIGINT)
        else:
            stop.set()

    import time

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    sinks = [UdpSink(rx.getsockname()), RecordSink(path, rig, method)]
    # Python's own SIGINT handler, as in a terminal (serve leaves an ignored SIGINT ignored:
    # a test run started in the background inherits SIG_IGN)
    before = signal.signal(signal.SIGINT, signal.default_int_handler) if interrupt else None
    try:
        summary = serve(rig, "udp://127.0.0.1:0", sinks, method=method, stop=stop,
                        ready=ready, status_stream=None, duration_s=60,
                        candidates=candidates)
    finally:
        if interrupt:
            signal.signal(signal.SIGINT, before)
    sender.join(30)
    return summary, _received_points(rx), ready.epoch_ns


def _robot_socket():
    """A robot's UDP socket on a free loopback port, reads timing out after 0.3 s (its
    buffer holds a few seconds' points: read once serve has ended)."""
    import socket

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.3)
    return rx


def _received_points(rx) -> list:
    """The points waiting in the robot's socket ``rx`` (it has a timeout), decoded; closes it."""
    points = []
    try:
        while True:
            points.append(decode_point(rx.recv(4096)))
    except TimeoutError:
        pass
    rx.close()
    return points


CLOCK_FAULTS = dict(clock_offset_s={"cam2": 0.003, "cam3": -0.004},
                    clock_drift_ppm={"cam3": 30.0}, readout_s={"cam2": 0.01})


@pytest.mark.parametrize("method, clocks", [("filter", False), ("typeA", False),
                                            ("filter", True)])
def test_recorded_session_refused_offline_gives_the_live_points(tmp_path, method, clocks):
    """A real MCAP: `pslog fuse` of the session recorded live (RecordSink) gives exactly the
    points the robot received over UDP (within 1e-9 m, same times and cameras), although
    duplicates, a reordered and a late frame were dropped live: they are recorded apart, on
    /live/dropped/<reason>/<camera>, with the fused frames alone on the detection topics.
    With ``clocks`` the rig carries clock corrections (offsets, drift, a rolling shutter):
    applied live, recorded with the rig, applied again offline."""
    from mcap.reader import make_reader

    from pslog.cli import main
    from pslog.log.reader import read_session

    if clocks:
        rig, det = rally_session(1.0, **CLOCK_FAULTS)
        rig = true_rig(rig, SimulationOptions(**CLOCK_FAULTS))
    else:
        rig, det = rally_session(1.0)
    path, fused = tmp_path / "live.mcap", tmp_path / "fused.mcap"
    summary, points, epoch = _serve_session(rig, det, path, method)
    c = summary.counters
    assert c["duplicate"] > 0 and c["reordered"] == 1 and c["late"] == 1
    assert len(points) == c["points"] > 50
    # (live emits each filter point at its detection: no hold for the next camera; and
    # each type A point at once: no confirmation, no point from the detections after it)
    hold = (["--filter-hold", "off"] if method == "filter" else
            ["--confirm-gaps", "off"] if method == "typeA" else [])
    assert main(["fuse", str(path), "--method", method, *hold, "-o", str(fused)]) == 0
    offline = read_session(fused).tracks[method]
    np.testing.assert_array_equal([p.t_capture_ns - epoch for p in points], offline.time_ns)
    np.testing.assert_array_equal([p.camera_index for p in points], offline.camera)
    assert np.abs(np.array([p.position for p in points]) - offline.position_world).max() <= 1e-9
    # the recorded live track is the same points
    live = read_session(path)
    recorded = live.tracks[method]
    np.testing.assert_array_equal(recorded.time_ns, offline.time_ns)
    assert np.abs(recorded.position_world - offline.position_world).max() <= 1e-9
    assert live.detections.n_frames == c["fused"]
    assert live.metadata["live_method"] == method
    assert any("session time 0 is wall clock" in text for _, text in live.events)
    dropped = {}
    with open(path, "rb") as f:
        for _, channel, _ in make_reader(f).iter_messages():
            if channel.topic.startswith("/live/dropped/"):
                reason = channel.topic.split("/")[3]
                dropped[reason] = dropped.get(reason, 0) + 1
    assert dropped == {k: c[k] for k in ("duplicate", "reordered", "late")}
    assert main(["info", str(path)]) == 0


def test_a_filter_points_datagram_covariance_is_the_published_one(tmp_path):
    """Issue 10 over real UDP: each point datagram's covariance is the point's published
    one -- its diagonal the squares of the batch track's ``std_x_m``, ``std_y_m``,
    ``std_z_m`` (``pslog fuse --gating off`` of the recorded session: the same bits
    through sqrt; live = batch), its off-diagonal terms the filter's state at the point
    plus the term the point published, in full: at a rejected detection the jumps its gap
    may hide (isotropic), for one camera going on alone its unseen jump along that
    camera's ray. The session makes both matter: each frame's best-scored candidate
    (false blobs the filter's gate rejects), 30 % misses at 3 x 60 fps (one camera alone
    for a few frames, its term small enough to publish)."""
    from pslog.cli import main
    from pslog.fusion import filter as FM
    from pslog.fusion import prepare
    from pslog.fusion.filter import BallFilter, FilterOptions, fuse_filter
    from pslog.log.reader import read_session
    from pslog.timing import observations as timed_observations

    paper3 = apply_timing(builtin_rig("paper3"), "typeA")
    rig = Rig(tuple(c.replace(fps=60.0, offset=c.offset / 2) for c in paper3.cameras),
              "paper3@60")
    rig, det = rally_session(2.0, rig=rig, spurious_rate=0.3, miss_rate=0.3)
    path, fused = tmp_path / "live.mcap", tmp_path / "fused.mcap"
    summary, points, epoch = _serve_session(rig, det, path, "filter", faults=False,
                                            candidates=False)
    assert len(points) == summary.counters["points"] > 150
    assert main(["fuse", str(path), "--method", "filter", "--gating", "off",
                 "--filter-hold", "off", "-o", str(fused)]) == 0
    batch = read_session(fused).tracks["filter"]
    np.testing.assert_array_equal([p.t_capture_ns - epoch for p in points], batch.time_ns)
    np.testing.assert_array_equal([p.camera_index for p in points], batch.camera)
    q = batch.quality
    c = np.array([p.covariance for p in points])  # xx, xy, xz, yy, yz, zz
    # the diagonal: the batch's columns, to the bit
    np.testing.assert_array_equal(np.sqrt(c[:, [0, 3, 5]]),
                                  np.column_stack([q["std_x_m"], q["std_y_m"], q["std_z_m"]]))
    assert_allclose(np.sqrt(c[:, [0, 3, 5]].sum(axis=1)), q["std_m"], rtol=1e-12)
    # the term matters here: the same detections without jumps (jump_rate_per_s 0) publish
    # a smaller std at rejected detections and at one camera going on alone
    session = read_session(path)
    prep = prepare(timed_observations(session.detections, session.rig), rig)
    obs = prep.obs
    assert prep.doubt_px2 is None
    live = FilterOptions(hold_nis=None)  # (live's: no hold for the next camera)
    assert_allclose(fuse_filter(obs, rig, options=live).quality["std_m"], q["std_m"], rtol=0,
                    atol=0)
    none = fuse_filter(obs, rig, options=FilterOptions(jump_rate_per_s=0.0, hold_nis=None))
    # (it withholds fewer: the points the term lifted above max_std_m)
    assert set(batch.time_ns.tolist()) < set(none.time_ns.tolist())
    was = none.quality["std_m"][np.searchsorted(none.time_ns, batch.time_ns)]
    grown = q["std_m"] > was * (1 + 1e-9)
    rejected = q["rejected"] == 1
    assert np.count_nonzero(grown & rejected) >= 10 and np.count_nonzero(grown & ~rejected) >= 1
    # the off-diagonal terms, by hand: the state at the point (a replay of the detections),
    # plus the published term in full
    flt = BallFilter(rig)
    full = {}
    for t, cam, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(),
                              strict=True):
        made = flt.push(t, cam, u, v)
        if made is None:
            continue
        if flt.state() is None:  # the rejection that lost the track: no state at hand
            full[t] = None
            continue
        P = flt.state()[2][:3, :3].copy()
        if not flt._nu:  # the estimated drag's term V_p V_pᵀ / I_k (session 29), in full
            V = np.array(flt._V[:3])
            P += np.outer(V, V) / flt._drag_info
        std = np.array(made[1][1:4])
        extra = float((std**2).sum() - np.trace(P))
        start = flt._start_jump
        if made[1][9] != 1 and flt._I[FM._IJN] > 0 and int(flt._I[FM._IJTE]) == t:
            # after an accepted jump: its instant, w ε_p ε_pᵀ in full (_instant_term)
            e, w = flt._S[FM._SJE:FM._SJE + 3], flt._S[FM._SJE + 3]
            P += w * np.outer(e, e)
            extra -= float(w * (e @ e))
        if made[1][9] == 1:  # rejected: λ_j σ_j² T³/3 per axis
            P += extra / 3 * np.eye(3)
        elif start is not None and start[0] == t and extra > 0:  # a start: the jumps its
            P += start[1]  # window may hide, in full (window_jump_cov's position block)
        else:  # one camera alone (else extra is 0): along the camera's ray
            d = np.array(made[0]) - rig.cameras[cam].center_world
            P += extra * np.outer(d, d) / (d @ d)
        full[t] = P
    checked = 0
    for p, row in zip(points, c, strict=True):
        want = full[p.t_capture_ns - epoch]
        got = row[[0, 1, 2, 1, 3, 4, 2, 4, 5]].reshape(3, 3)
        if want is None:  # the published variances alone
            assert np.all(np.isnan(row[[1, 2, 4]]))
            continue
        assert np.all(np.linalg.eigvalsh(got) > 0)
        if np.allclose(np.diag(got), np.diag(want), rtol=1e-9, atol=0):
            assert_allclose(got, want, rtol=0, atol=1e-9 * np.diag(want).max())
            checked += 1
    assert checked >= 0.95 * len(points)


def test_sigint_stops_serve_cleanly_with_a_complete_session(tmp_path):
    """Ctrl-C (a real SIGINT) while serving: the fuser stops, the sinks are closed, the
    session is complete (readable, not a partial) and holds every point emitted."""
    from pslog.log.reader import read_session

    rig, det = rally_session(0.6)
    path = tmp_path / "live.mcap"
    summary, points, _ = _serve_session(rig, det, path, "filter", faults=False,
                                        interrupt=True)
    assert summary.interrupted
    session = read_session(path)
    assert session.detections.n_frames == det.n_frames == summary.counters["fused"]
    assert len(session.tracks["filter"]) == len(points) == summary.counters["points"] > 0
    assert not list(tmp_path.glob("*.partial"))


def test_sample_live_client_receives_every_point():
    """samples/live_client.py, run as a program, against a real fuser over real UDP: one
    line per point, the same sequence, positions and cameras the fuser sent."""
    import socket
    import subprocess
    import sys
    import threading
    from pathlib import Path

    from pslog.live.server import serve
    from pslog.live.sinks import UdpSink

    client = Path(__file__).resolve().parents[1] / "samples" / "live_client.py"
    assert len(client.read_text().splitlines()) < 40
    rig, det = rally_session(0.5)
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    expected = _run(fuser, datagrams(det, rig))  # how many points the session makes
    proc = subprocess.Popen([sys.executable, str(client), f"127.0.0.1:{port}",
                             str(len(expected))], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().startswith("listening on udp://127.0.0.1:")
        ready, stop = threading.Event(), threading.Event()
        sent: list = []

        class Keep:
            def emit(self, points):
                sent.extend(points)

            def close(self):
                pass

        thread = threading.Thread(target=serve, args=(rig, "udp://127.0.0.1:0",
                                                      [UdpSink(("127.0.0.1", port)), Keep()]),
                                  kwargs=dict(stop=stop, ready=ready, status_stream=None),
                                  daemon=True)
        thread.start()
        assert ready.wait(30)
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for d in frames(det, rig, ready.epoch_ns):
            tx.sendto(encode_detections(d), ready.address)
        tx.close()
        out, _ = proc.communicate(timeout=30)
        stop.set()
        thread.join(30)
    finally:
        proc.kill()
    lines = out.splitlines()
    assert proc.returncode == 0 and len(lines) == len(sent) == len(expected)
    for i, (line, p) in enumerate(zip(lines, sent, strict=True)):
        fields = line.split()
        assert fields[0] == str(i + 1) and fields[1] == "filter" and fields[2] == p.camera
        x, y, z = (float(fields[k].split("=")[1]) for k in (4, 5, 6))
        np.testing.assert_allclose((x, y, z), p.position_world, atol=1e-4)


def test_without_gating_each_frame_fuses_its_best_candidate(session):
    """FusionOptions(gating=False) with candidates: the best candidate of each frame, as
    offline fuse() with gating off (several rows of one frame would not stream)."""
    rig, det = session
    options = FusionOptions(gating=False)
    fuser = LiveFuser(rig, "typeA", options=options, candidates=True, epoch_ns=EPOCH)
    points = _run(fuser, datagrams(det, rig))
    assert fuser.counters()["fusion_error"] == 0
    _assert_same(points, fuse(det, rig, "typeA", replace(options, confirm_gaps=False)))


def test_frames_without_candidates_never_hold_the_order(session):
    """A frame where nothing was seen fuses nothing: swapped with the next frame (another
    camera's) it is still taken (its camera is alive), and the frame it overtook is fused,
    not dropped as reordered: the points are those of the whole session."""
    rig, det = session
    clean = frames(det, rig)
    empty = [i for i, d in enumerate(clean[:-1]) if len(d) == 0 and len(clean[i + 1])
             and clean[i + 1].camera != d.camera]
    assert len(empty) >= 3
    order = list(range(len(clean)))
    for i in empty:
        order[i], order[i + 1] = order[i + 1], order[i]
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    points = _run(fuser, [encode_detections(clean[i]) for i in order])
    c = fuser.counters()
    assert c["reordered"] == c["late"] == 0 and c["fused"] == len(clean)
    _assert_same(points, fuse(det, rig, "filter", LIVE))


def _overtaken(clean):
    """The frames in a send order where, every 11 frames, a frame with candidates is
    overtaken by the next one (another camera's, with candidates); arrival times 1 ms after
    the newest capture sent."""
    order = list(range(len(clean)))
    swaps = [i for i in range(5, len(clean) - 1, 11)
             if len(clean[i]) and len(clean[i + 1]) and clean[i + 1].camera != clean[i].camera]
    for i in swaps:
        order[i], order[i + 1] = order[i + 1], order[i]
    arrival, newest = [], 0
    for i in order:
        newest = max(newest, clean[i].t_capture_ns)
        arrival.append(newest + 1_000_000)
    return order, arrival, len(swaps)


def test_hold_fuses_frames_that_overtook_one_another(session):
    """hold_s > 0: a frame waits until the other cameras have sent one at least as recent,
    so frames that overtook one another are all fused, in capture order: the points are
    those of the whole session (without a hold the overtaken ones are dropped)."""
    rig, det = session
    clean = frames(det, rig)
    order, arrival, n_swaps = _overtaken(clean)
    data = [encode_detections(clean[i]) for i in order]
    assert n_swaps >= 8
    plain = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    _run(plain, data, arrival)
    assert plain.counters()["reordered"] == n_swaps
    held = LiveFuser(rig, "filter", epoch_ns=EPOCH, hold_s=0.05)
    points = _run(held, data, arrival)
    c = held.counters()
    assert c["reordered"] == c["late"] == 0 and c["fused"] == len(clean)
    _assert_same(points, fuse(det, rig, "filter", LIVE))


def test_hold_does_not_wait_for_a_silent_camera(session):
    """With a hold, a camera that went silent is not waited for: the others' frames are
    fused as soon as the live cameras have caught up (poll releases them on time)."""
    rig, det = session
    clean = [d for d in frames(det, rig) if d.camera != "cam3"
             or d.t_capture_ns - EPOCH < 0.3 * NS]
    fuser = LiveFuser(rig, "typeA", epoch_ns=EPOCH, hold_s=0.2, silent_after_s=0.05)
    waited = []
    for d in clean:
        for p in fuser.feed(encode_detections(d), d.t_capture_ns) + fuser.poll(d.t_capture_ns):
            if p.t_capture_ns - EPOCH > 0.5 * NS:
                waited.append(d.t_capture_ns - p.t_capture_ns)
    fuser.flush()
    # once cam3 is silent, a frame waits at most for the other live camera's next frame
    # (1/90 or 2/90 s later with cam3's shutter gone), never for the 0.2 s hold
    assert waited and max(waited) <= 0.0223 * NS
    assert fuser.counters()["fused"] == len(clean)


def test_point_wire_forms_equal_their_definitions(session):
    """LivePoint.to_datagram packs straight from its arrays and to_json sums the trace in
    Python (fast paths): the same bytes as encode_point(PointDatagram(...)) and the same JSON
    as numpy's sqrt(trace), for real points and for NaN, zero and huge values."""
    rig, det = session
    live = _run(LiveFuser(rig, "filter", epoch_ns=EPOCH, clock=Clock(EPOCH + 2 * NS)),
                datagrams(det, rig))
    rng = np.random.default_rng(3)
    odd = []
    for cov in (np.full((3, 3), np.nan), np.zeros((3, 3)), np.diag([1e300, 1e300, 1e300]),
                np.diag([-1e-30, 0.0, 0.0]), rng.normal(size=(3, 3))):
        p = live[0]
        odd.append(LivePoint(**{**p.__dict__, "cov_world": cov, "residual_px": math.nan,
                                "predicted_velocity": np.array([np.nan, 1.0, -2.5e-300]),
                                "position_world": rng.normal(size=3) * 1e3}))
    for i, p in enumerate(live[:50] + odd):
        c = p.cov_world
        expected = encode_point(PointDatagram(
            sequence=i + 1, camera_index=p.camera_index, camera=p.camera, method=p.method,
            t_capture_ns=p.t_capture_ns, t_emit_ns=p.t_emit_ns, t_arrival_ns=p.arrival_ns,
            position=p.position_world,
            covariance=(c[0, 0], c[0, 1], c[0, 2], c[1, 1], c[1, 2], c[2, 2]),
            residual_px=p.residual_px, camera_mask=p.camera_mask, flags=p.flags,
            predicted_position=p.predicted_position, predicted_velocity=p.predicted_velocity))
        assert p.to_datagram(i + 1) == expected
        with np.errstate(invalid="ignore"):
            std = float(np.sqrt(np.trace(c)))
        got = p.to_json()
        assert got["std_m"] == (std if math.isfinite(std) else None)
        assert [got["x"], got["y"], got["z"]] == [float(a) for a in p.position_world]
        assert json.dumps(got, allow_nan=False)


# ---- the garbage collector: between datagrams, never inside one -------------------------
class _Cycle:
    """An object in a reference cycle (only the collector frees it), weakly referenceable."""

    def __init__(self) -> None:
        self.me = self


@pytest.fixture
def collector():
    """The collector off and emptied for the test (its counts then move only by what the
    test makes), its setting and callbacks back after; yields the collections started
    (generations) while the test ran."""
    started: list[int] = []

    def seen(phase, info) -> None:
        if phase == "start":
            started.append(info["generation"])

    enabled, threshold = gc.isenabled(), gc.get_threshold()
    gc.disable()
    gc.collect()
    gc.callbacks.append(seen)
    try:
        yield started
    finally:
        gc.callbacks.remove(seen)
        gc.set_threshold(*threshold)
        if enabled:
            gc.enable()


def _make(n: int) -> list:
    """``n`` cyclic objects made (container allocations: the collector's count), weak
    references to them."""
    return [weakref.ref(_Cycle()) for _ in range(n)]


def _fill(count: int, refs: list | None = None) -> list:
    """Cyclic objects made until the collector's young count is at least ``count``; weak
    references to them (added to ``refs``)."""
    refs = [] if refs is None else refs
    while gc.get_count()[0] < count:
        refs.append(weakref.ref(_Cycle()))
    return refs


def test_collect_due_runs_the_collection_python_would_have_run(collector):
    """Over the youngest generation's threshold: the oldest generation whose count is over
    its own is collected (the cycles freed); at or under it nothing; a datagram waiting in
    the socket puts it off up to 4 thresholds; threshold 0 (collection off) never
    collects."""
    gc.set_threshold(100, 3, 2)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
        sock.bind(("127.0.0.1", 0))
        refs = _fill(99)  # (two objects a step: 99 or 100)
        assert gc.get_count()[0] <= 100
        _collect_due(sock)
        assert collector == [] and all(r() is not None for r in refs)  # (not over: nothing)
        _fill(101, refs)
        _collect_due(sock)
        assert collector == [0] and all(r() is None for r in refs)
        # each young collection counts one in generation 1: over 3, generation 1 next
        # (the weak references kept: freeing a tracked object lowers the count)
        for _ in range(3):
            _fill(101, refs)
            _collect_due(sock)
        assert collector == [0, 0, 0, 0] and gc.get_count()[1] == 4
        _fill(101, refs)
        _collect_due(sock)
        assert collector[-1] == 1 and gc.get_count()[1:] == (0, 1)
        while collector[-1] != 2 and len(collector) < 30:  # (4 of generation 0 per 1)
            _fill(101, refs)
            _collect_due(sock)
        assert collector == [0] * 4 + ([1] + [0] * 4) * 2 + [1, 2]  # (2 after the third 1)
        del collector[:]
        # a datagram waiting: put off, until over 4 thresholds' worth
        tx.sendto(b"x", sock.getsockname())
        time.sleep(0.05)
        # (the earlier references kept too: freeing them would lower the count)
        start = len(refs)
        _fill(399, refs)
        assert gc.get_count()[0] <= 400
        _collect_due(sock)
        assert collector == [] and all(r() is not None for r in refs[start:])
        _fill(401, refs)
        _collect_due(sock)
        assert collector == [0] and all(r() is None for r in refs)
        gc.set_threshold(0)
        _fill(1000, refs)
        _collect_due(sock)
        assert collector == [0]


def _serve_garbage(rig, det, sink, n: int = 12):
    """``n`` frames over real UDP to serve() with ``sink``, 3 ms apart; its summary."""
    ready, stop = threading.Event(), threading.Event()

    def send() -> None:
        assert ready.wait(30)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for d in frames(det, rig, ready.epoch_ns)[:n]:
                tx.sendto(encode_detections(d), ready.address)
                time.sleep(0.003)
        time.sleep(0.05)
        stop.set()

    sender = threading.Thread(target=send, daemon=True)
    sender.start()
    from pslog.live.server import serve

    summary = serve(rig, "udp://127.0.0.1:0", [sink], method="typeA", stop=stop,
                    ready=ready, status_stream=None, duration_s=30, rehearse_s=None)
    sender.join(30)
    return summary


class _Garbage:
    """A sink making cyclic garbage at every point handed out, 3 of the collector's young
    thresholds of it: whether a collection started inside ``emit`` (with the automatic
    collector on, every call would see one), and each call's references to what it made."""

    def __init__(self) -> None:
        self.inside = False
        self.collected_inside = 0
        self.made: list[list] = []
        #: per call, how many of the objects the earlier calls made were alive then
        self.alive: list[int] = []

    def emit(self, points) -> None:
        self.inside = True
        try:
            self.alive.append(sum(r() is not None for refs in self.made for r in refs))
            self.made.append(_make(3 * gc.get_threshold()[0]))
        finally:
            self.inside = False

    def close(self) -> None:
        pass


def test_serve_collects_between_datagrams_and_restores_the_collector(session):
    """serve() with the collector on: no collection starts while a datagram's points are
    handed out (a sink making 3 thresholds of cyclic garbage per call), the garbage of each
    call is freed before the next datagram's points (collected between them), and the
    collector is on again after; with the collector off (the user's choice) serve collects
    nothing and leaves it off."""
    rig, det = session
    sink = _Garbage()

    def seen(phase, info) -> None:
        if phase == "start" and sink.inside:
            sink.collected_inside += 1

    enabled = gc.isenabled()
    gc.callbacks.append(seen)
    try:
        gc.enable()
        summary = _serve_garbage(rig, det, sink)
        assert gc.isenabled()
        assert summary.counters["points"] > 5 and len(sink.made) > 5
        assert sink.collected_inside == 0
        # each call's cycles freed by the next call (collected between the two)
        assert sink.alive == [0] * len(sink.made)

        gc.disable()
        sink = _Garbage()
        started = []
        gc.callbacks.append(lambda phase, info: started.append(phase))
        summary = _serve_garbage(rig, det, sink)
        gc.callbacks.pop()
        assert not gc.isenabled()
        # (serve's own full collection before its freeze aside: none by the count)
        assert len(sink.made) > 5 and started == ["start", "stop"]
        assert sink.alive == [3 * gc.get_threshold()[0] * k for k in range(len(sink.made))]
    finally:
        gc.callbacks.remove(seen)
        if enabled:
            gc.enable()
        gc.collect()
