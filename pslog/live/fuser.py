"""The live fuser: detection datagrams in (bytes), 3D points out, as each datagram arrives.

Rules (docs/live.md, section *The fuser*):

- Every datagram is decoded (:mod:`pslog.live.protocol`); one that is not a valid detection
  datagram is counted under its reason (``truncated``, ``oversize``, ``foreign``,
  ``version``, ``malformed``) and dropped. A datagram of a camera the rig does not have is
  ``unknown_camera``; one whose pixel row lies outside the image of a rolling-shutter camera
  (no such row was read out, and its clock correction would go backwards) is ``malformed``.
- The session clock starts at ``epoch_ns`` (wall clock): a frame's LOGGED time
  (:mod:`pslog.timing`) is ``t_capture_ns - epoch_ns``.
- A datagram whose ``(camera, sequence, t_capture_ns)`` was seen before is a ``duplicate``
  (a sender that restarts its sequence at 0 sends new capture times: not duplicates).
- Frames go to :class:`pslog.fusion.stream.StreamFuser` in (logged time, camera) order, as
  it requires, and at once (no waiting: no added latency). A frame at or before the newest
  one pushed cannot be fused exactly any more (the methods' points are causal and already
  emitted): it is dropped, counted ``reordered`` when it is at most ``late_s`` older than
  the newest, ``late`` when older (or captured before the session started). A frame
  captured more than ``future_s`` after it arrived is ``future`` and dropped: a wrong clock
  or a forged time would otherwise become the newest frame, and every honest one late.
- What is fused is exactly the accepted frames, in order: a session recording them (and
  only them) on ``/detections/<camera>`` re-fuses offline to the same points
  (:class:`~pslog.live.sinks.RecordSink` writes the dropped ones on ``/live/dropped/...``).
- ``candidates=True`` fuses every candidate of a frame, the ball chosen by the gates of
  :mod:`pslog.fusion.gating` (as ``pslog fuse``); False fuses each frame's best-scored
  candidate alone (as ``pslog fuse --gating off``; faster).
- A camera with no datagram for ``silent_after_s`` is *silent*; the others keep fusing, and
  its next datagram makes it live again and is fused as any other.

Every point comes out as a :class:`LivePoint` holding the state predicted to its emit time:
the ``filter``'s own prediction (:meth:`pslog.fusion.filter.BallFilter.predict`); for the
other methods a constant-velocity estimate from the method's last two points (velocity
``(p1 - p0) / (t1 - t0)`` when they are at most ``max_gap_s`` apart, else NaN).
"""

from __future__ import annotations

import bisect
import heapq
import math
import operator
import struct
import time
from collections import deque
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import FusionError
from ..records import NS, Track
from ..rig import Rig
from ..timing import camera_parameters
from .protocol import (
    FLAG_INIT,
    FLAG_JUMP,
    FLAG_PREDICTION,
    REASONS,
    DatagramError,
    DetectionDatagram,
    decode_detections,
    pack_point,
)

#: The counters of :meth:`LiveFuser.counters`, in order.
COUNTERS = ("received", "fused", "duplicate", "reordered", "late", "future", *REASONS,
            "unknown_camera", "fusion_error", "lost", "overflow", "points")
#: Camera names the rig lacks remembered to be said (``LiveFuser.unknown_cameras``).
_UNKNOWN_NAMES = 8
#: Sequences remembered per camera for the duplicate test.
_SEEN = 4096
#: Frames remembered per camera to find the arrival time behind a point.
_ARRIVALS = 256
_I64_MAX = int(np.iinfo(np.int64).max)
_NAN_ROW = (math.nan, math.nan, math.nan)
_COV_KEYS = ("cov_xx_m2", "cov_xy_m2", "cov_xz_m2", "cov_yy_m2", "cov_yz_m2", "cov_zz_m2")


@dataclass(frozen=True, eq=False)
class LivePoint:
    """One fused point, as the fuser emits it.

    Attributes
    ----------
    method : str
    camera : str, the camera whose shutter made the point; camera_index : int (rig order)
    t_capture_ns : int, the instant the point describes (true capture time), wall clock ns
    t_emit_ns : int, when the fuser made it, wall clock ns
    position_world : (3,) float64, metres
    cov_world : (3, 3) float64, m² (NaN when the method has none): the point's published
        one (its method's quality columns; ``filter``: :meth:`~pslog.fusion.filter.BallFilter.
        point_covariance`, off-diagonal NaN on a push's earlier points)
    residual_px : float, reprojection residual, pixels (NaN unknown)
    camera_mask : int, bit c: camera c's detections made the point
    predicted_position : (3,) metres, predicted_velocity : (3,) m/s, at ``t_emit_ns``
    arrival_ns : int, wall clock arrival of the datagram of the point's detection
    flags : int, :data:`~pslog.live.protocol.FLAG_PREDICTION` etc.
    quality : dict name -> float, the method's quality columns
        (:data:`pslog.records.QUALITY_FIELDS`)
    epoch_ns : int, the session clock's zero (wall clock): the point's session time is
        ``t_capture_ns - epoch_ns``
    arrival_mono_ns, emit_mono_ns : int or None, ``arrival_ns`` and ``t_emit_ns`` on the
        clock the fuser's waits are counted on (:attr:`LiveFuser.monotonic`: the monotonic
        clock in :func:`~pslog.live.server.serve`; without one the wall clock, the same
        values); None (a point made by hand): the wall clock's
    """

    method: str
    camera: str
    camera_index: int
    t_capture_ns: int
    t_emit_ns: int
    position_world: np.ndarray
    cov_world: np.ndarray
    residual_px: float
    camera_mask: int
    predicted_position: np.ndarray
    predicted_velocity: np.ndarray
    arrival_ns: int
    flags: int = 0
    quality: dict = field(default_factory=dict)
    epoch_ns: int = 0
    arrival_mono_ns: int | None = None
    emit_mono_ns: int | None = None

    @property
    def latency_s(self) -> float:
        """Fusion latency: from the datagram's arrival to the point made, seconds, on the
        fuser's waits' clock (the monotonic clock in :func:`~pslog.live.server.serve`: a
        step of the wall clock while the frame was held does not enter it)."""
        if self.arrival_mono_ns is None or self.emit_mono_ns is None:
            return (self.t_emit_ns - self.arrival_ns) / NS
        return (self.emit_mono_ns - self.arrival_mono_ns) / NS

    @property
    def session_ns(self) -> int:
        """The point's time on the session clock (as recorded)."""
        return self.t_capture_ns - self.epoch_ns

    def to_datagram(self, sequence: int) -> bytes:
        """The point datagram (:mod:`pslog.live.protocol`)."""
        # packed straight from the arrays (as encode_point(PointDatagram(...)) would: the
        # same bytes, tests/test_live_protocol.py), once per point sent
        c = self.cov_world.tolist()
        return pack_point(sequence, self.camera_index, self.camera, self.method,
                          self.t_capture_ns, self.t_emit_ns, self.arrival_ns,
                          self.position_world.tolist(),
                          (c[0][0], c[0][1], c[0][2], c[1][1], c[1][2], c[2][2]),
                          self.residual_px, self.camera_mask, self.flags,
                          self.predicted_position.tolist(), self.predicted_velocity.tolist())

    def to_json(self) -> dict:
        """One JSON object (NaN as null): ``t`` capture time (s, wall clock), ``x, y, z`` (m),
        ``camera``, ``method``, ``latency_s`` (arrival to made), ``std_m``, ``t_emit``,
        ``residual_px``, ``camera_mask``, ``flags``, ``predicted`` ``[x, y, z]`` and
        ``velocity`` ``[vx, vy, vz]`` at ``t_emit``."""
        c = self.cov_world.tolist()  # Python floats: numpy's calls cost more on 3 x 3
        trace = c[0][0] + c[1][1] + c[2][2]  # np.trace's order
        std = math.sqrt(trace) if trace >= 0 else math.nan
        x, y, z = self.position_world.tolist()
        return {"t": self.t_capture_ns / NS, "x": x, "y": y, "z": z, "camera": self.camera,
                "method": self.method, "latency_s": self.latency_s,
                "std_m": _num(std), "t_emit": self.t_emit_ns / NS,
                "residual_px": _num(self.residual_px), "camera_mask": self.camera_mask,
                "flags": self.flags,
                "predicted": [_num(a) for a in self.predicted_position.tolist()],
                "velocity": [_num(a) for a in self.predicted_velocity.tolist()]}


def _layout(keys: tuple) -> tuple:
    """Where a Track's quality row (its columns ``keys`` in order) holds what a LivePoint
    takes: ``(residual, camera_mask, covariance getter, std getter, [(flag column, bit)],
    rejected)``, indices or None (:meth:`LiveFuser._points`, cached per key tuple)."""
    at = {k: j for j, k in enumerate(keys)}
    cov = (operator.itemgetter(*(at[k] for k in _COV_KEYS))
           if all(k in at for k in _COV_KEYS) else None)
    std = (operator.itemgetter(*(at[k] for k in ("std_x_m", "std_y_m", "std_z_m")))
           if all(k in at for k in ("std_x_m", "std_y_m", "std_z_m")) else None)
    flags = [(at[k], bit) for k, bit in (
        ("rejected", FLAG_PREDICTION), ("jump", FLAG_JUMP), ("init", FLAG_INIT)) if k in at]
    return at.get("residual_px", at.get("residual_max_px")), at.get("camera_mask"), cov, std, \
        flags, at.get("rejected")


def _num(value) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


@dataclass
class CameraLiveState:
    """What the fuser knows of one camera.

    Attributes
    ----------
    name : str; index : int (rig order)
    datagrams : int, valid datagrams of this camera (fused or dropped)
    frames : int, frames fused
    points : int, points whose shutter was this camera's
    lost : int, frames never received (gaps in the sequence)
    last_arrival_ns : int or None, wall clock arrival of its latest datagram
    last_seen_ns : int or None, the same arrival on the clock the fuser's waits are counted
        on (:attr:`LiveFuser.monotonic`: the monotonic clock in :func:`~pslog.live.server.
        serve`; else the wall clock, the same as ``last_arrival_ns``)
    last_capture_ns : int or None, capture time of its latest fused frame
    silent : bool, no datagram for ``silent_after_s`` (set by :meth:`LiveFuser.cameras`)
    """

    name: str
    index: int
    datagrams: int = 0
    frames: int = 0
    points: int = 0
    lost: int = 0
    last_arrival_ns: int | None = None
    last_seen_ns: int | None = None
    last_capture_ns: int | None = None
    silent: bool = True
    _last_sequence: int | None = None
    _newest_logged: int | None = None  # newest logged time received (any frame)
    _seen: set = field(default_factory=set)
    _seen_order: deque = field(default_factory=deque)
    # (true time of the frame's top row, arrival ns, the same arrival on the waits' clock)
    # of the latest frames, for the points
    _arrivals: deque = field(default_factory=lambda: deque(maxlen=_ARRIVALS))


def warm_up(method: str, *, candidates: bool = True, options=None) -> None:
    """Run ``method``'s streaming form over a short simulated rally, so that every compiled
    kernel it calls (:mod:`pslog._jit`) is loaded from numba's cache, or compiled on a fresh
    install, before the first real datagram: else the first datagrams of a live run wait
    ~0.3 s (loaded) to ~30 s (compiled) behind it, and the ones queued meanwhile with them.

    The rally (1.5 s, the paper's rig with the shutters the method fuses — type A unless it
    needs instants cameras share — 0.3 px noise, misses and false candidates, chip kicks and
    bounces) starts, restarts and updates the method's state as a match does; the kernels'
    signatures depend on dtypes, not on the rig, so the user's rig need not see it. Nothing
    of it is kept but the note that it ran: a second call with the same arguments returns at
    once (``pslog live`` warms up before it fixes the session clock's zero and starts its
    cameras; :func:`pslog.live.server.serve` calls it again).
    """
    from ..fusion import FusionOptions

    key = (method, bool(candidates), options or FusionOptions())
    if key in _WARMED:
        return
    from ..motion import rally_motion
    from ..rig import apply_timing, builtin_rig
    from ..simulation import SimulationOptions, simulate
    from .protocol import detection_datagrams, encode_detections

    # the shutters the method fuses (sync and type B need instants cameras share)
    timing = {"sync": "sync", "typeB": "typeB", "linear": "typeB"}.get(method, "typeA")
    rig = apply_timing(builtin_rig("paper3"), timing)
    detections, _ = simulate(rig, rally_motion(seed=1, duration=1.5), 1.5,
                             SimulationOptions(noise_px=0.3, miss_rate=0.02,
                                               spurious_rate=0.05, seed=2))
    now = [0]
    fuser = LiveFuser(rig, method, options=options, candidates=candidates, epoch_ns=0,
                      keep=False, clock=lambda: now[0])
    frames = [(d.t_capture_ns, encode_detections(d)) for d in detection_datagrams(detections)]
    for t, data in frames:
        now[0] = t
        fuser.feed(data, t)
    fuser.flush()
    _RALLIES[key] = (rig, frames)
    _WARMED.add(key)


#: the (method, candidates, options) :func:`warm_up` ran for in this process
_WARMED: set = set()
#: per such key, the rig and the datagrams ((capture ns, bytes)) of its warm-up rally
_RALLIES: dict = {}
#: a detection datagram's capture and sent times (bytes 24-40, :mod:`.protocol`)
_REHEARSAL_TIMES = struct.Struct("<qq")
#: the longest a rehearsal is expected to take, ns (:meth:`Rehearsal.plan`)
_MAX_REHEARSAL_NS = 2_000_000


class Rehearsal:
    """Keeps a live fuser's code warm while its datagrams are far apart (3 x 30 fps: 11 ms).

    Between two such datagrams the core runs other work and the fuser's code and tables
    leave its caches: a datagram then costs about twice its CPU back to back. :meth:`step`
    feeds ONE datagram of :func:`warm_up`'s rally to a fuser of its own (the method's
    decoding, gate, push, kernels, points and point datagrams; nothing sent, nothing of the
    real fuser touched; the rally replayed later and later in a loop), shortly before the
    next real datagram is due (:func:`pslog.live.server.serve` plans it, :meth:`plan`).

    Parameters
    ----------
    fuser : the real LiveFuser (its method, candidates, options and cameras' rates)
    lead_s : a rehearsal ends this long before the earliest time the next datagram can come
        (it starts the longest of the latest rehearsals' wall times earlier still)
    min_gap_s : no rehearsal when datagrams come closer than this (already warm)
    """

    def __init__(self, fuser: LiveFuser, lead_s: float = 0.0005,
                 min_gap_s: float = 0.004) -> None:
        warm_up(fuser.method, candidates=fuser.candidates, options=fuser.options)
        rig, self._frames = _RALLIES[(fuser.method, bool(fuser.candidates), fuser.options)]
        now = self._now = [0]
        self._shadow = LiveFuser(rig, fuser.method, options=fuser.options,
                                 candidates=fuser.candidates, epoch_ns=0, keep=False,
                                 clock=lambda: now[0])
        self._i = 0
        # the rally again, this much later each time (its times stamped anew)
        self._shift = 0
        self._span = self._frames[-1][0] - self._frames[0][0] + NS // 30
        self.lead_ns = int(lead_s * NS)
        self.min_gap_ns = int(min_gap_s * NS)
        self._period = [int(NS / f) for f in fuser._fps]
        #: per camera, its latest datagrams' delays (arrival on the fuser's waits' clock -
        #: capture, the sender's wall clock: a constant offset between the two clocks plus
        #: the trip and queue), ns
        self._delays: list[deque] = [deque(maxlen=16) for _ in fuser._fps]
        self._frames_seen = [0] * len(fuser._fps)
        #: when to rehearse, on the fuser's waits' clock (:attr:`LiveFuser.monotonic`: the
        #: monotonic clock in serve), ns (None: nothing planned)
        self.due: int | None = None
        #: rehearsals run (each one datagram of the rally)
        self.steps = 0
        self._durations: deque = deque(maxlen=8)  # the latest rehearsals' wall times, ns
        #: the longest of the latest rehearsals' wall times, at most 2 ms, ns (0 before any;
        #: updated by :meth:`plan`)
        self.duration_ns = 0

    def step(self) -> None:
        """One datagram of the rally through the rehearsal's own fuser, its points packed."""
        start = time.perf_counter_ns()
        if not self._frames:
            return
        if self._i == len(self._frames):
            self._i = 0
            self._shift += self._span
        t, data = self._frames[self._i]
        self._i += 1
        if self._shift:  # (its capture and sent times, protocol's header)
            t += self._shift
            data = bytearray(data)
            _REHEARSAL_TIMES.pack_into(data, 24, t, t)
        self._now[0] = t
        try:
            for n, p in enumerate(self._shadow.feed(data, t)):
                p.to_datagram(n)
        except Exception:  # (a rehearsal never stops the real fuser: no more of them)
            self._frames = []
            self.due = None
            return
        self.steps += 1
        self._durations.append(time.perf_counter_ns() - start)

    def plan(self, fuser: LiveFuser, now: int) -> None:
        """After a datagram of ``fuser`` (handled at ``now``, on the fuser's waits' clock,
        :attr:`LiveFuser.monotonic`: the monotonic clock in serve; without one the wall
        clock): when to rehearse for the next one, :attr:`due` on that clock. Each live
        camera's next frame is due a frame period after its latest fused one; it comes at
        the earliest with the least delay (arrival, on that clock, less capture) of its
        latest datagrams; the rehearsal is to end ``lead_s`` before the earliest camera's (it
        starts :attr:`duration_ns` before that: the longest of the latest rehearsals' wall
        times, at most 2 ms, so that one rehearsal preempted for long on a busy machine does
        not move every later one before the datagram it is for, where none would run and
        the estimate would never be renewed). The fuser's wall clock does not enter: a step
        of it (NTP, a VM's clock set again) neither moves the plan nor stops the rehearsals
        (on the wall clock, the delays after a step forward were the step longer than the
        least one for 16 datagrams of each camera: every rehearsal due in the past, none
        run). A step of the senders' own clock (on the fuser's host, with it) forward makes
        their delays shorter, the least one the newest: planned as before; backward, their
        frames are ``late`` (not fused, nothing to plan from) until their times pass the
        newest fused one."""
        self.duration_ns = min(max(self._durations, default=0), _MAX_REHEARSAL_NS)
        self.due = None
        if not self._frames:  # (a rehearsal failed: none any more)
            return
        earliest = None
        latest_arrival = None
        silent = fuser.silent_after_ns
        for c, state in enumerate(fuser._cams):
            capture, seen = state.last_capture_ns, state.last_seen_ns
            if capture is None or seen is None or now - seen > silent:
                continue
            delays = self._delays[c]
            if state.frames != self._frames_seen[c]:
                self._frames_seen[c] = state.frames
                delays.append(seen - capture)
            if latest_arrival is None or seen > latest_arrival:
                latest_arrival = seen
            expected = capture + self._period[c] + min(delays)
            if earliest is None or expected < earliest:
                earliest = expected
        if earliest is None or latest_arrival is None \
                or earliest - latest_arrival < self.min_gap_ns:
            return
        self.due = earliest - self.lead_ns - self.duration_ns


class LiveFuser:
    """Fuse detection datagrams as they arrive (module docstring for the rules).

    Parameters
    ----------
    rig : Rig, the cameras (their names are what the datagrams carry) and clock corrections
    method : a causal fusion method (``filter``, ``typeA``, ``nearest``, ...)
    late_s : float, a dropped out-of-order frame older than the newest fused one by more
        than this is counted ``late``, else ``reordered``, seconds
    future_s : float, a frame captured more than this after its arrival is dropped as
        ``future`` (clocks disagree or the time is forged), seconds
    options : FusionOptions (``confirm_gaps`` is always off here: a point per shutter at
        once; a typeA point across a long gap is not held for the next camera)
    candidates : bool, fuse every candidate through the gates (True) or each frame's best
        candidate (False)
    epoch_ns : int, the session clock's zero, wall clock ns (default: now)
    silent_after_s : float, a camera without a datagram this long is silent, seconds
    clock : callable returning the wall clock in ns (``time.time_ns``), stamps ``t_emit_ns``
    keep : bool, collect :attr:`accepted` and :attr:`dropped` (for a recorder to drain)
    hold_s : float, 0 (default): each frame is fused the moment it arrives. Above 0: a frame
        with candidates waits until every other live camera has sent a frame at least as
        recent (each camera sends in order, so nothing older can still come from it), at
        most ``hold_s`` after its arrival, and frames are fused in capture order: frames
        that overtake one another by up to ``hold_s`` are all fused instead of dropped as
        ``reordered``, at the cost of that wait (:meth:`poll` releases frames whose wait
        is over between datagrams)
    monotonic : callable returning the clock the fuser's waits are counted on, ns (the
        hold, a camera's silence), or None (default): the wall clock, ``clock``, and each
        datagram's wall-clock ``arrival_ns``. :func:`~pslog.live.server.serve` gives
        ``time.monotonic_ns`` and each datagram's arrival on it (:meth:`feed`): a step of
        the wall clock (NTP, a VM's clock set again) then neither makes a silent camera
        look live (a step back: held frames waiting for it as long as the step) nor a live
        one silent (forward); the capture-time checks (``future``, the points' times) stay
        on the wall clock, the senders' clock

    Attributes
    ----------
    accepted : list of DetectionDatagram, the fused frames not yet taken (with ``keep``)
    dropped : list of (DetectionDatagram, reason), valid datagrams not fused (``duplicate``,
        ``reordered``, ``late``, ``malformed``, ``fusion_error``), not yet taken
    stream : the :class:`~pslog.fusion.stream.StreamFuser`
    """

    def __init__(self, rig: Rig, method: str = "filter", *, late_s: float = 0.1,
                 options=None, candidates: bool = True, epoch_ns: int | None = None,
                 silent_after_s: float = 1.0, clock=time.time_ns, keep: bool = True,
                 hold_s: float = 0.0, future_s: float = 5.0, monotonic=None) -> None:
        from ..fusion import BREAK_SOURCES, FusionOptions, check_method, default_tolerance
        from ..fusion._prepare import default_max_gap_s
        from ..fusion.gating import _clock_model, _true_time_ns
        from ..fusion.stream import StreamFuser

        check_method(method)
        if not late_s >= 0:
            raise FusionError(f"late bound must be >= 0 seconds, got {late_s!r}")
        if not silent_after_s > 0:
            raise FusionError(f"silent-after must be > 0 seconds, got {silent_after_s!r}")
        if not 0 <= hold_s <= 10:
            raise FusionError(f"hold must be in [0, 10] seconds, got {hold_s!r}")
        self.hold_ns = int(hold_s * NS)
        # frames waiting (hold_s > 0): heap of (logged ns, camera, order, datagram, arrival
        # (wall clock), arrival on the waits' clock)
        self._held: list = []
        self._n_held = 0
        self.rig = rig
        self.method = method
        # (a point per shutter at once: typeA's long-gap points are not held for the next
        # camera's confirmation, pslog.fusion.confirm, nor the filter's surprising ones,
        # FusionOptions.filter_hold_nis)
        # (no options: 1 ms, or less for cameras faster than 333 fps, as pslog fuse's)
        self.options = replace(options or FusionOptions(tolerance_s=default_tolerance(rig)),
                               confirm_gaps=False,
                               confirm_every=False, confirm_sides=False,
                               confirm_breaks=False, break_source=BREAK_SOURCES[0],
                               filter_hold_nis=None)
        # without gating a frame's candidates cannot be told apart: its best one alone, as
        # fuse() does with gating off
        self.candidates = bool(candidates) and self.options.gating
        self.stream = StreamFuser(rig, method, self.options, candidates=self.candidates)
        self.clock = clock
        #: the clock of the waits (hold, silence): :meth:`feed`'s ``arrival_mono_ns``,
        #: :meth:`poll`'s and :meth:`cameras`' ``now_ns`` (None: the wall clock, ``clock``)
        self.monotonic = monotonic
        self.epoch_ns = int(clock() if epoch_ns is None else epoch_ns)
        self.late_ns = int(late_s * NS)
        self.future_ns = int(future_s * NS)
        self.silent_after_ns = int(silent_after_s * NS)
        self.keep = keep
        self.accepted: list[DetectionDatagram] = []
        self.dropped: list[tuple[DetectionDatagram, str]] = []
        self._counts = dict.fromkeys(COUNTERS, 0)
        self._names = tuple(rig.names)
        self._index = {name: i for i, name in enumerate(self._names)}
        #: the first camera names datagrams gave that the rig lacks (at most
        #: :data:`_UNKNOWN_NAMES`: a sender of random names must not grow it), in arrival order
        self.unknown_cameras: list[str] = []
        self._cams = [CameraLiveState(name, i) for i, name in enumerate(rig.names)]
        self._newest = (np.iinfo(np.int64).min, -1)  # (logged ns, camera) of the newest fused
        self._clock_p = camera_parameters(rig)
        self._readout = (self._clock_p["readout"] > 0).tolist()
        self._clock_model = _clock_model(rig)  # per camera (height, offset, drift, readout)
        self._true_time_ns = _true_time_ns  # timing.true_times_ns of one, in floats
        self._corrected = any(c.has_clock_correction for c in rig.cameras)
        self._fps = [c.fps for c in rig.cameras]
        self._max_gap_ns = int((self.options.max_gap_s or default_max_gap_s(rig)) * NS)
        self._filter = getattr(getattr(self.stream, "incremental", None), "filter", None)
        # (session ns, position: an array, or a list of floats without a filter)
        self._last_point: tuple[int, np.ndarray | list] | None = None
        self._layouts: dict[tuple, tuple] = {}  # quality keys -> _layout
        self._flushed = False
        #: name of the camera of the latest valid datagram ("" before any)
        self.last_camera = ""

    # ---- public ---------------------------------------------------------------------------
    def feed(self, data: bytes, arrival_ns: int,
             arrival_mono_ns: int | None = None) -> list[LivePoint]:
        """One received datagram (``arrival_ns``: wall clock; ``arrival_mono_ns``: the same
        arrival on :attr:`monotonic`'s clock, None: ``arrival_ns`` without one, now on it
        with one); returns the points it made (possibly none). Never raises on bad bytes:
        they are counted (:meth:`counters`)."""
        if arrival_mono_ns is None:
            arrival_mono_ns = arrival_ns if self.monotonic is None else self.monotonic()
        elif self.monotonic is None:  # (its waits would compare two clocks)
            raise FusionError("LiveFuser.feed: arrival_mono_ns given to a fuser made without "
                              "monotonic= (its waits are on the wall clock)")
        seen = int(arrival_mono_ns)
        counts = self._counts
        counts["received"] += 1
        try:
            d = decode_detections(data)
        except DatagramError as exc:
            counts[exc.reason] += 1
            return []
        cam = self._index.get(d.camera)
        if cam is None:
            counts["unknown_camera"] += 1
            unknown = self.unknown_cameras
            if len(unknown) < _UNKNOWN_NAMES and d.camera not in unknown:
                unknown.append(d.camera)
            return []
        state = self._cams[cam]
        self.last_camera = d.camera
        state.datagrams += 1
        state.last_arrival_ns = int(arrival_ns)
        state.last_seen_ns = seen
        state.silent = False
        reason = self._check(d, cam, state)
        if reason is None and d.t_capture_ns - arrival_ns > self.future_ns:
            reason = "future"  # never the newest frame: it would make every other one late
        if reason not in ("duplicate", "future"):
            # frames lost on the way: gaps in the camera's sequence, whether or not the
            # frame is fused (a frame that comes after a later one is no loss)
            last = state._last_sequence
            if last is not None and d.sequence == last + 1:
                state._last_sequence = d.sequence  # (the usual: the next one, nothing lost)
            else:
                self._sequence(d, cam, state, last)
        if reason is not None:
            return self._drop(d, reason)
        # accepted
        logged = d.t_capture_ns - self.epoch_ns
        if state._newest_logged is None or logged > state._newest_logged:
            state._newest_logged = logged
        key = (d.sequence, d.t_capture_ns)
        state._seen.add(key)
        state._seen_order.append(key)
        if len(state._seen_order) > _SEEN:
            state._seen.discard(state._seen_order.popleft())
        if not self.hold_ns:
            return self._fuse(d, cam, logged, int(arrival_ns), seen)
        if len(d.uv):
            heapq.heappush(self._held, (logged, cam, self._n_held, d, int(arrival_ns), seen))
            self._n_held += 1
            return self._release(seen)
        return self._fuse(d, cam, logged, int(arrival_ns), seen) + self._release(seen)

    def _sequence(self, d: DetectionDatagram, cam: int, state: CameraLiveState,
                  last: int | None) -> None:
        """:meth:`feed`'s count of the frames lost (gaps in the camera's sequence) for a
        datagram whose sequence is not its camera's latest + 1."""
        counts = self._counts
        if last is not None and d.sequence < last and state._newest_logged is not None \
                and d.t_capture_ns - self.epoch_ns > state._newest_logged:
            last = None  # a lower sequence with a newer capture time: the sender restarted
        if last is not None and d.sequence > last + 1 and d.sequence - last - 1 > 10 + (
                0 if state._newest_logged is None else 10 * self._fps[cam] * max(
                    0, d.t_capture_ns - self.epoch_ns - state._newest_logged) / NS):
            # more frames than the time since could hold (any gap past 10 before a frame
            # of the camera was fused: forged numbers, never 2**64 lost): renumbered
            last = None
        if last is not None and d.sequence > last + 1:
            gap = d.sequence - last - 1
            state.lost += gap
            counts["lost"] += gap
        elif last is not None and d.sequence < last and state.lost:
            state.lost -= 1  # it came after all
            counts["lost"] -= 1
        if last is None or d.sequence > last:
            state._last_sequence = d.sequence

    def poll(self, now_ns: int) -> list[LivePoint]:
        """With ``hold_s``: fuse the held frames whose wait is over at ``now_ns`` (on
        :attr:`monotonic`'s clock; without one, the wall clock); returns their points.
        Without: nothing to do."""
        return self._release(int(now_ns)) if self._held else []

    def _release(self, now: int, final: bool = False) -> list[LivePoint]:
        """Fuse the held frames, oldest first, while the oldest one is complete (every
        other live camera has sent a frame at least as recent) or has waited ``hold_s``
        (``now`` and the arrivals compared: on the waits' clock, :attr:`monotonic`)."""
        held = self._held
        points: list[LivePoint] = []
        while held:
            logged, cam, _, d, arrival, seen = held[0]
            if not final and now - seen < self.hold_ns:
                for c in self._cams:
                    if c.index == cam or c.last_seen_ns is None \
                            or now - c.last_seen_ns > self.silent_after_ns:
                        continue  # a silent camera is not waited for
                    if c._newest_logged is None or c._newest_logged < logged:
                        return points
            heapq.heappop(held)
            if (logged, cam) <= self._newest:  # overtaken by a frame released on time out
                late = self._newest[0] - logged > self.late_ns
                self._drop(d, "late" if late else "reordered")
                continue
            points += self._fuse(d, cam, logged, arrival, seen)
        return points

    def _fuse(self, d: DetectionDatagram, cam: int, logged: int, arrival_ns: int,
              seen: int):
        """Push one accepted frame (arrived at ``arrival_ns``, wall clock, and ``seen``, on
        the waits' clock) into the stream; its points."""
        counts, state = self._counts, self._cams[cam]
        k = len(d.uv)  # (len(d), without its Python __len__: once per datagram)
        if k:  # from now on the newest: an older frame with candidates cannot be fused
            self._newest = (logged, cam)
            # true_times_ns of the top row, in floats (the same ns; numpy costs more for one)
            top = logged if not self._corrected else self._true_time_ns(
                logged, 0.0, self._clock_model[cam])
            state._arrivals.append((top, arrival_ns, seen))
        try:
            if k:
                if k == 1:  # the usual frame: nothing to order (a copy: the stream's own)
                    uv = d.uv.copy()
                else:  # best first, as a session stores
                    order = np.argsort(-d.score, kind="stable")
                    if not self.candidates:
                        order = order[:1]
                    uv = d.uv[order]
                # (Python integers, checked: the camera the rig's, the times and the frame
                # index within int64)
                track = self.stream.push_frame(logged, cam, uv, d.frame_index)
            else:
                track = None
        except FusionError:
            # cannot happen on checked datagrams; never let it stop the fuser
            counts["fusion_error"] += 1
            return self._drop(d, "fusion_error", counted=True)
        counts["fused"] += 1
        state.frames += 1
        state.last_capture_ns = d.t_capture_ns
        if self.keep:
            self.accepted.append(d)
        return self._points(track) if track is not None and len(track.time_ns) else []

    def flush(self) -> list[LivePoint]:
        """The points still held (methods that wait for the tolerance, clock corrections);
        call once at the end of the stream."""
        if self._flushed:
            return []
        self._flushed = True
        points = self._release(0, final=True)
        try:
            track = self.stream.flush()
        except FusionError:
            self._counts["fusion_error"] += 1
            return points
        return points + (self._points(track) if len(track) else [])

    def counters(self) -> dict[str, int]:
        """Datagrams ``received``; frames ``fused``; dropped by reason (``duplicate``,
        ``reordered``, ``late``, ``truncated``, ``oversize``, ``foreign``, ``version``,
        ``malformed``, ``unknown_camera``, ``fusion_error``); frames ``lost`` on the way
        (sequence gaps); datagrams the socket's receive buffer had no room for, discarded by
        the kernel before the fuser could read them (``overflow``: :meth:`socket_overflow`,
        a flood); ``points`` emitted."""
        return dict(self._counts)

    def socket_overflow(self, total: int) -> None:
        """The kernel's count of datagrams its socket dropped for want of room (Linux
        ``SO_RXQ_OVFL``, from the start), as the server reads it beside a datagram."""
        self._counts["overflow"] = int(total)

    def cameras(self, now_ns: int | None = None) -> list[CameraLiveState]:
        """Each camera's state, ``silent`` updated to ``now_ns`` (on :attr:`monotonic`'s
        clock; without one, the wall clock; default: now)."""
        if now_ns is None:
            now_ns = (self.monotonic or self.clock)()
        now = int(now_ns)
        for c in self._cams:
            c.silent = c.last_seen_ns is None or now - c.last_seen_ns > self.silent_after_ns
        return list(self._cams)

    def take(self) -> tuple[list[DetectionDatagram], list[tuple[DetectionDatagram, str]]]:
        """The accepted and dropped datagrams collected since the last call (emptied)."""
        accepted, dropped = self.accepted, self.dropped
        self.accepted, self.dropped = [], []
        return accepted, dropped

    # ---- internals ------------------------------------------------------------------------
    def _check(self, d: DetectionDatagram, cam: int, state: CameraLiveState) -> str | None:
        if (d.sequence, d.t_capture_ns) in state._seen:
            return "duplicate"
        k = len(d.uv)
        if k and self._readout[cam]:
            h = self._clock_model[cam][0]
            if not all(0 <= v <= h for v in d.uv[:, 1].tolist()):  # rows: finite (decoded)
                return "malformed"
        logged = d.t_capture_ns - self.epoch_ns
        if logged < 0:
            return "late"
        if k and (logged, cam) <= self._newest:
            return "late" if self._newest[0] - logged > self.late_ns else "reordered"
        # a frame without candidates fuses nothing (offline fusion never sees it either):
        # in any order it only says that its camera is alive
        return None

    def _drop(self, d: DetectionDatagram, reason: str, counted: bool = False) -> list:
        if not counted:
            self._counts[reason] += 1
        if self.keep:
            self.dropped.append((d, reason))
        return []

    def _points(self, track: Track) -> list[LivePoint]:
        now = int(self.clock())
        now_seen = now if self.monotonic is None else int(self.monotonic())
        n = len(track.time_ns)
        q = track.quality
        names = self._names
        times = track.time_ns.tolist()
        cams = track.camera.tolist()
        positions = track.position_world
        # the quality columns as one row of Python floats per point (float(column[i]) each,
        # the same values; one numpy call per track, not one per column and point)
        keys = tuple(q)
        rows = (np.array(list(q.values()), dtype=np.float64).T.tolist() if keys
                else [[]] * n)
        layout = self._layouts.get(keys)
        if layout is None:
            layout = self._layouts[keys] = _layout(keys)
        residual, mask, cov_at, std_at, flag_at, rejected = layout
        flt = self._filter
        epoch = self.epoch_ns
        at_now = None  # (the filter's predicted position and velocity at now, if any)
        if flt is not None:
            predicted = flt.predict(now - epoch)
            if predicted is not None:
                at_now = predicted[0].tolist(), predicted[1].tolist()
        method = self.method
        new = object.__new__
        out = []
        for i in range(n):
            t, cam = times[i], cams[i]
            p = positions[i]
            row = rows[i]
            if flt is None:  # (constant velocity: on Python floats, one array of the four)
                position, cov_w, pred_p, pred_v = self._made(t, p.tolist(), row, layout, now)
            else:  # (the filter's: on Python floats, one read-only (6, 3) array of the four)
                nan = math.nan
                pl = p.tolist()
                full = None
                if cov_at is None and std_at is not None and rejected is not None and i == n - 1:
                    # the published variances (the columns), the correlations of the
                    # filter's state at this point and of the term the point published
                    full = flt.point_covariance(t, cam, pl, std_at(row), row[rejected] == 1)
                if cov_at is not None:
                    xx, xy, xz, yy, yz, zz = cov_at(row)
                    c0, c1, c2 = (xx, xy, xz), (xy, yy, yz), (xz, yz, zz)
                elif full is not None:
                    c0, c1, c2 = full
                elif std_at is not None:
                    sx, sy, sz = std_at(row)
                    # (np.diag of the squares, the off-diagonal terms not kept)
                    c0, c1, c2 = (sx ** 2, nan, nan), (nan, sy ** 2, nan), (nan, nan, sz ** 2)
                else:
                    c0 = c1 = c2 = _NAN_ROW
                # (before the filter has a state: the point, no velocity)
                pp, pv = at_now if at_now is not None else (pl, _NAN_ROW)
                block = np.array((pl, c0, c1, c2, pp, pv))
                block.flags.writeable = False
                position, cov_w, pred_p, pred_v = block[0], block[1:4], block[4], block[5]
            flags = 0
            for j, bit in flag_at:
                if row[j] == 1:
                    flags |= bit
            arrivals = self._cams[cam]._arrivals
            # the latest frame of the camera at or before the point (sorted: in fused order);
            # usually the frame just fused, its last one
            if arrivals and arrivals[-1][0] <= t:
                j = len(arrivals) - 1
            else:
                j = bisect.bisect_right(arrivals, (t, _I64_MAX)) - 1
            if j >= 0:
                _, arrival, seen = arrivals[j]
            else:
                arrival, seen = now, now_seen
            m = row[mask] if mask is not None else math.nan
            # a LivePoint of these fields (its frozen __init__ sets them one by one)
            point = new(LivePoint)
            point.__dict__.update(
                method=method, camera=names[cam], camera_index=cam,
                t_capture_ns=t + epoch, t_emit_ns=now, position_world=position,
                cov_world=cov_w,
                residual_px=row[residual] if residual is not None else math.nan,
                camera_mask=int(m) if math.isfinite(m) else 1 << cam,
                predicted_position=pred_p, predicted_velocity=pred_v,
                arrival_ns=arrival, flags=flags, quality=dict(zip(keys, row, strict=True)),
                epoch_ns=epoch, arrival_mono_ns=seen, emit_mono_ns=now_seen)
            out.append(point)
            self._cams[cam].points += 1
        self._counts["points"] += n
        return out

    def _made(self, t: int, p: list, row: list, layout: tuple, now: int) -> tuple:
        """A point of a method without a filter: its position, covariance, predicted
        position and velocity at ``now`` (wall clock), read-only views of one (6, 3) array
        made from Python floats (``p``: its position; ``row``: its quality row, ``layout``
        where). The prediction: constant velocity from the last two points (NaN velocity
        without a recent previous point); the covariance as :meth:`_points` builds a
        filter's."""
        cov_at, std_at = layout[2], layout[3]
        if cov_at is not None:
            xx, xy, xz, yy, yz, zz = cov_at(row)
            c0, c1, c2 = (xx, xy, xz), (xy, yy, yz), (xz, yz, zz)
        elif std_at is not None:
            sx, sy, sz = std_at(row)
            nan = math.nan
            c0, c1, c2 = (sx ** 2, nan, nan), (nan, sy ** 2, nan), (nan, nan, sz ** 2)
        else:
            c0 = c1 = c2 = _NAN_ROW
        px, py, pz = p
        last, self._last_point = self._last_point, (t, p)
        if last is None or not 0 < t - last[0] <= self._max_gap_ns:
            pred, vel = (px, py, pz), _NAN_ROW
        else:
            dt = (t - last[0]) / NS
            lx, ly, lz = last[1]
            vx, vy, vz = (px - lx) / dt, (py - ly) / dt, (pz - lz) / dt
            ahead = (now - self.epoch_ns - t) / NS
            pred, vel = (px + vx * ahead, py + vy * ahead, pz + vz * ahead), (vx, vy, vz)
        block = np.array((p, c0, c1, c2, pred, vel))
        block.flags.writeable = False
        return block[0], block[1:4], block[4], block[5]
