"""Summaries of a session for ``pslog info``: cameras, rates, measured shutter offsets."""

from __future__ import annotations

import numpy as np

from ..records import NS, Detections
from . import _mcapio as io
from . import _schemas as S
from .reader import read_session


def measure_timing(time_ns: np.ndarray) -> tuple[float, float]:
    """Frame period and shutter phase of one camera from its capture times.

    Robust to dropped frames and jitter: a first period is the median gap; each frame gets
    the frame number ``k`` implied by rounding gaps to whole periods; the period is then the
    least-squares slope of time over ``k`` and the phase the median of ``t - period * k``.

    Parameters
    ----------
    time_ns : (n,) int64, sorted capture times, n >= 2

    Returns
    -------
    period_s : float, seconds (NaN if fewer than 2 frames)
    phase_s : float, seconds, time of frame k = 0 (relative to ``time_ns[0]``'s second)
    """
    t = np.asarray(time_ns, dtype=np.int64)
    if len(t) < 2:
        return float("nan"), float("nan")
    rel = (t - t[0]).astype(np.float64) / NS  # small numbers keep float64 precise
    gaps = np.diff(rel)
    p0 = np.median(gaps[gaps > 0]) if np.any(gaps > 0) else float("nan")
    if not np.isfinite(p0):
        return float("nan"), float("nan")
    k = np.concatenate([[0], np.cumsum(np.maximum(np.round(gaps / p0), 0))])
    period = float(np.polyfit(k, rel, 1)[0]) if k[-1] > 0 else float(p0)
    phase = float(np.median(rel - period * k)) + t[0] / NS
    return period, phase


def timing_table(detections: Detections) -> list[dict]:
    """Per camera: frames, measured fps, shutter offset relative to camera 0, detection rate.

    The offset of camera i is its phase minus camera 0's, wrapped into [0, period_i).
    """
    rows, phases = [], []
    for i, name in enumerate(detections.camera_names):
        rows_i = detections.frame_camera == i
        period, phase = measure_timing(detections.frame_time_ns[rows_i])
        counts = detections.candidates_per_frame()[rows_i]
        n = int(rows_i.sum())
        rows.append({
            "name": name,
            "frames": n,
            "fps_measured": 1.0 / period if period > 0 else float("nan"),
            "detection_rate": float(np.mean(counts > 0)) if n else float("nan"),
            "candidates_per_frame": float(np.mean(counts)) if n else float("nan"),
        })
        phases.append((period, phase))
    period0, phase0 = phases[0] if phases else (float("nan"), float("nan"))
    for row, (period, phase) in zip(rows, phases, strict=True):
        p = period if np.isfinite(period) else period0
        row["offset_measured_s"] = (float((phase - phase0) % p)
                                    if np.isfinite(p) and np.isfinite(phase0) else float("nan"))
    return rows


def session_info(path) -> dict:
    """Summary of a session file as a JSON-able dict.

    On a finished file: ``cameras`` (per camera: name, frames, fps nominal/measured, shutter
    offset nominal/measured relative to the first camera, detection rate, images),
    ``topics`` (message counts), ``duration_s``, ``start_s``, ``end_s``, ``truth``,
    ``tracks`` (method -> points), ``events``, metadata fields and ``truncated: False``.
    On a truncated file: ``truncated: True``, what is salvageable (``topics``,
    ``last_time_s`` of any message, per kind the keys of
    :func:`pslog.log.recover.salvage_summary`, ``kept_bytes``, ``file_bytes``) and ``hint``
    (run ``pslog recover``).
    """
    path, size, complete = io.check_file(path)
    if not complete:
        return _truncated_info(path, size)
    from .reader import _Finished

    with _Finished(path) as f:
        counts = dict(sorted(f.counts.items()))
    session = read_session(path)
    det = session.detections
    rig = session.rig
    times = det.frame_time_ns
    cameras = timing_table(det)
    offset0 = rig.cameras[0].offset
    for row, cam in zip(cameras, rig.cameras, strict=True):
        row["fps_nominal"] = cam.fps
        row["offset_nominal_s"] = (cam.offset - offset0) % cam.frame_period
        row["images"] = counts.get(S.image_topic(cam.name), 0)
    meta = session.metadata
    return {
        "path": str(path),
        "truncated": False,
        "format_version": meta.get("format_version", ""),
        "timing": session.timing,
        "source": meta.get("source", ""),
        "creator": meta.get("creator", ""),
        "created_utc": meta.get("created_utc", ""),
        "rig": rig.name,
        "cameras": cameras,
        "topics": counts,
        "frames": det.n_frames,
        "candidates": det.n_candidates,
        "start_s": float(times[0] / NS) if len(times) else None,
        "end_s": float(times[-1] / NS) if len(times) else None,
        "duration_s": float((times[-1] - times[0]) / NS) if len(times) else 0.0,
        "images": session.n_images,
        "truth": session.truth is not None,
        "tracks": {m: len(t) for m, t in session.tracks.items()},
        "events": len(session.events),
        "file_bytes": size,
    }


def _truncated_info(path, size: int) -> dict:
    from .recover import salvage_summary

    topics: dict[int, int] = {}
    last_ns: dict[int, int] = {}

    def count(cid: int, t: int, _seq: int, _data: bytes) -> None:
        topics[cid] = topics.get(cid, 0) + 1
        last_ns[cid] = max(last_ns.get(cid, t), t)

    scan = io.scan_file(path, count)
    io.session_metadata(scan.metadata, path)
    name = {c: scan.channels[c].topic if c in scan.channels else f"channel {c}" for c in topics}
    named = {name[c]: n for c, n in topics.items()}
    last = max(last_ns.values(), default=None)
    return {
        "path": str(path),
        "truncated": True,
        "topics": dict(sorted(named.items())),
        "last_time_s": None if last is None else last / NS,
        **salvage_summary(named, {name[c]: t for c, t in last_ns.items()}),
        "kept_bytes": scan.complete_bytes,
        "file_bytes": size,
        "stop_reason": scan.stop_reason,
        "hint": f"the recording did not finish; run 'pslog recover {path} -o FIXED.mcap' "
                f"to salvage the complete records",
    }
