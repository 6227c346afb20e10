"""The live datagrams: fixed little-endian binary layouts, versioned, one UDP datagram each.

Two kinds, each starting with a 4-byte magic and a version byte, so a C/C++ reader needs one
``struct`` (``#pragma pack(1)``; every float64 lies on an 8-byte boundary) and a check of the
first five bytes. The tables below are repeated in ``docs/live.md``.

Times: every ``*_ns`` field is nanoseconds of the host's wall clock, the Unix epoch
(``time.time_ns()``, ``clock_gettime(CLOCK_REALTIME)``); cameras on other machines keep it
synchronised (NTP, PTP). The fuser counts its session clock from its start (``epoch_ns``):
the LOGGED time of :mod:`pslog.timing` is ``t_capture_ns - epoch_ns``.

Detection datagram (camera process -> fuser), magic ``PSLD``, version 1, ``72 + 32 k`` bytes:

======  ====  =======  ===================================================================
offset  size  type     field
======  ====  =======  ===================================================================
0       4     char[4]  magic ``PSLD``
4       1     u8       version (1)
5       1     u8       n: length of the camera name in bytes (1..32)
6       2     u16      k: number of candidates (0..64; 0: a frame where nothing was seen)
8       8     u64      sequence: per camera, +1 per frame (gaps: frames lost on the way)
16      8     i64      frame_index: the camera's frame counter (0 .. 2**32 - 1)
24      8     i64      t_capture_ns: the frame's top-row capture time (wall clock)
32      8     i64      t_sent_ns: the sender's wall clock when it sent the datagram
40      32    char[32] camera name, UTF-8, the rig's name, n bytes then zeros
72      32 k  f64[4]   k candidates, best first: u, v (distorted pixels), radius (pixels,
                       NaN unknown), score (detector confidence, 1 unknown)
======  ====  =======  ===================================================================

Point datagram (fuser -> ``--out``), magic ``PSLP``, version 1, 224 bytes:

======  ====  =======  ===================================================================
offset  size  type     field
======  ====  =======  ===================================================================
0       4     char[4]  magic ``PSLP``
4       1     u8       version (1)
5       1     u8       camera_index: the camera whose shutter made the point (rig order)
6       1     u8       length of the camera name in bytes
7       1     u8       length of the method name in bytes
8       8     u64      sequence: +1 per point sent by this fuser to this destination
16      8     i64      t_capture_ns: the instant the point describes (a shutter's time,
                       corrected by the rig's clock model; wall clock)
24      8     i64      t_emit_ns: when the fuser made the point (wall clock)
32      8     i64      t_arrival_ns: when the detection datagram that made it arrived
40      24    f64[3]   x, y, z: position, world metres (z up)
64      48    f64[6]   covariance xx, xy, xz, yy, yz, zz, m² (NaN when the method has none)
112     8     f64      residual_px: reprojection residual, pixels (NaN unknown)
120     4     u32      camera_mask: bit c set when camera c's detections made the point
124     4     u32      flags: bit 0 the point is a prediction (the detection was rejected),
                       bit 1 a velocity jump (bounce, kick), bit 2 a track (re)start
128     24    f64[3]   predicted position at t_emit_ns, world metres
152     24    f64[3]   predicted velocity at t_emit_ns, m/s (NaN when the method has none)
176     32    char[32] camera name, UTF-8, then zeros
208     16    char[16] method name (``filter``, ``typeA``...), ASCII, then zeros
======  ====  =======  ===================================================================

Decoding a datagram that is not a valid one raises :class:`DatagramError` whose ``reason``
is one of :data:`REASONS`:

- ``foreign``: it does not start with the magic (another program's datagram);
- ``version``: the magic, but a version this code does not read;
- ``truncated``: shorter than the fixed header, or its candidates cut mid-record;
- ``oversize``: longer than the largest valid datagram (:data:`MAX_DETECTION_BYTES`);
- ``malformed``: whole records but not as many as ``k`` says (``k`` too big or too small for
  the length), ``k`` above :data:`MAX_CANDIDATES`, a name that is empty, too long or not
  UTF-8, a NaN or infinite pixel or score (or an infinite radius), or a pixel beyond any
  image (:data:`pslog.camera.MAX_PIXEL`, as ``pslog import`` refuses).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from math import isfinite

import numpy as np

from ..camera import MAX_PIXEL
from ..errors import PslogError
from ..records import MAX_FRAME_INDEX

#: The version byte of both datagrams written by this code.
PROTOCOL_VERSION = 1
DETECTION_MAGIC = b"PSLD"
POINT_MAGIC = b"PSLP"
#: Longest camera name, bytes of UTF-8.
MAX_NAME_BYTES = 32
#: Longest method name in a point datagram, bytes.
MAX_METHOD_BYTES = 16
#: Most candidates one detection datagram may carry.
MAX_CANDIDATES = 64
#: Why a datagram was refused.
REASONS = ("truncated", "oversize", "foreign", "version", "malformed")

_DET_HEADER = struct.Struct("<4sBBHQqqq32s")
_CANDIDATE = struct.Struct("<4d")
DETECTION_HEADER_BYTES = _DET_HEADER.size  # 72
CANDIDATE_BYTES = _CANDIDATE.size  # 32
#: Longest valid detection datagram, bytes (:data:`MAX_CANDIDATES` candidates).
MAX_DETECTION_BYTES = DETECTION_HEADER_BYTES + MAX_CANDIDATES * CANDIDATE_BYTES
_POINT = struct.Struct("<4sBBBBQqqq3d6ddII3d3d32s16s")
POINT_BYTES = _POINT.size  # 224
#: Point flags (the ``flags`` field).
FLAG_PREDICTION, FLAG_JUMP, FLAG_INIT = 1, 2, 4
_NAN3 = (math.nan,) * 3
_INF = (math.inf, -math.inf)
#: one candidate record (u, v, radius, score), after the header
_ONE = struct.Struct("<4d")


class DatagramError(PslogError):
    """A datagram that is not a valid one; ``reason`` is one of :data:`REASONS`."""

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason


def _ro(a, shape) -> np.ndarray:
    a = np.array(a, dtype=np.float64).reshape(shape)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class DetectionDatagram:
    """One camera frame's detections, as sent by a camera process.

    Attributes
    ----------
    camera : str, the rig's camera name
    sequence : int, per camera, +1 per frame
    frame_index : int, the camera's frame counter
    t_capture_ns : int, top-row capture time, wall clock (Unix epoch) nanoseconds
    t_sent_ns : int, the sender's wall clock at send, nanoseconds
    uv : (k, 2) float64, distorted pixels, best candidate first
    radius : (k,) float64, pixels (NaN unknown)
    score : (k,) float64, detector confidence (1 unknown)
    """

    camera: str
    sequence: int
    frame_index: int
    t_capture_ns: int
    t_sent_ns: int
    uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    # None (unknown) becomes NaN radii and unit scores in __post_init__: always arrays after
    radius: np.ndarray = None  # type: ignore[assignment]
    score: np.ndarray = None  # type: ignore[assignment]

    def __post_init__(self) -> None:
        uv = _ro(self.uv, (-1, 2))
        k = len(uv)
        object.__setattr__(self, "uv", uv)
        object.__setattr__(self, "radius", _ro(np.full(k, np.nan) if self.radius is None
                                               else self.radius, (k,)))
        object.__setattr__(self, "score", _ro(np.ones(k) if self.score is None
                                              else self.score, (k,)))

    def __len__(self) -> int:
        return len(self.uv)


def detection_datagrams(detections, epoch_ns: int = 0,
                        sent_delay_ns: int = 0) -> list[DetectionDatagram]:
    """Every frame of a session's detections as the datagram its camera would have sent: to
    replay a recorded or simulated session into a live fuser.

    Parameters
    ----------
    detections : pslog.records.Detections, frames in (time, camera) order
    epoch_ns : int, wall clock of the session's time 0, nanoseconds: ``t_capture_ns`` is
        ``epoch_ns`` + the frame's logged time
    sent_delay_ns : int, ``t_sent_ns - t_capture_ns``

    Returns
    -------
    list of DetectionDatagram, one per frame (also the frames with no candidate), each
    camera's sequence numbered from 1.
    """
    bounds = np.searchsorted(detections.cand_frame,
                             np.arange(detections.n_frames + 1)).tolist()
    names = detections.camera_names
    seq = [0] * len(names)
    out = []
    for i, (cam, index, t) in enumerate(zip(detections.frame_camera.tolist(),
                                            detections.frame_index.tolist(),
                                            detections.frame_time_ns.tolist(), strict=True)):
        seq[cam] += 1
        a, b = bounds[i], bounds[i + 1]
        out.append(DetectionDatagram(names[cam], seq[cam], index, epoch_ns + t,
                                     epoch_ns + t + sent_delay_ns, detections.cand_uv[a:b],
                                     detections.cand_radius[a:b], detections.cand_score[a:b]))
    return out


def _name_bytes(name: str, limit: int, what: str) -> bytes:
    raw = name.encode("utf-8")
    if not 0 < len(raw) <= limit:
        raise DatagramError("malformed", f"{what} {name!r} must be 1 to {limit} bytes of UTF-8")
    return raw


def encode_detections(d: DetectionDatagram) -> bytes:
    """The detection datagram of ``d`` (layout: module docstring).

    Raises DatagramError (``malformed``) for a name that does not fit, more than
    :data:`MAX_CANDIDATES` candidates or a frame index past :data:`MAX_FRAME_INDEX` (what
    :func:`decode_detections` refuses)."""
    name = _name_bytes(d.camera, MAX_NAME_BYTES, "camera name")
    k = len(d.uv)
    if k > MAX_CANDIDATES:
        raise DatagramError("malformed", f"{k} candidates; a datagram carries at most "
                                         f"{MAX_CANDIDATES}")
    if not 0 <= int(d.frame_index) <= MAX_FRAME_INDEX:
        raise DatagramError("malformed", f"frame index {d.frame_index} is not in "
                                         f"0..{MAX_FRAME_INDEX}")
    header = _DET_HEADER.pack(DETECTION_MAGIC, PROTOCOL_VERSION, len(name), k,
                              int(d.sequence), int(d.frame_index), int(d.t_capture_ns),
                              int(d.t_sent_ns), name)
    if not k:
        return header
    body = np.empty((k, 4), dtype="<f8")
    body[:, :2] = d.uv
    body[:, 2] = d.radius
    body[:, 3] = d.score
    return header + body.tobytes()


def _check_start(data: bytes, magic: bytes, what: str) -> None:
    if data[:4] != magic[:len(data[:4])]:
        raise DatagramError("foreign", f"not a pslog {what} datagram (starts with "
                                       f"{bytes(data[:4])!r})")
    if len(data) < 5:
        raise DatagramError("truncated", f"{what} datagram of {len(data)} bytes is truncated")
    if data[4] != PROTOCOL_VERSION:
        raise DatagramError("version", f"{what} datagram version {data[4]}; this pslog reads "
                                       f"version {PROTOCOL_VERSION}")


def _beyond(camera: str, u: float, v: float) -> str:
    return (f"detection datagram of camera {camera!r}: pixel ({u:.6g}, {v:.6g}) is beyond "
            f"any image (at most {MAX_PIXEL:g} pixels)")


def decode_detections(data: bytes) -> DetectionDatagram:
    """The :class:`DetectionDatagram` of a received datagram; raises :class:`DatagramError`
    (module docstring) for anything else."""
    n = len(data)
    _check_start(data, DETECTION_MAGIC, "detection")
    if n > MAX_DETECTION_BYTES:
        raise DatagramError("oversize", f"detection datagram of {n} bytes; at most "
                                        f"{MAX_DETECTION_BYTES}")
    if n < DETECTION_HEADER_BYTES:
        raise DatagramError("truncated", f"detection datagram of {n} bytes is shorter than "
                                         f"its {DETECTION_HEADER_BYTES}-byte header")
    _, _, n_name, k, seq, frame, t_cap, t_sent, raw = _DET_HEADER.unpack_from(data)
    body = n - DETECTION_HEADER_BYTES
    if body % CANDIDATE_BYTES:
        raise DatagramError("truncated", f"detection datagram of {n} bytes: its candidates "
                                         f"are cut mid-record")
    if k > MAX_CANDIDATES or k != body // CANDIDATE_BYTES:
        raise DatagramError("malformed", f"detection datagram says {k} candidates but holds "
                                         f"{body // CANDIDATE_BYTES}")
    if not 0 < n_name <= MAX_NAME_BYTES or any(raw[n_name:]):
        raise DatagramError("malformed", f"detection datagram: bad camera name length {n_name}")
    try:
        camera = raw[:n_name].decode("utf-8")
    except UnicodeDecodeError:
        raise DatagramError("malformed", "detection datagram: camera name is not UTF-8") from None
    if not 0 <= frame <= MAX_FRAME_INDEX:  # (a session stores them as u32 counters: its
        # writer refuses the others, which would end a recording run)
        raise DatagramError("malformed", f"detection datagram of camera {camera!r}: frame "
                                         f"index {frame} is not in 0..{MAX_FRAME_INDEX}")
    if k == 1:  # (the usual frame: its four numbers by struct, one array of them)
        u, v, r, s = _ONE.unpack_from(data, DETECTION_HEADER_BYTES)
        if not (isfinite(u) and isfinite(v) and isfinite(s) and r not in _INF):
            raise DatagramError("malformed", f"detection datagram of camera {camera!r}: a "
                                             f"NaN or infinite pixel or score")
        if not (abs(u) <= MAX_PIXEL and abs(v) <= MAX_PIXEL):
            raise DatagramError("malformed", _beyond(camera, u, v))
        one = np.array((u, v, r, s))
        one.flags.writeable = False  # (its views inherit it)
        d = object.__new__(DetectionDatagram)
        d.__dict__.update(camera=camera, sequence=seq, frame_index=frame, t_capture_ns=t_cap,
                          t_sent_ns=t_sent, uv=one[:2].reshape(1, 2), radius=one[2:3],
                          score=one[3:4])
        return d
    cand = np.frombuffer(data, dtype="<f8", count=4 * k,
                         offset=DETECTION_HEADER_BYTES).reshape(k, 4)
    # radius may be NaN (unknown); pixels and scores must be numbers (in Python: a few
    # candidates are checked faster than numpy's calls on tiny arrays cost)
    if not all(isfinite(u) and isfinite(v) and isfinite(s) and r not in _INF
               for u, v, r, s in cand.tolist()):
        raise DatagramError("malformed", f"detection datagram of camera {camera!r}: a NaN or "
                                         f"infinite pixel or score")
    for u, v in cand[:, :2].tolist():
        if not (abs(u) <= MAX_PIXEL and abs(v) <= MAX_PIXEL):
            raise DatagramError("malformed", _beyond(camera, u, v))
    # the arrays as DetectionDatagram's own checks would make them (float64, C-contiguous,
    # read-only copies), without them: this runs once per datagram in the live fuser
    cols = cand.T.copy()  # (4, k): radius and score contiguous rows
    cols.setflags(write=False)
    uv = cand[:, :2].copy()
    uv.setflags(write=False)
    d = object.__new__(DetectionDatagram)
    d.__dict__.update(camera=camera, sequence=seq, frame_index=frame, t_capture_ns=t_cap,
                      t_sent_ns=t_sent, uv=uv, radius=cols[2], score=cols[3])
    return d


@dataclass(frozen=True, eq=False)
class PointDatagram:
    """One fused point as sent to ``--out`` (layout: module docstring).

    Attributes
    ----------
    sequence : int, +1 per point sent
    camera_index : int; camera : str
    method : str
    t_capture_ns, t_emit_ns, t_arrival_ns : int, wall clock nanoseconds
    position : (3,) float64, world metres
    covariance : (6,) float64, xx, xy, xz, yy, yz, zz, m² (NaN when none)
    residual_px : float
    camera_mask : int
    flags : int (:data:`FLAG_PREDICTION`, :data:`FLAG_JUMP`, :data:`FLAG_INIT`)
    predicted_position : (3,) float64, metres, at ``t_emit_ns``
    predicted_velocity : (3,) float64, m/s, at ``t_emit_ns`` (NaN when none)
    """

    sequence: int
    camera_index: int
    camera: str
    method: str
    t_capture_ns: int
    t_emit_ns: int
    t_arrival_ns: int
    position: tuple = _NAN3
    covariance: tuple = (math.nan,) * 6
    residual_px: float = math.nan
    camera_mask: int = 0
    flags: int = 0
    predicted_position: tuple = _NAN3
    predicted_velocity: tuple = _NAN3

    def __post_init__(self) -> None:
        for name, n in (("position", 3), ("covariance", 6), ("predicted_position", 3),
                        ("predicted_velocity", 3)):
            value = tuple(float(a) for a in np.asarray(getattr(self, name), dtype=np.float64)
                          .ravel())
            if len(value) != n:
                raise DatagramError("malformed", f"point {name} needs {n} numbers, "
                                                 f"got {len(value)}")
            object.__setattr__(self, name, value)


def encode_point(p: PointDatagram) -> bytes:
    """The point datagram of ``p`` (224 bytes)."""
    return pack_point(p.sequence, p.camera_index, p.camera, p.method, p.t_capture_ns,
                      p.t_emit_ns, p.t_arrival_ns, p.position, p.covariance, p.residual_px,
                      p.camera_mask, p.flags, p.predicted_position, p.predicted_velocity)


#: (name, limit) -> its checked UTF-8 bytes: a fuser sends a handful of names, per point
_NAMES: dict = {}


def _name_bytes_cached(name: str, limit: int, what: str) -> bytes:
    raw = _NAMES.get((name, limit))
    if raw is None:
        raw = _name_bytes(name, limit, what)
        if len(_NAMES) > 1024:  # names from anywhere: bounded
            _NAMES.clear()
        _NAMES[(name, limit)] = raw
    return raw


def pack_point(sequence: int, camera_index: int, camera: str, method: str,
               t_capture_ns: int, t_emit_ns: int, t_arrival_ns: int, position, covariance,
               residual_px: float, camera_mask: int, flags: int, predicted_position,
               predicted_velocity) -> bytes:
    """The point datagram of these fields (as :class:`PointDatagram`'s, the float triples
    and the covariance's 6 numbers as sequences of floats), without making a PointDatagram:
    the live fuser sends one per point. Raises DatagramError (``malformed``) for a name that
    does not fit."""
    camera_b = _name_bytes_cached(camera, MAX_NAME_BYTES, "camera name")
    method_b = _name_bytes_cached(method, MAX_METHOD_BYTES, "method name")
    return _POINT.pack(POINT_MAGIC, PROTOCOL_VERSION, int(camera_index), len(camera_b),
                       len(method_b), int(sequence), int(t_capture_ns), int(t_emit_ns),
                       int(t_arrival_ns), *position, *covariance, float(residual_px),
                       int(camera_mask), int(flags), *predicted_position,
                       *predicted_velocity, camera_b, method_b)


def decode_point(data: bytes) -> PointDatagram:
    """The :class:`PointDatagram` of a received datagram; raises :class:`DatagramError`."""
    _check_start(data, POINT_MAGIC, "point")
    if len(data) < POINT_BYTES:
        raise DatagramError("truncated", f"point datagram of {len(data)} bytes; it has "
                                         f"{POINT_BYTES}")
    if len(data) > POINT_BYTES:
        raise DatagramError("oversize", f"point datagram of {len(data)} bytes; it has "
                                        f"{POINT_BYTES}")
    v = _POINT.unpack(data)
    n_cam, n_method = v[3], v[4]
    camera_raw, method_raw = v[-2], v[-1]
    if not (0 < n_cam <= MAX_NAME_BYTES and 0 < n_method <= MAX_METHOD_BYTES):
        raise DatagramError("malformed", "point datagram: bad name length")
    try:
        camera = camera_raw[:n_cam].decode("utf-8")
        method = method_raw[:n_method].decode("utf-8")
    except UnicodeDecodeError:
        raise DatagramError("malformed", "point datagram: a name is not UTF-8") from None
    return PointDatagram(sequence=v[5], camera_index=v[2], camera=camera, method=method,
                         t_capture_ns=v[6], t_emit_ns=v[7], t_arrival_ns=v[8],
                         position=v[9:12], covariance=v[12:18], residual_px=v[18],
                         camera_mask=v[19], flags=v[20], predicted_position=v[21:24],
                         predicted_velocity=v[24:27])
