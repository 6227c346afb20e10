"""Derive a session from another: stream-copy it, images kept as stored (never decoded),
optionally replacing the detections (re-detection) and adding or replacing fused tracks."""

from __future__ import annotations

import contextlib
import json
import struct
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from pathlib import Path
from typing import cast

import numpy as np

from ..errors import InputError, LogFormatError
from ..outputs import check_output_path
from ..records import Detections, Track
from ..rig import Rig, timing_label
from . import _mcapio as io
from . import _schemas as S
from . import table as tables
from .reader import _PAD, _Batch, _Finished, _gather, _Irregular, old_left_out_counts
from .writer import SessionWriter, _Block


def copy_session(src, dst, *, detections: Detections | Callable[[], Detections] | None = None,
                 tracks: Sequence[Track] = (),
                 replace_tracks: bool = True,
                 metadata: Mapping[str, str | None] | None = None,
                 rig: Rig | None = None, force: bool = False,
                 rejections: Mapping | None = None, checked_chunks: Collection[int] = (),
                 layouts: Callable[[int], np.ndarray | None] | None = None
                 ) -> None:
    """Write ``dst`` as a copy of session ``src``.

    Parameters
    ----------
    detections : if given, replaces every detection message of ``src`` (camera names must
        be the rig's); a callable giving them is called once the rest is copied (so that
        they can be computed meanwhile, e.g. by ``pslog redetect``'s workers)
    tracks : fused tracks to add
    replace_tracks : drop every track of ``src`` (True) or only those whose method is in
        ``tracks`` (False)
    metadata : user metadata to add or replace (e.g. the new detector settings); a key
        given None is not copied (a setting of the source that no longer holds)
    rig : a corrected rig (same camera names, same order) replacing the session's calibration
    force : overwrite ``dst``
    rejections : method -> :class:`pslog.fusion.gating.Rejections`, the candidates the
        gating stage rejected for that method's track (written beside it; replaced with it)
    checked_chunks : byte offsets of Chunk records of ``src`` whose CRC the caller checks
        (``pslog redetect``'s workers check every image chunk they read: not computed
        twice); the caller must fail the copy if one does not match
    layouts : with ``checked_chunks``: ``layouts(offset)`` gives the layout of a checked
        chunk's records as the caller found them reading it (:func:`record_layout`; it may
        wait for it). A chunk whose MessageIndex records state exactly that layout (message
        records only, each listed with its channel and log time) and whose every channel is
        copied as it is, is then written byte for byte without being decompressed here
        (``pslog redetect``: its workers decompress every image chunk anyway)

    Calibration, poses, images, truth, events, metadata and any foreign topics are copied
    byte for byte (the calibration and poses are re-derived only from a given ``rig``).
    ``dst`` may not be ``src`` in any spelling; it is written as ``<dst>.partial`` and
    appears only when complete (on any failure nothing is left and an old ``dst`` stays).
    """
    new_methods = {t.method for t in tracks}
    with open_copy(src, dst, detections=detections, new_methods=new_methods,
                   replace_tracks=replace_tracks, metadata=metadata, rig=rig, force=force,
                   checked_chunks=checked_chunks, layouts=layouts) as w:
        for track in tracks:
            w.add_track(track, left_out=track.dropped or None)
        for method, rejected in (rejections or {}).items():
            w.add_rejections(method, rejected)


@contextlib.contextmanager
def open_copy(src, dst, *, detections: Detections | Callable[[], Detections] | None = None,
              new_methods: Collection[str] = (), replace_tracks: bool = True,
              metadata: Mapping[str, str | None] | None = None, rig: Rig | None = None,
              force: bool = False, checked_chunks: Collection[int] = (),
              layouts: Callable[[int], np.ndarray | None] | None = None
              ) -> Iterator[SessionWriter]:
    """:func:`copy_session` as a context: ``dst``'s writer once everything of ``src`` is
    copied (and ``detections`` written), for the caller to add the new tracks and their
    rejections (``new_methods``: their methods, the tracks of ``src`` dropped for them when
    ``replace_tracks`` is False) while it still makes some (``pslog fuse`` writes each
    method's track as the method ends). ``dst`` appears when the context ends without an
    exception, complete; on any exception (an interrupt too) nothing is left and an old
    ``dst`` stays. An interrupt during the final close itself is held until the close is done
    (:func:`pslog.log.writer._signals_held`): ``dst`` is then the complete new file, and the
    interrupt is raised after. The parameters are :func:`copy_session`'s."""
    src_path = Path(src)
    dst = check_output_path(dst, force, inputs=[src_path])  # before reading anything
    with _Finished(src_path) as f:
        meta, old_rig = f.meta, f.rig
        first_static = f.collect([S.calibration_topic(old_rig.names[0])])
        start_ns = min((t for t, _s, _d in next(iter(first_static.values()), [])), default=0)
        # the copy keeps the source's channel ids: its chunks are then copied as they are
        channel_ids: dict[str, int] = {}
        for c in sorted(f.summary.channels.values(), key=lambda c: c.id):
            channel_ids.setdefault(c.topic, c.id)
    if rig is not None and rig.names != old_rig.names:
        raise InputError(f"rig cameras {', '.join(rig.names)} differ from the session's "
                         f"{', '.join(old_rig.names)} (names and order must match)")
    if isinstance(detections, Detections):
        _check_cameras(detections, old_rig.names)
    new_methods = set(new_methods)
    # the left-out counts of a file fused before they went with each track (one session
    # metadata key, every method's): a track kept gets its own in its channel's metadata,
    # the key itself is not copied (it would name tracks the copy does not have)
    old_left_out = old_left_out_counts(meta)
    user_meta = {k: v for k, v in meta.items()
                 if k not in S.RESERVED_KEYS and k != S.LEFT_OUT_KEY}
    user_meta["derived_from"] = src_path.name
    for key, value in (metadata or {}).items():
        if value is None:
            user_meta.pop(key, None)
        else:
            user_meta[key] = value

    new_rig = rig is not None
    if rig is None:
        rig = old_rig
    # a corrected rig may have other shutter offsets: its label says what they are
    timing = timing_label(rig) if new_rig else meta.get("timing", "custom")
    with SessionWriter(dst, rig, force=force, timing=timing,
                       source=meta.get("source", ""), metadata=user_meta,
                       start_ns=start_ns, on_error="discard", inputs=[src_path],
                       write_static=new_rig, channel_ids=channel_ids,
                       # no timed flush: the same command writes the same bytes however long
                       # its methods took (pslog fuse writes tracks as they end)
                       flush_interval_s=float("inf")) as w:
        if not replace_tracks:
            for kept, counts in old_left_out.items():
                if kept not in new_methods:
                    w.channel_metadata[S.track_topic(kept)] = {
                        S.LEFT_OUT_KEY: json.dumps(counts, sort_keys=True)}
        scan = io.Scan()
        # a corrected rig: its calibration and poses are written by the writer; otherwise
        # the recorded messages are copied verbatim (re-deriving them from the parsed rig
        # can differ in the last bit, e.g. the quaternion, across numpy/OpenCV versions)
        static = ({S.calibration_topic(n) for n in rig.names}
                  | {S.transform_topic(n) for n in rig.names}) if new_rig else set()

        def copy(cid: int, t: int, seq: int, data: bytes) -> None:
            channel = scan.channels[cid]
            topic = channel.topic
            if topic in static:
                return  # written by the new writer from the corrected rig
            camera_topic = S.parse_camera_topic(topic)
            if camera_topic and camera_topic[1] == "image":
                w._add_image_raw(topic, t, data, seq)
                return
            if camera_topic and camera_topic[1] == "detections" and detections is not None:
                return
            parts = topic.split("/")
            if len(parts) >= 3 and parts[1] == "tracks" and (
                    replace_tracks or parts[2] in new_methods):
                return
            schema = scan.schemas.get(channel.schema_id)
            w._add_foreign(topic, schema, channel, t, data, seq)

        with _Finished(src_path) as f:
            if detections is None:
                w._adopt_table(tables.DETECTIONS, _table_data(f, tables.DETECTIONS))
            w._adopt_table(tables.BALL_TRUTH, _table_data(f, tables.BALL_TRUTH))
            w._adopt_table(tables.TRUTH, _table_data(f, tables.TRUTH))
            for topic in f.topics.values():  # the tracks copied as they are
                method = S.parse_track_topic(topic)
                if method and not replace_tracks and method not in new_methods:
                    name = tables.track_table(method)
                    w._adopt_table(name, _table_data(f, name))
            fast = _copy_chunks(f, w, static, detections is not None, replace_tracks,
                                new_methods, frozenset(checked_chunks), layouts)
        if not fast:  # no summary index to go by: every record in turn
            io.scan_file(src_path, copy, scan=scan)  # copy's own errors propagate unchanged
        if detections is not None:
            if not isinstance(detections, Detections):
                detections = detections()
                _check_cameras(detections, old_rig.names)
            w.add_detections(detections)
        yield w


def record_layout(records) -> np.ndarray | None:
    """A chunk's decompressed ``records`` (framing checked) as ``(k, 3)`` int64 rows
    ``(offset of the record, channel, log time)``, one per record in file order; None when
    a record is not a Message (or the records do not end with the last one)."""
    rows, at = [], 0
    for op, body, end in io.walk_records(records):
        if op != io.OP_MESSAGE or end - body < io._MESSAGE_HEAD:
            return None
        cid, _seq, t = struct.unpack_from("<HIQ", records, body)
        rows.append((body - 9, cid, t))
        at = end
    if at != len(records):
        return None
    return np.array(rows, dtype=np.int64).reshape(-1, 3)


def _index_layout(indexes: bytes, offsets: dict[int, int], chunk_end: int
                  ) -> np.ndarray | None:
    """The layout (:func:`record_layout`) a chunk's MessageIndex records ``indexes`` (read
    from ``chunk_end`` on; ``offsets``: channel -> their file offsets) state, sorted by
    offset; None when a record does not check out."""
    parts = []
    for cid, at in offsets.items():
        at -= chunk_end
        if at < 0 or at + 15 > len(indexes):
            return None
        op, length, channel, size = struct.unpack_from("<BQHI", indexes, at)
        if (op != io.OP_MESSAGE_INDEX or channel != cid or size % 16 or length != 6 + size
                or at + 15 + size > len(indexes)):
            return None
        entries = np.frombuffer(indexes, dtype="<u8", count=size // 8,
                                offset=at + 15).reshape(-1, 2)
        if len(entries) and entries.max() >= 1 << 63:
            return None
        rows = np.empty((len(entries), 3), dtype=np.int64)
        rows[:, 0], rows[:, 1], rows[:, 2] = entries[:, 1], cid, entries[:, 0]
        parts.append(rows)
    if not parts:
        return None
    layout = np.concatenate(parts)
    return layout[np.argsort(layout[:, 0], kind="stable")]


def _copy_indexed(f: _Finished, w: SessionWriter, index, fate: dict, topics: dict[int, str],
                  found: np.ndarray | None) -> bool:
    """Write a chunk of ``f`` byte for byte without decompressing it, when its records were
    found (``found``: their layout, :func:`record_layout`, by the reader that checked the
    chunk) to be exactly what its MessageIndex records state, every channel of it is kept
    with the same id, none of whose messages a table is made from, and its record's start
    and end times are their first and last log times: what :func:`_verbatim` and
    :func:`_copy_raw` decide from the decompressed records. False: nothing written."""
    cids = index.message_index_offsets.keys()
    if found is None or not len(found) or not cids or not all(
            fate.get(c) is not None and fate[c][0] == c and c not in w._table_parts
            for c in cids):
        return False
    f.file.seek(index.chunk_start_offset)
    record = f.file.read(index.chunk_length)
    if len(record) != index.chunk_length or record[0] != io.OP_CHUNK or \
            int.from_bytes(record[1:9], "little") != index.chunk_length - 9:
        return False
    end = index.chunk_start_offset + index.chunk_length
    indexes = f.file.read(index.message_index_length)
    if len(indexes) != index.message_index_length:
        return False
    layout = _index_layout(indexes, index.message_index_offsets, end)
    if layout is None or not np.array_equal(layout, found):
        return False
    start, end_time = int(layout[:, 2].min()), int(layout[:, 2].max())
    if (int.from_bytes(record[9:17], "little") != start
            or int.from_bytes(record[17:25], "little") != end_time):
        return False
    ids, first, counts = np.unique(layout[:, 1], return_index=True, return_counts=True)
    order = np.argsort(first, kind="stable")  # in order of each channel's first message
    w._add_raw_chunk(record, indexes,
                     {cid: at - end for cid, at in index.message_index_offsets.items()},
                     dict(zip(ids[order].tolist(), counts[order].tolist(), strict=True)),
                     start, end_time, topics)
    return True


def _check_cameras(detections: Detections, names: tuple[str, ...]) -> None:
    if tuple(detections.camera_names) != names:
        raise InputError(f"detections are for cameras {', '.join(detections.camera_names)}, "
                         f"session has {', '.join(names)}")


def _table_data(f: _Finished, name: str) -> bytes | None:
    """The attachment data of ``f``'s table ``name`` when it is there and consistent."""
    if f.table(name) is None:
        return None
    return f._attachment(f.attachments[name])


def _copy_chunks(f: _Finished, w: SessionWriter, static: set[str], new_detections: bool,
                 replace_tracks: bool, new_methods: set[str],
                 checked: frozenset[int] = frozenset(),
                 layouts: Callable[[int], np.ndarray | None] | None = None) -> bool:
    """Copy the messages of ``f`` a chunk at a time, each chunk checked as the reader checks
    it (decompressed, its CRC and its MessageIndex records against its message records).

    A chunk that holds only message records, all of them kept, on channels that have the
    same id here, whose messages no table here is made from (:meth:`SessionWriter.
    _adopt_table`), is written byte for byte, its compressed bytes and indexes as they
    are (:meth:`SessionWriter._add_raw_chunk`): most of a session, never compressed
    again. Any other chunk's kept messages are written as one block (no Python object
    per message). False, before writing anything, when the summary does not account for
    every message (messages outside chunks, chunks without indexes, no statistics): then
    the caller walks the file record by record."""
    import mmap

    summary = f.summary
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    stats = summary.statistics
    if not chunks or stats is None or not all(c.message_index_offsets for c in chunks):
        return False
    with mmap.mmap(f.file.fileno(), 0, access=mmap.ACCESS_READ) as buf:
        indexed = 0
        for c in chunks:
            end = c.chunk_start_offset + c.chunk_length
            counts, _ = io.message_index_counts(buf, end, min(len(buf),
                                                              end + c.message_index_length))
            indexed += sum(counts.values())
    if indexed != stats.message_count:
        return False
    # what becomes of each channel: dropped (None), or its channel here and whether images
    fate: dict[int, tuple[int, bool] | None] = {}
    topics: dict[int, str] = {}
    for cid, channel in summary.channels.items():
        topic = channel.topic
        camera_topic = S.parse_camera_topic(topic)
        parts = topic.split("/")
        if topic in static or (camera_topic and camera_topic[1] == "detections"
                               and new_detections) or (
                len(parts) >= 3 and parts[1] == "tracks"
                and (replace_tracks or parts[2] in new_methods)):
            fate[cid] = None
            continue
        schema = summary.schemas.get(channel.schema_id)
        schema_rec = None if schema is None else io.SchemaRec(
            schema.id, schema.name, schema.encoding, schema.data)
        new = w._foreign_channel(topic, schema_rec, io.ChannelRec(
            cid, channel.schema_id, topic, channel.message_encoding, dict(channel.metadata)))
        fate[cid] = (new, bool(camera_topic and camera_topic[1] == "image"))
        topics[new] = topic
    for index in chunks:
        here = [cid for cid in index.message_index_offsets if fate.get(cid) is not None]
        if not here:
            continue
        if layouts is not None and index.chunk_start_offset in checked and _copy_indexed(
                f, w, index, fate, topics, layouts(index.chunk_start_offset)):
            continue
        record, records = _read_record(f, index, index.chunk_start_offset not in checked)
        rec = np.frombuffer(records, dtype=np.uint8)
        try:
            got = f._indexed(index, rec, index.message_index_offsets.keys())
            batch = _merge(got, rec)
        except (_Irregular, struct.error):
            try:  # the framing the record walk needs, with its usual error
                io.check_framing(records)
            except LogFormatError as exc:
                raise io.damaged_error(f.path, index.chunk_start_offset, str(exc)) from None
            batch = _walk(records)
        else:
            if _verbatim(index, batch, len(records), fate, w) and _copy_raw(
                    f, w, index, batch, topics, record):
                continue
        del records, record
        for images in (False, True):
            cids = np.array([c for c, v in fate.items() if v is not None and v[1] == images],
                            dtype=np.int64)
            sel = np.flatnonzero(np.isin(batch.channel, cids))
            if not len(sel):
                continue
            payload, _ = _gather(batch.buf, batch.start[sel], batch.end[sel])
            w._add_block(_Block(_remap(batch.channel[sel], fate), batch.time[sel], batch.seq[sel],
                                batch.end[sel] - batch.start[sel], payload.tobytes()),
                         topics, images=images)
    return True


def _read_record(f: _Finished, index, validate_crc: bool) -> tuple[bytes, bytes]:
    """(the Chunk record as stored, its decompressed records checked as
    :meth:`_Finished.read_chunk` checks them, framing left to the caller): the record read
    once, for :func:`_copy_raw` too, and decompressed where it was read."""
    f.file.seek(index.chunk_start_offset)
    record = f.file.read(index.chunk_length)
    try:
        if len(record) != index.chunk_length or record[0] != io.OP_CHUNK or \
                int.from_bytes(record[1:9], "little") != index.chunk_length - 9:
            raise LogFormatError("chunk record does not match the summary's index")
        # a view of the record (chunk_payload reads any buffer): decompressed in place
        records = io.chunk_payload(cast(bytes, memoryview(record)[9:]),
                                   validate_crc=validate_crc, framing=False)
    except LogFormatError as exc:
        raise io.damaged_error(f.path, index.chunk_start_offset, str(exc)) from None
    return record, bytes(records)  # (a copy only of an uncompressed chunk's view)


def _verbatim(index, batch: _Messages, size: int, fate: dict, w: SessionWriter) -> bool:
    """Whether a chunk (its messages ``batch``, found through its indexes; ``size`` bytes of
    records) can be copied byte for byte: message records only, back to back, each on a
    kept channel with the same id here, none of whose messages a table is made from."""
    cids = index.message_index_offsets.keys()
    if not len(batch.channel) or not all(
            fate.get(c) is not None and fate[c][0] == c and c not in w._table_parts
            for c in cids):
        return False
    begin = batch.start - io._MESSAGE_HEAD - 9  # each record's opcode
    return bool(begin[0] == 0 and batch.end[-1] == size
                and np.array_equal(begin[1:], batch.end[:-1]))


def _copy_raw(f: _Finished, w: SessionWriter, index, batch: _Messages,
              topics: dict[int, str], record: bytes) -> bool:
    """Write a chunk of ``f`` and its MessageIndex records as they are (see
    :func:`_verbatim`); False (nothing written) when the chunk record's start and end times,
    which its CRC does not cover, are not its messages' first and last log times: then the
    chunk is written anew."""
    end = index.chunk_start_offset + index.chunk_length
    f.file.seek(end)
    indexes = f.file.read(index.message_index_length)
    if len(indexes) != index.message_index_length:
        raise io.damaged_error(f.path, index.chunk_start_offset, "chunk cut short")
    start, end_time = int(batch.time.min()), int(batch.time.max())
    # the Chunk record's message start and end times (after opcode and length: MCAP spec)
    if (int.from_bytes(record[9:17], "little") != start
            or int.from_bytes(record[17:25], "little") != end_time):
        return False
    ids, first, counts = np.unique(batch.channel, return_index=True, return_counts=True)
    order = np.argsort(first, kind="stable")
    w._add_raw_chunk(record, indexes,
                     {cid: at - end for cid, at in index.message_index_offsets.items()},
                     dict(zip(ids[order].tolist(), counts[order].tolist(), strict=True)),
                     start, end_time, topics)
    return True


class _Messages:
    """A chunk's messages in file order: channel, log time, sequence and where each one's
    data lies in ``buf`` (``start``/``end``), (n,) int64 columns."""

    def __init__(self, buf, channel, time, seq, start, end) -> None:
        self.buf, self.channel, self.time, self.seq, self.start, self.end = (
            buf, channel, time, seq, start, end)


def _merge(got: dict[int, _Batch], rec: np.ndarray) -> _Messages:
    """The messages of every channel of a chunk (channel -> :class:`_Batch`, offsets into
    ``rec``) in file order."""
    if not got:
        empty = np.zeros(0, np.int64)
        return _Messages(rec, empty, empty, empty, empty, empty)
    batches = list(got.values())
    start = np.concatenate([b.start for b in batches])
    order = np.argsort(start, kind="stable")
    channel = np.concatenate([np.full(len(b), cid, np.int64) for cid, b in got.items()])
    return _Messages(rec, channel[order], np.concatenate([b.time for b in batches])[order],
                     np.concatenate([b.seq for b in batches])[order], start[order],
                     np.concatenate([b.end for b in batches])[order])


def _walk(records: bytes) -> _Messages:
    """The messages of a chunk's records walked one by one (framing checked by the caller)."""
    rows = []
    for op, body, end in io.walk_records(records):
        if op == io.OP_MESSAGE:
            cid, seq, t = struct.unpack_from("<HIQ", records, body)
            rows.append((cid, t, seq, body + io._MESSAGE_HEAD, end))
    cols = np.array(rows, dtype=np.int64).reshape(-1, 5)
    buf = np.frombuffer(records + bytes(_PAD), dtype=np.uint8)
    return _Messages(buf, *(cols[:, i] for i in range(5)))


def _remap(channel: np.ndarray, fate: dict) -> np.ndarray:
    """This writer's channel of each source channel id (all kept)."""
    lookup = np.zeros(max(fate) + 1, dtype=np.int64)
    for cid, v in fate.items():
        if v is not None:
            lookup[cid] = v[0]
    return lookup[channel]
