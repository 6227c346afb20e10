"""A CSV or .rrd export killed with SIGKILL leaves ``<out>.partial``: the next run writing
the same output takes it over, through the real CLI (session 28).

Before, nothing proved that pslog had written such a partial (it is no MCAP), so every
later run was refused until the user deleted it by hand. Now the writer marks its partial
with an owner file ``<out>.partial.pslog`` naming the partial's device and inode
(``pslog.outputs.claim_partial``): a partial that is still that very file is pslog's and is
removed with a notice; a user's file of the partial's name (no owner file, or put in the
killed partial's place: another inode) is still never deleted.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "throw.mcap"
OLD = b"old output\n"


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    """A session with ~3,000 detections (its CSV export takes long enough to be killed)."""
    path = tmp_path_factory.mktemp("killed-in") / "s.mcap"
    run = run_pslog("simulate", "--rig", "paper3", "--motion", "rally", "--duration", "40",
                    "--spurious", "0.3", "--seed", "3", "-o", path)
    assert run.code == 0, run.stderr
    return path


def _killed(args: list, out: Path, tries: int = 6) -> int:
    """Run ``pslog ARGS`` and SIGKILL it as soon as its partial holds data (the write is
    under way). Returns the killed process's pid."""
    partial = out.with_name(out.name + ".partial")
    for _ in range(tries):
        # its temporary files in a folder of the test's (a killed run cannot remove its own:
        # the .rrd writer's named pipe stayed in /tmp after every test run)
        scratch = tempfile.mkdtemp(prefix="pslog-killed-")
        proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", *map(str, args)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                env={**os.environ, "TMPDIR": scratch})
        try:
            deadline = time.monotonic() + 120
            while proc.poll() is None and time.monotonic() < deadline:
                with contextlib.suppress(OSError):
                    if partial.stat().st_size:
                        break
                time.sleep(0.0005)
            proc.send_signal(signal.SIGKILL)
        finally:
            proc.wait()
            shutil.rmtree(scratch, ignore_errors=True)
        if proc.returncode == -signal.SIGKILL and partial.exists():
            return proc.pid
        out.write_bytes(OLD)  # it finished first: again
    pytest.skip(f"pslog {args[0]} always finished before it could be killed")


@pytest.mark.parametrize("kind", ["csv", "rrd"])
def test_a_killed_exports_partial_is_taken_over_by_the_next_run(kind, session, tmp_path):
    out = tmp_path / f"out.{kind}"
    partial, owner = tmp_path / f"out.{kind}.partial", tmp_path / f"out.{kind}.partial.pslog"
    out.write_bytes(OLD)
    args = (["export", session, "--detections", out, "--force"] if kind == "csv" else
            ["view", SAMPLE, "--save", out, "--force"])
    pid = _killed(args, out)
    assert out.read_bytes() == OLD and partial.exists()  # the old output kept
    assert f"pid {pid}\n" in owner.read_text()

    run = run_pslog(*args)
    assert run.code == 0, run.stderr
    assert f"removed {partial} left by an interrupted run (process {pid})" in run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]  # owner file gone too
    assert out.read_bytes() != OLD
    if kind == "csv":
        assert out.read_text().startswith("camera,time,u,v")


def test_a_users_file_in_place_of_a_killed_partial_is_kept(session, tmp_path):
    """The user moved a file of theirs to the killed run's partial's name (the owner file
    still there): another inode, so nothing proves pslog made it: refused, kept."""
    out = tmp_path / "out.csv"
    partial, owner = tmp_path / "out.csv.partial", tmp_path / "out.csv.partial.pslog"
    out.write_bytes(OLD)
    args = ["export", session, "--detections", out, "--force"]
    _killed(args, out)
    mine = tmp_path / "mine.txt"
    mine.write_text("my own notes\n")
    os.replace(mine, partial)
    before = fingerprint(tmp_path)
    assert_one_line_error(run_pslog(*args), 1, contains=(
        f"{partial} exists", "cannot tell it made it", "delete it or move it away"))
    assert_untouched(before, tmp_path)
    assert partial.read_text() == "my own notes\n" and owner.exists()

    # the user deletes their file: the owner file, now marking nothing, goes with the next
    # run, and so does the temporary of an owner file of a run killed while writing it
    partial.unlink()
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (tmp_path / f"out.csv.partial.pslog.{gone}").write_text(
        f"pslog partial owner 1\nfile out.csv.partial\ndevice 1\ninode 2\npid {gone}\n")
    run = run_pslog(*args)
    assert run.code == 0 and run.stderr == "", run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]
