"""The per-session caches and closed forms behind typeA's speed (issue 12) against the direct
forms they replace: the same values (bit for bit where the arithmetic is the same, to 1e-12
where a closed form regroups it), on a session with lens distortion, misses and jitter."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog import Rig, SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import prepare
from pslog.fusion._prepare import (
    bracket,
    default_max_gap_s,
    direction_jacobian,
    direction_jacobian_along,
    dot_t,
    merged_slots,
)
from pslog.fusion.pseudo import fuse_type_a


@pytest.fixture(scope="module")
def prep():
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    rig = Rig(tuple(c.replace(dist=np.array([-0.25, 0.08, 0.001, -0.001, 0.0]))
                    for c in rig.cameras), rig.name)
    det, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(
        noise_px=0.5, miss_rate=0.3, drop_rate=0.1, jitter_s=0.0005, seed=3))
    return prepare(det.best(), rig)


def test_previous_instant_is_the_binary_search(prep):
    t = prep.obs.time_ns
    assert_array_equal(prep.previous_instant, np.searchsorted(t, t, side="left") - 1)


def test_previous_instant_with_shared_instants():
    # (synchronised cameras: several rows per instant; the latest row of the instant before)
    rig = apply_timing(builtin_rig("paper3"), "sync")
    det, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(seed=1))
    p = prepare(det.best(), rig)
    t = p.obs.time_ns
    assert len(np.unique(t)) < len(t)
    assert_array_equal(p.previous_instant, np.searchsorted(t, t, side="left") - 1)


def test_row_brackets_are_bracket_at_each_row(prep):
    for c in range(len(prep.cameras)):
        prev, nxt = prep.row_brackets(c)
        direct_prev, direct_next = bracket(prep, c, prep.obs.time_ns)
        assert_array_equal(prev, direct_prev)
        assert_array_equal(nxt, direct_next)


def test_observed_rays_and_jacobians_are_the_per_row_forms(prep):
    rows = np.arange(0, len(prep.obs), 7)
    cam, uv = prep.obs.camera[rows], prep.uv_undistorted[rows]
    assert_array_equal(prep.observed_rays[rows], prep.rays_from_undistorted(cam, uv))
    assert_array_equal(prep.observed_direction_jacobians[:, :, rows],
                       direction_jacobian(prep, cam, uv))


def test_direction_jacobian_along_is_the_contracted_jacobian(prep):
    rng = np.random.default_rng(0)
    rows = np.flatnonzero(np.all(np.isfinite(prep.uv_undistorted), axis=1))
    cam = prep.obs.camera[rows]
    uv = prep.uv_undistorted[rows] + rng.normal(0, 5, (len(rows), 2))
    v = rng.normal(size=(3, len(rows)))
    expected = dot_t(v, direction_jacobian(prep, cam, uv))
    assert_allclose(direction_jacobian_along(prep, cam, uv, v), expected, rtol=1e-12,
                    atol=1e-12 * np.abs(expected).max())


def test_merged_slots_merge_each_repeat_into_its_first_slot():
    rows = np.array([[5, 5, 7, 5, -1, -1],
                     [1, 2, 3, 4, 5, 6],
                     [9, 8, 9, 8, 9, -1]])
    merges, taken = merged_slots(rows)
    got = {(s, t): same.tolist() for s, t, same in merges}
    assert got == {(0, 1): [True, False, False], (0, 3): [True, False, False],
                   (0, 2): [False, False, True], (0, 4): [False, False, True],
                   (1, 3): [False, False, True]}
    assert_array_equal(taken, [[False, True, False, True, False, False],
                               [False] * 6,
                               [False, False, True, True, True, False]])


def test_type_a_is_the_same_with_a_fresh_and_a_reused_preparation(prep):
    # the caches are made once per Prepared: a second run on it (warm caches) and a run on a
    # fresh one give the same points and quality columns, bit for bit
    rig = Rig(prep.cameras, "lens")
    max_gap_s = default_max_gap_s(rig)
    first = fuse_type_a(prep, max_gap_s)[0]
    again = fuse_type_a(prep, max_gap_s)[0]
    fresh = fuse_type_a(prepare(prep.obs, rig), max_gap_s)[0]
    for track in (again, fresh):
        assert_array_equal(track.time_ns, first.time_ns)
        assert_array_equal(track.position_world, first.position_world)
        for k, v in first.quality.items():
            assert_array_equal(track.quality[k], v)


@pytest.mark.parametrize("python", [False, True])
def test_lensless_rows_are_prepare_columns(python):
    """_prepare_kernel.lensless_rows (a stream's new rows of cameras without a lens, one
    compiled pass) gives prepare's undistorted pixels, rays, pixel Jacobians and observed
    rays and direction Jacobians, byte for byte, far-off and NaN pixels included (no ray);
    its pure-Python original the same."""
    from pslog import Observations
    from pslog.fusion import _prepare_kernel

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    rng = np.random.default_rng(11)
    n = 400
    uv = np.concatenate([rng.uniform(-100, 740, (n - 4, 2)),
                         [[1e300, 5.0], [-7e3, 100.0], [6400.0, -6400.0], [np.nan, 3.0]]])
    obs = Observations(np.arange(n, dtype=np.int64) * 1000, np.arange(n) % 3, uv,
                       np.zeros(n, np.int64))
    with np.errstate(all="ignore"):
        prep = prepare(obs, rig)
        rays, jac = prep.observed_rays, prep.observed_direction_jacobians
    cams = rig.cameras
    tables = (np.array([np.asarray(c.K, float).ravel() for c in cams]),
              np.array([10.0 * max(c.width, c.height) for c in cams]),
              np.ascontiguousarray([np.asarray(c.R, float) for c in cams]),
              np.ascontiguousarray(prep._cols("K_inv").T), np.ascontiguousarray(prep._cols("R").T),
              np.ascontiguousarray(prep._rt_k_inv_cols.T))
    out = (np.empty((n, 2)), np.empty((n, 3)), np.empty((n, 2, 2)), np.empty((n, 4)),
           np.empty((n, 3)), np.empty((3, 2, n)))
    fn = _prepare_kernel.lensless_rows.py_func if python else _prepare_kernel.lensless_rows
    with np.errstate(all="ignore"):
        fn(obs.camera.astype(np.int64), uv, *tables, *out)
    assert np.isnan(out[0][[-4, -3, -1]]).all() and np.isfinite(out[0][:-4]).all()
    assert np.isfinite(out[1][-2]).all()  # 6400 px: at the edge, a ray
    for got, expected in zip(out, (prep.uv_undistorted, prep.ray_dir, prep.uv_jacobian,
                                   np.nan_to_num(prep.uv_jacobian).reshape(-1, 4), rays, jac),
                             strict=True):
        assert got.tobytes() == np.ascontiguousarray(expected).tobytes()
    # (prepare's lensless rows are this kernel's: the rays also against Camera.rays, the
    # numpy form, for the pixels that have one)
    for c, cam in enumerate(cams):
        rows = np.flatnonzero((obs.camera == c) & np.isfinite(out[1]).all(axis=1))
        assert len(rows) > 100
        with np.errstate(all="ignore"):
            expected = cam.rays(uv[rows])[1]
        assert out[1][rows].tobytes() == np.ascontiguousarray(expected).tobytes()


def test_rig_geometry_checked_once_and_refused_every_time():
    """prepare's rig constants (check_baselines, the fundamental matrices) are made once per
    camera geometry: the same F bit for bit, a copy each time (a caller's change does not
    reach the next prepare); a rig with two cameras at one centre is refused at every call."""
    from pslog.errors import RigError
    from pslog.fusion._prepare import _checked_geometry
    from pslog.geometry import fundamental_matrices

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    first = _checked_geometry(rig)
    assert first.tobytes() == fundamental_matrices(rig.cameras).tobytes()
    first[:] = 0.0
    assert _checked_geometry(rig).tobytes() == fundamental_matrices(rig.cameras).tobytes()
    cams = rig.cameras
    bad = Rig((cams[0], cams[1].replace(R=cams[0].R, t=cams[0].t), cams[2]), "bad")
    for _ in range(2):
        with pytest.raises(RigError, match="same centre"):
            _checked_geometry(bad)


def _view_flags_numpy(prep, points, used):
    """invalid_points' numpy form (the matrix products of each camera's points, as it was
    before its compiled pass): the reference of the compiled flags."""
    from pslog.fusion._prepare import BEHIND, OUTSIDE_VIEW, finite_rows

    flags = np.zeros(len(points), dtype=np.int64)
    finite = finite_rows(points)
    for c, cam in enumerate(prep.cameras):
        rows = np.flatnonzero(used[:, c] & finite)
        in_cam = np.take(points, rows, axis=0) @ cam.R.T + cam.t
        z = in_cam[:, 2]
        behind = z <= 1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = (in_cam[:, :2] / z[:, None]) @ cam.K[:2, :2].T + cam.K[:2, 2]
        box = prep.view_box[c]
        outside = ~behind & ~((uv[:, 0] >= box[0]) & (uv[:, 0] <= box[2])
                              & (uv[:, 1] >= box[1]) & (uv[:, 1] <= box[3]))
        flags[rows] |= behind * BEHIND | outside * OUTSIDE_VIEW
    return flags


def test_view_flags_are_the_matrix_products_flags(prep):
    # points on the edges of each camera's view box (to the last bit: a product rounded
    # otherwise than numpy's matmul moves some across), behind it, NaN, at random
    from pslog.fusion._prepare import invalid_points

    rng = np.random.default_rng(5)
    k, m = 30_000, len(prep.cameras)
    parts = [rng.normal(size=(k, 3)) * 3]
    for c, cam in enumerate(prep.cameras):
        box = prep.view_box[c]
        u = rng.choice([box[0], box[2]], k)
        v = rng.uniform(box[1], box[3], k)
        u[: k // 2], v[: k // 2] = rng.uniform(box[0], box[2], k // 2), rng.choice(
            [box[1], box[3]], k // 2)
        z = rng.uniform(0.5, 30.0, k) * rng.choice([1.0, 1.0, 1.0, -1.0], k)
        x = (u - cam.K[0, 2] - cam.K[0, 1] * (v - cam.K[1, 2]) / cam.K[1, 1]) / cam.K[0, 0]
        y = (v - cam.K[1, 2]) / cam.K[1, 1]
        parts.append((np.column_stack([x * z, y * z, z]) - cam.t) @ cam.R)
    points = np.ascontiguousarray(np.concatenate(parts))
    points[::97] = np.nan
    used = rng.random((len(points), m)) < 0.7
    flags = invalid_points(prep, points, used)
    expected = _view_flags_numpy(prep, points, used)
    assert np.count_nonzero(expected & 2) > 1000 and np.count_nonzero(expected & 1) > 1000
    assert_array_equal(flags, expected)


def test_ray_depths_rows_are_ray_depths():
    # every depth to the last bit, most of them about 0 (points in the plane through a
    # camera's centre across its ray: the sign is what nview_points keeps), NaN rows too
    from pslog.fusion._prepare_kernel import ray_depths_rows
    from pslog.geometry import ray_depths

    rng = np.random.default_rng(6)
    k, m = 20_000, 3
    centers = rng.normal(size=(m, 3)) * 5
    dirs = rng.normal(size=(k, m, 3))
    dirs /= np.linalg.norm(dirs, axis=2, keepdims=True)
    dirs[::101, 1] = np.nan
    points = rng.normal(size=(k, 3)) * 4
    points[1::2] = centers[0] + np.cross(dirs[1::2, 0], rng.normal(size=(k // 2, 3)))
    points[::97] = np.nan
    out = np.empty((k, m))
    ray_depths_rows(points, centers, dirs, out)
    expected = ray_depths(points, np.broadcast_to(centers, (k, m, 3)), dirs)
    assert np.count_nonzero(np.abs(expected[:, 0]) < 1e-14) > k // 4
    assert_array_equal(out, expected)
    assert_array_equal(out > 0, expected > 0)


def test_probes_take_the_compiled_passes_only_where_they_give_numpys_bits():
    # on x86-64 (OpenBLAS, numpy's einsum) both kernels repeat numpy's order, so the
    # probes pass (elsewhere they may not); a kernel summing in another order (products
    # rounded before the sum, or the dot's terms in the natural order) must fail its
    # probe: numpy's forms then
    import platform

    import numba

    from pslog.fusion._prepare import (
        _ray_depths_probe,
        _view_probe,
        ray_depths_compiled,
        view_flags_compiled,
    )
    from pslog.fusion._prepare_kernel import ray_depths_rows, view_project

    here = platform.machine() in ("x86_64", "AMD64")  # the orders the kernels repeat
    assert view_flags_compiled() == _view_probe(view_project) == here or not here
    assert ray_depths_compiled() == _ray_depths_probe(ray_depths_rows) == here or not here

    @numba.njit  # view_project's sums without fused multiply-adds
    def rounded_products(points, cams, boxes, out):
        for p in range(points.shape[0]):
            for c in range(cams.shape[0]):
                q = points[p]
                x = ((q[0] * cams[c, 0] + q[1] * cams[c, 1]) + q[2] * cams[c, 2]) + cams[c, 9]
                y = ((q[0] * cams[c, 3] + q[1] * cams[c, 4]) + q[2] * cams[c, 5]) + cams[c, 10]
                z = ((q[0] * cams[c, 6] + q[1] * cams[c, 7]) + q[2] * cams[c, 8]) + cams[c, 11]
                u = v = 0.0
                if z > 1e-9:
                    u = ((x / z) * cams[c, 12] + (y / z) * cams[c, 13]) + boxes[c, 4]
                    v = ((x / z) * cams[c, 14] + (y / z) * cams[c, 15]) + boxes[c, 5]
                out[p, c, 0], out[p, c, 1], out[p, c, 2], out[p, c, 3], out[p, c, 4] = (
                    x, y, z, u, v)

    @numba.njit  # the dot products' terms in their natural order
    def natural_order(points, centers, dirs, out):
        for p in range(dirs.shape[0]):
            for c in range(dirs.shape[1]):
                o = points[p] - centers[c]
                d = dirs[p, c]
                out[p, c] = ((o[0] * d[0] + o[1] * d[1]) + o[2] * d[2]) / (
                    (d[0] * d[0] + d[1] * d[1]) + d[2] * d[2])

    assert not _view_probe(rounded_products)
    assert not _ray_depths_probe(natural_order)
