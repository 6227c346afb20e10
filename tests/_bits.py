"""Bit-for-bit comparisons with this machine's BLAS and LAPACK, where they can hold.

Several of pslog's compiled kernels sum in the order of the BLAS/LAPACK routine (or the
numpy product) they replaced, with one rounding per product and one per sum, so that on a
machine whose BLAS does the same their results are the library's to the last bit, and
replacing the library call changed no output. Tests check that bit for bit.

A BLAS whose kernels fuse a multiply and an add into one rounding (FMA: OpenBLAS's AVX2 and
AVX-512 kernels on some CPUs; seen on an AMD EPYC with AVX-512 here, where even a
two-term ``np.dot`` differs from ``a0*b0 + a1*b1`` in its last bit) gives other last bits,
which no plain-arithmetic kernel can reproduce: there the difference is rounding, a few
units in the last place per operation (more after an ill-conditioned solve). On such a
machine the tests compare within a tolerance instead — still far below what any wrong
equation, index or sign gives.

:func:`blas_is_plain` tells which machine this is, by a probe that shares no code with
pslog's kernels (so a mutated kernel cannot turn the exact comparison off):
``np.dot``, ``scipy.linalg.blas.ddot`` and ``@`` of 2-16-term random products against the
sum written out in order.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal


def _in_order(a: np.ndarray, b: np.ndarray) -> float:
    """``sum(a[i] * b[i])`` left to right, one rounding per product and per sum."""
    s = 0.0
    for x, y in zip(a.tolist(), b.tolist(), strict=True):
        s += x * y
    return s


@functools.cache
def blas_is_plain() -> bool:
    """Whether numpy's and scipy's BLAS give the in-order, unfused sums' bits on this machine
    (dot products of 2-16 terms, vectors and small matrix products; 600 random cases)."""
    from scipy.linalg import blas

    rng = np.random.default_rng(20261202)
    for n in (2, 3, 4, 6, 8, 12, 16):
        for _ in range(30):
            a = rng.normal(size=n) * 10.0 ** rng.uniform(-3, 3, size=n)
            b = rng.normal(size=n)
            want = _in_order(a, b)
            if float(np.dot(a, b)) != want or float(blas.ddot(a, b)) != want:
                return False
            A, B = rng.normal(size=(3, n)), rng.normal(size=(n, 3))
            M = A @ B
            if any(M[i, j] != _in_order(A[i], B[:, j]) for i in range(3) for j in range(3)):
                return False
    return True


def assert_blas_bits(actual, desired, *, rtol: float = 1e-8, atol_rel: float = 1e-12,
                     err_msg: str = "") -> None:
    """``actual`` equals ``desired`` bit for bit where :func:`blas_is_plain`, else within
    ``rtol`` of each value and ``atol_rel`` of the largest magnitude (NaN where NaN)."""
    actual, desired = np.asarray(actual), np.asarray(desired)
    if blas_is_plain():
        assert_array_equal(actual, desired, err_msg=err_msg)
        return
    assert actual.shape == desired.shape, (actual.shape, desired.shape)
    finite = desired[np.isfinite(desired)] if desired.dtype.kind == "f" else desired
    scale = float(np.max(np.abs(finite))) if finite.size else 0.0
    if desired.dtype.kind in "fc":
        assert_allclose(actual, desired, rtol=rtol, atol=atol_rel * scale, err_msg=err_msg)
    else:
        assert_array_equal(actual, desired, err_msg=err_msg)
