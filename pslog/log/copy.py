"""Derive a session from another: stream-copy it, images kept as stored (never decoded),
optionally replacing the detections (re-detection) and adding or replacing fused tracks."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from ..errors import InputError
from ..outputs import check_output_path
from ..records import Detections, Track
from ..rig import Rig, timing_label
from . import _mcapio as io
from . import _schemas as S
from .reader import _Finished
from .writer import SessionWriter


def copy_session(src, dst, *, detections: Detections | None = None, tracks: Sequence[Track] = (),
                 replace_tracks: bool = True, metadata: Mapping[str, str] | None = None,
                 rig: Rig | None = None, force: bool = False,
                 rejections: Mapping | None = None) -> None:
    """Write ``dst`` as a copy of session ``src``.

    Parameters
    ----------
    detections : if given, replaces every detection message of ``src`` (camera names must
        be the rig's)
    tracks : fused tracks to add
    replace_tracks : drop every track of ``src`` (True) or only those whose method is in
        ``tracks`` (False)
    metadata : user metadata to add or replace (e.g. the new detector settings)
    rig : a corrected rig (same camera names, same order) replacing the session's calibration
    force : overwrite ``dst``
    rejections : method -> :class:`pslog.fusion.gating.Rejections`, the candidates the
        gating stage rejected for that method's track (written beside it; replaced with it)

    Calibration, poses, images, truth, events, metadata and any foreign topics are copied
    byte for byte (the calibration and poses are re-derived only from a given ``rig``).
    ``dst`` may not be ``src`` in any spelling; it is written as ``<dst>.partial`` and
    appears only when complete (on any failure nothing is left and an old ``dst`` stays).
    """
    src_path = Path(src)
    dst = check_output_path(dst, force, inputs=[src_path])  # before reading anything
    with _Finished(src_path) as f:
        meta, old_rig = f.meta, f.rig
        first_static = f.collect([S.calibration_topic(old_rig.names[0])])
        start_ns = min((t for t, _s, _d in next(iter(first_static.values()), [])), default=0)
    if rig is not None and rig.names != old_rig.names:
        raise InputError(f"rig cameras {', '.join(rig.names)} differ from the session's "
                         f"{', '.join(old_rig.names)} (names and order must match)")
    if detections is not None and tuple(detections.camera_names) != old_rig.names:
        raise InputError(f"detections are for cameras {', '.join(detections.camera_names)}, "
                         f"session has {', '.join(old_rig.names)}")
    new_methods = {t.method for t in tracks}
    user_meta = {k: v for k, v in meta.items() if k not in S.RESERVED_KEYS}
    user_meta["derived_from"] = src_path.name
    user_meta.update(metadata or {})

    new_rig = rig is not None
    if rig is None:
        rig = old_rig
    # a corrected rig may have other shutter offsets: its label says what they are
    timing = timing_label(rig) if new_rig else meta.get("timing", "custom")
    with SessionWriter(dst, rig, force=force, timing=timing,
                       source=meta.get("source", ""), metadata=user_meta,
                       start_ns=start_ns, on_error="discard", inputs=[src_path],
                       write_static=new_rig) as w:
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

        io.scan_file(src_path, copy, scan=scan)  # copy's own errors propagate unchanged
        if detections is not None:
            w.add_detections(detections)
        for track in tracks:
            w.add_track(track)
        for method, rejected in (rejections or {}).items():
            w.add_rejections(method, rejected)
