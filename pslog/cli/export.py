"""``pslog export``: a session's detections (the import format) and/or fused tracks as CSV."""

from __future__ import annotations

import argparse

from ._common import add_force, declare_files


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("session", metavar="SESSION.mcap", help="session or fused session")
    parser.add_argument("--detections", metavar="DET.csv",
                        help="write every detection candidate, in the 'pslog import' format")
    parser.add_argument("--csv", metavar="TRACKS.csv",
                        help="write the fused tracks: time,x,y,z,camera,method (+ quality)")
    add_force(parser)
    declare_files(parser, inputs=("session",), outputs=("detections", "csv"))


def run(args: argparse.Namespace) -> int:
    from pslog.errors import InputError
    from pslog.log import read_session

    if not args.detections and not args.csv:
        raise InputError("nothing to export: give --detections DET.csv and/or --csv TRACKS.csv")
    # the outputs were checked before run() (declare_files): never the session, never
    # existing without --force
    session = read_session(args.session)
    if args.csv and not session.tracks:
        raise InputError(f"{args.session} has no fused tracks to export (run 'pslog fuse')")
    # one exporter per option: each writes its own file from the session
    for path, export in ((args.detections, _export_detections), (args.csv, _export_tracks)):
        if path:
            export(session, path, args.force)
    return 0


def _export_detections(session, path: str, force: bool) -> None:
    from pslog.log.csvio import session_clock_origin, write_detections_csv

    n = write_detections_csv(session.detections, path, force=force, inputs=[session.path],
                             origin_ns=session_clock_origin(session.metadata, session.path))
    print(f"wrote {path}: {n} detections")


def _export_tracks(session, path: str, force: bool) -> None:
    from pslog.log.csvio import export_tracks_csv

    n = export_tracks_csv(session, path, force=force)
    print(f"wrote {path}: {n} track points ({', '.join(sorted(session.tracks))})")
