"""Tests of pslog.camera: projection, distortion, rays, pose and validation of Camera."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.camera import Camera, look_at
from pslog.errors import PslogError, RigError

# Realistic plumb_bob distortion of a cheap wide lens: [k1, k2, p1, p2, k3].
REALISTIC_DIST = np.array([-0.3, 0.1, 1e-3, -1.2e-3, -0.02])


def _K(fx: float, fy: float, cx: float, cy: float, skew: float = 0.0) -> np.ndarray:
    return np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    R, _ = cv2.Rodrigues(rng.uniform(-np.pi, np.pi, 3) / np.sqrt(3))
    return R


def _random_camera(rng: np.random.Generator, dist=None, skew: float = 0.0,
                   name: str = "cam") -> Camera:
    """A 640 x 480 camera with a random pose and slightly random intrinsics."""
    fx = rng.uniform(450.0, 700.0)
    K = _K(fx, fx * rng.uniform(0.97, 1.03), rng.uniform(300, 340), rng.uniform(220, 260), skew)
    return Camera(name, 640, 480, K, np.zeros(5) if dist is None else dist,
                  _random_rotation(rng), rng.uniform(-2.0, 2.0, 3), fps=30.0)


def _points_in_view(cam: Camera, rng: np.random.Generator, n: int,
                    z_range=(0.5, 6.0), fraction: float = 0.8) -> np.ndarray:
    """World points (n, 3) in front of ``cam`` whose ideal projection lies in the central
    ``fraction`` of the image (so every distortion in these tests is invertible there)."""
    z = rng.uniform(*z_range, n)
    half_w, half_h = fraction * cam.width / 2, fraction * cam.height / 2
    u = cam.K[0, 2] + rng.uniform(-half_w, half_w, n)
    v = cam.K[1, 2] + rng.uniform(-half_h, half_h, n)
    xy = cam.normalized_from_pixels(np.stack([u, v], axis=1))
    points_cam = np.hstack([xy * z[:, None], z[:, None]])
    return (points_cam - cam.t) @ cam.R  # x_world = Rᵀ (x_cam - t), row-wise


def _image_grid(cam: Camera, nu: int = 33, nv: int = 25) -> np.ndarray:
    """Pixels (nu * nv, 2) covering the whole image, corners included."""
    u, v = np.meshgrid(np.linspace(-0.5, cam.width - 0.5, nu),
                       np.linspace(-0.5, cam.height - 0.5, nv))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def _cv2_project(cam: Camera, points_world: np.ndarray) -> np.ndarray:
    rvec, _ = cv2.Rodrigues(cam.R)
    uv, _ = cv2.projectPoints(points_world.reshape(-1, 1, 3), rvec, cam.t, cam.K, cam.dist)
    return uv.reshape(-1, 2)


# ---- projection ---------------------------------------------------------------------------

@pytest.mark.parametrize("dist", [
    np.zeros(5),
    REALISTIC_DIST,
    np.array([0.05, -0.01, -2e-3, 1e-3, 0.001]),  # mild pincushion
    np.array([-0.1, 0.0, 0.0, 0.0, 0.0]),
])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_project_matches_cv2(dist, seed):
    rng = np.random.default_rng(seed)
    cam = _random_camera(rng, dist=dist)
    points_world = _points_in_view(cam, rng, 200)
    uv, in_front = cam.project(points_world)
    assert uv.shape == (200, 2) and in_front.shape == (200,)
    assert in_front.all()
    assert_allclose(uv, _cv2_project(cam, points_world), rtol=0, atol=1e-8)


def test_project_with_skew_follows_K():
    # cv2.projectPoints ignores skew; check against K @ [x_d, y_d, 1] directly.
    rng = np.random.default_rng(5)
    cam = _random_camera(rng, dist=REALISTIC_DIST, skew=3.5)
    points_world = _points_in_view(cam, rng, 100)
    uv, _ = cam.project(points_world)
    points_cam = points_world @ cam.R.T + cam.t
    xy_d = cam.distort_normalized(points_cam[:, :2] / points_cam[:, 2:])
    expected = np.hstack([xy_d, np.ones((100, 1))]) @ cam.K.T
    assert_allclose(uv, expected[:, :2], rtol=0, atol=1e-9)
    # and the skew really matters: without it the pixels differ
    uv_no_skew, _ = cam.replace(K=_K(cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]))\
        .project(points_world)
    assert np.abs(uv - uv_no_skew).max() > 0.1


def test_project_single_point_and_hand_computed():
    cam = Camera("c", 640, 480, _K(500.0, 400.0, 320.0, 240.0))
    uv, in_front = cam.project([1.0, -0.5, 2.0])  # a single (3,) point is accepted
    assert_allclose(uv, [[320 + 500 * 0.5, 240 - 400 * 0.25]], rtol=0, atol=1e-12)
    assert_array_equal(in_front, [True])


def test_project_rejects_wrong_shape():
    cam = Camera("c", 640, 480, _K(500.0, 500.0, 320.0, 240.0))
    with pytest.raises(ValueError, match="points_world"):
        cam.project(np.zeros((4, 2)))


def test_points_behind_or_on_camera_plane_are_flagged_not_projected():
    rng = np.random.default_rng(3)
    cam = _random_camera(rng, dist=REALISTIC_DIST)
    ahead = _points_in_view(cam, rng, 5)
    # Mirror the points through the camera centre: behind the camera, they would project
    # to the very same pixels if the sign of z were ignored.
    behind = 2 * cam.center_world - ahead
    on_plane_cam = np.array([[0.3, -0.2, 0.0], [0.0, 0.0, 0.0]])
    on_plane = (on_plane_cam - cam.t) @ cam.R
    uv, in_front = cam.project(np.vstack([ahead, behind, on_plane]))
    assert_array_equal(in_front, [True] * 5 + [False] * 7)
    assert np.all(np.isfinite(uv[:5]))
    assert np.all(np.isnan(uv[5:]))


# ---- distortion ---------------------------------------------------------------------------

@pytest.mark.parametrize("focal", [500.0, 600.0, 800.0])
@pytest.mark.parametrize("dist", [
    REALISTIC_DIST,
    np.array([-0.3, 0.1, -1e-3, 1e-3, -0.02]),
    np.array([0.1, -0.05, 5e-4, 5e-4, 0.01]),
])
def test_undistort_then_distort_round_trip_across_image(focal, dist):
    """Every pixel of the image (corners included) undistorts to an ideal point that
    distorts back onto it to 1e-9 px."""
    cam = Camera("c", 640, 480, _K(focal, focal, 319.5, 239.5), dist)
    uv = _image_grid(cam)
    xy = cam.undistort_normalized(uv)
    back = cam.pixels_from_normalized(cam.distort_normalized(xy))
    assert_allclose(back, uv, rtol=0, atol=1e-9)
    # the distortion is real: undistorted pixels move by several pixels at the corners
    assert np.abs(cam.undistort(uv) - uv).max() > 5.0


@pytest.mark.parametrize("dist", [REALISTIC_DIST, np.array([0.1, -0.05, 5e-4, 5e-4, 0.01])])
def test_distort_then_undistort_round_trip(dist):
    """Ideal pixels -> distorted -> undistorted gives back the ideal pixels to 1e-9 px."""
    cam = Camera("c", 640, 480, _K(600.0, 590.0, 321.0, 242.0, skew=0.7), dist)
    ideal_uv = _image_grid(cam)
    distorted_uv = cam.pixels_from_normalized(
        cam.distort_normalized(cam.normalized_from_pixels(ideal_uv)))
    assert_allclose(cam.undistort(distorted_uv), ideal_uv, rtol=0, atol=1e-9)


def test_undistort_without_distortion_is_identity():
    cam = Camera("c", 640, 480, _K(600.0, 600.0, 320.0, 240.0))
    uv = _image_grid(cam)
    assert_allclose(cam.undistort(uv), uv, rtol=0, atol=1e-12)


@pytest.mark.parametrize("focal", [500.0, 600.0])
def test_undistort_matches_cv2_undistort_points(focal):
    cam = Camera("c", 640, 480, _K(focal, focal * 1.01, 318.0, 243.0), REALISTIC_DIST)
    uv = _image_grid(cam)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 500, 1e-20)
    xy_cv2 = cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.K, cam.dist,
                                 criteria=criteria).reshape(-1, 2)
    # normalized coordinates; 1e-10 here is ~6e-8 px
    assert_allclose(cam.undistort_normalized(uv), xy_cv2, rtol=0, atol=1e-10)


def test_undistort_propagates_nan():
    cam = Camera("c", 640, 480, _K(600.0, 600.0, 320.0, 240.0), REALISTIC_DIST)
    xy = cam.undistort_normalized(np.array([[np.nan, 10.0], [100.0, 200.0]]))
    assert np.all(np.isnan(xy[0]))
    assert np.all(np.isfinite(xy[1]))


# ---- rays and pose ------------------------------------------------------------------------

@pytest.mark.parametrize("dist", [np.zeros(5), REALISTIC_DIST])
@pytest.mark.parametrize("skew", [0.0, 2.0])
def test_point_lies_on_ray_of_its_projection(dist, skew):
    rng = np.random.default_rng(11)
    cam = _random_camera(rng, dist=dist, skew=skew)
    points_world = _points_in_view(cam, rng, 300, z_range=(0.3, 20.0))
    uv, _ = cam.project(points_world)
    origin, directions = cam.rays(uv)
    assert origin.shape == (3,) and directions.shape == (300, 3)
    assert_allclose(origin, cam.center_world, rtol=0, atol=0)
    assert_allclose(np.linalg.norm(directions, axis=1), 1.0, rtol=0, atol=1e-12)
    offsets = points_world - origin
    along = np.einsum("ij,ij->i", offsets, directions)
    assert np.all(along > 0)  # the ray points towards the scene, not away from it
    perpendicular = offsets - along[:, None] * directions
    assert np.linalg.norm(perpendicular, axis=1).max() < 1e-9  # metres


def test_ray_of_principal_point_is_optical_axis():
    rng = np.random.default_rng(4)
    cam = _random_camera(rng, dist=REALISTIC_DIST)
    _, directions = cam.rays(cam.K[:2, 2])
    assert_allclose(directions[0], cam.R[2], rtol=0, atol=1e-12)  # camera z in world


def test_center_world_and_world_from_cam_are_consistent():
    rng = np.random.default_rng(8)
    for _ in range(5):
        cam = _random_camera(rng)
        center = cam.center_world
        assert_allclose(cam.R @ center + cam.t, 0.0, rtol=0, atol=1e-12)
        T = cam.world_from_cam
        assert T.shape == (4, 4)
        assert_array_equal(T[3], [0, 0, 0, 1])
        assert_allclose(T[:3, 3], center, rtol=0, atol=0)
        points_world = rng.normal(size=(20, 3))
        points_cam = points_world @ cam.R.T + cam.t
        back = np.hstack([points_cam, np.ones((20, 1))]) @ T.T
        assert_allclose(back[:, :3], points_world, rtol=0, atol=1e-12)
        cam_from_world = np.eye(4)
        cam_from_world[:3, :3], cam_from_world[:3, 3] = cam.R, cam.t
        assert_allclose(T @ cam_from_world, np.eye(4), rtol=0, atol=1e-12)


def test_projection_matrix_projects_like_undistorted_camera():
    rng = np.random.default_rng(9)
    cam = _random_camera(rng, skew=1.5)
    P = cam.P
    assert P.shape == (3, 4)
    assert_allclose(P, cam.K @ np.hstack([cam.R, cam.t[:, None]]), rtol=0, atol=0)
    points_world = _points_in_view(cam, rng, 50)
    homogeneous = np.hstack([points_world, np.ones((50, 1))]) @ P.T
    uv, _ = cam.project(points_world)
    assert_allclose(homogeneous[:, :2] / homogeneous[:, 2:], uv, rtol=0, atol=1e-9)
    # the camera centre is P's null space
    assert_allclose(P @ np.append(cam.center_world, 1.0), 0.0, rtol=0, atol=1e-9)


def test_frame_period():
    cam = Camera("c", 640, 480, _K(1, 1, 0, 0), fps=25)
    assert cam.frame_period == 1 / 25
    assert isinstance(cam.fps, float)


def test_in_image_bounds():
    cam = Camera("c", 640, 480, _K(600.0, 600.0, 320.0, 240.0))
    uv = np.array([[-0.5, -0.5], [639.49, 479.49], [639.5, 100], [100, 479.5], [-0.51, 10],
                   [np.nan, 10.0], [5.0, 5.0]])
    assert_array_equal(cam.in_image(uv), [True, True, False, False, False, False, True])
    assert_array_equal(cam.in_image(uv, margin=10.0), [False] * 6 + [False])
    assert cam.in_image(np.array([[10.0, 10.0]]), margin=10.0)[0]


# ---- look_at ------------------------------------------------------------------------------

@pytest.mark.parametrize("eye, target", [
    ((-1.5, 1.0, 3.0), (1.5, 1.0, 1.0)),
    ((4.0, -3.0, 0.5), (0.0, 0.0, 0.0)),
    ((0.0, 0.0, 5.0), (0.0, 0.0, 0.0)),  # straight down, along -up
    ((0.0, 0.0, -5.0), (0.0, 0.0, 0.0)),  # straight up
])
def test_look_at(eye, target):
    R, t = look_at(eye, target)
    assert_allclose(R @ R.T, np.eye(3), rtol=0, atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
    cam = Camera("c", 640, 480, _K(400.0, 400.0, 319.5, 239.5), R=R, t=t)
    assert_allclose(cam.center_world, eye, rtol=0, atol=1e-12)
    uv, in_front = cam.project(np.array([target]))
    assert in_front[0]
    assert_allclose(uv[0], [319.5, 239.5], rtol=0, atol=1e-9)  # target at the principal point
    forward = np.subtract(target, eye)
    if np.linalg.norm(np.cross(forward, [0, 0, 1])) > 1e-9:
        # a point above the target appears higher in the image (smaller v), not sideways
        uv_up, _ = cam.project(np.array([np.add(target, [0.0, 0.0, 0.1])]))
        assert uv_up[0, 1] < 239.5
        assert uv_up[0, 0] == pytest.approx(319.5, abs=1e-9)


# ---- validation ---------------------------------------------------------------------------

def _good_fields() -> dict:
    return dict(name="camX", width=640, height=480, K=_K(600.0, 600.0, 320.0, 240.0),
                dist=np.zeros(5), R=np.eye(3), t=np.zeros(3), fps=30.0, offset=0.0)


def test_valid_camera_is_frozen_and_read_only():
    cam = Camera(**_good_fields())
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0
    with pytest.raises(AttributeError):
        cam.fps = 60.0  # type: ignore[misc]
    assert cam == Camera(**_good_fields())
    assert cam != cam.replace(offset=0.01)
    assert cam.replace(offset=0.01).offset == 0.01


def _rotation_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("changes, key", [
    ({"R": np.diag([1.0, 1.0, -1.0])}, "R"),  # a reflection, det -1
    ({"R": 1.01 * np.eye(3)}, "R"),  # scaled
    ({"R": _rotation_z(0.3) + 1e-4}, "R"),
    ({"R": np.eye(3)[:2]}, "R"),
    ({"K": _K(600.0, 600.0, 320.0, 240.0) + np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0]])}, "K"),
    ({"K": np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, 2]])}, "K"),
    ({"K": _K(-600.0, 600.0, 320.0, 240.0)}, "K"),
    ({"K": _K(600.0, 0.0, 320.0, 240.0)}, "K"),
    ({"K": np.eye(4)}, "K"),
    ({"K": _K(np.nan, 600.0, 320.0, 240.0)}, "K"),
    ({"K": "six hundred"}, "K"),
    ({"dist": np.zeros(4)}, "dist"),
    ({"dist": [0.0, 0.0, np.inf, 0.0, 0.0]}, "dist"),
    ({"t": np.zeros((3, 1))}, "t"),
    ({"t": [0.0, np.nan, 0.0]}, "t"),
    ({"fps": 0.0}, "fps"),
    ({"fps": -30.0}, "fps"),
    ({"fps": np.inf}, "fps"),
    ({"fps": "30"}, "fps"),
    ({"offset": np.nan}, "offset"),
    ({"offset": -1e-9}, "offset"),
    ({"offset": 1 / 30}, "offset"),
    ({"width": 0}, "width"),
    ({"width": 640.0}, "width"),
    ({"height": -480}, "height"),
    ({"height": True}, "height"),
])
def test_invalid_camera_raises_rig_error_naming_camera_and_key(changes, key):
    fields = _good_fields() | changes
    with pytest.raises(RigError) as info:
        Camera(**fields)
    message = str(info.value)
    assert "camX" in message and key in message
    assert "\n" not in message
    assert isinstance(info.value, PslogError)


def test_offset_must_lie_within_one_frame_period():
    # the offset is the shutter phase: a whole period or more is not a distinct schedule
    with pytest.raises(RigError) as info:
        Camera(**(_good_fields() | {"offset": 0.5}))
    assert str(info.value) == ("camera 'camX': offset 0.5 s must be in [0, 0.0333333 s), "
                               "the frame period at 30 fps")
    with pytest.raises(RigError, match=r"offset 0\.01 s must be in \[0, 0\.00833333 s\)"):
        Camera(**(_good_fields() | {"fps": 120.0, "offset": 0.01}))
    last = np.nextafter(1 / 30, 0.0)
    assert Camera(**(_good_fields() | {"offset": last})).offset == last
    assert Camera(**(_good_fields() | {"offset": -0.0})).offset == 0.0


def test_slightly_imperfect_rotation_is_accepted():
    R = _rotation_z(0.3) + 1e-8
    assert Camera(**(_good_fields() | {"R": R})).R[0, 0] == R[0, 0]


@pytest.mark.parametrize("name", ["", None, 3])
def test_invalid_camera_name(name):
    with pytest.raises(RigError, match="name"):
        Camera(**(_good_fields() | {"name": name}))


def test_undistort_beyond_the_fold_over_radius_is_nan_not_wrong():
    # with k1=-0.3, k2=0.1, k3=-0.02 the model's distorted radius peaks near 0.905; the
    # corners of a 640x480 image at f=400 px lie at radius 1.0, which no ideal point reaches
    K = np.array([[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]])
    cam = Camera("wide", 640, 480, K, np.array([-0.3, 0.1, 0.0, 0.0, -0.02]))
    uv = np.array([[-0.5, -0.5], [319.5, 239.5], [400.0, 300.0]])
    xy = cam.undistort_normalized(uv)
    assert np.all(np.isnan(xy[0]))
    assert np.all(np.isfinite(xy[1:]))
    _, directions = cam.rays(uv)
    assert np.all(np.isnan(directions[0])) and np.all(np.isfinite(directions[1:]))


def test_distort_inverts_undistort_in_pixels():
    K = np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]])
    cam = Camera("lens", 640, 480, K, np.array([-0.2, 0.05, 1e-3, -5e-4, 0.0]))
    uv = np.stack(np.meshgrid(np.linspace(20, 620, 7), np.linspace(20, 460, 5)), -1).reshape(-1, 2)
    np.testing.assert_allclose(cam.distort(cam.undistort(uv)), uv, atol=1e-9)
    # hand-computed: the principal point stays; k1 alone maps x = 0.2 to 0.2 (1 - 0.2 * 0.2²)
    plain = Camera("k1", 640, 480, K, np.array([-0.2, 0.0, 0.0, 0.0, 0.0]))
    np.testing.assert_allclose(plain.distort([[320.0, 240.0], [420.0, 240.0]]),
                               [[320.0, 240.0], [320.0 + 500.0 * 0.2 * (1 - 0.2 * 0.04), 240.0]])


# ---- hostile values (issue 8) -------------------------------------------------------------
@pytest.mark.parametrize("dist", [np.zeros(5), np.array([-0.3, 0.1, 0.001, -0.001, -0.02])])
def test_far_off_pixels_give_a_direction_or_nan_and_never_a_warning(dist):
    import warnings

    from pslog.rig import builtin_rig

    cam = builtin_rig("paper3").cameras[0].replace(dist=dist)
    uv = np.array([[1e300, 2.0], [1e308, 1e308], [-1e308, 0.0], [1e154, 1.0], [1e6, 1e6],
                   [np.nan, 1.0], [320.0, 240.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning fails the test
        _, directions = cam.rays(uv)
        undistorted = cam.undistort(uv)
    finite = np.all(np.isfinite(directions), axis=1)
    assert_allclose(np.linalg.norm(directions[finite], axis=1), 1.0)
    assert finite[-1] and not finite[5]
    if not np.any(dist):  # a pinhole ray of a far pixel lies along the image's x axis
        assert_allclose(directions[0], cam.R[0], atol=1e-12)
    else:  # beyond the lens model's fold-over: no ray, said with NaN
        assert not finite[:5].any() and np.isnan(undistorted[:5]).all()


@pytest.mark.parametrize("key,value,why", [
    ("width", 99999999999, "beyond any camera"), ("height", 65537, "beyond any camera"),
    ("fps", 1e7, "fps must be in"), ("name", "a,b", "one of ,"), ("name", "x\ny", "control"),
])
def test_absurd_camera_values_are_refused(key, value, why):
    from pslog.rig import builtin_rig

    with pytest.raises(RigError, match=why):
        builtin_rig("paper3").cameras[0].replace(**{key: value})
