"""One place where pslog compiles its sequential kernels with numba.

Most of pslog is columnar numpy. A few loops cannot be vectorised: the causal filter updates
its state one detection at a time (each update depends on the last), and some per-point kernels
run hundreds of thousands of times on a 90-minute match. Those are written as plain Python
functions over float64 arrays and scalars, decorated with :func:`kernel`, which compiles them
with numba in nopython mode:

- ``cache=True``: the machine code is written next to the module (``__pycache__``) or, where
  that is read-only, to numba's per-user cache (or ``NUMBA_CACHE_DIR``), so only the first run
  on a machine pays the compile time (``python -m pslog.warm`` pays it at install); where no
  cache folder can be written, kernels are compiled in memory at every run instead;
- ``nogil=True``: a kernel releases the GIL (live fusion beside a recorder thread);
- ``error_model="numpy"``: a division by zero gives inf/nan as in numpy instead of raising;
- no ``fastmath``: IEEE arithmetic is kept, so results do not depend on reassociation (one
  exception, opted into per kernel: ``contract``, a product added to a sum fused into one
  multiply-add, for a kernel that repeats a BLAS product whose kernels fuse them).

The undecorated Python function stays available as ``kernel_fn.py_func`` (numba's attribute):
tests run both and compare, and a mutation of the equation fails both.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal, TypeVar, cast

F = TypeVar("F", bound=Callable[..., Any])


def kernel(fn: F | None = None, *, inline: bool = False, contract: bool = False) -> Any:
    """Compile ``fn`` with numba (nopython, cached, GIL released, numpy error model).

    ``@kernel(inline=True)``: a helper that numba inlines into the kernels calling it (numba
    IR, ``inline="always"``). A compiled call takes a reference to each array argument and
    releases it on return (two atomic operations per array, per call); a helper given a
    few arrays and called several times per point spent more on those than on its
    arithmetic (type A's per-point helpers: ~40 % of the kink test's time). Inlined, it
    reads its caller's arrays directly. The arithmetic is the same (the same bits); the
    first compile of its callers takes longer.

    ``@kernel(contract=True)``: a product added to a sum (``acc + a * b``) is one fused
    multiply-add where the CPU has one (LLVM's ``contract``, no other fast-math: no
    reassociation): for a kernel that repeats a BLAS matrix product whose kernels sum
    ``k`` in order with fused multiply-adds (OpenBLAS's on x86-64 with FMA), so it gives
    the product's bits (a test compares them)."""
    if fn is None:
        return lambda f: kernel(f, inline=inline, contract=contract)
    try:
        import numba  # imported here: `pslog --help` and the light commands never load LLVM
    except Exception as exc:  # e.g. NUMBA_NUM_THREADS=0: numba refuses to start
        from .errors import PslogError

        raise PslogError(f"numba could not start ({type(exc).__name__}: {exc}); check the "
                         f"NUMBA_* environment variables") from exc

    how: Literal["never", "always"] = "always" if inline else "never"
    try:
        return cast(F, numba.njit(cache=True, nogil=True, error_model="numpy",
                                  inline=how, fastmath={"contract"} if contract else False)(fn))
    except RuntimeError:
        # numba raises "cannot cache function ...: no locator available" when neither the
        # module's folder nor numba's per-user cache folder can be written (a read-only
        # install with no writable home, as in some containers): compile in memory then,
        # at every run, rather than fail (NUMBA_CACHE_DIR names a writable cache folder)
        return cast(F, numba.njit(cache=False, nogil=True, error_model="numpy",
                                  inline=how, fastmath={"contract"} if contract else False)(fn))


def preload(*modules: str) -> None:
    """Start numba and import the kernel ``modules`` on a background thread, now.

    A command that will run kernels pays, before its first kernel runs, for numba's import
    (LLVM's bindings, numba's type system: about 0.2 CPU seconds), its CPU target's
    registries (the first cache load refreshes them: about 0.2 s) and the kernel modules'
    imports (:mod:`pslog.estimation`'s, with scipy, about 0.15 s). Started on a daemon
    thread at the beginning of the command, that work overlaps its reading and gating on a
    second core instead of delaying its first kernel; the kernels themselves are still
    loaded from numba's cache at their first call (only the signatures used).

    A fault is not reported here: the same import in the command raises it as usual.

    Parameters
    ----------
    modules : dotted names of modules that define kernels (``pslog.fusion.filter``)
    """
    import threading

    def load() -> None:
        import importlib

        try:
            import numba  # noqa: F401 (the point: its import, off the command's thread)
            from numba.core.compiler_lock import global_compiler_lock
            from numba.core.registry import cpu_target

            with global_compiler_lock:  # as numba's own cache load refreshes it
                cpu_target.target_context.refresh()
        except BaseException:  # the command's own import reports it
            return
        for name in modules:
            try:
                module = importlib.import_module(name)
                # a module's own warm-up: its kernels' machine code loaded from numba's
                # cache in the signatures the command calls (the load otherwise falls on
                # the first call, on the command's way)
                warm = getattr(module, "_preload", None)
                if callable(warm):
                    warm()
            except BaseException:  # (likewise)
                pass

    threading.Thread(target=load, name="pslog-preload", daemon=True).start()
