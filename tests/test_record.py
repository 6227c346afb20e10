"""Recording sessions: synthetic rigs, video files, failing sources, signals, SIGKILL."""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.cli import main
from pslog.log import read_session
from pslog.records import NS
from pslog.rig import apply_timing, builtin_rig, save_rig
from recorders import record_synthetic
from recorders.sources import synthetic_times
from tests._sources import ScheduledSource, Spec

ORANGE_BGR = (20, 110, 255)


def _best_errors(session) -> np.ndarray:
    """Pixel distance of every frame's best candidate to the truth's projection."""
    obs = session.detections.best()
    errors = np.empty(len(obs))
    for i, cam in enumerate(session.rig.cameras):
        rows = obs.camera == i
        uv, _ = cam.project(session.truth.at(obs.time_ns[rows]))
        errors[rows] = np.linalg.norm(obs.uv[rows] - uv, axis=1)
    return errors


def test_record_synthetic_library(tmp_path):
    rig = builtin_rig("paper3")
    out = tmp_path / "s.mcap"
    summary = record_synthetic(rig, "throw", out, timing="typeA", duration=0.4, status=None)
    session = read_session(out)
    typea = apply_timing(rig, "typeA")
    assert session.rig == typea and session.timing == "typeA"
    det = session.detections
    for i, cam in enumerate(typea.cameras):
        rows = det.frame_camera == i
        assert_array_equal(det.frame_time_ns[rows], synthetic_times(cam, 0.4))
        assert_array_equal(det.frame_index[rows], np.arange(rows.sum()))
    assert summary.n_frames == det.n_frames == session.n_images == 36
    assert np.all(det.candidates_per_frame() >= 1)
    assert_array_equal(session.truth.time_ns, np.unique(det.frame_time_ns))
    errors = _best_errors(session)
    assert np.sqrt(np.mean(errors**2)) < 0.4 and errors.max() < 1.0
    assert session.metadata["synthetic_motion"] == "throw"
    assert session.metadata["detector_hsv"] == "4,22,120,255,70,255"
    with pytest.raises(Exception, match="exists"):
        record_synthetic(rig, "throw", out, duration=0.1, status=None)


def test_cli_synthetic_without_frames(tmp_path, capsys):
    out = tmp_path / "s.mcap"
    rc = main(["record", "--synthetic", "--rig", "paper2", "--timing", "sync", "--motion",
               "spiral", "--duration", "0.3", "--fast", "--no-frames", "-o", str(out)])
    assert rc == 0
    err = capsys.readouterr().err
    assert "cam2" in err
    # the session's own span (9 frames at 30 fps), not the wall time it took to render
    assert "18 frames over 0.267 s of session time, recorded in " in err, err
    session = read_session(out)
    assert session.n_images == 0 and session.timing == "sync"
    assert session.detections.n_frames == 18
    assert _best_errors(session).max() < 1.0


def _write_clip(path: Path, centers: np.ndarray, fps: float = 30.0) -> None:
    """An MJPG video of an orange disc (radius 6 px) at ``centers`` (n, 2) over grey-green."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (640, 480))
    assert writer.isOpened()
    for u, v in centers:
        frame = np.full((480, 640, 3), (60, 120, 70), np.uint8)
        cv2.circle(frame, (round(u * 16), round(v * 16)), 6 * 16, ORANGE_BGR, -1,
                   lineType=cv2.LINE_8, shift=4)
        writer.write(frame)
    writer.release()


@pytest.fixture
def two_camera_rig(tmp_path) -> Path:
    path = tmp_path / "rig.toml"
    save_rig(builtin_rig("paper2"), path)
    return path


def test_record_video_files_with_offsets(tmp_path, two_camera_rig):
    n = 20
    k = np.arange(n)
    centers1 = np.stack([100 + 10.3 * k, 200 + 3.1 * k], axis=1)
    centers2 = np.stack([500 - 7.7 * k, 100 + 8.9 * k], axis=1)
    _write_clip(tmp_path / "a.avi", centers1)
    _write_clip(tmp_path / "b.avi", centers2)
    out = tmp_path / "s.mcap"
    rc = main(["record", "--rig", str(two_camera_rig), "--source", f"cam1={tmp_path}/a.avi@0.25",
               "--source", f"cam2={tmp_path}/b.avi", "--offset", "cam2=0.0167", "-o", str(out)])
    assert rc == 0
    session = read_session(out)
    det = session.detections
    assert session.n_images == det.n_frames == 2 * n
    for cam, offset, centers in ((0, 0.25, centers1), (1, 0.0167, centers2)):
        rows = np.flatnonzero(det.frame_camera == cam)
        assert_array_equal(det.frame_index[rows], k)
        expected_ns = np.round((offset + k / 30.0) * NS).astype(np.int64)
        assert np.abs(det.frame_time_ns[rows] - expected_ns).max() <= 1000  # 1 µs
        best = det.best()
        mine = best.camera == cam
        # cv2.circle rasterises to whole pixels; MJPG blurs the edge a little
        assert_allclose(best.uv[mine], centers, atol=0.5)
    assert any("container timestamps" in text for _t, text in session.events)


@pytest.mark.parametrize("bad", ["garbage.avi", "/dev/video63"])
def test_source_that_fails_to_open(tmp_path, two_camera_rig, capsys, bad):
    _write_clip(tmp_path / "a.avi", np.tile([[320.0, 240.0]], (10, 1)))
    (tmp_path / "garbage.avi").write_text("not a video")
    spec = str(tmp_path / bad) if not bad.startswith("/") else bad
    out = tmp_path / "s.mcap"
    rc = main(["record", "--rig", str(two_camera_rig), "--source", f"cam1={tmp_path}/a.avi",
               "--source", f"cam2={spec}", "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 0  # the other camera recorded
    assert "cam2" in err and "cannot open" in err
    session = read_session(out)
    assert_array_equal(np.bincount(session.detections.frame_camera, minlength=2), [10, 0])
    assert any("cam2 failed" in text and "cannot open" in text for _t, text in session.events)


def test_record_errors(tmp_path, two_camera_rig, capsys):
    _write_clip(tmp_path / "a.avi", np.tile([[320.0, 240.0]], (3, 1)))
    clip = f"cam1={tmp_path}/a.avi"
    out = str(tmp_path / "s.mcap")
    rig = str(two_camera_rig)
    cases = [
        (["--source", clip], "no source for camera(s) cam2"),
        (["--source", clip, "--source", "cam2=0", "--source", "cam9=1"], "cam9"),
        (["--source", clip, "--source", f"cam2={tmp_path}/missing.mp4"], "missing.mp4"),
        (["--source", clip, "--source", "cam2=0", "--hsv", "1,2,3"], "--hsv"),
        (["--source", clip, "--source", "cam2=0", "--offset", "cam2=0.1"], "no video file"),
        (["--synthetic", "--source", clip], "--synthetic"),
        (["--synthetic", "--motion", "loop"], "unknown motion"),
    ]
    usage = ("--hsv", "unknown motion", "--synthetic")  # bad values and clashes: exit 2
    for extra, message in cases:
        try:
            code = main(["record", "--rig", rig, "-o", out, *extra])
        except SystemExit as exc:
            code = exc.code
        assert code == (2 if message in usage else 1), (extra, code)
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err, (extra, err)
        assert not Path(out).exists()
    Path(out).write_bytes(b"keep me")
    assert main(["record", "--rig", rig, "-o", out, "--source", clip, "--source",
                 "cam2=0"]) == 1
    assert "--force" in capsys.readouterr().err
    assert Path(out).read_bytes() == b"keep me"


class _StallingSource(ScheduledSource):
    """A live 30 fps camera that pauses 1.6 s after 10 frames, resumes for 10 frames, then
    dies (stamped when delivered)."""

    stamp_due = False

    def delay_s(self, k: int) -> float:
        return 1.6 if k >= 10 else 0.0

    def end(self, k: int) -> bool:
        from recorders.sources import SourceError

        if k == 20:
            raise SourceError("test camera unplugged")
        return False


def test_camera_that_stalls_and_dies_is_logged_while_others_record(tmp_path):
    from recorders.record import record
    from recorders.sources import FileSpec

    _write_clip(tmp_path / "a.avi", np.tile([[320.0, 240.0]], (30, 1)))
    rig = builtin_rig("paper2")
    out = tmp_path / "s.mcap"
    summary = record(rig, {"cam1": FileSpec(str(tmp_path / "a.avi"), 640, 480),
                           "cam2": Spec(_StallingSource, "stalling test camera")}, out, status=None)
    assert summary.failed == ("cam2",)
    cam1, cam2 = summary.cameras
    assert cam1.frames == 30 and cam1.state == "done"
    assert cam2.frames == 20 and "unplugged" in cam2.message
    assert cam2.drops >= 40  # the 1.6 s gap at 30 fps
    events = read_session(out).events
    texts = [text for _t, text in events]
    assert any("cam2 stopped delivering frames" in t for t in texts)
    assert any("cam2 delivering again" in t for t in texts)
    # the stall just after its last frame, before the frame that ends it
    stalled = next(t for t, text in events if "cam2 stopped delivering" in text)
    again = next(t for t, text in events if "cam2 delivering again" in text)
    frames = np.sort(read_session(out).detections.frame_time_ns[
        read_session(out).detections.frame_camera == 1])
    assert stalled == frames[9] + 1 and again == frames[10] > stalled
    assert any("cam2 failed: test camera unplugged" in t for t in texts)
    det = read_session(out).detections
    assert_array_equal(np.bincount(det.frame_camera), [30, 20])


def test_record_says_when_the_measured_shutter_offsets_are_not_the_rigs(
        tmp_path, two_camera_rig, capsys):
    k = np.arange(12)
    centers = np.stack([100 + 10.3 * k, 200 + 3.1 * k], axis=1)
    _write_clip(tmp_path / "a.avi", centers)
    _write_clip(tmp_path / "b.avi", centers)
    sources = ["--source", f"cam1={tmp_path}/a.avi", "--source", f"cam2={tmp_path}/b.avi"]
    # cam2's file starts 11.1 ms later: its shutter is 11.1 ms after cam1's, the rig says 0
    rc = main(["record", "--rig", str(two_camera_rig), *sources, "--offset", "cam2=0.0111",
               "-o", str(tmp_path / "late.mcap")])
    assert rc == 0
    captured = capsys.readouterr()
    assert "note:" not in captured.out  # stdout stays for data; messages go to stderr
    notes = [ln for ln in captured.err.splitlines() if ln.startswith("pslog record: note:")]
    assert len(notes) == 1, notes
    assert "cam2 11.1 ms (rig 0.0 ms)" in notes[0] and "'sync'" in notes[0]
    assert "cam1 " not in notes[0]
    # a whole number of periods later is the same shutter phase: nothing to say
    rc = main(["record", "--rig", str(two_camera_rig), *sources, "--offset", "cam2=0.0667",
               "-o", str(tmp_path / "whole.mcap")])
    assert rc == 0
    assert "note:" not in str(capsys.readouterr())
    # more than half a period later: measured as a negative phase (-8.3 ms), said as the
    # offset within the frame period a rig takes (25.0 ms; a rig refuses -8.3)
    rc = main(["record", "--rig", str(two_camera_rig), *sources, "--offset", "cam2=0.025",
               "-o", str(tmp_path / "later.mcap")])
    assert rc == 0
    notes = [ln for ln in capsys.readouterr().err.splitlines()
             if ln.startswith("pslog record: note:")]
    assert len(notes) == 1 and "cam2 25.0 ms (rig 0.0 ms)" in notes[0], notes


def test_offset_note_that_cannot_read_the_session_back_is_not_an_error(tmp_path, capsys):
    """The note re-reads a complete recording; if that read fails, the recording stands."""
    from pslog.cli.record import _note_offsets

    broken = tmp_path / "gone.mcap"
    broken.write_bytes(b"not an MCAP file")
    _note_offsets(broken, builtin_rig("paper2"))  # no exception
    err = capsys.readouterr().err
    assert err.startswith("pslog record: note: the recorded shutter offsets could not be "
                          "compared"), err
    assert str(broken) in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("argv", [["record", "--help"], ["record", "--no-such-option"],
                                  ["record", "--rig", "paper3", "-o", "/no/such/dir/s.mcap",
                                   "--synthetic"]])
def test_record_leaves_the_signal_handlers_as_it_found_them(argv):
    """Building the parser, an argparse error or a refused output must not take over
    Ctrl-C/SIGTERM for the rest of the process (pytest then ignored Ctrl-C)."""
    import signal

    before = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        code = main(argv)
    except SystemExit as exc:  # --help and argparse errors
        code = exc.code
    assert code in (0, 1, 2)
    assert {sig: signal.getsignal(sig) for sig in before} == before


def test_synthetic_cameras_render_the_clock_errors_their_rig_corrects(tmp_path, capsys):
    """A rig from 'pslog sync' (cam2's clock 4 ms late, drifting 30 ppm, its rolling shutter
    reading rows over 20 ms) recorded with --synthetic: each camera sees the ball at the true
    times of its stamps, as 'pslog live --synthetic' renders it, so the stored rig's
    corrections put the fused points on the motion (rendered on the nominal clock, as before,
    the corrections moved them off it: median 17.2 mm here; rendered with them 3.0, as a rig
    without clock errors gives on this rally, 3.1)."""
    from dataclasses import replace

    from pslog.evaluation import evaluate

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    cam2 = replace(rig.cameras[1], clock_offset=0.004, clock_drift_ppm=30.0, readout=0.02)
    save_rig(replace(rig, cameras=(rig.cameras[0], cam2, rig.cameras[2])),
             tmp_path / "synced.toml")
    out, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    assert main(["record", "--synthetic", "--rig", str(tmp_path / "synced.toml"), "--motion",
                 "rally", "--duration", "1.5", "--fast", "--no-frames", "-o", str(out)]) == 0
    session = read_session(out)
    assert session.rig.cameras[1].clock_offset == 0.004  # the corrections are stored
    assert main(["fuse", str(out), "--method", "typeA", "-o", str(fused)]) == 0
    capsys.readouterr()
    session = read_session(fused)
    accuracy = evaluate(session.tracks["typeA"], session.truth)
    assert accuracy.n_points > 100
    assert accuracy.median_mm < 6.0, accuracy


def test_record_outside_a_terminal_prints_no_status_line_of_zeros(tmp_path, capsys):
    """stderr not a terminal (a log): a status line only once a period has passed, with the
    counts, never the loop's first line of zeros before any frame (a new user's walkthrough,
    session 23: '[ 3.1 s] cam1: 0 fr 0.0 fps 0 det 0 drop | ...' as the only line); a camera
    started without a frame yet says so."""
    from recorders.status import CameraStatus, StatusBoard

    out = tmp_path / "s.mcap"
    rc = main(["record", "--synthetic", "--rig", "paper2", "--timing", "sync", "--motion",
               "spiral", "--duration", "0.3", "--fast", "--no-frames", "-o", str(out)])
    assert rc == 0
    err = capsys.readouterr().err
    assert "18 frames over 0.267 s of session time" in err, err
    # frames with a candidate: the recorder cannot tell the ball from a static orange object
    # ('pslog info' can: its "moving" rate), so it does not say "with ball"
    assert re.search(r"cam1 +9 frames .* 9 with a candidate \(100\.0 %\)", err), err
    assert not re.search(r" 0 fr +0\.0 fps 0 det", err), err
    board = StatusBoard([CameraStatus("cam1", "synthetic", state="recording")])
    assert board.line().endswith("cam1: started, no frame yet")
    board.cameras[0].add_frame(0, True, 0.0)
    assert "cam1: 1 fr" in board.line()


def test_every_line_record_writes_to_stderr_names_the_command(tmp_path, capsys, monkeypatch):
    """The recorder's status lines, messages and summary start with ``pslog record: `` as
    every command's lines on stderr do (they had no prefix: session 30's walkthrough); only
    the summary's per-camera table below its first line is indented."""
    import recorders.record

    monkeypatch.setattr(recorders.record, "_LOG_REFRESH_S", 0.1)  # status lines into a log
    out = tmp_path / "s.mcap"
    rc = main(["record", "--synthetic", "--rig", "paper2", "--timing", "sync", "--motion",
               "spiral", "--duration", "0.5", "--no-frames", "-o", str(out)])
    assert rc == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    status = [ln for ln in lines if ln.startswith("pslog record: [")]
    # (each camera's part: recording 'N fr ...', finished 'done (N fr)' when the board
    # refreshes after the cameras ended, as on a loaded machine, or 'no frame yet')
    assert status and all(re.search(r"\d+ fr[ )]", ln) or "no frame yet" in ln
                          for ln in status), lines
    assert f"pslog record: recorded: {out}" in lines, lines
    table = [ln for ln in lines if not ln.startswith("pslog record: ")]
    assert len(table) == 3 and all(ln.startswith("  ") for ln in table), lines
    assert [ln.split()[0] for ln in table] == ["cam1", "cam2", "total"], lines
