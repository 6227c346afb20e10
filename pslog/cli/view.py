"""pslog view: browse a session and its fused 3D tracks in rerun.

Without ``--save``/``--serve``/``--connect``/``--stdout`` (one at most) the native viewer is
spawned, which needs a display; on a machine without one this says so and suggests ``--save``
or ``--serve``. Everything rerun would otherwise report as a Rust log line, a traceback or a
hang is checked first or caught and said in one line: ``--save`` writes through
:func:`viewers.rrd_file.rrd_file` (full disk, read-only folder), ``--serve`` checks its ports,
``--connect`` checks that a rerun viewer answers at ``--url`` within seconds.
"""

from __future__ import annotations

import argparse
import os
import sys

from ._common import (
    add_force,
    check_output,
    declare_files,
    installed_command,
    nonnegative_float,
    usage_error,
)

#: seconds to wait for a rerun viewer to accept a connection (--connect)
CONNECT_TIMEOUT_S = 3.0
#: longest wait for a live viewer to take the logged data, seconds (only a hang reaches it)
SEND_TIMEOUT_S = 60.0
_DEFAULT_GRPC_URL = "rerun+http://127.0.0.1:9876/proxy"
#: the HTTP/2 client connection preface and an empty SETTINGS frame (RFC 9113, 3.4)
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])



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


def check_free_port(number: int, option: str) -> None:
    """Refuse a port the servers of ``--serve`` could not listen on (rerun would print a
    Rust error log and a traceback, or serve nothing): in use, or privileged."""
    import errno
    import socket

    from pslog.errors import InputError

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        # as rerun does: every interface, address reuse on (a port in TIME_WAIT is free)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(("0.0.0.0", number))
            sock.listen()
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise InputError(f"port {number} is in use by another program; choose "
                                 f"another with {option}") from None
            if exc.errno == errno.EACCES:
                raise InputError(f"port {number} is privileged (below 1024; only root may "
                                 f"listen there); choose another with {option}") from None
            raise InputError(f"cannot listen on port {number} ({option}): "
                             f"{exc.strerror or exc}") from None


def check_viewer_reachable(url: str | None) -> str:
    """The gRPC URL of ``--connect`` if a viewer accepts connections there within
    :data:`CONNECT_TIMEOUT_S`; rerun itself would retry silently for ever."""
    import errno
    import socket
    from urllib.parse import urlsplit

    from pslog.errors import InputError

    url = url or _DEFAULT_GRPC_URL
    try:
        parts = urlsplit(url.removeprefix("rerun+"))
        host, number = parts.hostname, parts.port
    except ValueError:
        host = number = None
    if not host or not number:
        raise InputError(f"--url must look like {_DEFAULT_GRPC_URL}, got {url!r}")
    try:
        with socket.create_connection((host, number), timeout=CONNECT_TIMEOUT_S) as sock:
            # a viewer speaks gRPC, i.e. HTTP/2: it answers the client preface with a
            # SETTINGS frame. Anything else (another program on the port) would take the
            # data and never let rerun finish, so the process would hang at exit.
            sock.sendall(_HTTP2_PREFACE)
            answer = b""
            while len(answer) < 9:
                more = sock.recv(9 - len(answer))
                if not more:
                    break
                answer += more
    except OSError as exc:
        reason = "timed out" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        nobody = {errno.ECONNREFUSED, errno.EHOSTUNREACH, errno.ENETUNREACH}
        if isinstance(exc, TimeoutError) or exc.errno not in nobody:
            raise InputError(f"the program at {url} does not answer as a rerun viewer "
                             f"({reason} within {CONNECT_TIMEOUT_S:g} s); check --url"
                             ) from None
        raise InputError(f"no rerun viewer at {url} ({reason}); start one with 'rerun' "
                         f"(it listens on port 9876), or use --save out.rrd or --serve"
                         ) from None
    if len(answer) < 9 or answer[3] != 4:
        raise InputError(f"the program at {url} does not answer as a rerun viewer (no gRPC "
                         f"handshake); check --url")
    return url


def run(args: argparse.Namespace) -> int:
    from pslog.errors import PslogError
    from viewers import FramesChoice, load_view_data, log_view, new_stream
    from viewers.rrd_file import rrd_file

    frames = (args.frames if isinstance(args.frames, FramesChoice)  # parsed by argparse
              else FramesChoice.parse(args.frames))
    if args.url and not args.connect:
        print(f"pslog view: error: --url is where --connect sends the data; add --connect "
              f"(pslog view ... --connect --url {args.url}) (see 'pslog view --help')",
              file=sys.stderr)
        return 2
    sinks = [flag for flag, on in (("--save", args.save), ("--serve", args.serve),
                                   ("--connect", args.connect), ("--stdout", args.stdout)) if on]
    if len(sinks) > 1:
        return usage_error("view", f"choose one of --save, --serve, --connect and --stdout, "
                                   f"not {' and '.join(sinks)}")
    to_file_or_server = bool(sinks)
    if not to_file_or_server and (args.headless or not has_display()):
        why = "--headless given" if args.headless else "no display (DISPLAY/WAYLAND_DISPLAY unset)"
        print(f"pslog view: {why}, so no viewer window can open; use --save out.rrd (then "
              f"'rerun out.rrd' where there is a display), --serve to browse from a web "
              f"browser, or --connect to a viewer running elsewhere", file=sys.stderr)
        return 1
    if args.save:
        check_output(args.save, args.force, inputs=args.sessions)
    url = None
    if args.stdout:
        pass
    elif args.serve:
        if args.web_port == args.grpc_port:
            return usage_error("view", f"--web-port and --grpc-port must differ, both are "
                                       f"{args.web_port}")
        check_free_port(args.web_port, "--web-port")
        check_free_port(args.grpc_port, "--grpc-port")
    elif args.connect:
        url = check_viewer_reachable(args.url)
    # read and fuse before any sink starts, so errors come out before a viewer does
    data = load_view_data(args.sessions, methods=args.methods, start=args.start, end=args.end)
    out = sys.stderr if args.stdout else sys.stdout
    for note in data.notes:
        print(note, file=out)

    import rerun as rr

    rec = new_stream()

    def report(counts: dict[str, int]) -> None:
        print("logged " + ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items()
                                    if v), file=out)

    if args.save:
        with rrd_file(rec, args.save, force=args.force, inputs=args.sessions) as path:
            counts = log_view(rec, data, frames)
        report(counts)
        print(f"wrote {path}; open it with: {installed_command('rerun')} {path}", file=out)
        return 0
    if args.stdout:
        rec.stdout()
    elif args.serve:
        uri = rec.serve_grpc(grpc_port=args.grpc_port)
        try:
            rr.serve_web_viewer(web_port=args.web_port, open_browser=has_display(),
                                connect_to=uri)
        except RuntimeError as exc:  # lost a race for the port since the check
            raise PslogError(f"cannot serve the web viewer on port {args.web_port}: "
                             f"{exc}") from None
    elif args.connect:
        rec.connect_grpc(url)
    else:
        rec.spawn()
    counts = log_view(rec, data, frames)
    try:
        rec.flush(timeout_sec=SEND_TIMEOUT_S)
    except RuntimeError:
        where = f"the viewer at {url}" if args.connect else "the viewer"
        raise PslogError(f"{where} did not take the data within {SEND_TIMEOUT_S:g} s; is "
                         f"it still running?") from None
    report(counts)
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
