"""The causal streaming form of fusion: detections pushed as they arrive, points out.

Every method is causal, so running the batch kernel over a trailing window of recent
detections gives, for each new detection, the same point as the batch run over the whole
session (a method with an incremental form, the registry's ``streamer``, ``filter`` and
``typeA``, is instead fed each admitted detection once, with the same points). A point is
*settled*, and emitted, once nothing that could still arrive can change it:

- ``typeA`` and ``nearest`` use only detections at or before the new one in (time, camera)
  order, so its point is emitted as soon as it is pushed;
- ``sync``, ``typeB`` and ``linear`` group detections within the tolerance, so a point at
  ``t`` is emitted once a detection later than ``t + tolerance`` arrives, or on :meth:`flush`.

Each push's Track also carries the counts of the points the method dropped
(``Track.dropped``) that became settled with it, so the stream's Tracks joined
(:meth:`Track.concat <pslog.records.Track.concat>`) count what the batch counts, reason by
reason: the incremental forms count each dropped point once; the window methods, whose
window re-fuses points an earlier window already dropped, count only the drops after the
last counted one and, for ``sync``, ``typeB`` and ``linear``, before the tolerance's wait,
as they emit points (:data:`pslog.fusion.stereo.Drops`: each drop's time and camera).

With ``candidates=True``, the gate's rows from the session's first choice on wait until the
verdict on that choice is known (:class:`pslog.fusion.gating.StreamStart`: its camera's
next frame, at most ``static_s``), so the session's first points come out together then.

Pushed times are LOGGED times: each detection is corrected by its camera's clock parameters
(``clock_offset``, ``clock_drift_ppm``, ``readout``) through :func:`pslog.timing.true_times_ns`,
exactly as :func:`pslog.timing.observations` corrects a whole session, so the stream's points
equal ``fuse(timing.observations(detections, rig), rig, method)``. Corrected times can reorder
detections across cameras, so a corrected detection waits in a queue until it is *admitted*:
until no detection still to come (pushed in logged order, at a row ``v >= 0``) can be corrected
to an earlier time. Admission costs a latency of about the spread of the cameras' corrections
(offsets, drift so far, and the pushed detection's readout term) plus the time to the next push;
with no clock correction in the rig a detection is admitted when pushed (no extra latency).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import cast

import numpy as np

from ..errors import FusionError
from ..geometry import fundamental_matrices
from ..records import NS, Observations, Track
from ..rig import Rig
from . import METHODS, FusionOptions, causal_methods, check_method, check_tolerance
from ._prepare import default_max_gap_s, prepare
from .gating import _clock_model, _true_time_ns, stream_arrays
from .stereo import NOISE_EVERY_S, NOISE_WINDOW_S, Drops, sync_groups


class StreamFuser:
    """Incremental fusion of one rig's detections with one method.

    Parameters
    ----------
    rig : Rig
    method : a name of a causal method of :data:`pslog.fusion.METHODS` (an offline one,
        such as ``smooth``, is refused: each of its points uses every detection)
    options : FusionOptions

    Examples
    --------
    >>> fuser = StreamFuser(rig, "typeA")                        # doctest: +SKIP
    >>> track = fuser.push(time_ns, camera, uv)                  # doctest: +SKIP
    """

    def __init__(self, rig: Rig, method: str, options: FusionOptions | None = None, *,
                 candidates: bool = False) -> None:
        if len(rig) < 2:
            raise FusionError(f"fusion needs at least two cameras; rig has {len(rig)}")
        self.rig = rig
        self.method = check_method(method)
        if not METHODS[method].causal:
            raise FusionError(f"method {method!r} is offline (each of its points uses every "
                              f"detection) and cannot stream; streaming methods: "
                              f"{', '.join(causal_methods())}")
        self._immediate = not METHODS[method].waits_tolerance
        self.options = options or FusionOptions()
        if self.options.clock_covariance is not None:
            raise FusionError("the clocks' consider covariance (clock_covariance) is offline "
                              "only (pslog.fusion.clock): fuse the session instead")
        check_tolerance(rig, self.options.tolerance_s)
        self._max_gap_s = self.options.max_gap_s or default_max_gap_s(rig)
        self._resolved = replace(self.options, max_gap_s=self._max_gap_s)  # (as fuse's)
        # the method's batch function, which a window method calls with ``drops`` (Method)
        self._function = cast(Callable[..., Track], METHODS[method].function)
        # the history a point still to emit reaches back to (the window methods; typeA and
        # filter keep their own): every such point is at or after the newest row less the
        # settling time (which _settled keeps on top), and uses, at most, ``nearest`` the
        # other cameras' latest detections within max_gap_s, ``typeB`` and ``linear`` two
        # stereo points within max_gap_s whose detections lie within the tolerance of them,
        # ``sync`` one group within the tolerance: max_gap_s + tolerance (less loses a bridged
        # partner: stream-equals-batch tests at long gaps). The cut is then moved back to the
        # start of a sync group (see _settled), so the window groups exactly as the batch does.
        # ``nearest``'s covariance also extrapolates each partner's image motion from that
        # camera's previous two detections, each within max_gap_s of the next (three times
        # max_gap_s back), and takes the detections' noise from the residuals of the
        # NOISE_WINDOW_S before the latest checkpoint (NOISE_EVERY_S apart), each residual
        # from its camera's three previous detections (stereo.detection_noise), and tests
        # each slot's newest detection's residual from its camera's three previous ones for
        # a break (stereo.innovations: four times max_gap_s back; within the noise's reach
        # unless max_gap_s exceeds NOISE_EVERY_S + NOISE_WINDOW_S).
        # ``sync``, ``typeB`` and ``linear`` test each stereo point (and typeB / linear each
        # prediction) at the detections' noise (stereo.refusal_noise: nearest's estimator)
        # at the point's time, a stereo point up to max_gap_s before the point to emit, and
        # the residual test takes each slot's image speed from its camera's previous
        # detection (within max_gap_s): max_gap_s more than nearest's noise reach.
        reach_s = self._max_gap_s
        if method == "nearest":
            reach_s = max(NOISE_EVERY_S + NOISE_WINDOW_S + 3 * self._max_gap_s,
                          4 * self._max_gap_s)
        elif method in ("sync", "typeB", "linear"):
            reach_s = NOISE_EVERY_S + NOISE_WINDOW_S + 4 * self._max_gap_s
        self._history_ns = int((reach_s + self.options.tolerance_s) * NS) + 1
        self._settle_ns = 0 if self._immediate else int(self.options.tolerance_s * NS)
        self._F = fundamental_matrices(rig.cameras)
        self._time = np.zeros(0, np.int64)
        self._camera = np.zeros(0, np.int32)
        self._uv = np.zeros((0, 2))
        self._frame = np.zeros(0, np.int64)
        # each row's doubt (pslog.fusion.gating.choice_doubt, pixels²; 0: none)
        self._doubt = np.zeros(0)
        # the window's first rows as prepare made them at the last push (undistorted pixels,
        # rays, pixel Jacobians; each row's own: prepared again, the same bits)
        self._head: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._emitted_until: tuple[int, int] = (np.iinfo(np.int64).min, -1)  # (time, camera)
        # the window methods' dropped points counted so far: every one at or before this
        # (time, camera), each counted once, when it became settled (as a point is emitted)
        self._counted_until: tuple[int, int] = (np.iinfo(np.int64).min, -1)
        # the clock model (pslog.timing), per camera in rig order
        self._clock_model = _clock_model(rig)
        self._corrected = any(c.has_clock_correction for c in rig.cameras)
        self._last_logged: tuple[int, int] = (np.iinfo(np.int64).min, -1)  # (time, camera)
        # corrected detections not yet admitted to the window (unordered)
        self._q_time = np.zeros(0, np.int64)
        self._q_camera = np.zeros(0, np.int32)
        self._q_uv = np.zeros((0, 2))
        self._q_frame = np.zeros(0, np.int64)
        self._q_doubt = np.zeros(0)
        # a method with an incremental form (filter) takes each admitted detection once
        streamer = METHODS[method].streamer
        self.incremental = streamer(rig, self.options) if streamer is not None else None
        self._fed = 0  # rows of the window already given to it (the last one is kept)
        # its answer to no new rows, made once (one empty Track, shared: Tracks are frozen)
        self._nothing = (None if self.incremental is None else self.incremental.push(
            np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros((0, 2)),
            np.zeros(0, np.int64)))
        # candidates=True: rows with one (time, camera) are a frame's candidates, gated as
        # fuse(Detections) gates them (pslog.fusion.gating.StreamGate), so the stream equals
        # fuse(detections, rig, method) with gating on
        self._gate = None
        if candidates and self.options.gating:
            from .gating import StreamGate, gating_key

            self._gate = StreamGate(rig, gating_key(method, self.options)[1], self._max_gap_s)
        # the doubt of the gate's choices, for the methods that take it: those re-run on the
        # window (their covariance holds it: stereo.doubt_covariance) and typeA's incremental
        # form (it withholds a point resting on a choice in doubt), which is told each push's
        # doubt through its innermost stream's ``next_doubt``
        self._doubts = None
        self._doubt_sink = None
        # the verdict on the session's first choice, which may come a few frames later
        # (gating.late_doubt): the gate's rows are held until it is known, then fused
        # with the doubt it gives (None: no verdict to wait for, or it has come)
        self._start = None
        if self._gate is not None and METHODS[method].uses_doubt:
            from .gating import StreamDoubt, StreamStart

            self._doubts = StreamDoubt(self._gate)
            self._start = StreamStart(self._gate, self._doubts)
            sink = self.incremental
            while sink is not None and not hasattr(sink, "next_doubt"):
                sink = getattr(sink, "inner", None)
            self._doubt_sink = sink
        # the incremental form's own path for one detection (push_one(t, c, u, v) -> Track),
        # when nothing is to reorder; and when nothing is to gate either, a push of one
        # detection goes straight to it
        self._push_one = (getattr(self.incremental, "push_one", None)
                          if not self._corrected else None)
        self._one = self._push_one if self._gate is None else None

    def push(self, time_ns, camera, uv, frame_index=None) -> Track:
        """Add detections (arrays, or scalars for one); returns the points that became settled
        (possibly none).

        Parameters
        ----------
        time_ns : int (n,), LOGGED times on the session clock, nanoseconds, in (time, camera)
            order and later than any pushed before; corrected here by the rig's clock model
        camera : int (n,), camera indices in rig order
        uv : float (n, 2), distorted pixel coordinates (``v``, the row, times a rolling shutter)
        frame_index : int (n,), optional
        """
        if self._one is not None and (one := _one_detection(time_ns, camera, uv, frame_index,
                                                              len(self.rig))) is not None:
            # one detection of the usual form (the live case): checked as below, to the
            # incremental form's own one-detection path
            if one[:2] <= self._last_logged:
                raise FusionError("StreamFuser.push: detections must arrive in (time, camera) "
                                  f"order of their logged times; got t={one[0]} ns after "
                                  f"t={self._last_logged[0]} ns")
            self._last_logged = one[:2]
            return self._one(*one)
        if self._gate is not None:  # the chosen candidates, in logged order
            pushed = (time_ns, camera, uv)
            time_ns, camera, uv, frame_index = self._gate.push(time_ns, camera, uv, frame_index)
            if self._doubts is not None:  # (its frames of several candidates: valid rows)
                t_pushed = np.atleast_1d(np.asarray(pushed[0]))
                c_pushed = np.atleast_1d(np.asarray(pushed[1]))
                self._doubts.frames(t_pushed, c_pushed)
                self._doubts.seen_frames(t_pushed, c_pushed,
                                         np.asarray(pushed[2], np.float64).reshape(-1, 2))
            if self._start is not None:  # (held until the first choice's verdict)
                time_ns, camera, uv, frame_index = self._started(time_ns, camera, uv,
                                                                 frame_index)
            return self._push_rows(time_ns, camera, uv, frame_index, self._doubt_of(
                time_ns, camera, uv))
        time_ns, camera, uv, frame_index = stream_arrays(
            time_ns, camera, uv, frame_index, len(self.rig), "StreamFuser.push")
        return self._push_rows(time_ns, camera, uv, frame_index)

    def _started(self, time_ns, camera, uv, frame_index, final: bool = False):
        """The gate's rows to fuse now (:class:`~pslog.fusion.gating.StreamStart`): none
        while the verdict on the session's first choice is open, then every held one."""
        assert self._start is not None
        rows = self._start.rows(time_ns, camera, uv, frame_index, final)
        if self._start.done:
            self._start = None
        return rows

    def _tell_doubt(self, doubt: np.ndarray | None) -> None:
        """Give the incremental form the doubt of the rows it is about to take (None, or
        all 0: none), when it takes any (``next_doubt``: typeA's)."""
        if self._doubt_sink is not None:
            self._doubt_sink.next_doubt = (None if doubt is None or not np.any(doubt)
                                           else np.asarray(doubt, np.float64))

    def _doubt_of(self, time_ns, camera, uv) -> np.ndarray | None:
        """The doubt of the gate's chosen rows (None: none in doubt, or not used)."""
        return None if self._doubts is None else self._doubts.of(time_ns, camera, uv)

    def push_frame(self, time_ns: int, camera: int, uv: np.ndarray, frame_index: int) -> Track:
        """:meth:`push` of one frame's candidates, best first, as ``pslog live`` pushes them:
        Python integers (``camera`` in the rig, ``time_ns`` and ``frame_index`` within int64:
        checked by the caller) and a (k, 2) float64 array of the caller's own (k = 0: push's). The
        same Track (and the same errors) as ``push(np.full(k, time_ns), np.full(k, camera),
        uv, np.full(k, frame_index))``, without making and checking those columns: the
        gate's decision at once and the incremental form's one-detection path where they
        apply."""
        one, gate = self._push_one, self._gate
        if one is not None and len(uv) and self._start is None:
            # (an empty frame: push's own path, which keeps no key; the session's start,
            # whose rows wait for a verdict: push's too)
            chosen = uv if gate is None else gate.push_frame(time_ns, camera, frame_index, uv)
            doubts = self._doubts if chosen is not None else None
            doubt = None
            if chosen is not None and len(chosen) == 1:
                u, v = chosen[0].tolist()
            if doubts is not None:  # (as push: its frame, then)
                if len(uv) > 1:  # (frames notes nothing of a frame of one candidate)
                    doubts.frames(np.full(len(uv), time_ns, np.int64),
                                  np.full(len(uv), camera, np.int32))
                doubts.seen_frame(time_ns, camera, uv.tolist())
                if len(chosen) == 1:  # (its one row's: of's, on Python numbers)
                    one_doubt = doubts.of_one(time_ns, camera, u, v)
                    doubt = np.array([one_doubt]) if one_doubt else None
                else:
                    doubt = doubts.of(np.full(len(chosen), time_ns, np.int64),
                                      np.full(len(chosen), camera, np.int32), chosen)
            if chosen is not None and len(chosen) <= 1:
                if not len(chosen):  # (every candidate rejected: nothing new)
                    return self._settled(final=False)
                key = (time_ns, camera)
                if key <= self._last_logged:
                    raise FusionError("StreamFuser.push: detections must arrive in (time, "
                                      f"camera) order of their logged times; got t={time_ns} "
                                      f"ns after t={self._last_logged[0]} ns")
                self._last_logged = key
                if self._doubt_sink is not None:  # (_tell_doubt's: None, or in doubt)
                    self._doubt_sink.next_doubt = doubt
                return one(time_ns, camera, u, v)
            if chosen is not None:  # (the gate kept several: the rows of push)
                c = len(chosen)
                return self._push_rows(np.full(c, time_ns, np.int64),
                                       np.full(c, camera, np.int32), chosen,
                                       np.full(c, frame_index, np.int64), doubt)
        k = len(uv)
        return self.push(np.full(k, time_ns, np.int64), np.full(k, camera, np.int32), uv,
                         np.full(k, frame_index, np.int64))

    def _push_rows(self, time_ns, camera, uv, frame_index,
                   doubt: np.ndarray | None = None) -> Track:
        """The rest of :meth:`push`: checked rows (the gate's chosen ones, with their
        doubt: None for none) into the method."""
        if len(time_ns) == 0:
            return self._settled(final=False)
        keys = ([(int(time_ns[0]), int(camera[0]))] if len(time_ns) == len(camera) == 1  # (one)
                else list(zip(time_ns.tolist(), camera.tolist(), strict=True)))
        if any(b <= a for a, b in zip([self._last_logged, *keys[:-1]], keys, strict=True)):
            raise FusionError("StreamFuser.push: detections must arrive in (time, camera) "
                              f"order of their logged times; got t={time_ns[0]} ns after "
                              f"t={self._last_logged[0]} ns")
        self._last_logged = keys[-1]
        if self.incremental is not None and not self._corrected:  # nothing to reorder
            self._tell_doubt(doubt)
            if len(time_ns) == 1 and self._push_one is not None:  # (a frame's chosen one)
                u, v = uv[0].tolist()
                return self._push_one(int(time_ns[0]), int(camera[0]), u, v)
            return self.incremental.push(time_ns, camera, uv, frame_index)
        model = self._clock_model  # true_times_ns, row by row in floats (the same ns)
        true_ns = np.array([_true_time_ns(t, v, model[c]) for t, v, c in zip(
            time_ns.tolist(), uv[:, 1].tolist(), camera.tolist(), strict=True)], np.int64)
        self._q_time = np.concatenate([self._q_time, true_ns])
        self._q_camera = np.concatenate([self._q_camera, camera])
        self._q_uv = np.concatenate([self._q_uv, uv])
        self._q_frame = np.concatenate([self._q_frame, frame_index])
        self._q_doubt = np.concatenate([self._q_doubt, np.zeros(len(time_ns)) if doubt is None
                                        else doubt])
        self._admit(final=False)
        return self._settled(final=False)

    def flush(self) -> Track:
        """Emit every remaining point (end of stream); never raises on a valid stream (an
        end with no common instant left, for the methods that need one, emits nothing)."""
        if self._gate is not None:  # the frames the gate still held, then the rest
            gate, self._gate = self._gate, None
            time_ns, camera, uv, frame_index = gate.flush()  # (checked arrays, as push's)
            if self._start is not None:  # (the rows still held: the verdict now)
                time_ns, camera, uv, frame_index = self._started(time_ns, camera, uv,
                                                                 frame_index, final=True)
            early = self._push_rows(time_ns, camera, uv, frame_index,
                                    self._doubt_of(time_ns, camera, uv))
            return Track.concat([early, self.flush()])  # every column and count of both
        self._admit(final=True)
        return self._settled(final=True)

    def _admit(self, final: bool) -> None:
        """Move the queued detections that no later push can precede into the window."""
        if self._corrected and not final:
            # the earliest corrected time a detection still to come can have: logged no
            # earlier than the last push, row >= 0 (the model is increasing in both)
            last = self._last_logged[0]
            bound = min(_true_time_ns(last, 0.0, clock) for clock in self._clock_model)
            ready = self._q_time < bound
        else:
            ready = np.ones(len(self._q_time), dtype=bool)
        if not ready.any():
            return
        order = np.flatnonzero(ready)[np.lexsort((self._q_frame[ready], self._q_camera[ready],
                                                  self._q_time[ready]))]
        time_ns, camera = self._q_time[order], self._q_camera[order]
        behind = len(self._time) > 0 and bool(
            (time_ns[0], camera[0]) <= (self._time[-1], self._camera[-1]))
        if behind or np.any((time_ns[1:] == time_ns[:-1]) & (camera[1:] == camera[:-1])):
            raise FusionError("StreamFuser.push: a corrected detection falls at or before one "
                              "already fused (a row above the image with a rolling shutter, "
                              "or two frames of a camera corrected to one nanosecond)")
        self._time = np.concatenate([self._time, time_ns])
        self._camera = np.concatenate([self._camera, camera])
        self._uv = np.concatenate([self._uv, self._q_uv[order]])
        self._frame = np.concatenate([self._frame, self._q_frame[order]])
        self._doubt = np.concatenate([self._doubt, self._q_doubt[order]])
        keep = ~ready
        self._q_time, self._q_camera = self._q_time[keep], self._q_camera[keep]
        self._q_uv, self._q_frame = self._q_uv[keep], self._q_frame[keep]
        self._q_doubt = self._q_doubt[keep]

    def _settled(self, final: bool) -> Track:
        if self.incremental is not None:  # it keeps its own state: feed the new rows once
            f = self._fed
            ends = final and hasattr(self.incremental, "flush")  # (points it still holds)
            if f == len(self._time):  # nothing new (a frame the gate or the queue holds)
                if ends:
                    return _joined(cast(Track, self._nothing), self.incremental.flush())
                return cast(Track, self._nothing)  # set whenever incremental is
            self._tell_doubt(self._doubt[f:])
            out = self.incremental.push(self._time[f:], self._camera[f:], self._uv[f:],
                                        self._frame[f:])
            if ends:
                out = _joined(out, self.incremental.flush())
            self._time, self._camera = self._time[-1:], self._camera[-1:]
            self._uv, self._frame = self._uv[-1:], self._frame[-1:]
            self._doubt = self._doubt[-1:]
            self._fed = len(self._time)
            return out
        if len(self._time) == 0:
            return _empty(self.method)
        obs = Observations(self._time, self._camera, self._uv, self._frame)
        if not self._immediate and not np.any(
                sync_groups(obs, len(self.rig), self.options.tolerance_s)[1] >= 2):
            # no common instant in the window (yet, or any more: a synchronised camera lost
            # the ball): no point, which on a valid stream is no error, even at the end
            track, dropped = _empty(self.method), {}
        else:
            prepared = prepare(obs, self.rig, self._F, head=self._head)
            jac = prepared.uv_jacobian  # (always made by prepare)
            self._head = (None if jac is None
                          else (prepared.uv_undistorted, prepared.ray_dir, jac))
            if np.any(self._doubt > 0):  # (the gate's choices in doubt: as the batch's)
                prepared = replace(prepared, doubt_px2=self._doubt.copy())
            # fuse's method on the window (the options resolved as fuse resolves them), with
            # the dropped points' times: the window re-fuses points already counted
            drops: Drops = []
            track = self._function(prepared, self.rig, self._resolved, drops=drops)
            dropped = self._settled_drops(drops, final)
        newest = int(self._time[-1])
        key_t, key_c = self._emitted_until
        new = (track.time_ns > key_t) | ((track.time_ns == key_t) & (track.camera > key_c))
        if not final and self._settle_ns:
            new &= track.time_ns < newest - self._settle_ns
        out = track.select(new)
        if dropped:  # (select keeps no counts: the settled drops')
            out = replace(out, dropped=dropped)
        if len(out):
            self._emitted_until = (int(out.time_ns[-1]), int(out.camera[-1]))
        # keep only the history the next points can reach, cut at the start of a group
        cut = self._cut_row(obs, newest - self._history_ns - self._settle_ns)
        self._time, self._camera = self._time[cut:], self._camera[cut:]
        self._uv, self._frame = self._uv[cut:], self._frame[cut:]
        self._doubt = self._doubt[cut:]
        if self._head is not None:
            self._head = (self._head[0][cut:], self._head[1][cut:], self._head[2][cut:])
        return out

    def _settled_drops(self, drops: Drops, final: bool) -> dict[str, int]:
        """The counts by reason of the window's dropped points (``drops``: the method's
        :data:`~pslog.fusion.stereo.Drops` on the window) that became settled with this push,
        as its points do (after the last counted, and, for the methods that wait for the
        tolerance, before the newest row less it; every one on ``final``): each drop counted
        once, at the push that settles it, so the stream's counts summed are the batch's."""
        key_t, key_c = self._counted_until
        newest = int(self._time[-1])
        bound = newest - self._settle_ns
        counts: dict[str, int] = {}
        for reason, time_ns, camera in drops:
            on = (time_ns > key_t) | ((time_ns == key_t) & (camera > key_c))
            if not final and self._settle_ns:
                on &= time_ns < bound
            n = int(np.count_nonzero(on))
            if n:
                counts[reason] = counts.get(reason, 0) + n
        if self._settle_ns:  # (every drop before the bound is settled: counted now)
            self._counted_until = max(self._counted_until, (bound - 1, np.iinfo(np.int32).max))
        else:  # (every drop at or before the newest row)
            self._counted_until = (newest, int(self._camera[-1]))
        return counts

    def _cut_row(self, obs: Observations, reach_ns: int) -> int:
        """First row of the window to keep: the start of the latest sync group starting at
        or before ``reach_ns`` (the earliest time a point still to emit can use), 0 if none.

        Cutting at a time alone is not enough: :func:`~pslog.fusion.stereo.sync_groups`
        groups greedily from the start of each run of detections closer than the tolerance,
        and at several unsynchronised cameras such a run can last the whole session, so a
        window starting inside a group splits it, and every later group of the run (a common
        instant that is not one, or a lone detection that was not alone) shifts with it: a
        stereo point, and so a ``typeB`` / ``linear`` point, that batch does not make.

        The greedy grouping is causal (a group's start depends only on the detections before
        it), so a window starting at a group start of the batch grouping groups its rows
        exactly as the batch does; by induction, every window does. A group spans at most the
        tolerance, so a point at ``t`` that uses a group within ``max_gap_s`` (its time at
        most ``tolerance`` after the group's start) finds it whole in the window, which keeps
        ``tolerance`` more than ``max_gap_s + tolerance`` at most.
        """
        if not len(obs) or int(obs.time_ns[0]) > reach_ns:
            return 0
        group = sync_groups(obs, len(self.rig), self.options.tolerance_s)[0]
        starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
        latest = int(np.searchsorted(obs.time_ns[starts], reach_ns, side="right")) - 1
        return int(starts[latest])


def _one_detection(time_ns, camera, uv, frame_index, n_cameras: int
                   ) -> tuple[int, int, float, float] | None:
    """``(time, camera, u, v)`` as Python numbers when a push is one detection in a usual
    form, valid as :func:`~pslog.fusion.gating.stream_arrays` checks it: integer scalars
    (time within int64, camera in the rig) and a pair of floats (a sequence, or a (2,) or
    (1, 2) float64 array), or one-row integer arrays and a (1, 2) float64 array;
    ``frame_index`` None or an integer of the same form. None otherwise: the general path
    converts the push, or names what is wrong with it."""
    if isinstance(time_ns, int | np.integer) and isinstance(camera, int | np.integer):
        t, c = int(time_ns), int(camera)
        if frame_index is not None and not (isinstance(frame_index, int | np.integer)
                                            and -2**63 <= frame_index < 2**63):
            return None
        if type(uv) is np.ndarray:
            if uv.dtype != np.float64 or uv.size != 2 or uv.ndim > 2 or uv.shape[-1] != 2:
                return None
            u, v = uv.reshape(2).tolist()
        elif type(uv) in (list, tuple) and len(uv) == 2 and isinstance(uv[0], float) \
                and isinstance(uv[1], float):
            u, v = float(uv[0]), float(uv[1])
        else:
            return None
    elif (type(time_ns) is np.ndarray and type(camera) is np.ndarray and type(uv) is np.ndarray
          and time_ns.shape == (1,) and camera.shape == (1,) and uv.shape == (1, 2)
          and time_ns.dtype.kind == "i" and camera.dtype.kind == "i"
          and uv.dtype == np.float64):
        if frame_index is not None and not (type(frame_index) is np.ndarray
                                            and frame_index.shape == (1,)
                                            and frame_index.dtype.kind == "i"):
            return None
        t, c = int(time_ns[0]), int(camera[0])
        u, v = uv[0].tolist()
    else:
        return None
    if not (0 <= c < n_cameras and -2**63 <= t < 2**63):
        return None
    return t, c, u, v


def _joined(first: Track, last: Track) -> Track:
    """``first`` then ``last`` (:meth:`Track.concat`), ``first`` itself (its columns, and
    ``last``'s dropped counts added) when ``last`` has no point: concat would add the
    columns of an empty ``last`` that ``first`` lacks, NaN over ``first``'s points."""
    if len(last):
        return Track.concat([first, last])
    if not last.dropped:
        return first
    dropped = dict(first.dropped)
    for k, n in last.dropped.items():
        dropped[k] = dropped.get(k, 0) + n
    return replace(first, dropped=dropped)


def _empty(method: str) -> Track:
    return Track(method, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32))
