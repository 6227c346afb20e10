"""Simulated sessions: what each camera of a rig would detect of a ball in motion.

The paper's section 3.1 projects the true trajectory onto each camera's image plane at its
shutter times; :func:`simulate` does the same for any rig and schedule, with optional pixel
noise, shutter jitter, dropped frames and missed detections, and returns the detections and
the ground truth sampled at every capture time.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera
from .errors import InputError, RigError
from .motion import Motion
from .records import NS, Detections, Truth
from .rig import Rig
from .timing import camera_parameters, logged_times_ns, true_times_ns, true_times_s

#: Session metadata key of the clock faults a simulated session was made with (JSON).
TRUTH_CLOCK_KEY = "truth_clock"
#: Fixed-point iterations for the row a rolling shutter reads the ball at: each multiplies
#: the error by readout * (ball's row speed) / height, well below 0.1 for any real motion.
_ROW_ITERATIONS = 8
#: Largest difference, pixels, between the row a rolling-shutter capture was timed for and
#: the row the ball is then seen at (a converged fixed point is far closer).
_ROW_TOLERANCE_PX = 1e-6

#: Longest simulation, in frames of all cameras together (about 2 GB of detections).
MAX_SIMULATED_FRAMES = 20_000_000


@dataclass(frozen=True)
class SimulationOptions:
    """Imperfections of a simulated capture.

    Attributes
    ----------
    noise_px : float, standard deviation of Gaussian detection noise per pixel axis
    jitter_s : float, standard deviation of each shutter's deviation from its schedule,
        seconds; the log records the actual (jittered) capture time
    drop_rate : float in [0, 1), fraction of frames lost entirely (no frame record)
    miss_rate : float in [0, 1), fraction of captured frames with no detection
    seed : int, random seed
    clock_offset_s : mapping camera name -> seconds, the cameras' true clock offsets
        (:mod:`pslog.timing`); the first camera's must be 0 (it defines the clock)
    clock_drift_ppm : mapping camera name -> ppm, the cameras' true clock drifts (first: 0)
    readout_s : mapping camera name -> seconds, the cameras' true rolling-shutter readouts
    host_jitter_s : float, standard deviation of the logged stamps around the (faulted)
        clock's times, seconds: host arrival jitter (frame indices stay exact)
    spurious_rate : float in [0, 1], fraction of frames (of every camera) given one false
        candidate ("a reflection, a shirt")
    spurious_radius_px : float >= 0, where that false candidate is: 0, anywhere in the image
        (uniform); > 0, within this many pixels of the ball's true pixel (uniform over the
        annulus from a quarter of it to it), anywhere when the ball is not in view
    distractors : sequence of ``(camera name or None, (x, y, z))``: a static second ball-like
        object at a world point (metres), a candidate in every frame of the named camera
        (None: of every camera whose view contains it)
    blackouts : sequence of ``(camera name, start_s, duration_s)``: the camera misses the
        ball (no ball candidate; false ones still appear) for captures in
        ``[start, start + duration)`` seconds of true time

    The clock faults are the timing model's parameters (:func:`true_rig`): the simulator
    captures at true times and logs through the model's exact inverse. The candidate faults
    draw from their own random stream (seeded by ``seed``), so a session with them has the
    very same ball detections as the one without; with any candidate fault the ball's
    candidates get realistic scores (uniform in [0.5, 1]; false ones [0.2, 0.9], a
    distractor [0.6, 1]: it may outscore the ball), else every score is 1.
    """

    noise_px: float = 0.0
    jitter_s: float = 0.0
    drop_rate: float = 0.0
    miss_rate: float = 0.0
    seed: int = 0
    clock_offset_s: Mapping[str, float] = field(default_factory=dict)
    clock_drift_ppm: Mapping[str, float] = field(default_factory=dict)
    readout_s: Mapping[str, float] = field(default_factory=dict)
    host_jitter_s: float = 0.0
    spurious_rate: float = 0.0
    spurious_radius_px: float = 0.0
    distractors: tuple = ()
    blackouts: tuple = ()

    def __post_init__(self) -> None:
        for name in ("clock_offset_s", "clock_drift_ppm", "readout_s"):
            object.__setattr__(self, name, {str(k): float(v)
                                            for k, v in dict(getattr(self, name)).items()})
        for name in ("noise_px", "jitter_s", "host_jitter_s"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"{name} must be finite and >= 0, got {value!r}")
        for name in ("drop_rate", "miss_rate"):
            value = getattr(self, name)
            if not (0.0 <= value < 1.0):
                raise InputError(f"{name} must be in [0, 1), got {value!r}")
        # 1 is a valid (if harsh) rate: a false candidate in every frame; the ball stays
        if not (0.0 <= self.spurious_rate <= 1.0):
            raise InputError(f"spurious_rate must be in [0, 1], got {self.spurious_rate!r}")
        if not (np.isfinite(self.spurious_radius_px) and self.spurious_radius_px >= 0):
            raise InputError(f"spurious radius must be finite and >= 0 pixels, got "
                             f"{self.spurious_radius_px!r}")
        distractors = []
        for camera, point in self.distractors:
            point = tuple(float(x) for x in point)
            if len(point) != 3 or not all(np.isfinite(point)):
                raise InputError(f"distractor point must be three finite coordinates (metres), "
                                 f"got {point!r}")
            distractors.append((None if camera is None else str(camera), point))
        object.__setattr__(self, "distractors", tuple(distractors))
        blackouts = []
        for camera, start, duration in self.blackouts:
            start, duration = float(start), float(duration)
            if not (np.isfinite(start) and start >= 0):
                raise InputError(f"blackout of camera {camera!r}: start must be >= 0 seconds, "
                                 f"got {start!r}")
            if not (np.isfinite(duration) and duration > 0):
                raise InputError(f"blackout of camera {camera!r}: duration must be > 0 "
                                 f"seconds, got {duration!r}")
            blackouts.append((str(camera), start, duration))
        object.__setattr__(self, "blackouts", tuple(blackouts))

    @property
    def dirty(self) -> bool:
        """True when any candidate fault (spurious, distractor, blackout) is set."""
        return bool(self.spurious_rate > 0 or self.distractors or self.blackouts)


def check_duration(rig: Rig, duration: float) -> float:
    """``duration`` seconds if it is at least a frame period and gives at most
    :data:`MAX_SIMULATED_FRAMES` frames of ``rig``'s cameras, else :class:`InputError`
    saying why."""
    if not np.isfinite(duration) or duration <= 0:
        raise InputError(f"duration must be > 0 seconds, got {duration!r}")
    shortest = min(cam.frame_period for cam in rig.cameras)
    if duration < shortest:
        raise InputError(f"duration {duration:g} s is too short to hold a frame (a frame "
                         f"period of this rig is {shortest:.4g} s)")
    n_frames = duration * sum(cam.fps for cam in rig.cameras)
    if n_frames > MAX_SIMULATED_FRAMES:
        raise InputError(f"duration {duration:g} s gives {n_frames:.3g} frames; simulate at "
                         f"most {MAX_SIMULATED_FRAMES:.0e} frames (a 90-minute match of three "
                         f"30 fps cameras is 4.9e5)")
    return duration


def check_simulation(rig: Rig, options: SimulationOptions) -> None:
    """:class:`InputError` if ``options`` make no sense for ``rig`` (:func:`check_jitter`,
    :func:`check_noise`, :func:`true_rig`, host jitter as :func:`check_jitter`)."""
    check_jitter(rig, options.jitter_s)
    check_jitter(rig, options.host_jitter_s, "host jitter")
    check_noise(rig, options.noise_px)
    true_rig(rig, options)
    check_candidate_faults(rig, options)


def check_candidate_faults(rig: Rig, options: SimulationOptions) -> None:
    """:class:`InputError` naming the value if a distractor or blackout names a camera not
    in ``rig``, or a distractor is in no named camera's view (it would never be seen)."""
    for camera, point in options.distractors:
        if camera is not None and camera not in rig.names:
            raise InputError(f"distractor for unknown camera {camera!r} "
                             f"(rig has {', '.join(rig.names)})")
        seen = _distractor_cameras(rig, camera, point)
        if not seen:
            where = "the view of any camera" if camera is None else f"camera {camera}'s view"
            raise InputError(f"distractor at {','.join(f'{x:g}' for x in point)} m is not in "
                             f"{where} (in front of it and inside its image)")
    for camera, _start, _duration in options.blackouts:
        if camera not in rig.names:
            raise InputError(f"blackout for unknown camera {camera!r} "
                             f"(rig has {', '.join(rig.names)})")


def _distractor_cameras(rig: Rig, camera: str | None, point) -> list[int]:
    """Indices of the cameras that see a distractor at ``point``: ``camera`` (if it sees
    it) or every camera whose view contains it."""
    # a far-off point (1e300 m) overflows the distortion polynomial: NaN means not seen,
    # not a RuntimeWarning on the user's terminal
    with np.errstate(all="ignore"):
        uv = _project(rig, np.arange(len(rig), dtype=np.int32),
                      np.tile(np.asarray(point, dtype=np.float64), (len(rig), 1)))
    visible = np.all(np.isfinite(uv), axis=1)
    return [i for i, name in enumerate(rig.names)
            if visible[i] and (camera is None or camera == name)]


def true_rig(rig: Rig, options: SimulationOptions) -> Rig:
    """``rig`` with the clock faults of ``options`` as its cameras' timing-model parameters
    (``clock_offset``, ``clock_drift_ppm``, ``readout``): the rig a perfect ``pslog sync``
    would recover.

    Raises
    ------
    InputError naming the camera and the problem: an unknown camera, a value the rig
    refuses (a readout of a frame period or more, a drift beyond 1000 ppm...), an offset or
    drift on the first camera (it defines the session clock).
    """
    changes: dict[str, dict[str, float]] = {}
    for key, values in (("clock_offset", options.clock_offset_s),
                        ("clock_drift_ppm", options.clock_drift_ppm),
                        ("readout", options.readout_s)):
        for name, value in values.items():
            if name not in rig.names:
                raise InputError(f"{key} for unknown camera {name!r} "
                                 f"(rig has {', '.join(rig.names)})")
            changes.setdefault(name, {})[key] = value
    first = rig.cameras[0].name
    if changes.get(first, {}).get("clock_offset") or changes.get(first, {}).get(
            "clock_drift_ppm"):
        raise InputError(f"camera {first!r} is the first of the rig and defines the session "
                         f"clock: its clock offset and drift are 0 by definition (fault the "
                         f"other cameras)")
    try:
        return Rig(tuple(c.replace(**changes.get(c.name, {})) for c in rig.cameras), rig.name)
    except RigError as exc:
        raise InputError(str(exc)) from None


def truth_clock(rig: Rig, options: SimulationOptions) -> str:
    """The clock faults of a simulation as the JSON stored in the session metadata under
    :data:`TRUTH_CLOCK_KEY`: ``{"cameras": {name: {"clock_offset": s, "clock_drift_ppm":
    ppm, "readout": s}}, "host_jitter_s": s}``, every camera of the rig, floats exact."""
    faulted = true_rig(rig, options)
    return json.dumps({
        "cameras": {c.name: {"clock_offset": c.clock_offset,
                             "clock_drift_ppm": c.clock_drift_ppm, "readout": c.readout}
                    for c in faulted.cameras},
        "host_jitter_s": float(options.host_jitter_s)})


def read_truth_clock(rig: Rig, metadata: Mapping[str, str]) -> Rig | None:
    """The session rig with the true clock parameters of a simulated session (from
    ``metadata[TRUTH_CLOCK_KEY]``), to score a ``pslog sync`` estimate; None if the session
    holds none."""
    text = metadata.get(TRUTH_CLOCK_KEY)
    if text is None:
        return None
    try:
        cameras = json.loads(text)["cameras"]
        return Rig(tuple(c.replace(**{k: float(v) for k, v in cameras[c.name].items()})
                         for c in rig.cameras), rig.name)
    except (ValueError, KeyError, TypeError, AttributeError, RigError) as exc:
        raise InputError(f"session metadata {TRUTH_CLOCK_KEY!r} is malformed: {exc}") from None


def check_jitter(rig: Rig, jitter_s: float, what: str = "jitter") -> float:
    """``jitter_s`` if below half the shortest frame period of ``rig``, else
    :class:`InputError`: more would swap frames of one camera and merge neighbours."""
    fastest = max(rig.cameras, key=lambda c: c.fps)
    if not jitter_s < 0.5 * fastest.frame_period:
        raise InputError(
            f"{what} {jitter_s:g} s must be below half a frame period "
            f"({0.5 * fastest.frame_period:.6g} s at {fastest.fps:g} fps, camera "
            f"{fastest.name}): more would swap frames of one camera")
    return jitter_s


def check_noise(rig: Rig, noise_px: float) -> float:
    """``noise_px`` if at most the largest image side of ``rig``, else :class:`InputError`:
    a detection would say nothing of where the ball is."""
    largest = max(max(c.width, c.height) for c in rig.cameras)
    if not noise_px <= largest:
        raise InputError(f"noise {noise_px:g} px is beyond the image size ({largest} px): "
                         f"detections would say nothing of the ball")
    return noise_px


def check_exposure(rig: Rig, exposure_s: float) -> float:
    """``exposure_s`` if it is in ``[0, frame period)`` of every camera of ``rig``, else
    :class:`InputError` saying why: a shutter cannot stay open into the next frame.

    (For rendered sessions, ``pslog record --synthetic --exposure``.)
    """
    fastest = max(rig.cameras, key=lambda c: c.fps)
    if not (np.isfinite(exposure_s) and 0 <= exposure_s < fastest.frame_period):
        raise InputError(
            f"exposure {exposure_s!r} s must be in [0, {fastest.frame_period:.6g}) s, shorter "
            f"than the frame period at {fastest.fps:g} fps (camera {fastest.name}): a shutter "
            f"cannot stay open into the next frame")
    return exposure_s


def _project(rig: Rig, camera: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Pixels (n, 2) of ``positions`` (n, 3) in each row's camera; NaN where not visible."""
    uv = np.full((len(positions), 2), np.nan)
    for i, cam in enumerate(rig.cameras):  # loop over cameras, vectorized over frames
        rows = camera == i
        uv_cam, in_front = cam.project(positions[rows])
        visible = in_front & cam.in_image(uv_cam)
        uv_cam[~visible] = np.nan
        uv[rows] = uv_cam
    return uv


def shutter_times(camera: Camera, duration: float) -> np.ndarray:
    """Nominal shutter times (k,) float64 seconds of ``camera`` in ``[0, duration)``:
    ``offset + k / fps`` for k = 0, 1, ... (the offset is within ``[0, 1 / fps)``, as
    :class:`~pslog.camera.Camera` checks), so frame ``k`` is row ``k``."""
    n_frames = np.ceil((duration - camera.offset) * camera.fps)
    if not n_frames <= MAX_SIMULATED_FRAMES:  # also NaN: no array of 224 GB attempted
        raise InputError(f"duration {duration:g} s gives {n_frames:.3g} frames of camera "
                         f"{camera.name}; simulate at most {MAX_SIMULATED_FRAMES:.0e} frames")
    k = np.arange(max(int(n_frames), 0) + 1)
    t = camera.offset + k / camera.fps
    return t[t < duration]


def capture_times(rig: Rig, duration: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nominal shutter times of every camera in ``[0, duration)``.

    Returns
    -------
    time_s : (F,) float64 seconds, camera : (F,) int32, frame_index : (F,) int64 —
    sorted by (time, camera)
    """
    check_duration(rig, duration)
    times, cameras, indices = [], [], []
    for i, cam in enumerate(rig.cameras):
        t = shutter_times(cam, duration)
        times.append(t)
        cameras.append(np.full(len(t), i, dtype=np.int32))
        indices.append(np.arange(len(t), dtype=np.int64))
    time_s, camera, frame_index = (np.concatenate(x) for x in (times, cameras, indices))
    order = np.lexsort((camera, time_s))
    return time_s[order], camera[order], frame_index[order]


def simulate(
    rig: Rig, motion: Motion, duration: float | None = None,
    options: SimulationOptions | None = None,
) -> tuple[Detections, Truth]:
    """Detections of ``motion`` by every camera of ``rig`` over ``[0, duration)`` seconds
    (:func:`simulate_labelled` without the ball labels)."""
    detections, truth, _ = simulate_labelled(rig, motion, duration, options)
    return detections, truth


def simulate_labelled(
    rig: Rig, motion: Motion, duration: float | None = None,
    options: SimulationOptions | None = None,
) -> tuple[Detections, Truth, Detections]:
    """Detections of ``motion`` by every camera of ``rig`` over ``[0, duration)`` seconds,
    the truth, and which candidates are the ball.

    A frame whose projection falls outside the image, or behind the camera, is recorded
    without a ball candidate. Truth is sampled at every capture time (exactly).

    With clock faults (``options``' clock offsets, drifts, readouts): the shutters follow
    ``rig``'s schedule on the true clock; each frame's top row is logged on its camera's
    clock through :func:`pslog.timing.logged_times_ns`; the ball is captured at the true time
    of the row it is seen at (:func:`pslog.timing.true_times_ns` of the logged time and that
    row), where the motion is sampled and projected, and where the truth is sampled. So
    ``true_times_ns(logged, v, ...)`` with the detection's noise-free row ``v`` and the true
    parameters (:func:`true_rig`) is the truth's time. Host jitter is then added to the
    logged stamps. The true clock is camera 1's: truth times are on the session clock.

    With candidate faults (spurious blobs, distractors, blackouts: :class:`SimulationOptions`)
    frames get false candidates beside (or instead of) the ball's.

    Returns
    -------
    detections : Detections, every frame with all its candidates (best score first)
    truth : Truth
    ball : Detections, the same frames holding only the ball's candidate (none where the
        ball was not detected): the label of every candidate (:func:`ball_mask`)
    """
    options = options or SimulationOptions()
    check_simulation(rig, options)
    clock = camera_parameters(true_rig(rig, options))
    duration = motion.duration if duration is None else float(duration)
    rng = np.random.default_rng(options.seed)
    time_s, camera, frame_index = capture_times(rig, duration)
    if options.jitter_s > 0:
        time_s = time_s + rng.normal(0.0, options.jitter_s, len(time_s))
    top_ns = np.round(time_s * NS).astype(np.int64)  # true time of each frame's top row
    keep = rng.random(len(top_ns)) >= options.drop_rate
    top_ns, camera, frame_index = top_ns[keep], camera[keep], frame_index[keep]
    h, off, drift, readout = (clock[k][camera] for k in
                              ("height", "clock_offset", "clock_drift_ppm", "readout"))
    # the camera's clock stamps the top row: logged through the model's exact inverse
    logged_ns = logged_times_ns(top_ns, 0.0, h, off, drift, readout)
    # with a rolling shutter the ball's row is read later, and where the ball is then
    # depends on that time: a fixed point, a few iterations
    row = np.zeros(len(top_ns))
    if np.any(readout > 0):
        for _ in range(_ROW_ITERATIONS):
            t = true_times_s(logged_ns / NS, row, h, off, drift, readout)
            v = _project(rig, camera, motion.position(t))[:, 1]
            row = np.where(np.isfinite(v), v, 0.0)  # unseen: the top row's time
    time_ns = true_times_ns(logged_ns, row, h, off, drift, readout)  # capture of the ball
    positions = motion.position(time_ns / NS)

    uv = _project(rig, camera, positions)
    if np.any(readout > 0):
        # a ball crossing the image's edge during the readout has no consistent row (seen
        # at a row whose time puts it outside): such a frame detects nothing
        consistent = np.abs(uv[:, 1] - row) <= _ROW_TOLERANCE_PX
        uv[~consistent] = np.nan
    uv_true = uv
    if options.noise_px > 0:
        uv = uv + rng.normal(0.0, options.noise_px, uv.shape)
    detected = np.all(np.isfinite(uv), axis=1) & (rng.random(len(uv)) >= options.miss_rate)
    if options.host_jitter_s > 0:  # the host stamps arrival; the shutter kept its time
        logged_ns = logged_ns + np.rint(
            rng.normal(0.0, options.host_jitter_s * NS, len(logged_ns))).astype(np.int64)
    cand_frame = np.flatnonzero(detected)
    cand_uv = uv[cand_frame]
    cand_score = np.ones(len(cand_frame))
    is_ball = np.ones(len(cand_frame), dtype=bool)
    if options.dirty:
        cand_frame, cand_uv, cand_score, is_ball = _false_candidates(
            rig, options, camera, time_ns, uv_true, cand_frame, cand_uv)
    # jitter may reorder frames or make two captures coincide; Detections.from_frames sorts
    detections = Detections.from_frames(
        rig.names, logged_ns, camera, frame_index, cand_frame, cand_uv,
        cand_radius=np.full(len(cand_frame), np.nan), cand_score=cand_score)
    ball = Detections.from_frames(
        rig.names, logged_ns, camera, frame_index, cand_frame[is_ball], cand_uv[is_ball],
        cand_radius=np.full(int(is_ball.sum()), np.nan), cand_score=cand_score[is_ball])

    truth_ns = np.unique(time_ns)
    return detections, Truth(truth_ns, motion.position(truth_ns / NS)), ball


#: Scores drawn for candidates of a dirty session: (low, high) of a uniform distribution.
BALL_SCORE = (0.5, 1.0)
SPURIOUS_SCORE = (0.2, 0.9)
DISTRACTOR_SCORE = (0.6, 1.0)


def _false_candidates(rig: Rig, options: SimulationOptions, camera, time_ns, uv_true,
                      cand_frame, cand_uv):
    """The ball's candidates (less the blacked-out ones) plus the false ones, with scores.

    Drawn from a random stream of their own (``[seed, 1]``): the ball's detections stay
    those of the clean session. Returns (cand_frame, cand_uv, cand_score, is_ball)."""
    rng = np.random.default_rng([options.seed, 1])
    n_frames = len(camera)
    keep = np.ones(len(cand_frame), dtype=bool)
    # a blackout may outlast any session (1e308 s): clip its end to the last frame so the
    # nanosecond bounds stay integers (round(inf) raises)
    last_ns = int(time_ns.max()) + 1 if len(time_ns) else 0
    for name, start, duration in options.blackouts:
        i = rig.names.index(name)
        t = time_ns[cand_frame]
        begin_ns = round(min(start * NS, last_ns))
        end_ns = round(min((start + duration) * NS, last_ns))
        keep &= ~((camera[cand_frame] == i) & (t >= begin_ns) & (t < end_ns))
    frames = [cand_frame[keep]]
    uvs = [cand_uv[keep]]
    scores = [rng.uniform(*BALL_SCORE, len(cand_frame))[keep]]
    labels = [np.ones(int(keep.sum()), dtype=bool)]
    for name, point in options.distractors:
        seen = _distractor_cameras(rig, name, point)
        rows = np.flatnonzero(np.isin(camera, seen))
        uv = _project(rig, camera[rows], np.tile(np.asarray(point), (len(rows), 1)))
        if options.noise_px > 0:
            uv = uv + rng.normal(0.0, options.noise_px, uv.shape)
        ok = np.all(np.isfinite(uv), axis=1)
        frames.append(rows[ok])
        uvs.append(uv[ok])
        scores.append(rng.uniform(*DISTRACTOR_SCORE, int(ok.sum())))
        labels.append(np.zeros(int(ok.sum()), dtype=bool))
    if options.spurious_rate > 0:
        rows = np.flatnonzero(rng.random(n_frames) < options.spurious_rate)
        size = np.array([[c.width, c.height] for c in rig.cameras], dtype=np.float64)[
            camera[rows]]
        uv = rng.random((len(rows), 2)) * size  # anywhere in the image
        radius = options.spurious_radius_px
        if radius > 0:  # near the ball where it is in view: an annulus around it
            r = radius * np.sqrt(rng.uniform(1 / 16, 1.0, len(rows)))
            angle = rng.uniform(0, 2 * np.pi, len(rows))
            near = uv_true[rows] + r[:, None] * np.column_stack([np.cos(angle),
                                                                 np.sin(angle)])
            inside = np.all(np.isfinite(near), axis=1) & np.all(near >= 0, axis=1) & np.all(
                near < size, axis=1)
            uv[inside] = near[inside]
        frames.append(rows)
        uvs.append(uv)
        scores.append(rng.uniform(*SPURIOUS_SCORE, len(rows)))
        labels.append(np.zeros(len(rows), dtype=bool))
    return (np.concatenate(frames), np.concatenate(uvs), np.concatenate(scores),
            np.concatenate(labels))


def ball_mask(detections: Detections, ball: Detections) -> np.ndarray:
    """(C,) bool: which candidates of ``detections`` are the ball, by the labels ``ball``
    (:func:`simulate_labelled`; a session's ``ball_truth``): a candidate is the ball when
    its camera, frame index and pixel equal a labelled one's."""
    labelled = {(int(ball.frame_camera[f]), int(ball.frame_index[f]), float(u), float(v))
                for f, (u, v) in zip(ball.cand_frame.tolist(), ball.cand_uv.tolist(),
                                     strict=True)}
    if not labelled:
        return np.zeros(detections.n_candidates, dtype=bool)
    cam = detections.frame_camera[detections.cand_frame].tolist()
    idx = detections.frame_index[detections.cand_frame].tolist()
    return np.array([(c, i, u, v) in labelled for c, i, (u, v) in zip(
        cam, idx, detections.cand_uv.tolist(), strict=True)], dtype=bool)
