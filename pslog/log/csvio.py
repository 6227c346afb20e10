"""Detections and fused tracks as CSV (``pslog import`` / ``pslog export``).

Detections CSV (import and export use exactly this format)::

    camera,time,u,v[,frame][,score]
    cam1,0.000000000,412.5,233.25,0,1.0

- ``camera``: a camera name of the rig; ``time``: capture time in seconds on the session's
  common clock (parsed exactly as a decimal, rounded to the nanosecond); ``u, v``: pixels as
  detected (distorted); ``frame``: the camera's frame index (optional); ``score``: detector
  confidence in [0, 1] (optional, default 1).
- Rows may come in any order. Rows with the same camera and time are the candidates of one
  frame (they must agree on ``frame``). Without a ``frame`` column, each camera's frames are
  numbered 0, 1, 2, ... in time order.
- Frames without any candidate cannot be expressed in this format (no row).

Export writes all six columns, times as exact decimals with 9 digits and pixels with
``repr`` precision, so import -> export -> import reproduces every value.
"""

from __future__ import annotations

import csv
from decimal import ROUND_HALF_EVEN, Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from ..errors import InputError, OutputExistsError
from ..records import NS, Detections
from ..rig import Rig

DETECTION_COLUMNS = ("camera", "time", "u", "v", "frame", "score")
_REQUIRED = ("camera", "time", "u", "v")
TRACK_COLUMNS = ("time", "x", "y", "z", "camera", "method")


def _time_ns(text: str) -> int:
    """Exact decimal seconds -> integer ns (half-even rounding below 1 ns)."""
    value = Decimal(text.strip())
    if not value.is_finite():
        raise InvalidOperation
    return int((value * NS).to_integral_value(rounding=ROUND_HALF_EVEN))


def format_time(time_ns: int) -> str:
    """Integer ns -> exact decimal seconds with 9 digits (``-0.000000001``)."""
    sign = "-" if time_ns < 0 else ""
    seconds, ns = divmod(abs(int(time_ns)), NS)
    return f"{sign}{seconds}.{ns:09d}"


def read_detections_csv(path, rig: Rig) -> Detections:
    """Parse a detections CSV (format in the module docstring) against ``rig``'s cameras.

    Raises InputError naming the line (and column) of the first malformed row or unknown
    camera.
    """
    path = Path(path)
    try:
        handle = open(path, newline="", encoding="utf-8")  # closed by the with below
    except FileNotFoundError:
        raise InputError(f"no such file: {path}") from None
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc}") from None
    index = {name: i for i, name in enumerate(rig.names)}
    cams, times, frames, uv, scores = [], [], [], [], []
    with handle:
        reader = csv.reader(handle)
        try:
            header = next(reader, None)
        except (csv.Error, UnicodeDecodeError) as exc:
            raise InputError(f"{path}: line 1: unreadable header: {exc}") from None
        if header is None:
            raise InputError(f"{path}: empty file (expected header camera,time,u,v)")
        header = [h.strip() for h in header]
        unknown = [h for h in header if h not in DETECTION_COLUMNS]
        missing = [h for h in _REQUIRED if h not in header]
        if unknown or missing or len(set(header)) != len(header):
            raise InputError(
                f"{path}: line 1: bad header {','.join(header)!r}: expected columns "
                f"camera,time,u,v and optionally frame,score"
                + (f" (unknown: {', '.join(unknown)})" if unknown else "")
                + (f" (missing: {', '.join(missing)})" if missing else ""))
        col = {name: header.index(name) for name in header}
        has_frame, has_score = "frame" in col, "score" in col
        line = 1
        try:
            for row in reader:
                line = reader.line_num
                if not row or all(not cell.strip() for cell in row):
                    continue
                if len(row) != len(header):
                    raise InputError(f"{path}: line {line}: expected {len(header)} fields, "
                                     f"got {len(row)}")
                name = row[col["camera"]].strip()
                if name not in index:
                    raise InputError(f"{path}: line {line}: unknown camera {name!r} "
                                     f"(rig has {', '.join(rig.names)})")
                cams.append(index[name])
                key = "time"
                try:
                    times.append(_time_ns(row[col["time"]]))
                    key = "u"
                    u = float(row[col["u"]])
                    key = "v"
                    v = float(row[col["v"]])
                    if not (np.isfinite(u) and np.isfinite(v)):
                        raise ValueError
                    uv.append((u, v))
                    if has_frame:
                        key = "frame"
                        frame = int(row[col["frame"]].strip())
                        if frame < 0:
                            raise ValueError
                        frames.append(frame)
                    if has_score:
                        key = "score"
                        score = float(row[col["score"]])
                        if not 0.0 <= score <= 1.0:
                            raise ValueError
                        scores.append(score)
                except (ValueError, InvalidOperation):
                    raise InputError(f"{path}: line {line}: bad {key} value "
                                     f"{row[col[key]].strip()!r}") from None
        except csv.Error as exc:
            raise InputError(f"{path}: line {line}: {exc}") from None
        except UnicodeDecodeError:
            raise InputError(f"{path}: line {line + 1}: not UTF-8 text") from None
    return _detections_from_rows(rig, np.asarray(cams, np.int32), np.asarray(times, np.int64),
                                 np.asarray(uv, np.float64).reshape(-1, 2),
                                 np.asarray(frames, np.int64) if has_frame else None,
                                 np.asarray(scores, np.float64) if has_score else None, path)


def _detections_from_rows(rig: Rig, cams, times, uv, frames, scores, path) -> Detections:
    """Group candidate rows into frames: one frame per distinct (camera, time)."""
    n = len(cams)
    if n == 0:
        raise InputError(f"{path}: no detection rows")
    keys = np.stack([cams.astype(np.int64), times], axis=1)
    unique, cand_frame = np.unique(keys, axis=0, return_inverse=True)
    cand_frame = cand_frame.ravel()
    frame_camera = unique[:, 0].astype(np.int32)
    frame_time = unique[:, 1]
    if frames is not None:
        frame_index = np.zeros(len(unique), np.int64)
        frame_index[cand_frame] = frames
        if np.any(frame_index[cand_frame] != frames):
            bad = int(np.flatnonzero(frame_index[cand_frame] != frames)[0])
            raise InputError(f"{path}: rows of camera {rig.names[cams[bad]]} at time "
                             f"{format_time(times[bad])} disagree on frame")
    else:
        # np.unique sorts by (camera, time): rank within each camera is the frame number
        starts = np.searchsorted(frame_camera, frame_camera, side="left")
        frame_index = np.arange(len(unique)) - starts
    return Detections.from_frames(rig.names, frame_time, frame_camera, frame_index, cand_frame,
                                  uv, None, scores)


def _open_output(path, force: bool):
    path = Path(path)
    if path.exists() and not force:
        raise OutputExistsError(f"{path} exists; use --force to overwrite it")
    if not path.parent.is_dir():
        raise InputError(f"output folder does not exist: {path.parent}")
    return open(path, "w", newline="", encoding="utf-8")


def write_detections_csv(detections: Detections, path, *, force: bool = False) -> int:
    """Write every candidate as a row (``camera,time,u,v,frame,score``) in time order;
    returns the number of rows."""
    rows = detections.cand_frame
    names = np.asarray(detections.camera_names, dtype=object)[detections.frame_camera[rows]]
    times = detections.frame_time_ns[rows].tolist()
    frames = detections.frame_index[rows].tolist()
    u = detections.cand_uv[:, 0].tolist()
    v = detections.cand_uv[:, 1].tolist()
    score = detections.cand_score.tolist()
    with _open_output(path, force) as f:
        f.write(",".join(DETECTION_COLUMNS) + "\n")
        f.writelines(f"{c},{format_time(t)},{a!r},{b!r},{k},{s!r}\n"
                     for c, t, a, b, k, s in zip(names, times, u, v, frames, score, strict=True))
    return len(rows)


def export_tracks_csv(session, path, *, force: bool = False) -> int:
    """Write the fused tracks of ``session`` (a :class:`~pslog.log.Session`) as CSV:
    ``time,x,y,z,camera,method`` (seconds, world metres, camera name), then one column per
    quality field any track has (empty where a track lacks it). Rows sorted by method, time.
    Returns the number of rows; InputError if the session has no tracks."""
    tracks = session.tracks
    if not tracks:
        raise InputError(f"{session.path} has no fused tracks (run 'pslog fuse' first)")
    quality = sorted({k for t in tracks.values() for k in t.quality})
    names = session.rig.names
    count = 0
    with _open_output(path, force) as f:
        f.write(",".join((*TRACK_COLUMNS, *quality)) + "\n")
        for method in sorted(tracks):
            track = tracks[method]
            cols = [track.quality[k].tolist() if k in track.quality else [None] * len(track)
                    for k in quality]
            for i, (t, (x, y, z), c) in enumerate(zip(
                    track.time_ns.tolist(), track.position_world.tolist(),
                    track.camera.tolist(), strict=True)):
                extra = "".join("," + ("" if col[i] is None else repr(col[i])) for col in cols)
                f.write(f"{format_time(t)},{x!r},{y!r},{z!r},{names[c]},{method}{extra}\n")
            count += len(track)
    return count
