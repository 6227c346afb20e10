"""Exact ball detection in a JPEG frame without decoding every pixel (``pslog redetect``).

A stored frame (baseline JPEG, 4:4:4, as ``pslog record`` writes them) is decoded in two
compiled passes instead of by :func:`cv2.imdecode`:

1. **entropy decoding and a colour screen** (:func:`screen_blocks`): every 8 x 8 block's
   coefficients are Huffman-decoded (the part of a decode no reduced-size decode avoids) but
   not transformed. Each pixel of a block is ``dc q_0 / 8 + 128 + sum_k c_k q_k b_k(x, y)``
   (``q_k`` the quantisation step, ``b_k`` the IDCT's basis function), so by the triangle
   inequality every pixel of each component (Y, Cb, Cr) lies within ``dc q_0 / 8 + 128 +/-
   sum_k |c_k| q_k max |b_k|``, widened by 2 levels and 2^-10 of it for libjpeg's integer
   IDCT (which differs from the real one by at most one level; its constants are rounded to
   13 bits). A table made once per colour range (:func:`_ycc_table`: every one of the 2^24
   Y, Cb, Cr values converted to BGR as libjpeg does, then to HSV and thresholded as
   :class:`~recorders.detect.BallDetector` does, in cells of 4 x 4 x 4 levels, summed into a
   3-D prefix table) says in 8 look-ups whether any colour of the block's Y x Cb x Cr box is
   in the range. A block none of whose possible colours is in the range holds no pixel of
   the detector's mask. On the recorded sessions 2 % of the blocks of a frame pass;
2. **the blocks that pass** are decoded again from the bit position the first pass noted
   (:func:`screen_blocks` with ``store``), inverse-transformed by libjpeg's default integer
   IDCT (``jidctint.c``: the same integer arithmetic, hence the same pixels; libjpeg-turbo's
   SIMD versions are bit-exact with it) and screened again by the same table on the box of
   their exact Y, Cb, Cr values (:func:`render_blocks`): the bound is loose where a block
   holds an edge (the white lines of a green field: 340 blocks of a 1280 x 720 frame pass
   the bound, 15 this); only those are converted to BGR with libjpeg's tables
   (``jdcolor.c``) into a frame whose other pixels hold a colour outside the range, and
   their coarse pixels inside the detector's BGR box gathered.

The detector then runs on that frame from those coarse pixels
(:meth:`~recorders.detect.BallDetector.detect_screened`). Its candidates depend on the
frame only through the mask of pixels in the HSV range, which is the decoded frame's
everywhere: the same pixels in the blocks that pass, no pixel in range in the others (in
either frame). So the candidates are those of ``cv2.imdecode``'s frame, to the last bit
(tests compare them frame by frame).

Anything else goes to ``cv2.imdecode`` (:class:`ScreenedDecoder` returns None): progressive
or arithmetic-coded files, other subsampling or precision, an Adobe or EXIF marker (colour
transform, orientation), restart markers out of order, corrupt or truncated entropy data,
coefficients beyond what 8-bit samples produce (libjpeg-turbo's SIMD IDCT works in 16 bits).
"""

from __future__ import annotations

import functools

import numpy as np

from pslog._jit import kernel

from .detect import Candidates

_FAST_BITS = 11  # Huffman look-ahead bits (a table of 2048 int32 per Huffman table)
#: zigzag index -> natural index (row-major 8 x 8), with 16 guard entries as libjpeg has
_ZIGZAG = np.array([0, 1, 8, 16, 9, 2, 3, 10, 17, 24, 32, 25, 18, 11, 4, 5, 12, 19, 26, 33,
                    40, 48, 41, 34, 27, 20, 13, 6, 7, 14, 21, 28, 35, 42, 49, 56, 57, 50, 43,
                    36, 29, 22, 15, 23, 30, 37, 44, 51, 58, 59, 52, 45, 38, 31, 39, 46, 53,
                    60, 61, 54, 47, 55, 62, 63] + [63] * 16, dtype=np.int64)
_CELL = 4  # Y, Cb, Cr levels per cell of the colour table
#: the largest |DC q_0| and bound sum_k |c_k| q_k max |b_k| of a block decoded here (8-bit
#: samples give a few thousand at most): beyond, the frame goes to cv2.imdecode. Every
#: max |b_k| >= 1/8, so each |c_k q_k| < 8 x 4000 < 2^15: libjpeg-turbo's SIMD IDCT, which
#: multiplies in 16 bits, gives the C code's pixels for every block decoded here
_MAX_COEF = 4000
_MARGIN_LEVELS = 2.0  # added to each bound: libjpeg's integer IDCT against the real one
_MARGIN_RELATIVE = 1.0 / 1024


def _basis_peaks() -> np.ndarray:
    """(64,) float64: max over the block's pixels of |b_k| for each coefficient k in zigzag
    order, b_uv(x, y) = C(u) C(v) / 4 cos((2x + 1) u pi / 16) cos((2y + 1) v pi / 16)."""
    c = np.array([1 / np.sqrt(2)] + [1.0] * 7)
    i = np.arange(8)
    peak = np.abs(np.cos((2 * i[:, None] + 1) * i[None, :] * np.pi / 16)).max(axis=0) * c / 2
    return np.outer(peak, peak).reshape(64)[_ZIGZAG[:64]]


def _colour_tables() -> np.ndarray:
    """(4, 256) int32: libjpeg's ``build_ycc_rgb_table`` (``jdcolor.c``): Cr->R, Cb->B,
    Cr->G, Cb->G (the last two scaled by 2^16, Cb->G holding the rounding half)."""
    fix = lambda x: int(x * (1 << 16) + 0.5)  # noqa: E731
    x = np.arange(256, dtype=np.int64) - 128
    return np.stack([(fix(1.40200) * x + (1 << 15)) >> 16, (fix(1.77200) * x + (1 << 15)) >> 16,
                     -fix(0.71414) * x, -fix(0.34414) * x + (1 << 15)]).astype(np.int32)


def _idct_limit() -> np.ndarray:
    """(1024,) uint8: libjpeg's post-IDCT range limit, indexed by ``x & 1023`` (``x`` the
    descaled output around 0): ``x + 128`` clamped to 0..255 for ``-512 <= x < 512``."""
    x = np.arange(1024)
    return np.clip(np.where(x < 512, x, x - 1024) + 128, 0, 255).astype(np.uint8)


@kernel(inline=True)
def _blue(y: int, cb: int, tables: np.ndarray) -> int:
    """B of Y, Cb as libjpeg converts it (``jdcolor.c``; ``tables`` :func:`_colour_tables`)."""
    return min(max(y + tables[1, cb], 0), 255)


@kernel(inline=True)
def _green(y: int, cb: int, cr: int, tables: np.ndarray) -> int:
    """G of Y, Cb, Cr as libjpeg converts it."""
    return min(max(y + ((np.int64(tables[3, cb]) + tables[2, cr]) >> 16), 0), 255)


@kernel(inline=True)
def _red(y: int, cr: int, tables: np.ndarray) -> int:
    """R of Y, Cr as libjpeg converts it."""
    return min(max(y + tables[0, cr], 0), 255)


@functools.lru_cache(maxsize=8)
def _ycc_table(hsv) -> np.ndarray:
    """(65, 65, 65) int32 prefix sums over cells of 4 x 4 x 4 Y, Cb, Cr levels: a cell
    counts 1 if any of its colours, converted to BGR as libjpeg does, is in ``hsv`` (a
    :class:`~recorders.detect.HsvRange`, thresholded as the detector does: all 2^24 BGR
    colours converted once by OpenCV). About 0.1 s, once per range (made before the
    workers are forked)."""
    import cv2

    from .detect import _bgr_box

    lo, hi = _bgr_box(hsv)
    n = 256 // _CELL
    table = np.zeros((n + 1, n + 1, n + 1), np.int32)
    if lo is None or hi is None:
        return table
    # every colour of the BGR box of the range (the others are outside it), 16 blue levels
    # at a time
    inside = np.zeros((256, 256, 256), dtype=bool)  # [b, g, r]
    gr = np.empty((16, 256, 256, 3), dtype=np.uint8)
    gr[..., 1] = np.arange(256, dtype=np.uint8)[None, :, None]
    gr[..., 2] = np.arange(256, dtype=np.uint8)[None, None, :]
    for b0 in range(lo[0] - lo[0] % 16, hi[0] + 1, 16):
        gr[..., 0] = np.arange(b0, b0 + 16, dtype=np.uint8)[:, None, None]
        inside[b0:b0 + 16] = (hsv.mask(cv2.cvtColor(gr.reshape(16 * 256, 256, 3),
                                                     cv2.COLOR_BGR2HSV)) > 0).reshape(16, 256, 256)
    n = 256 // _CELL
    cells = np.zeros((n, n, n), dtype=np.bool_)
    _ycc_cells(inside, _colour_tables(), np.array(lo, np.int64), np.array(hi, np.int64), cells)
    table[1:, 1:, 1:] = cells.cumsum(0).cumsum(1).cumsum(2)
    return table


@kernel
def _ycc_cells(inside: np.ndarray, tables: np.ndarray, lo: np.ndarray, hi: np.ndarray,
               cells: np.ndarray) -> None:
    """``cells`` (64, 64, 64) bool out: any Y, Cb, Cr of the cell whose BGR (libjpeg's
    conversion, ``tables`` :func:`_colour_tables`) is ``inside`` (256, 256, 256) bool
    [b, g, r], which is False outside the BGR box ``[lo, hi]`` ((3,) each)."""
    for y in range(256):
        for cb in range(256):
            b = _blue(y, cb, tables)
            if b < lo[0] or b > hi[0]:
                continue
            for cr in range(256):
                r = _red(y, cr, tables)
                if r < lo[2] or r > hi[2]:
                    continue
                g = _green(y, cb, cr, tables)
                if g >= lo[1] and g <= hi[1] and inside[b, g, r]:
                    cells[y // _CELL, cb // _CELL, cr // _CELL] = True


def _huffman(counts: bytes, values: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                    np.ndarray] | None:
    """Tables of one Huffman table (``counts``: codes of each length 1..16, ``values``):
    ``fast`` (2^11,) int32 indexed by the next 11 bits -- ``value << 16 | symbol << 8 |
    whole << 7 | bits``: a code of at most 11 bits, its symbol, and, where the code and
    the value's extra bits fit in 11 bits (``whole``), the value (sign-extended) and all the
    bits they take, else the code's length; 0 for longer codes -- and ``maxcode`` (18,),
    ``offset`` (17,), ``symbols`` (256,) for those (libjpeg's ``jpeg_huff_decode``). None
    for an invalid table."""
    fast = np.zeros(1 << _FAST_BITS, np.int32)
    maxcode = np.full(18, -1, np.int64)
    maxcode[17] = 1 << 40  # longer than 16 bits: stops the slow search (then refused)
    offset = np.zeros(17, np.int64)
    symbols = np.zeros(256, np.uint8)
    if sum(counts) > 256 or len(values) < sum(counts):
        return None
    symbols[:sum(counts)] = np.frombuffer(values[:sum(counts)], np.uint8)
    code = k = 0
    for length in range(1, 17):
        offset[length] = k - code
        for _ in range(counts[length - 1]):
            if length <= _FAST_BITS:
                rs, shift = values[k], _FAST_BITS - length
                s = rs & 15
                for low in range(1 << shift):
                    i = (code << shift) | low
                    if s and length + s <= _FAST_BITS:
                        v = (i >> (_FAST_BITS - length - s)) & ((1 << s) - 1)
                        if v < 1 << (s - 1):
                            v += (-1 << s) + 1
                        fast[i] = (v << 16) | (rs << 8) | 128 | (length + s)
                    else:
                        fast[i] = (rs << 8) | length
            code += 1
            k += 1
        if code > 1 << length:
            return None  # more codes than the length allows
        maxcode[length] = code - 1 if counts[length - 1] else -1
        code <<= 1
    return fast, maxcode, offset, symbols


class _Header:
    """What the decoding needs from a frame's header (markers up to the scan's start);
    ``ok`` False where the frame is for ``cv2.imdecode``."""

    def __init__(self, blob: bytes | memoryview | np.ndarray) -> None:
        self.ok = False
        try:
            self._parse(bytes(blob[:65536]))
        except (IndexError, ValueError, KeyError):
            self.ok = False

    def _parse(self, d: bytes) -> None:
        if d[:2] != b"\xff\xd8":
            return
        quant: dict[int, np.ndarray] = {}
        huff: dict[tuple[int, int], tuple] = {}
        frame = None
        restart, jfif, i = 0, False, 2
        while i + 4 <= len(d):
            if d[i] != 0xFF:
                return
            marker = d[i + 1]
            if marker == 0xFF:  # fill byte
                i += 1
                continue
            length = int.from_bytes(d[i + 2:i + 4], "big")
            seg = d[i + 4:i + 2 + length]
            if len(seg) != length - 2:
                return
            if marker == 0xDB:  # quantisation tables (8-bit only)
                j = 0
                while j < len(seg):
                    if seg[j] >> 4 or len(seg) < j + 65:
                        return
                    quant[seg[j] & 15] = np.frombuffer(seg[j + 1:j + 65], np.uint8).astype(
                        np.int64)
                    j += 65
            elif marker == 0xC4:  # Huffman tables
                j = 0
                while j < len(seg):
                    counts = seg[j + 1:j + 17]
                    values = seg[j + 17:j + 17 + sum(counts)]
                    table = _huffman(counts, values)
                    if len(counts) != 16 or table is None or seg[j] >> 4 > 1:
                        return
                    if seg[j] >> 4 == 0 and max(values, default=0) > 15:
                        return  # a DC symbol beyond 15: libjpeg refuses the table
                    huff[(seg[j] >> 4, seg[j] & 15)] = table
                    j += 17 + sum(counts)
            elif marker in (0xC0, 0xC1):  # baseline / extended sequential, Huffman
                if seg[0] != 8 or seg[5] != 3:
                    return
                frame = (int.from_bytes(seg[1:3], "big"), int.from_bytes(seg[3:5], "big"),
                         [tuple(seg[6 + 3 * k:9 + 3 * k]) for k in range(3)])
            elif marker == 0xDD:
                restart = int.from_bytes(seg[0:2], "big")
            elif marker == 0xE0 and seg[:5] == b"JFIF\x00":
                jfif = True
            elif marker in (0xE1, 0xEE) or 0xC2 <= marker <= 0xCF or marker in (0xD8, 0xD9):
                return  # EXIF (orientation), Adobe (colour transform), other processes
            elif marker == 0xDA:
                self._scan(seg, frame, quant, huff, restart, jfif, i + 2 + length)
                return
            i += 2 + length

    def _scan(self, seg: bytes, frame, quant: dict, huff: dict, restart: int, jfif: bool,
              start: int) -> None:
        if frame is None or seg[0] != 3:
            return
        height, width, comps = frame
        ids = [c[0] for c in comps]
        if height == 0 or width == 0 or any(c[1] != 0x11 for c in comps):
            return  # a DNL height, or chroma subsampled
        if not jfif and ids != [1, 2, 3]:
            return  # libjpeg might take the components as RGB
        order = [ids.index(seg[1 + 2 * k]) for k in range(3)]
        if order != [0, 1, 2] or tuple(seg[7:10]) != (0, 63, 0):
            return  # components out of order, or not the whole spectrum in one scan
        keys = sorted(huff)
        at = {key: n for n, key in enumerate(keys)}
        self.dc = np.array([at[(0, seg[2 + 2 * k] >> 4)] for k in range(3)], np.int64)
        self.ac = np.array([at[(1, seg[2 + 2 * k] & 15)] for k in range(3)], np.int64)
        self.fast = np.stack([huff[key][0] for key in keys])
        self.maxcode = np.stack([huff[key][1] for key in keys])
        self.offset = np.stack([huff[key][2] for key in keys])
        self.symbols = np.stack([huff[key][3] for key in keys])
        q = np.stack([quant[c[2]] for c in comps])  # (3, 64) zigzag order
        self.weights = q * _basis_peaks()[None]  # (3, 64): q_k max |b_k|
        self.quant = np.zeros((3, 64), np.int64)
        self.quant[:, _ZIGZAG[:64]] = q  # natural order, for the IDCT
        self.height, self.width, self.restart, self.start = height, width, restart, start
        self.ok = True


@kernel(inline=True)
def _refill(data: np.ndarray, pos: int, buf: np.uint64, nbits: int, fed: int
            ) -> tuple[int, np.uint64, int, int]:
    """Top the bit buffer ``buf`` (``nbits`` valid bits from its top) up to more than 56
    bits from ``data[pos:]``: four bytes at once where none is 0xFF, else byte by byte
    (0xFF 0x00 is a 0xFF byte; at a marker or the end, zero bytes are fed, counted in
    ``fed``, and ``pos`` stays). Returns (pos, buf, nbits, fed). :func:`screen_blocks` takes
    the four bytes itself where it can and calls this for the rest (inlined, the helper's
    reference to ``data`` was counted at every refill: the screen 2.5 % slower)."""
    end = data.shape[0]
    if pos + 4 <= end:
        b0, b1 = np.uint64(data[pos]), np.uint64(data[pos + 1])
        b2, b3 = np.uint64(data[pos + 2]), np.uint64(data[pos + 3])
        if b0 != 255 and b1 != 255 and b2 != 255 and b3 != 255:
            word = (b0 << np.uint64(24)) | (b1 << np.uint64(16)) | (b2 << np.uint64(8)) | b3
            return pos + 4, buf | (word << np.uint64(32 - nbits)), nbits + 32, fed
    while nbits <= 56:
        b = 0
        if pos < end:
            b = int(data[pos])
            if b == 0xFF:
                if pos + 1 < end and data[pos + 1] == 0:
                    pos += 2
                else:
                    b = 0
                    fed += 1
            else:
                pos += 1
        else:
            fed += 1
        buf |= np.uint64(b) << np.uint64(56 - nbits)
        nbits += 8
    return pos, buf, nbits, fed


@kernel(inline=True)
def _slow_code(buf: np.uint64, t: int, maxcode: np.ndarray, offset: np.ndarray,
               symbols: np.ndarray) -> tuple[int, int]:
    """(symbol, code length) of a code longer than the fast table's bits; (-1, 0) for no
    valid code."""
    length = _FAST_BITS + 1
    code = np.int64(buf >> np.uint64(64 - length))
    while code > maxcode[t, length]:
        length += 1
        code = np.int64(buf >> np.uint64(64 - length))
    if length > 16:
        return -1, 0
    return int(symbols[t, code + offset[t, length]]), length


@kernel(inline=True)
def _code(e: int, buf: np.uint64, t: int, maxcode: np.ndarray, offset: np.ndarray,
          symbols: np.ndarray) -> tuple[int, int]:
    """(symbol, code length) of the next code: from its fast-table entry ``e`` (a code of at
    most 11 bits, not taken whole with its value), else by :func:`_slow_code`; (-1, 0) for
    no valid code. (A DC table's symbols are 0..15: its header refuses others.)"""
    if e:
        return np.int64((e >> 8) & 255), np.int64(e & 31)
    return _slow_code(buf, t, maxcode, offset, symbols)


@kernel(inline=True)
def _extended(buf: np.uint64, s: int) -> tuple[int, np.uint64]:
    """(value, the bits after it): the next ``s`` bits of ``buf`` (at its top) as a signed
    value, libjpeg's ``HUFF_EXTEND``."""
    v = np.int64(buf >> np.uint64(64 - s))
    if v < (1 << (s - 1)):
        v += (-1 << s) + 1
    return v, buf << np.uint64(s)


@kernel(inline=True)
def _any_inside(colours: np.ndarray, lo0: int, hi0: int, lo1: int, hi1: int, lo2: int,
                hi2: int) -> bool:
    """Whether a cell of ``[lo0, hi0) x [lo1, hi1) x [lo2, hi2)`` (Y, Cb, Cr cells) of the
    colour table holds a colour in the range (``colours`` its prefix sums, :func:`_ycc_table`)."""
    return (colours[hi0, hi1, hi2] - colours[lo0, hi1, hi2] - colours[hi0, lo1, hi2]
            - colours[hi0, hi1, lo2] + colours[lo0, lo1, hi2] + colours[lo0, hi1, lo2]
            + colours[hi0, lo1, lo2] - colours[lo0, lo1, lo2]) > 0


@kernel
def screen_blocks(data: np.ndarray, start: int, nbx: int, nby: int, restart: int,
                  dc_table: np.ndarray, ac_table: np.ndarray, fast: np.ndarray,
                  maxcode: np.ndarray, offset: np.ndarray, symbols: np.ndarray,
                  weights: np.ndarray, quant: np.ndarray, colours: np.ndarray,
                  state: np.ndarray, store: bool, coefs: np.ndarray) -> int:
    """Entropy-decode a baseline 4:4:4 scan (3 components, one block each per MCU).

    Parameters
    ----------
    data : (n,) uint8, the JPEG file
    start : offset of the entropy-coded data (after the SOS segment)
    nbx, nby : MCUs per row, rows of MCUs; with ``store``, ``nby`` is the number of
        MCUs listed in ``state`` to decode
    restart : restart interval in MCUs (0: none)
    dc_table, ac_table : (3,) int64, each component's Huffman table (index into the next)
    fast, maxcode, offset, symbols : the Huffman tables stacked, see :func:`_huffman`
    weights : (3, 64) float64, zigzag order: q_k max |b_k| per component
    quant : (3, 64) int64, natural order: quantisation steps (DC at 0)
    colours : (65, 65, 65) int32, :func:`_ycc_table`
    state : (m, 8) int64; screening (``store`` False): out, one row per MCU that passes
        the screen: MCU index, byte position, bit buffer, valid bits, zero bytes fed, the
        three DC predictors, as they were at the MCU's start; decoding: in
    store : False: screen every MCU; True: decode the listed MCUs into ``coefs``
    coefs : (m, 3, 64) int16, out with ``store``: natural order, DC not yet dequantised

    Returns
    -------
    n : screening: how many MCUs pass (rows of ``state``); decoding: 0; < 0: the frame
        is for ``cv2.imdecode`` (-1 invalid code, -2 data ran out, -3 restart marker
        missing, -4 coefficient index beyond 63, -5 a coefficient too large, -6 after the
        scan comes no EOI)
    """
    end = data.shape[0]
    pred = np.zeros(3, np.int64)
    amp = np.zeros(3)
    shift = np.uint64(64 - _FAST_BITS)
    n_out = 0
    todo = nby if store else nbx * nby
    pos = start
    buf = np.uint64(0)
    nbits = 0
    fed = 0
    rst = 0
    s_pos = s_nbits = s_fed = s_p0 = s_p1 = s_p2 = 0
    s_buf = np.uint64(0)
    for it in range(todo):
        if store:
            mcu = state[it, 0]
            pos = state[it, 1]
            buf = np.uint64(state[it, 2])
            nbits = state[it, 3]
            fed = state[it, 4]
            pred[0] = state[it, 5]
            pred[1] = state[it, 6]
            pred[2] = state[it, 7]
            coefs[it] = 0
        else:
            mcu = it
            if restart and mcu and mcu % restart == 0:
                if nbits < 8 * fed:
                    return -2
                if pos + 1 >= end or data[pos] != 0xFF or data[pos + 1] != 0xD0 + (rst & 7):
                    return -3
                pos += 2
                rst += 1
                buf = np.uint64(0)
                nbits = 0
                fed = 0
                pred[:] = 0
            s_pos, s_buf, s_nbits, s_fed = pos, buf, nbits, fed
            s_p0, s_p1, s_p2 = pred[0], pred[1], pred[2]
        for c in range(3):
            if nbits < 32:
                if (pos + 4 <= end and data[pos] != 255 and data[pos + 1] != 255
                        and data[pos + 2] != 255 and data[pos + 3] != 255):
                    # (_refill's four bytes at once, here: inlined, its reference to
                    # ``data`` was kept across its branches at every refill)
                    buf |= ((np.uint64(data[pos]) << np.uint64(24))
                            | (np.uint64(data[pos + 1]) << np.uint64(16))
                            | (np.uint64(data[pos + 2]) << np.uint64(8))
                            | np.uint64(data[pos + 3])) << np.uint64(32 - nbits)
                    nbits += 32
                    pos += 4
                else:
                    pos, buf, nbits, fed = _refill(data, pos, buf, nbits, fed)
            t = dc_table[c]
            e = fast[t, buf >> shift]
            if e & 128:
                length = e & 31
                buf <<= np.uint64(length)
                nbits -= length
                pred[c] += e >> 16
            else:
                s, length = _code(e, buf, t, maxcode, offset, symbols)
                if length == 0:
                    return -1
                buf <<= np.uint64(length)
                nbits -= length
                if s:
                    diff, buf = _extended(buf, s)
                    nbits -= s
                    pred[c] += diff
            if store:
                coefs[it, c, 0] = pred[c]
            a = 0.0
            k = 1
            t = ac_table[c]
            while k < 64:
                if nbits < 32:
                    if (pos + 4 <= end and data[pos] != 255 and data[pos + 1] != 255
                            and data[pos + 2] != 255 and data[pos + 3] != 255):
                        # (_refill's four bytes at once, here: inlined, its reference to
                        # ``data`` was kept across its branches at every refill)
                        buf |= ((np.uint64(data[pos]) << np.uint64(24))
                                | (np.uint64(data[pos + 1]) << np.uint64(16))
                                | (np.uint64(data[pos + 2]) << np.uint64(8))
                                | np.uint64(data[pos + 3])) << np.uint64(32 - nbits)
                        nbits += 32
                        pos += 4
                    else:
                        pos, buf, nbits, fed = _refill(data, pos, buf, nbits, fed)
                e = fast[t, buf >> shift]
                if e & 128:  # code and value in the look-ahead: one step
                    length = e & 31
                    buf <<= np.uint64(length)
                    nbits -= length
                    k += (e >> 12) & 15
                    v = np.int64(e >> 16)
                else:
                    rs, length = _code(e, buf, t, maxcode, offset, symbols)
                    if length == 0:
                        return -1
                    buf <<= np.uint64(length)
                    nbits -= length
                    r = rs >> 4
                    s = rs & 15
                    if s == 0:
                        if r != 15:
                            break  # end of block
                        k += 16
                        continue
                    k += r
                    v, buf = _extended(buf, s)
                    nbits -= s
                if k > 63:
                    return -4
                if store:
                    coefs[it, c, _ZIGZAG[k]] = v
                else:
                    a += abs(v) * weights[c, k]
                k += 1
            amp[c] = a
        if store:
            continue
        # the screen: each component's range of values, in cells of the colour table
        lo0 = lo1 = lo2 = hi0 = hi1 = hi2 = 0
        for c in range(3):
            dc = pred[c] * quant[c, 0]
            if abs(dc) > _MAX_COEF or amp[c] > _MAX_COEF:
                return -5
            centre = dc * 0.125 + 128.0
            margin = amp[c] * (1.0 + _MARGIN_RELATIVE) + _MARGIN_LEVELS
            lo = max(0, min(255, int(np.floor(centre - margin)))) // _CELL
            hi = max(0, min(255, int(np.ceil(centre + margin)))) // _CELL + 1
            if c == 0:
                lo0, hi0 = lo, hi
            elif c == 1:
                lo1, hi1 = lo, hi
            else:
                lo2, hi2 = lo, hi
        if _any_inside(colours, lo0, hi0, lo1, hi1, lo2, hi2):
            state[n_out, 0] = mcu
            state[n_out, 1] = s_pos
            state[n_out, 2] = np.int64(s_buf)
            state[n_out, 3] = s_nbits
            state[n_out, 4] = s_fed
            state[n_out, 5] = s_p0
            state[n_out, 6] = s_p1
            state[n_out, 7] = s_p2
            n_out += 1
    if store:
        return 0
    if nbits < 8 * fed:
        return -2  # the codes ran into a marker or the end of the file
    while pos < end and data[pos] == 0xFF and pos + 1 < end and data[pos + 1] == 0xFF:
        pos += 1
    if pos + 1 >= end or data[pos] != 0xFF or data[pos + 1] != 0xD9:
        return -6
    return n_out


@kernel(inline=True)
def _descale(x: int, n: int) -> int:
    return (x + (1 << (n - 1))) >> n


@kernel(inline=True)
def _idct_1d(e0: int, e2: int, e4: int, e6: int, o1: int, o3: int, o5: int, o7: int):
    """One pass of libjpeg's ``jpeg_idct_islow`` over 8 values (even part ``e0``..``e6``,
    odd part ``o1``..``o7``, each already scaled as the pass takes it): the 8 outputs in
    order, before the pass's descaling (its even and odd parts, operation for operation)."""
    z1 = (e2 + e6) * 4433
    tmp2 = z1 + e6 * (-15137)
    tmp3 = z1 + e2 * 6270
    tmp0 = (e0 + e4) << 13
    tmp1 = (e0 - e4) << 13
    tmp10 = tmp0 + tmp3
    tmp13 = tmp0 - tmp3
    tmp11 = tmp1 + tmp2
    tmp12 = tmp1 - tmp2
    tmp0, tmp1, tmp2, tmp3 = o7, o5, o3, o1
    z1 = tmp0 + tmp3
    z2 = tmp1 + tmp2
    z3 = tmp0 + tmp2
    z4 = tmp1 + tmp3
    z5 = (z3 + z4) * 9633
    tmp0 = tmp0 * 2446
    tmp1 = tmp1 * 16819
    tmp2 = tmp2 * 25172
    tmp3 = tmp3 * 12299
    z1 = z1 * (-7373)
    z2 = z2 * (-20995)
    z3 = z3 * (-16069) + z5
    z4 = z4 * (-3196) + z5
    tmp0 += z1 + z3
    tmp1 += z2 + z4
    tmp2 += z2 + z3
    tmp3 += z1 + z4
    return (tmp10 + tmp3, tmp11 + tmp2, tmp12 + tmp1, tmp13 + tmp0,
            tmp13 - tmp0, tmp12 - tmp1, tmp11 - tmp2, tmp10 - tmp3)


@kernel(inline=True)
def _idct_islow(coef: np.ndarray, quant: np.ndarray, limit: np.ndarray, out: np.ndarray,
                ws: np.ndarray) -> None:
    """libjpeg's ``jpeg_idct_islow`` (``jidctint.c``, CONST_BITS 13, PASS1_BITS 2, its
    zero-column and zero-row short cuts): ``coef`` (64,) int16 natural order, ``quant``
    (64,) int64, ``limit`` :func:`_idct_limit`, ``out`` (64,) uint8 row-major, ``ws``
    (64,) int64 work space."""
    for col in range(8):
        if (coef[8 + col] == 0 and coef[16 + col] == 0 and coef[24 + col] == 0
                and coef[32 + col] == 0 and coef[40 + col] == 0 and coef[48 + col] == 0
                and coef[56 + col] == 0):
            dc = (np.int64(coef[col]) * quant[col]) << 2
            for r in range(8):
                ws[r * 8 + col] = dc
            continue
        y = _idct_1d(np.int64(coef[col]) * quant[col], np.int64(coef[16 + col]) * quant[16 + col],
                     np.int64(coef[32 + col]) * quant[32 + col],
                     np.int64(coef[48 + col]) * quant[48 + col],
                     np.int64(coef[8 + col]) * quant[8 + col],
                     np.int64(coef[24 + col]) * quant[24 + col],
                     np.int64(coef[40 + col]) * quant[40 + col],
                     np.int64(coef[56 + col]) * quant[56 + col])
        for r in range(8):
            ws[r * 8 + col] = _descale(y[r], 11)
    for row in range(8):
        w = row * 8
        if (ws[w + 1] == 0 and ws[w + 2] == 0 and ws[w + 3] == 0 and ws[w + 4] == 0
                and ws[w + 5] == 0 and ws[w + 6] == 0 and ws[w + 7] == 0):
            v = limit[_descale(ws[w], 5) & 1023]
            for j in range(8):
                out[w + j] = v
            continue
        y = _idct_1d(ws[w], ws[w + 2], ws[w + 4], ws[w + 6], ws[w + 1], ws[w + 3], ws[w + 5],
                     ws[w + 7])
        for j in range(8):
            out[w + j] = limit[_descale(y[j], 18) & 1023]


@kernel(inline=True)
def _value_range(values: np.ndarray, bh: int, bw: int) -> tuple[int, int]:
    """(least, largest) of a block's ``values`` (64,) uint8 row-major in its first ``bh``
    rows and ``bw`` columns (those in the frame)."""
    least, most = 255, 0
    for i in range(bh):
        for j in range(bw):
            v = np.int64(values[i * 8 + j])
            least, most = min(least, v), max(most, v)
    return least, most


@kernel
def render_blocks(coefs: np.ndarray, state: np.ndarray, n: int, nbx: int,
                  quant: np.ndarray, limit: np.ndarray, tables: np.ndarray,
                  colours: np.ndarray, frame: np.ndarray, step: int, lo: np.ndarray,
                  hi: np.ndarray, xy: np.ndarray, bgr: np.ndarray, drawn: np.ndarray) -> int:
    """Inverse-transform the first ``n`` MCUs of ``state`` (their coefficients ``coefs``
    (n, 3, 64)) as libjpeg does (``quant`` (3, 64) natural order, ``limit``
    :func:`_idct_limit`) and, where a colour of the box of their exact Y, Cb and Cr values
    is in the range (``colours`` :func:`_ycc_table`: the screen again, on the pixels' own
    values instead of their bound; most blocks that pass the bound, e.g. along the white
    lines of a green field, do not, most of them on their Cr alone), convert them to BGR
    (``tables`` :func:`_colour_tables`) into ``frame`` (H, W, 3) uint8, and gather their
    pixels ``frame[i step, j step]`` inside the BGR box ``[lo, hi]`` (i < H // step,
    j < W // step): ``xy`` (m, 2) int32 out, coarse column and row; ``bgr`` (m, 3) uint8
    out (m >= 64 n). ``drawn`` (n,) uint8 out: 1 where the MCU was written. Returns how
    many pixels were gathered. A block not written holds no pixel in the range: its pixels
    in ``frame`` keep their colour."""
    ws = np.zeros(64, np.int64)
    ycc = np.zeros((3, 64), np.uint8)
    h, w = frame.shape[0], frame.shape[1]
    rows, cols = h // step, w // step
    found = 0
    for it in range(n):
        y0 = (state[it, 0] // nbx) * 8
        x0 = (state[it, 0] % nbx) * 8
        bh, bw = min(8, h - y0), min(8, w - x0)
        # each component's cells, from its least to its largest value in the frame, Cr, Cb
        # then Y, each tested once transformed, the others' cells all taken (a box holding
        # the final one: none of its colours in the range, none of the block's): most blocks
        # that pass the bound fail on one component, and need no other transform
        lo0 = lo1 = lo2 = 0
        hi0 = hi1 = hi2 = 256 // _CELL
        drawn[it] = 1
        for c in (2, 1, 0):
            _idct_islow(coefs[it, c], quant[c], limit, ycc[c], ws)
            least, most = _value_range(ycc[c], bh, bw)
            if c == 2:
                lo2, hi2 = least // _CELL, most // _CELL + 1
            elif c == 1:
                lo1, hi1 = least // _CELL, most // _CELL + 1
            else:
                lo0, hi0 = least // _CELL, most // _CELL + 1
            if not _any_inside(colours, lo0, hi0, lo1, hi1, lo2, hi2):
                drawn[it] = 0
                break
        if not drawn[it]:
            continue
        for i in range(bh):
            yy = y0 + i
            coarse_row = yy % step == 0 and yy // step < rows
            for j in range(bw):
                xx = x0 + j
                y = np.int64(ycc[0, i * 8 + j])
                cb = ycc[1, i * 8 + j]
                cr = ycc[2, i * 8 + j]
                b = _blue(y, cb, tables)
                g = _green(y, cb, cr, tables)
                r = _red(y, cr, tables)
                frame[yy, xx, 0] = b
                frame[yy, xx, 1] = g
                frame[yy, xx, 2] = r
                if (coarse_row and xx % step == 0 and xx // step < cols
                        and lo[0] <= b <= hi[0] and lo[1] <= g <= hi[1]
                        and lo[2] <= r <= hi[2]):
                    xy[found, 0] = xx // step
                    xy[found, 1] = yy // step
                    bgr[found, 0] = b
                    bgr[found, 1] = g
                    bgr[found, 2] = r
                    found += 1
    return found


@kernel
def clear_blocks(frame: np.ndarray, state: np.ndarray, n: int, nbx: int,
                 fill: np.ndarray, drawn: np.ndarray) -> None:
    """Give the blocks of the first ``n`` MCUs of ``state`` that were ``drawn`` ((n,) uint8,
    :func:`render_blocks`) the colour ``fill`` (3,) uint8 again in ``frame`` (H, W, 3)
    uint8."""
    h, w = frame.shape[0], frame.shape[1]
    for it in range(n):
        if not drawn[it]:
            continue
        y0 = (state[it, 0] // nbx) * 8
        x0 = (state[it, 0] % nbx) * 8
        for yy in range(y0, min(y0 + 8, h)):
            for xx in range(x0, min(x0 + 8, w)):
                frame[yy, xx, 0] = fill[0]
                frame[yy, xx, 1] = fill[1]
                frame[yy, xx, 2] = fill[2]


class ScreenedDecoder:
    """Detects the ball in JPEG frames (bytes) with ``detector`` (a
    :class:`~recorders.detect.BallDetector` at full size) from the screened blocks only
    (see the module's text): :meth:`detect` gives the candidates of ``cv2.imdecode``'s
    frame, or None where the frame is for ``cv2.imdecode``. One per process (its buffers
    are reused from frame to frame)."""

    def __init__(self, detector) -> None:
        from .detect import _bgr_box, _nearest_is_stride

        self.detector = detector
        self.table = _ycc_table(detector.hsv)
        lo, hi = _bgr_box(detector.hsv)
        self.lo = np.array(lo if lo is not None else (255, 255, 255), np.uint8)
        self.hi = np.array(hi if hi is not None else (0, 0, 0), np.uint8)
        self.fill = _outside(detector.hsv)
        self.limit = _idct_limit()
        self.tables = _colour_tables()
        self._stride = _nearest_is_stride
        self._header: _Header | None = None
        self._head = b""
        self._buffers: dict[tuple[int, int], tuple] = {}

    def _header_of(self, data: np.ndarray) -> _Header:
        head = self._head
        if head and data.shape[0] > len(head) and data[:len(head)].tobytes() == head:
            return self._header  # type: ignore[return-value]
        header = _Header(data)
        self._header, self._head = header, (data[:header.start].tobytes() if header.ok
                                            else b"")
        return header

    def detect(self, blob) -> Candidates | None:
        """The detector's candidates in the frame ``blob`` (JPEG bytes), or None."""
        if self.fill is None:
            return None
        data = np.frombuffer(blob, dtype=np.uint8)
        # (read-only whatever the blob's buffer: the kernels' one compiled signature, which
        # pslog.warm compiles; an uncompressed chunk's bytes are a writable bytearray's)
        data.flags.writeable = False
        h = self._header_of(data)
        if not h.ok:
            return None
        nbx, nby = -(-h.width // 8), -(-h.height // 8)
        buffers = self._buffers.get((h.height, h.width))
        if buffers is None:
            frame = np.empty((h.height, h.width, 3), np.uint8)
            frame[:] = self.fill
            buffers = self._buffers[h.height, h.width] = (
                frame, np.zeros((nbx * nby, 8), np.int64), np.zeros((nbx * nby, 3, 64), np.int16))
        frame, state, coefs = buffers
        n = screen_blocks(data, h.start, nbx, nby, h.restart, h.dc, h.ac, h.fast, h.maxcode,
                          h.offset, h.symbols, h.weights, h.quant, self.table, state, False,
                          coefs)
        if n < 0:
            return None
        if n:
            screen_blocks(data, h.start, nbx, n, h.restart, h.dc, h.ac, h.fast, h.maxcode,
                          h.offset, h.symbols, h.weights, h.quant, self.table, state, True,
                          coefs)
        s = self.detector.downscale
        xy = np.empty((64 * n, 2), np.int32)
        bgr = np.empty((64 * n, 3), np.uint8)
        drawn = np.zeros(n, np.uint8)
        try:
            found = render_blocks(coefs, state, n, nbx, h.quant, self.limit, self.tables,
                                  self.table, frame, s, self.lo, self.hi, xy, bgr, drawn)
            if self._stride(h.height, h.width, s):
                return self.detector.detect_screened(frame, xy[:found], bgr[:found])
            return self.detector.detect(frame)
        finally:
            clear_blocks(frame, state, n, nbx, self.fill, drawn)


def _outside(hsv) -> np.ndarray | None:
    """(3,) uint8 a BGR colour outside ``hsv`` (None if every colour is inside)."""
    import cv2

    grid = np.stack(np.meshgrid(*[np.arange(0, 256, 51)] * 3, indexing="ij"), -1).reshape(
        1, -1, 3).astype(np.uint8)
    inside = hsv.mask(cv2.cvtColor(grid, cv2.COLOR_BGR2HSV))[0] > 0
    if inside.all():
        return None
    return grid[0, int(np.argmin(inside))].copy()
