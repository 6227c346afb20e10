"""Low-level MCAP access shared by the reader, ``copy_session``, ``session_info`` and
``recover_session``: file checks, chunk decompression with every check the format allows
(lengths, decompression, CRC, framing), a strict top-level record walk for readers, a
salvaging walk for recovery that skips damaged chunks and resynchronises after damaged record
headers, the summary section, and a fast message walk inside chunks.

The ``mcap`` package parses each record through several Python objects; for ~10^6 small
messages that dominates reading time, so messages inside chunks are sliced out here with
``struct.unpack_from`` (record layout: https://mcap.dev/spec). Why not the ``mcap`` reader
where it would do: measured in one run (benchmarks/bench_peers.py, bench_match.py), its
``iter_messages`` with protobuf decoding reads ~0.1 M detections/s where this walk reads
~0.6 M/s and the columnar tables (table.py) several M/s; and its strict reader stops at the
first damaged record, where ``recover`` must skip and resynchronise. The ``mcap`` package
still writes every file (writer.py) and is what a peer tool uses (docs/log-format.md).
"""

from __future__ import annotations

import mmap
import os
import re
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import LogFormatError, shell_word
from . import _schemas as S

MAGIC = b"\x89MCAP0\r\n"

# opcodes of the MCAP spec
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL = 0x01, 0x02, 0x03, 0x04
OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX, OP_CHUNK_INDEX = 0x05, 0x06, 0x07, 0x08
OP_ATTACHMENT, OP_STATISTICS, OP_METADATA, OP_DATA_END = 0x09, 0x0B, 0x0C, 0x0F
OP_METADATA_INDEX = 0x0D
#: opcodes of the records a summary section holds, and the footer
_SUMMARY_OPS = frozenset({OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_CHUNK_INDEX, 0x0A,
                          OP_STATISTICS, 0x0D, 0x0E})


def starts_as_mcap(path) -> bool:
    """Whether ``path`` is a regular file starting with the MCAP magic (a session, perhaps
    cut or damaged); False for anything unreadable."""
    try:
        if not os.path.isfile(path):
            return False
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


_MESSAGE_HEAD = 22  # channel u16, sequence u32, log_time u64, publish_time u64
_unpack = struct.unpack_from


def check_file(path, header: bool = True) -> tuple[Path, int, bool]:
    """``(path, size, complete)``; LogFormatError if missing or not an MCAP at all, or (with
    ``header``) if its Header record is damaged (:func:`header_damage`).

    ``complete`` means the file ends with the closing magic written by a finished writer.

    A damaged Header record is refused by every reader although pslog uses nothing in it:
    it is damage all the same (a record walk cannot pass a damaged length), and what
    damaged it may have damaged more; ``pslog info`` reports it, ``pslog recover`` skips
    it (docs/log-format.md).
    """
    path = Path(path)
    if not path.exists():
        from ..inputs import not_there

        raise LogFormatError(not_there(path) or f"no such file: {path}")
    if not path.is_file():
        raise LogFormatError(f"not a file: {path}")
    tail = b""
    try:
        size = path.stat().st_size
        with open(path, "rb") as f:
            head = f.read(len(MAGIC))
            if head == MAGIC and size >= 2 * len(MAGIC) + 9:
                f.seek(size - len(MAGIC))
                tail = f.read()
    except OSError as exc:  # e.g. EIO from /proc/self/mem, EACCES: name the file
        raise LogFormatError(f"cannot read {path}: {exc.strerror or exc}") from None
    if head != MAGIC:
        if _magic_damaged(path):
            raise LogFormatError(f"{path}: the MCAP magic (bytes 0..7) is damaged; run "
                                 f"'pslog recover {shell_word(path)}"
                                 f" -o FIXED.mcap' to salvage the data")
        if size == 0:  # ("not an MCAP file" named no problem a user could see)
            raise LogFormatError(f"{path} is empty (0 bytes): not an MCAP session")
        csv = _csv_kind(path)
        if csv == "detections":
            raise LogFormatError(f"{path} is a detections CSV, not an MCAP session ('pslog "
                                 f"import --rig RIG --detections {shell_word(path)} -o "
                                 f"SESSION.mcap' makes one)")
        if csv == "tracks":
            raise LogFormatError(f"{path} is a CSV of fused tracks ('pslog export --csv'), "
                                 f"not an MCAP session")
        raise LogFormatError(f"not an MCAP file: {path}")
    # ``complete``: the closing magic written by a finished writer
    complete = tail == MAGIC
    if header:
        damage, _after = header_records_damage(path)
        if damage is not None:
            raise header_error(path, damage)
    return path, size, complete


def header_error(path, damage: tuple[int, int, str]) -> LogFormatError:
    """The one-line error of a damaged Header record (``damage`` as
    :func:`header_records_damage` gives it)."""
    start, end, reason = damage
    return LogFormatError(f"{path}: its MCAP Header record (bytes {start}..{end}) is damaged "
                          f"({reason}); run 'pslog recover {shell_word(path)}"
                          f" -o FIXED.mcap' to salvage "
                          f"the data")


#: longest Header record examined, bytes (pslog's are tens of bytes: two short strings)
_HEADER_MAX = 1 << 16
#: opcodes a record may have (MCAP 0x01 Header .. 0x10 Summary Offset... 0x0F Data End)
_KNOWN_OPS = frozenset(range(0x01, 0x10))


def header_records_damage(path) -> tuple[tuple[int, int, str] | None,
                                          tuple[int, int, str] | None]:
    """``(header, after)``, each ``(start, end, reason)`` or None, from one read of the
    file's head. ``header``: the Header record after the leading magic is damaged (its
    opcode, its length, its two strings); a file cut inside its header is truncated, not
    damaged: None. ``after``: the record right after an intact Header record (pslog's
    session metadata record) has no record's opcode (a Header whose strings fill it exactly
    is intact even then: that is the next record's damage); ``end`` is where that record's
    own length field says it ends (its opcode alone is damaged) or ``start + 1``."""
    start = len(MAGIC)
    with open(path, "rb") as f:
        # the longest Header examined, one byte past it, and the next record's 9-byte head
        head = f.read(start + 9 + _HEADER_MAX + 9)
        size = os.fstat(f.fileno()).st_size
    if len(head) < start + 9:
        return None, None
    op, length = _unpack("<BQ", head, start)
    end = start + 9 + length
    if op != OP_HEADER:
        return (start, start + 1, f"opcode {op:#04x}, not a Header"), None
    if end + 1 > size:
        if size > start + 9 + _HEADER_MAX:
            return (start, start + 9, f"length {length} runs past the end of the file"), None
        return None, None  # cut inside the header
    if end > start + 9 + _HEADER_MAX:
        return (start, start + 9, f"length {length} is beyond any Header record"), None
    try:  # (within the bytes a Header may take and one more, as before the next record's)
        own = head[:start + 9 + _HEADER_MAX + 1]
        _profile, at = _string(own, start + 9)
        _library, at = _string(own, at)
    except (struct.error, UnicodeDecodeError):
        return (start, end, "its strings are unreadable"), None
    if at != end:
        return (start, end, "its strings do not fill it"), None
    nxt = head[end:end + 9]
    if len(nxt) < 9 or nxt[0] in _KNOWN_OPS:
        return None, None
    (length,) = _unpack("<Q", nxt, 1)
    stop = end + 9 + length
    return None, (end, (stop if stop <= size else end + 1), f"opcode {nxt[0]:#04x} is no "
                                                               f"record's")


def tail_magic_damaged(path) -> bool:
    """Whether a file ends with the closing MCAP magic but for one or two bytes: a finished
    file damaged at its very end, not a recording cut short."""
    path = Path(path)
    size = path.stat().st_size
    if size < 2 * len(MAGIC) + 29:
        return False
    with open(path, "rb") as f:
        f.seek(size - len(MAGIC) - 29)
        tail = f.read()
    return (tail[0] == OP_FOOTER
            and 0 < sum(a != b for a, b in zip(tail[-len(MAGIC):], MAGIC, strict=True)) <= 2)


def truncated_error(path) -> LogFormatError:
    if tail_magic_damaged(path):
        return LogFormatError(f"{path}: its closing MCAP magic (the last 8 bytes) is damaged; "
                              f"run 'pslog recover {shell_word(path)}"
                              f" -o FIXED.mcap' to salvage the data")
    recording = still_recording(path)
    setup = cut_in_setup(path)  # nothing for recover to salvage: say so, not "run recover"
    if recording is not None:
        return LogFormatError(f"{path} is incomplete (truncated): it may still be recording "
                              f"({recording}); if no recorder is writing it, "
                              + ("it is beyond repair (cut within its session set-up)"
                                 if setup else
                                 f"run 'pslog recover {shell_word(path)}"
                                 f" -o FIXED.mcap' to salvage it"))
    if setup:
        return LogFormatError(f"{path} is truncated within its session set-up (its first "
                              f"{Path(path).stat().st_size} bytes, before the session "
                              f"metadata ends): nothing was recorded; the file is beyond "
                              f"repair")
    return LogFormatError(f"{path} is truncated (the recording did not finish); "
                          f"run 'pslog recover {shell_word(path)} -o FIXED.mcap' to salvage it")


def cut_in_setup(path) -> bool:
    """Whether the file ends before the end of its first Metadata record (pslog writes the
    session's metadata right after the Header, before any message): a file cut there holds
    nothing :func:`salvage_file` could make a session of. Reads the first records only."""
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            head = f.read(_HEADER_MAX)
    except OSError:
        return False
    if head[:len(MAGIC)] != MAGIC:
        return False
    at = len(MAGIC)
    for _ in range(4):  # Header, then (pslog's) the Metadata record
        if at + 9 > len(head):
            return at + 9 > size
        op = head[at]
        end = at + 9 + int.from_bytes(head[at + 1:at + 9], "little")
        if op == OP_METADATA:
            return end > size
        if op not in (OP_HEADER, OP_SCHEMA, OP_CHANNEL):
            return False
        at = end
    return False


def still_recording(path) -> str | None:
    """Why an unfinished ``path`` may be a recording in progress (``being written by another
    pslog``, ``modified 3 s ago``, ``named *.partial``), or None: the same rule as ``pslog
    info`` (:func:`pslog.log.info.session_info`)."""
    import time

    from ..outputs import locked_by_another
    from .info import RECENT_S

    path = Path(path)
    if locked_by_another(path):
        return "another pslog is writing it"
    try:
        age = max(time.time() - path.stat().st_mtime, 0.0)
    except OSError:
        return None
    if age < RECENT_S:
        return f"modified {age:.0f} s ago"
    if path.name.endswith(".partial"):
        return "named *.partial"
    return None


def _string(buf, pos: int) -> tuple[str, int]:
    (n,) = _unpack("<I", buf, pos)
    return bytes(buf[pos + 4:pos + 4 + n]).decode("utf-8"), pos + 4 + n


def _string_map(buf, pos: int) -> tuple[dict[str, str], int]:
    (n,) = _unpack("<I", buf, pos)
    end, pos, out = pos + 4 + n, pos + 4, {}
    while pos < end:
        key, pos = _string(buf, pos)
        value, pos = _string(buf, pos)
        out[key] = value
    return out, end


@dataclass
class SchemaRec:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass
class ChannelRec:
    id: int
    schema_id: int
    topic: str
    encoding: str
    metadata: dict[str, str] = field(default_factory=dict)


def parse_schema(buf, pos: int) -> SchemaRec:
    (sid,) = _unpack("<H", buf, pos)
    name, pos = _string(buf, pos + 2)
    encoding, pos = _string(buf, pos)
    (n,) = _unpack("<I", buf, pos)
    return SchemaRec(sid, name, encoding, bytes(buf[pos + 4:pos + 4 + n]))


def parse_channel(buf, pos: int) -> ChannelRec:
    cid, sid = _unpack("<HH", buf, pos)
    topic, pos = _string(buf, pos + 4)
    encoding, pos = _string(buf, pos)
    metadata, _ = _string_map(buf, pos)
    return ChannelRec(cid, sid, topic, encoding, metadata)


def parse_metadata(buf, pos: int) -> tuple[str, dict[str, str]]:
    name, pos = _string(buf, pos)
    data, _ = _string_map(buf, pos)
    return name, data


# ---- validation ---------------------------------------------------------------------------
#: the compressions a chunk may name (mcap.dev/spec: "", "zstd", "lz4")
_COMPRESSIONS = ("", "zstd", "lz4")
#: a chunk claiming more uncompressed bytes than this is damaged, not real (pslog writes
#: chunks of about 1 MB; other writers rarely exceed a few tens of MB)
_MAX_CHUNK_BYTES = 1 << 31

# Field layouts of the records met in a data section (mcap.dev/spec), for a structural check
# that a record's fields exactly fill its length: H u16, I u32, Q u64, s string (u32 length +
# UTF-8), b bytes (u32 length), B bytes (u64 length), m string map (u32 byte length), r message
# index entries (u32 byte length, 16 bytes each).
_SHAPES = {
    OP_HEADER: "ss",
    OP_FOOTER: "QQI",
    OP_SCHEMA: "Hssb",
    OP_CHANNEL: "HHssm",
    OP_MESSAGE_INDEX: "Hr",
    OP_ATTACHMENT: "QQssBI",
    OP_METADATA: "sm",
    OP_DATA_END: "I",
    OP_CHUNK: "QQQIsB",
}
_FIXED = {"H": 2, "I": 4, "Q": 8}


def _fills(buf, pos: int, end: int, shape: str) -> bool:
    """Whether fields of ``shape`` (see ``_SHAPES``) read from ``pos`` end exactly at ``end``."""
    for kind in shape:
        if kind in _FIXED:
            pos += _FIXED[kind]
        elif kind == "B":
            if pos + 8 > end:
                return False
            pos += 8 + _unpack("<Q", buf, pos)[0]
        else:
            if pos + 4 > end:
                return False
            (n,) = _unpack("<I", buf, pos)
            if pos + 4 + n > end:
                return False
            if kind == "s":
                try:
                    bytes(buf[pos + 4:pos + 4 + n]).decode("utf-8")
                except UnicodeDecodeError:
                    return False
            elif kind == "m":
                try:
                    _string_map(buf, pos)
                except (struct.error, UnicodeDecodeError):
                    return False
                # a map whose last entry runs past its length is damaged
                if not _map_fits(buf, pos):
                    return False
            elif kind == "r" and n % 16:
                return False
            pos += 4 + n
        if pos > end:
            return False
    return pos == end


def _map_fits(buf, pos: int) -> bool:
    (n,) = _unpack("<I", buf, pos)
    end, pos = pos + 4 + n, pos + 4
    while pos < end:
        for _ in range(2):
            if pos + 4 > end:
                return False
            pos += 4 + _unpack("<I", buf, pos)[0]
    return pos == end


def record_plausible(buf, pos: int, n: int, messages: bool = True) -> int | None:
    """End offset of the record at ``pos`` if its header and fields are consistent (a record
    that may appear in a data section, lying within ``buf[:n]``), else None. A chunk passes
    on its header alone: :func:`chunk_payload` checks its contents. ``messages``: whether a
    Message record may stand outside chunks (only in unchunked files)."""
    if pos + 9 > n:
        return None
    op, length = _unpack("<BQ", buf, pos)
    end = pos + 9 + length
    if end > n:
        return None
    if op == OP_MESSAGE:
        return end if messages and length >= _MESSAGE_HEAD else None
    shape = _SHAPES.get(op)
    if shape is None:
        return None  # summary-only records, unknown opcodes: not in a data section
    try:
        if not _fills(buf, pos + 9, end, shape):
            return None
        if op == OP_CHUNK:
            (clen,) = _unpack("<I", buf, pos + 9 + 28)
            compression = bytes(buf[pos + 9 + 32:pos + 9 + 32 + clen])
            (size,) = _unpack("<Q", buf, pos + 9 + 16)
            if compression.decode("ascii") not in _COMPRESSIONS or size > _MAX_CHUNK_BYTES:
                return None
    except (struct.error, UnicodeDecodeError):
        return None
    return end


def chunk_header(buf, body: int) -> tuple[int, int]:
    """``(message_start_time, message_end_time)`` as a chunk's header states them."""
    return _unpack("<QQ", buf, body)


def chunk_payload(body: bytes, validate_crc: bool = True, framing: bool = True) -> bytes:
    """Decompressed records of a Chunk record body, checked: header consistent with the body's
    length, decompression, uncompressed size, CRC (when the writer stored one) and the
    framing of the records inside (``framing=False``: the caller checks it, e.g. columnar
    from the message indexes). LogFormatError saying what is wrong otherwise."""
    try:
        _start, _end, size, crc, n = _unpack("<QQQII", body, 0)
        compression = bytes(body[32:32 + n]).decode("ascii")
        pos = 32 + n
        (length,) = _unpack("<Q", body, pos)
    except (struct.error, UnicodeDecodeError):
        raise LogFormatError("chunk header is damaged") from None
    data = body[pos + 8:pos + 8 + length]
    if len(data) != length or pos + 8 + length != len(body):
        raise LogFormatError("chunk lengths are inconsistent")
    if size > _MAX_CHUNK_BYTES:
        raise LogFormatError(f"chunk claims {size} uncompressed bytes")
    try:
        if compression == "zstd":
            import zstandard

            # read at most one byte more than promised: a damaged stream cannot balloon;
            # from the caller's buffer as it is (a memoryview too: no copy of the bytes)
            with zstandard.ZstdDecompressor().stream_reader(data) as reader:
                data = reader.read(size + 1)
        elif compression == "lz4":
            import lz4.frame

            data = lz4.frame.decompress(bytes(data))
        elif compression:
            raise LogFormatError(f"unsupported chunk compression {compression!r}")
    except LogFormatError:
        raise
    except Exception as exc:  # zstd/lz4 errors on damaged data: their types vary by version
        raise LogFormatError(f"chunk does not decompress ({exc})") from None
    if len(data) != size:
        raise LogFormatError(f"chunk decompresses to {len(data)} bytes, header says {size}")
    if validate_crc and crc and zlib.crc32(data) != crc:
        raise LogFormatError("chunk CRC mismatch")
    if framing:
        check_framing(data)
    return data


def check_framing(records: bytes) -> None:
    """LogFormatError unless ``records`` is a whole number of records (a chunk's contents)."""
    pos, n = 0, len(records)
    while pos < n:
        if pos + 9 > n:
            raise LogFormatError("chunk ends inside a record header")
        op, length = _unpack("<BQ", records, pos)
        pos += 9 + length
        if op == OP_MESSAGE and length < _MESSAGE_HEAD:
            raise LogFormatError("chunk holds a message record too short for its header")
    if pos != n:
        raise LogFormatError("chunk ends inside a record")


def damaged_error(path, offset: int, reason: str) -> LogFormatError:
    """The one line every reader gives on a damaged record."""
    return LogFormatError(f"{path}: damaged data at byte {offset} ({reason}); run "
                          f"'pslog recover {shell_word(path)}"
                          f" -o FIXED.mcap' to salvage the intact data")


def walk_records(buf, start: int = 0) -> Iterator[tuple[int, int, int]]:
    """``(opcode, body_start, body_end)`` of every record in ``buf`` from ``start``; stops
    before an incomplete record."""
    pos, n = start, len(buf)
    while pos + 9 <= n:
        op, length = _unpack("<BQ", buf, pos)
        end = pos + 9 + length
        if end > n:
            return
        yield op, pos + 9, end
        pos = end


def message_spans(records, channels) -> list[tuple[int, int, int, int, int]]:
    """``(channel, sequence, log time, start, end)`` of each message in ``records`` whose
    channel is in ``channels``: its data is ``records[start:end]`` (no copy made). Hot loop:
    kept minimal on purpose (the framing was checked by :func:`chunk_payload`)."""
    out = []
    pos, n = 0, len(records)
    while pos < n:
        op, length = _unpack("<BQ", records, pos)
        body = pos + 9
        if op == OP_MESSAGE:
            cid, seq, t = _unpack("<HIQ", records, body)
            if cid in channels:
                out.append((cid, seq, t, body + _MESSAGE_HEAD, body + length))
        pos = body + length
    return out


def collect_messages(records: bytes, out: dict[int, list]) -> None:
    """Append ``(log_time, sequence, data)`` of each message in ``records`` whose channel is a
    key of ``out`` to ``out[channel]``. Hot loop: kept minimal on purpose (the framing was
    checked by :func:`chunk_payload`); :func:`message_spans`' walk, written out here (built
    on it, reading messages was 30 % slower: 260 against 336 ns a message)."""
    pos, n = 0, len(records)
    while pos < n:
        op, length = _unpack("<BQ", records, pos)
        body = pos + 9
        if op == OP_MESSAGE:
            cid, seq, t = _unpack("<HIQ", records, body)
            target = out.get(cid)
            if target is not None:
                target.append((t, seq, records[body + _MESSAGE_HEAD:body + length]))
        pos = body + length


# ---- summary ----------------------------------------------------------------------------------
@dataclass
class ChunkIndexRec:
    start_ns: int
    end_ns: int
    offset: int        # of the chunk record
    length: int        # of the chunk record, opcode and length field included
    message_index_offsets: dict[int, int]


@dataclass
class MetadataIndexRec:
    offset: int  # of the metadata record
    length: int  # of the metadata record, opcode and length field included
    name: str


@dataclass
class Summary:
    """The parts of a summary section recovery and the readers use."""

    start: int  # offset of the summary section (just after DataEnd)
    schemas: dict[int, SchemaRec] = field(default_factory=dict)
    channels: dict[int, ChannelRec] = field(default_factory=dict)
    chunks: list[ChunkIndexRec] = field(default_factory=list)
    channel_counts: dict[int, int] = field(default_factory=dict)
    #: the MetadataIndex records: where each metadata record lies, as the summary (with its
    #: CRC) states it
    metadata: list[MetadataIndexRec] = field(default_factory=list)


def summary_span(buf) -> tuple[int, int]:
    """Byte range of the summary section and footer as the footer states it (for messages)."""
    n = len(buf)
    foot = n - len(MAGIC) - 29
    try:
        (start,) = _unpack("<Q", buf, foot + 9)
    except struct.error:
        return 0, n
    return (start if len(MAGIC) < start <= foot else max(foot, 0)), n


def read_summary(buf) -> Summary | None:
    """The summary section of a finished file, or None when there is none or it is damaged
    (footer inconsistent, CRC mismatch, a record that does not parse)."""
    n = len(buf)
    foot = n - len(MAGIC) - 29
    if foot < len(MAGIC) or bytes(buf[n - len(MAGIC):]) != MAGIC:
        return None
    op, length, start, _offsets, crc = _unpack("<BQQQI", buf, foot)
    if op != OP_FOOTER or length != 20 or not len(MAGIC) < start <= foot:
        return None
    if crc and zlib.crc32(buf[start:foot + 25]) != crc:
        return None
    summary = Summary(start)
    try:
        for sop, body, _end in walk_records(buf[start:foot]):
            if sop == OP_SCHEMA:
                schema = parse_schema(buf, start + body)
                summary.schemas[schema.id] = schema
            elif sop == OP_CHANNEL:
                channel = parse_channel(buf, start + body)
                summary.channels[channel.id] = channel
            elif sop == OP_CHUNK_INDEX:
                summary.chunks.append(_parse_chunk_index(buf, start + body))
            elif sop == OP_METADATA_INDEX:
                offset, length = _unpack("<QQ", buf, start + body)
                name, _ = _string(buf, start + body + 16)
                summary.metadata.append(MetadataIndexRec(offset, length, name))
            elif sop == OP_STATISTICS:
                (nmap,) = _unpack("<I", buf, start + body + 42)
                pos = start + body + 46
                for i in range(nmap // 10):
                    cid, count = _unpack("<HQ", buf, pos + 10 * i)
                    summary.channel_counts[cid] = count
    except (struct.error, UnicodeDecodeError):
        return None
    for c in summary.chunks:
        if not len(MAGIC) <= c.offset < c.offset + c.length <= start:
            return None
    summary.chunks.sort(key=lambda c: c.offset)
    return summary


def metadata_at(buf, index: MetadataIndexRec, limit: int
                ) -> tuple[tuple[str, dict[str, str]] | None, str]:
    """The metadata record a summary's ``index`` points to, checked against it (a metadata
    record has no CRC; the summary that locates it has one).

    Returns ``(record, "")`` when intact; ``(record, what)`` when only the record's opcode or
    length field is damaged (``what`` says which): its contents fill the index's span exactly
    under the index's name, so they are the record's, read exactly; ``(None, what)`` when
    its contents are damaged (or the index points outside the data section, ``limit``).
    ``what`` completes "the record is damaged ...", e.g. ``in its contents``."""
    start, end = index.offset, index.offset + index.length
    if not (len(MAGIC) <= start and start + 9 <= end <= limit):
        return None, "where the file's index locates it (outside the data section)"
    if not _fills(buf, start + 9, end, _SHAPES[OP_METADATA]):
        return None, "in its contents"
    record = parse_metadata(buf, start + 9)
    if record[0] != index.name:
        return None, "in its contents"
    op, length = _unpack("<BQ", buf, start)
    if op != OP_METADATA:
        return record, "in its opcode (its contents are intact)"
    if length != index.length - 9:
        return record, (f"in its length field (it says {length} bytes, the file's index "
                        f"{index.length - 9}; its contents are intact)")
    return record, ""


def _parse_chunk_index(buf, pos: int) -> ChunkIndexRec:
    start_ns, end_ns, offset, length, n = _unpack("<QQQQI", buf, pos)
    pos += 36
    offsets = {}
    for i in range(n // 10):
        cid, where = _unpack("<HQ", buf, pos + 10 * i)
        offsets[cid] = where
    return ChunkIndexRec(start_ns, end_ns, offset, length, offsets)


def message_index_counts(buf, pos: int, n: int) -> tuple[dict[int, int], int]:
    """Messages per channel listed by the MessageIndex records from ``pos`` on (those that
    follow a chunk), and the offset after them."""
    counts: dict[int, int] = {}
    while True:
        end = record_plausible(buf, pos, n)
        if end is None or buf[pos] != OP_MESSAGE_INDEX:
            return counts, pos
        cid, size = _unpack("<HI", buf, pos + 9)
        counts[cid] = counts.get(cid, 0) + size // 16
        pos = end


# ---- walking a data section ----------------------------------------------------------------
@dataclass
class Damage:
    """A part of a data section that could not be read: a damaged chunk, or bytes that are no
    record at all (up to the next record found)."""

    start: int                      # byte offset
    end: int                        # byte offset just past the damaged part
    reason: str
    chunk: bool = False             # a chunk record (its header at least looked right)
    start_ns: int | None = None     # message time range, from the chunk's header or index
    end_ns: int | None = None
    counts: dict[int, int] | None = None  # messages per channel id, when the index says


@dataclass
class Scan:
    """What a sequential walk of a (possibly truncated) MCAP file found."""

    schemas: dict[int, SchemaRec] = field(default_factory=dict)
    channels: dict[int, ChannelRec] = field(default_factory=dict)
    metadata: list[tuple[str, dict[str, str]]] = field(default_factory=list)
    complete_bytes: int = len(MAGIC)  # offset just past the last complete data record
    finished: bool = False            # DataEnd or Footer reached
    stop_reason: str = ""
    damaged: list[Damage] = field(default_factory=list)  # salvage walks only
    #: salvage walks only: records whose header was damaged but whose contents were read
    #: exactly, located by the intact summary (a metadata record's length field)
    repaired: list[Damage] = field(default_factory=list)
    summary: Summary | None = None    # salvage walks only: the intact summary, if any


def scan_file(path, on_message=None, validate_crc: bool = True,
              scan: Scan | None = None, strict: bool = True) -> Scan:
    """Walk a file's data section record by record. ``on_message(channel_id, log_time,
    sequence, data)`` is called for every message (inside chunks or not) of a complete
    record, in file order, once that record (a whole chunk) is parsed; it may look at
    ``scan`` (pass your own) for the schemas and channels seen so far. Its exceptions
    propagate unchanged (never taken for damaged input).

    ``strict``: any damaged record or a data section without its end raises a one-line
    LogFormatError naming the byte offset (what readers want). Otherwise the walk stops
    quietly at the first incomplete or damaged record (``stop_reason`` says why)."""
    path, _size, _complete = check_file(path)
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
        scan = _scan(buf, on_message, validate_crc, scan or Scan())
    if strict and not scan.finished:
        raise damaged_error(path, scan.complete_bytes, scan.stop_reason)
    return scan


def _handler(scan: Scan, pending: list | None):
    """Parse one record into ``scan``; a message goes to ``pending`` (when not None) as
    ``(channel_id, log_time, sequence, data)``, for the caller to hand to its callback once
    the record is parsed: outside the parse's ``try``, so that an exception of the callback
    (a full disk while copying) is never taken for damaged input."""
    def handle(op: int, body: int, end: int, data) -> None:
        if op == OP_SCHEMA:
            schema = parse_schema(data, body)
            scan.schemas[schema.id] = schema
        elif op == OP_CHANNEL:
            channel = parse_channel(data, body)
            scan.channels[channel.id] = channel
        elif op == OP_MESSAGE and pending is not None:
            cid, seq, t = _unpack("<HIQ", data, body)
            pending.append((cid, t, seq, bytes(data[body + _MESSAGE_HEAD:end])))
    return handle


def _deliver(pending: list, on_message) -> None:
    """Hand parsed messages to the caller's callback; its exceptions propagate unchanged."""
    for message in pending:
        on_message(*message)
    pending.clear()


def _scan(buf, on_message, validate_crc: bool, scan: Scan) -> Scan:
    # buf is an mmap: files of many GB are walked without being read into memory at once
    pos, n = len(MAGIC), len(buf)
    pending: list | None = [] if on_message is not None else None
    handle = _handler(scan, pending)
    while True:
        if pos + 9 > n:
            scan.stop_reason = "file ends inside a record header" if pos < n else "file ends"
            break
        op, length = _unpack("<BQ", buf, pos)
        body, end = pos + 9, pos + 9 + length
        if end > n:
            scan.stop_reason = f"file ends inside a record (opcode 0x{op:02x})"
            break
        if op not in (OP_DATA_END, OP_FOOTER) and record_plausible(buf, pos, n) is None:
            if pos == len(MAGIC):
                # a damaged Header record holds nothing we use (profile, library): go on at
                # the next intact record (the session metadata)
                nxt = _resync(buf, pos + 1, n, {}, _has_chunk(buf, n))
                if nxt < n:
                    pos = nxt
                    continue
            scan.stop_reason = "no valid record here"
            break
        damaged = False
        try:
            if op == OP_CHUNK:
                records = chunk_payload(buf[body:end], validate_crc)
                for cop, cbody, cend in walk_records(records):
                    handle(cop, cbody, cend, records)
            elif op == OP_METADATA:
                scan.metadata.append(parse_metadata(buf, body))
            elif op in (OP_DATA_END, OP_FOOTER):
                scan.finished = True
                scan.complete_bytes = pos
                break
            else:
                handle(op, body, end, buf)
        except (LogFormatError, struct.error, UnicodeDecodeError) as exc:
            # the data from here on cannot be trusted: stop, keep what we have (the
            # messages parsed before the damage too)
            scan.stop_reason = str(exc)
            damaged = True
        if pending:
            _deliver(pending, on_message)
        if damaged:
            break
        pos = end
        scan.complete_bytes = pos
    return scan


# ---- salvage --------------------------------------------------------------------------------
# where a resynchronising search may find a record again: a record opcode a data section holds
# between chunks, followed by a length below 2^40 (a damaged region's random bytes rarely
# match; each match is then checked in full)
_RESYNC = re.compile(rb"[\x03\x04\x06\x0c\x0f][\x00-\xff]{5}\x00\x00\x00")
_DEFINITION = re.compile(rb"[\x03\x04][\x00-\xff]{5}\x00\x00\x00")
_MESSAGE_INDEX = re.compile(rb"\x07[\x00-\xff]{5}\x00\x00\x00")
_RESYNC_CHUNK = re.compile(rb"\x06[\x00-\xff]{5}\x00\x00\x00")


def salvage_file(path, on_message=None, scan: Scan | None = None,
                 tolerate_magic: bool = False) -> Scan:
    """Walk a damaged file's data section keeping every intact record: each chunk is checked
    (header, decompression, CRC, framing) and skipped when damaged; after bytes that are no
    record (a damaged length field, a cut) the walk picks up at the next intact record, found
    through the summary's chunk index when the summary is intact, else by a forward search
    for a record whose fields are consistent (and, for a chunk, whose contents check out).

    Every skipped part is in ``scan.damaged``; channels and schemas whose records were lost
    are taken from an intact summary. ``on_message`` is called as in :func:`scan_file`, for
    the messages of intact records only; its exceptions propagate unchanged. Streams
    (mmap): files larger than memory are fine.
    ``tolerate_magic``: accept a file whose leading magic is damaged."""
    path = Path(path)
    try:
        check_file(path, header=False)  # a damaged Header record is skipped like any damage
    except LogFormatError:
        if not (tolerate_magic and path.is_file() and _magic_damaged(path)):
            raise
    scan = scan or Scan()
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
        _salvage(buf, on_message, scan)
    return scan


def _csv_kind(path: Path) -> str | None:
    """``detections`` or ``tracks`` when ``path`` starts as pslog's CSV of that kind (its
    header; a byte-order mark allowed), else None: a reader given one says so."""
    try:
        with open(path, "rb") as f:
            start = f.read(64).removeprefix(b"\xef\xbb\xbf")
    except OSError:
        return None
    from .csvio import DETECTION_COLUMNS, TRACK_COLUMNS

    if start.startswith(",".join(DETECTION_COLUMNS[:4]).encode()):  # (its required columns)
        return "detections"
    if start.startswith(",".join(TRACK_COLUMNS).encode()):
        return "tracks"
    return None


def _magic_damaged(path: Path) -> bool:
    """A file that starts with the MCAP magic but for one or two bytes (a flipped bit)."""
    with open(path, "rb") as f:
        head = f.read(len(MAGIC) + 1)
    return (len(head) == len(MAGIC) + 1 and head[-1] == OP_HEADER
            and sum(a != b for a, b in zip(head, MAGIC, strict=False)) <= 2)


def _salvage(buf, on_message, scan: Scan) -> None:
    n = len(buf)
    summary = scan.summary = read_summary(buf)
    # the data section ends where the summary starts (DataEnd just before it)
    limit = summary.start if summary is not None else n
    indexed = {c.offset: c for c in summary.chunks} if summary is not None else {}
    if summary is not None:
        # channels first met in a damaged chunk are still known
        for sid, schema in summary.schemas.items():
            scan.schemas.setdefault(sid, schema)
        for cid, channel in summary.channels.items():
            scan.channels.setdefault(cid, channel)
    pending: list | None = [] if on_message is not None else None
    handle = _handler(scan, pending)

    def skip(damage: Damage) -> None:
        scan.damaged.append(damage)
        # channels a damaged part defined, searched for at once: the messages of later
        # chunks on them are still to come
        _rescue_definitions(buf, damage.start, damage.end, scan)
    # Message records outside chunks exist only in unchunked files; in a chunked file a
    # "message" met outside a chunk is the uncompressed literal of a damaged chunk's contents
    # (zstd stores JPEG bytes nearly verbatim), which may be cut by a block header
    chunked = bool(indexed) or _has_chunk(buf, limit)
    metadata = {m.offset: m for m in summary.metadata} if summary is not None else {}
    pos = len(MAGIC)
    chunk_end = -1  # the end of the last chunk read whole
    while pos < limit:
        meta_index = metadata.get(pos)
        if meta_index is not None:
            # a metadata record the intact summary locates: read from the index's span when
            # only its header (opcode, length field: no CRC covers them) is damaged
            record, problem = metadata_at(buf, meta_index, limit)
            if record is not None:
                scan.metadata.append(record)
                if problem:
                    scan.repaired.append(Damage(pos, pos + meta_index.length,
                                                f"metadata record {record[0]!r} damaged "
                                                f"{problem}"))
                pos += meta_index.length
                scan.complete_bytes = pos
                continue
        end = record_plausible(buf, pos, limit, messages=not chunked)
        op = buf[pos]
        if end is None:
            index = indexed.get(pos)
            if index is not None:  # the index knows where this chunk ends
                nxt = pos + index.length
                skip(_chunk_damage(buf, pos, nxt, "chunk header damaged",
                                                  indexed, limit))
            elif op == OP_CHUNK and pos + 9 + 40 <= limit:
                # a chunk whose length field reaches past the file: a cut, or a damaged length
                nxt = _resync(buf, pos + 1, limit, indexed, chunked)
                reason = ("file ends inside this chunk" if _cut_at(buf, pos, nxt, limit)
                          else "chunk header damaged")
                skip(_chunk_damage(buf, pos, nxt, reason, indexed, limit))
            else:
                nxt = _resync(buf, pos + 1, limit, indexed, chunked)
                if pos == chunk_end and _index_opcode_only(buf, pos, nxt):
                    # the MessageIndex records of the chunk just read, the first one's
                    # opcode damaged: an index, no message lost with it
                    skip(Damage(pos, nxt, f"the MessageIndex records of the chunk before, "
                                          f"the first one damaged in its opcode "
                                          f"({op:#04x}); that chunk's messages are kept",
                                counts={}))
                else:
                    reason = ("file ends inside a record" if _cut_at(buf, pos, nxt, limit)
                              else "no valid record")
                    skip(Damage(pos, nxt, reason))
            pos = nxt
            continue
        if op in (OP_DATA_END, OP_FOOTER):
            scan.finished = True
            scan.complete_bytes = end
            break
        try:
            if op == OP_CHUNK:
                records = chunk_payload(buf[pos + 9:end])
                for cop, cbody, cend in walk_records(records):
                    handle(cop, cbody, cend, records)
            elif op == OP_METADATA:
                scan.metadata.append(parse_metadata(buf, pos + 9))
            else:
                handle(op, pos + 9, end, buf)
        except (LogFormatError, struct.error, UnicodeDecodeError) as exc:
            if pending:  # a damaged record's messages are not kept, even those before
                pending.clear()  # the damage (the part is reported as skipped)
            if op != OP_CHUNK:
                skip(Damage(pos, end, f"opcode 0x{op:02x}: {exc}"))
                pos = end
                continue
            index = indexed.get(pos)
            if index is not None and index.length != end - pos:
                end = pos + index.length  # the length field itself was damaged
            # a damaged length may still land inside the file: trust it only when a record
            # follows, else search for the next record
            if index is None and end < limit and record_plausible(
                    buf, end, limit, messages=not chunked) is None:
                end = _resync(buf, pos + 1, limit, indexed, chunked)
            skip(_chunk_damage(buf, pos, end, str(exc), indexed, limit))
            pos = end
            continue
        if pending:
            _deliver(pending, on_message)
        if op == OP_CHUNK:
            chunk_end = end
        pos = end
        scan.complete_bytes = pos
    else:
        # walked to the end without DataEnd: a cut file, or the summary's start
        scan.finished = summary is not None
    for damage in scan.damaged:
        if damage.counts is None:
            damage.counts = _trailing_index_counts(buf, damage.start, damage.end, limit)
    if scan.damaged and not scan.finished:
        scan.stop_reason = scan.damaged[-1].reason


def _rescue_definitions(buf, start: int, end: int, scan: Scan) -> None:
    """Schema and Channel records lying verbatim in a damaged part: zstd stores the start of
    a chunk and incompressible bytes as literals, so the channels a damaged chunk defined
    often survive there, and with them the messages of intact chunks on those channels.
    A record must fill its length exactly and carry printable names; known ids are kept."""
    pos = start
    while (match := _DEFINITION.search(buf, pos, end)) is not None:
        where = pos = match.start()
        pos += 1
        if record_plausible(buf, where, end) is None:
            continue
        try:
            if buf[where] == OP_CHANNEL:
                channel = parse_channel(buf, where + 9)
                if (channel.topic.isprintable() and channel.encoding.isprintable()
                        and channel.topic):
                    scan.channels.setdefault(channel.id, channel)
            else:
                schema = parse_schema(buf, where + 9)
                if schema.name.isprintable() and schema.encoding.isprintable() and schema.name:
                    scan.schemas.setdefault(schema.id, schema)
        except (struct.error, UnicodeDecodeError):
            continue


def _cut_at(buf, pos: int, nxt: int, limit: int) -> bool:
    """Whether the unreadable part from ``pos`` is a record cut by the end of the file (its
    length reaches past the end, and nothing intact follows)."""
    if nxt < limit:
        return False
    return pos + 9 > limit or pos + 9 + _unpack("<Q", buf, pos + 1)[0] > limit


def _index_opcode_only(buf, pos: int, end: int) -> bool:
    """Whether ``pos..end`` is MessageIndex records but for the first one's opcode: its
    fields fill its length exactly and intact MessageIndex records follow it to ``end``."""
    if pos + 9 > end:
        return False
    stop = pos + 9 + _unpack("<Q", buf, pos + 1)[0]
    if not (stop <= end and _fills(buf, pos + 9, stop, _SHAPES[OP_MESSAGE_INDEX])):
        return False
    return message_index_counts(buf, stop, end)[1] == end


def _trailing_index_counts(buf, start: int, end: int, limit: int) -> dict[int, int] | None:
    """Messages per channel of the MessageIndex records that end a damaged part exactly at
    ``end`` (those of a chunk whose own length field was damaged), if any."""
    pos = max(start, end - (1 << 16))
    while (match := _MESSAGE_INDEX.search(buf, pos, end)) is not None:
        counts, after = message_index_counts(buf, match.start(), limit)
        if counts and after == end:
            return counts
        pos = match.start() + 1
    return None


def _has_chunk(buf, limit: int) -> bool:
    pos = len(MAGIC)
    while (match := _RESYNC_CHUNK.search(buf, pos, limit)) is not None:
        if record_plausible(buf, match.start(), limit) is not None:
            return True
        pos = match.start() + 1
    return False


def _chunk_damage(buf, pos: int, end: int, reason: str, indexed: dict, limit: int) -> Damage:
    index = indexed.get(pos)
    damage = Damage(pos, end, reason, chunk=True)
    if index is not None:
        damage.start_ns, damage.end_ns = index.start_ns, index.end_ns
        damage.counts = {}
        for cid, where in index.message_index_offsets.items():
            counts, _ = message_index_counts(buf, where, limit)
            damage.counts[cid] = counts.get(cid, 0)
        return damage
    if pos + 9 + 16 <= limit:
        damage.start_ns, damage.end_ns = chunk_header(buf, pos + 9)
    # a chunk's MessageIndex records follow it: they say what it held
    (length,) = _unpack("<Q", buf, pos + 1)
    if pos + 9 + length <= end:
        counts, _after = message_index_counts(buf, pos + 9 + length, limit)
        damage.counts = counts or None
    return damage


def _resync(buf, pos: int, limit: int, indexed: dict, chunked: bool) -> int:
    """Offset of the next intact record at or after ``pos`` (``limit`` if none): the next
    intact chunk of the index, or an intact record found by searching before it."""
    bound = next((o for o in sorted(indexed) if o >= pos and _intact_at(buf, o, limit, chunked)),
                 limit)
    while True:
        match = _RESYNC.search(buf, pos, bound)
        if match is None:
            return bound
        where = match.start()
        if _intact_at(buf, where, limit, chunked):
            return where
        pos = where + 1


def _intact_at(buf, pos: int, limit: int, chunked: bool, depth: int = 0) -> bool:
    """Whether an intact record starts at ``pos``: a chunk whose contents check out, or a
    record whose fields are consistent and that begins a chain of such records leading to an
    intact chunk or the end of the data section (record-like bytes inside a damaged chunk's
    compressed data break such a chain)."""
    end = record_plausible(buf, pos, limit, messages=not chunked)
    if end is None:
        return False
    op = buf[pos]
    if op == OP_CHUNK:
        try:
            chunk_payload(buf[pos + 9:end])
        except LogFormatError:
            return False
    elif op != OP_DATA_END and chunked:
        if end == limit or depth > 64:
            return True
        return _intact_at(buf, end, limit, chunked, depth + 1)
    elif op == OP_DATA_END:
        # four bytes of CRC: too easily matched by chance; a summary record or the footer
        # must follow
        return end == limit or buf[end] in _SUMMARY_OPS
    return True


def session_metadata(records: list[tuple[str, dict[str, str]]], path) -> dict[str, str]:
    """The ``pslog.session`` record; LogFormatError when the file is not a pslog session."""
    for name, data in records:
        if name == S.SESSION_METADATA:
            check_version(data, path)
            return data
    raise LogFormatError(f"not a pslog session (no '{S.SESSION_METADATA}' metadata): {path}")


def check_version(data: dict[str, str], path) -> None:
    version = data.get("format_version", "")
    try:
        major = int(version.split(".")[0])
    except ValueError:
        raise LogFormatError(f"{path}: bad format_version {version!r}") from None
    if data.get("format") != S.FORMAT_NAME:
        raise LogFormatError(f"not a pslog session (format {data.get('format')!r}): {path}")
    if major > S.FORMAT_MAJOR:
        raise LogFormatError(f"{path}: session format {version} is newer than this pslog "
                             f"reads ({S.FORMAT_VERSION}); update pslog")
