"""SIGTERM to a command that writes a file (a service manager stopping it, ``timeout``):
like Ctrl-C, one line, exit 143, no ``.partial`` left, the input untouched, and no worker
process left behind (SIGTERM reaches the parent only, unlike a terminal's Ctrl-C)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .promises import assert_untouched, fingerprint


def _pids_mentioning(text: str) -> list[int]:
    pids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                cmdline = Path(f"/proc/{entry}/cmdline").read_bytes()
            except OSError:
                continue
            if text.encode() in cmdline:
                pids.append(int(entry))
    return pids


@pytest.fixture(scope="module")
def session_with_frames(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("sigterm") / "frames.mcap"
    subprocess.run([sys.executable, "-m", "pslog.cli", "record", "--synthetic", "--rig",
                    "paper3", "--timing", "typeA", "--motion", "rally", "--duration", "6",
                    "--fast", "-o", str(path)], check=True, capture_output=True, timeout=300)
    return path


@pytest.fixture(scope="module")
def long_session(tmp_path_factory) -> Path:
    """Four minutes of detections: `pslog fuse` on it runs for seconds, time to signal it."""
    path = tmp_path_factory.mktemp("sigterm") / "long.mcap"
    subprocess.run([sys.executable, "-m", "pslog.cli", "simulate", "--rig", "paper3",
                    "--timing", "typeA", "--motion", "rally", "--duration", "240",
                    "--noise-px", "0.3", "-o", str(path)], check=True, capture_output=True,
                   timeout=300)
    return path


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])  # HUP: a closed terminal
@pytest.mark.parametrize("command", [["redetect", "--workers", "2"], ["fuse"]])
def test_sigterm_mid_command_is_one_line_and_leaves_nothing(session_with_frames, long_session,
                                                             tmp_path, command, sig):
    out = tmp_path / "out.mcap"
    session = session_with_frames if command[0] == "redetect" else long_session
    before = fingerprint(session)
    proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", command[0],
                             str(session), *command[1:], "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PSLOG_PROGRESS="off"))
    partial = tmp_path / "out.mcap.partial"
    deadline = time.monotonic() + 120
    while not partial.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    if proc.poll() is not None:
        pytest.skip("the command finished before it could be signalled")
    proc.send_signal(sig)  # at once: the .partial of `fuse` lives ~0.3 s
    _, err = proc.communicate(timeout=60)
    if out.exists() and not partial.exists():
        # the signal came while the finished file was being put in place (the writer holds
        # signals for that): the output is complete, and the command still says it stopped
        assert proc.returncode in (0, 128 + sig), err
        pytest.skip("the command finished before the signal reached it")
    assert proc.returncode == 128 + sig, err
    lines = err.strip().splitlines()
    assert lines == [f"pslog {command[0]}: terminated ({sig.name})"], err
    assert not out.exists() and not partial.exists()
    assert_untouched(before, session)
    time.sleep(1.0)
    assert _pids_mentioning(str(tmp_path)) == []  # no worker left running


def _thread_start_interrupted(monkeypatch) -> None:
    """Make the start of the writer's flusher thread raise a Ctrl-C, as a signal landing
    while ``Thread.start`` waits for the new thread does."""
    import threading

    start = threading.Thread.start

    def interrupted(thread):
        if thread.name.startswith("pslog-flush-"):
            raise KeyboardInterrupt
        return start(thread)

    monkeypatch.setattr(threading.Thread, "start", interrupted)


@pytest.mark.parametrize("existing", [False, True])
def test_interrupt_while_the_writer_starts_leaves_no_partial(tmp_path, rig3, monkeypatch,
                                                             existing):
    """The CI failure of session 6: SIGTERM at once as ``pslog redetect``'s output appeared
    landed in the flusher's start, outside the writer's cleanup, and left the ``.partial``."""
    from pslog.log import SessionWriter

    out = tmp_path / "out.mcap"
    if existing:
        out.write_bytes(b"an old output")
    _thread_start_interrupted(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        SessionWriter(out, rig3, on_error="discard", force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == (["out.mcap"] if existing else [])
    if existing:
        assert out.read_bytes() == b"an old output"


def test_writer_left_open_by_an_interrupt_is_closed_by_the_command(tmp_path, rig3):
    """A writer made but never entered (the interrupt came between its construction and its
    ``with``): the command's interrupt handler removes a derived output's ``.partial`` and
    finishes a recording with what it holds."""
    from pslog.log import SessionWriter, read_session
    from pslog.log.writer import close_abandoned

    derived = SessionWriter(tmp_path / "derived.mcap", rig3, on_error="discard")
    recording = SessionWriter(tmp_path / "rec.mcap", rig3)
    recording.add_frame(0, 0, 1_000, uv=[[10.0, 20.0]])
    assert derived.target == tmp_path / "derived.mcap.partial" and derived.target.exists()
    close_abandoned()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.mcap"]
    assert read_session(tmp_path / "rec.mcap").detections.n_frames == 1


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_a_signal_taken_by_another_thread_waits_for_the_writer_close(tmp_path, rig3, sig):
    """Review of session 11: the kernel hands a process-directed signal to any thread that does
    not block it (the writer's flush and compression threads), and CPython runs the Python
    handler in the main thread anyway, so masking the main thread alone let SIGTERM raise inside
    ``close()`` and leave the ``.partial``. Here the signal goes to another thread on purpose
    (as the kernel may choose) while ``close()`` runs: it is raised after ``close()``, the old
    output replaced by the complete new one and no ``.partial`` left."""
    import threading

    from pslog.cli import Terminated, _termination_interrupts
    from pslog.log import SessionWriter, read_session
    from pslog.log import writer as writer_module

    out = tmp_path / "out.mcap"
    out.write_bytes(b"an old output")
    writer = SessionWriter(out, rig3, on_error="discard", force=True)
    writer.add_frame(0, 0, 1_000, uv=[[10.0, 20.0]])
    go, sent = threading.Event(), threading.Event()

    def signal_myself() -> None:  # started before the close: a thread of the writer's age
        go.wait(10)
        signal.pthread_kill(threading.get_ident(), sig)
        sent.set()

    signaller = threading.Thread(target=signal_myself, daemon=True)
    signaller.start()
    close = writer._close
    raised_in_close: list[BaseException] = []

    def close_with_a_signal() -> None:
        """The signal arrives in the middle of the close, on another thread."""
        go.set()
        sent.wait(5)
        signaller.join(5)
        time.sleep(0.05)  # the main thread's eval loop runs pending Python handlers here
        try:
            close()
        except BaseException as exc:  # what the old mask let through
            raised_in_close.append(exc)
            raise

    writer._close = close_with_a_signal  # type: ignore[method-assign]
    # as in a terminal, whatever started the suite (a background job ignores SIGINT)
    old_sigint = signal.signal(signal.SIGINT, signal.default_int_handler)
    restore = _termination_interrupts()
    expected = KeyboardInterrupt if sig == signal.SIGINT else Terminated
    try:
        with pytest.raises(expected):
            writer.close()
            time.sleep(0.05)
        writer_module.close_abandoned()  # what the command does on the interrupt
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        restore()
        signal.signal(signal.SIGINT, old_sigint)
    assert sent.is_set() and not raised_in_close
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.mcap"]
    assert read_session(out).detections.n_frames == 1
    assert signal.pthread_sigmask(signal.SIG_BLOCK, set()) == set()


def _children(pid: int) -> list[int]:
    try:
        return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _ignored_signals(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigIgn:"):
            return int(line.split()[1], 16)
    return 0


def test_redetect_workers_leave_ctrl_c_to_the_main_process(session_with_frames, tmp_path):
    """A terminal's Ctrl-C goes to the whole process group: a worker interrupted while it held
    the task queue's lock hung the pool's shutdown (review, session 7: 1 run in ~50), others
    printed their tracebacks. The workers ignore SIGINT and SIGTERM; the main process stops
    them. Then Ctrl-C to the group is one line, exit 130, nothing left."""
    out = tmp_path / "out.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", "redetect",
                             str(session_with_frames), "--workers", "2", "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PSLOG_PROGRESS="off"), start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        workers: list[int] = []
        while len(workers) < 2 and proc.poll() is None and time.monotonic() < deadline:
            workers = [c for c in _children(proc.pid)
                       if b"pslog" in Path(f"/proc/{c}/cmdline").read_bytes()
                       or Path(f"/proc/{c}/cmdline").read_bytes().startswith(
                           sys.executable.encode())]
            time.sleep(0.01)
        if proc.poll() is not None:
            pytest.skip("the command finished before its workers could be seen")
        time.sleep(0.2)  # the workers' initializer has run by now
        masks = [_ignored_signals(w) for w in workers if Path(f"/proc/{w}").exists()]
        both = (1 << (signal.SIGINT - 1)) | (1 << (signal.SIGTERM - 1))
        assert masks and all(m & both == both for m in masks), [hex(m) for m in masks]
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    if proc.returncode == 0:  # finished meanwhile: the output is complete
        assert out.exists()
        return
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["pslog redetect: interrupted"], err
    assert not (tmp_path / "out.mcap.partial").exists()


def test_a_signal_in_importlibs_code_is_raised_again_elsewhere():
    """CI saw ``pslog fuse`` hang after a SIGTERM: the handler raised Terminated inside
    importlib's weakref callback (``_get_module_lock``'s ``cb``, run in the main thread),
    where Python prints and drops an exception — the interrupt was lost and the global import
    lock stayed taken, so the fusion threads' next imports waited for ever. In importlib's
    own code the handler now sends the signal again a moment later, raised where it is safe."""
    import types

    from pslog.cli import Terminated, _raising, _termination_interrupts

    in_importlib = types.SimpleNamespace(
        f_code=types.SimpleNamespace(co_filename="<frozen importlib._bootstrap>"))
    restore = _termination_interrupts()
    try:
        _raising(Terminated)(signal.SIGTERM, in_importlib)  # must not raise here...
        with pytest.raises(Terminated):
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:  # ...but here, once sent again
                time.sleep(0.01)
            pytest.fail("the signal was never raised again")
    finally:
        restore()
    with pytest.raises(Terminated):  # anywhere else: at once
        _raising(Terminated)(signal.SIGTERM, None)
