"""One compiled signature per kernel whatever the caller: the batch fuse, the streaming forms
one detection or several rows a push, and the library's callers with arrays of their own
(writable or read-only) give type A's and the filter's kernels arguments of the same types.

numba compiles a kernel once per signature (array dtypes, layouts, read-only or not), then
loads it from its cache; ``python -m pslog.warm`` compiles the signatures the commands use.
A second signature of type A's kernel (~20 CPU s) or the filter's loop was compiled again in
every fresh process that met it (tests, ``pslog live``), so the stream hands its kernels
read-only, contiguous columns, as a batch run's Observations hold them."""

import subprocess
import sys

_SCRIPT = """
import numpy as np
from pslog.fusion import FusionOptions, fuse
from pslog.fusion import _pseudo_kernel, filter as filter_module
from pslog.fusion.stream import StreamFuser
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate
from pslog.timing import observations as timed_observations
from pslog.motion import rally_motion

rig = apply_timing(builtin_rig("paper3"), "typeA")
detections, _ = simulate(rig, rally_motion(seed=1, duration=1.0), 1.0,
                         SimulationOptions(noise_px=0.3, seed=2))
obs = timed_observations(detections, rig)
for method in ("typeA", "filter"):
    fuse(obs, rig, method, FusionOptions(gating=False))  # read-only columns
    one, rows = StreamFuser(rig, method), StreamFuser(rig, method)
    for i in range(len(obs)):  # one detection a push: Python scalars
        one.push(int(obs.time_ns[i]), int(obs.camera[i]), obs.uv[i])
    for i in range(0, len(obs) - 3, 3):  # three rows a push: writable arrays of the caller
        rows.push(obs.time_ns[i:i + 3].copy(), obs.camera[i:i + 3].copy(), obs.uv[i:i + 3].copy())
    one.flush(), rows.flush()
for k in (_pseudo_kernel.type_a_kernel, _pseudo_kernel.brackets_kernel, filter_module._run):
    print(k.py_func.__name__, len(k.signatures))
"""


def test_batch_and_streams_call_each_kernel_in_one_signature():
    run = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stderr
    counts = dict(line.split() for line in run.stdout.splitlines())
    assert counts == {"type_a_kernel": "1", "brackets_kernel": "1", "_run": "1"}


_GATE_PRELOAD = """
from pslog.fusion import _gate_kernel
from pslog.fusion.gating import gate
from pslog.motion import rally_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

names = ("points_all", "support_all", "lags_camera", "static_camera")
_gate_kernel._preload()  # as pslog fuse's preload thread runs it (its errors unseen there)
print(*(len(getattr(_gate_kernel, k).signatures) for k in names))
rig = apply_timing(builtin_rig("paper3"), "typeA")
detections, _ = simulate(rig, rally_motion(seed=1, duration=1.0), 1.0,
                         SimulationOptions(noise_px=0.3, seed=2, spurious_rate=0.2))
for causal in (True, False):
    gate(detections, rig, causal=causal)  # the batch gate's compiled kernels (loaded)
print(*(len(getattr(_gate_kernel, k).signatures) for k in names))
"""


def test_gate_preload_loads_the_batch_gates_kernels_in_their_signatures():
    # pslog fuse's preload thread loads the gate's kernels while the session is read; a
    # call that does not match a kernel's arguments raised there unseen (static_camera
    # was then loaded on the gate's way) or would compile a signature no gate uses
    run = subprocess.run([sys.executable, "-c", _GATE_PRELOAD], capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == ["1 1 1 1", "1 1 1 1"]


_FILTER_PRELOAD = """
from pslog.fusion import FusionOptions, fuse
from pslog.fusion import filter as filter_module
from pslog.motion import rally_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate
from pslog.timing import observations

names = ("_run", "_window_fit", "_turn_window_fit", "_pixel_rows", "_combined_point",
         "_point", "_withheld", "_lengths", "_kept_columns")
filter_module._preload()  # as pslog fuse's preload thread runs it (its errors unseen there)
print(*(len(getattr(filter_module, k).signatures) for k in names))
rig = apply_timing(builtin_rig("paper3"), "typeA")
detections, _ = simulate(rig, rally_motion(seed=1, duration=3.0), 3.0,
                         SimulationOptions(noise_px=0.3, seed=2))
fuse(observations(detections, rig), rig, "filter", FusionOptions())  # the batch filter
print(*(len(getattr(filter_module, k).signatures) for k in names))
"""


def test_filter_preload_loads_the_batch_filters_kernels_in_their_signatures():
    # the filter's kernels that Python calls, loaded on pslog fuse's preload thread: a
    # signature that does not match the batch filter's arguments would compile one no run
    # uses (and leave the real one's load on the filter's way)
    run = subprocess.run([sys.executable, "-c", _FILTER_PRELOAD], capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == ["1 1 1 1 1 1 1 1 1", "1 1 1 1 1 1 1 1 1"]


_TYPE_A_PRELOAD = """
from pslog.fusion import FusionOptions, _pseudo_kernel, for_session, fuse
from pslog.motion import rally_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

names = ("type_a_kernel", "brackets_kernel", "bend_rows", "previous_next", "long_gap_kernel",
         "checkpoint_noise_kernel", "residual_norms_kernel", "window_mean_squares_kernel",
         "model_rescale_kernel")
_pseudo_kernel._preload()  # as pslog fuse's preload thread runs it (its errors unseen there)
print(*(len(getattr(_pseudo_kernel, k).signatures) for k in names))
rig = apply_timing(builtin_rig("paper3"), "typeA")
detections, _ = simulate(rig, rally_motion(seed=1, duration=3.0), 3.0,
                         SimulationOptions(noise_px=0.3, seed=2))
fuse(detections, rig, "typeA", for_session(FusionOptions(), {}))  # pslog fuse's type A
print(*(len(getattr(_pseudo_kernel, k).signatures) for k in names))
"""


def test_type_a_preload_loads_the_batch_kernels_in_their_signatures():
    # (session 44) type A's kernels, loaded on pslog fuse's preload thread: a signature
    # that does not match the batch's arguments would compile one no run uses (and leave
    # the real one's load on type A's way)
    run = subprocess.run([sys.executable, "-c", _TYPE_A_PRELOAD], capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0, run.stderr
    preloaded, after = run.stdout.splitlines()
    assert all(int(n) >= 1 for n in preloaded.split())
    assert after == preloaded
