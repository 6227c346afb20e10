"""Shared test fixtures: rigs, small JPEGs, simulated sessions and a CLI runner."""

from __future__ import annotations

import os
import signal
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from pslog.records import Detections, Truth
from pslog.rig import Rig, apply_timing, builtin_rig

# every command a test starts runs this tree's code, from whatever folder it starts in: the
# repository's root first on the children's PYTHONPATH, the entries given made absolute (a
# relative one, `PYTHONPATH=.`, read from a test's tmp_path found no pslog there, and the
# child imported the installed one: another worktree's code, whose passing or failing said
# nothing of this tree's; review, session 36)
_ROOT = Path(__file__).resolve().parents[1]
os.environ["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(
    [str(_ROOT)] + [str(Path(p).resolve()) for p in
                    os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))

# a command that runs longer than the progress period (5 s, on a loaded machine) would add a
# progress line to the standard error other tests read; tests/test_progress.py turns it on
os.environ.setdefault("PSLOG_PROGRESS", "off")

# the synthetic cameras' rendered backgrounds (recorders.render.background_cache_dir): one
# folder for the suite's processes (both test processes and every command they start share
# it), not the user's cache
os.environ.setdefault("PSLOG_CACHE_DIR", os.path.join(
    tempfile.gettempdir(), f"pslog-test-cache-{os.getuid()}"))

# the suite started under ``nohup`` (or by a service that ignores SIGHUP) would hand its ignored
# SIGHUP to every command it starts, and the tests of what a closed terminal does would then
# test nothing: commands run as from a terminal
signal.signal(signal.SIGHUP, signal.SIG_DFL)
# likewise a suite started in the background of a script (bash then ignores SIGINT in it):
# the tests of what Ctrl-C does would find it ignored in the commands they start
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def make_jpeg(value: int = 128, width: int = 64, height: int = 48) -> bytes:
    """A small real JPEG (a gradient plus ``value``) encoded with OpenCV."""
    import cv2

    ramp = np.linspace(0, 100, width, dtype=np.float64)[None, :, None]
    image = np.clip(value + ramp + np.zeros((height, width, 3)), 0, 255).astype(np.uint8)
    ok, data = cv2.imencode(".jpg", image)
    assert ok
    return data.tobytes()


@pytest.fixture
def rig3() -> Rig:
    """The paper's three-camera rig with type-A shutter offsets (1/90 s apart)."""
    return apply_timing(builtin_rig("paper3"), "typeA")


@dataclass
class SimSession:
    path: Path
    rig: Rig
    detections: Detections
    truth: Truth


@pytest.fixture
def sim_session(tmp_path, rig3) -> SimSession:
    """A simulated spiral session (3 cameras, 1.2 s, 0.3 px noise, some misses and drops)
    written with detections and truth, no images."""
    from pslog.log import SessionWriter
    from pslog.motion import get_motion
    from pslog.simulation import SimulationOptions, simulate

    options = SimulationOptions(noise_px=0.3, miss_rate=0.1, drop_rate=0.05, seed=3)
    detections, truth = simulate(rig3, get_motion("spiral"), options=options)
    path = tmp_path / "sim.mcap"
    with SessionWriter(path, rig3, timing="typeA", source="test") as writer:
        writer.add_detections(detections)
        writer.add_truth(truth)
    return SimSession(path, rig3, detections, truth)


@pytest.fixture
def cli(capsys):
    """Run ``pslog ARGS...`` in-process; returns (exit code, stdout, stderr)."""
    from pslog.cli import main

    def run(*args) -> tuple[int, str, str]:
        code = main([str(a) for a in args])
        captured = capsys.readouterr()
        return code, captured.out, captured.err

    return run


@pytest.fixture
def truth_first_session(tmp_path, rig3) -> tuple[bytes, list[int]]:
    """A synthetic-style session: truth for 1 s written up front, then two batches of 10
    frames per camera with images; returns the file and the end offsets of its chunks
    (in order: ..., truth, images 1, detections 1, images 2, detections 2)."""
    from pslog.log import SessionWriter
    from pslog.log import _mcapio as io
    from pslog.records import Truth

    path = tmp_path / "truth_first.mcap"
    truth_t = np.arange(300, dtype=np.int64) * 3_333_333
    # a huge flush interval: only the explicit flushes below write chunks
    with SessionWriter(path, rig3, flush_interval_s=1e6) as w:
        w.add_truth(Truth(truth_t, np.zeros((300, 3))))
        w.flush()
        for batch in (range(10), range(10, 20)):
            # images flushed before their detections are added: the writer itself always
            # writes detections first, this file has the other order to test recovery with
            for k in batch:
                for cam in range(3):
                    w.add_image(cam, k, k * 33_333_333 + cam * 11_111_111, make_jpeg(k))
            w.flush()
            for k in batch:
                for cam in range(3):
                    w.add_frame(cam, k, k * 33_333_333 + cam * 11_111_111, uv=[[1.0, 2.0]])
            w.flush()
    data = path.read_bytes()
    ends = [end for op, _, end in io.walk_records(data, len(io.MAGIC)) if op == io.OP_CHUNK]
    return data, ends


#: the files that take longest, longest first (per-file times of a whole run, 2026-12-01).
#: `bash run.sh test`'s two processes take whole files (--dist loadfile); these start first,
#: so that both processes end on short files. xdist's own order (most tests first; run.sh
#: turns it off with --no-loadscope-reorder) left the files of few but long tests for the
#: end -- the README's examples, Ray's batches, the live runs: the README's 4 tests were the
#: last 15 % of a process's run, and the other process ended before them or not by luck.
LONGEST_FIRST = (
    "test_readme.py",
    "test_batch.py",
    "test_stream_gating.py",
    "test_live_command.py",
    "faults/test_live_command.py",
    "faults/test_writers.py",
    "faults/test_inputs.py",
    "test_stream_window.py",
    "faults/test_view_faults.py",
    "test_sync.py",
    "faults/test_signals.py",
    "faults/test_corruption.py",
    "faults/test_record_camera_killed.py",
    "faults/test_record_faults.py",
    "test_fusion_validity.py",
    "test_progress.py",
    "test_detect.py",
    "test_smooth_kernels.py",
    "test_estimation.py",
    "faults/test_live_hostile.py",
    "test_batch_threads.py",
    "test_record.py",
    "test_log_chunks.py",
    "test_batch_address.py",
    "test_cli.py",
    "faults/test_sigterm_commands.py",
)


def pytest_collection_modifyitems(config, items):
    """Run the files of :data:`LONGEST_FIRST` first, in that order, then the others, most
    tests first (as xdist orders them); each file's tests in their own order."""
    here = Path(__file__).parent
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    files: dict[str, int] = {}
    for item in items:
        name = item.path.relative_to(here).as_posix() if item.path.is_relative_to(here) else ""
        files[name] = files.get(name, 0) + 1

    def key(item) -> tuple[int, int]:
        path = item.path
        name = path.relative_to(here).as_posix() if path.is_relative_to(here) else ""
        return (rank.get(name, len(rank)), -files[name] if name not in rank else 0)

    items.sort(key=key)  # stable: a file's tests stay in order
