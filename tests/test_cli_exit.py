"""The ``pslog`` command's last step (pslog.cli._before_exit): as the command, every object
still alive is frozen before the interpreter's shutdown (its collections then skip them);
``main`` called by a program or a test leaves the collector as it was."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
from pathlib import Path

from pslog.cli import main

# a console script as pip writes one (its file named pslog), reporting at exit how many
# objects the collector holds frozen; atexit runs after main returned, before the shutdown
_SCRIPT = """\
import atexit, gc, sys
atexit.register(lambda: print("frozen", gc.get_freeze_count(), file=sys.stderr))
from pslog.cli import main
sys.exit(main())
"""


def _frozen_at_exit(tmp_path: Path, *argv: str) -> tuple[int, str]:
    script = tmp_path / "pslog"
    script.write_text(_SCRIPT)
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    done = subprocess.run([sys.executable, str(script), *argv], capture_output=True,
                          text=True, timeout=120, env=env)
    line = [ln for ln in done.stderr.splitlines() if ln.startswith("frozen ")]
    assert line, done.stderr
    return done.returncode, line[-1]


def test_the_command_freezes_its_objects_before_exit(tmp_path):
    code, line = _frozen_at_exit(tmp_path, "rig", "list")
    assert code == 0
    assert int(line.split()[1]) > 10_000  # the modules' objects, pslog's and argparse's


def test_a_failing_command_freezes_them_too(tmp_path):
    code, line = _frozen_at_exit(tmp_path, "info", str(tmp_path / "missing.mcap"))
    assert code == 1
    assert int(line.split()[1]) > 10_000


def test_main_called_in_a_process_leaves_the_collector(capsys):
    before = gc.get_freeze_count()
    assert main(["rig", "list"]) == 0
    assert gc.get_freeze_count() == before
    assert "paper3" in capsys.readouterr().out
