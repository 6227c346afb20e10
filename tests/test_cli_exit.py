"""The ``pslog`` command's last step (pslog.cli._before_exit): as the command, every object
still alive is frozen before the interpreter's shutdown (its collections then skip them);
``main`` called by a program or a test leaves the collector as it was."""

from __future__ import annotations

import gc
import os
import subprocess
import sys
from pathlib import Path

import pytest

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


_HELD_POOL_LOCK = r"""
import sys, time
from concurrent.futures import ThreadPoolExecutor
from pslog.cli import _before_exit

# the session writer's compression pool, its semaphore's lock left held by the main thread,
# as a SIGTERM raised by a handler between a `with` block's __enter__ and its body leaves it
pool = ThreadPoolExecutor(1, thread_name_prefix=sys.argv[2])
pool.submit(time.sleep, 0.3)
pool._idle_semaphore._cond.acquire()  # (the worker, done, waits for it to say it is idle)
time.sleep(0.6)
print("before exit", flush=True)
_before_exit(int(sys.argv[1]))  # (then the interpreter's shutdown joins the pool's thread)
"""


@pytest.mark.parametrize("code, prefix", [(143, "pslog-zstd"), (130, "pslog-encode")])
def test_a_signalled_command_exits_though_a_pool_thread_is_stuck(code, prefix):
    """Session 36: ``pslog fuse`` said "terminated (SIGTERM)" and never exited (a CI run): the
    signal's exception had left a writer pool's lock held, its worker waited for it, and the
    interpreter's shutdown joined the worker. A signalled command with such a pool alive
    exits at once, with the signal's code."""
    run = subprocess.run([sys.executable, "-c", _HELD_POOL_LOCK, str(code), prefix],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == code, run.stderr
    assert run.stdout == "before exit\n"


def test_an_error_exit_still_joins_the_pool_threads():
    """An error (exit 1) is raised by the command's own code, no handler's: its pool threads
    are joined by the shutdown as before (no ``os._exit``; the stuck pool here would hang)."""
    with pytest.raises(subprocess.TimeoutExpired):
        subprocess.run([sys.executable, "-c", _HELD_POOL_LOCK, "1", "pslog-zstd"],
                       capture_output=True, text=True, timeout=5)
