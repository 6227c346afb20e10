"""Processes of a test's command: the ones below it, and the CPU time they use (a hang guard
that tells a loaded machine from a hung command: a slowed command still uses CPU), and the
time it spent blocked (neither on a core nor waiting for one)."""

from __future__ import annotations

import os
import time
from pathlib import Path


def _children_files(pid: int) -> list[int] | None:
    """``pid``'s children from ``/proc/PID/task/*/children`` (every thread's), or None
    where the kernel does not give that file (built without CONFIG_PROC_CHILDREN, or a
    sandbox's /proc without it)."""
    tasks = list(Path(f"/proc/{pid}/task").glob("*"))
    if not tasks or not (tasks[0] / "children").exists():
        return None if tasks else []
    children = []
    for task in tasks:
        try:
            children += [int(c) for c in (task / "children").read_text().split()]
        except (OSError, ValueError):
            continue
    return children


def _parent(stat: str) -> int:
    """The parent pid field of a ``/proc/PID/stat`` line (the name may hold spaces and
    parentheses: the fields after its last ``)``)."""
    return int(stat.rsplit(")", 1)[1].split()[1])


def _children_scan(pid: int, proc: Path = Path("/proc")) -> list[int]:
    """``pid``'s children by scanning every ``/proc/*/stat`` for its parent pid (what
    ``children`` files give, where they are absent)."""
    children = []
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if _parent((entry / "stat").read_text()) == pid:
                children.append(int(entry.name))
        except (OSError, ValueError, IndexError):
            continue  # (gone meanwhile)
    return children


def descendants(pid: int, *, scan: bool = False) -> list[int]:
    """Every process below ``pid`` (its camera processes, multiprocessing's resource tracker).
    From the kernel's ``/proc/PID/task/*/children`` files; where those are absent (``scan``
    forces it), from the parent pid of every process in ``/proc/*/stat``."""
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        children = None if scan else _children_files(parent)
        if children is None:
            children = _children_scan(parent)
        found.extend(children)
        todo.extend(children)
    return found


def cpu_s(pid: int) -> float:
    """CPU seconds (user and system) used so far by ``pid`` and the processes below it that
    still run (a finished one's are its parent's once waited for)."""
    ticks = 0
    for member in [pid, *descendants(pid)]:
        try:
            with open(f"/proc/{member}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        ticks += int(fields[11]) + int(fields[12]) + int(fields[13]) + int(fields[14])
    return ticks / os.sysconf("SC_CLK_TCK")


def blocked_s(pid: int) -> float | None:
    """Seconds ``pid``'s main thread has spent blocked so far (asleep, waiting on a socket,
    a lock, a child): its age less its time on a core and its time waiting for one
    (``/proc/PID/schedstat``), so what a loaded machine adds to a command's length is not
    in it. None when it is gone or the kernel does not say."""
    try:
        with open(f"/proc/{pid}/schedstat") as f:
            on_cpu, waiting = (int(v) for v in f.read().split()[:2])
        with open(f"/proc/{pid}/stat") as f:
            started = int(f.read().rsplit(")", 1)[1].split()[19])
    except (OSError, ValueError, IndexError):
        return None
    age = time.clock_gettime(time.CLOCK_BOOTTIME) - started / os.sysconf("SC_CLK_TCK")
    return max(0.0, age - (on_cpu + waiting) / 1e9)
