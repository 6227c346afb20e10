"""Type A's compiled kernels (pslog.fusion._pseudo_kernel) against their pure-Python originals
(``kernel_fn.py_func``) and against the numpy forms they replace, on real sessions with a
strong lens, missed detections, dropped frames and outliers.

The equations themselves (eq. (1) interpolation, the snap, eqs. (2)-(4), the quality columns
and the covariance) are held by the hand-computed tests of test_fusion.py,
test_fusion_validity.py and test_paper.py, which run the compiled code."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from test_fusion_validity import dirty_session

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import FusionOptions, fuse, prepare, pseudo_stereo_points
from pslog.fusion import _pseudo_kernel as kernels
from pslog.fusion.pseudo import _all_brackets


def _python_kernels(monkeypatch) -> list[str]:
    """Replace every compiled kernel of the module by its pure-Python original (the others
    call them through the module's globals, so the whole computation runs in Python)."""
    names = [name for name, fn in vars(kernels).items() if hasattr(fn, "py_func")]
    for name in names:
        monkeypatch.setattr(kernels, name, getattr(kernels, name).py_func)
    return names


def _outputs(obs, rig, noise_px):
    track = fuse(obs, rig, "typeA", FusionOptions(noise_px=noise_px))
    prep = prepare(obs, rig)
    rows = np.arange(len(obs))
    past = pseudo_stereo_points(prep, rows, rows, int(0.2e9))
    return track, past


@pytest.mark.parametrize(("seed", "lens", "noise_px"), [(0, True, 0.5), (1, False, None),
                                                        (2, True, 1.0)])
def test_compiled_kernels_equal_their_python_originals(monkeypatch, seed, lens, noise_px):
    rig, obs, _ = dirty_session("typeA", seed, lens=lens)
    compiled, compiled_past = _outputs(obs, rig, noise_px)
    assert len(compiled) > 15
    # (numpy scalars in Python warn where the compiled numpy error model gives NaN silently)
    with monkeypatch.context() as patch, np.errstate(all="ignore"):
        assert "type_a_kernel" in _python_kernels(patch)
        python, python_past = _outputs(obs, rig, noise_px)
    # IEEE arithmetic in both (no fastmath), the same operations in the same order
    assert_array_equal(python.time_ns, compiled.time_ns)
    assert_array_equal(python.position_world, compiled.position_world)
    assert python.quality.keys() == compiled.quality.keys()
    for key, column in compiled.quality.items():
        assert_array_equal(python.quality[key], column, err_msg=key)
    assert python.dropped == compiled.dropped
    for field in compiled_past.__dataclass_fields__:
        assert_array_equal(getattr(python_past, field), getattr(compiled_past, field),
                           err_msg=field)


@pytest.mark.parametrize("timing", ["typeA", "sync"])
def test_brackets_kernel_equals_the_searchsorted_brackets(timing):
    # sync timing: every instant holds several rows (equal times), the exact-match case
    rig = apply_timing(builtin_rig("paper3"), timing)
    det, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(
        noise_px=0.5, miss_rate=0.3, drop_rate=0.1, seed=3))
    prep = prepare(det.best(), rig)
    prev, nxt, previous_instant = _all_brackets(prep)
    for camera in range(len(rig)):
        expected_prev, expected_next = prep.row_brackets(camera)
        assert_array_equal(prev[camera], expected_prev)
        assert_array_equal(nxt[camera], expected_next)
    assert_array_equal(previous_instant, prep.previous_instant)
    assert np.any(previous_instant < np.arange(len(previous_instant)) - 1) == (timing == "sync")


def test_reprojection_and_validity_helpers_equal_the_numpy_forms():
    # the kernels' per-point projection (through the lens) and view test against
    # _prepare's columns, at points in front, behind and outside the view
    from pslog.fusion._prepare import invalid_points, reprojection_px

    rig, obs, _ = dirty_session("typeA", 4, lens=True)
    prep = prepare(obs, rig)
    cam = kernels.camera_tables(prep)[0]
    rng = np.random.default_rng(0)
    points = rng.uniform([-6.0, -6.0, -2.0], [9.0, 8.0, 6.0], (400, 3))
    uv = rng.uniform([-100.0, -100.0], [740.0, 580.0], (400, 2))
    for c in range(len(rig)):
        camera = np.full(len(points), c)
        expected = reprojection_px(prep, points, camera, uv)
        got = np.array([kernels._reprojection(cam, c, *p, u, v) for p, (u, v) in zip(
            points, uv, strict=True)])
        assert_array_equal(np.isnan(got), np.isnan(expected))
        ok = ~np.isnan(expected)
        # (numpy's 3 x 3 product goes through BLAS, which may fuse multiply-adds)
        np.testing.assert_allclose(got[ok], expected[ok], rtol=1e-12, atol=1e-9)
        used = np.zeros((len(points), len(rig)), dtype=bool)
        used[:, c] = True
        flags = invalid_points(prep, points, used)
        got_flags = np.array([kernels._invalid(cam, c, *p) for p in points])
        assert_array_equal(got_flags, flags)
        assert {0, 1, 2} <= set(got_flags.tolist())  # in view, behind, outside


def test_past_point_flags_name_both_cameras_that_made_them():
    """A past point is OUTSIDE_VIEW when it falls outside the view of either camera that
    made it (the observed one and the partner: the kernel tests both), PARALLEL where its
    rays meet at less than the least angle, and has no flag without a partner: against
    invalid_points' columns, camera 1's view shrunk to its centre (a point outside the
    partner's view only is then common)."""
    from dataclasses import replace

    from pslog.fusion._prepare import MIN_RAY_ANGLE_DEG, OUTSIDE_VIEW, PARALLEL, invalid_points

    rig, obs, _ = dirty_session("typeA", 0, lens=True)
    prep = prepare(obs, rig)
    box = prep.view_box.copy()
    cu, cv = (box[1, 0] + box[1, 2]) / 2, (box[1, 1] + box[1, 3]) / 2
    box[1] = (cu - 5.0, cv - 5.0, cu + 5.0, cv + 5.0)
    prep = replace(prep, view_box=box)
    rows = np.arange(len(obs))
    # (each past point as the second next detection's P_{t-2} makes it: partner brackets
    # ending up to two rows later)
    past = pseudo_stereo_points(prep, rows, np.minimum(rows + 2, len(obs) - 1), int(0.2e9))
    has = past.partner >= 0
    used = np.zeros((len(rows), len(rig)), dtype=bool)
    used[rows, obs.camera] = True
    used[rows[has], past.partner[has]] = True
    expected = invalid_points(prep, past.points_world, used) & OUTSIDE_VIEW
    assert_array_equal(past.flags[has] & OUTSIDE_VIEW, expected[has])
    with np.errstate(invalid="ignore"):
        parallel = np.degrees(past.angle_rad) < MIN_RAY_ANGLE_DEG
    assert_array_equal((past.flags[has] & PARALLEL) > 0, parallel[has])
    assert_array_equal(past.flags[~has], 0)
    assert_array_equal(past.valid, has & (past.flags == 0) & np.all(
        np.isfinite(past.points_world), axis=1))
    # the cases are there: outside the partner's view only, and inside both
    partner_only = has & (obs.camera != 1) & (past.partner == 1)
    assert np.any(partner_only & (past.flags & OUTSIDE_VIEW > 0))
    assert np.any(has & (past.flags == 0))
