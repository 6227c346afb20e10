"""Fusion methods run at once on threads (pslog.fusion._parallel): the same tracks, the same
rejections and the same errors as one after another, whatever the scheduling."""

from __future__ import annotations

import sys
import threading
import time

import numpy as np
import pytest

from pslog.cli import main
from pslog.fusion import METHODS, FusionOptions
from pslog.fusion._parallel import run_methods
from pslog.fusion.gating import fuse_detections
from pslog.log import read_session


@pytest.fixture(scope="module")
def dirty(tmp_path_factory):
    """Four seconds of three type-B cameras (shared and lone instants: every method suits
    them) with spurious blobs."""
    path = tmp_path_factory.mktemp("parallel") / "dirty.mcap"
    assert main(["simulate", "--rig", "paper3", "--timing", "typeB", "--motion", "rally",
                 "--duration", "4", "--noise-px", "0.3", "--spurious", "0.05",
                 "--seed", "4", "-o", str(path)]) == 0
    return path


def _same_track(a, b) -> None:
    assert a.method == b.method
    np.testing.assert_array_equal(a.time_ns, b.time_ns)
    np.testing.assert_array_equal(a.camera, b.camera)
    # bit for bit (NaN where NaN): compare the bytes
    assert a.position_world.tobytes() == b.position_world.tobytes()
    assert sorted(a.quality) == sorted(b.quality)
    for name in a.quality:
        assert np.asarray(a.quality[name]).tobytes() == np.asarray(b.quality[name]).tobytes()
    assert dict(a.dropped) == dict(b.dropped)


@pytest.mark.parametrize("gating", [True, False])
def test_threads_give_the_tracks_of_one_after_another(dirty, gating):
    s = read_session(dirty)
    methods = list(METHODS)  # every method, both gating forms
    options = FusionOptions(gating=gating)
    one, rej_one = fuse_detections(s.detections, s.rig, methods, options, workers=1)
    for workers in (2, 3):
        many, rej_many = fuse_detections(s.detections, s.rig, methods, options,
                                         workers=workers)
        assert list(many) == methods  # in the asked order
        for m in methods:
            _same_track(one[m], many[m])
            for name in ("frame_time_ns", "camera", "frame_index", "uv", "score", "reason"):
                assert (getattr(rej_one[m], name).tobytes()
                        == getattr(rej_many[m], name).tobytes())


def test_cli_workers_write_the_same_tracks(dirty, tmp_path, capsys):
    outs = {}
    for workers in ("1", "2"):
        out = tmp_path / f"fused{workers}.mcap"
        assert main(["fuse", str(dirty), "-o", str(out), "--workers", workers]) == 0
        outs[workers] = read_session(out).tracks
    printed = capsys.readouterr().out.replace("fused2.mcap", "fused1.mcap").splitlines()
    assert printed[: len(printed) // 2] == printed[len(printed) // 2:]  # same summary
    assert list(outs["1"]) == list(outs["2"]) and len(outs["1"]) >= 5
    for m in outs["1"]:
        _same_track(outs["1"][m], outs["2"][m])


@pytest.mark.parametrize("value", ["0", "65", "two"])
def test_cli_workers_out_of_range_is_one_line(dirty, tmp_path, capsys, value):
    with pytest.raises(SystemExit) as stop:
        main(["fuse", str(dirty), "-o", str(tmp_path / "x.mcap"), "--workers", value])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--workers" in err[0], err
    assert not (tmp_path / "x.mcap").exists()


def test_shared_input_made_once_per_key_and_results_in_order():
    made = []
    lock = threading.Lock()

    def make(key, method):
        with lock:
            made.append(key)
        time.sleep(0.01)  # the other methods of the key wait for it
        return {"key": key}

    methods = ["typeA", "smooth", "nearest", "filter", "typeB"]
    keys = ["causal", "offline", "causal", "causal", "wait"]
    out = run_methods(methods, keys, make, lambda m, v: (m, v["key"]), workers=2)
    assert out == list(zip(methods, keys, strict=True))
    assert sorted(made) == ["causal", "offline", "wait"]


@pytest.mark.parametrize("workers", [1, 2, 4])
def test_the_first_failing_method_in_the_asked_order_is_raised(workers):
    """smooth starts first (the costliest) and fails at once; typeA, earlier in the asked
    order, fails later: typeA's error is the one raised, as one after another would."""
    ran = []

    def run(method, value):
        ran.append(method)
        if method == "smooth":
            raise ValueError("smooth failed")
        if method == "typeA":
            time.sleep(0.05)
            raise ValueError("typeA failed")
        return method

    methods = ["nearest", "typeA", "smooth", "filter"]
    with pytest.raises(ValueError, match="typeA failed"):
        run_methods(methods, [0, 0, 1, 0], lambda k, m: None, run, workers=workers)
    assert "nearest" in ran  # before typeA in the asked order: it ran


def test_no_method_starts_after_a_failure_later_in_order_than_it():
    """smooth (second asked, the costliest: started first) fails at once: typeA, asked
    before it, still runs (one after another it would have run first); filter, asked after
    it and not yet started, never starts (one after another would have stopped at smooth)."""
    from pslog.fusion._parallel import start_order

    # the premise: smooth first, then the rest cheapest first (nearest, typeA, filter)
    assert start_order(["typeA", "smooth", "nearest", "filter"], 2) == [1, 2, 0, 3]
    ran = []

    def run(method, value):
        ran.append(method)
        if method == "smooth":
            raise RuntimeError("smooth failed")
        if method == "nearest":
            time.sleep(0.2)
        return method

    with pytest.raises(RuntimeError, match="smooth failed"):
        run_methods(["typeA", "smooth", "nearest", "filter"], [0, 1, 0, 0],
                    lambda k, m: None, run, workers=2)
    assert "typeA" in ran and "filter" not in ran


def test_an_error_making_the_shared_input_fails_every_method_of_its_key():
    def make(key, method):
        if key == "bad":
            raise KeyError("gate failed")
        return key

    with pytest.raises(KeyError, match="gate failed"):
        run_methods(["a", "b", "c"], ["good", "bad", "bad"], make, lambda m, v: v, workers=2)
    assert run_methods(["a", "b"], ["good", "good"], make, lambda m, v: v, workers=2) == [
        "good", "good"]



def test_each_result_is_delivered_as_its_method_ends():
    """MethodRun (what ``pslog fuse`` writes each track from) hands typeA's result to the
    iterating thread while smooth still runs: smooth waits for the consumer to have got
    typeA's result, so the run completes only if results come as each method ends, not
    once all have (no timing involved)."""
    from pslog.fusion._parallel import MethodRun

    got_type_a = threading.Event()

    def run(method, value):
        if method == "smooth":  # started first (the costliest)
            assert got_type_a.wait(30), "typeA's result was not delivered before smooth ended"
        return method

    order = []
    for i, result in MethodRun(["smooth", "typeA"], [0, 0], lambda k, m: None, run, 2):
        order.append((i, result))
        if result == "typeA":
            got_type_a.set()
    assert order == [(1, "typeA"), (0, "smooth")]


def test_a_failure_stops_the_delivery_and_the_ranked_error_is_raised():
    """The error raised once every method has ended is the first failing one in the asked
    order (filter, asked first, fails after nearest); no failed method's result is
    delivered."""
    from pslog.fusion._parallel import MethodRun

    nearest_failed = threading.Event()

    def run(method, value):
        if method == "nearest":
            nearest_failed.set()
            raise ValueError("nearest failed")
        assert nearest_failed.wait(30)
        if method == "filter":
            raise ValueError("filter failed")
        return method

    delivered = []
    with pytest.raises(ValueError, match="filter failed"):
        for _i, result in MethodRun(["filter", "typeA", "nearest"], [0, 0, 0],
                                    lambda k, m: None, run, 3):
            delivered.append(result)
    assert set(delivered) <= {"typeA"}  # (delivered only if it came before the failure)


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_gating_forms_share_their_common_part_and_gate_as_alone(dirty, workers, monkeypatch):
    """Methods of three gating forms (offline; causal; causal waiting for the tolerance)
    fused together compute the forms' common part (gating.gate_common) once, and each form's
    rejections and each track are bit for bit those of the form gated alone."""
    from pslog.fusion import fuse, prepare
    from pslog.fusion import gating as G

    session = read_session(dirty)
    det, rig = session.detections, session.rig
    options = FusionOptions()
    methods = ["smooth", "typeA", "typeB", "nearest"]
    assert len({G.gating_key(m, options) for m in methods}) == 3
    made = []
    real = G.gate_common

    def counted(*args):
        made.append(threading.current_thread().name)
        return real(*args)

    monkeypatch.setattr(G, "gate_common", counted)
    tracks, rejections = fuse_detections(det, rig, methods, options, workers=workers)
    assert len(made) == 1
    monkeypatch.setattr(G, "gate_common", real)
    for m in methods:
        alone = G.gate_for(det, rig, m, options)
        for field in ("frame_time_ns", "camera", "frame_index", "uv", "score", "reason"):
            assert (getattr(alone.rejections, field).tobytes()
                    == getattr(rejections[m], field).tobytes())
        assert len(alone.rejections) == len(rejections[m]) > 0
        _same_track(tracks[m], fuse(alone.observations, rig, m, options,
                                    prepared=prepare(alone.observations, rig)))

def test_preload_starts_numba_and_the_kernel_modules_on_a_thread():
    import subprocess
    import sys

    code = (
        "import sys, threading\n"
        "from pslog._jit import preload\n"
        "assert 'numba' not in sys.modules\n"
        "preload('pslog.no_such_module', 'pslog.fusion.filter')\n"
        "for t in threading.enumerate():\n"
        "    if t.name == 'pslog-preload':\n"
        "        t.join(300)\n"
        "print('numba' in sys.modules, 'pslog.fusion.filter' in sys.modules)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["True", "True"]  # a missing module stops nothing
    assert run.stderr == ""


def test_preload_loads_the_batch_gates_kernel_in_the_signature_gating_calls():
    """The preload thread runs a kernel module's _preload(): the batch gate's compiled
    points (pslog.fusion._gate_kernel.points_all) is then ready in the very signature
    gating._points calls it with (a gate adds none), before any gate runs."""
    import subprocess
    import sys

    code = (
        "import threading\n"
        "from pslog._jit import preload\n"
        "preload('pslog.fusion._gate_kernel')\n"
        "for t in threading.enumerate():\n"
        "    if t.name == 'pslog-preload':\n"
        "        t.join(300)\n"
        "import pslog.fusion._gate_kernel as gk\n"
        "before = list(gk.points_all.signatures)\n"
        "from pslog.fusion.gating import gate\n"
        "from pslog.motion import get_motion\n"
        "from pslog.simulation import simulate\n"
        "from pslog.rig import apply_timing, builtin_rig\n"
        "rig = apply_timing(builtin_rig('paper3'), 'typeA')\n"
        "gated = gate(simulate(rig, get_motion('spiral'), 1.0)[0], rig)\n"
        "assert len(gated.observations) > 0\n"
        "print(len(before), before == list(gk.points_all.signatures))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["1", "True"]


def test_a_method_failing_beside_others_is_one_line(tmp_path, capsys):
    """sync needs shared instants, which a type-A session lacks: its error, raised on a
    worker thread while typeA and filter fuse, is the command's one line; nothing written."""
    session = tmp_path / "a.mcap"
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "2",
                 "-o", str(session)]) == 0
    capsys.readouterr()
    out = tmp_path / "f.mcap"
    code = main(["fuse", str(session), "--method", "typeA,sync,filter", "-o", str(out),
                 "--workers", "2"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and err[0].startswith("pslog fuse: error: method sync needs"), err
    assert not out.exists() and not (tmp_path / "f.mcap.partial").exists()


def test_sigterm_while_methods_fuse_on_threads_is_one_line(tmp_path):
    """SIGTERM while the worker threads fuse: the waiting main thread takes it at once, one
    line, exit 143, nothing written, and a method still running does not hold the exit.
    Three times, at the first progress line saying the methods fuse: a signal there found
    kernels still running as the interpreter shut down, and the process died of SIGSEGV
    (-11) in 10 of 160 runs before session 32 (cli._before_exit)."""
    import os
    import signal
    import subprocess
    import sys

    session = tmp_path / "long.mcap"
    subprocess.run([sys.executable, "-m", "pslog.cli", "simulate", "--rig", "paper3",
                    "--timing", "typeA", "--motion", "rally", "--duration", "240",
                    "-o", str(session)], check=True, capture_output=True, timeout=300)
    out = tmp_path / "f.mcap"
    signalled = 0
    for _ in range(3):
        proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", "fuse", str(session),
                                 "-o", str(out), "--workers", "2"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                env=dict(os.environ, PSLOG_PROGRESS="lines",
                                         PSLOG_PROGRESS_INTERVAL="0.05"))
        assert proc.stderr is not None
        seen = []
        for line in proc.stderr:  # progress lines until a method fuses
            seen.append(line)
            if "fusing" in line:
                break
        if proc.poll() is not None:
            proc.communicate(timeout=60)
            continue  # the command finished before it could be signalled
        proc.send_signal(signal.SIGTERM)
        rest = proc.communicate(timeout=60)[1]  # hang guard: a running method holds nothing
        lines = [x for x in (seen + rest.splitlines()) if x.strip()]
        if proc.returncode == 0:
            out.unlink()
            continue  # the command finished before the signal reached it
        signalled += 1
        assert proc.returncode == 143, (proc.returncode, rest)
        assert lines[-1].strip() == "pslog fuse: terminated (SIGTERM)", lines[-3:]
        assert not any("Traceback" in x or "Exception" in x for x in lines), lines
        assert not out.exists() and not (tmp_path / "f.mcap.partial").exists()
    if not signalled:
        pytest.skip("the command finished before it could be signalled")


_NATIVE_EXIT = """
import sys, threading, time
import pslog.cli as cli

code, name = int(sys.argv[1]), sys.argv[2]
threading.Thread(target=time.sleep, args=(60,), name=name, daemon=True).start()
print("before")  # to a pipe: buffered, so the exit must flush it
cli._before_exit(code)
print("after")
"""


@pytest.mark.parametrize(("code", "name", "ends_there"), [
    (143, "pslog-fuse-0", True), (1, "pslog-preload", True), (130, "pslog-fuse-1", True),
    (0, "pslog-fuse-0", False),  # a command that succeeded waited for its threads
    (143, "pslog-progress", False),  # a Python thread: the shutdown stops it safely
])
def test_a_stopped_command_ends_without_the_shutdown_while_a_kernel_runs(code, name,
                                                                        ends_there):
    """A command that failed or was stopped while one of its native-work threads still runs
    ends with os._exit(code) after flushing its output (the shutdown would free what the
    thread's kernel uses); otherwise the command returns to the normal shutdown."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # (buffered)
    proc = subprocess.run([sys.executable, "-c", _NATIVE_EXIT, str(code), name],
                          capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == (code if ends_there else 0), proc.stderr
    assert proc.stdout == ("before\n" if ends_there else "before\nafter\n"), proc.stdout



def test_a_stopped_command_without_a_stdout_still_ends_without_the_shutdown():
    """Started with its standard output closed ('>&-': ``sys.stdout`` is None), the same
    exit: no traceback from the flush, the signal's code."""
    import os
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-c", _NATIVE_EXIT, "143", "pslog-fuse-0"],
                          stderr=subprocess.PIPE, text=True, timeout=60,
                          preexec_fn=lambda: os.close(1))
    assert proc.returncode == 143, proc.stderr
    assert proc.stderr == "", proc.stderr

_ARENAS = """
import ctypes, os, sys
from pslog.cli import main

os.environ["PSLOG_PROGRESS"] = "lines"  # (its thread starts before the command runs)
code = main(["fuse", sys.argv[1], "--method", "nearest,typeA", "-o", sys.argv[2]])  # on threads
libc = ctypes.CDLL(None)
libc.fopen.restype, libc.fopen.argtypes = ctypes.c_void_p, [ctypes.c_char_p, ctypes.c_char_p]
libc.malloc_info.argtypes, libc.fclose.argtypes = [ctypes.c_int, ctypes.c_void_p], [ctypes.c_void_p]
f = libc.fopen(sys.argv[3].encode(), b"w")
libc.malloc_info(0, f)  # glibc's XML: one <heap> per malloc arena
libc.fclose(f)
print(code, open(sys.argv[3]).read().count("<heap nr="))
"""


@pytest.mark.skipif(__import__("platform").libc_ver()[0] != "glibc",
                    reason="glibc's malloc arenas")
def test_cli_fuse_threads_allocate_from_one_malloc_arena(dirty, tmp_path):
    # (pslog.cli.fuse.one_malloc_arena: fewer page faults, a lower peak; without it each
    # fusing thread, the preload's, the writer's get an arena of their own)
    import os
    import subprocess

    env = {k: v for k, v in os.environ.items()
           if k not in ("MALLOC_ARENA_MAX", "GLIBC_TUNABLES")}
    run = subprocess.run([sys.executable, "-c", _ARENAS, str(dirty), str(tmp_path / "f.mcap"),
                          str(tmp_path / "malloc.xml")], capture_output=True, text=True,
                         env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines()[-1].split() == ["0", "1"]  # (after the command's lines)


@pytest.mark.parametrize("workers", [1, 2, 3, 4])
@pytest.mark.parametrize("methods", [["nearest", "typeA", "smooth", "filter"],
                                     ["filter", "smooth", "typeA"],
                                     ["sync", "typeB", "linear", "smooth", "filter"]])
def test_threads_take_the_methods_so_that_they_end_in_the_write_order(methods, workers):
    """``pslog fuse`` writes each track once it and those before it in
    :func:`finishing_order` have ended. Threads taking the methods in :func:`start_order`,
    each method lasting its :data:`COST`, end them in that order but for the costliest
    (the longest chain, beside the others): no track waits for a method started after
    it. (Session 39: with the rest taken costliest first, ``filter``, the first to write,
    ended last on a default 90-minute fuse and every track was written after the fusion.)"""
    from pslog.fusion._parallel import COST, finishing_order, start_order

    free = [0.0] * workers
    end = {}
    for i in start_order(methods, workers):
        thread = min(range(workers), key=lambda j: free[j])
        free[thread] += COST[methods[i]]
        end[methods[i]] = free[thread]
    costliest = max(methods, key=lambda m: COST[m])
    ended = [m for m in sorted(methods, key=lambda m: end[m]) if m != costliest]
    assert ended == [m for m in finishing_order(methods) if m != costliest]
