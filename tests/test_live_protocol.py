"""The live datagrams: exact round trips, the documented byte layout, every refusal reason."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from pslog.errors import PslogError
from pslog.live.protocol import (
    CANDIDATE_BYTES,
    DETECTION_HEADER_BYTES,
    MAX_CANDIDATES,
    MAX_DETECTION_BYTES,
    POINT_BYTES,
    PROTOCOL_VERSION,
    DatagramError,
    DetectionDatagram,
    PointDatagram,
    decode_detections,
    decode_point,
    encode_detections,
    encode_point,
)

T0 = 1_764_470_000_123_456_789  # a wall-clock time, ns


def _det(k=2, camera="cam2", **kw) -> DetectionDatagram:
    rng = np.random.default_rng(k)
    args = dict(camera=camera, sequence=2**40 + 3, frame_index=2**32 - 9, t_capture_ns=T0,
                t_sent_ns=T0 + 1_500_000, uv=rng.uniform(0, 640, (k, 2)),
                radius=np.r_[np.nan, rng.uniform(1, 9, max(k - 1, 0))][:k],
                score=rng.uniform(0, 1, k))
    args.update(kw)
    return DetectionDatagram(**args)


@pytest.mark.parametrize("k", [0, 1, 5, MAX_CANDIDATES])
def test_detection_round_trip_is_exact(k):
    d = _det(k)
    data = encode_detections(d)
    assert len(data) == DETECTION_HEADER_BYTES + k * CANDIDATE_BYTES == 72 + 32 * k
    e = decode_detections(data)
    assert (e.camera, e.sequence, e.frame_index, e.t_capture_ns, e.t_sent_ns) == (
        d.camera, d.sequence, d.frame_index, d.t_capture_ns, d.t_sent_ns)
    np.testing.assert_array_equal(e.uv, d.uv)
    np.testing.assert_array_equal(e.radius, d.radius)  # NaN radius (unknown) survives
    np.testing.assert_array_equal(e.score, d.score)
    assert len(e) == k


def test_detection_layout_is_as_documented():
    """A C reader's struct: the offsets of docs/live.md, little-endian."""
    d = _det(1, camera="ç1")  # a multi-byte UTF-8 name
    data = encode_detections(d)
    assert data[:4] == b"PSLD" and data[4] == PROTOCOL_VERSION == 1
    name = "ç1".encode()
    assert data[5] == len(name) == 3
    assert struct.unpack_from("<H", data, 6)[0] == 1
    assert struct.unpack_from("<Q", data, 8)[0] == d.sequence
    assert struct.unpack_from("<qqq", data, 16) == (d.frame_index, d.t_capture_ns, d.t_sent_ns)
    assert data[40:72] == name + bytes(32 - len(name))
    u, v, r, s = struct.unpack_from("<4d", data, 72)
    assert (u, v, s) == (d.uv[0, 0], d.uv[0, 1], d.score[0]) and math.isnan(r)


def test_point_round_trip_and_layout():
    p = PointDatagram(sequence=9, camera_index=2, camera="cam3", method="filter",
                      t_capture_ns=T0, t_emit_ns=T0 + 300_000, t_arrival_ns=T0 + 200_000,
                      position=(1.0, -2.5, 0.75), covariance=(1e-6, 2e-7, 3e-7, 4e-6, 5e-7, 6e-6),
                      residual_px=0.3, camera_mask=0b101, flags=2,
                      predicted_position=(1.1, -2.4, 0.7), predicted_velocity=(3.0, 4.0, -1.0))
    data = encode_point(p)
    assert len(data) == POINT_BYTES == 224
    assert data[:5] == b"PSLP\x01" and data[5] == 2 and data[6] == 4 and data[7] == 6
    assert struct.unpack_from("<Qqqq", data, 8) == (9, T0, T0 + 300_000, T0 + 200_000)
    assert struct.unpack_from("<3d", data, 40) == p.position
    assert struct.unpack_from("<6d", data, 64) == p.covariance
    assert struct.unpack_from("<dII", data, 112) == (0.3, 0b101, 2)
    assert struct.unpack_from("<3d3d", data, 128) == p.predicted_position + p.predicted_velocity
    assert data[176:180] == b"cam3" and data[208:214] == b"filter"
    q = decode_point(data)
    assert q == p or all(getattr(q, f) == getattr(p, f) for f in p.__dataclass_fields__)
    # NaN covariance and velocity (typeA) survive as NaN
    r = decode_point(encode_point(PointDatagram(1, 0, "cam1", "typeA", 1, 2, 3, (0, 0, 1))))
    assert all(math.isnan(c) for c in r.covariance + r.predicted_velocity)


def _reason(data: bytes) -> str:
    with pytest.raises(DatagramError) as info:
        decode_detections(data)
    assert isinstance(info.value, PslogError) and "\n" not in str(info.value)
    return info.value.reason


def _with(data: bytes, offset: int, raw: bytes) -> bytes:
    return data[:offset] + raw + data[offset + len(raw):]


GOOD = encode_detections(_det(3))


@pytest.mark.parametrize("data, reason", [
    (b"", "truncated"),
    (b"PSL", "truncated"),
    (b"PSLD", "truncated"),
    (GOOD[:40], "truncated"),                       # inside the header
    (GOOD[:-5], "truncated"),                       # a candidate cut mid-record
    (GOOD[:-32], "malformed"),                      # whole records, k too big for the length
    (GOOD + bytes(32), "malformed"),                # k too small for the length
    (_with(GOOD, 6, struct.pack("<H", 65)), "malformed"),   # k above the limit
    (encode_detections(_det(MAX_CANDIDATES)) + bytes(32), "oversize"),
    (bytes(70_000), "foreign"),
    (b"GET / HTTP/1.1\r\n\r\n", "foreign"),
    (b"PSLP" + GOOD[4:], "foreign"),                # a point magic is no detection
    (_with(GOOD, 4, b"\x02"), "version"),
    (_with(GOOD, 4, b"\x00"), "version"),
    (_with(GOOD, 72, struct.pack("<d", math.nan)), "malformed"),     # NaN u
    (_with(GOOD, 80, struct.pack("<d", math.inf)), "malformed"),     # inf v
    (_with(GOOD, 96, struct.pack("<d", -math.inf)), "malformed"),    # inf score
    (_with(GOOD, 88, struct.pack("<d", math.inf)), "malformed"),     # inf radius
    (_with(GOOD, 72, struct.pack("<d", 1e300)), "malformed"),        # u beyond any image
    (_with(GOOD, 80 + 64, struct.pack("<d", -655361.0)), "malformed"),  # v of the third
    (_with(encode_detections(_det(1)), 72, struct.pack("<d", 655361.0)), "malformed"),  # k=1
    (_with(GOOD, 5, b"\x00"), "malformed"),         # empty name
    (_with(GOOD, 5, b"\x21"), "malformed"),         # name longer than its field
    (_with(GOOD, 5, b"\x02"), "malformed"),         # bytes after the name's length
    (_with(GOOD, 40, b"\xff\xfe\x00\x00"), "malformed"),  # not UTF-8
    (_with(GOOD, 16, struct.pack("<q", -5)), "malformed"),  # a negative frame index
    # past the session's u32 frame counter: once ended a recording run (the writer refused it)
    (_with(GOOD, 16, struct.pack("<q", 2**32)), "malformed"),
])
def test_every_bad_detection_datagram_has_its_reason(data, reason):
    assert _reason(data) == reason


def test_the_largest_frame_index_a_session_stores_is_accepted_and_no_larger_one_is_sent():
    assert decode_detections(_with(GOOD, 16, struct.pack("<q", 2**32 - 1))).frame_index == 2**32 - 1
    with pytest.raises(DatagramError, match=r"frame index 4294967296 is not in 0\.\.4294967295"):
        encode_detections(_det(1, frame_index=2**32))


def test_pixels_up_to_import_s_bound_are_accepted():
    """The bound is ``pslog import``'s (one constant): 655360 px either sign is a pixel."""
    from pslog.camera import MAX_PIXEL

    assert MAX_PIXEL == 655360
    for k in (1, 3):
        data = encode_detections(_det(k))
        data = _with(data, 72, struct.pack("<2d", MAX_PIXEL, -MAX_PIXEL))
        assert decode_detections(data).uv[0].tolist() == [MAX_PIXEL, -MAX_PIXEL]
    with pytest.raises(DatagramError, match=r"pixel \(1e\+300, .*\) is beyond any image "
                                            r"\(at most 655360 pixels\)"):
        decode_detections(_with(GOOD, 72, struct.pack("<d", 1e300)))


def test_oversize_bound_is_the_largest_valid_datagram():
    assert len(encode_detections(_det(MAX_CANDIDATES))) == MAX_DETECTION_BYTES
    with pytest.raises(DatagramError) as info:
        encode_detections(_det(MAX_CANDIDATES + 1))
    assert info.value.reason == "malformed"
    with pytest.raises(DatagramError):
        encode_detections(_det(1, camera="x" * 33))


@pytest.mark.parametrize("data, reason", [
    (b"PSLP\x01", "truncated"),
    (b"PSLD\x01" + bytes(219), "foreign"),
    (b"PSLP\x07" + bytes(219), "version"),
    (b"PSLP\x01" + bytes(230), "oversize"),
    (b"PSLP\x01" + bytes(219), "malformed"),        # zero-length names
])
def test_bad_point_datagrams(data, reason):
    with pytest.raises(DatagramError) as info:
        decode_point(data)
    assert info.value.reason == reason


@pytest.mark.parametrize("k", [0, 1, 3, MAX_CANDIDATES])
def test_decoded_arrays_are_those_of_the_checked_constructor(k):
    """decode_detections builds its DetectionDatagram without the constructor's checks (a
    fast path): the same arrays, float64, C-contiguous and read-only, as the constructor's."""
    e = decode_detections(encode_detections(_det(k)))
    ref = DetectionDatagram(e.camera, e.sequence, e.frame_index, e.t_capture_ns, e.t_sent_ns,
                            np.array(e.uv), np.array(e.radius), np.array(e.score))
    for name, shape in (("uv", (k, 2)), ("radius", (k,)), ("score", (k,))):
        a, b = getattr(e, name), getattr(ref, name)
        assert a.shape == b.shape == shape and a.dtype == b.dtype == np.float64
        assert a.flags.c_contiguous and not a.flags.writeable
        np.testing.assert_array_equal(a, b)
    assert e.__dict__.keys() == ref.__dict__.keys()
