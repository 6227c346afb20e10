"""Bit-for-bit comparisons with this machine's BLAS and LAPACK, where they can hold.

Several of pslog's compiled kernels sum in the order of the BLAS/LAPACK routine (or the
numpy product) they replaced, with one rounding per product and one per sum, so that where
the library runs the kernels these were matched against, their results are the library's to
the last bit, and replacing the library call changed no output. Tests check that bit for
bit there.

OpenBLAS picks its kernels by CPU at load time, and not all give those bits: on an AMD
EPYC with AVX-512 (session 19's host, OpenBLAS core ``SkylakeX``) ``dpbtrf``/``dpbtrs`` and
the small products differ in their last bits (measured: even a two-term ``np.dot`` differs
from ``a0*b0 + a1*b1``), and under ``OPENBLAS_CORETYPE=Nehalem`` numpy's small products do
(no FMA there: the kernel's partial sums). No plain-arithmetic kernel can reproduce every
such order; the difference is rounding, a few units in the last place per operation (more
after an ill-conditioned solve). Elsewhere the tests compare within a tolerance — still far
below what any wrong equation, index or sign gives.

:func:`blas_is_plain` tells which machine this is, by the cores numpy's and scipy's
OpenBLAS report (``*_get_corename``; nothing that pslog's kernels compute, so a mutated
kernel cannot turn the exact comparison off): exact where both are among
:data:`PLAIN_CORES`, the cores the exact comparisons were seen to hold on.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.testing import assert_allclose, assert_array_equal

#: OpenBLAS cores whose kernels give the bits the compiled kernels follow: ``Haswell``
#: (session 19's host forced with ``OPENBLAS_CORETYPE=Haswell``: every exact comparison
#: holds) and ``Zen`` (the AMD EPYC hosts without AVX-512 of sessions 1-18, where CI ran the
#: exact comparisons)
PLAIN_CORES = frozenset({"Haswell", "Zen"})


def openblas_cores() -> frozenset[str] | None:
    """The kernel sets ("cores") numpy's and scipy's bundled OpenBLAS chose on this machine;
    None when either is not a bundled OpenBLAS that says (another BLAS: unknown order)."""
    import ctypes
    import glob
    import os

    import numpy
    import scipy

    cores = set()
    for package in (numpy, scipy):
        site = os.path.dirname(os.path.dirname(package.__file__))
        libs = glob.glob(os.path.join(site, f"{package.__name__}.libs",
                                      "libscipy_openblas*.so*"))
        if len(libs) != 1:
            return None
        try:
            lib = ctypes.CDLL(libs[0])  # the copy the package loaded: the same kernels
        except OSError:
            return None
        for name in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename",
                     "openblas_get_corename"):
            get = getattr(lib, name, None)
            if get is not None:
                get.restype = ctypes.c_char_p
                cores.add(get().decode())
                break
        else:
            return None
    return frozenset(cores)


@functools.cache
def blas_is_plain() -> bool:
    """Whether numpy's and scipy's OpenBLAS run kernels whose bits the compiled kernels
    follow here (:data:`PLAIN_CORES`)."""
    cores = openblas_cores()
    return cores is not None and cores <= PLAIN_CORES


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
