"""Frame sources: live cameras, video files and rendered synthetic cameras.

A *spec* (picklable, made in the parent) names what to open; its ``open()`` runs in the
camera's own process and returns a *source*; after ``set_start(t0_ns)`` its ``read()`` yields
``(frame_index, time_ns, frame_bgr)`` on the session's common clock, or ``None`` at the end.

Session clock: integer nanoseconds since the session start ``t0_ns``, a reading of the host's
``CLOCK_MONOTONIC`` (:func:`time.monotonic_ns`) that every camera process shares.

- Live camera: the driver's buffer timestamp (``CAP_PROP_POS_MSEC``; V4L2 stamps buffers
  with ``CLOCK_MONOTONIC``) when it is meaningful (positive, within 1 s of the host clock and
  increasing), else the host clock read right after ``grab()``. Which one is used is
  reported (and logged as an event).
- Video file: the container timestamp of each frame (``CAP_PROP_POS_MSEC`` after reading it;
  frame number / fps if the container has none) plus the source's start offset, so files
  recorded by separate cameras share one clock.
- Synthetic: frame ``k`` of camera ``i`` is captured at ``offset_i + k / fps_i`` on the true
  clock (the rig's shutter schedule, as :func:`pslog.simulation.capture_times`), stamped on
  the camera's clock as the rig's clock model has it (:func:`synthetic_times`); in real time
  the source waits until the end of that frame's exposure on the session clock.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

# FFmpeg's own lines as OpenCV decodes a damaged or cut file ("[mjpeg @ 0x...] overread 2",
# "bad vlc") went to the terminal among the recording's status lines: the source's end
# reason says it in pslog's words (_FileSource.end_reason). Read by OpenCV once, when its
# FFmpeg backend starts: set before cv2 opens any video, inherited by the camera processes;
# a level the user set is kept. -8: AV_LOG_QUIET.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")

import cv2
import numpy as np

from pslog.camera import Camera
from pslog.errors import PslogError
from pslog.motion import Motion
from pslog.outputs import native_stderr
from pslog.records import NS
from pslog.simulation import shutter_times

from .render import CameraRenderer, RenderOptions

_DRIVER_CLOCK_TOLERANCE_NS = NS  # a driver timestamp this close to the host clock is trusted


class SourceError(PslogError):
    """A source failed to open or stopped delivering frames."""


class FrameSource:
    """Base of opened sources."""

    #: how capture times are obtained (for the log)
    clock: str = ""
    #: True when the source produces frames on its own schedule (it cannot wait for us)
    live: bool = False

    def read(self) -> tuple[int, int, np.ndarray] | None:  # pragma: no cover - interface
        raise NotImplementedError

    def set_start(self, t0_ns: int) -> None:
        """The session started at ``t0_ns`` (``time.monotonic_ns()``); live sources stamp
        frames relative to it."""

    def close(self) -> None:
        pass

    def end_reason(self) -> str:
        """Why :meth:`read` returned None, in the recording's summary."""
        return "end of source"


# ---- live camera ------------------------------------------------------------------------
@dataclass(frozen=True)
class DeviceSpec:
    """A live camera: a device index (``0``) or a path (``/dev/video2``)."""

    device: int | str
    width: int
    height: int
    fps: float

    def describe(self) -> str:
        return f"camera device {self.device}"

    def open(self) -> FrameSource:
        return _DeviceSource(self)


class _DeviceSource(FrameSource):
    live = True

    def __init__(self, spec: DeviceSpec) -> None:
        v4l2 = Path("/dev").is_dir() and hasattr(cv2, "CAP_V4L2")
        self._cap = cv2.VideoCapture(spec.device, cv2.CAP_V4L2 if v4l2 else cv2.CAP_ANY)
        if not self._cap.isOpened():
            raise SourceError(f"cannot open {spec.describe()}")
        self._cap.set(cv2.CAP_PROP_FRAME_WIDTH, spec.width)
        self._cap.set(cv2.CAP_PROP_FRAME_HEIGHT, spec.height)
        self._cap.set(cv2.CAP_PROP_FPS, spec.fps)
        self._spec = spec
        self._t0 = time.monotonic_ns()
        self._index = 0
        self._driver_clock: bool | None = None  # decided on the first frame
        self._last_ns = -1
        self.clock = "undecided"

    def set_start(self, t0_ns: int) -> None:
        self._t0 = int(t0_ns)

    def read(self) -> tuple[int, int, np.ndarray] | None:
        while True:
            if not self._cap.grab():
                raise SourceError(f"{self._spec.describe()} stopped delivering frames")
            host_ns = time.monotonic_ns()
            ok, frame = self._cap.retrieve()
            if not ok or frame is None:
                raise SourceError(f"{self._spec.describe()} delivered an unreadable frame")
            if frame.shape[:2] != (self._spec.height, self._spec.width):
                raise SourceError(
                    f"{self._spec.describe()} delivers {frame.shape[1]}x{frame.shape[0]} "
                    f"frames, the rig says {self._spec.width}x{self._spec.height}")
            driver_ns = round(self._cap.get(cv2.CAP_PROP_POS_MSEC) * 1e6)
            capture_ns = self._choose_clock(driver_ns, host_ns)
            time_ns = capture_ns - self._t0
            if time_ns < 0 or time_ns <= self._last_ns:
                continue  # buffered before the session started, or a repeat
            self._last_ns = time_ns
            index = self._index
            self._index += 1
            return index, time_ns, frame

    def _choose_clock(self, driver_ns: int, host_ns: int) -> int:
        plausible = driver_ns > 0 and abs(driver_ns - host_ns) < _DRIVER_CLOCK_TOLERANCE_NS
        if self._driver_clock is None:
            self._driver_clock = plausible
            self.clock = ("driver buffer timestamps (CLOCK_MONOTONIC)" if plausible
                          else "host monotonic clock at grab (driver has no usable timestamps)")
        elif self._driver_clock and (not plausible or driver_ns - self._t0 <= self._last_ns):
            self._driver_clock = False
            self.clock = "host monotonic clock at grab (driver timestamps became unusable)"
        return driver_ns if self._driver_clock else host_ns

    def close(self) -> None:
        self._cap.release()


# ---- video file ---------------------------------------------------------------------------
@dataclass(frozen=True)
class FileSpec:
    """A video file; its frame times are container timestamps + ``offset_s`` seconds."""

    path: str
    width: int
    height: int
    offset_s: float = 0.0

    def describe(self) -> str:
        return f"video file {self.path}" + (f" (offset {self.offset_s:+g} s)"
                                            if self.offset_s else "")

    def open(self) -> FrameSource:
        return _FileSource(self)


class _FileSource(FrameSource):
    live = False

    def __init__(self, spec: FileSpec) -> None:
        if not Path(spec.path).is_file():
            raise SourceError(f"cannot open {spec.describe()}: no such file")
        with native_stderr():  # FFmpeg's own lines for a file that is no video
            self._cap = cv2.VideoCapture(spec.path)
        if not self._cap.isOpened():
            raise SourceError(f"cannot open {spec.describe()}: not a video OpenCV can read")
        self._spec = spec
        self._fps = self._cap.get(cv2.CAP_PROP_FPS) or 0.0
        self._offset_ns = round(spec.offset_s * NS)
        self._index = 0
        self._last_ns = -1
        self._container_clock = True
        self.clock = "container timestamps" + (f" + offset {spec.offset_s:g} s"
                                               if spec.offset_s else "")

    def read(self) -> tuple[int, int, np.ndarray] | None:
        ok, frame = self._cap.read()
        if not ok or frame is None:
            return None
        if frame.shape[:2] != (self._spec.height, self._spec.width):
            raise SourceError(
                f"{self._spec.describe()} has {frame.shape[1]}x{frame.shape[0]} frames, "
                f"the rig says {self._spec.width}x{self._spec.height}")
        index = self._index
        self._index += 1
        stamp_ns = round(self._cap.get(cv2.CAP_PROP_POS_MSEC) * 1e6)
        if self._container_clock and index > 0 and stamp_ns <= self._last_ns - self._offset_ns:
            # no usable container timestamps: fall back to the nominal frame rate
            if self._fps <= 0:
                raise SourceError(f"{self._spec.describe()} has neither timestamps nor a "
                                  f"frame rate")
            self._container_clock = False
            self.clock = f"frame number / {self._fps:g} fps + offset {self._spec.offset_s:g} s"
        if not self._container_clock:
            stamp_ns = round(index / self._fps * NS)
        time_ns = stamp_ns + self._offset_ns
        self._last_ns = time_ns
        return index, time_ns, frame

    def close(self) -> None:
        self._cap.release()

    def end_reason(self) -> str:
        """"end of source", or, when the file's header declares more frames than were
        decoded (a file cut short by a full disk or a crash, damaged in its middle: the
        decoder stops at the first frame it cannot read, exactly as at the end), how many
        were read of how many declared: the recording would otherwise say "0 dropped" and
        end as if the file were whole. A count within one frame of the declared one is the
        end (some containers round their duration)."""
        try:
            declared = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        except (cv2.error, ValueError, OverflowError):
            declared = 0
        if declared > self._index + 1:
            return (f"end of source after {self._index} of the {declared} frames its header "
                    f"declares: the rest could not be decoded (file cut short or damaged)")
        return "end of source"


def end_reason(source) -> str:
    """Why ``source.read()`` returned None, for the recording's summary: its
    :meth:`FrameSource.end_reason` when it has one (a source passed to ``record`` or ``live``
    need only read, set its start and close), else "end of source"."""
    method = getattr(source, "end_reason", None)
    return method() if callable(method) else "end of source"


# ---- synthetic ----------------------------------------------------------------------------
@dataclass(frozen=True)
class SyntheticSpec:
    """A rendered camera of a rig watching ``motion``.

    ``motion.position`` must be picklable (a module-level function, as in
    :data:`pslog.motion.MOTIONS`) since the camera runs in its own process.
    """

    camera: Camera
    camera_index: int
    motion: Motion
    options: RenderOptions
    duration_s: float
    realtime: bool = True

    def describe(self) -> str:
        return f"synthetic {self.camera.name} ({self.motion.name})"

    def open(self) -> FrameSource:
        return _SyntheticSource(self)


def synthetic_times(camera: Camera, duration_s: float) -> np.ndarray:
    """The stamps (k,) int64 ns on ``camera``'s own (logged) clock of its frames: its shutter
    fires at ``offset + k / fps`` on the TRUE clock in ``[0, duration_s)`` (the rig's
    ``offset`` is a phase on the true clock, docs/timing.md; :func:`shutter_times`), and its
    clock stamps a frame's top row at the logged time the rig's clock model maps onto that
    (:func:`pslog.timing.logged_times_ns`, as ``pslog simulate`` logs them): ``offset -
    clock_offset + k / fps`` without drift. A frame stamped before 0 is not taken (as
    simulate drops it). Without a clock correction: the shutter times themselves."""
    true_ns = np.round(shutter_times(camera, duration_s) * NS).astype(np.int64)
    if not camera.has_clock_correction:
        return true_ns
    from pslog.timing import logged_times_ns

    logged = logged_times_ns(true_ns, 0.0, camera.height, camera.clock_offset,
                             camera.clock_drift_ppm, camera.readout)
    return logged[logged >= 0]


class _SyntheticSource(FrameSource):
    def __init__(self, spec: SyntheticSpec) -> None:
        self._spec = spec
        self.live = spec.realtime
        self._renderer = CameraRenderer(spec.camera, spec.options, spec.camera_index)
        self._times = synthetic_times(spec.camera, spec.duration_s)
        self._next = 0
        self._t0 = time.monotonic_ns()
        self.clock = "synthetic shutter schedule" + (" (real time)" if spec.realtime else "")
        self.skipped = 0  # frames skipped because rendering fell behind real time

    def set_start(self, t0_ns: int) -> None:
        self._t0 = int(t0_ns)

    def read(self) -> tuple[int, int, np.ndarray] | None:
        if self._spec.realtime:
            # like a camera, do not wait for a frame whose exposure ended long ago
            late = time.monotonic_ns() - self._t0 - self._spec.camera.frame_period * NS
            while self._next < len(self._times) and self._times[self._next] < late:
                self._next += 1
                self.skipped += 1
        if self._next >= len(self._times):
            return None
        index = self._next
        self._next += 1
        time_ns = int(self._times[index])
        frame = self._renderer.render(self._spec.motion.position, time_ns / NS, index)
        if self._spec.realtime:
            ready_ns = self._t0 + time_ns + int(self._spec.options.exposure_s * NS / 2)
            wait = (ready_ns - time.monotonic_ns()) / NS
            if wait > 0:
                time.sleep(wait)
        return index, time_ns, frame


# ---- pre-decoded frames (benchmarks) --------------------------------------------------------
@dataclass(frozen=True)
class FramesSpec:
    """Frames already decoded into a ``.npy`` file of shape (n, H, W, 3) uint8, replayed
    (cycling) as ``count`` frames at ``fps`` from ``offset_s``; for throughput benchmarks."""

    path: str
    count: int
    fps: float = 30.0
    offset_s: float = 0.0

    def describe(self) -> str:
        return f"decoded frames {self.path}"

    def open(self) -> FrameSource:
        return _FramesSource(self)


class _FramesSource(FrameSource):
    live = False

    def __init__(self, spec: FramesSpec) -> None:
        try:
            self._frames = np.load(spec.path, mmap_mode="r")
        except (OSError, ValueError) as exc:
            raise SourceError(f"cannot open {spec.describe()}: {exc}") from None
        self._spec = spec
        self._next = 0
        self.clock = f"nominal {spec.fps:g} fps"

    def read(self) -> tuple[int, int, np.ndarray] | None:
        if self._next >= self._spec.count:
            return None
        index = self._next
        self._next += 1
        frame = np.ascontiguousarray(self._frames[index % len(self._frames)])
        time_ns = round((self._spec.offset_s + index / self._spec.fps) * NS)
        return index, time_ns, frame
