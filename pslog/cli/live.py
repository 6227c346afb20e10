"""``pslog live``: per-camera processes stream detections to a live fuser that emits a 3D
point at every shutter (to UDP, JSON lines, the MCAP session, rerun, Foxglove)."""

from __future__ import annotations

import argparse
import re
from typing import Any

from pslog.cli._common import (
    add_force,
    add_rig,
    declare_files,
    motion_name,
    number_at_most,
    run_stoppable,
    usage_error,
)

DESCRIPTION = """\
Fuse live: every --source camera runs in its own process (capture, ball detection) and sends
each frame's detections with its capture time as one UDP datagram to the fuser, which listens
at --listen (so detections may also come from other processes or machines: the datagram
format is in docs/live.md). The fuser runs a causal method and emits every 3D point as soon as
the detection that makes it arrives: as point datagrams to --out, as JSON lines on stdout
(--jsonl; status lines stay on stderr), into an MCAP session (--record), to a live rerun
viewer (--view spawns one, --serve serves the web viewer) or to Foxglove (--foxglove, its
WebSocket server).

Without --source or --synthetic the fuser only listens. --synthetic renders every camera of
the rig watching --motion in real time (frames paced by their capture times on the rig's
shutter schedule, detected like camera frames). A video file source is sent at its frames'
capture times too.

A status line on stderr shows per camera whether it is live or silent; each camera process
says its pid when it starts. A camera process that dies (crashes, is killed, its device
stops delivering) is reported and restarted after a back-off (1 s, doubling up to 30 s); a
source that cannot be opened at all is not retried, and if none can, the run ends with
exit code 1. The other cameras keep fusing, and the camera is fused again once it sends.
The run ends at --duration, when every source has ended, or on Ctrl-C, SIGTERM or SIGHUP
(a closed terminal), which stop the camera processes and finish the session file cleanly
(exit code 0). A SIGKILL loses at most the last half second written (the session file is
flushed every 0.5 s): the file is left unfinished, and 'pslog recover' salvages it. If the
disk fills up, the run stops and what was written is kept; the error says where. With
--force an old session is replaced only by a complete new one, never by an empty one.
"""

EXAMPLES = """\
examples:
  pslog live --rig rig.toml --synthetic --motion rally --duration 5 --jsonl
  pslog live --rig rig.toml --source cam1=0 --source cam2=1 --source cam3=2 \\
      --out udp://127.0.0.1:10010 --record session.mcap
  pslog live --rig rig.toml --listen udp://0.0.0.0:10006 --foxglove
"""

#: default UDP addresses (the fuser's listen address, where detections arrive)
DEFAULT_LISTEN = "udp://127.0.0.1:10006"
_ADDRESS = re.compile(r"^(?:udp://)?(?:\[(?P<v6>[^\]]+)\]|(?P<host>[^:/\[\]]+)):(?P<port>[0-9]+)$")
#: seconds the fuser keeps listening once every camera process has ended, for the last
#: datagrams still on their way
_GRACE_S = 0.5
#: the closing hint for --hold: at least this many frames dropped as reordered, and this
#: share of those received, without --hold; the hold it suggests, seconds
REORDERED_HINT_MIN = 10
REORDERED_HINT_SHARE = 0.05
REORDERED_HINT_HOLD_S = 0.03
#: seconds a stopped run still waits for a --jsonl reader that is not reading (a full pipe)
_STDOUT_GRACE_S = 2.0
#: argparse type of a run's times: positive, and short enough to count in int64 nanoseconds
#: of the wall clock (about 30 years; 1e300 s used to overflow in the fuser's loop)
_LONGEST = number_at_most(1e9, "s", "about 30 years", positive=True)


def udp_address(text: str, lowest_port: int = 1) -> tuple[str, int]:
    """argparse type: ``udp://HOST:PORT`` (or ``HOST:PORT``; ``[::1]:PORT`` for IPv6) ->
    (host, port)."""
    match = _ADDRESS.match(text.strip())
    if match is None:
        raise argparse.ArgumentTypeError(f"not a UDP address udp://HOST:PORT: {text!r}")
    host = match.group("v6") or match.group("host")
    port = int(match.group("port"))
    if not lowest_port <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port must be in {lowest_port}..65535, got {text!r}")
    return host, port


def listen_address(text: str) -> tuple[str, int]:
    """argparse type of ``--listen``: as :func:`udp_address`, port 0 for any free port."""
    return udp_address(text, lowest_port=0)


def streaming_method(text: str) -> str:
    """A fusion method that can run live (a causal one)."""
    from pslog.fusion import METHODS, causal_methods

    if "," in text:
        raise argparse.ArgumentTypeError(
            f"one method, got {text!r} (streaming methods: {', '.join(causal_methods())})")
    if text not in METHODS:
        raise argparse.ArgumentTypeError(
            f"unknown method {text!r} (choose from {', '.join(causal_methods())})")
    if not METHODS[text].causal:
        raise argparse.ArgumentTypeError(
            f"method {text!r} cannot run live (streaming methods: "
            f"{', '.join(causal_methods())})")
    return text


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.rig import TIMING_PRESETS

    from ._common import int_in, port
    from .record import add_detector_arguments

    parser.description = DESCRIPTION
    parser.epilog = EXAMPLES
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    add_rig(parser)
    parser.add_argument("--source", action="append", default=[], metavar="NAME=SPEC",
                        help="camera NAME sends from SPEC: a device index, /dev/videoN, or a "
                             "video file with an optional @OFFSET in seconds (repeat per "
                             "camera; cameras without one may send from elsewhere)")
    parser.add_argument("--synthetic", action="store_true",
                        help="render every camera of the rig in real time instead of "
                             "reading sources")
    parser.add_argument("--motion", default="rally", type=motion_name, metavar="MOTION",
                        help="synthetic ball motion: straight, spiral, fall, turntable, "
                             "throw, rally (default %(default)s)")
    parser.add_argument("--timing", choices=TIMING_PRESETS,
                        help="set the rig's shutter offsets from a preset (default: the "
                             "rig's own offsets)")
    parser.add_argument("--duration", type=_LONGEST, metavar="S",
                        help="stop after S seconds (of session time once cameras run; "
                             "synthetic default: the motion's duration; otherwise until "
                             "the sources end or Ctrl-C)")
    parser.add_argument("--method", default="filter", type=streaming_method, metavar="METHOD",
                        help="causal fusion method: filter or typeA (or another streaming "
                             "method; default %(default)s)")
    parser.add_argument("--hold", type=number_at_most(10.0, "s", "a frame waits for the "
                                                      "others, not for ever"),
                        default=0.0, metavar="S",
                        help="seconds a frame may wait for the other cameras' frames so that "
                             "frames arriving out of order are all fused in capture order "
                             "instead of dropped (default %(default)s: fused at once; try "
                             "0.05 with shutters that fire together, sync or typeB)")
    parser.add_argument("--listen", default=DEFAULT_LISTEN, type=listen_address,
                        metavar="udp://HOST:PORT",
                        help="where the fuser receives detection datagrams; port 0 for any "
                             "free one, said on stderr (default %(default)s)")
    parser.add_argument("--out", type=udp_address, metavar="udp://HOST:PORT",
                        help="send every point as a datagram there (format: docs/live.md)")
    parser.add_argument("--jsonl", action="store_true",
                        help="print every point as one JSON object per line on stdout")
    parser.add_argument("--record", metavar="SESSION.mcap",
                        help="record the session (detections and the emitted points; with "
                             "--synthetic the motion's truth too) there")
    view = parser.add_mutually_exclusive_group()
    view.add_argument("--view", action="store_true",
                      help="show the points live in a rerun viewer (needs a display)")
    view.add_argument("--serve", action="store_true",
                      help="serve a live rerun web viewer (http://localhost:--web-port)")
    view.add_argument("--foxglove", action="store_true",
                      help="publish live to Foxglove through its WebSocket server")
    parser.add_argument("--web-port", type=port, default=9090, metavar="PORT",
                        help="web viewer port with --serve (default %(default)s)")
    parser.add_argument("--grpc-port", type=port, default=9876, metavar="PORT",
                        help="data server port with --serve (default %(default)s)")
    parser.add_argument("--foxglove-port", type=int_in(0, 65535), default=8765,
                        metavar="PORT",
                        help="Foxglove WebSocket server port with --foxglove, 0 for any free "
                             "one, said on stderr (default %(default)s)")
    parser.add_argument("--status-every", type=_LONGEST, default=1.0, metavar="S",
                        help="seconds between status lines on stderr (default %(default)s)")
    add_detector_arguments(parser)
    add_force(parser)
    from .record import video_files

    declare_files(parser, inputs=("rig", video_files), outputs=("record",),
                  sessions=("record",))


def run(args: argparse.Namespace) -> int:
    # SIGINT and SIGTERM only request a stop from here on (finishing the work cleanly)
    return run_stoppable(_run, args)


def _say(text: str) -> None:
    import sys

    print(f"pslog live: {text}", file=sys.stderr, flush=True)


def _run(args: argparse.Namespace, stop) -> int:
    import threading
    import time

    import numpy as np

    from pslog.errors import InputError
    from pslog.live.fuser import warm_up
    from pslog.live.server import bind_udp, serve
    from pslog.outputs import stdout_closed
    from pslog.rig import apply_timing, resolve_rig

    if args.jsonl and stdout_closed():  # closed when Python started (``>&-``)
        raise InputError("--jsonl cannot write to standard output: it is closed")
    rig = resolve_rig(args.rig)
    if args.timing:
        rig = apply_timing(rig, args.timing)
    if args.serve and args.web_port == args.grpc_port:
        return usage_error("live", f"--web-port and --grpc-port must differ, both are "
                                   f"{args.web_port}")
    if len(rig) < 2:
        return usage_error("live", f"live fusion needs at least two cameras; the rig has "
                                   f"{len(rig)}")
    from pslog.live.protocol import MAX_CANDIDATES, MAX_NAME_BYTES

    if args.max_candidates > MAX_CANDIDATES:
        return usage_error("live", f"--max-candidates must be at most {MAX_CANDIDATES} (what "
                                   f"one detection datagram carries), got {args.max_candidates}")
    long = [n for n in rig.names if len(n.encode("utf-8")) > MAX_NAME_BYTES]
    if long:
        raise InputError(f"camera name {long[0]!r} is longer than the {MAX_NAME_BYTES} bytes a "
                         f"live datagram carries; rename it in the rig file")
    specs = _camera_specs(args, rig)
    if isinstance(specs, int):
        return specs  # a usage error, already said
    listen = _udp_text(args.listen)
    options = None
    if specs:
        from recorders.live import SenderOptions

        from .record import parse_hsv

        options = SenderOptions(
            hsv=parse_hsv(args.hsv), max_candidates=args.max_candidates,
            duration_ns=None if args.duration is None else int(args.duration * 1e9))
    # the method's compiled kernels loaded before the session clock's zero is fixed and the
    # cameras start: else their first frames would wait behind the load (docs/live.md, serve)
    warm_up(args.method)  # silent: a failure after it is still one line
    sock = bind_udp(listen)  # a busy port fails here, before any output is opened
    try:
        sinks, recording = _sinks(args, rig, stop, sock.getsockname())
    except BaseException:
        sock.close()
        raise
    bound = (args.listen[0], sock.getsockname()[1])  # the port chosen for port 0
    _say(f"listening for detection datagrams on {_udp_text(bound)}")
    cameras = None
    if specs:
        from recorders.live import LiveCameras

        cameras = LiveCameras(specs, _sender_address(bound), options, say=_say)
    ready = threading.Event()
    epoch_ns = time.time_ns()  # the session clock's zero (wall clock), fuser and cameras
    watcher = None
    if cameras is not None:
        def finished() -> None:
            # every source ended: give the last datagrams a moment, then stop the fuser
            if not stop.event.wait(_GRACE_S):
                stop.set("the end of the sources")

        watcher = threading.Thread(target=cameras.run, args=(stop.event, ready),
                                   kwargs={"when_finished": finished,
                                           "epoch_ns": lambda: epoch_ns},
                                   name="pslog-live-cameras", daemon=True)
        watcher.start()
    from pslog.outputs import WriteError

    try:
        summary = serve(rig, listen, sinks, method=args.method,
                        duration_s=args.duration if cameras is None else None,
                        stop=stop.event, status_every_s=args.status_every, ready=ready,
                        epoch_ns=epoch_ns, sock=sock, hold_s=args.hold,
                        starting=None if cameras is None else cameras.starting)
    except WriteError as exc:
        stop.event.set()
        if watcher is not None:
            watcher.join()
        if recording is None or not _recording_failed(recording, exc):
            raise
        if cameras is not None:
            _say("camera processes:\n" + cameras.summary())
        raise _record_write_error(recording, args.record, exc, cameras is not None) from None
    finally:
        stop.event.set()
        if watcher is not None:
            watcher.join()
    if cameras is not None:
        _say("camera processes:\n" + cameras.summary())
    lat = summary.latency_ns
    if len(lat):
        cpu = getattr(summary, "cpu_ns", np.zeros(0))
        on_cpu = (f"; the fuser's CPU time per datagram median {np.median(cpu) / 1e3:.0f} us"
                  if len(cpu) else "")
        _say(f"{summary.counters.get('points', len(lat))} points; fusion latency (datagram "
             f"arrival to point out) median {np.median(lat) / 1e3:.0f} us, p99 "
             f"{np.percentile(lat, 99) / 1e3:.0f} us{on_cpu}")
    reordered = int(summary.counters.get("reordered", 0))
    received = int(summary.counters.get("received", 0))
    if not args.hold and reordered >= max(REORDERED_HINT_MIN, REORDERED_HINT_SHARE * received):
        # walk41: 4 x 60 fps shutters 3-5 ms apart on a busy machine lost 306 of 656 frames
        # so, with nothing said; --hold 0.03 then lost 12
        _say(f"{reordered} of {received} frames dropped as reordered (each arrived after a "
             f"later frame of another camera had been fused; kept in the recording's "
             f"/live/dropped topics): --hold {REORDERED_HINT_HOLD_S:g} lets each frame wait "
             f"that long for the other cameras' and fuses them in capture order, at that "
             f"cost in latency (docs/live.md)")
    _say_refused(sinks)
    no_camera = cameras is not None and cameras.all_failed
    if recording is not None:
        if recording.empty:
            if not no_camera:
                _say(f"no detection arrived: nothing was recorded to {args.record}")
        else:
            _say(f"recorded {args.record}: {recording.frames} frames, {recording.points} "
                 f"points")
    if no_camera and cameras is not None:
        failed = "; ".join(f"{c.name}: {c.message}" for c in cameras.cameras)
        raise InputError(f"no camera could be opened ({failed})")
    return 0


def _say_refused(sinks) -> None:
    """A note when point datagrams to --out were refused (the system said nothing listened
    there: the robot not started, or gone): counted by the sink, they were said nowhere
    (sweep41: a receiver closed mid-run, the run ended as if every point had reached it).
    A count from below: after the port's refusal each send that finds it closed again is
    refused, the others leave and are lost unseen."""
    from pslog.live.sinks import UdpSink

    for sink in sinks:
        if isinstance(sink, UdpSink) and sink.errors:
            n = sink.sent + sink.errors
            _say(f"note: --out {_udp_text(sink.destination[:2])}: {sink.errors} of {n} "
                 f"point datagram{'s' if n != 1 else ''} refused (nothing listened there at "
                 f"times: the receiver not started, or gone; more may have been lost unseen)")


def _recording_failed(recording, exc: BaseException) -> bool:
    """Whether ``exc`` is the session file's own write error (not another output's)."""
    return exc is getattr(recording, "_error", None) or str(exc).startswith(
        f"cannot write {recording.path}")


def _record_write_error(recording, name: str, exc, cameras: bool):
    """The one line for a session file that could not be written, as ``pslog record`` says
    it: where what was written is kept and how to salvage it."""
    from pslog.outputs import WriteError

    target = recording.writer.target
    kept = (f"what was written before is in {target}, unfinished (salvage it with: pslog "
            f"recover {target} -o fixed.mcap)" if target.exists() else "nothing was kept")
    if target != recording.path:
        kept += f"; the old {name} is untouched"
    stopped = "stopped the fuser and the cameras" if cameras else "stopped the fuser"
    return WriteError(f"cannot write {name}: {exc.reason}; {stopped}; {kept}", exc.reason)


def _camera_specs(args: argparse.Namespace, rig):
    """Camera name -> source spec of the camera processes to start ({} when the fuser only
    listens); an exit code after a usage error."""
    from pslog.errors import InputError

    if args.synthetic:
        if args.source:
            return usage_error("live", "--synthetic renders every camera; do not give --source")
        from pslog.motion import get_motion
        from pslog.simulation import check_duration
        from recorders.live import synthetic_specs

        motion = get_motion(args.motion)
        duration = motion.duration if args.duration is None else args.duration
        try:
            check_duration(rig, duration)
        except InputError as exc:
            return usage_error("live", str(exc))
        return synthetic_specs(rig, motion, duration)
    if not args.source:
        return {}
    from .record import MalformedSource, parse_sources

    try:
        return parse_sources(rig, args.source, [])
    except MalformedSource as exc:
        return usage_error("live", str(exc))


def _sender_address(listen: tuple[str, int]) -> tuple[str, int]:
    """Where the camera processes on this machine send to: the listen address, loopback
    when the fuser listens on every interface."""
    host, port = listen
    if host in ("0.0.0.0", ""):
        return "127.0.0.1", port
    if host == "::":
        return "::1", port
    return host, port


def _udp_text(address: tuple[str, int]) -> str:
    host, port = address
    return f"udp://[{host}]:{port}" if ":" in host else f"udp://{host}:{port}"


def _sinks(args: argparse.Namespace, rig, stop, listening: tuple) -> tuple[list, Any]:
    """The fuser's outputs, in the order points reach them (the robot's UDP first), and the
    recording among them (None without --record). Any that fails to open is one error line,
    and the ones opened before it are closed again (a new session file removed).
    ``listening``: the fuser's own socket address (an --out that reaches it is refused)."""
    from pslog.errors import InputError
    from pslog.live.sinks import UdpSink

    sinks: list = []
    recording: Any = None  # a RecordSink subclass made in _recording
    try:
        if args.out is not None:
            sinks.append(UdpSink(_udp_text(args.out)))
            if _reaches(sinks[-1], listening):
                raise InputError(
                    f"--out {_udp_text(args.out)} is where pslog live listens "
                    f"({_udp_text(args.listen)}): its points would come back to it as "
                    f"foreign datagrams, none to a robot; give the robot's address")
        if args.jsonl:
            sinks.append(_jsonl(args, stop))
        if args.record:
            recording = _recording(args, rig)
            sinks.append(recording)
        methods = (args.method,)
        if args.view or args.serve:
            from viewers.live import RerunLiveSink

            sink = RerunLiveSink("spawn" if args.view else "serve", rig, methods=methods,
                                 web_port=args.web_port, grpc_port=args.grpc_port)
            sinks.append(sink)
            if args.serve:
                _say(f"rerun web viewer at {sink.address}")
        if args.foxglove:
            from viewers.live import FoxgloveSink

            sink = FoxgloveSink(rig, "127.0.0.1", args.foxglove_port, methods=methods)
            sinks.append(sink)
            _say(f"Foxglove WebSocket server at {sink.address}")
    except BaseException:
        for sink in sinks:
            if sink is recording:
                recording.discard()
            else:
                sink.close()
        raise
    return sinks, recording


def _reaches(sink, listening: tuple) -> bool:
    """Whether ``sink``'s datagrams reach the socket bound to ``listening``: the same port,
    sent to an address of this machine (the source address the OS chose for it is the
    destination itself) that the socket takes (its own, or any: a wildcard bind)."""
    host, port = sink.destination[:2]
    if port != listening[1]:
        return False
    try:
        local = sink.sock.getsockname()[0] == host
    except OSError:
        return False
    return local and (listening[0] in ("0.0.0.0", "::") or listening[0] == host)


def _jsonl(args: argparse.Namespace, stop):
    """core's JsonlSink on stdout; when the reader goes away (``| head``) and stdout was the
    only output, the run stops (nothing is left to do)."""
    import sys

    from pslog.live.sinks import JsonlSink

    alone = not (args.out or args.record or args.view or args.serve or args.foxglove)

    import select
    import time

    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (a test's capture)
        fd = None

    class Jsonl(JsonlSink):
        give_up = None  # time.monotonic() after which a stopped run stops waiting

        def emit(self, points) -> None:
            for point in points:
                # a reader that stopped reading (a full pipe) would block the write for
                # ever, and Ctrl-C with it: wait while the run goes on, and for a slow
                # reader at most _STDOUT_GRACE_S more once the run is stopped
                while fd is not None and not self._broken and \
                        not select.select([], [fd], [], 0.1)[1]:
                    if not stop.is_set():
                        continue
                    if self.give_up is None:
                        self.give_up = time.monotonic() + _STDOUT_GRACE_S
                    elif time.monotonic() > self.give_up:
                        self._broken = True
                        _say("standard output is not being read: the last points were not "
                             "printed")
                super().emit([point])
            if self._broken and alone and not stop.is_set():
                stop.set("standard output closed")

    return Jsonl(sys.stdout)


def _synthetic_truth(args: argparse.Namespace, rig):
    """The ball's truth of ``--synthetic``'s motion at every shutter of ``rig`` from the
    motion's time 0 (:func:`recorders.synthetic.synthetic_truth`, as ``pslog record
    --synthetic`` stores it)."""
    from pslog.motion import get_motion
    from recorders.synthetic import synthetic_truth

    motion = get_motion(args.motion)
    return synthetic_truth(rig, motion, motion.duration if args.duration is None
                           else args.duration)


def _recording(args: argparse.Namespace, rig):
    """core's RecordSink that, when nothing at all was recorded, leaves no session behind:
    a new file is removed, an old one (``--force``) kept instead of replaced by an empty one."""
    from pslog.live.sinks import RecordSink
    from pslog.rig import timing_label

    truth = _synthetic_truth(args, rig) if args.synthetic else None

    class Recording(RecordSink):
        empty = False
        _first: tuple[int, int, int] | None = None  # (camera, frame index, session ns)

        def _write_frame(self, d) -> None:
            if self._first is None:
                self._first = (self._index[d.camera], int(d.frame_index),
                               self._session(d.t_capture_ns))
            super()._write_frame(d)

        def _write_truth(self) -> None:
            """The synthetic motion's truth at every shutter, on the session clock: the
            cameras' schedule starts a whole number of seconds after the fuser's clock
            (recorders.live), read off the first frame written (walk41: a live synthetic
            recording held no truth, its accuracy could not be evaluated)."""
            from pslog.records import Truth
            from recorders.sources import synthetic_times

            if truth is None or self._first is None:
                return
            cam, index, t = self._first
            stamps = synthetic_times(rig.cameras[cam], index * 2 / rig.cameras[cam].fps + 1)
            if index >= len(stamps):
                return
            shift = t - int(stamps[index])
            self.writer.add_truth(Truth(truth.time_ns + shift, truth.position_world))

        def close(self) -> None:
            if self.frames == 0 and self.dropped_frames == 0:
                self.empty = True
                self.abort()
            else:
                if self._error is None:
                    self._jobs.put((self._write_truth,))
                super().close()

        def discard(self) -> None:
            self.abort()

    return Recording(args.record, rig, args.method, force=args.force, timing=timing_label(rig),
                     source="live " + " ".join(["--synthetic"] if args.synthetic
                                               else args.source))
