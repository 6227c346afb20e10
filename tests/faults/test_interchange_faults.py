"""Malformed calibrations of other tools and refused exports through the real CLI (issue 13,
interchange): each case asserts the three promises of :mod:`tests.faults.promises`."""

from __future__ import annotations

from pathlib import Path

import pytest

from ._inprocess import assert_refused as assert_refused_here
from ._inprocess import first_case
from .promises import assert_refused

GOOD_ANIPOSE = """\
[cam_0]
name = "cam1"
size = [ 640, 480,]
matrix = [ [ 500.0, 0.0, 320.0,], [ 0.0, 500.0, 240.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ 0.0, 0.0, 0.0, 0.0, 0.0,]
rotation = [ 0.0, 0.0, 0.0,]
translation = [ 0.0, 0.0, 3.0,]

[cam_1]
name = "cam2"
size = [ 640, 480,]
matrix = [ [ 500.0, 0.0, 320.0,], [ 0.0, 500.0, 240.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ 0.0, 0.0, 0.0, 0.0, 0.0,]
rotation = [ 0.0, 0.3, 0.0,]
translation = [ -1.0, 0.0, 3.0,]
"""

GOOD_OPENCV = """\
%YAML:1.0
---
image_width: 640
image_height: 480
camera_matrix: !!opencv-matrix
   rows: 3
   cols: 3
   dt: d
   data: [ 500., 0., 320., 0., 500., 240., 0., 0., 1. ]
distortion_coefficients: !!opencv-matrix
   rows: 1
   cols: 5
   dt: d
   data: [ 0., 0., 0., 0., 0. ]
rvec: [ 0.0, 0.0, 0.0 ]
tvec: [ 0.0, 0.0, 3.0 ]
"""


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """A folder with a fused simulated session and an old output of each kind."""
    from pslog.cli import main

    folder = tmp_path_factory.mktemp("inputs")
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                 "--duration", "0.5", "-o", str(folder / "s.mcap")]) == 0
    assert main(["fuse", str(folder / "s.mcap"), "-o", str(folder / "f.mcap")]) == 0
    (folder / "old.toml").write_text("old\n")
    (folder / "old.jsonl").write_text("old\n")
    (folder / "traj").mkdir()
    (folder / "traj" / "typeA.tum").write_text("old\n")
    return folder


@pytest.mark.parametrize("name, old, new, why", [
    ("calibration.toml", "translation = [ 0.0, 0.0, 3.0,]\n", "",
     ("calibration.toml", "[cam_0]", "missing key(s) translation")),
    ("calibration.toml", "rotation = [ 0.0, 0.3, 0.0,]", "rotation = [ 0.0, 0.3]",
     ("calibration.toml", "[cam_1]", "rotation must have shape")),
    ("calibration.toml", "translation = [ -1.0,", "translation = [ inf,",
     ("calibration.toml", "[cam_1]", "non-finite")),
    ("calibration.toml", "translation = [ -1.0, 0.0, 3.0,]", "translation = [ -1000.0, 0.0, "
     "3000.0,]", ("calibration.toml", "look like millimetres", "--units mm")),
    ("calibration.toml", "[cam_0]", "[cam_0\n", ("calibration.toml", "malformed TOML")),
    ("calibration.toml", "matrix", "intrinsics", ("calibration.toml", "unknown rig format")),
    ("calibration.toml", "[cam_1]\nname = \"cam2\"\nsize = [ 640, 480,]\nmatrix",
     "[cam_1]\nname = \"cam2\"\nsize = [ 640, 480,]\nintrinsics",
     ("calibration.toml", "[cam_1]", "missing key(s) matrix")),
    ("cams.yml", "rvec: [ 0.0, 0.0, 0.0 ]\n", "", ("cams.yml", "missing key R or rvec")),
    ("cams.yml", "tvec: [ 0.0, 0.0, 3.0 ]", "tvec: [ 0.0, .nan, 3.0 ]",
     ("cams.yml", "tvec has non-finite values")),
    ("cams.yml", "rows: 3\n   cols: 3", "rows: 2\n   cols: 3",
     ("cams.yml", "camera_matrix")),
    ("cams.yml", "tvec: [", "tvec: {[", ("cams.yml", "malformed OpenCV FileStorage")),
])
def test_malformed_calibration_is_one_line_exit_1_nothing_written(work, name, old, new, why,
                                                                  request):
    good = GOOD_ANIPOSE if name.endswith(".toml") else GOOD_OPENCV
    assert old in good
    (work / name).write_text(good.replace(old, new))
    assert_refused_here(work, 1, ["rig", "import", name, "-o", "rig.toml"], why,
                        real=first_case(request))


def test_malformed_calibration_given_as_rig_to_fuse_is_refused(work):
    (work / "cams.yml").write_text(GOOD_OPENCV.replace("image_width: 640\n", ""))
    assert_refused(work, 1, ["fuse", "s.mcap", "--rig", "cams.yml", "-o", "new.mcap"],
                   ("cams.yml", "missing key image_width"))


@pytest.mark.parametrize("args, why", [
    (["rig", "import", "cal.toml", "-o", "old.toml"], ("old.toml", "--force")),
    (["export", "f.mcap", "--jsonl", "old.jsonl"], ("old.jsonl", "--force")),
    (["export", "f.mcap", "--tum", "traj"], ("typeA.tum", "--force")),
    (["export", "f.mcap", "--tum", "old.jsonl"], ("old.jsonl", "not a folder")),
    (["export", "s.mcap", "--c3d", "t.c3d"], ("s.mcap", "no fused tracks")),
])
def test_exports_never_overwrite_or_write_what_they_cannot(work, args, why, request):
    (work / "cal.toml").write_text(GOOD_ANIPOSE)
    assert_refused_here(work, 1, args, why, real=first_case(request))


@pytest.mark.parametrize("args, why", [
    # each was written (exit 0) under the other format's name; '--c3d t.csv' then replaced
    # the Parquet '--parquet t.csv' had written
    (["--parquet", "t.csv"], "--parquet t.csv: a Parquet file is named .parquet or .pq"),
    (["--c3d", "t.csv"], "--c3d t.csv: a C3D file is named .c3d"),
    (["--csv", "t.parquet"], "--csv t.parquet: a CSV file is named .csv"),
    (["--jsonl", "t.json"], "--jsonl t.json: a JSON Lines file is named .jsonl or .ndjson"),
    (["--detections", "d.txt"], "--detections d.txt: a CSV file is named .csv"),
    # one bad name among good ones: nothing written
    (["--csv", "t.csv", "--jsonl", "t.jsonl", "--c3d", "t"], "--c3d t: a C3D file"),
    # a new --tum folder named as a file (session 33: 'traj.tum/' was made, typeA.tum inside)
    (["--tum", "traj.tum"], "--tum traj.tum: a folder, one TUM file per method inside"),
], ids=["parquet-as-csv", "c3d-as-csv", "csv-as-parquet", "jsonl-as-json", "detections-txt",
        "one-bad-of-three", "tum-folder-as-file"])
def test_export_refuses_a_name_of_another_format(work, args, why, request):
    """Session 32: as ``rig export -o`` and ``view --save``, a file named for another format
    is a bad command-line value (exit 2), refused before anything is read or written."""
    line = assert_refused_here(work, 2, ["export", "f.mcap", *args], why,
                               real=first_case(request))
    assert line.startswith("pslog export: error: "), line


def test_export_takes_each_format_s_other_suffixes(work):
    from pslog.cli import main

    names = ["T.CSV", "t.ndjson", "t.pq", "t.C3D"]
    assert main(["export", str(work / "f.mcap"), "--csv", str(work / names[0]), "--jsonl",
                 str(work / names[1]), "--parquet", str(work / names[2]), "--c3d",
                 str(work / names[3])]) == 0
    assert all((work / n).stat().st_size > 0 for n in names)


def test_parquet_without_pyarrow_is_one_line(work):
    """pyarrow shadowed by a package that fails to import, as when it is not installed."""
    shadow = work.parent / "shadow"
    (shadow / "pyarrow").mkdir(parents=True, exist_ok=True)
    (shadow / "pyarrow" / "__init__.py").write_text("raise ImportError('no pyarrow')\n")
    from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog

    before = fingerprint(work)
    run = run_pslog("export", "f.mcap", "--parquet", "t.parquet", cwd=work,
                    env={"PYTHONPATH": str(shadow)})
    assert_one_line_error(run, 1, contains=("--parquet needs pyarrow", "pslog[parquet]"))
    assert_untouched(before, work)
