"""Salvage every intact record of a damaged (truncated or partly corrupt) session MCAP."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from ..errors import LogFormatError, PslogError
from ..outputs import RECOVER_LIBRARY, locked_by_another, replacing
from ..records import NS
from ..rig import Rig
from . import _mcapio as io
from . import _schemas as S
from . import table as tables


def salvage_summary(counts: dict[str, int], last_ns: dict[str, int]) -> dict:
    """What survived, per kind of record, from per-topic message counts and last log times.

    Kinds are reported separately because they reach the file at different moments: images
    go straight to disk, detections in chunks about once a second, and the ground truth of
    a synthetic session all at the start, so "the last message" says little about how much
    of the recording is usable.

    Returns
    -------
    dict with ``detection_frames``, ``last_detection_ns`` (int ns or None), ``images``,
    ``last_image_ns`` (int ns or None) and ``truth_points``.
    """
    def kind(topic: str) -> str | None:
        parsed = S.parse_camera_topic(topic)
        return parsed[1] if parsed else None

    det = [t for t in counts if kind(t) == "detections"]
    img = [t for t in counts if kind(t) == "image"]
    return {
        "detection_frames": sum(counts[t] for t in det),
        "last_detection_ns": max((last_ns[t] for t in det), default=None),
        "images": sum(counts[t] for t in img),
        "last_image_ns": max((last_ns[t] for t in img), default=None),
        "truth_points": counts.get(S.TRUTH_TOPIC, 0),
    }


def describe_salvage(summary: dict) -> str:
    """One phrase for users from a :func:`salvage_summary` dict, e.g. ``172 detection frames
    (to t = 2.190 s), 232 images (to t = 3.100 s), 300 truth points``; says so plainly when
    no detection frame survived."""
    parts = []
    if summary["detection_frames"]:
        parts.append(f"{summary['detection_frames']} detection frames "
                     f"(to t = {summary['last_detection_ns'] / NS:.3f} s)")
    if summary["images"]:
        parts.append(f"{summary['images']} images (to t = {summary['last_image_ns'] / NS:.3f} s)")
    if summary["truth_points"]:
        parts.append(f"{summary['truth_points']} truth points")
    text = ", ".join(parts) or "only the session set-up (rig, calibrations)"
    if not summary["detection_frames"]:
        text += ("; no detection frame survived (detections are written in chunks up to a "
                 "second late, so a file cut within about a second of starting has none)")
    return text


def recover_session(src, dst, *, force: bool = False) -> dict:
    """Copy every intact record of ``src`` into a finished, indexed MCAP ``dst``.

    Each chunk is checked (header, decompression, CRC, framing of its records) and a damaged
    one is skipped; every intact record before and after it is kept. After bytes that are no
    record (a cut, a damaged length field) the walk picks up at the next intact record (see
    :func:`pslog.log._mcapio.salvage_file`). Works on finished files too (a plain copy).
    Messages are streamed, so files larger than memory recover (only the detection,
    truth and track messages are kept, to rebuild the columnar tables:
    :mod:`pslog.log.table`).

    Returns
    -------
    dict with ``messages`` (total recovered), ``topics`` (topic -> count), ``first_time_ns``
    and ``last_time_ns`` (log times of the recovered messages of any kind, None if none),
    the keys of :func:`salvage_summary` (``detection_frames``, ``last_detection_ns``,
    ``images``, ``last_image_ns``, ``truth_points``), ``file_bytes``, ``kept_bytes`` (bytes
    of the data section read), ``discarded_bytes`` (the damaged parts), ``damaged`` (one
    dict per skipped part, see :func:`describe_damage`), ``unknown_channel_messages``
    (intact messages whose channel record was lost with a damaged part), ``data_complete``
    (no data record was lost), ``was_complete`` (src was a finished, undamaged file),
    ``being_recorded`` (another pslog held src's writer lock as the copy began: a recording
    in progress, copied as far as it had been written) and ``stop_reason``.
    """
    src, size = Path(src), 0
    if not src.is_file():
        io.check_file(src)  # its one-line error
    # a recording in progress (its recorder holds the writer's lock): the copy holds what it
    # had written by now, which the caller says (it was reported as a salvage, in silence)
    recording = locked_by_another(src)

    from mcap.writer import CompressionType, Writer

    topics: dict[str, int] = {}
    last_ns: dict[str, int] = {}  # per topic
    times: list[int | None] = [None, None]  # first, last log time
    unknown = [0]
    scan = io.Scan()
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    # the messages of the topics a columnar table stands for, by topic: (times, sequences,
    # payloads), rebuilt into tables at the end (a salvaged file's own tables are dropped:
    # they would name messages that were lost)
    kept: dict[str, tuple[list, list, list]] = {}
    table_topics = _TableTopics()
    static: dict[str, bytes] = {}  # each camera's first calibration and transform message

    # dst is checked (never src in any spelling), written as <dst>.partial and moved over
    # dst only when complete; removed on any failure
    with replacing(dst, "wb", force=force, inputs=[src]) as f:
        dst = Path(dst)
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start(profile="", library=RECOVER_LIBRARY)

        def copy(cid: int, t: int, seq: int, data: bytes) -> None:
            new = channel_ids.get(cid)
            if new is None:
                channel = scan.channels.get(cid)
                if channel is None:
                    unknown[0] += 1
                    return  # its channel record was lost with a damaged part
                if channel.schema_id and channel.schema_id not in schema_ids:
                    schema = scan.schemas.get(channel.schema_id) or _pslog_schema(channel.topic)
                    if schema is None:
                        unknown[0] += 1
                        return
                    schema_ids[channel.schema_id] = writer.register_schema(
                        schema.name, schema.encoding, schema.data)
                new = channel_ids[cid] = writer.register_channel(
                    channel.topic, channel.encoding, schema_ids.get(channel.schema_id, 0),
                    channel.metadata)
            writer.add_message(new, t, data, t, seq)
            topic = scan.channels[cid].topic
            if topic in table_topics:  # kept to rebuild the columnar tables
                rows = kept.get(topic)
                if rows is None:
                    rows = kept[topic] = ([], [], [])
                rows[0].append(t)
                rows[1].append(seq)
                rows[2].append(data)
            if topic.endswith(("/calibration", "/transform")):  # the rig, if the metadata
                static.setdefault(topic, data)                     # record is lost
            topics[topic] = topics.get(topic, 0) + 1
            last_ns[topic] = max(last_ns.get(topic, t), t)
            times[0] = t if times[0] is None else min(times[0], t)
            times[1] = t if times[1] is None else max(times[1], t)

        io.salvage_file(src, copy, scan=scan, tolerate_magic=True)
        size = src.stat().st_size
        rebuilt = None
        try:
            meta = io.session_metadata(scan.metadata, src)  # refuse to "recover" what is not ours
        except LogFormatError:
            if not (scan.damaged and not scan.metadata):
                raise
            # lost with a damaged part: the rig from the cameras' calibration and pose
            # messages, their frame rates and offsets from the detections' times
            rebuilt = _rebuilt_metadata(static, kept)
            if rebuilt is None:
                raise LogFormatError(
                    f"{src}: the session metadata (rig, cameras) was in the damaged part at "
                    f"byte {scan.damaged[0].start}, and no intact calibration of every camera "
                    f"survived to rebuild it; the file is beyond repair") from None
            meta = rebuilt
            scan.metadata.append((S.SESSION_METADATA, rebuilt))
        try:  # records outside chunks have no CRC: a damaged rig shows only when parsed
            Rig.from_toml(meta.get("rig_toml", ""), source="the rig")
        except PslogError as exc:
            raise LogFormatError(f"{src}: the session metadata (rig, cameras) is damaged "
                                 f"({exc}); nothing usable can be recovered") from None
        if not topics:
            reason = scan.damaged[0].reason if scan.damaged else "no messages"
            raise LogFormatError(f"{src}: no intact message could be recovered ({reason})")
        for name, data in scan.metadata:
            writer.add_metadata(name, data)
        _write_tables(writer, Rig.from_toml(meta["rig_toml"], source="the rig").names, kept)
        writer.finish()
    damaged = [describe_damage(d, scan.channels) for d in scan.damaged]
    discarded = sum(d["end"] - d["start"] for d in damaged)
    complete = scan.finished and not damaged
    repaired = [{"start": d.start, "end": d.end, "reason": d.reason} for d in scan.repaired]
    tail = "; ".join(f"{d['reason']} at byte {d['start']}" for d in damaged[:3])
    return {
        "source": str(src),
        "output": str(dst),
        "rebuilt_metadata": rebuilt is not None,
        "was_complete": complete and scan.summary is not None and not repaired,
        "repaired": repaired,
        "messages": sum(topics.values()),
        "topics": dict(sorted(topics.items())),
        "first_time_ns": times[0],
        "last_time_ns": times[1],
        **salvage_summary(topics, last_ns),
        "file_bytes": size,
        "kept_bytes": size - discarded,
        "data_complete": complete,  # the data section was whole (at most the summary lost)
        "discarded_bytes": discarded,
        "damaged": damaged,
        "unknown_channel_messages": unknown[0],
        "being_recorded": recording,
        "stop_reason": ("" if complete and scan.summary is not None else
                        "only the summary section was damaged; no data lost" if complete
                        else tail + ("; ..." if len(damaged) > 3 else "")),
    }


def _rebuilt_metadata(static: dict[str, bytes], kept: dict) -> dict[str, str] | None:
    """A session metadata record rebuilt from each camera's calibration and transform
    message (in the file's order: the rig's) and the times of its detection frames (frame
    rate rounded to 1 mHz; offsets those of a shutter preset when within a twentieth of a
    period of them), or None when a camera's calibration, pose or two detection frames did
    not survive."""
    import numpy as np

    from ..camera import Camera
    from ..rig import TIMING_PRESETS, apply_timing, timing_label
    from .info import measure_timing

    names = [parsed[0] for t in static if t.endswith("/calibration")
             and (parsed := S.parse_camera_topic(t)) is not None]
    if not names:
        return None
    timed = []
    for name in names:
        calib_data = static.get(S.calibration_topic(name))
        pose_data = static.get(S.transform_topic(name))
        rows = kept.get(S.detections_topic(name))
        if calib_data is None or pose_data is None or rows is None or len(rows[0]) < 2:
            return None
        times = np.sort(np.asarray(rows[0], dtype=np.int64))
        timed.append((name, calib_data, pose_data, times))
    ref = int(min(times[0] for *_, times in timed))
    cameras = []
    try:
        for name, calib_data, pose_data, times in timed:
            calib = S.CameraCalibration.FromString(calib_data)
            pose = S.FrameTransform.FromString(pose_data)
            world_from_cam = S.rotation_from_quaternion(
                [pose.rotation.x, pose.rotation.y, pose.rotation.z, pose.rotation.w])
            centre = np.array([pose.translation.x, pose.translation.y, pose.translation.z])
            period, phase = measure_timing(times, ref)
            if not period > 0:
                return None
            R = world_from_cam.T
            cameras.append(Camera(
                name=name, width=int(calib.width), height=int(calib.height),
                K=np.asarray(calib.K, dtype=np.float64).reshape(3, 3),
                dist=np.asarray(list(calib.D)[:5] + [0.0] * (5 - len(calib.D[:5]))),
                R=R, t=-R @ centre, fps=round(1.0 / period, 3), offset=phase % period))
        rig = Rig(tuple(cameras), "recovered")
        first = cameras[0].offset
        rig = Rig(tuple(c.replace(offset=(c.offset - first) % (1.0 / c.fps))
                        for c in cameras), "recovered")
        for preset in TIMING_PRESETS:
            snapped = apply_timing(rig, preset)
            if all(abs(a.offset - b.offset) < 0.05 / a.fps
                   for a, b in zip(rig.cameras, snapped.cameras, strict=True)):
                rig = snapped
                break
    except (PslogError, ValueError, TypeError):  # a calibration that is no camera
        return None
    return {"format": S.FORMAT_NAME, "format_version": S.FORMAT_VERSION,
            "rig_toml": rig.to_toml(), "timing": timing_label(rig),
            "source": "pslog recover: session metadata lost; rig rebuilt from the cameras' "
                      "calibration and pose messages, frame rates and offsets from the "
                      "detections' times",
            "creator": RECOVER_LIBRARY,
            "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
            "camera_names": ",".join(rig.names)}


def _pslog_schema(topic: str) -> io.SchemaRec | None:
    """The schema of a pslog topic, for a channel whose schema record was lost with a damaged
    part (pslog's schemas are fixed by the topic)."""
    camera = S.parse_camera_topic(topic)
    kind = camera[1] if camera else None
    by_kind: dict[str | None, Any] = {
        "calibration": S.CameraCalibration, "transform": S.FrameTransform,
        "image": S.CompressedImage, "detections": S.DetectionFrame}
    message = by_kind.get(kind)
    if topic == S.TRUTH_TOPIC:
        message = S.TruthPoint
    elif S.parse_ball_truth_topic(topic):
        message = S.DetectionFrame
    elif S.parse_rejections_topic(topic):
        message = S.Rejection
    elif topic == S.EVENTS_TOPIC:
        message = S.Log
    elif S.parse_track_topic(topic):
        message = S.TrackPoint
    elif topic.startswith("/tracks/") and topic.endswith("/scene"):
        message = S.SceneUpdate
    if message is None:
        return None
    return io.SchemaRec(0, message.DESCRIPTOR.full_name, S.PROTOBUF,
                        S.file_descriptor_set(message))


def describe_damage(damage: io.Damage, channels: dict) -> dict:
    """A skipped part of a damaged file as a JSON-able dict: ``start``, ``end`` (byte
    offsets), ``reason``, ``chunk`` (whether it is a chunk), ``start_ns``/``end_ns`` (message
    times the chunk's header or index states, or None) and ``messages`` (topic -> count from
    the chunk's message indexes, or None when unknown)."""
    counts: dict[str, int] | None = None
    if damage.counts is not None:
        counts = {}
        for cid, k in damage.counts.items():
            topic = channels[cid].topic if cid in channels else f"channel {cid}"
            counts[topic] = counts.get(topic, 0) + k
    return {"start": damage.start, "end": damage.end, "reason": damage.reason,
            "chunk": damage.chunk, "start_ns": damage.start_ns, "end_ns": damage.end_ns,
            "messages": None if counts is None else dict(sorted(counts.items()))}


def damage_line(d: dict) -> str:
    """One line for users about a :func:`describe_damage` dict."""
    what = d.get("label") or ("damaged chunk at bytes" if d["chunk"] else "unreadable bytes")
    text = f"{what} {d['start']}..{d['end']}"
    if d["start_ns"] is not None and d["end_ns"] is not None and d["end_ns"] >= d["start_ns"]:
        text += f", t = {d['start_ns'] / NS:.3f} .. {d['end_ns'] / NS:.3f} s"
    if d["messages"]:
        text += ", " + ", ".join(f"{n} on {t}" for t, n in d["messages"].items())
    elif d["chunk"]:
        text += ", message count unknown"
    return f"{text} ({d['reason']})"


class _TableTopics:
    """``topic in`` this: the topic is one a columnar table may stand for (any camera name:
    the rig is known only once the metadata is read)."""

    def __contains__(self, topic: str) -> bool:
        return (topic == S.TRUTH_TOPIC or topic.startswith("/truth/ball/")
                or (topic.startswith("/camera/") and topic.endswith("/detections"))
                or S.parse_track_topic(topic) is not None)


def _write_tables(writer, camera_names, kept: dict[str, tuple[list, list, list]]) -> None:
    """Add the columnar tables (:mod:`pslog.log.table`) made from the recovered messages of
    their topics, as :class:`pslog.log.SessionWriter` adds them at close."""
    from .reader import _Batch

    for name in tables.names(kept):  # a track's table when any of its messages is left
        topics = tables.topics_of(name, camera_names)
        if not any(t in kept for t in topics) and name != tables.DETECTIONS:
            continue
        per_topic = {}
        for topic in topics:
            if topic in kept:
                times, seqs, datas = kept[topic]
                per_topic[topic] = [_Batch.from_messages(list(zip(times, seqs, datas,
                                                                  strict=True)))]
        data = tables.build(name, camera_names, per_topic)
        if data is not None:
            writer.add_attachment(0, 0, name, tables.MEDIA_TYPE, data)
