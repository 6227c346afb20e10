"""A ground truth of one's own (motion capture, a measured trajectory) read for ``pslog eval
--truth FILE``: a CSV ``t,x,y,z`` or a TUM trajectory, the formats ``pslog export`` writes.

- CSV: a header naming the time column ``t`` (or ``time``, ``timestamp``) and ``x, y, z``
  (separated by commas, or by tabs throughout);
  other columns are ignored (``pslog export --csv``'s ``camera`` and quality columns), but a
  ``method`` column must hold one method (a tracks CSV of one method, the truth of another
  rig). Times in seconds **on the original clock**: the clock of the CSV ``pslog import``
  read (Unix-epoch times stay Unix-epoch), as ``pslog export --csv`` and ``--detections``
  write them; for a session not imported (simulated, recorded) it is the session clock.
- TUM (``timestamp tx ty tz [qx qy qz qw]``, space separated, ``#`` comment lines): times
  in seconds **on the session clock**, as ``pslog export --tum`` writes ``truth.tum`` (and
  evo reads it); the orientation is ignored.

Positions are world metres. Times are parsed exactly to the nanosecond (decimal, never
through float64), so an exported truth read back is the same to the bit. A truth's times
must increase strictly, and it needs two samples with a position at least; the truth is
interpolated linearly between the samples (:meth:`pslog.records.Truth.at`). A row whose x, y
and z are all empty (or all NaN) is a gap, as motion-capture software writes a marker it lost
(session 40, review40): the truth is NaN there, so the points between the samples around it
are not scored (``truth_gap``) rather than scored against a straight line across the gap (a
lost second of a rally: smooth's max error 16 -> 646 mm). Any other position must be finite.
A CSV is comma-separated, or tab-separated where its name ends ``.tsv`` or its header holds
tabs and no comma (Qualisys' export). :func:`truth_for_tracks` puts it on the session clock
and refuses a truth that shares no time with the tracks (naming both spans), one on the
other clock than its format's (naming the offset) and one whose positions look like
millimetres.
"""

from __future__ import annotations

import codecs
import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..inputs import binary_format, check_input_file
from ..log._mcapio import starts_as_mcap
from ..log.csvio import csv_rows
from ..records import NS, Track, Truth

#: bytes of a truth file judged text or not before the rest is read
_TEXT_PROBE_BYTES = 1 << 20
#: the names a CSV truth's time column may have (seconds)
TIME_COLUMNS = ("t", "time", "timestamp")
#: a truth whose positions lie a median this far (metres) from the world origin, a hundred
#: times further than the tracks', is taken for millimetres and refused (as ``pslog rig
#: import`` refuses cameras beyond 100 m without ``--units``)
MILLIMETRE_LIMIT_M = 100.0
#: a truth coordinate beyond this many metres from the world origin is refused, naming its
#: line: no rig's world (1e308 was read, and the error sums overflowed with a numpy warning)
MAX_POSITION_M = 1e6
#: a truth whose samples lie a median this many times the tracks' point steps apart, over a
#: span this many times theirs, holds times in another unit than seconds (milliseconds:
#: 1000) and is refused (as ``pslog import`` refuses detections so far apart,
#: :data:`pslog.log.csvio._UNIT_RATIO`); a truth that is merely sparse (a ball at rest
#: measured twice) spans the tracks' time, not hundreds of times it
UNIT_RATIO = 300.0


@dataclass(frozen=True)
class TruthFile:
    """A truth trajectory as read from a file, its times on the file's own clock.

    Attributes
    ----------
    path : Path
    format : str, ``"csv"`` or ``"tum"``
    clock : str, ``"original"`` (CSV: the clock of the imported detections, session time +
        the session's clock origin) or ``"session"`` (TUM)
    truth : Truth, n >= 2 samples: time_ns (n,) int64 on that clock, strictly increasing;
        position_world (n, 3) float64, metres, finite but in a gap's rows (all NaN), two
        rows finite at least
    """

    path: Path
    format: str
    clock: str
    truth: Truth


def read_truth_file(path: str | Path) -> TruthFile:
    """Read a truth trajectory (CSV ``t,x,y,z`` or TUM: the module docstring).

    The format is a ``.tum`` or ``.csv`` / ``.tsv`` suffix's, else the content's: a first
    line starting with ``#``, or a number and no comma, is TUM; anything else a CSV (its
    first line the header).

    Raises
    ------
    InputError : a missing or unreadable file, an MCAP session, JSON, a detections CSV, a
        malformed line (named), times not increasing, a position not finite (but a gap's:
        x, y, z all empty or NaN), fewer than two samples with a position, a tracks CSV of
        several methods
    """
    path = Path(path)
    check_input_file(path)
    if starts_as_mcap(path):
        raise InputError(f"{path} is an MCAP session, not a truth trajectory (a CSV t,x,y,z "
                         f"or a TUM file; a session's own truth needs no --truth)")

    def binary(byte: int, why: str = "is not UTF-8 text") -> InputError:
        kind = binary_format(data, path)
        if kind == "parquet":
            return InputError(f"{path} is a Parquet file, not a truth trajectory (a CSV "
                              f"t,x,y,z or a TUM file)")
        if kind == "c3d":
            return InputError(f"{path} is a C3D file: --truth reads a CSV t,x,y,z (seconds, "
                              f"metres) or a TUM trajectory, not C3D; export the marker's "
                              f"trajectory from your motion-capture software as CSV")
        return InputError(f"{path}: not a text file (byte {byte} {why}); expected a CSV "
                          f"t,x,y,z or a TUM trajectory")

    data = b""
    try:
        with open(path, "rb") as handle:
            # (its first MiB judged before the rest is read: a video given by mistake, GBs,
            # was read whole into memory, twice, before 'not a text file')
            data = handle.read(_TEXT_PROBE_BYTES)
            try:
                codecs.getincrementaldecoder("utf-8")().decode(data, final=False)
            except UnicodeDecodeError as exc:
                raise binary(exc.start) from None
            if b"\0" in data:
                raise binary(data.index(b"\0"), "is a NUL")
            data += handle.read()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise binary(exc.start) from None
    first = next((line.strip() for line in text.splitlines() if line.strip()), "")
    if not first:
        raise InputError(f"{path}: empty file (expected a CSV t,x,y,z or a TUM trajectory)")
    if first.startswith(("{", "[")):
        raise InputError(f"{path} holds JSON, not a truth trajectory (a CSV t,x,y,z or a TUM "
                         f"file)")
    suffix = path.suffix.lower()
    tum = (suffix == ".tum" or (suffix not in (".csv", ".tsv") and (
        first.startswith("#") or ("," not in first and _is_number(first.split()[0])))))
    if tum:
        times, positions, lines = _read_tum(text, path)
    else:
        tabs = suffix == ".tsv" or ("\t" in first and "," not in first)
        times, positions, lines = _read_csv(text, path, "\t" if tabs else ",")
    n_known = int(np.count_nonzero(np.isfinite(positions).all(axis=1)))
    if n_known < 2:
        gaps = len(times) - n_known
        raise InputError(f"{path}: {n_known} sample{'s' if n_known != 1 else ''}"
                         f"{f' with a position ({gaps} gap rows)' if gaps else ''}: a truth "
                         f"needs two at least (it is interpolated between them)")
    step = np.diff(times)
    bad = np.flatnonzero(step <= 0)
    if len(bad):
        k = int(bad[0])
        from ..log.csvio import format_time

        raise InputError(f"{path}: line {lines[k + 1]}: time {format_time(times[k + 1])} s "
                         f"is not after line {lines[k]}'s {format_time(times[k])} s: a "
                         f"truth's times must increase (sort the rows by time; of a time "
                         f"given twice keep one)")
    return TruthFile(path, "tum" if tum else "csv", "session" if tum else "original",
                     Truth(times, positions))


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _number(text: str, what: str, path: Path, line: int) -> float:
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is None or not np.isfinite(value) or abs(value) > MAX_POSITION_M:
        reason = ("empty" if not text.strip() else
                  "not a number" if value is None else "not a finite number"
                  if not np.isfinite(value) else
                  f"beyond any rig's world (at most {MAX_POSITION_M:g} m from the origin)")
        raise InputError(f"{path}: line {line}: {what} {text!r}: {reason}"
                         + (" (every truth sample needs a position in metres; a gap, a time "
                            "without one: x, y and z all empty)" if "world" not in reason
                            else ""))
    return value


def _position(cells: list[str], names: list[str], path: Path,
              line: int) -> tuple[float, float, float]:
    """A row's x, y, z: NaN where all three are empty or NaN (a gap: a marker the motion
    capture lost), else each a finite number (:func:`_number`)."""
    if all(not cell.strip() or cell.strip().lower() == "nan" for cell in cells):
        return (np.nan, np.nan, np.nan)
    x, y, z = (_number(cell, f"{name} value", path, line)
               for cell, name in zip(cells, names, strict=True))
    return (x, y, z)


def _seconds(text: str, path: Path, line: int) -> int:
    from ..log.csvio import _Invalid, _time_ns

    try:
        return _time_ns(text.strip())
    except _Invalid as exc:
        reason = str(exc)
    except ValueError:
        reason = "not a number of seconds"
    raise InputError(f"{path}: line {line}: time {text.strip()!r}: {reason}")


def _read_csv(text: str, path: Path,
              delimiter: str = ",") -> tuple[np.ndarray, np.ndarray, list[int]]:
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    try:
        header = [h.strip() for h in next(reader)]
    except csv.Error as exc:
        raise InputError(f"{path}: line 1: unreadable header: {exc}") from None
    lower = [h.lower() for h in header]
    if {"u", "v"} <= set(lower) and "x" not in lower:
        raise InputError(f"{path} holds detections (camera,time,u,v: pixels), not a truth "
                         f"trajectory: a CSV t,x,y,z in metres")
    time_col = next((lower.index(name) for name in TIME_COLUMNS if name in lower), None)
    missing = [name for name in "xyz" if name not in lower]
    if time_col is None or missing or len(set(lower)) != len(lower):
        shown = ",".join(header)
        shown = shown if len(shown) <= 200 else shown[:200] + "..."
        raise InputError(f"{path}: line 1: bad header {shown!r}: expected columns t,x,y,z "
                         f"(time in seconds, or named time or timestamp; x, y, z in metres; "
                         f"other columns ignored)" + _separator_hint(header))
    cols = [lower.index(name) for name in "xyz"]
    method_col = lower.index("method") if "method" in lower else None
    times: list[int] = []
    positions: list[tuple[float, ...]] = []
    lines: list[int] = []
    methods: dict[str, int] = {}
    for line, row in csv_rows(reader, len(header), path):
        if method_col is not None:
            methods.setdefault(row[method_col].strip(), line)
        times.append(_seconds(row[time_col], path, line))
        positions.append(_position([row[c] for c in cols], [header[c] for c in cols],
                                   path, line))
        lines.append(line)
    if len(methods) > 1:
        raise InputError(f"{path} holds the tracks of {len(methods)} methods "
                         f"({', '.join(methods)}): keep one method's rows as the truth")
    return (np.asarray(times, np.int64), np.asarray(positions, np.float64).reshape(-1, 3),
            lines)


def _separator_hint(header: list[str]) -> str:
    """A note for a header of one field holding semicolons (a spreadsheet's CSV where the
    decimal mark is a comma)."""
    if len(header) == 1 and ";" in header[0]:
        return ("; its fields are separated by ';': separate them by commas (or tabs), with "
                "decimal points")
    return ""


def _read_tum(text: str, path: Path) -> tuple[np.ndarray, np.ndarray, list[int]]:
    times: list[int] = []
    positions: list[tuple[float, ...]] = []
    lines: list[int] = []
    for line, raw in enumerate(text.splitlines(), start=1):
        fields = raw.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) not in (4, 8):
            raise InputError(f"{path}: line {line}: {len(fields)} fields: a TUM line is "
                             f"'timestamp tx ty tz qx qy qz qw' (or its first four), "
                             f"separated by spaces")
        times.append(_seconds(fields[0], path, line))
        positions.append(_position(fields[1:4], ["tx", "ty", "tz"], path, line))
        lines.append(line)
    return (np.asarray(times, np.int64), np.asarray(positions, np.float64).reshape(-1, 3),
            lines)


def _span(first: int, last: int) -> str:
    from ..log.csvio import format_time

    return f"{format_time(first)}-{format_time(last)} s"


def truth_for_tracks(read: TruthFile, tracks: Sequence[Track], origin_ns: int = 0) -> Truth:
    """``read``'s truth on the session clock of ``tracks``, checked against them.

    Parameters
    ----------
    read : a truth file (:func:`read_truth_file`)
    tracks : the tracks it scores (each sorted by time)
    origin_ns : the session clock's origin on the original clock, ns
        (:func:`pslog.log.csvio.session_clock_origin`; 0: the clocks are one)

    Raises
    ------
    InputError : a track with no point inside the truth's time span (both spans named, on
        the file's clock), or the truth's times on the other clock (where the tracks would
        overlap them: the origin to add or subtract named), or positions in millimetres
    """
    shift = int(origin_ns) if read.clock == "original" else 0
    t = read.truth.time_ns
    first, last = int(t[0]) - shift, int(t[-1]) - shift  # (Python ints: no overflow)
    spans = [(track.method, int(track.time_ns[0]), int(track.time_ns[-1]))
             for track in tracks if len(track)]

    def meets(lo: int, hi: int) -> list[bool]:
        return [bool(np.any((track.time_ns >= lo) & (track.time_ns <= hi)))
                for track in tracks if len(track)]

    met = meets(first, last)
    if spans and not all(met):
        from ..log.csvio import format_time

        clock = ("the original clock (session time + the session's clock origin "
                 f"{format_time(origin_ns)} s)" if read.clock == "original" and origin_ns
                 else "the session clock")
        other = origin_ns if shift else -origin_ns  # (the times read on the other clock)
        if origin_ns and not any(met) and any(meets(first + other, last + other)):
            # (times counted from the truth's own start, a mocap's, meet the session
            # clock's span too: adding the origin then put them 0.437 s off, in silence;
            # walk40)
            lo = min(s[1] for s in spans) + origin_ns
            hi = max(s[2] for s in spans) + origin_ns
            own = (f"; times counted from the truth's own start (a motion-capture "
                   f"system's clock) are on neither clock: put them on the cameras' (the "
                   f"tracks span {_span(lo, hi)} on the original clock) first")
            if shift:
                raise InputError(
                    f"{read.path}: its times ({_span(int(t[0]), int(t[-1]))}) span the "
                    f"session clock's, but a CSV truth's are on the original clock, as 'pslog "
                    f"export --csv' writes them: if they are session times, add the session's "
                    f"clock origin {format_time(origin_ns)} s to every time (or give the truth "
                    f"as a TUM file, on the session clock){own}")
            raise InputError(
                f"{read.path}: its times ({_span(int(t[0]), int(t[-1]))}) are on the "
                f"original clock, but a TUM truth's are on the session clock, as 'pslog "
                f"export --tum' writes them: subtract the session's clock origin "
                f"{format_time(origin_ns)} s from every time (or give the truth as a CSV "
                f"t,x,y,z, on the original clock)")
        if any(met):  # (one track outside the truth's span, the others not)
            method, lo, hi = next(s for s, m in zip(spans, met, strict=True) if not m)
            whose = f"track {method}: the truth spans {_span(int(t[0]), int(t[-1]))}, the track"
        else:
            lo, hi = min(s[1] for s in spans), max(s[2] for s in spans)
            whose = f"the tracks: the truth spans {_span(int(t[0]), int(t[-1]))}, the tracks"
        raise InputError(f"{read.path}: no time in common with {whose} "
                         f"{_span(lo + shift, hi + shift)}, both on {clock}; nothing to score")
    if spans:
        _check_seconds(read, tracks, spans)
        known = read.truth.position_world
        known = known[np.isfinite(known).all(axis=1)]  # (a gap's NaN rows left out)
        truth_norm = float(np.median(np.linalg.norm(known, axis=1)))
        points = np.concatenate([track.position_world for track in tracks])
        points = points[np.isfinite(points).all(axis=1)]
        track_norm = float(np.median(np.linalg.norm(points, axis=1))) if len(points) else 0.0
        if truth_norm > MILLIMETRE_LIMIT_M and truth_norm > 100 * track_norm:
            raise InputError(f"{read.path}: its positions lie a median {truth_norm:.4g} m from "
                             f"the world origin, the tracks' {track_norm:.3g} m: they look "
                             f"like millimetres; give metres (divide x, y, z by 1000)")
        if origin_ns:
            _check_clock(read, tracks, origin_ns)
    if not shift:
        return read.truth
    if not (-(2**63) <= first and last < 2**63):  # (an int64 of ns on the session clock)
        raise InputError(f"{read.path}: times beyond the session clock's range")
    return Truth(read.truth.time_ns - np.int64(shift), read.truth.position_world)


def _other_clock(read: TruthFile, origin_ns: int) -> InputError:
    """The error of a truth whose times are on the other clock than its format's."""
    from ..log.csvio import format_time

    t = read.truth.time_ns
    if read.clock == "original":
        return InputError(
            f"{read.path}: its times ({_span(int(t[0]), int(t[-1]))}) are on the "
            f"session clock, but a CSV truth's are on the original clock, as 'pslog "
            f"export --csv' writes them: add the session's clock origin "
            f"{format_time(origin_ns)} s to every time (or give the truth as a TUM "
            f"file, on the session clock)")
    return InputError(
        f"{read.path}: its times ({_span(int(t[0]), int(t[-1]))}) are on the "
        f"original clock, but a TUM truth's are on the session clock, as 'pslog "
        f"export --tum' writes them: subtract the session's clock origin "
        f"{format_time(origin_ns)} s from every time (or give the truth as a CSV "
        f"t,x,y,z, on the original clock)")


#: a truth that fits the tracks this many times better (median distance) read on the other
#: clock than its format's is refused as on that clock (:func:`_check_clock`)
OTHER_CLOCK_RATIO = 10.0


def _median_distance(truth: Truth, tracks: Sequence[Track]) -> tuple[float, int]:
    """Median distance (m) of the tracks' points from ``truth`` where it spans them, and
    their count."""
    d = [np.linalg.norm(truth.at(track.time_ns) - track.position_world, axis=1)
         for track in tracks if len(track)]
    every = np.concatenate(d) if d else np.zeros(0)
    every = every[np.isfinite(every)]
    return (float(np.median(every)) if len(every) else np.inf), len(every)


def _check_clock(read: TruthFile, tracks: Sequence[Track], origin_ns: int) -> None:
    """InputError if the truth, overlapping the tracks on its format's clock, fits them
    :data:`OTHER_CLOCK_RATIO` times better on the other one (over at least half as many
    points): the clocks of a session with a small origin (a first frame at -0.4 ms: -1 s)
    overlap, and a truth on the wrong one scored every track a metre off in silence."""
    t, position = read.truth.time_ns, read.truth.position_world
    shift = origin_ns if read.clock == "original" else 0
    other = 0 if read.clock == "original" else origin_ns
    if not all(-(2**63) <= int(t[0]) - s and int(t[-1]) - s < 2**63 for s in (shift, other)):
        return  # (times beyond the session clock's range on one clock: not that one)
    given, n_given = _median_distance(Truth(t - np.int64(shift), position), tracks)
    moved, n_moved = _median_distance(Truth(t - np.int64(other), position), tracks)
    if n_moved >= max(3, n_given / 2) and OTHER_CLOCK_RATIO * moved < given:
        raise _other_clock(read, origin_ns)


def _check_seconds(read: TruthFile, tracks: Sequence[Track], spans) -> None:
    """InputError if the truth's samples lie :data:`UNIT_RATIO` times the tracks' point
    steps apart (medians) over a span that many times theirs: times in milliseconds (or
    microseconds) read as seconds, which scored every track metres off in silence."""
    steps = [float(np.median(np.diff(track.time_ns))) for track in tracks if len(track) >= 2]
    t = read.truth.time_ns
    if not steps or min(steps) <= 0:
        return
    step, track_step = float(np.median(np.diff(t))), min(steps)
    span = float(t[-1] - t[0])
    track_span = max(s[2] for s in spans) - min(s[1] for s in spans)
    ratio = step / track_step
    if ratio >= UNIT_RATIO and span >= UNIT_RATIO * max(track_span, track_step):
        unit, factor = (("milliseconds", "1000") if ratio < 1000 * UNIT_RATIO
                        else ("microseconds", "1e6"))
        raise InputError(f"{read.path}: its samples lie a median {step / NS:.4g} s apart over "
                         f"{span / NS:.4g} s, {ratio:.0f} times the tracks' "
                         f"{track_step / NS * 1e3:.4g} ms over {track_span / NS:.4g} s: the "
                         f"times look like {unit}; give seconds (divide them by {factor})")


def describe(read: TruthFile, truth: Truth, origin_ns: int = 0) -> str:
    """One line saying which truth ``pslog eval`` scores against: the file, its format and
    clock, samples, span (on the file's clock) and sample steps."""
    from ..log.csvio import format_time

    t = read.truth.time_ns
    step = np.diff(truth.time_ns) / NS * 1e3
    clock = ("TUM, session clock" if read.clock == "session" else
             f"CSV, original clock: session time + {format_time(origin_ns)} s" if origin_ns
             else "CSV, original clock = session clock")
    gaps = int(np.count_nonzero(~np.isfinite(read.truth.position_world).all(axis=1)))
    return (f"truth: {read.path} ({clock}): {len(t)} samples, {_span(int(t[0]), int(t[-1]))}, "
            f"steps median {float(np.median(step)):.3g} ms, largest {float(step.max()):.3g} "
            f"ms (interpolated linearly between samples"
            + (f"; {gaps} gap rows: the points between the samples around them not scored"
               if gaps else "") + ")")


#: :func:`truth_clock_shift` searches the truth's clock offset within ±this many seconds, on
#: a grid of :data:`_SHIFT_COARSE_S`, then around the best within one step, on a grid of
#: :data:`_SHIFT_FINE_S`.
SHIFT_SEARCH_S = 1.0
_SHIFT_COARSE_S = 2e-3
_SHIFT_FINE_S = 0.05e-3
#: The shift is said when it is at least this (seconds) and lowers the median error by at
#: least this share: a truth on the cameras' clock finds its best within a fraction of a
#: millisecond (the tracks' own timing errors), below both.
SHIFT_NOTE_S = 1e-3
#: The search scores at most this many of the track's points, evenly spread.
_SHIFT_POINTS = 1000
SHIFT_NOTE_GAIN = 0.2


@dataclass(frozen=True)
class TruthShift:
    """The time shift of a truth that best fits a track (:func:`truth_clock_shift`).

    Attributes
    ----------
    method : str, the track it was measured on (the most accurate as given)
    shift_s : float, seconds to add to the truth's times for the smallest median error
    median_mm : float, the track's median error with the truth shifted so
    median_given_mm : float, its median error with the truth as given
    """

    method: str
    shift_s: float
    median_mm: float
    median_given_mm: float

    @property
    def notable(self) -> bool:
        """A shift a truth on the cameras' clock would not show: said by ``pslog eval``."""
        return (abs(self.shift_s) >= SHIFT_NOTE_S
                and self.median_mm <= (1.0 - SHIFT_NOTE_GAIN) * self.median_given_mm)


def _median_errors(truth: Truth, time_s: np.ndarray, points: np.ndarray,
                   shifts: np.ndarray) -> np.ndarray:
    """Median distance (m) of ``points`` at ``time_s`` (seconds, relative to the truth's
    first sample) from the truth with its times moved by each of ``shifts`` (seconds);
    NaN where fewer than half the points fall inside the moved truth's span."""
    t_truth = (truth.time_ns - truth.time_ns[0]) / NS
    out = np.full(len(shifts), np.nan)
    for i, d in enumerate(shifts):
        t = time_s - d  # the moved truth at t is the given one at t - d
        inside = (t >= t_truth[0]) & (t <= t_truth[-1])
        if np.count_nonzero(inside) * 2 < len(t):
            continue
        ti = t[inside]
        at = np.stack([np.interp(ti, t_truth, truth.position_world[:, k]) for k in range(3)],
                      axis=1)
        out[i] = float(np.median(np.linalg.norm(points[inside] - at, axis=1)))
    return out


def truth_clock_shift(truth: Truth, tracks: Sequence[Track]) -> TruthShift | None:
    """How far the truth's clock seems off the tracks': the time shift of the truth (within
    ±:data:`SHIFT_SEARCH_S`) that gives a track its smallest median error, on the track
    whose smallest median is the smallest of all; None: no track with 10 finite points in
    the truth's span.

    A motion-capture truth on a clock of its own (another host's Unix time, a few ms off the
    first camera's; a clock counted from the capture's start) moves every error by the
    ball's speed times the offset: 4 ms at 5 m/s is 2 cm, which ``pslog eval`` would
    charge to the fusion (walk40). The median of the distances is robust to a track's few
    false points; the track best at its own shift, not the best as given (a method lagging
    the ball looked best against a late truth and put the shift 0.5 ms off). Not a
    correction: ``pslog eval`` says it (:attr:`TruthShift.notable`) and scores the truth as
    given.
    """
    coarse = np.arange(-SHIFT_SEARCH_S, SHIFT_SEARCH_S + _SHIFT_COARSE_S / 2, _SHIFT_COARSE_S)
    best = None
    for track in tracks:
        ok = np.flatnonzero(np.isfinite(track.position_world).all(axis=1))
        given = truth.at(track.time_ns[ok])
        inside = np.isfinite(given).all(axis=1)
        if np.count_nonzero(inside) < 10:
            continue
        med0 = float(np.median(np.linalg.norm(track.position_world[ok][inside]
                                              - given[inside], axis=1)))
        if len(ok) > _SHIFT_POINTS:  # (evenly over the track: a 90-minute match in ~0.2 s)
            ok = ok[np.linspace(0, len(ok) - 1, _SHIFT_POINTS).round().astype(np.int64)]
        time_s = (track.time_ns[ok] - truth.time_ns[0]) / NS
        points = track.position_world[ok]
        errors = _median_errors(truth, time_s, points, coarse)
        if not np.isfinite(errors).any():
            continue
        i = int(np.nanargmin(errors))
        if best is None or errors[i] < best[0]:
            best = (float(errors[i]), coarse[i], track, time_s, points, med0)
    if best is None:
        return None
    _, d0, track, time_s, points, med0 = best
    fine = d0 + np.arange(-_SHIFT_COARSE_S, _SHIFT_COARSE_S + _SHIFT_FINE_S / 2, _SHIFT_FINE_S)
    errors = _median_errors(truth, time_s, points, fine)
    i = int(np.nanargmin(errors))
    return TruthShift(track.method, float(fine[i]), float(errors[i]) * 1e3, med0 * 1e3)
