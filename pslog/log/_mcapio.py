"""Low-level MCAP access shared by the reader, ``copy_session``, ``session_info`` and
``recover_session``: file checks, a top-level record walk that stops cleanly at the first
incomplete record, chunk decompression, and a fast message walk inside chunks.

The ``mcap`` package parses each record through several Python objects; for ~10^6 small
messages that dominates reading time, so messages inside chunks are sliced out here with
``struct.unpack_from`` (record layout: https://mcap.dev/spec).
"""

from __future__ import annotations

import mmap
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import LogFormatError
from . import _schemas as S

MAGIC = b"\x89MCAP0\r\n"

# opcodes of the MCAP spec
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL = 0x01, 0x02, 0x03, 0x04
OP_MESSAGE, OP_CHUNK = 0x05, 0x06
OP_METADATA, OP_DATA_END = 0x0C, 0x0F

_MESSAGE_HEAD = 22  # channel u16, sequence u32, log_time u64, publish_time u64
_unpack = struct.unpack_from


def check_file(path) -> tuple[Path, int, bool]:
    """``(path, size, complete)``; LogFormatError if missing or not an MCAP at all.

    ``complete`` means the file ends with the closing magic written by a finished writer.
    """
    path = Path(path)
    if not path.exists():
        raise LogFormatError(f"no such file: {path}")
    if not path.is_file():
        raise LogFormatError(f"not a file: {path}")
    size = path.stat().st_size
    with open(path, "rb") as f:
        head = f.read(len(MAGIC))
        if head != MAGIC:
            raise LogFormatError(f"not an MCAP file: {path}")
        complete = False
        if size >= 2 * len(MAGIC) + 9:
            f.seek(size - len(MAGIC))
            complete = f.read() == MAGIC
    return path, size, complete


def truncated_error(path) -> LogFormatError:
    return LogFormatError(f"{path} is truncated (the recording did not finish); "
                          f"run 'pslog recover {path} -o FIXED.mcap' to salvage it")


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


def chunk_payload(body: bytes, validate_crc: bool = False) -> bytes:
    """Decompressed records of a Chunk record body."""
    _start, _end, size, crc, n = _unpack("<QQQII", body, 0)
    compression = body[32:32 + n].decode("ascii")
    pos = 32 + n
    (length,) = _unpack("<Q", body, pos)
    data = body[pos + 8:pos + 8 + length]
    if len(data) != length:
        raise LogFormatError("chunk is cut short")
    if compression == "zstd":
        import zstandard

        data = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    elif compression == "lz4":
        import lz4.frame

        data = lz4.frame.decompress(data)
    elif compression:
        raise LogFormatError(f"unsupported chunk compression {compression!r}")
    if validate_crc and crc and zlib.crc32(data) != crc:
        raise LogFormatError("chunk CRC mismatch")
    return data


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


def collect_messages(records: bytes, out: dict[int, list]) -> None:
    """Append ``(log_time, sequence, data)`` of each message in ``records`` whose channel is a
    key of ``out`` to ``out[channel]``. Hot loop: kept minimal on purpose."""
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


@dataclass
class Scan:
    """What a sequential walk of a (possibly truncated) MCAP file found."""

    schemas: dict[int, SchemaRec] = field(default_factory=dict)
    channels: dict[int, ChannelRec] = field(default_factory=dict)
    metadata: list[tuple[str, dict[str, str]]] = field(default_factory=list)
    complete_bytes: int = len(MAGIC)  # offset just past the last complete data record
    finished: bool = False            # DataEnd or Footer reached
    stop_reason: str = ""


def scan_file(path, on_message=None, validate_crc: bool = True,
              scan: Scan | None = None) -> Scan:
    """Walk a file's data section record by record, stopping at the first incomplete or
    corrupt record. ``on_message(channel_id, log_time, sequence, data)`` is called for every
    message (inside chunks or not) of a complete record, in file order; it may look at
    ``scan`` (pass your own) for the schemas and channels seen so far."""
    path, _size, _complete = check_file(path)
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
        return _scan(buf, on_message, validate_crc, scan or Scan())


def _scan(buf, on_message, validate_crc: bool, scan: Scan) -> Scan:
    # buf is an mmap: files of many GB are walked without being read into memory at once
    pos, n = len(MAGIC), len(buf)

    def handle(op: int, body: int, end: int, data) -> None:
        if op == OP_SCHEMA:
            rec = parse_schema(data, body)
            scan.schemas[rec.id] = rec
        elif op == OP_CHANNEL:
            rec = parse_channel(data, body)
            scan.channels[rec.id] = rec
        elif op == OP_MESSAGE and on_message is not None:
            cid, seq, t = _unpack("<HIQ", data, body)
            on_message(cid, t, seq, bytes(data[body + _MESSAGE_HEAD:end]))

    while True:
        if pos + 9 > n:
            scan.stop_reason = "file ends inside a record header" if pos < n else "file ends"
            break
        op, length = _unpack("<BQ", buf, pos)
        body, end = pos + 9, pos + 9 + length
        if end > n:
            scan.stop_reason = f"file ends inside a record (opcode 0x{op:02x})"
            break
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
        except Exception as exc:
            # any failure to parse a complete record (bad CRC, zstd/lz4 errors, garbage
            # lengths) means the data from here on cannot be trusted: stop, keep what we have
            scan.stop_reason = f"corrupt record at byte {pos}: {exc}"
            break
        pos = end
        scan.complete_bytes = pos
    return scan


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
