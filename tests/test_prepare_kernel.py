"""prepare()'s compiled rays (_prepare_kernel.rays_from_normalized): Camera.rays' directions
bit for bit, from the normalised coordinates prepare inverts the lens for once, and its
pure-Python original the same; on ordinary pixels and on the edge cases Camera.rays handles
(NaN, infinite and far-off pixels, the principal point)."""

from __future__ import annotations

import numpy as np
import pytest

from pslog import builtin_rig
from pslog.fusion import _prepare_kernel
from pslog.fusion._prepare import _rays

LENSES = (None, (-0.25, 0.08, 0.001, -0.001, 0.0), (0.3, -0.1, 0.01, 0.02, 0.05))


@pytest.mark.parametrize("lens", LENSES)
def test_rays_equal_camera_rays_bit_for_bit(lens):
    rng = np.random.default_rng(7)
    for cam in builtin_rig("paper3").cameras:
        if lens is not None:
            cam = cam.replace(dist=np.array(lens))
        cx, cy = cam.K[0, 2], cam.K[1, 2]
        uv = np.concatenate([rng.uniform(-2000, 3000, (3000, 2)),
                             rng.uniform(0, 640, (3000, 2)),
                             [[np.nan, 1.0], [1.0, np.nan], [1e300, 5.0], [-1e300, 1e300],
                              [np.inf, 0.0], [cx, cy], [cx + 1e-9, cy]]])
        with np.errstate(all="ignore"):
            expected = cam.rays(uv)[1]
            xy = cam.undistort_normalized(uv)
            got = _rays(cam, xy)
            python = np.empty_like(got)
            _prepare_kernel.rays_from_normalized.py_func(xy, np.asarray(cam.R, float), python)
        assert np.isnan(expected).any() and np.isfinite(expected).any()
        assert got.tobytes() == expected.tobytes()
        assert np.array_equal(python, expected, equal_nan=True)
        # and prepare's undistorted pixels from the same coordinates: Camera.undistort's
        assert cam.pixels_from_normalized(xy).tobytes() == cam.undistort(uv).tobytes()


def test_rays_hand_computed():
    """The principal point looks along the optical axis, the world's R[2]; a pixel one
    focal length to the right, 45 degrees off it towards R[0]."""
    cam = builtin_rig("paper3").cameras[0]
    out = np.empty((2, 3))
    _prepare_kernel.rays_from_normalized(np.array([[0.0, 0.0], [1.0, 0.0]]),
                                         np.asarray(cam.R, float), out)
    assert np.allclose(out[0], cam.R[2], atol=1e-15)
    assert np.allclose(out[1], (cam.R[0] + cam.R[2]) / np.sqrt(2), atol=1e-15)


@pytest.mark.parametrize("lens", LENSES[:2])
def test_observed_rays_and_jacobians_equal_numpy_forms(lens):
    """Prepared.observed_rays / observed_direction_jacobians (compiled) against
    rays_from_undistorted and direction_jacobian (numpy), byte for byte, on a session with
    missed detections and damaged pixels (NaN, 1e300: no ray)."""
    from pslog import Observations, Rig, SimulationOptions, apply_timing, get_motion, simulate
    from pslog.fusion import prepare
    from pslog.fusion._prepare import direction_jacobian

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    if lens is not None:
        rig = Rig(tuple(c.replace(dist=np.array(lens)) for c in rig.cameras), rig.name)
    det, _ = simulate(rig, get_motion("throw"),
                      options=SimulationOptions(noise_px=0.5, miss_rate=0.2, seed=3))
    obs = det.best()
    uv = obs.uv.copy()
    uv[::17], uv[5::19] = 1e300, np.nan
    prep = prepare(Observations(obs.time_ns, obs.camera, uv, obs.frame_index), rig)
    with np.errstate(all="ignore"):
        rays = prep.rays_from_undistorted(prep.obs.camera, prep.uv_undistorted)
        jac = direction_jacobian(prep, prep.obs.camera, prep.uv_undistorted)
    assert np.isnan(rays).any() and np.isfinite(rays).any()
    assert prep.observed_rays.tobytes() == rays.tobytes()
    assert prep.observed_direction_jacobians.tobytes() == jac.tobytes()


def test_previous_next_equals_stable_sort_form():
    from pslog.fusion.innovation import _previous_next

    rng = np.random.default_rng(2)
    for n, m in ((0, 1), (1, 1), (50, 3), (2000, 4)):
        camera = rng.integers(0, m, n).astype(np.int32)
        order = np.argsort(camera, kind="stable")
        same = camera[order][1:] == camera[order][:-1]
        before, after = np.full(n, -1), np.full(n, -1)
        before[order[1:][same]] = order[:-1][same]
        after[order[:-1][same]] = order[1:][same]
        got = _previous_next(camera)
        assert np.array_equal(got[0], before) and np.array_equal(got[1], after)


@pytest.mark.parametrize("shared_origins", [True, False])
def test_least_squares_pixel_jacobians_compiled_equal_numpy_bit_for_bit(shared_origins):
    """nview_points' d(point)/d(pixel) (_prepare.least_squares_pixel_jacobians) by the
    compiled kernels (normal_inverse, ray_pixel_jacobian; what pslog fuse's nearest, sync,
    typeB and linear use) equals its numpy form bit for bit: two, three and four rays,
    unused rays (NaN directions there too), near-parallel rays (|det A| at the 1e-12
    cut), NaN points, origins broadcast from one per camera (a rig's centres) or per
    point; and the Jacobian moves the least-squares point as a finite difference does."""
    from pslog.fusion._prepare import least_squares_pixel_jacobians
    from pslog.geometry import triangulate_rays

    rng = np.random.default_rng(3)
    for m in (2, 3, 4):
        k = 3000
        centers = rng.normal(size=(m, 3)) * 3.0
        origins = (np.broadcast_to(centers, (k, m, 3)) if shared_origins
                   else centers + rng.normal(size=(k, m, 3)) * 0.1)
        dirs = rng.normal(size=(k, m, 3))
        dirs /= np.linalg.norm(dirs, axis=2, keepdims=True)
        dirs[:50, 1] = dirs[:50, 0] * (1 + 1e-7)  # near-parallel pairs
        dirs[:50, 1] /= np.linalg.norm(dirs[:50, 1], axis=1, keepdims=True)
        used = rng.random((k, m)) < 0.8
        used[:100] = True
        dirs[~used & (rng.random((k, m)) < 0.5)] = np.nan
        points = triangulate_rays(origins, np.where(used[..., None], dirs, 0.0), used)[0]
        points[rng.random(k) < 0.02] = np.nan
        turns = [rng.normal(size=(3, 2, k)) for _ in range(m)]
        with np.errstate(all="ignore"):
            want = least_squares_pixel_jacobians(points, origins, dirs, used, turns,
                                                 compiled=False)
            got = least_squares_pixel_jacobians(points, origins, dirs, used, turns,
                                                compiled=True)
        assert len(want) == len(got) == m
        for w, g in zip(want, got, strict=True):
            assert w.shape == g.shape == (3, 2, k)
            assert w.tobytes() == g.tobytes()
        assert np.isnan(want[0]).any() and np.isfinite(want[0]).sum() > want[0].size // 2
    # (the equation itself: a turn of ray 0 by the Jacobian's direction moves the point
    # as the triangulation of the turned ray does, to first order)
    k, eps = 200, 1e-7
    origins = np.broadcast_to(centers[:2], (k, 2, 3))
    dirs = rng.normal(size=(k, 2, 3))
    dirs /= np.linalg.norm(dirs, axis=2, keepdims=True)
    used = np.ones((k, 2), dtype=bool)
    points = triangulate_rays(origins, dirs, used)[0]
    turn = rng.normal(size=(3, 2, k))  # tangent to the unit directions (they stay unit)
    turn -= dirs[:, 0].T[:, None, :] * np.einsum("ijk,ki->jk", turn, dirs[:, 0])[None]
    J = least_squares_pixel_jacobians(points, origins, dirs, used, [turn, np.zeros_like(turn)],
                                      compiled=True)[0]
    moved = dirs.copy()
    moved[:, 0] += eps * turn[:, 0].T
    shifted = triangulate_rays(origins, moved, used)[0]
    assert np.allclose((shifted - points) / eps, J[:, 0].T, rtol=1e-4, atol=1e-4)


@pytest.mark.parametrize("lens", LENSES)
def test_prepare_with_a_head_of_earlier_rows_is_prepare_of_all_bit_for_bit(lens):
    # a stream prepares its window again at every push, reusing the rows prepared before
    # (prepare's ``head``): every row's values are its own, so the result is the same bits
    from pslog import Observations, Rig
    from pslog.fusion._prepare import prepare

    rig = builtin_rig("paper3")
    if lens is not None:
        rig = Rig(tuple(c.replace(dist=np.array(lens)) for c in rig.cameras), rig.name)
    rng = np.random.default_rng(3)
    n = 400
    uv = np.concatenate([rng.uniform(0, 640, (n - 3, 2)), [[1e300, 5.0], [np.nan, 1.0],
                                                           [-3000.0, 9000.0]]])
    obs = Observations(np.arange(n, dtype=np.int64) * 1_000_000, rng.integers(0, 3, n),
                       uv, np.arange(n))
    with np.errstate(all="ignore"):
        whole = prepare(obs, rig)
        for h in (0, 1, 150, n - 1, n):
            first = prepare(obs.select(slice(0, h)), rig)
            again = prepare(obs, rig, head=(first.uv_undistorted, first.ray_dir,
                                            first.uv_jacobian))
            for name in ("uv_undistorted", "ray_dir", "uv_jacobian"):
                assert getattr(again, name).tobytes() == getattr(whole, name).tobytes(), (h,
                                                                                          name)
