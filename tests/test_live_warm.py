"""A live run loads its method's compiled kernels before it says it is ready, not behind the
first datagrams (which would wait ~0.3 s loaded, ~30 s compiled, with every datagram queued
meanwhile: the first second of a match lost to latency)."""

from __future__ import annotations

import subprocess
import sys

import pytest

_SCRIPT = """
import sys, threading
from pslog.live.server import serve
from pslog.rig import apply_timing, builtin_rig

method, module = sys.argv[1], sys.argv[2]
rig = apply_timing(builtin_rig("paper2"), "typeA")  # not warm_up's own rig
stop, ready = threading.Event(), threading.Event()
t = threading.Thread(target=serve, args=(rig, "udp://127.0.0.1:0", []),
                     kwargs=dict(method=method, stop=stop, ready=ready, status_stream=None))
t.start()
assert ready.wait(300), "never ready"
mod = sys.modules[module]
kernels = [f for f in vars(mod).values() if hasattr(f, "py_func") and hasattr(f, "signatures")]
loaded = [f.py_func.__name__ for f in kernels if f.signatures]
stop.set()
t.join()
print(len(kernels), len(loaded))
"""


@pytest.mark.parametrize("method, module", [("filter", "pslog.fusion.filter"),
                                            ("typeA", "pslog.fusion._pseudo_kernel")])
def test_kernels_are_loaded_before_ready(method, module):
    run = subprocess.run([sys.executable, "-c", _SCRIPT, method, module], capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    n_kernels, n_loaded = map(int, run.stdout.split())
    assert n_kernels > 0
    # the kernels a stream runs (not every one: a module also holds batch-only kernels)
    assert n_loaded >= min(n_kernels, 3), run.stdout
