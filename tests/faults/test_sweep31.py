"""Session 31's small user-facing defects through the real CLI: every bad command-line value
of ``calibrate`` exits 2 as argparse's do (an --offset beyond the frame period exited 1), and
``rig export`` never writes a format under another format's name (a Pose2Sim calibration
named ``.yml`` was written as TOML)."""

from __future__ import annotations

from pathlib import Path

import pytest

from pslog.rig import Rig, builtin_rig, save_rig

from ._inputs import write_points_csv
from .promises import assert_refused


@pytest.fixture
def work(tmp_path) -> Path:
    """pts.csv (paper3's cam1) and rig.toml holding cam1 at 30 fps, shutter offset 20 ms."""
    write_points_csv(tmp_path / "pts.csv")
    cam = builtin_rig("paper3").cameras[0].replace(offset=0.02)
    save_rig(Rig((cam,), "lab"), tmp_path / "rig.toml")
    return tmp_path


CALIBRATE = ["calibrate", "--points", "pts.csv", "--width", "640", "--height", "480"]


@pytest.mark.parametrize("args, contains", [
    # was exit 1 ("camera 'new': offset 0.04 s must be in [0, 0.0333333 s)")
    ([*CALIBRATE, "--name", "new", "--rig", "rig.toml", "--offset", "0.04"],
     ("argument --offset: 0.04 s must be below the frame period", "at 30 fps")),
    ([*CALIBRATE, "--name", "new", "--rig", "rig.toml", "--offset", "0.02", "--fps", "60"],
     ("argument --offset: 0.02 s", "0.0166667 s at 60 fps")),
    # the rig's offset kept at a new frame rate: its --fps is the bad value
    ([*CALIBRATE, "--name", "cam1", "--rig", "rig.toml", "--force", "--fps", "60"],
     ("argument --fps: the offset of camera 'cam1' in rig.toml, 0.02 s", "give --offset")),
    (["calibrate", "--points", "pts.csv", "--name", "cam1", "--rig", "rig.toml",
      "--fix-intrinsics", "--fps", "60"], "argument --fps: the offset of camera 'cam1'"),
    (["calibrate", "--points", "pts.csv", "--name", "cam1", "--rig", "rig.toml",
      "--fix-intrinsics", "--width", "320"], "--width 320 differs from the width of camera"),
    (["calibrate", "--points", "pts.csv", "--name", "new", "--rig", "rig.toml"],
     "--width and --height are required for a new camera"),
    (["calibrate", "--chessboard", "9x6", "--name", "new", "--rig", "rig.toml"],
     "--chessboard needs --images"),
    ([*CALIBRATE, "--images", "shots", "--name", "new", "--rig", "rig.toml"],
     "--images goes with --chessboard"),
    (["calibrate", "--chessboard", "9x6", "--images", "shots", "--fix-intrinsics", "--name",
      "new", "--rig", "rig.toml"], "--fix-intrinsics goes with --points"),
    # was exit 1 from the camera's check ("width 99999999 pixels is beyond any camera")
    (["calibrate", "--points", "pts.csv", "--name", "new", "--rig", "rig.toml", "--width",
      "99999999", "--height", "480"], "argument --width: must be in 1..65536"),
], ids=["offset", "offset-at-fps", "fps-against-rig", "fps-fix-intrinsics",
        "width-against-rig", "no-size", "no-images", "images-alone", "fix-chessboard",
        "width-huge"])
def test_every_bad_calibrate_value_exits_2_in_one_line(work, args, contains):
    line = assert_refused(work, 2, args, contains)
    assert line.startswith("pslog calibrate: error: ") and "--help" in line, line


def test_a_missing_file_is_still_a_fault_of_calibrate(work):
    """Exit 1 stays for what names a file or camera that is not there."""
    assert_refused(work, 1, ["calibrate", "--points", "pts.csv", "--name", "new", "--rig",
                             "other.toml", "--fix-intrinsics"], "other.toml does not exist")


@pytest.mark.parametrize("fmt, name, contains", [
    # was written as TOML: Pose2Sim never finds it (it reads *.toml), pslog read it as OpenCV
    ("pose2sim", "Calib.yml", "a Pose2Sim calibration (TOML) is named .toml"),
    ("pose2sim", "Calib.yaml", "a Pose2Sim calibration (TOML) is named .toml"),
    ("anipose", "calibration.json", "an aniposelib calibration (TOML) is named .toml"),
    ("anipose", "calibration", "an aniposelib calibration (TOML) is named .toml"),
    ("opencv", "cameras.toml", "an OpenCV FileStorage file is named .yml"),
    ("opencv", "new.txt", "an OpenCV FileStorage file is named .yml"),  # (was exit 1)
])
def test_rig_export_refuses_a_name_of_another_format(work, fmt, name, contains):
    line = assert_refused(work, 2, ["rig", "export", "paper3", "--format", fmt, "-o", name],
                          (f"-o {name}: ", contains))
    assert line.startswith("pslog rig export: error: "), line


@pytest.mark.parametrize("args, contains", [
    # were exit 1 ("rig.toml: camera 'cam1': offset 5 s must be in [0, 0.0333333 s)"), where
    # simulate's --readout / --clock-offset against the rig exit 2
    (["--offset", "cam1=5"], ("argument --offset: rig.toml: camera 'cam1': offset 5 s",
                              "the frame period at 30 fps")),
    (["--fps", "60", "--offset", "cam1=0.02"], ("argument --offset", "at 60 fps")),
    (["--offset", "cam9=0.001"], ("argument --offset", "unknown camera(s) cam9")),
    (["--timing", "typeA", "--offset", "cam1=0.001"], "give --timing or --offset, not both"),
], ids=["offset", "offset-at-fps", "offset-unknown-camera", "offset-and-timing"])
def test_rig_import_options_that_do_not_fit_the_file_exit_2(work, args, contains):
    line = assert_refused(work, 2, ["rig", "import", "rig.toml", *args, "-o", "new.toml"],
                          contains)
    assert line.startswith("pslog rig import: error: "), line
