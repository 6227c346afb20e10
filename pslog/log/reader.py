"""Read a pslog session MCAP: columnar detections, truth, tracks, events, never images
unless asked (:func:`iter_images`).

Speed: the summary's chunk index says which chunks hold which channels, so image chunks are
never read; detection chunks are decompressed whole and their messages sliced out with
``struct`` (see ``_mcapio``) and decoded with the generated protobuf class directly.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

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


@dataclass(frozen=True)
class Image:
    """One stored frame: ``data`` is the encoded bytes as stored (``format`` e.g. ``jpeg``)."""

    camera: int
    frame_index: int
    time_ns: int
    format: str
    data: bytes


class _Finished:
    """A finished session file opened for seeking: summary, metadata, rig."""

    def __init__(self, path) -> None:
        path, self.size, complete = io.check_file(path)
        self.path = path
        if not complete:
            raise io.truncated_error(path)
        from mcap.exceptions import McapError
        from mcap.reader import SeekingReader

        self.file = open(path, "rb")  # closed by close()
        try:
            reader = SeekingReader(self.file)
            summary = reader.get_summary()
            metadata = [(m.name, m.metadata) for m in reader.iter_metadata()]
        except (McapError, ValueError, EOFError, UnicodeDecodeError) as exc:
            self.file.close()
            raise LogFormatError(f"{path}: damaged MCAP summary ({exc}); "
                                 f"try 'pslog recover'") from None
        except Exception:
            self.file.close()
            raise
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

    def collect(self, topics: Sequence[str]) -> dict[str, list[tuple[int, int, bytes]]]:
        """``topic -> [(log_time, sequence, data), ...]`` in file order for ``topics``."""
        wanted = {cid: [] for cid, topic in self.topics.items() if topic in set(topics)}
        if not wanted:
            return {}
        chunks = self.summary.chunk_indexes
        if chunks:
            for index in sorted(chunks, key=lambda c: c.chunk_start_offset):
                if not wanted.keys() & index.message_index_offsets.keys():
                    continue  # e.g. an image chunk: never read
                self.file.seek(index.chunk_start_offset + 9)
                body = self.file.read(index.chunk_length - 9)
                io.collect_messages(io.chunk_payload(body), wanted)
        else:  # unchunked file written by another program: walk it all
            io.scan_file(self.path, lambda cid, t, seq, data: (
                wanted[cid].append((t, seq, data)) if cid in wanted else None))
        return {self.topics[cid]: msgs for cid, msgs in wanted.items()}


def read_session(path) -> Session:
    """Read a session MCAP without decoding images.

    Raises LogFormatError for a missing file, a non-MCAP, an MCAP that is not a pslog session,
    and a truncated file (pointing to ``pslog recover``).
    """
    with _Finished(path) as f:
        rig = f.rig
        det_topics = [S.detections_topic(n) for n in rig.names]
        track_topics = sorted(t for t in f.topics.values() if S.parse_track_topic(t))
        found = f.collect([*det_topics, S.TRUTH_TOPIC, S.EVENTS_TOPIC, *track_topics])
        detections = decode_detections(rig.names, [found.get(t, []) for t in det_topics])
        truth = decode_truth(found[S.TRUTH_TOPIC]) if S.TRUTH_TOPIC in found else None
        tracks = {}
        for topic in track_topics:
            method = S.parse_track_topic(topic)
            tracks[method] = decode_track(method, rig.names, found.get(topic, []))
        events = decode_events(found.get(S.EVENTS_TOPIC, []))
        n_images = sum(f.counts.get(S.image_topic(n), 0) for n in rig.names)
        return Session(path=f.path, rig=rig, detections=detections, truth=truth, tracks=tracks,
                       timing=f.meta.get("timing", "custom"), metadata=dict(f.meta),
                       events=events, n_images=n_images)


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
    extra: dict[str, np.ndarray] = {}
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
                extra.setdefault(key, np.full(n, np.nan))[i] = value
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
        parse = S.CompressedImage.FromString
        for _schema, channel, message in f.reader.iter_messages(
                topics=topics, starting_at=start_ns, ending_before=end_ns, log_time_order=True):
            m = parse(message.data)
            yield Image(camera_of[channel.topic], message.sequence, message.log_time,
                        m.format, m.data)
