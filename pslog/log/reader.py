"""Read a pslog session MCAP: columnar detections, truth, tracks, events, never images
unless asked (:func:`iter_images`).

Speed: the summary's chunk index says which chunks hold which channels, so image chunks are
never read; the chunks read are decompressed into one buffer, each topic's messages located
through the chunks' MessageIndex records (checked against the message records, the framing
checked from them too) and pslog's own messages (detections, truth, tracks) decoded from the
protobuf wire format with numpy, all messages of a topic at once: linear in the session's
length, no Python object per message. Anything irregular (a damaged index, a valid protobuf
encoding pslog does not write) falls back to the record walk and the protobuf classes.

Damage: the summary is checked against its CRC before it is trusted, and every chunk read is
checked (lengths, decompression, CRC, framing); a damaged one is a one-line LogFormatError
naming the file, the byte offset and ``pslog recover`` (which keeps every intact chunk).
"""

from __future__ import annotations

import heapq
import json
import mmap
import struct
import zlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np
from mcap.exceptions import McapError

from ..errors import InputError, LogFormatError, shell_word
from ..records import Detections, Track, Truth
from ..rig import Rig
from . import _mcapio as io
from . import _schemas as S
from . import table as tables


@dataclass(frozen=True)
class Session:
    """A session as read from its MCAP (images not included; see :func:`iter_images`).

    Attributes
    ----------
    path : the file
    rig : cameras and shutter offsets, as recorded
    detections : every frame's detections, sorted by (time, camera)
    truth : ground truth (simulated sessions) or None
    tracks : fused tracks by method name
    timing : ``typeA``, ``sync``, ``typeB`` or ``custom``
    metadata : the whole ``pslog.session`` metadata record (string key/values)
    events : (time_ns, text) notes, in time order
    n_images : number of stored frames (all cameras)
    ball_truth : simulated sessions with false candidates: Detections holding only the ball's
        candidate of each frame (:func:`pslog.simulation.ball_mask`), else None
    rejections : method -> :class:`pslog.fusion.gating.Rejections`, the candidates the
        gating stage rejected for that method's track (fused sessions)
    left_out : method -> {reason: count}, the points each fused track's method made but
        left out as invalid or untrustworthy (``Track.dropped`` as ``pslog fuse`` wrote it:
        in each track channel's metadata, or in an older file's session metadata; empty
        when not recorded)
    fused_with : method -> {option: value}, the ``pslog fuse`` choices that shaped each
        track's points (typeA's ``confirm-gaps``: session 45 on; empty when not recorded)
    """

    path: Path
    rig: Rig
    detections: Detections
    truth: Truth | None
    tracks: dict[str, Track]
    timing: str
    metadata: dict[str, str]
    events: list[tuple[int, str]]
    n_images: int
    ball_truth: Detections | None = None
    rejections: dict = field(default_factory=dict)
    left_out: dict[str, dict[str, int]] = field(default_factory=dict)
    fused_with: dict[str, dict[str, str]] = field(default_factory=dict)


def _reason_counts(value) -> dict[str, int] | None:
    """``{reason: count}`` of a parsed JSON value; None when it is no such mapping."""
    if not isinstance(value, dict):
        return None
    return {str(r): int(n) for r, n in value.items()
            if isinstance(n, (int, float)) and not isinstance(n, bool) and n == n
            and abs(n) < 2 ** 63}


def old_left_out_counts(metadata: Mapping[str, str]) -> dict[str, dict[str, int]]:
    """``{method: {reason: count}}`` as a file fused before the counts went with each track
    holds them: every method's in the session metadata (:data:`._schemas.LEFT_OUT_KEY`);
    empty when absent or unreadable."""
    try:
        value = json.loads(metadata.get(S.LEFT_OUT_KEY, "{}"))
    except ValueError:
        return {}
    if not isinstance(value, dict):
        return {}
    return {str(m): counts for m, reasons in value.items()
            if (counts := _reason_counts(reasons)) is not None}


def left_out_counts(f: _Finished, methods) -> dict[str, dict[str, int]]:
    """``{method: {reason: count}}`` of the tracks of ``methods`` in ``f``: each from its
    track channel's metadata, else (a file fused before) from the session metadata."""
    old = old_left_out_counts(f.meta)
    out: dict[str, dict[str, int]] = {}
    by_topic = {c.topic: c for c in sorted(f.summary.channels.values(), key=lambda c: c.id)
                if S.LEFT_OUT_KEY in c.metadata}
    for method in methods:
        channel = by_topic.get(S.track_topic(method))
        counts = None
        if channel is not None:
            try:
                counts = _reason_counts(json.loads(channel.metadata[S.LEFT_OUT_KEY]))
            except ValueError:
                counts = None
        elif method in old:
            counts = old[method]
        if counts:
            out[method] = counts
    return out


def fused_with_settings(f: _Finished, methods) -> dict[str, dict[str, str]]:
    """``{method: {option: value}}`` of the tracks of ``methods`` in ``f`` whose channel
    metadata records them (:data:`pslog.log._schemas.FUSED_WITH_KEY`); a damaged record is
    left out (it says nothing the points need)."""
    out: dict[str, dict[str, str]] = {}
    for c in f.summary.channels.values():
        if S.FUSED_WITH_KEY not in c.metadata:
            continue
        method = next((m for m in methods if S.track_topic(m) == c.topic), None)
        try:
            value = json.loads(c.metadata[S.FUSED_WITH_KEY])
        except ValueError:
            continue
        if method is not None and isinstance(value, dict):
            out[method] = {str(k): str(v) for k, v in value.items()}
    return out


@dataclass(frozen=True)
class Image:
    """One stored frame: ``data`` is the encoded bytes as stored (``format`` e.g. ``jpeg``)."""

    camera: int
    frame_index: int
    time_ns: int
    format: str
    data: bytes


#: what reading a damaged summary raises: our own checks, the mcap package's errors and the
#: low-level errors its parser lets through on bytes that are no record (short reads, bad
#: lengths, bad UTF-8)
_SUMMARY_PARSE_ERRORS = (LogFormatError, McapError, struct.error, UnicodeDecodeError, EOFError,
                         IndexError, ValueError, KeyError)


class DamagedSummaryError(LogFormatError):
    """The summary section or footer of a finished file is damaged (the data may be whole):
    ``reason`` says where, in pslog's words (never a parser's)."""

    def __init__(self, path, reason: str, todo: str = "it rebuilds the index from the data "
                                                      "and keeps every intact record") -> None:
        super().__init__(f"{path}: {reason}; run 'pslog recover {shell_word(path)}"
                         f" -o FIXED.mcap': {todo}")
        self.reason = reason


class DamagedMetadataError(DamagedSummaryError):
    """The session metadata record (rig, cameras: no CRC covers it) is damaged; ``exact``:
    only its opcode or length field, its contents intact (``pslog recover`` repairs it
    exactly), else its contents (``pslog recover`` rebuilds the rig from the calibrations)."""

    def __init__(self, path, start: int, end: int, problem: str, exact: bool) -> None:
        self.start, self.end, self.exact = start, end, exact
        super().__init__(path, f"its session metadata record (bytes {start}..{end}) is "
                               f"damaged {problem}",
                         "it repairs the record exactly" if exact else
                         "it rebuilds the rig from the cameras' calibration messages")


def _pslog_topic(topic: str, cameras: Sequence[str]) -> bool:
    """Whether ``topic`` is one pslog writes and reads (docs/log-format.md) in a session of
    ``cameras``."""
    camera = S.parse_camera_topic(topic)
    return bool(topic in (S.TRUTH_TOPIC, S.EVENTS_TOPIC)
                or (camera is not None and camera[0] in cameras and topic in (
                    S.detections_topic(camera[0]), S.image_topic(camera[0]),
                    S.calibration_topic(camera[0]), S.transform_topic(camera[0]),
                    S.ball_truth_topic(camera[0])))
                or S.parse_track_topic(topic) or S.parse_rejections_topic(topic))


class _Finished:
    """A finished session file opened for seeking: summary, metadata, rig."""

    def __init__(self, path, header: bool = True) -> None:
        # header=False: a damaged Header record, and a metadata record damaged in its
        # opcode or length field only (its contents intact, read exactly), are let through
        # (pslog info reports them: metadata_damage)
        path, self.size, complete = io.check_file(path, header=False)
        self.path = path
        # the Header record and the record after it, from one read (the latter is reported
        # after the summary's damage, below)
        damage, after = io.header_records_damage(path) if header else (None, None)
        if damage is not None:
            raise io.header_error(path, damage)
        if not complete:
            raise io.truncated_error(path)
        from mcap.reader import SeekingReader

        self.file = open(path, "rb")  # closed by close()
        #: (start, end, what) of a metadata record read exactly despite a damaged header
        self.metadata_damage: list[tuple[int, int, str]] = []
        metadata: list[tuple[str, dict[str, str]]] = []
        start = end = 0
        try:
            # the summary's own CRC first: a damaged index would send reads astray
            with mmap.mmap(self.file.fileno(), 0, access=mmap.ACCESS_READ) as buf:
                checked = io.read_summary(buf)
                start, end = io.summary_span(buf)
                if checked is None:
                    raise DamagedSummaryError(
                        path, f"its summary (the index at the end of the file, bytes "
                              f"{start}..{end}) is damaged")
                # each metadata record where the summary locates it, checked against it
                # (metadata records have no CRC)
                for index in checked.metadata:
                    record, problem = io.metadata_at(buf, index, checked.start)
                    if problem and (record is None or header):
                        raise DamagedMetadataError(path, index.offset,
                                                   index.offset + index.length, problem,
                                                   exact=record is not None)
                    if problem:
                        self.metadata_damage.append(
                            (index.offset, index.offset + index.length,
                             f"metadata record {index.name!r} damaged {problem}; 'pslog "
                             f"recover' repairs it exactly"))
                    if record is not None:
                        metadata.append(record)
            reader = SeekingReader(self.file)
            summary = reader.get_summary()
        except DamagedSummaryError:
            self.file.close()
            raise
        except _SUMMARY_PARSE_ERRORS:
            # what the mcap package raises on bytes it cannot parse (a summary without a
            # CRC); any other exception is a bug, not damage, and propagates as it is
            self.file.close()
            raise DamagedSummaryError(path, f"its summary (the index at the end of the file, "
                                            f"bytes {start}..{end}) does not parse") from None
        if summary is None:
            self.file.close()
            raise LogFormatError(f"{path}: MCAP has no summary section; try 'pslog recover'")
        # the record after the Header with no record's opcode: named as itself (the Header
        # is intact), unless it is a metadata record checked above
        if after is not None and after[0] not in {i.offset for i in checked.metadata}:
            self.file.close()
            raise LogFormatError(f"{path}: its record at bytes {after[0]}..{after[1]} (the one "
                                 f"after the MCAP Header record) is damaged ({after[2]}); run "
                                 f"'pslog recover {shell_word(path)}"
                                 f" -o FIXED.mcap' to salvage the data")
        try:
            self.meta = io.session_metadata(metadata, path)
            self.rig = Rig.from_toml(self.meta.get("rig_toml", ""),
                                     source=f"{path} (session metadata)")
        except Exception:
            self.file.close()
            raise
        self.summary = summary
        self.reader = reader
        self.topics = {c.id: c.topic for c in summary.channels.values()}
        for channel in summary.channels.values():
            if (channel.message_encoding != S.PROTOBUF
                    and _pslog_topic(channel.topic, self.rig.names)):
                # another tool's channel on one of pslog's topics: its messages would be
                # decoded as pslog's (and recover would copy them as they are)
                self.file.close()
                raise LogFormatError(
                    f"{path}: channel {channel.id} on pslog's topic {channel.topic} has "
                    f"message encoding {channel.message_encoding!r}, not {S.PROTOBUF!r}: "
                    f"another tool's channel; "
                    f"remove it or move it to a topic of its own")
        stats = summary.statistics
        #: topic -> messages in the file, summed over every channel of the topic (pslog
        #: writes one channel per topic; another tool may add a second one on it)
        self.counts: dict[str, int] = {}
        for c, n in ({} if stats is None else stats.channel_message_counts).items():
            if c in self.topics:
                self.counts[self.topics[c]] = self.counts.get(self.topics[c], 0) + n
        self.attachments = {a.name: a for a in summary.attachment_indexes}
        #: table name -> why its columnar table was not used (see :meth:`table`)
        self.table_problems: dict[str, str] = {}

    #: whether :meth:`table` reads tables at all (benchmarks time the message path too)
    use_tables = True

    def table(self, name: str):
        """The :class:`~pslog.records.Detections` (or :class:`~pslog.records.Truth`) of
        columnar table ``name`` (:mod:`pslog.log.table`) when the file has it and it agrees
        with the per-message topics it stands for; else None, with the reason in
        :attr:`table_problems` when a table is there but not used."""
        index = self.attachments.get(name)
        if index is None or not self.use_tables:
            return None
        try:
            data = self._attachment_data(index, aligned=True)
            counts, columns = tables.decode(data, name, self.rig.names)
            topics = tables.topics_of(name, self.rig.names)
            expected = {t: self.counts.get(t, 0) for t in topics}
            if counts != expected:
                raise LogFormatError(f"table names {sum(counts.values())} messages of "
                                     f"{', '.join(counts) or 'no topic'}, the file has "
                                     f"{sum(expected.values())}")
            # one row per message: a frame per detection message (per camera), a sample per
            # truth message, a point per track message
            rows = columns["frame_time_ns" if "frame_time_ns" in columns else "time_ns"]
            per_topic = (np.bincount(columns["frame_camera"], minlength=len(topics))
                         if "frame_camera" in columns and len(rows)
                         and 0 <= columns["frame_camera"].min()
                         and columns["frame_camera"].max() < len(topics)
                         else None)
            if len(rows) != sum(counts.values()) or (
                    per_topic is not None
                    and list(per_topic) != [counts.get(t, 0) for t in topics]):
                raise LogFormatError(f"table holds {len(rows)} rows for "
                                     f"{sum(counts.values())} messages")
            if name == tables.TRUTH:
                return Truth(columns["time_ns"], columns["position_world"])
            method = tables.track_method(name)
            if method is not None:
                return tables.track_from_columns(method, columns)
            return Detections(tuple(self.rig.names), **columns)
        except (LogFormatError, InputError, ValueError) as exc:
            self.table_problems[name] = str(exc)
            return None

    def _attachment(self, index) -> bytes:
        """The data of an attachment, its record and CRC checked (MCAP "Attachment")."""
        return cast(bytes, self._attachment_data(index, aligned=False))

    def _attachment_data(self, index, aligned: bool) -> bytes | memoryview:
        """:meth:`_attachment`; ``aligned``: a view of the data in a writable buffer, its
        start 8-byte aligned in memory (a table's raw columns are then arrays on that
        buffer, not copies), read there straight from the file."""
        self.file.seek(index.offset)
        if aligned:
            # where the data starts in the record: after opcode, length, two times, and
            # the name and media type the index names (checked below as in any record)
            start = 25 + 4 + len(index.name.encode()) + 4 + len(index.media_type.encode()) + 8
            # (a bytearray: numpy's own large buffers ask the kernel for huge pages, which
            # cost twice the CPU time to fault in here)
            buffer = bytearray(index.length + 8)
            shift = -(np.frombuffer(buffer, np.uint8, 1).ctypes.data + start) % 8
            view = memoryview(buffer)[shift:shift + index.length]
            record: bytes | memoryview = view[:self.file.readinto(view)]
        else:
            record = self.file.read(index.length)
        if len(record) != index.length or len(record) < 9 + 8 + 8 + 4 + 4 + 8 + 4 or \
                record[0] != io.OP_ATTACHMENT or \
                int.from_bytes(record[1:9], "little") != len(record) - 9:
            raise LogFormatError("attachment record does not match the summary's index")
        try:
            at = 25
            at += 4 + int.from_bytes(record[at:at + 4], "little")  # name
            at += 4 + int.from_bytes(record[at:at + 4], "little")  # media type
            size = int.from_bytes(record[at:at + 8], "little")
            at += 8
        except IndexError:
            raise LogFormatError("attachment record malformed") from None
        if at + size + 4 != len(record):
            raise LogFormatError("attachment record malformed")
        crc = int.from_bytes(record[-4:], "little")
        if crc and zlib.crc32(memoryview(record)[9:-4]) != crc:
            raise LogFormatError("attachment fails its CRC")
        return record[at:at + size]

    def close(self) -> None:
        self.file.close()

    def __enter__(self) -> _Finished:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def read_chunk(self, index, framing: bool = True) -> bytes:
        """The checked, decompressed records of the chunk of a ChunkIndex; a one-line
        LogFormatError naming the byte offset (and ``pslog recover``) if it is damaged.
        ``framing=False``: the records' framing is left for the caller to check."""
        try:
            return self._chunk(index, framing)
        except LogFormatError as exc:
            raise io.damaged_error(self.path, index.chunk_start_offset, str(exc)) from None

    def _chunk(self, index, framing: bool = True) -> bytes:
        self.file.seek(index.chunk_start_offset)
        record = self.file.read(index.chunk_length)
        if len(record) != index.chunk_length or record[0] != io.OP_CHUNK or \
                int.from_bytes(record[1:9], "little") != index.chunk_length - 9:
            raise LogFormatError("chunk record does not match the summary's index")
        return io.chunk_payload(record[9:], framing=framing)

    def check_chunks(self) -> list[dict]:
        """Check every chunk (decompression, CRC, framing): one dict per damaged chunk as
        :func:`pslog.log.recover.describe_damage` makes it (byte range, reason, time range,
        messages per topic from the chunk's message indexes). Reads the whole file, image
        chunks included."""
        from .recover import describe_damage

        damaged = []
        with mmap.mmap(self.file.fileno(), 0, access=mmap.ACCESS_READ) as buf:
            for index in sorted(self.summary.chunk_indexes,
                                key=lambda c: c.chunk_start_offset):
                try:
                    self._chunk(index)
                except LogFormatError as exc:
                    end = index.chunk_start_offset + index.chunk_length
                    counts, _ = io.message_index_counts(
                        buf, end, min(len(buf), end + index.message_index_length))
                    damaged.append(describe_damage(io.Damage(
                        index.chunk_start_offset, end, str(exc), chunk=True,
                        start_ns=index.message_start_time, end_ns=index.message_end_time,
                        counts=counts), self.summary.channels))
        return damaged

    def collect(self, topics: Sequence[str], skip: frozenset[int] = frozenset()
                ) -> dict[str, list[tuple[int, int, bytes]]]:
        """``topic -> [(log_time, sequence, data), ...]`` in file order for ``topics``;
        ``skip``: offsets of chunks not to read (known to be damaged)."""
        wanted: dict[int, list[tuple[int, int, bytes]]] = {
            cid: [] for cid, topic in self.topics.items() if topic in set(topics)}
        if not wanted:
            return {}
        chunks = self.summary.chunk_indexes
        if chunks:
            for index in sorted(chunks, key=lambda c: c.chunk_start_offset):
                if index.message_index_offsets and \
                        not wanted.keys() & index.message_index_offsets.keys():
                    continue  # e.g. an image chunk: never read (a chunk without message
                    # indexes, as another writer may make it, can hold anything: read)
                if index.chunk_start_offset in skip:
                    continue
                io.collect_messages(self.read_chunk(index), wanted)
        else:  # unchunked file written by another program: walk it all
            io.scan_file(self.path, lambda cid, t, seq, data: (
                wanted[cid].append((t, seq, data)) if cid in wanted else None))
        out: dict[str, list[tuple[int, int, bytes]]] = {}
        for cid, msgs in wanted.items():
            topic = self.topics[cid]
            if topic in out:  # a second channel on the topic: both, in log-time order
                out[topic] = sorted(out[topic] + msgs, key=lambda m: m[0])
            else:
                out[topic] = msgs
        return out

    def collect_batches(self, topics: Sequence[str], skip: frozenset[int] = frozenset()
                        ) -> dict[str, _Batch]:
        """As :meth:`collect`, each topic's messages as one :class:`_Batch`: found through
        the chunks' MessageIndex records (each entry checked against the message record it
        points at), without a Python object per message. A chunk whose index does not
        check out is walked record by record; when a topic's message count then differs
        from the summary's statistics, the whole file is read the per-message way."""
        wanted = {cid for cid, topic in self.topics.items() if topic in set(topics)}
        if not wanted:
            return {}
        chunks = self.summary.chunk_indexes
        shared_topic = len({self.topics[cid] for cid in wanted}) < len(wanted)
        if not chunks or not all(c.message_index_offsets for c in chunks) or shared_topic:
            # (two channels on one topic, as no pslog writer makes: merged per message)
            # unchunked, or chunks without message indexes (another writer's): walk them
            return {t: _Batch.from_messages(m) for t, m in self.collect(topics, skip).items()}
        chosen = [c for c in sorted(chunks, key=lambda c: c.chunk_start_offset)
                  if wanted & c.message_index_offsets.keys()
                  and c.chunk_start_offset not in skip]  # e.g. image chunks: never read
        # every chunk read is decompressed into one shared buffer, and each topic's messages
        # are offsets into it: no copy per message, nor per topic
        total = sum(c.uncompressed_size for c in chosen)
        shared = np.zeros(total + _PAD, dtype=np.uint8)
        at = 0
        parts: dict[int, list[_Batch]] = {cid: [] for cid in wanted}
        for index in chosen:
            here = wanted & index.message_index_offsets.keys()
            records = self.read_chunk(index, framing=False)
            size = len(records)
            inside = at + size <= total  # else an index whose size is wrong: a copy of its own
            rec = shared[at:at + size] if inside else np.zeros(size + _PAD, dtype=np.uint8)
            rec[:size] = np.frombuffer(records, dtype=np.uint8)
            del records
            try:
                got = self._indexed(index, rec[:size], here)
            except (_Irregular, struct.error):
                raw = rec[:size].tobytes()
                try:  # the framing the record walk needs, with its usual error
                    io.check_framing(raw)
                except LogFormatError as exc:
                    raise io.damaged_error(self.path, index.chunk_start_offset,
                                           str(exc)) from None
                found: dict[int, list] = {cid: [] for cid in here}
                io.collect_messages(raw, found)
                got = {cid: _Batch.from_messages(m) for cid, m in found.items()}
            else:
                for batch in got.values():
                    batch.buf = shared if inside else rec
                    if inside:
                        batch.start += at
                        batch.end += at
            if inside:
                at += size
            for cid, batch in got.items():
                parts[cid].append(batch)
        out = {self.topics[cid]: _Batch.join(parts[cid], shared) for cid in wanted}
        if not skip and any(len(b) != self.counts.get(t, len(b)) for t, b in out.items()):
            # an index that left messages out: the record walk is the authority
            return {t: _Batch.from_messages(m) for t, m in self.collect(topics, skip).items()}
        return out

    def _indexed(self, index, rec: np.ndarray, channels) -> dict[int, _Batch]:
        """The messages of ``channels`` in a chunk's records ``rec`` (uint8), found through
        its MessageIndex records, as offsets into ``rec``; :class:`_Irregular` when an index
        does not match the records."""
        chunk_end = index.chunk_start_offset + index.chunk_length
        self.file.seek(chunk_end)
        raw = self.file.read(index.message_index_length)
        n = len(rec)
        _check_framing(rec, raw, index.message_index_offsets, chunk_end)
        out = {}
        for cid in channels:
            at = index.message_index_offsets[cid] - chunk_end
            if at < 0 or at + 15 > len(raw):
                raise _Irregular("message index outside its range")
            op, length, channel, size = struct.unpack_from("<BQHI", raw, at)
            if (op != io.OP_MESSAGE_INDEX or channel != cid or size % 16 or length != 6 + size
                    or at + 15 + size > len(raw)):
                raise _Irregular("message index record does not check out")
            entries = np.frombuffer(raw, dtype="<u8", count=size // 8,
                                    offset=at + 15).reshape(-1, 2)
            order = np.argsort(entries[:, 1], kind="stable")  # file order
            times, offsets = entries[order, 0], entries[order, 1]
            if len(offsets) and (offsets[-1] > n - 31 or np.any(np.diff(offsets) == 0)):
                raise _Irregular("message index offsets out of range")
            offsets = offsets.astype(np.int64)
            end = offsets + 9 + _load(rec, offsets + 1, 8).astype(np.int64)
            if (np.any(rec[offsets] != io.OP_MESSAGE) or np.any(end < offsets + 31)
                    or np.any(end > n) or np.any(_load(rec, offsets + 9, 2) != cid)
                    or np.any(_load(rec, offsets + 15, 8) != times)):
                raise _Irregular("message index entry does not match its record")
            out[cid] = _Batch(rec, offsets + 31, end, times.view(np.int64),
                              _load(rec, offsets + 11, 4).view(np.int64))
        return out


def read_session(path) -> Session:
    """Read a session MCAP without decoding images.

    Raises LogFormatError for a missing file, a non-MCAP, an MCAP that is not a pslog session,
    a truncated file and a damaged chunk among those read (naming its byte offset and
    pointing to ``pslog recover``).
    """
    with _Finished(path) as f:
        return _read(f)


def _read(f: _Finished, skip: frozenset[int] = frozenset()) -> Session:
    """The session of an open file; ``skip``: offsets of damaged chunks to leave out."""
    from google.protobuf.message import DecodeError

    rig = f.rig
    det_topics = [S.detections_topic(n) for n in rig.names]
    track_topics = sorted(t for t in f.topics.values() if S.parse_track_topic(t))
    ball_topics = [S.ball_truth_topic(n) for n in rig.names]
    rejection_topics = sorted(t for t in f.topics.values() if S.parse_rejections_topic(t))
    # the columnar tables, when there and consistent (a file read around damaged chunks
    # is read from what its messages still hold, as before)
    table_det = None if skip else f.table(tables.DETECTIONS)
    table_truth = (None if skip or S.TRUTH_TOPIC not in f.topics.values()
                   else f.table(tables.TRUTH))
    table_ball = (None if skip or not any(t in f.topics.values() for t in ball_topics)
                  else f.table(tables.BALL_TRUTH))
    table_tracks = {} if skip else {
        t: f.table(tables.track_table(cast(str, S.parse_track_topic(t)))) for t in track_topics}
    table_tracks = {t: v for t, v in table_tracks.items() if v is not None}
    wanted = [*([] if table_det is not None else det_topics),
              *([] if table_truth is not None else [S.TRUTH_TOPIC]), S.EVENTS_TOPIC,
              *(t for t in track_topics if t not in table_tracks),
              *([] if table_ball is not None else ball_topics),
              *rejection_topics]
    found = f.collect_batches(wanted, skip)
    none = _Batch.concatenate([])
    try:
        detections = (table_det if table_det is not None else
                      decode_detections(rig.names, [found.get(t, none) for t in det_topics]))
        truth = (table_truth if table_truth is not None else
                 decode_truth(found[S.TRUTH_TOPIC]) if S.TRUTH_TOPIC in found else None)
        tracks = {}
        for topic in track_topics:
            method = cast(str, S.parse_track_topic(topic))  # (a track topic)
            tracks[method] = (table_tracks[topic] if topic in table_tracks else
                              decode_track(method, rig.names, found.get(topic, none)))
        events = decode_events(found.get(S.EVENTS_TOPIC, none).messages())
        ball_truth = (table_ball if table_ball is not None else
                      decode_detections(rig.names, [found.get(t, none) for t in ball_topics])
                      if any(t in found for t in ball_topics) else None)
        try:
            rejections = {S.parse_rejections_topic(t): decode_rejections(
                rig.names, found.get(t, none).messages())
                          for t in rejection_topics}
        except LogFormatError as exc:
            raise LogFormatError(f"{f.path}: {exc}") from None
    except DecodeError as exc:
        # only a chunk written without CRCs can get here with damaged bytes
        raise LogFormatError(f"{f.path}: a message does not decode ({exc}); run 'pslog "
                             f"recover {f.path} -o FIXED.mcap' to salvage the rest") from None
    n_images = sum(f.counts.get(S.image_topic(n), 0) for n in rig.names)
    return Session(path=f.path, rig=rig, detections=detections, truth=truth, tracks=tracks,
                   timing=f.meta.get("timing", "custom"), metadata=dict(f.meta),
                   events=events, n_images=n_images, ball_truth=ball_truth,
                   rejections=rejections, left_out=left_out_counts(f, tracks),
                   fused_with=fused_with_settings(f, tracks))


def decode_detections(camera_names: Sequence[str], per_camera: Sequence) -> Detections:
    """Detections from each camera's DetectionFrame messages (a :class:`_Batch`, or a list of
    ``(log_time, sequence, data)``): decoded columnar, else (anything irregular) one by one."""
    batches = [m if isinstance(m, _Batch) else _Batch.from_messages(m) for m in per_camera]
    try:
        return _detections_columnar(camera_names, batches)
    except _Irregular:
        return _decode_detections_messages(camera_names, [b.messages() for b in batches])


def _detections_columnar(camera_names: Sequence[str], batches: Sequence[_Batch]) -> Detections:
    times, cams, frames, count_parts, columns = [], [], [], [], []
    for cam, batch in enumerate(batches):
        fields, _ = _decode_fields(batch, {1: "varint", 2: "bytes", 3: "varint", 4: "packed",
                                           5: "packed", 6: "packed", 7: "packed"})
        times.append(batch.time)
        cams.append(np.full(len(batch), cam, dtype=np.int32))
        frames.append(fields[3][1].view(np.int64))
        values = [_packed(batch.buf, fields[f][1]) for f in (4, 5, 6, 7)]
        k = values[0][1]
        if any(np.any(c != k) for _v, c in values[1:]):
            raise _Irregular("candidate arrays of unequal length")
        count_parts.append(k)
        columns.append([v for v, _c in values])
    counts = np.concatenate(count_parts) if count_parts else np.zeros(0, np.int64)
    u, v, radius, score = ((np.concatenate([c[j] for c in columns]) if columns else np.zeros(0))
                           for j in range(4))
    n_cand = len(u)
    return Detections.from_frames(
        tuple(camera_names), np.concatenate(times) if times else np.zeros(0, np.int64),
        np.concatenate(cams) if cams else np.zeros(0, np.int32),
        np.concatenate(frames) if frames else np.zeros(0, np.int64),
        np.repeat(np.arange(len(counts)), counts),
        np.column_stack([u, v]) if n_cand else np.zeros((0, 2)),
        radius.astype(np.float64), score.astype(np.float64))


def _decode_detections_messages(camera_names: Sequence[str],
                                per_camera: Sequence[list[tuple[int, int, bytes]]]
                                ) -> Detections:
    """Detections decoded one message at a time (the columnar decoder's fallback)."""
    parse = S.DetectionFrame.FromString
    times, cams, frames, count_list = [], [], [], []
    u, v, radius, score = [], [], [], []
    for cam, msgs in enumerate(per_camera):
        cams.append(np.full(len(msgs), cam, dtype=np.int32))
        for t, _seq, data in msgs:
            m = parse(data)
            times.append(t)
            frames.append(m.frame_index)
            k = len(m.u)
            count_list.append(k)
            if k:
                u.extend(m.u)
                v.extend(m.v)
                radius.extend(m.radius)
                score.extend(m.score)
    counts = np.asarray(count_list, dtype=np.int64)
    n_cand = int(counts.sum())
    if not (len(u) == len(v) == len(radius) == len(score) == n_cand):
        raise LogFormatError("detection message with candidate arrays of unequal length")
    return Detections.from_frames(
        tuple(camera_names), np.asarray(times, dtype=np.int64),
        np.concatenate(cams) if cams else np.zeros(0, np.int32),
        np.asarray(frames, dtype=np.int64), np.repeat(np.arange(len(counts)), counts),
        np.column_stack([u, v]) if n_cand else np.zeros((0, 2)),
        np.asarray(radius, dtype=np.float64), np.asarray(score, dtype=np.float64))


def decode_truth(msgs) -> Truth:
    """Truth from its TruthPoint messages (a :class:`_Batch` or ``(log_time, sequence,
    data)`` list), sorted by time."""
    batch = msgs if isinstance(msgs, _Batch) else _Batch.from_messages(msgs)
    try:
        fields, _ = _decode_fields(batch, {1: "varint", 2: "double", 3: "double",
                                           4: "double"})
    except _Irregular:
        return _decode_truth_messages(batch.messages())
    times = batch.time
    order = np.argsort(times, kind="stable")
    xyz = np.column_stack([fields[f][1] for f in (2, 3, 4)]).reshape(-1, 3)
    return Truth(times[order], xyz[order])


def _decode_truth_messages(msgs: list[tuple[int, int, bytes]]) -> Truth:
    parse = S.TruthPoint.FromString
    time_list, xyz = [], []
    for t, _seq, data in msgs:
        m = parse(data)
        time_list.append(t)
        xyz.append((m.x, m.y, m.z))
    times = np.asarray(time_list, dtype=np.int64)
    order = np.argsort(times, kind="stable")
    return Truth(times[order], np.asarray(xyz, dtype=np.float64).reshape(-1, 3)[order])


def decode_track(method: str, camera_names: Sequence[str], msgs) -> Track:
    """A Track from its TrackPoint messages (a :class:`_Batch` or ``(log_time, sequence,
    data)`` list). Fixed quality fields that are NaN at every point are left out (the writer
    stores NaN for fields a track does not have)."""
    batch = msgs if isinstance(msgs, _Batch) else _Batch.from_messages(msgs)
    try:
        return _track_columnar(method, camera_names, batch)
    except _Irregular:
        return _decode_track_messages(method, camera_names, batch.messages())


#: points whose quality maps are read at a time (rows of a few hundred bytes each)
_MAP_BLOCK = 1 << 15


def _track_columnar(method: str, camera_names: Sequence[str], batch: _Batch) -> Track:
    n = len(batch)
    if n == 0:
        raise _Irregular("empty")  # the per-message path makes the empty track
    buf = batch.buf
    fields, maps = _decode_fields(batch, {1: "varint", 2: "bytes", 3: "double", 4: "double",
                                          5: "double", 6: "bytes", 7: "double", 8: "double",
                                          9: "double"}, stop=10)
    cams = _strings(buf, fields[6][1], camera_names)
    if np.any(cams < 0):
        raise _Irregular("unknown camera")  # the per-message path names it
    # the quality map: every point of a pslog track has the same keys, which protobuf writes
    # in the same order; the first point's entries are the template the others must match
    # byte for byte but for the values (entry: 0x52 len 0x0a klen key 0x11 double)
    first = buf[maps[0]:batch.end[0]].tobytes()
    template, at = [], 0
    while at < len(first):
        if at + 4 > len(first):
            raise _Irregular("map entry")
        length, klen = first[at + 1], first[at + 3]
        if (first[at] != 0x52 or length >= 0x80 or first[at + 2] != 0x0A or klen >= 0x80
                or length != klen + 11 or at + 2 + length > len(first)
                or first[at + 4 + klen] != 0x11):
            raise _Irregular("map entry not in the usual form")
        template.append((at, first[at:at + 5 + klen], first[at + 4:at + 4 + klen]))
        at += 2 + length
    keys = [k for _a, _h, k in template]
    if len(set(keys)) != len(keys) or np.any(batch.end - maps != len(first)):
        raise _Irregular("maps differ in form")
    # every point's map read as one row of bytes (a pass over the track's memory, not one
    # per key), in blocks to bound the memory it takes
    width = len(first)
    slots = {key.decode("utf-8"): at + len(head) for at, head, key in template}
    values = {k: np.empty(n) for k in slots}
    if width:
        fixed = np.ones(width, dtype=bool)  # the bytes every point shares: all but values
        for at in slots.values():
            fixed[at:at + 8] = False
        expected = np.frombuffer(first, dtype=np.uint8)[fixed]
        rows = _windows(buf, width)
        for lo in range(0, n, _MAP_BLOCK):
            block = rows[maps[lo:lo + _MAP_BLOCK]]
            if not np.all(block[:, fixed] == expected):
                raise _Irregular("maps differ in keys")
            for key, at in slots.items():
                values[key][lo:lo + _MAP_BLOCK] = block[:, at:at + 8].copy().view("<f8")[:, 0]
    # key order as the per-message path gives it: protobuf's own order of the first point's
    # map (all points have the same keys)
    first_keys = list(S.TrackPoint.FromString(buf[batch.start[0]:batch.end[0]].tobytes())
                      .quality)
    if sorted(first_keys) != sorted(values):
        raise _Irregular("map keys")
    times = batch.time
    xyz = np.column_stack([fields[f][1] for f in (3, 4, 5)])
    quality = {k: fields[f][1] for f, k in zip((7, 8, 9), S.TRACK_FIXED_QUALITY, strict=True)}
    quality = {k: v for k, v in quality.items() if not np.all(np.isnan(v))}
    quality.update({k: values[k] for k in first_keys})
    order = np.argsort(times, kind="stable")
    return Track(method, times[order], xyz[order], cams[order].astype(np.int32),
                 {k: v[order] for k, v in quality.items()})


def _decode_track_messages(method: str, camera_names: Sequence[str],
                           msgs: list[tuple[int, int, bytes]]) -> Track:
    """A Track decoded one message at a time (the columnar decoder's fallback)."""
    parse = S.TrackPoint.FromString
    index = {name: i for i, name in enumerate(camera_names)}
    n = len(msgs)
    times = np.empty(n, dtype=np.int64)
    xyz = np.empty((n, 3))
    cams = np.empty(n, dtype=np.int32)
    fixed = {k: np.empty(n) for k in S.TRACK_FIXED_QUALITY}
    # map quality: (point, value) lists per key, made arrays once at the end (an array per
    # key allocated at each point made reading quadratic in the track's length)
    extra_rows: dict[str, tuple[list[int], list[float]]] = {}
    rows = []
    for i, (t, _seq, data) in enumerate(msgs):
        m = parse(data)
        times[i] = t
        rows.append((m.x, m.y, m.z, m.ray_miss_m, m.snap_px, m.ray_shift_m))
        try:
            cams[i] = index[m.camera]
        except KeyError:
            raise LogFormatError(f"track {method!r}: unknown camera {m.camera!r}") from None
        if m.quality:
            for key, value in m.quality.items():
                at = extra_rows.get(key)
                if at is None:
                    at = extra_rows[key] = ([], [])
                at[0].append(i)
                at[1].append(value)
    extra: dict[str, np.ndarray] = {}
    for key, (points, values) in extra_rows.items():
        column = extra[key] = np.full(n, np.nan)
        column[np.asarray(points, dtype=np.int64)] = values
    if n:
        table = np.asarray(rows, dtype=np.float64)
        xyz = table[:, :3]
        for j, key in enumerate(S.TRACK_FIXED_QUALITY):
            fixed[key] = table[:, 3 + j]
    quality = {k: v for k, v in fixed.items() if n and not np.all(np.isnan(v))}
    quality.update(extra)
    order = np.argsort(times, kind="stable")
    return Track(method, times[order], xyz[order], cams[order],
                 {k: v[order] for k, v in quality.items()})


def decode_rejections(camera_names: Sequence[str], msgs: list[tuple[int, int, bytes]]):
    """:class:`pslog.fusion.gating.Rejections` from ``pslog.Rejection`` messages."""
    from ..fusion.gating import Rejections

    parse = S.Rejection.FromString
    index = {name: i for i, name in enumerate(camera_names)}
    rows = []
    for t, _seq, data in msgs:
        m = parse(data)
        if m.camera not in index:
            raise LogFormatError(f"rejection of unknown camera {m.camera!r}")
        rows.append((t, index[m.camera], m.frame_index, m.u, m.v, m.score, m.reason))
    rows.sort(key=lambda r: (r[0], r[1]))
    try:
        return Rejections.from_rows(rows)
    except ValueError as exc:
        raise LogFormatError(f"a rejection record does not decode: {exc}") from None


def decode_events(msgs: list[tuple[int, int, bytes]]) -> list[tuple[int, str]]:
    parse = S.Log.FromString
    events = [(t, parse(data).message) for t, _seq, data in msgs]
    return sorted(events, key=lambda e: e[0])


def iter_images(path, cameras: Sequence[int] | None = None, start_ns: int | None = None,
                end_ns: int | None = None) -> Iterator[Image]:
    """Stored frames in time order, optionally of some cameras (indices) and within
    ``[start_ns, end_ns)``; only chunks holding the requested images are read."""
    with _Finished(path) as f:
        names = f.rig.names
        chosen = range(len(names)) if cameras is None else [int(c) for c in cameras]
        for c in chosen:
            if not 0 <= c < len(names):
                raise LogFormatError(f"camera index {c} out of range (rig has {len(names)})")
        camera_of = {S.image_topic(names[c]): c for c in chosen}
        topics = [t for t in camera_of if t in f.counts]
        if not topics:
            return
        yield from _images(f, camera_of, topics, start_ns, end_ns)


def _images(f: _Finished, camera_of: dict[str, int], topics: list[str],
            start_ns: int | None, end_ns: int | None) -> Iterator[Image]:
    """Images of ``topics`` in log-time order, reading one chunk at a time (each checked):
    chunks in order of their first message time; a message is yielded once no chunk still to
    be read can hold an earlier one."""
    lo = -1 if start_ns is None else start_ns
    hi = float("inf") if end_ns is None else end_ns
    camera = {cid: camera_of[t] for cid, t in f.topics.items() if t in topics}
    if not f.summary.chunk_indexes:  # an unchunked file written by another program
        found = f.collect(topics)
        merged = sorted((t, seq, camera_of[topic], data) for topic, msgs in found.items()
                        for t, seq, data in msgs)
        for t, seq, cam, data in merged:
            if (start_ns is None or t >= start_ns) and (end_ns is None or t < end_ns):
                m = parse_image(data, f.path)
                yield Image(cam, seq, t, m.format, m.data)
        return
    chunks = sorted((c for c in f.summary.chunk_indexes
                     if (camera.keys() & c.message_index_offsets.keys()
                         or not c.message_index_offsets)  # (no index: may hold images)
                     and c.message_end_time >= lo and c.message_start_time < hi),
                    key=lambda c: (c.message_start_time, c.chunk_start_offset))
    pending: list[tuple[int, int, int, int, bytes]] = []  # time, order, camera, seq, data
    order = 0
    for i in range(len(chunks) + 1):
        horizon = chunks[i].message_start_time if i < len(chunks) else float("inf")
        while pending and pending[0][0] < horizon:
            t, _order, cam, seq, data = heapq.heappop(pending)
            m = parse_image(data, f.path)
            yield Image(cam, seq, t, m.format, m.data)
        if i == len(chunks):
            break
        by_channel: dict[int, list] = {cid: [] for cid in camera}
        io.collect_messages(f.read_chunk(chunks[i]), by_channel)
        for cid, msgs in by_channel.items():
            for t, seq, data in msgs:
                if lo <= t < hi:
                    heapq.heappush(pending, (t, order, camera[cid], seq, data))
                    order += 1


def parse_image(data: bytes | memoryview, path) -> S.CompressedImage:
    from google.protobuf.message import DecodeError

    try:
        return S.CompressedImage.FromString(data)
    except DecodeError as exc:  # only a chunk written without CRCs can get here damaged
        raise LogFormatError(f"{path}: an image does not decode ({exc}); run 'pslog recover "
                             f"{path} -o FIXED.mcap' to salvage the rest") from None


def image_data(records, start: int, end: int, path) -> bytes | memoryview:
    """The ``data`` (the encoded frame) of the ``foxglove.CompressedImage`` message
    ``records[start:end]``: a view of its bytes in ``records`` (no copy: ``pslog redetect``
    reads a 250 kB frame at about 0.1 ms less than :func:`parse_image`'s copy) where the
    message holds exactly what pslog writes -- fields 1 (a timestamp of varints 1 and 2), 4
    and 3 (UTF-8 strings) and 2 (bytes), each of its own wire type -- else
    :func:`parse_image`'s (the same bytes, the same errors)."""
    buf = memoryview(records)
    span = _image_span(buf, start, end)
    if span is None:
        return parse_image(buf[start:end], path).data
    return buf[span[0]:span[1]]


def _one_varint(buf: memoryview, at: int, end: int) -> tuple[int, int]:
    """(value, position after it) of the varint at ``buf[at]``; (-1, 0) if it does not end
    before ``end`` within 10 bytes."""
    value = shift = 0
    for pos in range(at, min(at + 10, end)):
        byte = buf[pos]
        value |= (byte & 127) << shift
        if byte < 128:
            return value, pos + 1
        shift += 7
    return -1, 0


def _image_span(buf: memoryview, at: int, end: int) -> tuple[int, int] | None:
    """(start, end) of the last ``data`` field of the CompressedImage ``buf[at:end]``, or
    None where the message holds anything else than :func:`image_data` says (a field of
    another number or wire type, a varint or length beyond it, a timestamp with other
    fields, a string that is not UTF-8): protobuf's parser then decides."""
    span = None
    while at < end:
        tag, at = _one_varint(buf, at, end)
        if tag < 0 or tag & 7 != 2:
            return None
        length, at = _one_varint(buf, at, end)
        if length < 0 or at + length > end:
            return None
        field = tag >> 3
        if field == 2:
            span = (at, at + length)
        elif field == 1:  # google.protobuf.Timestamp: seconds (1), nanos (2), varints
            pos = at
            while pos < at + length:
                key, pos = _one_varint(buf, pos, at + length)
                if key not in (8, 16):
                    return None
                _value, pos = _one_varint(buf, pos, at + length)
                if pos == 0:
                    return None
        elif field in (3, 4):
            try:
                bytes(buf[at:at + length]).decode("utf-8")
            except UnicodeDecodeError:
                return None
        else:
            return None
        at += length
    return span


# ---- columnar fast path ---------------------------------------------------------------------
# A match holds millions of small messages; decoding them one protobuf object at a time costs
# microseconds each. Here the messages of a topic are gathered into one byte array (their
# offsets from the chunks' MessageIndex records, checked against the records themselves) and
# the protobuf wire format of pslog's own messages is decoded with numpy, all messages of a
# topic at once. Anything irregular (a field of another wire type, a damaged index, keys of a
# track's quality map in another order than its first point's) falls back to the per-message
# path, which gives the same result (and the same errors) as before.

class _Irregular(Exception):
    """The columnar decoder meets something it does not handle: use the per-message path."""


#: bytes after the last message of a batch, so that fixed-width loads never read past it
_PAD = 16


@dataclass
class _Batch:
    """Messages of one topic as columns: ``buf`` holds their data back to back (plus
    :data:`_PAD` zero bytes), message ``i`` is ``buf[start[i]:end[i]]``, logged at
    ``time[i]`` with sequence ``seq[i]``; in file order."""

    buf: np.ndarray    # uint8
    start: np.ndarray  # int64
    end: np.ndarray    # int64
    time: np.ndarray   # int64
    seq: np.ndarray    # int64

    def __len__(self) -> int:
        return len(self.start)

    @classmethod
    def from_messages(cls, msgs: Sequence[tuple[int, int, bytes]]) -> _Batch:
        lengths = np.fromiter((len(d) for _t, _s, d in msgs), dtype=np.int64, count=len(msgs))
        end = np.cumsum(lengths)
        buf = np.frombuffer(b"".join(d for _t, _s, d in msgs) + bytes(_PAD), dtype=np.uint8)
        return cls(buf, end - lengths, end,
                   np.fromiter((t for t, _s, _d in msgs), dtype=np.int64, count=len(msgs)),
                   np.fromiter((s for _t, s, _d in msgs), dtype=np.int64, count=len(msgs)))

    @classmethod
    def concatenate(cls, parts: Sequence[_Batch]) -> _Batch:
        """One batch of ``parts`` (whose buffers need no padding) in order."""
        if not parts:
            return cls(np.zeros(_PAD, np.uint8), *(np.zeros(0, np.int64) for _ in range(4)))
        shifts = np.cumsum([0] + [len(p.buf) for p in parts[:-1]])
        return cls(np.concatenate([*(p.buf for p in parts), np.zeros(_PAD, np.uint8)]),
                   np.concatenate([p.start + s for p, s in zip(parts, shifts, strict=True)]),
                   np.concatenate([p.end + s for p, s in zip(parts, shifts, strict=True)]),
                   np.concatenate([p.time for p in parts]),
                   np.concatenate([p.seq for p in parts]))

    @classmethod
    def join(cls, parts: Sequence[_Batch], shared: np.ndarray) -> _Batch:
        """One batch of ``parts``: offsets into ``shared`` when they all are, else (a chunk
        walked record by record) a compact copy of each."""
        if parts and all(p.buf is shared for p in parts):
            return cls(shared, *(np.concatenate([getattr(p, k) for p in parts])
                                 for k in ("start", "end", "time", "seq")))
        compact = []
        for p in parts:
            buf, begin = _gather(p.buf, p.start, p.end)
            compact.append(cls(buf, begin, begin + (p.end - p.start), p.time, p.seq))
        return cls.concatenate(compact)

    def messages(self) -> list[tuple[int, int, bytes]]:
        """The per-message form ``[(log_time, sequence, data), ...]``."""
        # not a copy of a shared buffer: each message's bytes (ignore: numpy's stubs give
        # ndarray the buffer protocol on Python >= 3.12 only)
        raw = memoryview(self.buf)  # type: ignore[arg-type]
        return [(t, s, bytes(raw[a:b])) for t, s, a, b in zip(
            self.time.tolist(), self.seq.tolist(), self.start.tolist(), self.end.tolist(),
            strict=True)]


def _gather(records: np.ndarray, start: np.ndarray, end: np.ndarray) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """The byte ranges ``records[start[i]:end[i]]`` (sorted, disjoint) back to back (no
    padding: see :meth:`_Batch.concatenate`), and where each begins in it."""
    lengths = end - start
    begin = np.cumsum(lengths) - lengths
    if len(start) * 256 < len(records):  # a few large ranges (images): slices, no mask
        return np.concatenate([records[a:b] for a, b in zip(start.tolist(), end.tolist(),
                                                            strict=True)]
                              or [records[:0]]), begin
    # a byte mask of the ranges (+1 where one starts, -1 where it ends, summed up): one pass
    # over the chunk instead of an index per byte
    edge = (np.bincount(start, minlength=len(records) + 1)
            - np.bincount(end, minlength=len(records) + 1))
    mask = np.cumsum(edge[:-1]) > 0
    return records[mask], begin


def _check_framing(rec: np.ndarray, raw: bytes, offsets: dict[int, int], chunk_end: int
                   ) -> None:
    """The framing check of :func:`pslog.log._mcapio.check_framing`, columnar: the message
    records every MessageIndex of the chunk lists must follow one another exactly, and what
    lies between them (schemas, channels: a few records) is walked as usual.
    :class:`_Irregular` when anything does not add up (the caller then walks the whole chunk,
    which raises the usual error if the framing is wrong)."""
    n = len(rec)
    start_parts = []
    for at in offsets.values():
        at -= chunk_end
        if at < 0 or at + 15 > len(raw):
            raise _Irregular("message index outside its range")
        op, length, _channel, size = struct.unpack_from("<BQHI", raw, at)
        if op != io.OP_MESSAGE_INDEX or size % 16 or length != 6 + size or \
                at + 15 + size > len(raw):
            raise _Irregular("message index record does not check out")
        start_parts.append(np.frombuffer(raw, dtype="<u8", count=size // 8,
                                    offset=at + 15)[1::2])
    starts = np.sort(np.concatenate(start_parts)) if start_parts else np.zeros(0, np.uint64)
    if len(starts) and (starts[-1] > n - 9 or np.any(np.diff(starts) == 0)):
        raise _Irregular("message offsets out of range")
    starts = starts.astype(np.int64)
    length = _load(rec, starts + 1, 8)
    if np.any(length > np.uint64(n)) or np.any(rec[starts] != io.OP_MESSAGE) or \
            np.any(length < 22):
        raise _Irregular("an indexed record is no message")
    ends = starts + 9 + length.astype(np.int64)
    # the gaps between consecutive messages (and before the first, after the last) hold
    # whole records
    gap_from = np.concatenate([[0], ends])
    gap_to = np.concatenate([starts, [n]])
    if np.any(gap_to < gap_from):
        raise _Irregular("records overlap")
    for a, b in zip(gap_from[gap_to > gap_from].tolist(), gap_to[gap_to > gap_from].tolist(),
                    strict=True):
        try:
            io.check_framing(bytes(rec[a:b]))
        except LogFormatError:
            raise _Irregular("framing between messages") from None


def _windows(buf: np.ndarray, width: int) -> np.ndarray:
    """Read-only view of every ``width`` consecutive bytes of ``buf``: row ``i`` is
    ``buf[i:i + width]`` (gathering rows copies ``width`` bytes per index, not an index per
    byte)."""
    return np.lib.stride_tricks.as_strided(buf, shape=(len(buf) - width + 1, width),
                                           strides=(1, 1), writeable=False)


def _load(buf: np.ndarray, pos: np.ndarray, width: int) -> np.ndarray:
    """Little-endian unsigned integers of ``width`` bytes at ``pos``, as uint64."""
    raw = _windows(buf, width)[pos]
    if width == 8:
        return raw.view("<u8")[:, 0]
    if width in (2, 4):  # (the rows' bytes read as one little-endian integer each)
        return raw.view(f"<u{width}")[:, 0].astype(np.uint64)
    out = np.zeros(len(pos), dtype=np.uint64)
    for i in range(width):
        out |= raw[:, i].astype(np.uint64) << np.uint64(8 * i)
    return out


def _doubles(buf: np.ndarray, pos: np.ndarray) -> np.ndarray:
    return _windows(buf, 8)[pos].view("<f8")[:, 0]


def _varint(buf: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Protobuf varints at ``pos``: (values as uint64, position after each)."""
    b = buf[pos]
    if not np.any(b & 0x80):
        return b.astype(np.uint64), pos + 1
    value = np.zeros(len(pos), dtype=np.uint64)
    length = np.zeros(len(pos), dtype=np.int64)
    done = np.zeros(len(pos), dtype=bool)
    for i in range(10):
        b = buf[pos + i].astype(np.uint64)
        live = ~done
        value[live] |= (b[live] & np.uint64(0x7F)) << np.uint64(7 * i)
        length[live] = i + 1
        done |= b < 0x80
        if done.all():
            return value, pos + length
    raise _Irregular("varint longer than 10 bytes")


#: wire types of the field kinds the columnar decoder reads
_WIRE = {"varint": 0, "double": 1, "bytes": 2, "packed": 2}


def _decode_fields(batch: _Batch, spec: dict[int, str], stop: int | None = None
                   ) -> tuple[dict[int, tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Decode the top-level fields of every message of ``batch``: ``spec`` maps field numbers
    to kinds (``varint``, ``double``, ``bytes``, ``packed`` doubles); each appears at most
    once per message. Decoding a message stops at the first field ``stop`` (a map whose
    entries end the message). Returns ``{field: (present, value)}`` (value: uint64 for
    varint, float64 for double, (start, length) int64 pairs as a (n, 2) array for bytes and
    packed) and where each message's ``stop`` field begins (its end if none)."""
    buf, end = batch.buf, batch.end
    n = len(batch)
    pos = batch.start.copy()
    present = {f: np.zeros(n, dtype=bool) for f in spec}
    values: dict[int, np.ndarray] = {}
    for f, kind in spec.items():
        if kind == "varint":
            values[f] = np.zeros(n, dtype=np.uint64)
        elif kind == "double":
            values[f] = np.zeros(n)
        else:
            values[f] = np.zeros((n, 2), dtype=np.int64)
    stop_at = end.copy()
    live = np.flatnonzero(pos < end)
    while len(live):
        p = pos[live]
        tag, p = _varint(buf, p)
        field = (tag >> np.uint64(3)).astype(np.int64)
        wire = (tag & np.uint64(7)).astype(np.int64)
        nxt = np.full(len(p), -1, dtype=np.int64)
        if stop is not None:
            here = field == stop
            if here.any():
                stop_at[live[here]] = pos[live[here]]
                nxt[here] = end[live[here]]
        for f, kind in spec.items():
            sel = field == f
            if not sel.any():
                continue
            if np.any(wire[sel] != _WIRE[kind]):
                raise _Irregular(f"field {f} of another wire type")
            rows = live[sel]
            if present[f][rows].any():
                raise _Irregular(f"field {f} repeated")
            present[f][rows] = True
            ps = p[sel]
            if kind == "varint":
                v, after = _varint(buf, ps)
                values[f][rows] = v
            elif kind == "double":
                values[f][rows] = _doubles(buf, ps)
                after = ps + 8
            else:
                length, ps = _varint(buf, ps)
                if np.any(length > np.uint64(1 << 31)):
                    raise _Irregular("length out of range")
                length = length.astype(np.int64)
                if kind == "packed" and np.any(length % 8):
                    raise _Irregular("packed doubles of a partial length")
                values[f][rows, 0] = ps
                values[f][rows, 1] = length
                after = ps + length
            nxt[sel] = after
        if np.any(nxt < 0):
            raise _Irregular("unexpected field")
        if np.any(nxt > end[live]):
            raise _Irregular("field runs past its message")
        pos[live] = nxt
        live = live[nxt < end[live]]
    return {f: (present[f], values[f]) for f in spec}, stop_at


def _packed(buf: np.ndarray, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Packed doubles of every message back to back, and their count per message."""
    counts = ranges[:, 1] // 8
    total = int(counts.sum())
    if not total:
        return np.zeros(0), counts
    first = np.cumsum(counts) - counts
    pos = np.repeat(ranges[:, 0] - 8 * first, counts) + 8 * np.arange(total, dtype=np.int64)
    return _doubles(buf, pos), counts


def _strings(buf: np.ndarray, ranges: np.ndarray, names: Sequence[str]) -> np.ndarray:
    """Index in ``names`` of each string field ((start, length) rows); -1 for any other."""
    out = np.full(len(ranges), -1, dtype=np.int64)
    for i, name in enumerate(names):
        raw = np.frombuffer(name.encode(), dtype=np.uint8)
        sel = np.flatnonzero(ranges[:, 1] == len(raw))
        if len(raw) > len(buf):
            continue
        if len(raw) and len(sel):
            same = np.all(_windows(buf, len(raw))[ranges[sel, 0]] == raw, axis=1)
            sel = sel[same]
        out[sel] = i
    return out
