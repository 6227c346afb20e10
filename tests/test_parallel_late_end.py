"""pslog.fusion._parallel: a method that ends while the iterating thread's wait times out.

The iteration waits for each ending method (0.25 s at a time, to stay interruptible) and,
on a timeout, stops when no fusion thread is alive any more. A thread that queued its method
and ended between the timeout and that check left its result undelivered: the iteration
ended without it and ``fuse_detections`` raised ``KeyError: 'smooth'`` (``bench_dirty.py
--more`` on a machine at load 18, session 13). The interleaving is made here: the queue's
timed wait lets every thread end, then times out.
"""

from __future__ import annotations

import queue
import threading

from pslog.fusion._parallel import MethodRun


class _EndsDuringTheWait(queue.SimpleQueue):
    """The first timed wait: every fusion thread ends (queuing what it queues), then the
    wait times out as if they had ended just after it."""

    def __init__(self) -> None:
        super().__init__()
        self.threads: list[threading.Thread] = []
        self.timed_out = False

    def get(self, block=True, timeout=None):
        if timeout is not None and not self.timed_out:
            self.timed_out = True
            for thread in self.threads:
                thread.join()
            raise queue.Empty
        return super().get(block, timeout)


def test_a_result_queued_as_the_wait_times_out_is_delivered():
    go = threading.Event()

    def run(method, value):
        go.wait()
        return method.upper()

    methods = ["smooth", "typeA"]
    fused = MethodRun(methods, methods, lambda key, method: None, run, workers=2)
    late = _EndsDuringTheWait()
    late.threads = fused.threads
    fused.ended = late  # (the threads wait for ``go``: nothing is queued yet)
    go.set()
    got = {i: result for i, result in fused}
    assert got == {0: "SMOOTH", 1: "TYPEA"}
