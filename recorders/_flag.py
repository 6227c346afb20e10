"""A stop/start flag that camera processes share with their parent, without a lock.

``multiprocessing.Event`` guards its state with a lock that every ``is_set()`` takes: a
camera process killed (SIGKILL, the OOM killer) while inside ``is_set()`` never releases it,
and every other camera process and the parent then block for ever in their own next
``is_set()`` -- one dead camera silently stopped them all (seen in ``pslog live``: the killed
camera was never reported, the others went silent). A flag is one shared byte here: its
reads and writes are single stores, which no process can leave half done, so a process dying
at any instruction leaves the others running.
"""

from __future__ import annotations

import time

_POLL_S = 0.002  # how often wait() looks at the flag: a start or a stop is seen within it


class ProcessFlag:
    """A flag set once by one process and read by others (spawned ``Process`` arguments).

    Parameters
    ----------
    ctx : a multiprocessing context (the flag's shared byte is made in its shared memory)
    """

    def __init__(self, ctx) -> None:
        self._byte = ctx.RawValue("b", 0)

    def set(self) -> None:
        self._byte.value = 1

    def is_set(self) -> bool:
        return bool(self._byte.value)

    def wait(self, timeout: float | None = None) -> bool:
        """Until the flag is set or ``timeout`` seconds passed (``None``: no limit);
        returns whether it is set."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while not self._byte.value:
            if deadline is None:
                time.sleep(_POLL_S)
                continue
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            time.sleep(min(_POLL_S, left))
        return True


def settled(value, stop: ProcessFlag) -> int:
    """A shared integer the parent writes once just before it sets the start flag (the session
    clock's origin), read by a camera once the flag is set: waits until it is nonzero (or the
    stop flag is set). Without a lock nothing orders the two stores for another core: x86 keeps
    their order, a weaker memory model (ARM) may show the flag first."""
    while not value.value and not stop.is_set():
        time.sleep(_POLL_S)
    return int(value.value)
