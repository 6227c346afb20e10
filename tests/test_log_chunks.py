"""pslog.log._chunks writes the very bytes the mcap writer's add_message makes."""

from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from pslog.log import _chunks


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


@pytest.mark.parametrize("big", [False, True])
def test_block_write_is_add_message_byte_for_byte(big):
    rng = np.random.default_rng(3)
    batches = [_messages(rng, n, big) for n in ([5000, 1, 20_000] if not big else [30, 7])]
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
