"""Session 39's hostile-input sweep through the real CLI and the Python API on real files.
``pslog sync --search-ms 1e-320`` was a traceback (the scan's step underflowed to 0: a
division by zero), and ``pslog.sync(search_s=0)`` too; a negative ``search_s`` scanned
backwards in silence, NaN was called longer than the session. ``pslog demo --duration`` below
a frame period failed after the run with "no such file: session.mcap", below two frames a
camera with "track 'typeA' has no point inside the ground truth's span" (exit 1 both), and
``recorders.record_synthetic`` recorded no file without a word. ``pslog recover`` of a session
still being recorded copied what was written so far and called it a salvage, where every
other command says the file may still be recording. ``FusionOptions(noise_px=1e-200)`` gave
every typeA point a NaN std_m (``pslog fuse`` refuses that noise). ``pslog.fuse`` took
``clock_uncertainty="off"`` for on, and a wrong ``rig`` or ``options`` type, like
``pslog.read_session(123)``, was an AttributeError or TypeError from deep inside.
``pslog calibrate --fps 0.05`` was exit 1 where ``--fps 1e308`` is exit 2; ``--chessboard 2x3``
a cv2.error traceback, ``99999x99999`` "out of memory: Unable to allocate 112. GiB", ``--square
1e-30`` OpenCV's assertion text. ``pslog fuse --max-gap-ms`` below the frame period made no
point, "too few detections close enough in time", the option unnamed. ``NUMBA_NUM_THREADS=0
pslog fuse`` was a traceback: another thread's import of a kernel module half imported;
``NUMBA_NUM_THREADS=abc`` numba's nine-line warning with a traceback's text. ``pslog import``
of a detections CSV in milliseconds went through: 33 s between a 30 fps camera's frames.
``pslog live --out`` at its own ``--listen`` address sent every point back to itself."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import pslog
from pslog.errors import FusionError, InputError
from pslog.fusion import FusionOptions

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep39")
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                     "--noise-px", "0.3", "--clock-offset", "cam2=3", "--seed", "60239",
                     "-o", folder / "s.mcap")
    assert done.code == 0, done.stderr
    return folder


@pytest.mark.parametrize("search_ms", ["1e-320", "1e-9"])
def test_an_offset_search_narrower_than_a_nanosecond_is_a_usage_error(inputs, tmp_path,
                                                                      search_ms):
    """``--search-ms 1e-320``: a ZeroDivisionError traceback before."""
    before = fingerprint(inputs)
    run = run_pslog("sync", inputs / "s.mcap", "--search-ms", search_ms, "-o",
                    tmp_path / "synced.mcap")
    assert_one_line_error(run, 2, contains=("--search-ms", "at least 1e-06 ms", search_ms))
    assert not (tmp_path / "synced.mcap").exists()
    assert_untouched(before, inputs)


def test_the_narrowest_offset_search_is_a_nanosecond(inputs, tmp_path):
    """1e-6 ms is 9.999999999999999e-10 s in floating point: still the nanosecond allowed."""
    run = run_pslog("sync", inputs / "s.mcap", "--estimate", "offset", "--search-ms", "1e-6",
                    "-o", tmp_path / "synced.mcap")
    assert run.code == 0, run.stderr
    assert (tmp_path / "synced.mcap").stat().st_size > 0


@pytest.mark.parametrize("search_s", [0.0, -0.001, float("nan"), float("inf"), 1e-323, True,
                                      "5 ms", 61.0])
def test_syncs_api_names_an_offset_search_that_is_no_span(inputs, search_s):
    """``pslog.sync(search_s=0)`` and 1e-323: ZeroDivisionError; -0.001: a backwards scan
    taken in silence; NaN, inf: 'not shorter than the session'; True: one second."""
    session = pslog.read_session(inputs / "s.mcap")
    with pytest.raises(InputError, match=r"offset search ±.* s: give seconds in \[1e-09, 60\]"):
        pslog.sync(session, "offset", search_s=search_s)
    from pslog.estimation.sync import estimate_clocks  # the estimator's own entry point
    obs = session.detections.best()
    with pytest.raises(InputError, match=r"offset search ±"):
        estimate_clocks(obs, session.rig, ("offset",), search_s)


@pytest.mark.parametrize("duration", ["0.05", "0.01", "1e-320"])
def test_a_demo_too_short_to_fuse_is_a_usage_error_and_leaves_nothing(tmp_path, duration):
    """Below a frame period: exit 1 'no such file: .../session.mcap' after the run; below two
    frames of a camera: exit 1 'track 'typeA' has no point inside the ground truth's span'."""
    run = run_pslog("demo", "--out", "d", "--duration", duration, "--no-view", cwd=tmp_path)
    assert_one_line_error(run, 2, contains=("--duration", "at least 0.1 s", duration))
    assert list(tmp_path.iterdir()) == []


def test_record_synthetic_refuses_a_duration_without_a_frame(tmp_path):
    """The library entry point: a 10 ms recording of 30 fps cameras recorded no file and
    said nothing (its callers then found no session)."""
    from pslog.rig import builtin_rig
    from recorders import record_synthetic

    rig = builtin_rig("paper3")
    with pytest.raises(InputError, match=r"0\.01 s is too short to hold a frame"):
        record_synthetic(rig, "throw", tmp_path / "r.mcap", duration=0.01, fast=True,
                         frames=False)
    assert list(tmp_path.iterdir()) == []


def test_recover_of_a_session_still_being_recorded_says_so(tmp_path):
    """Every reader refuses a file a recorder is writing ('it may still be recording');
    ``recover`` copied its first seconds and reported a salvage, not a word of the recording
    going on: the copy taken for the whole of it."""
    live = tmp_path / "live.mcap"
    env = {**os.environ, "PSLOG_PROGRESS": "off"}
    recorder = subprocess.Popen(
        [sys.executable, "-m", "pslog.cli", "record", "--synthetic", "--rig", "paper3",
         "--timing", "typeA", "--motion", "rally", "--duration", "8", "--no-frames",
         "-o", str(live)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
        text=True)
    try:
        deadline = time.monotonic() + 120
        while not (live.exists() and live.stat().st_size > 0):
            assert recorder.poll() is None, recorder.communicate()[1]
            assert time.monotonic() < deadline, "the recording never started"
            time.sleep(0.1)
        run = run_pslog("recover", live, "-o", tmp_path / "copy.mcap")
        assert recorder.poll() is None, "the recording ended before recover: no test"
        assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
        note = run.stdout.splitlines()[0]
        assert note.startswith(f"note: {live} is still being recorded (another pslog is "
                               f"writing it): {tmp_path / 'copy.mcap'} holds what it had "
                               f"written so far"), run.stdout
        assert note.endswith("run this again once the recording has ended, for all of it")
        assert (tmp_path / "copy.mcap").stat().st_size > 0
        _, err = recorder.communicate(timeout=180)  # (8 s of session time, in real time)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.communicate()
    assert recorder.returncode == 0, err
    run = run_pslog("recover", live, "-o", tmp_path / "whole.mcap")
    assert run.code == 0, run.stderr
    assert "still being recorded" not in run.stdout, run.stdout  # finished: a plain copy
    assert f"{live} was complete" in run.stdout, run.stdout


@pytest.mark.parametrize("noise_px", [1e-200, 1e-320, 1e-4])
def test_fusion_options_refuse_a_noise_whose_covariances_underflow(inputs, noise_px):
    """``pslog fuse --noise-px`` refuses 0 < noise < 0.001 px; the library took it, and every
    typeA point of ``pslog.fuse(options=FusionOptions(noise_px=1e-200))`` had std_m NaN."""
    with pytest.raises(FusionError, match=r"pixel noise must be 0 \(noise-free\) or in "
                                          r"\[0.001, 1000\] pixels"):
        FusionOptions(noise_px=noise_px)
    # the least allowed, and 0, still fuse with finite (or zero) std_m
    session = pslog.read_session(inputs / "s.mcap")
    for least in (1e-3, 0.0):
        track = pslog.fuse(session, "typeA", options=FusionOptions(noise_px=least))["typeA"]
        assert len(track) > 0 and np.all(np.isfinite(track.quality["std_m"])), least


@pytest.mark.parametrize("call, says", [
    (lambda s: pslog.read_session(123), "read_session: path 123: give a file name"),
    (lambda s: pslog.fuse(s, "nearest", rig=123), "rig 123: give a Rig"),
    (lambda s: pslog.fuse(s, "nearest", options={"max_gap_s": 1.0}),
     "options {'max_gap_s': 1.0}: give a pslog.fusion.FusionOptions"),
    (lambda s: pslog.fuse(s, "nearest", clock_uncertainty="off"),
     "clock_uncertainty 'off': give True or False")])
def test_the_api_names_an_argument_of_the_wrong_type(inputs, call, says):
    """Each was an AttributeError or TypeError from deep inside, and ``clock_uncertainty=
    "off"`` was taken as on (a non-empty string)."""
    session = pslog.read_session(inputs / "s.mcap")
    with pytest.raises(InputError) as caught:
        call(session)
    assert says in str(caught.value)


def test_calibrate_a_frame_rate_below_any_camera_is_a_usage_error(tmp_path):
    """``--fps 0.05``: exit 1 from the rig's check, where ``--fps 1e308`` is exit 2."""
    sample = Path(__file__).resolve().parents[2] / "samples" / "cam1_points.csv"
    (tmp_path / "points.csv").write_bytes(sample.read_bytes())
    before = fingerprint(tmp_path)
    run = run_pslog("calibrate", "--points", "points.csv", "--name", "cam9", "--rig",
                    "rig.toml", "--width", "640", "--height", "480", "--fps", "0.05",
                    cwd=tmp_path)
    assert_one_line_error(run, 2, contains=("--fps", "at least 0.1 fps", "0.05"))
    assert_untouched(before, tmp_path)


@pytest.mark.parametrize("gap_ms, methods", [("5", ()), ("23", ("--method", "typeA"))])
def test_a_max_gap_below_the_frame_period_is_named_when_no_point_is_made(inputs, tmp_path,
                                                                         gap_ms, methods):
    """``--max-gap-ms 5`` (or 23 for typeA, which bridges a camera's frame to its next): 'no
    fusion method produced a point', 'too few detections close enough in time', and the
    option that made them so unnamed."""
    before = fingerprint(inputs)
    out = tmp_path / "fused.mcap"
    run = run_pslog("fuse", inputs / "s.mcap", "--max-gap-ms", gap_ms, *methods, "-o", out)
    why = f"--max-gap-ms {gap_ms} is shorter than the 33.33 ms frame period"
    assert_one_line_error(run, 1, contains=("no fusion method produced a point", why))
    assert f"no point from typeA: too few detections close enough in time ({why}" in run.stdout
    assert not out.exists()
    assert_untouched(before, inputs)


@pytest.mark.parametrize("args, says", [
    (("--chessboard", "2x3"), "bad chessboard pattern '2x3': each side needs 3 to 1000"),
    (("--chessboard", "9x2"), "bad chessboard pattern '9x2': each side needs 3 to 1000"),
    (("--chessboard", "99999x99999"), "'99999x99999': each side needs 3 to 1000"),
    (("--chessboard", "9x6", "--square", "1e-30"), "--square: must be at least 0.0001 m")])
def test_a_chessboard_no_camera_can_see_is_a_usage_error(tmp_path, args, says):
    """2x3: a cv2.error traceback (OpenCV's corner finder needs more than 2 a side);
    99999x99999: 'out of memory: Unable to allocate 112. GiB' (its board points); a square of
    1e-30 m: OpenCV's assertion text ('matH0.size() == Size(3, 3)')."""
    import cv2

    shots = tmp_path / "shots"
    shots.mkdir()
    cv2.imwrite(str(shots / "view.png"), np.full((480, 640), 128, np.uint8))
    before = fingerprint(tmp_path)
    run = run_pslog("calibrate", *args, "--images", "shots", "--name", "cam9", "--rig",
                    "rig.toml", cwd=tmp_path)
    assert_one_line_error(run, 2, contains=says)
    assert_untouched(before, tmp_path)


@pytest.mark.parametrize("pattern, square, says", [
    ((2, 6), 0.025, "bad chessboard pattern (2, 6): each side needs 3 to 1000"),
    ((9, 6.5), 0.025, "bad chessboard pattern (9, 6.5): expected COLSxROWS"),
    ((9, 6), 1e-30, "chessboard square 1e-30 m: give its side in [0.0001, 1] metres"),
    ((9, 6), float("nan"), "chessboard square nan m")])
def test_calibrate_chessboard_names_a_pattern_or_square_out_of_bounds(pattern, square, says):
    """The library entry point, before any image is searched (a blank image: before, 'no 9x6
    chessboard found' or the cv2.error of a 2-corner side)."""
    from pslog.calibration import calibrate_chessboard

    blank = np.full((480, 640), 128, np.uint8)
    with pytest.raises(InputError) as caught:
        calibrate_chessboard([blank] * 3, pattern, square)
    assert says in str(caught.value)


def test_numba_refusing_to_start_under_fuses_threads_is_one_line(inputs, tmp_path):
    """``NUMBA_NUM_THREADS=0 pslog fuse``: the methods' threads import the kernel modules at
    once; the first import fails in pslog's words ("numba could not start"), and another
    thread, meeting that module half imported, raised "ImportError: cannot import name
    '_prepare_kernel'", the error reported (a traceback). ``--workers 1``, ``sync`` and
    ``view`` said it in one line already."""
    before = fingerprint(inputs)
    out = tmp_path / "fused.mcap"
    run = run_pslog("fuse", inputs / "s.mcap", "-o", out, env={"NUMBA_NUM_THREADS": "0"})
    assert_one_line_error(run, 1, contains=("numba could not start", "NUMBA_"))
    assert not out.exists() and not list(tmp_path.iterdir())
    assert_untouched(before, inputs)


def test_a_numba_variable_numba_cannot_parse_is_one_warning_line(inputs, tmp_path):
    """``NUMBA_NUM_THREADS=abc``: numba warns and goes on with its default; its warning was
    nine lines on stderr with a traceback's text among them, now one line of pslog's."""
    out = tmp_path / "fused.mcap"
    run = run_pslog("fuse", inputs / "s.mcap", "--method", "nearest", "-o", out,
                    env={"NUMBA_NUM_THREADS": "abc"})
    assert run.code == 0, run.stderr
    assert "Traceback" not in run.stderr, run.stderr
    assert run.stderr.splitlines() == [
        "pslog fuse: warning: numba: environment variable 'NUMBA_NUM_THREADS' is defined but "
        "its associated value 'abc' could not be parsed; numba takes its default instead"]
    assert out.stat().st_size > 0


@pytest.mark.parametrize("scale, ratio", [
    (1000, "1000 times its 33.33 ms frame period at 30 fps: the time column is seconds "
           "(milliseconds: divide them by 1000)"),
    (1e6, "1000000 times its 33.33 ms frame period at 30 fps: the time column is seconds "
          "(microseconds: divide them by 1e6)")])
def test_a_detections_csv_in_milliseconds_is_refused_naming_the_unit(inputs, tmp_path, scale,
                                                                     ratio):
    """A detector's log in milliseconds (or microseconds) imported without a word: each
    camera's frames 33 s apart in a 30 fps rig, and ``pslog fuse`` then said only "too few
    detections close enough in time"."""
    exported = tmp_path / "det.csv"
    assert run_pslog("export", inputs / "s.mcap", "--detections", exported).code == 0
    lines = exported.read_text().splitlines()
    header = lines[0].split(",")
    at = header.index("time")
    scaled = [lines[0]]
    for line in lines[1:]:
        cells = line.split(",")
        cells[at] = repr(float(cells[at]) * scale)
        scaled.append(",".join(cells))
    wrong = tmp_path / "det_ms.csv"
    wrong.write_text("\n".join(scaled) + "\n")
    before = fingerprint(tmp_path)
    run = run_pslog("import", "--rig", "paper3", "--timing", "typeA", "--detections", wrong,
                    "-o", tmp_path / "s.mcap")
    assert_one_line_error(run, 1, contains=(
        f"{wrong}: camera cam1's frames are", ratio))
    assert_untouched(before, tmp_path)
    # the same CSV in seconds, every third frame of each camera left out: imported
    kept = [lines[0]] + [line for i, line in enumerate(lines[1:]) if (i // 3) % 3 == 0]
    sparse = tmp_path / "sparse.csv"
    sparse.write_text("\n".join(kept) + "\n")
    run = run_pslog("import", "--rig", "paper3", "--timing", "typeA", "--detections", sparse,
                    "-o", tmp_path / "s.mcap")
    assert run.code == 0, run.stderr


@pytest.mark.parametrize("listen_host, out_host", [("127.0.0.1", "127.0.0.1"),
                                                   ("0.0.0.0", "localhost")])
def test_live_refuses_to_send_its_points_to_its_own_listen_address(tmp_path, listen_host,
                                                                   out_host):
    """``--out`` equal to ``--listen`` (or to any local address a wildcard bind takes): the
    points came back to the fuser, counted as foreign datagrams, none to a robot, and the
    run ended with exit 0."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    run = run_pslog("live", "--rig", "paper3", "--synthetic", "--duration", "1",
                    "--listen", f"udp://{listen_host}:{port}",
                    "--out", f"udp://{out_host}:{port}", "--record", tmp_path / "live.mcap")
    assert_one_line_error(run, 1, contains=(
        f"--out udp://{out_host}:{port} is where pslog live listens "
        f"(udp://{listen_host}:{port})", "give the robot's address"))
    assert list(tmp_path.iterdir()) == []
