"""Several fusion methods at once, on threads, with the results of running them in turn.

:func:`pslog.fusion.gating.fuse_detections` fuses every method a command asks for from one
session. The methods are independent given their input (the gated observations and their
:class:`~pslog.fusion.Prepared` rays, shared by the methods that need the same gating form),
and their heavy work runs where Python's GIL is released (pslog's numba kernels are compiled
``nogil``; numpy releases it in its large array operations), so on a machine with two cores
two methods fuse at the same time: the default methods of a 90-minute session (``smooth`` on
one core; gating, ``filter``, ``typeA`` and ``nearest`` on the other) take the time of the
longest chain instead of the sum.

The outcome does not depend on the scheduling:

- each method's track is computed by the same code from the same inputs as when the methods
  run in turn (a method reads its shared input and never writes it), so it is the same bit
  for bit; the results are returned in the order the methods were asked for;
- an input shared by several methods (one gating form) is computed once, by the first
  method that needs it, while the others wait for it; it is dropped once the last method
  that needs it is done (a 90-minute match's columns are hundreds of MB);
- when methods fail, the error raised is that of the first failing method in the asked
  order, as running them in turn would raise: after a failure no method later in that order
  starts, the earlier ones still run (one of them may fail too, and its error comes first);
- the workers are daemon threads and the calling thread only waits: a Ctrl-C or SIGTERM
  (raised in the main thread) interrupts at once, no method starts after it, and a method
  already running cannot delay the process's exit.

``workers=1`` runs the methods in turn on the calling thread (``pslog fuse --workers 1``).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Hashable, Sequence
from functools import partial
from typing import Any

#: the methods' relative cost: CPU seconds of each on the 90-minute three-camera type-A
#: session of benchmarks/bench_match.py (its gating excluded; sync, typeB and linear, which
#: do not suit it, guessed from nearest's numpy work). The costliest start first, so that
#: the longest chain runs beside the others instead of after them (a scheduling hint only:
#: the results do not depend on it)
COST = {"smooth": 9.0, "nearest": 1.7, "sync": 1.5, "typeB": 2.0, "linear": 2.0,
        "typeA": 1.0, "filter": 0.8}


_UNSET = object()


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS tells it)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this OS
        return max(1, os.cpu_count() or 1)


def default_workers(n_methods: int) -> int:
    """Threads for ``n_methods`` methods: the usable cores, at most one per method."""
    return max(1, min(usable_cores(), n_methods))


class _Shared:
    """One input shared by the methods of a key: made once, dropped after its last use."""

    def __init__(self, uses: int) -> None:
        self.lock = threading.Lock()  # held while it is made: the others wait for it
        self.made = False
        self.value: Any = None
        self.error: BaseException | None = None
        self.uses = uses

    def get(self, make: Callable[[], Any]) -> Any:
        with self.lock:
            if not self.made:
                try:
                    self.value = make()
                except BaseException as exc:  # every method of the key fails with it
                    self.error = exc
                self.made = True
            if self.error is not None:
                raise self.error
            return self.value

    def release(self) -> None:
        with self.lock:
            self.uses -= 1
            if self.uses == 0:
                self.value = None


def run_methods(
    methods: Sequence[str], keys: Sequence[Hashable], make: Callable[[Hashable, str], Any],
    run: Callable[[str, Any], Any], workers: int, started: Callable[[str], None] | None = None,
    finished: Callable[[str], None] | None = None,
) -> list[Any]:
    """``[run(m, make(key_m, m)) for m in methods]``, on ``workers`` threads.

    Parameters
    ----------
    methods : the method names, in the order the results are returned (and errors ranked)
    keys : (len(methods),) the key of each method's shared input; ``make(key, method)``
        makes it once per key (called for the first method of the key that starts)
    make : ``make(key, method) -> input`` shared by the methods of ``key``
    run : ``run(method, input) -> result``
    workers : threads; 1 runs every method in turn on the calling thread
    started : ``started(method)`` called as each method starts (progress)
    finished : ``finished(method)`` called as each method ends (progress)

    Returns
    -------
    list, the results in ``methods`` order
    """
    n = len(methods)
    uses: dict[Hashable, int] = {}
    for key in keys:
        uses[key] = uses.get(key, 0) + 1
    shared = {key: _Shared(count) for key, count in uses.items()}
    results: list[Any] = [None] * n
    if workers <= 1 or n <= 1:
        for i, (method, key) in enumerate(zip(methods, keys, strict=True)):
            if started is not None:
                started(method)
            results[i] = run(method, shared[key].get(partial(make, key, method)))
            shared[key].release()  # the last method of its key: its arrays go
            if finished is not None:
                finished(method)
        return results

    results = [_UNSET] * n  # a thread's result, or still _UNSET if it never got there
    # costliest first; ties in the asked order
    order = sorted(range(n), key=lambda i: -COST.get(methods[i], 1.0))
    lock = threading.Lock()
    state = {"next": 0, "limit": n, "stopped": False, "running": 0}
    errors: dict[int, BaseException] = {}
    done = threading.Event()

    def take() -> int | None:
        with lock:
            while state["next"] < n and not state["stopped"]:
                i = order[state["next"]]
                state["next"] += 1
                if i < state["limit"]:  # not after a failed method in the asked order
                    return i
            return None

    def worker() -> None:
        try:
            while (i := take()) is not None:
                method, key = methods[i], keys[i]
                try:
                    if started is not None:
                        started(method)
                    value = shared[key].get(partial(make, key, method))
                    results[i] = run(method, value)
                    del value
                except BaseException as exc:  # raised by the caller's thread, ranked
                    with lock:
                        errors[i] = exc
                        state["limit"] = min(state["limit"], i)
                finally:
                    shared[key].release()
                    if finished is not None:
                        finished(method)
        finally:
            with lock:
                state["running"] -= 1
                if state["running"] == 0:
                    done.set()

    threads = []
    try:
        for j in range(min(workers, n)):
            thread = threading.Thread(target=worker, name=f"pslog-fuse-{j}", daemon=True)
            with lock:
                state["running"] += 1
            try:
                thread.start()  # RuntimeError when its stack cannot be had (out of memory)
            except BaseException:
                with lock:
                    state["running"] -= 1
                raise
            threads.append(thread)
        # interruptible: a Ctrl-C or SIGTERM is raised here, in the main thread; a thread that
        # died before its ``finally`` (out of memory in its start-up) must not hang the wait
        while not done.wait(0.25):
            if not any(thread.is_alive() for thread in threads):
                break
    except BaseException:
        with lock:
            state["stopped"] = True  # no method starts after an interrupt or a failed start
        raise
    if errors:
        # out of memory in one thread makes others fail in odd ways (a module half imported):
        # the MemoryError is the one to report
        memory = [i for i, exc in errors.items() if isinstance(exc, MemoryError)]
        raise errors[min(memory or errors)]
    if any(result is _UNSET for result in results):  # a thread died without a word
        raise MemoryError("a fusion thread ended before its method finished")
    return results


class MethodProgress:
    """The command's progress (:mod:`pslog.progress`) while methods fuse, at once or in
    turn: one step per method, named by the methods running (``fusing smooth, typeA``, in
    the asked order), each counted complete when it ends; the last one when the command's
    next step begins, as :func:`pslog.progress.step` counts a step done."""

    def __init__(self, methods: Sequence[str]) -> None:
        self.methods = list(methods)
        self.running: list[str] = []
        self.left = len(self.methods)
        self.begun = False
        self.lock = threading.Lock()

    def _what(self) -> str | None:
        names = [m for m in self.methods if m in self.running]
        return f"fusing {', '.join(names)}" if names else None

    def started(self, method: str) -> None:
        from .. import progress

        with self.lock:
            self.running.append(method)
            if not self.begun:  # the step before (reading) is complete
                self.begun = True
                progress.step(self._what() or "")
            else:
                progress.update(what=self._what())

    def finished(self, method: str) -> None:
        from .. import progress

        with self.lock:
            self.running.remove(method)
            self.left -= 1
            if self.left:  # (the last one: when the command's next step begins)
                progress.update(advance=1.0, what=self._what())
