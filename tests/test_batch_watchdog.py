"""The local Ray cluster's watchdog (pslog/batch.py ``_start_watchdog``, session 38) kills
only what holds a file in its own cluster's folder: never the batch, never a process whose
file lies in a folder that merely begins with the same name (another batch's
``pslog-ray-*`` beside it, or any shared path), whether the batch ends normally (it holds its
logs there while it shuts down) or is killed outright; and it removes the folder. Real
processes (no Ray: the watchdog reads /proc alone), the real ``_start_watchdog`` started by a
process that stands for the batch."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

pytestmark = pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="needs /proc")

#: holds a file open (argv[1]) until killed or 120 s; says 'ready' once it is open
_HOLDER = ("import sys, time\nf = open(sys.argv[1], 'a')\nprint('ready', flush=True)\n"
           "time.sleep(120)\n")

#: the batch's part: the watchdog started for the folder, a log held open there (as Ray's
#: driver does), then, on a line on stdin, the normal end (_shutdown: the pipe closed, the
#: watchdog waited for), the watchdog's exit code printed
_BATCH = textwrap.dedent("""
    import os, sys
    from pslog.batch import _start_watchdog
    watchdog = _start_watchdog(sys.argv[1])
    log = open(os.path.join(sys.argv[1], "driver.log"), "a")
    print("ready", watchdog.pid, flush=True)
    sys.stdin.readline()
    watchdog.stdin.close()
    print(watchdog.wait(timeout=30), flush=True)
    sys.stdin.readline()
""")


def _start(code: str, *argv) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, "-c", code, *map(str, argv)], text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.stdout.readline().startswith("ready")
    return proc


@pytest.mark.parametrize("end", ["normal", "killed"])
def test_the_watchdog_kills_only_what_holds_a_file_in_its_own_folder(tmp_path, end):
    folder = tmp_path / "pslog-ray-abc"
    sibling = tmp_path / "pslog-ray-abcd"  # (the folder's name and more: not inside it)
    folder.mkdir()
    sibling.mkdir()
    batch = _start(_BATCH, folder)
    inside = _start(_HOLDER, folder / "agent.log")
    beside = _start(_HOLDER, sibling / "agent.log")
    shared = _start(_HOLDER, tmp_path / "user.log")
    try:
        if end == "normal":
            batch.stdin.write("\n")
            batch.stdin.flush()
            assert batch.stdout.readline().strip() == "0"  # (the watchdog's exit code)
            assert batch.poll() is None  # the batch itself, holding its log, not killed
        else:
            batch.send_signal(signal.SIGKILL)
            batch.wait(timeout=10)
        assert inside.wait(timeout=20) == -signal.SIGKILL
        for proc in (beside, shared):
            assert proc.poll() is None
        deadline = time.monotonic() + 10  # (the watchdog removes it after its kills)
        while folder.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not folder.exists()
        assert (sibling / "agent.log").exists()
        if end == "normal":
            batch.stdin.write("\n")
            batch.stdin.flush()
            assert batch.wait(timeout=10) == 0
    finally:
        for proc in (batch, inside, beside, shared):
            if proc.poll() is None:
                proc.kill()
            proc.wait()
