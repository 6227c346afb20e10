"""Shared parts of :mod:`pslog.calibration`: constants, result types and the helpers both
the point and the chessboard calibration use."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import Camera

#: Distortion models for :func:`calibrate_from_points`: which of ``[k1, k2, p1, p2, k3]`` are
#: estimated (the others stay zero).
DISTORTION_MODELS = {
    "none": (),
    "k1": ("k1",),
    "k1k2": ("k1", "k2"),
    "k1k2k3": ("k1", "k2", "k3"),
    "full": ("k1", "k2", "p1", "p2", "k3"),
}
#: ``"auto"``: ``none`` below 10 points (6 points give 12 equations for the 10 pinhole + pose
#: unknowns; adding distortion would fit the noise), ``k1k2`` up to 99, ``full`` from 100.
AUTO_K1K2_MIN_POINTS = 10
AUTO_FULL_MIN_POINTS = 100

MIN_POINTS = 6
MIN_POINTS_POSE = 4
#: Points whose spread off their best-fit plane (smallest / largest singular value of the
#: centred points) is below this count as coplanar: the DLT needs real depth.
COPLANAR_RATIO = 1e-3
#: Same for collinear (second / largest) when only the pose is solved.
COLLINEAR_RATIO = 1e-3
MIN_CHESSBOARD_VIEWS = 3

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Outcome of :func:`calibrate_from_points`.

    Attributes
    ----------
    camera : Camera
        The calibrated camera (pose in the world of the points).
    rms_px : float
        Root mean square reprojection error, pixels.
    residuals_px : (n,) float64
        Reprojection error of each point, pixels, in input order.
    model : str
        Distortion model estimated (a key of :data:`DISTORTION_MODELS`), or ``"fixed"``
        when the intrinsics were given and only the pose was solved.
    """

    camera: Camera
    rms_px: float
    residuals_px: np.ndarray
    model: str

    @property
    def fixed_intrinsics(self) -> bool:
        return self.model == "fixed"

    def worst(self, count: int = 5) -> np.ndarray:
        """Indices (into the input points) of the ``count`` largest residuals, worst first."""
        return np.argsort(-self.residuals_px, kind="stable")[:count]


@dataclass(frozen=True, eq=False)
class ChessboardResult:
    """Outcome of :func:`calibrate_chessboard`.

    Attributes
    ----------
    camera : Camera
        Intrinsics and image size from the board; pose as passed in (identity by default).
    rms_px : float
        RMS reprojection error over all corners of the used views, pixels.
    used, rejected : tuple of int
        Indices of the input images in which the board was / was not found.
    view_rms_px : (len(used),) float64
        RMS reprojection error per used view, pixels.
    """

    camera: Camera
    rms_px: float
    used: tuple[int, ...]
    rejected: tuple[int, ...]
    view_rms_px: np.ndarray


# ---- helpers ----------------------------------------------------------------------------------

def _make_camera(name, width, height, K, dist, R, t, fps, offset) -> Camera:
    K = np.array(K, dtype=np.float64)
    K[1, 0] = K[2, 0] = K[2, 1] = 0.0
    K[2, 2] = 1.0
    return Camera(name, int(width), int(height), K, np.asarray(dist, dtype=np.float64), R,
                  np.asarray(t, dtype=np.float64).ravel(), fps=fps, offset=offset)


def _cv_message(exc: cv2.error) -> str:
    text = str(exc).strip().splitlines()
    return text[-1] if text else "OpenCV error"
