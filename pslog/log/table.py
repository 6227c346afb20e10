"""Columnar tables of a session: its detections, ball labels, ground truth and fused tracks
(one table per method) as little-endian numpy columns in MCAP attachments, written when the
session closes (format: docs/log-format.md, "Columnar tables").

A 90-minute match holds half a million detection messages; decoding them is most of the
time of reading a session. The same data as a few arrays reads at memory speed. The per-frame
messages stay in the file (streaming tools such as Foxglove read those); a table is only used
when it agrees with them (the per-topic message counts it names equal the summary's
statistics summed over each topic's channels, it holds one row per message counted, its
attachment CRC holds, its columns have the documented dtypes and shapes), else the reader
decodes the messages, as it does for files written before tables existed. Counts are all the
summary tells about the messages: a tool that rewrites messages without changing their
number must drop these attachments (docs/log-format.md; ``pslog recover`` rebuilds them).

An attachment's data: a 4-byte little-endian header length ``H``, ``H`` bytes of UTF-8
JSON (the header), zero bytes up to a multiple of 8, then each column's bytes at the
``offset`` (from the end of that padding) the header gives, zstd-compressed or raw.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import cast

import numpy as np

from ..errors import LogFormatError
from . import _schemas as S

#: the attachments' names (one attachment per table) and media type
DETECTIONS = "pslog/table/detections"
BALL_TRUTH = "pslog/table/ball_truth"
TRUTH = "pslog/table/truth"
TABLES = (DETECTIONS, BALL_TRUTH, TRUTH)
#: a fused track's table: this prefix and the method name (one table per track topic)
TRACK_PREFIX = "pslog/table/track/"
MEDIA_TYPE = "application/vnd.pslog.table"
#: ``format`` and ``version`` of the header: a reader refuses (falls back on) any other
FORMAT = "pslog.table"
VERSION = 1

#: each table's columns: name -> (dtype, trailing shape); the leading dimension is the
#: number of frames (``frame_*``), candidates (``cand_*``) or samples (truth)
_DETECTION_COLUMNS = {
    "frame_time_ns": ("<i8", ()), "frame_camera": ("<i4", ()), "frame_index": ("<i8", ()),
    "cand_frame": ("<i8", ()), "cand_uv": ("<f8", (2,)), "cand_radius": ("<f8", ()),
    "cand_score": ("<f8", ()),
}
COLUMNS = {
    DETECTIONS: _DETECTION_COLUMNS,
    BALL_TRUTH: _DETECTION_COLUMNS,
    TRUTH: {"time_ns": ("<i8", ()), "position_world": ("<f8", (3,))},
}
#: a track table's fixed columns (leading dimension: the track's points); each per-point
#: quality column follows as ``quality/<name>``, ``<f8``, in the order of the Track's
#: ``quality`` mapping (the map order of the first point's message: protobuf's deterministic,
#: key-sorted form, as the writer serialises it)
TRACK_COLUMNS = {"time_ns": ("<i8", ()), "position_world": ("<f8", (3,)),
                 "camera": ("<i4", ())}
QUALITY_PREFIX = "quality/"
#: columns smaller than this are stored raw (a zstd frame would not pay off); so are columns
#: zstd shrinks by less than 10 %
_COMPRESS_FROM = 4096
#: a column of at least this many bytes is first tried on a sample (:func:`_sample`): one
#: whose sample zstd shrinks by less than 10 % (:data:`_SAMPLE_GAIN`) is stored raw without
#: compressing the whole column (noisy doubles: most quality columns of a fused track, 0.1
#: CPU s a track of a 90-minute match spent on frames thrown away). The choice depends on
#: the bytes alone: the same column is always stored alike
_SAMPLE_FROM = 1 << 18
#: the sample's compressed size, relative, from which a long column is stored raw: the
#: share a whole column is kept compressed below (0.9). It was 0.95 until session 21: on
#: the fused 90-minute match 40 of the four track tables' 56 columns had samples shrunk by
#: 5-8 %, were compressed whole (0.24 CPU s) and stored raw all the same (the whole shrunk
#: as little: each whole ratio within 0.01 of its sample's); no column's sample was between
#: 0.886 and 0.917, so the match's tables are the same bytes either way. A column whose
#: sample shrinks by 5-10 % but whose whole would shrink by more is now stored raw (the
#: same values; readers take either codec)
_SAMPLE_GAIN = 0.9
#: the sample: this many bytes from the start, the middle and the end of the column
_SAMPLE_BYTES = 1 << 15


def track_table(method: str) -> str:
    """The name of the table of track ``method``."""
    return TRACK_PREFIX + method


def track_method(table: str) -> str | None:
    """The method whose track table ``table`` is, or None (not a track table)."""
    if table.startswith(TRACK_PREFIX) and len(table) > len(TRACK_PREFIX):
        return table[len(TRACK_PREFIX):]
    return None


def _columns_of(table: str, names: Sequence[str]) -> dict[str, tuple[str, tuple]]:
    """``name -> (dtype, trailing shape)`` of ``table`` given its column ``names`` (a track
    table's quality columns are the track's own; every other table's are fixed)."""
    if track_method(table) is None:
        return COLUMNS[table]
    return {**TRACK_COLUMNS, **{n: ("<f8", ()) for n in names
                                if n.startswith(QUALITY_PREFIX) and n not in TRACK_COLUMNS}}


def table_of(topic: str, camera_names: Sequence[str]) -> tuple[str, int] | None:
    """``(table, camera index)`` whose rows a message of ``topic`` is (camera 0 for truth
    and tracks), or None."""
    if topic == S.TRUTH_TOPIC:
        return TRUTH, 0
    method = S.parse_track_topic(topic)
    if method:
        return track_table(method), 0
    for i, name in enumerate(camera_names):
        if topic == S.detections_topic(name):
            return DETECTIONS, i
        if topic == S.ball_truth_topic(name):
            return BALL_TRUTH, i
    return None


def topics_of(table: str, camera_names: Sequence[str]) -> list[str]:
    """The per-message topics a table stands for, in camera order."""
    if table == TRUTH:
        return [S.TRUTH_TOPIC]
    method = track_method(table)
    if method is not None:
        return [S.track_topic(method)]
    make = S.detections_topic if table == DETECTIONS else S.ball_truth_topic
    return [make(n) for n in camera_names]


def encode(table: str, camera_names: Sequence[str], counts: Mapping[str, int],
           columns: Mapping[str, np.ndarray]) -> bytes:
    """The attachment data of ``table`` (:func:`encode_parts` joined)."""
    return b"".join(encode_parts(table, camera_names, counts, columns))


def encode_parts(table: str, camera_names: Sequence[str], counts: Mapping[str, int],
                 columns: Mapping[str, np.ndarray]) -> list:
    """The attachment data of ``table`` as pieces (bytes-like) to write one after another:
    the columns' bytes are not copied into one more buffer (a fused match's track table
    is tens of MB).

    Parameters
    ----------
    camera_names : the rig's cameras (``frame_camera`` indexes them)
    counts : per-message topic -> number of messages the table stands for
    columns : name -> array, every column of :data:`COLUMNS` ``[table]`` (a track table:
        those of :data:`TRACK_COLUMNS` and any ``quality/<name>`` columns, kept in order)
    """
    from ._chunks import _compress_all

    blobs, described, at = [], {}, 0
    named = list(_columns_of(table, list(columns)).items())
    values_of = [np.ascontiguousarray(columns[name], dtype=dtype) for name, (dtype, _s) in named]
    raws = [v.reshape(-1).view(np.uint8).data for v in values_of]  # no copy
    # every column large enough compressed at once (on the writer's thread pool), but a
    # long one only when zstd shrinks a sample of it
    big = [i for i, raw in enumerate(raws) if len(raw) >= _COMPRESS_FROM]
    long = [i for i in big if len(raws[i]) >= _SAMPLE_FROM]
    samples = [_sample(raws[i]) for i in long]
    hopeless = {i for i, sample, packed in zip(long, samples, _compress_all(samples),
                                                strict=True)
                if len(packed) >= _SAMPLE_GAIN * len(sample)}
    big = [i for i in big if i not in hopeless]
    packed_of = dict(zip(big, _compress_all([raws[i] for i in big]), strict=True))
    for i, ((name, (dtype, _s)), values, raw) in enumerate(zip(named, values_of, raws,
                                                                strict=True)):
        codec, stored = "none", cast("bytes | memoryview", raw)
        if i in packed_of:
            packed = packed_of[i]
            if len(packed) < 0.9 * len(raw):  # noisy doubles barely shrink: kept raw, read
                codec, stored = "zstd", packed  # without a decompression pass

        described[name] = {"dtype": dtype, "shape": list(values.shape), "codec": codec,
                           "offset": at, "size": len(stored)}
        pad = -len(stored) % 8
        blobs += [stored, bytes(pad)]
        at += len(stored) + pad
    header = json.dumps({"format": FORMAT, "version": VERSION, "table": table,
                         "cameras": list(camera_names),
                         "topics": {t: int(n) for t, n in counts.items()},
                         "columns": described}, separators=(",", ":")).encode()
    head = len(header).to_bytes(4, "little") + header
    return [head + bytes(-len(head) % 8), *blobs]


def _sample(raw: memoryview) -> bytes:
    """:data:`_SAMPLE_BYTES` from the start, the middle and the end of ``raw``."""
    size, k = len(raw), _SAMPLE_BYTES
    middle = (size - k) // 2
    return b"".join([raw[:k], raw[middle:middle + k], raw[size - k:]])


def decode(data: bytes | memoryview, table: str, camera_names: Sequence[str],
           header_only: bool = False) -> tuple[dict[str, int], dict[str, np.ndarray]]:
    """``(topic counts, columns)`` of a table's attachment data; LogFormatError naming what
    does not check out (wrong format, version, table, cameras, a column's dtype, shape,
    length or bytes). ``header_only``: the header's checks alone, no column (``{}``).

    Every column is a writable native-order array. A raw column of ``data`` that is a
    writable buffer is an array on it where its bytes are aligned (no copy: the reader
    reads a table into such a buffer); any other column is a copy, as the per-message
    decoder gives one."""
    import zstandard

    if len(data) < 4:
        raise LogFormatError("table shorter than its header")
    size = int.from_bytes(data[:4], "little")
    if 4 + size > len(data):
        raise LogFormatError("table header runs past its data")
    try:
        header = json.loads(bytes(data[4:4 + size]).decode("utf-8"))
        if not isinstance(header, dict):
            raise ValueError("not an object")
    except (UnicodeDecodeError, ValueError) as exc:
        raise LogFormatError(f"table header is no JSON object ({exc})") from None
    if header.get("format") != FORMAT or header.get("version") != VERSION:
        raise LogFormatError(f"table format {header.get('format')!r} version "
                             f"{header.get('version')!r} (this pslog reads {FORMAT} "
                             f"{VERSION})")
    if header.get("table") != table or header.get("cameras") != list(camera_names):
        raise LogFormatError("table names another table or other cameras")
    counts = header.get("topics")
    if not isinstance(counts, dict) or not all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 0
            for n in counts.values()):
        raise LogFormatError("table topic counts malformed")
    described = header.get("columns")
    if not isinstance(described, dict):
        raise LogFormatError("table columns malformed")
    expected_columns = _columns_of(table, list(described))
    if set(described) != set(expected_columns):
        raise LogFormatError("table columns differ from the format's")
    if header_only:
        return counts, {}
    body = 4 + size + (-(4 + size) % 8)
    out = {}
    for name, (dtype, shape) in expected_columns.items():
        d = described[name]
        try:
            offset, stored, codec = int(d["offset"]), int(d["size"]), d["codec"]
            dims = [int(x) for x in d["shape"]]
            if d["dtype"] != dtype:
                raise ValueError(f"dtype {d['dtype']}")
        except (KeyError, TypeError, ValueError) as exc:
            raise LogFormatError(f"table column {name} malformed ({exc})") from None
        if dims[1:] != list(shape) or len(dims) != 1 + len(shape) or min(dims) < 0:
            raise LogFormatError(f"table column {name} has shape {dims}")
        if offset < 0 or stored < 0 or body + offset + stored > len(data):
            raise LogFormatError(f"table column {name} runs past the data")
        blob = data[body + offset:body + offset + stored]
        expected = int(np.prod(dims)) * np.dtype(dtype).itemsize
        if codec == "zstd":
            try:
                blob = zstandard.ZstdDecompressor().decompress(blob, max_output_size=expected)
            except zstandard.ZstdError as exc:
                raise LogFormatError(f"table column {name} does not decompress ({exc})"
                                     ) from None
        elif codec != "none":
            raise LogFormatError(f"table column {name}: unknown codec {codec!r}")
        if len(blob) != expected:
            raise LogFormatError(f"table column {name} holds {len(blob)} bytes, not "
                                 f"{expected}")
        array = np.frombuffer(blob, dtype=dtype).reshape(dims)
        if not (array.flags.writeable and array.flags.aligned and array.dtype.isnative):
            # a writable copy in native order, as the per-message decoder gives
            array = np.array(array, dtype=np.dtype(dtype).newbyteorder("="))
        out[name] = array
    if track_method(table) is not None and len({len(v) for v in out.values()}) > 1:
        raise LogFormatError("track table columns differ in length")
    return counts, out


def build(name: str, camera_names: Sequence[str], per_topic: Mapping[str, list]
          ) -> bytes | None:
    """The attachment data of table ``name`` made from its topics' messages, decoded as
    :func:`pslog.log.reader.read_session` decodes them (so the table is what reading the
    messages gives); None when a message does not decode (readers then decode the messages
    and report it).

    Parameters
    ----------
    per_topic : topic -> messages, each a list of ``pslog.log.reader._Batch`` parts in file
        order (a topic absent: no message)
    """
    from google.protobuf.message import DecodeError

    from ..errors import PslogError
    from .reader import _Batch, decode_detections, decode_track, decode_truth

    topics = topics_of(name, camera_names)
    batches = [_Batch.concatenate(per_topic.get(t, [])) for t in topics]
    counts = {t: len(b) for t, b in zip(topics, batches, strict=True)}
    try:
        method = track_method(name)
        if name == TRUTH:
            truth = decode_truth(batches[0])
            columns = {"time_ns": truth.time_ns, "position_world": truth.position_world}
        elif method is not None:
            track = decode_track(method, camera_names, batches[0])
            columns = track_columns(track)
            if len(track):  # the map's keys in the first message's byte order (see
                b = batches[0]  # track_from_columns), not this process's parse order
                keys = _entry_keys(b.buf[b.start[0]:b.end[0]].tobytes())
                extra = [QUALITY_PREFIX + k for k in track.quality
                         if k not in S.TRACK_FIXED_QUALITY]
                ordered = [QUALITY_PREFIX + k for k in keys]
                if sorted(ordered) == sorted(extra):
                    rest = [k for k in columns if k not in extra]
                    columns = {k: columns[k] for k in rest + ordered}
        else:
            d = decode_detections(camera_names, batches)
            columns = {k: getattr(d, k) for k in COLUMNS[name]}
    except (DecodeError, PslogError, ValueError):
        return None
    return encode(name, camera_names, counts, columns)


def track_columns(track) -> dict[str, np.ndarray]:
    """The columns of a :class:`~pslog.records.Track`'s table (quality in its order)."""
    return {"time_ns": track.time_ns, "position_world": track.position_world,
            "camera": track.camera,
            **{QUALITY_PREFIX + k: v for k, v in track.quality.items()}}


def track_from_columns(method: str, columns: Mapping[str, np.ndarray]):
    """The :class:`~pslog.records.Track` of a decoded track table's columns."""
    from ..records import Track

    n = len(QUALITY_PREFIX)
    quality = {k[n:]: v for k, v in columns.items() if k.startswith(QUALITY_PREFIX)}
    # the fixed fields first, then the map's keys as this process's protobuf orders them
    # (as the per-message reader does; the table holds them in the writer's byte order)
    fixed = [k for k in S.TRACK_FIXED_QUALITY if k in quality]
    extra = [k for k in quality if k not in S.TRACK_FIXED_QUALITY]
    order = fixed + quality_order(extra)
    if sorted(order) == sorted(quality):
        quality = {k: quality[k] for k in order}
    return Track(method, columns["time_ns"], columns["position_world"], columns["camera"],
                 quality)


def names(topics) -> list[str]:
    """Every table a file with these ``topics`` may hold: :data:`TABLES`, then one per
    track topic (sorted)."""
    return [*TABLES, *sorted(track_table(m) for t in topics
                             if (m := S.parse_track_topic(t)))]


def track_columns_of(tracks: Sequence) -> dict[str, np.ndarray]:
    """The columns of the track table of the :class:`~pslog.records.Track` s a writer wrote
    on one topic (in order), made without the messages: what reading those messages gives
    (:func:`pslog.log.reader.decode_track`), so a writer needs not keep them.

    Reading concatenates the points in file order and sorts them by time (stable); a fixed
    ``TrackPoint`` field (:data:`pslog.log._schemas.TRACK_FIXED_QUALITY`) NaN at every point
    is left out (the writer stores NaN for a field a track lacks); a map key is a column,
    NaN at the points of a track without it (an empty track has none), in the order the
    messages give (:func:`_map_order`). Empty: no quality column at all.
    """
    n = sum(len(t) for t in tracks)
    times = np.concatenate([t.time_ns for t in tracks] or [np.zeros(0, np.int64)])
    # one track already in time order (a fused track): its own arrays, not copies (a
    # match's columns are tens of MB)
    one = len(tracks) == 1 and bool(np.all(times[1:] >= times[:-1]))
    order = slice(None) if one else np.argsort(times, kind="stable")

    def column(key: str) -> np.ndarray:
        if one:
            t = tracks[0]
            return t.quality[key] if key in t.quality else np.full(len(t), np.nan)
        return np.concatenate([t.quality[key] if key in t.quality else np.full(len(t), np.nan)
                               for t in tracks])[order]

    quality = {}
    if n:
        for key in S.TRACK_FIXED_QUALITY:
            values = column(key)
            if not np.all(np.isnan(values)):
                quality[key] = values
        for key in dict.fromkeys(k for t in tracks for k in _map_order(t)):
            quality[key] = column(key)
    if one:
        position, camera = tracks[0].position_world, np.asarray(tracks[0].camera)
    else:
        position = np.concatenate([t.position_world for t in tracks]
                                  or [np.zeros((0, 3))])[order]
        camera = np.concatenate([t.camera for t in tracks] or [np.zeros(0, np.int32)])[order]
    return {"time_ns": times if one else times[order], "position_world": position,
            "camera": camera.astype(np.int32, copy=False),
            **{QUALITY_PREFIX + k: v for k, v in quality.items()}}


def _map_order(track) -> list[str]:
    """The quality map keys of ``track``'s messages in the order the writer serialises them
    (the first point's map: the writer's map bytes are protobuf's own, checked by the
    writer); none for an empty track (it has no message). The order a reader's protobuf
    iterates a parsed map in varies between processes; :func:`quality_order` gives it from
    this one."""
    extra = [k for k in track.quality if k not in S.TRACK_FIXED_QUALITY]
    if not extra or not len(track):
        return []
    msg = S.TrackPoint()
    for key in extra:
        msg.quality[key] = float(track.quality[key][0])
    return _entry_keys(msg.SerializeToString(deterministic=True))


def _entry_keys(data: bytes) -> list[str]:
    """The keys of the quality map entries (field 10) of a serialised ``TrackPoint``, in
    byte order (a malformed message: the keys found up to where it stops making sense)."""

    def varint(at: int) -> tuple[int, int]:
        value = shift = 0
        while True:
            b = data[at]
            value |= (b & 0x7F) << shift
            at, shift = at + 1, shift + 7
            if b < 0x80:
                return value, at

    keys, at = [], 0
    try:
        while at < len(data):
            tag, at = varint(at)
            wire = tag & 7
            if wire == 0:
                _v, at = varint(at)
            elif wire == 1:
                at += 8
            elif wire == 5:
                at += 4
            elif wire == 2:
                length, at = varint(at)
                body, at = data[at:at + length], at + length
                if tag >> 3 == 10 and body[:1] == b"\x0a":  # map entry: its key first
                    size, start, shift = 0, 1, 0
                    while True:
                        b = body[start]
                        size |= (b & 0x7F) << shift
                        start, shift = start + 1, shift + 7
                        if b < 0x80:
                            break
                    keys.append(body[start:start + size].decode("utf-8"))
            else:
                break
    except (IndexError, UnicodeDecodeError):
        pass
    return keys


def quality_order(keys: Sequence[str]) -> list[str]:
    """``keys`` (quality map keys in a message's byte order) in the order this process's
    protobuf iterates the map parsed from such a message: the order the per-message reader
    gives the Track's ``quality`` mapping."""
    data = b"".join(_entry(k) for k in keys)
    return list(S.TrackPoint.FromString(data).quality)


def _entry(key: str) -> bytes:
    raw = key.encode("utf-8")
    body = _varint(len(raw)) + raw
    entry = b"\x0a" + body + b"\x11" + bytes(8)
    return b"\x52" + _varint(len(entry)) + entry


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        b, n = n & 0x7F, n >> 7
        out.append(b | (0x80 if n else 0))
        if not n:
            return bytes(out)
