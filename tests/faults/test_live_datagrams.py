"""Bad datagrams sent over REAL UDP to a real live fuser (pslog.live.server.serve on a free
loopback port): each is counted and dropped, the fuser keeps fusing, points equal those of
the clean stream; a silent camera; a bound port; bad addresses."""

from __future__ import annotations

import contextlib
import io
import socket
import struct
import threading
import time

import numpy as np
import pytest

from pslog.errors import PslogError
from pslog.fusion import FusionOptions, fuse
from pslog.live.protocol import (
    DetectionDatagram,
    decode_point,
    detection_datagrams,
    encode_detections,
)
from pslog.live.server import serve
from pslog.live.sinks import JsonlSink, RecordSink, UdpSink
from pslog.records import NS
from tests._live import rally_session, subset

#: offline fusion as live fuses: every point at its detection (no hold for the next camera)
LIVE_AS_FUSED = FusionOptions(filter_hold_nis=None)

#: a run that has not ended by then has hung
HANG_S = 30.0


class Receiver:
    """A robot's socket: collects the point datagrams the fuser sends."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.address = self.sock.getsockname()
        self.points = []

    def drain(self):
        with contextlib.suppress(TimeoutError):
            while True:
                self.points.append(decode_point(self.sock.recv(4096)))
        return self.points


@contextlib.contextmanager
def live(rig, method="filter", expect_error=False, **kwargs):
    """serve() in a thread on a free loopback port; yields (send, receiver, result) where
    result["summary"] is the LiveSummary once the block has ended (stop set on exit), or
    result["error"] what it raised (only with ``expect_error``)."""
    receiver = Receiver()
    ready, stop = threading.Event(), threading.Event()
    status = io.StringIO()
    out = io.StringIO()
    result: dict = {"status": status, "jsonl": out}
    sinks = [UdpSink(receiver.address), JsonlSink(out), *kwargs.pop("sinks", [])]

    def run():
        try:
            result["summary"] = serve(rig, "udp://127.0.0.1:0", sinks, method=method,
                                      stop=stop, ready=ready, status_stream=status, **kwargs)
        except BaseException as exc:  # the test asserts there was none
            result["error"] = exc

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    assert ready.wait(HANG_S), "serve never became ready"
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    result["epoch"] = ready.epoch_ns

    def send(data: bytes) -> None:
        tx.sendto(data, ready.address)

    try:
        yield send, receiver, result
    finally:
        stop.set()
        thread.join(HANG_S)
        tx.close()
        assert not thread.is_alive(), "serve did not stop"
        receiver.drain()
        receiver.sock.close()
    assert expect_error or "error" not in result, result.get("error")


def _frames(det, rig, epoch):
    """The session's frames on the fuser's clock (``epoch`` + session time)."""
    return detection_datagrams(det, epoch)


@pytest.fixture(scope="module")
def session():
    return rally_session(0.7)


def _good(d: DetectionDatagram) -> bytes:
    return encode_detections(d)


def _f64(data: bytes, offset: int, value: float) -> bytes:
    return data[:offset] + struct.pack("<d", value) + data[offset + 8:]


#: kind -> (counter, how the bad datagram is made from a good frame's, and frames to drop)
FAULTS = {
    "duplicate": ("duplicate", lambda d, prev: _good(d)),
    "reordered": ("reordered", None),  # a frame held back, sent after the next one
    "late": ("late", lambda d, prev: _good(DetectionDatagram(
        d.camera, 1, 1, d.t_capture_ns - NS // 2 - 7, 0, [[320.0, 240.0]]))),
    "truncated": ("truncated", lambda d, prev: _good(d)[:60]),
    "cut-candidate": ("truncated", lambda d, prev: (_good(d) + bytes(32))[:-7]),
    "oversize": ("oversize", lambda d, prev: _good(d)[:8] + bytes(60_000)),
    "foreign": ("foreign", lambda d, prev: b"RTPS\x02\x01" + bytes(50)),
    "version": ("version", lambda d, prev: _good(d)[:4] + b"\x02" + _good(d)[5:]),
    "nan": ("malformed", lambda d, prev: _f64(_good(DetectionDatagram(
        d.camera, 8_000_000, 1, d.t_capture_ns + 1, 0, [[1.0, 2.0]])), 72, float("nan"))),
    "inf": ("malformed", lambda d, prev: _f64(_good(DetectionDatagram(
        d.camera, 8_000_000, 1, d.t_capture_ns + 1, 0, [[1.0, 2.0]])), 80, float("inf"))),
    "k-too-big": ("malformed", lambda d, prev: _good(d)[:6] + struct.pack(
        "<H", len(d) + 1) + _good(d)[8:]),
    "unknown-camera": ("unknown_camera", lambda d, prev: _good(DetectionDatagram(
        "cam7", 1, 1, d.t_capture_ns + 1, 0, d.uv))),
}


@pytest.mark.parametrize("kind", sorted(FAULTS))
def test_bad_datagram_is_counted_dropped_and_fusion_goes_on(session, kind):
    """Every 10th frame is followed by a bad datagram of ``kind`` (for ``reordered``, that
    frame is held back and sent after the next one). The fuser counts each under its
    reason, says so in its status, and the points the robot receives over UDP are those of
    the frames fused (offline fusion of them, within 1e-9 m)."""
    rig, det = session
    counter, make = FAULTS[kind]
    keep = np.ones(det.n_frames, bool)
    with live(rig, status_every_s=0.05) as (send, receiver, result):
        frames = _frames(det, rig, result["epoch"])
        expected = 0
        held = None
        for i, d in enumerate(frames):
            if kind == "reordered" and i % 10 == 5 and len(d):
                held = d  # sent after the next frame: out of order (a frame without
                # candidates would be taken in any order: it fuses nothing)
                keep[i] = False
                continue
            send(_good(d))
            if held is not None:
                send(_good(held))
                held = None
                expected += 1
            elif kind != "reordered" and i % 10 == 5:
                send(make(d, frames[i - 1]))
                expected += 1
            time.sleep(0.0005)
    summary = result["summary"]
    c = summary.counters
    assert c[counter] == expected > 0, c
    others = [k for k in ("duplicate", "reordered", "late", "truncated", "oversize", "foreign",
                          "version", "malformed", "unknown_camera", "fusion_error")
              if k != counter]
    assert not any(c[k] for k in others), c
    assert c["fused"] == keep.sum() and c["lost"] == 0
    assert f"{counter} {expected}" in result["status"].getvalue()
    offline = fuse(subset(det, keep), rig, "filter", LIVE_AS_FUSED)
    got = receiver.points
    assert len(got) == len(offline) == c["points"] > 0
    np.testing.assert_array_equal([p.t_capture_ns - result["epoch"] for p in got],
                                  offline.time_ns)
    assert np.abs(np.array([p.position for p in got]) - offline.position_world).max() <= 1e-9
    # JSON lines too: one per point
    assert len(result["jsonl"].getvalue().splitlines()) == len(got)


def test_silent_camera_is_reported_and_fused_again_when_back(session):
    """cam2 sends nothing for 0.5 s of real time: the status shows it silent while cam1 and
    cam3 keep making points; back, its frames make points again."""
    rig, det = session
    with live(rig, status_every_s=0.05, silent_after_s=0.2) as (send, receiver, result):
        start = time.time_ns() + 20_000_000
        frames = _frames(det, rig, start)
        result_gap = []
        for d in frames:
            while time.time_ns() < d.t_capture_ns:
                time.sleep(0.0002)
            t = d.t_capture_ns - start
            if d.camera == "cam2" and 0.1 * NS < t < 0.6 * NS:
                result_gap.append(d)
                continue
            send(_good(d))
        time.sleep(0.05)
    status = result["status"].getvalue()
    assert "camera cam2 silent" in status and "cam2 SILENT" in status
    assert "camera cam2 live again" in status
    silent_lines = [line for line in status.splitlines() if "cam2 SILENT" in line]
    assert all("cam1 live" in line and "cam3 live" in line for line in silent_lines)
    points = receiver.points
    during = [p for p in points if 0.35 * NS < p.t_capture_ns - start < 0.6 * NS]
    after = [p for p in points if p.t_capture_ns - start > 0.6 * NS]
    assert during and {p.camera for p in during} <= {"cam1", "cam3"}
    assert "cam2" in {p.camera for p in after}
    cams = {c.name: c for c in result["summary"].cameras}
    assert cams["cam2"].lost == len(result_gap)


def test_port_in_use_is_one_line_error_and_leaves_no_file(tmp_path, session):
    rig, _ = session
    busy = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    busy.bind(("127.0.0.1", 0))
    port = busy.getsockname()[1]
    path = tmp_path / "live.mcap"
    try:
        with pytest.raises(PslogError) as info:
            serve(rig, f"udp://127.0.0.1:{port}", [RecordSink(path, rig)], duration_s=1)
    finally:
        busy.close()
    text = str(info.value)
    assert "\n" not in text and f"udp://127.0.0.1:{port}" in text and "in use" in text
    assert list(tmp_path.iterdir()) == []  # the new session file was removed


@pytest.mark.parametrize("address, says", [
    ("udp://127.0.0.1:70000", "70000"),
    ("udp://127.0.0.1:port", "not a number"),
    ("tcp://127.0.0.1:10006", "only udp://"),
    ("udp://127.0.0.1", "expected udp://HOST:PORT"),
    ("udp://no-such-host.invalid:10006", "no-such-host.invalid"),
    ("udp://192.0.2.1:10006", "192.0.2.1"),  # a documentation address: not this machine's
])
def test_bad_listen_address_is_one_line_error(session, address, says):
    rig, _ = session
    with pytest.raises(PslogError) as info:
        serve(rig, address, [], duration_s=1)
    assert "\n" not in str(info.value) and says in str(info.value)


@pytest.mark.parametrize("address", ["udp://no-such-host.invalid:9", "udp://:9",
                                     "udp://127.0.0.1:-1"])
def test_bad_out_address_is_one_line_error(address):
    with pytest.raises(PslogError) as info:
        UdpSink(address)
    assert "\n" not in str(info.value) and "--out" in str(info.value)


def test_nothing_listening_at_out_does_not_stop_the_fuser(session):
    """Points sent where nobody listens (ICMP port unreachable) are counted, not fatal."""
    rig, det = session
    gone = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gone.bind(("127.0.0.1", 0))
    address = gone.getsockname()
    gone.close()
    sink = UdpSink(address)
    with live(rig, sinks=[sink]) as (send, receiver, result):
        for d in _frames(det, rig, result["epoch"]):
            send(_good(d))
            time.sleep(0.0005)
    assert result["summary"].counters["points"] > 0
    assert sink.sent + sink.errors == result["summary"].counters["points"]
    assert len(receiver.points) == result["summary"].counters["points"]


def test_full_disk_while_recording_is_one_line_error_after_the_points(tmp_path, session):
    """The disk fills up under the recording: serve stops with a one-line PslogError
    naming the session file and the OS's reason, after closing every sink; the robot got
    every point made until then (its UDP sink comes first), and no traceback of the
    recording thread."""
    from tests.faults._mounts import fill, small_tmpfs

    rig, det = session
    with small_tmpfs(tmp_path / "disk", "256k") as disk:
        path = disk / "live.mcap"
        record = RecordSink(path, rig, flush_interval_s=0.05)
        fill(disk, free=6_000)
        with live(rig, expect_error=True, sinks=[record]) as (send, receiver, result):
            for second in range(30):  # the session again each second, until the disk is full
                for d in _frames(det, rig, result["epoch"] + second * NS):
                    send(_good(d))
                    time.sleep(0.0003)
                time.sleep(0.1)
                if record._error is not None:
                    break
        error = result.get("error")
        assert isinstance(error, PslogError), error
        text = str(error)
        assert "\n" not in text and str(path) in text and "No space left" in text
        assert receiver.points  # the points made before the disk filled were sent


@pytest.mark.parametrize("kwargs, says", [
    (dict(method="smooth"), "offline"),
    (dict(method="typeZ"), "unknown fusion method"),
    (dict(status_every_s=0), "status period"),
    (dict(duration_s=-1), "duration"),
    (dict(silent_after_s=-2), "silent"),
    (dict(late_s=float("nan")), "late"),
])
def test_bad_serve_settings_are_one_line_errors_leaving_no_file(tmp_path, session, kwargs,
                                                                  says):
    rig, _ = session
    path = tmp_path / "live.mcap"
    with pytest.raises(PslogError) as info:
        serve(rig, "udp://127.0.0.1:0", [RecordSink(path, rig)], **kwargs)
    assert "\n" not in str(info.value) and says in str(info.value)
    assert list(tmp_path.iterdir()) == []


def test_with_a_hold_overtaken_frames_are_fused_over_real_udp(session):
    """serve(hold_s=0.05): frames sent out of order (each 10th held back behind the next)
    are all fused in capture order: nothing dropped, the robot's points are those of the
    whole session."""
    rig, det = session
    with live(rig, hold_s=0.05) as (send, receiver, result):
        frames = _frames(det, rig, result["epoch"])
        held = None
        for i, d in enumerate(frames):
            if i % 10 == 5 and len(d):
                held = d
                continue
            send(_good(d))
            if held is not None:
                send(_good(held))
                held = None
            time.sleep(0.0005)
    c = result["summary"].counters
    assert c["reordered"] == c["late"] == 0 and c["fused"] == det.n_frames
    offline = fuse(det, rig, "filter", LIVE_AS_FUSED)
    got = receiver.points
    assert len(got) == len(offline)
    np.testing.assert_array_equal([p.t_capture_ns - result["epoch"] for p in got],
                                  offline.time_ns)
    assert np.abs(np.array([p.position for p in got]) - offline.position_world).max() <= 1e-9
