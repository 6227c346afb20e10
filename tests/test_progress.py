"""Progress of long commands (pslog.progress): plain lines on standard error when it is not a
terminal, rich's bar on a terminal, nothing on standard output, and a bad setting refused in
one line."""

from __future__ import annotations

import io
import os
import pty
import re
import select
import subprocess
import sys
import time

import pytest

from pslog.progress import Progress, command_progress, step, update
from tests.faults.promises import assert_one_line_error, run_pslog


def test_lines_name_the_command_the_count_and_the_step(monkeypatch):
    monkeypatch.setenv("PSLOG_PROGRESS", "auto")  # a StringIO is no terminal: lines
    monkeypatch.setenv("PSLOG_PROGRESS_INTERVAL", "0.05")
    stream = io.StringIO()
    with Progress("fuse", total=4, stream=stream) as progress:
        assert progress.mode == "lines"
        progress.step("reading the session")
        progress.step("typeA")
        progress.step("smooth")
        time.sleep(0.3)
    lines = stream.getvalue().splitlines()
    assert lines and all(line.startswith("pslog fuse: ") for line in lines)
    assert re.fullmatch(r"pslog fuse: 2/4 steps \(50 %\), smooth, \d+\.\d s", lines[-1])
    count = len(lines)
    time.sleep(0.2)  # closed: no line after the block
    assert len(stream.getvalue().splitlines()) == count


def test_unknown_total_says_that_work_goes_on(monkeypatch):
    monkeypatch.setenv("PSLOG_PROGRESS", "lines")
    progress = Progress("recover", stream=io.StringIO())
    assert re.fullmatch(r"pslog recover: working, \d+\.\d s", progress.line())
    progress.update(advance=1500, what="chunks")
    assert progress.line().startswith("pslog recover: 1,500 steps, chunks")


def test_step_and_update_do_nothing_outside_a_command(monkeypatch):
    step("nothing listens")
    update(advance=3)
    monkeypatch.setenv("PSLOG_PROGRESS", "off")
    with command_progress("sync", total=2) as progress:
        step("estimating")
        update(advance=0.5)
        assert (progress.what, progress.completed) == ("estimating", 0.5)
    step("after")
    assert progress.what == "estimating"


@pytest.mark.parametrize("name,value", [("PSLOG_PROGRESS", "loud"),
                                        ("PSLOG_PROGRESS_INTERVAL", "-1"),
                                        ("PSLOG_PROGRESS_INTERVAL", "often")])
def test_a_bad_setting_is_one_line(tmp_path, name, value, monkeypatch, request):
    from tests.faults._inprocess import first_case, run_inprocess

    env = {"PSLOG_PROGRESS": "lines", name: value}
    if first_case(request):
        run = run_pslog("simulate", "--rig", "paper3", "-o", tmp_path / "s.mcap", env=env)
    else:  # in this process (tests/faults/_inprocess.py): the setting is read as it starts
        for key, text in env.items():
            monkeypatch.setenv(key, text)
        run = run_inprocess("simulate", "--rig", "paper3", "-o", tmp_path / "s.mcap")
    assert_one_line_error(run, 1, contains=name)
    assert not (tmp_path / "s.mcap").exists()


def test_a_command_prints_lines_to_stderr_and_the_same_stdout(tmp_path):
    """`pslog sync` on a 3 s session: progress lines on stderr naming its steps; stdout (the
    JSON result) identical to a run without progress."""
    from tests.faults._inprocess import run_inprocess

    raw = tmp_path / "raw.mcap"
    # the session and the run without progress in this process; the run with it a real one
    assert run_inprocess("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                         "rally", "--duration", "3", "--clock-offset", "cam2=2", "--seed", "3",
                         "-o", raw).code == 0
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("PSLOG_PROGRESS", "off")
        quiet = run_inprocess("sync", raw, "-o", tmp_path / "a.mcap", "--json")
    loud = run_pslog("sync", raw, "-o", tmp_path / "b.mcap", "--json",
                     env={"PSLOG_PROGRESS": "lines", "PSLOG_PROGRESS_INTERVAL": "0.05"})
    assert quiet.code == loud.code == 0, loud.stderr
    assert quiet.stdout == loud.stdout and quiet.stderr == ""
    lines = loud.stderr.splitlines()
    assert lines and all(line.startswith("pslog sync: ") for line in lines)
    assert any("choosing the clock model (auto) of 3 cameras" in line for line in lines)


def test_a_terminal_gets_a_bar_that_is_gone_at_the_end(tmp_path):
    """On a pseudo-terminal: rich's bar (control sequences, the step's name) on stderr, and
    the command's own result."""
    out = tmp_path / "s.mcap"
    master, slave = pty.openpty()
    env = {**os.environ, "PSLOG_PROGRESS": "auto", "COLUMNS": "120"}
    proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", "simulate", "--rig", "paper3",
                             "--motion", "rally", "--duration", "60", "-o", str(out)],
                            stdin=subprocess.DEVNULL, stdout=slave, stderr=slave, env=env)
    os.close(slave)
    seen = b""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        ready, _, _ = select.select([master], [], [], 1.0)
        if ready:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the child closed the terminal
                break
            if not chunk:
                break
            seen += chunk
        elif proc.poll() is not None:
            break
    proc.wait(timeout=60)
    os.close(master)
    text = seen.decode(errors="replace")
    assert proc.returncode == 0, text
    assert "pslog simulate" in text and "simulating 60.0 s of rally" in text
    assert "\x1b[" in text  # drawn with control sequences, not printed as lines
    assert f"wrote {out}" in text


def test_fuse_names_each_method_as_it_runs(tmp_path):
    from tests.faults._inprocess import run_inprocess

    raw = tmp_path / "raw.mcap"  # (made in this process: not what is tested)
    assert run_inprocess("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                         "rally", "--duration", "20", "--seed", "4", "-o", raw).code == 0
    run = run_pslog("fuse", raw, "-o", tmp_path / "f.mcap", "--method", "smooth,typeA",
                    env={"PSLOG_PROGRESS": "lines", "PSLOG_PROGRESS_INTERVAL": "0.05"})
    assert run.code == 0, run.stderr
    steps = [line.split(", ")[1] for line in run.stderr.splitlines()
             if line.startswith("pslog fuse: ") and "/4 steps" in line]
    # in order, each once or more: smooth, then typeA (a sub-second step may fall between
    # two lines)
    assert "fusing smooth" in steps
    assert steps == sorted(steps, key=["reading the session", "fusing smooth", "fusing typeA",
                                       f"writing {tmp_path / 'f.mcap'}"].index)
