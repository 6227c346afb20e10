"""Commands the tests start run this tree's code, from whatever folder they start in (review,
session 36): with ``PYTHONPATH=.`` (relative) or none, a child started in a test's
``tmp_path`` imported the installed pslog — another worktree's code — and a fault test of
this tree's fix then passed or failed on that code's behaviour."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pslog

ROOT = Path(__file__).resolve().parents[1]


def _child_pslog(cwd: Path, env: dict | None = None) -> Path:
    done = subprocess.run([sys.executable, "-c", "import pslog; print(pslog.__file__)"],
                          cwd=cwd, env=env or os.environ, capture_output=True, text=True,
                          check=True)
    return Path(done.stdout.strip()).resolve()


def test_a_child_started_elsewhere_imports_this_trees_pslog(tmp_path):
    assert Path(pslog.__file__).resolve() == ROOT / "pslog" / "__init__.py"
    assert _child_pslog(tmp_path) == ROOT / "pslog" / "__init__.py"


def test_run_pslog_keeps_this_tree_behind_a_pythonpath_a_test_gives(tmp_path):
    """``run_pslog(env={"PYTHONPATH": shadow})`` (a package shadowed, as the parquet fault
    test's pyarrow) puts the shadow first and this tree after it, not the installed code."""
    from faults.promises import run_pslog

    shadow = tmp_path / "shadow"
    shadow.mkdir()
    (shadow / "sitecustomize.py").write_text(
        "import os, pslog\n"
        "open(os.environ['PSLOG_PROBE_OUT'], 'w').write(pslog.__file__)\n")
    out = tmp_path / "probe.txt"
    os.environ["PSLOG_PROBE_OUT"] = str(out)
    try:
        run = run_pslog("--version", cwd=tmp_path, env={"PYTHONPATH": str(shadow)})
    finally:
        del os.environ["PSLOG_PROBE_OUT"]
    assert run.code == 0, run.stderr
    assert Path(out.read_text()).resolve() == ROOT / "pslog" / "__init__.py"
