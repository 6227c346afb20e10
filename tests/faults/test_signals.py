"""Signals to a real ``pslog record`` at several moments (issue 8).

Each case runs a real-time synthetic recording (three camera processes) as a subprocess in its
own process group, sends signals the way a terminal or a service manager does (SIGINT and
SIGTERM to the whole group; SIGKILL to the recorder or the group) at a chosen moment, and
checks that it stops cleanly: no traceback, "stopped" reported, the exit code, a readable
file (after ``pslog recover`` for SIGKILL). It also measures the seconds of recording lost:
the time the signal was sent, on the session clock (the file's "recording started" event
relates the session clock to the host's monotonic clock), minus the time of the last
detection in the file. ``pytest -s`` prints the figures.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from pslog.log import read_session
from pslog.records import NS

from .promises import run_pslog

#: the promise: a signal loses at most this much of the recording, seconds
MAX_LOST_S = 1.0
#: every case measured, for the summary printed at the end (and the README)
FIGURES: list[tuple[str, str]] = []


@dataclass
class Recorder:
    """A running ``pslog record --synthetic`` (real time) and its stderr, line by line."""

    proc: subprocess.Popen
    out: Path
    lines: list[tuple[float, str]] = field(default_factory=list)
    stdout: str = ""

    @property
    def stderr(self) -> str:
        return "\n".join(text for _t, text in self.lines)

    def wait_line(self, text: str, timeout: float = 60.0) -> float:
        """Until a stderr line contains ``text``; returns when it came (monotonic s)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for when, line in list(self.lines):
                if text in line:
                    return when
            assert self.proc.poll() is None or self._reader.is_alive(), (
                f"recorder ended before {text!r}:\n{self.stderr}")
            time.sleep(0.01)
        raise AssertionError(f"no {text!r} on stderr within {timeout} s:\n{self.stderr}")

    def wait_camera_process(self, timeout: float = 30.0) -> None:
        """Until a camera process exists (spawned, still starting up): not merely another
        member of the group (multiprocessing's resource tracker comes first)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(_is_camera_process(pid) for pid in _group_members(self.proc.pid)):
                return
            time.sleep(0.005)
        raise AssertionError(f"no camera process started:\n{self.stderr}")

    def finish(self, timeout: float = 60.0) -> int:
        try:
            code = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            raise AssertionError(f"recorder hung after the signal:\n{self.stderr}") from None
        self._reader.join(timeout=10)
        self.stdout = self.proc.stdout.read()
        return code


def _group_members(pgid: int) -> list[int]:
    members = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            if int(fields[2]) == pgid and fields[0] != "Z":
                members.append(int(entry.name))
    return members


def _is_camera_process(pid: int) -> bool:
    """A process multiprocessing spawned to run a target (a camera), by its command line."""
    try:
        return b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


@pytest.fixture
def start():
    """``start(out)`` runs a recorder; on teardown, whatever is left of its process group
    (a failed assertion before ``finish()``) is killed rather than left running 30 s."""
    started: list[Recorder] = []

    def run(out: Path) -> Recorder:
        rec = _start(out)
        started.append(rec)
        return rec

    yield run
    for rec in started:
        if rec.proc.poll() is None or _group_members(rec.proc.pid):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(rec.proc.pid, signal.SIGKILL)
            rec.proc.wait(timeout=10)


def _start(out: Path) -> Recorder:
    proc = subprocess.Popen(
        [sys.executable, "-m", "pslog.cli", "record", "--synthetic", "--rig", "paper3",
         "--timing", "typeA", "--motion", "turntable", "--duration", "30", "--no-frames",
         "-o", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True,
        start_new_session=True)
    rec = Recorder(proc, out)

    def read() -> None:
        for line in proc.stderr:
            rec.lines.append((time.monotonic(), line.rstrip("\n")))

    rec._reader = threading.Thread(target=read, daemon=True)
    rec._reader.start()
    return rec


def _send(rec: Recorder, sig: signal.Signals, group: bool) -> int:
    """Send ``sig``; returns when, on the host's monotonic clock (ns)."""
    sent = time.monotonic_ns()
    (os.killpg if group else os.kill)(rec.proc.pid, sig)
    return sent


def _lost_s(path: Path, sent_ns: int) -> float:
    """Seconds between the signal and the last detection stored in ``path``."""
    session = read_session(path)
    starts = [re.search(r"host monotonic clock (\d+) ns", text) for _t, text in session.events]
    starts = [int(m.group(1)) for m in starts if m]
    assert len(starts) == 1, f"no 'recording started' event in {path}: {session.events}"
    assert session.detections.n_frames > 0, f"{path} holds no detection"
    signal_s = (sent_ns - starts[0]) / NS
    return signal_s - session.detections.frame_time_ns.max() / NS


def _assert_no_traceback(rec: Recorder) -> None:
    for stream in (rec.stderr, rec.stdout):
        assert "Traceback" not in stream, stream
        assert "KeyboardInterrupt" not in stream, stream


def _assert_stopped(rec: Recorder, code: int, name: str) -> None:
    """A clean stop: exit 0, the summary says stopped, no camera failed."""
    _assert_no_traceback(rec)
    assert code == 0, f"exit {code}\n{rec.stderr}"
    assert f"recording stopped by {name}" in rec.stderr, rec.stderr
    summary = [line for _t, line in rec.lines if line.startswith("  cam")]
    assert len(summary) == 3 and all("[stopped]" in line for line in summary), rec.stderr
    assert "failed" not in rec.stderr and "error" not in rec.stderr, rec.stderr


def _record_figure(case: str, lost: float | None) -> None:
    # negative: frames captured just after the signal (while the stop spread) were kept too
    figure = ("nothing recorded yet" if lost is None else
              f"{max(lost, 0.0):.2f} s lost (last detection {-lost:+.2f} s from the signal)")
    FIGURES.append((case, figure))
    print(f"\n[signals] {case}: {figure}")


@pytest.fixture(scope="module", autouse=True)
def _print_figures():
    yield
    if FIGURES:
        print("\n[signals] case | seconds of recording lost")
        for case, figure in FIGURES:
            print(f"[signals] {case} | {figure}")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP],
                         ids=["SIGINT", "SIGTERM", "SIGHUP"])
def test_signal_to_the_group_while_cameras_start(start, tmp_path, sig):
    """Ctrl-C (SIGINT to the foreground group), SIGTERM or SIGHUP (a closed terminal) to the
    group while the camera processes are still starting up: a clean stop, no file left, one
    line saying so. SIGHUP killed multiprocessing's resource tracker (it ignores only SIGINT
    and SIGTERM), and starting the next camera printed its "process died unexpectedly"
    warning."""
    from recorders.record import _STOP_TIMEOUT_S

    rec = start(tmp_path / "s.mcap")
    rec.wait_camera_process()
    sent = _send(rec, sig, group=True)
    code = rec.finish()
    took = (time.monotonic_ns() - sent) / NS
    _assert_no_traceback(rec)
    assert "Warning" not in rec.stderr and "resource_tracker" not in rec.stderr, rec.stderr
    # the cameras not ready yet are ended, not waited for (up to the stop timeout: 10-15 s
    # from the command line on a busy machine)
    assert took < _STOP_TIMEOUT_S / 2, f"{took:.1f} s to stop\n{rec.stderr}"
    if code == 0:  # the recording had just started: then it is a clean stop like the others
        _assert_stopped(rec, code, sig.name)
        _record_figure(f"{sig.name} to the group, cameras starting", None)
        return
    assert code == 1, rec.stderr
    last = rec.lines[-1][1]
    assert last.startswith("pslog record: error: stopped before any camera delivered a frame")
    assert f"recording stopped by {sig.name}" in rec.stderr
    assert "[failed]" not in rec.stderr
    assert not rec.out.exists() and list(tmp_path.iterdir()) == []
    _record_figure(f"{sig.name} to the group, cameras starting", None)


@pytest.mark.parametrize(("sig", "after_s"), [(signal.SIGINT, 0.5), (signal.SIGTERM, 0.5),
                                              (signal.SIGINT, 2.0), (signal.SIGTERM, 2.0)])
def test_signal_to_the_group_while_recording(start, tmp_path, sig, after_s):
    """In the first second and mid-run: the file is finished (readable without recovery)
    and holds everything up to the signal."""
    rec = start(tmp_path / "s.mcap")
    started = rec.wait_line("] cam1:")  # the first status line: cameras recording
    time.sleep(max(started + after_s - time.monotonic(), 0))
    sent = _send(rec, sig, group=True)
    _assert_stopped(rec, rec.finish(), sig.name)
    lost = _lost_s(rec.out, sent)
    _record_figure(f"{sig.name} to the group {after_s:g} s into the recording", lost)
    assert -0.5 < lost <= MAX_LOST_S


def _sigint_then_wait_for_shutdown(rec: Recorder) -> int:
    """A Ctrl-C to the group a second into the recording; returns when the recorder says it
    is stopping (the moment for a second signal), with the time the SIGINT was sent."""
    started = rec.wait_line("] cam1:")
    time.sleep(max(started + 1.0 - time.monotonic(), 0))
    sent = _send(rec, signal.SIGINT, group=True)
    rec.wait_line("stopping")
    return sent


def test_second_signal_during_shutdown(start, tmp_path):
    """Ctrl-C, then SIGTERM to the group while the file is being finished: still one clean
    stop (the second signal does not interrupt the first one's shutdown)."""
    rec = start(tmp_path / "s.mcap")
    sent = _sigint_then_wait_for_shutdown(rec)
    _send(rec, signal.SIGTERM, group=True)
    _assert_stopped(rec, rec.finish(), "SIGINT")
    lost = _lost_s(rec.out, sent)
    _record_figure("SIGINT, then SIGTERM to the group during shutdown", lost)
    assert -0.5 < lost <= MAX_LOST_S


def _kill_then_recover(tmp_path, rec: Recorder, code: int, sent: int, case: str) -> None:
    assert code == -signal.SIGKILL, rec.stderr
    # the orphaned camera processes notice and exit on their own
    deadline = time.monotonic() + 10
    while _group_members(rec.proc.pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = _group_members(rec.proc.pid)
    if left:
        os.killpg(rec.proc.pid, signal.SIGKILL)
        pytest.fail(f"camera processes survived their parent: {left}")
    fixed = tmp_path / "fixed.mcap"
    run = run_pslog("recover", rec.out, "-o", fixed)
    assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
    lost = _lost_s(fixed, sent)
    _record_figure(case, lost)
    # negative: detections past the signal were kept (after a SIGINT the cameras run on for
    # a few frames while the recorder stops); what matters is that at most a second is lost
    assert -0.5 < lost <= MAX_LOST_S


def test_sigkill_mid_run_then_recover(start, tmp_path):
    """SIGKILL to the recorder alone, mid-run: ``pslog recover`` salvages all but at most
    the last second."""
    rec = start(tmp_path / "s.mcap")
    started = rec.wait_line("] cam1:")
    time.sleep(max(started + 2.0 - time.monotonic(), 0))
    sent = _send(rec, signal.SIGKILL, group=False)
    _kill_then_recover(tmp_path, rec, rec.finish(), sent,
                       "SIGKILL to the recorder 2 s into the recording")


def test_sigkill_during_shutdown_then_recover(start, tmp_path):
    """Ctrl-C, then SIGKILL to the whole group while the file is being finished."""
    rec = start(tmp_path / "s.mcap")
    sent = _sigint_then_wait_for_shutdown(rec)
    _send(rec, signal.SIGKILL, group=True)
    code = rec.finish()
    if code == 0:
        pytest.skip("the recorder finished before SIGKILL arrived")
    _kill_then_recover(tmp_path, rec, code, sent,
                       "SIGINT, then SIGKILL to the group during shutdown")


#: a ``pslog`` console script whose Ctrl-C (or SIGTERM, SIGHUP: argv[1]) comes at the start of
#: one import (an audit hook sends a real signal to the process when the import named by
#: argv[2] begins)
_EARLY_CTRL_C = """
import os, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal (not inherited SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_DFL)
signal.signal(signal.SIGHUP, signal.SIG_DFL)
signum, module, sys.argv = int(sys.argv[1]), sys.argv[2], ["pslog", *sys.argv[3:]]
sent = []
def hook(event, args):
    if event == "import" and args[0] == module and not sent:
        sent.append(1)
        os.kill(os.getpid(), signum)
sys.addaudithook(hook)
from pslog.cli import main
sys.exit(main())
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.parametrize("module", ["argparse", "pslog.cli._common", "numpy"],
                         ids=["loading pslog.cli", "loading the command", "loading numpy"])
def test_ctrl_c_while_the_command_loads(tmp_path, module, sig):
    """Ctrl-C in the first hundredth of a second of ``pslog record`` (the tester's 0.05 s):
    a KeyboardInterrupt traceback from the imports, or numpy's ImportError when it hit
    numpy's C extension. Now: one line, exit 130, nothing written. SIGTERM and SIGHUP there
    (a service stopped at once, a terminal closed) ended it silently with their default
    action (review of session 11): now one line, exit 143 / 129. Only the interpreter's own
    start-up, before ``pslog.cli`` is imported, remains uncovered."""
    from .promises import Run, assert_one_line_error

    args = ("record", "--synthetic", "--rig", "paper3", "--fast", "--duration", "1", "-o",
            str(tmp_path / "s.mcap"))
    proc = subprocess.run([sys.executable, "-c", _EARLY_CTRL_C, str(int(sig)), module, *args],
                          capture_output=True, text=True, timeout=60,
                          stdin=subprocess.DEVNULL)
    run = Run(args, proc.returncode, proc.stdout, proc.stderr)
    if sig == signal.SIGINT:
        assert_one_line_error(run, 130, contains="pslog record: interrupted")
    else:
        assert_one_line_error(run, 128 + sig, contains=(
            f"pslog record: terminated ({signal.Signals(sig).name})"))
    assert list(tmp_path.iterdir()) == []
