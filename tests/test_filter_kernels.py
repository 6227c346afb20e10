"""The ``filter``'s compiled kernels (numba, :mod:`pslog._jit`): each equals its pure-Python
original (``py_func``) exactly, the whole step run in pure Python gives the compiled
filter's points bit for bit, and a rejected detection reports its innovation against the
prediction (hand computation)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _bits import assert_blas_bits
from _rally import rally
from numpy.testing import assert_array_equal
from test_filter import lab_rig, python_kernels, session, swing

from pslog import NS, Observations, SimulationOptions, get_motion, simulate
from pslog.fusion import filter as FM
from pslog.fusion.filter import FILTER_QUALITY, BallFilter, FilterOptions, fuse_filter


def _random_state(rng, n):
    A = rng.normal(size=(n, n))
    P = A @ A.T * 1e-4 + np.diag([1e-5] * 3 + [1e-3] * 3 + [0.2] * (n - 6))
    x = np.concatenate([rng.uniform([0.5, 0.5, 0.3], [2.5, 1.5, 1.5]), rng.normal(size=3),
                        rng.normal(size=n - 6) * 3])
    return x, P.ravel()


def _same(a, b):
    if isinstance(a, tuple):
        assert len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _same(x, y)
    else:
        assert_array_equal(np.asarray(a), np.asarray(b))


def test_each_kernel_equals_its_python_original_on_random_cases():
    rig = lab_rig(3)
    flt = BallFilter(rig)
    cams, O = flt._cam_table, flt._opts
    # the supported model with a drag of its own too (its terms in _predicted and _mixed)
    O_ks = BallFilter(rig, FilterOptions(supported_drag_per_m=0.003))._opts
    rng = np.random.default_rng(1)
    for i in range(40):
        O = O_ks if i % 2 else flt._opts
        x6, P6 = _random_state(rng, 6)
        x7, P7 = _random_state(rng, 7)
        dt, c = rng.uniform(-0.05, 0.2), rng.uniform(0, 1)
        cam = int(rng.integers(3))
        u, v = rng.uniform(0, 800), rng.uniform(0, 600)
        calls = [
            (FM._project, (cams, cam, *x6[:3])),
            (FM._predicted, (x6, P6, dt, c, O, 0.3)),
            (FM._turn_predicted, (x7, P7, dt, 0.3, 0.7)),
            (FM._turn_predicted, (x7 * [1, 1, 1, 1, 1, 1, 1e-5], P7, dt, 0.3, 0.7)),
            (FM._innovation, (cams, cam, x6, P6, 6, u, v, 0.25)),
            (FM._innovation, (cams, cam, x7, P7, 7, u, v, 0.25)),
            (FM._turn_mixed, (0.4, x6, P6, x7, P7, dt, 2.0)),
            (FM._turn_start, (x6, P6, 0.5, 36.0)),
            (FM._combined, (x6, P6, x7, P7, 0.3)),
            (FM._combined_point, (x6, P6, x7, P7, 0.3)),
            (FM._turn_probability, (0.3, c, 2.0, 5.0, 0.7, 1.5, 0.8)),
        ]
        ok, inn = FM._innovation(cams, cam, x6, P6, 6, u, v, 0.25)
        if ok:
            calls += [(FM._updated, (x6, P6, inn)),
                      (FM._mixed, (x6, inn, c, 0.05, dt, 0.8, rng.normal(size=6) * 1e-3, O))]
        for shape in range(int(O[FM._ONSHAPES])):
            calls.append((FM._jumped, (x6, P6, abs(dt), O, shape)))
        for fn, args in calls:
            _same(fn(*args), fn.py_func(*args))


def _dirty(obs, seed=0):
    uv = obs.uv.copy()
    rng = np.random.default_rng(seed)
    spurious = rng.choice(len(uv), len(uv) // 20, replace=False)
    uv[spurious] = rng.uniform([0, 0], [800, 600], (len(spurious), 2))
    return Observations(obs.time_ns, obs.camera, uv, obs.frame_index)


@pytest.mark.parametrize("turning", [False, True])
def test_the_step_in_pure_python_gives_the_compiled_points_bit_for_bit(turning, monkeypatch):
    # a kicked rally (jumps) and a ball swung then released (the turn model alone, then the
    # pair again), with misses and spurious detections (rejections, restarts)
    rig = lab_rig(3)
    motion, seconds = (swing(1.0), None) if turning else (rally(2.0, seed=4)[0], 2.0)
    obs, _ = session(rig, motion, seconds, noise_px=0.5, miss_rate=0.2, seed=4)
    obs = _dirty(obs)
    options = FilterOptions(withhold=turning)  # the rally's jumps: every point output
    compiled = fuse_filter(obs, rig, options=options)
    python_kernels(monkeypatch)
    python = fuse_filter(obs, rig, options=options)
    assert len(compiled) > 50 and np.sum(compiled.quality["rejected"]) > 0
    assert np.sum(compiled.quality["jump"]) > 0 or turning
    assert_array_equal(compiled.time_ns, python.time_ns)
    # bit for bit where this machine's BLAS sums unfused (the Python originals' small numpy
    # products go to the BLAS; tests/_bits.py), else to rounding
    assert_blas_bits(compiled.position_world, python.position_world)
    for name in FILTER_QUALITY:
        assert_blas_bits(compiled.quality[name], python.quality[name], err_msg=name)
    assert compiled.dropped == python.dropped


def test_a_rejected_detection_reports_its_innovation_against_the_prediction():
    # by hand: the point of a rejected detection is the prediction; its innovation_px is the
    # detection's distance from the prediction's projection and its NIS y' S⁻¹ y with
    # S = H P Hᵀ + σ² I (the ballistic model alone, fixed noise, no turn model)
    rig = lab_rig(3)
    # (no jump rate, no drag estimated: predict() is then the process model's prediction the
    # gate uses; the estimated drag moves the published point, tests/test_filter_drag.py)
    options = FilterOptions(adapt_rate=0.0, accel_adapt_rate=0.0, model_switch_per_s=0.0,
                            turn_switch_per_s=0.0, noise_px=0.4, withhold=False,
                            jump_rate_per_s=0.0, drag_std_per_m=0.0)
    obs, _ = session(rig, get_motion("throw"), noise_px=0.3, seed=6)
    flt = BallFilter(rig, options)
    bad = 40
    for i in range(bad):
        flt.push(int(obs.time_ns[i]), int(obs.camera[i]), *obs.uv[i])
    t, cam = int(obs.time_ns[bad]), int(obs.camera[bad])
    p, _, P = flt.predict(t)
    camera = rig.cameras[cam]
    z = camera.project(p[None])[0][0] + [60.0, -45.0]  # another orange object
    from pslog.estimation.projection import project_with_jacobian

    h, J = project_with_jacobian(camera, p[None])
    S = J[0] @ P[:3, :3] @ J[0].T + 0.4**2 * np.eye(2)
    y = z - h[0]
    point, quality = flt.push(t, cam, *z)
    q = dict(zip(FILTER_QUALITY, quality, strict=True))
    assert q["rejected"] == 1.0 and q["jump"] == 0.0
    np.testing.assert_allclose(point, p, rtol=0, atol=1e-12)
    assert q["innovation_px"] == pytest.approx(math.hypot(*y), rel=1e-9)
    assert q["residual_px"] == q["innovation_px"]
    assert q["nis"] == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-7)


def test_the_state_survives_a_python_round_trip_of_the_window():
    # the window (re)initialisation's detections live in the state arrays; the Python fit
    # reads and writes them: a session with gaps restarts the same in batch and pushed
    rig = lab_rig(3)
    detections, _ = simulate(rig, get_motion("throw"), None,
                             SimulationOptions(noise_px=0.3, seed=7))
    obs = detections.best()
    gap = (obs.time_ns > 0.3 * NS) & (obs.time_ns < 0.6 * NS)
    obs = obs.select(~gap)
    batch = fuse_filter(obs, rig)
    flt = BallFilter(rig)
    pushed = [flt.push(t, c, u, v) for t, c, (u, v) in zip(
        obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(), strict=True)]
    pushed = [p for p in pushed if p is not None]
    assert np.sum(batch.quality["init"]) >= 2
    assert_array_equal(np.array([p[0] for p in pushed]), batch.position_world)
    assert_array_equal(np.array([p[1] for p in pushed]),
                       np.stack([batch.quality[k] for k in FILTER_QUALITY], axis=1))


def test_the_filter_does_not_depend_on_the_order_of_the_rigs_cameras():
    # a kicked rally (jump replays): the same cameras listed in another order give the same
    # points. The replay once weighted gravity by the replayed detection's camera index
    # (none for the first camera, twice for the third) instead of the ballistic model's
    # probability: the order then moved points by millimetres.
    from pslog import Rig

    rig = lab_rig(3)
    obs, _ = session(rig, rally(2.0, seed=4)[0], 2.0, noise_px=0.5, miss_rate=0.2, seed=4)
    obs = _dirty(obs)
    options = FilterOptions(withhold=False)
    order = [2, 0, 1]  # new position k holds the old camera order[k]
    new_index = np.argsort(order)
    permuted = Rig(tuple(rig.cameras[k] for k in order), rig.name)
    moved = Observations(obs.time_ns, new_index[obs.camera], obs.uv, obs.frame_index)
    a = fuse_filter(obs, rig, options=options)
    b = fuse_filter(moved, permuted, options=options)
    assert np.sum(a.quality["jump"]) > 0  # the replay ran
    assert_array_equal(a.time_ns, b.time_ns)
    np.testing.assert_allclose(b.position_world, a.position_world, rtol=0, atol=1e-9)
