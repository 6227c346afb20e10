"""Salvage the complete records of a damaged (truncated or partly corrupt) session MCAP."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError, LogFormatError, OutputExistsError
from . import _mcapio as io
from . import _schemas as S


def recover_session(src, dst, *, force: bool = False) -> dict:
    """Copy every complete record of ``src`` into a finished, indexed MCAP ``dst``.

    The walk stops at the first incomplete or corrupt record (a writer killed mid-chunk
    leaves at most its last flush interval there). Works on finished files too (a plain copy).
    Messages are streamed, so files larger than memory recover.

    Returns
    -------
    dict with ``messages`` (total recovered), ``topics`` (topic -> count), ``first_time_ns``
    and ``last_time_ns`` (log times of the recovered messages, None if none),
    ``detection_frames``, ``file_bytes``, ``kept_bytes`` (data section parsed),
    ``discarded_bytes`` (after the last complete data record, including a damaged summary),
    ``data_complete`` (no data record was lost), ``was_complete`` (src was a finished file)
    and ``stop_reason``.
    """
    src, size, complete = io.check_file(src)
    dst = Path(dst)
    if dst.exists() and dst.resolve() == src.resolve():
        raise InputError(f"output {dst} is the damaged input; choose another file")
    if dst.exists() and not force:
        raise OutputExistsError(f"{dst} exists; use --force to overwrite it")
    if not dst.parent.is_dir():
        raise InputError(f"output folder does not exist: {dst.parent}")

    from mcap.writer import CompressionType, Writer

    tmp = dst.with_name(dst.name + ".partial")
    topics: dict[str, int] = {}
    times = [None, None]  # first, last log time
    scan = io.Scan()
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    f = open(tmp, "wb")  # closed below, also on error
    writer = Writer(f, compression=CompressionType.ZSTD)
    writer.start(profile="", library="pslog recover")

    def copy(cid: int, t: int, seq: int, data: bytes) -> None:
        new = channel_ids.get(cid)
        if new is None:
            channel = scan.channels.get(cid)
            if channel is None:
                return  # its channel record was lost with the damaged part
            if channel.schema_id and channel.schema_id not in schema_ids:
                schema = scan.schemas.get(channel.schema_id)
                if schema is None:
                    return
                schema_ids[channel.schema_id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data)
            new = channel_ids[cid] = writer.register_channel(
                channel.topic, channel.encoding, schema_ids.get(channel.schema_id, 0),
                channel.metadata)
        writer.add_message(new, t, data, t, seq)
        topic = scan.channels[cid].topic
        topics[topic] = topics.get(topic, 0) + 1
        times[0] = t if times[0] is None else min(times[0], t)
        times[1] = t if times[1] is None else max(times[1], t)

    try:
        io.scan_file(src, copy, scan=scan)
        io.session_metadata(scan.metadata, src)  # refuse to "recover" something not ours
        for name, data in scan.metadata:
            writer.add_metadata(name, data)
        writer.finish()
        f.close()
    except BaseException:
        f.close()
        tmp.unlink(missing_ok=True)
        raise
    if not topics:
        tmp.unlink(missing_ok=True)
        raise LogFormatError(f"{src}: no complete message could be recovered "
                             f"({scan.stop_reason or 'no messages'})")
    tmp.replace(dst)
    return {
        "source": str(src),
        "output": str(dst),
        "was_complete": complete and scan.finished,
        "messages": sum(topics.values()),
        "topics": dict(sorted(topics.items())),
        "first_time_ns": times[0],
        "last_time_ns": times[1],
        "detection_frames": sum(n for t, n in topics.items()
                                if (p := S.parse_camera_topic(t)) and p[1] == "detections"),
        "file_bytes": size,
        "kept_bytes": scan.complete_bytes,
        "data_complete": scan.finished,  # the data section was whole (only the summary lost)
        "discarded_bytes": 0 if complete and scan.finished else size - scan.complete_bytes,
        "stop_reason": ("" if complete and scan.finished else
                        "only the summary section was damaged; no data lost" if scan.finished
                        else scan.stop_reason),
    }
