"""Write many MCAP messages at once: the chunks, message indexes and summary entries the
``mcap`` package's :class:`mcap.writer.Writer` makes for the same messages added one by one
with ``add_message`` (byte for byte: same chunk boundaries, same record order, same zstd
frames), built with numpy instead of a dozen Python calls per message.

The ``mcap`` writer keeps its summary state (chunk indexes, statistics, the channel and schema
records waiting for the next chunk) in private attributes; this module reads and updates
them. :func:`supported` says whether the installed ``mcap`` has them; when it does not, the
caller adds messages one by one as before.
"""

from __future__ import annotations

import functools
import sys
import threading
import zlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

#: one message record's fixed part: opcode, record length, channel, sequence, log and
#: publish time (MCAP spec, "Message" record), packed (31 bytes)
_HEAD = np.dtype([("op", "u1"), ("length", "<u8"), ("channel", "<u2"), ("sequence", "<u4"),
                  ("log_time", "<u8"), ("publish_time", "<u8")])
_OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX, _OP_ATTACHMENT = 0x05, 0x06, 0x07, 0x09
_U32 = 1 << 32
#: payload bytes from which a block's chunk records are assembled by the compiled loop
_COMPILED_FROM = 1 << 20
#: zstd level of the chunks written in blocks: -1 (zstd's first "fast" level) shrinks a
#: fused 90-minute match's track chunks as level 1 does (the file 623.2 MB against 621.3)
#: for about 0.35 CPU s less of the 1.3 s level 1 took (1.06 GB of messages), and
#: decompresses slightly faster (3.6 against 3.3 GB/s); level 1 had replaced the ``mcap``
#: writer's default 3 (ratio 3.49 against 3.47, 1.5 times the speed); any level decodes alike
ZSTD_LEVEL = -1
#: zstd level of a fused track's chunks (messages written as whole records,
#: ``write_messages(assembled=True)``): -3 compresses a fused 90-minute match's four track
#: topics (1.06 GB of messages) in 1.47 CPU s against -1's 1.90 (-23 %), to 291.1 MB against
#: 278.1 (+4.7 %; the fused file 641 MB against 628, +2 %): compressing the tracks is the
#: largest cost of writing a fused file, and a default ``pslog fuse`` lacks CPU on two
#: cores. Levels -4 to -15 were no faster per MB saved (-7: 1.37 s, 325.8 MB). Sessions
#: (detections, images) keep :data:`ZSTD_LEVEL`: -3 made a simulated one 4 % larger for
#: no time that matters
TRACK_ZSTD_LEVEL = -3
#: zstd level of the table columns (:func:`_compress_all`; a column is kept compressed only
#: when zstd shrinks it by 10 %: a decision of this level, not changed with the chunks')
TABLE_ZSTD_LEVEL = 1


#: distinct channels of a block from which :func:`channels_seen` sorts (``np.unique``) rather
#: than scanning the block once per channel
_FEW_CHANNELS = 16


def channels_seen(channel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct values of ``channel`` (n,) integer ids, in order of first appearance, and
    how many times each appears: ``np.unique(channel, return_index=True,
    return_counts=True)`` reordered by first index, the same values. A block holds a few
    channels (a fused track's: two) among hundreds of thousands of messages: counted by
    ``np.bincount`` and found by a scan per channel instead of sorted (a tenth of the time,
    on the writer's thread)."""
    channel = np.asarray(channel)
    if (len(channel) and channel.dtype.kind in "iu" and channel.min() >= 0
            and channel.max() < 1 << 16):
        counts = np.bincount(channel)
        ids = np.flatnonzero(counts)
        if len(ids) <= _FEW_CHANNELS:
            first = np.array([int(np.argmax(channel == i)) for i in ids.tolist()],
                             dtype=np.int64)
            order = np.argsort(first, kind="stable")
            return ids[order].astype(channel.dtype), counts[ids][order]
    ids, first, counts = np.unique(channel, return_index=True, return_counts=True)
    order = np.argsort(first, kind="stable")
    return ids[order], counts[order]


def supported(writer) -> bool:
    """Whether ``writer`` (an ``mcap.writer.Writer``) exposes the state this module needs and
    compresses chunks with zstd (the only compression pslog writes)."""
    from mcap.writer import CompressionType

    names = ("_Writer__chunk_builder", "_Writer__chunk_indices", "_Writer__statistics",
             "_Writer__stream", "_Writer__chunk_size", "_Writer__compression",
             "_Writer__index_types", "_Writer__enable_crcs", "_Writer__enable_data_crcs",
             "_Writer__flush", "_Writer__channels", "_Writer__finalize_chunk",
             "_Writer__attachment_indexes")
    return (all(hasattr(writer, n) for n in names)
            and writer._Writer__chunk_builder is not None
            and writer._Writer__compression == CompressionType.ZSTD)


def fits(sequence: np.ndarray, log_time: np.ndarray) -> bool:
    """Whether the fields fit the record's widths (else ``add_message`` raises its own error)."""
    return bool(len(sequence) == 0 or (sequence.min() >= 0 and sequence.max() < _U32
                                       and log_time.min() >= 0))


def record_head(channel: int, log_time: int, length: int, sequence: int = 0) -> bytes:
    """The 31-byte head of a Message record of ``length`` payload bytes (publish time = log
    time), as :func:`write_messages` lays it out."""
    head = np.zeros(1, dtype=_HEAD)
    head["op"], head["length"], head["channel"] = _OP_MESSAGE, length + _HEAD.itemsize - 9, \
        channel
    head["sequence"], head["log_time"], head["publish_time"] = sequence, log_time, log_time
    return head.tobytes()


def write_messages(writer, channel: np.ndarray, log_time: np.ndarray, sequence: np.ndarray,
                   data: bytes, lengths: np.ndarray, assembled: bool = False) -> None:
    """Add ``n`` messages to ``writer`` in order and finish their chunk(s), as ``n`` calls of
    ``add_message(channel[i], log_time[i], data_i, log_time[i], sequence[i])`` followed by
    ``flush()`` would (the stream itself is not flushed).

    Parameters
    ----------
    writer : ``mcap.writer.Writer`` for which :func:`supported` holds, with no message in its
        chunk in progress (its pending schema and channel records open the first chunk)
    channel : (n,) channel ids
    log_time : (n,) int64 log time, ns, >= 0 (also the publish time)
    sequence : (n,) sequence numbers in [0, 2**32)
    data : the messages' payloads back to back (bytes-like)
    lengths : (n,) int64 byte length of each payload
    assembled : ``data`` holds the whole Message records back to back instead, each
        payload after its head (:func:`record_head`, as the fields above make it): each
        chunk's records are then compressed from ``data`` as they are (no copy unless
        schema or channel records precede them in the chunk)
    """
    from mcap.records import ChunkIndex
    from mcap.writer import IndexType

    n = len(channel)
    if n == 0:
        return
    builder = writer._Writer__chunk_builder
    if builder.num_messages:
        writer._Writer__finalize_chunk()  # someone's single messages: their chunk first
    prefix = builder.record_writer.end()  # schema/channel records registered since
    builder.reset()
    limit = writer._Writer__chunk_size
    stats = writer._Writer__statistics
    stream = writer._Writer__stream
    data_crcs = writer._Writer__enable_data_crcs
    index_messages = bool(writer._Writer__index_types & IndexType.MESSAGE)
    crcs = writer._Writer__enable_crcs
    writer._Writer__flush()  # whatever sits in the writer's own record buffer

    lengths = np.asarray(lengths, dtype=np.int64)
    log_time = np.asarray(log_time, dtype=np.int64)
    channel = np.asarray(channel, dtype=np.int64)
    sizes = lengths + _HEAD.itemsize
    ends = np.cumsum(sizes)  # end of record i counted from the first record
    data_ends = np.cumsum(lengths)
    payload = np.frombuffer(data, dtype=np.uint8)
    if assembled:
        head_bytes = None
    else:
        head = np.zeros(n, dtype=_HEAD)
        head["op"] = _OP_MESSAGE
        head["length"] = sizes - 9
        head["channel"] = channel
        head["sequence"] = sequence
        head["log_time"] = log_time
        head["publish_time"] = log_time
        head_bytes = head.view(np.uint8).reshape(n, _HEAD.itemsize)
        del head

    # statistics as add_message keeps them
    if stats.message_count == 0:
        stats.message_start_time = int(log_time.min())
    else:
        stats.message_start_time = min(int(log_time.min()), stats.message_start_time)
    stats.message_end_time = max(int(log_time.max()), stats.message_end_time)
    ids, counts = channels_seen(channel)  # a new channel's key where add_message puts it
    for cid, k in zip(ids.tolist(), counts.tolist(), strict=True):
        stats.channel_message_counts[cid] += k
    stats.message_count += n

    # the chunks' uncompressed records first, then compressed together (zstd releases the
    # GIL: the chunks of a block are compressed on every core), then written in order;
    # a large block's records are assembled by a compiled loop (numpy's masks cost as much
    # as the compression) where numba's kernels are loaded already (a fused track's writer:
    # ._wire); a recorder never waits for numba to load (seconds on a busy machine, frames
    # lost meanwhile): numpy's masks, the same bytes
    compiled: Callable[..., None] | None = None
    if not assembled and len(data) >= _COMPILED_FROM and "pslog.log._wire" in sys.modules:
        from ._wire import assemble_records

        compiled = assemble_records
    bodies = []
    s, base = 0, len(prefix)
    while s < n:
        # add_message closes the chunk after the first message that takes it past the limit
        done_before = int(ends[s - 1]) if s else 0
        e = int(np.searchsorted(ends, limit - base + done_before, side="right")) + 1
        e = min(e, n)
        rec_start = base + (ends[s:e] - sizes[s:e] - done_before)  # offsets in the chunk
        total = base + int(ends[e - 1]) - done_before
        if assembled:  # the records as they are: a view, or after the pending records
            records = payload[done_before:int(ends[e - 1])]
            if base:
                body = np.empty(total, dtype=np.uint8)
                body[:base] = np.frombuffer(prefix, dtype=np.uint8)
                body[base:] = records
            else:
                body = records
            del records
            bodies.append((s, e, rec_start, body))
            del body
            s, base = e, 0
            continue
        assert head_bytes is not None
        body = np.empty(total, dtype=np.uint8)
        body[:base] = np.frombuffer(prefix, dtype=np.uint8) if base else body[:0]
        d0 = int(data_ends[s - 1]) if s else 0
        if compiled is not None:  # each record's head and payload copied in place
            compiled(body, head_bytes[s:e], rec_start, payload, data_ends[s:e] - lengths[s:e],
                     lengths[s:e])
        else:
            is_head = np.zeros(total, dtype=bool)
            where = (rec_start[:, None] + np.arange(_HEAD.itemsize)).ravel()
            is_head[where] = True
            is_head[:base] = True
            body[where] = head_bytes[s:e].ravel()
            body[~is_head] = payload[d0:int(data_ends[e - 1])]
            del is_head, where
        bodies.append((s, e, rec_start, body))  # compressed from the array: no copy
        del body
        s, base = e, 0
    packed = _pack_all([b[3] for b in bodies], crcs,
                       TRACK_ZSTD_LEVEL if assembled else ZSTD_LEVEL)
    for (s, e, rec_start, raw), (compressed, crc) in zip(bodies, packed, strict=True):
        times = log_time[s:e]
        start_time, end_time = int(times.min()), int(times.max())
        # the chunk record: its fixed fields, then the compressed records (written as they
        # are, not joined into one more copy)
        chunk_head = b"".join([
            bytes([_OP_CHUNK]),
            (8 + 8 + 8 + 4 + 4 + 4 + 8 + len(compressed)).to_bytes(8, "little"),
            start_time.to_bytes(8, "little"), end_time.to_bytes(8, "little"),
            len(raw).to_bytes(8, "little"), crc.to_bytes(4, "little"),
            (4).to_bytes(4, "little"), b"zstd", len(compressed).to_bytes(8, "little")])
        chunk_start = stream.tell()
        stream.write(chunk_head)
        stream.write(compressed)
        record_length = len(chunk_head) + len(compressed)
        index = ChunkIndex(message_start_time=start_time, message_end_time=end_time,
                           chunk_start_offset=chunk_start, chunk_length=record_length,
                           message_index_offsets={}, message_index_length=0,
                           compression="zstd", compressed_size=len(compressed),
                           uncompressed_size=len(raw))
        # message indexes: one per channel, in order of each channel's first message
        pieces = []
        index_start = chunk_start + record_length
        if index_messages:
            chans = channel[s:e]
            at = 0
            for cid in channels_seen(chans)[0].tolist():
                sel = np.flatnonzero(chans == cid)
                entries = np.empty((len(sel), 2), dtype="<u8")
                entries[:, 0] = times[sel]
                entries[:, 1] = rec_start[sel]
                size = 16 * len(sel)
                piece = b"".join([bytes([_OP_MESSAGE_INDEX]), (6 + size).to_bytes(8, "little"),
                                  cid.to_bytes(2, "little"), size.to_bytes(4, "little"),
                                  entries.tobytes()])
                index.message_index_offsets[cid] = index_start + at
                at += len(piece)
                pieces.append(piece)
        indexes = b"".join(pieces)
        index.message_index_length = len(indexes)
        stream.write(indexes)
        if data_crcs:
            writer._Writer__data_section_crc = zlib.crc32(indexes, zlib.crc32(
                compressed, zlib.crc32(chunk_head, writer._Writer__data_section_crc)))
        writer._Writer__chunk_indices.append(index)
        stats.chunk_count += 1


#: (process id, thread pool) compressing chunks; made again in a forked child (the
#: parent's threads do not exist there)
_POOL: tuple[int, object] | None = None


#: each thread's zstd compressors by level (a compressor serves one thread at a time)
_COMPRESSORS = threading.local()


def _compressor(level: int):
    """This thread's ``zstandard.ZstdCompressor`` of ``level``, made once: the same frames
    as ``zstandard.compress(data, level)``, which makes a compressor (its context and
    tables) for every chunk (a fused match's thousand chunks: about 6 % of their
    compression time)."""
    made = getattr(_COMPRESSORS, "by_level", None)
    if made is None:
        made = _COMPRESSORS.by_level = {}
    compressor = made.get(level)
    if compressor is None:
        import zstandard

        compressor = made[level] = zstandard.ZstdCompressor(level=level)
    return compressor


def _pack(raw: Any, crcs: bool, level: int) -> tuple[bytes, int]:
    """A chunk's records compressed at zstd ``level`` and their CRC-32 (0 when not
    computed): both release the GIL, so a pool thread does both."""
    return _compressor(level).compress(raw), (zlib.crc32(raw) if crcs else 0)


def _compress_table(raw: Any) -> bytes:
    """``raw`` compressed at :data:`TABLE_ZSTD_LEVEL` by this thread's compressor."""
    return _compressor(TABLE_ZSTD_LEVEL).compress(raw)


def _pack_all(raws: list, crcs: bool, level: int) -> list[tuple[bytes, int]]:
    """:func:`_pack` of each, on the pool of :func:`_compress_all`."""
    pool = _pool() if len(raws) > 1 else None
    if pool is None:
        return [_pack(r, crcs, level) for r in raws]
    return list(pool.map(functools.partial(_pack, crcs=crcs, level=level), raws))


def _pool():
    """The thread pool compressing chunks (None on one core)."""
    import os

    if (os.cpu_count() or 1) < 2:
        return None
    global _POOL
    if _POOL is None or _POOL[0] != os.getpid():
        from concurrent.futures import ThreadPoolExecutor

        _POOL = (os.getpid(), ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1),
                                                 thread_name_prefix="pslog-zstd"))
    return _POOL[1]


def _compress_all(raws: Sequence[Any]) -> list[bytes]:
    """``zstandard.compress`` of each at :data:`TABLE_ZSTD_LEVEL` (one zstd frame with its
    content size, as the ``mcap`` writer makes them), on a pool of threads when there are
    several."""
    pool = _pool() if len(raws) > 1 else None
    if pool is None:
        return [_compress_table(r) for r in raws]
    return list(pool.map(_compress_table, raws))


def register_channel(writer, channel_id: int, topic: str, message_encoding: str,
                     schema_id: int, metadata) -> None:
    """``writer.register_channel`` with the id chosen by the caller (a session copy keeps
    its source's ids, so that the source's chunks can be copied as they are); the id must
    be free."""
    from mcap.records import Channel

    channels = writer._Writer__channels
    if channel_id in channels or not 0 < channel_id < 1 << 16:
        raise ValueError(f"channel id {channel_id} is taken or out of range")
    channel = Channel(id=channel_id, topic=topic, message_encoding=message_encoding,
                      schema_id=schema_id, metadata=dict(metadata))
    channels[channel_id] = channel
    writer._Writer__statistics.channel_count += 1
    builder = writer._Writer__chunk_builder
    builder.add_channel(channel)
    if builder.count > writer._Writer__chunk_size:
        writer._Writer__finalize_chunk()


def write_raw_chunk(writer, record, indexes, index_offsets: dict[int, int],
                    counts: dict[int, int], start_time: int, end_time: int) -> None:
    """Write a whole Chunk record and its MessageIndex records as they are (copied from
    another file: no decompression, no compression) and account for them as
    :func:`write_messages` does (chunk index, statistics).

    Parameters
    ----------
    writer : ``mcap.writer.Writer`` for which :func:`supported` holds; every channel of the
        chunk is registered there with the same id as in the chunk
    record : the Chunk record (opcode, length, fields, compressed records)
    indexes : the MessageIndex records that followed it
    index_offsets : channel -> offset of its MessageIndex record from the start of
        ``indexes``
    counts : channel -> messages of that channel in the chunk (in order of the index)
    start_time, end_time : the chunk's first and last message log time, ns
    """
    from mcap.records import ChunkIndex

    builder = writer._Writer__chunk_builder
    if builder.num_messages:
        writer._Writer__finalize_chunk()
    pending = builder.record_writer.end()  # schema/channel records registered since: they
    builder.reset()  # precede the messages that refer to them, outside any chunk
    stream = writer._Writer__stream
    writer._Writer__flush()
    record, indexes = memoryview(record), memoryview(indexes)
    data_crcs = writer._Writer__enable_data_crcs
    if pending:
        stream.write(pending)
        if data_crcs:
            writer._Writer__data_section_crc = zlib.crc32(pending,
                                                          writer._Writer__data_section_crc)
    # the chunk record's fixed fields: op, length, start, end, uncompressed size, crc,
    # compression string, compressed size (MCAP spec, "Chunk")
    usize = int.from_bytes(record[25:33], "little")
    clen = int.from_bytes(record[37:41], "little")
    compression = bytes(record[41:41 + clen]).decode()
    csize = int.from_bytes(record[41 + clen:49 + clen], "little")
    chunk_start = stream.tell()
    stream.write(record)
    stream.write(indexes)
    if data_crcs:
        writer._Writer__data_section_crc = zlib.crc32(
            indexes, zlib.crc32(record, writer._Writer__data_section_crc))
    index_start = chunk_start + len(record)
    writer._Writer__chunk_indices.append(ChunkIndex(
        message_start_time=start_time, message_end_time=end_time,
        chunk_start_offset=chunk_start, chunk_length=len(record),
        message_index_offsets={cid: index_start + at for cid, at in index_offsets.items()},
        message_index_length=len(indexes), compression=compression, compressed_size=csize,
        uncompressed_size=usize))
    stats = writer._Writer__statistics
    n = sum(counts.values())
    if n:
        if stats.message_count == 0:
            stats.message_start_time = start_time
        else:
            stats.message_start_time = min(start_time, stats.message_start_time)
        stats.message_end_time = max(end_time, stats.message_end_time)
    for cid, k in counts.items():
        stats.channel_message_counts[cid] += k
    stats.message_count += n
    stats.chunk_count += 1


def write_attachment(writer, name: str, media_type: str, parts) -> None:
    """``writer.add_attachment(0, 0, name, media_type, b"".join(parts))`` (log and create
    time 0) with the same bytes, its ``data`` written piece by piece: no copy of it (the
    ``mcap`` writer copies an attachment's data four times on its way to the file)."""
    from mcap.records import AttachmentIndex
    from mcap.writer import IndexType

    writer._Writer__flush()
    stream = writer._Writer__stream
    size = sum(len(p) for p in parts)
    name_b, media_b = name.encode(), media_type.encode()
    head = b"".join([(0).to_bytes(8, "little"), (0).to_bytes(8, "little"),
                     len(name_b).to_bytes(4, "little"), name_b,
                     len(media_b).to_bytes(4, "little"), media_b,
                     size.to_bytes(8, "little")])
    length = len(head) + size + 4
    offset = stream.tell()
    crc = zlib.crc32(head)
    pieces = [bytes([_OP_ATTACHMENT]) + length.to_bytes(8, "little") + head]
    for p in parts:
        crc = zlib.crc32(p, crc)
        pieces.append(p)
    pieces.append(crc.to_bytes(4, "little"))
    data_crcs = writer._Writer__enable_data_crcs
    for p in pieces:
        stream.write(p)
        if data_crcs:
            writer._Writer__data_section_crc = zlib.crc32(p, writer._Writer__data_section_crc)
    writer._Writer__statistics.attachment_count += 1
    if writer._Writer__index_types & IndexType.ATTACHMENT:
        writer._Writer__attachment_indexes.append(AttachmentIndex(
            offset=offset, length=9 + length, create_time=0, log_time=0, data_size=size,
            name=name, media_type=media_type))
