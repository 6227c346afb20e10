"""The screened decoder of ``pslog redetect`` (recorders/_jpeg.py): the exact candidates of
``cv2.imdecode``'s frames from the few blocks whose colours may be in the range."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.testing import assert_array_equal

from pslog.cli import main
from pslog.log import iter_images, read_session
from recorders import HsvRange, redetect
from recorders import _jpeg as J
from recorders.detect import BallDetector
from recorders.record import jpeg_params

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"
RANGES = [HsvRange(), HsvRange(100, 130, 120, 255, 70, 255), HsvRange(170, 10, 60, 255, 40, 255),
          HsvRange(35, 85, 40, 255, 40, 255),  # orange, blue, red (wrapping), the field's green
          HsvRange(0, 179, 0, 20, 245, 255)]  # the lines' brightest white (Y above 240 only)


@pytest.fixture(scope="module")
def frames() -> list[bytes]:
    return [bytes(i.data) for i in iter_images(SAMPLE)]


def _exact(detector: BallDetector, blob: bytes):
    return detector.detect(cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_COLOR))


def _same(a, b) -> bool:
    return all(np.array_equal(x, y) for x, y in ((a.uv, b.uv), (a.radius, b.radius),
                                                 (a.area, b.area), (a.score, b.score)))


@pytest.mark.parametrize("hsv", RANGES, ids=["orange", "blue", "red", "green", "white"])
def test_screened_candidates_are_the_decoded_frames(frames, hsv):
    detector = BallDetector(hsv, 5, compiled=True)
    decoder = J.ScreenedDecoder(detector)
    found = 0
    for blob in frames[::3]:
        got = decoder.detect(blob)
        assert got is not None  # the recorder's frames are all for the screened decoder
        exact = _exact(detector, blob)
        assert _same(got, exact)
        found += len(exact)
    assert (found > 0) == (hsv != RANGES[1])  # no blue in the sample


def _all_blocks(blob: bytes) -> tuple[np.ndarray, int]:
    """Every block of ``blob`` decoded by the kernels (a colour table that passes all)."""
    data = np.frombuffer(blob, np.uint8)
    h = J._Header(data)
    assert h.ok
    nbx, nby = -(-h.width // 8), -(-h.height // 8)
    state = np.zeros((nbx * nby, 8), np.int64)
    coefs = np.zeros((nbx * nby, 3, 64), np.int16)
    table = np.zeros((65, 65, 65), np.int32)
    table[1:, 1:, 1:] = np.ones((64, 64, 64), np.int32).cumsum(0).cumsum(1).cumsum(2)
    n = J.screen_blocks(data, h.start, nbx, nby, h.restart, h.dc, h.ac, h.fast, h.maxcode,
                        h.offset, h.symbols, h.weights, h.quant, table, state, False, coefs)
    assert n == nbx * nby
    J.screen_blocks(data, h.start, nbx, n, h.restart, h.dc, h.ac, h.fast, h.maxcode, h.offset,
                    h.symbols, h.weights, h.quant, table, state, True, coefs)
    frame = np.zeros((h.height, h.width, 3), np.uint8)
    xy, bgr = np.zeros((64 * n, 2), np.int32), np.zeros((64 * n, 3), np.uint8)
    drawn = np.zeros(n, np.uint8)
    J.render_blocks(coefs, state, n, nbx, h.quant, J._idct_limit(), J._colour_tables(), table,
                    frame, 2, np.zeros(3, np.uint8), np.full(3, 255, np.uint8), xy, bgr, drawn)
    assert drawn.all()
    return frame, n


def test_every_block_is_decoded_to_libjpegs_pixels(frames):
    # entropy decoding, integer IDCT and colour conversion over whole frames: the sample's,
    # a noisy 1280 x 720 frame with restart markers, and one of a random picture at quality 100
    rng = np.random.default_rng(3)
    noisy = np.clip(rng.normal(90, 40, (720, 1280, 3)), 0, 255).astype(np.uint8)
    blobs = [frames[0], frames[70],
             cv2.imencode(".jpg", noisy, [*jpeg_params(90), cv2.IMWRITE_JPEG_RST_INTERVAL, 7])[
                 1].tobytes(),
             cv2.imencode(".jpg", noisy[:100, :200], jpeg_params(100))[1].tobytes()]
    for blob in blobs:
        frame, _ = _all_blocks(blob)
        assert_array_equal(frame, cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_COLOR))


def test_bound_keeps_every_block_with_a_pixel_in_range():
    # dots of two pixels at every place in a block on a green field, of an orange at the
    # edge of the range (hue 20 of 4..22), so that only the bound's far end reaches the
    # range: at quality 100 each dot is nearly an impulse, whose coefficients all peak at
    # the dot (the triangle inequality nearly an equality); at 90 the dots are blurred
    # (the bound at half its width leaves pixels in range outside the kept blocks)
    hsv = HsvRange()
    detector = BallDetector(hsv, 100, compiled=True)
    decoder = J.ScreenedDecoder(detector)
    field = np.empty((128, 256, 3), np.uint8)
    field[:] = (40, 140, 50)
    for k in range(64):
        y, x = 16 * (k // 16) + k % 8, 16 * (k % 16) + (k // 8) % 8
        field[y, x:x + 2] = (30, 110, 160)
    for quality in (100, 95, 90):
        blob = cv2.imencode(".jpg", field, jpeg_params(quality))[1].tobytes()
        exact = _exact(detector, blob)
        got = decoder.detect(blob)
        assert got is not None and _same(got, exact)
        assert len(exact) >= 16  # (most dots seen: 64 at quality 100)
        decoded = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_COLOR)
        mask = hsv.mask(cv2.cvtColor(decoded, cv2.COLOR_BGR2HSV)) > 0
        kept, n = _screened(decoder, blob)
        assert n < 0.5 * 32 * 16  # most blocks screened out
        assert not (mask & ~kept).any()  # no pixel in range outside a kept block
        drawn = _drawn(decoder, blob)
        assert not (mask & ~drawn).any()  # nor outside a block drawn (its exact values)
        assert not (drawn & ~kept).any()


@pytest.mark.parametrize("hsv", RANGES, ids=["orange", "blue", "red", "green", "white"])
def test_blocks_drawn_hold_every_pixel_in_range(frames, hsv):
    """Of the blocks that pass the bound, only those whose exact Y, Cb, Cr values' box
    holds a colour of the range are converted and drawn: every pixel in the range is in one
    (the decoded frame's mask); for the ball's orange, most blocks that pass the bound are
    not drawn."""
    decoder = J.ScreenedDecoder(BallDetector(hsv, 5, compiled=True))
    passed = drawn_total = 0
    for blob in frames[::9]:
        decoded = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_COLOR)
        mask = hsv.mask(cv2.cvtColor(decoded, cv2.COLOR_BGR2HSV)) > 0
        kept, _n = _screened(decoder, blob)
        drawn = _drawn(decoder, blob)
        assert not (mask & ~drawn).any() and not (drawn & ~kept).any()
        passed += kept.sum()
        drawn_total += drawn.sum()
    if hsv == RANGES[0]:  # the ball's orange: the lines' blocks pass the bound, not this
        assert 0 < drawn_total < 0.5 * passed


def _drawn(decoder: J.ScreenedDecoder, blob: bytes) -> np.ndarray:
    """(H, W) bool: the pixels of the blocks ``render_blocks`` draws of those that pass the
    bound."""
    data = np.frombuffer(blob, np.uint8)
    h = J._Header(data)
    nbx, nby = -(-h.width // 8), -(-h.height // 8)
    state = np.zeros((nbx * nby, 8), np.int64)
    coefs = np.zeros((nbx * nby, 3, 64), np.int16)
    n = J.screen_blocks(data, h.start, nbx, nby, h.restart, h.dc, h.ac, h.fast, h.maxcode,
                        h.offset, h.symbols, h.weights, h.quant, decoder.table, state, False,
                        coefs)
    J.screen_blocks(data, h.start, nbx, n, h.restart, h.dc, h.ac, h.fast, h.maxcode, h.offset,
                    h.symbols, h.weights, h.quant, decoder.table, state, True, coefs)
    frame = np.zeros((h.height, h.width, 3), np.uint8)
    xy, bgr = np.zeros((64 * n, 2), np.int32), np.zeros((64 * n, 3), np.uint8)
    drawn = np.zeros(n, np.uint8)
    J.render_blocks(coefs, state, n, nbx, h.quant, J._idct_limit(), J._colour_tables(),
                    decoder.table, frame, 2, decoder.lo, decoder.hi, xy, bgr, drawn)
    kept = np.zeros(nbx * nby, bool)
    kept[state[:n, 0][drawn > 0]] = True
    return kept.reshape(nby, nbx).repeat(8, 0).repeat(8, 1)[:h.height, :h.width]


def _screened(decoder: J.ScreenedDecoder, blob: bytes) -> tuple[np.ndarray, int]:
    data = np.frombuffer(blob, np.uint8)
    h = J._Header(data)
    nbx, nby = -(-h.width // 8), -(-h.height // 8)
    state = np.zeros((nbx * nby, 8), np.int64)
    n = J.screen_blocks(data, h.start, nbx, nby, h.restart, h.dc, h.ac, h.fast, h.maxcode,
                        h.offset, h.symbols, h.weights, h.quant, decoder.table, state, False,
                        np.zeros((1, 3, 64), np.int16))
    kept = np.zeros(nbx * nby, bool)
    kept[state[:n, 0]] = True
    return kept.reshape(nby, nbx).repeat(8, 0).repeat(8, 1)[:h.height, :h.width], n


def _dc_symbol_16(blob: bytes) -> bytes:
    """``blob`` whose first DC Huffman table's last symbol (its longest code's, which the
    frame's few large DC differences use, if any) is 16: a table libjpeg refuses (a DC
    symbol is a difference's bit count, 0..15)."""
    b = bytearray(blob)
    at = b.index(b"\xff\xc4") + 4
    while b[at] >> 4:  # (an AC table first: the next one)
        at += 17 + sum(b[at + 1:at + 17])
    b[at + 17 + sum(b[at + 1:at + 17]) - 1] = 16
    return bytes(b)


def test_other_jpegs_go_to_opencv(frames):
    # 4:2:0, progressive, an EXIF orientation, a truncated file, a DC table with a symbol
    # beyond 15: None (the frame is then decoded by cv2.imdecode), and the re-detection stays
    # exact
    frame = cv2.imdecode(np.frombuffer(frames[10], np.uint8), cv2.IMREAD_COLOR)
    detector = BallDetector(HsvRange(), 5, compiled=True)
    decoder = J.ScreenedDecoder(detector)
    exif = bytearray(frames[10])
    exif[2:2] = b"\xff\xe1\x00\x08Exif\x00\x00"
    others = [cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes(),
              cv2.imencode(".jpg", frame, [*jpeg_params(90), cv2.IMWRITE_JPEG_PROGRESSIVE, 1])[
                  1].tobytes(), bytes(exif), frames[10][:len(frames[10]) // 2],
              _dc_symbol_16(frames[10])]
    redetector = redetect._Redetector(HsvRange(), 5, True)
    for blob in others:
        assert decoder.detect(blob) is None
        decoded = cv2.imdecode(np.frombuffer(blob, np.uint8), cv2.IMREAD_COLOR)
        found = redetector(blob)
        if decoded is None:  # (OpenCV refuses the truncated file: not re-detected, the
            assert found is None  # frame keeps its old candidates)
            continue
        assert found is not None
        uv, _radius, score = found
        exact = detector.detect(decoded)
        assert_array_equal(uv, exact.uv)
        assert_array_equal(score, exact.score)
    assert decoder.detect(frames[10]) is not None


def test_redetect_command_gives_the_exact_session(tmp_path, monkeypatch):
    # through the command: the screened decoder (compiled, one process) against today's
    # exact path (OpenCV's decoder and screen): the same candidates to the last bit
    exact, screened = tmp_path / "exact.mcap", tmp_path / "screened.mcap"
    assert main(["redetect", str(SAMPLE), "-o", str(exact), "--workers", "1"]) == 0
    monkeypatch.setattr(redetect, "_COMPILED_FROM", 0)
    calls = []
    original = J.ScreenedDecoder.detect
    monkeypatch.setattr(J.ScreenedDecoder, "detect",
                        lambda self, blob: calls.append(1) or original(self, blob))
    assert main(["redetect", str(SAMPLE), "-o", str(screened), "--workers", "1"]) == 0
    assert len(calls) == 135
    a, b = read_session(exact).detections, read_session(screened).detections
    for name in ("cand_frame", "cand_uv", "cand_radius", "cand_score", "frame_time_ns"):
        assert_array_equal(getattr(a, name), getattr(b, name))


def test_a_writable_blob_uses_the_kernels_one_signature(frames):
    """A frame's bytes in a writable buffer (an uncompressed chunk's bytearray) are decoded
    through the same compiled signature as bytes (the one pslog.warm compiles): no compile
    in a user's command."""
    detector = BallDetector(HsvRange(), 5, compiled=True)
    decoder = J.ScreenedDecoder(detector)
    got = decoder.detect(frames[0])
    again = decoder.detect(bytearray(frames[0]))
    assert got is not None and again is not None and _same(got, again)
    assert len(J.screen_blocks.signatures) == 1
