"""The fit's large temporaries come from the heap and stay there for reuse inside
``_memory.kept`` instead of fresh mappings returned to the system at every free (glibc).

Each check runs in a fresh interpreter: the allocator's state is the process's (fits run
earlier in a test process leave free heap blocks that serve a large array from the heap)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from pslog.estimation import _memory

pytestmark = pytest.mark.skipif(_memory._glibc() is None or not hasattr(
    _memory._glibc(), "mallinfo2"), reason="glibc's mallopt and mallinfo2 only")

_PRELUDE = """
import ctypes
import numpy as np
from pslog.estimation import _memory

SIZE = 48 * 2**20  # the band of a 90-minute fit's normal equations


class Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]


def info():
    fn = _memory._glibc().mallinfo2
    fn.restype = Info
    return fn()


def mapped_while_alive():
    # bytes in mmapped blocks while a SIZE array is alive; the heap's size after it is freed
    a = np.empty(SIZE // 8)
    a.fill(1.0)
    mapped = info().hblkhd
    del a
    return mapped, info().arena
"""


def _run(body: str) -> None:
    done = subprocess.run([sys.executable, "-c", _PRELUDE + body + "\nprint('ok')"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_inside_kept_large_arrays_come_from_the_heap_and_stay_for_reuse():
    _run("""
mapped, _ = mapped_while_alive()
assert mapped >= SIZE, mapped  # outside: a fresh mapping, unmapped (faulted in anew) when freed
with _memory.kept():
    before = info().hblkhd
    mapped, heap = mapped_while_alive()
    assert mapped < before + SIZE, mapped  # from the heap
    assert heap >= SIZE, heap  # and kept there, freed, for the next one
mapped, heap = mapped_while_alive()
assert mapped >= SIZE, mapped  # left: large blocks mapped again
assert heap < SIZE, heap  # and the heap's free top returned to the system
""")


def test_kept_nests_and_restores_only_when_the_outermost_leaves():
    _run("""
with _memory.kept():
    with _memory.kept():
        pass
    assert _memory._depth == 1
    before = info().hblkhd
    assert mapped_while_alive()[0] < before + SIZE  # still kept
assert _memory._depth == 0
assert mapped_while_alive()[0] >= SIZE
""")


@pytest.mark.parametrize("variable, value", [("MALLOC_TOP_PAD_", "0"),
                                             ("GLIBC_TUNABLES", "glibc.malloc.trim_threshold=0")])
def test_an_allocator_the_user_tunes_is_left_alone(variable, value):
    _run(f"""
import os
os.environ[{variable!r}] = {value!r}  # as if the process had started with it
with _memory.kept():
    mapped, _ = mapped_while_alive()
    assert mapped >= SIZE, mapped  # glibc's own setting: a fresh mapping
""")
