"""The reader's columnar fast path (MessageIndex-located messages, protobuf decoded with numpy)
gives exactly what the per-message path gives, and falls back to it on anything irregular:
a damaged MessageIndex, other valid protobuf encodings, maps of other key sets. Eval's
vectorised matching of rejections to ball labels counts as the tuple sets did."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from pslog.cli import main
from pslog.evaluation import rejection_counts
from pslog.log import _schemas as S
from pslog.log import read_session
from pslog.log import reader as R


@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    """A dirty simulated session (false candidates near the ball, a distractor, misses)
    fused with every method: detections, ball labels, truth, four tracks, rejections."""
    tmp = tmp_path_factory.mktemp("columnar")
    session, out = tmp / "dirty.mcap", tmp / "fused.mcap"
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                 "--duration", "3", "--noise-px", "0.5", "--spurious", "0.3",
                 "--spurious-radius", "30", "--distractor", "0.5,0.5,0.5", "--miss-rate",
                 "0.1", "--seed", "4", "-o", str(session)]) == 0
    assert main(["fuse", str(session), "-o", str(out)]) == 0
    return out


def _same(a, b, what=""):
    if isinstance(a, dict):
        assert list(a) == list(b), what
        for k in a:
            _same(a[k], b[k], f"{what}.{k}")
        return
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, what
    assert a.tobytes() == b.tobytes(), what  # bit for bit, NaN included


def _per_message(path):
    """The session's columns the per-message way (the fallback decoders on a record walk)."""
    with R._Finished(path) as f:
        names = f.rig.names
        det = [S.detections_topic(n) for n in names]
        ball = [S.ball_truth_topic(n) for n in names]
        tracks = sorted(t for t in f.topics.values() if S.parse_track_topic(t))
        found = f.collect([*det, *ball, S.TRUTH_TOPIC, *tracks])
    return (R._decode_detections_messages(names, [found.get(t, []) for t in det]),
            R._decode_detections_messages(names, [found.get(t, []) for t in ball]),
            R._decode_truth_messages(found[S.TRUTH_TOPIC]),
            {S.parse_track_topic(t): R._decode_track_messages(S.parse_track_topic(t), names,
                                                              found[t]) for t in tracks})


def _assert_session_equal(session, expected):
    detections, ball, truth, tracks = expected
    for got, want in ((session.detections, detections), (session.ball_truth, ball)):
        for k in ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
                  "cand_radius", "cand_score"):
            _same(getattr(got, k), getattr(want, k), k)
    _same(session.truth.time_ns, truth.time_ns)
    _same(session.truth.position_world, truth.position_world)
    assert list(session.tracks) == list(tracks)
    for method, want in tracks.items():
        got = session.tracks[method]
        for k in ("time_ns", "position_world", "camera"):
            _same(getattr(got, k), getattr(want, k), f"{method}.{k}")
        _same(got.quality, want.quality, f"{method}.quality")  # same keys, same order


def test_columnar_read_equals_the_per_message_path(fused):
    session = read_session(fused)
    assert len(session.tracks) == 4 and session.ball_truth is not None
    assert session.detections.n_candidates > session.detections.n_frames  # false candidates
    _assert_session_equal(session, _per_message(fused))


def test_columnar_decoders_take_the_fast_path_on_pslog_files(fused):
    """The columnar decoders themselves (no fallback) read every topic of a fused file."""
    with R._Finished(fused) as f:
        names = f.rig.names
        topics = sorted(t for t in f.topics.values() if S.parse_track_topic(t))
        found = f.collect_batches([*topics, *[S.detections_topic(n) for n in names]])
    for topic in topics:
        assert len(R._track_columnar(S.parse_track_topic(topic), names, found[topic])) > 0
    det = R._detections_columnar(names, [found[S.detections_topic(n)] for n in names])
    assert det.n_candidates > 0


def _message_index_entries(path):
    """Byte offsets in the file of every MessageIndex record's entries (outside chunks, so
    without any CRC), with their lengths."""
    with R._Finished(path) as f:
        where = [(off, cid) for c in f.summary.chunk_indexes
                 for cid, off in c.message_index_offsets.items()]
    raw = path.read_bytes()
    out = []
    for off, _cid in where:
        _op, _length, _channel, size = struct.unpack_from("<BQHI", raw, off)
        out.append((off + 15, size))
    return out


@pytest.mark.parametrize("damage", ["offsets", "duplicate", "times"])
def test_a_damaged_message_index_falls_back_to_the_record_walk(fused, tmp_path, damage):
    expected = _per_message(fused)
    data = bytearray(fused.read_bytes())
    for start, size in _message_index_entries(fused):
        if size < 32:
            continue
        if damage == "offsets":  # an entry's offset points elsewhere in the chunk
            struct.pack_into("<Q", data, start + 8, 3)
        elif damage == "duplicate":  # the second entry repeats the first
            data[start + 16:start + 32] = data[start:start + 16]
        else:  # a log time that is not the record's
            struct.pack_into("<Q", data, start, 12345)
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(bytes(data))
    _assert_session_equal(read_session(broken), expected)


def _varint(n: int) -> bytes:
    out = bytearray()
    n &= (1 << 64) - 1
    while True:
        b, n = n & 0x7F, n >> 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _field(number: int, wire: int, payload: bytes) -> bytes:
    return _varint(number << 3 | wire) + payload


def test_unpacked_repeated_doubles_and_negative_frame_index_decode_as_protobuf_does():
    """Valid protobuf the writer never makes: a frame's candidates as unpacked repeated
    doubles (the columnar path falls back), and a negative frame index (10-byte varint,
    read by the columnar path)."""
    unpacked = b"".join([_field(1, 0, _varint(7)), _field(3, 0, _varint(-2))]
                        + [_field(f, 1, struct.pack("<d", x)) for f, x in
                           ((4, 1.5), (4, 2.5), (5, 3.0), (5, 4.0), (6, 1.0), (6, 1.0),
                            (7, 0.5), (7, 0.25))])
    packed = S.DetectionFrame(time_ns=9, frame_index=-3, u=[5.0], v=[6.0], radius=[1.0],
                              score=[0.75]).SerializeToString(deterministic=True)
    got = R.decode_detections(["a", "b"], [[(7, 0, unpacked)], [(9, 1, packed)]])
    assert got.frame_index.tolist() in ([-2, -3], [-3, -2])
    order = np.argsort(got.frame_time_ns)
    assert got.frame_index[order].tolist() == [-2, -3]
    assert sorted(got.cand_uv.tolist()) == [[1.5, 3.0], [2.5, 4.0], [5.0, 6.0]]
    batch = R._Batch.from_messages([(9, 1, packed)])
    columnar = R._detections_columnar(["a", "b"], [batch, R._Batch.from_messages([])])
    assert columnar.frame_index.tolist() == [-3] and columnar.cand_score.tolist() == [0.75]
    with pytest.raises(R._Irregular):
        R._detections_columnar(["a"], [R._Batch.from_messages([(7, 0, unpacked)])])


def test_track_maps_of_other_key_sets_fall_back_with_the_per_message_key_order():
    def point(t, keys, x=1.0):
        m = S.TrackPoint(time_ns=t, method="m", x=x, y=0.0, z=-2.0, camera="b",
                         ray_miss_m=float("nan"))
        for k in keys:
            m.quality[k] = float(len(k)) + t
        return (t, 0, m.SerializeToString(deterministic=True))

    same_keys = [point(t, ["gap_s", "a_long_quality_name_beyond_16"]) for t in (3, 1, 2)]
    mixed = [point(1, ["gap_s"]), point(2, ["std_m", "gap_s"]), point(3, [])]
    for msgs in (same_keys, mixed):
        got = R.decode_track("m", ["a", "b"], msgs)
        want = R._decode_track_messages("m", ["a", "b"], msgs)
        _same(got.time_ns, want.time_ns)
        _same(got.position_world, want.position_world)
        _same(got.camera, want.camera)
        _same(got.quality, want.quality)
    with pytest.raises(R._Irregular):
        R._track_columnar("m", ["a", "b"], R._Batch.from_messages(mixed))
    # the same key set at every point: columnar, and the long key is checked byte for byte
    assert list(R._track_columnar("m", ["a", "b"], R._Batch.from_messages(same_keys))
                .quality) == list(R._decode_track_messages("m", ["a", "b"], same_keys).quality)
    with pytest.raises(Exception, match="unknown camera 'c'"):
        R.decode_track("m", ["a", "b"], [(1, 0, S.TrackPoint(camera="c").SerializeToString())])


def _counts_by_sets(rejections, detections, ball):
    """rejection_counts' figures the way it counted before: Python tuple sets."""
    def keys(camera, frame, uv):
        return list(zip(np.asarray(camera).tolist(), np.asarray(frame).tolist(),
                        uv[:, 0].tolist(), uv[:, 1].tolist(), strict=True))

    cand = keys(detections.frame_camera[detections.cand_frame],
                detections.frame_index[detections.cand_frame], detections.cand_uv)
    rejected_keys = set(keys(rejections.camera, rejections.frame_index, rejections.uv))
    labels = set(keys(ball.frame_camera[ball.cand_frame], ball.frame_index[ball.cand_frame],
                      ball.cand_uv))
    rejected = np.array([k in rejected_keys for k in cand])
    is_ball = np.array([k in labels for k in cand])
    return (int(np.count_nonzero(rejected & ~is_ball)), int(np.count_nonzero(rejected & is_ball)),
            int(np.count_nonzero(~rejected & ~is_ball)), int(np.count_nonzero(~is_ball)))


def test_rejection_counts_match_the_tuple_sets(fused):
    session = read_session(fused)
    for method, rejections in session.rejections.items():
        counts = rejection_counts(method, rejections, session.detections, session.ball_truth)
        assert counts.rejected > 0
        assert (counts.correct, counts.wrong, counts.kept_false, counts.false_candidates) == \
            _counts_by_sets(rejections, session.detections, session.ball_truth)


def test_track_quality_entries_are_protobufs_own_bytes(fused):
    """The writer's columnar quality map bytes equal protobuf's serialization of each point
    (same process: protobuf's map order is its own, per process), and a written track reads
    back with every value bit for bit."""
    from pslog.log.writer import _quality_entries

    session = read_session(fused)
    for track in session.tracks.values():
        extra = {k: v for k, v in track.quality.items() if k not in S.TRACK_FIXED_QUALITY}
        entries = _quality_entries(extra, len(track), block=50)  # several blocks
        assert entries is not None
        entries = list(entries)
        assert len(entries) == len(track) > 50
        for i in range(len(track)):
            msg = S.TrackPoint()
            for k, values in extra.items():
                msg.quality[k] = float(values[i])
            assert msg.SerializeToString(deterministic=True) == entries[i]
    # keys of 117 bytes or more do not fit the one-byte entry length: the per-point way
    assert _quality_entries({"k" * 120: np.ones(1)}, 1) is None
    assert list(_quality_entries({}, 2)) == [b"", b""]
