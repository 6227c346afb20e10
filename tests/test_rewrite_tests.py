"""tools/rewrite_tests.py (run by ``bash run.sh test`` before the suite): the cache it writes
is the one pytest reads, with bytecode writing off, instead of rewriting the module."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _tool():  # loaded by its path (tools/ is not put on the suite's sys.path)
    spec = importlib.util.spec_from_file_location("rewrite_tests",
                                                  ROOT / "tools" / "rewrite_tests.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


rewrite = _tool().rewrite


def test_pytest_reads_the_written_cache_and_rewrites_nothing(tmp_path):
    (tmp_path / "conftest.py").write_text("")
    (tmp_path / "helper.py").write_text("X = 1\n")  # not a test module: pytest leaves it
    (tmp_path / "test_one.py").write_text(
        "from helper import X\n\ndef test_x():\n    a = [X, 2]\n    assert a == [1, 3]\n")
    assert rewrite(tmp_path) == 2  # conftest.py and test_one.py
    assert rewrite(tmp_path) == 0  # current: left alone
    assert sorted(p.name for p in (tmp_path / "__pycache__").iterdir()) == [
        f"{name}.{sys.implementation.cache_tag}-pytest-{__import__('pytest').__version__}.pyc"
        for name in ("conftest", "test_one")]

    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
    run = subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p",
                          "no:xdist", "-p", "no:randomly", "--rootdir", str(tmp_path),
                          "-c", os.devnull, "--debug=debug.log", "test_one.py"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    # the assertion still rewritten (its values reported), from the cache
    assert run.returncode == 1 and "assert [1, 2] == [1, 3]" in run.stdout, run.stdout
    log = (tmp_path / "debug.log").read_text()
    # (pytest's trace messages; conftest.py's import comes before the trace starts)
    assert f"found cached rewritten pyc for {tmp_path / 'test_one.py'}" in log, log
    assert f"rewriting {tmp_path / 'test_one.py'!r}" not in log, log
