"""``pslog import``: build a session from a CSV of detections (format: pslog.log.csvio)."""

from __future__ import annotations

import argparse

from ._common import add_force, add_rig, check_output, declare_files


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_rig(parser)
    parser.add_argument("--detections", required=True, metavar="DET.csv",
                        help="detections CSV, header camera,time,u,v (optional frame,score); "
                             "time in seconds "
                             "on the common clock, pixels as detected; rows in any order")
    parser.add_argument("--timing", default="custom",
                        choices=("custom", "sync", "typeA", "typeB"),
                        help="label: the shutter preset the rig's offsets follow (the offsets "
                             "themselves come from the rig; default %(default)s)")
    parser.add_argument("-o", "--output", required=True, metavar="SESSION.mcap",
                        help="session file to write")
    add_force(parser)
    declare_files(parser, inputs=("rig", "detections"), outputs=("output",))


def run(args: argparse.Namespace) -> int:
    from pslog.log import SessionWriter
    from pslog.log.csvio import read_detections_csv
    from pslog.rig import resolve_rig

    output = check_output(args.output, args.force)
    rig = resolve_rig(args.rig)
    detections = read_detections_csv(args.detections, rig)
    with SessionWriter(output, rig, force=args.force, timing=args.timing,
                       source=f"pslog import {args.detections}", on_error="discard",
                       inputs=[args.detections]) as writer:
        writer.add_detections(detections)
    print(f"wrote {output}: {detections.n_candidates} detections in {detections.n_frames} "
          f"frames of {len(rig)} cameras ({', '.join(rig.names)})")
    return 0
