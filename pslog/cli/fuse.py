"""pslog fuse: fuse a session's detections into 3D tracks, written into a copy of the session."""

from __future__ import annotations

import argparse

from ._common import add_force, check_output, nonnegative_float, positive_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("session", help="session MCAP file")
    parser.add_argument(
        "--method", action="append", dest="methods", metavar="METHOD",
        help="fusion method: sync, nearest, typeA, typeB, linear (repeat for several; "
             "default: every method the rig's timing allows)")
    parser.add_argument("-o", "--output", required=True,
                        help="output MCAP: a copy of the session with one topic per track")
    parser.add_argument(
        "--rig", metavar="RIG",
        help="fuse with this corrected rig (TOML file; same camera names and order) instead of "
             "the recorded calibration; the output session carries it")
    parser.add_argument("--tolerance-ms", type=nonnegative_float, default=1.0,
                        help="detections this close count as simultaneous (default 1 ms)")
    parser.add_argument("--max-gap-ms", type=positive_float, default=None,
                        help="longest span a method may bridge (default 3.5 frame periods)")
    add_force(parser)


def run(args: argparse.Namespace) -> int:
    from pslog.errors import FusionError, RigError
    from pslog.fusion import METHODS, FusionOptions, check_method, fuse_all
    from pslog.log import copy_session, read_session
    from pslog.rig import resolve_rig

    output = check_output(args.output, args.force)
    session = read_session(args.session)
    rig = session.rig
    if args.rig is not None:
        rig = resolve_rig(args.rig)
        if rig.names != session.rig.names:
            raise RigError(f"{args.rig}: cameras {', '.join(rig.names)} differ from the "
                           f"session's {', '.join(session.rig.names)} (names and order must "
                           f"match)")
    options = FusionOptions(tolerance_s=args.tolerance_ms / 1e3,
                            max_gap_s=None if args.max_gap_ms is None else args.max_gap_ms / 1e3)
    observations = session.detections.best()
    if args.methods:
        methods = [check_method(m) for m in dict.fromkeys(args.methods)]
        tracks = fuse_all(observations, rig, methods, options)
    else:  # every method that can run on this rig and timing
        tracks = {}
        for method in METHODS:
            try:
                tracks.update(fuse_all(observations, rig, [method], options))
            except FusionError as exc:
                print(f"skipping {method}: {exc}")
    if not tracks:
        raise FusionError("no fusion method produced a track")
    copy_session(args.session, output, tracks=list(tracks.values()), force=args.force,
                 rig=None if args.rig is None else rig)
    for method, track in tracks.items():
        print(f"{method:<8} {len(track):>7d} points")
    print(f"wrote {output}")
    return 0
