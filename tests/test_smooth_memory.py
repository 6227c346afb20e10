"""The fit's large temporaries come from the heap and stay there for reuse inside
``_memory.kept`` instead of fresh mappings returned to the system at every free (glibc)."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest

from pslog.estimation import _memory

pytestmark = pytest.mark.skipif(_memory._glibc() is None or not hasattr(
    _memory._glibc(), "mallinfo2"), reason="glibc's mallopt and mallinfo2 only")

SIZE = 48 * 2**20  # the band of a 90-minute fit's normal equations


class _Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]


def _info() -> _Info:
    fn = _memory._glibc().mallinfo2
    fn.restype = _Info
    return fn()


def _mapped_while_alive() -> tuple[int, int]:
    """Bytes in mmapped blocks while a SIZE array is alive, and the heap's size after it is
    freed."""
    a = np.empty(SIZE // 8)
    a.fill(1.0)
    mapped = _info().hblkhd
    del a
    return mapped, _info().arena


def test_inside_kept_large_arrays_come_from_the_heap_and_stay_for_reuse():
    mapped, _ = _mapped_while_alive()
    assert mapped >= SIZE  # outside: a fresh mapping, unmapped (faulted in anew) when freed
    with _memory.kept():
        before = _info().hblkhd
        mapped, heap = _mapped_while_alive()
        assert mapped < before + SIZE  # from the heap
        assert heap >= SIZE  # and kept there, freed, for the next one
    mapped, heap = _mapped_while_alive()
    assert mapped >= SIZE  # left: large blocks mapped again
    assert heap < SIZE  # and the heap's free top returned to the system


def test_kept_nests_and_restores_only_when_the_outermost_leaves():
    with _memory.kept():
        with _memory.kept():
            pass
        assert _memory._depth == 1
        before = _info().hblkhd
        assert _mapped_while_alive()[0] < before + SIZE  # still kept
    assert _memory._depth == 0
    assert _mapped_while_alive()[0] >= SIZE
