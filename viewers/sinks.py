"""Where a rerun recording goes live: a spawned viewer window, a served web viewer, a viewer
already running elsewhere (gRPC), or standard output.

rerun reports most failures of these sinks as a Rust log line, a traceback or a hang (a busy
port, a viewer that is not there: it retries for ever; a program on the port that is not a
viewer: the process hangs at exit). :func:`open_sink` checks all of that first and raises one
:class:`~pslog.errors.InputError` in words; :meth:`Sink.finish` bounds the wait for a viewer to
take the data. With :func:`viewers.rrd_file.rrd_file` for files this is every sink of
``pslog view``; the command keeps only its argument parsing and error mapping::

    sink = open_sink("connect", url="rerun+http://127.0.0.1:9876/proxy")  # checks
    rec = new_stream()
    sink.start(rec)
    log_view(rec, data, frames)
    sink.finish(rec)  # PslogError if the viewer does not take the data in time
"""

from __future__ import annotations

import argparse
import errno
import os
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING
from urllib.parse import quote, urlsplit

from pslog.errors import InputError, PslogError

if TYPE_CHECKING:
    import rerun as rr

#: seconds to wait for a rerun viewer to accept a connection (connect)
CONNECT_TIMEOUT_S = 3.0
#: longest wait for a live viewer to take the logged data, seconds (only a hang reaches it)
SEND_TIMEOUT_S = 60.0
#: where rerun's own viewer listens by default
DEFAULT_GRPC_URL = "rerun+http://127.0.0.1:9876/proxy"
#: the kinds of live sink
KINDS = ("spawn", "serve", "connect", "stdout")
#: the HTTP/2 client connection preface and an empty SETTINGS frame (RFC 9113, 3.4)
_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])

#: rerun's standard flags (``rr.script_add_args``: dest, action, type, default) in our
#: wording (metavar and help in the style of pslog's options). Built here without importing
#: rerun (over a CPU second per ``pslog view`` process, ``--help`` and usage errors included);
#: tests/test_view_flags.py checks them against rerun's own
_RERUN_FLAGS: dict[str, tuple[str, type | None, str | None, str]] = {
    # dest: (action, type, metavar, help); every value flag defaults to None, every switch
    # to False
    "headless": ("store_true", None, None, "do not open a viewer window"),
    "connect": ("store_true", None, None,
                "send to a rerun viewer already running (at --url)"),
    "serve": ("store_true", None, None,
              "serve a web viewer at http://localhost:PORT (--web-port) until Ctrl-C"),
    "url": ("store", str, "URL",
            "rerun viewer to send to with --connect (default: rerun's local viewer)"),
    "save": ("store", str, "OUT.rrd",
             "write a rerun recording to this file (open it with 'rerun OUT.rrd')"),
    "stdout": ("store_true", None, None,
               "write the recording to standard output, to pipe into 'rerun -'"),
}


def add_sink_arguments(parser: argparse.ArgumentParser) -> None:
    """rerun's standard flags (``--headless``, ``--connect``, ``--serve``, ``--url``,
    ``--save``, ``--stdout``) in pslog's wording."""
    for dest, (action, kind, metavar, text) in _RERUN_FLAGS.items():
        if action == "store_true":
            parser.add_argument(f"--{dest}", dest=dest, action=action, help=text)
        else:
            parser.add_argument(f"--{dest}", dest=dest, type=kind, default=None,
                                metavar=metavar, help=text)


def has_display() -> bool:
    """Whether a native viewer window can open (on Linux: an X11 or Wayland display)."""
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def check_free_port(number: int, option: str) -> None:
    """Refuse a port the servers of ``serve`` could not listen on (rerun would print a Rust
    error log and a traceback, or serve nothing): in use, or privileged. ``option`` names the
    setting in the message (``--web-port``)."""
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


def check_url(url: str) -> tuple[str, int]:
    """``(host, port)`` of a gRPC viewer URL such as :data:`DEFAULT_GRPC_URL`.

    Raises
    ------
    InputError : the URL has no host or port (a malformed command-line value)
    """
    try:
        parts = urlsplit(url.removeprefix("rerun+"))
        host, number = parts.hostname, parts.port
    except ValueError:
        host = number = None
    if not host or not number:
        raise InputError(f"--url must look like {DEFAULT_GRPC_URL}, got {url!r}")
    return host, number


def check_viewer_reachable(url: str | None, timeout_s: float = CONNECT_TIMEOUT_S) -> str:
    """The gRPC URL to connect to (default :data:`DEFAULT_GRPC_URL`) if a rerun viewer
    accepts connections there within ``timeout_s`` seconds; rerun itself would retry silently
    for ever."""
    url = url or DEFAULT_GRPC_URL
    host, number = check_url(url)
    try:
        with socket.create_connection((host, number), timeout=timeout_s) as sock:
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
                             f"({reason} within {timeout_s:g} s); check --url") from None
        raise InputError(f"no rerun viewer at {url} ({reason}); start one with 'rerun' "
                         f"(it listens on port 9876), or use --save out.rrd or --serve"
                         ) from None
    if len(answer) < 9 or answer[3] != 4:
        raise InputError(f"the program at {url} does not answer as a rerun viewer (no gRPC "
                         f"handshake); check --url")
    return url


@dataclass
class Sink:
    """A checked live sink (see :func:`open_sink`); ``uri`` is the gRPC address of the data
    once a ``serve`` sink started."""

    kind: str
    web_port: int = 9090
    grpc_port: int = 9876
    url: str | None = None
    uri: str | None = None

    def start(self, rec: rr.RecordingStream) -> None:
        """Send ``rec`` here from now on (a ``spawn`` sink opens the viewer window)."""
        if self.kind == "stdout":
            rec.stdout()
        elif self.kind == "serve":
            import rerun as rr

            self.uri = rec.serve_grpc(grpc_port=self.grpc_port)
            try:
                rr.serve_web_viewer(web_port=self.web_port, open_browser=has_display(),
                                    connect_to=self.uri)
            except RuntimeError as exc:  # lost a race for the port since the check
                raise PslogError(f"cannot serve the web viewer on port {self.web_port}: "
                                 f"{exc}") from None
        elif self.kind == "connect":
            rec.connect_grpc(self.url)
        else:
            rec.spawn()

    def finish(self, rec: rr.RecordingStream, timeout_s: float = SEND_TIMEOUT_S) -> None:
        """Wait until the viewer took everything logged to ``rec``, at most ``timeout_s``."""
        try:
            rec.flush(timeout_sec=timeout_s)
        except RuntimeError:
            where = f"the viewer at {self.url}" if self.kind == "connect" else "the viewer"
            raise PslogError(f"{where} did not take the data within {timeout_s:g} s; is it "
                             f"still running?") from None

    @property
    def web_address(self) -> str:
        """The address to browse a ``serve`` sink at."""
        return f"http://localhost:{self.web_port}/?url={quote(self.uri or '')}"

    def serve_until_interrupted(self, rec: rr.RecordingStream,
                                announce: Callable[[], None] | None = None) -> None:
        """Keep a ``serve`` sink up until Ctrl-C (then end the stream and return: the
        serving's normal end), or until SIGTERM or SIGHUP, raised on as the command's
        ``Terminated`` (a KeyboardInterrupt subclass: its one line, exit 143 or 129).
        (Not ``rr.script_teardown``: it took either for a Ctrl-C, printed "Ctrl-C received.
        Exiting." on stdout and returned, exit 0.) ``announce`` is called first, inside the
        wait: a Ctrl-C just after it still ends the serving normally."""
        try:
            if announce is not None:
                announce()
            while True:
                time.sleep(1)
        except KeyboardInterrupt as exc:
            if type(exc) is not KeyboardInterrupt:  # SIGTERM or SIGHUP
                raise
        finally:
            rec.disconnect()


def open_sink(kind: str, *, web_port: int = 9090, grpc_port: int = 9876,
              url: str | None = None, connect_timeout_s: float = CONNECT_TIMEOUT_S) -> Sink:
    """A live sink of ``kind`` (:data:`KINDS`), checked before anything is logged: for
    ``serve`` both ports free and distinct, for ``connect`` a viewer answering at ``url``
    within ``connect_timeout_s`` seconds.

    Raises
    ------
    InputError : the ports or the viewer are not usable; the message says why
    """
    if kind not in KINDS:
        raise InputError(f"unknown sink {kind!r} (choose from {', '.join(KINDS)})")
    if kind == "serve":
        if web_port == grpc_port:
            raise InputError(f"--web-port and --grpc-port must differ, both are {web_port}")
        check_free_port(web_port, "--web-port")
        check_free_port(grpc_port, "--grpc-port")
    elif kind == "connect":
        url = check_viewer_reachable(url, connect_timeout_s)
    return Sink(kind, web_port, grpc_port, url)
