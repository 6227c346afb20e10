"""numba's first import beside other threads' imports (pslog._jit.preload, settle_imports):
fresh processes, the real preload thread, real imports.

The CI failure (``AttributeError: module 'numba' has no attribute 'core'`` at a kernel load
in ``pslog fuse``): the preload thread's ``import numba`` held ``importlib.resources``'
module lock (llvmlite imports it) while the command's thread imported ``importlib.metadata``
(the MCAP writer), which takes ``importlib.resources.abc``'s lock before its package's; the
import system ended the wait with an error in the preload thread, which left numba half
imported, and the next ``import numba`` made a numba module without its submodules."""

from __future__ import annotations

import subprocess
import sys

import pytest

from pslog.fusion import METHODS

#: every kernel module pslog fuse preloads
KERNEL_MODULES = sorted({k for m in METHODS.values() for k in m.kernels}
                        | {"pslog.log._wire", "pslog.fusion._gate_kernel"})


def _python(code: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=timeout)


def test_the_packages_numba_shares_are_all_imported_before_the_preload_thread():
    """After settle_imports (what preload does on the calling thread), numba's import, its
    target's first refresh and the kernel modules' imports import no package outside numba
    and llvmlite: no package is left for the preload thread and another to import at once
    (a package missing from NUMBA_SHARED_PACKAGES, e.g. importlib.resources, fails this)."""
    code = (
        "import sys\n"
        "from pslog._jit import _lazy_blas_probe, settle_imports\n"
        f"settle_imports(*{KERNEL_MODULES!r})\n"
        "before = set(sys.modules)\n"
        "import importlib, numba\n"
        "from numba.core import cpu\n"
        "from numba.core.compiler_lock import global_compiler_lock\n"
        "from numba.core.registry import cpu_target\n"
        "_lazy_blas_probe(cpu)\n"
        "with global_compiler_lock:\n"
        "    cpu_target.target_context.refresh()\n"
        f"for name in {KERNEL_MODULES!r}:\n"
        "    importlib.import_module(name)\n"
        "new = [m for m in set(sys.modules) - before\n"
        "       if hasattr(sys.modules[m], '__path__')\n"
        "       and m.partition('.')[0] not in ('numba', 'llvmlite')]\n"
        "print(sorted(new))\n")
    run = _python(code)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"


#: the preload thread paused where the CI run's was: holding importlib.resources' module
#: lock before the module exists (the global import lock released, as between finders),
#: until the main thread waits for that lock; the main thread then imports as
#: mcap.writer does, and runs kernels
FORCED = '''
import _imp, importlib._bootstrap as boot, sys, threading, time
main_tid = threading.get_ident()
paused = threading.Event()

class Pause:
    done = False
    def find_spec(self, name, path=None, target=None):
        if (name == "importlib.resources" and not self.done
                and threading.current_thread().name == "pslog-preload"):
            self.done = True
            _imp.release_lock()  # (finders run under the global import lock)
            try:
                paused.set()
                end = time.monotonic() + 60
                while time.monotonic() < end:
                    lock = boot._blocking_on.get(main_tid)
                    if lock is not None and lock.name == "importlib.resources":
                        break
                    time.sleep(0.001)
            finally:
                _imp.acquire_lock()
        return None

sys.meta_path.insert(0, Pause())
from pslog._jit import preload
preload("pslog.fusion._gate_kernel", "pslog.fusion._pseudo_kernel")
thread = next(t for t in threading.enumerate() if t.name == "pslog-preload")
while thread.is_alive() and not paused.wait(0.01):
    pass
import importlib.metadata  # the command thread's import (mcap.writer's)
thread.join(600)
import pslog.fusion._gate_kernel as gk
gk._preload()
print("ok", paused.is_set())
'''


def test_kernels_load_after_numbas_preload_met_the_commands_imports():
    """The CI failure's schedule forced (see FORCED): before the fix the preload thread's
    import failed there and the kernel load raised AttributeError; now the package is
    imported before the preload thread starts, and the kernels load."""
    run = _python(FORCED)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout.split()[0] == "ok"
    assert "Traceback" not in run.stderr


def test_a_numba_import_failed_part_way_on_the_preload_thread_is_one_line(tmp_path):
    """Should numba's first import still fail part-way on the preload thread (here forced:
    one of its modules cannot be found once), ``pslog fuse`` says so in one line (exit 1),
    not numba's AttributeError at the first kernel load."""
    from pslog.cli import main

    session = tmp_path / "s.mcap"
    assert main(["simulate", "--rig", "paper3", "--duration", "1", "-o", str(session)]) == 0
    code = (
        "import sys, threading\n"
        "class FailOnce:\n"
        "    done = False\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'numba.core.cpu' and not self.done and \\\n"
        "                threading.current_thread().name == 'pslog-preload':\n"
        "            self.done = True\n"
        "            raise ImportError('forced')\n"
        "sys.meta_path.insert(0, FailOnce())\n"
        "from pslog._jit import preload\n"
        "preload('pslog.fusion.filter')\n"
        "for t in threading.enumerate():\n"
        "    if t.name == 'pslog-preload':\n"
        "        t.join(300)\n"
        "from pslog.cli import main\n"
        f"sys.exit(main(['fuse', {str(session)!r}, '--method', 'filter', '-o',\n"
        f"               {str(tmp_path / 'f.mcap')!r}]))\n")
    run = _python(code)
    assert run.returncode == 1, run.stderr[-3000:]
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and "numba could not start" in lines[0], run.stderr[-3000:]
    assert "forced" in lines[0]
    assert not (tmp_path / "f.mcap").exists()


@pytest.mark.parametrize("module", ["json.tool"])
def test_a_thread_importing_during_the_first_refresh_finds_its_module(module):
    """numba's first refresh (pslog's BLAS probe hooked on it) must not change
    sys.meta_path under another thread walking it: a hook taken out meanwhile made that
    thread skip the next finder (the path's: ModuleNotFoundError). Forced: a thread walks
    the finders while the hook is there, paused until the refresh has returned."""
    code = f'''
import _imp, sys, threading, time
refreshed = threading.Event()
started = threading.Event()

class Pause:
    def find_spec(self, name, path=None, target=None):
        if name == {module!r} and threading.current_thread().name == "walker":
            _imp.release_lock()
            try:
                started.set()
                refreshed.wait(600)
                time.sleep(0.05)
            finally:
                _imp.acquire_lock()
        return None

import numba
from numba.core import cpu
from numba.core.compiler_lock import global_compiler_lock
from numba.core.registry import cpu_target
from pslog._jit import _lazy_blas_probe
_lazy_blas_probe(cpu)
errors = []

def walk():
    while not any(type(f).__name__.endswith("BeforeArraymath") for f in sys.meta_path):
        time.sleep(0.0005)
    try:
        __import__({module!r})
    except BaseException as exc:
        errors.append(repr(exc))

class Hold:  # the walker starts once the hook is in
    def find_spec(self, name, path=None, target=None):
        if name == "numba.np.arraymath":
            walker.start()
            _imp.release_lock()
            try:
                started.wait(600)
            finally:
                _imp.acquire_lock()
        return None

walker = threading.Thread(target=walk, name="walker")
from importlib.machinery import PathFinder
at = sys.meta_path.index(PathFinder)  # the walker paused just before the path's finder
sys.meta_path[at:at] = [Hold(), Pause()]
with global_compiler_lock:
    cpu_target.target_context.refresh()
refreshed.set()
walker.join(600)
print(errors or "ok")
'''
    run = _python(code)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout.strip() == "ok"


#: a thread makes numba's target context (a kernel module imported: numba makes it under the
#: context's own lock, then takes the compiler lock), paused inside until another thread
#: holds the compiler lock (3 s at most); the preload thread starts meanwhile
MAKING = '''
import sys, threading, time
paused, done = threading.Event(), []

def tracer(frame, event, arg):
    code = frame.f_code
    if (event == "call" and code.co_name == "__init__"
            and code.co_filename.endswith("cpu.py") and "numba" in code.co_filename):
        from numba.core.compiler_lock import global_compiler_lock
        paused.set()
        end = time.monotonic() + 3
        while time.monotonic() < end:
            if not global_compiler_lock._lock.acquire(blocking=False):
                break  # another thread holds it
            global_compiler_lock._lock.release()
            time.sleep(0.001)
    return None

def make():
    sys.settrace(tracer)
    import pslog.fusion._prepare_kernel  # noqa: F401 (its kernels made)
    sys.settrace(None)
    done.append(True)

maker = threading.Thread(target=make, daemon=True)
maker.start()
paused.wait(600)
from pslog._jit import preload
preload("pslog.fusion.filter")  # (imports only: no kernel loaded)
preloading = next(t for t in threading.enumerate() if t.name == "pslog-preload")
maker.join(60)
preloading.join(60)
print("hung" if maker.is_alive() or preloading.is_alive() else "ok", done)
sys.stdout.flush()
import os
os._exit(0)  # (a hung thread would keep the process)
'''


def test_the_preload_beside_a_thread_making_kernels_does_not_hang():
    """The preload thread refreshes numba's target under the compiler lock; it got the
    target context inside that lock, while a thread making kernels held the context's own
    lock (making it) and waited for the compiler lock: both waited for good (a stress loop
    of ``pslog fuse`` hung so, its fusion threads importing kernel modules). Forced: the
    maker paused inside the context's making until the compiler lock is held elsewhere."""
    run = _python(MAKING, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout.split()[0] == "ok", run.stdout + run.stderr[-3000:]
