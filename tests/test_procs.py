"""tests/_procs.py, the hang guards' view of a command's processes: the processes below one
found from the kernel's ``children`` files, or, where a sandbox's /proc has none, by the
parent pid in every ``/proc/*/stat`` (the same processes either way), and its blocked time."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from _procs import descendants

# a parent with two children, one of which has a child of its own; the grandchild renames
# itself with spaces and parentheses (what /proc/PID/stat's name field may hold), then all
# say they are ready on stdout and wait for stdin to close
TREE = r"""
import subprocess, sys
role, code = sys.argv[1], sys.argv[2]
if role == "leaf":
    with open("/proc/self/comm", "w") as f:
        f.write("a) (b c")
    print("ready", flush=True)
    sys.stdin.read()
    raise SystemExit
kids = [subprocess.Popen([sys.executable, "-c", code, r, code], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
        for r in (["leaf", "mid"] if role == "top" else ["leaf"])]
for k in kids:
    k.stdout.readline()
print(" ".join(str(k.pid) for k in kids), flush=True)
sys.stdin.read()
for k in kids:
    k.stdin.close()
    k.wait()
"""


def test_descendants_from_children_files_and_from_a_scan_of_proc():
    top = subprocess.Popen([sys.executable, "-c", TREE, "top", TREE], stdin=subprocess.PIPE,
                           stdout=subprocess.PIPE, text=True)
    try:
        leaf, mid = (int(p) for p in top.stdout.readline().split())
        below = set(descendants(top.pid))
        # mid's own leaf: the one process below mid
        (grand,) = descendants(mid)
        assert below == {leaf, mid, grand}
        assert set(descendants(top.pid, scan=True)) == below
        assert descendants(mid, scan=True) == [grand]
        assert descendants(leaf) == descendants(leaf, scan=True) == []
        with open(f"/proc/{grand}/comm") as f:
            assert f.read().strip() == "a) (b c"  # (the name a scan must read past)
    finally:
        top.stdin.close()
        top.wait(30)


def test_blocked_time_is_the_sleep_not_the_work():
    """A process that sleeps 0.6 s, then computes about as long, reads its own blocked time:
    the sleep, not the computation nor its waits for a core (whatever the machine's load)."""
    if not Path("/proc/self/schedstat").exists():
        pytest.skip("this kernel has no /proc/PID/schedstat (blocked_s is None there)")
    # (the blocked time across the sleep and the computation only: the interpreter's start,
    # which may wait on the disk, is not in it)
    code = ("import os, sys, time; sys.path.insert(0, sys.argv[1]); from _procs import blocked_s;"
            "b = blocked_s(os.getpid()); time.sleep(0.6); t = time.thread_time(); n = 0\n"
            "while time.thread_time() - t < 0.6: n += 1\n"
            "print(blocked_s(os.getpid()) - b)")
    done = subprocess.run([sys.executable, "-c", code, str(Path(__file__).parent)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    # the sleep, within the accounting's own error: under CI's load one run read 0.584 s
    # (the scheduler's run/wait clocks against CLOCK_BOOTTIME); the computation counted
    # would read >= 1.2 s, the sleep missed ~0
    assert 0.5 <= float(done.stdout) < 0.8
