"""Camera intrinsics from a chessboard (OpenCV's usual procedure).

``findChessboardCorners`` + ``cornerSubPix`` per image, then ``calibrateCamera`` with
OpenCV's default 5-term model. A chessboard does not give the camera's pose in the world;
the caller keeps a known pose or uses identity.

Images come from a folder or a video file (:func:`read_calibration_images`).

Conventions: OpenCV (``x_cam = R @ x_world + t``, plumb_bob ``[k1, k2, p1, p2, k3]``),
metres and pixels.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError, PslogError, shown
from ._common import (
    IMAGE_SUFFIXES,
    MIN_CHESSBOARD_VIEWS,
    ChessboardResult,
    _cv_message,
    _make_camera,
)

# ---- chessboard -------------------------------------------------------------------------------

#: Fewest inner corners per side: OpenCV's corner finder needs more than 2 (a 2xN pattern
#: was a cv2.error traceback).
MIN_PATTERN_SIDE = 3
#: Most inner corners per side: beyond any printed board (9x6 to 30x20); a 99999x99999
#: pattern asked for a 112 GiB array of board points, said as "out of memory".
MAX_PATTERN_SIDE = 1000
#: Smallest square side, metres: 0.1 mm, below any printed board's (at 1e-30 m OpenCV's
#: initial homography failed with its own assertion text).
MIN_SQUARE_M = 1e-4
#: Largest square side, metres: no board's square is larger.
MAX_SQUARE_M = 1.0


def check_pattern(pattern: object, text: object = None) -> tuple[int, int]:
    """``pattern`` as (cols, rows) if both are whole numbers in [:data:`MIN_PATTERN_SIDE`,
    :data:`MAX_PATTERN_SIDE`], else :class:`InputError` naming it (as ``text`` if given)."""
    spelled = pattern if text is None else text
    # (a numpy array of two whole numbers too, as API callers hold sizes: np.array((9, 6)))
    sides = (tuple(pattern) if isinstance(pattern, (tuple, list)) else
             tuple(pattern.tolist()) if isinstance(pattern, np.ndarray) and pattern.ndim == 1
             else ())
    if len(sides) != 2 or not all(isinstance(p, (int, np.integer)) and not isinstance(p, bool)
                                  for p in sides):
        raise InputError(f"bad chessboard pattern {shown(spelled, 80)}: expected COLSxROWS of "
                         f"inner corners, e.g. 9x6")
    cols, rows = int(sides[0]), int(sides[1])
    if not (MIN_PATTERN_SIDE <= min(cols, rows) and max(cols, rows) <= MAX_PATTERN_SIDE):
        raise InputError(f"bad chessboard pattern {shown(spelled, 80)}: each side needs "
                         f"{MIN_PATTERN_SIDE} to {MAX_PATTERN_SIDE} inner corners")
    return cols, rows


def check_square(square: object) -> float:
    """``square`` as metres if it is a number in [:data:`MIN_SQUARE_M`,
    :data:`MAX_SQUARE_M`], else :class:`InputError` naming it."""
    if (isinstance(square, bool) or not isinstance(square, (int, float, np.number))
            or not MIN_SQUARE_M <= float(square) <= MAX_SQUARE_M):
        raise InputError(f"chessboard square {square!r} m: give its side in "
                         f"[{MIN_SQUARE_M:g}, {MAX_SQUARE_M:g}] metres")
    return float(square)

def parse_pattern(text: str) -> tuple[int, int]:
    """``"9x6"`` -> ``(9, 6)``: inner corners per row and per column, each in
    [:data:`MIN_PATTERN_SIDE`, :data:`MAX_PATTERN_SIDE`] (:func:`check_pattern`)."""
    parts = str(text).lower().replace("×", "x").split("x")
    try:
        cols, rows = (int(p) for p in parts)
    except ValueError:
        raise InputError(f"bad chessboard pattern {text!r}: expected COLSxROWS of inner "
                         f"corners, e.g. 9x6") from None
    return check_pattern((cols, rows), text)


def read_calibration_images(path: str | Path, *, max_frames: int = 60,
                            unreadable: list[str] | None = None
                            ) -> tuple[list[np.ndarray], list[str]]:
    """Load calibration images from a folder of images or a video file.

    Parameters
    ----------
    path : str or Path
        A folder (every image file in it, sorted by name) or a video file.
    max_frames : int
        From a video, at most this many frames, evenly spaced over its length (neighbouring
        frames show nearly the same view and only slow the calibration down).
    unreadable : list of str, optional
        Given: an image file of the folder that cannot be read or decoded is skipped and
        named here (``"x.png (empty file)"``) instead of raising; raises only when no file
        is left.

    Returns
    -------
    images : list of (height, width) uint8 grayscale arrays
    labels : list of str, the file name or ``frame N`` of each image

    Raises
    ------
    InputError
        Missing path, unreadable image, a video that cannot be opened, or no images.
    """
    path = Path(path)
    if not path.exists():
        from ..inputs import not_there

        raise InputError(not_there(path) or f"calibration images not found: {path}")
    if path.is_dir():
        files = sorted(p for p in path.iterdir()
                       if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise InputError(f"no image files ({', '.join(IMAGE_SUFFIXES)}) in folder {path}")
        from ..outputs import native_stderr

        images, labels, skipped = [], [], []
        for file in files:
            with native_stderr():  # libpng's / libjpeg's own words: the reason is said below
                image = cv2.imread(str(file), cv2.IMREAD_GRAYSCALE)
            if image is None:
                why = _unreadable_reason(file)
                if unreadable is None:
                    raise InputError(f"cannot read image {file} ({why})")
                skipped.append(f"{file.name} ({why})")
                continue
            images.append(image)
            labels.append(file.name)
        if unreadable is not None:
            unreadable.extend(skipped)
        if not images:
            raise InputError(f"none of the {len(files)} image files in folder {path} can be "
                             f"read: {listed(skipped)}")
        return images, labels
    return _read_video_frames(path, max_frames)


def _unreadable_reason(file: Path) -> str:
    """Why OpenCV read no image from ``file``, in pslog's words."""
    try:
        with open(file, "rb") as f:
            head = f.read(1)
    except OSError as exc:
        from ..outputs import os_reason

        return f"cannot be opened: {os_reason(exc)}"
    return "empty file" if not head else "not a decodable image"


def listed(names: Sequence[str], most: int = 5) -> str:
    """``a, b, c, ... (N more)``: at most ``most`` names (a message's list of files)."""
    more = f", ... ({len(names) - most} more)" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def calibrate_chessboard(
    images: Sequence[np.ndarray],
    pattern: tuple[int, int] = (9, 6),
    square: float = 0.025,
    *,
    name: str = "cam",
    fps: float = 30.0,
    offset: float = 0.0,
    R: np.ndarray | None = None,
    t: np.ndarray | None = None,
) -> ChessboardResult:
    """Intrinsics from views of a chessboard (OpenCV's standard procedure).

    Parameters
    ----------
    images : sequence of (height, width) uint8 grayscale or (height, width, 3) BGR arrays,
        all the same size
    pattern : (cols, rows)
        Inner corners per row and per column (a board of 10 x 7 squares is ``(9, 6)``), each
        3 to 1000.
    square : float
        Side of a square, metres, 1e-4 to 1 (scales only the per-view board poses, which are
        discarded).
    name, fps, offset
        Copied into the camera.
    R, t : optional
        Pose to give the camera (world -> camera); identity and zero if omitted.

    Returns
    -------
    ChessboardResult

    Raises
    ------
    InputError
        No images, images of different sizes, the board found in fewer than
        :data:`MIN_CHESSBOARD_VIEWS` images, or a pattern or square outside the bounds above.
    """
    cols, rows = check_pattern(pattern)
    square = check_square(square)
    if not images:
        raise InputError("no calibration images")
    grays = [_gray(im) for im in images]
    size = grays[0].shape
    for i, gray in enumerate(grays):
        if gray.shape != size:
            raise InputError(f"image {i} is {gray.shape[1]}x{gray.shape[0]}, the first is "
                             f"{size[1]}x{size[0]}; all images must have the same size")
    height, width = size
    board = np.zeros((cols * rows, 3), np.float32)
    board[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square

    find_flags = (cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
                  | cv2.CALIB_CB_FAST_CHECK)
    subpix_criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    corners, used, rejected = [], [], []
    for i, gray in enumerate(grays):
        found, found_corners = cv2.findChessboardCorners(gray, (cols, rows), flags=find_flags)
        if not found:
            rejected.append(i)
            continue
        corners.append(cv2.cornerSubPix(gray, found_corners,
                                        _subpix_window(found_corners, cols, rows), (-1, -1),
                                        subpix_criteria))
        used.append(i)
    if not used:
        raise InputError(f"no {cols}x{rows} chessboard found in any of the {len(grays)} "
                         f"images (pattern counts inner corners)")
    if len(used) < MIN_CHESSBOARD_VIEWS:
        raise InputError(f"{cols}x{rows} chessboard found in only {len(used)} of "
                         f"{len(grays)} images; need at least {MIN_CHESSBOARD_VIEWS} views")
    try:
        rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(
            [board] * len(used), corners, (width, height), None, None)
    except cv2.error as exc:
        raise InputError(f"chessboard calibration failed: {_cv_message(exc)}") from None
    view_rms = np.empty(len(used))
    for k, (rvec, tvec, found_corners) in enumerate(zip(rvecs, tvecs, corners, strict=True)):
        projected = cv2.projectPoints(board, rvec, tvec, K, dist)[0].reshape(-1, 2)
        view_rms[k] = np.sqrt(np.mean(np.sum((projected - found_corners.reshape(-1, 2)) ** 2,
                                             axis=1)))
    pose = (np.eye(3) if R is None else R, np.zeros(3) if t is None else t)
    # the user's values (name, size, rate, offset, pose) checked with a plain lens first: a
    # camera refused below is then OpenCV's solution, not them
    _make_camera(name, width, height, [[width, 0, width / 2], [0, width, height / 2],
                                       [0, 0, 1]], np.zeros(5), *pose, fps, offset)
    try:
        camera = _make_camera(name, width, height, K, dist.ravel()[:5], *pose, fps, offset)
    except PslogError as exc:  # no lens at all: too few views, or views too alike
        raise InputError(f"chessboard calibration from {len(used)} views gave no plausible "
                         f"lens ({exc}); take more views, the board tilted in different "
                         f"directions and near the image's corners") from None
    return ChessboardResult(camera, float(rms), tuple(used), tuple(rejected), view_rms)


# ---- helpers ----------------------------------------------------------------------------------

#: Largest half-side of ``cornerSubPix``'s search window, pixels (OpenCV's sample's 11).
MAX_SUBPIX_HALF_WINDOW = 11


def _subpix_window(found: np.ndarray, cols: int, rows: int) -> tuple[int, int]:
    """``cornerSubPix``'s half window for one view: half the closest two corners' spacing.

    A fixed 11 px half window (a 23 px search square) reaches past the neighbouring corners
    of a board whose squares are small in the image (a webcam's 640x480, a 25 mm board a
    metre away: squares of 12-15 px): every corner was pulled towards its neighbours, and a
    camera of f 520 px calibrated at 362 px, RMS 1.4 px (session 42's walkthrough). Half the
    spacing (ROS camera_calibration's rule) keeps the window to the corner's own squares; at
    most :data:`MAX_SUBPIX_HALF_WINDOW`, so a board large in the image is refined as before.
    """
    grid = found.reshape(rows, cols, 2).astype(np.float64)
    spacing = min(float(np.linalg.norm(np.diff(grid, axis=0), axis=2).min()),
                  float(np.linalg.norm(np.diff(grid, axis=1), axis=2).min()))
    half = int(min(MAX_SUBPIX_HALF_WINDOW, max(1, np.ceil(0.5 * spacing))))
    return half, half


def _gray(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.dtype != np.uint8:
        raise InputError(f"calibration images must be 8-bit, got {image.dtype}")
    return image


def _read_video_frames(path: Path, max_frames: int) -> tuple[list[np.ndarray], list[str]]:
    from ..outputs import native_stderr

    with native_stderr():
        return _read_video_frames_quietly(path, max_frames)


def _read_video_frames_quietly(path: Path, max_frames: int
                               ) -> tuple[list[np.ndarray], list[str]]:
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise InputError(f"{path} is neither a folder of images nor a readable video")
        count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        wanted = None
        if count > max_frames:
            wanted = set(np.linspace(0, count - 1, max_frames).round().astype(int).tolist())
        # Read sequentially (seeking is unreliable in many codecs) and keep the wanted frames.
        images, labels, index = [], [], 0
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            if wanted is None or index in wanted:
                images.append(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
                labels.append(f"frame {index}")
            index += 1
    finally:
        capture.release()
    if not images:
        raise InputError(f"no frames could be read from video {path}")
    return images, labels
