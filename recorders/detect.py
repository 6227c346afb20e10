"""Ball detection by colour: HSV thresholding, connected components, sub-pixel centroids.

The paper's reference [5] finds the ball by fast colour thresholding; we do the same in two
passes so that a 1280 x 720 frame costs about a millisecond on one core:

1. coarse: the frame subsampled by ``downscale`` (nearest neighbour), screened by a BGR box
   that holds every colour of the HSV range (one :func:`cv2.inRange`), the few pixels that
   pass converted to HSV and thresholded (the whole coarse frame when many pass), labelled
   with :func:`cv2.connectedComponentsWithStats` after a 4 x 4 max-pooling (labelling costs
   per pixel, even empty ones); the largest blobs become regions of interest. The screen
   changes nothing but the cost: the pooled mask is the one of converting every pixel;
2. fine: each region (padded so it surely contains the whole blob) is thresholded again at
   full resolution; its components give the candidates. The centroid is the mean of the
   mask's pixel centres (sub-pixel by averaging; OpenCV pixel centres are integers), the
   apparent radius ``sqrt(area / pi)``, the roundness the ratio of the minor to the major
   axis of the second moments (1 for a disc, lower when motion-blurred), and the score

   ``score = fill * sqrt(roundness) * area / (area + 4 px)``

   in [0, 1], where ``fill`` is the area divided by the area of the moment ellipse (about 1
   for a solid disc or ellipse, lower for ragged blobs) and the last factor discounts
   specks of a few pixels.

A ball of radius r >= 1.5 px always leaves a pixel in the coarse grid at ``downscale = 2``.

Hue is OpenCV's 0..179 (degrees / 2); saturation and value 0..255. A range whose hue
minimum exceeds its maximum wraps around red (``170,10,...``).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from pslog.errors import InputError

_PAD = 2  # full-resolution pixels added around a coarse blob's box
_POOL = 4  # max-pooling factor of the coarse mask before labelling
_SPECK_PX = 4.0  # area at which the size factor of the score is 1/2
# screened pixels are converted one by one while fewer than 1/_SPARSE_FRACTION of the frame
# pass the BGR box (gathering them costs about 8 times a whole-frame conversion per pixel)
_SPARSE_FRACTION = 8
_CN_MAX = 512  # OpenCV's CV_CN_MAX: most channels of a Mat
#: a pooled coarse mask (or the part of it that holds its set cells): (uint8 cells, > 0
#: where set; the pooled column and row of its first cell, both even)
_Pooled = tuple[np.ndarray, int, int]


@dataclass(frozen=True)
class HsvRange:
    """An inclusive HSV box (OpenCV scales: hue 0..179, saturation and value 0..255).

    The default suits an orange ball (a golf ball as in the small-size league) under
    indoor light, including its shaded side.
    """

    hmin: int = 4
    hmax: int = 22
    smin: int = 120
    smax: int = 255
    vmin: int = 70
    vmax: int = 255

    def __post_init__(self) -> None:
        for name, top in (("hmin", 179), ("hmax", 179), ("smin", 255), ("smax", 255),
                          ("vmin", 255), ("vmax", 255)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not (
                    0 <= value <= top):
                raise InputError(f"HSV {name} must be an integer in 0..{top}, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.smin > self.smax or self.vmin > self.vmax:
            raise InputError(f"HSV range is empty: {self.text()}")

    @classmethod
    def parse(cls, text: str) -> HsvRange:
        """``"hmin,hmax,smin,smax,vmin,vmax"``, e.g. ``"4,22,120,255,70,255"``."""
        parts = [p.strip() for p in str(text).split(",")]
        if len(parts) != 6:
            raise InputError(f"--hsv needs six integers hmin,hmax,smin,smax,vmin,vmax, "
                             f"got {text!r}")
        try:
            values = [int(p) for p in parts]
        except ValueError:
            raise InputError(f"--hsv needs six integers, got {text!r}") from None
        return cls(*values)

    def text(self) -> str:
        return (f"{self.hmin},{self.hmax},{self.smin},{self.smax},{self.vmin},{self.vmax}")

    def mask(self, hsv: np.ndarray) -> np.ndarray:
        """(H, W) uint8 mask (255 inside) of an HSV image (H, W, 3) uint8."""
        if self.hmin <= self.hmax:
            return cv2.inRange(hsv, (self.hmin, self.smin, self.vmin),
                               (self.hmax, self.smax, self.vmax))
        low = cv2.inRange(hsv, (self.hmin, self.smin, self.vmin), (179, self.smax, self.vmax))
        high = cv2.inRange(hsv, (0, self.smin, self.vmin), (self.hmax, self.smax, self.vmax))
        return cv2.bitwise_or(low, high)


@dataclass(frozen=True)
class Candidates:
    """Ball candidates of one frame, best (highest score) first.

    Attributes
    ----------
    uv : (k, 2) float64, centroid in pixels (OpenCV convention: pixel centres are integers)
    radius : (k,) float64, ``sqrt(area / pi)``, pixels
    area : (k,) float64, pixels
    roundness : (k,) float64 in (0, 1], minor / major axis of the second moments
    score : (k,) float64 in [0, 1]
    """

    uv: np.ndarray
    radius: np.ndarray
    area: np.ndarray
    roundness: np.ndarray
    score: np.ndarray

    def __len__(self) -> int:
        return len(self.score)

    @classmethod
    def empty(cls) -> Candidates:
        z = np.zeros(0)
        return cls(np.zeros((0, 2)), z, z, z, z)


class BallDetector:
    """Finds up to ``max_candidates`` orange blobs in BGR frames.

    Parameters
    ----------
    hsv : HsvRange, colour of the ball
    max_candidates : int, K, candidates kept per frame (best first)
    min_area : float, smallest blob kept, full-resolution pixels
    downscale : int, subsampling of the coarse pass (1: threshold the whole frame at full
        resolution; 2 finds balls of radius >= 1.5 px)
    compiled : bool, screen the coarse pixels with one compiled loop (numba) instead of
        OpenCV's subsampling, screen and gather: the same candidates, about 0.3 ms less per
        1280 x 720 frame, but about 0.5 s to load numba per process; for long runs
    """

    def __init__(self, hsv: HsvRange | None = None, max_candidates: int = 5,
                 min_area: float = 2.0, downscale: int = 2, compiled: bool = False) -> None:
        if max_candidates < 1:
            raise InputError(f"max_candidates must be >= 1, got {max_candidates!r}")
        if downscale < 1:
            raise InputError(f"downscale must be >= 1, got {downscale!r}")
        self.hsv = hsv or HsvRange()
        self.max_candidates = int(max_candidates)
        self.min_area = float(min_area)
        self.downscale = int(downscale)
        self.compiled = bool(compiled)
        self._screen = _compiled_screen() if self.compiled else None
        self._buffers: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    def warm(self, width: int, height: int) -> np.ndarray:
        """Do now what the first frame of ``width`` x ``height`` would do lazily -- the BGR box
        of the colour range (about 0.3 s, cached per range), this OpenCV build's subsampling
        check for the size, every pass on a frame holding a ball -- so a camera's first frames
        are not late. Returns the frame used (a ball-coloured disc on black)."""
        frame = np.zeros((int(height), int(width), 3), np.uint8)
        hsv = self.hsv
        hue = (hsv.hmin + (hsv.hmax - hsv.hmin) % 180 // 2) % 180
        pixel = np.array([[[hue, (hsv.smin + hsv.smax) // 2, (hsv.vmin + hsv.vmax) // 2]]],
                         np.uint8)
        colour = cv2.cvtColor(pixel, cv2.COLOR_HSV2BGR)[0, 0]
        radius = max(min(int(width), int(height)) // 40, 3)
        cv2.circle(frame, (int(width) // 2, int(height) // 2), radius,
                   tuple(int(c) for c in colour), -1)
        self.detect(frame)
        return frame

    def detect(self, frame_bgr: np.ndarray) -> Candidates:
        """Candidates of one frame (H, W, 3) uint8 BGR."""
        if frame_bgr.ndim != 3 or frame_bgr.shape[2] != 3 or frame_bgr.dtype != np.uint8:
            raise InputError(f"frames must be (H, W, 3) uint8 BGR, got {frame_bgr.shape} "
                             f"{frame_bgr.dtype}")
        s = self.downscale
        h, w = frame_bgr.shape[:2]
        if not _nearest_is_stride(h, w, s):
            pooled = self._coarse_cells(_coarse(frame_bgr, s))
        elif self._screen is not None:
            pooled = self._coarse_cells_compiled(frame_bgr)
        else:
            pooled = self._coarse_cells_strided(frame_bgr)
        return self._from_pooled(frame_bgr, pooled)

    def detect_screened(self, frame_bgr: np.ndarray, xy: np.ndarray, colours: np.ndarray
                        ) -> Candidates:
        """:meth:`detect` of a frame (H, W, 3) uint8 BGR whose coarse pixels inside the
        BGR box of the range are those of ``xy`` ((n, 2) int32 coarse column and row) and
        ``colours`` ((n, 3) uint8), in any order; the frame's other coarse pixels outside
        it (:class:`recorders._jpeg.ScreenedDecoder`, which knows them without a pass over
        the frame). The coarse grid must be the frame's every ``downscale``-th pixel
        (:func:`_nearest_is_stride`). The same candidates as :meth:`detect`."""
        s = self.downscale
        h, w = frame_bgr.shape[:2]
        pooled = self._pooled(xy, colours, h // s, w // s) if len(xy) else None
        return self._from_pooled(frame_bgr, pooled)

    def _from_pooled(self, frame_bgr: np.ndarray, pooled: _Pooled | None) -> Candidates:
        """The candidates of a frame from its pooled coarse mask (None: empty)."""
        if pooled is None:
            return Candidates.empty()
        s = self.downscale
        h, w = frame_bgr.shape[:2]
        cells, px, py = pooled
        _, _, stats, _ = cv2.connectedComponentsWithStats(cells, connectivity=8)
        stats = stats[1:]
        # the largest blobs first; a few more than K since some may fade at full resolution
        order = np.argsort(-stats[:, cv2.CC_STAT_AREA], kind="stable")[:2 * self.max_candidates]
        cell = _POOL * s  # full-resolution pixels per pooled cell
        boxes = stats[order, :4].astype(np.int64)
        boxes[:, 0] += px
        boxes[:, 1] += py
        boxes *= cell
        # INTER_NEAREST samples source pixel floor(i * s): coarse pixel i stands for
        # full-resolution pixels [i*s, i*s + s), and the blob may reach up to s - 1 beyond
        x0 = np.maximum(boxes[:, 0] - _PAD - s, 0)
        y0 = np.maximum(boxes[:, 1] - _PAD - s, 0)
        x1 = np.minimum(boxes[:, 0] + boxes[:, 2] + _PAD + s, w)
        y1 = np.minimum(boxes[:, 1] + boxes[:, 3] + _PAD + s, h)
        rows = [self._fine(frame_bgr, *box) for box in _merge_boxes(x0, y0, x1, y1)]
        rows = [r for r in rows if len(r)]
        if not rows:
            return Candidates.empty()
        table = np.concatenate(rows)  # columns: u, v, area, roundness, fill
        u, v, area, roundness, fill = table.T
        score = np.clip(fill, 0.0, 1.0) * np.sqrt(roundness) * area / (area + _SPECK_PX)
        best = np.lexsort((-area, -score))[:self.max_candidates]
        return Candidates(uv=np.stack([u[best], v[best]], axis=1),
                          radius=np.sqrt(area[best] / np.pi), area=area[best],
                          roundness=roundness[best], score=score[best])

    def _coarse_cells(self, coarse: np.ndarray) -> _Pooled | None:
        """The coarse mask max-pooled by ``_POOL`` (uint8, > 0 where a cell holds a pixel in
        the HSV range; a :data:`_Pooled`), or None if no pixel is in range.

        Converting every coarse pixel to HSV is most of the cost of a frame; most pixels of
        a frame are far from the ball's colour. So a BGR box holding every colour of the HSV
        range (:func:`_bgr_box`) screens the pixels first with one ``inRange``, and only the
        few that pass are converted: the pooled mask is exactly the one of the whole frame
        (a pixel outside the box is outside the range). When many pass (a scene full of
        colours near the ball's) the whole coarse frame is converted as before.
        """
        ch, cw = coarse.shape[:2]
        ph, pw = -(-ch // _POOL), -(-cw // _POOL)
        lo, hi = _bgr_box(self.hsv)
        if lo is None:
            return None
        screen = cv2.inRange(coarse, lo, hi)
        n = cv2.countNonZero(screen)
        if not n:
            return None
        if n <= ch * cw // _SPARSE_FRACTION:
            xy = cv2.findNonZero(screen).reshape(-1, 2)
            return self._pooled(xy, _gather(coarse, xy, 1), ch, cw)
        mask = self.hsv.mask(cv2.cvtColor(coarse, cv2.COLOR_BGR2HSV))
        if not cv2.countNonZero(mask):
            return None
        # label a 4 x 4 max-pooled copy: labelling costs per pixel even where the mask is
        # empty, and blobs closer than a pooled cell may share a box (the fine pass splits them)
        if (ph * _POOL, pw * _POOL) != (ch, cw):
            mask = cv2.copyMakeBorder(mask, 0, ph * _POOL - ch, 0, pw * _POOL - cw,
                                      cv2.BORDER_CONSTANT, value=0)
        return cv2.resize(mask, (pw, ph), interpolation=cv2.INTER_AREA), 0, 0  # > 0 if any set

    def _coarse_cells_strided(self, frame_bgr: np.ndarray) -> _Pooled | None:
        """:meth:`_coarse_cells` of the subsampled frame without subsampling it (where OpenCV's
        nearest-neighbour subsampling picks every ``downscale``-th pixel, checked by
        :func:`_nearest_is_stride`): the same pooled mask.

        Subsampling a 1280 x 720 frame costs more than screening it (0.35 ms, about as much
        as ``numpy``'s strided copy: 3-byte pixels gathered one by one). Instead, the kept
        rows are seen in place as ``cw`` pixels of ``3 * downscale`` channels each (a row
        stride OpenCV takes without a copy), whose first three are the coarse pixel: one
        ``inRange`` with the other channels' bounds wide open screens exactly the coarse
        pixels, and the few that pass are gathered from the frame itself."""
        s = self.downscale
        h, w = frame_bgr.shape[:2]
        ch, cw = h // s, w // s
        lo, hi = _bgr_box(self.hsv)
        if lo is None:
            return None
        if not frame_bgr.flags.c_contiguous or 3 * s > _CN_MAX:
            return self._coarse_cells(_coarse(frame_bgr, s))
        rows = frame_bgr[:ch * s].reshape(ch, s * w * 3)[:, :cw * s * 3]
        pixels = rows.reshape(ch, cw, 3 * s)  # a view: no copy
        screen = cv2.inRange(pixels, *_wide_bounds(lo, hi, s))
        n = cv2.countNonZero(screen)
        if not n:
            return None
        if n > ch * cw // _SPARSE_FRACTION:  # many pass: the whole coarse frame converted
            return self._coarse_cells(_coarse(frame_bgr, s))
        xy = cv2.findNonZero(screen).reshape(-1, 2)
        return self._pooled(xy, _gather(frame_bgr, xy, s), ch, cw)

    def _pooled(self, xy: np.ndarray, colours: np.ndarray, ch: int, cw: int
                ) -> _Pooled | None:
        """The pooled mask of a ``ch`` x ``cw`` coarse frame from its screened pixels:
        ``xy`` (n, 2) int32 coarse column and row, ``colours`` (n, 3) uint8 BGR (those inside
        the HSV range set their cell); None if none is.

        Only the part of the pooled mask from the first set cells' even row and column to
        the last set cells (a :data:`_Pooled`): labelling costs per pixel, empty ones too
        (about 0.1 ms for the 90 x 160 cells of a 1280 x 720 frame, against a few us for
        the few cells a ball sets), and OpenCV's 8-connected labelling (scanning blocks of
        2 x 2 pixels from an even row and column) gives the components of such a part in
        the order and with the statistics of the whole mask's (``tests/test_detect.py``
        compares them on random masks)."""
        inside = self.hsv.mask(cv2.cvtColor(colours[None], cv2.COLOR_BGR2HSV))[0] > 0
        if not inside.any():
            return None
        xy = xy[inside]
        col, row = xy[:, 0] // _POOL, xy[:, 1] // _POOL
        x0, y0 = int(col.min()) & ~1, int(row.min()) & ~1
        cells = np.zeros((int(row.max()) + 1 - y0, int(col.max()) + 1 - x0), dtype=np.uint8)
        cells[row - y0, col - x0] = 255
        return cells, x0, y0

    def _coarse_cells_compiled(self, frame_bgr: np.ndarray) -> _Pooled | None:
        """:meth:`_coarse_cells` of the subsampled frame, the subsampling, screen and
        gather of the screened pixels done by one compiled loop over ``frame_bgr`` (where
        OpenCV's nearest-neighbour subsampling picks every ``downscale``-th pixel, checked by
        :func:`_nearest_is_stride`): the same pooled mask."""
        s = self.downscale
        h, w = frame_bgr.shape[:2]
        ch, cw = h // s, w // s
        lo, hi = _bgr_box(self.hsv)
        if lo is None:
            return None
        buffers = self._buffers.get((ch, cw))
        if buffers is None:
            cap = max(ch * cw // _SPARSE_FRACTION, 1)
            buffers = self._buffers[ch, cw] = (np.empty((cap, 2), np.int32),
                                               np.empty((cap, 3), np.uint8))
        xy, colours = buffers
        n = self._screen(frame_bgr, s, ch, cw, np.array(lo, np.uint8), np.array(hi, np.uint8),
                         xy, colours)
        if not n:
            return None
        if n > min(ch * cw // _SPARSE_FRACTION, len(xy)):  # many pass: the whole frame
            return self._coarse_cells(_coarse(frame_bgr, s))
        return self._pooled(xy[:n], colours[:n], ch, cw)

    def _fine(self, frame_bgr: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """Components of the full-resolution mask in a box: rows (n, 5) of
        u, v (frame pixels), area, roundness, fill."""
        return self._components(frame_bgr[y0:y1, x0:x1], x0, y0)

    def _components(self, roi: np.ndarray, x0: int, y0: int) -> np.ndarray:
        """:meth:`_fine` of ``roi`` (h, w, 3) uint8 BGR, whose pixel (0, 0) is the frame's
        pixel (x0, y0)."""
        mask = self.hsv.mask(cv2.cvtColor(roi, cv2.COLOR_BGR2HSV))
        _, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        keep = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= self.min_area) + 1
        out = np.empty((len(keep), 5))
        for row, label in enumerate(keep):  # a handful of blobs per box
            m = cv2.moments((labels == label).view(np.uint8), binaryImage=True)
            area = m["m00"]
            # central second moments per pixel; + 1/12 treats pixels as unit squares
            cxx = m["mu20"] / area + 1 / 12
            cyy = m["mu02"] / area + 1 / 12
            cxy = m["mu11"] / area
            spread = np.sqrt(((cxx - cyy) / 2) ** 2 + cxy**2)
            major = (cxx + cyy) / 2 + spread
            minor = (cxx + cyy) / 2 - spread
            # a filled ellipse with semi-axes a, b has variances a²/4, b²/4
            ellipse_area = 4 * np.pi * np.sqrt(max(major * minor, 1e-12))
            cu, cv = centroids[label]
            out[row] = (cu + x0, cv + y0, area, np.sqrt(max(minor, 0.0) / major),
                        area / ellipse_area)
        return out


def _coarse(frame_bgr: np.ndarray, s: int) -> np.ndarray:
    """The frame subsampled by ``s`` (nearest neighbour), or itself for ``s = 1``."""
    if s == 1:
        return frame_bgr
    h, w = frame_bgr.shape[:2]
    return cv2.resize(frame_bgr, (w // s, h // s), interpolation=cv2.INTER_NEAREST)


@functools.lru_cache(maxsize=64)
def _nearest_is_stride(h: int, w: int, s: int) -> bool:
    """Whether :func:`_coarse` of an (h, w, 3) uint8 frame takes exactly the pixels
    ``(i * s, j * s)``: found by subsampling two frames of this size whose colours encode
    each pixel's column and row, so the compiled screen samples the pixels this OpenCV
    build samples (whatever its rounding or IPP path), or is not used."""
    if s == 1:
        return True
    if h // s < 1 or w // s < 1 or max(h, w) >= 1 << 16:
        return False
    x, y = np.arange(w, dtype=np.uint16), np.arange(h, dtype=np.uint16)[:, None]
    cols = np.empty((h, w, 3), np.uint8)  # column, low and high byte; row's low byte
    cols[..., 0], cols[..., 1], cols[..., 2] = x & 255, x >> 8, y & 255
    rows = np.empty((h, w, 3), np.uint8)  # row, low and high byte; column's low byte
    rows[..., 0], rows[..., 1], rows[..., 2] = y & 255, y >> 8, x & 255
    a, b = _coarse(cols, s), _coarse(rows, s)
    j = s * np.arange(w // s, dtype=np.uint16)
    i = s * np.arange(h // s, dtype=np.uint16)[:, None]
    return bool(np.array_equal(a[..., 0] | (a[..., 1].astype(np.uint16) << 8), j + 0 * i)
                and np.array_equal(b[..., 0] | (b[..., 1].astype(np.uint16) << 8), i + 0 * j)
                and np.array_equal(a[..., 2], (i & 255) + 0 * j)
                and np.array_equal(b[..., 2], (j & 255) + 0 * i))


def _gather(image: np.ndarray, xy: np.ndarray, s: int) -> np.ndarray:
    """(n, 3) colours of the pixels ``image[y * s, x * s]`` of ``xy`` ((n, 2) columns x, y):
    one ``np.take`` of the flat pixel indices where the image is contiguous (a third of the
    time of indexing by row and column, about 0.13 ms less for the 4,000 pixels a noisy
    1280 x 720 frame passes through the screen)."""
    if not image.flags.c_contiguous:
        return image[xy[:, 1] * s, xy[:, 0] * s]
    flat = xy[:, 1].astype(np.intp) * (s * image.shape[1]) + xy[:, 0] * s
    return np.take(image.reshape(-1, 3), flat, axis=0)


@functools.lru_cache(maxsize=64)
def _wide_bounds(lo: tuple[int, int, int], hi: tuple[int, int, int], s: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``inRange`` bounds ((3 s,) float64 each) of pixels of ``3 s`` channels, ``s``
    frame pixels side by side: the first inside the BGR box ``[lo, hi]``, the others
    anywhere."""
    return (np.array(lo + (0,) * (3 * s - 3), np.float64),
            np.array(hi + (255,) * (3 * s - 3), np.float64))


def _compiled_screen():
    """The compiled screen (imports numba on first use)."""
    from ._screen import screen_samples

    return screen_samples


@functools.lru_cache(maxsize=16)
def _bgr_box(hsv: HsvRange) -> tuple[tuple[int, int, int], tuple[int, int, int]] | \
        tuple[None, None]:
    """The smallest BGR box (lower, upper corner, inclusive) holding every colour that
    OpenCV's BGR->HSV conversion puts inside ``hsv``; (None, None) if no colour is inside.

    Found by converting all 2**24 colours once (about 40 ms, cached per range), so it is
    exact for this OpenCV build, whatever its rounding.
    """
    gr = np.empty((256, 256, 3), dtype=np.uint8)
    gr[..., 1] = np.arange(256, dtype=np.uint8)[:, None]
    gr[..., 2] = np.arange(256, dtype=np.uint8)[None, :]
    step = 16  # blue levels per conversion: 1 M pixels, 3 MB
    image = np.tile(gr, (step, 1, 1))
    seen = np.zeros((3, 256), dtype=bool)
    for b0 in range(0, 256, step):
        image[..., 0] = np.repeat(np.arange(b0, b0 + step, dtype=np.uint8), 256)[:, None]
        inside = hsv.mask(cv2.cvtColor(image, cv2.COLOR_BGR2HSV)).reshape(step, 256, 256) > 0
        seen[0, b0:b0 + step] |= inside.any(axis=(1, 2))
        seen[1] |= inside.any(axis=(0, 2))
        seen[2] |= inside.any(axis=(0, 1))
    if not seen[0].any():
        return None, None
    lo = tuple(int(np.argmax(s)) for s in seen)
    hi = tuple(int(255 - np.argmax(s[::-1])) for s in seen)
    return lo, hi


def _merge_boxes(x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray
                 ) -> list[tuple[int, int, int, int]]:
    """Merge overlapping boxes so no blob is counted twice (a few boxes: plain loop)."""
    boxes = [[int(a), int(b), int(c), int(d)] for a, b, c, d in zip(x0, y0, x1, y1, strict=True)]
    merged = True
    while merged and len(boxes) > 1:
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                    boxes[i] = [min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]),
                                max(a[3], b[3])]
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return [tuple(b) for b in boxes]
