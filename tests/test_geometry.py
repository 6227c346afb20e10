"""Tests of pslog.geometry: fundamental matrix, epipolar lines, triangulation, eq. (4)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.camera import Camera, look_at
from pslog.geometry import (
    closest_points_on_lines,
    closest_points_on_rays,
    crossing_of_rays,
    epipolar_lines,
    fundamental_matrix,
    ray_depths,
    triangulate_rays,
    triangulate_two_rays,
)

DIST = np.array([-0.3, 0.1, 1e-3, -1.2e-3, -0.02])


def _rig_cameras(dist=DIST) -> list[Camera]:
    """Four distorted cameras of different intrinsics around a 3 x 2 x 2 m volume."""
    eyes = [(-1.5, 1.0, 3.0), (1.5, -2.0, 3.0), (4.5, 1.0, 3.0), (1.0, 4.0, 2.5)]
    cameras = []
    for i, eye in enumerate(eyes):
        R, t = look_at(eye, (1.5 + 0.1 * i, 1.0, 1.0 - 0.05 * i))
        f = 500.0 + 40 * i
        K = np.array([[f, 0.5 * i, 320.0 + i], [0.0, f * 1.01, 240.0 - i], [0.0, 0.0, 1.0]])
        cameras.append(Camera(f"cam{i + 1}", 640, 480, K, dist, R, t))
    return cameras


def _volume_points(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform([0.0, 0.0, 0.0], [3.0, 2.0, 2.0], (n, 3))


def _homogeneous(uv: np.ndarray) -> np.ndarray:
    return np.hstack([uv, np.ones((len(uv), 1))])


def _normalized_epipolar_residual(F, uv_a, uv_b) -> np.ndarray:
    """x_bᵀ F x_a with F scaled to unit norm and pixels scaled to ~1 (Hartley-style),
    so that the residual is dimensionless and ~1e-16 relative precision applies."""
    scale = np.diag([1 / 320, 1 / 320, 1.0])
    F_n = np.linalg.inv(scale).T @ F @ np.linalg.inv(scale)
    F_n /= np.linalg.norm(F_n)
    xa, xb = _homogeneous(uv_a) @ scale.T, _homogeneous(uv_b) @ scale.T
    return np.einsum("ij,jk,ik->i", xb, F_n, xa)


# ---- fundamental matrix and epipolar lines -----------------------------------------------

@pytest.mark.parametrize("pair", [(0, 1), (1, 0), (0, 2), (1, 3), (2, 3)])
def test_epipolar_constraint_holds_for_projected_pairs(pair):
    cameras = _rig_cameras()
    cam_a, cam_b = cameras[pair[0]], cameras[pair[1]]
    F = fundamental_matrix(cam_a, cam_b)
    assert F.shape == (3, 3)
    assert np.linalg.norm(F) == pytest.approx(1.0, abs=1e-12)
    assert abs(np.linalg.det(F)) < 1e-12  # rank 2
    points = _volume_points(np.random.default_rng(0), 500)
    uv_a = cam_a.undistort(cam_a.project(points)[0])
    uv_b = cam_b.undistort(cam_b.project(points)[0])
    residual = _normalized_epipolar_residual(F, uv_a, uv_b)
    assert np.abs(residual).max() < 1e-9
    # a wrong correspondence does not satisfy it: the check is not vacuous
    assert np.abs(_normalized_epipolar_residual(F, uv_a, uv_b[::-1])).max() > 1e-3


def test_fundamental_matrix_of_swapped_pair_is_transpose():
    cam_a, cam_b = _rig_cameras()[:2]
    F_ab, F_ba = fundamental_matrix(cam_a, cam_b), fundamental_matrix(cam_b, cam_a)
    sign = np.sign(np.sum(F_ab * F_ba.T))
    assert_allclose(F_ab, sign * F_ba.T, rtol=0, atol=1e-12)


def test_epipoles_are_projections_of_other_camera_centre():
    cam_a, cam_b = _rig_cameras(dist=np.zeros(5))[:2]
    F = fundamental_matrix(cam_a, cam_b)
    e_a = cam_a.P @ np.append(cam_b.center_world, 1.0)  # centre of b seen by a
    e_b = cam_b.P @ np.append(cam_a.center_world, 1.0)
    assert_allclose(F @ (e_a / np.linalg.norm(e_a)), 0.0, rtol=0, atol=1e-12)
    assert_allclose(F.T @ (e_b / np.linalg.norm(e_b)), 0.0, rtol=0, atol=1e-12)


def test_fundamental_matrix_matches_cv2_find_fundamental_mat():
    cam_a, cam_b = _rig_cameras()[1:3]
    points = _volume_points(np.random.default_rng(1), 200)
    uv_a = cam_a.undistort(cam_a.project(points)[0])
    uv_b = cam_b.undistort(cam_b.project(points)[0])
    F_cv2, _ = cv2.findFundamentalMat(uv_a, uv_b, cv2.FM_8POINT)
    F_cv2 /= np.linalg.norm(F_cv2)
    F = fundamental_matrix(cam_a, cam_b)
    sign = np.sign(np.sum(F * F_cv2))
    assert_allclose(F, sign * F_cv2, rtol=0, atol=1e-7)


def test_epipolar_lines_are_normalized_and_contain_true_point():
    cam_a, cam_b = _rig_cameras()[0], _rig_cameras()[2]
    F = fundamental_matrix(cam_a, cam_b)
    points = _volume_points(np.random.default_rng(2), 300)
    uv_a = cam_a.undistort(cam_a.project(points)[0])
    uv_b = cam_b.undistort(cam_b.project(points)[0])
    lines = epipolar_lines(F, uv_a)
    assert lines.shape == (300, 3)
    assert_allclose(np.hypot(lines[:, 0], lines[:, 1]), 1.0, rtol=0, atol=1e-14)
    distance_px = np.einsum("ij,ij->i", lines, _homogeneous(uv_b))
    assert np.abs(distance_px).max() < 1e-9
    # signed distance in pixels: a point moved 3 px along the normal is 3 px away
    moved = uv_b + 3.0 * lines[:, :2]
    assert_allclose(np.einsum("ij,ij->i", lines, _homogeneous(moved)), 3.0, rtol=0, atol=1e-9)
    # the epipolar line of b's point in image a contains a's point (F transposed)
    lines_a = epipolar_lines(F.T, uv_b)
    assert np.abs(np.einsum("ij,ij->i", lines_a, _homogeneous(uv_a))).max() < 1e-9


def test_epipolar_lines_match_cv2_compute_correspond_epilines():
    cam_a, cam_b = _rig_cameras()[:2]
    F = fundamental_matrix(cam_a, cam_b)
    uv_a = np.random.default_rng(3).uniform([0, 0], [640, 480], (50, 2))
    lines_cv2 = cv2.computeCorrespondEpilines(uv_a.reshape(-1, 1, 2), 1, F).reshape(-1, 3)
    lines = epipolar_lines(F, uv_a)
    sign = np.sign(np.sum(lines * lines_cv2, axis=1))[:, None]
    assert_allclose(lines, sign * lines_cv2, rtol=0, atol=1e-9)


def test_epipolar_lines_with_one_fundamental_matrix_per_point():
    cameras = _rig_cameras()
    points = _volume_points(np.random.default_rng(11), 40)
    pairs = [(0, 1), (2, 0), (3, 1), (1, 2)] * 10  # a different camera pair per point
    F = np.stack([fundamental_matrix(cameras[a], cameras[b]) for a, b in pairs])
    uv_a = np.stack([cameras[a].undistort(cameras[a].project(p)[0])[0]
                     for (a, _), p in zip(pairs, points, strict=True)])
    uv_b = np.stack([cameras[b].undistort(cameras[b].project(p)[0])[0]
                     for (_, b), p in zip(pairs, points, strict=True)])
    lines = epipolar_lines(F, uv_a)
    for i in range(4):  # the same as with each pair's single F
        assert_allclose(lines[i::4], epipolar_lines(F[i], uv_a[i::4]), rtol=0, atol=1e-12)
    assert np.abs(np.einsum("ij,ij->i", lines, _homogeneous(uv_b))).max() < 1e-9


# ---- nearest point on a 2D line (section 2.2, step 2) ------------------------------------

def test_closest_points_on_lines_hand_computed():
    s = np.sqrt(0.5)
    lines = np.array([
        [1.0, 0.0, -3.0],  # u = 3
        [0.0, 1.0, 2.0],  # v = -2
        [s, -s, 0.0],  # u = v (45°)
        [-s, s, 0.0],  # u = v with the opposite normal
        [1.0, 0.0, -3.0],  # a point already on its line
    ])
    uv = np.array([[5.0, 7.0], [1.0, 1.0], [2.0, 0.0], [2.0, 0.0], [3.0, -4.0]])
    on_line, distance = closest_points_on_lines(lines, uv)
    assert_allclose(on_line, [[3, 7], [1, -2], [1, 1], [1, 1], [3, -4]], rtol=0, atol=1e-12)
    assert_allclose(distance, [2.0, 3.0, np.sqrt(2), np.sqrt(2), 0.0], rtol=0, atol=1e-12)


def test_closest_points_on_epipolar_lines_random():
    rng = np.random.default_rng(4)
    angle = rng.uniform(0, 2 * np.pi, 100)
    lines = np.stack([np.cos(angle), np.sin(angle), rng.uniform(-500, 500, 100)], axis=1)
    uv = rng.uniform(-100, 700, (100, 2))
    on_line, distance = closest_points_on_lines(lines, uv)
    assert_allclose(np.einsum("ij,ij->i", lines, _homogeneous(on_line)), 0, rtol=0, atol=1e-9)
    assert_allclose(np.linalg.norm(uv - on_line, axis=1), distance, rtol=0, atol=1e-9)
    direction = np.stack([-lines[:, 1], lines[:, 0]], axis=1)
    assert_allclose(np.einsum("ij,ij->i", uv - on_line, direction), 0, rtol=0, atol=1e-9)


# ---- two-ray triangulation (section 2.2, step 3) -----------------------------------------

def test_triangulate_two_crossing_rays_hand_computed():
    # both pass through (1, 2, 3); directions of any length
    points, miss = triangulate_two_rays(
        np.array([[0.0, 2.0, 3.0], [1.0, 0.0, 0.0]]), np.array([[2.0, 0.0, 0.0], [0, 1, 1.5]]),
        np.array([[1.0, 0.0, 3.0], [5.0, 6.0, 3.0]]), np.array([[0.0, 5.0, 0.0], [-1, -1, 0]]))
    assert_allclose(points, [[1, 2, 3], [1, 2, 3]], rtol=0, atol=1e-12)
    assert_allclose(miss, [0, 0], rtol=0, atol=1e-12)


def test_triangulate_two_skew_rays_midpoint_of_common_perpendicular():
    # the x-axis and the line through (0, 0, 1) along y: perpendicular from (0,0,0) to (0,0,1)
    points, miss = triangulate_two_rays([0.0, 0.0, 0.0], [[3.0, 0.0, 0.0]],
                                        [0.0, 0.0, 1.0], [[0.0, -0.5, 0.0]])
    assert_allclose(points, [[0.0, 0.0, 0.5]], rtol=0, atol=1e-15)
    assert_allclose(miss, [1.0], rtol=0, atol=1e-15)
    # the same configuration shifted and seen from origins far along the lines
    points, miss = triangulate_two_rays([[7.0, 1.0, 2.0]], [[1.0, 0.0, 0.0]],
                                        [[2.0, -4.0, 4.0]], [[0.0, 1.0, 0.0]])
    assert_allclose(points, [[2.0, 1.0, 3.0]], rtol=0, atol=1e-12)
    assert_allclose(miss, [2.0], rtol=0, atol=1e-12)


def test_crossing_of_rays_gives_the_ray_parameters_whose_signs_say_in_front():
    # the x-axis and the line through (0, 0, 1) along y: feet at (0, 0, 0) and (0, 0, 1),
    # reached at s = -2 / 3 along (3, 0, 0) from (2, 0, 0) and k = 8 along (0, -0.5, 0) from
    # (0, 4, 1)
    points, miss, s, k = crossing_of_rays([2.0, 0.0, 0.0], [[3.0, 0.0, 0.0]],
                                          [0.0, 4.0, 1.0], [[0.0, -0.5, 0.0]])
    assert_allclose(points, [[0.0, 0.0, 0.5]], atol=1e-15)
    assert_allclose(miss, [1.0], atol=1e-15)
    assert_allclose(s, [-2 / 3], rtol=1e-15)
    assert_allclose(k, [8.0], rtol=1e-15)
    # a stereo pair looking along +z with crossed (negative-disparity) rays: the crossing is
    # behind both, at s, k < 0, although the rays meet exactly
    points, miss, s, k = crossing_of_rays([0.0, 0.0, 0.0], [[0.1, 0.0, 1.0]],
                                          [1.0, 0.0, 0.0], [[-0.1, 0.0, 1.0]])
    assert_allclose(points, [[0.5, 0.0, 5.0]], atol=1e-12)
    assert s[0] == pytest.approx(5.0) and k[0] == pytest.approx(5.0) and miss[0] < 1e-12
    points, miss, s, k = crossing_of_rays([0.0, 0.0, 0.0], [[-0.1, 0.0, 1.0]],
                                          [1.0, 0.0, 0.0], [[0.1, 0.0, 1.0]])
    assert_allclose(points, [[0.5, 0.0, -5.0]], atol=1e-12)
    assert s[0] == pytest.approx(-5.0) and k[0] == pytest.approx(-5.0) and miss[0] < 1e-12
    assert np.all(np.isnan(crossing_of_rays([0.0, 0, 0], [[1.0, 0, 0]], [0.0, 1, 0],
                                            [[2.0, 0, 0]])[2]))


def test_ray_depths_hand_computed():
    points = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, -2.0]])
    origins = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [[0.0, 0.0, 0.0], [0.0, 0, 1.0]]])
    dirs = np.array([[[0.0, 0.0, 2.0], [0.0, 1.0, 0.0]], [[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]])
    assert_allclose(ray_depths(points, origins, dirs), [[1.5, 2.0], [-2.0, -3.0]])
    assert_allclose(ray_depths(points, origins[:, 0], dirs[:, 0]), [1.5, -2.0])


def test_triangulate_two_rays_parallel_gives_nan():
    points, miss = triangulate_two_rays(
        np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]),
        np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0]]),
        np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 1.0]]),
        np.array([[-2.0, 0.0, 0.0], [3.0, 3.0, 0.0], [0.0, 1.0, 0.0]]))
    assert np.all(np.isnan(points[:2])) and np.all(np.isnan(miss[:2]))
    assert_allclose(points[2], [0.0, 0.0, 0.5], rtol=0, atol=1e-15)  # not parallel: fine
    assert miss[2] == pytest.approx(1.0, abs=1e-15)
    # 1e-7 rad apart: numerically parallel, NaN rather than a point kilometres away
    points, miss = triangulate_two_rays([0.0, 0.0, 0.0], [[1.0, 0.0, 0.0]],
                                        [0.0, 0.0, 1e-3], [[1.0, 1e-7, 0.0]])
    assert np.all(np.isnan(points)) and np.isnan(miss[0])


def test_triangulate_two_rays_from_cameras_is_exact():
    cameras = _rig_cameras()
    points = _volume_points(np.random.default_rng(5), 400)
    cam_a, cam_b = cameras[0], cameras[1]
    origin_a, dir_a = cam_a.rays(cam_a.project(points)[0])
    origin_b, dir_b = cam_b.rays(cam_b.project(points)[0])
    estimate, miss = triangulate_two_rays(origin_a, dir_a, origin_b, dir_b)
    assert np.abs(estimate - points).max() < 1e-9
    assert miss.max() < 1e-9


# ---- N-ray triangulation -------------------------------------------------------------------

def _camera_rays(cameras, points):
    origins, directions = [], []
    for cam in cameras:
        origin, direction = cam.rays(cam.project(points)[0])
        origins.append(np.broadcast_to(origin, direction.shape))
        directions.append(direction)
    return np.stack(origins, axis=1), np.stack(directions, axis=1)  # (n, m, 3)


@pytest.mark.parametrize("n_cameras", [2, 3, 4])
def test_triangulate_rays_exact_for_noise_free_cameras(n_cameras):
    cameras = _rig_cameras()[:n_cameras]
    points = _volume_points(np.random.default_rng(6), 300)
    origins, directions = _camera_rays(cameras, points)
    estimate, rms_miss, n_rays = triangulate_rays(origins, directions)
    assert np.abs(estimate - points).max() < 1e-9
    assert rms_miss.max() < 1e-9
    assert_array_equal(n_rays, n_cameras)


def test_triangulate_rays_masks_invalid_rays():
    cameras = _rig_cameras()
    points = _volume_points(np.random.default_rng(7), 6)
    origins, directions = _camera_rays(cameras, points)
    directions = directions.copy()
    # corrupt some rays badly; the mask must exclude them
    valid = np.array([[True, True, True, True],
                      [True, False, True, False],
                      [False, True, True, False],
                      [True, False, False, False],  # one ray: no point
                      [False, False, False, False],  # none
                      [True, True, True, True]])
    directions[~valid] = [0.3, 0.3, -0.9]
    directions[5, 2] = np.nan  # an unmasked non-finite ray is ignored too
    estimate, rms_miss, n_rays = triangulate_rays(origins, directions, valid)
    assert_array_equal(n_rays, [4, 2, 2, 1, 0, 3])
    ok = [0, 1, 2, 5]
    assert np.abs(estimate[ok] - points[ok]).max() < 1e-9
    assert rms_miss[ok].max() < 1e-9
    assert np.all(np.isnan(estimate[3:5]))


@pytest.mark.filterwarnings("error")
def test_triangulate_rays_ignores_zero_length_directions():
    cameras = _rig_cameras()[:3]
    points = _volume_points(np.random.default_rng(12), 3)
    origins, directions = _camera_rays(cameras, points)
    directions = directions.copy()
    directions[0, 1] = 0.0  # two good rays left
    directions[1, :2] = 0.0  # one good ray left
    estimate, _, n_rays = triangulate_rays(origins, directions)
    assert_array_equal(n_rays, [2, 1, 3])
    assert np.abs(estimate[[0, 2]] - points[[0, 2]]).max() < 1e-9
    assert np.all(np.isnan(estimate[1]))


def test_triangulate_rays_parallel_rays_give_nan():
    origins = np.array([[[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    directions = np.array([[[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]])
    estimate, _, n_rays = triangulate_rays(origins, directions)
    assert np.all(np.isnan(estimate))
    assert n_rays[0] == 2


def test_triangulate_rays_two_rays_equal_two_ray_midpoint():
    rng = np.random.default_rng(8)
    origins = rng.normal(size=(200, 2, 3))
    directions = rng.normal(size=(200, 2, 3))
    estimate, rms_miss, _ = triangulate_rays(origins, directions)
    midpoint, miss = triangulate_two_rays(origins[:, 0], directions[:, 0],
                                          origins[:, 1], directions[:, 1])
    assert_allclose(estimate, midpoint, rtol=0, atol=1e-8)
    # the midpoint is miss/2 from each ray
    assert_allclose(rms_miss, miss / 2, rtol=0, atol=1e-8)


def test_triangulate_rays_least_squares_hand_computed():
    # three lines: the x-axis, the y-axis, and the line x = y = 1 along z. The summed
    # squared distance (y²+z²) + (x²+z²) + ((x-1)²+(y-1)²) is least at (1/2, 1/2, 0).
    origins = np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]])
    directions = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]])
    estimate, rms_miss, _ = triangulate_rays(origins, directions)

    def cost(p):
        # distances² to the x-axis: y²+z²; y-axis: x²+z²; vertical line: (x-1)²+(y-1)²
        return p[1] ** 2 + p[2] ** 2 + p[0] ** 2 + p[2] ** 2 + (p[0] - 1) ** 2 + (p[1] - 1) ** 2

    assert_allclose(estimate[0], [0.5, 0.5, 0.0], rtol=0, atol=1e-12)
    assert rms_miss[0] == pytest.approx(np.sqrt(cost(estimate[0]) / 3), abs=1e-12)
    for step in np.eye(3) * 1e-3:
        assert cost(estimate[0] + step) > cost(estimate[0])
        assert cost(estimate[0] - step) > cost(estimate[0])


# ---- nearest point on a ray (eq. 4) -------------------------------------------------------

def test_closest_points_on_rays_hand_computed():
    result = closest_points_on_rays(np.array([1.0, 2.0, 3.0]), np.array([[0.0, 0.0, 2.0]]),
                                    np.array([[4.0, 5.0, 10.0]]))
    assert_allclose(result, [[1.0, 2.0, 10.0]], rtol=0, atol=1e-15)
    # behind the origin: the full line (k < 0) is used, as in eq. (3)
    result = closest_points_on_rays(np.array([[1.0, 2.0, 3.0]]), np.array([[0.0, 0.0, 1.0]]),
                                    np.array([[0.0, 0.0, -1.0]]))
    assert_allclose(result, [[1.0, 2.0, -1.0]], rtol=0, atol=1e-15)


def test_closest_points_on_rays_independent_of_direction_length():
    rng = np.random.default_rng(9)
    origins = rng.normal(size=(100, 3))
    directions = rng.normal(size=(100, 3))
    points = rng.normal(size=(100, 3)) * 3
    base = closest_points_on_rays(origins, directions, points)
    for scale in (1e-3, 0.5, -2.0, 1e3):
        assert_allclose(closest_points_on_rays(origins, scale * directions, points), base,
                        rtol=0, atol=1e-12)
    # the result lies on the ray and the offset is perpendicular to it
    unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    assert np.abs(np.cross(base - origins, unit)).max() < 1e-12
    assert_allclose(np.einsum("ij,ij->i", points - base, directions), 0, rtol=0, atol=1e-12)


def test_closest_point_on_camera_ray_recovers_point_on_ray():
    """Eq. (4) on a real camera ray: a prediction off the ray snaps to the true point
    when the error is perpendicular to the ray."""
    cam = _rig_cameras()[2]
    points = _volume_points(np.random.default_rng(10), 50)
    origin, directions = cam.rays(cam.project(points)[0])
    perpendicular = np.cross(directions, [0.0, 0.0, 1.0])
    predicted = points + 0.05 * perpendicular / np.linalg.norm(perpendicular, axis=1)[:, None]
    assert_allclose(closest_points_on_rays(origin, directions, predicted), points,
                    rtol=0, atol=1e-9)


def test_ray_angles_hand_computed():
    from pslog.geometry import ray_angles

    dirs = np.array([
        [[1.0, 0, 0], [0, 2.0, 0], [0, 0, 0]],          # x and y: 90°, third ray invalid
        [[1.0, 0, 0], [1.0, 1.0, 0], [3.0, 0, 0]],      # largest pair 45°
        [[1.0, 0, 0], [-5.0, 0, 0], [0, 0, 0]],         # a line has no sense: 0°
        [[0, 0, 1.0], [np.nan, 0, 0], [0, 0, 0]],       # one usable ray: undefined
    ])
    valid = np.array([[True, True, False], [True, True, True], [True, True, False],
                      [True, True, True]])
    np.testing.assert_allclose(np.degrees(ray_angles(dirs, valid))[:3], [90.0, 45.0, 0.0],
                               atol=1e-12)
    assert np.isnan(ray_angles(dirs, valid)[3])
