"""Per-observation geometry shared by every fusion method, computed once per session."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FusionError
from ..geometry import fundamental_matrices
from ..records import NS, Observations
from ..rig import Rig, check_baselines

#: Pixels farther than this many image sizes from the image are not detections.
_FAR_IMAGES = 10


@dataclass(frozen=True, eq=False)
class Prepared:
    """Observations with their rays, ready for vectorized fusion.

    Attributes
    ----------
    obs : Observations, sorted by (time, camera)
    t : (n,) float64, seconds since the first observation (for ratios of time intervals)
    uv_undistorted : (n, 2) float64, undistorted pixels
    ray_origin : (n, 3) float64, camera centre of each observation, world metres
    ray_dir : (n, 3) float64, unit viewing-ray direction, world
    centers : (m, 3) camera centres; K_inv, R : (m, 3, 3) per camera
    F : (m, m, 3, 3), ``F[a, b]`` with ``x_bᵀ F[a, b] x_a = 0`` (undistorted pixels)
    per_camera : list of (n_c,) int64 arrays, global rows of each camera's observations
    """

    obs: Observations
    t: np.ndarray
    uv_undistorted: np.ndarray
    ray_origin: np.ndarray
    ray_dir: np.ndarray
    centers: np.ndarray
    K_inv: np.ndarray
    R: np.ndarray
    F: np.ndarray
    per_camera: list[np.ndarray]

    def rays_from_undistorted(self, camera: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Unit world directions (n, 3) of undistorted pixels ``uv`` (n, 2) of ``camera`` (n,)."""
        homogeneous = np.hstack([uv, np.ones((len(uv), 1))])
        rays_cam = np.einsum("nij,nj->ni", self.K_inv[camera], homogeneous)
        dirs = np.einsum("nji,nj->ni", self.R[camera], rays_cam)  # Rᵀ @ ray
        return dirs / np.linalg.norm(dirs, axis=1, keepdims=True)


def prepare(obs: Observations, rig: Rig, F: np.ndarray | None = None) -> Prepared:
    """Undistort every observation and compute its viewing ray (one vectorized pass per camera).

    ``F`` may pass :func:`pslog.geometry.fundamental_matrices` of ``rig.cameras`` computed
    earlier."""
    n_cams = len(rig)
    check_baselines(rig)
    if len(obs) and (obs.camera.min() < 0 or obs.camera.max() >= n_cams):
        raise FusionError(f"observation camera index {int(obs.camera.max())} is not in the "
                          f"{n_cams}-camera rig")
    uv_und = np.empty_like(obs.uv)
    ray_dir = np.empty((len(obs), 3))
    per_camera = []
    for i, cam in enumerate(rig.cameras):
        rows = np.flatnonzero(obs.camera == i)
        per_camera.append(rows)
        if len(rows):
            uv_und[rows] = cam.undistort(obs.uv[rows])
            ray_dir[rows] = cam.rays(obs.uv[rows])[1]
            # a pixel far outside the image (1e300 from a damaged file) is no detection: no
            # ray, as for a pixel beyond the lens model's fold-over (and no overflow later)
            far = rows[~np.all(np.abs(obs.uv[rows]) <= _FAR_IMAGES * max(cam.width,
                                                                        cam.height), axis=1)]
            uv_und[far] = np.nan
            ray_dir[far] = np.nan
    centers = np.array([c.center_world for c in rig.cameras])
    if F is None:
        F = fundamental_matrices(rig.cameras)
    t = (obs.time_ns - (obs.time_ns[0] if len(obs) else 0)) / NS
    return Prepared(
        obs=obs, t=t.astype(np.float64), uv_undistorted=uv_und,
        ray_origin=centers[obs.camera] if len(obs) else np.zeros((0, 3)), ray_dir=ray_dir,
        centers=centers, K_inv=np.array([np.linalg.inv(c.K) for c in rig.cameras]),
        R=np.array([c.R for c in rig.cameras]), F=F, per_camera=per_camera,
    )


def latest_row_at_or_before(prep: Prepared, camera: int, row: np.ndarray) -> np.ndarray:
    """Global row of ``camera``'s latest observation at or before global row ``row`` (m,)
    in (time, camera) order; -1 if none. Row order, not time, makes causality exact: a point
    made at row ``e`` never depends on a row after ``e``, even one with the same timestamp."""
    rows = prep.per_camera[camera]
    if len(rows) == 0:
        return np.full(len(row), -1, dtype=np.int64)
    pos = np.searchsorted(rows, row, side="right") - 1
    return np.where(pos >= 0, rows[np.maximum(pos, 0)], -1)


def bracket(prep: Prepared, camera: int, time_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``camera``'s observations bracketing each time: the latest at or before and the
    earliest at or after (the same row on an exact match); -1 where missing."""
    rows = prep.per_camera[camera]
    if len(rows) == 0:
        missing = np.full(len(time_ns), -1, dtype=np.int64)
        return missing, missing
    times = prep.obs.time_ns[rows]
    before = np.searchsorted(times, time_ns, side="right") - 1
    after = np.searchsorted(times, time_ns, side="left")
    prev = np.where(before >= 0, rows[np.maximum(before, 0)], -1)
    nxt = np.where(after < len(rows), rows[np.minimum(after, len(rows) - 1)], -1)
    return prev, nxt


def default_max_gap_s(rig: Rig) -> float:
    """3.5 frame periods of the slowest camera: bridges two missed frames, not more."""
    return 3.5 / min(c.fps for c in rig.cameras)
