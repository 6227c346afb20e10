"""Ball detection: HSV ranges, candidates, sub-pixel accuracy on rendered frames."""

from __future__ import annotations

import functools

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.camera import Camera, look_at
from pslog.errors import InputError
from recorders import detect
from recorders.detect import BallDetector, HsvRange
from recorders.render import CameraRenderer, RenderOptions

GREEN_BGR = (50, 130, 60)
ORANGE_BGR = (20, 110, 255)


def _close_camera(dist=(0.0, 0.0, 0.0, 0.0, 0.0)) -> Camera:
    """A camera 1.8 m above the field seeing a golf ball with a radius of 5..10 px."""
    R, t = look_at((1.5, -0.5, 1.8), (1.5, 1.0, 0.0))
    K = np.array([[700.0, 0.0, 319.5], [0.0, 700.0, 239.5], [0.0, 0.0, 1.0]])
    return Camera("close", 640, 480, K, np.array(dist, dtype=float), R, t)


def _flat(shape=(480, 640)) -> np.ndarray:
    frame = np.empty((*shape, 3), dtype=np.uint8)
    frame[:] = GREEN_BGR
    return frame


def test_hsv_parse_and_errors():
    assert HsvRange.parse("4, 22,120,255,70,255") == HsvRange()
    assert HsvRange.parse(HsvRange(170, 10, 1, 2, 3, 4).text()) == HsvRange(170, 10, 1, 2, 3, 4)
    for bad in ("1,2,3", "a,2,3,4,5,6", "0,200,0,255,0,255", "0,10,200,100,0,255"):
        with pytest.raises(InputError):
            HsvRange.parse(bad)


def test_empty_frame_has_no_candidate():
    found = BallDetector().detect(_flat())
    assert len(found) == 0
    assert found.uv.shape == (0, 2)


def test_candidates_sorted_by_score_and_limited():
    frame = _flat()
    cv2.circle(frame, (100, 100), 8, ORANGE_BGR, -1)  # round ball
    cv2.ellipse(frame, (400, 300), (20, 3), 30, 0, 360, ORANGE_BGR, -1)  # elongated blob
    frame[50:52, 600:602] = ORANGE_BGR  # a 4-pixel speck
    found = BallDetector(max_candidates=5).detect(frame)
    assert len(found) == 3
    assert np.all(np.diff(found.score) <= 0)
    assert_allclose(found.uv[0], (100, 100), atol=1e-9)  # symmetric disc: exact centre
    assert found.roundness[0] > 0.95 and found.score[0] > 0.9
    assert_allclose(found.radius, np.sqrt(found.area / np.pi))
    ellipse = np.argmax(found.area)
    assert_allclose(found.uv[ellipse], (400, 300), atol=0.05)
    assert found.roundness[ellipse] < 0.3 and found.score[ellipse] < 0.5
    speck = np.argmin(found.area)
    assert found.area[speck] == 4 and found.score[speck] < 0.5
    assert len(BallDetector(max_candidates=1).detect(frame)) == 1


def test_coarse_pass_finds_small_balls_and_matches_full_resolution():
    frame = _flat()
    centers = [(33.3, 41.7), (320.6, 239.2), (600.1, 401.9)]
    for u, v in centers:  # discs of radius 1.6 px drawn with 1/16 px precision
        cv2.circle(frame, (round(u * 16), round(v * 16)), round(1.6 * 16), ORANGE_BGR, -1,
                   lineType=cv2.LINE_8, shift=4)
    coarse = BallDetector(downscale=2).detect(frame)
    full = BallDetector(downscale=1).detect(frame)
    assert len(coarse) == len(full) == 3
    order_c, order_f = np.argsort(coarse.uv[:, 0]), np.argsort(full.uv[:, 0])
    assert_array_equal(coarse.uv[order_c], full.uv[order_f])
    assert_allclose(coarse.uv[order_c], centers, atol=0.5)


def test_hue_range_wrapping_around_red():
    frame = _flat()
    cv2.circle(frame, (200, 200), 6, (30, 20, 220), -1)  # red: hue about 177
    assert len(BallDetector().detect(frame)) == 0
    found = BallDetector(HsvRange(170, 5, 120, 255, 70, 255)).detect(frame)
    assert len(found) == 1
    assert_allclose(found.uv[0], (200, 200), atol=1e-9)


def test_rejects_non_bgr_frames():
    with pytest.raises(InputError):
        BallDetector().detect(np.zeros((10, 10), np.uint8))


@pytest.mark.parametrize("dist", [(0.0, 0.0, 0.0, 0.0, 0.0), (-0.25, 0.08, 0.001, -0.001, 0.0)])
def test_centroid_accuracy_on_unblurred_renders(dist):
    """Issue target: < 0.25 px RMS against the true projection of the ball's centre for a
    radius of at least 5 px (rendered with shading, noise and lens distortion)."""
    cam = _close_camera(dist)
    renderer = CameraRenderer(cam, RenderOptions(exposure_s=0.0, noise_sigma=2.0), 0)
    rng = np.random.default_rng(3)
    detector = BallDetector()
    errors, radii = [], []
    while len(errors) < 40:
        center = np.array([rng.uniform(0.5, 2.5), rng.uniform(0.2, 1.8), rng.uniform(0.03, 0.6)])
        uv, _ = cam.project(center[None])
        if not cam.in_image(uv, margin=20)[0]:
            continue
        found = detector.detect(renderer.render_positions(center[None], len(errors)))
        assert len(found) >= 1
        errors.append(found.uv[0] - uv[0])
        radii.append(renderer.apparent_radius_px(center))
    errors = np.array(errors)
    assert min(radii) >= 5.0
    rms = np.sqrt(np.mean(np.sum(errors**2, axis=1)))
    assert rms < 0.25, rms


def test_blurred_ball_is_centred_on_its_mid_exposure_position():
    cam = _close_camera()
    renderer = CameraRenderer(cam, RenderOptions(exposure_s=0.004, noise_sigma=2.0), 0)

    def position(t):  # 4 m/s along x: a 1.6 cm smear of a 4.3 cm ball
        return np.stack([1.5 + 4.0 * t, np.full_like(t, 1.0), np.full_like(t, 0.3)], axis=1)

    found = BallDetector().detect(renderer.render(position, 0.0))
    uv, _ = cam.project(position(np.array([0.0])))
    assert len(found) == 1
    assert_allclose(found.uv[0], uv[0], atol=0.3)


@pytest.mark.parametrize("hsv", [HsvRange(), HsvRange(170, 10, 120, 255, 70, 255),
                                 HsvRange(100, 130, 40, 200, 20, 240)])
def test_bgr_screen_box_holds_every_colour_of_the_range(hsv):
    """The BGR box that screens coarse pixels before the HSV conversion must never drop a
    colour inside the range (all 2**24 colours), and is the tightest such box."""
    lo, hi = detect._bgr_box(hsv)
    colours = np.empty((256, 256, 256, 3), dtype=np.uint8)  # (b, g, r)
    colours[..., 0] = np.arange(256, dtype=np.uint8)[:, None, None]
    colours[..., 1] = np.arange(256, dtype=np.uint8)[None, :, None]
    colours[..., 2] = np.arange(256, dtype=np.uint8)[None, None, :]
    image = colours.reshape(4096, 4096, 3)
    inside = hsv.mask(cv2.cvtColor(image, cv2.COLOR_BGR2HSV)) > 0
    screened = cv2.inRange(image, lo, hi) > 0
    assert inside.any() and not np.any(inside & ~screened)
    values = image[inside]
    assert_array_equal(values.min(axis=0), lo)
    assert_array_equal(values.max(axis=0), hi)


def _busy_frames() -> tuple[np.ndarray, ...]:
    """Rendered frames with balls, specks and patches of random colours near the ball's
    (rendered once per process for the tests that detect in them; each test gets writable
    copies: a read-only frame would make numba compile the screen for read-only arrays, a
    signature production never uses and warm does not compile)."""
    return tuple(f.copy() for f in _busy_frames_rendered())


@functools.cache
def _busy_frames_rendered() -> tuple[np.ndarray, ...]:
    cam = Camera("wide", 1280, 720, np.array([[800.0, 0, 639.5], [0, 800.0, 359.5], [0, 0, 1]]),
                 np.zeros(5), *look_at((1.5, -1.5, 2.5), (1.5, 1.0, 0.0)))
    renderer = CameraRenderer(cam, RenderOptions(exposure_s=0.004, noise_sigma=2.0), 0)
    rng = np.random.default_rng(5)
    frames = []
    for k in range(4):
        frame = renderer.render_positions(np.array([[0.5 + 0.6 * k, 1.0, 0.1 + 0.2 * k]]), k)
        patch = rng.integers(0, 256, (60 + 40 * k, 90, 3), dtype=np.uint8)
        patch[..., 2] = np.maximum(patch[..., 2], 100)  # reddish: many pass the screen
        frame[200:260 + 40 * k, 700:790] = patch
        cv2.circle(frame, (100 + 200 * k, 600), 2 + 2 * k, ORANGE_BGR, -1)
        frame[30 + k, 30:34] = ORANGE_BGR  # a speck
        frames.append(frame)
    return tuple(frames)


@pytest.mark.parametrize("downscale", [1, 2, 3])
def test_screened_coarse_pass_equals_converting_every_pixel(monkeypatch, downscale):
    """The coarse pass converts only the pixels the BGR box lets through while they are few,
    else every pixel: both give the same candidates, in the same order, to the last bit."""
    frames = [*_busy_frames(), _flat()]
    detector = BallDetector(max_candidates=20, downscale=downscale)
    monkeypatch.setattr(detect, "_SPARSE_FRACTION", 1)  # always screen pixel by pixel
    screened = [detector.detect(f) for f in frames]
    monkeypatch.setattr(detect, "_SPARSE_FRACTION", 10**9)  # always convert the whole frame
    whole = [detector.detect(f) for f in frames]
    assert sum(len(c) for c in whole) > 20
    for a, b in zip(screened, whole, strict=True):
        for name in ("uv", "radius", "area", "roundness", "score"):
            assert_array_equal(getattr(a, name), getattr(b, name))


def test_hsv_range_holding_no_colour_finds_nothing():
    empty = HsvRange(0, 179, 255, 255, 0, 0)  # saturation 255 at value 0: no colour
    assert detect._bgr_box(empty) == (None, None)
    frame = _flat()
    cv2.circle(frame, (100, 100), 8, ORANGE_BGR, -1)
    assert len(BallDetector(empty).detect(frame)) == 0


def _odd_frames() -> tuple[np.ndarray, ...]:
    """Busy frames, cropped to odd sizes, as non-contiguous views and after a JPEG round trip
    (the frames `pslog redetect` sees); the JPEG round trips made once per process for the
    24 tests that detect in them, every frame a writable copy (or a view of one) per test."""
    frames = _busy_frames()
    jpeg = [f.copy() for f in _jpeg_frames()]
    return (*frames, *jpeg, frames[0][:717, :1279], frames[1][3:, 5:], frames[2][:, ::-1],
            frames[3][::-1][:101, :203], _flat((7, 9)))


@functools.cache
def _jpeg_frames() -> tuple[np.ndarray, ...]:
    return tuple(cv2.imdecode(cv2.imencode(".jpg", f, [cv2.IMWRITE_JPEG_QUALITY, 90])[1],
                              cv2.IMREAD_COLOR) for f in _busy_frames_rendered()[:2])


@pytest.mark.parametrize("downscale", [1, 2, 3, 4])
@pytest.mark.parametrize("sparse", [8, 1, 10**9])
def test_compiled_screen_gives_the_same_candidates(monkeypatch, downscale, sparse):
    """``compiled=True`` (one numba loop subsampling, screening and gathering) finds the same
    candidates as OpenCV's resize, inRange and findNonZero, to the last bit, in either
    regime of the coarse pass (few pixels screened, or the whole frame converted) and where
    OpenCV's subsampling is not a plain stride (downscale 3 of 1280 columns: the fallback)."""
    monkeypatch.setattr(detect, "_SPARSE_FRACTION", sparse)
    plain = BallDetector(max_candidates=20, downscale=downscale)
    compiled = BallDetector(max_candidates=20, downscale=downscale, compiled=True)
    total = 0
    for frame in _odd_frames():
        a, b = plain.detect(frame), compiled.detect(frame)
        total += len(a)
        for name in ("uv", "radius", "area", "roundness", "score"):
            assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
            assert getattr(b, name).dtype == getattr(a, name).dtype
    assert total > 40


@pytest.mark.parametrize("downscale", [1, 2, 3, 4])
@pytest.mark.parametrize("sparse", [8, 1, 10**9])
def test_strided_screen_gives_the_candidates_of_opencvs_subsampling(monkeypatch, downscale,
                                                                    sparse):
    """Without numba, the coarse pixels are screened in place (every ``downscale``-th row
    seen as pixels of ``3 * downscale`` channels) and gathered from the frame: the same
    candidates, to the last bit, as subsampling the frame with OpenCV's resize first (the
    detector made to believe the subsampling is no stride), in both regimes of the coarse
    pass, on odd sizes, non-contiguous views and JPEG round trips."""
    monkeypatch.setattr(detect, "_SPARSE_FRACTION", sparse)
    detector = BallDetector(max_candidates=20, downscale=downscale)
    # and a frame of saturated colours (0 and 255 channels: the bounds of the channels the
    # screen leaves open), orange blobs on random black, white and primary pixels
    rng = np.random.default_rng(3)
    levels = np.array([[0, 0, 0], [255, 255, 255], [255, 0, 0], [0, 0, 255], [0, 255, 0]],
                      np.uint8)
    saturated = levels[rng.integers(0, len(levels), (96, 160))]
    for x, y, r in ((30, 20, 6), (100, 60, 9), (140, 15, 4)):
        cv2.circle(saturated, (x, y), r, (0, 140, 255), -1)
    frames = [*_odd_frames(), saturated]
    strided = [detector.detect(frame) for frame in frames]
    monkeypatch.setattr(detect, "_nearest_is_stride", lambda h, w, s: False)
    total = 0
    for frame, b in zip(frames, strided, strict=True):
        a = detector.detect(frame)
        total += len(a)
        for name in ("uv", "radius", "area", "roundness", "score"):
            assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
            assert getattr(b, name).dtype == getattr(a, name).dtype
    assert total > 40


def test_gather_takes_the_strided_pixels():
    """``_gather`` (a flat ``np.take`` on contiguous images) against indexing by row and
    column, contiguous or not."""
    rng = np.random.default_rng(5)
    image = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    for s, view in ((1, image), (2, image), (3, image), (1, image[:, ::-1]), (2, image[1:])):
        h, w = view.shape[0] // s, view.shape[1] // s
        xy = np.stack([rng.integers(0, w, 50), rng.integers(0, h, 50)], axis=1).astype(np.int32)
        assert_array_equal(detect._gather(view, xy, s), view[xy[:, 1] * s, xy[:, 0] * s])


def test_screen_kernel_is_inrange_and_findnonzero_of_the_subsampled_frame():
    """The kernel (compiled and pure Python) against OpenCV on frames whose colours sit on
    and around the box's bounds; only the first ``m`` pixels stored, all counted."""
    from recorders._screen import screen_samples

    rng = np.random.default_rng(11)
    lo, hi = np.array([10, 60, 120], np.uint8), np.array([40, 90, 200], np.uint8)
    # each channel at, just inside and just outside its bounds
    levels = np.stack([lo - 1, lo, lo + 1, hi - 1, hi, hi + 1]).astype(np.uint8)  # (6, 3)
    for k in range(12):
        h, w, s = int(rng.integers(5, 90)), int(rng.integers(5, 90)), 1 + k % 3
        frame = levels[rng.integers(0, 6, (h, w, 3)), np.arange(3)]
        coarse = frame[::s, ::s][:h // s, :w // s]
        found = cv2.findNonZero(cv2.inRange(np.ascontiguousarray(coarse), lo, hi))
        want = np.zeros((0, 2), np.int32) if found is None else found.reshape(-1, 2)
        assert len(want) > 0
        for fn in (screen_samples, screen_samples.py_func):
            for cap in (len(want) + 3, max(len(want) // 2, 1)):
                xy, bgr = np.full((cap, 2), -1, np.int32), np.zeros((cap, 3), np.uint8)
                n = fn(frame, s, h // s, w // s, lo, hi, xy, bgr)
                m = min(n, cap)
                assert n == len(want)
                assert_array_equal(xy[:m], want[:m])
                assert_array_equal(bgr[:m], coarse[want[:m, 1], want[:m, 0]])


@pytest.mark.parametrize(("h", "w", "s", "stride"), [(720, 1280, 2, True), (480, 640, 2, True),
                                                     (721, 1281, 2, True), (7, 9, 1, True),
                                                     (720, 1280, 3, False)])
def test_nearest_subsampling_is_a_stride_where_opencv_says_so(h, w, s, stride):
    """The compiled screen is used only where OpenCV's nearest-neighbour resize takes every
    s-th pixel (1280 // 3 = 426 columns are spread over 1280: not a stride)."""
    assert detect._nearest_is_stride(h, w, s) is stride


def test_pooled_part_is_labelled_as_the_whole_pooled_mask():
    """The coarse pass keeps only the part of the pooled mask from its first set cells' even
    row and column to its last ones (labelling the empty rest cost 0.1 ms a 1280 x 720
    frame): OpenCV labels the components of that part in the whole mask's order, with its
    statistics once offset (random masks of random sizes, sparse to dense; an odd first
    row or column reorders them)."""
    rng = np.random.default_rng(12)
    detector = BallDetector()
    for _ in range(400):
        ch, cw = int(rng.integers(4, 120)), int(rng.integers(4, 200))
        n = int(rng.integers(1, ch * cw // 2))
        xy = np.stack([rng.integers(0, cw, n), rng.integers(0, ch, n)], axis=1).astype(np.int32)
        cells, x0, y0 = detector._pooled(xy, np.tile(np.array(ORANGE_BGR, np.uint8), (n, 1)),
                                         ch, cw)
        whole = np.zeros((-(-ch // 4), -(-cw // 4)), np.uint8)
        whole[xy[:, 1] // 4, xy[:, 0] // 4] = 255
        _, _, expected, _ = cv2.connectedComponentsWithStats(whole, connectivity=8)
        _, _, got, _ = cv2.connectedComponentsWithStats(cells, connectivity=8)
        got[1:, 0] += x0
        got[1:, 1] += y0
        assert_array_equal(got[1:], expected[1:])
