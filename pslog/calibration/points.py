"""Camera calibration from 3D-2D point correspondences (the paper's Tsai-style set-up).

A normalized DLT of the 3x4 projection matrix gives a pinhole start (K, R, t), which
``cv2.calibrateCamera`` (one non-planar view, ``CALIB_USE_INTRINSIC_GUESS``) refines
together with the distortion by Levenberg-Marquardt. Skew is dropped (OpenCV's model has
none). How many distortion terms are estimated depends on the number of points
(:data:`DISTORTION_MODELS`, ``"auto"``): one view of a few dozen points constrains the
radial terms well but the tangential terms and k3 only weakly (they trade off against the
principal point and k1/k2), so those stay zero unless there are plenty of points.
With known intrinsics (``K``/``dist`` given) only the pose is solved (``cv2.solvePnP``),
and coplanar points are fine.

Conventions: OpenCV (``x_cam = R @ x_world + t``, plumb_bob ``[k1, k2, p1, p2, k3]``),
metres and pixels.
"""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np

from ..camera import MAX_PIXEL, Camera
from ..errors import InputError
from ..inputs import check_input_file, not_there
from ._common import (
    AUTO_FULL_MIN_POINTS,
    AUTO_K1K2_MIN_POINTS,
    COLLINEAR_RATIO,
    COPLANAR_RATIO,
    DISTORTION_MODELS,
    MIN_POINTS,
    MIN_POINTS_POSE,
    CalibrationResult,
    _cv_message,
    _make_camera,
)

_POINT_COLUMNS = ("x", "y", "z", "u", "v")
#: Largest magnitude of each column: a surveyed point 1000 km from the origin, or a pixel
#: beyond any image, is a typo (the cameras' own bound, camera.py)
_MAX_WORLD_M = 1e6
_MAX_VALUE = (_MAX_WORLD_M,) * 3 + (MAX_PIXEL,) * 2
_BEYOND = (f"any surveyed point (at most {_MAX_WORLD_M:g} m from the origin)",) * 3 + (
    f"any image (at most {MAX_PIXEL:g} pixels)",) * 2
_LM_CRITERIA = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-15)
_DIST_FLAGS = {"k1": cv2.CALIB_FIX_K1, "k2": cv2.CALIB_FIX_K2, "k3": cv2.CALIB_FIX_K3}


# ---- point correspondences -------------------------------------------------------------------

def read_points_csv(path: str | Path, *, with_lines: bool = False):
    """Read 3D-2D correspondences from a CSV with header ``x,y,z,u,v``.

    Columns may come in any order; other columns (labels) are ignored; blank lines are
    skipped.

    Parameters
    ----------
    path : str or Path
    with_lines : bool
        Also return the file line number of each point.

    Returns
    -------
    points_world : (n, 3) float64 metres
    uv : (n, 2) float64 pixels (as detected, i.e. distorted)
    lines : (n,) int64, only with ``with_lines``: 1-based line of each point in the file

    Raises
    ------
    InputError
        Missing file, missing column, wrong number of fields or a non-numeric / non-finite
        value (the message names the line).
    """
    path = Path(path)
    if path.exists():  # a folder, device or FIFO: said in pslog's words (not read for ever)
        check_input_file(path, "points file")
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except FileNotFoundError:
        raise InputError(not_there(path) or f"points file not found: {path}") from None
    except UnicodeDecodeError as exc:  # (not the codec's own words)
        raise InputError(f"{path}: not a text CSV file (byte {exc.start} is not UTF-8 text); "
                         f"expected header x,y,z,u,v") from None
    except OSError as exc:
        raise InputError(not_there(path) or f"cannot read points file {path}: "
                                            f"{exc.strerror or exc}") from None
    except csv.Error as exc:
        raise InputError(f"cannot read points file {path}: {exc}") from None
    numbered = [(i + 1, row) for i, row in enumerate(rows) if any(c.strip() for c in row)]
    if not numbered:
        raise InputError(f"{path}: empty file (expected header x,y,z,u,v)")
    header_line, header = numbered[0]
    header = [c.strip().lower() for c in header]
    missing = [c for c in _POINT_COLUMNS if c not in header]
    if missing:
        raise InputError(f"{path}:{header_line}: missing column(s) {','.join(missing)} "
                         f"(header must contain x,y,z,u,v; got {','.join(header)})")
    columns = [header.index(c) for c in _POINT_COLUMNS]
    values = np.empty((len(numbered) - 1, 5))
    lines = np.empty(len(numbered) - 1, dtype=np.int64)
    for k, (line, row) in enumerate(numbered[1:]):
        if len(row) != len(header):
            raise InputError(f"{path}:{line}: expected {len(header)} fields, got {len(row)}")
        for j, col in enumerate(columns):
            text = row[col].strip()
            try:
                value = float(text)
            except ValueError:
                raise InputError(f"{path}:{line}: {_POINT_COLUMNS[j]} is not a number: "
                                 f"{text!r}") from None
            if not np.isfinite(value):
                raise InputError(f"{path}:{line}: {_POINT_COLUMNS[j]} is not finite: {text!r}")
            if abs(value) > _MAX_VALUE[j]:  # (else "coplanar" or a failed solve, not the cell)
                raise InputError(f"{path}:{line}: {_POINT_COLUMNS[j]} {text} is beyond "
                                 f"{_BEYOND[j]}")
            values[k, j] = value
        lines[k] = line
    points_world, uv = np.ascontiguousarray(values[:, :3]), np.ascontiguousarray(values[:, 3:])
    return (points_world, uv, lines) if with_lines else (points_world, uv)


def calibrate_from_points(
    points_world: np.ndarray,
    uv: np.ndarray,
    width: int,
    height: int,
    *,
    name: str = "cam",
    fps: float = 30.0,
    offset: float = 0.0,
    K: np.ndarray | None = None,
    dist: np.ndarray | None = None,
    model: str = "auto",
) -> CalibrationResult:
    """Calibrate one camera from world points and their pixels.

    Parameters
    ----------
    points_world : (n, 3) float64 metres
        At least 6 non-coplanar points, or at least 4 non-collinear points when ``K`` is
        given.
    uv : (n, 2) float64 pixels
        Their (distorted) image positions.
    width, height : int
        Image size, pixels.
    name, fps, offset
        Copied into the returned camera.
    K : (3, 3) float64, optional
        Known intrinsics: solve the pose only (``cv2.solvePnP``), keeping ``K`` and ``dist``.
    dist : (5,) float64, optional
        Known distortion ``[k1, k2, p1, p2, k3]`` (zeros if omitted), used only with ``K``.
    model : str
        Distortion terms to estimate: ``"auto"`` or a key of :data:`DISTORTION_MODELS`.

    Returns
    -------
    CalibrationResult

    Raises
    ------
    InputError
        Too few, coplanar (without ``K``), collinear or non-finite points, points behind the
        camera, or an estimation that fails.
    """
    points_world, uv = _check_correspondences(points_world, uv)
    n = len(points_world)
    if K is not None:
        return _solve_pose(points_world, uv, width, height, name, fps, offset, K, dist)
    if dist is not None:
        raise InputError("dist given without K: known distortion needs known intrinsics")
    if n < MIN_POINTS:
        raise InputError(f"need at least {MIN_POINTS} points to calibrate, got {n} "
                         f"(4 suffice with known intrinsics)")
    singular = _spread(points_world)
    if singular[2] <= COPLANAR_RATIO * singular[0]:
        raise InputError(f"the {n} points are coplanar (off-plane spread "
                         f"{singular[2] / singular[0]:.1e} of their extent); full calibration "
                         f"needs points at different depths, or known intrinsics "
                         f"(--fix-intrinsics)")
    if model == "auto":
        model = ("none" if n < AUTO_K1K2_MIN_POINTS
                 else "k1k2" if n < AUTO_FULL_MIN_POINTS else "full")
    if model not in DISTORTION_MODELS:
        raise InputError(f"unknown distortion model {model!r} "
                         f"(choose from auto, {', '.join(DISTORTION_MODELS)})")
    n_unknowns = 10 + len(DISTORTION_MODELS[model])
    if 2 * n < n_unknowns:
        raise InputError(f"distortion model {model!r} has {n_unknowns} unknowns; "
                         f"{n} points give only {2 * n} equations")

    P = dlt_projection_matrix(points_world, uv)
    K0, R0, t0 = decompose_projection_matrix(P)
    _check_in_front(points_world, R0, t0, "the DLT solution")
    K0[0, 1] = 0.0  # OpenCV's model has no skew; the DLT's small skew is noise
    cx, cy = K0[0, 2], K0[1, 2]
    if not (0 <= cx < width and 0 <= cy < height):  # (OpenCV's bare assertion otherwise)
        raise InputError(f"the points' principal point ({cx:.1f}, {cy:.1f}) px lies outside "
                         f"the {width}x{height} image (its pixels reach u {uv[:, 0].max():.0f},"
                         f" v {uv[:, 1].max():.0f}): check --width/--height, and that each u,v "
                         f"belongs to its x,y,z")

    flags = cv2.CALIB_USE_INTRINSIC_GUESS
    estimated = DISTORTION_MODELS[model]
    for term, flag in _DIST_FLAGS.items():
        if term not in estimated:
            flags |= flag
    if "p1" not in estimated:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    try:
        _, K1, dist1, rvecs, tvecs = cv2.calibrateCamera(
            [points_world.astype(np.float32)], [uv.astype(np.float32)], (int(width), int(height)),
            K0, np.zeros(5), flags=flags, criteria=_LM_CRITERIA)
    except cv2.error as exc:
        raise InputError(f"calibration did not converge: {_cv_message(exc)}") from None
    # calibrateCamera works in float32 for the points; polish in float64 so that noise-free
    # data is recovered to the last digits.
    K1, dist1, R1, t1 = _refine_float64(points_world, uv, K1, dist1.ravel()[:5],
                                        rvecs[0], tvecs[0], estimated)
    if not (np.all(np.isfinite(K1)) and np.all(np.isfinite(dist1)) and K1[0, 0] > 0
            and K1[1, 1] > 0):
        raise InputError("calibration diverged (check that each u,v belongs to its x,y,z)")
    _check_in_front(points_world, R1, t1, "the refined solution")
    camera = _make_camera(name, width, height, K1, dist1, R1, t1, fps, offset)
    return _result(camera, points_world, uv, model)


def dlt_projection_matrix(points_world: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Normalized (Hartley) DLT estimate of the projection matrix.

    Parameters
    ----------
    points_world : (n, 3) float64 metres, n >= 6, not coplanar
    uv : (n, 2) float64 pixels

    Returns
    -------
    P : (3, 4) float64 with ``uv ~ P @ [x, y, z, 1]``, scaled to ``||P[2, :3]|| = 1``; its
    overall sign is arbitrary.
    """
    # Normalizing both point sets (centroid at 0, mean distance sqrt(dim)) makes the linear
    # system well conditioned; without it, pixels (~100s) and metres (~1) differ by orders of
    # magnitude and the SVD solution is noticeably worse.
    T_world = _normalizing_transform(points_world)
    T_image = _normalizing_transform(uv)
    X = _homogeneous(points_world) @ T_world.T
    x = _homogeneous(uv) @ T_image.T
    n = len(X)
    A = np.zeros((2 * n, 12))
    A[0::2, 0:4] = X
    A[0::2, 8:12] = -x[:, 0:1] * X
    A[1::2, 4:8] = X
    A[1::2, 8:12] = -x[:, 1:2] * X
    # (full_matrices=False: the full U of 2n x 2n was 29 GiB for 30,000 points)
    P_normalized = np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 4)
    P = np.linalg.inv(T_image) @ P_normalized @ T_world
    return P / np.linalg.norm(P[2, :3])


def decompose_projection_matrix(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split ``P = s K [R | t]`` by RQ decomposition.

    Parameters
    ----------
    P : (3, 4) float64, any scale and sign

    Returns
    -------
    K : (3, 3) float64, upper triangular, positive diagonal, ``K[2, 2] = 1``
    R : (3, 3) float64 rotation world -> camera (det +1)
    t : (3,) float64 translation world -> camera, metres
    """
    P = np.asarray(P, dtype=np.float64)
    # The sign of P is arbitrary; with det(M) > 0, K (positive diagonal) and R (det +1) follow.
    if np.linalg.det(P[:, :3]) < 0:
        P = -P
    M = P[:, :3]
    # RQ of M from QR of its row- and column-reversed transpose.
    flip = np.eye(3)[::-1]
    Q, U = np.linalg.qr((flip @ M).T)
    K = flip @ U.T @ flip
    R = flip @ Q.T
    signs = np.diag(np.sign(np.diag(K)))
    K, R = K @ signs, signs @ R
    t = np.linalg.solve(K, P[:, 3])  # P = K [R | t] holds at P's own scale
    K = K / K[2, 2]
    K[1, 0] = K[2, 0] = K[2, 1] = 0.0
    K[2, 2] = 1.0
    return K, R, t


# ---- helpers ----------------------------------------------------------------------------------

def _check_correspondences(points_world, uv) -> tuple[np.ndarray, np.ndarray]:
    # contiguous copies: OpenCV rejects strided views (e.g. columns sliced from a table)
    points_world = np.ascontiguousarray(points_world, dtype=np.float64)
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    if points_world.ndim != 2 or points_world.shape[1] != 3:
        raise InputError(f"points_world must have shape (n, 3), got {points_world.shape}")
    if uv.shape != (len(points_world), 2):
        raise InputError(f"uv must have shape ({len(points_world)}, 2), got {uv.shape}")
    if not (np.all(np.isfinite(points_world)) and np.all(np.isfinite(uv))):
        raise InputError("points contain non-finite values")
    n = len(points_world)
    if n > 1:
        # degenerate sets before any solver: every x,y,z (or every u,v) the same leaves
        # the solvers NaN spreads and an SVD that does not converge
        world = _spread(points_world)
        if not world[0] > 0:
            raise InputError(f"all {n} points have the same x,y,z: the points must be "
                             f"spread out in the world")
        image = np.linalg.svd(uv - uv.mean(axis=0), compute_uv=False)
        if not image[0] > 0:
            raise InputError(f"all {n} points have the same u,v: each point's pixel must "
                             f"be where the camera sees it")
        if image[1] <= COLLINEAR_RATIO * image[0]:
            raise InputError(f"the {n} points' u,v lie on one line in the image: each "
                             f"point's pixel must be where the camera sees it")
    return points_world, uv


def _spread(points: np.ndarray) -> np.ndarray:
    """Singular values (3,) of the centred points, largest first."""
    return np.linalg.svd(points - points.mean(axis=0), compute_uv=False)


def _solve_pose(points_world, uv, width, height, name, fps, offset, K, dist
                ) -> CalibrationResult:
    n = len(points_world)
    if n < MIN_POINTS_POSE:
        raise InputError(f"need at least {MIN_POINTS_POSE} points to solve a pose, got {n}")
    singular = _spread(points_world)
    if singular[1] <= COLLINEAR_RATIO * singular[0]:
        raise InputError(f"the {n} points are collinear; a pose needs points spanning a plane")
    K = np.asarray(K, dtype=np.float64)
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64)
    # SQPnP finds the global optimum for planar and non-planar sets alike (n >= 3); LM then
    # polishes the reprojection error.
    try:
        ok, rvec, tvec = cv2.solvePnP(points_world, uv, K, dist, flags=cv2.SOLVEPNP_SQPNP)
        if not ok:
            raise InputError("solvePnP found no pose for these points")
        rvec, tvec = cv2.solvePnPRefineLM(points_world, uv, K, dist, rvec, tvec,
                                          criteria=_LM_CRITERIA)
    except cv2.error as exc:
        raise InputError(f"pose estimation failed: {_cv_message(exc)}") from None
    R = cv2.Rodrigues(rvec)[0]
    t = tvec.ravel()
    _check_in_front(points_world, R, t, "the pose")
    camera = _make_camera(name, width, height, K, dist, R, t, fps, offset)
    return _result(camera, points_world, uv, "fixed")


def _refine_float64(points_world, uv, K, dist, rvec, tvec, estimated, iterations: int = 20):
    """Gauss-Newton polish of calibrateCamera's solution in float64.

    Unknowns: fx, fy, cx, cy, the estimated distortion terms, rvec, tvec. Jacobians come from
    ``cv2.projectPoints``; the step is accepted only if it lowers the squared error, so this
    can never make the fit worse.
    """
    dist_index = [("k1", "k2", "p1", "p2", "k3").index(term) for term in estimated]
    K = np.array(K, dtype=np.float64)
    dist = np.array(dist, dtype=np.float64)
    rvec = np.array(rvec, dtype=np.float64).reshape(3, 1)
    tvec = np.array(tvec, dtype=np.float64).reshape(3, 1)
    target = uv.ravel()

    def residual(K, dist, rvec, tvec):
        projected, jac = cv2.projectPoints(points_world, rvec, tvec, K, dist)
        return projected.ravel() - target, jac

    r, jac = residual(K, dist, rvec, tvec)
    cost = r @ r
    for _ in range(iterations):
        # projectPoints' Jacobian columns: rvec(3) tvec(3) fx fy cx cy dist(5..)
        J = np.hstack([jac[:, 6:10], jac[:, [10 + i for i in dist_index]], jac[:, 0:6]])
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        K_new = K.copy()
        K_new[0, 0] += step[0]
        K_new[1, 1] += step[1]
        K_new[0, 2] += step[2]
        K_new[1, 2] += step[3]
        dist_new = dist.copy()
        dist_new[dist_index] += step[4:4 + len(dist_index)]
        rvec_new = rvec + step[-6:-3, None]
        tvec_new = tvec + step[-3:, None]
        r_new, jac_new = residual(K_new, dist_new, rvec_new, tvec_new)
        cost_new = r_new @ r_new
        if not cost_new < cost:
            break
        K, dist, rvec, tvec, r, jac = K_new, dist_new, rvec_new, tvec_new, r_new, jac_new
        converged = cost - cost_new <= 1e-14 * max(cost, 1e-300)
        cost = cost_new
        if converged:
            break
    return K, dist, cv2.Rodrigues(rvec)[0], tvec.ravel()


def _check_in_front(points_world, R, t, what: str) -> None:
    depth = points_world @ R[2] + t[2]
    behind = int(np.count_nonzero(depth <= 0))
    if behind:
        raise InputError(f"{what} puts {behind} of {len(depth)} points behind the camera "
                         f"(check that each u,v belongs to its x,y,z)")


def _result(camera: Camera, points_world, uv, model: str) -> CalibrationResult:
    projected, _ = camera.project(points_world)
    residuals = np.linalg.norm(projected - uv, axis=1)
    residuals.setflags(write=False)
    return CalibrationResult(camera, float(np.sqrt(np.mean(residuals ** 2))), residuals, model)


def _normalizing_transform(points: np.ndarray) -> np.ndarray:
    """Similarity (dim+1, dim+1) moving the centroid to 0 and the mean distance to sqrt(dim)."""
    dim = points.shape[1]
    centroid = points.mean(axis=0)
    mean_distance = np.mean(np.linalg.norm(points - centroid, axis=1))
    scale = np.sqrt(dim) / mean_distance
    T = np.eye(dim + 1)
    T[:dim, :dim] *= scale
    T[:dim, dim] = -scale * centroid
    return T


def _homogeneous(points: np.ndarray) -> np.ndarray:
    return np.hstack([points, np.ones((len(points), 1))])
