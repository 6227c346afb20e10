"""The filter's length columns (``innovation_px``, ``residual_px``) are CPython's
``math.hypot`` of the step's vectors, bit for bit, as the pure-Python filter took them
(benchmarks/filter_equality.py compares the whole filter with it). The compiled
:func:`pslog.fusion.filter._lengths` repeats CPython's algorithm (numba's and numpy's hypot
are libm's, which differ from it in the last bit now and then): compared here on random
pixel vectors, on the whole range of doubles, near and below the smallest normal, with
huge ratios and with 0, inf and NaN."""

import math

import numpy as np
import pytest

from pslog.fusion import filter as filter_module

# the kernel repeats CPython 3.11's hypot; elsewhere the filter maps math.hypot itself
pytestmark = pytest.mark.skipif(not filter_module._HYPOT_COMPILED,
                                reason="the compiled lengths are CPython 3.11's hypot")


def _lengths(x: np.ndarray, y: np.ndarray, init: np.ndarray | None = None) -> np.ndarray:
    """The kernel's two length rows for vectors (x, y): both as the batch filter calls it
    (an output table of rows, the quality table it fills)."""
    n = len(x)
    rows = np.zeros((n, filter_module._OUT_COLS))
    rows[:, 7], rows[:, 8], rows[:, 9], rows[:, 10] = x, y, y, x
    if init is not None:
        rows[:, 15] = init
    q = np.full((len(filter_module.FILTER_QUALITY), n), -1.0)
    filter_module._lengths(rows, q)
    return q[4:6]


def _bits_equal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return (a.view(np.int64) == b.view(np.int64)) | (np.isnan(a) & np.isnan(b))


def _check(x: np.ndarray, y: np.ndarray) -> None:
    q = _lengths(x, y)
    expected = np.array([math.hypot(a, b) for a, b in zip(x.tolist(), y.tolist(),
                                                          strict=True)])
    for row in q:  # (hypot(x, y) and hypot(y, x))
        bad = np.flatnonzero(~_bits_equal(row, expected))
        assert len(bad) == 0, [(x[i], y[i], row[i], expected[i]) for i in bad[:5]]


def test_lengths_are_cpython_hypot_on_pixel_vectors():
    rng = np.random.default_rng(12)
    x, y = rng.normal(size=(2, 50_000)) * rng.choice([0.01, 1.0, 30.0, 1e4], (2, 50_000))
    # numpy's (libm's) hypot differs from CPython's on some of these: the test can tell
    assert not np.all(_bits_equal(np.hypot(x, y), np.array(list(map(math.hypot, x, y)))))
    _check(x, y)


def test_lengths_are_cpython_hypot_over_every_exponent():
    rng = np.random.default_rng(13)
    n = 40_000
    e = rng.integers(-1074, 1024, n)
    x = np.ldexp(rng.random(n), e) * rng.choice([-1.0, 1.0], n)
    y = np.ldexp(rng.random(n), np.clip(e + rng.integers(-70, 70, n), -1074, 1023))
    _check(x, y)
    # near and below the smallest normal (the division by the larger below 2**-1024)
    e = rng.integers(-1076, -1000, n)
    _check(np.ldexp(rng.random(n), e), np.ldexp(rng.random(n), e + rng.integers(-60, 60, n)))
    # random bit patterns (every exponent, NaNs among them) and near-equal pairs
    bits = rng.integers(0, 2**63, (2, n), dtype=np.int64).view(np.float64)
    _check(bits[0], bits[1])
    with np.errstate(over="ignore", invalid="ignore"):
        _check(bits[0], np.nextafter(bits[0], np.inf) * (1 + rng.random(n) * 1e-6))


def test_lengths_of_zero_inf_nan_and_extremes():
    special = np.array([0.0, -0.0, math.inf, -math.inf, math.nan, 5e-324, 1e-310,
                        2.2250738585072014e-308, 2.0**-1024, 1.7976931348623157e308, 1.0, 3.0,
                        4.0, 1e300, 1e-300, 1e154, 1e-154])
    x, y = np.meshgrid(special, special)
    _check(x.ravel(), y.ravel())
    assert _lengths(np.array([math.inf]), np.array([math.nan]))[0, 0] == math.inf
    assert _lengths(np.array([3.0]), np.array([4.0]))[0, 0] == 5.0


def test_a_starts_residual_is_its_fits():
    # a start's row (init 1) carries its fit's residual in column 9, not a vector
    q = _lengths(np.array([3.0, 3.0]), np.array([4.0, 4.0]), init=np.array([1.0, 0.0]))
    assert q[1].tolist() == [4.0, 5.0]  # (column 9 holds y: 4.0 as given)
    assert q[0].tolist() == [5.0, 5.0]


def test_the_filter_takes_the_compiled_lengths_here():
    # the probe that decides it agrees with math.hypot on this interpreter and CPU
    assert filter_module._hypot_compiled()
