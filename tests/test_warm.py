"""``python -m pslog.warm`` (run by ``bash run.sh`` after installing) runs the real commands
that compile every numba kernel, and leaves nothing behind but numba's cache."""

import os
import subprocess
import sys


def test_warm_runs_the_commands_and_leaves_no_file(tmp_path):
    env = dict(os.environ, TMPDIR=str(tmp_path))
    run = subprocess.run([sys.executable, "-m", "pslog.warm"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "numba kernels ready in" in run.stdout
    assert "Traceback" not in run.stderr
    assert list(tmp_path.iterdir()) == []  # its session files were in a removed folder
