"""A pytest plugin: the CPU seconds each test file costs, its subprocesses included.

Around each test (setup, call and teardown: a module's fixtures fall on its first and last
test) it reads ``resource.getrusage`` for the test process and for its waited-for children
(``RUSAGE_CHILDREN``: every ``pslog`` command a test ran and waited for), and adds user +
system time to the test's file. At the end each test process appends one JSON line per file
to the file named by ``PSLOG_CPU_LOG`` (default ``cpu-per-file.jsonl``): ``{"file", "tests",
"self_s", "children_s", "wall_s"}``; with pytest-xdist, one line per file and worker.
Summarise: ``python tools/cpu_per_file.py [LOG]`` (files by CPU, most first).

Not counted: a child still running when its test ends (not waited for), collection, and
processes the tests did not start (numba's cache, another worker). Use:

    PYTHONPATH=tools python -m pytest -p cpu_per_file tests/...
"""

from __future__ import annotations

import json
import os
import resource
import sys
import time
from collections import defaultdict

import pytest

_TOTALS: dict[str, list[float]] = defaultdict(lambda: [0, 0.0, 0.0, 0.0])


def _cpu(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    own, children, wall = (_cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN),
                           time.monotonic())
    yield
    total = _TOTALS[item.nodeid.split("::")[0]]
    total[0] += 1
    total[1] += _cpu(resource.RUSAGE_SELF) - own
    total[2] += _cpu(resource.RUSAGE_CHILDREN) - children
    total[3] += time.monotonic() - wall


def pytest_sessionfinish(session):
    if not _TOTALS:
        return
    lines = "".join(json.dumps({"file": f, "tests": t[0], "self_s": round(t[1], 2),
                                "children_s": round(t[2], 2), "wall_s": round(t[3], 1)}) + "\n"
                    for f, t in _TOTALS.items())
    with open(os.environ.get("PSLOG_CPU_LOG", "cpu-per-file.jsonl"), "a") as log:
        log.write(lines)


def main(path: str) -> None:
    files: dict[str, list[float]] = defaultdict(lambda: [0, 0.0, 0.0, 0.0])
    with open(path) as log:
        for line in log:
            row = json.loads(line)
            total = files[row["file"]]
            for i, key in enumerate(("tests", "self_s", "children_s", "wall_s")):
                total[i] += row[key]
    print(f"{'CPU s':>8} {'self':>7} {'children':>8} {'wall s':>7} {'tests':>5}  file")
    for name, (tests, own, children, wall) in sorted(
            files.items(), key=lambda kv: -(kv[1][1] + kv[1][2])):
        print(f"{own + children:8.1f} {own:7.1f} {children:8.1f} {wall:7.1f} {tests:5.0f}  {name}")
    print(f"{sum(t[1] + t[2] for t in files.values()):8.1f} in all")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "cpu-per-file.jsonl")
