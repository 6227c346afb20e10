"""The live viewers of ``pslog live`` (viewers/live.py): a real rerun stream served over gRPC
and read back by a real rerun client, a real Foxglove WebSocket server read by a real
WebSocket client speaking its protocol, the same topics and schemas as a recorded session
file, and sinks that drop (and count) rather than delay the fuser."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import signal
import socket
import struct
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from _live import free_port
from _rrd import RERUN, batch_column, capture_times, rrd_chunks
from mcap.reader import make_reader

from pslog.errors import InputError
from pslog.live.fuser import LivePoint
from pslog.live.protocol import DetectionDatagram
from pslog.log import SessionWriter
from pslog.log import _schemas as S
from pslog.motion import get_motion
from pslog.records import NS, Track
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate
from viewers._columns import PIXEL_CENTER
from viewers.live import FoxgloveSink, RerunLiveSink, std_m

T0 = 1_790_000_000 * NS  # a wall-clock session clock, as the live camera processes stamp
HANG_S = 60.0  # generous guard against a hang, never a timing assertion


@pytest.fixture(scope="module")
def rig():
    return apply_timing(builtin_rig("paper3"), "typeA")


@pytest.fixture(scope="module")
def stream(rig):
    """A throw seen by the three cameras: each frame's detection datagram and, per frame with
    a detection, a point at the true position (covariance, prediction and velocity set)."""
    det, truth = simulate(rig, get_motion("throw"), 0.3,
                          SimulationOptions(noise_px=0.3, miss_rate=0.1, seed=5))
    bounds = np.searchsorted(det.cand_frame, np.arange(det.n_frames + 1))
    datagrams, points = [], []
    for i in range(det.n_frames):
        cam = int(det.frame_camera[i])
        t = T0 + int(det.frame_time_ns[i])
        rows = slice(bounds[i], bounds[i + 1])
        datagrams.append(DetectionDatagram(
            camera=rig.names[cam], sequence=int(det.frame_index[i]),
            frame_index=int(det.frame_index[i]), t_capture_ns=t, t_sent_ns=t + 1000,
            uv=det.cand_uv[rows], radius=det.cand_radius[rows], score=det.cand_score[rows]))
        if bounds[i + 1] > bounds[i]:
            p = truth.at(np.array([det.frame_time_ns[i]]))[0]
            sigma = 0.002 * (1 + i % 3)
            points.append(LivePoint(
                method="filter", camera=rig.names[cam], camera_index=cam, t_capture_ns=t,
                t_emit_ns=t + 400_000, position_world=p, cov_world=np.eye(3) * sigma ** 2,
                residual_px=0.1 * (i % 5), camera_mask=1 << cam,
                predicted_position=p + np.array([0.001, 0.0, 0.0]),
                predicted_velocity=np.array([1.0, 0.5, -0.2]), arrival_ns=t + 300_000,
                quality={"std_m": np.sqrt(3) * sigma, "residual_px": 0.1 * (i % 5)}))
    return datagrams, points


# ---- rerun ---------------------------------------------------------------------------------
def _rows(rrd: Path, entity: str) -> int:
    """Rows of ``entity`` in an .rrd that may still be being written (0 if unreadable yet)."""
    try:
        temporal, _ = rrd_chunks(rrd, unfinished=True)
    except Exception:  # the client is still writing the first bytes
        return 0
    return sum(b.num_rows for b in temporal.get(entity, []))


@contextlib.contextmanager
def _rerun_client(uri: str, out: Path):
    """A real rerun client: ``rerun URI --save OUT`` reads the served stream into a file. It
    gets its own process group (``rerun`` is a wrapper that starts the binary), ended whole."""
    client = subprocess.Popen([str(RERUN), uri, "--save", str(out), "--port", str(free_port())],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    try:
        yield client
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(client.pid, signal.SIGKILL)
        client.wait()


def _check_rerun_content(rrd: Path, rig, datagrams, points) -> None:
    temporal, static = rrd_chunks(rrd, unfinished=True)
    for cam in rig.names:
        assert {f"/world/cameras/{cam}", f"/world/cameras/{cam}/image"} <= static
    base = "/world/tracks/filter"
    # every point where it was emitted, at its capture time on the session clock
    track = temporal[base]
    np.testing.assert_array_equal(capture_times(track), [p.t_capture_ns for p in points])
    np.testing.assert_allclose(np.array([v[0] for v in batch_column(track, "Points3D:positions")]),
                               np.array([p.position_world for p in points]), atol=1e-6)
    # its uncertainty: a sphere of radius 2σ (σ = sqrt of the covariance's trace)
    radii = [v[0] for v in batch_column(temporal[f"{base}/uncertainty"], "Points3D:radii")]
    np.testing.assert_allclose(radii, [2 * std_m(p.cov_world) for p in points], rtol=1e-6)
    assert sum(b.num_rows for b in temporal[f"{base}/trail"]) == len(points) - 1
    predicted = batch_column(temporal[f"{base}/predicted"], "Points3D:positions")
    np.testing.assert_allclose(np.array([v[0] for v in predicted]),
                               np.array([p.predicted_position for p in points]), atol=1e-6)
    assert sum(b.num_rows for b in temporal[f"{base}/predicted/velocity"]) == len(points)
    latency = batch_column(temporal["/plots/latency_ms/filter"], "Scalars:scalars")
    np.testing.assert_allclose([v[0] for v in latency], [0.1] * len(points))
    # each camera's detections on its image plane (rerun pixel centres), every frame logged
    # (an empty one clears the last), and one ray per candidate
    for cam in rig.names:
        mine = [d for d in datagrams if d.camera == cam]
        image = temporal[f"/world/cameras/{cam}/image/detections"]
        np.testing.assert_array_equal(capture_times(image), [d.t_capture_ns for d in mine])
        shown = batch_column(image, "Points2D:positions")
        for d, uv in zip(mine, shown, strict=True):
            np.testing.assert_allclose(np.array(uv or np.zeros((0, 2))).reshape(-1, 2),
                                       d.uv + PIXEL_CENTER, atol=1e-3)
        rays = batch_column(temporal[f"/world/rays/{cam}"], "LineStrips3D:strips")
        assert [len(r or []) for r in rays] == [len(d) for d in mine]
        assert f"/plots/detection_rate/{cam}" in temporal


def test_rerun_serve_streams_points_and_detections_to_a_client(rig, stream, tmp_path,
                                                               monkeypatch):
    """``--serve``: the sink serves the stream (gRPC and the web viewer, both on free ports);
    a real rerun client connected to it receives the rig, every point (position, 2σ sphere,
    trail, predicted state, latency) and every camera frame's detections and rays."""
    monkeypatch.delenv("DISPLAY", raising=False)  # no browser opens
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    datagrams, points = stream
    sink = RerunLiveSink("serve", rig, web_port=free_port(), grpc_port=free_port())
    assert sink.address.startswith("http://localhost:")
    out = tmp_path / "client.rrd"
    try:
        with _rerun_client(sink.sink.uri, out):
            by_time = sorted([(d.t_capture_ns, 0, d) for d in datagrams]
                             + [(p.t_capture_ns, 1, p) for p in points], key=lambda x: x[:2])
            for _t, kind, item in by_time:  # as the fuser hands them over
                if kind == 0:
                    sink.detections(item)
                else:
                    sink.emit([item])
            deadline = time.monotonic() + HANG_S
            while (_rows(out, "/world/tracks/filter") < len(points)
                   or _rows(out, "/plots/latency_ms/filter") < len(points)):
                assert time.monotonic() < deadline, "the client never got every point"
                time.sleep(0.2)
            time.sleep(0.5)  # the rest of the same flush (detections were logged earlier)
        sink.close()
        assert sink.error is None
        counters = sink.counters()
        assert counters["points"] == len(points) and counters["dropped_points"] == 0
        assert counters["detections"] == len(datagrams)
    finally:
        sink.close()
    _check_rerun_content(out, rig, datagrams, points)


def test_rerun_connect_sends_to_a_running_viewer(rig, stream, tmp_path):
    """``connect``: the stream goes to a rerun gRPC server already running (here one that saves
    what it receives); closing the sink delivers everything logged."""
    datagrams, points = stream
    port = free_port()
    out = tmp_path / "viewer.rrd"
    viewer = subprocess.Popen([str(RERUN), "--bind", "127.0.0.1", "--port", str(port),
                               "--save", str(out)], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + HANG_S
        while True:  # until the viewer listens
            with contextlib.suppress(OSError):
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            assert time.monotonic() < deadline and viewer.poll() is None
            time.sleep(0.1)
        sink = RerunLiveSink("connect", rig, url=f"rerun+http://127.0.0.1:{port}/proxy")
        for d in datagrams:
            sink.detections(d)
        sink.emit(points)  # one batch
        sink.close()
        assert sink.error is None and sink.counters()["points"] == len(points)
        while _rows(out, "/world/tracks/filter") < len(points):
            assert time.monotonic() < deadline, "the viewer never got every point"
            time.sleep(0.2)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(viewer.pid, signal.SIGKILL)
        viewer.wait()
    temporal, static = rrd_chunks(out, unfinished=True)
    assert {f"/world/cameras/{c}/image" for c in rig.names} <= static
    assert sum(b.num_rows for b in temporal["/world/cameras/cam3/image/detections"]) == len(
        [d for d in datagrams if d.camera == "cam3"])


def test_rerun_view_without_display_explains(rig, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(InputError, match=r"no display .* use --serve"):
        RerunLiveSink("spawn", rig)


def test_rerun_serve_refuses_a_port_in_use(rig):
    with socket.socket() as busy:
        busy.bind(("0.0.0.0", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(InputError) as info:
            RerunLiveSink("serve", rig, web_port=free_port(), grpc_port=port)
    message = str(info.value)
    assert f"port {port} is in use" in message and "\n" not in message


class _StalledRerun(RerunLiveSink):
    """A viewer that takes for ever to draw a point: its thread waits at the first one."""

    def __init__(self, *args, **kwargs) -> None:
        self.entered = threading.Event()
        self.release = threading.Event()
        super().__init__(*args, **kwargs)

    def _point(self, p) -> None:
        self.entered.set()
        assert self.release.wait(HANG_S)
        super()._point(p)


def test_a_stalled_viewer_drops_and_counts_but_never_blocks(rig, stream, tmp_path):
    """The fuser's calls return while the viewer is stuck: what does not fit in the queue is
    dropped and counted; once the viewer moves on it shows what was queued."""
    _datagrams, points = stream
    rec = rr.RecordingStream("pslog")
    path = tmp_path / "stalled.rrd"
    rec.save(path)
    sink = _StalledRerun(None, rig, recording=rec, queue_items=3)
    sink.emit([points[0]])
    assert sink.entered.wait(HANG_S)  # the viewer's thread is now stuck in the first point

    def fuser() -> None:  # every other point and a status line, each call returning at once
        for p in points[1:]:
            sink.emit([p])
        sink.status("cam1 live", {"received": 1})

    thread = threading.Thread(target=fuser)
    thread.start()
    thread.join(HANG_S)
    assert not thread.is_alive(), "emit blocked on a stalled viewer"
    assert sink.counters()["dropped_points"] == len(points) - 4  # 1 drawing + 3 queued
    sink.release.set()
    sink.close()
    rec.disconnect()
    assert sink.counters()["points"] == 4
    temporal, _ = rrd_chunks(path, unfinished=True)
    np.testing.assert_array_equal(capture_times(temporal["/world/tracks/filter"]),
                                  [p.t_capture_ns for p in points[:4]])


# ---- Foxglove ------------------------------------------------------------------------------
def _recorded_channels(tmp_path, rig, datagrams, points) -> dict[str, tuple[str, bytes]]:
    """topic -> (schema name, schema data) of a session file recorded with the same rig,
    detections and track as the live run."""
    path = tmp_path / "recorded.mcap"
    with SessionWriter(path, rig) as writer:
        for d in datagrams:
            writer.add_frame(rig.names.index(d.camera), d.frame_index, d.t_capture_ns, d.uv,
                             d.radius, d.score)
        writer.add_track(Track(
            "filter", np.array([p.t_capture_ns for p in points]),
            np.array([p.position_world for p in points]),
            np.array([p.camera_index for p in points])))
        writer.add_event(points[0].t_capture_ns, "a live session has events")
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    return {c.topic: (summary.schemas[c.schema_id].name, summary.schemas[c.schema_id].data)
            for c in summary.channels.values()}


class _FoxgloveClient:
    """A client of the Foxglove WebSocket protocol (JSON control messages, binary message
    data: opcode 1, subscription id u32, log time u64, payload)."""

    def __init__(self, ws) -> None:
        self.ws = ws
        self.channels: dict[str, dict] = {}  # topic -> advertised channel
        self.topic_of: dict[int, str] = {}  # subscription id -> topic

    async def read_advertisements(self, topics) -> None:
        while not set(topics) <= set(self.channels):
            message = json.loads(await self.ws.recv())
            if message["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in message["channels"]})

    async def subscribe(self, topics) -> None:
        subs = [{"id": i, "channelId": self.channels[t]["id"]} for i, t in enumerate(topics)]
        self.topic_of = dict(enumerate(topics))
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def next_message(self) -> tuple[str, int, bytes]:
        """(topic, log time, payload) of the next message data."""
        while True:
            data = await self.ws.recv()
            if isinstance(data, bytes) and data[0] == 1:
                sub, log_time = struct.unpack_from("<IQ", data, 1)
                return self.topic_of[sub], log_time, data[13:]


def _decode(topic: str, payload: bytes):
    cls = {"calibration": S.CameraCalibration, "detections": S.DetectionFrame,
           "transform": S.FrameTransform}.get(topic.rsplit("/", 1)[1])
    if topic.endswith("/scene"):
        cls = S.SceneUpdate
    elif topic.startswith("/tracks/"):
        cls = S.TrackPoint
    return cls.FromString(payload)


def test_foxglove_publishes_the_recorded_topics_live(rig, stream, tmp_path):
    """A real WebSocket client speaking the Foxglove protocol sees the recorded file's topics
    with the same protobuf schemas, subscribes, and decodes the camera calibration, a
    camera's detections and the track point exactly as they were emitted."""
    import websockets

    datagrams, points = stream
    sink = FoxgloveSink(rig, port=0)
    recorded = _recorded_channels(tmp_path, rig, datagrams, points)
    point = points[7]
    frame = next(d for d in datagrams if len(d) and d.camera == "cam2")
    wanted = ["/camera/cam1/calibration", "/camera/cam2/detections", "/tracks/filter",
              "/tracks/filter/scene"]

    async def run() -> dict[str, list]:
        async with websockets.connect(
                sink.address, subprotocols=["foxglove.sdk.v1", "foxglove.websocket.v1"],
                max_size=None) as ws:
            client = _FoxgloveClient(ws)
            await client.read_advertisements(recorded)
            for topic, (name, data) in recorded.items():  # same topics, schemas as a file
                channel = client.channels[topic]
                assert (channel["schemaName"], channel["encoding"]) == (name, "protobuf")
                assert base64.b64decode(channel["schema"]) == data
            assert set(client.channels) == set(recorded)
            await client.subscribe(wanted)
            got: dict[str, list] = {}
            # the calibration is re-sent every second: once it arrives the subscriptions
            # are active, and the point and the detections go out
            while "/camera/cam1/calibration" not in got:
                topic, log_time, payload = await client.next_message()
                got.setdefault(topic, []).append((log_time, _decode(topic, payload)))
            sink.detections(frame)
            sink.emit([point])
            while not {"/tracks/filter", "/tracks/filter/scene",
                       "/camera/cam2/detections"} <= set(got):
                topic, log_time, payload = await client.next_message()
                got.setdefault(topic, []).append((log_time, _decode(topic, payload)))
            return got

    try:
        got = asyncio.run(asyncio.wait_for(run(), HANG_S))
    finally:
        sink.close()
    calib = got["/camera/cam1/calibration"][0][1]
    cam1 = rig.camera("cam1")
    assert (calib.frame_id, calib.width, calib.height) == ("cam1", cam1.width, cam1.height)
    np.testing.assert_array_equal(calib.K, cam1.K.ravel())
    (log_time, msg), = got["/tracks/filter"]
    assert log_time == msg.time_ns == point.t_capture_ns
    assert (msg.x, msg.y, msg.z) == tuple(point.position_world)  # exact: float64 both ways
    assert (msg.method, msg.camera) == ("filter", point.camera)
    assert dict(msg.quality) == point.quality  # the method's quality columns, as recorded
    assert all(np.isnan(getattr(msg, k)) for k in S.TRACK_FIXED_QUALITY)
    sphere = got["/tracks/filter/scene"][0][1].entities[0].spheres[0]
    assert (sphere.pose.position.x, sphere.pose.position.y, sphere.pose.position.z) == tuple(
        point.position_world)
    (log_time, det), = got["/camera/cam2/detections"]
    assert log_time == det.time_ns == frame.t_capture_ns and det.frame_index == frame.frame_index
    np.testing.assert_array_equal(np.column_stack([det.u, det.v]), frame.uv)
    np.testing.assert_array_equal(det.score, frame.score)
    assert sink.counters()["points"] == 1 and sink.error is None


def test_foxglove_refuses_a_port_in_use(rig):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        with pytest.raises(InputError) as info:
            FoxgloveSink(rig, port=port)
    message = str(info.value)
    assert f"127.0.0.1:{port}" in message and "in use" in message and "\n" not in message


def test_foxglove_close_is_idempotent_and_frees_the_port(rig):
    """Closing stops the server: the same port can be served again at once."""
    sink = FoxgloveSink(rig, port=0)
    port = sink.port
    sink.close()
    sink.close()
    again = FoxgloveSink(rig, port=port)
    again.close()
    sink.emit([object()])  # after close: dropped and counted, no error
    assert sink.counters()["dropped_points"] == 1


# ---- a live run ----------------------------------------------------------------------------
def _file_messages(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    with path.open("rb") as f:
        out: dict[str, list[tuple[int, bytes]]] = {}
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append((message.log_time, message.data))
    return out


def test_a_live_run_shows_in_foxglove_and_rerun_as_it_is_recorded(tmp_path):
    """``serve`` with the recording, the Foxglove server and a rerun stream, detections sent
    over real UDP: a Foxglove client subscribed before the run gets, byte for byte and with
    the same log times, the messages the session file holds on the track and detection
    topics; the rerun stream holds every point at its session time."""
    import websockets

    from pslog.live.fuser import LiveFuser
    from pslog.live.protocol import encode_detections
    from pslog.live.server import serve
    from pslog.live.sinks import RecordSink
    from tests._live import EPOCH, frames, rally_session

    rig, det = rally_session(0.6)
    # candidates worst first: the recording (and so Foxglove) keeps a fused frame best first
    sent = [DetectionDatagram(d.camera, d.sequence, d.frame_index, d.t_capture_ns,
                              d.t_sent_ns, d.uv[::-1], d.radius[::-1], d.score[::-1])
            for d in frames(det, rig)]
    assert any(len(d) > 1 and d.score[0] < d.score[-1] for d in sent)
    # the points the fuser makes before its final flush (same datagrams, same order)
    offline = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    n_points = sum(len(offline.feed(encode_detections(d), d.t_capture_ns)) for d in sent)
    assert n_points > 20
    session = tmp_path / "live.mcap"
    rec = rr.RecordingStream("pslog")
    rrd = tmp_path / "live.rrd"
    rec.save(rrd)
    sinks = [RecordSink(session, rig, "filter"), FoxgloveSink(rig, port=0),
             RerunLiveSink(None, rig, recording=rec)]
    stop, ready = threading.Event(), threading.Event()
    server = threading.Thread(target=serve, args=(rig, "udp://127.0.0.1:0", sinks),
                              kwargs=dict(stop=stop, ready=ready, epoch_ns=EPOCH,
                                          status_stream=None))
    topics = ["/camera/cam1/calibration", "/tracks/filter",
              *(f"/camera/{c}/detections" for c in rig.names)]

    async def client() -> dict[str, list]:
        got: dict[str, list] = {}
        async with websockets.connect(sinks[1].address, max_size=None,
                                      subprotocols=["foxglove.sdk.v1"]) as ws:
            fox = _FoxgloveClient(ws)
            await fox.read_advertisements(topics)
            await fox.subscribe(topics)
            while "/camera/cam1/calibration" not in got:  # the subscriptions are active
                topic, log_time, payload = await fox.next_message()
                got.setdefault(topic, []).append((log_time, payload))
            server.start()
            assert ready.wait(HANG_S)
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as udp:
                for d in sent:
                    udp.sendto(encode_detections(d), ready.address)
            frames_in = 0
            while len(got.get("/tracks/filter", [])) < n_points or frames_in < len(sent):
                topic, log_time, payload = await fox.next_message()
                got.setdefault(topic, []).append((log_time, payload))
                frames_in += topic.endswith("/detections")
            stop.set()  # serve flushes, closes every sink: the Foxglove server stops
            with contextlib.suppress(websockets.ConnectionClosed):
                while True:
                    topic, log_time, payload = await fox.next_message()
                    got.setdefault(topic, []).append((log_time, payload))
        return got

    try:
        got = asyncio.run(asyncio.wait_for(client(), HANG_S))
    finally:
        stop.set()
        if server.is_alive() or server.ident is not None:
            server.join(HANG_S)
        for sink in sinks[1:]:
            sink.close()
    rec.disconnect()
    recorded = _file_messages(session)
    track = got["/tracks/filter"]
    assert len(track) >= n_points
    assert track == recorded["/tracks/filter"][:len(track)]
    for cam in rig.names:
        topic = f"/camera/{cam}/detections"
        assert got[topic] == recorded[topic] and len(got[topic]) == sum(
            d.camera == cam for d in sent)
    temporal, _ = rrd_chunks(rrd, unfinished=True)
    shown = capture_times(temporal["/world/tracks/filter"])
    stored = [t for t, _ in recorded["/tracks/filter"]]
    np.testing.assert_array_equal(shown, stored)  # session times, every point
    assert sinks[2].counters()["dropped_points"] == 0


def test_live_detection_rate_counts_the_ball_not_a_static_distractor(rig, tmp_path):
    """The live view's rolling rate counted the frames with any candidate: a second orange
    object in view read 100 % though the ball was missed in half the frames. It counts the
    frames with a candidate off every static spot of the camera's last 2 s: once the spot is
    seen in 10 frames, the plotted rate is the ball's (against the simulation's labels)."""
    from pslog.simulation import simulate_labelled

    det, _truth, ball = simulate_labelled(rig, get_motion("throw"), 1.5, SimulationOptions(
        noise_px=0.5, miss_rate=0.5, distractors=(("cam1", (0.5, 0.3, 0.1)),), seed=3))
    rec = rr.RecordingStream("pslog")
    path = tmp_path / "live.rrd"
    rec.save(path)
    sink = RerunLiveSink(None, rig, recording=rec)
    bounds = np.searchsorted(det.cand_frame, np.arange(det.n_frames + 1))
    for i in range(det.n_frames):
        t = T0 + int(det.frame_time_ns[i])
        sink.detections(DetectionDatagram(
            camera=rig.names[det.frame_camera[i]], sequence=int(det.frame_index[i]),
            frame_index=int(det.frame_index[i]), t_capture_ns=t, t_sent_ns=t + 1000,
            uv=det.cand_uv[bounds[i]:bounds[i + 1]],
            radius=det.cand_radius[bounds[i]:bounds[i + 1]],
            score=det.cand_score[bounds[i]:bounds[i + 1]]))
    sink.close()
    rec.flush()
    assert sink.error is None
    rows = np.flatnonzero(det.frame_camera == 0)
    assert (det.candidates_per_frame()[rows] > 0).all()  # the distractor in every frame
    seen = ball.candidates_per_frame()[rows] > 0  # the frames the ball was detected in
    assert 0.3 < seen.mean() < 0.7
    temporal, _ = rrd_chunks(path, unfinished=True)
    rate = np.array([v[0] for v in batch_column(temporal["/plots/detection_rate/cam1"],
                                                "Scalars:scalars")])
    window = round(rig.cameras[0].fps)  # the last second
    expected = np.array([100.0 * seen[max(0, i + 1 - window):i + 1].mean()
                         for i in range(len(rows))])
    settled = 10 - 1 + window  # the spot static from its 10th frame, then a whole window
    assert len(rate) == len(rows) > settled + 5
    np.testing.assert_allclose(rate[settled:], expected[settled:])
    assert rate[:settled].max() == 100.0  # before: the distractor's frames counted
