"""Summaries of a session for ``pslog info``: cameras, rates, measured shutter offsets."""

from __future__ import annotations

import numpy as np

from ..errors import LogFormatError, shell_word
from ..records import NS, Detections
from . import _mcapio as io
from . import _schemas as S

_UNFINISHED = "the recording did not finish"
#: a file modified this recently may still be being written by a recorder, seconds
RECENT_S = 10.0


def measure_timing(time_ns: np.ndarray, ref_ns: int = 0) -> tuple[float, float]:
    """Frame period and shutter phase of one camera from its capture times.

    Robust to dropped frames and jitter: a first period is the longest whole fraction of the
    median gap that the gaps are multiples of (:func:`_first_period`); each frame gets
    the frame number ``k`` implied by rounding gaps to whole periods; the period is then the
    least-squares slope of time over ``k`` and the phase the median of ``t - period * k``.
    Full precision on any clock (e.g. Unix-epoch nanoseconds, ~1.7e18): all arithmetic is on
    int64 differences, converted to float only once small.

    Parameters
    ----------
    time_ns : (n,) int64, sorted capture times, n >= 2
    ref_ns : int, the time the phase is measured from (pass one reference for every camera
        to compare phases)

    Returns
    -------
    period_s : float, seconds (NaN if fewer than 2 frames)
    phase_s : float, seconds, time of frame k = 0 relative to ``ref_ns``
    """
    t = np.asarray(time_ns, dtype=np.int64)
    if len(t) < 2:
        return float("nan"), float("nan")
    rel = (t - t[0]).astype(np.float64) / NS  # small numbers keep float64 precise
    gaps = np.diff(rel)
    p0 = _first_period(gaps[gaps > 0])
    if not np.isfinite(p0):
        return float("nan"), float("nan")
    k = np.concatenate([[0], np.cumsum(np.maximum(np.round(gaps / p0), 0))])
    period = float(np.polyfit(k, rel, 1)[0]) if k[-1] > 0 else float(p0)
    phase = float(np.median(rel - period * k)) + int(t[0] - ref_ns) / NS
    return period, phase


#: gaps within this fraction of a period of a whole number of periods fit that period
_FIT_TOLERANCE = 0.2
#: the share of gaps that must fit a period for it to be the frame period
_FIT_SHARE = 0.8
#: a period shorter than the median gap needs this share of gaps of about one period
_SINGLE_SHARE = 0.1
#: the median gap is tried as up to this many frame periods (frames dropped in between)
_MOST_PERIODS = 8


def _first_period(gaps: np.ndarray) -> float:
    """The frame period the positive ``gaps`` (s) are whole multiples of: the median gap
    divided by the smallest ``m`` in 1.._MOST_PERIODS for which _FIT_SHARE of the gaps lie
    within _FIT_TOLERANCE of a multiple of ``median / m`` and, for ``m`` > 1, _SINGLE_SHARE of
    them about one such period (frames dropped leave some single gaps; timestamps rounded to
    a coarse tick or late by a fixed amount fit a fraction of the period without any: a 30 fps
    camera on 10-ms ticks is not a 100 fps one); the median alone when none fits (jitter beyond
    the tolerance; the least-squares slope of :func:`measure_timing` then refines it). With half
    the frames or more dropped the median gap is two periods or more: taken as the period,
    every single-period gap rounded to 0 or 1 at random (a session with 60 % drops measured
    13 fps instead of 30, and offsets off by milliseconds)."""
    if not len(gaps):
        return float("nan")
    median = float(np.median(gaps))
    for m in range(1, _MOST_PERIODS + 1):
        ratio = gaps / (median / m)
        whole = np.round(ratio)
        fits = np.mean(np.abs(ratio - whole) <= _FIT_TOLERANCE) >= _FIT_SHARE
        if fits and (m == 1 or np.mean(whole == 1) >= _SINGLE_SHARE):
            return median / m
    return median


def timing_table(detections: Detections, nominal_offsets_s=None, rig=None) -> list[dict]:
    """Per camera: frames, measured fps, shutter offset, detection rate.

    Only offsets between cameras can be measured: camera 0 is placed at its nominal offset
    and camera i at the offset nearest its nominal one that matches the measured phase
    difference (signed: a camera 0.1 ms early on a nominal offset of 0 reads -0.1 ms, not a
    period minus 0.1 ms); with cameras of other rates (``rig`` given), that difference is
    known only up to whole periods of camera 0, one shift for every camera, and the one that
    puts the cameras nearest their nominal offsets is taken (as
    :func:`pslog.timing.shutter_phases`).

    Parameters
    ----------
    detections : the session's detections
    nominal_offsets_s : (n_cameras,) the rig's offsets, seconds; None: all 0 (the measured
        offsets are then relative to camera 0, within half a period)
    rig : Rig or None; given, each frame's time is first corrected by the rig's clock model
        (:func:`pslog.timing.true_times_ns` of the frame's top row, ``v`` = 0), so the phases
        are measured on true times: after ``pslog sync`` they agree with the rig's offsets
    """
    names = detections.camera_names
    nominal = (np.zeros(len(names)) if nominal_offsets_s is None
               else np.asarray(nominal_offsets_s, dtype=np.float64))
    times = detections.frame_time_ns
    if rig is not None and any(c.has_clock_correction for c in rig.cameras) and len(times):
        from ..timing import camera_parameters, true_times_ns

        p, cam = camera_parameters(rig), detections.frame_camera
        # v = 0: a frame's logged time is its top row's; each camera's correction is
        # increasing in time, so every camera's frames stay in order
        times = true_times_ns(times, 0.0, p["height"][cam], p["clock_offset"][cam],
                              p["clock_drift_ppm"][cam], p["readout"][cam])
    ref = int(times.min()) if len(times) else 0  # one reference: phases comparable
    rows, phases = [], []
    for i, name in enumerate(names):
        rows_i = detections.frame_camera == i
        period, phase = measure_timing(times[rows_i], ref)
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
    if not phases:
        return rows
    from ..timing import nearest_schedule

    period0, phase0 = phases[0]
    used = np.array([period if np.isfinite(period) else period0 for period, _ in phases])
    miss = np.array([phase for _, phase in phases]) - phase0 - (nominal - nominal[0])
    # cameras of other rates: camera 0's first frame fixes the clock's zero only up to whole
    # periods of camera 0, each giving the same schedule: the shift, the same for every
    # camera, that puts them nearest their nominal offsets (as pslog sync measures them;
    # review48: a 60/30 fps rig whose 60 fps camera's first frame was dropped read its 30
    # fps cameras 16.7 ms off their true offsets)
    if rig is not None:
        miss = nearest_schedule(miss, used, [c.fps for c in rig.cameras])
    for i, row in enumerate(rows):
        if np.isfinite(used[i]) and np.isfinite(phase0) and np.isfinite(miss[i]):
            row["offset_measured_s"] = float(nominal[i] + miss[i]
                                             - used[i] * np.round(miss[i] / used[i]))
        else:
            row["offset_measured_s"] = float("nan")
    return rows


#: a measured shutter offset this far from the rig's is worth telling the user, seconds
OFFSET_NOTE_S = 2e-3


def offset_disagreements(detections: Detections, rig) -> list[tuple[str, float, float]]:
    """``(camera, measured_s, rig_s)`` for each camera whose measured shutter offset (see
    :func:`timing_table`) is more than :data:`OFFSET_NOTE_S` from the rig's: e.g. video files
    started at other moments (``--source cam2=b.mp4@0.011``) on a rig whose offsets say
    ``sync``. The session keeps the rig's offsets; the user decides which are right. Measured
    on times corrected by the rig's clock model, as :func:`session_info`."""
    nominal = [cam.offset for cam in rig.cameras]
    rows = timing_table(detections, nominal, rig)
    return [(row["name"], row["offset_measured_s"], offset)
            for row, offset in zip(rows, nominal, strict=True)
            if np.isfinite(row["offset_measured_s"])
            and abs(row["offset_measured_s"] - offset) > OFFSET_NOTE_S]


#: a camera without a frame for longer than this while the session runs is worth telling,
#: seconds (or :data:`GAP_NOTE_PERIODS` frame periods, if longer): a camera unplugged or
#: whose process died; frames dropped under load are single frames
GAP_NOTE_S = 0.5
GAP_NOTE_PERIODS = 10


def camera_gaps(detections: Detections, rig, events=()) -> list[dict]:
    """The stretches of the session during which a camera sent no frame, longer than
    :data:`GAP_NOTE_S` (or :data:`GAP_NOTE_PERIODS` of its frame periods): one dict per
    stretch, ``camera``, ``start_s`` (its last frame before, or the session's first frame),
    ``end_s`` (its first frame after, or the session's last frame), ``kind`` (``stopped``:
    none to the end, ``late``: none from the start, ``gap``, ``none``: no frame at all), and
    ``note``: the first of
    ``events`` (``(time_ns, text)``, the recorder's notes) within the stretch (or after its
    start, for a camera that stopped) naming the
    camera (``camera cam3 failed: camera process died``), else ``""`` (:func:`session_info`
    adds ``imported``: the session is a CSV's, whose detector may write no row for a frame
    without the ball, which :func:`gap_text` then says). A camera without
    any frame is one stretch over the whole session. Times on the logged session clock."""
    times = detections.frame_time_ns
    if not len(times):
        return []
    first, last = int(times.min()), int(times.max())
    gaps = []
    for i, cam in enumerate(rig.cameras):
        t = np.sort(times[detections.frame_camera == i])
        limit = max(GAP_NOTE_S, GAP_NOTE_PERIODS / cam.fps) * NS
        edges = np.concatenate(([first], t, [last]))
        for k in np.flatnonzero(np.diff(edges) > limit):
            start, end = int(edges[k]), int(edges[k + 1])
            kind = ("gap" if 0 < k < len(edges) - 2 else "stopped" if k == len(edges) - 2
                    else "late")
            if not len(t):
                kind = "none"
            words = (f"camera {cam.name} ", f"{cam.name}:")
            # a camera stopped: said after its last frame, maybe after the session's last
            # (pslog live says a camera silent once a second has passed without it)
            until = end if kind in ("gap", "late") else np.inf
            note = next((text for when, text in events if start <= when <= until
                         and any(w in text for w in words)), "")
            gaps.append({"camera": cam.name, "start_s": start / NS, "end_s": end / NS,
                         "kind": kind, "note": note})
    return gaps


def gap_text(gap: dict, short: bool = False) -> str:
    """One of :func:`camera_gaps`'s stretches in words (``short``: for a table's cell)."""
    name, start, end = gap["camera"], gap["start_s"], gap["end_s"]
    span = {"stopped": f"after t = {start:.3f} s (to the end, {end:.3f} s)",
            "late": f"before t = {end:.3f} s (from the start, {start:.3f} s)",
            "none": "at all",
            "gap": f"from t = {start:.3f} to {end:.3f} s"}[gap["kind"]]
    if short:
        return f"{name}: no frame {span}"
    if gap.get("imported"):  # a detector may write no row for a frame without the ball
        return (f"{name}: no frame {span}, {end - start:.2f} s (no row in the imported "
                f"CSV: a camera lost or late, frames dropped, or a detector writing no row "
                f"for a frame without the ball)")
    why = {"stopped": "a camera that stopped or was unplugged",
           "late": "a camera that started late",
           "none": "a camera that never delivered",
           "gap": "a camera lost for a while, or its frames dropped"}[gap["kind"]]
    text = f"{name}: no frame {span}, {end - start:.2f} s ({why})"
    if gap["note"]:
        text += f"; the recorder's note: {gap['note']}"
    return text


#: a spot holding a candidate in at least this share of a camera's frames is static
STATIC_SHARE = 0.5
#: ... and in at least this many of them (a few frames prove nothing)
STATIC_MIN_FRAMES = 10
#: grid cell of the spot search, pixels: a static candidate lies within 1.5 cells (6 px) of
#: its spot, far beyond a detector's jitter on a still object (well below a pixel)
STATIC_CELL_PX = 4.0
#: most static spots looked for per camera
STATIC_MOST_SPOTS = 4
_FRAME_BITS = 22  # a camera's frame rank in a key: 4 M frames (39 h at 30 fps)
_CELL_LIMIT = 1 << 19  # a cell index in a key, clipped: +-2 M px (4 px cells)


def static_candidates(detections: Detections) -> tuple[list[list[dict]], np.ndarray]:
    """Candidates that stay at one pixel spot through a camera's session, per camera.

    A second orange object in view (a static distractor) is a candidate in every frame, so
    the share of frames with a candidate reads 100 % though the ball was missed in half of
    them. Per camera, the grid cell (``STATIC_CELL_PX`` px) whose 3 x 3 neighbourhood holds a
    candidate in the most frames is a static spot when those frames (counted exactly on the
    neighbourhood's candidates) are at least ``STATIC_SHARE`` of the camera's frames and
    ``STATIC_MIN_FRAMES``; its candidates are static, and the search repeats on the rest, up
    to ``STATIC_MOST_SPOTS`` spots (0.8 s for 970,000 candidates of a 90-minute match). A
    ball at rest for half the session is one too: the figure says a candidate did not move,
    not what it was.

    Returns
    -------
    spots : per camera, a list of ``{"u", "v", "share"}``: the spot's median pixel
        (distorted, as detected) and the share of the camera's frames with a candidate there
    static : (C,) bool, the candidates at a spot
    """
    static = np.zeros(detections.n_candidates, dtype=bool)
    spots: list[list[dict]] = [[] for _ in detections.camera_names]
    if not detections.n_candidates:
        return spots, static
    offsets = [(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)]
    cand_camera = detections.frame_camera[detections.cand_frame]
    for i in range(len(detections.camera_names)):
        frames = np.flatnonzero(detections.frame_camera == i)
        need = max(STATIC_MIN_FRAMES, STATIC_SHARE * len(frames))
        rows = np.flatnonzero((cand_camera == i) & np.all(np.isfinite(detections.cand_uv), 1))
        rank = np.searchsorted(frames, detections.cand_frame[rows])  # frame of the camera
        if len(frames) >= 1 << _FRAME_BITS:  # (a frame rank must fit its key)
            continue
        # cells shifted to [1, 2^20 - 2]: with their neighbours, 20 bits each, non-negative
        cells = np.clip(np.floor(detections.cand_uv[rows] / STATIC_CELL_PX),
                        1 - _CELL_LIMIT, _CELL_LIMIT - 2).astype(np.int64) + _CELL_LIMIT
        keys = (cells[:, 0] << 21) | cells[:, 1]  # one int64 per cell (21 bits per axis)
        left = np.ones(len(rows), dtype=bool)
        for _ in range(STATIC_MOST_SPOTS):
            if np.count_nonzero(left) < need:
                break
            # frames per cell (one per frame however many candidates it has there), then per
            # 3 x 3 neighbourhood: a sum of its cells' counts (a still object's jitter across
            # a cell border splits its frames, never repeats them; the spot's share is then
            # counted exactly on its candidates)
            pairs = np.unique((keys[left] << _FRAME_BITS) | rank[left])
            cell_keys, n = np.unique(pairs >> _FRAME_BITS, return_counts=True)
            around = np.zeros(len(cell_keys), dtype=np.int64)
            for dx, dy in offsets:
                near = cell_keys + ((dx << 21) + dy)
                at = np.minimum(np.searchsorted(cell_keys, near), len(cell_keys) - 1)
                around += np.where(cell_keys[at] == near, n[at], 0)
            if around.max() < need:
                break
            best = cell_keys[np.argmax(around)]
            centre = np.array([best >> 21, best & ((1 << 21) - 1)])
            member = left & np.all(np.abs(cells - centre) <= 1, axis=1)
            share = len(np.unique(rank[member])) / len(frames)
            if share * len(frames) < need:  # (frames counted twice in the sum)
                break
            uv = detections.cand_uv[rows[member]]
            spots[i].append({"u": float(np.median(uv[:, 0])), "v": float(np.median(uv[:, 1])),
                             "share": share})
            static[rows[member]] = True
            left &= ~member
    return spots, static


def moving_frames(detections: Detections, static: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: the frames with a candidate off every static spot — the ball's detection
    rate, a static distractor's candidate (in every frame) left out (``pslog info``'s
    "moving", the viewer's detection rate). ``static``: :func:`static_candidates`' mask of
    the candidates (C,), found when not given."""
    if static is None:
        static = static_candidates(detections)[1]
    moving = np.zeros(detections.n_frames, dtype=bool)
    moving[detections.cand_frame[~static]] = True
    return moving


def session_info(path) -> dict:
    """Summary of a session file as a JSON-able dict.

    On a finished file: ``cameras`` (per camera: name, frames, fps nominal/measured, shutter
    offset as the rig states it and as measured on times corrected by the rig's clock model
    (see :func:`timing_table`), ``detection_rate`` (share of frames with at least one
    candidate), ``candidates_per_frame``, ``static_spots`` and ``moving_rate`` (share of
    frames with a candidate off every static spot: :func:`static_candidates`),
    images, the timing model's ``clock_offset_s``, ``clock_drift_ppm``, ``readout_s``),
    ``clock_corrected`` (any of those non-zero), ``clock_origin_ns`` (the session clock's
    origin on the original clock, 0 if none), ``topics`` (message counts), ``duration_s``,
    ``start_s``, ``end_s``, ``truth``, ``tables`` (columnar table -> ``ok`` or
    ``unusable: <reason>``, when the messages are read instead: :mod:`pslog.log.table`),
    ``tracks`` (method -> points), ``events``, ``camera_gaps`` (the stretches a camera sent
    no frame: :func:`camera_gaps`), ``offsets_off`` (cameras whose measured shutter offset
    is more than :data:`OFFSET_NOTE_S` from the rig's: :func:`offset_disagreements`),
    metadata fields, ``truncated: False`` and
    ``damaged`` (every chunk is checked: one dict per damaged chunk, see
    :func:`pslog.log.recover.describe_damage`; the rest of the summary leaves them out).
    On a truncated file, or one whose summary is damaged: ``truncated: True``, what is
    salvageable (``topics``, ``last_time_s`` of any message, per kind the keys of
    :func:`pslog.log.recover.salvage_summary`, ``kept_bytes``, ``file_bytes``, ``damaged``),
    ``still_recording`` (modified within the last :data:`RECENT_S` seconds or named
    ``*.partial``: a recorder may still be writing it), ``age_s`` and ``hint``.
    """
    path, size, complete = io.check_file(path, header=False)  # reported, as other damage
    if not complete:
        return _scanned_info(path, size, "its closing MCAP magic (the last 8 bytes) is damaged"
                             if io.tail_magic_damaged(path) else _UNFINISHED)
    from .reader import DamagedMetadataError, DamagedSummaryError, _Finished, _read

    try:
        f = _Finished(path, header=False)
    except DamagedSummaryError as exc:
        return _scanned_info(path, size, exc.reason,
                             metadata_named=isinstance(exc, DamagedMetadataError))
    with f:
        counts = dict(sorted(f.counts.items()))
        damaged = f.check_chunks()
        session = _read(f, frozenset(d["start"] for d in damaged))
        # each columnar table there: used, or why not (then the messages were read)
        tables = {name: ("ok" if f.table(name) is not None else
                         f"unusable: {f.table_problems.get(name, '?')}")
                  for name in sorted(f.attachments) if name.startswith("pslog/table/")}
    # read exactly all the same, but damage: readers refuse the file, recover repairs it
    for start, end, reason in f.metadata_damage:
        damaged.insert(0, {"start": start, "end": end, "reason": reason, "chunk": False,
                           "start_ns": None, "end_ns": None, "messages": None,
                           "label": "damaged record at bytes"})
    header, after = io.header_records_damage(path)  # (one read of the file's head)
    # the record after the Header: a metadata record's damage is in f.metadata_damage
    if after is not None and after[0] not in {d["start"] for d in damaged}:
        damaged.insert(0, {"start": after[0], "end": after[1], "reason": after[2],
                           "chunk": False, "start_ns": None, "end_ns": None, "messages": None,
                           "label": "damaged record at bytes"})
    if header is not None:  # nothing pslog reads, but damage all the same: readers refuse it
        start, end, reason = header
        damaged.insert(0, {"start": start, "end": end, "reason": f"MCAP Header record: {reason}",
                           "chunk": False, "start_ns": None, "end_ns": None, "messages": None})
    det = session.detections
    rig = session.rig
    times = det.frame_time_ns
    # measured on the times the rig's clock model corrects (as fusion sees them)
    cameras = timing_table(det, [cam.offset for cam in rig.cameras], rig)
    spots, static = static_candidates(det)
    moving = moving_frames(det, static)
    for i, (row, cam) in enumerate(zip(cameras, rig.cameras, strict=True)):
        row["static_spots"] = spots[i]
        n = row["frames"]
        row["moving_rate"] = (float(np.mean(moving[det.frame_camera == i])) if n
                              else float("nan"))
        row["fps_nominal"] = cam.fps
        row["offset_nominal_s"] = cam.offset  # as the rig states it
        row["images"] = counts.get(S.image_topic(cam.name), 0)
        # the timing model's parameters (pslog.timing), applied when fusing
        row["clock_offset_s"] = cam.clock_offset
        row["clock_drift_ppm"] = cam.clock_drift_ppm
        row["readout_s"] = cam.readout
    meta = session.metadata
    from ..timing import CLOCK_STD_KEY
    from .csvio import session_clock_origin
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
        "offset_reference": rig.names[0],
        "clock_corrected": any(cam.has_clock_correction for cam in rig.cameras),
        # (the clock model estimated on this session by 'pslog sync', not one given with the
        # rig: an earlier session's, carried into a new recording; walk42)
        "clock_synced": bool(meta.get(CLOCK_STD_KEY)),
        "clock_origin_ns": session_clock_origin(meta, path),
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
        "camera_gaps": [{**gap, "imported": str(meta.get("source", "")).startswith(
            "pslog import")} for gap in camera_gaps(det, rig, session.events)],
        "offsets_off": [{"camera": c["name"], "measured_s": c["offset_measured_s"],
                         "rig_s": c["offset_nominal_s"]} for c in cameras
                        if abs(c["offset_measured_s"] - c["offset_nominal_s"]) > OFFSET_NOTE_S],
        "file_bytes": size,
        "tables": tables,
        "damaged": damaged,
        "hint": (f"{len(damaged)} damaged "
                 f"{'chunk(s)' if all(d['chunk'] for d in damaged) else 'part(s)'}; run "
                 f"'pslog recover {shell_word(path)} -o FIXED.mcap' to salvage every intact one"
                 if damaged else ""),
    }


def _scanned_info(path, size: int, problem: str, metadata_named: bool = False) -> dict:
    import time

    from .recover import describe_damage, salvage_summary

    topics: dict[int, int] = {}
    last_ns: dict[int, int] = {}

    static: dict[str, bytes] = {}  # what recover rebuilds a lost metadata record from
    detection_ns: dict[str, tuple[list, list, list]] = {}
    scan = io.Scan()

    def count(cid: int, t: int, _seq: int, data: bytes) -> None:
        topics[cid] = topics.get(cid, 0) + 1
        last_ns[cid] = max(last_ns.get(cid, t), t)
        channel = scan.channels.get(cid)
        if channel is None:
            return
        if channel.topic.endswith(("/calibration", "/transform")):
            static.setdefault(channel.topic, data)
        elif channel.topic.endswith("/detections"):
            detection_ns.setdefault(channel.topic, ([], [], []))[0].append(t)

    io.salvage_file(path, count, scan=scan)
    if scan.damaged and not any(name == S.SESSION_METADATA for name, _ in scan.metadata):
        from .recover import _rebuilt_metadata

        where = (f"{path}: {problem}" if metadata_named else  # (the problem says where)
                 f"{path}: {problem}, and its session metadata (rig, cameras) is lost "
                 f"(damaged or cut at byte {scan.damaged[0].start})")
        if _rebuilt_metadata(static, detection_ns) is None:
            raise LogFormatError(f"{where}, with no intact calibration of every camera to "
                                 f"rebuild it from; the file is beyond repair")
        raise LogFormatError(f"{where}; run 'pslog recover {shell_word(path)} -o FIXED.mcap': it "
                             f"rebuilds the rig from the cameras' calibration messages")
    io.session_metadata(scan.metadata, path)
    name = {c: scan.channels[c].topic if c in scan.channels else f"channel {c}" for c in topics}
    named = {name[c]: n for c, n in topics.items()}
    last = max(last_ns.values(), default=None)
    age = max(time.time() - path.stat().st_mtime, 0.0)
    # a finished file (closing magic written) is not being recorded, whatever its age
    recording = (problem == _UNFINISHED and (age < RECENT_S or path.name.endswith(".partial")))
    damaged = [describe_damage(d, scan.channels) for d in scan.damaged]
    recover = f"run 'pslog recover {shell_word(path)} -o FIXED.mcap' to salvage the intact records"
    return {
        "path": str(path),
        "truncated": True,
        "problem": problem,
        "topics": dict(sorted(named.items())),
        "last_time_s": None if last is None else last / NS,
        **salvage_summary(named, {name[c]: t for c, t in last_ns.items()}),
        "kept_bytes": size - sum(d["end"] - d["start"] for d in damaged),
        "file_bytes": size,
        "damaged": damaged,
        "stop_reason": scan.stop_reason,
        "still_recording": recording,
        "age_s": age,
        "hint": (f"it may still be recording (modified {age:.0f} s ago"
                 + (", named *.partial" if path.name.endswith(".partial") else "")
                 + f"): wait for the recorder to finish; if none is running, {recover}"
                 if recording else f"{problem}; {recover}"),
    }
