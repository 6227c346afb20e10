"""Protobuf wire format for many messages at once, with numpy: the bytes protobuf's own
``SerializeToString`` gives for pslog's detection messages (``pslog.DetectionFrame``), made
for a block of frames at a time instead of a Python object per frame. (Track points, many
more fields per message, are written by the compiled loop of :mod:`._wire`.)

A *piece* is a column of variable-length byte strings: ``(matrix, lengths)``, row ``i`` being
``matrix[i, :lengths[i]]``. Fields are pieces; a message is its fields' pieces concatenated
row by row; a nested message is a length-delimited field around its message's piece. Proto3
rules as protobuf (upb) applies them: a scalar field at its default (0, +0.0: all bits zero)
is left out, -0.0 and NaN are written; fields in field-number order; a sub-message that was
set is written even when empty. Callers check the result against protobuf on sample rows.
"""

from __future__ import annotations

import numpy as np

Piece = tuple[np.ndarray, np.ndarray]  # (n, W) uint8, (n,) int64


def varint(values: np.ndarray) -> Piece:
    """Base-128 varints of non-negative integers (< 2**63)."""
    v = np.asarray(values, dtype=np.uint64).copy()
    n = len(v)
    out = np.zeros((n, 10), dtype=np.uint8)
    lengths = np.ones(n, dtype=np.int64)
    for j in range(10):
        low = (v & np.uint64(0x7F)).astype(np.uint8)
        v >>= np.uint64(7)
        more = v > 0
        out[:, j] = low | (more.astype(np.uint8) << 7)
        lengths += more
        if not more.any():
            return out[:, :j + 1], lengths
    return out, lengths


def const(n: int, data: bytes) -> Piece:
    """The same bytes on every row."""
    raw = np.frombuffer(data, dtype=np.uint8)
    return np.broadcast_to(raw, (n, len(raw))), np.full(n, len(raw), dtype=np.int64)


def field_varint(number: int, values: np.ndarray) -> Piece:
    """An int64/uint64 field (values >= 0), left out where 0."""
    v = np.asarray(values, dtype=np.int64)
    body, lengths = varint(v)
    piece = concat([const(len(v), bytes([number << 3])), (body, lengths)])
    return _where(piece, v != 0)


def field_double(number: int, values: np.ndarray) -> Piece:
    """A double field, left out where its bits are all zero (+0.0)."""
    v = np.ascontiguousarray(values, dtype="<f8")
    raw = v.view(np.uint8).reshape(len(v), 8)
    piece = concat([const(len(v), bytes([number << 3 | 1])),
                    (raw, np.full(len(v), 8, dtype=np.int64))])
    return _where(piece, v.view(np.uint64) != 0)


def field_message(number: int, inner: Piece) -> Piece:
    """A length-delimited field (a sub-message or a string) holding ``inner``."""
    n = len(inner[1])
    return concat([const(n, bytes([number << 3 | 2])), varint(inner[1]), inner])


def field_strings(number: int, index: np.ndarray, strings: list[str]) -> Piece:
    """A string field, row ``i`` holding ``strings[index[i]]`` (non-empty strings)."""
    encoded = [s.encode("utf-8") for s in strings]
    width = max((len(s) for s in encoded), default=0)
    table = np.zeros((len(encoded), width), dtype=np.uint8)
    for k, s in enumerate(encoded):
        table[k, :len(s)] = np.frombuffer(s, dtype=np.uint8)
    sizes = np.array([len(s) for s in encoded], dtype=np.int64)
    return field_message(number, (table[index], sizes[index]))


def concat(pieces: list[Piece]) -> Piece:
    """Each row's byte strings one after another (rows of one length in every piece: a
    plain stack of columns, see :func:`grouped`)."""
    n = len(pieces[0][1])
    if n and all(lengths.min() == lengths.max() for _m, lengths in pieces):
        parts = [np.asarray(m)[:, :int(lengths[0])] for m, lengths in pieces]
        out = np.hstack(parts) if parts else np.zeros((n, 0), np.uint8)
        return out, np.full(n, out.shape[1], dtype=np.int64)
    width = sum(m.shape[1] for m, _l in pieces)
    out = np.zeros((n, width), dtype=np.uint8)
    at = np.zeros(n, dtype=np.int64)
    for matrix, lengths in pieces:
        w = matrix.shape[1]
        if w == 0:
            continue
        valid = np.arange(w)[None, :] < lengths[:, None]
        rows = np.broadcast_to(np.arange(n)[:, None], (n, w))[valid]
        cols = (at[:, None] + np.arange(w)[None, :])[valid]
        out[rows, cols] = np.asarray(matrix)[valid]
        at = at + lengths
    return out, at


def _where(piece: Piece, keep: np.ndarray) -> Piece:
    return piece[0], np.where(keep, piece[1], 0)


def rows(piece: Piece) -> tuple[bytes, np.ndarray]:
    """Every row's bytes back to back, and each row's length."""
    matrix, lengths = piece
    valid = np.arange(matrix.shape[1])[None, :] < lengths[:, None]
    return np.asarray(matrix)[valid].tobytes(), lengths


def grouped(key: np.ndarray, encode) -> tuple[bytes, np.ndarray]:
    """``encode(rows)`` (rows: indices) -> a piece, run on the rows of each value of ``key``
    (rows of one key must give byte strings of one length in every piece, so each run is a
    stack of columns), the results put back in row order: (bytes back to back, lengths)."""
    n = len(key)
    groups, inverse = np.unique(key, return_inverse=True)
    lengths = np.zeros(n, dtype=np.int64)
    done = []
    for g in range(len(groups)):
        rows = np.flatnonzero(inverse == g)
        matrix, lens = encode(rows)
        lengths[rows] = lens
        done.append((rows, np.asarray(matrix), lens))
    starts = np.cumsum(lengths) - lengths
    out = np.empty(int(lengths.sum()), dtype=np.uint8)
    for rows, matrix, lens in done:
        w = matrix.shape[1]
        if not w:
            continue
        where = starts[rows][:, None] + np.arange(w)
        if lens.min() == lens.max():  # (a key that did not fix every length: masked)
            out[where[:, :int(lens[0])].ravel()] = matrix[:, :int(lens[0])].ravel()
        else:
            valid = np.arange(w)[None, :] < lens[:, None]
            out[where[valid]] = matrix[valid]
    return out.tobytes(), lengths


def varint_size(values: np.ndarray) -> np.ndarray:
    """Bytes of each value's varint (non-negative values)."""
    v = np.asarray(values, dtype=np.uint64)
    size = np.ones(len(v), dtype=np.int64)
    for j in range(1, 10):
        size += v >= np.uint64(1 << (7 * j))
    return size
