"""smooth's first (DLT) trajectory in compiled passes (``pslog.estimation._initial``): the
linear rows' quadratic forms, residuals and depths against the numpy gathers and einsums they
replaced, bit for bit, on random rows and on a whole first trajectory of a lensed rig; and a
hand case whose values are known."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _rigs import ring_rig
from numpy.testing import assert_array_equal

from pslog import SimulationOptions, simulate
from pslog.estimation import _initial, trajectory
from pslog.estimation._kernels import data_terms
from pslog.motion import rally_motion
from pslog.timing import observations


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _numpy_rows(camera, R, t, f, xy, depth, w, X):
    """The numpy form (trajectory._initial_control_numpy's lines): the gathered camera
    parameters, ``J``, target, ``data_terms``; the residuals and new depths at ``X``."""
    Rg, tg, fg = R[camera], t[camera], f[camera]
    A = Rg[:, :2, :] - xy[:, :, None] * Rg[:, 2:3, :]
    a0 = tg[:, :2] - xy * tg[:, 2:3]
    scale = fg / np.maximum(depth[:, None], 1e-3)
    J = A * scale[:, :, None]
    target = -(a0 * scale)
    upper, v = data_terms(J, target, w)
    new_depth = np.maximum(np.einsum("nj,nj->n", Rg[:, 2], X) + tg[:, 2], 1e-3)
    r = np.einsum("naj,nj->na", J, X) + a0 * scale
    return upper, v, r, new_depth


def _random_rows(seed: int, n: int = 2000):
    rng = np.random.default_rng(seed)
    C = 4
    R = np.array([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(C)])
    t = rng.normal(size=(C, 3)) * 3
    f = rng.uniform(300, 1500, size=(C, 2))
    camera = rng.integers(0, C, n).astype(np.int64)
    xy = rng.normal(size=(n, 2)) * 0.4
    depth = rng.uniform(0.5, 8, n)
    depth[:20] = rng.uniform(-1, 2e-3, 20)  # clamped at 1 mm
    depth[20] = np.nan
    w = rng.uniform(0, 2, n)
    X = rng.normal(size=(n, 3)) * 2
    return camera, R, t, f, xy, depth, w, X


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize("compiled", [True, False])
def test_dlt_passes_are_the_numpy_form_bit_for_bit(seed, compiled):
    """Every entry of the quadratic forms, the residuals and the depths has the numpy
    form's bits (NaN where it is NaN); the undecorated Python form too."""
    camera, R, t, f, xy, depth, w, X = _random_rows(seed)
    terms = _initial.dlt_terms if compiled else _initial.dlt_terms.py_func
    residuals = _initial.dlt_residuals if compiled else _initial.dlt_residuals.py_func
    n = 2000 if compiled else 300
    args = (camera[:n], R, t, f, xy[:n], depth[:n])
    upper, v = terms(*args, w[:n])
    r, new_depth = residuals(*args, X[:n])
    want = _numpy_rows(*args, w[:n], X[:n])
    for got, ref in zip((upper, v, r, new_depth), want, strict=True):
        assert_array_equal(_bits(got), _bits(ref))


def test_dlt_rows_of_a_hand_case():
    """A camera at the origin looking down +z (R = I, t = 0), f = (400, 500), a point at
    depth 2 on the ray through xy = (0.1, -0.2): the rows are ``f/d (1, 0, -x)`` and
    ``f/d (0, 1, -y)``, the residual 0 there and ``f/d`` per metre across; the new depth is
    the point's z."""
    R = np.eye(3)[None]
    t = np.zeros((1, 3))
    f = np.array([[400.0, 500.0]])
    xy = np.array([[0.1, -0.2]])
    camera = np.zeros(1, np.int64)
    X = np.array([[0.2, -0.4, 2.0]])
    upper, v = _initial.dlt_terms(camera, R, t, f, xy, np.array([2.0]), np.array([3.0]))
    J = np.array([[200.0, 0.0, -20.0], [0.0, 250.0, 50.0]])
    M = 3.0 * J.T @ J
    np.testing.assert_allclose(upper[0], M[np.triu_indices(3)], rtol=1e-15)
    np.testing.assert_array_equal(v[0], 0.0)  # t = 0: the rows pass through the origin
    r, depth = _initial.dlt_residuals(camera, R, t, f, xy, np.array([2.0]), X)
    np.testing.assert_allclose(r[0], 0.0, atol=1e-12)
    assert depth[0] == 2.0
    r, _ = _initial.dlt_residuals(camera, R, t, f, xy, np.array([2.0]),
                                  X + np.array([0.01, 0.0, 0.0]))
    np.testing.assert_allclose(r[0], [2.0, 0.0], atol=1e-12)  # 200 px per metre in x


def rally_problem(rig, motion_seed: int, seconds: float, options: SimulationOptions,
                  prior) -> trajectory._Problem:
    """smooth's problem of a simulated rally on ``rig``: its pieces, knots every 0.033 s
    without breaks, and ``prior`` (the tests of the first trajectory and the hat trace)."""
    detections, _ = simulate(rig, rally_motion(motion_seed, seconds), seconds, options)
    obs = observations(detections, rig)
    usable = np.all(np.isfinite(obs.uv), axis=1)
    pieces = trajectory.split_pieces(obs, usable, 0.12)
    t = (obs.time_ns - obs.time_ns[0]) / 1e9
    knots = [trajectory._knots_with_breaks(t[p[0]], t[p[-1]] + 1e-9, 0.033, np.zeros(0))
             for p in pieces]
    return trajectory._Problem(obs, rig, pieces, knots, prior)


def test_first_trajectory_is_the_numpy_form_bit_for_bit():
    """The whole first trajectory of a 3-second rally on a lensed four-camera ring: the
    same control points as the numpy form's, bit for bit."""
    prior = trajectory.SmoothOptions().prior
    problem = rally_problem(ring_rig(4, "lab4"), 5, 3.0,
                            SimulationOptions(noise_px=0.5, seed=3, miss_rate=0.05),
                            replace(prior, sigma_accel=10 * prior.sigma_accel))
    got = trajectory._initial_control(problem, 1.0)
    want = trajectory._initial_control_numpy(problem, 1.0)
    assert len(got) == problem.m
    assert_array_equal(_bits(got), _bits(want))
