"""Write pytest's cache of the test modules' rewritten assertions once, before the suite.

pytest rewrites each test module's ``assert`` statements (to report the values compared)
when it imports the module, and caches the result beside it
(``__pycache__/NAME.cpython-3XX-pytest-V.pyc``, keyed by the source's hash) unless bytecode
writing is off: with ``PYTHONDONTWRITEBYTECODE`` set (as on some CI images, and on the
development machines), nothing is cached and every test process rewrites every module at its
collection. ``bash run.sh test`` runs the suite in three such processes (pytest-xdist), each
collecting the whole suite: ~11 CPU s of collection each, ~4 with the cache (the rest: the
imports). This module writes the cache in one process, without importing the tests (the
rewrite alone: ~4.5 CPU s); pytest reads the cache even when it may not write it.

Only what pytest itself would rewrite: ``conftest.py`` and ``test_*.py`` (pytest's default
``python_files``, this project's). Best effort: a pytest whose internals differ, or a
read-only checkout, leaves the modules to be rewritten at collection as before (exit 0,
nothing written). A module whose cache is current is left alone.

Run: ``python tools/rewrite_tests.py [FOLDER]`` (default: ``tests``); prints nothing.
"""

from __future__ import annotations

import sys
import types
from pathlib import Path


def rewrite(folder: Path) -> int:
    """Cache the rewritten code of ``folder``'s test modules; returns how many were written."""
    try:
        from _pytest.assertion import rewrite as rw

        read, write, test = rw._read_pyc, rw._write_pyc, rw._rewrite_test
        cache_dir, tail = rw.get_cache_dir, rw.PYC_TAIL
    except (ImportError, AttributeError):  # another pytest: its collection rewrites them
        return 0
    quiet = types.SimpleNamespace(trace=lambda message: None)  # (pytest's AssertionState)
    written = 0
    for source in sorted(folder.rglob("*.py")):
        if source.name != "conftest.py" and not source.name.startswith("test_"):
            continue
        pyc = cache_dir(source) / (source.name[:-3] + tail)
        try:
            if read(source, pyc) is not None:
                continue
            source_hash, code = test(source, None)
            pyc.parent.mkdir(exist_ok=True)
            written += bool(write(quiet, code, source_hash, pyc))
        except (OSError, SyntaxError):  # unwritable, or a module pytest will report itself
            continue
    return written


if __name__ == "__main__":
    rewrite(Path(sys.argv[1] if len(sys.argv) > 1 else "tests"))
