"""Detections and fused tracks as CSV (``pslog import`` / ``pslog export``).

Detections CSV (import and export use exactly this format)::

    camera,time,u,v[,frame][,score]
    cam1,0.000000000,412.5,233.25,0,1.0

- ``camera``: a camera name of the rig; ``time``: capture time in seconds on any clock
  common to the cameras (parsed exactly as a decimal, rounded to the nanosecond; negative and
  Unix-epoch times included, see below); ``u, v``: pixels as
  detected (distorted); ``frame``: the camera's frame index (optional); ``score``: detector
  confidence in [0, 1] (optional, default 1).
- Rows may come in any order. Rows with the same camera and time are the candidates of one
  frame (they must agree on ``frame``); one camera's frame index cannot appear at two
  different times. A candidate given twice (camera, time, u, v equal: a file appended to
  itself) is refused. Without a ``frame`` column, each camera's frames are numbered
  from their times: 0 first, and each step the frame periods it spans (a frame without a
  row, a miss the detector did not write, leaves a gap: :func:`_frames_from_times`).
- A frame without any candidate (the ball missed) is one row with ``u`` and ``v`` empty
  (``cam1,0.011111111,,,1,``): a frame, no candidate.
- One CSV per camera (:func:`read_camera_csvs`, ``pslog import --detections NAME=FILE``):
  the same rows without the ``camera`` column (or with it, naming that camera in every row).
- Fields separated by commas, or by tabs throughout (a first line of tabs and no comma: a
  .tsv, a spreadsheet's "text, tab delimited").

Text cells (camera names, methods) that a spreadsheet would take for a formula, those
starting with ``=`` ``+`` ``-`` ``@`` (a rig imported with a camera ``-x``, ``=1+2``), are
written with a ``'`` before them, as OWASP advises against CSV injection (:func:`csv_text`);
import reads ``'-x`` back as ``-x``.

Export writes all six columns, times as exact decimals with 9 digits and pixels with
``repr`` precision, and a row for every frame without a candidate, so export -> import
reproduces every frame and value (import -> export -> import too).

Times from any clock: a session stores times >= 0 counted from a session start (MCAP log
times are unsigned, and the timing model's drift term counts from it). CSV times all in
``[0, 1e6 s)`` are stored as they are; otherwise (a negative time, e.g. a jittered first
frame at -0.4 ms, or Unix-epoch times) the session clock's origin is the earliest time
rounded down to a whole second, recorded in the session metadata as ``clock_origin_ns``
(decimal integer nanoseconds, :func:`session_clock`), and export adds it back, so the
original times come back to the nanosecond. Times are never converted through float64.
"""

from __future__ import annotations

import codecs
import csv
import unicodedata
from decimal import ROUND_HALF_EVEN, Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from ..camera import MAX_PIXEL as _MAX_PIXEL
from ..errors import InputError, shell_word
from ..inputs import binary_format, check_input_file
from ..outputs import replacing
from ..records import MAX_FRAME_INDEX, NS, Detections
from ..rig import Rig

DETECTION_COLUMNS = ("camera", "time", "u", "v", "frame", "score")
_REQUIRED = ("camera", "time", "u", "v")
TRACK_COLUMNS = ("time", "x", "y", "z", "camera", "method")


#: First characters that make a spreadsheet read a cell as a formula (OWASP, "CSV
#: Injection"; tab and carriage return too, which no camera name holds).
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def csv_text(text: str) -> str:
    """``text`` as a CSV text cell a spreadsheet shows as text: a ``'`` before a cell that
    starts with one of :data:`FORMULA_STARTS` (``=1+2`` -> ``'=1+2``), or with ``'`` then
    one of them (``'=x`` -> ``''=x``, so :func:`csv_text_read` gives every text back);
    other text as it is. For text cells only: a number (``-0.5``) is written as it is."""
    if text.lstrip("'").startswith(FORMULA_STARTS):
        return "'" + text
    return text


def csv_text_read(text: str) -> str:
    """The text :func:`csv_text` wrote ``text`` for: one leading ``'`` removed if what
    follows it is a formula's start (after any more ``'``); else ``text`` as it is."""
    if text.startswith("'") and text.lstrip("'").startswith(FORMULA_STARTS):
        return text[1:]
    return text


class _Invalid(ValueError):
    """A parsed but invalid cell value; the message is the reason shown to the user."""


#: Largest time accepted, seconds, either sign (int64 nanoseconds: about 292 years).
_MAX_TIME_S = Decimal(2**63 - 1) / NS
#: CSV times all within [0, this) seconds are stored as they are (session clock origin 0);
#: others get an origin (:func:`session_clock`). 1e6 s is 11.6 days: beyond any recording
#: counted from its start, far below Unix-epoch times (1.7e9 s).
PLAIN_CLOCK_LIMIT_S = 1_000_000
#: Session metadata key of the session clock's origin: decimal integer nanoseconds.
CLOCK_ORIGIN_KEY = "clock_origin_ns"


def _time_ns(text: str) -> int:
    """Exact decimal seconds (any sign) -> integer ns (half-even rounding below 1 ns)."""
    try:
        value = Decimal(text)
    except InvalidOperation:
        raise ValueError(text) from None
    if not value.is_finite():
        raise _Invalid("not a finite number of seconds")
    # compare before scaling: a huge exponent would overflow the decimal context
    if value.copy_abs() > _MAX_TIME_S:  # copy_abs: exact, no context
        # (a Unix time in ms, 1.76e12, or µs: walk40's mocap was refused without a hint)
        unit = ("; a Unix time in milliseconds or microseconds? give seconds"
                if value.copy_abs() < _MAX_TIME_S * 10**6 else "")
        raise _Invalid(f"beyond the range of times (±{float(_MAX_TIME_S):.3g} s){unit}")
    # exact: the decimal context has 28 digits, an int64 of nanoseconds at most 19
    ns = int((value * NS).to_integral_value(rounding=ROUND_HALF_EVEN))
    if not -(2**63) < ns < 2**63:
        raise _Invalid(f"beyond the range of times (±{float(_MAX_TIME_S):.3g} s)")
    return ns


def _pixel(text: str) -> float:
    value = float(text)
    if not np.isfinite(value):
        raise _Invalid("not a finite number")
    if abs(value) > _MAX_PIXEL:
        raise _Invalid(f"beyond any image (at most {_MAX_PIXEL:g} pixels)")
    return value


def _frame_number(text: str) -> int:
    value = int(text)
    if value < 0:
        raise _Invalid("frame indices are >= 0")
    if value > MAX_FRAME_INDEX:
        raise _Invalid(f"beyond any frame counter (at most {MAX_FRAME_INDEX})")
    return value


def _unit_score(text: str) -> float:
    value = float(text)
    if not 0.0 <= value <= 1.0:  # also rejects NaN
        raise _Invalid("not in [0, 1]")
    return value


_PARSE = {"time": (_time_ns, "not a number of seconds"), "u": (_pixel, "not a number"),
          "v": (_pixel, "not a number"), "frame": (_frame_number, "not an integer"),
          "score": (_unit_score, "not a number")}


def _cell(row: list[str], col: dict[str, int], key: str, path: Path, line: int):
    """Parse the ``key`` cell of ``row``; InputError naming the line, column, value and why."""
    parse, unparseable = _PARSE[key]
    text = row[col[key]].strip()
    try:
        return parse(text)
    except _Invalid as exc:
        reason = str(exc)
    except ValueError:
        reason = unparseable
    raise InputError(f"{path}: line {line}: bad {key} value {text!r}: {reason}")


def csv_rows(reader, n_fields: int, path):
    """Each row of a ``csv.reader`` with a value, with its line number (blank rows skipped),
    of ``n_fields`` fields: an :class:`InputError` naming the line of a row of another
    length, of a CSV syntax error or of text that is not UTF-8."""
    line = 1
    try:
        for row in reader:
            line = reader.line_num
            if not row or all(not cell.strip() for cell in row):
                continue
            if len(row) != n_fields:
                raise InputError(f"{path}: line {line}: expected {n_fields} fields, got "
                                 f"{len(row)}")
            yield line, row
    except csv.Error as exc:  # (the line the reader stopped on: the faulty one)
        raise InputError(f"{path}: line {reader.line_num}: {exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: line {line + 1}: not UTF-8 text") from None


def format_time(time_ns: int) -> str:
    """Integer ns -> exact decimal seconds with 9 digits (``-0.000000001``)."""
    sign = "-" if time_ns < 0 else ""
    seconds, ns = divmod(abs(int(time_ns)), NS)
    return f"{sign}{seconds}.{ns:09d}"


def session_clock(detections: Detections) -> tuple[Detections, int]:
    """``detections`` on a session clock, and its origin: ``(shifted, origin_ns)`` with
    ``shifted`` times = original - ``origin_ns``, all >= 0.

    ``origin_ns`` is 0 when every time is already in ``[0, PLAIN_CLOCK_LIMIT_S)`` seconds
    (the session keeps the times as given); otherwise the earliest time rounded down to a
    whole second (so the session's times keep the original sub-second digits).
    """
    times = detections.frame_time_ns
    if len(times) == 0:
        return detections, 0
    first, last = int(times.min()), int(times.max())
    if first >= 0 and last < PLAIN_CLOCK_LIMIT_S * NS:
        return detections, 0
    origin = (first // NS) * NS  # floor, also for negative times
    if last - origin >= 2**63:
        raise InputError(f"times span {(last - first) / NS:.3g} s: a session holds at most "
                         f"{float(_MAX_TIME_S):.3g} s")
    shifted = Detections(detections.camera_names, detections.frame_time_ns - origin,
                         detections.frame_camera, detections.frame_index, detections.cand_frame,
                         detections.cand_uv, detections.cand_radius, detections.cand_score)
    return shifted, origin


def parse_columns(text: str) -> dict[str, str]:
    """``--columns`` of ``pslog import``: ``NAME=COLUMN,...`` (a pslog column each, e.g.
    ``time=t_unix,u=px,v=py,frame=frame_id,score=conf``) as {file's column: pslog's}. A
    COLUMN in double quotes is taken whole, commas and quotes inside it (``time="t,unix"``,
    ``""`` for a quote, as CSV quotes a header); columns compare in Unicode's composed form
    (NFC: an accent typed as one character or as two). Raises InputError naming a malformed
    item (an unmatched quote), a name that is not a detections column, a name or a file's
    column given twice."""
    out: dict[str, str] = {}
    named: set[str] = set()
    items: list[str] = []
    chars: list[str] = []
    quoted = False
    for char in text:  # (commas inside double quotes belong to a column's name)
        if char == '"':
            quoted = not quoted
        if char == "," and not quoted:
            items.append("".join(chars))
            chars = []
        else:
            chars.append(char)
    items.append("".join(chars))
    if quoted:
        raise InputError(f"--columns: {_shown(text)} has an unmatched double quote (quote a "
                         f"column whole: time=\"t,unix\")")
    for k, item in enumerate(items):
        name, eq, column = (part.strip() for part in item.partition("="))
        if len(column) >= 2 and column[0] == column[-1] == '"':
            column = column[1:-1].replace('""', '"')
        if not eq or not name or not column:
            comma = (f" (a column whose name holds a comma: quote it, "
                     f"{items[k - 1].strip()},{item.strip()} as "
                     f"{items[k - 1].partition('=')[0].strip()}=\""
                     f"{items[k - 1].partition('=')[2].strip()},{item.strip()}\")"
                     if k and not eq and item.strip() and "=" in items[k - 1] else "")
            raise InputError(f"--columns: {_shown(item.strip())} is not NAME=COLUMN (e.g. "
                             f"time=t_unix,u=px,v=py){comma}")
        if name not in DETECTION_COLUMNS:
            raise InputError(f"--columns: {_shown(name)} is not a detections column (one of "
                             f"{', '.join(DETECTION_COLUMNS)})")
        column = unicodedata.normalize("NFC", column)
        if name in named or column in out:
            raise InputError(f"--columns: {_shown(name if name in named else column)} given "
                             f"twice")
        named.add(name)
        out[column] = name
    return out


def _shown(text: str, limit: int = 80) -> str:
    """``text`` for an error line: quoted, escapes for what would break the line (a newline,
    a control character), shortened past ``limit`` characters."""
    return repr(text if len(text) <= limit else text[:limit] + "...")


def _header_cells(header: list[str]) -> str:
    """A header's cells for an error line, each as :func:`_shown` gives it, 200 characters at
    most."""
    cells = ", ".join(_shown(h, 40) for h in header)
    return cells if len(cells) <= 200 else cells[:200] + "..."


def read_detections_csv(path, rig: Rig, camera: str | None = None,
                        empty: bool = False, columns: dict[str, str] | None = None
                        ) -> Detections:
    """Parse a detections CSV (format in the module docstring) against ``rig``'s cameras.

    Times are the CSV's own (int64 ns, any sign); :func:`session_clock` puts them on a
    session clock for writing.

    Parameters
    ----------
    path : the CSV file
    rig : the rig whose cameras the rows name
    camera : None: every row names its camera (column ``camera``, required); a camera name
        of ``rig``: the file holds that camera's rows alone (one CSV per camera,
        ``pslog import --detections NAME=FILE``): header ``time,u,v[,frame][,score]``, a
        ``camera`` column optional, and where there every row must name ``camera``
    empty : a file of no rows (its header alone) is read as no frames, not refused
        (:func:`read_camera_csvs`: a camera that saw nothing)
    columns : {the file's column: pslog's} (:func:`parse_columns`: ``pslog import
        --columns``), a detector's own header read as pslog's; each named column must be in
        the file

    Raises InputError naming the line (and column) of the first malformed row or unknown
    camera (or, with ``camera``, a row naming another).
    """
    path = Path(path)
    if camera is not None and rig.spelling(camera) is None:
        raise InputError(f"--detections {camera}={path}: unknown camera {camera!r} (rig has "
                         f"{', '.join(rig.names)})")
    if camera is not None:
        camera = rig.spelling(camera)  # (the rig's own Unicode spelling of it)
    required = _REQUIRED if camera is None else _REQUIRED[1:]
    expected, optional = (("camera,time,u,v", "frame,score") if camera is None
                          else ("time,u,v", "frame,score,camera"))
    check_input_file(path)  # a device or FIFO would be read for ever
    try:
        # utf-8-sig: Excel's "CSV UTF-8" and Windows editors start with a byte-order mark
        handle = open(path, newline="", encoding="utf-8-sig")  # closed by the with below
    except FileNotFoundError:
        raise InputError(f"no such file: {path}") from None
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    index = {name: i for i, name in enumerate(rig.names)}
    cams, times, frames, uv, scores, lines, missed = [], [], [], [], [], [], []
    head = _head(path)
    nul = head.find(b"\0")
    try:  # (invalid UTF-8 before it: said so below, as the reader meets it)
        codecs.getincrementaldecoder("utf-8")().decode(head[:nul] if nul >= 0 else b"")
    except UnicodeDecodeError:
        nul = -1
    if nul >= 0:  # (a text file holds none: a file of zeros was read whole as one line)
        handle.close()
        from ._mcapio import starts_as_mcap

        if starts_as_mcap(path):
            raise InputError(f"{path} is an MCAP session, not a detections CSV (export "
                             f"its detections with 'pslog export {shell_word(path)} "
                             f"--detections DET.csv')")
        kind = binary_format(head, path)
        if kind == "parquet":  # (--parquet's; any Parquet file)
            raise InputError(f"{path} is a Parquet file ('pslog export --parquet' writes the "
                             f"fused tracks as one), not a detections CSV (header {expected})")
        if kind == "c3d":
            raise InputError(f"{path} is a C3D file (motion-capture points: 'pslog export "
                             f"--c3d' writes the fused tracks as one), not a detections CSV "
                             f"(header {expected}); pslog imports detections, not C3D")
        raise InputError(f"{path}: not a text CSV file (byte {nul} is a NUL); expected "
                         f"header {expected}")
    with handle:
        reader = csv.reader(handle, delimiter="\t" if _tab_separated(head) else ",")
        try:
            header = next(reader, None)
        except UnicodeDecodeError as exc:  # (not the codec's own words)
            from ._mcapio import starts_as_mcap

            if starts_as_mcap(path):
                raise InputError(f"{path} is an MCAP session, not a detections CSV (export "
                                 f"its detections with 'pslog export {shell_word(path)} "
                                 f"--detections DET.csv')") from None
            raise InputError(f"{path}: not a text CSV file (byte {exc.start} is not UTF-8 "
                             f"text); expected header {expected}") from None
        except csv.Error as exc:
            raise InputError(f"{path}: line 1: unreadable header: {exc}") from None
        if header is None:
            raise InputError(f"{path}: empty file (expected header {expected})")
        header = [h.strip() for h in header]
        if columns:  # (a detector's own names: --columns)
            own = [unicodedata.normalize("NFC", h) for h in header]  # (parse_columns')
            absent = [c for c in columns if c not in own]
            if absent:
                raise InputError(f"{path}: line 1: no column {_shown(absent[0])} (--columns "
                                 f"{columns[absent[0]]}={_shown(absent[0])[1:-1]}); the header "
                                 f"has {_header_cells(header)}")
            twice = [h for h in columns if own.count(h) > 1]
            if twice:
                raise InputError(f"{path}: line 1: column {_shown(twice[0])} (--columns "
                                 f"{columns[twice[0]]}=...) is in the header "
                                 f"{own.count(twice[0])} times: which one is meant is not "
                                 f"known; rename one in the file")
            clash = [h for h in own if h in columns.values() and h not in columns]
            if clash:
                mapped = next(c for c, n in columns.items() if n == clash[0])
                raise InputError(f"{path}: line 1: --columns {clash[0]}={_shown(mapped)[1:-1]} "
                                 f"reads {_shown(mapped)} as {clash[0]}, but the header has "
                                 f"a column {clash[0]} too: map that one to another name or "
                                 f"leave {clash[0]} out of --columns")
            header = [columns.get(h, h) for h in own]
        unknown = [h for h in header if h not in DETECTION_COLUMNS]
        missing = [h for h in required if h not in header]
        if header and header[0].startswith("#") and "timestamp tx ty tz" in header[0]:
            raise InputError(f"{path} holds a TUM trajectory (timestamp tx ty tz qx qy qz "
                             f"qw: 'pslog export --tum'), not detections: a detections CSV "
                             f"is header camera,time,u,v ('pslog export SESSION.mcap "
                             f"--detections DET.csv' writes one)")
        if tuple(header[:len(TRACK_COLUMNS)]) == TRACK_COLUMNS:  # (pslog export --csv's)
            raise InputError(f"{path} holds fused tracks ({','.join(TRACK_COLUMNS)}: "
                             f"'pslog export --csv'), not detections: a detections CSV "
                             f"is header camera,time,u,v ('pslog export SESSION.mcap "
                             f"--detections DET.csv' writes one)")
        if unknown or missing or len(set(header)) != len(header):
            if header and header[0].startswith(("{", "[")):  # (--jsonl's, any JSON)
                raise InputError(f"{path} holds JSON, not a detections CSV (header "
                                 f"{expected})")
            shown = ",".join(header)
            shown = shown if len(shown) <= 200 else shown[:200] + "..."  # (one line, short)
            unknown = unknown if len(unknown) <= 10 else [*unknown[:10], "..."]
            raise InputError(
                f"{path}: line 1: bad header {shown!r}: expected columns "
                f"{expected} and optionally {optional}"
                + (f" (unknown: {', '.join(unknown)})" if unknown else "")
                + (f" (missing: {', '.join(missing)})" if missing else "")
                + (f" (twice: {', '.join(sorted({h for h in header if header.count(h) > 1}))})"
                   if len(set(header)) != len(header) else "")
                + ("; one camera's file: name its camera, --detections CAMERA=FILE"
                   if missing == ["camera"] and not unknown else "")
                # (walk42: a detector's own header refused without a word of --columns)
                + (f"; a detector's own column names are read as pslog's with --columns "
                   f"{','.join(f'{m}=COLUMN' for m in missing)}"
                   if missing and unknown and len(header) > 1 else "")
                + ("; its fields are separated by ';': separate them by commas (or tabs), "
                   "with decimal points" if len(header) == 1 and ";" in header[0] else ""))
        col = {name: header.index(name) for name in header}
        has_frame, has_score = "frame" in col, "score" in col
        for line, row in csv_rows(reader, len(header), path):
            name = row[col["camera"]].strip() if "camera" in col else str(camera)
            if csv_text_read(name) in index:  # '-x: the rig's -x as csv_text wrote it
                name = csv_text_read(name)
            if name not in index:  # another Unicode spelling of a rig's name, or None
                name = rig.spelling(name) or name
            if camera is not None and name != camera:
                raise InputError(f"{path}: line {line}: camera {name!r}, but the file "
                                 f"was given as camera {camera}'s (--detections "
                                 f"{camera}={path}): every row of a camera's own CSV "
                                 f"names that camera, or the column is left out")
            if name not in index:
                raise InputError(f"{path}: line {line}: unknown camera {name!r} "
                                 f"(rig has {', '.join(rig.names)})")
            cams.append(index[name])
            lines.append(line)
            times.append(_cell(row, col, "time", path, line))
            # u and v both empty: a frame without a candidate (the ball missed)
            miss = not row[col["u"]].strip() and not row[col["v"]].strip()
            missed.append(miss)
            uv.append((np.nan, np.nan) if miss else (_cell(row, col, "u", path, line),
                                                     _cell(row, col, "v", path, line)))
            if has_frame:
                frames.append(_cell(row, col, "frame", path, line))
            if has_score:
                scores.append(np.nan if miss and not row[col["score"]].strip()
                              else _cell(row, col, "score", path, line))
    return _detections_from_rows(rig, np.asarray(cams, np.int32), np.asarray(times, np.int64),
                                 np.asarray(uv, np.float64).reshape(-1, 2),
                                 np.asarray(frames, np.int64) if has_frame else None,
                                 np.asarray(scores, np.float64) if has_score else None, path,
                                 np.asarray(lines, np.int64), np.asarray(missed, bool),
                                 empty=empty)


def _head(path: Path) -> bytes:
    """The file's first MiB (empty where it cannot be read: its reader says why)."""
    try:
        with open(path, "rb") as raw:
            return raw.read(1 << 20)
    except OSError:
        return b""


def _tab_separated(head: bytes) -> bool:
    """Whether the first line of ``head`` holds tabs and no comma: a tab-separated file (a
    .tsv, a spreadsheet's "text, tab delimited"), read as such."""
    line = head.lstrip(b"\r\n").partition(b"\n")[0]
    return b"\t" in line and b"," not in line


def read_camera_csvs(files, rig: Rig, columns: dict[str, str] | None = None) -> Detections:
    """One CSV per camera (``pslog import --detections NAME=FILE ...``) as one session's
    detections: each file read by :func:`read_detections_csv` as its camera's, the frames of
    all joined. The same detections as one CSV of every file's rows, each with its camera
    named (``camera`` column), read by :func:`read_detections_csv`.

    Parameters
    ----------
    files : mapping camera name -> CSV path, each camera once (any order)
    rig : the rig the names are cameras of

    A file of no rows (its header alone: a camera that saw nothing) gives that camera no
    frames, as the joined CSV would hold none of its rows (review40: it was refused, the
    other cameras' rows with it); every file without rows is refused, naming them.

    Raises InputError as :func:`read_detections_csv`, naming the file and line.
    """
    parts = [read_detections_csv(path, rig, camera=name, empty=True, columns=columns)
             for name, path in files.items()]
    if all(d.n_frames == 0 for d in parts):
        raise InputError(f"{', '.join(map(str, files.values()))}: no detection rows")
    offsets = np.cumsum([0, *(d.n_frames for d in parts)])[:-1]
    return Detections.from_frames(
        rig.names, np.concatenate([d.frame_time_ns for d in parts]),
        np.concatenate([d.frame_camera for d in parts]),
        np.concatenate([d.frame_index for d in parts]),
        np.concatenate([d.cand_frame + k for d, k in zip(parts, offsets, strict=True)]),
        np.concatenate([d.cand_uv for d in parts]),
        np.concatenate([d.cand_radius for d in parts]),
        np.concatenate([d.cand_score for d in parts]))


def _detections_from_rows(rig: Rig, cams, times, uv, frames, scores, path,
                          lines, missed=None, empty: bool = False) -> Detections:
    """Group candidate rows into frames: one frame per distinct (camera, time).

    ``lines`` (n,) int64 are the rows' line numbers in the file, for error messages;
    ``missed`` (n,) bool marks rows that stand for a frame without a candidate; ``empty``:
    no rows give no frames (else refused).
    """
    n = len(cams)
    if n == 0 and empty:
        return Detections.from_frames(rig.names, np.zeros(0, np.int64), np.zeros(0, np.int32),
                                      np.zeros(0, np.int64), np.zeros(0, np.int64),
                                      np.zeros((0, 2)))
    if n == 0:
        raise InputError(f"{path}: no detection rows")
    keys = np.stack([cams.astype(np.int64), times], axis=1)
    unique, cand_frame = np.unique(keys, axis=0, return_inverse=True)
    cand_frame = cand_frame.ravel()
    frame_camera = unique[:, 0].astype(np.int32)
    frame_time = unique[:, 1]
    if frames is not None:
        # each frame takes the index of its first row (rows are in file order)
        first_row = np.full(len(unique), n)
        np.minimum.at(first_row, cand_frame, np.arange(n))
        frame_index = frames[first_row]
        disagree = np.flatnonzero(frame_index[cand_frame] != frames)
        if len(disagree):
            bad = int(disagree[0])
            raise InputError(f"{path}: lines {lines[first_row[cand_frame[bad]]]} and "
                             f"{lines[bad]}: rows of camera {rig.names[cams[bad]]} at time "
                             f"{format_time(times[bad])} s disagree on frame "
                             f"({frame_index[cand_frame[bad]]} and {frames[bad]})")
        _check_one_time_per_frame(rig, frame_camera, frame_index, frame_time, cand_frame,
                                  lines, path)
    else:
        frame_index = _frames_from_times(rig, frame_camera, frame_time)
    _check_no_repeated_candidate(rig, cams, times, uv, lines, path, missed, cand_frame)
    _check_seconds(rig, frame_camera, frame_index, frame_time, path)
    if missed is not None and missed.any():  # frames, not candidates
        keep = ~missed
        cand_frame, uv = cand_frame[keep], uv[keep]
        scores = None if scores is None else scores[keep]
    return Detections.from_frames(rig.names, frame_time, frame_camera, frame_index, cand_frame,
                                  uv, None, scores)


#: Without a ``frame`` column, a step between a camera's frames counts as ``m`` frame periods
#: of the median step (not one) when the median is within this share of ``m`` rig periods,
#: ``m`` 2 to :data:`_MAX_MEDIAN_PERIODS`: a camera that saw the ball in fewer than half its
#: frames, whose median step is then two or more periods.
_PERIOD_TOLERANCE = 0.1
_MAX_MEDIAN_PERIODS = 4


def _frames_from_times(rig: Rig, frame_camera, frame_time) -> np.ndarray:
    """Each camera's frame numbers from its frames' times (a CSV without a ``frame``
    column): the first frame 0, and each step between consecutive frames the number of
    frame periods it spans, rounded (at least 1), the period being the camera's median step
    (its measured frame period, the rig's ``fps`` only where the median spans several
    periods: :data:`_PERIOD_TOLERANCE`). A detector that writes no row for a frame without
    a ball so leaves a gap in the numbers, as a ``frame`` column would: numbered 0, 1, 2, ...
    (before session 40) a session's misses shifted every later frame's number, and ``pslog
    sync``'s line of host stamps against frame numbers (``--regularize``) then moved every
    time by up to seconds (walk40: 5 % misses, offsets 46-47 ms off, points 12 cm off).

    ``frame_camera``, ``frame_time`` (n,) sorted by (camera, time), times distinct within
    a camera. Returns ``frame_index`` (n,) int64.
    """
    frame_index = np.zeros(len(frame_time), dtype=np.int64)
    for c, camera in enumerate(rig.cameras):
        rows = np.flatnonzero(frame_camera == c)
        if len(rows) < 2:
            continue
        steps = np.diff(frame_time[rows]).astype(np.float64)  # ns, > 0
        period = float(np.median(steps))
        ratio = period / (camera.frame_period * NS)
        m = round(ratio)
        if 2 <= m <= _MAX_MEDIAN_PERIODS and abs(ratio / m - 1.0) <= _PERIOD_TOLERANCE:
            period /= m
        counts = np.maximum(np.rint(np.minimum(steps / period, MAX_FRAME_INDEX)), 1)
        if counts.sum() > MAX_FRAME_INDEX:  # (times no frame counter spans: in time order)
            counts = np.ones(len(steps))
        frame_index[rows] = np.concatenate(([0], np.cumsum(counts.astype(np.int64))))
    return frame_index


#: A camera whose frames lie this many frame periods apart (median) holds times in another
#: unit than seconds: milliseconds (1000), microseconds; a ball seen at every 300th frame
#: of a 30 fps camera, 10 s apart, is no session to fuse either.
_UNIT_RATIO = 300.0


def _check_seconds(rig: Rig, frame_camera, frame_index, frame_time, path) -> None:
    """InputError if a camera's frames are :data:`_UNIT_RATIO` frame periods or more apart
    (the median over its consecutive frames, per frame index step): a CSV of milliseconds
    imported without a word, its cameras' frames 33 s apart, and ``pslog fuse`` then found
    "too few detections close enough in time"."""
    for c, camera in enumerate(rig.cameras):
        mine = frame_camera == c
        if np.count_nonzero(mine) < 3:
            continue
        order = np.argsort(frame_time[mine], kind="stable")
        t, k = frame_time[mine][order], frame_index[mine][order]
        steps = np.maximum(np.diff(k), 1)  # (a CSV's own frame numbers: per frame)
        spacing = float(np.median(np.diff(t) / steps)) / NS
        ratio = spacing / camera.frame_period
        if ratio >= _UNIT_RATIO:
            unit, factor = (("milliseconds", "1000") if ratio < 1000 * _UNIT_RATIO
                            else ("microseconds", "1e6"))
            raise InputError(
                f"{path}: camera {camera.name}'s frames are {spacing:.4g} s apart (the median), "
                f"{ratio:.0f} times its {camera.frame_period * 1e3:.4g} ms frame period at "
                f"{camera.fps:g} fps: the time column is seconds ({unit}: divide them by "
                f"{factor})")


def _check_no_repeated_candidate(rig: Rig, cams, times, uv, lines, path, missed,
                                 cand_frame) -> None:
    """InputError if one candidate (camera, time, u, v: to the bit) has two rows: a
    detector gives a frame's candidates at distinct pixels, so a repeated row is a file
    appended to itself, which would be fused as two candidates of one frame. Only the rows
    of frames with several rows are compared (most frames have one)."""
    rows = np.flatnonzero(~missed) if missed is not None else np.arange(len(cams))
    rows = rows[np.bincount(cand_frame[rows])[cand_frame[rows]] > 1]
    if len(rows) < 2:
        return
    keys = np.stack([cand_frame[rows].astype(np.int64),
                     *np.ascontiguousarray(uv[rows]).view(np.int64).T], axis=1)
    order = np.lexsort(keys.T[::-1])
    same = np.flatnonzero((keys[order[1:]] == keys[order[:-1]]).all(axis=1))
    if not len(same):
        return
    # of several repeats, the one whose second row comes first in the file
    pairs = [sorted((int(lines[rows[order[k]]]), int(lines[rows[order[k + 1]]])))
             for k in same]
    first, second = min(pairs, key=lambda pair: (pair[1], pair[0]))
    row = rows[int(np.flatnonzero(lines[rows] == first)[0])]
    raise InputError(f"{path}: lines {first} and {second} are the same candidate (camera "
                     f"{rig.names[cams[row]]} at {format_time(times[row])} s, pixel "
                     f"({uv[row, 0]:g}, {uv[row, 1]:g})): rows repeated, as in a file appended "
                     f"to itself; remove the repeats")


def _check_one_time_per_frame(rig: Rig, frame_camera, frame_index, frame_time, cand_frame,
                              lines, path) -> None:
    """InputError if two frames (distinct camera and time) share camera and frame index.

    Their first lines in the file are named; of several clashes the one completed earliest in
    the file is reported.
    """
    first_line = np.full(len(frame_camera), np.iinfo(np.int64).max)
    np.minimum.at(first_line, cand_frame, lines)
    order = np.lexsort((first_line, frame_index, frame_camera))
    same = ((frame_camera[order[1:]] == frame_camera[order[:-1]])
            & (frame_index[order[1:]] == frame_index[order[:-1]]))
    if not same.any():
        return
    clashes = np.flatnonzero(same)
    k = int(clashes[np.argmin(first_line[order[clashes + 1]])])
    a, b = order[k], order[k + 1]  # first_line[a] < first_line[b]
    raise InputError(f"{path}: lines {first_line[a]} and {first_line[b]}: camera "
                     f"{rig.names[frame_camera[a]]} frame {frame_index[a]} at two times "
                     f"({format_time(frame_time[a])} s and {format_time(frame_time[b])} s)")


def write_detections_csv(detections: Detections, path, *, force: bool = False,
                         inputs=(), origin_ns: int = 0) -> int:
    """Write every candidate as a row (``camera,time,u,v,frame,score``) in time order, and
    every frame without a candidate as a row with ``u``, ``v`` and ``score`` empty; returns
    the number of candidates. Times are written on the original clock: ``origin_ns`` (the
    session's clock origin, :func:`session_clock`) is added back exactly. ``path`` may not
    be one of ``inputs`` (the files the detections came from); it appears only when
    complete."""
    n_cand = len(detections.cand_frame)
    empty = np.flatnonzero(np.bincount(detections.cand_frame,
                                       minlength=detections.n_frames) == 0)
    # candidates and empty frames by frame (frames are in time order), candidates of a
    # frame in their stored order
    rows = np.concatenate([detections.cand_frame, empty])
    order = np.argsort(rows, kind="stable")
    rows = rows[order]
    names = np.asarray([csv_text(n) for n in detections.camera_names],
                       dtype=object)[detections.frame_camera[rows]]
    origin = int(origin_ns)
    times = [t + origin for t in detections.frame_time_ns[rows].tolist()]  # Python ints
    frames = detections.frame_index[rows].tolist()
    cand = order.tolist()  # < n_cand: that candidate; else an empty frame
    u = detections.cand_uv[:, 0].tolist()
    v = detections.cand_uv[:, 1].tolist()
    score = detections.cand_score.tolist()
    with replacing(path, force=force, inputs=inputs) as f:
        f.write(",".join(DETECTION_COLUMNS) + "\n")
        f.writelines(f"{c},{format_time(t)},{u[i]!r},{v[i]!r},{k},{score[i]!r}\n"
                     if i < n_cand else f"{c},{format_time(t)},,,{k},\n"
                     for c, t, k, i in zip(names, times, frames, cand, strict=True))
    return n_cand


def export_tracks_csv(session, path, *, force: bool = False) -> int:
    """Write the fused tracks of ``session`` (a :class:`~pslog.log.Session`) as CSV:
    ``time,x,y,z,camera,method`` (seconds on the original clock, like the detections: the
    session's clock origin added back; world metres, camera name), then one column per
    quality field any track has (empty where a track lacks it). Rows sorted by method, time.
    Returns the number of rows; InputError if the session has no tracks. ``path`` may not
    be the session's file; it appears only when complete."""
    tracks = session.tracks
    if not tracks:
        raise InputError(f"{session.path} has no fused tracks (run 'pslog fuse' first)")
    quality = sorted({k for t in tracks.values() for k in t.quality})
    names = [csv_text(n) for n in session.rig.names]
    origin = session_clock_origin(session.metadata, session.path)
    count = 0
    with replacing(path, force=force, inputs=[session.path]) as f:
        f.write(",".join((*TRACK_COLUMNS, *map(csv_text, quality))) + "\n")
        for method in sorted(tracks):
            track = tracks[method]
            method_cell = csv_text(method)
            cols = [track.quality[k].tolist() if k in track.quality else [None] * len(track)
                    for k in quality]
            for i, (t, (x, y, z), c) in enumerate(zip(
                    track.time_ns.tolist(), track.position_world.tolist(),
                    track.camera.tolist(), strict=True)):
                extra = "".join("," + ("" if col[i] is None else repr(col[i])) for col in cols)
                f.write(f"{format_time(t + origin)},{x!r},{y!r},{z!r},{names[c]},"
                        f"{method_cell}{extra}\n")
            count += len(track)
    return count


def session_clock_origin(metadata, path="session") -> int:
    """The session clock's origin, integer ns, from a session's metadata
    (:data:`CLOCK_ORIGIN_KEY`); 0 for sessions without one (all older sessions).
    LogFormatError naming ``path`` if the value is not a decimal integer."""
    from ..errors import LogFormatError

    text = metadata.get(CLOCK_ORIGIN_KEY)
    if text is None:
        return 0
    try:
        origin = int(text.strip(), 10)
    except (ValueError, AttributeError):
        raise LogFormatError(f"{path}: session metadata {CLOCK_ORIGIN_KEY} {text!r} is not "
                             f"an integer number of nanoseconds") from None
    if not -(2**63) <= origin < 2**63:
        raise LogFormatError(f"{path}: session metadata {CLOCK_ORIGIN_KEY} {text!r} is out "
                             f"of range")
    return origin
