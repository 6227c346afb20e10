"""pslog view: browse a session and its fused 3D tracks in rerun.

Without ``--save``/``--serve``/``--connect``/``--stdout`` the native viewer is spawned, which
needs a display; on a machine without one this says so and suggests ``--save`` or ``--serve``.
"""

from __future__ import annotations

import argparse
import os
import sys

from ._common import add_force, check_output, declare_files, installed_command, nonnegative_float


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from viewers.data import FramesChoice

    from ._common import checked_by, port
    parser.add_argument("sessions", nargs="+", metavar="SESSION.mcap",
                        help="session MCAP, then optionally fused copies of it (pslog fuse "
                             "output) whose tracks are shown too")
    parser.add_argument("--methods", metavar="M1,M2",
                        help="tracks to show, comma-separated; a fusion method no file holds is "
                             "fused on the fly (default: every stored track, else typeA)")
    parser.add_argument("--frames", default="all", metavar="all|none|every:N",
                        type=checked_by(FramesChoice.parse, "frames"),
                        help="recorded images to include (default %(default)s; every:N keeps "
                             "frames whose index is a multiple of N)")
    parser.add_argument("--start", type=nonnegative_float, metavar="S",
                        help="start, seconds after the session's first frame")
    parser.add_argument("--end", type=nonnegative_float, metavar="S",
                        help="end, seconds after the session's first frame")
    parser.add_argument("--web-port", type=port, default=9090,
                        metavar="PORT", help="port of the web viewer with --serve "
                                             "(default %(default)s)")
    parser.add_argument("--grpc-port", type=port, default=9876,
                        metavar="PORT", help="port of the data server with --serve "
                                             "(default %(default)s)")
    add_force(parser)
    import rerun as rr  # rerun's standard flags: --save, --serve, --connect, --url, ...

    rr.script_add_args(parser)
    _reword_rerun_flags(parser)
    declare_files(parser, inputs=("sessions",), outputs=("save",))


def has_display() -> bool:
    """Whether a native viewer window can open (on Linux: an X11 or Wayland display)."""
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def run(args: argparse.Namespace) -> int:
    from viewers import FramesChoice, load_view_data, log_view, new_stream

    frames = FramesChoice.parse(args.frames)
    to_file_or_server = args.save or args.serve or args.connect or args.stdout
    if not to_file_or_server and (args.headless or not has_display()):
        why = "--headless given" if args.headless else "no display (DISPLAY/WAYLAND_DISPLAY unset)"
        print(f"pslog view: {why}, so no viewer window can open; use --save out.rrd (then "
              f"'rerun out.rrd' where there is a display) or --serve to browse from a web "
              f"browser", file=sys.stderr)
        return 1
    if args.save:
        check_output(args.save, args.force)
    # read and fuse before any sink starts, so errors come out before a viewer does
    data = load_view_data(args.sessions, methods=args.methods, start=args.start, end=args.end)
    out = sys.stderr if args.stdout else sys.stdout
    for note in data.notes:
        print(note, file=out)

    import rerun as rr

    rec = new_stream()
    if args.stdout:
        rec.stdout()
    elif args.serve:
        uri = rec.serve_grpc(grpc_port=args.grpc_port)
        rr.serve_web_viewer(web_port=args.web_port, open_browser=has_display(), connect_to=uri)
    elif args.connect:
        rec.connect_grpc(args.url)
    elif args.save:
        rec.save(args.save)
    else:
        rec.spawn()
    try:
        counts = log_view(rec, data, frames)
    except BaseException:  # e.g. a damaged image chunk met while logging: no partial .rrd
        if args.save:
            from pathlib import Path

            rec.disconnect()
            Path(args.save).unlink(missing_ok=True)
        raise
    rec.flush()
    print("logged " + ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items() if v),
          file=out)
    if args.save:
        rec.disconnect()  # writes the file's footer
        print(f"wrote {args.save}; open it with: {installed_command('rerun')} {args.save}",
              file=out)
    if args.serve:
        from urllib.parse import quote

        print(f"serving the web viewer at http://localhost:{args.web_port}/?url={quote(uri)} "
              f"(Ctrl-C to stop)", file=out, flush=True)
        try:
            rr.script_teardown(args)  # sleeps until Ctrl-C
        except KeyboardInterrupt:
            pass
        finally:
            rec.disconnect()
    return 0


#: our wording of rerun's standard flags (same metavar and help style as the other options)
_RERUN_FLAGS = {
    "headless": (None, "do not open a viewer window"),
    "connect": (None, "send to a rerun viewer already running (at --url)"),
    "serve": (None, "serve a web viewer at http://localhost:PORT (--web-port) until Ctrl-C"),
    "url": ("URL", "rerun viewer to send to with --connect (default: rerun's local viewer)"),
    "save": ("OUT.rrd", "write a rerun recording to this file (open it with 'rerun OUT.rrd')"),
    "stdout": (None, "write the recording to standard output, to pipe into 'rerun -'"),
}


def _reword_rerun_flags(parser: argparse.ArgumentParser) -> None:
    for action in parser._actions:
        if action.dest in _RERUN_FLAGS:
            action.metavar, action.help = _RERUN_FLAGS[action.dest]
