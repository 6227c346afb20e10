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


@pytest.mark.parametrize("command", [["redetect", "--workers", "2"], ["fuse"]])
def test_sigterm_mid_command_is_one_line_and_leaves_nothing(session_with_frames, tmp_path,
                                                             command):
    out = tmp_path / "out.mcap"
    before = fingerprint(session_with_frames)
    proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", command[0],
                             str(session_with_frames), *command[1:], "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PSLOG_PROGRESS="off"))
    partial = tmp_path / "out.mcap.partial"
    deadline = time.monotonic() + 120
    while not partial.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    if proc.poll() is not None:
        pytest.skip("the command finished before it could be signalled")
    time.sleep(0.2)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    lines = err.strip().splitlines()
    assert lines == [f"pslog {command[0]}: terminated (SIGTERM)"], err
    assert not out.exists() and not partial.exists()
    assert_untouched(before, session_with_frames)
    time.sleep(1.0)
    assert _pids_mentioning(str(tmp_path)) == []  # no worker left running
