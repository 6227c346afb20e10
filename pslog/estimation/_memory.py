"""The C allocator kept from returning a long fit's temporaries to the system between
iterations (glibc only; elsewhere nothing changes).

A Gauss–Newton iteration on a 90-minute session allocates and frees a few hundred MB of
arrays (the band of the normal equations alone is 47 MB, its factor as much, the
residuals, Jacobians and quadratic forms of 486,000 detections 70 MB more). glibc serves
an array above its mmap threshold (at most 32 MB, raised as large blocks are freed) from a
fresh mapping and trims the top of its heap as soon as 2x that is free, so each iteration
gets its memory back from the kernel one zeroed 4 kB page at a time: 250,000 page faults
and 1.9 s of system time in a 7 s fit. Inside :func:`kept`, arrays come from the heap and
the heap is not trimmed (``mallopt``: ``M_MMAP_THRESHOLD``, ``M_TRIM_THRESHOLD``,
``M_TOP_PAD``), so freed blocks are reused; on leaving, the heap's free top is returned
(``malloc_trim``) and the thresholds are set to the values glibc's own adjustment reaches
after large arrays were freed (32 MB mapped, 64 MB trimmed). The peak memory is unchanged
(the same arrays are alive at once); the outputs cannot change (only where memory comes
from does).

The setting is the process's, not the fit's: while a fit runs, every thread's allocations
follow it (in ``pslog fuse`` the other methods' on their threads too), and after the first
fit the thresholds stay at the fixed values above instead of glibc's own adjustment. A user
who tunes glibc's allocator (``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_``,
``MALLOC_TOP_PAD_``, ``GLIBC_TUNABLES``) is left alone: :func:`kept` then changes nothing;
where ``mallopt`` refuses a value the fit runs with glibc's settings. A thread other than
the main one allocates from its own arena, whose heaps glibc caps at 64 MB: there arrays
larger than that are mapped afresh whatever the threshold (the gain is the main thread's
and smaller arrays').
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_M_TRIM_THRESHOLD, _M_TOP_PAD, _M_MMAP_THRESHOLD = -1, -2, -3
_lock = threading.Lock()
_depth = 0
_libc = None


def _glibc():
    """glibc's ``mallopt`` and ``malloc_trim``, or None (another C library)."""
    global _libc
    if _libc is None:
        _libc = False
        try:
            name = ctypes.util.find_library("c")
            lib = ctypes.CDLL(name) if name else None
            if lib is not None and hasattr(lib, "mallopt") and hasattr(lib, "malloc_trim"):
                lib.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
                lib.malloc_trim.argtypes = [ctypes.c_size_t]
                _libc = lib
        except OSError:
            pass
    return _libc or None


def _tuned_by_user() -> bool:
    """Whether the environment tunes glibc's allocator (then :func:`kept` leaves it)."""
    return (any(os.environ.get(k) for k in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_",
                                            "MALLOC_TOP_PAD_"))
            or "glibc.malloc" in os.environ.get("GLIBC_TUNABLES", ""))


@contextmanager
def kept() -> Iterator[None]:
    """Inside: freed large arrays stay with the process for reuse (module docstring)."""
    global _depth
    lib = None if _tuned_by_user() else _glibc()
    if lib is None:
        yield
        return
    with _lock:
        _depth += 1
        if _depth == 1:
            # mallopt returns 0 for a value it refuses (older glibc: thresholds above 32 MB):
            # the fit then runs with glibc's settings, restored below all the same
            (lib.mallopt(_M_MMAP_THRESHOLD, 2**31 - 1)
             and lib.mallopt(_M_TRIM_THRESHOLD, 2**31 - 1)
             and lib.mallopt(_M_TOP_PAD, 64 * 2**20))
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                lib.mallopt(_M_MMAP_THRESHOLD, 32 * 2**20)
                lib.mallopt(_M_TRIM_THRESHOLD, 64 * 2**20)
                lib.mallopt(_M_TOP_PAD, 0)
                lib.malloc_trim(0)
