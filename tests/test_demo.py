"""pslog demo: the README's main job, end to end on real files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from pslog.evaluation import evaluate
from pslog.log import read_session


def test_demo_records_fuses_evaluates_and_saves_a_recording(tmp_path):
    out = tmp_path / "demo"
    result = subprocess.run([sys.executable, "-m", "pslog.cli", "demo", "--out", str(out)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert "Table 1" in result.stdout and "typeA" in result.stdout
    assert f"rerun {out / 'demo.rrd'}" in result.stdout
    session = read_session(out / "fused.mcap")
    assert session.n_images == 135 and set(session.tracks) == {"typeA", "nearest", "smooth",
                                                               "filter"}
    type_a = evaluate(session.tracks["typeA"], session.truth)
    nearest = evaluate(session.tracks["nearest"], session.truth)
    # (90 Hz but the points whose intervals hold the throw's bounce: refused as kink)
    assert 86.5 < type_a.rate_hz <= 90.0 and type_a.mean_mm < 10.0
    assert nearest.mean_mm > 3 * type_a.mean_mm
    assert (out / "demo.rrd").stat().st_size > 1_000_000
    # a second run into the same folder refuses to overwrite, with one line (in this
    # process, tests/faults/_inprocess.py: the refusal comes before anything runs)
    from faults._inprocess import run_inprocess

    again = run_inprocess("demo", "--out", out, timeout=300)
    assert again.code == 1 and "--force" in again.stderr
    assert "Traceback" not in again.stderr


def test_ctrl_c_during_the_recording_stops_the_demo(tmp_path):
    """The recorder turns Ctrl-C into a clean stop of the recording; the demo must then stop
    too (exit 130, saying so, nothing kept), not fuse and evaluate a shortened throw."""
    out = tmp_path / "demo"
    proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", "demo", "--out", str(out),
                             "--realtime", "--duration", "30", "--no-view"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while not (out / "session.mcap").exists():  # the recording has begun
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "interrupted" in stderr, stderr
    assert "2/4" not in stdout, stdout
    assert not out.exists()
