"""``pslog import``: build a session from a CSV of detections (format: pslog.log.csvio)."""

from __future__ import annotations

import argparse

from ._common import add_force, add_rig, declare_files


class _OneCsv(argparse.Action):
    """``--detections`` given once: a second one silently replaced the first (walk39: one
    CSV per camera, ``--detections left.csv --detections right.csv``, imported the right
    camera's alone and said "2 cameras")."""

    def __call__(self, parser, namespace, values, option_string=None):
        before = getattr(namespace, self.dest, None)
        if before is not None:
            parser.error(f"argument --detections: given twice ({before}, {values}): pslog "
                         f"import reads one CSV holding every camera's rows (column camera); "
                         f"join the cameras' files into one first (docs/log-format.md)")
        setattr(namespace, self.dest, values)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.rig import TIMING_PRESETS

    add_rig(parser)
    parser.add_argument("--detections", required=True, metavar="DET.csv", action=_OneCsv,
                        help="detections CSV, header camera,time,u,v (optional frame,score); "
                             "time in seconds on any clock common to the cameras (negative or "
                             "Unix-epoch too: the session records its origin and 'pslog "
                             "export --detections / --csv' give the times back), pixels as "
                             "detected; rows in any order; a row with u and v empty: a "
                             "frame without a detection")
    parser.add_argument("--timing", default="rig", choices=(*TIMING_PRESETS, "rig"),
                        help="set the rig's shutter offsets from a preset (default: 'rig', the "
                             "rig's own offsets); the session's timing label names the preset "
                             "the offsets match, else custom")
    parser.add_argument("-o", "--output", required=True, metavar="SESSION.mcap",
                        help="session file to write")
    add_force(parser)
    declare_files(parser, inputs=("rig", "detections"), outputs=("output",),
                  sessions=("output",))


def run(args: argparse.Namespace) -> int:
    from pslog.errors import InputError
    from pslog.log import SessionWriter
    from pslog.log.csvio import (
        CLOCK_ORIGIN_KEY,
        format_time,
        read_detections_csv,
        session_clock,
    )
    from pslog.rig import apply_timing, resolve_rig, timing_label

    output = args.output  # checked before run() (declare_files)
    rig = resolve_rig(args.rig)
    if args.timing != "rig":
        rig = apply_timing(rig, args.timing)
    read = read_detections_csv(args.detections, rig)  # (its errors name the file)
    try:
        detections, origin_ns = session_clock(read)
    except InputError as exc:  # (session_clock judges the times, not the file: name it)
        raise InputError(f"{args.detections}: {exc}") from None
    metadata = {CLOCK_ORIGIN_KEY: str(origin_ns)} if origin_ns else {}
    with SessionWriter(output, rig, force=args.force, timing=timing_label(rig),
                       source=f"pslog import {args.detections}", on_error="discard",
                       inputs=[args.detections], metadata=metadata) as writer:
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
    unseen = [name for c, name in enumerate(rig.names)
              if not (detections.frame_camera == c).any()]
    if unseen:  # (a rig camera without a row: its CSV left out?)
        print(f"note: {args.detections} has no frame of camera{'s' if len(unseen) > 1 else ''} "
              f"{', '.join(unseen)}: nothing of {'them' if len(unseen) > 1 else 'it'} to fuse")
    return 0


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
