"""Columnar building blocks for the rerun recording: timelines, colours, image-space helpers.

Everything here works on whole columns (numpy arrays); the recording is sent with
``rr.send_columns`` in a few calls per entity, never one call per point.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import rerun as rr

from pslog import palette
from pslog.camera import Camera

#: Name of the capture-time timeline (the session's common clock).
CAPTURE_TIME = "capture_time"
#: Name of the frame-index timeline (each camera's frame counter).
FRAME = "frame"

# Session clocks later than this (1973 in Unix time) are wall clocks: shown as timestamps.
_EPOCH_CLOCK_NS = 100_000_000 * 1_000_000_000

#: OpenCV puts pixel centres at integer coordinates, rerun's image space at +0.5 (the image
#: covers [0, width] x [0, height]); 2D points and the pinhole's principal point shift by this.
PIXEL_CENTER = 0.5

# one palette for every viewer and the MCAP's Foxglove scene (pslog/palette.py)
METHOD_COLORS = palette.METHOD_COLORS
CAMERA_COLORS = palette.CAMERA_COLORS
TRUTH_COLOR = palette.TRUTH_COLOR
REJECTED_COLOR = palette.REJECTED_COLOR
COLOR_NAMES = palette.COLOR_NAMES


def camera_path(name: str) -> str:
    return f"world/cameras/{name}"


def image_path(name: str) -> str:
    return f"world/cameras/{name}/image"


method_colors = palette.method_colors
camera_color = palette.camera_color


class Clock:
    """Index columns for the two timelines.

    ``capture_time`` is a duration timeline (seconds from the clock's zero) for session clocks
    that start near zero (simulations, host monotonic clocks) and a timestamp timeline for
    wall clocks, so the viewer shows readable times either way.
    """

    def __init__(self, first_ns: int) -> None:
        self.wall = first_ns > _EPOCH_CLOCK_NS

    def index(self, time_ns: np.ndarray, frame: np.ndarray | None = None) -> list[rr.TimeColumn]:
        """TimeColumns for rows at ``time_ns`` (n,) int64 and optional ``frame`` (n,) int64."""
        # integer nanoseconds, passed as datetime/timedelta so rerun does not scale them
        time_ns = np.asarray(time_ns, dtype=np.int64)
        if self.wall:
            columns = [rr.TimeColumn(CAPTURE_TIME, timestamp=time_ns.astype("datetime64[ns]"))]
        else:
            columns = [rr.TimeColumn(CAPTURE_TIME, duration=time_ns.astype("timedelta64[ns]"))]
        if frame is not None:
            columns.append(rr.TimeColumn(FRAME, sequence=np.asarray(frame, dtype=np.int64)))
        return columns


def send(rec: rr.RecordingStream, path: str, clock: Clock, time_ns: np.ndarray,
         frame: np.ndarray | None, columns) -> int:
    """``send_columns`` for ``len(time_ns)`` rows (nothing when there are none); returns rows."""
    if len(time_ns) == 0:
        return 0
    rr.send_columns(path, indexes=clock.index(time_ns, frame), columns=columns, recording=rec)
    return len(time_ns)


def strips_array(strips: np.ndarray) -> pa.ListArray:
    """Polylines of equal length as rerun's LineStrip2D/3D arrow column, built in one go.

    Parameters
    ----------
    strips : (n, s, d) float, d = 2 (image) or 3 (world, metres): n polylines of s points

    Returns
    -------
    The arrow list array rerun takes as is (its own conversion walks the strips one by one
    in Python: seconds for the half a million rays of a 90-minute match).
    """
    strips = np.ascontiguousarray(strips, dtype=np.float32)
    n, s, d = strips.shape
    batch = rr.components.LineStrip3DBatch if d == 3 else rr.components.LineStrip2DBatch
    kind = batch._ARROW_DATATYPE
    inner = pa.FixedSizeListArray.from_arrays(pa.array(strips.reshape(-1)),
                                              type=kind.value_type)
    offsets = pa.array(np.arange(n + 1, dtype=np.int32) * s)
    return pa.ListArray.from_arrays(offsets, inner, type=kind)


def image_space(uv: np.ndarray) -> np.ndarray:
    """OpenCV pixels (n, 2) -> rerun image coordinates (n, 2) float32 (see PIXEL_CENTER);
    a pixel beyond float32 (a recording made before live refused them) becomes infinite."""
    with np.errstate(over="ignore"):
        return (np.asarray(uv, dtype=np.float64) + PIXEL_CENTER).astype(np.float32)


def undistorted_bounds(cam: Camera) -> tuple[float, float, float, float]:
    """Bounding box ``(u_min, v_min, u_max, v_max)`` of the image border in undistorted
    pixels: epipolar lines are clipped to it before being sampled and re-distorted."""
    w, h = cam.width, cam.height
    if not np.any(cam.dist):
        return -0.5, -0.5, w - 0.5, h - 0.5
    s = np.linspace(0.0, 1.0, 65)
    border = np.concatenate([
        np.column_stack([s * w - 0.5, np.full_like(s, -0.5)]),
        np.column_stack([s * w - 0.5, np.full_like(s, h - 0.5)]),
        np.column_stack([np.full_like(s, -0.5), s * h - 0.5]),
        np.column_stack([np.full_like(s, w - 0.5), s * h - 0.5]),
    ])
    uv = cam.undistort(border)
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    # a strongly distorted lens can send the corners far out: stay within 3 image sizes
    lo = np.maximum(uv.min(axis=0), [-w, -h])
    hi = np.minimum(uv.max(axis=0), [2 * w, 2 * h])
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def line_polylines(cam: Camera, lines: np.ndarray, samples: int = 24
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Image lines of undistorted pixels drawn on the distorted image of ``cam``.

    Parameters
    ----------
    cam : the camera whose image the lines are in
    lines : (n, 3) float64, ``a u + b v + c = 0`` with ``a² + b² = 1``, undistorted pixels
    samples : points per polyline when the lens distorts (a straight line needs two)

    Returns
    -------
    strips : (m, s, 2) float32, rerun image coordinates, one polyline per visible line
    visible : (n,) bool, which lines cross the image (rows of ``strips``)
    """
    lines = np.asarray(lines, dtype=np.float64).reshape(-1, 3)
    s = samples if np.any(cam.dist) else 2
    u0, v0, u1, v1 = undistorted_bounds(cam)
    normal = lines[:, :2]
    direction = np.column_stack([-normal[:, 1], normal[:, 0]])
    foot = -lines[:, 2:3] * normal  # point of the line nearest the origin
    # slab clipping of foot + k * direction to the box, vectorized
    with np.errstate(divide="ignore", invalid="ignore"):
        k_lo = np.full(len(lines), -np.inf)
        k_hi = np.full(len(lines), np.inf)
        for axis, lo, hi in ((0, u0, u1), (1, v0, v1)):
            d = direction[:, axis]
            p = foot[:, axis]
            ka, kb = (lo - p) / d, (hi - p) / d
            flat = np.abs(d) < 1e-12
            inside = (p >= lo) & (p <= hi)
            k_lo = np.where(flat, np.where(inside, k_lo, np.inf),
                            np.maximum(k_lo, np.minimum(ka, kb)))
            k_hi = np.where(flat, np.where(inside, k_hi, -np.inf),
                            np.minimum(k_hi, np.maximum(ka, kb)))
    visible = np.isfinite(k_lo) & np.isfinite(k_hi) & (k_hi > k_lo)
    visible &= np.all(np.isfinite(lines), axis=1)
    t = np.linspace(0.0, 1.0, s)
    k = k_lo[visible, None] + (k_hi - k_lo)[visible, None] * t[None, :]  # (m, s)
    points = foot[visible, None, :] + k[:, :, None] * direction[visible, None, :]
    distorted = cam.distort(points.reshape(-1, 2)).reshape(-1, s, 2)
    return image_space(distorted.reshape(-1, 2)).reshape(-1, s, 2), visible


def lengths_of(mask_2d: np.ndarray) -> np.ndarray:
    """Partition lengths (rows,) of a (rows, k) boolean mask flattened row-major."""
    return np.asarray(mask_2d, dtype=bool).sum(axis=1).astype(np.int64)
