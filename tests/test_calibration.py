"""Calibration from 3D-2D points and from a chessboard, library and CLI."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.calibration import (
    calibrate_chessboard,
    calibrate_from_points,
    decompose_projection_matrix,
    dlt_projection_matrix,
    parse_pattern,
    read_calibration_images,
    read_points_csv,
)
from pslog.camera import Camera, look_at
from pslog.cli import main
from pslog.errors import InputError
from pslog.rig import Rig, builtin_rig, load_rig, save_rig

K_TRUE = np.array([[600.0, 0.0, 330.0], [0.0, 605.0, 236.0], [0.0, 0.0, 1.0]])
DIST_TRUE = np.array([-0.2, 0.05, 0.0, 0.0, 0.0])


def _camera() -> Camera:
    # Beside the long side of the volume, 2.5 m up, looking at its middle.
    R, t = look_at((1.5, -1.5, 2.5), (1.5, 1.0, 0.75))
    return Camera("cam1", 640, 480, K_TRUE, DIST_TRUE, R, t, fps=30.0, offset=0.0)


def _pole_points(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """A calibration rig of 5 x 3 poles over 3 x 2 m with marks at 6 heights up to 1.5 m,
    keeping the marks the camera sees."""
    xs, ys = np.meshgrid(np.linspace(0.0, 3.0, 5), np.linspace(0.0, 2.0, 3))
    heights = np.linspace(0.0, 1.5, 6)
    points_world = np.stack(np.broadcast_arrays(
        xs.reshape(-1, 1), ys.reshape(-1, 1), heights[None, :]), axis=-1).reshape(-1, 3)
    uv, in_front = camera.project(points_world)
    keep = in_front & camera.in_image(uv)
    return points_world[keep], uv[keep]


def _write_points(path, points_world, uv) -> None:
    rows = ["x,y,z,u,v"] + [",".join(repr(float(v)) for v in row)
                            for row in np.hstack([points_world, uv])]
    path.write_text("\n".join(rows) + "\n")


# ---- library: points -------------------------------------------------------------------------

def test_noise_free_points_recover_the_camera_exactly():
    camera = _camera()
    points_world, uv = _pole_points(camera)
    assert len(points_world) >= 40
    result = calibrate_from_points(points_world, uv, 640, 480, name="cam1")
    assert result.model == "k1k2"
    got = result.camera
    assert_allclose(got.K, K_TRUE, rtol=1e-6, atol=1e-6)
    assert_allclose(got.dist, DIST_TRUE, atol=1e-6)
    assert_allclose(got.R, camera.R, atol=1e-6)
    assert_allclose(got.center_world, camera.center_world, atol=1e-6)
    assert result.rms_px < 1e-6
    assert result.residuals_px.shape == (len(points_world),)


def test_noisy_points_recover_centre_to_millimetres():
    camera = _camera()
    points_world, uv = _pole_points(camera)
    for seed in range(5):
        noisy = uv + np.random.default_rng(seed).normal(0.0, 0.2, uv.shape)
        result = calibrate_from_points(points_world, noisy, 640, 480, name="cam1")
        got = result.camera
        assert np.linalg.norm(got.center_world - camera.center_world) < 0.005
        assert_allclose(np.diag(got.K)[:2], np.diag(K_TRUE)[:2], rtol=3e-3)
        assert_allclose(got.K[:2, 2], K_TRUE[:2, 2], atol=2.0)
        assert_allclose(got.dist[:2], DIST_TRUE[:2], atol=0.03)
        # 0.2 px per axis is 0.28 px per point; the fit absorbs a little of it
        assert 0.2 < result.rms_px < 0.35


def test_outlier_is_the_worst_point():
    camera = _camera()
    points_world, uv = _pole_points(camera)
    uv = uv.copy()
    uv[7] += (4.0, -3.0)
    result = calibrate_from_points(points_world, uv, 640, 480)
    assert result.worst(3)[0] == 7
    assert result.residuals_px[7] > 2.0


def test_few_points_use_the_pinhole_model():
    camera = _camera().replace(dist=np.zeros(5))
    points_world, uv = _pole_points(camera)
    pick = np.random.default_rng(3).choice(len(points_world), 6, replace=False)
    result = calibrate_from_points(points_world[pick], uv[pick], 640, 480)
    assert result.model == "none"
    assert_array_equal(result.camera.dist, np.zeros(5))
    assert_allclose(result.camera.center_world, camera.center_world, atol=1e-6)


def test_many_points_estimate_the_full_distortion_model():
    dist = np.array([-0.2, 0.05, 0.001, -0.0015, -0.01])
    camera = _camera().replace(dist=dist)
    xs, ys, zs = np.meshgrid(np.linspace(0.0, 3.0, 7), np.linspace(0.0, 2.0, 4),
                             np.linspace(0.0, 1.5, 6))
    points_world = np.stack([xs.ravel(), ys.ravel(), zs.ravel()], axis=1)
    uv = camera.project(points_world)[0]
    keep = camera.in_image(uv)
    assert keep.sum() >= 100
    result = calibrate_from_points(points_world[keep], uv[keep], 640, 480)
    assert result.model == "full"
    assert_allclose(result.camera.dist, dist, atol=1e-6)
    assert_allclose(result.camera.center_world, camera.center_world, atol=1e-6)
    with pytest.raises(InputError, match="unknown distortion model 'fisheye'"):
        calibrate_from_points(points_world[keep], uv[keep], 640, 480, model="fisheye")


def test_dlt_and_decomposition_are_exact_on_a_pinhole():
    camera = _camera().replace(dist=np.zeros(5))
    points_world, uv = _pole_points(camera)
    for sign in (1.0, -1.0):
        K, R, t = decompose_projection_matrix(sign * 3.0 * dlt_projection_matrix(points_world, uv))
        assert_allclose(K, camera.K, rtol=1e-9, atol=1e-7)
        assert_allclose(R, camera.R, atol=1e-9)
        assert_allclose(t, camera.t, atol=1e-9)


def test_too_few_points_error():
    camera = _camera()
    points_world, uv = _pole_points(camera)
    with pytest.raises(InputError, match="at least 6 points"):
        calibrate_from_points(points_world[:5], uv[:5], 640, 480)


def test_coplanar_points_error_and_fix_intrinsics_accepts_them():
    camera = _camera()
    points_world, uv = _pole_points(camera)
    floor = points_world[:, 2] == 0.0
    assert floor.sum() >= 8
    with pytest.raises(InputError, match="coplanar"):
        calibrate_from_points(points_world[floor], uv[floor], 640, 480)
    noisy = uv[floor] + np.random.default_rng(0).normal(0.0, 0.2, (floor.sum(), 2))
    result = calibrate_from_points(points_world[floor], noisy, 640, 480,
                                   K=camera.K, dist=camera.dist)
    assert result.fixed_intrinsics
    assert_array_equal(result.camera.K, camera.K)
    assert_array_equal(result.camera.dist, camera.dist)
    assert np.linalg.norm(result.camera.center_world - camera.center_world) < 0.02
    corners = [0, 4, -5, -1]  # the floor's outermost marks
    exact = calibrate_from_points(points_world[floor][corners], uv[floor][corners], 640, 480,
                                  K=camera.K, dist=camera.dist)
    assert_allclose(exact.camera.center_world, camera.center_world, atol=1e-6)
    with pytest.raises(InputError, match="at least 4 points"):
        calibrate_from_points(points_world[:3], uv[:3], 640, 480, K=camera.K)


def test_points_behind_the_camera_error():
    camera = _camera()
    points_world, uv = _pole_points(camera)
    with pytest.raises(InputError, match="behind the camera"):
        # mirrored pixels: the best projective fit puts the points behind the camera or fails
        calibrate_from_points(points_world, uv[::-1], 640, 480)


# ---- CSV -------------------------------------------------------------------------------------

def test_read_points_csv(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text("label,u,v,x,y,z\na,1,2,0.1,0.2,0.3\n\nb,3,4,1,2,3\n")
    points_world, uv, lines = read_points_csv(path, with_lines=True)
    assert_array_equal(points_world, [[0.1, 0.2, 0.3], [1, 2, 3]])
    assert_array_equal(uv, [[1, 2], [3, 4]])
    assert_array_equal(lines, [2, 4])


@pytest.mark.parametrize(("text", "message"), [
    ("x,y,z,u\n1,2,3,4\n", r"missing column\(s\) v"),
    ("x,y,z,u,v\n1,2,3,4,5\n1,2,oops,4,5\n", r"p.csv:3: z is not a number: 'oops'"),
    ("x,y,z,u,v\n1,2,3,4,nan\n", r"p.csv:2: v is not finite"),
    ("x,y,z,u,v\n1,2,3,4\n", r"p.csv:2: expected 5 fields, got 4"),
    ("", "empty file"),
])
def test_read_points_csv_errors(tmp_path, text, message):
    path = tmp_path / "p.csv"
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        read_points_csv(path)


# ---- CLI: points -----------------------------------------------------------------------------

def test_cli_points_writes_and_replaces_the_camera(tmp_path, capsys):
    camera = _camera()
    points_world, uv = _pole_points(camera)
    noisy = uv + np.random.default_rng(1).normal(0.0, 0.2, uv.shape)
    csv_path, rig_path = tmp_path / "points.csv", tmp_path / "lab.toml"
    _write_points(csv_path, points_world, noisy)
    args = ["calibrate", "--points", str(csv_path), "--name", "cam1", "--width", "640",
            "--height", "480", "--rig", str(rig_path), "--fps", "25", "--offset", "0.01"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "reprojection RMS 0.2" in out and "camera centre (world)" in out
    assert "worst points: #" in out and "added camera 'cam1'" in out
    rig = load_rig(rig_path)
    assert rig.names == ("cam1",) and rig.name == "lab"
    got = rig.camera("cam1")
    assert (got.fps, got.offset) == (25.0, 0.01)
    assert np.linalg.norm(got.center_world - camera.center_world) < 0.005

    # a rig with other cameras: the calibrated one is replaced in place, the others untouched
    others = builtin_rig("paper3")
    save_rig(Rig((others.cameras[1], got, others.cameras[2]), "hall"), rig_path)
    before = rig_path.read_text()
    assert main(args) == 1  # replacing needs --force
    assert "already in" in capsys.readouterr().err
    assert rig_path.read_text() == before
    _write_points(csv_path, points_world, uv)
    assert main([*args, "--force"]) == 0
    assert "replaced camera 'cam1' (camera 2 of 3)" in capsys.readouterr().out
    rig = load_rig(rig_path)
    assert rig.name == "hall" and rig.names == ("cam2", "cam1", "cam3")
    assert rig.cameras[0] == others.cameras[1] and rig.cameras[2] == others.cameras[2]
    assert_allclose(rig.camera("cam1").center_world, camera.center_world, atol=1e-6)


def test_cli_fix_intrinsics_solves_the_pose_from_floor_points(tmp_path, capsys):
    camera = _camera()
    points_world, uv = _pole_points(camera)
    floor = points_world[:, 2] == 0.0
    csv_path, rig_path = tmp_path / "floor.csv", tmp_path / "rig.toml"
    _write_points(csv_path, points_world[floor], uv[floor])
    args = ["calibrate", "--points", str(csv_path), "--name", "cam1", "--rig", str(rig_path),
            "--fix-intrinsics"]
    assert main(args) == 1
    assert "--fix-intrinsics needs camera 'cam1'" in capsys.readouterr().err
    assert not rig_path.exists()
    # without --fix-intrinsics the floor points are refused
    assert main([*args[:-1], "--width", "640", "--height", "480"]) == 1
    assert "coplanar" in capsys.readouterr().err
    # known intrinsics, wrong pose: --fix-intrinsics puts the camera where it is
    save_rig(Rig((camera.replace(R=np.eye(3), t=np.zeros(3), fps=60.0),)), rig_path)
    assert main(args) == 0
    assert "pose only" in capsys.readouterr().out
    got = load_rig(rig_path).camera("cam1")
    assert_array_equal(got.K, camera.K)
    assert got.fps == 60.0
    assert_allclose(got.center_world, camera.center_world, atol=1e-6)


def test_cli_keeps_the_clock_sync_estimated_for_the_camera_it_replaces(tmp_path, capsys):
    """A rig from 'pslog rig show SYNCED.mcap' holds each camera's clock; calibrating a camera
    again (--force, or --fix-intrinsics) replaces its geometry and keeps its clock, and says
    so: dropped, 'pslog fuse --rig' lost the sync (3 webcams: typeA 29.8 mm, filter 23.7,
    against 9.0 and 5.2 with the clocks kept)."""
    camera = _camera()
    points_world, uv = _pole_points(camera)
    csv_path, rig_path = tmp_path / "points.csv", tmp_path / "synced.toml"
    _write_points(csv_path, points_world, uv)
    first = builtin_rig("paper3").cameras[0]
    synced = camera.replace(R=np.eye(3), t=np.zeros(3), clock_offset=0.0066,
                            clock_drift_ppm=55.0, readout=0.028)
    save_rig(Rig((first.replace(name="cam0", readout=0.025), synced), "lab"), rig_path)
    for extra in (["--force", "--width", "640", "--height", "480"], ["--fix-intrinsics"]):
        assert main(["calibrate", "--points", str(csv_path), "--name", "cam1", "--rig",
                     str(rig_path), *extra]) == 0
        out = capsys.readouterr().out
        assert ("replaced camera 'cam1' (camera 2 of 2) in " in out and "; kept its clock: "
                "offset +6.6000 ms, drift +55.000 ppm, readout 28.0000 ms" in out), out
        got = load_rig(rig_path).camera("cam1")
        assert (got.clock_offset, got.clock_drift_ppm, got.readout) == (0.0066, 55.0, 0.028)
        assert_allclose(got.center_world, camera.center_world, atol=1e-6)
        assert load_rig(rig_path).cameras[0].readout == 0.025  # the other camera untouched


def test_cli_drops_the_clock_of_a_camera_given_a_new_frame_rate(tmp_path, capsys):
    """A new --fps is a new clock: the estimated readout (28 ms, beyond a 60 fps frame) would
    make the rig invalid after the solve; the camera is replaced without its clock, and the
    line says to sync again."""
    camera = _camera()
    points_world, uv = _pole_points(camera)
    csv_path, rig_path = tmp_path / "points.csv", tmp_path / "synced.toml"
    _write_points(csv_path, points_world, uv)
    synced = camera.replace(R=np.eye(3), t=np.zeros(3), clock_offset=0.0066,
                            clock_drift_ppm=55.0, readout=0.028)
    first = builtin_rig("paper3").cameras[0]
    save_rig(Rig((first.replace(name="cam0"), synced), "lab"), rig_path)
    assert main(["calibrate", "--points", str(csv_path), "--name", "cam1", "--rig",
                 str(rig_path), "--force", "--width", "640", "--height", "480",
                 "--fps", "60"]) == 0
    out = capsys.readouterr().out
    assert "dropped its clock (30 -> 60 fps): run 'pslog sync' again" in out, out
    got = load_rig(rig_path).camera("cam1")
    assert (got.fps, got.clock_offset, got.clock_drift_ppm, got.readout) == (60.0, 0.0, 0.0, 0.0)


# a missing file is a fault (exit 1); a bad value, alone, with another option or against the
# rig, is a bad command line (exit 2, argparse's, as in every command)
@pytest.mark.parametrize(("extra", "code", "message"), [
    (["--points", "missing.csv", "--width", "640", "--height", "480"], 1,
     "points file not found"),
    (["--points", "pts.csv"], 2, "--width and --height are required"),
    (["--chessboard", "9by6", "--images", "imgs"], 2, "bad chessboard pattern '9by6'"),
    (["--chessboard", "9x6", "--images", "no_such_dir"], 1, "calibration images not found"),
    (["--chessboard", "9x6"], 2, "needs --images"),
])
def test_cli_errors(tmp_path, capsys, monkeypatch, extra, code, message):
    monkeypatch.chdir(tmp_path)
    camera = _camera()
    _write_points(tmp_path / "pts.csv", *_pole_points(camera))
    try:
        got = main(["calibrate", "--name", "cam1", "--rig", "rig.toml", *extra])
    except SystemExit as exc:  # a bad value on the command line: argparse's exit 2
        got = exc.code
    assert got == code
    err = capsys.readouterr().err
    assert err.startswith("pslog calibrate: error: ") and message in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "rig.toml").exists()


# ---- chessboard ------------------------------------------------------------------------------

PATTERN = (9, 6)
SQUARE = 0.025
K_BOARD = np.array([[600.0, 0.0, 318.0], [0.0, 600.0, 243.0], [0.0, 0.0, 1.0]])
DIST_BOARD = np.array([-0.1, 0.02, 0.0, 0.0, 0.0])


def _board_texture(per_square: int, margin: int) -> np.ndarray:
    """A 10 x 7 square board with ``margin`` white squares round it, uint8."""
    cols, rows = PATTERN
    n_x, n_y = cols + 1 + 2 * margin, rows + 1 + 2 * margin
    iy, ix = np.mgrid[0:n_y * per_square, 0:n_x * per_square] // per_square
    inside = (ix >= margin) & (ix < n_x - margin) & (iy >= margin) & (iy < n_y - margin)
    return np.where(inside & ((ix + iy) % 2 == 0), 0, 255).astype(np.uint8)


def _board_views(count: int = 8) -> list[np.ndarray]:
    """Images of the board (inner corners 9 x 6, first inner corner at the board origin) in
    ``count`` random poses, through K_BOARD and DIST_BOARD.

    Each (distorted) pixel's viewing ray is intersected with the board plane and the board
    texture sampled there with cv2.remap.
    """
    camera = Camera("cam1", 640, 480, K_BOARD, DIST_BOARD)
    per_square, margin = 40, 1
    texture = _board_texture(per_square, margin)
    v, u = np.mgrid[0:camera.height, 0:camera.width].astype(np.float64)
    xy = camera.undistort_normalized(np.stack([u.ravel(), v.ravel()], axis=1))
    rays_cam = np.hstack([xy, np.ones((len(xy), 1))])
    rng = np.random.default_rng(5)
    centre = np.array([4 * SQUARE, 2.5 * SQUARE, 0.0])
    images = []
    for k in range(count):
        rvec = np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)])
        R = cv2.Rodrigues(rvec)[0]
        # the board centre 0.4-0.55 m away, spread over the image
        target = np.array([rng.uniform(-0.1, 0.1), rng.uniform(-0.07, 0.07),
                           0.4 + 0.15 * k / count])
        t = target - R @ centre
        normal = R[:, 2]  # board z axis in the camera frame
        points_board = ((normal @ t) / (rays_cam @ normal))[:, None] * rays_cam - t
        points_board = points_board @ R  # Rᵀ (X - t), row by row
        # board metres -> texture pixels: the first inner corner is margin + 1 squares in
        map_xy = ((points_board[:, :2] / SQUARE + margin + 1) * per_square - 0.5
                  ).astype(np.float32).reshape(camera.height, camera.width, 2)
        image = cv2.remap(texture, map_xy, None, cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=200)
        images.append(cv2.GaussianBlur(image, (0, 0), 0.7))
    return images


@pytest.fixture(scope="module")
def board_images():
    return _board_views()


def test_chessboard_recovers_intrinsics(board_images):
    blank = np.full((480, 640), 128, np.uint8)
    result = calibrate_chessboard([*board_images, blank], PATTERN, SQUARE, name="cam1")
    assert result.used == tuple(range(len(board_images)))
    assert result.rejected == (len(board_images),)
    K = result.camera.K
    assert_allclose([K[0, 0], K[1, 1]], [600.0, 600.0], rtol=0.01)
    assert_allclose(K[:2, 2], K_BOARD[:2, 2], atol=5.0)
    assert_allclose(result.camera.dist[0], DIST_BOARD[0], atol=0.05)
    assert result.rms_px < 0.5
    assert result.view_rms_px.shape == (len(board_images),)
    assert_array_equal(result.camera.R, np.eye(3))
    assert (result.camera.width, result.camera.height) == (640, 480)


def test_chessboard_errors(board_images):
    blank = np.full((480, 640), 128, np.uint8)
    with pytest.raises(InputError, match="no 9x6 chessboard found in any of the 2 images"):
        calibrate_chessboard([blank, blank], PATTERN)
    with pytest.raises(InputError, match="only 2 of 3 images"):
        calibrate_chessboard([*board_images[:2], blank], PATTERN)
    with pytest.raises(InputError, match="same size"):
        calibrate_chessboard([board_images[0], blank[:240]], PATTERN)
    assert parse_pattern("9x6") == (9, 6)
    for bad in ("9", "9x", "1x6", "axb"):
        with pytest.raises(InputError, match="bad chessboard pattern"):
            parse_pattern(bad)


def test_cli_chessboard_folder_and_video(tmp_path, capsys, board_images):
    folder = tmp_path / "shots"
    folder.mkdir()
    for k, image in enumerate(board_images):
        cv2.imwrite(str(folder / f"view{k:02d}.png"), image)
    cv2.imwrite(str(folder / "zz_blank.png"), np.full((480, 640), 90, np.uint8))
    (folder / "notes.txt").write_text("not an image")
    rig_path = tmp_path / "rig.toml"
    args = ["calibrate", "--chessboard", "9x6", "--square", "0.025", "--images", str(folder),
            "--name", "cam9", "--rig", str(rig_path)]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert f"images: {len(board_images)} used, 1 rejected" in out
    assert "zz_blank.png" in out and "identity R, zero t" in out
    got = load_rig(rig_path).camera("cam9")
    assert_allclose(got.K[0, 0], 600.0, rtol=0.01)

    # an existing camera keeps its pose; from a video file this time
    camera = _camera()
    save_rig(Rig((builtin_rig("paper3").cameras[0], camera.replace(name="cam9"))), rig_path)
    video = tmp_path / "board.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30, (640, 480), False)
    assert writer.isOpened()
    for image in board_images:
        writer.write(image)
    writer.release()
    images, labels = read_calibration_images(video)
    assert len(images) == len(board_images) and labels[0] == "frame 0"
    assert main([*args[:6], str(video), *args[7:], "--force"]) == 0
    out = capsys.readouterr().out
    assert "kept from the rig" in out
    rig = load_rig(rig_path)
    assert rig.names == ("cam1", "cam9")
    assert_array_equal(rig.camera("cam9").R, camera.R)
    assert_array_equal(rig.camera("cam9").t, camera.t)
    assert_allclose(rig.camera("cam9").K[0, 0], 600.0, rtol=0.01)


def test_cli_chessboard_skips_unreadable_images_and_names_them(tmp_path, capsys,
                                                                board_images):
    """An image file that cannot be decoded (cut short, empty, text named .png) was fatal
    ("cannot read image X", at the first one): now each is skipped and named, in one warning
    line, and the camera calibrated from the rest, the same as without them; too few usable
    views left is one line naming the skipped files too."""
    folder = tmp_path / "shots"
    folder.mkdir()
    for k, image in enumerate(board_images):
        cv2.imwrite(str(folder / f"view{k:02d}.png"), image)
    rig_path, clean_rig = tmp_path / "rig.toml", tmp_path / "clean.toml"
    args = ["calibrate", "--chessboard", "9x6", "--square", "0.025", "--name", "cam9",
            "--images", str(folder)]
    assert main([*args, "--rig", str(clean_rig)]) == 0
    capsys.readouterr()
    png = (folder / "view00.png").read_bytes()
    (folder / "a_cut.png").write_bytes(png[:len(png) // 3])
    (folder / "b_empty.jpg").write_bytes(b"")
    (folder / "c_text.png").write_text("not an image")
    assert main([*args, "--rig", str(rig_path)]) == 0
    captured = capsys.readouterr()
    n = len(board_images)
    assert captured.err == (f"pslog calibrate: warning: 3 of {n + 3} image files unreadable, "
                            f"skipped: a_cut.png (not a decodable image), b_empty.jpg (empty "
                            f"file), c_text.png (not a decodable image)\n"), captured.err
    assert f"images: {n} used, 0 rejected (board not found), 3 unreadable (skipped) of " \
           f"{n + 3}" in captured.out, captured.out
    assert load_rig(rig_path).camera("cam9") == load_rig(clean_rig).camera("cam9")

    # too few usable views: one line, the skipped files named; the rig untouched
    for k in range(2, n):
        (folder / f"view{k:02d}.png").unlink()
    before = rig_path.read_bytes()
    assert main([*args, "--rig", str(rig_path), "--force"]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(
        "pslog calibrate: error: 9x6 chessboard found in only 2 of 2 images; need at least 3 "
        "views; 3 unreadable image file(s) skipped: a_cut.png (not a decodable image), "), err
    for k in range(2):
        (folder / f"view{k:02d}.png").unlink()
    assert main([*args, "--rig", str(rig_path), "--force"]) == 1
    assert capsys.readouterr().err == (
        f"pslog calibrate: error: none of the 3 image files in folder {folder} can be read: "
        f"a_cut.png (not a decodable image), b_empty.jpg (empty file), c_text.png (not a "
        f"decodable image)\n")
    assert rig_path.read_bytes() == before
