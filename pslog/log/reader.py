"""Read a pslog session MCAP: columnar detections, truth, tracks, events, never images
unless asked (:func:`iter_images`).

Speed: the summary's chunk index says which chunks hold which channels, so image chunks are
never read; detection chunks are decompressed whole and their messages sliced out with
``struct`` (see ``_mcapio``) and decoded with the generated protobuf class directly.

Damage: the summary is checked against its CRC before it is trusted, and every chunk read is
checked (lengths, decompression, CRC, framing); a damaged one is a one-line LogFormatError
naming the file, the byte offset and ``pslog recover`` (which keeps every intact chunk).
"""

from __future__ import annotations

import heapq
import mmap
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError

from ..errors import LogFormatError
from ..records import Detections, Track, Truth
from ..rig import Rig
from . import _mcapio as io
from . import _schemas as S


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
    """The summary section or footer of a finished file is damaged (the data may be whole)."""

    def __init__(self, path, reason: str) -> None:
        super().__init__(f"{path}: damaged MCAP summary ({reason}); run 'pslog recover {path} "
                         f"-o FIXED.mcap' to salvage the data")
        self.reason = reason


class _Finished:
    """A finished session file opened for seeking: summary, metadata, rig."""

    def __init__(self, path, header: bool = True) -> None:
        # header=False: a damaged Header record is let through (pslog info reports it)
        path, self.size, complete = io.check_file(path, header)
        self.path = path
        if not complete:
            raise io.truncated_error(path)
        from mcap.reader import SeekingReader

        self.file = open(path, "rb")  # closed by close()
        try:
            # the summary's own CRC first: a damaged index would send reads astray
            with mmap.mmap(self.file.fileno(), 0, access=mmap.ACCESS_READ) as buf:
                checked = io.read_summary(buf)
                start, end = io.summary_span(buf)
            if checked is None:
                raise LogFormatError(f"summary section or footer, bytes {start}..{end}, fails "
                                     f"its checks")
            reader = SeekingReader(self.file)
            summary = reader.get_summary()
            metadata = [(m.name, m.metadata) for m in reader.iter_metadata()]
        except _SUMMARY_PARSE_ERRORS as exc:
            # what our checks and the mcap package raise on bytes they cannot parse; any
            # other exception is a bug, not damage, and propagates as it is
            self.file.close()
            raise DamagedSummaryError(path, str(exc) or type(exc).__name__) from None
        if summary is None:
            self.file.close()
            raise LogFormatError(f"{path}: MCAP has no summary section; try 'pslog recover'")
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
        stats = summary.statistics
        self.counts = ({} if stats is None else
                       {self.topics[c]: n for c, n in stats.channel_message_counts.items()
                        if c in self.topics})

    def close(self) -> None:
        self.file.close()

    def __enter__(self) -> _Finished:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def read_chunk(self, index) -> bytes:
        """The checked, decompressed records of the chunk of a ChunkIndex; a one-line
        LogFormatError naming the byte offset (and ``pslog recover``) if it is damaged."""
        try:
            return self._chunk(index)
        except LogFormatError as exc:
            raise io.damaged_error(self.path, index.chunk_start_offset, str(exc)) from None

    def _chunk(self, index) -> bytes:
        self.file.seek(index.chunk_start_offset)
        record = self.file.read(index.chunk_length)
        if len(record) != index.chunk_length or record[0] != io.OP_CHUNK or \
                int.from_bytes(record[1:9], "little") != index.chunk_length - 9:
            raise LogFormatError("chunk record does not match the summary's index")
        return io.chunk_payload(record[9:])

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
        wanted = {cid: [] for cid, topic in self.topics.items() if topic in set(topics)}
        if not wanted:
            return {}
        chunks = self.summary.chunk_indexes
        if chunks:
            for index in sorted(chunks, key=lambda c: c.chunk_start_offset):
                if not wanted.keys() & index.message_index_offsets.keys():
                    continue  # e.g. an image chunk: never read
                if index.chunk_start_offset in skip:
                    continue
                io.collect_messages(self.read_chunk(index), wanted)
        else:  # unchunked file written by another program: walk it all
            io.scan_file(self.path, lambda cid, t, seq, data: (
                wanted[cid].append((t, seq, data)) if cid in wanted else None))
        return {self.topics[cid]: msgs for cid, msgs in wanted.items()}


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
    found = f.collect([*det_topics, S.TRUTH_TOPIC, S.EVENTS_TOPIC, *track_topics,
                       *ball_topics, *rejection_topics], skip)
    try:
        detections = decode_detections(rig.names, [found.get(t, []) for t in det_topics])
        truth = decode_truth(found[S.TRUTH_TOPIC]) if S.TRUTH_TOPIC in found else None
        tracks = {}
        for topic in track_topics:
            method = S.parse_track_topic(topic)
            tracks[method] = decode_track(method, rig.names, found.get(topic, []))
        events = decode_events(found.get(S.EVENTS_TOPIC, []))
        ball_truth = (decode_detections(rig.names, [found.get(t, []) for t in ball_topics])
                      if any(t in found for t in ball_topics) else None)
        try:
            rejections = {S.parse_rejections_topic(t): decode_rejections(rig.names,
                                                                         found.get(t, []))
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
                   rejections=rejections)


def decode_detections(camera_names: Sequence[str],
                      per_camera: Sequence[list[tuple[int, int, bytes]]]) -> Detections:
    """Detections from each camera's ``(log_time, sequence, data)`` DetectionFrame messages.

    Hot path (one call per frame of a match): plain list appends, numpy at the end.
    """
    parse = S.DetectionFrame.FromString
    times, cams, frames, counts = [], [], [], []
    u, v, radius, score = [], [], [], []
    for cam, msgs in enumerate(per_camera):
        cams.append(np.full(len(msgs), cam, dtype=np.int32))
        for t, _seq, data in msgs:
            m = parse(data)
            times.append(t)
            frames.append(m.frame_index)
            k = len(m.u)
            counts.append(k)
            if k:
                u.extend(m.u)
                v.extend(m.v)
                radius.extend(m.radius)
                score.extend(m.score)
    counts = np.asarray(counts, dtype=np.int64)
    n_cand = int(counts.sum())
    if not (len(u) == len(v) == len(radius) == len(score) == n_cand):
        raise LogFormatError("detection message with candidate arrays of unequal length")
    return Detections.from_frames(
        tuple(camera_names), np.asarray(times, dtype=np.int64),
        np.concatenate(cams) if cams else np.zeros(0, np.int32),
        np.asarray(frames, dtype=np.int64), np.repeat(np.arange(len(counts)), counts),
        np.column_stack([u, v]) if n_cand else np.zeros((0, 2)),
        np.asarray(radius, dtype=np.float64), np.asarray(score, dtype=np.float64))


def decode_truth(msgs: list[tuple[int, int, bytes]]) -> Truth:
    parse = S.TruthPoint.FromString
    times, xyz = [], []
    for t, _seq, data in msgs:
        m = parse(data)
        times.append(t)
        xyz.append((m.x, m.y, m.z))
    times = np.asarray(times, dtype=np.int64)
    order = np.argsort(times, kind="stable")
    return Truth(times[order], np.asarray(xyz, dtype=np.float64).reshape(-1, 3)[order])


def decode_track(method: str, camera_names: Sequence[str],
                 msgs: list[tuple[int, int, bytes]]) -> Track:
    """A Track from its TrackPoint messages. Fixed quality fields that are NaN at every
    point are left out (the writer stores NaN for fields a track does not have)."""
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
                     if camera.keys() & c.message_index_offsets.keys()
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
        found = {cid: [] for cid in camera}
        io.collect_messages(f.read_chunk(chunks[i]), found)
        for cid, msgs in found.items():
            for t, seq, data in msgs:
                if lo <= t < hi:
                    heapq.heappush(pending, (t, order, camera[cid], seq, data))
                    order += 1


def parse_image(data: bytes, path) -> S.CompressedImage:
    from google.protobuf.message import DecodeError

    try:
        return S.CompressedImage.FromString(data)
    except DecodeError as exc:  # only a chunk written without CRCs can get here damaged
        raise LogFormatError(f"{path}: an image does not decode ({exc}); run 'pslog recover "
                             f"{path} -o FIXED.mcap' to salvage the rest") from None
