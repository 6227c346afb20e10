"""copy_session copies the source's chunks byte for byte (no decompression and compression
again) and the copy reads back exactly as one made message by message."""

from __future__ import annotations

import hashlib
from collections import defaultdict

import numpy as np
import pytest
from conftest import make_jpeg
from mcap.reader import make_reader

from pslog.log import SessionWriter, copy_session, read_session
from pslog.log import copy as copy_module
from pslog.log import table as tables
from pslog.log.reader import _Finished
from pslog.records import Track


def _content(path):
    """Everything a reader gets from a session file: per topic, the digest of its messages
    in file order (log and publish time, sequence, data) and its schema; every table's
    counts and decoded columns; the metadata (creation time aside); the channels."""
    per: dict[str, hashlib._Hash] = defaultdict(hashlib.sha256)
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, m in reader.iter_messages(log_time_order=False):
            per[channel.topic].update(b"%d %d %d %d|" % (m.log_time, m.publish_time,
                                                         m.sequence, len(m.data)) + m.data)
            per[channel.topic + "#schema"].update(schema.name.encode() + schema.data)
        meta = [(m.name, {k: v for k, v in m.metadata.items() if k != "created_utc"})
                for m in reader.iter_metadata()]
        channels = sorted((c.topic, c.message_encoding, sorted(c.metadata.items()))
                          for c in reader.get_summary().channels.values())
    tabs = {}
    with _Finished(path) as fin:
        for name, index in fin.attachments.items():
            counts, columns = tables.decode(fin._attachment(index), name, fin.rig.names)
            tabs[name] = (counts, {k: (v.dtype.str, v.shape, v.tobytes())
                                   for k, v in columns.items()})
    return {k: v.hexdigest() for k, v in per.items()}, tabs, meta, channels


def _chunk_records(path) -> list[bytes]:
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
        data = path.read_bytes()
    return [data[c.chunk_start_offset:c.chunk_start_offset + c.chunk_length]
            for c in summary.chunk_indexes]


def _messages_only(record: bytes) -> bool:
    from pslog.log import _mcapio as io

    records = io.chunk_payload(record[9:])
    return all(op == io.OP_MESSAGE for op, _body, _end in io.walk_records(records))


@pytest.fixture
def recorded(tmp_path, sim_session, monkeypatch):
    """A session with images, detections, truth and an event, written in many chunks at
    the ``mcap`` writer's zstd level (as another writer or an older pslog wrote them: a
    chunk compressed again comes out different)."""
    from pslog.log import _chunks

    monkeypatch.setattr(_chunks, "ZSTD_LEVEL", 3)
    s = sim_session
    path = tmp_path / "rec.mcap"
    det = s.detections
    with SessionWriter(path, s.rig, timing="typeA", flush_interval_s=0) as w:
        for i in range(det.n_frames):
            sel = det.cand_frame == i
            w.add_frame(int(det.frame_camera[i]), int(det.frame_index[i]),
                        int(det.frame_time_ns[i]), det.cand_uv[sel], det.cand_radius[sel],
                        det.cand_score[sel], image=make_jpeg(i % 256))
            if i % 40 == 39:
                w.flush()  # a chunk of detections and one of images
        w.add_truth(s.truth)
        w.add_event(int(det.frame_time_ns[3]), "note")
    monkeypatch.undo()
    return path


def _track(method: str, n: int, shift: float = 0.0) -> Track:
    t = np.arange(n, dtype=np.int64) * 10_000_000
    return Track(method, t, np.column_stack([np.arange(n) + shift, np.zeros(n),
                                             np.ones(n)]),
                 camera=np.arange(n) % 3,
                 quality={"ray_miss_m": np.full(n, 0.001), "speed_mps": np.arange(n) * 0.5})


def _by_messages(monkeypatch, *args, **kwargs) -> None:
    """copy_session as it was: every chunk decompressed, its messages written again."""
    with monkeypatch.context() as m:
        m.setattr(copy_module, "_verbatim", lambda *a: False)
        copy_session(*args, **kwargs)


def test_copy_writes_the_source_chunks_as_they_are(recorded, tmp_path, monkeypatch):
    fused, slow = tmp_path / "fused.mcap", tmp_path / "slow.mcap"
    track = _track("typeA", 300)
    copy_session(recorded, fused, tracks=[track])
    _by_messages(monkeypatch, recorded, slow, tracks=[track])
    assert _content(fused) == _content(slow)
    # every chunk of the source that holds messages only is in the copy byte for byte (those
    # with channel records too are written again); the copy made message by message
    # shares none of them
    source = _chunk_records(recorded)
    plain = [c for c in source if _messages_only(c)]
    assert len(source) > 10 and len(plain) > 0.9 * len(source)
    copied = set(_chunk_records(fused))
    assert all(c in copied for c in plain)
    assert not any(c in copied for c in source if c not in plain)
    again = set(_chunk_records(slow))
    assert sum(c in again for c in plain) < len(plain) / 2
    # and pslog reads it back as the source, plus the track
    a, b = read_session(recorded), read_session(fused)
    np.testing.assert_array_equal(a.detections.cand_uv, b.detections.cand_uv)
    np.testing.assert_array_equal(a.truth.position_world, b.truth.position_world)
    assert b.n_images == a.n_images and b.events == a.events
    np.testing.assert_array_equal(b.tracks["typeA"].position_world, track.position_world)
    with _Finished(fused) as f:
        assert f.table(tables.DETECTIONS) is not None and not f.table_problems


def test_refusing_a_copy_drops_and_adds_channels_alike(recorded, tmp_path, monkeypatch):
    # a re-fuse: the copied file's tracks replaced (their channels dropped, new ones after),
    # or kept beside a new method
    fused = tmp_path / "fused.mcap"
    copy_session(recorded, fused, tracks=[_track("typeA", 200), _track("filter", 100)])
    for kwargs in ({"tracks": [_track("typeA", 150, 1.0)]},
                   {"tracks": [_track("smooth", 120, 2.0)], "replace_tracks": False}):
        fast, slow = tmp_path / "fast.mcap", tmp_path / "slow.mcap"
        copy_session(fused, fast, force=True, **kwargs)
        _by_messages(monkeypatch, fused, slow, force=True, **kwargs)
        assert _content(fast) == _content(slow)
        assert set(read_session(fast).tracks) == set(read_session(slow).tracks)


def test_copy_of_a_damaged_chunk_is_refused_not_copied(recorded, tmp_path):
    from pslog.errors import LogFormatError

    data = bytearray(recorded.read_bytes())
    with open(recorded, "rb") as f:
        chunk = make_reader(f).get_summary().chunk_indexes[5]
    data[chunk.chunk_start_offset + chunk.chunk_length - 20] ^= 0xFF  # in its zstd bytes
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    out = tmp_path / "out.mcap"
    with pytest.raises(LogFormatError, match="recover"):
        copy_session(damaged, out, tracks=[_track("typeA", 10)])
    assert not out.exists() and not (tmp_path / "out.mcap.partial").exists()


def test_a_chunk_whose_header_times_are_wrong_is_written_anew(recorded, tmp_path):
    """The Chunk record's start/end times are outside its CRC: a chunk whose header says
    other times than its messages' is not copied as it is (the copy's chunk and its index
    would disagree), but written again with the right ones (review, session 7)."""
    data = bytearray(recorded.read_bytes())
    with open(recorded, "rb") as f:
        chunk = [c for c in make_reader(f).get_summary().chunk_indexes
                 if c.message_start_time > 0][5]
    data[chunk.chunk_start_offset + 9:chunk.chunk_start_offset + 17] = bytes(8)  # start 0
    odd = tmp_path / "odd.mcap"
    odd.write_bytes(bytes(data))
    out = tmp_path / "out.mcap"
    copy_session(odd, out, tracks=[_track("typeA", 10)])
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    raw = out.read_bytes()
    for c in summary.chunk_indexes:
        record = raw[c.chunk_start_offset:c.chunk_start_offset + c.chunk_length]
        assert int.from_bytes(record[9:17], "little") == c.message_start_time
        assert int.from_bytes(record[17:25], "little") == c.message_end_time
    np.testing.assert_array_equal(read_session(out).detections.cand_uv,
                                  read_session(recorded).detections.cand_uv)
