"""pslog.log._chunks writes the very bytes the mcap writer's add_message makes."""

from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from pslog.log import (
    _chunks,
    _wire,  # noqa: F401  (loaded: large blocks take the compiled loop)
)


def _messages(rng, n, big=False):
    channel = rng.integers(1, 4, n)
    times = np.sort(rng.integers(0, 10**12, n))
    times[::7] = times[::7][::-1]  # out of order here and there
    seq = rng.integers(0, 2**32, n)
    sizes = rng.integers(0, 200_000 if big else 300, n)
    datas = [rng.bytes(int(k)) for k in sizes]
    return channel, times, seq, datas


def _write(batches, bulk: bool) -> bytes:
    out = io.BytesIO()
    w = Writer(out, compression=CompressionType.ZSTD)
    assert _chunks.supported(w)
    w.start(profile="", library="test")
    w.add_metadata("m", {"a": "b"})
    sid = w.register_schema("s", "protobuf", b"xyz")
    for k, (channel, times, seq, datas) in enumerate(batches):
        for c in range(1, 4 + k):  # new channels registered between blocks: a prefix
            if c > len(w._Writer__channels):
                w.register_channel(f"/t{c}", "protobuf", sid)
        if bulk:
            _chunks.write_messages(w, channel, times, seq, b"".join(datas),
                                   np.array([len(d) for d in datas]))
        else:
            for c, t, s, d in zip(channel.tolist(), times.tolist(), seq.tolist(), datas,
                                  strict=True):
                w.add_message(c, t, d, t, s)
        w.flush()
    w.finish()
    return out.getvalue()


def _compressible(rng, n):
    """Messages that zstd shrinks (repeated fields, as protobuf messages are): the level
    shows in the bytes."""
    channel, times, seq, _ = _messages(rng, n)
    datas = [b"pslog" * int(k % 40) + rng.bytes(8) for k in range(n)]
    return channel, times, seq, datas


@pytest.mark.parametrize("big", [False, True])
def test_block_write_is_add_message_byte_for_byte(big, monkeypatch):
    # at the mcap writer's own zstd level, the very bytes of add_message one by one (the
    # small blocks by numpy's masks, the large ones by the compiled loop)
    monkeypatch.setattr(_chunks, "ZSTD_LEVEL", 3)
    rng = np.random.default_rng(3)
    batches = [_messages(rng, n, big) for n in ([5000, 1, 20_000] if not big else [30, 7])]
    batches.append(_compressible(rng, 30_000))
    one_by_one = _write(batches, bulk=False)
    block = _write(batches, bulk=True)
    assert block == one_by_one
    # and it reads back: every message, in order
    got = [(c.id, m.log_time, m.sequence, m.data)
           for _s, c, m in make_reader(io.BytesIO(block)).iter_messages(log_time_order=False)]
    want = [(c, t, s, d) for channel, times, seq, datas in batches
            for c, t, s, d in zip(channel.tolist(), times.tolist(), seq.tolist(), datas,
                                  strict=True)]
    assert got == want


def test_block_write_level_changes_bytes_not_content():
    # pslog's own level (1: faster, as small) compresses differently from the mcap
    # writer's 3; every reader gets the same records back
    assert _chunks.ZSTD_LEVEL != 3
    rng = np.random.default_rng(4)
    batches = [_compressible(rng, n) for n in (10_000, 3, 20_000)]
    one_by_one = _write(batches, bulk=False)
    block = _write(batches, bulk=True)
    assert block != one_by_one  # the compressed chunks differ

    def records(data):
        reader = make_reader(io.BytesIO(data))
        summary = reader.get_summary()
        return ([(c.id, m.log_time, m.publish_time, m.sequence, m.data)
                 for _s, c, m in reader.iter_messages(log_time_order=False)],
                [(i.message_start_time, i.message_end_time, i.uncompressed_size,
                  sorted(i.message_index_offsets)) for i in summary.chunk_indexes],
                dict(summary.statistics.channel_message_counts),
                summary.statistics.message_count)

    assert records(block) == records(one_by_one)


def test_attachment_written_in_pieces_is_add_attachment_byte_for_byte():
    rng = np.random.default_rng(5)
    data = [rng.bytes(1000), b"", memoryview(np.arange(5000, dtype="<f8")).cast("B"), b"x"]

    def write(pieces: bool) -> bytes:
        out = io.BytesIO()
        w = Writer(out, compression=CompressionType.ZSTD)
        w.start(profile="", library="test")
        sid = w.register_schema("s", "protobuf", b"xyz")
        w.add_message(w.register_channel("/t", "protobuf", sid), 5, b"m", 5)
        for name in ("pslog/table/a", "b"):
            if pieces:
                _chunks.write_attachment(w, name, "application/x", data)
            else:
                w.add_attachment(0, 0, name, "application/x", b"".join(data))
        w.finish()
        return out.getvalue()

    assert write(True) == write(False)


def test_assemble_records_kernel_is_its_python_original():
    # the compiled loop that lays a block's records into a chunk: each record's 31-byte
    # head then its payload, at the offsets given (empty payloads included)
    from pslog.log._wire import assemble_records

    rng = np.random.default_rng(6)
    n = 50
    lengths = rng.integers(0, 40, n)
    lengths[[3, 17]] = 0
    data_start = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    payload = rng.integers(0, 256, int(lengths.sum()), dtype=np.uint8)
    heads = rng.integers(0, 256, (n, 31), dtype=np.uint8)
    base = 7  # a prefix of schema/channel records before the first record
    rec_start = base + np.concatenate([[0], np.cumsum(lengths + 31)[:-1]])
    total = int(base + (lengths + 31).sum())
    got, want = np.zeros(total, np.uint8), np.zeros(total, np.uint8)
    assemble_records(got, heads, rec_start, payload, data_start, lengths)
    assemble_records.py_func(want, heads, rec_start, payload, data_start, lengths)
    expected = np.zeros(total, np.uint8)
    for i in range(n):
        at = rec_start[i]
        expected[at:at + 31] = heads[i]
        expected[at + 31:at + 31 + lengths[i]] = payload[data_start[i]:data_start[i] + lengths[i]]
    np.testing.assert_array_equal(want, expected)
    np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("n_channels", [1, 2, 5, _chunks._FEW_CHANNELS,
                                        _chunks._FEW_CHANNELS + 1, 300])
def test_channels_seen_is_unique_in_order_of_first_appearance(n_channels):
    """The writer's channel census (bincount and a scan per channel for a few channels,
    np.unique past them) gives np.unique's ids and counts, ordered by first appearance."""
    rng = np.random.default_rng(n_channels)
    ids = rng.permutation(np.arange(1, 60_000))[:n_channels]  # first seen in no sorted order
    channel = np.concatenate([ids, ids[rng.integers(0, n_channels, 20_000)]])
    rng.shuffle(channel[n_channels:])
    for dtype in (np.int64, np.uint16, np.int32):
        seen, counts = _chunks.channels_seen(channel.astype(dtype))
        want, first, want_counts = np.unique(channel, return_index=True, return_counts=True)
        order = np.argsort(first, kind="stable")
        assert seen.tolist() == want[order].tolist() == ids.tolist()
        assert counts.tolist() == want_counts[order].tolist()
    empty = _chunks.channels_seen(np.zeros(0, dtype=np.int64))
    assert empty[0].tolist() == [] and empty[1].tolist() == []
