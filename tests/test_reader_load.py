"""The columnar reader's little-endian integers (``pslog.log.reader._load``), every width it
reads (2, 4, 8; and one read byte by byte): the bytes' value as ``int.from_bytes`` gives it,
at any position, the top bit set too (session 44: widths 2 and 4 read as one integer a row)."""

import numpy as np
import pytest

from pslog.log.reader import _load


@pytest.mark.parametrize("width", [2, 3, 4, 8])
def test_each_width_reads_the_little_endian_value(width):
    rng = np.random.default_rng(77049)
    buf = rng.integers(0, 256, 4096, dtype=np.uint8)
    buf[:16] = 0xFF  # (every bit set: no sign, no overflow)
    pos = np.r_[0, rng.integers(0, len(buf) - width + 1, 500), len(buf) - width]
    got = _load(buf, pos, width)
    assert got.dtype == np.uint64
    want = [int.from_bytes(buf[p:p + width].tobytes(), "little") for p in pos.tolist()]
    assert got.tolist() == want
