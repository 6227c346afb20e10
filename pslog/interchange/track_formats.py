"""A session's fused tracks (and ground truth) in the formats of other tools.

- TUM trajectories (:func:`write_tum`), one file per method and ``truth.tum``: the format of
  the TUM RGB-D benchmark that ``evo_traj`` / ``evo_ape`` read. Lines ``timestamp tx ty tz
  qx qy qz qw``: seconds on the session clock, world metres, and the identity orientation
  ``0 0 0 1`` (a ball has a position, no orientation: evaluate with evo's default
  translation-only APE).
- JSON lines (:func:`write_jsonl`): one object per point, for pandas (``read_json(...,
  lines=True)``), jq and any language.
- Parquet (:func:`write_parquet`, needs pyarrow: ``pip install 'pslog[parquet]'``): one row
  per point, columnar.
- C3D (:func:`write_c3d`, needs the ``c3d`` package: ``pip install 'pslog[c3d]'``): one
  point per method (and ``truth``) on one uniform frame grid, in millimetres, for
  biomechanics tools (Mokka, OpenSim, Visual3D, ezc3d, btk).

Times: every format but C3D gives the exact integer nanoseconds of the session clock
(``time_ns``; TUM and JSON's ``time`` in seconds with 9 decimals). Each writer writes
``<file>.partial`` and renames it when complete (:func:`pslog.outputs.replacing`): an
existing file is replaced only with ``force`` and only by a complete one.
"""

from __future__ import annotations

import errno
import json
import math
import os
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError, OutputExistsError
from ..outputs import (
    check_output_path,
    not_a_folder,
    remove_when_done,
    replacing,
    write_error,
)

NS = 1_000_000_000
#: the TUM file of the ground truth, beside one ``<method>.tum`` per method
TRUTH_TUM = "truth.tum"
#: C3D label of the ground truth's point
TRUTH_LABEL = "truth"


def _seconds(time_ns: int) -> str:
    """Integer ns as exact decimal seconds, 9 digits (``12.000000001``)."""
    sign = "-" if time_ns < 0 else ""
    seconds, ns = divmod(abs(int(time_ns)), NS)
    return f"{sign}{seconds}.{ns:09d}"


def _tracks(session) -> dict:
    if not session.tracks:
        raise InputError(f"{session.path} has no fused tracks to export (run 'pslog fuse')")
    return {m: session.tracks[m] for m in sorted(session.tracks)}


# ---- TUM ----------------------------------------------------------------------------------

#: the first line of every TUM file pslog writes (how an earlier export is told apart)
TUM_HEADER = ("# timestamp tx ty tz qx qy qz qw (pslog: session clock s, world m, "
              "identity orientation)\n")


def tum_files(session, folder: str | Path) -> dict[str, Path]:
    """The files :func:`write_tum` writes: ``name -> path`` (methods, then ``truth``)."""
    folder = Path(folder)
    files = {method: folder / f"{method}.tum" for method in _tracks(session)}
    if session.truth is not None and len(session.truth):
        files["truth"] = folder / TRUTH_TUM
    return files


def write_tum(session, folder: str | Path, *, force: bool = False) -> dict[str, int]:
    """Write every fused track, and the truth, as TUM trajectories in ``folder``.

    ``folder`` is created if missing (its parent must exist). Every file is checked before
    any is written: with one already there and no ``force``, nothing is written. The folder
    then holds this export's trajectories only: an earlier export's ``<name>.tum`` (a file
    that starts with :data:`TUM_HEADER`) for a method this session lacks is refused without
    ``force`` and removed with it, once the new files are in place; any other file in the
    folder (one of yours, a ``.tum`` of another tool) is kept as it is.

    Returns
    -------
    dict : name (method or ``truth``) -> number of poses written
    """
    if os.fspath(folder) == "-":
        raise InputError("--tum '-': pslog writes a folder of files, not standard output; "
                         "give a folder name (./- for a folder named -)")
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--tum {folder}: a file, not a folder (TUM files are written into "
                         f"a folder, one per method)")
    files = tum_files(session, folder)
    if not folder.exists():
        if folder.is_symlink():  # a loop, or a link whose target is gone: not "File exists"
            try:
                os.stat(folder)
                what = f"a symbolic link to {os.readlink(folder)}, which does not exist"
            except OSError as exc:
                what = ("a loop of symbolic links" if exc.errno == errno.ELOOP else
                        f"a symbolic link to {os.readlink(folder)}, which does not exist")
            raise InputError(f"--tum {folder} is {what}; give the folder's real name or "
                             f"another name")
        if not folder.parent.is_dir():
            if folder.parent.exists():
                raise InputError(f"--tum {folder}: {not_a_folder(folder.parent)}")
            raise InputError(f"--tum {folder}: folder {folder.parent} does not exist")
        try:
            folder.mkdir()
        except OSError as exc:
            raise write_error(folder, exc) from None
    for path in files.values():  # all checked before any is written
        check_output_path(path, force, [session.path])
    obsolete = sorted(set(_earlier_tum_export(folder)) - set(files.values()))
    if obsolete and not force:
        raise OutputExistsError(f"--tum {folder} holds an earlier export's "
                                f"{', '.join(p.name for p in obsolete)}, which this session "
                                f"would not replace; use --force to replace the whole export "
                                f"(files of other tools in it are kept)")
    counts = {}
    for name, path in files.items():
        if name == "truth":
            times, positions = session.truth.time_ns, session.truth.position_world
        else:
            track = session.tracks[name]
            times, positions = track.time_ns, track.position_world
        counts[name] = _write_tum_file(path, times, positions, force, session.path)
    for path in obsolete:  # once the new ones are in place (all_or_nothing: after the moves)
        remove_when_done(path)
    return counts


def _earlier_tum_export(folder: Path) -> list[Path]:
    """The ``*.tum`` files in ``folder`` that a pslog export wrote (they start with
    :data:`TUM_HEADER`)."""
    found = []
    for path in folder.glob("*.tum"):
        try:
            if not path.is_file() or path.is_symlink():
                continue
            with open(path, "rb") as f:
                head = f.read(len(TUM_HEADER))
        except OSError:
            continue
        if head == TUM_HEADER.encode():
            found.append(path)
    return found


def _write_tum_file(path: Path, times: np.ndarray, positions: np.ndarray, force: bool,
                    source) -> int:
    with replacing(path, force=force, inputs=[source]) as f:
        f.write(TUM_HEADER)
        for t, (x, y, z) in zip(times.tolist(), positions.tolist(), strict=True):
            f.write(f"{_seconds(t)} {x!r} {y!r} {z!r} 0 0 0 1\n")
    return len(times)


# ---- JSON lines ---------------------------------------------------------------------------

def _finite_or_none(value: float):
    return value if math.isfinite(value) else None


def write_jsonl(session, path: str | Path, *, force: bool = False) -> int:
    """One JSON object per fused point, sorted by method then time::

        {"method": "typeA", "time": "0.011111111", "time_ns": 11111111,
         "position": [x, y, z], "camera": "cam2", "quality": {"ray_miss_m": 0.0004, ...}}

    ``time``: exact decimal seconds on the session clock (a string: a JSON number would be a
    double); ``position``: world metres; ``quality``: the track's per-point fields
    (:data:`pslog.records.QUALITY_FIELDS`), ``null`` where not applicable. Returns the
    number of lines."""
    tracks = _tracks(session)
    names = session.rig.names
    count = 0
    with replacing(path, force=force, inputs=[session.path]) as f:
        for method, track in tracks.items():
            quality = {k: v.tolist() for k, v in sorted(track.quality.items())}
            for i, (t, p, c) in enumerate(zip(track.time_ns.tolist(),
                                              track.position_world.tolist(),
                                              track.camera.tolist(), strict=True)):
                record = {"method": method, "time": _seconds(t), "time_ns": t, "position": p,
                          "camera": names[c],
                          "quality": {k: _finite_or_none(v[i]) for k, v in quality.items()}}
                f.write(json.dumps(record, allow_nan=False) + "\n")
            count += len(track)
    return count


# ---- Parquet ------------------------------------------------------------------------------

def write_parquet(session, path: str | Path, *, force: bool = False) -> int:
    """One row per fused point: ``method`` (string), ``time_ns`` (int64, session clock),
    ``time_s`` (float64), ``x``, ``y``, ``z`` (float64, world metres), ``camera`` (string),
    then one float64 column per quality field any track has (null where a track lacks it or
    it is not applicable). Rows sorted by method, then time. Needs pyarrow."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise InputError("--parquet needs pyarrow, which is not installed: pip install "
                         "'pslog[parquet]' (or pip install pyarrow)") from None
    tracks = _tracks(session)
    quality_names = sorted({k for t in tracks.values() for k in t.quality})
    names = np.array(session.rig.names, dtype=object)
    method = np.concatenate([np.full(len(t), m, dtype=object) for m, t in tracks.items()])
    time_ns = np.concatenate([t.time_ns for t in tracks.values()])
    position = np.concatenate([t.position_world for t in tracks.values()])
    camera = np.concatenate([names[t.camera] for t in tracks.values()])
    columns = {
        "method": pa.array(method, pa.string()),
        "time_ns": pa.array(time_ns, pa.int64()),
        "time_s": pa.array(time_ns / 1e9, pa.float64()),
        "x": pa.array(position[:, 0]), "y": pa.array(position[:, 1]),
        "z": pa.array(position[:, 2]),
        "camera": pa.array(camera, pa.string()),
    }
    for key in quality_names:
        values = np.concatenate([t.quality.get(key, np.full(len(t), np.nan))
                                 for t in tracks.values()])
        columns[key] = pa.array(values, pa.float64(), mask=~np.isfinite(values))
    table = pa.table(columns)
    with replacing(path, "wb", force=force, inputs=[session.path]) as f:
        pq.write_table(table, f)
    return table.num_rows


# ---- C3D ----------------------------------------------------------------------------------

def c3d_grid(session) -> tuple[float, int, int]:
    """The uniform frame grid of a session's C3D: ``(rate_hz, first_ns, n_frames)``.

    Rate: the highest point rate of the methods (1 / the mean interval between points of
    the densest track, its gaps left out: :func:`_point_interval`); when its cameras share
    one frame rate and that is within :data:`SHUTTER_RATE_TOLERANCE` of a whole multiple k of
    it, k times the frame rate exactly (k shutter phases a frame: a mean from a few seconds
    is 0.3 % off, enough to drift the grid off the points and put two on a frame); of those
    and 1 / the median interval, the one the points keep to best (:func:`_coherence`: a
    ``smooth --rate 89`` grid stays 89 Hz); rounded to 1e-6 Hz. Phase: the circular mean
    of the densest track's times modulo the frame period (Mardia & Jupp, *Directional
    Statistics*, 2000, sec. 2.2), so that its points sit at the frames' centres: exact for
    points on a regular shutter
    schedule such as type A's, and with jittered times (host stamps) the fewest points are
    half a period from their frame, where two fall on one. First frame: the one of that
    phase nearest the earliest point (at most half a period from it); every point is put on
    its nearest frame.

    Where that grid puts more than :data:`C3D_SHARED_SHARE` of the tracks' points on a frame
    with another (left out), the multiples ``k · fps`` (``k`` = 1 .. :data:`C3D_MULTIPLES`)
    of the cameras' frame rates are tried (session 41: two 60 fps cameras 4 ms apart, the
    ball missed in a fifth of the frames: the rate chosen so, 78.9 Hz (the median's),
    left out 30 % of a track; 240 Hz holds every point within 0.1 ms of its frame): the
    lowest that leaves out as few points as any (within that share) and that the densest
    track keeps to (:func:`_coherence` at least :data:`C3D_COHERENT`: a jittered schedule
    keeps to no finer grid, and stays on the first), within :data:`C3D_GRID_MAX_FRAMES`
    frames.
    (Review41b: two 30 fps cameras 3 ms apart first hold their points apart on a grid they
    keep to at 10 x 30 Hz, beyond the 8 x tried before.)
    """
    tracks = _tracks(session)
    spans = [(_point_interval(t.time_ns), t) for t in tracks.values() if len(t) > 1]
    spans = [(d, t) for d, t in spans if d > 0]
    if not spans:
        raise InputError(f"{session.path}: C3D needs a track of at least two points at "
                         f"different times to set its frame rate")
    interval, densest = min(spans, key=lambda s: s[0])
    # (intervals > 0: points of one time, a filter's of cameras firing together, made the
    # median 0 and the rate a ZeroDivisionError traceback)
    steps = np.diff(densest.time_ns)
    rates: list[float] = [NS / interval, NS / float(np.median(steps[steps > 0]))]
    fps = {cam.fps for cam in session.rig.cameras}
    if len(fps) == 1:  # the shutters' own rate: k shutter phases a frame period of the rig
        k = round(rates[0] / (frame_rate := fps.pop()))
        if k >= 1 and abs(rates[0] - k * frame_rate) <= SHUTTER_RATE_TOLERANCE * rates[0]:
            rates.insert(0, float(k * frame_rate))
    # the one whose frames the points keep to best (a grid of --rate 89 Hz is not 90's)
    coherence = [_coherence(densest.time_ns, r) for r in rates]
    rate = round(rates[int(np.argmax(coherence))], 6)
    earliest = min(int(t.time_ns.min()) for t in tracks.values() if len(t))
    last = max(int(t.time_ns.max()) for t in tracks.values() if len(t))

    def grid(rate: float) -> tuple[float, int, int]:
        period = NS / rate
        angle = 2 * np.pi * ((densest.time_ns - earliest) % period) / period
        phase = float(np.angle(np.mean(np.exp(1j * angle)))) / (2 * np.pi) * period
        first = earliest + round(phase)  # |phase| <= period / 2: frame 0 is the earliest's
        return rate, first, round((last - first) * rate / NS) + 1

    def left_out(rate: float, first: int) -> int:
        """The tracks' points sharing a frame with another on the grid."""
        return sum(len(t) - len(np.unique(np.round((t.time_ns - first) * rate / NS)))
                   for t in tracks.values())

    chosen = grid(rate)
    total = sum(len(t) for t in tracks.values())
    lost_chosen = left_out(rate, chosen[1])
    if lost_chosen <= C3D_SHARED_SHARE * total:
        return chosen
    # points left out: the multiples of the cameras' frame rates, lowest first, as fine as
    # C3D's frames allow (review41b: two 30 fps cameras 3 ms apart, a tenth of the ball
    # missed, lost 41 % of the points on the median's 33 Hz: the first multiple holding
    # them apart that the points keep to, 300 Hz, is k = 10, beyond the 8 tried)
    top = max(1.0, (C3D_GRID_MAX_FRAMES - 1) * NS / max(last - earliest, 1))
    trials = sorted({round(k * f, 6) for f in {cam.fps for cam in session.rig.cameras}
                     for k in range(1, min(C3D_MULTIPLES, int(top / f)) + 1)})
    found = [(r, first, n) for r, first, n in map(grid, trials) if n <= C3D_GRID_MAX_FRAMES]
    lost = [left_out(r, first) for r, first, _n in found]
    least = min(lost, default=total)
    for (r, first, n), k in zip(found, lost, strict=True):
        if k <= least + C3D_SHARED_SHARE * total and k < lost_chosen and (
                _coherence(densest.time_ns, r) >= C3D_COHERENT):
            return r, first, n
    return chosen


#: a point rate this close (relative) to k times the cameras' frame rate is k shutters a frame
SHUTTER_RATE_TOLERANCE = 0.02
#: the multiples of the cameras' frame rates :func:`c3d_grid` tries where points are left out
#: (at most: those within :data:`C3D_MAX_FRAMES` frames)
C3D_MULTIPLES = 1000
#: the share of the points :func:`c3d_grid` lets share a frame (left out) on the grid it keeps
C3D_SHARED_SHARE = 1e-3
#: the least :func:`_coherence` of the densest track with a finer grid :func:`c3d_grid` takes
C3D_COHERENT = 0.9
#: intervals longer than this many times the median are gaps (a missed detection), not the
#: schedule's own: left out of :func:`_point_interval`'s mean
GAP_INTERVAL = 1.5


def _point_interval(time_ns: np.ndarray) -> float:
    """A track's mean interval between points, ns: the mean of its intervals up to
    :data:`GAP_INTERVAL` times their median (a missed detection's longer one left out).

    Not the median itself: shutters spread unevenly over the frame period (4 x 60 fps at
    0 / 2.9 / 7.4 / 12.6 ms: intervals 2.9, 4.5, 5.2, 4.1 ms) have a median interval (4.3
    ms, 232 Hz) longer than their mean (4.17 ms, 240 Hz, the rate their points come at), and
    a grid at the median's rate has fewer frames than points: walk41's C3D left out 12 % of
    every method's points, "sharing a frame". For evenly spread shutters (type A), jittered
    or not, both are the same period."""
    intervals = np.diff(np.asarray(time_ns, dtype=np.int64)).astype(np.float64)
    intervals = intervals[intervals > 0]
    if not len(intervals):
        return 0.0
    median = float(np.median(intervals))
    return float(np.mean(intervals[intervals <= GAP_INTERVAL * median]))


def _coherence(time_ns: np.ndarray, rate: float) -> float:
    """How well times keep to a grid of ``rate`` Hz: the mean resultant length of their
    phases on it (1: all at one phase; a grid drifting off them over the session: near 0)."""
    t = (np.asarray(time_ns, dtype=np.int64) - int(time_ns[0])).astype(np.float64)
    phase = 2 * np.pi * np.mod(t * (rate / NS), 1.0)
    return float(np.hypot(np.mean(np.cos(phase)), np.mean(np.sin(phase))))


#: most frames of a finer grid :func:`c3d_grid` tries: what the header's 16-bit frame numbers
#: hold, which every reader reads (a finer grid is never the reason for a long file)
C3D_GRID_MAX_FRAMES = 65535
#: most frames a C3D file of pslog holds. Beyond 65535 the header's 16-bit first and last
#: frame say 65535 and the count is in the parameters, as c3d.org's "Maintaining C3D frame
#: count compatibility" has it (the ``c3d`` package writes them so): ``POINT:LONG_FRAMES``
#: (a float32: whole numbers exact up to 2**24, hence this limit; 51.8 h at 90 Hz),
#: ``POINT:FRAMES`` 65535 and ``TRIAL:ACTUAL_START_FIELD`` / ``ACTUAL_END_FIELD`` (each two
#: 16-bit words, low first), which btk (Mokka) and the ``c3d`` reader take
C3D_MAX_FRAMES = 2**24


def c3d_check(session) -> tuple[float, int, int]:
    """:class:`InputError` when :func:`write_c3d` would refuse ``session`` (no c3d package,
    no track to set the frame rate, too many frames): said before any file is written.
    Returns the grid (:func:`c3d_grid`), for :func:`write_c3d`'s ``grid``."""
    try:
        import c3d  # noqa: F401 (only whether it is there)
    except ImportError:
        raise InputError("--c3d needs the c3d package, which is not installed: pip install "
                         "'pslog[c3d]' (or pip install c3d)") from None
    rate, first, n_frames = c3d_grid(session)
    if n_frames > C3D_MAX_FRAMES:  # (its frame count, a float32 parameter, inexact beyond)
        raise InputError(f"{session.path}: {n_frames} frames at {rate:g} Hz: beyond the "
                         f"{C3D_MAX_FRAMES} frames a C3D file counts exactly (its "
                         f"POINT:LONG_FRAMES is a 32-bit float); export --csv, --jsonl or "
                         f"--parquet, or cut the session")
    return rate, first, n_frames


def write_c3d(session, path: str | Path, *, force: bool = False,
              grid: tuple[float, int, int] | None = None
              ) -> tuple[int, float, dict[str, tuple[int, int]]]:
    """Write one C3D point per method (labels are the method names) and ``truth`` (when the
    session has one, interpolated at the frame times), on the grid of :func:`c3d_grid`.

    Units: ``POINT:UNITS = "mm"`` with the coordinates in millimetres (pslog's metres times
    1000), the unit biomechanics tools expect; floating-point storage, so nothing is lost to
    a scale factor. A frame where a method has no point holds an invalid point (residual
    -1); the residual of a valid point is the method's ``ray_miss_m`` in mm when it has one,
    else 0. A method whose points each have a frame of their own is written point by point,
    each on its nearest frame. One of which two points would fall on one frame (irregular
    times: rolling shutters, drifting clocks, jittered host stamps; the nearer was kept and
    the other left out, 11-30 % of a rolling-shutter session's points) is resampled onto the
    grid instead (:func:`_resample`): its position at each frame's time, linear between the
    points either side, where the session's detections explain the gap between them
    (:func:`_detection_gaps`): no detection whose point the method left out lies between
    them, at most :data:`C3D_BRIDGE_MISSED` frame without the ball, and at most
    :data:`C3D_BRIDGE_PERIODS` frame periods of the grid or :data:`GAP_INTERVAL` of the
    slowest camera apart, the longer (the bound for frames the session lost, which have no
    row to count; a method that does not make a point a detection: no more than
    :data:`GAP_INTERVAL` times its median interval either). Any other gap stays empty, but
    for a lone point in it, on its nearest frame (of lone points nearest one frame, the
    nearest in time; the others counted). Which methods, their valid frames and their
    points left out so are returned for the command to say.

    C3D numbers its frames with integers (``POINT:RATE`` and the header's first frame): the
    first frame's time is ``(first_frame - 1) / rate`` on the session clock only to within
    half a frame period; the exact time of frame 1 is stored as ``PSLOG:FIRST_FRAME_S``
    (decimal seconds, a string: C3D has no 64-bit number). ``grid``: :func:`c3d_check`'s
    return for this session, when the caller checked it (the grid is the export's costliest
    part: a 36 s rally's took 0.07 s, and was made three times).

    Returns
    -------
    (n_frames, rate_hz, {method resampled: (its valid frames, its lone points left out
    beside a nearer one)})
    """
    if grid is None:  # (given: :func:`c3d_check`'s, the session checked)
        grid = c3d_check(session)
    import c3d

    tracks = _tracks(session)
    rate, first, n_frames = grid
    labels = list(tracks)
    has_truth = session.truth is not None and len(session.truth) > 1
    if has_truth:
        labels.append(TRUTH_LABEL)
    points = np.zeros((n_frames, len(labels), 5), dtype=np.float32)
    points[:, :, 3] = -1.0  # invalid until a point is put there
    frame_ns = first + np.round(np.arange(n_frames) * (NS / rate)).astype(np.int64)
    resampled: dict[str, tuple[int, int]] = {}
    # a gap of lost frames (no row in the session): bridged up to 1.5 frame periods of the
    # slowest camera (a sync rig's points come in bunches a frame period apart) or two of
    # the grid's
    longest_ns = max(C3D_BRIDGE_PERIODS * NS / rate,
                     GAP_INTERVAL * NS / min(cam.fps for cam in session.rig.cameras))
    for j, (method, track) in enumerate(tracks.items()):
        frames = np.clip(np.round((track.time_ns - first) * rate / NS).astype(np.int64), 0,
                         n_frames - 1)
        residual = track.quality.get("ray_miss_m", np.zeros(len(track)))
        residual = np.where(np.isfinite(residual), residual * 1000.0, 0.0)
        if len(np.unique(frames)) == len(track):  # a frame for each point: the points
            points[frames, j, :3] = track.position_world * 1000.0
            points[frames, j, 3] = residual
            points[frames, j, 4] = 0.0
            continue
        withheld, missed = _detection_gaps(session, method)
        bridge_ns = longest_ns
        if withheld is None:  # not a point a detection: no longer than its own spacing
            bridge_ns = min(bridge_ns, GAP_INTERVAL * _median_step(track.time_ns))
        valid, position, res, nearer = _resample(track.time_ns, track.position_world,
                                                 residual, frame_ns, bridge_ns, withheld,
                                                 missed)
        points[valid, j, :3] = position * 1000.0
        points[valid, j, 3] = res
        points[valid, j, 4] = 0.0
        resampled[method] = (len(valid), nearer)
    if has_truth:
        at = session.truth.at(frame_ns)
        ok = np.all(np.isfinite(at), axis=1)
        points[ok, -1, :3] = at[ok] * 1000.0
        points[ok, -1, 3] = 0.0
    writer = _exact_start_writer(c3d)(point_rate=float(rate), analog_rate=0.0,
                                      point_scale=-1.0, point_units="mm  ")
    writer.set_point_labels(labels)
    start_frame = round(first * rate / NS) + 1  # frame 1 at the clock's 0
    writer.set_start_frame(start_frame)
    # the integer start frame is within half a period of the grid's first time: the exact
    # time, for a reader that needs it
    group = writer.add_group(max((i for i, _g in writer.group_listed()), default=0) + 1,
                             "PSLOG", "pslog's export")
    text = _seconds(first)
    group.add_str("FIRST_FRAME_S", "session-clock time of the first frame, seconds", text,
                  len(text))
    writer.add_frames([(frame, np.zeros((0, 0), dtype=np.float32)) for frame in points])
    with replacing(path, "wb", force=force, inputs=[session.path]) as f, \
            warnings.catch_warnings():
        # c3d warns "No analog data found in file." for a points-only file, which is what a
        # tracker has: not a problem to show the user
        warnings.simplefilter("ignore", UserWarning)
        writer.write(f)
        if start_frame >> 16:  # c3d's own reader: as many frames more, each invalid here
            f.seek(512 * (int(writer.header.data_block) - 1) + points[:, :, :4].nbytes)
            f.write(_invalid_frames(start_frame >> 16, len(labels)))
            f.truncate()
            f.write(bytes(-f.tell() % 512))
    return n_frames, rate, resampled


def _invalid_frames(n: int, n_points: int) -> bytes:
    """``n`` C3D frames of ``n_points`` invalid points (float storage: x y z 0, residual
    word -1), written after a file's last frame where the ``c3d`` package's reader (0.6)
    reads one frame more per 65,536 of a start frame past 65,535 (its ``first_frame`` joins
    TRIAL:ACTUAL_START_FIELD's words as ``low + 65535 · high``): it reads those instead of
    the block's zero padding, which is a valid point at the origin; every other reader takes
    the count from the parameters and reads none of them."""
    frame = np.zeros((n, n_points, 4), dtype="<f4")
    frame[:, :, 3] = -1.0
    return frame.tobytes()


def _exact_start_writer(c3d):
    """``c3d.Writer`` with its start frame read back as the file format has it. ``write``
    takes the start frame from the writer's ``first_frame``, which (``c3d`` 0.6, the
    reader's code) joins TRIAL:ACTUAL_START_FIELD's two 16-bit words as ``low + 65535 ·
    high``, and writes that back: a start past frame 65,535 was written one frame early per
    65,536 (a track at 1000 s on a 90 Hz grid, frame 90,004: 90,003, its every frame 11 ms
    early to btk and Mokka, which read ``high << 16 | low``). Here ``first_frame`` is the
    words' 32-bit value, so ``write`` keeps the frame :func:`write_c3d` set."""

    class Writer(c3d.Writer):
        @property
        def first_frame(self) -> int:
            param = self.get("TRIAL:ACTUAL_START_FIELD")
            if param is None:
                return int(self.header.first_frame)
            low, high = (int(w) for w in param.uint16_array)
            return high << 16 | low

    return Writer


#: :func:`write_c3d` resamples a method's track at a frame's time between the points either
#: side of it when at most :data:`C3D_BRIDGE_MISSED` of the session's frames between them
#: lack the ball (the method's gate kept no candidate of theirs: one missed detection
#: bridged) and none holds a detection whose point the method withheld
#: (:func:`_detection_gaps`: a gap the method left stays empty); and, for frames the session
#: lost (no row), no longer than this many frame periods of the grid or
#: :data:`GAP_INTERVAL` frame periods of the slowest camera
C3D_BRIDGE_PERIODS = 2.0
#: the frames without the ball a bridge of :func:`_resample` may cross
C3D_BRIDGE_MISSED = 1
#: a method makes a point a detection when it has points at this share of the times of the
#: detections its gate kept, at least (type A, smooth, filter, nearest: 0.9-1; typeB,
#: linear, sync make one of several cameras' detections: 0.1-0.4)
C3D_POINT_A_DETECTION = 0.5


def _detection_gaps(session, method: str) -> tuple[np.ndarray | None, np.ndarray]:
    """What the session's detections say of the gaps in ``method``'s track: ``(withheld,
    missed)``, sorted int64 ns.

    ``withheld``: the capture times of the ball's detections the method made no point at.
    The ball's detections are the candidates its gating kept (every candidate less the
    track's ``rejections``), at their true times (:func:`pslog.timing.true_times_ns`: clock
    offset, drift, the rolling shutter's row), the times the methods give their points. A
    point the method left out (``Track.dropped``: smooth's ``contradicted_run``, type A's
    ``kink``, ``contradicted`` or ``break``, the filter's ``held``, ...) is not in the
    track, so its detection is here: a gap holding one is the method's, and
    :func:`_resample` does not bridge it. None for a method that does not make a point a
    detection (fewer than :data:`C3D_POINT_A_DETECTION` of them at its points' times:
    typeB, linear and sync make one of several cameras' detections, ``smooth --rate`` its
    own grid): its detections without a point are no sign of a point withheld.

    ``missed``: the top-row true times of the session's frames holding no such candidate (a
    frame whose candidates the gate all refused holds no ball for the method, as a missed
    one)."""
    from ..timing import camera_parameters, true_times_ns

    track, d = session.tracks[method], session.detections
    p = camera_parameters(session.rig)
    frame, camera = d.cand_frame, d.frame_camera[d.cand_frame]
    keep = np.ones(len(frame), dtype=bool)
    rejected = session.rejections.get(method)
    if rejected is not None and len(rejected):  # (camera, frame counter, pixel) as stored
        def keys(cam, index, uv):
            table = np.empty(len(cam), dtype=[("c", "<i8"), ("i", "<i8"), ("u", "<f8"),
                                              ("v", "<f8")])
            table["c"], table["i"], table["u"], table["v"] = cam, index, uv[:, 0], uv[:, 1]
            return table
        keep = ~np.isin(keys(camera, d.frame_index[frame], d.cand_uv),
                        keys(rejected.camera, rejected.frame_index, rejected.uv))
    frame, camera = frame[keep], camera[keep]
    seen = np.unique(true_times_ns(d.frame_time_ns[frame], d.cand_uv[keep, 1],
                                   p["height"][camera], p["clock_offset"][camera],
                                   p["clock_drift_ppm"][camera], p["readout"][camera]))
    empty = np.ones(len(d.frame_time_ns), dtype=bool)
    empty[frame] = False
    cam = d.frame_camera[empty]
    missed = np.sort(true_times_ns(d.frame_time_ns[empty], 0.0, p["height"][cam],
                                   p["clock_offset"][cam], p["clock_drift_ppm"][cam],
                                   p["readout"][cam]))
    made = np.isin(seen, track.time_ns)
    if not len(seen) or np.count_nonzero(made) < C3D_POINT_A_DETECTION * len(seen):
        return None, missed
    return seen[~made], missed


def _median_step(time_ns: np.ndarray) -> float:
    """The median interval between a track's distinct times, ns (inf with fewer than two)."""
    steps = np.diff(np.unique(np.asarray(time_ns, np.int64)))
    return float(np.median(steps)) if len(steps) else math.inf


def _resample(time_ns: np.ndarray, position: np.ndarray, residual: np.ndarray,
              frame_ns: np.ndarray, bridge_ns: float, withheld: np.ndarray | None = None,
              missed: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """A track at the frame times ``frame_ns`` (a uniform grid): ``(frames, positions,
    residuals, nearer)`` of the frames inside it, each linear in time between the points
    either side of its time (a point at the frame's time exactly: that point), where those
    are at most ``bridge_ns`` apart, no time of ``withheld`` lies between them (sorted int64
    ns: the detections the method made no point at, :func:`_detection_gaps`; a span the
    method left empty stays empty) and at most :data:`C3D_BRIDGE_MISSED` of ``missed`` (the
    frames without the ball). A point with no frame so (no bridge reaches
    its nearest frame) goes on its nearest frame as it is, so that its place in the track
    is in the file; where two or more such points are nearest one frame (all within one
    frame period, no frame between them), the frame holds the one nearest its time, the
    track's position there to within the least time (nearest-neighbour resampling), and
    the others are counted: ``nearer``, said by ``pslog export``. Points of one time
    (cameras firing together) are first made one, their mean."""
    order = np.argsort(time_ns, kind="stable")
    t, inverse, count = np.unique(np.asarray(time_ns, np.int64)[order], return_inverse=True,
                                  return_counts=True)
    pos = np.zeros((len(t), 3))
    np.add.at(pos, inverse, np.asarray(position, np.float64)[order])
    pos /= count[:, None]
    res = np.zeros(len(t))
    np.add.at(res, inverse, np.asarray(residual, np.float64)[order])
    res /= count
    if len(t) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), 0
    after = np.searchsorted(t, frame_ns, side="left")  # first point at or after the frame
    exact = (after < len(t)) & (t[np.minimum(after, len(t) - 1)] == frame_ns)
    inside = (after > 0) & (after < len(t))
    a = np.clip(after - 1, 0, len(t) - 1)
    b = np.clip(after, 0, len(t) - 1)
    inside &= (t[b] - t[a]) <= bridge_ns
    if withheld is not None and len(withheld):  # no bridge across a point the method withheld
        inside &= (np.searchsorted(withheld, t[b], side="left")
                   == np.searchsorted(withheld, t[a], side="right"))
    if missed is not None and len(missed):  # nor across frames without the ball, but one
        inside &= (np.searchsorted(missed, t[b], side="left")
                   - np.searchsorted(missed, t[a], side="right")) <= C3D_BRIDGE_MISSED
    frames = np.flatnonzero(exact | inside)
    a, b = a[frames], b[frames]
    w = np.where(exact[frames], 1.0,
                 (frame_ns[frames] - t[a]) / np.maximum(t[b] - t[a], 1).astype(np.float64))
    out_pos = pos[a] + w[:, None] * (pos[b] - pos[a])
    out_res = res[a] + w * (res[b] - res[a])
    # a point with no neighbour within the bridge (a lone point between gaps) is on no
    # frame yet: on its nearest frame, as it is (the nearest in time of such points there;
    # the others counted)
    period = float(frame_ns[1] - frame_ns[0]) if len(frame_ns) > 1 else 1.0
    near = np.clip(np.round((t - frame_ns[0]) / period).astype(np.int64), 0,
                   len(frame_ns) - 1)
    lone = np.flatnonzero(~np.isin(near, frames))
    nearer = 0
    if len(lone):
        lone = lone[np.lexsort((np.abs(t[lone] - frame_ns[near[lone]]), near[lone]))]
        first = np.r_[True, near[lone][1:] != near[lone][:-1]]
        nearer = int(np.count_nonzero(~first))
        lone = lone[first]
        frames = np.concatenate([frames, near[lone]])
        out_pos = np.concatenate([out_pos, pos[lone]])
        out_res = np.concatenate([out_res, res[lone]])
        order = np.argsort(frames)
        frames, out_pos, out_res = frames[order], out_pos[order], out_res[order]
    return frames, out_pos, out_res, nearer
