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

Cache freshness: numba keys a kernel's cached machine code by its own source file only, but
the code also holds what the kernel took from other modules at compile time — inlined
helpers (``_stereo_kernel`` inlines ``_prepare_kernel``'s ray helpers), frozen constants
(``_pseudo_kernel`` freezes ``innovation.KINK_SIGMAS``). After an edit or a ``git pull``
that changed only such a module, numba would load the stale code. A kernel's cache stamp
here is numba's stamp *and* a digest of the contents of the pslog modules its file imports
from (:func:`_imports_digest`, one level: a value a kernel freezes is defined in its own
file or one it imports it from), so such a change compiles the kernel again.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
import re
from collections.abc import Callable
from typing import Any, Literal, TypeVar, cast

F = TypeVar("F", bound=Callable[..., Any])

#: the source files of the modules that defined kernels (their caches stamped by
#: :func:`_imports_digest` as well)
_KERNEL_FILES: set[str] = set()

#: an import statement's module in a kernel file: relative (``from ._prepare_kernel import``,
#: ``from .. import``) or absolute within pslog (``from pslog.motion import``)
_IMPORT_FROM = re.compile(r"^[ \t]*from[ \t]+(\.+[\w.]*|pslog(?:\.\w+)*)[ \t]+import[ \t]+"
                          r"(?:\(([\w\s,]*)\)|([\w \t,]*))", re.M)


@functools.cache
def _imports_digest(py_file: str, package: str) -> str:
    """SHA-256 of the contents of ``py_file`` and of the source files of the modules it
    imports from within its package tree (relative ``from`` imports, or ``pslog``'s),
    in sorted path order; a file that cannot be read counts as its error's name."""
    def read(path: str) -> bytes:
        try:
            with open(path, "rb") as f:
                return f.read()
        except OSError as exc:
            return type(exc).__name__.encode()

    own = read(py_file)
    files = set()
    for module, wrapped, names in _IMPORT_FROM.findall(own.decode("utf-8", "replace")):
        try:
            base = importlib.util.resolve_name(module, package)
        except (ImportError, ValueError):
            continue
        # the module, and each imported name that is a submodule (``from . import helpers``)
        for name in [base, *(f"{base}.{n}" for n in re.findall(r"\w+", wrapped + names)
                             if n != "as")]:
            try:
                spec = importlib.util.find_spec(name)
            except (ImportError, ValueError):
                continue
            if spec is not None and spec.origin and spec.origin.endswith(".py"):
                files.add(os.path.realpath(spec.origin))
    files.discard(os.path.realpath(py_file))
    digest = hashlib.sha256(own)
    for path in sorted(files):
        digest.update(b"\0" + path.encode() + b"\0" + read(path))
    return digest.hexdigest()


def _stamped_locators(numba_caching: Any) -> None:
    """Put in front of numba's cache locators ones that stamp a kernel file's cache with
    :func:`_imports_digest` too (numba's stamp: its own file only); for any other
    numba-cached function they decline and numba's own are used as before. Not with
    ``NUMBA_CACHE_LOCATOR_CLASSES`` set: numba then uses the classes it names alone."""
    def named(name: str) -> Any:  # numba < 0.61 spelled its cache classes with a "_"
        return getattr(numba_caching, name, None) or getattr(numba_caching, "_" + name, None)

    impl = named("CacheImpl")
    bases = [named(n) for n in ("UserProvidedCacheLocator", "InTreeCacheLocator",
                                "UserWideCacheLocator")]
    if impl is None or not hasattr(impl, "_locator_classes") or None in bases:
        return  # a numba whose cache is arranged otherwise: its own stamps only
    if getattr(impl, "_pslog_stamped", False):
        return
    ours = []
    for base in bases:
        def get_source_stamp(self: Any, _base: Any = base) -> Any:
            return (_base.get_source_stamp(self),
                    _imports_digest(os.path.realpath(self._py_file), self._pslog_package))

        def from_function(cls: Any, py_func: Any, py_file: str, _base: Any = base) -> Any:
            if os.path.realpath(py_file) not in _KERNEL_FILES:
                return None
            locator = _base.from_function.__func__(cls, py_func, py_file)
            if locator is not None:
                module = py_func.__module__
                locator._pslog_package = module.rpartition(".")[0] or module
            return locator

        ours.append(type("Pslog" + base.__name__, (base,), {
            "__module__": __name__, "get_source_stamp": get_source_stamp,
            "from_function": classmethod(from_function)}))
    impl._locator_classes = [*ours, *impl._locator_classes]
    impl._pslog_stamped = True


def _scipy_linalg_file(name: str) -> Any:
    """The import system's spec of ``scipy.linalg.<name>`` found in scipy's ``linalg``
    folder by the path finder's own search, without importing :mod:`scipy.linalg` (None:
    not there)."""
    import importlib.machinery

    import scipy

    folders = [os.path.join(path, "linalg") for path in getattr(scipy, "__path__", [])]
    return importlib.machinery.PathFinder.find_spec(name, folders)


def _blas_found_by_file(numba_linalg: Any) -> None:
    """numba's ``ensure_blas`` for the one call its ``numba.np.arraymath`` makes at import,
    giving the same verdict without importing :mod:`scipy.linalg`.

    numba asks once whether scipy's Cython BLAS exists (``_HAVE_BLAS``: a compiled ``np.dot``
    of floats calls BLAS, else a loop) by importing ``scipy.linalg.cython_blas``; that
    imports the whole of :mod:`scipy.linalg` (its decompositions, scipy's array-API layer,
    numpy's f2py: 0.3-0.4 CPU s of the first load's ~0.6), in every process at its first
    kernel load. The same question is answered by finding that extension module in
    scipy's ``linalg`` folder (the import system's own search, not the import), then
    numba's integer-width check as numba does it; a missing one raises ImportError as
    numba's import would. Compiled code calls BLAS and LAPACK through numba's helper
    library, which imports scipy's Cython modules itself at the first such call, as before
    (the filter's window fit: LAPACK; type A, nearest, the gate, smooth: none, so a command
    of those alone never imports :mod:`scipy.linalg`); later callers (a kernel's ``np.dot``
    or ``np.linalg`` compiled) get numba's own function back."""
    # (scipy: numba has imported it, its version check)
    if _scipy_linalg_file("cython_blas") is None:
        raise ImportError("scipy 0.16+ is required for linear algebra")
    check = getattr(numba_linalg, "_check_lapack_int_width", None)
    if check is not None:
        check()


class _BeforeArraymath:
    """A meta-path finder that finds nothing: a hook on the import of
    ``numba.np.arraymath`` while :func:`_lazy_blas_probe`'s refresh is under way (``armed``,
    numba's compiler lock held): it gives ``numba.np.linalg`` the probe as
    ``ensure_blas`` for arraymath's import. Put at the front of ``sys.meta_path`` once and
    left there: taking it out again while another thread walks the list to import a
    module would make that thread skip a finder (the path's: ModuleNotFoundError)."""

    def __init__(self) -> None:
        self.armed = False
        self.patched: tuple[Any, Any] | None = None

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> None:
        if name == "numba.np.arraymath" and self.armed and self.patched is None:
            import sys

            linalg: Any = sys.modules.get("numba.np.linalg")
            own = getattr(linalg, "ensure_blas", None)
            if own is not None:
                linalg.ensure_blas = functools.partial(_blas_found_by_file, linalg)
                self.patched = (linalg, own)


def _lazy_blas_probe(numba_cpu: Any) -> None:
    """Make numba's first kernel load answer its BLAS question without importing
    :mod:`scipy.linalg` (:func:`_blas_found_by_file`). numba imports its modules, then
    ``numba.np.linalg`` and ``numba.np.arraymath`` in that order, in
    ``CPUContext.load_additional_registries`` (at the first cache load or compile); during
    that call a hook on the import system (:class:`_BeforeArraymath`) sees ``arraymath``
    looked for and gives ``numba.np.linalg`` the probe as ``ensure_blas`` for arraymath's
    import; numba's own function is put back when the call returns. Every module is
    imported when and in the order numba imports it. A numba arranged otherwise (no such
    method, no ``ensure_blas``, arraymath already imported) is left as it is."""
    import sys

    context: Any = getattr(numba_cpu, "CPUContext", None)
    load = getattr(context, "load_additional_registries", None)
    if load is None or getattr(load, "_pslog_lazy_blas", False):
        return
    hook = _BeforeArraymath()

    def load_additional_registries(self: Any) -> Any:
        if "numba.np.arraymath" in sys.modules:
            return load(self)
        if hook not in sys.meta_path:
            sys.meta_path.insert(0, hook)  # type: ignore[arg-type]
        hook.armed = True  # (numba's compiler lock held: one refresh at a time)
        try:
            return load(self)
        finally:
            hook.armed = False
            if hook.patched is not None:
                linalg, own = hook.patched
                linalg.ensure_blas = own
                hook.patched = None

    load_additional_registries._pslog_lazy_blas = True  # type: ignore[attr-defined]
    context.load_additional_registries = load_additional_registries


#: scipy's Cython BLAS and LAPACK modules, whose functions numba's compiled ``np.linalg``
#: calls (:func:`cython_linalg_by_file`)
_CYTHON_LINALG = ("cython_blas", "cython_lapack")


class _LinalgLoader:
    """``scipy.linalg``'s own loader, that also gives the module, once run, the Cython
    modules :func:`cython_linalg_by_file` loaded before it as its attributes (as their
    import as submodules would have: ``import scipy.linalg.cython_lapack`` then
    ``scipy.linalg.cython_lapack.x``); anything else is the loader's."""

    def __init__(self, loader: Any) -> None:
        self._loader = loader

    def __getattr__(self, name: str) -> Any:
        return getattr(self._loader, name)

    def create_module(self, spec: Any) -> Any:
        return self._loader.create_module(spec)

    def exec_module(self, module: Any) -> None:
        import sys

        self._loader.exec_module(module)
        for name in _CYTHON_LINALG:
            sub = sys.modules.get(f"scipy.linalg.{name}")
            if sub is not None and not hasattr(module, name):
                setattr(module, name, sub)


class _LinalgFinder:
    """A meta-path finder of ``scipy.linalg`` alone, once :func:`cython_linalg_by_file`
    loaded its Cython modules: the spec of the first finder after it in ``sys.meta_path``
    that finds the module (the one that would have found it without this one), with
    :class:`_LinalgLoader`; put at the front of ``sys.meta_path`` then and left there (as
    :class:`_BeforeArraymath`). Not the path's spec directly: a finder before the path's
    (a frozen application's archive, an editable install's) finds ``scipy.linalg``
    elsewhere, and the path's spec there is another module (an empty namespace package
    where the folder holds only the extension modules)."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != "scipy.linalg":
            return None
        import sys

        finders = list(sys.meta_path)
        later = finders[finders.index(self) + 1:] if self in finders else finders
        for finder in later:
            find = getattr(finder, "find_spec", None)
            spec = None if find is None else find(name, path, target)
            if spec is None:
                continue
            if spec.loader is not None and hasattr(spec.loader, "exec_module"):
                spec.loader = cast(Any, _LinalgLoader(spec.loader))
            return spec
        return None


_LINALG_FINDER = _LinalgFinder()


def cython_linalg_by_file() -> None:
    """Load scipy's ``scipy.linalg.cython_blas`` and ``cython_lapack`` extension modules by
    their files, under their names, without importing :mod:`scipy.linalg`.

    numba's compiled ``np.linalg`` calls scipy's Cython LAPACK (and ``np.dot`` its BLAS):
    at a function's first call numba's helper library imports ``scipy.linalg.cython_lapack``
    for its pointer, and that import runs ``scipy.linalg``'s ``__init__`` first (its
    decompositions, scipy's array-API layer, the docstrings it parses: ~0.15-0.2 CPU s, in
    a default ``pslog fuse`` the filter's first window fit) for a module that needs none of
    it. Found in ``sys.modules``, the module is taken as it is (the same extension module:
    CPython loads an extension once per process). A ``scipy.linalg`` imported later gets
    them as attributes (:class:`_LinalgFinder`). Nothing is done where ``scipy.linalg`` is
    imported already, or a module is not found (numba's import then does as before)."""
    import sys

    if "scipy.linalg" in sys.modules or all(f"scipy.linalg.{n}" in sys.modules
                                            for n in _CYTHON_LINALG):
        return
    try:
        specs = [_scipy_linalg_file(n) for n in _CYTHON_LINALG]
        if any(s is None or not s.origin for s in specs):
            return
        if _LINALG_FINDER not in sys.meta_path:
            sys.meta_path.insert(0, _LINALG_FINDER)  # type: ignore[arg-type]
        for name, found in zip(_CYTHON_LINALG, specs, strict=True):
            full = f"scipy.linalg.{name}"
            if full in sys.modules:
                continue
            spec = importlib.util.spec_from_file_location(full, cast(Any, found).origin)
            if spec is None or spec.loader is None:
                return
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            sys.modules.setdefault(full, module)
    except Exception:  # (numba's own import at the call reports a fault)
        return


#: the packages outside numba and llvmlite that a first ``import numba`` (and its CPU
#: target's first refresh) imports: :func:`settle_imports` imports them on the calling
#: thread before pslog starts a thread that imports numba (tests/test_jit_threads.py checks
#: that the list is complete for the installed numba)
NUMBA_SHARED_PACKAGES = ("email", "html", "importlib.metadata", "importlib.resources",
                         "logging", "numpy.polynomial", "numpy.random", "scipy", "scipy._lib",
                         "yaml")

#: what made numba's first import fail on pslog's preload thread (None: it did not)
_preload_failure: BaseException | None = None


def settle_imports(*modules: str) -> None:
    """Import, on the calling thread, the packages that threads about to start would
    otherwise import for the first time at once: those of :data:`NUMBA_SHARED_PACKAGES`
    and the packages holding ``modules`` or among them (``pslog.estimation`` for
    ``pslog.estimation._kernels``); a missing one is skipped.

    Python (up to 3.14, CPython issue 83065) locks each module while it is imported,
    taking a module's lock before its package's: a thread importing ``pkg.mod`` (which
    imports ``pkg`` first) and another importing ``pkg`` (whose ``__init__`` imports
    ``pkg.mod``) wait for each other, and the import system ends that with an error in one
    of them (``_DeadlockError``). numba's first import on pslog's preload thread imports
    ``importlib.resources`` (llvmlite) while the command's thread imports
    ``importlib.metadata`` (the MCAP writer), which imports ``importlib.resources.abc``
    first: the preload's import failed part-way, and the next ``import numba`` made a
    second numba module without its ``core`` attribute (the submodules stayed imported),
    so every kernel load then raised ``AttributeError: module 'numba' has no attribute
    'core'``. With every package imported before the threads start, none is imported by
    two threads at once (a module's lock is then only ever taken with its package
    imported: no two threads wait for each other)."""
    import sys

    for name in (*NUMBA_SHARED_PACKAGES, *modules):
        if name not in sys.modules:
            try:
                spec = importlib.util.find_spec(name)  # (imports its package)
                if spec is not None and spec.submodule_search_locations is not None:
                    importlib.import_module(name)  # itself a package
            except Exception:  # (its importer reports it)
                pass


def _started_numba() -> Any:
    """``import numba``, or :class:`~pslog.errors.PslogError` saying why it cannot start
    (one line): numba refuses to start (NUMBA_* variables), or its first import failed
    part-way on the preload thread, leaving a numba module without its submodules."""
    import sys

    try:
        import numba  # imported here: `pslog --help` and the light commands never load LLVM
    except Exception as exc:  # e.g. NUMBA_NUM_THREADS=0: numba refuses to start
        from .errors import PslogError

        raise PslogError(f"numba could not start ({type(exc).__name__}: {exc}); check the "
                         f"NUMBA_* environment variables") from exc
    if getattr(numba, "core", None) is not sys.modules.get("numba.core"):
        from .errors import PslogError

        why = _preload_failure
        raise PslogError("numba could not start: its first import failed part-way"
                         + (f" ({type(why).__name__}: {why})" if why is not None else "")
                         + "; run the command again")
    return numba


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
    numba = _started_numba()
    how: Literal["never", "always"] = "always" if inline else "never"
    import inspect

    from numba.core import caching, cpu

    _stamped_locators(caching)
    _lazy_blas_probe(cpu)
    _KERNEL_FILES.add(os.path.realpath(inspect.getfile(fn)))
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

    A fault is not reported here: the same import in the command raises it as usual (a
    first import of numba that failed part-way here: :func:`kernel` says so in one line).
    The packages that numba's import shares with the rest of the program, and those
    holding ``modules``, are imported first, on the calling thread (:func:`settle_imports`:
    two threads importing one package at once can fail).

    Parameters
    ----------
    modules : dotted names of modules that define kernels (``pslog.fusion.filter``)
    """
    import threading

    settle_imports(*modules)

    def load() -> None:
        import importlib

        global _preload_failure
        try:
            import numba  # noqa: F401 (the point: its import, off the command's thread)
        except BaseException as exc:  # the command's own import reports it
            _preload_failure = exc
            return
        try:
            from numba.core import cpu
            from numba.core.compiler_lock import global_compiler_lock
            from numba.core.registry import cpu_target

            _lazy_blas_probe(cpu)

            # the target context got (made, the first time) before the compiler lock is
            # taken, as numba does: it makes it under the context's own lock, then takes
            # the compiler lock (CPUContext.init). Got inside the compiler lock, a thread
            # making a kernel meanwhile (a kernel module imported) held the one and waited
            # for the other: a fuse that hung for good
            context = cpu_target.target_context
            with global_compiler_lock:  # as numba's own cache load refreshes it
                context.refresh()
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
