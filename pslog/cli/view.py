"""pslog view: browse a session and its fused 3D tracks in rerun.

Without ``--save``/``--serve``/``--connect``/``--stdout`` (one at most) the native viewer is
spawned, which needs a display; on a machine without one this says so and suggests ``--save``
or ``--serve``. Everything rerun would otherwise report as a Rust log line, a traceback or a
hang is checked first or caught and said in one line: ``--save`` writes through
:func:`viewers.rrd_file.rrd_file` (full disk, read-only folder), ``--stdout`` through
:func:`viewers.rrd_file.rrd_stdout` (a reader that went away, a full or closed output), the
live sinks go through :func:`viewers.sinks.open_sink` (``--serve`` checks its ports,
``--connect`` checks that a rerun viewer answers at ``--url`` within seconds). This
module only parses and maps errors: every rerun call lives in :mod:`viewers`.
"""

from __future__ import annotations

import argparse
import sys

from pslog.errors import shell_word

from ._common import (
    add_force,
    add_method_option,
    check_output,
    declare_files,
    installed_command,
    misnamed,
    nonnegative_float,
    positive_float,
    usage_error,
)


def _frames(text: str):
    """argparse type of ``--frames``: the parsed :class:`viewers.data.FramesChoice`; the
    library's message as argparse's error (exit 2)."""
    from pslog.errors import PslogError
    from viewers.data import FramesChoice

    try:
        return FramesChoice.parse(text)
    except PslogError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from ._common import port

    parser.add_argument("sessions", nargs="+", metavar="SESSION.mcap",
                        help="session MCAP, then optionally fused copies of it (pslog fuse "
                             "output) whose tracks are shown too")
    add_method_option(parser, "tracks to show, repeat or give a comma-separated list; a "
                              "fusion method no file holds is fused on the fly (default: every "
                              "stored track, else typeA)", known_only=False)
    parser.add_argument("--frames", default="all", metavar="all|none|every:N",
                        type=_frames,
                        help="recorded images to include (default %(default)s; every:N keeps "
                             "frames whose index is a multiple of N)")
    parser.add_argument("--start", type=nonnegative_float, metavar="S",
                        help="start, seconds after the session's first frame")
    parser.add_argument("--end", type=nonnegative_float, metavar="S",
                        help="end, seconds after the session's first frame")
    parser.add_argument("--detail", default="600", metavar="all|S|A:B",
                        help="where every frame's rays, epipolar lines, Figure 2 overlays and "
                             "plot points are kept: 'all', the first S seconds shown, or A:B "
                             "seconds after the session's first frame; beyond it one frame in "
                             "--thin-every (plots: first/last/min/max per bucket). Default "
                             "%(default)s: a long match stays light; tracks, detections and "
                             "images are always complete")
    parser.add_argument("--thin-every", type=int, default=10, metavar="N",
                        help="thinning factor beyond --detail (default %(default)s)")
    parser.add_argument("--web-port", type=port, default=9090,
                        metavar="PORT", help="port of the web viewer with --serve "
                                             "(default %(default)s)")
    parser.add_argument("--grpc-port", type=port, default=9876,
                        metavar="PORT", help="port of the data server with --serve "
                                             "(default %(default)s)")
    add_force(parser)
    from viewers.sinks import CONNECT_TIMEOUT_S, add_sink_arguments

    add_sink_arguments(parser)  # rerun's standard flags: --save, --serve, --connect, --url, ...
    parser.add_argument("--connect-timeout", type=positive_float, default=CONNECT_TIMEOUT_S,
                        metavar="S", help="seconds to wait for the viewer at --url to answer "
                                          "with --connect (default %(default)s)")
    declare_files(parser, inputs=("sessions",), outputs=("save",))


def run(args: argparse.Namespace) -> int:
    from pslog.errors import PslogError
    from viewers.data import parse_methods
    from viewers.sinks import check_url, has_display, open_sink

    if args.url and not args.connect:
        print(f"pslog view: error: --url is where --connect sends the data; add --connect "
              f"(pslog view ... --connect --url {args.url}) (see 'pslog view --help')",
              file=sys.stderr)
        return 2
    # malformed values are command-line errors (exit 2), found before any file is read
    if args.start is not None and args.end is not None and args.start >= args.end:
        return usage_error("view", f"--start ({args.start:g} s) must be before --end "
                                   f"({args.end:g} s)")
    from viewers.data import DetailChoice

    try:
        detail = DetailChoice.parse(args.detail, args.thin_every)
    except PslogError as exc:
        return usage_error("view", f"argument --detail/--thin-every: {exc}")
    try:
        parse_methods(args.methods)
    except PslogError as exc:
        return usage_error("view", f"argument --method: {exc}")
    if args.connect and args.url:
        try:
            check_url(args.url)
        except PslogError as exc:
            return usage_error("view", f"argument {exc}")
    sinks = [flag for flag, on in (("--save", args.save), ("--serve", args.serve),
                                   ("--connect", args.connect), ("--stdout", args.stdout)) if on]
    if len(sinks) > 1:
        return usage_error("view", f"choose one of --save, --serve, --connect and --stdout, "
                                   f"not {' and '.join(sinks)}")
    if not sinks and (args.headless or not has_display()):
        why = "--headless given" if args.headless else "no display (DISPLAY/WAYLAND_DISPLAY unset)"
        print(f"pslog view: {why}, so no viewer window can open; use --save out.rrd (then "
              f"'rerun out.rrd' where there is a display), --serve to browse from a web "
              f"browser, or --connect to a viewer running elsewhere", file=sys.stderr)
        return 1
    if args.serve and args.web_port == args.grpc_port:
        return usage_error("view", f"--web-port and --grpc-port must differ, both are "
                                   f"{args.web_port}")
    sink = None
    if args.save:
        check_output(args.save, args.force, inputs=args.sessions)
        # (after check_output: an input or a folder named is said as such, exit 1) rerun
        # writes its own format whatever the name: a recording is named .rrd, never written
        # under another format's name (``--save out.txt`` wrote one), as 'rig export' -o
        wrong = misnamed("--save", args.save, "rrd")
        if wrong:
            return usage_error("view", wrong)
    elif args.stdout:
        from pslog.outputs import stdout_closed

        if stdout_closed():  # closed when Python started (``>&-``): said before reading
            raise PslogError("cannot write to standard output: it is closed")
    else:  # ports and viewer checked before the data is read: errors come out first
        kind = "serve" if args.serve else "connect" if args.connect else "spawn"
        sink = open_sink(kind, web_port=args.web_port, grpc_port=args.grpc_port,
                         url=args.url, connect_timeout_s=args.connect_timeout)
    from pslog import progress

    # rerun loaded only now: a command refused above did not pay for it (a CPU second)
    from viewers import load_view_data, log_view, new_stream
    from viewers.rrd_file import rrd_file, rrd_stdout

    # read and fuse before any sink starts, so errors come out before a viewer does
    progress.update(total=2, what="reading the sessions (fusing what is not stored)")
    from viewers.data import ViewOptionError

    try:
        data = load_view_data(args.sessions, methods=args.methods, start=args.start,
                              end=args.end, detail=detail)
    except ViewOptionError as exc:  # a value that does not fit the sessions: as fuse's
        message = str(exc) if exc.option in str(exc) else f"argument {exc.option}: {exc}"
        return usage_error("view", message)
    out = sys.stderr if args.stdout else sys.stdout
    if not args.stdout:  # (on stderr, a note before a failed write would make two lines)
        for note in data.notes:
            print(note, file=out)
    rec = new_stream()
    progress.step("logging to rerun")

    def report(counts: dict[str, int]) -> None:
        print("logged " + ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items()
                                    if v), file=out)

    if args.stdout:  # through a pipe pslog copies: a failed write is one line, not a hang
        with rrd_stdout(rec):
            counts = log_view(rec, data, args.frames)
        for note in data.notes:
            print(note, file=out)
        report(counts)
        return 0
    if sink is None:
        with rrd_file(rec, args.save, force=args.force, inputs=args.sessions) as path:
            counts = log_view(rec, data, args.frames)
        report(counts)
        rerun = shell_word(installed_command("rerun"))
        print(f"wrote {path}; open it with: {rerun} {shell_word(path)}", file=out)
        return 0
    sink.start(rec)
    counts = log_view(rec, data, args.frames)
    sink.finish(rec)
    progress.done()
    report(counts)
    if sink.kind == "serve":
        sink.serve_until_interrupted(rec, lambda: print(
            f"serving the web viewer at {sink.web_address} (Ctrl-C to stop)", file=out,
            flush=True))
    return 0
