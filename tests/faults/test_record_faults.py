"""``pslog record`` under faults (issue 8): a disk that fills up while recording, bad sources.

A full disk cannot take the file's end, so the promise there is: the cameras stop cleanly,
what was written before stays (with ``--force``, the old session is untouched and the new
one is kept as ``<file>.partial``), the error says where and how to salvage it, exit 1. The
recorder's live status lines and summary come before that one error line on stderr.
"""

from __future__ import annotations

import contextlib
import re

import cv2
import numpy as np
import pytest

from pslog.log import read_session

from ._inprocess import first_case, run_inprocess
from ._mounts import fill, read_only, small_tmpfs
from .promises import Run, assert_one_line_error, assert_untouched, fingerprint, run_pslog

RECORD = ("record", "--synthetic", "--rig", "paper3", "--timing", "typeA", "--motion",
          "turntable", "--fast", "--duration", "20", "--jpeg-quality", "100")


def _assert_error_last(run: Run, *contains: str) -> str:
    """No traceback, exit 1, and the last stderr line is the only error line."""
    for stream in (run.stderr, run.stdout):
        assert "Traceback" not in stream, stream
    assert run.code == 1, run.stderr
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    errors = [line for line in lines if "error" in line.lower()]
    assert errors == [lines[-1]], run.stderr
    for text in contains:
        assert text in lines[-1], lines[-1]
    return lines[-1]


@pytest.mark.parametrize("old", [False, True], ids=["new file", "--force over a session"])
def test_disk_full_while_recording(tmp_path, old):
    with small_tmpfs(tmp_path / "disk", "1500k") as disk:
        out = disk / "s.mcap"
        if old:
            out.write_bytes(b"the old session")
        before = fingerprint(out)
        run = run_pslog(*RECORD, "-o", out, *(["--force"] if old else []))
        line = _assert_error_last(run, str(out), "No space left on device",
                                  "stopped the cameras", "pslog recover")
        assert "recording stopped, the file could not be written" in run.stderr
        assert "[failed]" not in run.stderr
        kept = out.with_name("s.mcap.partial") if old else out
        assert f"is in {kept}," in line
        if old:
            assert_untouched(before, out)
            assert "the old" in line and "untouched" in line
        assert kept.stat().st_size > 500_000  # the frames written before the disk filled
        fixed = tmp_path / "fixed.mcap"
        recovered = run_pslog("recover", kept, "-o", fixed)
        assert recovered.code == 0, recovered.stderr
        session = read_session(fixed)
        assert session.n_images > 0
        # the detections wait in memory while the large images fill the disk; they are
        # written before the images of their frames, so none of those is lost (0 once)
        assert session.detections.n_frames >= session.n_images


def test_unwritable_folder_or_full_disk_before_the_start(tmp_path):
    """Nothing can be written at all: one line before any camera starts, nothing left."""
    with read_only(tmp_path / "ro") as folder:
        before = fingerprint(folder)
        run = run_pslog(*RECORD, "-o", folder / "s.mcap", timeout=30)
        assert_one_line_error(run, 1, contains=(str(folder / "s.mcap"),
                                                "Read-only file system"))
        assert_untouched(before, folder)
    with small_tmpfs(tmp_path / "disk", "64k") as disk:
        fill(disk)
        before = fingerprint(disk)
        run = run_pslog(*RECORD, "-o", disk / "s.mcap", timeout=30)
        assert_one_line_error(run, 1, contains=(str(disk / "s.mcap"), "No space left"))
        assert_untouched(before, disk)


def _clip(path) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, (640, 480))
    for _ in range(3):
        writer.write(np.full((480, 640, 3), 90, np.uint8))
    writer.release()


def test_negative_offset_is_refused_up_front(tmp_path):
    _clip(tmp_path / "a.avi")
    before = fingerprint(tmp_path)
    run = run_pslog("record", "--rig", "paper2", "--source", "cam1=a.avi@-1", "--source",
                    "cam2=a.avi", "-o", "s.mcap", cwd=tmp_path, timeout=20)
    assert_one_line_error(run, 2, contains=("camera 'cam1'", ">= 0"))
    assert_untouched(before, tmp_path)


def _in_process(*args) -> Run:
    """``pslog ARGS`` through :func:`pslog.cli.main` in this process (faster than a
    subprocess where nothing but the exit code and stderr is looked at)."""
    import contextlib
    import io

    from pslog.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:  # argparse's own errors
            code = exc.code
    return Run(tuple(map(str, args)), code, out.getvalue(), err.getvalue())


@pytest.mark.parametrize(("values", "contains"), [
    (("--source", "cam1="), "--source must be NAME=SPEC"),
    (("--source", "=0"), "--source must be NAME=SPEC"),
    (("--source", "cam1=a.avi@-1", "--source", "cam2=a.avi"), ">= 0"),
    (("--source", "cam1=a.avi@nan", "--source", "cam2=a.avi"), "finite"),
    (("--source", "cam1=a.avi", "--source", "cam2=a.avi", "--offset", "cam1=nan"), "finite"),
    (("--source", "cam1=a.avi", "--source", "cam2=a.avi", "--offset", "cam1=x"), "number"),
    (("--synthetic", "--offset", "cam1=nan"), "--offset"),
], ids=["empty spec", "empty name", "negative @", "nan @", "nan --offset", "text --offset",
        "--offset with --synthetic"])
def test_malformed_source_values_are_usage_errors(tmp_path, monkeypatch, values, contains):
    """Exit 2 for a malformed command-line value, as argparse does (these gave 1)."""
    _clip(tmp_path / "a.avi")
    monkeypatch.chdir(tmp_path)
    before = fingerprint(tmp_path)
    run = _in_process("record", "--rig", "paper2", *values, "-o", "s.mcap")
    assert_one_line_error(run, 2, contains=contains)
    assert_untouched(before, tmp_path)


@pytest.mark.parametrize("spelling", ["a.avi", "./a.avi", "sub/../a.avi", "link.avi"])
def test_video_source_that_is_the_output_is_refused(tmp_path, spelling, request):
    _clip(tmp_path / "a.avi")
    (tmp_path / "sub").mkdir()
    (tmp_path / "link.avi").symlink_to("a.avi")
    before = fingerprint(tmp_path)
    # the first spelling as a real process, the others in this one (tests/faults/_inprocess.py)
    run = (run_pslog if first_case(request) else run_inprocess)(
        "record", "--rig", "paper2", "--source", "cam1=a.avi", "--source", "cam2=a.avi", "-o",
        spelling, "--force", cwd=tmp_path, timeout=20)
    line = assert_one_line_error(run, 1, contains="is the input")
    assert re.search(r"never replaces an input", line)
    assert_untouched(before, tmp_path)


@pytest.mark.parametrize("limit", ["tmpfs", "RLIMIT_FSIZE"])
def test_demo_on_a_full_disk_says_nothing_was_kept(tmp_path, limit):
    """The demo removes what it wrote when it fails; its error once still pointed at the
    deleted session ("salvage it with: pslog recover d/session.mcap ...")."""
    import resource

    def small_files():
        resource.setrlimit(resource.RLIMIT_FSIZE, (10 * 1024, resource.RLIM_INFINITY))

    with contextlib.ExitStack() as stack:
        if limit == "tmpfs":
            disk = stack.enter_context(small_tmpfs(tmp_path / "disk", "64k"))
            preexec = None
        else:
            disk, preexec = tmp_path, small_files
        before = fingerprint(disk)
        run = run_pslog("demo", "--out", "d", "--duration", "0.3", cwd=disk, timeout=120,
                        preexec_fn=preexec)
        line = assert_one_line_error(run, 1, contains=("session.mcap", "nothing was kept"))
        assert "recover" not in line
        assert not (disk / "d").exists()
        assert_untouched(before, disk)


def test_a_source_file_that_is_no_video_is_said_in_pslogs_words_alone(tmp_path):
    """A ``--source`` file that is no video (random bytes named .mp4): FFmpeg's own lines
    as OpenCV probes it (``[mov,mp4,... @ 0x...] moov atom not found``, on the camera
    process's standard error) no longer come before pslog's: the camera is reported
    failed, nothing is written."""
    import random

    (tmp_path / "noise.mp4").write_bytes(random.Random(2).randbytes(3000))
    # (a file each: one file for two cameras is refused since session 42's walk)
    (tmp_path / "noise2.mp4").write_bytes((tmp_path / "noise.mp4").read_bytes())
    run = run_pslog("record", "--rig", "paper2", "--source", "cam1=noise.mp4", "--source",
                    "cam2=noise2.mp4", "-o", "rec.mcap", cwd=tmp_path, timeout=60)
    assert run.code == 1, run.stderr
    assert "not a video OpenCV can read" in run.stderr
    assert "moov atom" not in run.stderr and " @ 0x" not in run.stderr, run.stderr
    assert "Traceback" not in run.stderr
    assert not (tmp_path / "rec.mcap").exists()
