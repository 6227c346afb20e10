"""Rigs to and from aniposelib / Pose2Sim calibration.toml and OpenCV FileStorage files
(pslog.interchange.rig_formats, ``pslog rig import|export``, ``--rig`` of every command)."""

from __future__ import annotations

import tomllib

import cv2
import numpy as np
import pytest

from pslog.camera import Camera
from pslog.errors import RigError
from pslog.interchange.rig_formats import ImportOptions, rig_to_format
from pslog.rig import Rig, apply_timing, builtin_rig, load_rig, load_rig_file, resolve_rig

# An aniposelib CameraGroup.dump in the shape aniposelib writes (cam_N tables, size as
# [width, height], 5 distortions, Rodrigues rotation, translation in the board's unit: mm)
ANIPOSE_MM = """\
[cam_0]
name = "A"
size = [ 1440, 1080,]
matrix = [ [ 1850.25, 0.0, 719.5,], [ 0.0, 1850.25, 539.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.0361, 0.0, 0.0, 0.0, 0.0,]
rotation = [ -0.0017, -0.0018, -0.0046,]
translation = [ 2.55, -2.77, 1818.17,]

[cam_1]
name = "B"
size = [ 1440, 1080,]
matrix = [ [ 1935.5, 0.0, 719.5,], [ 0.0, 1935.5, 539.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.3133, 0.0, 0.0, 0.0, 0.0,]
rotation = [ -0.2257, -2.982, 0.3874,]
translation = [ 117.37, 262.5, 1478.8,]

[metadata]
adjusted = true
error = 1.668
"""

# Pose2Sim's writer: [cam_NN] sections, sizes as floats, 4 distortions, fisheye = false,
# translations in metres, a [metadata] table
POSE2SIM = """\
[cam_01]
name = "cam_01"
size = [ 1088.0, 1920.0]
matrix = [ [ 1681.24, 0.0, 532.97], [ 0.0, 1681.07, 948.13], [ 0.0, 0.0, 1.0]]
distortions = [ -0.00072, 0.00218, 9.5e-06, 1.07e-05]
rotation = [ 1.688, 1.048, -0.4195]
translation = [ 0.321, 0.956, 2.890]
fisheye = false

[cam_02]
name = "cam_02"
size = [ 1088.0, 1920.0]
matrix = [ [ 1673.72, 0.0, 534.49], [ 0.0, 1673.79, 963.22], [ 0.0, 0.0, 1.0]]
distortions = [ -0.00074, 0.00213, 1.51e-05, 4.54e-06]
rotation = [ 1.349, 1.596, -1.198]
translation = [ -0.111, 0.776, 3.067]
fisheye = false

[metadata]
adjusted = false
error = 0.0
"""


def _random_rig(seed: int = 0, n: int = 4) -> Rig:
    """Cameras with random rotations (away from 180°, where Rodrigues is ill-conditioned),
    translations, intrinsics, distortions and timing (clock keys included)."""
    rng = np.random.default_rng(seed)
    cameras = []
    for i in range(n):
        axis = rng.normal(size=3)
        rvec = axis / np.linalg.norm(axis) * rng.uniform(0.1, 2.8)
        R = cv2.Rodrigues(rvec)[0]
        K = np.array([[rng.uniform(300, 2000), 0.0, rng.uniform(300, 700)],
                      [0.0, rng.uniform(300, 2000), rng.uniform(200, 500)], [0.0, 0.0, 1.0]])
        fps = float(rng.choice([30.0, 60.0, 119.88]))
        cameras.append(Camera(
            f"cam {i}ü", int(rng.integers(320, 4000)), int(rng.integers(240, 3000)), K,
            rng.normal(scale=0.1, size=5), R, rng.normal(scale=3.0, size=3), fps=fps,
            offset=float(rng.uniform(0, 1 / fps)),
            clock_offset=0.0 if i == 0 else float(rng.normal(scale=0.01)),
            clock_drift_ppm=0.0 if i == 0 else float(rng.normal(scale=20)),
            readout=float(rng.uniform(0, 0.5 / fps))))
    return Rig(tuple(cameras), "random rig")


def _assert_rigs_close(a: Rig, b: Rig, atol: float = 1e-12) -> None:
    assert a.names == b.names and a.name == b.name
    for ca, cb in zip(a.cameras, b.cameras, strict=True):
        assert (ca.width, ca.height) == (cb.width, cb.height)
        for key in ("K", "dist", "R", "t"):
            np.testing.assert_allclose(getattr(cb, key), getattr(ca, key), rtol=0, atol=atol,
                                       err_msg=f"{ca.name} {key}")
        for key in ("fps", "offset", "clock_offset", "clock_drift_ppm", "readout"):
            assert getattr(cb, key) == getattr(ca, key), (ca.name, key)


CASES = [("anipose", "calibration.toml"), ("pose2sim", "Calib.toml"), ("opencv", "c.yml"),
         ("opencv", "c.yaml"), ("opencv", "c.xml"), ("opencv", "c.json")]


@pytest.mark.parametrize("units", ["m", "mm"])
@pytest.mark.parametrize("fmt,name", CASES)
def test_pslog_rig_survives_a_round_trip_through_every_format(tmp_path, fmt, name, units):
    rig = _random_rig()
    path = tmp_path / name
    path.write_text(rig_to_format(rig, fmt, units, path.suffix), encoding="utf-8")
    loaded = load_rig_file(path, options=ImportOptions(units=units))
    assert loaded.format == fmt and loaded.units == units and loaded.timed
    _assert_rigs_close(rig, loaded.rig)


@pytest.mark.parametrize("fmt,name", CASES)
def test_translation_units_are_written_as_asked(tmp_path, fmt, name):
    rig = builtin_rig("paper3")
    m, mm = tmp_path / f"m{name}", tmp_path / f"mm{name}"
    m.write_text(rig_to_format(rig, fmt, "m", m.suffix), encoding="utf-8")
    mm.write_text(rig_to_format(rig, fmt, "mm", mm.suffix), encoding="utf-8")
    # the same file read in the wrong unit would be 1000 times off (cameras ~3 mm from the
    # origin): refused, naming the right unit, instead of silently shrinking the rig
    with pytest.raises(RigError, match=r"look like metres.*--units m ") as info:
        load_rig(m, options=ImportOptions(units="mm"))
    assert str(m) in str(info.value) and "\n" not in str(info.value)
    as_mm_file_in_m = load_rig(mm, options=ImportOptions(units="m"))  # m given: no check
    np.testing.assert_allclose(as_mm_file_in_m.cameras[1].t,
                               load_rig(m, options=ImportOptions(units="m")).cameras[1].t * 1000)
    np.testing.assert_allclose(load_rig(mm, options=ImportOptions(units="mm")).cameras[1].t,
                               rig.cameras[1].t, rtol=0, atol=1e-12)


def test_anipose_file_round_trips_its_own_values_exactly(tmp_path):
    src = tmp_path / "calibration.toml"
    src.write_text(ANIPOSE_MM, encoding="utf-8")
    rig = load_rig(src, options=ImportOptions(units="mm"))
    out = tmp_path / "again.toml"
    out.write_text(rig_to_format(rig, "anipose", "mm"), encoding="utf-8")
    a, b = tomllib.loads(ANIPOSE_MM), tomllib.loads(out.read_text(encoding="utf-8"))
    for key in ("cam_0", "cam_1"):
        assert b[key]["name"] == a[key]["name"] and b[key]["size"] == a[key]["size"]
        for field in ("matrix", "distortions", "rotation", "translation"):
            np.testing.assert_allclose(b[key][field], a[key][field], rtol=0, atol=1e-12)


def test_conventions_match_opencv_projection_of_the_files_own_rvec_and_tvec(tmp_path):
    """The world -> camera Rodrigues rotation, translation (mm -> m), K and distortion mean
    what cv2.projectPoints (aniposelib's and Pose2Sim's projection) says they mean."""
    src = tmp_path / "calibration.toml"
    src.write_text(ANIPOSE_MM, encoding="utf-8")
    rig = load_rig(src, options=ImportOptions(units="mm"))
    data = tomllib.loads(ANIPOSE_MM)
    for cam, key in zip(rig.cameras, ("cam_0", "cam_1"), strict=True):
        table = data[key]
        assert (cam.width, cam.height) == tuple(table["size"])
        # points 1 m in front of the camera, in the file's unit (mm)
        rng = np.random.default_rng(1)
        in_cam = np.column_stack([rng.uniform(-0.3, 0.3, (20, 2)), rng.uniform(1, 3, 20)])
        world_m = (in_cam - cam.t) @ cam.R  # R^T (x - t)
        expected, _ = cv2.projectPoints(world_m * 1000, np.array(table["rotation"]),
                                        np.array(table["translation"]),
                                        np.array(table["matrix"]),
                                        np.array(table["distortions"]))
        uv, in_front = cam.project(world_m)
        assert in_front.all()
        np.testing.assert_allclose(uv, expected.reshape(-1, 2), atol=1e-6)


def test_anipose_file_in_millimetres_is_refused_without_units_and_read_with_them(tmp_path):
    src = tmp_path / "calibration.toml"
    src.write_text(ANIPOSE_MM, encoding="utf-8")
    with pytest.raises(RigError, match=r"look like millimetres.*--units mm") as info:
        load_rig(src)
    assert str(src) in str(info.value)
    loaded = load_rig_file(src, options=ImportOptions(units="mm"))
    assert loaded.format == "anipose" and loaded.units == "mm" and not loaded.timed
    assert loaded.rig.names == ("A", "B")
    assert [c.fps for c in loaded.rig.cameras] == [30.0, 30.0]  # the stated default
    np.testing.assert_allclose(loaded.rig.cameras[1].t, [0.11737, 0.2625, 1.4788])
    # --units m is an explicit choice: no check
    assert load_rig(src, options=ImportOptions(units="m")).cameras[1].t[2] == 1478.8


def test_pose2sim_file_is_read_as_metres_with_four_distortions(tmp_path):
    src = tmp_path / "Calib_scene.toml"
    src.write_text(POSE2SIM, encoding="utf-8")
    loaded = load_rig_file(src)
    assert loaded.format == "pose2sim" and loaded.units == "m"
    cam = loaded.rig.cameras[0]
    assert (cam.name, cam.width, cam.height) == ("cam_01", 1088, 1920)
    np.testing.assert_array_equal(cam.dist, [-0.00072, 0.00218, 9.5e-06, 1.07e-05, 0.0])
    np.testing.assert_array_equal(cam.t, [0.321, 0.956, 2.890])
    np.testing.assert_allclose(cv2.Rodrigues(cam.R)[0].ravel(), [1.688, 1.048, -0.4195],
                               atol=1e-12)
    # written back as Pose2Sim writes it
    text = rig_to_format(loaded.rig, "pose2sim")
    data = tomllib.loads(text)
    assert data["cam_01"]["fisheye"] is False and data["cam_01"]["size"] == [1088.0, 1920.0]
    assert len(data["cam_01"]["distortions"]) == 4
    assert data["metadata"] == {"adjusted": False, "error": 0.0}


def test_anipose_export_sections_sort_in_camera_order_beyond_ten_cameras():
    # aniposelib loads sorted(section names): cam_10 would come before cam_2
    rig = Rig(tuple(builtin_rig("paper3").cameras[0].replace(name=f"c{i}") for i in range(12)))
    data = tomllib.loads(rig_to_format(rig, "anipose"))
    sections = [k for k in data if k != "metadata"]
    assert sorted(sections) == sections and [data[k]["name"] for k in sections] == list(
        rig.names)


def test_opencv_single_camera_file_as_opencv_calibration_writes_it(tmp_path):
    """One camera at the top level (the layout of OpenCV's calibration sample), rvec/tvec,
    a 5 x 1 distortion, extra keys ignored, the camera named after the file."""
    path = tmp_path / "left.yml"
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    storage.write("calibration_time", "today")
    storage.write("image_width", 1280)
    storage.write("image_height", 720)
    K = np.array([[900.0, 0, 640.5], [0, 901.0, 360.25], [0, 0, 1]])
    storage.write("camera_matrix", K)
    storage.write("distortion_coefficients", np.array([[0.1], [-0.2], [0.001], [0.002], [0.3]]))
    storage.write("rvec", np.array([[0.1], [0.2], [0.3]]))
    storage.write("tvec", np.array([[0.5], [-0.25], [4.0]]))
    storage.write("avg_reprojection_error", 0.21)
    storage.release()
    loaded = load_rig_file(path)
    cam = loaded.rig.cameras[0]
    assert loaded.format == "opencv" and cam.name == "left" and (cam.width, cam.height) == (
        1280, 720)
    np.testing.assert_array_equal(cam.K, K)
    np.testing.assert_array_equal(cam.dist, [0.1, -0.2, 0.001, 0.002, 0.3])
    np.testing.assert_array_equal(cam.R, cv2.Rodrigues(np.array([0.1, 0.2, 0.3]))[0])
    np.testing.assert_array_equal(cam.t, [0.5, -0.25, 4.0])


def test_opencv_ros_camera_info_style_matrices_and_eight_coefficients(tmp_path):
    path = tmp_path / "cams.yaml"
    path.write_text("""\
%YAML:1.0
---
rig_name: "two"
left:
   camera_name: "L"
   image_width: 640
   image_height: 480
   camera_matrix:
      rows: 3
      cols: 3
      data: [ 500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0 ]
   distortion_coefficients: !!opencv-matrix
      rows: 1
      cols: 8
      dt: d
      data: [ 0.01, 0.02, 0.0, 0.0, 0.03, 0.0, 0.0, 0.0 ]
   R: !!opencv-matrix
      rows: 3
      cols: 3
      dt: d
      data: [ 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0 ]
   T: [ 0.0, 0.0, 3.0 ]
right:
   image_width: 640
   image_height: 480
   camera_matrix: !!opencv-matrix
      rows: 3
      cols: 3
      dt: d
      data: [ 500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0 ]
   rvec: [ 0.0, 0.0, 0.0 ]
   tvec: [ -0.5, 0.0, 3.0 ]
""", encoding="utf-8")
    rig = load_rig(path)
    assert rig.names == ("L", "right") and rig.name == "two"
    np.testing.assert_array_equal(rig.cameras[0].dist, [0.01, 0.02, 0.0, 0.0, 0.03])
    np.testing.assert_array_equal(rig.cameras[1].t, [-0.5, 0.0, 3.0])


@pytest.mark.parametrize("text,why", [
    (ANIPOSE_MM.replace('translation = [ 2.55, -2.77, 1818.17,]\n', ''),
     r"\[cam_0\]: missing key\(s\) translation"),
    (ANIPOSE_MM.replace("rotation = [ -0.0017, -0.0018, -0.0046,]", "rotation = [ 1.0, 2.0]"),
     r"\[cam_0\]: rotation must have shape"),
    (ANIPOSE_MM.replace("distortions = [ -0.0361, 0.0, 0.0, 0.0, 0.0,]",
                        "distortions = [ -0.0361, 0.0, 0.0]"), "distortions must have shape"),
    (ANIPOSE_MM.replace("translation = [ 2.55,", "translation = [ nan,"),
     "translation has non-finite values"),
    (ANIPOSE_MM.replace("size = [ 1440, 1080,]", "size = [ 1440.5, 1080,]", 1),
     "whole pixels"),
    (ANIPOSE_MM.replace('name = "A"\n', 'name = "A"\nfisheye = true\n'), "fisheye"),
    (ANIPOSE_MM.replace('matrix = [ [ 1850.25', 'matrix = [ [ "x"'), "matrix is not numeric"),
    ("[cam_0]\nname = 1\n", "unknown rig format.*it has cam_0"),
    ("title = 'something else'\n", "unknown rig format"),
    ("[cam_0]\nmatrix = [[1.0]]\n", r"\[cam_0\]: missing key\(s\) size, distortions"),
])
def test_malformed_toml_calibrations_are_one_line_errors_naming_file_and_problem(
        tmp_path, text, why):
    path = tmp_path / "calibration.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RigError, match=why) as info:
        load_rig(path, options=ImportOptions(units="mm"))
    assert str(path) in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("text,why", [
    ("", "empty file"),
    ("camera_matrix: [1, 2\n  foo: {", "malformed OpenCV FileStorage file"),
    ("image_width: 640\nimage_height: 480\n", "missing key camera_matrix"),
    ("image_width: 640\nimage_height: 480\ncamera_matrix: [1.0, 2.0]\nR: [0.0, 0.0, 0.0]\n"
     "T: [0.0, 0.0, 1.0]\n", "camera_matrix must have shape"),
    ("image_width: 640\nimage_height: 480\ncamera_matrix: [500.0, 0.0, 320.0, 0.0, 500.0, "
     "240.0, 0.0, 0.0, 1.0]\nT: [0.0, 0.0, 1.0]\n", "missing key R or rvec"),
    ("image_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n  rows: 3\n"
     "  cols: 3\n  dt: d\n  data: [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]\n"
     "distortion_coefficients: [0.1, 0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0]\n"
     "rvec: [0.0, 0.0, 0.0]\ntvec: [0.0, 0.0, .inf]\n", "beyond k3"),
    ("image_width: 640\nimage_height: 480\ncamera_matrix: !!opencv-matrix\n  rows: 3\n"
     "  cols: 3\n  dt: d\n  data: [500.0, 0.0, 320.0, 0.0, 500.0, 240.0, 0.0, 0.0, 1.0]\n"
     "rvec: [0.0, 0.0, 0.0]\ntvec: [0.0, 0.0, .nan]\n", "tvec has non-finite values"),
])
def test_malformed_opencv_files_are_one_line_errors_naming_file_and_problem(
        tmp_path, text, why):
    path = tmp_path / "cam.yml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RigError, match=why) as info:
        load_rig(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_unknown_format_is_named(tmp_path):
    path = tmp_path / "rig.toml"
    path.write_text(rig_to_format(builtin_rig("paper2"), "anipose"), encoding="utf-8")
    with pytest.raises(RigError, match="unknown rig format 'kalibr'"):
        load_rig(path, "kalibr")
    with pytest.raises(RigError, match=r"an anipose calibration, not a pslog rig TOML"):
        load_rig(path, "pslog")


# ---- the CLI ------------------------------------------------------------------------------

def test_rig_import_and_export_commands(tmp_path, cli):
    src = tmp_path / "calibration.toml"
    src.write_text(ANIPOSE_MM, encoding="utf-8")
    out = tmp_path / "rig.toml"
    code, stdout, _ = cli("rig", "import", src, "--units", "mm", "--fps", "120", "--offset",
                          "B=0.004", "-o", out)
    assert code == 0 and "anipose" in stdout and "read as mm" in stdout
    rig = load_rig(out)
    assert [c.fps for c in rig.cameras] == [120.0, 120.0]
    assert [c.offset for c in rig.cameras] == [0.0, 0.004]
    # never over an existing file without --force
    code, _, err = cli("rig", "import", src, "--units", "mm", "-o", out)
    assert code == 1 and "--force" in err
    for fmt, name in (("anipose", "a.toml"), ("pose2sim", "p.toml"), ("opencv", "o.xml")):
        code, stdout, _ = cli("rig", "export", out, "--format", fmt, "--units", "mm", "-o",
                              tmp_path / name)
        assert code == 0, stdout
        back = load_rig(tmp_path / name, options=ImportOptions(units="mm"))
        _assert_rigs_close(rig, back)
    code, _, err = cli("rig", "export", out, "--format", "opencv", "-o", tmp_path / "o.txt")
    assert code == 2 and ".yml" in err and not (tmp_path / "o.txt").exists()


@pytest.mark.parametrize("fmt,name", [("anipose", "calibration.toml"), ("opencv", "c.yml")])
def test_rig_import_refuses_a_metres_file_given_units_mm(tmp_path, cli, fmt, name):
    """The mirror of the millimetre check: paper3 (cameras ~3 m from the origin) written in
    metres and imported with --units mm would put its cameras ~3 mm from the origin."""
    src = tmp_path / name
    src.write_text(rig_to_format(builtin_rig("paper3"), fmt, "m", src.suffix), encoding="utf-8")
    out = tmp_path / "rig.toml"
    code, _, err = cli("rig", "import", src, "--units", "mm", "-o", out)
    assert code == 1 and err.count("\n") == 1 and "Traceback" not in err
    assert str(src) in err and "look like metres" in err and "--units m " in err
    assert not out.exists()
    code, _, _ = cli("rig", "import", src, "--units", "m", "-o", out)
    assert code == 0 and load_rig(out).cameras[1].t == pytest.approx(
        builtin_rig("paper3").cameras[1].t)


def test_rig_import_refuses_units_for_a_pslog_rig_toml(tmp_path, cli):
    src = tmp_path / "own.toml"
    src.write_text(builtin_rig("paper3").to_toml(), encoding="utf-8")
    out = tmp_path / "rig.toml"
    for units in ("mm", "m"):
        code, _, err = cli("rig", "import", src, "--units", units, "-o", out)
        assert code == 1 and err.count("\n") == 1 and "Traceback" not in err
        assert str(src) in err and "pslog rig TOML" in err and f"--units {units}" in err
        assert not out.exists()
    code, _, _ = cli("rig", "import", src, "-o", out)  # without --units: imported as it is
    assert code == 0 and load_rig(out).names == builtin_rig("paper3").names


def test_rig_check_names_a_foreign_format(tmp_path, cli):
    src = tmp_path / "Calib.toml"
    src.write_text(POSE2SIM, encoding="utf-8")
    code, stdout, _ = cli("rig", "check", src)
    assert code == 0 and "pose2sim calibration, translations read as m" in stdout
    assert "30 fps" in stdout


def test_foreign_calibration_is_accepted_by_rig_taking_commands(tmp_path, cli, sim_session):
    """simulate --rig takes an OpenCV file; fuse --rig takes an anipose file and keeps the
    session's frame rates and offsets (the file has none); calibrate, which rewrites its rig
    file as pslog TOML, refuses a foreign one rather than replace it."""
    from pslog.log import read_session

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    yml = tmp_path / "cams.yml"
    yml.write_text(rig_to_format(rig, "opencv", "m", ".yml"), encoding="utf-8")
    code, _, err = cli("simulate", "--rig", yml, "--motion", "throw", "--duration", "0.3",
                       "-o", tmp_path / "s.mcap")
    assert code == 0, err
    assert read_session(tmp_path / "s.mcap").rig.names == rig.names

    moved = Rig(tuple(c.replace(t=c.t + np.array([0.001, 0.0, 0.0]), fps=30.0, offset=0.0)
                      for c in sim_session.rig.cameras))
    toml = tmp_path / "calibration.toml"
    text = rig_to_format(moved, "anipose")
    # as aniposelib writes it: no pslog timing keys
    toml.write_text("\n".join(line for line in text.splitlines()
                              if not line.startswith(("fps", "offset", "clock", "readout"))),
                    encoding="utf-8")
    assert not load_rig_file(toml).timed
    fused = tmp_path / "fused.mcap"
    code, _, err = cli("fuse", sim_session.path, "--rig", toml, "-o", fused)
    assert code == 0, err
    got = read_session(fused).rig
    assert [c.offset for c in got.cameras] == [c.offset for c in sim_session.rig.cameras]
    np.testing.assert_allclose(got.cameras[0].t, moved.cameras[0].t, atol=1e-12)
    before = toml.read_bytes()
    code, _, err = cli("calibrate", "--rig", toml, "--name", "cam1", "--points",
                       "samples/cam1_points.csv", "--force")
    assert code == 1 and "pslog rig import" in err and toml.read_bytes() == before
    assert resolve_rig(toml).names == rig.names



@pytest.mark.parametrize("fmt,name", [("anipose", "calibration.toml"), ("opencv", "c.yml")])
def test_a_pslog_exported_calibration_keeps_its_timing_as_rig(tmp_path, fmt, name):
    """What docs/interchange.md says: a file pslog exported carries its fps / offset keys,
    and simulate, record, import and live (resolve_rig without a session) use them; fuse
    --rig (timing_from, the session's rig) takes the geometry only, whatever keys the file
    has (session 23: a new user's synced clocks were reset by their exported calibration)."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    path = tmp_path / name
    path.write_text(rig_to_format(rig, fmt, "m", path.suffix), encoding="utf-8")
    resolved = resolve_rig(path)
    assert [c.offset for c in resolved.cameras] == [c.offset for c in rig.cameras]
    assert any(c.offset != 0 for c in resolved.cameras)
    session_rig = Rig(tuple(c.replace(clock_offset=0.002 * i, readout=0.02)
                            for i, c in enumerate(builtin_rig("paper3").cameras)))
    kept = resolve_rig(path, timing_from=session_rig)
    assert [(c.fps, c.offset, c.clock_offset, c.readout) for c in kept.cameras] == [
        (c.fps, c.offset, c.clock_offset, c.readout) for c in session_rig.cameras]
    # a genuine foreign file (no timing keys): 30 fps and offset 0
    bare = tmp_path / "Calib.toml"
    bare.write_text(POSE2SIM, encoding="utf-8")
    assert [(c.fps, c.offset) for c in resolve_rig(bare).cameras] == [(30.0, 0.0)] * 2


def test_fuse_rig_with_an_exported_calibration_keeps_the_synced_clocks(tmp_path, cli,
                                                                       sim_session):
    """``pslog fuse --rig calibration.toml`` on a synced session: the geometry from the
    calibration (exported by pslog before the sync, with its nominal fps and offsets), the
    frame rates, offsets and clock model from the session, as ``fuse --rig``'s help says."""
    from pslog.log import read_session
    from pslog.rig import save_rig

    # a session whose rig carries a clock model, as `pslog sync` leaves it
    synced_rig = Rig(tuple(c.replace(clock_offset=0.0015 * i, clock_drift_ppm=20.0 * i,
                                     readout=0.004)
                           for i, c in enumerate(sim_session.rig.cameras)))
    clocks = tmp_path / "synced.toml"
    save_rig(synced_rig, clocks)
    synced = tmp_path / "synced.mcap"
    code, _, err = cli("fuse", sim_session.path, "--rig", clocks, "--method", "typeA",
                       "-o", synced)
    assert code == 0, err
    calibration = tmp_path / "calibration.toml"
    code, _, err = cli("rig", "export", sim_session.path, "--format", "anipose",
                       "-o", calibration)
    assert code == 0, err
    assert load_rig_file(calibration).timed  # pslog's export writes fps and offset
    fused = tmp_path / "fused.mcap"
    code, _, err = cli("fuse", synced, "--rig", calibration, "--method", "typeA",
                       "-o", fused)
    assert code == 0, err
    got = read_session(fused).rig
    keys = ("fps", "offset", "clock_offset", "clock_drift_ppm", "readout")
    assert [[getattr(c, k) for k in keys] for c in got.cameras] == [
        [getattr(c, k) for k in keys] for c in synced_rig.cameras]
    assert any(c.clock_offset != 0 for c in got.cameras)
