"""SessionWriter.add_track writes, block by block, the very bytes protobuf gives each point's
TrackPoint and SceneUpdate (pslog.log._wire; detections: pslog.log._encode), zeros, -0.0,
NaN and long ids included."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

from pslog.log import SessionWriter, _chunks
from pslog.log import _schemas as S
from pslog.log import writer as W
from pslog.records import Track


def _track(n: int, method: str, extra: bool, rng) -> Track:
    t = np.sort(rng.integers(0, 10**13, n))
    t[0] = 0
    xyz = rng.normal(size=(n, 3))
    xyz[1::7, 0] = 0.0
    xyz[2::7, 1] = -0.0
    xyz[3::11] = 0.0
    xyz[4::13, 2] = np.nan
    quality = {"ray_miss_m": rng.random(n), "snap_px": np.where(rng.random(n) < .3, 0.0, 1.5)}
    if extra:
        quality["std_m"] = rng.random(n)
        quality["n_detections"] = rng.integers(0, 5, n).astype(float)
        quality["cov_xx_m2"] = np.where(rng.random(n) < .5, -0.0, 2e-5)
    return Track(method, t, xyz, rng.integers(0, 3, n).astype(np.int32), quality)


@pytest.mark.parametrize("extra", [True, False])
def test_track_blocks_are_protobufs_own_bytes(tmp_path, rig3, extra):
    rng = np.random.default_rng(5)
    n = W._TRACK_BLOCK + 1234  # more than one block
    tracks = [_track(n, "typeA", extra, rng), _track(300, "nearest", extra, rng)]
    path = tmp_path / "t.mcap"
    with SessionWriter(path, rig3) as w:
        for track in tracks:
            w.add_track(track)
        w.add_track(tracks[1])  # again: scene ids go on from 300
    got: dict[str, list[bytes]] = {}
    with open(path, "rb") as f:
        for _s, c, m in make_reader(f).iter_messages(log_time_order=False):
            got.setdefault(c.topic, []).append((m.log_time, m.data))
    for track, first_id in ((tracks[0], 0), (tracks[1], 0), (tracks[1], 300)):
        method, color = track.method, W.track_color(track.method)
        points = got[S.track_topic(method)]
        scenes = got[S.track_scene_topic(method)]
        if method == "nearest":
            points = points[first_id:first_id + len(track)]
            scenes = scenes[first_id:first_id + len(track)]
        for i in range(len(track)):
            x, y, z = track.position_world[i].tolist()
            t = int(track.time_ns[i])
            msg = S.TrackPoint(time_ns=t, method=method, x=x, y=y, z=z,
                               camera=rig3.names[track.camera[i]],
                               ray_miss_m=track.quality["ray_miss_m"][i],
                               snap_px=track.quality["snap_px"][i],
                               ray_shift_m=float("nan"))
            for key, values in track.quality.items():
                if key not in S.TRACK_FIXED_QUALITY:
                    msg.quality[key] = float(values[i])
            assert points[i] == (t, msg.SerializeToString(deterministic=True)), (method, i)
            assert scenes[i] == (t, W.scene_point(method, first_id + i, t, (x, y, z), color))


def test_the_block_path_is_taken(rig3):
    """The blocks above are the numpy encoder's, not the per-point fallback's."""
    rng = np.random.default_rng(6)
    for extra in (True, False):
        track = _track(500, "typeA", extra, rng)
        fixed = {k: (track.quality[k].tolist() if k in track.quality else [float("nan")] * 500)
                 for k in S.TRACK_FIXED_QUALITY}
        template = W._quality_template({k: v for k, v in track.quality.items()
                                        if k not in S.TRACK_FIXED_QUALITY})
        block = W._track_block(track, 0, 500, "typeA", rig3.names, fixed, template, 0,
                               W.track_color("typeA"), 1, 2)
        assert block is not None and len(block.time) == 1000


def test_detection_blocks_are_protobufs_own_bytes(tmp_path, rig3):
    """add_detections: every frame's DetectionFrame as protobuf writes it (frames without
    candidates, many candidates, time and frame index 0, NaN radius, -0.0), in frame order."""
    from pslog.records import Detections

    rng = np.random.default_rng(8)
    n = W._FRAME_BLOCK + 999
    k = rng.choice([0, 1, 1, 2, 7, 20], n)
    times = np.sort(rng.integers(0, 10**12, n))
    times[0] = 0
    uv = rng.normal(size=(int(k.sum()), 2)) * 300
    uv[::5, 0] = -0.0
    radius = np.where(rng.random(len(uv)) < .3, np.nan, 4.0)
    det = Detections.from_frames(rig3.names, times, rng.integers(0, 3, n),
                                 rng.integers(0, 10**6, n) * (np.arange(n) % 9 != 0),
                                 np.repeat(np.arange(n), k), uv, radius, rng.random(len(uv)))
    path = tmp_path / "d.mcap"
    with SessionWriter(path, rig3) as w:
        w.add_detections(det)
    block = W._detections_block(det, 0, 100, rig3.names, [1, 2, 3])
    assert block is not None  # the numpy encoder wrote them, not the per-frame fallback
    got: dict[str, list] = {}
    with open(path, "rb") as f:
        for _s, c, m in make_reader(f).iter_messages(log_time_order=False):
            got.setdefault(c.topic, []).append((m.log_time, m.sequence, m.data))
    bounds = np.searchsorted(det.cand_frame, np.arange(n + 1))
    seen = {name: 0 for name in rig3.names}
    for i in range(n):
        name = rig3.names[det.frame_camera[i]]
        a, b = bounds[i], bounds[i + 1]
        want = S.DetectionFrame(time_ns=int(det.frame_time_ns[i]), camera=name,
                                frame_index=int(det.frame_index[i]),
                                u=det.cand_uv[a:b, 0].tolist(), v=det.cand_uv[a:b, 1].tolist(),
                                radius=det.cand_radius[a:b].tolist(),
                                score=det.cand_score[a:b].tolist()).SerializeToString(deterministic=True)
        row = got[S.detections_topic(name)][seen[name]]
        seen[name] += 1
        assert row == (int(det.frame_time_ns[i]), int(det.frame_index[i]), want), i


def test_compiled_track_encoder_equals_its_python_and_protobuf(rig3):
    """_wire.encode_track compiled and as plain Python (py_func) write the same bytes, and
    they are protobuf's, over ids crossing decimal widths (9 -> 10 ... 99999 -> 100000),
    times whose seconds or nanoseconds are 0, and a long, non-ASCII camera name."""
    from pslog.log import _wire

    rng = np.random.default_rng(11)
    n = 40
    base = _track(n, "typeA", True, rng)
    t = base.time_ns.copy()
    t[1], t[2] = 7, 3_000_000_000  # seconds 0; nanoseconds 0
    track = Track("typeA", np.sort(t), base.position_world, base.camera, base.quality)
    names = ("cam1", "é" * 90, "c")  # a name of 180 bytes: a two-byte length varint
    fixed = {k: (track.quality[k].tolist() if k in track.quality else [float("nan")] * n)
             for k in S.TRACK_FIXED_QUALITY}
    template = W._quality_template({k: v for k, v in track.quality.items()
                                    if k not in S.TRACK_FIXED_QUALITY})
    color = W.track_color("typeA")
    for first_id in (0, 99_990, 10**12 - 20):
        block = W._track_block(track, 0, n, "typeA", names, fixed, template, first_id, color,
                               1, 2)
        assert block is not None
        ends = np.cumsum(block.length)
        for i in range(n):
            x, y, z = track.position_world[i].tolist()
            t = int(track.time_ns[i])
            msg = S.TrackPoint(time_ns=t, method="typeA", x=x, y=y, z=z,
                               camera=names[track.camera[i]],
                               **{k: fixed[k][i] for k in S.TRACK_FIXED_QUALITY})
            for key, values in track.quality.items():
                if key not in S.TRACK_FIXED_QUALITY:
                    msg.quality[key] = float(values[i])
            point = block.data[ends[2 * i] - block.length[2 * i]:ends[2 * i]]
            scene = block.data[ends[2 * i + 1] - block.length[2 * i + 1]:ends[2 * i + 1]]
            assert point == msg.SerializeToString(deterministic=True), (first_id, i)
            assert scene == W.scene_point("typeA", first_id + i, t, (x, y, z), color)
        # the same messages as whole MCAP records (each after its head: channel, sequence
        # 0, log and publish time), as the bulk writer cuts chunks from them
        records = W._track_block(track, 0, n, "typeA", names, fixed, template, first_id,
                                 color, 1, 2, records=True)
        assert records is not None and records.records and not block.records
        assert records.plain().data == block.data
        ends = np.cumsum(block.length)
        assert bytes(records.data) == b"".join(
            _chunks.record_head(int(c), int(t), int(k)) + block.data[e - k:e]
            for c, t, k, e in zip(block.channel, block.time, block.length, ends, strict=True))

    # the compiled kernel and its Python original, on the same arrays
    from pslog.log._wire import encode_track

    t = track.time_ns.astype(np.int64)
    bits = np.column_stack([track.position_world, *(np.asarray(fixed[k])
                                                    for k in S.TRACK_FIXED_QUALITY)])
    bits = np.ascontiguousarray(bits).view(np.uint64)
    keys = list(template[1])
    quality = np.column_stack([track.quality[k] for k in keys]).astype("<f8").view(np.uint64)
    args = (t, bits, track.camera.astype(np.int64), np.frombuffer(b"c1cam2", np.uint8),
            np.array([0, 2, 6, 6]), np.frombuffer(b"typeA", np.uint8), template[0],
            np.array([template[1][k] for k in keys], np.int64), np.ascontiguousarray(quality),
            np.arange(n, dtype=np.int64) * 37, *(np.frombuffer(x, np.uint8) for x in
                                                  (b"world", b"\x22\x02\x10\x05", b"\x12\x00",
                                                   b"", b"\x1a\x00")))
    for channels in ([-1, -1], [3, 70_000 % 65_536]):  # messages alone; whole records
        outs = []
        for fn in (encode_track, encode_track.py_func):
            out = np.zeros(_wire.bound(n, b"typeA", [b"cam2"], len(template[0]), 12), np.uint8)
            point_len, total_len = np.zeros(n, np.int64), np.zeros(n, np.int64)
            used = fn(*args, np.array(channels, np.int64), out, point_len, total_len)
            outs.append((out[:used].tobytes(), point_len.tolist(), total_len.tolist()))
        assert outs[0] == outs[1]


def test_rejection_blocks_are_protobufs_own_bytes(tmp_path, rig3):
    """add_rejections: every rejected candidate's pslog.Rejection as protobuf writes it
    (time and frame index 0, -0.0, NaN score, every reason), by the block encoder."""
    from pslog.fusion.gating import REASONS, Rejections

    rng = np.random.default_rng(9)
    n = W._FRAME_BLOCK + 777
    t = np.sort(rng.integers(0, 10**12, n))
    t[0] = 0
    uv = rng.normal(size=(n, 2)) * 300
    uv[::4, 1] = -0.0
    uv[1::9, 0] = 0.0
    score = np.where(rng.random(n) < .2, np.nan, rng.random(n))
    rej = Rejections(t, rng.integers(0, 3, n).astype(np.int32),
                     rng.integers(0, 10**7, n) * (np.arange(n) % 7 != 0), uv, score,
                     rng.integers(0, len(REASONS), n).astype(np.int8))
    assert W._rejections_block(rej, 0, 300, rig3.names, 5) is not None  # the block path
    path = tmp_path / "r.mcap"
    with SessionWriter(path, rig3) as w:
        w.add_rejections("typeA", rej)
    with open(path, "rb") as f:
        got = [(m.log_time, m.sequence, m.data) for _s, c, m in
               make_reader(f).iter_messages(log_time_order=False)
               if c.topic == S.rejections_topic("typeA")]
    assert len(got) == n
    for i in range(n):
        want = S.Rejection(time_ns=int(t[i]), camera=rig3.names[rej.camera[i]],
                           frame_index=int(rej.frame_index[i]), u=float(uv[i, 0]),
                           v=float(uv[i, 1]), score=float(score[i]),
                           reason=REASONS[rej.reason[i]]).SerializeToString(deterministic=True)
        assert got[i] == (int(t[i]), int(rej.frame_index[i]), want), i


def test_track_chunks_at_the_track_level_detections_at_the_session_level(tmp_path, rig3):
    """A fused track's chunks (its records written whole) are zstd frames of
    _chunks.TRACK_ZSTD_LEVEL, a session's detection chunks of _chunks.ZSTD_LEVEL: each chunk's
    compressed bytes are its records compressed again at that level (zstd is deterministic)."""
    import zstandard
    from mcap.reader import make_reader as reader_of

    from pslog.log import _chunks
    from pslog.records import Detections

    assert _chunks.TRACK_ZSTD_LEVEL != _chunks.ZSTD_LEVEL
    rng = np.random.default_rng(12)
    n = 3000
    times = np.sort(rng.integers(0, 10**11, n))
    det = Detections.from_frames(rig3.names, times, rng.integers(0, 3, n), np.arange(n),
                                 np.arange(n), rng.normal(size=(n, 2)) * 300,
                                 np.full(n, 4.0), rng.random(n))
    path = tmp_path / "t.mcap"
    with SessionWriter(path, rig3) as w:
        w.add_detections(det)
        w.flush()
        w.add_track(_track(6000, "typeA", True, rng), last=True)
    levels = {}
    with open(path, "rb") as f:
        reader = reader_of(f)
        summary = reader.get_summary()
        topics = {c.id: c.topic for c in summary.channels.values()}
        for index in summary.chunk_indexes:
            f.seek(index.chunk_start_offset + 1 + 8 + 8 + 8 + 8 + 4)
            size = int.from_bytes(f.read(4), "little")
            assert f.read(size) == b"zstd"
            stored = f.read(int.from_bytes(f.read(8), "little"))
            raw = zstandard.ZstdDecompressor().decompress(stored)
            kind = {topics[c].split("/")[1] for c in index.message_index_offsets}
            if kind == {"tracks"} and len(raw) > 100_000:  # the blocks, not the metadata's
                levels.setdefault("tracks", set()).update(
                    lv for lv in (-3, -1, 1, 3) if zstandard.compress(raw, lv) == stored)
            elif kind == {"camera"}:
                levels.setdefault("camera", set()).update(
                    lv for lv in (-3, -1, 1, 3) if zstandard.compress(raw, lv) == stored)
    assert levels == {"tracks": {_chunks.TRACK_ZSTD_LEVEL}, "camera": {_chunks.ZSTD_LEVEL}}


def test_a_track_after_buffered_rejections_keeps_its_records_whole(tmp_path, rig3):
    """pslog fuse writes a method's rejections (a few: queued one by one, still buffered)
    and then the next method's track: the rejections go in a chunk of their own and the
    track's first block is cut into chunks from its whole records like its other blocks
    (only its own two channels in them, at the track level), every message as written."""
    import zstandard

    from pslog.fusion.gating import Rejections

    rng = np.random.default_rng(13)
    first = _track(300, "typeA", True, rng)
    second = _track(W._TRACK_BLOCK + 100, "nearest", True, rng)
    rej = Rejections(np.array([5, 9]), np.array([0, 1], dtype=np.int32), np.array([1, 2]),
                     np.array([[10.0, 20.0], [30.0, 40.0]]), np.array([0.5, 0.25]),
                     np.array([0, 1], dtype=np.int8))
    path = tmp_path / "t.mcap"
    with SessionWriter(path, rig3) as w:
        w.add_track(first, last=True)
        w.add_rejections("typeA", rej)
        w.add_track(second, last=True)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        topics = {c.id: c.topic for c in summary.channels.values()}
        own = {S.track_topic("nearest"), S.track_scene_topic("nearest")}
        seen = 0
        for index in summary.chunk_indexes:
            here = {topics[c] for c in index.message_index_offsets}
            if not here & own:
                continue
            assert here <= own, here  # no rejection joined to the track's records
            f.seek(index.chunk_start_offset + 1 + 8 + 8 + 8 + 8 + 4)
            size = int.from_bytes(f.read(4), "little")
            assert f.read(size) == b"zstd"
            stored = f.read(int.from_bytes(f.read(8), "little"))
            raw = zstandard.ZstdDecompressor().decompress(stored)
            assert zstandard.compress(raw, _chunks.TRACK_ZSTD_LEVEL) == stored
            seen += 1
        assert seen >= 2
        got: dict[str, list[int]] = {}
        for _s, c, m in reader.iter_messages(log_time_order=False):
            got.setdefault(c.topic, []).append(m.log_time)
    assert got[S.rejections_topic("typeA")] == [5, 9]
    for track in (first, second):
        for topic in (S.track_topic(track.method), S.track_scene_topic(track.method)):
            assert got[topic] == track.time_ns.tolist()
