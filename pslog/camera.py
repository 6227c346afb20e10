"""One calibrated camera: intrinsics, plumb_bob distortion, pose and shutter timing.

Conventions (OpenCV): ``x_cam = R @ x_world + t``; pixel ``u`` right, ``v`` down; camera
``z`` forward. Distortion is plumb_bob ``[k1, k2, p1, p2, k3]``. SI units: metres, seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import RigError

_UNDISTORT_ITERATIONS = 20

#: Largest image side accepted, pixels: beyond any camera sensor (the largest are ~16k).
MAX_IMAGE_SIZE = 65536
#: Largest pixel coordinate accepted in a detection (imported or received live), either
#: sign, pixels: ten times the largest image side (a candidate just outside the image is
#: a real detection; one beyond this is not a number any detector gives).
MAX_PIXEL = 10.0 * MAX_IMAGE_SIZE
#: Highest frame rate accepted, frames per second (high-speed cameras reach ~1e5).
MAX_FPS = 1e6
#: Lowest frame rate accepted, frames per second: a frame every 10 s is a time-lapse, not a
#: ball tracker (and a rate near 0 makes frame periods and gaps overflow integer ns).
MIN_FPS = 0.1
#: Largest magnitude of a distortion coefficient accepted. Real plumb_bob fits stay within
#: a few units (k1 about -0.5..0.5 even for wide-angle lenses, k2 and k3 rarely beyond
#: tens, p1 and p2 about 1e-3); a thousand is no lens, and would fold the whole image over.
MAX_DIST = 1e3
_MAX_K = 1e7  # pixels: focal lengths and principal points
_MAX_T_M = 1e6  # metres: a camera 1000 km from the world origin is a typo
#: Largest clock offset accepted, seconds (a day): cameras whose clocks differ by more are
#: on different clocks altogether, which ``pslog import`` handles by a session clock origin.
MAX_CLOCK_OFFSET_S = 86400.0
#: Largest clock drift accepted, ppm: quartz oscillators are within ±100 ppm; 1000 ppm
#: (1 ms per second) is beyond any working clock.
MAX_CLOCK_DRIFT_PPM = 1000.0
#: Least non-zero pixel noise a fusion may assume (``FusionOptions.noise_px``, ``pslog fuse
#: --noise-px``): a tenth of the finest detectors' sub-pixel precision (~0.01 px). Below it
#: std_m is under a micrometre at any rig's scale, and the squares behind the covariances
#: underflow (every typeA point's std_m NaN at 1e-155 px; sync's NEES a 40-digit number at
#: 1e-8).
MIN_FUSE_NOISE_PX = 1e-3
#: Characters a camera name may not hold: names are CSV cells (``,`` ``"``) and parts of MCAP
#: topics ``/camera/<name>/...`` (``/``).
_NAME_FORBIDDEN = ',"/'
_NAME_MAX_LENGTH = 64


def check_camera_name(name) -> str:
    """``name`` if it is usable as a camera name, else :class:`RigError` saying why.

    A name is a CSV cell and a part of MCAP topics: non-empty, at most 64 characters, no
    control characters or line breaks (newlines, tabs, U+2028...), none of ``,`` ``"`` ``/``,
    no surrounding spaces.
    """
    if not isinstance(name, str) or not name:
        raise RigError(f"camera name must be a non-empty string, got {name!r}")
    why = None
    if len(name) > _NAME_MAX_LENGTH:
        why = f"longer than {_NAME_MAX_LENGTH} characters"
    elif any(ord(ch) < 0x20 or 0x7F <= ord(ch) < 0xA0 or ch in "\u2028\u2029"
             for ch in name):  # (U+2028, U+2029: line breaks to str.splitlines)
        why = "holds a control character or line break (newline, tab, ...)"
    elif any(ch in _NAME_FORBIDDEN for ch in name):
        why = "holds one of , \" / (names are CSV cells and parts of MCAP topics)"
    elif name != name.strip():
        why = "starts or ends with a space"
    if why:
        raise RigError(f"camera name {name!r} {why}")
    return name


def holds_non_number(value) -> bool:
    """Whether ``value`` (a number, or nested lists, tuples or arrays of numbers) holds
    anything but real numbers: a string or a boolean, which ``np.array(value, float)`` would
    silently read as a number (a rig's ``K = [["400", ...]]`` as 400, ``true`` as 1)."""
    if isinstance(value, np.ndarray):
        return value.dtype.kind not in "iuf"
    if isinstance(value, list | tuple):
        return any(holds_non_number(v) for v in value)
    return (isinstance(value, bool | np.bool_)
            or not isinstance(value, int | float | np.integer | np.floating))


def _as_array(value, shape: tuple[int, ...], name: str, camera: str) -> np.ndarray:
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # (an integer beyond any float: 10**400)
        raise RigError(f"camera {camera!r}: {name} is not numeric: {value!r}") from None
    if array.shape != shape:
        raise RigError(f"camera {camera!r}: {name} must have shape {shape}, got {array.shape}")
    if holds_non_number(value):  # (after the shape: nested at most two deep)
        raise RigError(f"camera {camera!r}: {name} is not numeric: {value!r}")
    if not np.all(np.isfinite(array)):
        raise RigError(f"camera {camera!r}: {name} has non-finite values")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera with plumb_bob distortion and a shutter schedule.

    Parameters
    ----------
    name : str
        Unique name within a rig (``cam1``).
    width, height : int
        Image size in pixels.
    K : array, shape (3, 3)
        Intrinsic matrix, upper triangular, positive focal lengths.
    dist : array, shape (5,)
        Distortion ``[k1, k2, p1, p2, k3]``.
    R : array, shape (3, 3)
        Rotation world -> camera (``cam_from_world``).
    t : array, shape (3,)
        Translation world -> camera, metres.
    fps : float
        Frame rate, frames per second.
    offset : float
        Nominal shutter offset within the frame period, seconds: frame ``k`` is captured at
        ``offset + k / fps`` on the session clock.
    clock_offset : float
        Offset of this camera's logged times from the session clock, seconds: see
        :mod:`pslog.timing` (true time = logged + clock_offset + drift term + readout term).
        0 for the first camera of a rig, whose clock is the session clock.
    clock_drift_ppm : float
        Rate error of this camera's clock, parts per million (true time gains
        ``clock_drift_ppm * 1e-6`` s per logged second since the session start, 0).
        0 for the first camera of a rig.
    readout : float
        Rolling-shutter readout, seconds from the top row to the bottom row (0: global
        shutter); in ``[0, frame period)``. A frame's logged time refers to its top row.
    """

    name: str
    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    fps: float = 30.0
    offset: float = 0.0
    clock_offset: float = 0.0
    clock_drift_ppm: float = 0.0
    readout: float = 0.0

    def __post_init__(self) -> None:
        name = check_camera_name(self.name)
        for key in ("width", "height"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
                raise RigError(f"camera {name!r}: {key} must be a positive integer, got {value!r}")
            if value > MAX_IMAGE_SIZE:
                raise RigError(f"camera {name!r}: {key} {value} pixels is beyond any camera "
                               f"(at most {MAX_IMAGE_SIZE})")
            object.__setattr__(self, key, int(value))
        K = _as_array(self.K, (3, 3), "K", name)
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise RigError(f"camera {name!r}: K must be upper triangular with K[2,2] = 1")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise RigError(f"camera {name!r}: K focal lengths must be positive, got "
                           f"fx={K[0, 0]}, fy={K[1, 1]}")
        if K[0, 0] < 1 or K[1, 1] < 1:  # K⁻¹ of a sub-pixel focal length overflows
            raise RigError(f"camera {name!r}: K focal lengths must be at least 1 pixel, got "
                           f"fx={K[0, 0]:g}, fy={K[1, 1]:g}")
        if np.abs(K).max() > _MAX_K:
            raise RigError(f"camera {name!r}: K has an entry of {np.abs(K).max():.3g} pixels, "
                           f"beyond any lens (at most {_MAX_K:g})")
        R = _as_array(self.R, (3, 3), "R", name)
        # a rotation's entries lie in [-1, 1]: checked first, R @ R.T of 1e308 overflows
        if (np.abs(R).max() > 1 + 1e-6 or not np.allclose(R @ R.T, np.eye(3), atol=1e-6)
                or abs(np.linalg.det(R) - 1) > 1e-6):
            raise RigError(f"camera {name!r}: R is not a rotation matrix (to 1e-6)")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "R", R)
        object.__setattr__(self, "dist", _as_array(self.dist, (5,), "dist", name))
        if np.abs(self.dist).max() > MAX_DIST:
            raise RigError(f"camera {name!r}: dist has an entry of "
                           f"{np.abs(self.dist).max():.3g}: beyond any lens (distortion "
                           f"coefficients are at most {MAX_DIST:g} in magnitude)")
        object.__setattr__(self, "t", _as_array(self.t, (3,), "t", name))
        if np.abs(self.t).max() > _MAX_T_M:
            raise RigError(f"camera {name!r}: t has an entry of {np.abs(self.t).max():.3g} m "
                           f"(at most {_MAX_T_M:g} m)")
        for key in ("fps", "offset", "clock_offset", "clock_drift_ppm", "readout"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise RigError(f"camera {name!r}: {key} must be a number, got {value!r}")
            try:  # (an integer beyond int64, e.g. TOML's fps = 2**70: np.isfinite refuses it)
                value = float(value)
            except OverflowError:
                raise RigError(f"camera {name!r}: {key} must be finite, got an integer beyond "
                               f"any float") from None
            if not np.isfinite(value):
                raise RigError(f"camera {name!r}: {key} must be finite, got {value!r}")
            # clock keys + 0.0: -0.0 becomes 0.0 (so "written when non-zero" loses nothing)
            object.__setattr__(self, key, float(value) + (0.0 if key != "offset" else -0.0))
        if not MIN_FPS <= self.fps <= MAX_FPS:
            raise RigError(f"camera {name!r}: fps must be in [{MIN_FPS:g}, {MAX_FPS:g}], got "
                           f"{self.fps:g}")
        # the offset is a phase: an offset of a period or more names the same shutter
        # schedule as offset % period and would only make rigs compare unequal
        if not 0.0 <= self.offset < self.frame_period:
            raise RigError(f"camera {name!r}: offset {self.offset:g} s must be in "
                           f"[0, {self.frame_period:.6g} s), the frame period at "
                           f"{self.fps:g} fps")
        if not abs(self.clock_offset) <= MAX_CLOCK_OFFSET_S:
            raise RigError(f"camera {name!r}: clock_offset {self.clock_offset:g} s is beyond "
                           f"±{MAX_CLOCK_OFFSET_S:g} s (a day): not one session clock")
        if not abs(self.clock_drift_ppm) <= MAX_CLOCK_DRIFT_PPM:
            raise RigError(f"camera {name!r}: clock_drift_ppm {self.clock_drift_ppm:g} is "
                           f"beyond ±{MAX_CLOCK_DRIFT_PPM:g} ppm (quartz clocks are within "
                           f"±100 ppm)")
        # a readout of a whole frame period or more would overlap the next frame's rows
        if not 0.0 <= self.readout < self.frame_period:
            raise RigError(f"camera {name!r}: readout {self.readout:g} s must be in "
                           f"[0, {self.frame_period:.6g} s), the frame period at "
                           f"{self.fps:g} fps")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        return (
            (self.name, self.width, self.height, self.fps, self.offset, self.clock_offset,
             self.clock_drift_ppm, self.readout)
            == (other.name, other.width, other.height, other.fps, other.offset,
                other.clock_offset, other.clock_drift_ppm, other.readout)
            and all(np.array_equal(getattr(self, k), getattr(other, k))
                    for k in ("K", "dist", "R", "t"))
        )

    __hash__ = None  # type: ignore[assignment]

    def replace(self, **changes) -> Camera:
        """A copy with some fields changed (validated again)."""
        values = {k: getattr(self, k) for k in
                  ("name", "width", "height", "K", "dist", "R", "t", "fps", "offset",
                   "clock_offset", "clock_drift_ppm", "readout")}
        values.update(changes)
        return Camera(**values)

    # ---- pose -------------------------------------------------------------------------
    @property
    def center_world(self) -> np.ndarray:
        """Camera centre (focal point) in world coordinates, shape (3,), metres: ``-Rᵀ t``."""
        return -self.R.T @ self.t

    @property
    def world_from_cam(self) -> np.ndarray:
        """Homogeneous transform camera -> world, shape (4, 4)."""
        T = np.eye(4)
        T[:3, :3] = self.R.T
        T[:3, 3] = self.center_world
        return T

    @property
    def P(self) -> np.ndarray:
        """Projection matrix ``K [R | t]`` of the undistorted camera, shape (3, 4)."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def has_clock_correction(self) -> bool:
        """True if any of ``clock_offset``, ``clock_drift_ppm``, ``readout`` is non-zero."""
        return bool(self.clock_offset or self.clock_drift_ppm or self.readout)

    @property
    def frame_period(self) -> float:
        """Seconds between two frames."""
        return 1.0 / self.fps

    # ---- projection -------------------------------------------------------------------
    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points to (distorted) pixels.

        Parameters
        ----------
        points_world : array, shape (n, 3), metres

        Returns
        -------
        uv : array, shape (n, 2), pixels; NaN where the point is not in front of the camera
        in_front : array, shape (n,), bool; False for points at or behind the camera plane
        """
        points_world = _check_points(points_world, 3, "points_world")
        # R applied to each row, written out (as in rays: a matmul's rounding may depend on
        # the number of rows, and a point's pixels must not)
        p, R = points_world, self.R
        points_cam = p[:, 0:1] * R[:, 0] + p[:, 1:2] * R[:, 1] + p[:, 2:3] * R[:, 2] + self.t
        z = points_cam[:, 2]
        in_front = z > 1e-12
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = points_cam[:, :2] / np.where(in_front, z, np.nan)[:, None]
        uv = self.pixels_from_normalized(self.distort_normalized(xy))
        return uv, in_front

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Apply plumb_bob distortion to ideal normalized coordinates, shape (n, 2) -> (n, 2)."""
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=1)

    def pixels_from_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Normalized image coordinates (n, 2) -> pixels (n, 2) through K (skew included)."""
        K = self.K
        u = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
        v = K[1, 1] * xy[:, 1] + K[1, 2]
        return np.stack([u, v], axis=1)

    def normalized_from_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Pixels (n, 2) -> normalized (still distorted) coordinates (n, 2) through K⁻¹."""
        K = self.K
        y = (uv[:, 1] - K[1, 2]) / K[1, 1]
        x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=1)

    def undistort_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels (n, 2) -> ideal normalized coordinates (n, 2).

        Inverts :meth:`distort_normalized` by Newton's method with the analytic Jacobian,
        vectorized; converges to machine precision for the distortions of real lenses. Rows
        the distortion model cannot produce (beyond its fold-over radius) come back NaN.
        """
        uv = _check_points(uv, 2, "uv")
        xy_d = self.normalized_from_pixels(uv)
        if not np.any(self.dist):
            return xy_d
        k1, k2, p1, p2, k3 = self.dist
        xy = xy_d.copy()
        # each row stops once it has converged, so its result does not depend on the other
        # rows of the call (a streaming fuser undistorts in other batches than a batch run)
        active = np.ones(len(xy), dtype=bool)
        # far outside the image the polynomial overflows and Newton's steps divide by a zero
        # Jacobian: those rows end NaN below, which is the answer, so no warning is wanted
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            for _ in range(_UNDISTORT_ITERATIONS):
                x, y = xy[:, 0], xy[:, 1]
                r2 = x * x + y * y
                radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
                d_radial = k1 + r2 * (2 * k2 + 3 * k3 * r2)  # d radial / d r2
                residual = self.distort_normalized(xy) - xy_d
                # Jacobian of distort_normalized, per point
                j00 = radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x
                j01 = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
                j10 = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
                j11 = radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x
                det = j00 * j11 - j01 * j10
                dx = (j11 * residual[:, 0] - j01 * residual[:, 1]) / det
                dy = (-j10 * residual[:, 0] + j00 * residual[:, 1]) / det
                active &= ~(np.max(np.abs(residual), axis=1) < 1e-15)
                xy[active, 0] -= dx[active]
                xy[active, 1] -= dy[active]
                if not np.any(active & np.all(np.isfinite(residual), axis=1)):
                    break
            # past the radius where the lens model folds over, no ideal point maps to the
            # pixel: say so with NaN rather than return a wrong ray (a NaN or infinite
            # residual counts as not converged)
            converged = np.abs(self.distort_normalized(xy) - xy_d) <= 1e-9
        xy[~np.all(converged, axis=1)] = np.nan
        return xy

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """Distorted pixels (n, 2) -> ideal (distortion-free) pixels (n, 2) with the same K."""
        return self.pixels_from_normalized(self.undistort_normalized(uv))

    def distort(self, uv_undistorted: np.ndarray) -> np.ndarray:
        """Ideal (undistorted) pixels (n, 2) -> distorted pixels (n, 2): where they fall on
        the recorded image. The inverse of :meth:`undistort`."""
        uv_undistorted = _check_points(uv_undistorted, 2, "uv_undistorted")
        return self.pixels_from_normalized(
            self.distort_normalized(self.normalized_from_pixels(uv_undistorted)))

    def rays(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Viewing rays of (distorted) pixels.

        Returns
        -------
        origin_world : array, shape (3,), the camera centre, metres (the paper's ``T``)
        directions_world : array, shape (n, 3), unit vectors (the paper's ``r``)
        """
        xy = self.undistort_normalized(uv)
        rays_cam = np.hstack([xy, np.ones((len(xy), 1))])
        # scale by the largest component first: the norm of a far-off pixel's ray
        # (1e300 px) would overflow although its direction is well defined
        rays_cam /= np.max(np.abs(rays_cam), axis=1, keepdims=True)
        # Rᵀ applied to each row, written out: a matmul (BLAS) may sum in another order, and
        # so round differently, depending on how many rows it is given, so one detection's
        # ray would depend on the batch it came in (a stream, pushed row by row, would then
        # differ from the batch fusion of the session in the last bits)
        x, y, z = rays_cam[:, 0:1], rays_cam[:, 1:2], rays_cam[:, 2:3]
        R = self.R
        directions_world = x * R[0] + y * R[1] + z * R[2]
        d0, d1, d2 = directions_world[:, 0], directions_world[:, 1], directions_world[:, 2]
        directions_world /= np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)[:, None]
        return self.center_world, directions_world

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Mask (n,) of pixels inside ``[-0.5 + margin, size - 0.5 - margin)``; NaN is outside."""
        u, v = uv[:, 0], uv[:, 1]
        with np.errstate(invalid="ignore"):
            return ((u >= -0.5 + margin) & (u < self.width - 0.5 - margin)
                    & (v >= -0.5 + margin) & (v < self.height - 0.5 - margin))


def _check_points(points, dim: int, name: str) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim == 1 and points.shape == (dim,):
        points = points[None, :]
    if points.ndim != 2 or points.shape[1] != dim:
        raise ValueError(f"{name} must have shape (n, {dim}), got {points.shape}")
    return points


def look_at(eye_world, target_world, up_world=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``R`` and translation ``t`` (world -> camera) of a camera at ``eye_world``
    looking at ``target_world``, with image ``v`` pointing away from ``up_world``."""
    eye = np.asarray(eye_world, dtype=np.float64)
    forward = np.asarray(target_world, dtype=np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up_world, dtype=np.float64))
    if np.linalg.norm(right) < 1e-9:  # looking straight along "up": pick any right vector
        right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])  # rows: camera x, y, z axes in world
    return R, -R @ eye
