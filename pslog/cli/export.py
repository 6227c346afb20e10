"""``pslog export``: a session's detections (the import format) and/or fused tracks as CSV,
TUM trajectories (evo), JSON lines, Parquet or C3D (docs/interchange.md)."""

from __future__ import annotations

import argparse
import os

from ._common import add_force, declare_files

EXAMPLES = """\
examples:
  pslog export fused.mcap --csv tracks.csv
  pslog export fused.mcap --tum traj/ && evo_ape tum traj/truth.tum traj/typeA.tum
  pslog export fused.mcap --jsonl tracks.jsonl --parquet tracks.parquet --c3d tracks.c3d
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = EXAMPLES
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("session", metavar="SESSION.mcap", help="session or fused session")
    parser.add_argument("--detections", metavar="DET.csv",
                        help="write every detection candidate, in the 'pslog import' format, "
                             "and every frame without one (u, v empty)")
    parser.add_argument("--csv", metavar="TRACKS.csv",
                        help="write the fused tracks: time,x,y,z,camera,method (+ quality)")
    parser.add_argument("--tum", metavar="DIR",
                        help="write one TUM trajectory per method (DIR/<method>.tum) and the "
                             "truth (DIR/truth.tum), for evo_traj / evo_ape: 'timestamp tx ty "
                             "tz qx qy qz qw', session-clock seconds, metres, identity "
                             "orientation. With --force an earlier export in DIR is replaced "
                             "as a whole (its <method>.tum the new session lacks removed); "
                             "other files in DIR are kept")
    parser.add_argument("--jsonl", metavar="TRACKS.jsonl",
                        help="write the fused tracks as JSON lines: one object per point "
                             "(method, time, position, camera, quality)")
    parser.add_argument("--parquet", metavar="TRACKS.parquet",
                        help="write the fused tracks as Parquet, one row per point (needs "
                             "pyarrow: pip install 'pslog[parquet]')")
    parser.add_argument("--c3d", metavar="TRACKS.c3d",
                        help="write the fused tracks as C3D, one point per method and the "
                             "truth, in millimetres (needs c3d: pip install 'pslog[c3d]')")
    add_force(parser)
    declare_files(parser, inputs=("session",),
                  outputs=("detections", "csv", "jsonl", "parquet", "c3d"), folders=("tum",))


#: each file option's format (a key of ``_common.FORMATS``: its suffixes)
_FORMAT_OF = {"--detections": "csv", "--csv": "csv", "--jsonl": "jsonl",
              "--parquet": "parquet", "--c3d": "c3d"}


def kept_outputs(args: argparse.Namespace) -> list[str]:
    """What a run that completed wrote besides its declared files: the --tum folder."""
    return [os.path.join(args.tum, "")] if args.tum else []


def run(args: argparse.Namespace) -> int:
    from pslog.errors import InputError
    from pslog.log import read_session

    from ._common import OTHER_FORMATS, misnamed, usage_error, written_suffix

    if args.tum is not None and not args.tum.strip():  # (was "nothing to export", exit 1)
        return usage_error("export", "argument --tum: empty folder name")
    if args.tum and not os.path.exists(args.tum) and written_suffix(
            os.path.normpath(args.tum)) in OTHER_FORMATS:
        # a new folder named as a file ('--tum traj.tum' made a folder traj.tum/ holding
        # typeA.tum...: the session 33 walkthrough); an existing path is said as it is
        return usage_error("export", f"--tum {args.tum}: a folder, one TUM file per method "
                                     f"inside (DIR/<method>.tum); name it without a file "
                                     f"suffix")
    track_options = (args.csv, args.tum, args.jsonl, args.parquet, args.c3d)
    if not args.detections and not any(track_options):
        raise InputError("nothing to export: give --detections DET.csv and/or the tracks as "
                         "--csv, --tum, --jsonl, --parquet or --c3d")
    # a file's name says its format, and a mismatch is a bad command line (exit 2), never a
    # file of one format under another's name: '--parquet t.csv' wrote Parquet under a CSV's
    # name (and '--c3d t.csv' then replaced it), as 'rig export -o' and 'view --save' refuse
    for option, path in (("--detections", args.detections), ("--csv", args.csv),
                         ("--jsonl", args.jsonl), ("--parquet", args.parquet),
                         ("--c3d", args.c3d)):
        wrong = misnamed(option, path, _FORMAT_OF[option]) if path else None
        if wrong:
            return usage_error("export", wrong)
    # the file outputs were checked before run() (declare_files): never the session, never
    # existing without --force; --tum's folder is checked by its writer, all files first
    session = read_session(args.session)
    if any(track_options) and not session.tracks:
        raise InputError(f"{args.session} has no fused tracks to export (run 'pslog fuse')")
    grid = None
    if args.c3d:  # what can be refused before anything is written, is
        from pslog.interchange.track_formats import c3d_check

        grid = c3d_check(session)
    # one exporter per option: each writes its own file(s) from the session, all or nothing
    # (all_or_nothing: every file complete first, then all moved over the old ones; on an
    # error or a signal none is, and the old files stay); the lines after the moves
    import contextlib
    import functools
    import io

    from pslog.outputs import all_or_nothing

    said = io.StringIO()
    made_tum = args.tum is not None and not os.path.exists(args.tum)
    try:
        with all_or_nothing(), contextlib.redirect_stdout(said):
            for path, export in ((args.detections, _export_detections),
                                 (args.csv, _export_tracks), (args.tum, _export_tum),
                                 (args.jsonl, _export_jsonl), (args.parquet, _export_parquet),
                                 (args.c3d, functools.partial(_export_c3d, grid=grid))):
                if path:
                    export(session, path, args.force)
    except BaseException:
        if made_tum:  # the --tum folder this run made, left empty
            with contextlib.suppress(OSError):
                os.rmdir(args.tum)
        raise
    print(said.getvalue(), end="")
    _say_session_clock(session, args)
    return 0


def _say_session_clock(session, args: argparse.Namespace) -> None:
    """One line when a session with a clock origin (times imported on another clock, e.g.
    Unix-epoch) goes out in a format that keeps the session clock (TUM, JSON lines, Parquet,
    C3D) while ``--detections`` and ``--csv`` give the original times back: a user comparing
    the TUM file with a truth of theirs on that clock found no pose in common (walk39)."""
    from pslog.log.csvio import format_time, session_clock_origin

    origin = session_clock_origin(session.metadata, session.path)
    kept = [f"--{name} {path}" for name, path in (("tum", args.tum), ("jsonl", args.jsonl),
                                                    ("parquet", args.parquet), ("c3d", args.c3d))
            if path]
    if origin and kept:
        print(f"note: {', '.join(kept)}: times on the session clock, whose origin is "
              f"{format_time(origin)} s on the imported one (original time = session time + "
              f"origin; --csv and --detections write the original times)")


def _export_detections(session, path: str, force: bool) -> None:
    from pslog.log.csvio import session_clock_origin, write_detections_csv

    n = write_detections_csv(session.detections, path, force=force, inputs=[session.path],
                             origin_ns=session_clock_origin(session.metadata, session.path))
    print(f"wrote {path}: {n} detection{'s' if n != 1 else ''}")


def _export_tracks(session, path: str, force: bool) -> None:
    from pslog.log.csvio import export_tracks_csv

    n = export_tracks_csv(session, path, force=force)
    print(f"wrote {path}: {n} track points ({', '.join(sorted(session.tracks))})")


def _export_tum(session, path: str, force: bool) -> None:
    from pslog.interchange.track_formats import write_tum

    counts = write_tum(session, path, force=force)
    print(f"wrote {path}: " + ", ".join(f"{name}.tum ({n} poses)"
                                        for name, n in counts.items()))


def _export_jsonl(session, path: str, force: bool) -> None:
    from pslog.interchange.track_formats import write_jsonl

    print(f"wrote {path}: {write_jsonl(session, path, force=force)} track points")


def _export_parquet(session, path: str, force: bool) -> None:
    from pslog.interchange.track_formats import write_parquet

    print(f"wrote {path}: {write_parquet(session, path, force=force)} rows")


def _export_c3d(session, path: str, force: bool, grid=None) -> None:
    from pslog.interchange.track_formats import write_c3d

    frames, rate, resampled = write_c3d(session, path, force=force, grid=grid)
    print(f"wrote {path}: {frames} frames at {rate:g} Hz, one point per method"
          + (" and the truth" if session.truth is not None else "") + " (mm)")
    if resampled:  # irregular times: two points on one frame (one was left out before)
        print(f"  resampled onto the {rate:g} Hz frames, as points of theirs would share "
              f"one (times on no common grid: rolling shutters, drifting clocks, jitter; or "
              f"cameras firing together): "
              + ", ".join(f"{m} {n} frames from {len(session.tracks[m])} points"
                          for m, (n, _nearer) in resampled.items())
              + "; linear between points with no detection the method withheld and at "
                "most one frame without the ball between them (any other gap stays empty; a "
                "lone point in it on its nearest frame); --csv, --jsonl or --parquet keep "
                "every point at its own time")
        nearer = {m: k for m, (_n, k) in resampled.items() if k}
        if nearer:  # lone points sharing a frame: the frame holds the nearest in time
            print("  not in the file: " + ", ".join(
                f"{m} {k} point{'s' if k > 1 else ''}" for m, k in nearer.items())
                + ", lone points (no frame bridged beside them) whose nearest frame holds "
                  "another lone point nearer its time; --csv, --jsonl or --parquet keep "
                  "them")
