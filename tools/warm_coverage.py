"""Check that ``python -m pslog.warm`` compiles every numba kernel of pslog and recorders.

Runs warm in a subprocess with an empty ``NUMBA_CACHE_DIR`` (a temporary folder; or
``--cache DIR``: check a cache that warm has filled already, without running it), then walks
every module that defines kernels (:func:`pslog._jit.kernel`; found by their source) and
lists each compiled, not inlined, kernel that has no cache index there: a kernel warm never
runs, compiled instead at its first use by a user (or twice at once by the test processes).
Exit status 1 when one is missing. A kernel whose signature differs between warm and its
other callers is not seen here (its index exists): compare the cache's files before and
after running the suite with the same ``NUMBA_CACHE_DIR``.

Run: ``python tools/warm_coverage.py [--cache DIR]`` (a cold warm takes minutes).
"""

from __future__ import annotations

import argparse
import glob
import importlib
import os
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def kernel_modules() -> list[str]:
    names = []
    for package in ("pslog", "recorders"):
        for path in sorted(glob.glob(os.path.join(ROOT, package, "**", "*.py"), recursive=True)):
            with open(path, encoding="utf-8") as f:
                if "\n@kernel" in f.read():
                    rel = os.path.relpath(path, ROOT)[:-3].replace(os.sep, ".")
                    names.append(rel.removesuffix(".__init__"))
    return names


def missing(cache: str) -> tuple[list[str], int]:
    from numba.core.registry import CPUDispatcher

    indexes = {os.path.basename(p) for p in glob.glob(os.path.join(cache, "**", "*.nbi"),
                                                       recursive=True)}
    absent, n = [], 0
    for name in kernel_modules():
        module = importlib.import_module(name)
        stem = os.path.basename(module.__file__ or "")[:-3]
        for attr, obj in vars(module).items():
            if (not isinstance(obj, CPUDispatcher) or obj.__module__ != name
                    or obj.targetoptions.get("inline") == "always"):
                continue  # not a kernel of this module, or inlined into its callers
            n += 1
            if not any(i.startswith(f"{stem}.{obj.py_func.__qualname__}-") for i in indexes):
                absent.append(f"{name}.{attr}")
    return absent, n


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cache", help="a numba cache warm has filled (default: run warm "
                        "into an empty one)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="warm-coverage-") as tmp:
        cache = args.cache or tmp
        if not args.cache:
            start = time.perf_counter()
            run = subprocess.run([sys.executable, "-m", "pslog.warm"], cwd=ROOT,
                                 env={**os.environ, "NUMBA_CACHE_DIR": cache})
            print(f"warm: exit {run.returncode}, {time.perf_counter() - start:.1f} s wall")
            if run.returncode:
                return 1
        absent, n = missing(cache)
    for name in absent:
        print(f"not compiled by warm: {name}")
    print(f"{n - len(absent)} of {n} kernels compiled by warm")
    return 1 if absent else 0


if __name__ == "__main__":
    sys.exit(main())
