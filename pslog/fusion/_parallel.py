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
  a failure that makes other threads fail in odd ways is the one raised: a MemoryError, or
  a :class:`~pslog.errors.PslogError` when the first error is an ``ImportError`` (a kernel
  module whose import failed in one thread, numba refusing to start, is half imported to
  another thread importing it at once);
- the workers are daemon threads and the calling thread only waits: a Ctrl-C or SIGTERM
  (raised in the main thread) interrupts at once, no method starts after it, and a method
  already running cannot delay the process's exit.

``workers=1`` runs the methods in turn on the calling thread (``pslog fuse --workers 1``).

:class:`MethodRun` hands each result to the calling thread as its method ends (``pslog
fuse`` writes each track then, in :func:`finishing_order`, while the other methods still
fuse: the write, once a serial 2.8 s after the fusion of a 90-minute match, overlaps it).
"""

from __future__ import annotations

import os
import queue
import threading
from collections.abc import Callable, Hashable, Iterator, Sequence
from functools import partial
from typing import Any

from ..errors import PslogError

#: the methods' relative cost: thread CPU seconds of each on the 90-minute three-camera
#: type-A session of benchmarks/bench_match.py (its gating excluded; benchmarks/
#: fuse_timeline.py, session 39: smooth 3.38, filter 1.51, typeA 1.28, nearest 1.06; sync,
#: typeB and linear, which do not suit it, guessed from nearest's numpy work). A scheduling
#: hint only: the results do not depend on it, the time to the written file does
#: (:func:`start_order`, :func:`finishing_order`)
COST = {"smooth": 3.4, "filter": 1.5, "typeA": 1.3, "typeB": 1.2, "linear": 1.2,
        "nearest": 1.05, "sync": 1.0}


_UNSET = object()


def finishing_order(methods: Sequence[str]) -> list[str]:
    """``methods`` in the order they are expected to end: the cheapest first (:data:`COST`;
    ties in the asked order), as :func:`start_order` starts them. ``pslog fuse`` writes the
    tracks in this order, each as soon as it and those before it have ended: the file's
    layout is then the same whatever the scheduling and the number of threads (the same
    command writes the same bytes), and the costliest method's track, written last, is the
    only one written after the fusion."""
    return sorted(methods, key=lambda m: COST.get(m, 1.0))


def start_order(methods: Sequence[str], workers: int) -> list[int]:
    """The places in ``methods`` in the order threads take them: on two threads or more the
    costliest first (the longest chain runs beside the others instead of after them), then
    the rest cheapest first, so that they end in :func:`finishing_order` and each track is
    written while the others still fuse; on one thread cheapest first. (Session 39: the
    costliest first and then the rest costliest first had ``filter``, the first track to
    write, end last: every track of a default 90-minute ``pslog fuse`` was written after
    the fusion, 1.9 s of its 8.4 with the cores half idle.)"""
    ascending = sorted(range(len(methods)), key=lambda i: COST.get(methods[i], 1.0))
    if workers < 2 or len(ascending) < 2:
        return ascending
    first = max(ascending, key=lambda i: COST.get(methods[i], 1.0))  # (ties: the first)
    return [first] + [i for i in ascending if i != first]


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
    results: list[Any] = [None] * len(methods)
    for i, result in MethodRun(methods, keys, make, run, workers, started, finished):
        results[i] = result
    return results


class MethodRun:
    """The methods of :func:`run_methods` started at once (on ``workers`` threads, from the
    constructor on), their results delivered to the calling thread as each method ends:
    iterating gives ``(i, result)`` pairs, ``i`` the method's place in ``methods``, in the
    order the methods end (with one worker, or ``workers=1`` in turn on the calling
    thread as it iterates: the asked order). ``pslog fuse`` writes each track meanwhile.

    The results are those of running the methods in turn (see the module); the errors
    too: once a method failed no further result is delivered, and the iteration raises,
    when every method still running has ended, the error :func:`run_methods` raises (the
    first failing method's in the asked order). An interrupt in the iterating thread (or
    the iteration abandoned) stops every method that has not started. ``background``: on
    a thread even with one worker (or one method), the calling thread free meanwhile."""

    def __init__(
        self, methods: Sequence[str], keys: Sequence[Hashable],
        make: Callable[[Hashable, str], Any], run: Callable[[str, Any], Any], workers: int,
        started: Callable[[str], None] | None = None,
        finished: Callable[[str], None] | None = None, background: bool = False,
    ) -> None:
        self.methods, self.keys, self.make, self.run = list(methods), list(keys), make, run
        self.started, self.finished = started, finished
        n = len(self.methods)
        uses: dict[Hashable, int] = {}
        for key in self.keys:
            uses[key] = uses.get(key, 0) + 1
        self.shared = {key: _Shared(count) for key, count in uses.items()}
        # background: one worker thread even for one method or one worker (the caller's
        # thread meanwhile free: pslog fuse copies the session into its output)
        self.in_turn = (workers <= 1 or n <= 1) and not background
        self.results: list[Any] = [_UNSET] * n  # a thread's result, or _UNSET
        self.errors: dict[int, BaseException] = {}
        self.lock = threading.Lock()
        self.state = {"next": 0, "limit": n, "stopped": False, "running": 0}
        # a method's place as it ends (None: every worker has ended)
        self.ended: queue.SimpleQueue[int | None] = queue.SimpleQueue()
        self.threads: list[threading.Thread] = []
        if self.in_turn:
            return
        self.order = start_order(self.methods, workers)
        # the packages numba's first import shares with the rest imported here first: the
        # threads may import numba while another imports one of them (pslog._jit)
        from .._jit import settle_imports

        settle_imports()
        try:
            for j in range(min(workers, n)):
                thread = threading.Thread(target=self._worker, name=f"pslog-fuse-{j}",
                                          daemon=True)
                with self.lock:
                    self.state["running"] += 1
                try:
                    thread.start()  # RuntimeError when its stack cannot be had (out of memory)
                except BaseException:
                    with self.lock:
                        self.state["running"] -= 1
                        if self.state["running"] == 0:
                            self.ended.put(None)
                    raise
                self.threads.append(thread)
        except BaseException:
            self.stop()
            raise

    def stop(self) -> None:
        """No method starts after this (an interrupt, a failed start, an abandoned run)."""
        with self.lock:
            self.state["stopped"] = True

    def _take(self) -> int | None:
        with self.lock:
            state = self.state
            while state["next"] < len(self.methods) and not state["stopped"]:
                i = self.order[state["next"]]
                state["next"] += 1
                if i < state["limit"]:  # not after a failed method in the asked order
                    return i
            return None

    def _worker(self) -> None:
        try:
            while (i := self._take()) is not None:
                method, key = self.methods[i], self.keys[i]
                try:
                    if self.started is not None:
                        self.started(method)
                    value = self.shared[key].get(partial(self.make, key, method))
                    self.results[i] = self.run(method, value)
                    del value
                except BaseException as exc:  # raised by the caller's thread, ranked
                    with self.lock:
                        self.errors[i] = exc
                        self.state["limit"] = min(self.state["limit"], i)
                finally:
                    self.shared[key].release()
                    if self.finished is not None:
                        self.finished(method)
                    self.ended.put(i)
        finally:
            with self.lock:
                self.state["running"] -= 1
                if self.state["running"] == 0:
                    self.ended.put(None)

    def __iter__(self) -> Iterator[tuple[int, Any]]:
        if self.in_turn:
            yield from self._in_turn()
            return
        complete = False
        try:
            while True:
                # interruptible: a Ctrl-C or SIGTERM is raised here, in the main thread; a
                # thread that died before its ``finally`` (out of memory in its start-up)
                # must not hang the wait
                try:
                    i = self.ended.get(timeout=0.25)
                except queue.Empty:
                    if any(thread.is_alive() for thread in self.threads):
                        continue
                    # every thread has ended, perhaps after the wait timed out and before
                    # the check: what they queued meanwhile is still to be delivered
                    try:
                        i = self.ended.get_nowait()
                    except queue.Empty:
                        break
                if i is None:
                    break
                with self.lock:
                    failed = bool(self.errors)
                result = self.results[i]
                if failed or result is _UNSET:
                    continue  # after a failure: no result is delivered any more
                self.results[i] = None  # delivered: held by the caller only
                yield i, result
                del result
            complete = True
        finally:
            if not complete:
                self.stop()  # no method starts after an interrupt or an abandoned run
        if self.errors:
            # out of memory in one thread makes others fail in odd ways (a module half
            # imported): the MemoryError is the one to report
            memory = [i for i, exc in self.errors.items() if isinstance(exc, MemoryError)]
            first = min(memory or self.errors)
            # a kernel module whose import failed in one thread (numba refusing to start:
            # NUMBA_NUM_THREADS=0, said as a PslogError) is a half-imported module to another
            # thread importing it at once ("cannot import name ...", a traceback): the
            # failure's own error is the one to report
            said = [i for i, exc in self.errors.items() if isinstance(exc, PslogError)]
            if isinstance(self.errors[first], ImportError) and said:
                first = min(said)
            raise self.errors[first]
        if any(result is _UNSET for result in self.results):  # a thread died without a word
            raise MemoryError("a fusion thread ended before its method finished")

    def _in_turn(self) -> Iterator[tuple[int, Any]]:
        for i, (method, key) in enumerate(zip(self.methods, self.keys, strict=True)):
            if self.started is not None:
                self.started(method)
            result = self.run(method, self.shared[key].get(partial(self.make, key, method)))
            self.shared[key].release()  # the last method of its key: its arrays go
            if self.finished is not None:
                self.finished(method)
            yield i, result
            del result


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
