"""Simulated sessions: what each camera of a rig would detect of a ball in motion.

The paper's section 3.1 projects the true trajectory onto each camera's image plane at its
shutter times; :func:`simulate` does the same for any rig and schedule, with optional pixel
noise, shutter jitter, dropped frames and missed detections, and returns the detections and
the ground truth sampled at every capture time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera import Camera
from .errors import InputError
from .motion import Motion
from .records import NS, Detections, Truth
from .rig import Rig

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
    """

    noise_px: float = 0.0
    jitter_s: float = 0.0
    drop_rate: float = 0.0
    miss_rate: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("noise_px", "jitter_s"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"{name} must be finite and >= 0, got {value!r}")
        for name in ("drop_rate", "miss_rate"):
            value = getattr(self, name)
            if not (0.0 <= value < 1.0):
                raise InputError(f"{name} must be in [0, 1), got {value!r}")


def check_duration(rig: Rig, duration: float) -> float:
    """``duration`` seconds if it is > 0 and gives at most :data:`MAX_SIMULATED_FRAMES`
    frames of ``rig``'s cameras, else :class:`InputError` saying why."""
    if not np.isfinite(duration) or duration <= 0:
        raise InputError(f"duration must be > 0 seconds, got {duration!r}")
    n_frames = duration * sum(cam.fps for cam in rig.cameras)
    if n_frames > MAX_SIMULATED_FRAMES:
        raise InputError(f"duration {duration:g} s gives {n_frames:.3g} frames; simulate at "
                         f"most {MAX_SIMULATED_FRAMES:.0e} frames (a 90-minute match of three "
                         f"30 fps cameras is 4.9e5)")
    return duration


def check_simulation(rig: Rig, options: SimulationOptions) -> None:
    """:class:`InputError` if ``options`` make no sense for ``rig`` (:func:`check_jitter`,
    :func:`check_noise`)."""
    check_jitter(rig, options.jitter_s)
    check_noise(rig, options.noise_px)


def check_jitter(rig: Rig, jitter_s: float) -> float:
    """``jitter_s`` if below half the shortest frame period of ``rig``, else
    :class:`InputError`: more would swap frames of one camera and merge neighbours."""
    fastest = max(rig.cameras, key=lambda c: c.fps)
    if not jitter_s < 0.5 * fastest.frame_period:
        raise InputError(
            f"jitter {jitter_s:g} s must be below half a frame period "
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
    """Detections of ``motion`` by every camera of ``rig`` over ``[0, duration)`` seconds.

    A frame whose projection falls outside the image, or behind the camera, is recorded
    without a candidate. Truth is sampled at every capture time (exactly).
    """
    options = options or SimulationOptions()
    check_simulation(rig, options)
    duration = motion.duration if duration is None else float(duration)
    rng = np.random.default_rng(options.seed)
    time_s, camera, frame_index = capture_times(rig, duration)
    if options.jitter_s > 0:
        time_s = time_s + rng.normal(0.0, options.jitter_s, len(time_s))
    time_ns = np.round(time_s * NS).astype(np.int64)
    keep = rng.random(len(time_ns)) >= options.drop_rate
    time_ns, camera, frame_index = time_ns[keep], camera[keep], frame_index[keep]
    # jitter may reorder frames or make two captures coincide; Detections.from_frames sorts
    positions = motion.position(time_ns / NS)

    uv = np.full((len(time_ns), 2), np.nan)
    for i, cam in enumerate(rig.cameras):  # loop over cameras, vectorized over frames
        rows = camera == i
        uv_cam, in_front = cam.project(positions[rows])
        visible = in_front & cam.in_image(uv_cam)
        uv_cam[~visible] = np.nan
        uv[rows] = uv_cam
    if options.noise_px > 0:
        uv = uv + rng.normal(0.0, options.noise_px, uv.shape)
    detected = np.all(np.isfinite(uv), axis=1) & (rng.random(len(uv)) >= options.miss_rate)
    cand_frame = np.flatnonzero(detected)
    detections = Detections.from_frames(
        rig.names, time_ns, camera, frame_index, cand_frame, uv[cand_frame],
        cand_radius=np.full(len(cand_frame), np.nan), cand_score=np.ones(len(cand_frame)))

    truth_ns = np.unique(time_ns)
    return detections, Truth(truth_ns, motion.position(truth_ns / NS))
