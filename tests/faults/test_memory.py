"""Out of memory: the CLI's last handler turns an exception that a ``MemoryError`` (or a thread
whose stack could not be had) caused into one line ``out of memory: ...`` and exit 1, and
leaves every other exception alone (a bug's traceback is what its report needs).

Forcing a command to run out for real (``ulimit -v`` in a child) was tried: numpy raises
``MemoryError``, but OpenBLAS, glibc and LLVM then also fail in their own ways (their own one
line, or a crash) depending on which allocation fails first — not a test that passes the same
way twice. The exceptions here are real ones, raised and chained as Python chains them.
"""

from __future__ import annotations

import numpy as np
import pytest

from pslog.cli import _out_of_memory


def _numpy_memory_error() -> MemoryError:
    try:
        np.empty(2**62, dtype=np.uint8)  # 4 EiB: no machine has it
    except MemoryError as exc:
        return exc
    raise AssertionError("numpy allocated 4 EiB")


def test_memory_error_itself_names_the_allocation():
    assert "Unable to allocate" in _out_of_memory(_numpy_memory_error())


def test_memory_error_behind_another_exception():
    """A module whose import ran out half-way fails the next ``from . import`` with an
    ImportError; a numba dispatcher reports a SystemError: both with the MemoryError as their
    context."""
    for later in (ImportError("cannot import name '_prepare_kernel'"),
                  SystemError("CPUDispatcher returned a result with an exception set")):
        try:
            try:
                raise _numpy_memory_error()
            except MemoryError:
                raise later  # noqa: B904 -- implicit chaining (__context__) is what we test
        except type(later) as exc:
            assert "Unable to allocate" in _out_of_memory(exc)
    try:
        raise ValueError("wrapped") from _numpy_memory_error()
    except ValueError as exc:
        assert _out_of_memory(exc) is not None


def test_thread_that_cannot_start():
    assert _out_of_memory(RuntimeError("can't start new thread")) == "can't start new thread"


@pytest.mark.parametrize("exc", [ValueError("bad"), RuntimeError("other"), ImportError("x")])
def test_other_errors_are_not_memory(exc):
    assert _out_of_memory(exc) is None


def test_a_cycle_of_contexts_ends():
    a, b = ValueError("a"), ValueError("b")
    a.__context__, b.__context__ = b, a
    assert _out_of_memory(a) is None
