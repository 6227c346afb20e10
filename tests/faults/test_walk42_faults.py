"""Session 42's walkthrough (walk42), the faults a user made: through the real CLI on real
files, each case asserting the three promises (one line, exit code, nothing written).

Found and fixed: `pslog import` of a detector's own CSV (`cam_id,t_unix,x_px,y_px,frame_no,
conf`) without `--columns` said "bad header ... (unknown: ...) (missing: ...)" and not a word
of `--columns`, the option made for it; the line now names it with the missing columns.
`pslog record` (and `live`) given one video file for two cameras (a source copied for the
next camera, its file left) recorded cam1's clip as cam2's too, without a word: now a
command-line error (exit 2) naming both cameras, nothing written.
"""

from __future__ import annotations

import shutil

import pytest

from .promises import assert_one_line_error, run_pslog
from .test_sweep36 import _clip  # (an MJPEG clip of an orange ball crossing a green field)

_ROWS = "cam1,1780000000.000000,320.5,240.25,0,0.9\ncam2,1780000000.011100,300.0,200.0,0,0.8\n"


@pytest.mark.parametrize(("header", "hint"), [
    ("cam_id,t_unix,x_px,y_px,frame_no,conf",
     "--columns camera=COLUMN,time=COLUMN,u=COLUMN,v=COLUMN"),
    ("camera,t_unix,u,v,frame,score", "--columns time=COLUMN"),
])
def test_import_of_a_detectors_own_header_names_columns(tmp_path, header, hint):
    path = tmp_path / "detector.csv"
    path.write_text(header + "\n" + _ROWS)
    out = tmp_path / "lab.mcap"
    run = run_pslog("import", "--rig", "paper3", "--detections", path, "-o", out)
    assert_one_line_error(run, 1, contains=("bad header", hint))
    assert not out.exists() and not list(tmp_path.glob("lab.mcap*"))


@pytest.mark.parametrize("command", ["record", "live"])
def test_one_video_file_for_two_cameras_is_refused(tmp_path, command):
    a, b = tmp_path / "a.avi", tmp_path / "b.avi"
    _clip(a)
    shutil.copy(a, b)
    rig = tmp_path / "rig.toml"
    done = run_pslog("rig", "show", "paper2")
    assert done.code == 0, done.stderr
    rig.write_text(done.stdout)
    out = tmp_path / "s.mcap"
    extra = ["--duration", "1", "--record", out] if command == "live" else ["-o", out]
    run = run_pslog(command, "--rig", rig, "--source", f"cam1={a}",
                    "--source", f"cam2={tmp_path}/./a.avi@0.01", *extra)
    assert_one_line_error(run, 2, contains=(
        f"camera 'cam2' and camera 'cam1' both read {tmp_path}/./a.avi (as {a}): each "
        f"camera needs a video file of its own"))
    assert not list(tmp_path.glob("s.mcap*"))
    if command == "record":  # two files of equal bytes are two cameras' (not refused)
        run = run_pslog(command, "--rig", rig, "--source", f"cam1={a}", "--source",
                        f"cam2={b}", *extra)
        assert run.code == 0, run.stderr
