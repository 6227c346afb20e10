"""Camera calibration: from 3D-2D point correspondences (the paper's Tsai-style set-up) or
from a chessboard (OpenCV's usual intrinsics procedure).

- :mod:`.points` — ``calibrate_from_points``: a normalized DLT start, refined with the
  distortion by ``cv2.calibrateCamera``; with known intrinsics, the pose alone by
  ``cv2.solvePnP``.
- :mod:`.chessboard` — ``calibrate_chessboard``: intrinsics from images or a video of a
  chessboard.
- :mod:`._common` — constants and result types.

Conventions: OpenCV (``x_cam = R @ x_world + t``, plumb_bob ``[k1, k2, p1, p2, k3]``),
metres and pixels. Every public name is re-exported here.
"""

from ._common import (
    AUTO_FULL_MIN_POINTS,
    AUTO_K1K2_MIN_POINTS,
    COLLINEAR_RATIO,
    COPLANAR_RATIO,
    DISTORTION_MODELS,
    IMAGE_SUFFIXES,
    MIN_CHESSBOARD_VIEWS,
    MIN_POINTS,
    MIN_POINTS_POSE,
    CalibrationResult,
    ChessboardResult,
)
from .chessboard import calibrate_chessboard, parse_pattern, read_calibration_images
from .points import (
    calibrate_from_points,
    decompose_projection_matrix,
    dlt_projection_matrix,
    read_points_csv,
)

__all__ = [
    "AUTO_FULL_MIN_POINTS",
    "AUTO_K1K2_MIN_POINTS",
    "COLLINEAR_RATIO",
    "COPLANAR_RATIO",
    "DISTORTION_MODELS",
    "IMAGE_SUFFIXES",
    "MIN_CHESSBOARD_VIEWS",
    "MIN_POINTS",
    "MIN_POINTS_POSE",
    "CalibrationResult",
    "ChessboardResult",
    "calibrate_chessboard",
    "calibrate_from_points",
    "decompose_projection_matrix",
    "dlt_projection_matrix",
    "parse_pattern",
    "read_calibration_images",
    "read_points_csv",
]
