"""Write a pslog session MCAP (format: docs/log-format.md).

Crash safety: small messages (detections, truth, tracks, events) are buffered and written as
their own chunks at least every ``flush_interval_s``; images go straight into the chunk in
progress, which is closed at the same moments. So a killed process loses at most the last
interval, and detection chunks never contain image bytes, which lets the reader skip every
image chunk without decompressing it.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import threading
import time
import weakref
from collections.abc import Mapping
from datetime import UTC, datetime
from typing import Any, cast

import numpy as np

from ..errors import InputError, LogFormatError, PslogError
from ..outputs import (
    DERIVED_KEY,
    WriteError,
    check_output_path,
    open_locked,
    partial_path,
    write_error,
)
from ..palette import method_color, unit_rgb
from ..records import Detections, Track, Truth
from ..rig import Rig
from . import _chunks, table
from . import _schemas as S

#: Messages buffered before they are written even if the flush interval has not passed.
_MAX_PENDING = 20_000
#: Image bytes buffered before they are written as a chunk (mcap's own chunk size).
_IMAGE_CHUNK_BYTES = 1 << 20
#: Apparent diameter of the sphere drawn per fused track point in Foxglove, metres.
_TRACK_SPHERE_M = 0.043
#: How long each fused track point stays visible in Foxglove's 3D panel (a short trail).
_TRACK_LIFETIME_NS = 500_000_000
_LOG_LEVELS = {"debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}


def track_color(method: str) -> tuple[float, float, float]:
    """Foxglove (r, g, b) in [0, 1] of a method's track: the viewers' colour (pslog.palette)."""
    return unit_rgb(method_color(method))


def _locked(method):
    """Serialise a public method with the background flusher; an OS fault while writing
    (full disk, size limit, ...) becomes one :class:`~pslog.outputs.WriteError` naming the
    output."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        with self._lock:
            try:
                return method(self, *args, **kwargs)
            except OSError as exc:
                raise self._os_fault(exc) from None
    return wrapper


def _creator() -> str:
    from .. import package_version

    version = package_version()
    return f"pslog {version}" if version else "pslog"


class SessionWriter:
    """Write one session MCAP; use as a context manager.

    Parameters
    ----------
    path : output file; refused if it exists unless ``force`` or if it is one of ``inputs``.
        An existing file is replaced only when the new one is complete: the writer writes
        ``<path>.partial`` and moves it over ``path`` on a successful :meth:`close`. After
        :meth:`abort` the partial file is deleted.
    rig : the session's cameras; camera indices below refer to ``rig.cameras``
    timing : shutter preset name (``sync``, ``typeA``, ``typeB``) or ``custom``
    source : free text: what produced the session (``simulate motion=spiral ...``)
    metadata : extra string key/values for the session metadata record
    flush_interval_s : longest time, seconds, that written data stays in memory (``math.inf``:
        no timed flush — a derived output, whose ``.partial`` goes on any failure: its chunk
        boundaries then depend on what is written, never on how long the caller took)
    start_ns : session clock time (ns) stamped on the static calibration and pose messages
    write_static : write the rig's calibration and pose messages (False: the caller copies
        them, e.g. verbatim from the session it derives from)
    on_error : what becomes of the data written when the session fails (an exception inside
        ``with``, an OS fault such as a full disk):

        - ``"keep"`` (recordings, whose data exists nowhere else): a new file is written in
          place and kept; a replacement is kept as ``<path>.partial`` beside the untouched
          old session. Both are finished (readable) unless the failure was the OS refusing
          a write, which leaves a truncated file for ``pslog recover``.
        - ``"discard"`` (derived outputs, made again from their inputs: simulate, import,
          session copies): always written as ``<path>.partial``, removed on any failure, so
          nothing half-written is ever left under ``path`` and an old ``path`` stays.
    inputs : files the session is made from; ``path`` may not be one of them
    channel_ids : topic -> the MCAP channel id to give it (a session copy keeps its source's
        ids, so that the source's chunks are copied byte for byte); other topics get ids
        above all of these. Ignored where the installed ``mcap`` writer does not allow it

    Attributes
    ----------
    target : the file actually being written (``<path>.partial`` or ``path``), held under
        an exclusive lock (:func:`pslog.outputs.open_locked`) until closed
    """

    def __init__(self, path, rig: Rig, *, force: bool = False, timing: str = "custom",
                 source: str = "", metadata: Mapping[str, str] | None = None,
                 flush_interval_s: float = 0.5, start_ns: int = 0,
                 on_error: str = "keep", inputs=(), write_static: bool = True,
                 channel_ids: Mapping[str, int] | None = None) -> None:
        from mcap.writer import CompressionType, Writer

        if on_error not in ("keep", "discard"):
            raise ValueError(f"on_error must be 'keep' or 'discard', got {on_error!r}")
        self.path = check_output_path(path, force, inputs)
        self._discard = on_error == "discard"
        #: the file being written: ``<path>.partial`` when replacing a session or writing a
        #: derived one (moved over ``path`` once complete), else ``path`` itself
        self.target = (partial_path(self.path) if self._discard or self.path.exists()
                       else self.path)
        self._aborted = False  # abort(): nothing worth keeping was written
        self._failed = False  # an exception: keep both the old session and <path>.partial
        self._os_failed = False  # the OS refused a write: the MCAP stream cannot be finished
        # scene entity ids of each method's points, running over every add_track call (a live
        # recording adds a track a batch at a time; restarting at 0 would replace the
        # previous batch's markers in Foxglove)
        self._scene_ids: dict[str, int] = {}
        self._closed = True  # until the file is open
        self._lock = threading.RLock()
        extra = {str(k): str(v) for k, v in dict(metadata or {}).items()}
        clash = sorted(set(extra) & set(S.RESERVED_KEYS))
        if clash:
            raise InputError(f"metadata key(s) reserved by pslog: {', '.join(clash)}")
        self.rig = rig
        self._names = rig.names
        self._flush_interval = float(flush_interval_s)
        self._schema_ids: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._wanted_ids = {str(k): int(v) for k, v in dict(channel_ids or {}).items()}
        self._bulk = False
        # (channel, time, data, sequence) messages, or whole blocks of them (_add_block)
        self._pending: list[tuple[int, int, bytes, int] | _Block] = []
        # images wait here, not in the MCAP writer's chunk, so that the small messages buffered
        # meanwhile (the detections of those frames) are always written before them: when
        # the disk fills up, it is a large image chunk that does not fit, and the detections
        # of every frame whose image is in the file are in the file too (see flush())
        self._images: list[tuple[int, int, bytes, int] | _Block] = []  # as _pending
        self._image_bytes = 0
        self._track_methods: list[str] = []
        self._stop = threading.Event()
        self._flusher: threading.Thread | None = None
        self._flush_error: BaseException | None = None
        self._last_flush = time.monotonic()
        self.counts: dict[str, int] = {}
        # the messages of the topics that columnar tables stand for (detections, ball
        # labels, truth), kept as written (channel id -> parts), made tables at close
        self._table_rows: dict[int, tuple[str, int]] = {}  # channel -> (table, camera)
        self._table_parts: dict[int, list] = {}
        self._topic_of: dict[int, str] = {}
        # table -> a copied table's attachment data (None: none to copy, made again)
        self._adopted: dict[str, bytes | None] = {}
        # the tracks added on a track channel (its table is made from them at close, not from
        # copies of its messages: those are most of a fused session's bytes)
        self._tracks_of: dict[int, list[Track]] = {}
        #: topic -> metadata of its channel, set before the channel is registered (a track's
        #: left-out counts: :meth:`add_track`; a copied track's: :func:`.copy.open_copy`)
        self.channel_metadata: dict[str, dict[str, str]] = {}
        # the tables already written: a finished track's, as it is added (:meth:`add_track`
        # ``last=True``), not at close
        self._tables_written: set[str] = set()
        # the bytes handed to the OS up to here have had their writeback started (None:
        # not needed, the file put in place by a move to a free name or written in place)
        self._behind: int | None = None
        self._replaces = False  # the file is to be moved over an existing one at close

        opened = False
        try:  # once the file exists an exception (a Ctrl-C or SIGTERM included) removes it
            # the file is created, locked and wrapped with Ctrl-C and SIGTERM held, so that
            # one coming at once (a service stopping the command as its output appears) is
            # raised only where the cleanup below removes the file
            with _signals_held():
                try:
                    # locked while written: no other pslog run takes it for a stale partial
                    self._file = open_locked(self.target)  # closed in close()
                except OSError as exc:
                    raise write_error(self.path, exc) from None
                opened = True
                self._closed = False
                _OPEN.add(self)
                self._mcap = Writer(self._file, compression=CompressionType.ZSTD)
                if self.target != self.path and self.path.exists():
                    self._replaces = True  # (moved over a file at close: _write_behind)
                    self._behind = 0
                # messages written in blocks (_chunks)
                self._bulk = _chunks.supported(self._mcap)
            # metadata first and flushed at once, so even a file killed seconds later is a session
            record = {
                "format": S.FORMAT_NAME,
                "format_version": S.FORMAT_VERSION,
                "rig_toml": rig.to_toml(),
                "timing": str(timing),
                "source": str(source),
                "creator": _creator(),
                "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
                "camera_names": ",".join(self._names),
                **extra,
            }
            if self._discard:  # made from inputs that still exist: a stale partial may go
                record[DERIVED_KEY] = "true"
            with self._lock:
                try:
                    self._mcap.start(profile="", library=_creator())
                    self._mcap.add_metadata(S.SESSION_METADATA, record)
                    if write_static:
                        self._write_static(int(start_ns))
                    else:
                        self._register_detection_channels()
                    self.flush()
                except OSError as exc:
                    raise self._os_fault(exc) from None
            if 0 < self._flush_interval < float("inf"):
                # flush on a timer too, so data is on disk within the interval even when the
                # caller stops adding messages (a stalled camera) and is then killed
                flusher = threading.Thread(target=self._flush_loop, daemon=True,
                                           name=f"pslog-flush-{self.path.name}")
                flusher.start()  # one interrupted here stops by itself (close() sets _stop)
                self._flusher = flusher
        except BaseException:
            if not opened:  # nothing of ours to remove (a busy partial is another run's)
                raise
            self._failed = True
            self._discard = True  # nothing but the header was written: remove it
            self.close()  # never raises for a failed writer
            raise

    def _flush_loop(self) -> None:
        # poll often and flush a poll period early, so nothing stays buffered longer than
        # the interval
        poll = min(self._flush_interval / 4, 0.05)
        while not self._stop.wait(poll):
            with self._lock:
                if self._closed:
                    return
                try:
                    if time.monotonic() - self._last_flush >= self._flush_interval - poll:
                        self.flush()
                except BaseException as exc:  # e.g. disk full: raised by the next call
                    self._flush_error = exc
                    return

    # ---- channels ---------------------------------------------------------------------
    def _channel(self, topic: str, message_class) -> int:
        channel = self._channels.get(topic)
        if channel is None:
            name = message_class.DESCRIPTOR.full_name
            schema = self._schema_ids.get(name)
            if schema is None:
                schema = self._mcap.register_schema(
                    name=name, encoding=S.PROTOBUF, data=S.file_descriptor_set(message_class))
                self._schema_ids[name] = schema
            channel = self._register_channel(topic, S.PROTOBUF, schema,
                                             self.channel_metadata.get(topic, {}))
            self._channels[topic] = channel
            self._note_channel(topic, channel)
        return channel

    def _register_channel(self, topic: str, encoding: str, schema_id: int, metadata) -> int:
        """Register a channel with the MCAP writer: the id :attr:`_wanted_ids` names for
        ``topic`` when it is free, else one above every id used or wanted (the ``mcap``
        writer's own numbering when no id is wanted)."""
        if not (self._wanted_ids and self._bulk):
            return self._mcap.register_channel(topic, encoding, schema_id, metadata)
        used = self._channels.values()
        cid = self._wanted_ids.get(topic)
        if cid is None or cid in used:
            cid = max([*used, *self._wanted_ids.values()], default=0) + 1
        _chunks.register_channel(self._mcap, cid, topic, encoding, schema_id, metadata)
        return cid

    def _note_channel(self, topic: str, channel: int) -> None:
        """Keep the messages of ``channel`` if a columnar table stands for its topic (and
        no copied table stands for them: :meth:`_adopt_table`)."""
        row = table.table_of(topic, self._names)
        if row is not None:
            self._table_rows[channel] = row
            if self._adopted.get(row[0]) is None:
                self._table_parts[channel] = []
            self._topic_of[channel] = topic

    def _keep_table_rows(self, channel: np.ndarray, times: np.ndarray, sequence: np.ndarray,
                         data: bytes, lengths: np.ndarray) -> None:
        """Keep the written messages of the tables' channels (their bytes, times and
        sequence numbers) for :meth:`_write_tables`."""
        from .reader import _Batch, _gather

        here = set(_chunks.channels_seen(channel)[0].tolist()) & self._table_parts.keys()
        if not here:
            return
        ends = np.cumsum(lengths)
        starts = ends - lengths
        payload = np.frombuffer(data, dtype=np.uint8)
        for cid in sorted(here):
            sel = np.flatnonzero(channel == cid)
            buf, begin = _gather(payload, starts[sel], ends[sel])
            self._table_parts[cid].append(_Batch(buf, begin, begin + lengths[sel],
                                                 times[sel], sequence[sel]))

    def _direct_track(self, channel: int, topic: str) -> list[Track] | None:
        """The list that keeps the tracks added on ``channel`` (not their messages' bytes:
        its table is made from them), or None when other messages were written on it (its
        table is then made from the messages)."""
        if channel in self._tracks_of or self.counts.get(topic, 0) == 0:
            self._table_parts.pop(channel, None)  # its messages' bytes are not kept
            return self._tracks_of.setdefault(channel, [])
        return None

    def _adopt_table(self, name: str, data: bytes | None) -> None:
        """A table read from the session being copied (checked): written as it is at close
        when the messages its topics got here are exactly as many as it names (a copy of
        every one of them). The messages of its topics are then not kept (they were most
        of a copy's memory): should their number differ (messages added besides the copy),
        the session gets no such table and readers decode the messages, as they do for
        any file without tables."""
        self._adopted[name] = data
        if data is not None:
            for cid, (t, _cam) in self._table_rows.items():
                if t == name:
                    self._table_parts.pop(cid, None)

    def _write_tables(self) -> None:
        """Write each table whose topics have a channel as an attachment (see
        :mod:`pslog.log.table`), made from the messages written (:func:`table.build`), or a
        copied one (:meth:`_adopt_table`) that names as many messages as were written."""
        for name in table.names(self._topic_of.values()):  # fused tracks' tables too
            channels = [cid for cid, (t, _cam) in self._table_rows.items() if t == name]
            if not channels or name in self._tables_written:
                continue
            direct = [self._tracks_of[cid] for cid in channels if cid in self._tracks_of]
            per_topic = {self._topic_of[cid]: self._table_parts[cid] for cid in channels
                         if cid in self._table_parts}
            counts = {t: sum(len(b) for b in per_topic.get(t, []))
                      for t in table.topics_of(name, self._names)}
            unkept = any(cid not in self._table_parts and cid not in self._tracks_of
                         for cid in channels)
            if unkept:  # an adopted table's messages, counted but not kept
                counts = {t: self.counts.get(t, 0) for t in table.topics_of(name, self._names)}
            if direct:  # a track channel fed by add_track only
                counts = {t: sum(len(x) for x in direct[0])
                          for t in table.topics_of(name, self._names)}
            data = self._adopted.get(name)
            if data is not None:
                try:  # (its columns were checked as the session was read)
                    copied, _ = table.decode(data, name, self._names, header_only=True)
                except LogFormatError:
                    copied = None
                if copied != counts:
                    data = None
            parts = None if data is None else [data]
            if data is None and direct:
                parts = table.encode_parts(name, self._names, counts,
                                           table.track_columns_of(direct[0]))
            elif data is None and unkept:
                continue  # nothing to make it from: the messages stand alone
            elif data is None:
                data = table.build(name, self._names, per_topic)
                parts = None if data is None else [data]
            del data
            if parts is not None:
                if self._bulk:  # written piece by piece, not copied on its way
                    _chunks.write_attachment(self._mcap, name, table.MEDIA_TYPE, parts)
                else:
                    self._mcap.add_attachment(0, 0, name, table.MEDIA_TYPE, b"".join(parts))
                del parts

    def _write_static(self, time_ns: int) -> None:
        """Per camera: foxglove.CameraCalibration and foxglove.FrameTransform world -> camera."""
        for cam in self.rig.cameras:
            for topic, msg in camera_messages(cam, time_ns):
                self._queue(self._channel(topic, type(msg)), time_ns, msg.SerializeToString())
        self._register_detection_channels()

    def _register_detection_channels(self) -> None:
        # register the per-camera data channels up front: they land in the first chunk
        for name in self._names:
            self._channel(S.detections_topic(name), S.DetectionFrame)

    def _queue(self, channel: int, time_ns: int, data: bytes, sequence: int = 0) -> None:
        if time_ns < 0:
            raise InputError(_negative_time(time_ns))
        self._pending.append((channel, int(time_ns), data, int(sequence)))
        if len(self._pending) >= _MAX_PENDING:
            self._drain()
        self._maybe_flush()

    def _drain(self) -> None:
        """Write buffered small messages as chunk(s) of their own."""
        if not self._pending:
            return
        self._write_block(self._pending)
        self._pending.clear()
        self._mcap.flush()
        self._write_behind()

    def _write_block(self, messages: list[tuple[int, int, bytes, int] | _Block]) -> None:
        """Write ``(channel, time, data, sequence)`` messages as chunk(s): all at once with
        numpy (:mod:`._chunks`, the same bytes as the ``mcap`` writer's ``add_message`` one
        by one, which cost most of the time of writing a long session), or one by one when
        the installed ``mcap`` does not allow it or a field does not fit (its own error)."""
        if (len(messages) > 1 and isinstance(messages[-1], _Block) and messages[-1].records
                and self._bulk):
            # whole records after messages still buffered (a method's few rejections, queued
            # one by one, before the next method's track): those first, in chunk(s) of their
            # own, then the records cut into chunks as they are; joined, the records would
            # lose their heads and be laid out again (a fused match's first block of each
            # later track: 0.3 CPU s of copies and a slower zstd level, for the same messages)
            self._write_block(messages[:-1])
            self._write_block(messages[-1:])
            return
        if (len(messages) == 1 and isinstance(messages[0], _Block) and messages[0].records
                and self._bulk and _chunks.fits(messages[0].seq, messages[0].time)
                and not self._table_parts.keys()
                & set(_chunks.channels_seen(messages[0].channel)[0].tolist())):
            # whole records (a fused track's): the chunks are cut from them as they are
            block = messages[0]
            _chunks.write_messages(self._mcap, block.channel, block.time, block.seq,
                                   block.data, block.length, assembled=True)
            return
        messages = [m.plain() if isinstance(m, _Block) else m for m in messages]
        if any(isinstance(m, _Block) for m in messages):
            blocks, run = [], []
            for m in [*messages, None]:
                if isinstance(m, tuple):
                    run.append(m)
                    continue
                if run:
                    blocks.append(_Block.of(run))
                    run = []
                if m is not None:
                    blocks.append(m)
            channel, times, sequence, lengths = (np.concatenate([getattr(b, k) for b in blocks])
                                                 for k in ("channel", "time", "seq", "length"))
            data = b"".join(b.data for b in blocks)
        else:
            block = _Block.of(cast("list[tuple[int, int, bytes, int]]", messages))
            channel, times, sequence, lengths = block.channel, block.time, block.seq, \
                block.length
            data = block.data
        if self._bulk and _chunks.fits(sequence, times):
            _chunks.write_messages(self._mcap, channel, times, sequence, data, lengths)
        else:
            add = self._mcap.add_message
            ends = np.cumsum(lengths).tolist()
            for cid, time_ns, seq, a, b in zip(channel.tolist(), times.tolist(),
                                               sequence.tolist(), [0, *ends[:-1]], ends,
                                               strict=True):
                add(cid, time_ns, data[a:b], time_ns, seq)
        if self._table_parts:
            self._keep_table_rows(channel, times, sequence, data, lengths)

    def _write_images(self) -> None:
        """Write the buffered images as chunk(s) of their own, after the small messages
        buffered so far (their detections)."""
        self._drain()
        if not self._images:
            return
        self._write_block(self._images)
        self._images.clear()
        self._image_bytes = 0
        self._mcap.flush()
        self._write_behind()

    def _queue_blocks(self, n: int, step: int, make, ahead: bool = False) -> int:
        """Write rows ``[0, n)`` as blocks ``make(lo, hi)`` of ``step`` rows, until ``make``
        gives None (a block that is not protobuf's bytes); the first row not written.

        ``ahead``: each block is made on a thread of its own while the one before is
        written (``make`` must only read its inputs): its encoding (compiled, GIL
        released) then runs while this thread waits for the chunks' compression and
        writes them, instead of after (a fused match's tracks: a gigabyte of messages)."""
        lo = 0
        if not ahead or n <= step:
            while lo < n:
                hi = min(lo + step, n)
                block = make(lo, hi)
                if block is None:
                    break
                self._pending.append(block)
                self._drain()
                self._maybe_flush()
                lo = hi
            return lo
        from concurrent.futures import ThreadPoolExecutor

        # (on an error or an interrupt here, leaving the with waits for the block being
        # made, one block's encoding: tens of milliseconds)
        with ThreadPoolExecutor(1, thread_name_prefix="pslog-encode") as ahead_pool:
            made = ahead_pool.submit(make, 0, min(step, n))
            while lo < n:
                hi = min(lo + step, n)
                block = made.result()
                if block is None:
                    break
                if hi < n:  # the next block made while this one is written
                    made = ahead_pool.submit(make, hi, min(hi + step, n))
                self._pending.append(block)
                del block
                self._drain()
                self._maybe_flush()
                lo = hi
        return lo

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self._flush_interval:  # never when inf
            self.flush()

    def _write_behind(self) -> None:
        """Start the OS's writeback of what was written since the last call, once that is
        at least :data:`_BEHIND_BYTES`, where the file is to replace an existing one (called
        as chunks are written: :meth:`_drain`, :meth:`_write_images`).

        Why: moved over an existing file (:meth:`close`), a file that still has data the OS
        has not placed on disk is written out first, inside the move (ext4's default
        ``auto_da_alloc``, so that a crash never leaves an empty file where the old one
        was): the whole file's writeback started at once, 0.4–0.5 s of waiting at the end of
        a fused 90-minute match (600 MB). Started here a few tens of MB at a time, while
        the file is written, it runs beside the work (the calls ~0.04 s of system time in
        all), and the move finds little left. The same bytes, the same file: only when its
        pages go to disk changes. ``POSIX_FADV_DONTNEED`` on pages just written starts
        their writeback and leaves them cached (dirty or being written pages are not
        dropped; pages the OS had written out already, in a run slower than its own
        writeback's 30 s, are); where the OS has no ``posix_fadvise`` nothing is done."""
        if self._behind is None:
            return
        try:
            fd = self._file.fileno()
            done = os.lseek(fd, 0, os.SEEK_CUR)  # (what the OS has, not what is buffered)
            if done - self._behind >= _BEHIND_BYTES:
                os.posix_fadvise(fd, self._behind, done - self._behind, os.POSIX_FADV_DONTNEED)
                self._behind = done
        except (AttributeError, OSError):  # no posix_fadvise (not POSIX), an odd stream
            self._behind = None

    def _camera_name(self, camera: int) -> str:
        if not 0 <= int(camera) < len(self._names):
            raise InputError(f"camera index {camera} out of range (rig has {len(self._names)})")
        return self._names[int(camera)]

    def _check_open(self) -> None:
        if self._closed:
            raise LogFormatError(f"{self.path}: writer is closed")
        if self._flush_error is not None:
            raise self._flush_failure()

    def _flush_failure(self) -> BaseException:
        """The error the background flusher met, to raise in the caller's thread."""
        exc = self._flush_error
        if isinstance(exc, PslogError):
            return exc
        if isinstance(exc, OSError):
            return self._os_fault(exc)
        return LogFormatError(f"{self.path}: writing failed: {exc}")

    def _os_fault(self, exc: OSError) -> WriteError:
        """Note that the OS refused a write (the MCAP stream is now cut short) and return the
        one-line error naming the output."""
        self._os_failed = True
        return write_error(self.path, exc)

    # ---- public -----------------------------------------------------------------------
    @_locked
    def add_frame(self, camera: int, frame_index: int, time_ns: int, uv=None, radius=None,
                  score=None, image: bytes | None = None, image_format: str = "jpeg") -> None:
        """One captured frame: its detection message (also with no candidate) and optionally
        its encoded image.

        Parameters
        ----------
        uv : (k, 2) float64 pixels, k >= 0; radius : (k,) pixels (NaN unknown);
        score : (k,) in [0, 1] (default 1)
        """
        self._check_open()
        name = self._camera_name(camera)
        uv = np.zeros((0, 2)) if uv is None else np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        k = len(uv)
        radius = np.full(k, np.nan) if radius is None else np.asarray(radius, np.float64)
        score = np.ones(k) if score is None else np.asarray(score, np.float64)
        if radius.shape != (k,) or score.shape != (k,):
            raise InputError(f"camera {name}: uv, radius and score differ in length")
        msg = S.DetectionFrame(time_ns=int(time_ns), camera=name, frame_index=int(frame_index),
                               u=uv[:, 0].tolist(), v=uv[:, 1].tolist(),
                               radius=radius.tolist(), score=score.tolist())
        self._queue(self._channel(S.detections_topic(name), S.DetectionFrame), time_ns,
                    msg.SerializeToString(deterministic=True), frame_index)
        self._count(S.detections_topic(name))
        if image is not None:
            self.add_image(camera, frame_index, time_ns, image, image_format)

    @_locked
    def add_detections(self, detections: Detections) -> None:
        """Every frame of ``detections`` (camera names must match the rig)."""
        self._check_open()
        if tuple(detections.camera_names) != self._names:
            raise InputError(f"detections are for cameras {', '.join(detections.camera_names)}, "
                             f"rig has {', '.join(self._names)}")
        if detections.n_frames and detections.frame_time_ns[0] < 0:
            raise InputError(_negative_time(int(detections.frame_time_ns[0])))
        channels = [self._channel(S.detections_topic(n), S.DetectionFrame) for n in self._names]
        self._add_frames(detections, channels)
        for i, name in enumerate(self._names):
            self._count(S.detections_topic(name),
                        int(np.count_nonzero(detections.frame_camera == i)))

    def _add_frames(self, detections: Detections, channels: list[int]) -> None:
        """A DetectionFrame message per frame of ``detections`` on ``channels[camera]``:
        blocks of frames encoded with numpy (:func:`_detections_block`), the per-frame
        protobuf way for the rest when a block's sample frames differ from protobuf's."""
        lo, n = 0, detections.n_frames
        if all(self._names) and n >= _BLOCK_FROM and detections.frame_index.min() >= 0:
            lo = self._queue_blocks(n, _FRAME_BLOCK, lambda a, b: _detections_block(
                detections, a, b, self._names, channels))
        if lo >= n:
            return
        # split candidate arrays per frame once (vectorised) instead of masking per frame
        bounds = np.searchsorted(detections.cand_frame, np.arange(detections.n_frames + 1))
        u = detections.cand_uv[:, 0].tolist()
        v = detections.cand_uv[:, 1].tolist()
        radius = detections.cand_radius.tolist()
        score = detections.cand_score.tolist()
        make = S.DetectionFrame
        for row, (t, cam, idx) in enumerate(zip(detections.frame_time_ns[lo:].tolist(),
                                                 detections.frame_camera[lo:].tolist(),
                                                 detections.frame_index[lo:].tolist(),
                                                 strict=True), start=lo):
            a, b = bounds[row], bounds[row + 1]
            msg = make(time_ns=t, camera=self._names[cam], frame_index=idx, u=u[a:b],
                       v=v[a:b], radius=radius[a:b], score=score[a:b])
            self._queue(channels[cam], t, msg.SerializeToString(deterministic=True), idx)

    @_locked
    def add_ball_truth(self, ball: Detections) -> None:
        """Which candidate of each frame is the ball (a simulated session's labels:
        :func:`pslog.simulation.simulate_labelled`): a ``pslog.DetectionFrame`` holding the
        ball's candidate on ``/truth/ball/<cam>`` for every frame where the ball was
        detected."""
        self._check_open()
        if tuple(ball.camera_names) != self._names:
            raise InputError(f"ball labels are for cameras {', '.join(ball.camera_names)}, "
                             f"rig has {', '.join(self._names)}")
        channels = [self._channel(S.ball_truth_topic(n), S.DetectionFrame) for n in self._names]
        for f, (u, v), r, s in zip(ball.cand_frame.tolist(), ball.cand_uv.tolist(),
                                   ball.cand_radius.tolist(), ball.cand_score.tolist(),
                                   strict=True):
            t, cam = int(ball.frame_time_ns[f]), int(ball.frame_camera[f])
            if t < 0:
                raise InputError(_negative_time(t))
            idx = int(ball.frame_index[f])
            msg = S.DetectionFrame(time_ns=t, camera=self._names[cam], frame_index=idx,
                                   u=[u], v=[v], radius=[r], score=[s])
            self._queue(channels[cam], t, msg.SerializeToString(deterministic=True), idx)
            self._count(S.ball_truth_topic(self._names[cam]))

    @_locked
    def add_rejections(self, method: str, rejections) -> None:
        """The candidates the gating stage rejected for ``method``'s track
        (:class:`pslog.fusion.gating.Rejections`), one ``pslog.Rejection`` each on
        ``/tracks/<method>/rejections``."""
        self._check_open()
        if not method or "/" in method:
            raise InputError(f"track method must be a non-empty name without '/', got {method!r}")
        channel = self._channel(S.rejections_topic(method), S.Rejection)
        names = self._names
        if len(rejections) and not 0 <= rejections.camera.min() <= rejections.camera.max() \
                < len(names):
            raise InputError(f"rejections of {method!r}: camera index out of range of the rig")
        n, lo = len(rejections), 0
        if (all(names) and n >= _BLOCK_FROM and rejections.frame_time_ns.min() >= 0
                and rejections.frame_index.min() >= 0):
            lo = self._queue_blocks(n, _FRAME_BLOCK, lambda a, b: _rejections_block(
                rejections, a, b, names, channel))
        for t, cam, idx, (u, v), score, reason in zip(
                rejections.frame_time_ns[lo:].tolist(), rejections.camera[lo:].tolist(),
                rejections.frame_index[lo:].tolist(), rejections.uv[lo:].tolist(),
                rejections.score[lo:].tolist(), rejections.reason_names()[lo:], strict=True):
            if t < 0:
                raise InputError(_negative_time(t))
            msg = S.Rejection(time_ns=t, camera=names[cam], frame_index=idx, u=u, v=v,
                              score=score, reason=reason)
            self._queue(channel, t, msg.SerializeToString(deterministic=True), idx)
        self._count(S.rejections_topic(method), len(rejections))

    @_locked
    def add_image(self, camera: int, frame_index: int, time_ns: int, data: bytes,
                  format: str = "jpeg") -> None:
        """An encoded frame (bytes stored as given) as foxglove.CompressedImage."""
        self._check_open()
        name = self._camera_name(camera)
        msg = S.CompressedImage(frame_id=name, data=bytes(data), format=format)
        S.set_timestamp(msg.timestamp, time_ns)
        self._add_image_raw(S.image_topic(name), int(time_ns), msg.SerializeToString(),
                            int(frame_index))

    @_locked
    def _add_image_raw(self, topic: str, time_ns: int, data: bytes, sequence: int) -> None:
        if time_ns < 0:
            raise InputError(_negative_time(time_ns))
        channel = self._channel(topic, S.CompressedImage)
        self._images.append((channel, time_ns, data, sequence))
        self._image_bytes += len(data)
        self._count(topic)
        if self._image_bytes >= _IMAGE_CHUNK_BYTES:
            self._write_images()
        self._maybe_flush()

    @_locked
    def _add_foreign(self, topic: str, schema, channel, time_ns: int, data: bytes,
                     sequence: int) -> None:
        """Copy a message of any channel (``_mcapio.SchemaRec``/``ChannelRec``) as is."""
        cid = self._foreign_channel(topic, schema, channel)
        self._queue(cid, time_ns, data, sequence)
        self._count(topic)

    @_locked
    def _add_block(self, block: _Block, topics: dict[int, str], images: bool = False
                   ) -> None:
        """Copy messages at once, as they are: ``block``'s channels are this writer's
        (:meth:`_foreign_channel`), ``topics`` their topics; ``images``: written after the
        small messages, as :meth:`add_image` does. Sessions are copied a chunk at a time so."""
        self._check_open()
        if len(block.time) and block.time.min() < 0:
            raise InputError(_negative_time(int(block.time.min())))
        ids, counts = np.unique(block.channel, return_counts=True)
        for cid, k in zip(ids.tolist(), counts.tolist(), strict=True):
            self._count(topics[cid], k)
        if images:
            self._images.append(block)
            self._image_bytes += len(block.data)
            if self._image_bytes >= _IMAGE_CHUNK_BYTES:
                self._write_images()
        else:
            self._pending.append(block)
            self._drain()
        self._maybe_flush()

    @_locked
    def _add_raw_chunk(self, record, indexes, index_offsets: dict[int, int],
                       counts: dict[int, int], start_time: int, end_time: int,
                       topics: dict[int, str]) -> None:
        """Copy a chunk of another session as it is (:func:`._chunks.write_raw_chunk`):
        every channel of it registered here with its id there, ``topics`` their topics,
        ``counts`` their messages in it. Whatever is buffered is written first (file order
        as the messages came)."""
        self._check_open()
        self._write_images()
        _chunks.write_raw_chunk(self._mcap, record, indexes, index_offsets, counts,
                                start_time, end_time)
        for cid, k in counts.items():
            self._count(topics[cid], k)
        self._maybe_flush()

    def _foreign_channel(self, topic: str, schema, channel) -> int:
        """This writer's channel of ``topic`` (registered from a copied file's records, a
        ``_mcapio.SchemaRec`` or None and a ``_mcapio.ChannelRec``, if new)."""
        cid = self._channels.get(topic)
        if cid is None:
            sid = 0
            if schema is not None:
                # our own schemas are shared; anything else is registered once per content
                key = (schema.name if schema.name in S.SCHEMAS
                       else f"{schema.encoding}:{schema.name}:{hash(schema.data)}")
                sid = self._schema_ids.get(key, 0)
                if not sid:
                    sid = self._schema_ids[key] = self._mcap.register_schema(
                        schema.name, schema.encoding, schema.data)
            cid = self._register_channel(topic, channel.encoding, sid,
                                         {**channel.metadata,
                                          **self.channel_metadata.get(topic, {})})
            self._channels[topic] = cid
            self._note_channel(topic, cid)
        return cid

    @_locked
    def add_truth(self, truth: Truth) -> None:
        """Ground-truth positions (world metres), one ``pslog.TruthPoint`` per sample."""
        self._check_open()
        if len(truth) and truth.time_ns[0] < 0:
            raise InputError(_negative_time(int(truth.time_ns[0])))
        channel = self._channel(S.TRUTH_TOPIC, S.TruthPoint)
        make = S.TruthPoint
        for t, (x, y, z) in zip(truth.time_ns.tolist(), truth.position_world.tolist(),
                                strict=True):
            self._queue(channel, t, make(time_ns=t, x=x, y=y, z=z).SerializeToString())
        self._count(S.TRUTH_TOPIC, len(truth))

    @_locked
    def add_track(self, track: Track, *, left_out: Mapping[str, int] | None = None,
                  last: bool = False, fused_with: Mapping[str, str] | None = None) -> None:
        """A fused track: ``pslog.TrackPoint`` per point on ``/tracks/<method>`` and a
        Foxglove-viewable ``foxglove.SceneUpdate`` sphere per point on its ``/scene`` topic.

        ``left_out``: the points the method left out, by reason (``Track.dropped``), kept in
        the metadata of the track's channel (:data:`pslog.log._schemas.LEFT_OUT_KEY`): only
        with the first part of a track. ``last``: no more points of this method follow: its
        columnar table is written now, right after its messages, and the writer keeps none
        of its tracks (not at close: ``pslog fuse`` writes each method's track as the
        method ends, the fusion of the others going on meanwhile). ``fused_with``: the
        choices that shaped its points (option name: value), in the same metadata
        (:data:`pslog.log._schemas.FUSED_WITH_KEY`), with the first part too."""
        self._check_open()
        method = track.method
        if not method or "/" in method:
            raise InputError(f"track method must be a non-empty name without '/', got {method!r}")
        if table.track_table(method) in self._tables_written:
            raise InputError(f"track {method!r} was added with last=True already")
        if left_out is not None or fused_with is not None:
            topic = S.track_topic(method)
            if topic in self._channels:
                raise InputError(f"track {method!r}: left-out counts and settings go with "
                                 "its first part")
            meta = {}
            if left_out is not None:
                meta[S.LEFT_OUT_KEY] = json.dumps(
                    {str(k): int(v) for k, v in dict(left_out).items()}, sort_keys=True)
            if fused_with is not None:
                meta[S.FUSED_WITH_KEY] = json.dumps(
                    {str(k): str(v) for k, v in dict(fused_with).items()}, sort_keys=True)
            self.channel_metadata[topic] = meta
        if method not in self._track_methods:
            self._track_methods.append(method)
        color = track_color(method)
        channel = self._channel(S.track_topic(method), S.TrackPoint)
        scene_channel = self._channel(S.track_scene_topic(method), S.SceneUpdate)
        n = len(track)
        nan = np.full(n, np.nan)  # (arrays: lists of a match's floats were ~100 MB)
        fixed = {k: (np.asarray(track.quality[k], dtype=np.float64) if k in track.quality
                     else nan) for k in S.TRACK_FIXED_QUALITY}
        extra = {k: np.asarray(v, dtype=np.float64) for k, v in track.quality.items()
                 if k not in S.TRACK_FIXED_QUALITY}
        if n and track.time_ns.min() < 0:
            raise InputError(_negative_time(int(track.time_ns.min())))
        if n and not 0 <= track.camera.min() <= track.camera.max() < len(self._names):
            raise InputError(f"track {method!r}: camera index out of range of the rig")
        direct = self._direct_track(channel, S.track_topic(method))
        first_id = self._scene_ids.get(method, 0)
        # a block of points at a time, every message's bytes made with numpy (_encode) and
        # written as one block: a Python object per point was most of the time of writing a
        # fused match; each block is checked against protobuf on sample points, and any
        # difference sends the rest of the track the per-point way
        template = _quality_template(extra)
        lo = 0
        if template is not None and all(self._names) and n >= _BLOCK_FROM:
            lo = self._queue_blocks(n, _TRACK_BLOCK, lambda a, b: _track_block(
                track, a, b, method, self._names, fixed, template, first_id, color, channel,
                scene_channel, records=self._bulk), ahead=True)
        self._add_track_points(track, lo, n, method, fixed, extra, first_id, color, channel,
                               scene_channel)
        self._scene_ids[method] = first_id + n
        if direct is not None:
            direct.append(track)
            name = table.track_table(method)
            if last and self._adopted.get(name) is None:
                # (the messages of this track are buffered or written: the table names as
                # many, as a table written at close does)
                parts = table.encode_parts(name, self._names, {S.track_topic(method): sum(
                    len(x) for x in direct)}, table.track_columns_of(direct))
                if self._bulk:
                    _chunks.write_attachment(self._mcap, name, table.MEDIA_TYPE, parts)
                else:
                    self._mcap.add_attachment(0, 0, name, table.MEDIA_TYPE, b"".join(parts))
                del parts
                self._tables_written.add(name)
                direct.clear()  # the tracks go with their caller's references
        self._count(S.track_topic(method), n)
        self._count(S.track_scene_topic(method), n)

    def _add_track_points(self, track: Track, lo: int, hi: int, method: str, fixed: dict,
                          extra: dict, first_id: int, color, channel: int,
                          scene_channel: int) -> None:
        """Points ``lo:hi`` of a track, one protobuf message at a time."""
        if lo >= hi:
            return
        cameras = self._names
        # the quality map's bytes of every point at once (setting its keys one point at a
        # time was most of the cost of writing a track); None: the per-point way
        entries = _quality_entries({k: v[lo:hi] for k, v in extra.items()}, hi - lo)
        fixed = {k: v[lo:hi].tolist() for k, v in fixed.items()}
        for j, (t, (x, y, z), cam) in enumerate(zip(
                track.time_ns[lo:hi].tolist(), track.position_world[lo:hi].tolist(),
                track.camera[lo:hi].tolist(), strict=True)):
            i = lo + j
            msg = S.TrackPoint(time_ns=t, method=method, x=x, y=y, z=z, camera=cameras[cam],
                               **{k: fixed[k][j] for k in S.TRACK_FIXED_QUALITY})
            if entries is not None:
                data = msg.SerializeToString(deterministic=True) + next(entries)
                if j == 0:  # the same bytes as protobuf's own, checked on the first point
                    for k, values in extra.items():
                        msg.quality[k] = float(values[i])
                    if msg.SerializeToString(deterministic=True) != data:
                        entries = None
                        data = msg.SerializeToString(deterministic=True)
            else:
                for k, values in extra.items():
                    msg.quality[k] = float(values[i])
                data = msg.SerializeToString(deterministic=True)
            self._queue(channel, t, data)
            self._queue(scene_channel, t, scene_point(method, first_id + i, t, (x, y, z), color))

    @_locked
    def add_event(self, time_ns: int, text: str, camera: int | None = None,
                  level: str = "info") -> None:
        """A note in the log (``foxglove.Log`` on ``/events``), e.g. a camera that stopped."""
        self._check_open()
        if level not in _LOG_LEVELS:
            raise InputError(f"unknown event level {level!r} (have {', '.join(_LOG_LEVELS)})")
        msg = S.Log(level=cast("S.Log.Level.ValueType", _LOG_LEVELS[level]), message=str(text),
                    name="pslog" if camera is None else self._camera_name(camera))
        S.set_timestamp(msg.timestamp, time_ns)
        self._queue(self._channel(S.EVENTS_TOPIC, S.Log), time_ns, msg.SerializeToString())
        self._count(S.EVENTS_TOPIC)

    @_locked
    def flush(self) -> None:
        """Write everything buffered to the file now: the small messages (detections,
        events, truth, tracks) first, then the images. Images are much larger: on a disk
        that fills up, the write that fails is nearly always an image chunk, and every
        detection buffered until then is already written (``pslog recover`` keeps them)."""
        self._write_images()
        # hand the bytes to the OS too: a killed process loses nothing the OS has, and a
        # full disk is met now rather than at close
        self._file.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Flush and finish the file (summary, indexes, footer), then put it in place.
        Idempotent. Raises WriteError if the OS refused a write; a failed discard-mode
        writer leaves nothing, a failed keep-mode writer keeps what it wrote.

        Ctrl-C and SIGTERM are held while it runs (in the main thread): a KeyboardInterrupt
        raised half-way (waiting for the flusher, between finishing and moving the file)
        would leave the ``.partial`` behind; one that came meanwhile is raised after."""
        with _signals_held():
            self._close()

    def _close(self) -> None:
        self._stop.set()
        flusher = getattr(self, "_flusher", None)
        if flusher is not None and flusher is not threading.current_thread():
            flusher.join()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            _OPEN.discard(self)
            error: BaseException | None = None
            if self._flush_error is not None and not self._failed:
                error = self._flush_failure()
            elif self._flush_error is not None and isinstance(self._flush_error, OSError):
                self._os_failed = True
            # finish the stream unless it is thrown away or cut short by the OS (appending
            # after a failed write would put records after a torn one)
            finish = not self._os_failed and error is None and not (
                self._discard and (self._failed or self._aborted))
            try:
                if finish:
                    self._write_images()
                    self._write_tables()
                    self._mcap.finish()
            except OSError as exc:
                error = self._os_fault(exc)
            except BaseException as exc:
                error = exc
            try:
                self._file.flush()  # the last buffered bytes, before the file is moved
            except OSError as exc:
                if error is None and not self._failed:
                    error = self._os_fault(exc)
            failed = self._failed or error is not None
            # moved or removed while still open, i.e. locked: another run never takes a
            # finished partial for a stale one
            try:
                if self._discard and (failed or self._aborted):
                    self.target.unlink(missing_ok=True)
                elif self.target != self.path and not failed:
                    if self._aborted:
                        self.target.unlink(missing_ok=True)  # the old session stays
                    else:
                        old = _held(self.path) if self._replaces else None
                        try:
                            self.target.replace(self.path)
                        finally:
                            _release(old)
            except OSError as exc:
                if error is None and not self._failed:
                    error = write_error(self.path, exc)
            with contextlib.suppress(OSError):  # a failed flush above already said why
                self._file.close()
            if error is not None and not self._failed:
                raise error

    def abort(self) -> None:
        """Close without replacing an existing session (a new keep-mode file is still
        finished, so whatever was written stays readable; a discard-mode one is removed)."""
        self._aborted = True
        self.close()

    def _count(self, topic: str, n: int = 1) -> None:
        self.counts[topic] = self.counts.get(topic, 0) + n

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        # finish the file even on an exception: whatever was written stays readable; but an
        # existing session is only replaced by a run that completed
        if exc_type is not None:
            self._failed = True
        self.close()


def _held(path) -> int | None:
    """A descriptor of the file ``path`` (read only), or None: held across the move of a new
    file over it, the old file is released by :func:`_release` and not inside the move."""
    if os.name != "posix":  # (elsewhere a file open is not replaced)
        return None
    try:
        return os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return None


def _release(fd: int | None) -> None:
    """Close ``fd`` (from :func:`_held`) on a thread of its own: the last name of the file
    gone, its close gives the file's blocks back (0.2 s of waiting for a 600 MB file on
    ext4), while this thread goes on (``pslog fuse``'s report and exit)."""
    if fd is None:
        return
    try:
        threading.Thread(target=os.close, args=(fd,), name="pslog-release",
                         daemon=True).start()
    except RuntimeError:  # (no thread to be had: closed here)
        os.close(fd)


#: the writers whose file is open (see :func:`close_abandoned`)
_OPEN: weakref.WeakSet[SessionWriter] = weakref.WeakSet()


def close_abandoned() -> None:
    """Close every writer still open as if its ``with`` block had failed (a discard-mode
    writer's ``.partial`` removed, a keep-mode file finished with what it holds). For the
    command line's Ctrl-C/SIGTERM handler: an interrupt that lands between a writer's
    construction and its ``with`` block (or its caller's ``try``) leaves nobody else to
    close it."""
    for writer in list(_OPEN):
        writer._failed = True
        with contextlib.suppress(BaseException):
            writer.close()


#: True while :func:`_signals_held` holds the interrupts (blocks nest)
_HOLDING = False


@contextlib.contextmanager
def _signals_held():
    """Hold SIGINT, SIGTERM and SIGHUP for the block's length (in the main thread): a signal
    that came meanwhile is delivered (its handler raising) when the block ends.

    Masking the main thread alone is not enough: the kernel hands a process-directed signal to
    any thread that does not block it (the writer's flush and compression threads), and
    CPython then runs the Python handler in the main thread all the same. So the handlers
    themselves are swapped for one that notes the signal, and the noted signals are raised
    again, with the previous handlers back, when the block ends. An ignored signal (``nohup``)
    stays ignored; the mask stays too, so that no system call of the block sees EINTR."""
    import signal

    global _HOLDING
    if (_HOLDING or threading.current_thread() is not threading.main_thread()
            or not hasattr(signal, "pthread_sigmask")):
        yield
        return
    came: list[int] = []
    previous: dict[int, Any] = {}
    held = [True]

    def note(signum, _frame) -> None:
        if held[0]:
            if signum not in came:
                came.append(signum)
            return
        # left in place by a restore that a signal cut short: the previous handler's turn
        signal.signal(signum, previous[signum])
        signal.raise_signal(signum)

    watched = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, set(watched))
    _HOLDING = True
    try:
        for sig in watched:
            handler = signal.getsignal(sig)
            if handler is not signal.SIG_IGN and handler is not None:
                previous[sig] = signal.signal(sig, note)
        yield
    finally:
        _HOLDING = False
        held[0] = False
        error: BaseException | None = None
        for sig, handler in previous.items():
            try:
                signal.signal(sig, handler)
            except BaseException as exc:  # a signal that came just now, raised by its handler
                error = error or exc
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)  # one still pending in the
        # main thread is delivered here, to its own handler
        if error is not None:
            raise error
        # the first raised ends the block: a termination (SIGTERM, SIGHUP) before a Ctrl-C
        for sig in sorted(came, key=lambda s: s == signal.SIGINT):
            signal.raise_signal(sig)


class _Block:
    """Messages written at once: ``channel``, ``time`` (ns), ``seq`` and ``length`` (n,)
    int64 columns, ``data`` their payloads back to back."""

    __slots__ = ("channel", "data", "length", "records", "seq", "time")

    def __init__(self, channel, time, seq, length, data: Any, records: bool = False
                 ) -> None:  # data: bytes, or a uint8 array (records)
        self.channel, self.time, self.seq, self.length, self.data = (
            channel, time, seq, length, data)
        #: ``data`` holds whole MCAP Message records (each message after its 31-byte head,
        #: as :func:`._wire.encode_track` writes them), not the payloads alone
        self.records = records

    def plain(self) -> _Block:
        """The same messages with ``data`` their payloads alone (a records block's heads
        dropped)."""
        if not self.records:
            return self
        buf = memoryview(self.data).cast("B")
        ends = np.cumsum(self.length + _HEAD_BYTES)
        return _Block(self.channel, self.time, self.seq, self.length, b"".join(
            buf[e - n:e] for e, n in zip(ends.tolist(), self.length.tolist(), strict=True)))

    @classmethod
    def of(cls, messages: list[tuple[int, int, bytes, int]]) -> _Block:
        """The block of ``(channel, time, data, sequence)`` tuples."""
        n = len(messages)
        return cls(np.fromiter((m[0] for m in messages), dtype=np.int64, count=n),
                   np.fromiter((m[1] for m in messages), dtype=np.int64, count=n),
                   np.fromiter((m[3] for m in messages), dtype=np.int64, count=n),
                   np.fromiter((len(m[2]) for m in messages), dtype=np.int64, count=n),
                   b"".join([m[2] for m in messages]))


#: bytes of an MCAP Message record before its payload (opcode, length, channel, sequence,
#: log and publish time)
_HEAD_BYTES = 31
#: track points encoded and written at a time (bounded memory: a few hundred bytes a point)
_TRACK_BLOCK = 1 << 14

#: the bytes written between two starts of their writeback
#: (:meth:`SessionWriter._write_behind`)
_BEHIND_BYTES = 32 << 20
#: points of each block checked against protobuf's own serialization
_TRACK_CHECKS = 8


#: frames encoded and written at a time
_FRAME_BLOCK = 1 << 15
#: fewer points or frames than this (a live batch) are encoded one by one: numpy's fixed
#: cost per block would outweigh it
_BLOCK_FROM = 256


def _detections_block(detections: Detections, lo: int, hi: int, names, channels):
    """Frames ``lo:hi`` of ``detections`` as one :class:`_Block` of DetectionFrame messages
    on ``channels[camera]`` (as :meth:`SessionWriter.add_detections` queued them one by one),
    encoded with :mod:`._encode`; None when sample frames differ from protobuf's bytes."""
    from . import _encode as E

    make = S.DetectionFrame
    n = hi - lo
    t = detections.frame_time_ns[lo:hi].astype(np.int64)
    cam = detections.frame_camera[lo:hi].astype(np.int64)
    idx = detections.frame_index[lo:hi].astype(np.int64)
    bounds = np.searchsorted(detections.cand_frame, np.arange(lo, hi + 1))
    first, k = bounds[:-1], np.diff(bounds)
    cols = [np.ascontiguousarray(detections.cand_uv[:, 0], dtype="<f8"),
            np.ascontiguousarray(detections.cand_uv[:, 1], dtype="<f8"),
            np.ascontiguousarray(detections.cand_radius, dtype="<f8"),
            np.ascontiguousarray(detections.cand_score, dtype="<f8")]
    name_len = np.array([len(c.encode()) for c in names], dtype=np.int64)

    def encode(r):
        m = len(r)
        width = int(k[r].max()) if m else 0
        pieces = [E.field_varint(1, t[r]), E.field_strings(2, cam[r], list(names)),
                  E.field_varint(3, np.maximum(idx[r], 0))]
        if width:
            take = first[r][:, None] + np.arange(width)
            for j, c in enumerate(cols):
                raw = c[take].view(np.uint8).reshape(m, 8 * width)
                pieces.append(E.field_message(4 + j, (raw, 8 * k[r])))
        return E.concat(pieces)

    key = (E.varint_size(t) * (t != 0) + 11 * (E.varint_size(idx) * (idx != 0)
           + 11 * (name_len[cam] + 64 * k)))
    data, lengths = E.grouped(key, encode)
    ends = np.cumsum(lengths)
    starts = ends - lengths
    for j in sorted({0, n - 1, *np.linspace(0, n - 1, _TRACK_CHECKS).astype(int).tolist()}):
        a, b = bounds[j], bounds[j + 1]
        msg = make(time_ns=int(t[j]), camera=names[int(cam[j])], frame_index=int(idx[j]),
                   u=cols[0][a:b].tolist(), v=cols[1][a:b].tolist(),
                   radius=cols[2][a:b].tolist(), score=cols[3][a:b].tolist())
        if data[starts[j]:ends[j]] != msg.SerializeToString(deterministic=True):
            return None
    return _Block(np.asarray(channels, dtype=np.int64)[cam], t, idx, lengths, data)


def _rejections_block(rejections, lo: int, hi: int, names, channel: int):
    """Rows ``lo:hi`` of :class:`pslog.fusion.gating.Rejections` as one :class:`_Block` of
    ``pslog.Rejection`` messages (as :meth:`SessionWriter.add_rejections` queued them one by
    one), encoded with :mod:`._encode`; None when sample rows differ from protobuf's bytes
    (times and frame indices >= 0, camera names non-empty: checked by the caller)."""
    from ..fusion.gating import REASONS
    from . import _encode as E

    n = hi - lo
    t = rejections.frame_time_ns[lo:hi].astype(np.int64)
    cam = rejections.camera[lo:hi].astype(np.int64)
    idx = rejections.frame_index[lo:hi].astype(np.int64)
    uv = np.ascontiguousarray(rejections.uv[lo:hi], dtype=np.float64)
    score = np.ascontiguousarray(rejections.score[lo:hi], dtype=np.float64)
    reason = rejections.reason[lo:hi].astype(np.int64)
    data, lengths = E.rows(E.concat([
        E.field_varint(1, t), E.field_strings(2, cam, list(names)), E.field_varint(3, idx),
        E.field_double(4, uv[:, 0]), E.field_double(5, uv[:, 1]), E.field_double(6, score),
        E.field_strings(7, reason, list(REASONS))]))
    ends = np.cumsum(lengths)
    for j in sorted({0, n - 1, *np.linspace(0, n - 1, _TRACK_CHECKS).astype(int).tolist()}):
        want = S.Rejection(time_ns=int(t[j]), camera=names[int(cam[j])],
                           frame_index=int(idx[j]), u=float(uv[j, 0]), v=float(uv[j, 1]),
                           score=float(score[j]), reason=REASONS[int(reason[j])])
        if data[ends[j] - lengths[j]:ends[j]] != want.SerializeToString(deterministic=True):
            return None
    return _Block(np.full(n, channel, dtype=np.int64), t, idx, lengths, data)


def _quality_template(extra: dict[str, np.ndarray]):
    """``(template, slots)`` of a TrackPoint's quality map entries (see
    :func:`_quality_entries`): the bytes of one point's entries with each key's value at
    ``slots[key]``; None when the map is not of the usual form."""
    probe = S.TrackPoint()
    for k in extra:
        probe.quality[k] = 1.0
    raw = probe.SerializeToString(deterministic=True)
    template, slots, at = bytearray(), {}, 0
    while at < len(raw):
        if at + 4 > len(raw):
            return None
        length, klen = raw[at + 1], raw[at + 3]
        if (raw[at] != 0x52 or raw[at + 2] != 0x0A or length >= 0x80 or klen >= 0x80
                or length != klen + 11 or raw[at + 4 + klen] != 0x11):
            return None
        slots[raw[at + 4:at + 4 + klen].decode("utf-8")] = len(template) + 5 + klen
        template += raw[at:at + 2 + length]
        at += 2 + length
    if sorted(slots) != sorted(extra):
        return None
    return np.frombuffer(bytes(template), dtype=np.uint8), slots


def _track_block(track: Track, lo: int, hi: int, method: str, cameras, fixed: dict,
                 template, first_id: int, color, channel: int, scene_channel: int,
                 records: bool = False):
    """Points ``lo:hi`` of a track as one :class:`_Block` of messages (TrackPoint, then its
    SceneUpdate, per point, as :meth:`SessionWriter.add_track` queues them one by one),
    encoded by :func:`._wire.encode_track`; None when sample points differ from protobuf's
    bytes. ``records``: the block holds whole MCAP Message records (:attr:`_Block.records`),
    the messages' bytes the same."""
    n = hi - lo
    t = track.time_ns[lo:hi].astype(np.int64)
    xyz = np.ascontiguousarray(track.position_world[lo:hi], dtype=np.float64)
    cam = np.asarray(track.camera[lo:hi], dtype=np.int64)
    tmpl, slots = template
    # each key's values as IEEE bits, one column per key, put in place by the kernel
    keys = list(slots)
    quality = np.empty((n, len(keys)), dtype="<f8")
    for j, key in enumerate(keys):
        quality[:, j] = track.quality[key][lo:hi]
    fixed_cols = [np.asarray(fixed[k][lo:hi], dtype=np.float64) if len(fixed[k]) == len(track)
                  else np.full(n, np.nan) for k in S.TRACK_FIXED_QUALITY]
    ids = first_id + lo + np.arange(n, dtype=np.int64)
    lifetime, orientation, size, rgba = _scene_constants(tuple(float(v) for v in color))

    # every point's two messages by one compiled loop (_wire; numpy's per-field calls over
    # each layout group cost most of the time of writing a fused match)
    from . import _wire

    bits = np.column_stack([xyz, *fixed_cols]).view(np.uint64)
    names_b = [c.encode() for c in cameras]
    name_start = np.cumsum([0, *(len(x) for x in names_b)]).astype(np.int64)
    method_b = np.frombuffer(method.encode(), dtype=np.uint8)
    world_a, lifetime_a, orientation_a, size_a, rgba_a = consts = [
        np.frombuffer(x, dtype=np.uint8) for x in (S.WORLD_FRAME.encode(), lifetime,
                                                   orientation, size, rgba)]
    out = np.empty(_wire.bound(n, method.encode(), names_b, len(tmpl),
                               sum(len(x) for x in consts)), dtype=np.uint8)
    slot_at = np.array([slots[k] for k in keys], dtype=np.int64)
    point_len = np.empty(n, dtype=np.int64)
    lengths = np.empty(n, dtype=np.int64)
    channels = np.array([channel, scene_channel] if records else [-1, -1], dtype=np.int64)
    used = _wire.encode_track(t, np.ascontiguousarray(bits), cam,
                              np.frombuffer(b"".join(names_b), dtype=np.uint8), name_start,
                              method_b, tmpl, slot_at, quality.view(np.uint64), ids, world_a,
                              lifetime_a, orientation_a, size_a, rgba_a, channels, out,
                              point_len, lengths)
    # records: written from this buffer as it is (cut into chunks); else bytes of their own
    data = out[:used] if records else out[:used].tobytes()
    del out

    # protobuf's own bytes of sample points, compared
    gap = _HEAD_BYTES if records else 0
    ends = np.cumsum(lengths + 2 * gap)  # each point's end, its records' heads counted
    starts = ends - lengths - 2 * gap
    names = list(track.quality)
    for j in sorted({0, n - 1, *np.linspace(0, n - 1, _TRACK_CHECKS).astype(int).tolist()}):
        i = lo + j
        x, y, z = xyz[j].tolist()
        msg = S.TrackPoint(time_ns=int(t[j]), method=method, x=x, y=y, z=z,
                           camera=cameras[int(cam[j])],
                           **{k: float(c[j]) for k, c in zip(S.TRACK_FIXED_QUALITY, fixed_cols,
                                                             strict=True)})
        for k in names:
            if k not in S.TRACK_FIXED_QUALITY:
                msg.quality[k] = float(track.quality[k][i])
        point = msg.SerializeToString(deterministic=True)
        scene = scene_point(method, first_id + i, int(t[j]), (x, y, z), color)
        got = bytes(data[starts[j]:ends[j]])
        if point_len[j] != len(point) or lengths[j] != len(point) + len(scene) or (
                got[gap:gap + len(point)] != point or got[2 * gap + len(point):] != scene):
            return None
        if records and got[:gap] + got[gap + len(point):2 * gap + len(point)] != b"".join(
                _chunks.record_head(c, int(t[j]), len(m))
                for c, m in ((channel, point), (scene_channel, scene))):
            return None
    return _Block(np.tile(np.array([channel, scene_channel], dtype=np.int64), n),
                  np.repeat(t, 2), np.zeros(2 * n, dtype=np.int64),
                  np.column_stack([point_len, lengths - point_len]).ravel(), data,
                  records=records)


@functools.lru_cache(maxsize=64)
def _scene_constants(color: tuple[float, ...]) -> tuple[bytes, bytes, bytes, bytes]:
    """The encoded constant fields of a track's SceneUpdate spheres (lifetime, the pose's
    orientation, the sphere's size, ``color``'s RGBA), as :func:`scene_point` writes them."""
    from . import _encode as E

    lifetime = E.rows(E.field_message(4, E.concat([
        E.field_varint(1, np.array([_TRACK_LIFETIME_NS // 1_000_000_000])),
        E.field_varint(2, np.array([_TRACK_LIFETIME_NS % 1_000_000_000]))])))[0]
    orientation = E.rows(E.field_message(2, E.field_double(4, np.array([1.0]))))[0]
    size = E.rows(E.field_message(2, E.concat([E.field_double(k, np.array([_TRACK_SPHERE_M]))
                                                for k in (1, 2, 3)])))[0]
    rgba = E.rows(E.field_message(3, E.concat([E.field_double(k + 1, np.array([v]))
                                                for k, v in enumerate((*color, 1.0))])))[0]
    return lifetime, orientation, size, rgba


def _quality_entries(extra: dict[str, np.ndarray], n: int, block: int = 1 << 15):
    """The serialized ``quality`` map entries (field 10, the last field of a TrackPoint) of
    each of ``n`` points, one ``bytes`` per point from an iterator (made ``block`` points at a
    time: little memory); ``extra``: key -> (n,) values, set in this order as
    :meth:`SessionWriter.add_track` sets them. Every point has the same keys, set in the same
    order, so protobuf writes its entries in one order, found by serializing one map; each
    entry is ``0x52 len 0x0a klen key 0x11 <value, 8 bytes little endian>``. None when an
    entry is not of that form (a key of 117 bytes or more)."""
    if not extra or not n:
        return iter([b""] * n)
    found = _quality_template(extra)
    if found is None:
        return None
    return _entry_rows(found[0], found[1], extra, n, block)


def _entry_rows(template: np.ndarray, slots: dict[str, int], extra: dict[str, np.ndarray],
                n: int, block: int):
    width = len(template)
    for lo in range(0, n, block):
        hi = min(lo + block, n)
        rows = np.tile(template, (hi - lo, 1))
        for key, values in extra.items():
            rows[:, slots[key]:slots[key] + 8] = (np.asarray(values[lo:hi], dtype="<f8")
                                                  .view(np.uint8).reshape(hi - lo, 8))
        flat = rows.tobytes()
        del rows
        for at in range(0, len(flat), width):
            yield flat[at:at + width]


def _negative_time(time_ns: int) -> str:
    # MCAP log times are unsigned: the session clock must start at or after 0
    return f"time {time_ns} ns is before the session clock's zero; log times must be >= 0"


def camera_messages(cam, time_ns: int) -> list:
    """``(topic, message)`` of a camera's static messages: its foxglove.CameraCalibration and
    its foxglove.FrameTransform world -> camera, stamped ``time_ns`` (also used live)."""
    calib = S.CameraCalibration(
        frame_id=cam.name, width=cam.width, height=cam.height,
        distortion_model="plumb_bob", D=[float(d) for d in cam.dist],
        K=[float(k) for k in cam.K.ravel()],
        R=[float(r) for r in np.eye(3).ravel()],
        P=[float(p) for p in np.hstack([cam.K, np.zeros((3, 1))]).ravel()])
    S.set_timestamp(calib.timestamp, time_ns)
    world_from_cam = cam.world_from_cam
    q = S.quaternion_xyzw(world_from_cam[:3, :3])
    pose = S.FrameTransform(parent_frame_id=S.WORLD_FRAME, child_frame_id=cam.name)
    S.set_timestamp(pose.timestamp, time_ns)
    pose.translation.x, pose.translation.y, pose.translation.z = (
        float(x) for x in world_from_cam[:3, 3])
    pose.rotation.x, pose.rotation.y, pose.rotation.z, pose.rotation.w = (float(x) for x in q)
    return [(S.calibration_topic(cam.name), calib), (S.transform_topic(cam.name), pose)]


def scene_point(method: str, i: int, time_ns: int, xyz, color) -> bytes:
    """A serialized foxglove.SceneUpdate: the sphere of track point ``i`` (also used live)."""
    update = S.SceneUpdate()
    entity = update.entities.add(frame_id=S.WORLD_FRAME, id=f"{method}/{i}")
    S.set_timestamp(entity.timestamp, time_ns)
    entity.lifetime.seconds, entity.lifetime.nanos = divmod(_TRACK_LIFETIME_NS, 1_000_000_000)
    sphere = entity.spheres.add()
    sphere.pose.position.x, sphere.pose.position.y, sphere.pose.position.z = xyz
    sphere.pose.orientation.w = 1.0
    sphere.size.x = sphere.size.y = sphere.size.z = _TRACK_SPHERE_M
    sphere.color.r, sphere.color.g, sphere.color.b = color
    sphere.color.a = 1.0
    return update.SerializeToString(deterministic=True)

