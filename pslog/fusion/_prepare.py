"""Per-observation geometry shared by every fusion method, computed once per session."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache, cached_property
from typing import Any, cast

import numpy as np

from ..errors import FusionError
from ..geometry import _FEW, fundamental_matrices
from ..records import NS, Observations
from ..rig import Rig, check_baselines

#: Pixels farther than this many image sizes from the image are not detections.
_FAR_IMAGES = 10

#: Geometric validity of a fused point (see :func:`invalid_points`): bits of the reason.
BEHIND = 1          # behind a camera that contributed to it (or a ray parameter <= 0)
OUTSIDE_VIEW = 2    # outside the field of view of a camera that saw it
PARALLEL = 4        # its rays are nearly parallel: the depth is not determined
#: Rays closer to parallel than this, degrees, determine no depth worth a point: the depth
#: error grows like 1 / sin(angle), ~60x the lateral one at 1 degree.
MIN_RAY_ANGLE_DEG = 1.0
#: A contributing camera's view, for the validity check, is its image grown by this share of
#: its larger side on every edge: type A and type B put a point at one camera's instant in
#: the view of cameras that saw the ball up to a few frames earlier or later.
VIEW_MARGIN = 0.25
#: Pixel step of the numerical Jacobians (the snap's, and the reference ones), pixels.
_JACOBIAN_STEP_PX = 1e-3
#: Take the covariances' Jacobians by forward differences through each method's whole
#: construction instead of analytically: slow, a reference the tests compare with.
FINITE_DIFFERENCES = False


@dataclass(frozen=True, eq=False)
class Prepared:
    """Observations with their rays, ready for vectorized fusion.

    Attributes
    ----------
    obs : Observations, sorted by (time, camera)
    t : (n,) float64, seconds since the first observation (for ratios of time intervals)
    uv_undistorted : (n, 2) float64, undistorted pixels
    ray_origin : (n, 3) float64, camera centre of each observation, world metres (made at its
        first use)
    ray_dir : (n, 3) float64, unit viewing-ray direction, world
    centers : (m, 3) camera centres; K_inv, R : (m, 3, 3) per camera
    F : (m, m, 3, 3), ``F[a, b]`` with ``x_bᵀ F[a, b] x_a = 0`` (undistorted pixels)
    per_camera : list of (n_c,) int64 arrays, global rows of each camera's observations
    cameras : tuple of Camera, the rig's, in rig order
    uv_jacobian : (n, 2, 2) float64, d(undistorted pixel) / d(detected pixel) of each
        observation: maps detection noise (isotropic in the recorded image) to ideal pixels
    view_box : (m, 4) float64, ``(u_min, v_min, u_max, v_max)`` of each camera's view in
        undistorted pixels, grown by :data:`VIEW_MARGIN`
    doubt_px2 : (n,) float64 or None, the variance (recorded pixels², per axis) each
        observation adds to its point's covariance for the chance that the gate chose the
        wrong candidate (:func:`pslog.fusion.gating.choice_doubt`; 0 for a choice not in
        doubt); None: no choice in doubt (every session without a gate)
    """

    obs: Observations
    t: np.ndarray
    uv_undistorted: np.ndarray
    ray_dir: np.ndarray
    centers: np.ndarray
    K_inv: np.ndarray
    R: np.ndarray
    F: np.ndarray
    per_camera: list[np.ndarray]
    cameras: tuple = ()
    uv_jacobian: np.ndarray | None = None
    view_box: np.ndarray | None = None
    doubt_px2: np.ndarray | None = None

    def pixel_jacobians(self, rows: np.ndarray) -> np.ndarray | None:
        """:attr:`uv_jacobian` of observations ``rows`` (NaN, for a pixel no lens maps,
        as 0), or None when no camera has lens distortion (the identity)."""
        if not any(np.any(c.dist) for c in self.cameras):
            return None
        # (set by prepare() and every Prepared made; None only as the dataclass default)
        return np.nan_to_num(cast(np.ndarray, self.uv_jacobian)[rows])

    def rays_from_undistorted(self, camera: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Unit world directions (n, 3) of undistorted pixels ``uv`` (n, 2) of ``camera`` (n,)
        (or one camera for all, an int)."""
        # C order, as callers' row-wise reductions (einsum) may sum differently otherwise
        return np.ascontiguousarray(self.rays_t(camera, uv).T)

    def rays_t(self, camera: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """:meth:`rays_from_undistorted` component-major: unit directions (3, n). (Columns of
        length n, not rows of length 3: numpy is slow on short trailing axes.) ``K⁻¹`` then
        ``Rᵀ``, in the order of the matrix products they replace: the same bits."""
        Ki = _per_point(self._cols("K_inv"), camera)  # (9, n): Ki[3 i + j] = K⁻¹[i, j]
        R = _per_point(self._cols("R"), camera)
        u, v = uv[:, 0], uv[:, 1]
        x = Ki[0] * u + Ki[1] * v + Ki[2]
        y = Ki[3] * u + Ki[4] * v + Ki[5]
        z = Ki[6] * u + Ki[7] * v + Ki[8]
        d = R[0:3] * x  # Rᵀ (x, y, z): (Rᵀ)[i, j] = R[j, i] = R[3 j + i]
        d += R[3:6] * y
        d += R[6:9] * z
        d /= np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        return d

    @cached_property
    def observed_rays(self) -> np.ndarray:
        """:meth:`rays_from_undistorted` of every observation's own undistorted pixel (n, 3),
        made once (type A needs each row's ray several times; elementwise, so a row of it
        has the bits of a call on that row alone)."""
        return self._observed[0]

    @cached_property
    def observed_direction_jacobians(self) -> np.ndarray:
        """:func:`direction_jacobian` of every observation at its own undistorted pixel,
        (3, 2, n), made once (elementwise: a row's entries are those of a call on it alone)."""
        return self._observed[1]

    @cached_property
    def ray_origin(self) -> np.ndarray:
        """(n, 3) float64, the camera centre of each observation: made at its first use
        (type A's kernels read ``centers``: its 24 bytes a row were fresh memory at every
        call, docs/performance.md)."""
        return self.centers[self.obs.camera] if len(self.obs) else np.zeros((0, 3))

    @cached_property
    def _observed(self) -> tuple[np.ndarray, np.ndarray]:
        """:attr:`observed_rays` and :attr:`observed_direction_jacobians` in one compiled
        pass (their numpy expressions, operation for operation: the same bits)."""
        from . import _prepare_kernel

        n = len(self.obs)
        rays, jac = np.empty((n, 3)), np.empty((3, 2, n))
        _prepare_kernel.observed_rays_and_jacobians(
            np.ascontiguousarray(self.obs.camera, dtype=np.int64),
            np.ascontiguousarray(self.uv_undistorted, dtype=np.float64),
            np.ascontiguousarray(self._cols("K_inv").T), np.ascontiguousarray(self._cols("R").T),
            np.ascontiguousarray(self._rt_k_inv_cols.T), rays, jac)
        return rays, jac

    @cached_property
    def previous_instant(self) -> np.ndarray:
        """(n,) int64, the latest row of the instant before each row's (a strictly earlier
        time; -1: none): ``searchsorted(time_ns, time_ns, "left") - 1``, in one pass over the
        sorted times."""
        time_ns = self.obs.time_ns
        n = len(time_ns)
        start = np.ones(n, dtype=bool)  # the first row of its instant
        np.not_equal(time_ns[1:], time_ns[:-1], out=start[1:])
        first = np.where(start, np.arange(n), 0)
        np.maximum.accumulate(first, out=first)
        first -= 1
        return first

    def row_brackets(self, camera: int) -> tuple[np.ndarray, np.ndarray]:
        """:func:`bracket` of ``camera`` at every observation's time, (n,) each, made once
        per camera (type A brackets the same rows at several depths); a row of it is
        :func:`bracket` at that row's time."""
        cache = self.__dict__.setdefault("_row_brackets", {})
        if camera not in cache:
            cache[camera] = bracket(self, camera, self.obs.time_ns)
        return cache[camera]

    def _cols(self, name: str) -> np.ndarray:
        """Per-camera (3, 3) matrices ``name`` as (9, m) columns (cached)."""
        cache = self.__dict__.setdefault("_columns", {})
        if name not in cache:
            cache[name] = np.ascontiguousarray(getattr(self, name).reshape(-1, 9).T)
        return cache[name]

    @cached_property
    def lens_rows(self) -> np.ndarray:
        """Per camera (m, 8): ``fx, fy, cx, cy``, the optical axis ``R[2]`` in the world and
        ``t[2]`` (a world point's depth is ``R[2] · X + t[2]``), made once (the innovation
        test and the kink test of a fusion both read it)."""
        return np.array([[c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2], *c.R[2], c.t[2]]
                         for c in self.cameras], dtype=np.float64).reshape(-1, 8)

    @cached_property
    def _rt_k_inv_cols(self) -> np.ndarray:
        """Rᵀ K⁻¹ of every camera as (9, m) columns."""
        return np.ascontiguousarray((np.swapaxes(self.R, 1, 2) @ self.K_inv).reshape(-1, 9).T)

    @cached_property
    def _uv_jacobian_cols(self) -> np.ndarray | None:
        """:attr:`uv_jacobian` as (4, n) columns (NaN as 0), None without lens distortion."""
        if not any(np.any(c.dist) for c in self.cameras):
            return None
        jac = cast(np.ndarray, self.uv_jacobian)  # (as in pixel_jacobians)
        return np.ascontiguousarray(np.nan_to_num(jac).reshape(-1, 4).T)

    def pixel_jacobians_t(self, rows: np.ndarray) -> np.ndarray | None:
        """:meth:`pixel_jacobians` component-major: (2, 2, k), or None (the identity)."""
        cols = self._uv_jacobian_cols
        return None if cols is None else np.take(cols, rows, axis=1).reshape(2, 2, -1)

    @cached_property
    def _f_cols(self) -> np.ndarray:
        """:attr:`F` as (9, m * m) columns: ``F[a, b]`` is column ``a m + b``."""
        return np.ascontiguousarray(self.F.reshape(-1, 9).T)

    def fundamental_t(self, cam_a: np.ndarray, cam_b: np.ndarray) -> np.ndarray:
        """``F[cam_a, cam_b]`` of (k,) camera pairs as (9, k) columns (entry ``3 i + j``)."""
        return np.take(self._f_cols, cam_a * len(self.centers) + cam_b, axis=1)


def _per_point(columns: np.ndarray, camera) -> np.ndarray:
    """Per-camera ``columns`` (c, m) of each point's ``camera`` (k,): (c, k); for one camera
    given as an int, (c, 1), which broadcasts (the same values without k copies)."""
    if np.ndim(camera) == 0:
        return columns[:, int(camera), None]
    return np.take(columns, camera, axis=1)


def prepare(obs: Observations, rig: Rig, F: np.ndarray | None = None,
            head: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> Prepared:
    """Undistort every observation and compute its viewing ray (one vectorized pass per camera).

    ``F`` may pass :func:`pslog.geometry.fundamental_matrices` of ``rig.cameras`` computed
    earlier. ``head``: the undistorted pixels (h, 2), ray directions (h, 3) and pixel
    Jacobians (h, 2, 2) of the first ``h`` observations, from an earlier :func:`prepare` of
    them with this rig (a stream's window, prepared again at every push with new rows at
    its end): only the rows after them are computed. Every row's values depend on that row
    alone (the lens is inverted row by row), so the result has the same bits either way."""
    n_cams = len(rig)
    checked_F = _checked_geometry(rig)  # (check_baselines: a one-line error for a bad rig)
    if len(obs) and (obs.camera.min() < 0 or obs.camera.max() >= n_cams):
        raise FusionError(f"observation camera index {int(obs.camera.max())} is not in the "
                          f"{n_cams}-camera rig")
    uv_und = np.empty_like(obs.uv)
    ray_dir = np.empty((len(obs), 3))
    jac = np.empty((len(obs), 2, 2))
    h = 0
    if head is not None:
        h = min(len(head[0]), len(obs))
        uv_und[:h], ray_dir[:h], jac[:h] = head[0][:h], head[1][:h], head[2][:h]
    per_camera = [np.flatnonzero(obs.camera == i) for i in range(n_cams)]
    lensless = not any(np.any(cam.dist) for cam in rig.cameras)
    if lensless and len(obs) > h:
        # no lens: every row's ideal pixel, ray and (identity) Jacobian in one compiled pass,
        # the per-camera numpy operations below row by row (the same bits; fewer temporaries)
        _lensless_rows(rig, obs.select(slice(h, None)) if h else obs, uv_und[h:],
                       ray_dir[h:], jac[h:])
    for i, cam in enumerate(rig.cameras):
        rows = per_camera[i]
        if h:
            rows = rows[rows >= h]
        if len(rows) and not lensless:
            # the lens inverted once: Camera.undistort's pixels and Camera.rays' directions
            # from the same ideal normalised coordinates (each method inverts it itself)
            xy = cam.undistort_normalized(obs.uv[rows])
            uv_und[rows] = cam.pixels_from_normalized(xy)
            ray_dir[rows] = _rays(cam, xy)
            # a pixel far outside the image (1e300 from a damaged file) is no detection: no
            # ray, as for a pixel beyond the lens model's fold-over (and no overflow later)
            far = rows[~np.all(np.abs(obs.uv[rows]) <= _FAR_IMAGES * max(cam.width,
                                                                        cam.height), axis=1)]
            uv_und[far] = np.nan
            ray_dir[far] = np.nan
            jac[rows] = _undistortion_jacobian(cam, uv_und[rows])
    centers = np.array([c.center_world for c in rig.cameras])
    if F is None:
        F = checked_F
    t = (obs.time_ns - (obs.time_ns[0] if len(obs) else 0)) / NS
    return Prepared(
        obs=obs, t=t, uv_undistorted=uv_und, ray_dir=ray_dir,  # (t: float64, no copy)
        centers=centers, K_inv=_k_inverses(rig),
        R=np.array([c.R for c in rig.cameras]), F=F, per_camera=per_camera,
        cameras=tuple(rig.cameras), uv_jacobian=jac,
        view_box=np.array([_view_box(c) for c in rig.cameras]),
    )



def rays_only(prep: Prepared) -> tuple[Prepared, np.ndarray | None]:
    """``prep`` without its detections that have no ray (a pixel beyond the image or the
    lens model's fold-over, NaN: :func:`prepare` gives them NaN undistorted pixels and
    rays), and the rows kept (None: every row has a ray, ``prep`` itself). Every row keeps
    its own values and ``t`` is counted from the first row kept: the bits :func:`prepare`
    gives the session with those detections deleted. What ``nearest`` and ``typeA`` fuse, so
    that a detection without a ray is exactly a missing one (docs/methods.md, "A detection
    without a ray")."""
    ray = prep.ray_dir
    has = np.isfinite(ray[:, 0]) & np.isfinite(ray[:, 1]) & np.isfinite(ray[:, 2])
    if has.all():
        return prep, None
    rows = np.flatnonzero(has)
    obs = prep.obs.select(rows)
    t = (obs.time_ns - (obs.time_ns[0] if len(obs) else 0)) / NS
    return Prepared(
        obs=obs, t=t, uv_undistorted=prep.uv_undistorted[rows],
        ray_dir=ray[rows], centers=prep.centers,
        K_inv=prep.K_inv, R=prep.R, F=prep.F,
        per_camera=[np.flatnonzero(obs.camera == i) for i in range(len(prep.centers))],
        cameras=prep.cameras,
        uv_jacobian=None if prep.uv_jacobian is None else prep.uv_jacobian[rows],
        view_box=prep.view_box,
        doubt_px2=None if prep.doubt_px2 is None else prep.doubt_px2[rows]), rows


def array_key(*parts) -> tuple:
    """A hashable key of arrays (or nested tuples of them) by their float64 bytes: what a
    per-rig cache (:func:`rig_cached`) is keyed by."""
    return tuple(array_key(*p) if isinstance(p, tuple) else np.asarray(p, np.float64).tobytes()
                 for p in parts)


def rig_cached(cache: dict, key: tuple, make: Callable[[], Any]) -> Any:
    """``cache[key]``, made by ``make()`` the first time the key is met (the rigs' caches of
    derived geometry: a rig's tables made once, not per call; a cache past 256 rigs is
    emptied)."""
    value = cache.get(key)
    if value is None:
        value = make()
        if len(cache) > 256:
            cache.clear()
        cache[key] = value
    return value


#: The rigs whose geometry :func:`_checked_geometry` checked (keyed by the cameras' K, R and
#: t), with their fundamental matrices: a rig is checked and F made once, not per prepare
_RIG_GEOMETRY: dict[tuple, np.ndarray] = {}


def _checked_geometry(rig: Rig) -> np.ndarray:
    """:func:`~pslog.geometry.fundamental_matrices` of ``rig`` (m, m, 3, 3), a copy of the
    one made when its geometry (K, R, t) was first met and passed
    :func:`~pslog.rig.check_baselines` (which raises, every time, for a rig that fails)."""
    def checked() -> np.ndarray:
        check_baselines(rig)
        return fundamental_matrices(rig.cameras)

    return rig_cached(_RIG_GEOMETRY, array_key(*((c.K, c.R, c.t) for c in rig.cameras)),
                      checked).copy()


#: The cameras' K⁻¹ (m, 3, 3) of the rigs met (keyed by their K), made once: three
#: ``np.linalg.inv`` calls were ~2 % of a 2-minute type-A ``fuse``
_K_INVERSES: dict[tuple, np.ndarray] = {}


def _k_inverses(rig: Rig) -> np.ndarray:
    """``np.array([np.linalg.inv(c.K) for c in rig.cameras])``, a copy of the one made when
    these cameras' K were first met (the same bits: the same call on the same matrices)."""
    return rig_cached(_K_INVERSES, array_key(*(c.K for c in rig.cameras)),
                      lambda: np.array([np.linalg.inv(c.K) for c in rig.cameras])).copy()


def _lensless_rows(rig: Rig, obs: Observations, uv_und: np.ndarray, ray_dir: np.ndarray,
                   jac: np.ndarray) -> None:
    """:func:`prepare`'s per-camera pass for a rig without lens distortion, compiled
    (:func:`~pslog.fusion._prepare_kernel.lensless_rows`): ``uv_und`` (n, 2), ``ray_dir``
    (n, 3) and ``jac`` (n, 2, 2) written."""
    from . import _prepare_kernel

    cams = rig.cameras
    none = np.empty((0, 9))
    _prepare_kernel.lensless_rows(
        np.ascontiguousarray(obs.camera, dtype=np.int64), np.ascontiguousarray(obs.uv),
        np.array([np.asarray(c.K, np.float64).ravel() for c in cams]),
        np.array([float(_FAR_IMAGES * max(c.width, c.height)) for c in cams]),
        np.ascontiguousarray([np.asarray(c.R, np.float64) for c in cams]), none, none, none,
        uv_und, ray_dir, jac, np.empty((0, 4)), np.empty((0, 3)), np.empty((3, 2, 0)))


def _rays(cam, xy: np.ndarray) -> np.ndarray:
    """:meth:`~pslog.camera.Camera.rays`' unit world directions (k, 3) of ideal normalised
    coordinates ``xy`` (k, 2) (:meth:`~pslog.camera.Camera.undistort_normalized`), by its
    operations in its order, compiled (the same bits; numba loaded here, at the first use)."""
    from . import _prepare_kernel

    out = np.empty((len(xy), 3))
    _prepare_kernel.rays_from_normalized(np.ascontiguousarray(xy, dtype=np.float64),
                                         np.ascontiguousarray(cam.R, dtype=np.float64), out)
    return out


def _undistortion_jacobian(cam, uv_und: np.ndarray) -> np.ndarray:
    """(k, 2, 2) d(undistorted) / d(distorted) at undistorted pixels ``uv_und``: the inverse
    of the closed-form distortion's Jacobian (central differences; row by row, so a
    detection's value does not depend on which others are prepared with it)."""
    k = len(uv_und)
    if not np.any(cam.dist):
        return np.broadcast_to(np.eye(2), (k, 2, 2)).copy()
    h = 1e-3
    forward = np.empty((k, 2, 2))
    with np.errstate(invalid="ignore", over="ignore"):
        for axis in range(2):
            step = np.zeros(2)
            step[axis] = h
            forward[:, :, axis] = (cam.distort(uv_und + step)
                                   - cam.distort(uv_und - step)) / (2 * h)
        ok = np.all(np.isfinite(forward), axis=(1, 2))
        out = np.full((k, 2, 2), np.nan)
        if np.any(ok):
            out[ok] = np.linalg.inv(forward[ok])
    return out


#: :func:`_view_box` of the cameras met so far (a stream prepares its window at every push)
_VIEW_BOXES: dict[tuple, np.ndarray] = {}


def _view_box(cam) -> np.ndarray:
    """The camera's image, undistorted (its border's bounding box), grown by VIEW_MARGIN."""
    key = (cam.width, cam.height, np.asarray(cam.K, np.float64).tobytes(),
           np.asarray(cam.dist, np.float64).tobytes())
    box = _VIEW_BOXES.get(key)
    if box is None:
        if len(_VIEW_BOXES) > 256:
            _VIEW_BOXES.clear()
        box = _VIEW_BOXES[key] = _compute_view_box(cam)
    return box.copy()


def _compute_view_box(cam) -> np.ndarray:
    w, h = cam.width, cam.height
    s = np.linspace(0.0, 1.0, 33)
    border = np.concatenate([
        np.stack([s * w - 0.5, np.full_like(s, -0.5)], 1),
        np.stack([s * w - 0.5, np.full_like(s, h - 0.5)], 1),
        np.stack([np.full_like(s, -0.5), s * h - 0.5], 1),
        np.stack([np.full_like(s, w - 0.5), s * h - 0.5], 1)])
    ideal = cam.undistort(border)
    ideal = ideal[np.all(np.isfinite(ideal), axis=1)]
    if len(ideal) == 0:
        ideal = border
    grow = VIEW_MARGIN * max(w, h)
    return np.array([ideal[:, 0].min() - grow, ideal[:, 1].min() - grow,
                     ideal[:, 0].max() + grow, ideal[:, 1].max() + grow])


def finite_rows(points: np.ndarray) -> np.ndarray:
    """(k,) bool, rows of ``points`` (k, 3) all finite (``np.all(np.isfinite(.), axis=1)``)."""
    out = np.isfinite(points[:, 0])
    out &= np.isfinite(points[:, 1])
    out &= np.isfinite(points[:, 2])
    return out


def invalid_points(prep: Prepared, points: np.ndarray, used: np.ndarray,
                   finite: np.ndarray | None = None) -> np.ndarray:
    """Why each point is not a geometrically valid output, as bits (0: valid).

    Parameters
    ----------
    points : (k, 3) world metres
    used : (k, m) bool, the cameras whose detections made each point

    Returns
    -------
    (k,) int64, ``BEHIND`` if the point is at or behind the image plane of a camera that
    contributed to it; ``OUTSIDE_VIEW`` if it projects outside the view (image grown by
    :data:`VIEW_MARGIN`) of such a camera; a non-finite point gets no flag (its caller
    knows why it has none); ``finite``: :func:`finite_rows` of ``points``, if known
    """
    k, m = used.shape
    flags = np.zeros(k, dtype=np.int64)
    finite = finite_rows(points) if finite is None else finite
    mine = used & finite[:, None]
    counts = np.count_nonzero(mine, axis=0)
    if (k >= _FEW and points.flags.c_contiguous and points.dtype == np.float64
            and np.all((counts == 0) | (counts >= 2)) and view_flags_compiled()):
        # one compiled pass (_prepare_kernel.view_flags: the numpy below, its matrix
        # products' bits as OpenBLAS makes them of two rows or more of contiguous points;
        # a camera with one point goes the numpy way, whose product of one row takes
        # another path)
        from . import _prepare_kernel

        cams = np.array([np.concatenate([np.ravel(c.R), np.ravel(c.t), np.ravel(c.K[:2, :2])])
                         for c in prep.cameras], dtype=np.float64).reshape(m, 16)
        boxes = np.column_stack([np.asarray(prep.view_box, dtype=np.float64).reshape(m, 4),
                                 [c.K[0, 2] for c in prep.cameras],
                                 [c.K[1, 2] for c in prep.cameras]])
        _prepare_kernel.view_flags(points, np.ascontiguousarray(used, dtype=np.bool_),
                                   np.ascontiguousarray(finite, dtype=np.bool_), cams,
                                   np.ascontiguousarray(boxes), BEHIND, OUTSIDE_VIEW, flags)
        return flags
    for c in range(m):
        mine = used[:, c] & finite
        n_mine = np.count_nonzero(mine)
        if n_mine == 0:
            continue
        rows = None if n_mine == k else np.flatnonzero(mine)  # (None: every point)
        cam = prep.cameras[c]
        in_cam = (points if rows is None else np.take(points, rows, axis=0)) @ cam.R.T + cam.t
        z = in_cam[:, 2]
        behind = z <= 1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (in_cam[:, :2] / z[:, None]) @ cam.K[:2, :2].T + cam.K[:2, 2]
        box = cast(np.ndarray, prep.view_box)[c]  # (set by prepare())
        outside = ~behind & ~((uv[:, 0] >= box[0]) & (uv[:, 0] <= box[2])
                              & (uv[:, 1] >= box[1]) & (uv[:, 1] <= box[3]))
        bits = behind * BEHIND | outside * OUTSIDE_VIEW
        if rows is None:
            flags |= bits
        else:
            flags[rows] |= bits
    return flags


#: row counts the probes of the compiled passes try (numpy's and the BLAS's kernels may
#: take another path for a few rows, or at a multiple of their blocking)
_PROBE_ROWS = (2, 3, 4, 5, 7, 8, 16, 17, 33, 64, 100, 257, 1000)


def _probe_points(rows: int, seed: int) -> np.ndarray:
    """(rows, 3) probe points: signed magnitudes over 2**±20 m, some near zero."""
    rng = np.random.default_rng(seed)
    return np.ascontiguousarray(rng.standard_normal((rows, 3))
                                * np.exp2(rng.integers(-20, 21, (rows, 3))))


@cache
def view_flags_compiled() -> bool:
    """Whether :func:`pslog.fusion._prepare_kernel.view_flags` may stand for
    :func:`invalid_points`' numpy form here: its arithmetic (the probe kernel
    ``view_project``) gives the bits of numpy's ``points @ Rᵀ + t`` and
    ``(x / z, y / z) @ K[:2, :2]ᵀ + K[:2, 2]`` on probe points for several row counts and
    cameras. It repeats OpenBLAS's order on x86-64 with FMA; another BLAS, CPU or numpy
    may sum otherwise: the numpy form then (checked once per process, ~ms)."""
    from . import _prepare_kernel

    return _view_probe(_prepare_kernel.view_project)


def _view_probe(view_project) -> bool:
    """:func:`view_flags_compiled`'s probe of a kernel with ``view_project``'s signature."""
    rng = np.random.default_rng(17)
    m = 3
    R = np.linalg.qr(rng.standard_normal((m, 3, 3)))[0]
    t = rng.standard_normal((m, 3)) * 3
    K = np.zeros((m, 3, 3))
    K[:, 0, 0], K[:, 1, 1] = rng.uniform(300, 3000, m), rng.uniform(300, 3000, m)
    K[:, 0, 1] = rng.uniform(-2, 2, m)
    K[:, 0, 2], K[:, 1, 2], K[:, 2, 2] = rng.uniform(100, 2000, m), rng.uniform(100, 2000, m), 1
    cams = np.ascontiguousarray(np.concatenate([R.reshape(m, 9), t, K[:, :2, :2].reshape(m, 4)],
                                               axis=1))
    boxes = np.ascontiguousarray(np.column_stack([np.zeros((m, 4)), K[:, 0, 2], K[:, 1, 2]]))
    for i, rows in enumerate(_PROBE_ROWS):
        points = _probe_points(rows, i)
        out = np.empty((rows, m, 5))
        view_project(points, cams, boxes, out)
        for c in range(m):
            in_cam = points @ R[c].T + t[c]
            z = in_cam[:, 2]
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = (in_cam[:, :2] / z[:, None]) @ K[c, :2, :2].T + K[c, :2, 2]
            uv[z <= 1e-9] = 0.0
            if not (np.array_equal(out[:, c, :3].view(np.int64), in_cam.view(np.int64))
                    and np.array_equal(out[:, c, 3:].view(np.int64), uv.view(np.int64))):
                return False
    return True


@cache
def ray_depths_compiled() -> bool:
    """Whether :func:`pslog.fusion._prepare_kernel.ray_depths_rows` gives
    :func:`pslog.geometry.ray_depths`' bits here (it repeats the order in which numpy's
    einsum sums three terms on x86-64; another numpy or CPU may sum otherwise): probe rays
    and points for several row counts, checked once per process."""
    from . import _prepare_kernel

    return _ray_depths_probe(_prepare_kernel.ray_depths_rows)


def _ray_depths_probe(ray_depths_rows) -> bool:
    """:func:`ray_depths_compiled`'s probe of a kernel with ``ray_depths_rows``' signature."""
    from ..geometry import ray_depths

    rng = np.random.default_rng(19)
    centers = rng.standard_normal((3, 3)) * 5
    for i, rows in enumerate(_PROBE_ROWS):
        points = _probe_points(rows, 100 + i)
        dirs = np.ascontiguousarray(rng.standard_normal((rows, 3, 3)))
        out = np.empty((rows, 3))
        ray_depths_rows(points, centers, dirs, out)
        want = ray_depths(points, np.broadcast_to(centers, (rows, 3, 3)), dirs)
        if not np.array_equal(out.view(np.int64), want.view(np.int64)):
            return False
    return True


def reprojection_px(prep: Prepared, points: np.ndarray, camera: np.ndarray,
                    uv_undistorted: np.ndarray) -> np.ndarray:
    """Distance, in the recorded (distorted) image of ``camera`` (k,), between the projection
    of ``points`` (k, 3) and the image point ``uv_undistorted`` (k, 2), pixels (k,); NaN for
    a point behind that camera or a missing image point.

    :meth:`pslog.camera.Camera.project` and :meth:`~pslog.camera.Camera.distort` written out
    on columns, operation for operation (the same bits, without their (n, 2) stacks)."""
    out = np.full(len(points), np.nan)
    for c in range(len(prep.cameras)):
        rows = np.flatnonzero(camera == c)
        if len(rows) == 0:
            continue
        out[rows] = reprojection_one(prep, c, np.take(points, rows, axis=0),
                                     np.take(uv_undistorted, rows, axis=0))
    return out


def reprojection_one(prep: Prepared, c: int, points: np.ndarray, uv_undistorted: np.ndarray
                     ) -> np.ndarray:
    """:func:`reprojection_px` of points (k, 3) and image points (k, 2) of one camera ``c``."""
    cam = prep.cameras[c]
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        R = cam.R  # written out as in Camera.project (the bits must not depend on k)
        in_cam = (points[:, 0:1] * R[:, 0] + points[:, 1:2] * R[:, 1]
                  + points[:, 2:3] * R[:, 2] + cam.t)
        z = in_cam[:, 2]
        in_front = z > 1e-12
        z = np.where(in_front, z, np.nan)
        u, v = _distorted_pixels(cam, in_cam[:, 0] / z, in_cam[:, 1] / z)
        K = cam.K
        y = (uv_undistorted[:, 1] - K[1, 2]) / K[1, 1]
        x = (uv_undistorted[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        tu, tv = _distorted_pixels(cam, x, y)
        u -= tu
        v -= tv
        u *= u
        v *= v
        u += v
        return np.where(in_front, np.sqrt(u, out=u), np.nan)


def _distorted_pixels(cam, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (u, v) of ideal normalized coordinates (x, y) through the lens: the
    expressions of :meth:`pslog.camera.Camera.distort_normalized` and
    :meth:`~pslog.camera.Camera.pixels_from_normalized`."""
    k1, k2, p1, p2, k3 = cam.dist
    r2 = x * x + y * y
    if not np.any(cam.dist) and np.all(np.isfinite(r2 + r2)):
        # no lens: the model gives back (x, y) exactly (finite terms times zero coefficients
        # add zeros), as long as nothing overflows (then it gives NaN, hence the full form)
        xd, yd = x, y
        K = cam.K
        return K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    K = cam.K
    return K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]


def direction_jacobian(prep: Prepared, camera: np.ndarray | int, uv: np.ndarray
                       ) -> np.ndarray:
    """d(unit viewing direction, world) / d(undistorted pixel) of ``camera`` (k,; or one, an
    int) at ``uv`` (k, 2), component-major: (3, 2, k), entry ``[i, j]`` the (k,) column of
    d d_i / d uv_j.
    With ``r = Rᵀ K⁻¹ (u, v, 1)`` and ``d = r / |r|``, ``dd/duv = (I - d dᵀ) Rᵀ K⁻¹[:, :2] / |r|``.
    """
    M = _per_point(prep._rt_k_inv_cols, camera)  # (9, k), M[3 i + j] = (Rᵀ K⁻¹)[i, j]
    u, v = uv[:, 0], uv[:, 1]
    r = M[0::3] * u
    r += M[1::3] * v
    r += M[2::3]
    norm = np.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    d = r / norm
    M = M.reshape(3, 3, -1)[:, :2] / norm  # (3, 2, k)
    dM = d[0] * M[0]
    dM += d[1] * M[1]
    dM += d[2] * M[2]
    M -= d[:, None] * dM
    return M


def direction_jacobian_along(prep: Prepared, camera: np.ndarray, uv: np.ndarray,
                             v: np.ndarray) -> np.ndarray:
    """``vᵀ`` :func:`direction_jacobian` for vectors ``v`` (3, k): (2, k), without the
    (3, 2, k) Jacobian. With ``M = Rᵀ K⁻¹[:, :2]``, ``r = Rᵀ K⁻¹ (u, v, 1)``:
    ``vᵀ (I - d dᵀ) M / |r| = (vᵀM - (vᵀr / |r|²) rᵀM) / |r|`` (equal to rounding)."""
    M = _per_point(prep._rt_k_inv_cols, camera)  # (9, k), M[3 i + j] = (Rᵀ K⁻¹)[i, j]
    u, w = uv[:, 0], uv[:, 1]
    r = M[0::3] * u
    r += M[1::3] * w
    r += M[2::3]
    norm2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    vM = v[0] * M[0:2]
    vM += v[1] * M[3:5]
    vM += v[2] * M[6:8]
    rM = r[0] * M[0:2]
    rM += r[1] * M[3:5]
    rM += r[2] * M[6:8]
    rM *= (v[0] * r[0] + v[1] * r[1] + v[2] * r[2]) / norm2
    vM -= rM
    vM /= np.sqrt(norm2)
    return vM


def dot_t(v: np.ndarray | Sequence[np.ndarray], J: np.ndarray) -> np.ndarray:
    """``vᵀ J`` of component-major (3, k) vectors and (3, 2, k) matrices: (2, k)."""
    out = v[0] * J[0]
    out += v[1] * J[1]
    out += v[2] * J[2]
    return out


def least_squares_pixel_jacobians(points: np.ndarray, origins: np.ndarray, dirs: np.ndarray,
                                  used: np.ndarray, turns: list[np.ndarray],
                                  compiled: bool | None = None) -> list[np.ndarray]:
    """d(point) / d(undistorted pixel of ray j), component-major (3, 2, k), for each of m rays
    of the least-squares point (:func:`pslog.geometry.triangulate_rays`; for two rays the
    midpoint of their common perpendicular), given each ray's ``turns[j]`` = d(unit
    direction) / d(pixel) (3, 2, k) (:func:`direction_jacobian`). From ``A p = b``,
    ``A = Σ (I - d dᵀ)``, ``b = Σ (I - d dᵀ) o``: a turn ``δd`` of ray j moves the point by
    ``-A⁻¹ ((dᵀw) δd + d (wᵀ δd))`` with ``w = o - p``. Zero for unused rays.

    ``points`` (k, 3), ``origins`` and ``dirs`` (k, m, 3), ``used`` (k, m). ``compiled``:
    by :mod:`._prepare_kernel`'s kernels (the same bits; None: where that module is loaded,
    as :func:`prepare` loads it)."""
    import sys

    m = used.shape[1]
    if compiled is None:
        compiled = "pslog.fusion._prepare_kernel" in sys.modules
    if compiled and len(used):
        from . import _prepare_kernel as pk

        k = len(used)
        used = np.ascontiguousarray(used, dtype=bool)
        dirs = np.ascontiguousarray(dirs, dtype=np.float64)
        inverse = np.empty((6, k))
        pk.normal_inverse(used, dirs, inverse)
        pts = np.ascontiguousarray(points, dtype=np.float64)
        # origins broadcast from one per ray (a rig's camera centres): one row each
        shared = origins.strides[0] == 0
        out = []
        block = np.empty((m, 3, 2, k))  # one block: a caller may take the m slots at once
        for j in range(m):
            origin = np.ascontiguousarray(origins[:1, j] if shared else origins[:, j],
                                          dtype=np.float64)
            moved = block[j]
            pk.ray_pixel_jacobian(pts, origin, np.ascontiguousarray(dirs[:, j]),
                                  np.ascontiguousarray(used[:, j]),
                                  np.ascontiguousarray(turns[j], dtype=np.float64), inverse,
                                  moved)
            out.append(moved)
        return out
    # (k,) columns throughout: numpy is slow on short axes
    d = [[np.where(used[:, j], dirs[:, j, i], 0.0) for i in range(3)] for j in range(m)]
    n_used = used.sum(axis=1).astype(np.float64)
    # A's six distinct entries (symmetric), then its inverse by the adjugate
    A = {}
    for _, i, j in _SYM6:
        A[i, j] = n_used.copy() if i == j else np.zeros(len(n_used))
        for dj in d:
            A[i, j] -= dj[i] * dj[j]
    a, b, c = A[0, 0], A[0, 1], A[0, 2]
    e, f, i_ = A[1, 1], A[1, 2], A[2, 2]
    co = {(0, 0): e * i_ - f * f, (0, 1): c * f - b * i_, (0, 2): b * f - c * e,
          (1, 1): a * i_ - c * c, (1, 2): c * b - a * f, (2, 2): a * e - b * b}
    det = a * co[0, 0] + b * co[0, 1] + c * co[0, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = 1.0 / np.where(np.abs(det) > 1e-12, det, np.nan)
    A_inv = {}
    for (i, j), v in co.items():
        A_inv[i, j] = A_inv[j, i] = v * inv_det
    P = [points[:, i] for i in range(3)]
    out = []
    for j in range(m):
        w = [origins[:, j, i] - P[i] for i in range(3)]
        G = np.where(used[:, j], turns[j], 0.0)
        dj = d[j]
        inner = (dj[0] * w[0] + dj[1] * w[1] + dj[2] * w[2]) * G
        inner += np.array(dj)[:, None] * dot_t(w, G)
        moved = np.empty((3, 2, len(n_used)))
        for i in range(3):
            row = A_inv[i, 0] * inner[0]
            row += A_inv[i, 1] * inner[1]
            row += A_inv[i, 2] * inner[2]
            np.negative(row, out=row)
            moved[i] = np.where(used[:, j], row, 0.0)
        out.append(moved)
    return out


#: The six distinct entries of a symmetric 3 x 3 matrix, (row, column), in the order of the
#: ``cov_*_m2`` columns.
_SYM6 = (("xx", 0, 0), ("yy", 1, 1), ("zz", 2, 2), ("xy", 0, 1), ("xz", 0, 2), ("yz", 1, 2))


def merged_slots(rows: np.ndarray) -> tuple[list[tuple[int, int, np.ndarray]], np.ndarray]:
    """Which slots of :func:`covariance` add up into which: ``(s, t, same)`` moves slot
    ``t``'s Jacobian into slot ``s`` where ``same`` (k,) (the same detection, each into its
    first slot), in order; also returns the (k, n_slots) mask of the slots merged away."""
    n_slots = rows.shape[1]
    merges = []
    # on (k,) columns, not strided columns of (k, n_slots): numpy is slow on short axes
    cols = [np.ascontiguousarray(rows[:, s]) for s in range(n_slots)]
    free = [np.ones(len(rows), dtype=bool) for _ in range(n_slots)]  # not merged away
    for s in range(n_slots):
        # (free[s] no longer changes: only later slots are merged away from here on)
        open_s = free[s] & (cols[s] >= 0)
        if not open_s.any():
            continue
        for t in range(s + 1, n_slots):
            same = cols[t] == cols[s]
            same &= open_s
            same &= free[t]
            if same.any():
                merges.append((s, t, same))
                free[t] &= ~same
    taken = np.stack(free, axis=1)  # a later slot merged into an earlier one
    np.logical_not(taken, out=taken)
    return merges, taken


def times_pixel_jacobian(J: np.ndarray, L: np.ndarray | None) -> np.ndarray:
    """``J L`` of component-major (..., 2, k) and (2, 2, k) matrices (L None: the identity)."""
    if L is None:
        return J
    return J[..., 0, None, :] * L[0] + J[..., 1, None, :] * L[1]


def covariance(rows: np.ndarray, jacobians: list[np.ndarray],
               uv_jacobians: Sequence[np.ndarray | None],
               noise_px: float | np.ndarray) -> dict[str, np.ndarray]:
    """First-order covariance of points made from detections, as the quality columns
    ``std_m`` (sqrt of the trace: the RMS 3-D error to expect) and the six distinct entries
    ``cov_xx_m2`` ... ``cov_yz_m2`` (k,), m².

    Slot ``s`` holds detection ``rows[:, s]`` (-1: unused) and ``jacobians[s]``, component-
    major (3, 2, k), is d(point) / d(its undistorted pixel) (zero where unused); a detection
    used in several slots of a point (type A's newest frame ends a bracket) adds up its slots'
    Jacobians. Each detection's recorded pixel has independent isotropic noise of ``noise_px``
    per axis (a (k,) array: each point's), mapped to undistorted pixels by ``uv_jacobians[s]``
    (2, 2, k) (:meth:`Prepared.pixel_jacobians_t`; None for the identity, a rig without lens
    distortion).
    """
    k = rows.shape[0]
    merges, taken = merged_slots(rows)
    merged = list(jacobians)
    copied = set()
    for s, t, same in merges:
        if s not in copied:
            merged[s] = merged[s].copy()
            copied.add(s)
        merged[s][:, :, same] += merged[t][:, :, same]
    cov = np.zeros((6, k))
    first = np.array([i for _, i, _ in _SYM6])
    second = np.array([j for _, _, j in _SYM6])
    for s in range(rows.shape[1]):
        use = (rows[:, s] >= 0) & ~taken[:, s]
        if not np.any(use):
            continue
        JL = times_pixel_jacobian(merged[s], uv_jacobians[s])
        if not np.all(use):
            JL = np.where(use, JL, 0.0)
        # J Jᵀ's six distinct entries, its two outer products written out
        cov += JL[first, 0] * JL[second, 0] + JL[first, 1] * JL[second, 1]
    return covariance_columns(cov * noise_px**2)


def covariance_columns(cov: np.ndarray) -> dict[str, np.ndarray]:
    """Quality columns of covariances given by their six distinct entries (6, k) in the order
    xx, yy, zz, xy, xz, yz: ``std_m`` (sqrt of the trace) and ``cov_xx_m2`` ... ``cov_yz_m2``."""
    out = {"std_m": np.sqrt(cov[0] + cov[1] + cov[2])}
    for i, (name, _, _) in enumerate(_SYM6):
        out[f"cov_{name}_m2"] = cov[i]
    return out


def finite_difference_jacobians(evaluate, uv: list[np.ndarray], rows: np.ndarray
                                ) -> list[np.ndarray]:
    """The Jacobians :func:`covariance` takes (component-major, (3, 2, k)), by forward
    differences of ``evaluate(uv)`` (slots' undistorted pixels, a list of (k, 2), to points
    (k, 3)); a detection in several slots moves in all of them at once, so its first slot gets
    the whole derivative."""
    base = evaluate(uv)
    k, n_slots = rows.shape
    out = [np.zeros((3, 2, k)) for _ in range(n_slots)]
    h = _JACOBIAN_STEP_PX
    for s in range(n_slots):
        first = (rows[:, s] >= 0) & ~np.any(rows[:, :s] == rows[:, s:s + 1], axis=1)
        if not np.any(first):
            continue
        same = (rows == rows[:, s:s + 1]) & first[:, None]
        for axis in range(2):
            step = np.zeros((k, 2))
            step[:, axis] = h
            moved = [u + np.where(same[:, j:j + 1], step, 0.0) for j, u in enumerate(uv)]
            with np.errstate(invalid="ignore"):
                out[s][:, axis] = np.where(first[:, None], (evaluate(moved) - base) / h, 0.0).T
    return out


def camera_mask(used: np.ndarray) -> np.ndarray:
    """(k,) float64 bitmask of the cameras used (bit c for camera c; exact up to 53)."""
    out = np.zeros(used.shape[0])
    for c in range(used.shape[1]):  # (sums of distinct powers of two: exact in any order)
        out += used[:, c] * 2.0**c
    return out


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


def default_max_gap_s(rig: Rig | Prepared) -> float:
    """3.5 frame periods of the slowest camera (of a rig, or of a Prepared session's
    cameras): bridges two missed frames, not more."""
    return 3.5 / min(c.fps for c in rig.cameras)
