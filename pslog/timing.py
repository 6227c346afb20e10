"""The timing model: when a detection was really captured, from when it was logged.

THE model (every part of pslog that corrects times uses the functions below)::

    true time = logged + clock_offset_c + clock_drift_ppm_c * 1e-6 * (logged - session start)
                + readout_c * v / height_c

for a detection of camera ``c`` at distorted pixel row ``v`` (0 = top row), logged at time
``logged`` on the session clock:

- ``session start`` is 0 on the session clock (the session's times are counted from it), so
  the drift term is ``clock_drift_ppm * 1e-6 * logged``.
- The first camera of a rig defines the session clock: its ``clock_offset`` and
  ``clock_drift_ppm`` are 0 (:class:`~pslog.rig.Rig` enforces it). ``readout`` (rolling
  shutter, top row to bottom row, seconds; 0 = global shutter) is per camera, the first one
  included. A frame's logged time refers to its top row.
- The parameters are the rig's optional camera keys ``clock_offset`` (s),
  ``clock_drift_ppm`` and ``readout`` (s). Recorded log times are never rewritten: readers
  apply the correction (:func:`observations`), so a session can be re-synchronised at will.

Host timestamps that jitter (a frame stamped when it reached the host) are a separate matter:
:func:`regularize_times` replaces them by a robust straight-line fit against frame index.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import InputError, PslogError
from .records import NS, Detections, Observations
from .rig import Rig

#: ``pslog sync --regularize auto`` regularizes a camera's stamps when the robust jitter
#: around the line (:attr:`Regularization.jitter_s`) is above this, seconds.
REGULARIZE_AUTO_JITTER_S = 0.2e-3
#: Times between frames beyond this multiple of the robust residual scale are outliers.
_OUTLIER_SCALES = 5.0
#: Smallest residual ever called an outlier, seconds: stamps rounded to a microsecond (or a
#: perfectly regular clock, MAD 0) are not outliers for their rounding.
_OUTLIER_FLOOR_S = 2e-6
#: 1.4826 * MAD is the standard deviation of Gaussian residuals.
_MAD_TO_STD = 1.4826


def _broadcast(logged, v_px, height, clock_offset_s, drift_ppm, readout_s):
    return np.broadcast_arrays(
        np.asarray(logged), np.asarray(v_px, dtype=np.float64),
        np.asarray(height, dtype=np.float64), np.asarray(clock_offset_s, dtype=np.float64),
        np.asarray(drift_ppm, dtype=np.float64), np.asarray(readout_s, dtype=np.float64))


def true_times_ns(logged_ns, v_px, height, clock_offset_s, drift_ppm, readout_s) -> np.ndarray:
    """True capture times of detections from their logged times, by the timing model.

    ``true = logged + clock_offset + drift_ppm * 1e-6 * logged + readout * v / height``
    (module docstring; session start = 0 on the session clock).

    Parameters
    ----------
    logged_ns : int array (n,), logged times on the session clock, nanoseconds
    v_px : float array (n,), the detection's distorted pixel row (0 = top)
    height : array (n,) or scalar, image height of the detection's camera, pixels
    clock_offset_s : array (n,) or scalar, seconds
    drift_ppm : array (n,) or scalar, parts per million
    readout_s : array (n,) or scalar, rolling-shutter readout (top to bottom row), seconds

    All arguments broadcast (per-observation camera parameters allowed).

    Returns
    -------
    (n,) int64 nanoseconds: the logged time plus the correction rounded to the nearest
    nanosecond (the correction is computed in float64 on its own, so large logged times
    lose no precision).
    """
    logged, v, h, off, drift, readout = _broadcast(logged_ns, v_px, height, clock_offset_s,
                                                   drift_ppm, readout_s)
    logged = logged.astype(np.int64)
    correction = off * NS + drift * 1e-6 * logged.astype(np.float64) + _readout_ns(readout, v, h)
    return logged + np.rint(correction).astype(np.int64)


def _readout_ns(readout, v, h) -> np.ndarray:
    """``readout * v / height`` in ns; 0 for a global shutter whatever ``v`` (even NaN)."""
    with np.errstate(invalid="ignore"):
        term = np.where(readout != 0, readout * NS * v / h, 0.0)
    if not np.all(np.isfinite(term)):
        raise InputError("a rolling-shutter time needs the detection's pixel row: got a "
                         "non-finite row")
    if np.any(np.abs(term) > MAX_READOUT_TERM_NS):
        far = float(np.broadcast_to(v, np.shape(term))[np.argmax(np.abs(term))])
        raise InputError(f"a rolling-shutter time needs the detection's pixel row: got row "
                         f"{far:g}, far outside the image")
    return term


#: The largest rolling-shutter term (ns) a detection's row may give: a row further out is no
#: pixel of the image (1e18 ns, ~32 years, keeps every corrected time within int64)
MAX_READOUT_TERM_NS = 1e18


def true_times_s(logged_s, v_px, height, clock_offset_s, drift_ppm, readout_s) -> np.ndarray:
    """:func:`true_times_ns` in float seconds (for estimators), shapes as there.

    ``true = logged + clock_offset + drift_ppm * 1e-6 * logged + readout * v / height``.
    Derivatives (see :func:`clock_jacobian`): d/d clock_offset = 1,
    d/d drift_ppm = 1e-6 * logged_s, d/d readout = v / height (seconds per second of
    readout); d/d v = readout / height.
    """
    logged, v, h, off, drift, readout = _broadcast(logged_s, v_px, height, clock_offset_s,
                                                   drift_ppm, readout_s)
    logged = logged.astype(np.float64)
    return logged + off + drift * 1e-6 * logged + readout * v / h


def clock_jacobian(logged_s, v_px, height) -> np.ndarray:
    """Derivatives of :func:`true_times_s` with respect to ``(clock_offset_s, drift_ppm,
    readout_s)``, shape (n, 3): ``[1, 1e-6 * logged_s, v / height]`` per detection (the model
    is linear in its parameters, so these do not depend on them)."""
    logged, v, h = np.broadcast_arrays(np.asarray(logged_s, dtype=np.float64),
                                       np.asarray(v_px, dtype=np.float64),
                                       np.asarray(height, dtype=np.float64))
    return np.stack([np.ones_like(logged), 1e-6 * logged, v / h], axis=-1)


def logged_times_ns(true_ns, v_px, height, clock_offset_s, drift_ppm,
                    readout_s) -> np.ndarray:
    """The exact inverse of :func:`true_times_ns`: the logged times (int64 ns) whose true
    times are ``true_ns`` (for the simulator), shapes as there.

    ``logged = (true - clock_offset - readout * v / height) / (1 + drift_ppm * 1e-6)``,
    then corrected so that ``true_times_ns(logged_times_ns(t, ...), ...) == t`` to the
    nanosecond (off by at most 1 ns only where a positive drift makes the forward map step
    over a nanosecond: ``1 + drift * 1e-6`` true ns per logged ns).
    """
    true, v, h, off, drift, readout = _broadcast(true_ns, v_px, height, clock_offset_s,
                                                 drift_ppm, readout_s)
    true = true.astype(np.int64)
    rate = 1.0 + drift * 1e-6
    fixed = off * NS + _readout_ns(readout, v, h)
    # logged - true, small: computed apart from the (possibly large) times themselves
    delta = -(fixed + drift * 1e-6 * true.astype(np.float64)) / rate
    logged = true + np.rint(delta).astype(np.int64)
    for _ in range(3):  # rounding may leave the forward map 1 ns off: step onto it
        miss = true - true_times_ns(logged, v, h, off, drift, readout)
        if not np.any(miss):
            break
        logged = logged + miss
    return logged


def camera_parameters(rig: Rig) -> dict[str, np.ndarray]:
    """Per camera of ``rig`` (rig order): ``height`` (px), ``clock_offset`` (s),
    ``clock_drift_ppm``, ``readout`` (s), each an array (n_cameras,) float64."""
    return {key: np.array([float(getattr(c, key)) for c in rig.cameras])
            for key in ("height", "clock_offset", "clock_drift_ppm", "readout")}


def observations(detections: Detections, rig: Rig) -> Observations:
    """The fusion input of a session: the best candidate of every frame (as
    :meth:`~pslog.records.Detections.best`) at its true time by the rig's timing model.

    Each observation's time is corrected by its camera's ``clock_offset``,
    ``clock_drift_ppm`` and ``readout`` (:func:`true_times_ns`, ``v`` = the candidate's
    pixel row), then the observations are sorted again by (time, camera). If two
    observations of one camera land on the same nanosecond (possible only with parameters
    no real camera has, e.g. rows far outside the image), the later frame (by frame index)
    is moved on by 1 ns until every (time, camera) is unique: deterministic, and nothing
    dropped. With every clock parameter 0 this is exactly ``detections.best()``.

    Raises
    ------
    InputError if a correction is to be applied and the detections' cameras are not the
    rig's (names and order).
    """
    best = detections.best()
    # no correction: exactly .best(), whatever the rig (fusion checks the cameras itself)
    if not any(c.has_clock_correction for c in rig.cameras) or len(best) == 0:
        return best
    if tuple(detections.camera_names) != rig.names:
        raise InputError(f"detections of cameras {', '.join(detections.camera_names)} do not "
                         f"match the rig's {', '.join(rig.names)} (names and order)")
    p = camera_parameters(rig)
    cam = best.camera
    time_ns = true_times_ns(best.time_ns, best.uv[:, 1], p["height"][cam],
                            p["clock_offset"][cam], p["clock_drift_ppm"][cam],
                            p["readout"][cam])
    frame_index, uv = best.frame_index, best.uv
    while True:  # terminates: each pass moves the repeats strictly later
        order = np.lexsort((frame_index, cam, time_ns))
        time_ns, cam, frame_index, uv = time_ns[order], cam[order], frame_index[order], uv[order]
        repeat = np.zeros(len(time_ns), dtype=bool)
        repeat[1:] = (time_ns[1:] == time_ns[:-1]) & (cam[1:] == cam[:-1])
        if not repeat.any():
            return Observations(time_ns, cam, uv, frame_index)
        time_ns = time_ns + repeat.astype(np.int64)



#: ``pslog sync`` writes the shutter offsets it measures (:func:`shutter_phases`) where a
#: camera's is further than this share of its frame period from the rig's (a plan met
#: within it, e.g. a type-A stagger within the clocks' error, is kept as the rig says it)
PHASE_AGREE = 0.05
#: ... or further than this, seconds, whichever is less (2 ms: ``pslog info``'s, ``record``'s
#: and ``import``'s note of shutters off the rig's offsets, ``pslog.log.info.OFFSET_NOTE_S``,
#: which names ``pslog sync``: below 40 fps 5 % of a period is more, and a sync that kept
#: offsets those notes call off left them saying so again; review48)
PHASE_AGREE_MAX_S = 2e-3
#: ... provided every camera's frames keep one phase: a circular standard deviation of at
#: most this share of the frame period (a frame rate off its nominal one walks the phase
#: through the session; host stamps left jittery spread it)
PHASE_SPREAD = 0.02
#: ... and every camera has at least this many frames
PHASE_MIN_FRAMES = 30


@dataclass(frozen=True)
class ShutterPhases:
    """:func:`shutter_phases`' result, per camera in rig order.

    Attributes
    ----------
    offset_s : (n,) float64 seconds in [0, frame period): where in its frame period each
        camera's shutter fires on the session's true clock, the first camera's placed at the
        rig's offset (only differences between cameras are measured; NaN: no frame, or the
        first camera has none)
    spread_s : (n,) float64 seconds, the circular standard deviation of the frames' phases
        around ``offset_s`` (NaN: no frame)
    frames : (n,) int64, the frames measured
    """

    offset_s: np.ndarray
    spread_s: np.ndarray
    frames: np.ndarray

    def writable(self, rig: Rig) -> bool:
        """Whether the phases are measured well enough to stand for the rig's offsets: every
        camera has :data:`PHASE_MIN_FRAMES` frames whose phases spread at most
        :data:`PHASE_SPREAD` of its frame period."""
        period = np.array([c.frame_period for c in rig.cameras])
        return bool(np.all(self.frames >= PHASE_MIN_FRAMES)
                    and np.all(self.spread_s <= PHASE_SPREAD * period))

    def disagree(self, rig: Rig) -> bool:
        """Whether some camera's measured offset is further than :data:`PHASE_AGREE` of its
        frame period, or :data:`PHASE_AGREE_MAX_S` if less, from the rig's ``offset``
        (circularly: 0.1 ms and a period minus 0.1 ms are 0.2 ms apart)."""
        period = np.array([c.frame_period for c in rig.cameras])
        planned = np.array([c.offset for c in rig.cameras])
        miss = (self.offset_s - planned + period / 2) % period - period / 2
        return bool(np.any(np.abs(miss) > np.minimum(PHASE_AGREE * period,
                                                     PHASE_AGREE_MAX_S)))

    def rig(self, rig: Rig) -> Rig:
        """``rig`` with each camera's ``offset`` the measured one, to the nanosecond (the
        session clock's unit: a rig file reads 0.007226951, not 0.007226950999999249; a NaN
        keeps the rig's)."""
        cameras = []
        for cam, offset in zip(rig.cameras, self.offset_s.tolist(), strict=True):
            if np.isfinite(offset):
                offset = round(offset, 9)
                # (within [0, period): a float's modulo, or the rounding, can reach the
                # period itself)
                cam = cam.replace(offset=offset if offset < cam.frame_period else 0.0)
            cameras.append(cam)
        return Rig(tuple(cameras), rig.name)


def shutter_phases(frame_time_ns: np.ndarray, frame_camera: np.ndarray,
                   rig: Rig) -> ShutterPhases:
    """Each camera's shutter offset, measured from its frames' times on the true clock.

    A frame's logged time is its top row's, so its true time is :func:`true_times_ns` at row
    0 (the readout adds nothing there), then scaled about the earliest so that the first
    camera's frames keep its nominal rate (:data:`RATE_SCALE_MAX`: a rate common to every
    camera off the nominal one leaves the phases' differences, and walks each phase).
    Camera ``c``'s frames fire at ``offset_c + k / fps_c``
    (the rig's ``offset``, the simulator's shutter): each frame's phase is its true time
    modulo the frame period ``T_c``, an angle ``θ = 2π (t mod T_c) / T_c``, and the phase is
    their circular mean ``T_c / 2π · arg(Σ exp(iθ))`` (a phase that wraps, frames at 0.1 ms
    and ``T_c`` − 0.1 ms, averages to 0, not to ``T_c / 2``), its spread the circular
    standard deviation ``T_c / 2π · sqrt(−2 ln R̄)``, ``R̄ = |mean exp(iθ)|`` (Mardia & Jupp,
    *Directional Statistics*, 2000, §2.3). Only differences between cameras are measured
    (the session clock's zero is arbitrary): every phase is moved by one time so that the
    first camera's is the rig's offset (as ``pslog info`` places it); with cameras of other
    rates, that time is known only up to whole periods of the first camera, each giving the
    same schedule, and the one that puts the phases nearest the rig's offsets is taken.

    Parameters
    ----------
    frame_time_ns : (m,) int64, every frame's logged time (ns, session clock), as
        :attr:`~pslog.records.Detections.frame_time_ns`
    frame_camera : (m,) int, each frame's camera index in ``rig`` order
    rig : Rig, whose clock model corrects the times and whose ``fps`` gives each period

    Returns
    -------
    ShutterPhases
    """
    t = np.asarray(frame_time_ns, dtype=np.int64)
    cam = np.asarray(frame_camera, dtype=np.int64)
    n = len(rig)
    offset, spread = np.full(n, np.nan), np.full(n, np.nan)
    frames = np.bincount(cam, minlength=n)[:n].astype(np.int64) if len(cam) else \
        np.zeros(n, dtype=np.int64)
    if not len(t):
        return ShutterPhases(offset, spread, frames)
    p = camera_parameters(rig)
    true = true_times_ns(t, 0.0, p["height"][cam], p["clock_offset"][cam],
                         p["clock_drift_ppm"][cam], p["readout"][cam])
    ref = int(true.min())  # (differences from it are small: float64 keeps them to < 1 ns)
    # on the first camera's frame clock: its frames at its nominal rate, every camera's
    # time scaled alike (cameras of one model on one host clock run a common few hundred
    # ppm off their nominal rate; their phases keep their differences, which are what the
    # schedule's gaps are made of, while each walks against the nominal period: three
    # cameras at 29.99 fps in 30 s spread 2.93 ms each, and no phase was written)
    rel = (true - ref).astype(np.float64) / NS * _rate_scale(
        np.sort(true[cam == 0]), rig.cameras[0].frame_period)
    for c, camera in enumerate(rig.cameras):
        rows = cam == c
        if not rows.any():
            continue
        period = camera.frame_period
        # the reference's own phase, so that cameras of other rates share one origin (an
        # epoch-sized reference is a float64 to ~0.3 µs: below anything this decides)
        base = float(np.fmod(ref / NS, period))
        angle = 2 * np.pi * np.mod(base + rel[rows], period) / period
        mean = np.mean(np.exp(1j * angle))
        offset[c] = (np.angle(mean) / (2 * np.pi) * period) % period
        spread[c] = np.sqrt(-2 * np.log(min(abs(mean), 1.0))) / (2 * np.pi) * period
    if np.isfinite(offset[0]):
        periods = np.array([c.frame_period for c in rig.cameras])
        # (the nearest such time: a first camera measured a hair below its period's end,
        # 33.33 ms for 0, moved by a whole period of its own, 33.37 µs at 29.97 fps)
        shift = (rig.cameras[0].offset - offset[0] + periods[0] / 2) % periods[0] \
            - periods[0] / 2
        planned = np.array([c.offset for c in rig.cameras])
        # cameras of other rates: the first camera's frames fix the clock's zero only up to
        # whole periods of its own (a type-A plan of 60, 30 and 30 fps read 0, 27.8 and 5.6
        # ms against the plan's 0, 11.1 and 22.2 when the session's zero fell on the odd 60
        # fps frame): nearest_schedule
        miss = nearest_schedule(offset + shift - planned, periods,
                                [c.fps for c in rig.cameras])
        offset = np.mod(planned + miss, periods)
        offset[0] = rig.cameras[0].offset  # (by definition, not a float's sum)
        offset[offset >= periods] = 0.0  # (a modulo of a hair below 0 rounds to the period)
    else:
        offset[:] = np.nan
    return ShutterPhases(offset, spread, frames)


def nearest_schedule(miss_s: np.ndarray, periods: np.ndarray, fps) -> np.ndarray:
    """Measured minus planned shutter offsets ``miss_s`` (n,) s, moved by the whole number
    of the first camera's periods that puts every camera nearest its plan.

    The first camera's frames fix the clock's zero only up to whole periods of its own, and
    a shift by one moves the phase of a camera of another rate (a 60 fps camera's period is
    half a 30 fps one's): every such shift gives the same schedule (the same gaps between
    shutter instants). The shifts tried are the :func:`rate_shifts` of ``fps`` (one for
    cameras of one rate); of them, the one whose largest circular miss, in each camera's
    periods ``periods`` (n,) s, is least (NaN misses ignored). :func:`shutter_phases` and
    :func:`pslog.log.info.timing_table` measure offsets so."""
    k = np.arange(rate_shifts(fps), dtype=np.float64)[:, None]
    trial = miss_s[None, :] + k * periods[0]  # (K, n)
    with np.errstate(invalid="ignore"):
        wrapped = np.abs((trial + periods / 2) % periods - periods / 2) / periods
    return trial[int(np.argmin(np.max(np.where(np.isfinite(wrapped), wrapped, 0.0),
                                      axis=1)))]


#: :func:`shutter_phases` puts the times on the first camera's frame clock where its
#: measured frame period is within this share of its nominal one (further: another rate
#: than the rig's, e.g. frames dropped in a pattern; the times are kept)
RATE_SCALE_MAX = 0.01


def _rate_scale(times_ns: np.ndarray, period: float) -> float:
    """``period`` over the frame period the first camera's sorted times ``times_ns`` (k,)
    int64 keep (:func:`pslog.log.info.measure_timing`: robust to dropped frames and
    jitter), 1.0 where they are too few (:data:`PHASE_MIN_FRAMES`) or the ratio is further
    than :data:`RATE_SCALE_MAX` from 1."""
    from .log.info import measure_timing

    if len(times_ns) < PHASE_MIN_FRAMES:
        return 1.0
    ratio = period / measure_timing(times_ns)[0]
    return float(ratio) if abs(ratio - 1.0) <= RATE_SCALE_MAX else 1.0


#: the largest denominator of a ratio of two frame rates that :func:`rate_shifts` takes for
#: one (60/30, 30/25 = 6/5, 29.97/23.976 = 5/4, 25/120 = 5/24); rates of no such ratio, to
#: 1e-9, beat (29.97 beside 30, 999/1000: their instants pass through one another over 33
#: s) and are measured from the session clock's zero, the schedule of the session's start
_MOST_SHIFTS = 100


def rate_shifts(fps) -> int:
    """How many shifts by whole periods of the first camera give other phases to the other
    cameras (``fps``: (n,) each camera's frame rate, the first camera's first): the least
    common multiple of the denominators of ``fps_c / fps_0`` (1 for one frame rate, 2 for 30
    fps beside a 60 fps first camera, 5 for 30 beside 25), over the rates in a ratio of
    denominator up to :data:`_MOST_SHIFTS` (others beat: 1)."""
    from fractions import Fraction
    from math import lcm

    first = float(fps[0])
    count = 1
    for rate in fps[1:]:
        exact = float(rate) / first
        ratio = Fraction(exact).limit_denominator(_MOST_SHIFTS)
        if abs(float(ratio) - exact) <= 1e-9 * exact:
            count = min(lcm(count, ratio.denominator), 100 * _MOST_SHIFTS)
    return count


#: Session metadata key (docs/log-format.md) where ``pslog sync`` stores each estimate with
#: its standard deviation: JSON ``{"cameras": {name: {"clock_offset": [value, std],
#: "clock_drift_ppm": [value, std], "readout": [value, std]}}, "estimated": [names],
#: "selection": [tests] or null, "covariance": {"parameters": [[name, key], ...],
#: "matrix": [[...], ...]}}`` (s, ppm, s; ``selection``: ``--estimate auto``'s Wald
#: tests, as ``pslog sync --json`` prints them; ``covariance``: the estimates' joint
#: covariance, the offsets' correlations included, in the units of each key; written since
#: session 34, older sessions have the standard deviations alone).
CLOCK_STD_KEY = "clock_std"
CLOCK_KEYS = ("clock_offset", "clock_drift_ppm", "readout")


def clock_std_json(rig: Rig, stds, estimated=None, selection=None,
                   covariance: ClockCovariance | None = None, prior: Rig | None = None,
                   prior_estimated: bool = False) -> str:
    """The :data:`CLOCK_STD_KEY` value for ``rig`` (holding the estimates) and ``stds``, one
    ``(offset_std_s, drift_std_ppm, readout_std_s)`` per camera in rig order; with
    ``estimated`` (the parameters estimated), ``selection`` (``--estimate auto``: its
    tests, as ``pslog sync --json`` prints them), ``covariance`` (a
    :class:`ClockCovariance`: the estimates' joint covariance,
    :meth:`pslog.estimation.sync.SyncResult.clock_covariance`) and ``prior`` (the rig whose
    clock model the sync started from and tested against: the recorded one,
    :func:`recorded_clocks`) those too; ``prior_estimated``: that model holds an older sync's
    estimates (``pslog.api.SyncOutcome.prior_estimated``), recorded so later syncs say it."""
    import json

    value: dict = {"cameras": {
        cam.name: {key: [float(getattr(cam, key)), float(std)]
                   for key, std in zip(CLOCK_KEYS, row, strict=True)}
        for cam, row in zip(rig.cameras, stds, strict=True)}}
    if estimated is not None:
        value["estimated"] = list(estimated)
    if selection is not None:
        value["selection"] = selection
    if prior is not None:
        value["prior"] = {cam.name: {key: float(getattr(cam, key)) for key in CLOCK_KEYS}
                          for cam in prior.cameras}
        if prior_estimated:
            value["prior_estimated"] = True
    if covariance is not None:
        value["covariance"] = {
            "parameters": [[rig.cameras[c].name, CLOCK_KEYS[p]]
                           for c, p in zip(covariance.camera, covariance.parameter,
                                           strict=True)],
            "matrix": covariance.matrix.tolist()}
    return json.dumps(value)


def recorded_clocks(rig: Rig, metadata,
                    keys: tuple[str, ...] = CLOCK_KEYS) -> tuple[Rig, bool]:
    """``rig`` with the clock model it had before ``pslog sync`` estimated it: each clock
    parameter among ``keys`` (of :data:`CLOCK_KEYS`: those the new sync estimates, or tests)
    whose value is still the one a sync stored (:data:`CLOCK_STD_KEY`) takes the value that
    sync started from (its ``prior``, written since session 38, carried from sync to sync);
    a value changed since (a rig edited by hand) stays, and so does one the new sync does not
    estimate (``--estimate readout`` of a copy synced for its offsets keeps those offsets:
    put back, they were lost, the readouts fitted at offsets 0; session 38's review). And
    whether any was replaced. ``rig`` itself (False) for a session never synced, synced
    before session 38, or whose metadata is malformed (it is informative only).

    A synced copy synced again starts here: the first sync's estimates are the same data's,
    so holding them as the rig's known values (tested against, kept exact where a test does
    not reject) dropped their uncertainty (session 38: the readouts of a tied sync kept with
    σ 0, smooth's NEES 1.35 -> 3.41, paper3, seed 57310); from the recorded model the second
    sync is the first one (docs/timing.md, "Syncing a synced copy")."""
    import json

    text = metadata.get(CLOCK_STD_KEY)
    if not text:
        return rig, False
    try:
        stored = json.loads(text)
        prior, cams = stored["prior"], stored["cameras"]
        new, changed = [], False
        for cam in rig.cameras:
            values = {}
            for key in keys:
                held = cams.get(cam.name, {}).get(key)
                if held is not None and float(held[0]) == getattr(cam, key) \
                        and cam.name in prior:
                    values[key] = float(prior[cam.name][key])
            changed |= any(values[k] != getattr(cam, k) for k in values)
            new.append(cam.replace(**values) if values else cam)
        return (Rig(tuple(new), rig.name), True) if changed else (rig, False)
    except (ValueError, TypeError, KeyError, IndexError, AttributeError, PslogError):
        return rig, False


def read_clock_std(rig: Rig, metadata) -> list[dict[str, float]] | None:
    """Per camera of ``rig`` (rig order), the standard deviation of each clock parameter
    stored under :data:`CLOCK_STD_KEY`, for the parameters whose stored value is still the
    rig's (a rig changed since, e.g. ``pslog fuse --rig``, has no std for what changed).
    None when the key is absent or malformed (it is informative only)."""
    import json

    text = metadata.get(CLOCK_STD_KEY)
    if not text:
        return None
    try:
        cams = json.loads(text)["cameras"]
        out = []
        for cam in rig.cameras:
            stored = cams.get(cam.name, {})
            out.append({key: float(stored[key][1]) for key in CLOCK_KEYS
                        if key in stored and float(stored[key][0]) == getattr(cam, key)})
        return out
    except (ValueError, TypeError, KeyError, IndexError, AttributeError):
        return None


@dataclass(frozen=True, eq=False)
class ClockCovariance:
    """The joint covariance of a rig's estimated clock parameters (``pslog sync``'s, read
    from a session by :func:`read_clock_covariance`): what the fused points' consider
    covariance takes (:mod:`pslog.fusion.clock`).

    Attributes
    ----------
    camera : (k,) int64, rig index of each parameter's camera
    parameter : (k,) int64, which parameter: index into :data:`CLOCK_KEYS` (0
        ``clock_offset`` s, 1 ``clock_drift_ppm`` ppm, 2 ``readout`` s)
    matrix : (k, k) float64, their covariance in those units (symmetric, finite, positive
        semi-definite)
    """

    camera: np.ndarray
    parameter: np.ndarray
    matrix: np.ndarray

    def __post_init__(self) -> None:
        camera = np.asarray(self.camera, dtype=np.int64).reshape(-1)
        parameter = np.asarray(self.parameter, dtype=np.int64).reshape(-1)
        matrix = np.asarray(self.matrix, dtype=np.float64)
        k = len(camera)
        if len(parameter) != k or matrix.shape != (k, k):
            raise InputError(f"clock covariance: {k} cameras, {len(parameter)} parameters "
                             f"and a {matrix.shape} matrix do not match")
        if np.any(parameter < 0) or np.any(parameter >= len(CLOCK_KEYS)) or np.any(camera < 0):
            raise InputError(f"clock covariance: parameters {parameter.tolist()} of cameras "
                             f"{camera.tolist()}: a parameter is 0, 1 or 2 of a rig camera")
        # symmetric to 1e-9 of the correlation: pslog sync's T Σ Tᵀ is symmetric to ~1e-14
        # of σ_i σ_j, but an entry near 0 (correlation 5e-6) can differ from its transpose by
        # 2e-9 of itself, which a test relative to each entry refused (and a fuse then took
        # the clocks as exact, without a word)
        if not np.all(np.isfinite(matrix)) or (
                k and np.abs(_correlation(matrix)[0] - _correlation(matrix.T)[0]).max() > 1e-9):
            raise InputError("clock covariance: the matrix must be finite and symmetric")
        # (judged on the correlations: the units (s², ppm², s·ppm) are ~1e10 apart, so a
        # tolerance relative to the largest entry would pass an indefinite offsets' block)
        if k and (np.any(np.diag(matrix) < 0)
                  or np.linalg.eigvalsh(_correlation(matrix)[0]).min() < -1e-9):
            raise InputError("clock covariance: the matrix is not positive semi-definite")
        object.__setattr__(self, "camera", camera)
        object.__setattr__(self, "parameter", parameter)
        object.__setattr__(self, "matrix", (matrix + matrix.T) / 2)

    def __len__(self) -> int:
        return len(self.camera)

    def __eq__(self, other: object) -> bool:
        # by value, as FusionOptions (frozen, hashable) compares and hashes its fields: the
        # dataclass's own compared arrays (ValueError) and could not hash them (TypeError)
        if not isinstance(other, ClockCovariance):
            return NotImplemented
        return (np.array_equal(self.camera, other.camera)
                and np.array_equal(self.parameter, other.parameter)
                and np.array_equal(self.matrix, other.matrix))

    def __hash__(self) -> int:
        return hash((self.camera.tobytes(), self.parameter.tobytes(), self.matrix.tobytes()))

    def factor(self) -> np.ndarray:
        """``L`` (k, m) with ``L Lᵀ`` = :attr:`matrix` and m <= k its positive eigenvalues'
        count (a semi-definite matrix's square root: a parameter of zero variance, or two
        perfectly correlated, need no column).

        The eigen-decomposition is of the correlation matrix, scaled back: the parameters'
        units differ by ~1e10 in variance (an offset's σ of 0.1 ms is 1e-8 s², a short
        session's drift σ of 100 ppm 1e4 ppm²), and a cut-off relative to the largest
        eigenvalue of the raw matrix dropped the offsets' columns whole (and eigh's absolute
        error, eps times the largest, blurred what it kept)."""
        corr, scale = _correlation(self.matrix)
        values, vectors = np.linalg.eigh(corr)
        keep = values > 1e-12 * max(float(values.max(initial=0.0)), 1e-300)
        return scale[:, None] * vectors[:, keep] * np.sqrt(values[keep])


def _correlation(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(C, d)`` with ``matrix = d C d`` (``d`` (k,) the standard deviations, 1 where a
    variance is not positive, so that such a row stays as it is)."""
    variance = np.diag(matrix)
    scale = np.where(variance > 0, np.sqrt(np.abs(variance)), 1.0)
    return matrix / np.outer(scale, scale), scale


def read_clock_covariance(rig: Rig, metadata) -> ClockCovariance | None:
    """The covariance of ``rig``'s clock parameters that ``pslog sync`` estimated, from the
    session's metadata (:data:`CLOCK_STD_KEY`): the parameters of non-zero standard deviation
    whose stored value is still the rig's (as :func:`read_clock_std`), with their stored
    joint covariance, or, for a session synced before it was stored, the standard deviations
    alone (independent). None when there is none (no key, a malformed one, nothing
    estimated, or every estimate since replaced)."""
    import json

    stds = read_clock_std(rig, metadata)
    if stds is None:
        return None
    params = [(c, CLOCK_KEYS.index(key)) for c, row in enumerate(stds)
              for key in CLOCK_KEYS if row.get(key, 0.0) > 0]
    if not params:
        return None
    choices = [np.diag([stds[c][CLOCK_KEYS[p]] ** 2 for c, p in params])]
    try:
        stored = json.loads(metadata.get(CLOCK_STD_KEY))["covariance"]
        names = [(rig.names.index(name), CLOCK_KEYS.index(key))
                 for name, key in stored["parameters"]]
        matrix = np.asarray(stored["matrix"], dtype=np.float64)
        where = [names.index(p) for p in params]
        choices.insert(0, matrix[np.ix_(where, where)])
    except (ValueError, TypeError, KeyError, IndexError, AttributeError):
        pass  # (none stored, or not for these parameters: the standard deviations alone)
    for variance in choices:  # (a stored matrix no covariance is: the stds alone)
        try:
            return ClockCovariance(np.array([c for c, _ in params]),
                                   np.array([p for _, p in params]), variance)
        except InputError:
            continue
    return None


@dataclass(frozen=True)
class Regularization:
    """What :func:`regularize_times` found for one camera.

    Attributes
    ----------
    period_s : float, fitted seconds per frame index (NaN with fewer than 2 frames)
    start_s : float, fitted time of the first frame (its frame index) on the input clock,
        seconds (NaN with no frame)
    jitter_s : float, robust standard deviation of the stamps around the line
        (1.4826 * median absolute residual), seconds; NaN with fewer than 3 frames
    n_frames : int, frames fitted
    n_outliers : int, stamps further than ``5 * jitter`` (and 2 µs) from the line, left out
        of the fit (their times are replaced like every other)
    n_dropped : int, frame indices missing between the first and the last (dropped frames)
    first_index : int, the frame index ``start_s`` refers to
    covariance : (var start s², cov start·period s², var period s²), the line's least-squares
        covariance with ``jitter_s`` as the stamps' noise: a fitted time ``start + period ·
        (k - first_index)`` is off by ``δstart + δperiod · (k - first_index)``, which
        :func:`pslog.estimation.sync.estimate_clocks` carries into the clocks' standard
        deviations (NaN with fewer than 3 frames)
    """

    period_s: float
    start_s: float
    jitter_s: float
    n_frames: int
    n_outliers: int
    n_dropped: int
    first_index: int = 0
    covariance: tuple[float, float, float] = (float("nan"),) * 3

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def regularize_times(logged_ns, frame_index) -> tuple[np.ndarray, Regularization]:
    """Replace one camera's jittery host timestamps by a robust straight line of time
    against frame index.

    A camera's shutter runs on its own crystal: frame ``k`` is captured at
    ``start + period * k`` (a clock drift is just a slightly different period); the host
    stamps each frame when it arrives, with a delay that jitters by milliseconds. Frame
    indices stay exact (a gap is a dropped frame). The line is fitted robustly: a first
    period from the median of consecutive slopes, then least squares on the stamps within
    ``5`` robust scales (and at least 2 µs) of the line, three times; stamps outside are
    outliers (counted, and replaced by the line like the others).

    Parameters
    ----------
    logged_ns : (n,) int64, one camera's logged times, nanoseconds (any order)
    frame_index : (n,) int64, the frames' indices

    Returns
    -------
    times_ns : (n,) int64, the fitted times, in the input order
    report : :class:`Regularization`
    """
    t = np.asarray(logged_ns, dtype=np.int64)
    k = np.asarray(frame_index, dtype=np.int64)
    if t.shape != k.shape or t.ndim != 1:
        raise InputError(f"logged times {t.shape} and frame indices {k.shape} must be "
                         f"one-dimensional and of one length")
    n = len(t)
    nan = float("nan")
    if n < 2:
        return t.copy(), Regularization(nan, t[0] / NS if n else nan, nan, n, 0, 0)
    if len(np.unique(k)) < 2:
        raise InputError("regularizing times needs at least two distinct frame indices")
    # small float numbers: relative to the first stamp and index (epoch ns keep precision)
    t0, k0 = int(t.min()), int(k.min())
    rel = (t - t0).astype(np.float64) / NS
    kk = (k - k0).astype(np.float64)
    order = np.argsort(kk, kind="stable")
    dk, dt = np.diff(kk[order]), np.diff(rel[order])
    step = dk > 0
    period = float(np.median(dt[step] / dk[step]))
    start = float(np.median(rel - period * kk))
    inlier = np.ones(n, dtype=bool)
    for _ in range(3):
        resid = rel - (start + period * kk)
        scale = _MAD_TO_STD * float(np.median(np.abs(resid - np.median(resid[inlier]))[inlier]))
        inlier = np.abs(resid) <= max(_OUTLIER_SCALES * scale, _OUTLIER_FLOOR_S)
        if np.count_nonzero(inlier) < 2 or len(np.unique(kk[inlier])) < 2:
            inlier = np.ones(n, dtype=bool)
            break
        # least squares on the inliers, centred for conditioning
        km, tm = kk[inlier].mean(), rel[inlier].mean()
        dkm = kk[inlier] - km
        period = float(np.dot(dkm, rel[inlier] - tm) / np.dot(dkm, dkm))
        start = tm - period * km
    resid = rel - (start + period * kk)
    jitter = _MAD_TO_STD * float(np.median(np.abs(resid))) if n >= 3 else nan
    inlier = np.abs(resid) <= max(_OUTLIER_SCALES * jitter if n >= 3 else 0.0,
                                  _OUTLIER_FLOOR_S)
    fitted = t0 + np.rint((start + period * kk) * NS).astype(np.int64)
    n_dropped = int(k.max() - k.min() + 1 - len(np.unique(k)))
    # the line's covariance: jitter² (XᵀX)⁻¹ on the inliers, X = [1, k - k0]
    covariance = (nan,) * 3
    if n >= 3 and len(np.unique(kk[inlier])) >= 2:
        x = kk[inlier]
        XtX = np.array([[len(x), x.sum()], [x.sum(), x @ x]])
        cov = jitter**2 * np.linalg.inv(XtX)
        covariance = (float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1]))
    return fitted, Regularization(period, (t0 + start * NS) / NS, jitter, n,
                                  int(np.count_nonzero(~inlier)), n_dropped, k0, covariance)


def regularize_detections(detections: Detections, cameras=None
                          ) -> tuple[Detections, dict[str, Regularization]]:
    """:func:`regularize_times` applied to each camera's frames (or only those named in
    ``cameras``); returns the detections with the fitted frame times (candidates kept with
    their frames) and each regularized camera's report by name."""
    names = detections.camera_names
    wanted = set(names if cameras is None else cameras)
    time_ns = detections.frame_time_ns.copy()
    reports = {}
    for i, name in enumerate(names):
        rows = np.flatnonzero(detections.frame_camera == i)
        if name not in wanted or len(rows) == 0:
            continue
        time_ns[rows], reports[name] = regularize_times(time_ns[rows],
                                                        detections.frame_index[rows])
    out = Detections.from_frames(names, time_ns, detections.frame_camera,
                                 detections.frame_index, detections.cand_frame,
                                 detections.cand_uv, detections.cand_radius,
                                 detections.cand_score)
    return out, reports
