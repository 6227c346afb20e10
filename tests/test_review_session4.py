"""Fresh-eyes review of session 4's changes: the columnar MCAP reader on files another tool
wrote (other compressions, chunk sizes, protobuf fields in another order, no message index),
and the filter's coordinated-turn model against its closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from pslog.cli import main
from pslog.log import _schemas as S
from pslog.log import read_session


@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    """A small dirty session fused with two methods (detections with false candidates,
    truth, tracks with quality maps)."""
    tmp = tmp_path_factory.mktemp("review4")
    session, out = tmp / "dirty.mcap", tmp / "fused.mcap"
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                 "--duration", "1", "--noise-px", "0.5", "--spurious", "0.3",
                 "--spurious-radius", "30", "--miss-rate", "0.1", "--seed", "5",
                 "-o", str(session)]) == 0
    assert main(["fuse", str(session), "--method", "filter", "-o", str(out)]) == 0
    return out


def _reversed_fields(schema_name: str, data: bytes) -> bytes:
    """The same protobuf message, its fields written in reverse field-number order (a valid
    encoding: a parser merges fields in any order)."""
    cls = {"pslog.DetectionFrame": S.DetectionFrame, "pslog.TruthPoint": S.TruthPoint}.get(
        schema_name)
    if cls is None:
        return data
    msg = cls.FromString(data)
    parts = []
    for fd, _value in msg.ListFields():
        one = cls()
        one.MergeFrom(msg)
        for other, _ in one.ListFields():
            if other.number != fd.number:
                one.ClearField(other.name)
        parts.append(one.SerializeToString())
    return b"".join(reversed(parts))


def _rewrite(src, dst, compression, chunk_size, index_types=IndexType.ALL, reorder=True):
    """Copy ``src`` with the mcap package's own Writer (another tool's file)."""
    with open(src, "rb") as fin, open(dst, "wb") as fout:
        reader = make_reader(fin)
        w = Writer(fout, chunk_size=chunk_size, compression=compression,
                   index_types=index_types)
        w.start(profile="", library="another-tool")
        summary = reader.get_summary()
        schemas, channels = {}, {}
        for sid, schema in summary.schemas.items():
            schemas[sid] = w.register_schema(schema.name, schema.encoding, schema.data)
        for cid, ch in summary.channels.items():
            channels[cid] = w.register_channel(ch.topic, ch.message_encoding,
                                               schemas[ch.schema_id], ch.metadata)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            data = _reversed_fields(schema.name, message.data) if reorder else message.data
            w.add_message(channels[channel.id], message.log_time, data, message.publish_time,
                          message.sequence)
        for record in reader.iter_metadata():
            w.add_metadata(record.name, record.metadata)
        w.finish()


def _assert_same_session(a, b):
    for k in ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
              "cand_radius", "cand_score"):
        assert np.asarray(getattr(a.detections, k)).tobytes() == \
            np.asarray(getattr(b.detections, k)).tobytes(), k
    assert a.truth.time_ns.tobytes() == b.truth.time_ns.tobytes()
    assert a.truth.position_world.tobytes() == b.truth.position_world.tobytes()
    assert list(a.tracks) == list(b.tracks)
    for m in a.tracks:
        assert a.tracks[m].position_world.tobytes() == b.tracks[m].position_world.tobytes()
        assert list(a.tracks[m].quality) == list(b.tracks[m].quality)


@pytest.mark.parametrize("compression,chunk_size", [
    (CompressionType.NONE, 4096), (CompressionType.LZ4, 1 << 20),
    (CompressionType.ZSTD, 777)])
def test_a_file_another_tool_wrote_with_fields_in_another_order_reads_the_same(
        fused, tmp_path, compression, chunk_size):
    other = tmp_path / "other.mcap"
    _rewrite(fused, other, compression, chunk_size)
    _assert_same_session(read_session(other), read_session(fused))


def test_a_file_without_message_indexes_reads_every_message(fused, tmp_path):
    """Chunks without MessageIndex records (index_types without MESSAGE): the chunk index's
    message_index_offsets are empty, yet the messages are in the chunks."""
    other = tmp_path / "noindex.mcap"
    _rewrite(fused, other, CompressionType.ZSTD, 1 << 16,
             index_types=IndexType.CHUNK | IndexType.ATTACHMENT | IndexType.METADATA,
             reorder=False)
    got = read_session(other)
    want = read_session(fused)
    assert got.detections.n_frames == want.detections.n_frames > 0
    _assert_same_session(got, want)


# ---- the coordinated-turn model --------------------------------------------------------------


def test_turn_prediction_is_the_closed_form_circle_and_its_jacobian_the_derivative():
    """x(t) of a coordinated turn at rate ω about z is a circle; the covariance propagation
    uses F = ∂f/∂x (checked by central differences of the mean, ω included)."""
    from pslog.fusion import filter as FM

    f = FM.BallFilter.__new__(FM.BallFilter)
    f._q, f._turn_psd = 0.0, 0.0
    x = [0.3, -0.2, 1.1, 2.0, 1.0, 0.5, 3.0]
    dt = 0.37
    P = list(np.eye(7).ravel())
    xn, Pn = f._turn_predicted(x, P, dt)
    w = x[6]
    a = w * dt
    want = [x[0] + (math.sin(a) * x[3] - (1 - math.cos(a)) * x[4]) / w,
            x[1] + ((1 - math.cos(a)) * x[3] + math.sin(a) * x[4]) / w,
            x[2] + x[5] * dt,
            math.cos(a) * x[3] - math.sin(a) * x[4], math.sin(a) * x[3] + math.cos(a) * x[4],
            x[5], w]
    assert np.allclose(xn, want, rtol=0, atol=1e-12)

    def jacobian(x, h):  # ∂f/∂x by central differences of the predicted mean
        F = np.zeros((7, 7))
        for j in range(7):
            up, dn = list(x), list(x)
            up[j] += h
            dn[j] -= h
            F[:, j] = (np.array(f._turn_predicted(up, P, dt)[0])
                       - np.array(f._turn_predicted(dn, P, dt)[0])) / (2 * h)
        return F

    F = jacobian(x, 1e-6)
    assert np.allclose(np.array(Pn).reshape(7, 7), F @ F.T, atol=1e-6)
    # near ω = 0 (the series branch) too
    x0 = [*x[:6], 1e-5]
    F0 = jacobian(x0, 1e-7)
    assert np.allclose(np.array(f._turn_predicted(x0, P, dt)[1]).reshape(7, 7), F0 @ F0.T,
                       atol=1e-5)


def test_images_of_a_file_without_message_indexes_are_found(tmp_path, rig3):
    from conftest import make_jpeg

    from pslog.log import SessionWriter, iter_images

    session, other = tmp_path / "img.mcap", tmp_path / "noindex.mcap"
    with SessionWriter(session, rig3) as w:
        for k in range(3):
            for cam in range(3):
                w.add_frame(cam, k, k * 33_333_333 + cam * 11_111_111, uv=[[10.0 + k, 20.0]],
                            image=make_jpeg(20 * k + cam))
    want = [(i.camera, i.time_ns) for i in iter_images(session)]
    _rewrite(session, other, CompressionType.LZ4, 1 << 16,
             index_types=IndexType.CHUNK | IndexType.METADATA, reorder=False)
    assert len(want) == 9
    assert [(i.camera, i.time_ns) for i in iter_images(other)] == want
    assert read_session(other).detections.n_frames == 9


def test_methods_doc_states_the_filters_turn_defaults():
    """docs/methods.md quotes the turn model's thresholds; they must be the code's."""
    import re
    from pathlib import Path

    from pslog.fusion.filter import FilterOptions

    text = Path(__file__).resolve().parents[1].joinpath("docs", "methods.md").read_text()
    o = FilterOptions()
    quoted = {name: float(v) for name, v in re.findall(
        r"`(turn_on_accel2|turn_switch_per_s|turn_rate_psd|init_span_s|init_max_window)`? ?="
        r"\s*([0-9.]+)", text)}
    quoted.update({name: float(v) for v, name in re.findall(
        r"`?λ_t = ([0-9.]+) /s`? \(`(turn_switch_per_s)`", text)})
    assert o.turn_on_psd is None and quoted.get("turn_on_accel2") == o.turn_on_accel2
    for name, value in quoted.items():
        want = getattr(o, name)
        assert math.isclose(value, want) or (name == "init_span_s" and value == want * 1000), \
            (name, value, want)


def _moments(weights, means, covs):
    mean = sum(w * m for w, m in zip(weights, means, strict=True))
    cov = sum(w * (c + np.outer(m - mean, m - mean))
              for w, m, c in zip(weights, means, covs, strict=True))
    return mean, cov


@pytest.mark.parametrize("nu,dt", [(0.1, 0.011), (0.7, 0.2), (0.95, 1.5)])
def test_turn_mixing_keeps_the_mixtures_mean_and_covariance(nu, dt):
    """IMM mixing only relabels the models: the whole mixture's first two moments (position
    and velocity) are the same before and after (Bar-Shalom et al. 11.6.6)."""
    from pslog.fusion import filter as FM

    rng = np.random.default_rng(3)
    f = FM.BallFilter.__new__(FM.BallFilter)
    f._turn_switch = 0.5
    A, B = rng.normal(size=(6, 6)), rng.normal(size=(7, 7))
    Pg, Pt = A @ A.T + np.eye(6), B @ B.T + np.eye(7)
    xg, xt = rng.normal(size=6), rng.normal(size=7)
    f._xt, f._Pt = xt.tolist(), Pt.ravel().tolist()
    prior, x0, P0, xt0, Pt0 = f._turn_mixed(nu, xg.tolist(), Pg.ravel().tolist(), dt)
    p = min(0.5 * dt, 0.5)
    assert math.isclose(prior, nu * (1 - p) + (1 - nu) * p)
    before = _moments([1 - nu, nu], [xg, xt[:6]], [Pg, Pt[:6, :6]])
    Pt0 = np.array(Pt0).reshape(7, 7)
    after = _moments([1 - prior, prior], [np.array(x0), np.array(xt0[:6])],
                     [np.array(P0).reshape(6, 6), Pt0[:6, :6]])
    assert np.allclose(before[0], after[0], atol=1e-12)
    assert np.allclose(before[1], after[1], atol=1e-10)
    assert np.all(np.linalg.eigvalsh(Pt0) > 0)  # the turn model's covariance stays positive


# ---- live: stopping while a sender floods the socket ------------------------------------------
_FLOOD = r"""
import socket, sys, time
sys.path.insert(0, sys.argv[3])
from _live import datagrams, rally_session
rig, det = rally_session(1.0)
data = datagrams(det, rig, int(sys.argv[2]))
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
end = time.monotonic() + 60
i = 0
while time.monotonic() < end:  # faster than any fuser: one datagram every few µs
    try:
        sock.sendto(data[i % len(data)], ("127.0.0.1", int(sys.argv[1])))
    except OSError:
        pass
    i += 1
    if i == 2000:  # under way: the test stops the server from now on
        print("flooding", flush=True)
"""


def test_serve_stops_while_a_sender_floods_it(tmp_path):
    """At the stop, serve fuses what had arrived, then returns: a sender still sending
    (faster than the fuser) must not keep it draining the socket forever."""
    import subprocess
    import sys
    import threading
    import time
    from pathlib import Path

    from _live import EPOCH, rally_session

    from pslog.live.server import serve

    rig, _ = rally_session(0.1)
    ready, stop = threading.Event(), threading.Event()
    ready.address = None
    result = {}

    def run():
        result["summary"] = serve(rig, "udp://127.0.0.1:0", [], stop=stop, ready=ready,
                                  epoch_ns=EPOCH, status_stream=None)

    server = threading.Thread(target=run, daemon=True)
    server.start()
    assert ready.wait(60)
    script = tmp_path / "flood.py"
    script.write_text(_FLOOD)
    tests = str(Path(__file__).resolve().parent)
    flood = subprocess.Popen([sys.executable, str(script), str(ready.address[1]), str(EPOCH),
                              tests], stdout=subprocess.PIPE, text=True)
    try:
        # the flood under way (its setup done, 2,000 datagrams sent), not a fixed sleep; a
        # hang guard as the flood's own 60 s
        under_way = threading.Thread(target=flood.stdout.readline, daemon=True)
        under_way.start()
        under_way.join(60)
        assert not under_way.is_alive() and flood.poll() is None, "the flood did not start"
        time.sleep(0.5)  # the server draining the flood meanwhile
        assert flood.poll() is None
        stop.set()
        server.join(30)  # a generous hang guard: the flood lasts 60 s
        assert not server.is_alive(), "serve kept draining a socket a sender kept filling"
        assert result["summary"] is not None
    finally:
        flood.kill()
        flood.wait()
        stop.set()
        server.join(60)
