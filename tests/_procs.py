"""Processes of a test's command: the ones below it, and the CPU time they use (a hang guard
that tells a loaded machine from a hung command: a slowed command still uses CPU)."""

from __future__ import annotations

import os
from pathlib import Path


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (its camera processes, multiprocessing's resource tracker)."""
    found, todo = [], [pid]
    while todo:
        parent = todo.pop()
        for task in Path(f"/proc/{parent}/task").glob("*"):
            try:
                children = [int(c) for c in (task / "children").read_text().split()]
            except (OSError, ValueError):
                continue
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
