"""Compiled protobuf encoding of fused track points: the bytes of each point's
``pslog.TrackPoint`` and ``foxglove.SceneUpdate`` sphere, written by one loop
(:func:`pslog._jit.kernel`) into one buffer.

:mod:`._encode` makes the same bytes with numpy, a block of points at a time; its cost is
numpy's per-call overhead over the dozens of fields of each layout group (about 2.5 µs a
point, most of the time of writing a fused 90-minute match, four times for the default
methods). Here each point costs the bytes it writes. The wire rules are the ones
:mod:`._encode` states (proto3 as protobuf's upb applies them): a scalar field at its
default (0, +0.0: all bits zero) is left out, -0.0 and NaN are written, fields in
field-number order, a set sub-message is written even when empty. The writer checks the
result against protobuf's own ``SerializeToString`` on sample points (any difference: the
per-point way), and tests compare this kernel with :mod:`._encode` and with protobuf.

Imported only where a track is written (numba is loaded by the decorator).
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel


@kernel(inline=True)
def _varint_size(v):
    size = 1
    while v >= 128:
        v >>= 7
        size += 1
    return size


@kernel(inline=True)
def _put_varint(buf, at, v):
    while v >= 128:
        buf[at] = (v & 127) | 128
        v >>= 7
        at += 1
    buf[at] = v
    return at + 1


# The byte stores below index with unsigned integers: numba wraps a negative signed index
# around (a compare and select before each store), which kept LLVM from vectorising the
# copies; with unsigned ones the quality map's bytes (a few hundred a point) are copied a
# vector at a time and a value's 8 bytes in one store (the same bytes: 3.6 times faster
# over a fused 90-minute match's four tracks, 0.78 -> 0.21 thread CPU s in one run)


@kernel(inline=True)
def _put_bytes(buf, at, src):
    base = np.uint64(at)
    for j in range(np.uint64(len(src))):
        buf[base + j] = src[j]
    return at + len(src)


@kernel(inline=True)
def _put_u64(buf, at, bits):
    """``bits`` (uint64) as 8 little-endian bytes at ``buf[at]``."""
    base = np.uint64(at)
    for j in range(8):
        buf[base + np.uint64(j)] = (bits >> np.uint64(8 * j)) & np.uint64(255)


@kernel(inline=True)
def _put_double(buf, at, tag, bits):
    """A double field (``bits``: its IEEE bits as uint64), left out when all bits are 0."""
    if bits == 0:
        return at
    buf[np.uint64(at)] = tag
    _put_u64(buf, at + 1, bits)
    return at + 9


@kernel(inline=True)
def _double_size(bits):
    return 0 if bits == 0 else 9


@kernel(inline=True)
def _decimal_size(v):
    size = 1
    while v >= 10:
        v //= 10
        size += 1
    return size


@kernel(inline=True)
def _put_head(out, at, length, channel, t):
    """An MCAP Message record's 31-byte head at ``out[at]`` (MCAP spec, "Message"): opcode
    0x05, record length (``length`` payload bytes + 22), channel id, sequence 0, log time
    and publish time ``t``, little endian."""
    out[at] = 0x05
    v = length + 22
    for j in range(8):
        out[at + 1 + j] = (v >> (8 * j)) & 255
    out[at + 9] = channel & 255
    out[at + 10] = (channel >> 8) & 255
    for j in range(4):
        out[at + 11 + j] = 0
    for j in range(8):
        b = (t >> (8 * j)) & 255
        out[at + 15 + j] = b
        out[at + 23 + j] = b


#: bytes of a Message record before its payload (MCAP spec: opcode, length, channel,
#: sequence, log time, publish time)
HEAD = 31


@kernel
def encode_track(t, bits, cam, names, name_start, method, template, slots, quality, ids,
                 world, lifetime, orientation, size, rgba, channels, out, point_len, total_len):
    """Write each point's TrackPoint then SceneUpdate into ``out``; returns the bytes used.

    Parameters
    ----------
    t : (n,) int64 time, ns, >= 0
    bits : (n, 6) uint64 IEEE bits of x, y, z (metres) and the three fixed quality fields
    cam : (n,) int64 camera index into ``name_start``
    names, name_start : the camera names' UTF-8 bytes back to back, (cameras + 1,) offsets
    method : the method's UTF-8 bytes
    template, slots, quality : the quality map entries (field 10) of every point: the
        ``(w,)`` uint8 bytes of one point's entries (:func:`pslog.log.writer._quality_template`)
        with the 8 bytes of key ``j``'s value at ``slots[j]``, filled in from ``quality``
        ``(n, k)`` uint64 (the values' IEEE bits, key ``j`` in column ``j``)
    ids : (n,) int64 scene entity number (``<method>/<id>``)
    world, lifetime, orientation, size, rgba : uint8, the frame id and the constant fields
        (lifetime, the pose's orientation, the sphere's size and colour), already encoded
    channels : (2,) int64, the TrackPoint's and the SceneUpdate's MCAP channel ids: each
        message is then written as a whole MCAP Message record (:data:`HEAD` bytes of head,
        sequence 0, log and publish time ``t``, then the message), ready for a chunk (one
        copy less of a fused match's gigabyte of messages); (2,) of -1: the messages alone
    out : uint8 buffer large enough (see :func:`bound`)
    point_len, total_len : (n,) int64 outputs: TrackPoint bytes and both messages' bytes
        (without the records' heads)
    """
    n = len(t)
    at = 0
    slash = np.uint8(47)
    heads = channels[0] >= 0
    gap = HEAD if heads else 0
    for i in range(n):
        head_at = at
        at += gap
        start = at
        ti = t[i]
        # TrackPoint
        if ti != 0:
            out[at] = 0x08
            at = _put_varint(out, at + 1, ti)
        out[at] = 0x12
        at = _put_varint(out, at + 1, len(method))
        at = _put_bytes(out, at, method)
        at = _put_double(out, at, 0x19, bits[i, 0])
        at = _put_double(out, at, 0x21, bits[i, 1])
        at = _put_double(out, at, 0x29, bits[i, 2])
        c = cam[i]
        a, b = name_start[c], name_start[c + 1]
        out[at] = 0x32
        at = _put_varint(out, at + 1, b - a)
        for j in range(a, b):
            out[at] = names[j]
            at += 1
        at = _put_double(out, at, 0x39, bits[i, 3])
        at = _put_double(out, at, 0x41, bits[i, 4])
        at = _put_double(out, at, 0x49, bits[i, 5])
        at = _put_bytes(out, at, template)  # the map's entries, then their values
        row = at - len(template)
        for j in range(len(slots)):
            _put_u64(out, row + slots[j], quality[i, j])
        point_len[i] = at - start
        if heads:
            _put_head(out, head_at, at - start, channels[0], ti)
            head_at = at
            at += gap
        scene_start = at
        # SceneUpdate { entities (2): SceneEntity }
        sec, nanos = ti // 1_000_000_000, ti % 1_000_000_000
        stamp = 0
        if sec != 0:
            stamp += 1 + _varint_size(sec)
        if nanos != 0:
            stamp += 1 + _varint_size(nanos)
        digits = _decimal_size(ids[i])
        name = len(method) + 1 + digits
        position = (_double_size(bits[i, 0]) + _double_size(bits[i, 1])
                    + _double_size(bits[i, 2]))
        pose = 1 + _varint_size(position) + position + len(orientation)
        sphere = 1 + _varint_size(pose) + pose + len(size) + len(rgba)
        entity = (1 + _varint_size(stamp) + stamp + 1 + _varint_size(len(world)) + len(world)
                  + 1 + _varint_size(name) + name + len(lifetime)
                  + 1 + _varint_size(sphere) + sphere)
        out[at] = 0x12
        at = _put_varint(out, at + 1, entity)
        out[at] = 0x0A  # timestamp (1)
        at = _put_varint(out, at + 1, stamp)
        if sec != 0:
            out[at] = 0x08
            at = _put_varint(out, at + 1, sec)
        if nanos != 0:
            out[at] = 0x10
            at = _put_varint(out, at + 1, nanos)
        out[at] = 0x12  # frame_id (2)
        at = _put_varint(out, at + 1, len(world))
        at = _put_bytes(out, at, world)
        out[at] = 0x1A  # id (3): "<method>/<i>"
        at = _put_varint(out, at + 1, name)
        at = _put_bytes(out, at, method)
        out[at] = slash
        at += 1
        v = ids[i]
        for j in range(digits - 1, -1, -1):
            out[at + j] = 48 + v % 10
            v //= 10
        at += digits
        at = _put_bytes(out, at, lifetime)  # lifetime (4)
        out[at] = 0x4A  # spheres (9)
        at = _put_varint(out, at + 1, sphere)
        out[at] = 0x0A  # pose (1)
        at = _put_varint(out, at + 1, pose)
        out[at] = 0x0A  # position (1)
        at = _put_varint(out, at + 1, position)
        at = _put_double(out, at, 0x09, bits[i, 0])
        at = _put_double(out, at, 0x11, bits[i, 1])
        at = _put_double(out, at, 0x19, bits[i, 2])
        at = _put_bytes(out, at, orientation)
        at = _put_bytes(out, at, size)
        at = _put_bytes(out, at, rgba)
        total_len[i] = point_len[i] + at - scene_start
        if heads:
            _put_head(out, head_at, at - scene_start, channels[1], ti)
    return at


def bound(n: int, method: bytes, names: list[bytes], extra_width: int, constants: int) -> int:
    """Bytes :func:`encode_track` writes for ``n`` points at most (every field present, every
    varint at its widest)."""
    widest = max((len(x) for x in names), default=0)
    point = 11 + 10 + len(method) + 27 + 10 + widest + 27 + extra_width
    scene = 3 * 11 + 2 * 11 + 11 + 11 + len(method) + 1 + 20 + constants + 3 * 11 + 27 + 11
    return n * (point + scene + 2 * HEAD)


@kernel
def assemble_records(body, heads, rec_start, payload, data_start, lengths):
    """Write MCAP message records into a chunk's uncompressed ``body`` (uint8): record ``i``
    is its 31-byte head ``heads[i]`` at ``rec_start[i]`` followed by its payload
    ``payload[data_start[i]:data_start[i] + lengths[i]]`` (:func:`._chunks.write_messages`
    lays out where each goes; this only copies, bytes that numpy's masks would place alike).
    """
    width = heads.shape[1]
    for i in range(len(rec_start)):
        at = rec_start[i]
        for j in range(width):
            body[at + j] = heads[i, j]
        at += width
        src = data_start[i]
        body[at:at + lengths[i]] = payload[src:src + lengths[i]]
