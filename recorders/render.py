"""Synthetic camera images: what a calibrated camera sees of a ball over a textured field.

The renderer traces rays, so it is exact under the rig's lens distortion: every sample is a
(distorted) pixel position turned into a world ray by :meth:`pslog.camera.Camera.rays`.

- Background (once per camera): each pixel's 2 x 2 sub-pixel rays hit the ground plane
  ``z = 0``; there a tileable green carpet texture (5 mm texels, bilinear) plus white field
  lines (the ``field_size`` rectangle from the world origin, a centre line and a centre
  circle, 20 mm wide, anti-aliased analytically). Rays that miss the ground within 25 m
  see a grey wall.
- Ball (every frame): only a region of interest around the ball's projected path is traced,
  with ``supersample x supersample`` rays per pixel intersected with the sphere at several
  instants spread over the exposure (motion blur: the average of sub-frame renders, their
  number chosen so consecutive sub-frames overlap). Lambert shading plus ambient light and
  a specular highlight, light from above.
- Sensor noise: zero-mean Gaussian in 8-bit levels, drawn once into a bank; each frame adds a
  window at an offset chosen by ``(seed, camera, frame index)`` so frames are reproducible.

Timing convention: a frame's timestamp is the centre of its exposure, so the blurred ball's
centroid is (to first order) the ball's position at the timestamp.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from pslog.camera import Camera
from pslog.errors import InputError
from pslog.motion import BALL_RADIUS

#: Default ball colour (BGR): an orange golf ball as in the small-size league.
BALL_BGR = (20, 110, 255)

_TEXEL_M = 0.005  # carpet texture resolution, metres per texel
_TEXTURE_SIZE = 512  # texels per side of the (tileable) carpet tile
_LINE_WIDTH_M = 0.02
_LINE_BGR = np.array([232.0, 236.0, 236.0])
_WALL_BGR = np.array([150.0, 145.0, 140.0])
_GROUND_LIMIT_M = 25.0
_NOISE_PAD = 32  # the noise bank is this much larger than a frame on each axis
_LIGHT_WORLD = np.array([0.3, -0.4, 1.0]) / np.linalg.norm([0.3, -0.4, 1.0])
_AMBIENT, _DIFFUSE, _SPECULAR, _SHININESS = 0.45, 0.55, 0.35, 24.0
_MAX_SUBFRAMES = 64


@dataclass(frozen=True)
class RenderOptions:
    """How the synthetic cameras render.

    Attributes
    ----------
    ball_radius : float, metres (default a golf ball, 0.0215)
    ball_bgr : (3,) ball albedo colour, 8-bit BGR
    exposure_s : float, exposure time in seconds (0: no motion blur)
    noise_sigma : float, sensor noise standard deviation in 8-bit levels (0: none)
    supersample : int, rays per pixel along each axis for the ball (anti-aliasing)
    seed : int, seed of the carpet texture and of the sensor noise
    field_size : (2,) metres, the white-lined field rectangle ``[0, x] x [0, y]`` on ``z = 0``
    """

    ball_radius: float = BALL_RADIUS
    ball_bgr: tuple[float, float, float] = BALL_BGR
    exposure_s: float = 0.004
    noise_sigma: float = 2.0
    supersample: int = 3
    seed: int = 0
    field_size: tuple[float, float] = (3.0, 2.0)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.ball_radius) and self.ball_radius > 0):
            raise InputError(f"ball radius must be > 0 metres, got {self.ball_radius!r}")
        if not (np.isfinite(self.exposure_s) and self.exposure_s >= 0):
            raise InputError(f"exposure must be >= 0 seconds, got {self.exposure_s!r}")
        if not (np.isfinite(self.noise_sigma) and self.noise_sigma >= 0):
            raise InputError(f"noise must be >= 0 levels, got {self.noise_sigma!r}")
        if not (1 <= int(self.supersample) <= 8):
            raise InputError(f"supersample must be in 1..8, got {self.supersample!r}")


class CameraRenderer:
    """Renders frames of one camera; the background is traced once at construction.

    Parameters
    ----------
    camera : Camera
    options : RenderOptions
    camera_index : int, mixes into the noise seed so cameras get independent noise
    """

    def __init__(self, camera: Camera, options: RenderOptions | None = None,
                 camera_index: int = 0) -> None:
        self.camera = camera
        self.options = options or RenderOptions()
        self.camera_index = int(camera_index)
        self.background = render_background(camera, self.options)
        self._noise_bank = None
        if self.options.noise_sigma > 0:
            rng = np.random.default_rng([self.options.seed, self.camera_index, 7])
            shape = (camera.height + _NOISE_PAD, camera.width + _NOISE_PAD, 3)
            self._noise_bank = np.round(
                rng.normal(0.0, self.options.noise_sigma, shape)).astype(np.int16)

    def exposure_positions(self, position: Callable[[np.ndarray], np.ndarray],
                           time_s: float) -> np.ndarray:
        """Ball centres (n, 3) world metres at sub-frame instants spread evenly over the
        exposure centred on ``time_s``; enough instants that consecutive ball images overlap
        by more than half a radius (one when the exposure is 0)."""
        exposure = self.options.exposure_s
        if exposure <= 0:
            return position(np.array([time_s]))
        ends = position(np.array([time_s - exposure / 2, time_s + exposure / 2]))
        uv, in_front = self.camera.project(ends)
        radius_px = self.apparent_radius_px(ends.mean(axis=0))
        if np.all(in_front) and np.isfinite(radius_px):
            path_px = float(np.linalg.norm(uv[1] - uv[0]))
            n = int(np.clip(np.ceil(4 * path_px / max(radius_px, 0.5)) + 1, 2, _MAX_SUBFRAMES))
        else:
            n = 8
        instants = time_s + exposure * ((np.arange(n) + 0.5) / n - 0.5)
        return position(instants)

    def apparent_radius_px(self, center_world: np.ndarray) -> float:
        """Approximate image radius of the ball at ``center_world`` (3,), pixels (NaN when
        behind the camera); from the focal length and the depth, without distortion."""
        depth = float((self.camera.R @ center_world + self.camera.t)[2])
        if depth <= self.options.ball_radius:
            return float("nan")
        f = float(np.sqrt(self.camera.K[0, 0] * self.camera.K[1, 1]))
        return f * self.options.ball_radius / depth

    def render(self, position: Callable[[np.ndarray], np.ndarray], time_s: float,
               frame_index: int = 0) -> np.ndarray:
        """The frame captured at ``time_s`` (exposure centre) of a ball whose centre follows
        ``position(times (n,) s) -> (n, 3) world metres``; (H, W, 3) uint8 BGR."""
        return self.render_positions(self.exposure_positions(position, time_s), frame_index)

    def render_positions(self, centers_world: np.ndarray, frame_index: int = 0) -> np.ndarray:
        """The frame with the ball averaged over the sub-frame centres (n, 3) world metres
        (one centre: no blur), with sensor noise; (H, W, 3) uint8 BGR."""
        frame = self.background.copy()
        roi = self._ball_roi(centers_world)
        if roi is not None:
            x0, y0, x1, y1 = roi
            coverage, color = self._trace_ball(centers_world, roi)
            patch = frame[y0:y1, x0:x1].astype(np.float32)
            patch = patch * (1 - coverage[..., None]) + color
            frame[y0:y1, x0:x1] = np.clip(np.round(patch), 0, 255).astype(np.uint8)
        if self._noise_bank is not None:
            rng = np.random.default_rng([self.options.seed, self.camera_index, int(frame_index)])
            dy, dx = rng.integers(0, _NOISE_PAD, 2)
            window = self._noise_bank[dy:dy + self.camera.height, dx:dx + self.camera.width]
            frame = cv2.add(frame, window, dtype=cv2.CV_8U)
        return frame

    # ---- ball -------------------------------------------------------------------------
    def _ball_roi(self, centers_world: np.ndarray) -> tuple[int, int, int, int] | None:
        """Pixel box ``[x0, x1) x [y0, y1)`` that contains the ball at every centre."""
        cam, radius = self.camera, self.options.ball_radius
        depth = centers_world @ cam.R[2] + cam.t[2]
        if np.any(depth <= 1.5 * radius):
            return None  # touching or behind the camera: not rendered
        # extremal points of the sphere along the camera axes bound its image; distortion
        # bends the outline a little, hence the 25 % margin and 2 px padding
        offsets = radius * np.concatenate([cam.R[:2], -cam.R[:2]])  # world vectors
        points = (centers_world[:, None, :] + 1.25 * offsets[None]).reshape(-1, 3)
        uv, _ = cam.project(np.vstack([points, centers_world]))
        if not np.all(np.isfinite(uv)):
            return None
        x0 = int(np.floor(uv[:, 0].min())) - 2
        y0 = int(np.floor(uv[:, 1].min())) - 2
        x1 = int(np.ceil(uv[:, 0].max())) + 3
        y1 = int(np.ceil(uv[:, 1].max())) + 3
        x0, y0 = max(x0, 0), max(y0, 0)
        x1, y1 = min(x1, cam.width), min(y1, cam.height)
        if x1 <= x0 or y1 <= y0:
            return None
        return x0, y0, x1, y1

    def _trace_ball(self, centers_world: np.ndarray, roi: tuple[int, int, int, int]
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Coverage (h, w) in [0, 1] and premultiplied colour (h, w, 3) of the ball in ``roi``,
        averaged over sub-pixel rays and sub-frame centres."""
        x0, y0, x1, y1 = roi
        s = int(self.options.supersample)
        sub = (np.arange(s) + 0.5) / s - 0.5  # sample offsets within a pixel
        us = (np.arange(x0, x1)[:, None] + sub[None, :]).ravel()  # (w*s,)
        vs = (np.arange(y0, y1)[:, None] + sub[None, :]).ravel()  # (h*s,)
        uu, vv = np.meshgrid(us, vs)  # (h*s, w*s)
        origin, directions = self.camera.rays(np.stack([uu.ravel(), vv.ravel()], axis=1))
        radius = self.options.ball_radius
        # ray-sphere intersection for every (sub-frame, ray): |o + s d - c|² = r²
        oc = origin[None, :] - centers_world  # (n, 3)
        b = directions @ oc.T  # (m, n)
        c = np.einsum("ij,ij->i", oc, oc) - radius * radius  # (n,)
        disc = b * b - c[None, :]
        hit = disc > 0
        dist = -b - np.sqrt(np.where(hit, disc, 0.0))
        hit &= dist > 0
        ray, sub_frame = np.nonzero(hit)  # shade only the rays that hit
        d = directions[ray]
        normals = (origin + dist[ray, sub_frame, None] * d - centers_world[sub_frame]) / radius
        diffuse = np.clip(normals @ _LIGHT_WORLD, 0.0, None)
        half = _LIGHT_WORLD - d
        half /= np.linalg.norm(half, axis=1, keepdims=True)
        specular = np.clip(np.einsum("ij,ij->i", normals, half), 0.0, None) ** _SHININESS
        albedo = np.asarray(self.options.ball_bgr, dtype=np.float64)
        shade = np.zeros((*hit.shape, 3))
        shade[ray, sub_frame] = np.minimum(
            (_AMBIENT + _DIFFUSE * diffuse)[:, None] * albedo
            + (_SPECULAR * 255.0 * specular)[:, None], 255.0)
        h, w, n = y1 - y0, x1 - x0, len(centers_world)
        # average over the s x s samples of each pixel and the n sub-frames
        coverage = hit.reshape(h, s, w, s, n).mean(axis=(1, 3, 4))
        color = shade.reshape(h, s, w, s, n, 3).mean(axis=(1, 3, 4))
        return coverage.astype(np.float32), color.astype(np.float32)


# ---- background ---------------------------------------------------------------------------
def render_background(camera: Camera, options: RenderOptions | None = None) -> np.ndarray:
    """The field as seen by ``camera`` without the ball: (H, W, 3) uint8 BGR (read-only;
    cached per camera geometry, texture seed and field size: in the process, and on disk
    (:func:`background_cache_dir`), since every synthetic camera process of ``pslog
    record`` / ``live`` would otherwise trace its ~1.2 million rays again, ~0.5 CPU s)."""
    options = options or RenderOptions()
    key = (camera.width, camera.height, camera.K.tobytes(), camera.dist.tobytes(),
           camera.R.tobytes(), camera.t.tobytes(), options.seed, tuple(options.field_size))
    cached = _BACKGROUNDS.get(key)
    if cached is None:
        path = _background_file(key)
        cached = _load_background(path, (camera.height, camera.width, 3))
        if cached is None:
            cached = _trace_background(camera, options)
            _store_background(path, cached)
        cached.setflags(write=False)
        if len(_BACKGROUNDS) >= 8:
            _BACKGROUNDS.pop(next(iter(_BACKGROUNDS)))
        _BACKGROUNDS[key] = cached
    return cached


_BACKGROUNDS: dict[tuple, np.ndarray] = {}

#: Background files kept on disk (the least recently written beyond it are removed).
BACKGROUND_CACHE_FILES = 64


def background_cache_dir() -> Path | None:
    """Where rendered backgrounds are kept between processes: ``$PSLOG_CACHE_DIR`` (empty:
    no disk cache), else ``$XDG_CACHE_HOME/pslog`` or ``~/.cache/pslog``, each with a
    ``backgrounds`` folder. A folder that cannot be made or written is no cache (each
    process renders its own), never an error."""
    root = os.environ.get("PSLOG_CACHE_DIR")
    if root is None:
        xdg = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"),
                                                               ".cache")
        root = os.path.join(xdg, "pslog")
    # only an absolute folder: with no home (``~`` unexpanded) or a relative setting the
    # cache would land in the working folder, beside the user's outputs
    return Path(root) / "backgrounds" if root and os.path.isabs(root) else None


@lru_cache(maxsize=1)
def _render_code_digest() -> str:
    """A digest of the code a background is made by (this module, the camera model's rays,
    numpy's and OpenCV's versions: the texture's random numbers and blur): a file rendered
    by other code is another file, never a stale one."""
    from pslog import camera as camera_module

    digest = hashlib.sha256(f"numpy {np.__version__} opencv {cv2.__version__}".encode())
    for module_file in (__file__, camera_module.__file__):
        try:
            digest.update(Path(module_file).read_bytes())
        except OSError:  # (a frozen install: no source) — no disk cache then
            return ""
    return digest.hexdigest()


def _background_file(key: tuple) -> Path | None:
    folder, code = background_cache_dir(), _render_code_digest()
    if folder is None or not code:
        return None
    digest = hashlib.sha256(code.encode())
    digest.update(repr(key).encode())
    return folder / f"{digest.hexdigest()[:40]}.npy"


def _load_background(path: Path | None, shape: tuple[int, int, int]) -> np.ndarray | None:
    """The background stored at ``path``, or None (none, unreadable, or not of ``shape``)."""
    if path is None:
        return None
    try:
        image = np.load(path, allow_pickle=False)
    except Exception:  # whatever lies there (a zip, a damaged file): rendered again
        return None
    if not isinstance(image, np.ndarray) or image.shape != shape or image.dtype != np.uint8:
        return None
    return image


def _store_background(path: Path | None, image: np.ndarray) -> None:
    """Write ``image`` to ``path`` whole (a temporary file renamed: a reader never sees half
    of it) and keep the folder at :data:`BACKGROUND_CACHE_FILES`; any failure (read-only
    home, full disk) leaves no file and is no error."""
    if path is None:
        return
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".partial-", suffix=".npy", dir=path.parent)
        with os.fdopen(fd, "wb") as f:
            np.save(f, image, allow_pickle=False)
        os.replace(tmp, path)
        tmp = None
        files = sorted(path.parent.glob("*.npy"), key=lambda p: p.stat().st_mtime)
        for old in files[:-BACKGROUND_CACHE_FILES]:
            old.unlink(missing_ok=True)
    except OSError:
        pass
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def _trace_background(camera: Camera, options: RenderOptions) -> np.ndarray:
    h, w = camera.height, camera.width
    sub = np.array([-0.25, 0.25])
    acc = np.zeros((h, w, 3), dtype=np.float64)
    texture = _carpet_texture(options.seed)
    for dv in sub:  # 2 x 2 sub-pixel rays per pixel, averaged (anti-aliasing)
        for du in sub:
            uu, vv = np.meshgrid(np.arange(w) + du, np.arange(h) + dv)
            origin, directions = camera.rays(np.stack([uu.ravel(), vv.ravel()], axis=1))
            acc += _shade_ground(origin, directions, texture, options).reshape(h, w, 3)
    return np.clip(np.round(acc / 4), 0, 255).astype(np.uint8)


def _carpet_texture(seed: int) -> np.ndarray:
    """Tileable carpet: green with fibre noise and soft mottling, (N, N, 3) float32 BGR."""
    rng = np.random.default_rng([seed, 1234])
    n = _TEXTURE_SIZE
    fibre = rng.normal(0.0, 1.0, (n, n)).astype(np.float32)
    mottle = rng.normal(0.0, 1.0, (n, n)).astype(np.float32)
    # blur a 3 x 3 tiling and keep the centre: the result wraps seamlessly
    fibre = cv2.GaussianBlur(np.tile(fibre, (3, 3)), (0, 0), 0.8)[n:2 * n, n:2 * n]
    mottle = cv2.GaussianBlur(np.tile(mottle, (3, 3)), (0, 0), 12.0)[n:2 * n, n:2 * n]
    fibre /= fibre.std()
    mottle /= mottle.std()
    brightness = 1.0 + 0.05 * fibre + 0.07 * mottle
    base = np.array([48.0, 128.0, 58.0], dtype=np.float32)
    return brightness[..., None] * base


def _shade_ground(origin: np.ndarray, directions: np.ndarray, texture: np.ndarray,
                  options: RenderOptions) -> np.ndarray:
    """Colour (m, 3) float BGR seen along rays from ``origin`` (3,) in ``directions`` (m, 3)."""
    m = len(directions)
    out = np.tile(_WALL_BGR, (m, 1))
    dz = directions[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        dist = np.where(dz < -1e-9, -origin[2] / dz, np.inf)
    ground_xy = origin[:2] + dist[:, None] * directions[:, :2]
    ground = np.isfinite(dist) & np.all(np.abs(ground_xy) < _GROUND_LIMIT_M, axis=1)
    xy = ground_xy[ground]
    carpet = _sample_wrapped(texture, xy / _TEXEL_M)
    # the footprint of a ray on the ground (metres) sets the anti-aliasing width of the lines
    pixel_angle = 1.0 / 800.0
    footprint = dist[ground] * pixel_angle / np.maximum(-dz[ground], 0.05)
    cover = _line_coverage(xy, options.field_size, footprint)
    out[ground] = carpet * (1 - cover[:, None]) + _LINE_BGR * cover[:, None]
    return out


def _sample_wrapped(texture: np.ndarray, texel_xy: np.ndarray) -> np.ndarray:
    """Bilinear samples (m, 3) of a tileable ``texture`` (N, N, 3) float32 at texel
    coordinates (m, 2), wrapping around its edges."""
    n, m, width = texture.shape[0], len(texel_xy), 1024
    # cv2.remap wants 2D maps no larger than 32767 per side: fold the samples into rows
    rows = -(-m // width)
    maps = np.zeros((rows * width, 2), dtype=np.float32)
    maps[:m] = np.mod(texel_xy, n)
    maps = maps.reshape(rows, width, 2)
    out = cv2.remap(texture, maps[..., 0], maps[..., 1], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_WRAP)
    return out.reshape(-1, 3)[:m].astype(np.float64)


def _line_coverage(xy: np.ndarray, field_size: tuple[float, float],
                   footprint: np.ndarray) -> np.ndarray:
    """Fraction (m,) of a ground sample covered by a white line, smoothed over the sample's
    footprint (m,) metres."""
    fx, fy = field_size
    x, y = xy[:, 0], xy[:, 1]
    inside_x = (x >= -_LINE_WIDTH_M) & (x <= fx + _LINE_WIDTH_M)
    inside_y = (y >= -_LINE_WIDTH_M) & (y <= fy + _LINE_WIDTH_M)
    far = np.full(len(xy), np.inf)
    d = np.minimum.reduce([
        np.where(inside_y, np.abs(x), far),            # goal line x = 0
        np.where(inside_y, np.abs(x - fx), far),       # goal line x = fx
        np.where(inside_y, np.abs(x - fx / 2), far),   # centre line
        np.where(inside_x, np.abs(y), far),            # touch line y = 0
        np.where(inside_x, np.abs(y - fy), far),       # touch line y = fy
        np.abs(np.hypot(x - fx / 2, y - fy / 2) - 0.25 * min(fx, fy)),  # centre circle
    ])
    half = _LINE_WIDTH_M / 2
    soft = np.maximum(footprint, 1e-4)
    return np.clip((half - d) / soft + 0.5, 0.0, 1.0)
