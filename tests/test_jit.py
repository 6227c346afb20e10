"""pslog._jit.kernel: compiled kernels equal their Python originals, and a kernel whose
cache cannot be written anywhere is compiled in memory instead of failing."""

import numpy as np

from pslog._jit import kernel

SOURCE = '''
def total(a):
    s = 0.0
    for x in a:
        s += x
    return s / 0.0 if s < 0 else s
'''


def test_a_kernel_without_a_cache_location_is_compiled_in_memory():
    # a function compiled from a string has no file: numba finds no cache location for it,
    # exactly as for a module in a read-only folder with no writable home
    namespace: dict = {}
    exec(compile(SOURCE, "<no file>", "exec"), namespace)
    fn = kernel(namespace["total"])
    a = np.arange(5.0)
    assert fn(a) == fn.py_func(a) == 10.0
    assert np.isinf(fn(-a - 1))  # numpy's error model: a division by zero gives inf


def test_numba_refusing_to_start_is_one_line(tmp_path):
    import os
    import subprocess
    import sys

    from faults._inprocess import run_inprocess

    session = tmp_path / "s.mcap"  # (made in this process: not what is tested)
    cli = [sys.executable, "-m", "pslog.cli"]
    assert run_inprocess("simulate", "--rig", "paper3", "--timing", "typeA", "--duration",
                         "1", "-o", session).code == 0
    run = subprocess.run([*cli, "fuse", str(session), "--method", "typeA", "-o",
                          str(tmp_path / "f.mcap")], capture_output=True, text=True,
                         env=dict(os.environ, NUMBA_NUM_THREADS="0", PSLOG_PROGRESS="off"))
    assert run.returncode == 1
    assert run.stderr.strip().splitlines() == [
        "pslog fuse: error: numba could not start (ValueError: Number of threads specified "
        "must be > 0.); check the NUMBA_* environment variables"]
    assert not (tmp_path / "f.mcap").exists()


HELPERS = '''
from pslog._jit import kernel


@kernel(inline=True)
def shifted(x):
    return x + {shift}
'''

CONSTANTS = '''
SCALE = {scale}
'''

KERNELS = '''
from pslog._jit import kernel

from . import constants
from .helpers import shifted


@kernel
def apply(x):
    return shifted(x) * constants.SCALE
'''


def test_a_cached_kernel_is_compiled_again_when_a_module_it_imports_from_changes(tmp_path):
    # numba stamps a kernel's cache by its own file only; `apply` inlines a helper of one
    # file and freezes a constant of another: editing only those must not load stale code
    import subprocess
    import sys

    package = tmp_path / "kernels_pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "kernels.py").write_text(KERNELS)

    def run(scale: float, shift: float) -> float:
        (package / "helpers.py").write_text(HELPERS.format(shift=shift))
        (package / "constants.py").write_text(CONSTANTS.format(scale=scale))
        out = subprocess.run([sys.executable, "-c", "from kernels_pkg.kernels import apply; "
                              "print(apply(1.0), sum(apply.stats.cache_hits.values()))"],
                             cwd=tmp_path, capture_output=True, text=True, check=True)
        value, hits = out.stdout.split()
        return float(value), int(hits)

    assert run(2.0, 1.0) == (4.0, 0)  # compiled, cached
    assert run(2.0, 5.0) == (12.0, 0)  # the inlined helper changed (from .helpers import)
    assert run(3.0, 5.0) == (18.0, 0)  # the frozen constant changed (from . import constants)
    assert run(3.0, 5.0) == (18.0, 1)  # and then loaded from the cache



BLAS_PROBE = '''
import sys

import numpy as np

from pslog._jit import kernel

namespace = {"np": np}
exec(compile("def add(a, b):\\n    return a + b\\n"
             "def dot(a, b):\\n    return np.dot(a, b)\\n", "<no file>", "exec"), namespace)
add = kernel(namespace["add"])  # compiled in memory: numba loads its registries first
assert add(1.0, 2.0) == 3.0
import numba.np.arraymath as arraymath
import numba.np.linalg as numba_linalg

print(arraymath._HAVE_BLAS, "scipy.linalg" in sys.modules, numba_linalg.ensure_blas.__module__)
try:
    numba_linalg.ensure_blas()  # numba's own check (it imports scipy.linalg): its verdict
    print(True)
except ImportError:
    print(False)
dot = kernel(namespace["dot"])  # a float np.dot: BLAS's ddot, through numba's helpers
a, b = np.arange(1.0, 6.0), np.linspace(0.5, 3.0, 5)
print(dot(a, b) == np.dot(a, b))
'''


def test_numba_answers_its_blas_question_without_importing_scipy_linalg():
    # numba's first kernel load asks whether scipy's Cython BLAS exists (a compiled np.dot
    # then calls BLAS) by importing all of scipy.linalg (~0.2-0.35 CPU s a process);
    # pslog._jit answers it by finding the module: the same verdict as numba's own check,
    # scipy.linalg left unimported, numba's function back for np.dot, which still runs
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", BLAS_PROBE], capture_output=True, text=True,
                         check=True).stdout.split()
    have_blas, linalg_imported, ensure_blas_module, numbas_verdict, dot_equal = out
    assert have_blas == numbas_verdict == "True"
    assert linalg_imported == "False"
    assert ensure_blas_module == "numba.np.linalg"
    assert dot_equal == "True"


LAPACK_PROBE = '''
import sys

import numpy as np

import pslog.fusion.filter  # noqa: F401 (its import loads scipy's Cython LAPACK by file)
from pslog._jit import kernel

print("scipy.linalg.cython_lapack" in sys.modules, "scipy.linalg" in sys.modules)
namespace = {"np": np}
exec(compile("def solve(a, b):\\n    return np.linalg.solve(a, b)\\n", "<no file>", "exec"),
     namespace)
solve = kernel(namespace["solve"])  # compiled in memory: LAPACK's gesv, through numba
a = np.array([[4.0, 1.0, 0.5], [1.0, 3.0, 0.25], [0.5, 0.25, 2.0]])
b = np.array([1.0, 2.0, 3.0])
print(bool(np.array_equal(solve(a, b), np.linalg.solve(a, b))), "scipy.linalg" in sys.modules)
import scipy.linalg.cython_lapack  # (the statement's form that reads the attribute)

print(scipy.linalg.cython_lapack is sys.modules["scipy.linalg.cython_lapack"],
      bool(np.allclose(scipy.linalg.solve(a, b), np.linalg.solve(a, b))))
'''


def test_compiled_lapack_calls_do_not_import_scipy_linalg():
    # numba's compiled np.linalg imports scipy.linalg.cython_lapack at its first call, which
    # imported all of scipy.linalg (~0.15-0.2 CPU s of a default pslog fuse, the filter's
    # first window fit); pslog.fusion.filter loads the Cython modules by file instead: the
    # same solution, scipy.linalg left unimported, and a scipy.linalg imported later has
    # them as its attributes
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", LAPACK_PROBE], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ["True", "False", "True", "False", "True", "True"]


ARCHIVE_PROBE = '''
import importlib.machinery
import sys

served = []


class Archive:
    """A frozen application's importer (its archive's modules): ahead of the path's finder."""

    def find_spec(self, name, path=None, target=None):
        if name != "scipy.linalg":
            return None
        served.append(name)
        return importlib.machinery.PathFinder.find_spec(name, path, target)


sys.meta_path.insert(0, Archive())
import pslog.fusion.filter  # noqa: E402,F401 (its import loads scipy's Cython LAPACK by file)

print("scipy.linalg.cython_lapack" in sys.modules, "scipy.linalg" in sys.modules)
import scipy.linalg  # noqa: E402

print(served == ["scipy.linalg"],
      scipy.linalg.cython_lapack is sys.modules["scipy.linalg.cython_lapack"])
'''


def test_scipy_linalg_imported_later_is_found_where_it_would_be():
    # the finder cython_linalg_by_file puts ahead of every other takes the spec of the
    # finder that would have found scipy.linalg without it (a frozen application's archive,
    # an editable install's: the path's spec there is another module), not the path's
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", ARCHIVE_PROBE], capture_output=True,
                         text=True, check=True).stdout.split()
    assert out == ["True", "False", "True", "True"]
