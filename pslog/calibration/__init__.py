"""Camera calibration: from 3D-2D point correspondences (the paper's Tsai-style set-up) or
from a chessboard (OpenCV's usual intrinsics procedure).

Points (``calibrate_from_points``)
    A normalized DLT of the 3x4 projection matrix gives a pinhole start (K, R, t), which
    ``cv2.calibrateCamera`` (one non-planar view, ``CALIB_USE_INTRINSIC_GUESS``) refines
    together with the distortion by Levenberg-Marquardt. Skew is dropped (OpenCV's model has
    none). How many distortion terms are estimated depends on the number of points
    (:data:`DISTORTION_MODELS`, ``"auto"``): one view of a few dozen points constrains the
    radial terms well but the tangential terms and k3 only weakly (they trade off against the
    principal point and k1/k2), so those stay zero unless there are plenty of points.
    With known intrinsics (``K``/``dist`` given) only the pose is solved (``cv2.solvePnP``),
    and coplanar points are fine.

Chessboard (``calibrate_chessboard``)
    ``findChessboardCorners`` + ``cornerSubPix`` per image, then ``calibrateCamera`` with
    OpenCV's default 5-term model. A chessboard does not give the camera's pose in the world;
    the caller keeps a known pose or uses identity.

Conventions: OpenCV (``x_cam = R @ x_world + t``, plumb_bob ``[k1, k2, p1, p2, k3]``),
metres and pixels.

The package splits into :mod:`.points` (3D-2D correspondences, DLT), :mod:`.chessboard`
(chessboard images and videos) and :mod:`._common` (constants and result types); every
public name is re-exported here.
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
