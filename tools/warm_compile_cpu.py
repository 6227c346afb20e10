"""CPU seconds numba spends compiling each of pslog's kernels in ``python -m pslog.warm``.

Runs warm's two parts (:mod:`pslog.warm`) one after the other in this process, with the
``NUMBA_CACHE_DIR`` of the environment (give it an empty folder for a cold compile: nothing
is loaded from a cache then), and times each ``Dispatcher.compile`` on its own thread's CPU
clock, exclusive of the functions it compiled meanwhile (a kernel's compiled callees are
counted as theirs; ``inline=True`` helpers are not compiled on their own: their cost is
their callers'). Prints each part's CPU and its most costly compiles.

Run: ``NUMBA_CACHE_DIR=$(mktemp -d) python tools/warm_compile_cpu.py [--top N]``
"""

from __future__ import annotations

import argparse
import threading
import time
from collections import defaultdict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--top", type=int, default=14)
    top = parser.parse_args().top

    from numba.core import dispatcher

    local, exclusive = threading.local(), defaultdict(float)
    original = dispatcher.Dispatcher.compile

    def compile(self, sig):  # (numba's own method, timed)
        stack = local.__dict__.setdefault("stack", [])
        name = f"{self.py_func.__module__}.{self.py_func.__qualname__}"
        start = time.thread_time()
        stack.append([name, 0.0])
        try:
            return original(self, sig)
        finally:
            _, inner = stack.pop()
            total = time.thread_time() - start
            exclusive[name] += total - inner
            if stack:
                stack[-1][1] += total

    dispatcher.Dispatcher.compile = compile
    from pslog import warm

    for part in ("_first_part", "_second_part"):
        exclusive.clear()
        start = time.process_time()
        getattr(warm, part)()
        took = time.process_time() - start
        print(f"== warm.{part}: {took:.1f} CPU s, {sum(exclusive.values()):.1f} compiling")
        for name, seconds in sorted(exclusive.items(), key=lambda kv: -kv[1])[:top]:
            print(f"  {seconds:6.1f}  {name}")


if __name__ == "__main__":
    main()
