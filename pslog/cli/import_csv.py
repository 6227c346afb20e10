"""``pslog import``: build a session from a CSV of detections (format: pslog.log.csvio)."""

from __future__ import annotations

import argparse

from ._common import add_force, add_rig, declare_files


class _Detections(argparse.Action):
    """``--detections``, repeatable as ``NAME=FILE`` (one CSV per camera). Two files without
    camera names are refused at once: a second ``--detections`` had silently replaced the
    first (walk39: ``--detections left.csv --detections right.csv`` imported the right
    camera's alone and said "2 cameras")."""

    def __call__(self, parser, namespace, values, option_string=None):
        given = [*(getattr(namespace, self.dest, None) or ()), values]
        unnamed = [v for v in given if "=" not in v]
        if len(given) > 1 and unnamed:
            parser.error(f"argument --detections: given twice ({', '.join(given)}) without "
                         f"camera names: name each camera's file, --detections "
                         f"CAMERA=FILE (e.g. --detections cam1=left.csv --detections "
                         f"cam2=right.csv, cameras as the rig names them), or give one CSV "
                         f"holding every camera's rows (column camera)")
        setattr(namespace, self.dest, given)


def _detection_files(args: argparse.Namespace) -> list[str]:
    """The files in ``--detections CAMERA=FILE`` values (inputs, beside the values as given:
    which part is a camera is known only from the rig)."""
    return [v.partition("=")[2] for v in getattr(args, "detections", None) or () if "=" in v]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.rig import TIMING_PRESETS

    add_rig(parser)
    parser.add_argument("--detections", required=True, metavar="[CAMERA=]DET.csv",
                        action=_Detections,
                        help="detections CSV, header camera,time,u,v (optional frame,score); "
                             "time in seconds on any clock common to the cameras (negative or "
                             "Unix-epoch too: the session records its origin and 'pslog "
                             "export --detections / --csv' give the times back), pixels as "
                             "detected; rows in any order; a row with u and v empty: a "
                             "frame without a detection. One CSV per camera: repeat it as "
                             "CAMERA=FILE, a rig camera's name each (--detections "
                             "cam1=left.csv --detections cam2=right.csv); such a file's "
                             "header is time,u,v (optional frame,score), and a camera column, "
                             "if it has one, must name that camera in every row")
    parser.add_argument("--columns", metavar="NAME=COLUMN,...",
                        help="read a detector's own column names as pslog's, e.g. "
                             "--columns time=t_unix,u=px,v=py,frame=frame_id,score=conf "
                             "(names: camera, time, u, v, frame, score; each column named "
                             "must be in every file)")
    parser.add_argument("--timing", default="rig", choices=(*TIMING_PRESETS, "rig"),
                        help="set the rig's shutter offsets from a preset (default: 'rig', the "
                             "rig's own offsets); the session's timing label names the preset "
                             "the offsets match, else custom")
    parser.add_argument("-o", "--output", required=True, metavar="SESSION.mcap",
                        help="session file to write")
    add_force(parser)
    declare_files(parser, inputs=("rig", "detections", _detection_files), outputs=("output",),
                  sessions=("output",))


def run(args: argparse.Namespace) -> int:
    from pslog.errors import InputError
    from pslog.log import SessionWriter
    from pslog.log.csvio import (
        CLOCK_ORIGIN_KEY,
        format_time,
        parse_columns,
        read_camera_csvs,
        read_detections_csv,
        session_clock,
    )
    from pslog.rig import apply_timing, resolve_rig, timing_label

    output = args.output  # checked before run() (declare_files)
    rig = resolve_rig(args.rig)
    if args.timing != "rig":
        rig = apply_timing(rig, args.timing)
    named = _named_files(args.detections, rig)
    if isinstance(named, int):  # (a bad command line, said)
        return named
    # (their errors name the file and line)
    files = list(named.values()) if named else [args.detections[0]]
    label = ", ".join(files)
    columns = None
    if args.columns is not None:
        try:
            columns = parse_columns(args.columns)
        except InputError as exc:  # (a bad command-line value: exit 2)
            from ._common import usage_error

            return usage_error("import", f"argument {exc}")
    read = (read_camera_csvs(named, rig, columns) if named  # one CSV per camera
            else read_detections_csv(label, rig, columns=columns))
    try:
        detections, origin_ns = session_clock(read)
    except InputError as exc:  # (session_clock judges the times, not the file: name it)
        raise InputError(f"{label}: {exc}") from None
    metadata = {CLOCK_ORIGIN_KEY: str(origin_ns)} if origin_ns else {}
    with SessionWriter(output, rig, force=args.force, timing=timing_label(rig),
                       source=f"pslog import {' '.join(args.detections)}",
                       on_error="discard", inputs=files, metadata=metadata) as writer:
        writer.add_detections(detections)
    n, frames = detections.n_candidates, detections.n_frames
    print(f"wrote {output}: {n} detection{'s' if n != 1 else ''} in {frames} "
          f"frame{'s' if frames != 1 else ''} of {len(rig)} camera{'s' if len(rig) != 1 else ''} "
          f"({', '.join(rig.names)})"
          + (f"; session clock origin {format_time(origin_ns)} s (the CSV's times = session "
             f"times + origin)" if origin_ns else ""))
    apart = _apart_in_time(detections)
    if apart is not None:
        print(apart)
    gaps = _frames_without_row(detections)
    if gaps is not None:
        print(gaps)
    phases = _phases_off_the_rig(detections, rig, output)
    if phases is not None:
        print(phases)
    unseen = [name for c, name in enumerate(rig.names)
              if not (detections.frame_camera == c).any()]
    if unseen:  # (a rig camera without a row: its CSV left out?)
        for name in (n for n in unseen if n in named):  # (given: a camera that saw nothing)
            print(f"note: {named[name]} has no rows of camera {name}: nothing of it to fuse")
        unseen = [n for n in unseen if n not in named]
        them = f"{'s' if len(unseen) > 1 else ''} {', '.join(unseen)}"
        if unseen:
            print((f"note: no --detections CAMERA=FILE for camera{them}" if named else
                   f"note: {label} has no frame of camera{them}")
                  + f": nothing of {'them' if len(unseen) > 1 else 'it'} to fuse")
    return 0


def _named_files(values: list[str], rig) -> dict[str, str] | int:
    """``--detections`` values as ``{camera: file}`` (the per-camera form: every value
    ``CAMERA=FILE``), or ``{}`` for one CSV of every camera's rows; exit code 2, said, for a
    bad command line (a name the rig lacks, a camera or file given twice, an empty name)."""
    import os

    from ._common import usage_error

    def split(value: str) -> tuple[str, str, str]:
        # (a rig camera's name may hold '=' itself: the longest name the value starts with)
        own = [n for n in rig.names if value.startswith(n + "=")]
        if own:
            name = max(own, key=len)
            return name, "=", value[len(name) + 1:]
        return value.partition("=")

    def camera_of(value: str) -> str | None:
        name, sep, _path = split(value)
        if not sep or (rig.spelling(name) is None and len(values) == 1
                       and os.path.exists(value)):
            return None  # (a file named with an '=' given alone: taken whole)
        return name

    names = [camera_of(v) for v in values]
    if len(values) == 1 and names[0] is None:
        return {}
    named: dict[str, str] = {}
    for value, name in zip(values, names, strict=True):
        path = split(value)[2]
        if name is None or rig.spelling(name) is None:
            return usage_error("import", f"argument --detections {value}: no camera "
                                         f"{name!r} in the rig (it has {', '.join(rig.names)}); "
                                         f"give CAMERA=FILE, the rig's name for the camera")
        name = rig.spelling(name)  # (the rig's own Unicode spelling of it)
        if not path.strip():
            return usage_error("import", f"argument --detections {value}: empty file name")
        if not os.path.lexists(path) and os.path.lexists(value):
            # (a file of every camera's rows named cam1=...: 'no such file: x.csv' said not
            # which file was meant)
            return usage_error("import", f"argument --detections {value}: read as camera "
                                         f"{name}'s file {path}, which does not exist; for the "
                                         f"file {value} itself give ./{value}")
        if name in named:
            return usage_error("import", f"argument --detections: camera {name} given twice "
                                         f"({named[name]}, {path})")
        same = [c for c, p in named.items() if _same_file(p, path)]
        if same:
            return usage_error("import", f"argument --detections: {path} given for cameras "
                                         f"{same[0]} and {name}: one file per camera (or one "
                                         f"CSV of every camera's rows, given alone)")
        named[name] = path
    return named


def _same_file(a: str, b: str) -> bool:
    import os

    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.normpath(a) == os.path.normpath(b)


def _phases_off_the_rig(detections, rig, output) -> str | None:
    """A note when the CSV's times put some camera's shutters more than 2 ms from the rig's
    offsets (:func:`pslog.log.info.offset_disagreements`, as ``pslog record`` says it): the
    cameras' clocks or shutters are not where the rig plans them, which ``pslog sync``
    estimates. walk40's lab (webcams, host clocks off, offsets 0 in its rig file) fused its
    import without sync at 20-30 mm, 2-7 mm synced, and nothing had said so."""
    from pslog.errors import shell_word
    from pslog.log.info import offset_disagreements

    off = offset_disagreements(detections, rig)
    if not off:
        return None
    listed = ", ".join(f"{name} {(measured % rig.camera(name).frame_period) * 1e3:.1f} ms "
                       f"(rig {nominal * 1e3:.1f} ms)" for name, measured, nominal in off)
    return (f"note: the times put the shutters of {listed}, relative to "
            f"{rig.names[0]}'s, not where the rig's offsets plan them: clocks without genlock "
            f"(or the rig's offsets wrong); 'pslog sync {shell_word(output)} -o SYNCED.mcap' "
            f"estimates each camera's clock from the ball and writes the shutters' phases "
            f"it measures, then fuse that")


def _frames_without_row(detections) -> str | None:
    """A note naming each camera's frame numbers without a row (a detector that writes
    nothing for a frame without a ball, whose frames its ``frame`` column or, without one,
    its times number): ``pslog info``'s detection rates count only the frames given, and
    read 100 % for a camera that missed the ball in 5 % of its frames (walk40)."""
    import numpy as np

    parts = []
    for c, name in enumerate(detections.camera_names):
        k = np.unique(detections.frame_index[detections.frame_camera == c])
        if len(k) < 2:
            continue
        spanned = int(k[-1] - k[0] + 1)
        if spanned > len(k):
            parts.append(f"{name} {spanned - len(k)} of {spanned}")
    if not parts:
        return None
    return (f"note: frame numbers without a row (frames the detector wrote nothing for, or "
            f"the camera dropped): {', '.join(parts)}; they count as no frame, so 'pslog "
            f"info' rates the detections of the frames given only: write a row with u and v "
            f"empty for a frame without a detection to count it as missed")


def _apart_in_time(detections) -> str | None:
    """A note when some camera's frames do not overlap another's in time: the CSV's times
    are then not on one clock (e.g. each camera's own clock, years apart: walk39's import
    wrote a "session" of 56 years, and pslog sync blamed false candidates)."""
    import numpy as np

    from pslog.log.csvio import format_time

    times, cams = detections.frame_time_ns, detections.frame_camera
    names = detections.camera_names
    spans = sorted((int(times[cams == c].min()), int(times[cams == c].max()), names[c])
                   for c in range(len(names)) if np.any(cams == c))
    end, before = spans[0][1], spans[0][2]  # (the latest end so far, and its camera)
    for start, stop, after in spans[1:]:
        if start > end:  # (a gap in time no camera spans: nothing across it is fused)
            return (f"note: camera {after}'s frames start {format_time(start - end)} s after "
                    f"camera {before}'s end: the cameras' times do not overlap, so either "
                    f"they are not on one clock (then shift a camera's times in the CSV: "
                    f"'pslog sync' searches each clock's offset within half a frame period, "
                    f"--search-ms widens it) or the cameras never saw the ball at once; "
                    f"nothing across that gap can be fused")
        if stop > end:
            end, before = stop, after
    return None
