"""Live viewers of ``pslog live``: each fused point as it leaves the fuser, shown in rerun
(:class:`RerunLiveSink`, ``--view`` / ``--serve``) and in Foxglove (:class:`FoxgloveSink`,
``--foxglove``).

Both are sinks of :func:`pslog.live.server.serve` (``start``, ``emit``, ``detections``,
``dropped``, ``status``, ``event``, ``close``) and neither ever delays the fuser: each call
only puts the item in a bounded queue (about a microsecond) and returns; one background thread
per viewer does the logging. When a slow or absent viewer lets the queue fill up, new items
are dropped and counted (``counters()``: ``dropped_points``, ``dropped_detections``), never
waited for. A viewer that fails (its window closed...) prints one warning line and is skipped
from then on; the run goes on. Times are on the session clock (the wall clock minus the
fuser's ``epoch_ns``, given by ``start``), as in the recorded session, so the live view and
the later view of the recording line up.

What the rerun view shows (the recorded view's entity paths, colours and layout, see
:mod:`viewers.recording`; timeline ``capture_time``, the session clock, and ``frame``):

- the rig: each camera's pose and pinhole (``world/cameras/<cam>``, its image plane);
- each camera's detections as they arrive, on its image plane
  (``world/cameras/<cam>/image/detections``) and as viewing rays to the floor
  (``world/rays/<cam>``), and the ball's detection rate of the last second
  (``plots/detection_rate``: the frames with a candidate off every static spot);
- each fused point in its method's colour with a trail of the last half second
  (``world/tracks/<method>``, ``.../trail``), a translucent sphere of radius 2σ when the point
  has a covariance (``.../uncertainty``), the state predicted to the emit time (``.../predicted``
  and its velocity arrow over 0.1 s), and time series of the position std (mm), the
  reprojection residual (px) and the fusion latency (ms, datagram arrival to point out);
- the fuser's status line (cameras live / silent, counters) in the legend panel, and its
  events (a camera silent or back, the final counters) as a text log (``events``).

Foxglove: ``pslog live ... --foxglove`` serves the Foxglove WebSocket protocol on
``ws://127.0.0.1:8765`` (``--foxglove-port`` / host as the command says). Open it in the
Foxglove app: *Open connection* -> *Foxglove WebSocket* -> ``ws://HOST:8765``. The topics and
protobuf schemas are those of a recorded session file (docs/log-format.md), so a layout made
for a recording shows the live run too: ``/camera/<cam>/calibration`` and ``/transform``
(re-sent every second, so a client that connects late still gets them),
``/camera/<cam>/detections`` (``pslog.DetectionFrame``), ``/tracks/<method>``
(``pslog.TrackPoint``, the method's quality columns as recorded) and
``/tracks/<method>/scene`` (a ``foxglove.SceneUpdate`` sphere per point, for the 3D panel),
``/events`` (``foxglove.Log``) and ``/live/dropped/<reason>/<cam>`` (frames the fuser did not
fuse, as recorded). A fused frame's detections and a track point are byte for byte the
messages the recording (``--record``) stores, with the same log times. The fuser's status line
is a server status message (Foxglove's problems panel).
"""

from __future__ import annotations

import collections
import queue
import socket
import sys
import threading
from collections.abc import Sequence

import numpy as np
import rerun as rr

from pslog.errors import InputError
from pslog.live.sinks import dropped_topic
from pslog.log import _schemas as S
from pslog.log.writer import camera_messages, scene_point, track_color
from pslog.motion import BALL_RADIUS
from pslog.palette import color_name
from pslog.records import NS
from pslog.rig import Rig

from . import _columns as C
from ._columns import image_path
from .blueprint import build_blueprint, default_eye
from .recording import log_rig, new_stream
from .sinks import has_display, open_sink

#: items (a batch of points, a detection datagram, a status line) that may wait for a viewer;
#: beyond this the viewer is too slow and new items are dropped (counted)
QUEUE_ITEMS = 4096
#: longest wait at close for a viewer's thread to log what is queued, seconds
CLOSE_TIMEOUT_S = 10.0
#: the Foxglove default port (its app connects there by default)
FOXGLOVE_PORT = 8765
#: how often the Foxglove sink re-sends the cameras' calibration and pose, seconds
STATIC_EVERY_S = 1.0
#: plots of the live view: name -> (quantity, scale) as in :data:`viewers.blueprint.QUALITY_PLOTS`
LIVE_PLOTS = {"std_mm": ("std_m", 1e3), "residual_px": ("residual_px", 1.0),
              "latency_ms": ("latency_s", 1e3)}
_TRAIL_GAP_NS = int(0.1 * NS)  # no trail segment across a gap longer than this
_RAY_FALLBACK_M = 5.0  # rays that do not reach the floor are drawn this long
_VELOCITY_ARROW_S = 0.1  # the predicted velocity is drawn as the move over this time
_END = object()  # the queue's end marker
#: the live detection rate leaves out a candidate that stays within this many pixels of
#: candidates of most of the camera's last frames (pslog info's static spots: a second orange
#: object in view): the window, seconds; the spot's reach, px (1.5 of info's 4 px cells)
STATIC_WINDOW_S = 2.0
STATIC_REACH_PX = 6.0


def moving_candidate(uv: np.ndarray, recent: Sequence[np.ndarray]) -> bool:
    """True when a frame's candidates ``uv`` (k, 2), distorted pixels, hold one off every
    static spot of the camera's ``recent`` frames (each (k_i, 2), this frame's among them):
    a candidate is static when candidates of at least ``pslog.log.info.STATIC_SHARE`` of
    those frames, and ``STATIC_MIN_FRAMES`` of them, lie within :data:`STATIC_REACH_PX` of
    it — the live form of :func:`pslog.log.info.moving_frames` (a ball at rest is static
    too). A candidate without a pixel (not finite) counts as moving, as there."""
    from pslog.log.info import STATIC_MIN_FRAMES, STATIC_SHARE

    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    if not len(uv):
        return False
    need = max(STATIC_MIN_FRAMES, STATIC_SHARE * len(recent))
    if len(recent) < need:
        return True
    frames = [np.asarray(f, dtype=np.float64).reshape(-1, 2) for f in recent]
    other = np.concatenate(frames)
    frame = np.repeat(np.arange(len(frames)), [len(f) for f in frames])  # (m,), ascending
    close = np.hypot(*(uv[:, None, :] - other[None, :, :]).transpose(2, 0, 1)) <= STATIC_REACH_PX
    for row in close:  # (one row per candidate of the frame: a few)
        near = frame[row]  # the frames with a candidate near it, ascending, repeats adjacent
        if np.count_nonzero(np.diff(near, prepend=-1)) < need:
            return True
    return False


def _finite(values) -> np.ndarray | None:
    """``values`` as a float64 array if every entry is finite, else None."""
    array = np.asarray(values, dtype=np.float64)
    return array if array.size and np.all(np.isfinite(array)) else None


def std_m(cov_world) -> float:
    """Position standard deviation, metres: sqrt of the covariance's trace (as ``std_m`` of
    a track's quality); NaN when the point has no covariance."""
    cov = _finite(cov_world)
    if cov is None or cov.shape != (3, 3):
        return float("nan")
    return float(np.sqrt(max(np.trace(cov), 0.0)))


class _QueuedSink:
    """The :class:`pslog.live.Sink` calls queue their work for one background thread and
    return at once; subclasses say what is done with each item (``_points``, ``_detections``,
    ``_status``), what runs when the queue is idle (``_idle``) and at the end (``_finish``)."""

    #: the viewer's name in messages
    NAME = "viewer"
    #: how often ``_idle`` runs while nothing arrives, seconds (None: never)
    IDLE_EVERY_S: float | None = None

    def __init__(self, queue_items: int) -> None:
        self._queue: queue.Queue = queue.Queue(maxsize=max(1, int(queue_items)))
        self._counts = {"points": 0, "detections": 0, "dropped_points": 0,
                        "dropped_detections": 0}
        #: why the viewer stopped showing data (a one-line message), or None
        self.error: str | None = None
        self._closed = False
        #: the session clock's zero on the wall clock (the fuser's, from :meth:`start`): the
        #: viewers show session times, as the recorded session does; 0 until started
        self.epoch_ns = 0
        self._thread = threading.Thread(target=self._run, daemon=True,
                                        name=f"pslog-live-{self.NAME}")

    # ---- the Sink interface (called from the fuser's thread) ----------------------------
    def start(self, fuser) -> None:
        """Take the fuser's session clock (its ``epoch_ns``) before the first datagram."""
        self.epoch_ns = int(fuser.epoch_ns)

    def emit(self, points) -> None:
        """Queue ``points`` (a list of :class:`pslog.live.LivePoint`) for the viewer."""
        if points:
            self._offer(("points", list(points)), "dropped_points", len(points))

    def detections(self, datagram) -> None:
        """Queue one accepted detection datagram (:class:`pslog.live.DetectionDatagram`)."""
        self._offer(("detections", datagram), "dropped_detections", 1)

    def dropped(self, datagram, reason: str) -> None:
        """Queue a valid datagram the fuser did not fuse (``duplicate``, ``late``...)."""
        self._offer(("dropped", datagram, str(reason)), "dropped_detections", 1)

    def status(self, text: str, counters: dict) -> None:
        """Queue the fuser's status line (dropped, not counted, when the queue is full)."""
        self._offer(("status", str(text), dict(counters)), None, 0)

    def event(self, time_ns: int, text: str) -> None:
        """Queue a change worth keeping (a camera silent or back), ``time_ns`` wall clock."""
        self._offer(("event", int(time_ns), str(text)), None, 0)

    def close(self) -> None:
        """Log what is queued (at most :data:`CLOSE_TIMEOUT_S`), then end the viewer's stream.
        Idempotent; never raises for a viewer that failed (see :attr:`error`)."""
        if self._closed:
            return
        self._closed = True
        if self._thread.is_alive():
            try:  # the thread is draining the queue: room comes soon, unless it hangs
                self._queue.put(_END, timeout=CLOSE_TIMEOUT_S)
            except queue.Full:
                pass
            self._thread.join(CLOSE_TIMEOUT_S)
        try:
            self._finish()
        except Exception as exc:  # a viewer must not fail the run it watches
            self._fail(exc)

    def counters(self) -> dict[str, int]:
        """Points and detection frames shown, and those dropped because the viewer lagged
        (or failed)."""
        return dict(self._counts)

    # ---- internals ------------------------------------------------------------------------
    def _offer(self, item, dropped: str | None, n: int) -> None:
        if self._closed or self.error is not None:
            if dropped:
                self._counts[dropped] += n
            return
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            if dropped:
                self._counts[dropped] += n

    def _run(self) -> None:
        while True:
            try:
                item = self._queue.get(timeout=self.IDLE_EVERY_S)
            except queue.Empty:
                item = None
            if item is _END:
                return
            if self.error is not None:
                self._count_dropped(item)
                continue
            try:
                if item is None:
                    self._idle()
                elif item[0] == "points":
                    for p in item[1]:
                        self._point(p)
                        self._counts["points"] += 1
                    self._after_points()
                elif item[0] == "detections":
                    if self._detections(item[1]):
                        self._counts["detections"] += 1
                elif item[0] == "dropped":
                    self._dropped(item[1], item[2])
                elif item[0] == "event":
                    self._event(item[1], item[2])
                else:
                    self._status(item[1], item[2])
            except Exception as exc:
                self._fail(exc)
                self._count_dropped(item)

    def _count_dropped(self, item) -> None:
        if item is not None and item[0] == "points":
            self._counts["dropped_points"] += len(item[1])
        elif item is not None and item[0] in ("detections", "dropped"):
            self._counts["dropped_detections"] += 1

    def _fail(self, exc: BaseException) -> None:
        if self.error is None:
            self.error = f"the {self.NAME} stopped showing data: {exc}".splitlines()[0]
            print(f"pslog: warning: {self.error}", file=sys.stderr, flush=True)

    def _idle(self) -> None: ...

    def _after_points(self) -> None: ...

    def _point(self, p) -> None:
        raise NotImplementedError

    def _detections(self, d) -> bool:
        raise NotImplementedError

    def _dropped(self, d, reason: str) -> None: ...

    def _status(self, text: str, counters: dict) -> None: ...

    def _event(self, time_ns: int, text: str) -> None: ...

    def _finish(self) -> None: ...


# ---- rerun ---------------------------------------------------------------------------------
def look_target(rig: Rig) -> np.ndarray | None:
    """The world point nearest to every camera's optical axis (least squares), metres: where
    the cameras look, to aim the 3D view at before any point arrives; None if the axes are
    (nearly) parallel."""
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for cam in rig.cameras:
        axis = cam.world_from_cam[:3, 2]
        away = np.eye(3) - np.outer(axis, axis)  # projects onto the plane normal to the axis
        a += away
        b += away @ cam.center_world
    if np.linalg.cond(a) > 1e6:
        return None
    return np.linalg.solve(a, b)


class RerunLiveSink(_QueuedSink):
    """A live rerun view of the fuser's points and the cameras' detections.

    Parameters
    ----------
    kind : where the stream goes, as :func:`viewers.sinks.open_sink`: ``spawn`` (a viewer
        window, ``--view``), ``serve`` (a web viewer at ``http://localhost:WEB_PORT`` and a gRPC
        server at ``GRPC_PORT``, ``--serve``), ``connect`` (a viewer already running at ``url``)
        or ``stdout``; checked before anything is logged
    rig : the cameras (their poses, intrinsics and names: datagrams name their camera)
    methods : the fusion methods whose points will come (their colours and trails are set up
        front; a point of another method is shown too)
    web_port, grpc_port, url : as :func:`viewers.sinks.open_sink`
    recording : log into this stream (its sink already set) instead of opening ``kind``
    queue_items : items that may wait for the viewer before new ones are dropped

    Raises
    ------
    InputError : a port in use, no viewer at ``url``... (one line naming it)
    """

    NAME = "rerun viewer"

    def __init__(self, kind: str | None, rig: Rig, *, methods: Sequence[str] = ("filter",),
                 web_port: int = 9090, grpc_port: int = 9876, url: str | None = None,
                 recording: rr.RecordingStream | None = None,
                 queue_items: int = QUEUE_ITEMS) -> None:
        super().__init__(queue_items)
        self.rig = rig
        self._index = {name: i for i, name in enumerate(rig.names)}
        self._methods: list[str] = []
        self._colors: dict[str, tuple[int, int, int]] = {}
        self._last: dict[str, tuple[int, np.ndarray]] = {}  # method -> latest (time, point)
        self._frame: dict[str, int] = {}  # camera -> latest frame index
        self._hits = [collections.deque(maxlen=max(1, round(cam.fps))) for cam in rig.cameras]
        # each camera's last frames' candidates, for the static spots the rate leaves out
        self._recent = [collections.deque(maxlen=max(1, round(STATIC_WINDOW_S * cam.fps)))
                        for cam in rig.cameras]
        self._clock: C.Clock | None = None
        self._legend = ""
        if recording is None:
            if (kind or "spawn") == "spawn" and not has_display():
                raise InputError("no display (DISPLAY/WAYLAND_DISPLAY unset), so no rerun "
                                 "viewer window can open; use --serve to browse from a web "
                                 "browser, or --foxglove")
            self.sink = open_sink(kind or "spawn", web_port=web_port, grpc_port=grpc_port,
                                  url=url)
            self.rec = new_stream()
            self.sink.start(self.rec)
        else:
            self.sink = None
            self.rec = recording
        self._log_static(list(dict.fromkeys(methods)))
        self._thread.start()

    @property
    def address(self) -> str | None:
        """Where to watch: the web viewer's address (``serve``) or the viewer's URL."""
        if self.sink is None:
            return None
        return self.sink.web_address if self.sink.kind == "serve" else self.sink.url

    # ---- static --------------------------------------------------------------------------
    def _log_static(self, methods: list[str]) -> None:
        rec, rig = self.rec, self.rig
        rec.send_recording_name("pslog live")
        centers = np.array([c.center_world for c in rig.cameras])
        target = look_target(rig)
        rec.send_blueprint(build_blueprint(
            rig.names, methods, has_truth=False, quality=LIVE_PLOTS,
            eye=default_eye(centers, target[None, :] if target is not None
                            else np.zeros((0, 3))), recorded=False))
        log_rig(rec, rig, rejected=False)
        for c, cam in enumerate(rig.cameras):
            rec.log(f"plots/detection_rate/{cam.name}",
                    rr.SeriesLines(colors=[C.camera_color(c)], names=[cam.name]), static=True)
        for method in methods:
            self._method_color(method)
        self._show_legend("waiting for the first detections")

    def _method_color(self, method: str) -> tuple[int, int, int]:
        """The method's colour (as in the recorded view); its entities' styles are logged the
        first time it is seen."""
        color = self._colors.get(method)
        if color is not None:
            return color
        self._methods.append(method)
        self._colors = C.method_colors(self._methods)
        color = self._colors[method]
        rec, base = self.rec, f"world/tracks/{method}"
        rec.log(base, rr.Points3D.from_fields(colors=[color], radii=[BALL_RADIUS]), static=True)
        rec.log(f"{base}/trail", rr.LineStrips3D.from_fields(colors=[color], radii=[-2.5]),
                static=True)
        rec.log(f"{base}/uncertainty", rr.Points3D.from_fields(colors=[(*color, 48)]),
                static=True)
        # the method's own colour, smaller (a lighter tint would look like a camera's colour,
        # and translucency renders dark in the web viewer)
        light = color
        rec.log(f"{base}/predicted", rr.Points3D.from_fields(
            colors=[light], radii=[0.6 * BALL_RADIUS]), static=True)
        rec.log(f"{base}/predicted/velocity", rr.Arrows3D.from_fields(
            colors=[light], radii=[-1.5]), static=True)
        for plot in LIVE_PLOTS:
            rec.log(f"plots/{plot}/{method}", rr.SeriesLines(colors=[color], names=[method]),
                    static=True)
        return color

    def _show_legend(self, status: str) -> None:
        tracks = ", ".join(f"{m} {color_name(c)}" for m, c in self._colors.items())
        cameras = ", ".join(f"{n} {color_name(C.camera_color(c))}"
                            for c, n in enumerate(self.rig.names))
        self.rec.log("legend", rr.TextDocument(
            f"**Live** — {status}\n\n**Tracks**: {tracks or 'none yet'}; small: the state "
            f"predicted to the emit time, arrow: its velocity over {_VELOCITY_ARROW_S:g} s\n\n"
            f"**Cameras** (rays, detections): {cameras}", media_type="text/markdown"),
            static=True)

    # ---- per item ------------------------------------------------------------------------
    def _at(self, time_ns: int, frame: int | None) -> None:
        """Set the timelines for a wall-clock time: ``capture_time`` is the session clock."""
        time_ns = int(time_ns) - self.epoch_ns
        if self._clock is None:
            self._clock = C.Clock(int(time_ns))
        if self._clock.wall:
            self.rec.set_time(C.CAPTURE_TIME, timestamp=np.datetime64(int(time_ns), "ns"))
        else:
            self.rec.set_time(C.CAPTURE_TIME, duration=np.timedelta64(int(time_ns), "ns"))
        if frame is not None:
            self.rec.set_time(C.FRAME, sequence=int(frame))

    def _point(self, p) -> None:
        rec, method = self.rec, str(p.method)
        self._method_color(method)
        position = _finite(p.position_world)
        if position is None:
            return
        t = int(p.t_capture_ns)
        self._at(t, self._frame.get(p.camera))
        base = f"world/tracks/{method}"
        rec.log(base, rr.Points3D.from_fields(positions=[position]))
        last = self._last.get(method)
        if last is not None and 0 <= t - last[0] <= _TRAIL_GAP_NS:
            rec.log(f"{base}/trail", rr.LineStrips3D.from_fields(strips=[[last[1], position]]))
        self._last[method] = (t, position)
        std = std_m(p.cov_world)
        if not np.isfinite(std):  # a method without covariance may still give its std
            std = float((getattr(p, "quality", None) or {}).get("std_m", np.nan))
        if np.isfinite(std):  # 2σ, capped at 1 m so a wild one hides nothing
            rec.log(f"{base}/uncertainty", rr.Points3D.from_fields(
                positions=[position], radii=[min(2.0 * std, 1.0)]))
            rec.log(f"plots/std_mm/{method}", rr.Scalars(1e3 * std))
        predicted = _finite(p.predicted_position)
        if predicted is not None:
            rec.log(f"{base}/predicted", rr.Points3D.from_fields(positions=[predicted]))
            velocity = _finite(p.predicted_velocity)
            if velocity is not None:
                rec.log(f"{base}/predicted/velocity", rr.Arrows3D.from_fields(
                    origins=[predicted], vectors=[_VELOCITY_ARROW_S * velocity]))
        if np.isfinite(p.residual_px):
            rec.log(f"plots/residual_px/{method}", rr.Scalars(float(p.residual_px)))
        # fusion latency: the producing datagram's arrival to the point made (the fuser's
        # monotonic clock: a held frame's across a wall-clock step too)
        rec.log(f"plots/latency_ms/{method}", rr.Scalars(1e3 * p.latency_s))

    def _detections(self, d) -> bool:
        c = self._index.get(d.camera)
        if c is None:  # the fuser refuses unknown cameras; nothing to draw it in anyway
            return False
        cam = self.rig.cameras[c]
        self._frame[d.camera] = int(d.frame_index)
        self._at(int(d.t_capture_ns), int(d.frame_index))
        uv = np.asarray(d.uv, dtype=np.float64).reshape(-1, 2)
        # an empty frame is logged too: it clears the previous frame's points
        self.rec.log(f"{image_path(cam.name)}/detections",
                     rr.Points2D.from_fields(positions=C.image_space(uv)))
        origin, direction = cam.rays(uv) if len(uv) else (cam.center_world, np.zeros((0, 3)))
        with np.errstate(divide="ignore", invalid="ignore"):
            k = -origin[2] / direction[:, 2]
        k = np.where(np.isfinite(k) & (k > 0), k, _RAY_FALLBACK_M)
        strips = np.stack([np.broadcast_to(origin, direction.shape),
                           origin + k[:, None] * direction], axis=1).astype(np.float32)
        strips = strips[np.all(np.isfinite(strips), axis=(1, 2))]
        self.rec.log(f"world/rays/{cam.name}", rr.LineStrips3D.from_fields(strips=strips))
        # the frames the ball was detected in: a candidate off every static spot (a second
        # orange object in view, a candidate in every frame, does not read 100 %)
        self._recent[c].append(uv)
        hits = self._hits[c]
        hits.append(moving_candidate(uv, self._recent[c]))
        self.rec.log(f"plots/detection_rate/{cam.name}",
                     rr.Scalars(100.0 * sum(hits) / len(hits)))
        return True

    def _status(self, text: str, counters: dict) -> None:
        self._show_legend(text)

    def _event(self, time_ns: int, text: str) -> None:
        self._at(time_ns, None)
        self.rec.log("events", rr.TextLog(text))

    def _finish(self) -> None:
        try:
            if self.sink is not None:
                self.sink.finish(self.rec, CLOSE_TIMEOUT_S)
            else:
                self.rec.flush(timeout_sec=CLOSE_TIMEOUT_S)
        finally:
            if self.sink is not None:
                self.rec.disconnect()


# ---- Foxglove ------------------------------------------------------------------------------
def _schema(message_class):
    import foxglove

    return foxglove.Schema(name=message_class.DESCRIPTOR.full_name, encoding=S.PROTOBUF,
                           data=S.file_descriptor_set(message_class))


class FoxgloveSink(_QueuedSink):
    """A Foxglove WebSocket server publishing the live session with the topics and protobuf
    schemas of a recorded session file (see the module's docstring).

    Parameters
    ----------
    rig : the cameras
    host, port : where the WebSocket server listens (port 0: any free port, see :attr:`port`)
    methods : fusion methods whose track topics are advertised up front (another method's
        topics appear with its first point)
    queue_items : items that may wait before new ones are dropped

    Raises
    ------
    InputError : the server cannot listen there (port in use, unknown host), one line
    """

    NAME = "Foxglove server"
    IDLE_EVERY_S = STATIC_EVERY_S

    def __init__(self, rig: Rig, host: str = "127.0.0.1", port: int = FOXGLOVE_PORT, *,
                 methods: Sequence[str] = ("filter",),
                 queue_items: int = QUEUE_ITEMS) -> None:
        import foxglove

        super().__init__(queue_items)
        self.rig = rig
        self._names = set(rig.names)
        self._context = foxglove.Context()
        try:
            self.server = foxglove.start_server(name="pslog live", host=host, port=int(port),
                                                context=self._context)
        except RuntimeError as exc:
            reason = str(exc).removeprefix("FoxgloveError: ")
            if "in use" in reason:
                raise InputError(f"cannot serve Foxglove on {host}:{port}: the port is in use "
                                 f"by another program; choose another with --foxglove-port"
                                 ) from None
            raise InputError(f"cannot serve Foxglove on {host}:{port}: {reason}") from None
        #: the port the server listens on
        self.port = self.server.port
        self.host = host
        self._channels: dict[str, object] = {}
        self._track_methods: list[str] = []
        self._track_index: dict[str, int] = {}  # method -> points published (scene ids)
        self._latest_ns = 0
        self._last_static = 0.0
        try:
            for cam in rig.cameras:
                for topic, msg in camera_messages(cam, 0):
                    self._channel(topic, type(msg))
                self._channel(S.detections_topic(cam.name), S.DetectionFrame)
            for method in dict.fromkeys(methods):
                self._track_channels(method)
            self._channel(S.EVENTS_TOPIC, S.Log)
            self._publish_static()
        except BaseException:
            self.server.stop()
            raise
        self._thread.start()

    @property
    def address(self) -> str:
        """The WebSocket URL to open in Foxglove."""
        return f"ws://{self.host}:{self.port}"

    def _channel(self, topic: str, message_class):
        import foxglove

        channel = self._channels.get(topic)
        if channel is None:
            channel = self._channels[topic] = foxglove.Channel(
                topic, schema=_schema(message_class), message_encoding=S.PROTOBUF,
                context=self._context)
        return channel

    def _track_channels(self, method: str):
        if method not in self._track_index:
            self._track_methods.append(method)
            self._track_index[method] = 0
        return (self._channel(S.track_topic(method), S.TrackPoint),
                self._channel(S.track_scene_topic(method), S.SceneUpdate))

    def _publish_static(self) -> None:
        """The cameras' calibration and pose, stamped with the latest time seen (so the 3D
        panel finds the transforms of the data it shows)."""
        import time

        for cam in self.rig.cameras:
            for topic, msg in camera_messages(cam, self._latest_ns):
                self._channels[topic].log(msg.SerializeToString(), log_time=self._latest_ns)
        self._last_static = time.monotonic()

    def _idle(self) -> None:
        self._publish_static()

    def _after_points(self) -> None:
        import time

        # a steady stream never leaves the queue idle: re-send the static messages anyway
        if time.monotonic() - self._last_static >= STATIC_EVERY_S:
            self._publish_static()

    def _session(self, wall_ns: int) -> int:
        """Session time of a wall-clock time, as the recorded session stamps it (MCAP and
        WebSocket log times are unsigned: a time before the session's zero is put at 0)."""
        t = max(int(wall_ns) - self.epoch_ns, 0)
        self._latest_ns = max(self._latest_ns, t)
        return t

    def _point(self, p) -> None:
        position = _finite(p.position_world)
        if position is None:
            return
        method = str(p.method)
        track, scene = self._track_channels(method)
        t = self._session(p.t_capture_ns)
        x, y, z = (float(v) for v in position)
        # as SessionWriter.add_track: the fixed quality fields (NaN when the method has
        # none), the method's other quality columns in the map
        quality = dict(getattr(p, "quality", None) or {})
        msg = S.TrackPoint(time_ns=t, method=method, x=x, y=y, z=z, camera=str(p.camera),
                           **{k: float(quality.pop(k, float("nan")))
                              for k in S.TRACK_FIXED_QUALITY})
        for k, v in quality.items():
            msg.quality[k] = float(v)
        track.log(msg.SerializeToString(deterministic=True), log_time=t)
        i = self._track_index[method]
        self._track_index[method] = i + 1
        color = track_color(method)
        scene.log(scene_point(method, i, t, (x, y, z), color), log_time=t)

    def _frame(self, topic: str, d, best_first: bool) -> None:
        t = self._session(d.t_capture_ns)
        uv = np.asarray(d.uv, dtype=np.float64).reshape(-1, 2)
        radius = np.asarray(d.radius, np.float64)
        score = np.asarray(d.score, np.float64)
        if best_first:  # as the recording keeps a fused frame: best candidate first
            order = np.argsort(-score, kind="stable")
            uv, radius, score = uv[order], radius[order], score[order]
        msg = S.DetectionFrame(time_ns=t, camera=d.camera, frame_index=int(d.frame_index),
                               u=uv[:, 0].tolist(), v=uv[:, 1].tolist(),
                               radius=radius.tolist(), score=score.tolist())
        self._channel(topic, S.DetectionFrame).log(msg.SerializeToString(), log_time=t)

    def _detections(self, d) -> bool:
        if d.camera not in self._names:
            return False
        self._frame(S.detections_topic(d.camera), d, best_first=True)
        return True

    def _dropped(self, d, reason: str) -> None:
        if d.camera in self._names:
            self._frame(dropped_topic(reason, d.camera), d, best_first=False)

    def _event(self, time_ns: int, text: str) -> None:
        t = self._session(time_ns)
        msg = S.Log(level=2, message=text, name="pslog")  # info, as SessionWriter.add_event
        S.set_timestamp(msg.timestamp, t)
        self._channel(S.EVENTS_TOPIC, S.Log).log(msg.SerializeToString(), log_time=t)

    def _status(self, text: str, counters: dict) -> None:
        import foxglove

        self.server.publish_status(text, foxglove.StatusLevel.Info, id="pslog-live")

    def _finish(self) -> None:
        try:
            for channel in self._channels.values():
                channel.close()
        finally:
            self.server.stop()
            self._wait_stopped()

    def _wait_stopped(self, timeout_s: float = 2.0) -> None:
        """Return once the server's port is free again (the SDK stops it asynchronously), so
        a new server may take it at once; at most ``timeout_s``."""
        import time

        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with socket.socket() as probe:
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                try:
                    probe.bind((self.host, self.port))
                    return
                except OSError:
                    time.sleep(0.02)


__all__ = ["CLOSE_TIMEOUT_S", "FOXGLOVE_PORT", "QUEUE_ITEMS", "FoxgloveSink",
           "RerunLiveSink", "look_target", "std_m"]
