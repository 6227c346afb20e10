"""``filter``, the causal extended Kalman filter: one step against a hand computation, accuracy
bounds that a wrong equation breaks, jumps (bounces, kicks), outliers, streaming and
causality, prediction to "now", and an honest standard deviation."""

from __future__ import annotations

import numpy as np
import pytest
from _rally import rally
from numpy.testing import assert_allclose, assert_array_equal

from pslog import (
    NS,
    Camera,
    Motion,
    Observations,
    Rig,
    SimulationOptions,
    get_motion,
    look_at,
    simulate,
)
from pslog.estimation.projection import project_with_jacobian
from pslog.evaluation import errors_m, evaluate
from pslog.fusion import METHODS, causal_methods, default_methods, fuse
from pslog.fusion import filter as FM
from pslog.fusion.filter import FILTER_QUALITY, BallFilter, FilterOptions, fuse_filter
from pslog.fusion.stream import StreamFuser
from pslog.motion import G
from pslog.simulation import true_rig
from pslog.timing import observations as corrected_observations

DIST = np.array([-0.18, 0.06, 3e-4, -5e-4, -0.01])


def lab_rig(n: int = 3, fps: float = 30.0, distortion: bool = True) -> Rig:
    """Cameras of these tests (not the built-in ones): around a 3 x 2 m floor, 2.5 m up,
    lens distortion, type-A shutters."""
    cams = []
    for i in range(n):
        angle = 2 * np.pi * i / n + 0.3
        eye = (1.5 + 3.8 * np.cos(angle), 1.0 + 3.2 * np.sin(angle), 2.5 + 0.25 * i)
        R, t = look_at(eye, (1.5, 1.0, 0.7))
        K = [[610.0 + 10 * i, 0.2, 401.0], [0.0, 612.0 + 10 * i, 301.0], [0.0, 0.0, 1.0]]
        cams.append(Camera(f"l{i + 1}", 800, 600, K, DIST if distortion else np.zeros(5), R,
                           t, fps, i / (n * fps)))
    return Rig(tuple(cams), f"lab{n}")


def roll(seconds: float, seed: int = 0, friction: float = 0.4) -> Motion:
    """A ball rolling on the floor (a robot-soccer ball): its centre at the radius's height,
    no gravity acceleration, rolling friction decelerating it by ``friction`` m/s² until it
    stops, kicked along the floor every 0.6-1.6 s at 1.5-4 m/s towards a random point of the
    3 x 2 m floor (piecewise closed form; the kicks are velocity jumps)."""
    rng = np.random.default_rng(seed)
    starts, origins, directions, speeds = [], [], [], []
    t, p = 0.0, np.array([1.5, 1.0, 0.0215])
    while t < seconds + 2.0:
        target = np.array([rng.uniform(0.3, 2.7), rng.uniform(0.3, 1.7), p[2]])
        d = (target - p) / max(np.linalg.norm(target - p), 1e-9)
        s0 = rng.uniform(1.5, 4.0)
        dur = rng.uniform(0.6, 1.6)
        starts.append(t)
        origins.append(p.copy())
        directions.append(d)
        speeds.append(s0)
        tau = min(dur, s0 / friction)
        p = p + d * (s0 * tau - 0.5 * friction * tau * tau)
        t += dur
    starts = np.array(starts)

    def position(times: np.ndarray) -> np.ndarray:
        k = np.clip(np.searchsorted(starts, times, side="right") - 1, 0, len(starts) - 1)
        tau = np.minimum(times - starts[k], np.array(speeds)[k] / friction)
        s = np.array(speeds)[k] * tau - 0.5 * friction * tau * tau
        return np.array(origins)[k] + s[:, None] * np.array(directions)[k]

    return Motion("roll", seconds, position, "a ball rolling on the floor, kicked")


def swing(release: float = 1.0, radius: float = 0.5, omega: float = 4.0) -> Motion:
    """A ball swung on a horizontal circle (centre (1.5, 1.0, 0.8) m, ``omega`` rad/s) and
    released at ``release`` s: then a drag-free flight with the circle's tangential velocity
    and 1.5 m/s upwards (closed form)."""
    centre = np.array([1.5, 1.0, 0.8])
    end = omega * release
    v0 = np.array([-radius * omega * np.sin(end), radius * omega * np.cos(end), 1.5])

    def position(times: np.ndarray) -> np.ndarray:
        angle = omega * np.minimum(times, release)
        p = centre + radius * np.stack([np.cos(angle), np.sin(angle), 0 * angle], axis=1)
        s = np.maximum(times - release, 0.0)
        p += s[:, None] * v0
        p[:, 2] -= 0.5 * G * s * s
        return p

    return Motion("swing", release + 0.45, position, "swung on a circle, then released")


def session(rig, motion, duration=None, **options):
    detections, truth = simulate(rig, motion, duration, SimulationOptions(**options))
    return detections.best(), truth


# ---- one EKF step, by hand ----------------------------------------------------------------

def test_one_predict_and_update_step_equals_the_hand_computation():
    rig = lab_rig(3)
    cam = rig.cameras[1]
    # ballistic alone; no withholding (this state's std_m, 27 mm, is above the default bound);
    # the drag not estimated (its own step by hand: tests/test_filter_drag.py)
    options = FilterOptions(noise_px=0.4, accel_psd=0.3, drag_per_m=0.02, adapt_rate=0.0,
                            model_switch_per_s=0.0, turn_switch_per_s=0.0, max_std_m=None,
                            drag_std_per_m=0.0,
                            # the step's own std_m (a plain update's doubt on "no jump", its
                            # published term: test_filter_surprise.py)
                            surprise_cov=False)
    flt = BallFilter(rig, options)
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 6))
    P0 = A @ A.T * 1e-4 + np.diag([1e-5] * 3 + [1e-3] * 3)
    p0, v0 = np.array([1.2, 0.9, 1.1]), np.array([2.0, -0.7, 1.5])
    t0, t1 = 1_000_000_000, 1_011_111_111
    flt.set_state(t0, p0, v0, P0)

    # by hand: constant acceleration g - k|v|v over dt; F P Fᵀ + Q (white-noise acceleration)
    dt = (t1 - t0) / NS
    a = np.array([0.0, 0.0, -G]) - 0.02 * np.linalg.norm(v0) * v0
    x_pred = np.concatenate([p0 + v0 * dt + 0.5 * a * dt**2, v0 + a * dt])
    F = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    q = 0.3
    Q = q * np.block([[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)],
                      [dt**2 / 2 * np.eye(3), dt * np.eye(3)]])
    P_pred = F @ P0 @ F.T + Q
    # the detection: the projection of a point near the prediction, with lens distortion
    z = cam.project(x_pred[:3][None] + [[0.004, -0.003, 0.002]])[0][0]
    h, J = project_with_jacobian(cam, x_pred[:3][None])
    H = np.hstack([J[0], np.zeros((2, 3))])
    S = H @ P_pred @ H.T + 0.4**2 * np.eye(2)
    K = P_pred @ H.T @ np.linalg.inv(S)
    y = z - h[0]
    x_new = x_pred + K @ y
    P_new = P_pred - K @ S @ K.T

    assert_allclose(flt.predict(t1)[0], x_pred[:3], rtol=0, atol=1e-12)
    assert_allclose(flt.predict(t1)[1], x_pred[3:], rtol=0, atol=1e-12)
    # predict() adds the jumps the gap may hide (λ_j = 1/s, σ_j = 6 m/s: a compound Poisson
    # process; docs/methods.md "A prediction's covariance across its gap"); the update
    # uses the process model's P_pred
    jumps = 1.0 * 6.0**2 * np.block([[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)],
                                     [dt**2 / 2 * np.eye(3), dt * np.eye(3)]])
    assert_allclose(flt.predict(t1)[2], P_pred + jumps, rtol=0, atol=1e-12)
    point, quality = flt.push(t1, 1, *z)
    q = dict(zip(FILTER_QUALITY, quality, strict=True))
    time_ns, x, P = flt.state()
    assert time_ns == t1
    assert_allclose(point, x_new[:3], rtol=0, atol=1e-12)
    assert_allclose(x, x_new, rtol=0, atol=1e-12)
    assert_allclose(P, P_new, rtol=0, atol=1e-12)
    assert q["nis"] == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-10)
    assert q["innovation_px"] == pytest.approx(np.linalg.norm(y), rel=1e-12)
    assert q["std_m"] == pytest.approx(np.sqrt(np.trace(P_new[:3, :3])), rel=1e-12)
    assert q["residual_px"] == pytest.approx(
        np.linalg.norm(z - cam.project(x_new[:3][None])[0][0]), rel=1e-9)
    assert (q["jump"], q["rejected"], q["init"]) == (0.0, 0.0, 0.0)
    assert q["gap_s"] == pytest.approx(dt)


def test_one_step_of_the_two_models_equals_the_hand_computation():
    # the interacting multiple model of docs/methods.md: ballistic and supported models with
    # one covariance, the mixture's mean, μ and the models' difference e
    rig = lab_rig(3)
    cam = rig.cameras[2]
    # the supported model's own drag k_s (0 by default) apart from the ballistic one's k
    options = FilterOptions(noise_px=0.4, accel_psd=0.3, drag_per_m=0.02, adapt_rate=0.0,
                            accel_adapt_rate=0.0, model_switch_per_s=3.0,
                            supported_drag_per_m=0.005,
                            turn_switch_per_s=0.0)  # the turn model has its own test
    flt = BallFilter(rig, options)
    rng = np.random.default_rng(4)
    A = rng.normal(size=(6, 6))
    P0 = A @ A.T * 1e-4 + np.diag([1e-5] * 3 + [1e-3] * 3)
    p0, v0 = np.array([1.0, 1.1, 0.8]), np.array([-1.0, 0.6, 0.4])
    t0, t1 = 2_000_000_000, 2_011_111_111
    flt.set_state(t0, p0, v0, P0)  # μ = 0.9, e = 0

    dt = (t1 - t0) / NS
    g = np.array([0.0, 0.0, -G])
    p = 3.0 * dt
    c = 0.9 * (1 - p) + 0.1 * p
    # the mixture's acceleration: c (g - k‖v‖v) + (1 - c)(-k_s‖v‖v)
    a = c * g - (0.005 + c * (0.02 - 0.005)) * np.linalg.norm(v0) * v0
    x_pred = np.concatenate([p0 + v0 * dt + 0.5 * a * dt**2, v0 + a * dt])
    F = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    Q = 0.3 * np.block([[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)],
                        [dt**2 / 2 * np.eye(3), dt * np.eye(3)]])
    P_pred = F @ P0 @ F.T + Q
    # e = 0 before: the models' step difference alone, gravity and the drags' difference
    # at the mixture's predicted velocity
    v_pred = x_pred[3:]
    d = g - (0.02 - 0.005) * np.linalg.norm(v_pred) * v_pred
    e = np.concatenate([0.5 * d * dt**2, d * dt])
    # a detection of the supported model's prediction (no gravity), a little off
    z = cam.project((x_pred[:3] - c * e[:3])[None] + [[0.001, -0.002, 0.001]])[0][0]
    h, J = project_with_jacobian(cam, x_pred[:3][None])
    H = np.hstack([J[0], np.zeros((2, 3))])
    S = H @ P_pred @ H.T + 0.4**2 * np.eye(2)
    K = P_pred @ H.T @ np.linalg.inv(S)
    y = z - h[0]
    hd = J[0] @ e[:3]
    y_b, y_s = y - (1 - c) * hd, y + c * hd
    nis_b, nis_s = y_b @ np.linalg.solve(S, y_b), y_s @ np.linalg.solve(S, y_s)
    mu = c / (c + (1 - c) * np.exp(np.clip((nis_b - nis_s) / 2, -4, 4)))
    y_mix = y - (mu - c) * hd
    x_new = x_pred + (mu - c) * e + K @ y_mix
    P_new = P_pred - K @ S @ K.T
    e_new = e - K @ hd

    assert_allclose(flt.predict(t1)[0], x_pred[:3], rtol=0, atol=1e-12)
    _, quality = flt.push(t1, 2, *z)
    _, x, P = flt.state()
    assert_allclose(x, x_new, rtol=0, atol=1e-12)
    assert_allclose(P, P_new, rtol=0, atol=1e-12)
    assert flt._mu == pytest.approx(mu, rel=1e-9)
    assert mu < c  # the detection favours the supported model
    assert_allclose(flt._e, e_new, rtol=0, atol=1e-12)
    q = dict(zip(FILTER_QUALITY, quality, strict=True))
    assert q["nis"] == pytest.approx(y_mix @ np.linalg.solve(S, y_mix), rel=1e-9)


def _turn_mean(x, dt):
    """The coordinated turn's mean after ``dt`` (docs/methods.md), written apart from the
    filter's code: ``1 - cos a`` as ``2 sin²(a/2)`` and no series, complex-safe."""
    px, py, pz, vx, vy, vz, w = x
    a = w * dt
    s, c = np.sin(a), np.cos(a)
    sw, cw = s / w, 2.0 * np.sin(a / 2.0) ** 2 / w
    return np.array([px + sw * vx - cw * vy, py + cw * vx + sw * vy, pz + vz * dt,
                     c * vx - s * vy, s * vx + c * vy, vz, w])


def _turn_jacobian(x, dt):
    """∂(mean)/∂x by complex-step differentiation (exact to rounding)."""
    F = np.empty((7, 7))
    for j in range(7):
        step = np.zeros(7, dtype=complex)
        step[j] = 1e-30j
        F[:, j] = _turn_mean(x + step, dt).imag / 1e-30
    return F


def _cwna(q, dt, n=6):
    Q = np.zeros((n, n))
    Q[:6, :6] = q * np.block([[dt**3 / 3 * np.eye(3), dt**2 / 2 * np.eye(3)],
                              [dt**2 / 2 * np.eye(3), dt * np.eye(3)]])
    return Q


@pytest.mark.parametrize("omega", [4.2, -2e-4])  # a turn, and nearly straight (the series)
def test_one_prediction_of_the_turn_model_equals_the_hand_computation(omega):
    flt = BallFilter(lab_rig(3), FilterOptions(accel_psd=0.3, turn_rate_psd=0.7))
    rng = np.random.default_rng(5)
    A = rng.normal(size=(7, 7))
    P0 = A @ A.T * 1e-4 + np.diag([1e-5] * 3 + [1e-3] * 3 + [0.2])
    x0 = np.array([1.2, 0.9, 1.1, 2.0, -0.7, 1.5, omega])
    dt = 0.0111
    # by hand: the horizontal velocity turns by ω Δt, the height moves at constant speed;
    # P⁻ = F P Fᵀ + Q with white-noise acceleration q (accel_psd) and q_ω Δt on ω
    F = _turn_jacobian(x0, dt)
    Q = _cwna(0.3, dt, 7)
    Q[6, 6] = 0.7 * dt
    x_pred = _turn_mean(x0, dt)
    P_pred = F @ P0 @ F.T + Q
    xt, Pt = flt._turn_predicted(x0.tolist(), P0.ravel().tolist(), dt)
    assert_allclose(xt, x_pred, rtol=0, atol=1e-12)
    assert_allclose(np.reshape(Pt, (7, 7)), P_pred, rtol=0, atol=1e-12)
    # the transition's closed forms: the speed is kept, ∂v/∂ω = Δt (-v_y⁺, v_x⁺)
    assert np.hypot(*x_pred[3:5]) == pytest.approx(np.hypot(*x0[3:5]), rel=1e-14)
    assert_allclose(F[3:5, 6], dt * np.array([-x_pred[4], x_pred[3]]), rtol=1e-12)
    assert_allclose(F[3:5, 3:5], [[np.cos(omega * dt), -np.sin(omega * dt)],
                                  [np.sin(omega * dt), np.cos(omega * dt)]], rtol=0, atol=1e-15)


def test_one_step_of_the_turn_model_in_the_imm_equals_the_hand_computation():
    # mixing of the pair (here the ballistic model alone) and the turn model, their
    # predictions, likelihoods, the turn model's probability, both updates and the point
    rig = lab_rig(3)
    cam = rig.cameras[0]
    options = FilterOptions(noise_px=0.4, accel_psd=0.3, drag_per_m=0.02, adapt_rate=0.0,
                            accel_adapt_rate=0.0, model_switch_per_s=0.0,
                            turn_switch_per_s=2.0, turn_rate_psd=0.7, withhold=False,
                            surprise_cov=False)  # (test_filter_surprise.py)
    flt = BallFilter(rig, options)
    rng = np.random.default_rng(6)
    A, B = rng.normal(size=(7, 7)), rng.normal(size=(6, 6))
    Pt0 = A @ A.T * 1e-6 + np.diag([1e-5] * 3 + [1e-3] * 3 + [0.3])
    Pg0 = B @ B.T * 1e-6 + np.diag([1e-5] * 3 + [1e-3] * 3)
    xg0 = np.array([1.2, 0.9, 1.1, 2.0, -0.7, 1.5])
    xt0 = np.array([1.212, 0.891, 1.104, 1.9, -0.6, 1.45, 3.5])
    t0, t1 = 3_000_000_000, 3_011_111_111
    flt.set_state(t0, xg0[:3], xg0[3:], Pg0)
    flt._nu, flt._xt, flt._Pt = 0.4, xt0.tolist(), Pt0.ravel().tolist()

    dt = (t1 - t0) / NS
    nu, pt = 0.4, 2.0 * dt
    prior = nu * (1 - pt) + (1 - nu) * pt
    wt, wg = nu * pt / (1 - prior), (1 - nu) * pt / prior  # mixing weights
    d = xt0[:6] - xg0
    xg_m = xg0 + wt * d
    Pg_m = (1 - wt) * Pg0 + wt * Pt0[:6, :6] + wt * (1 - wt) * np.outer(d, d)
    xt_m = xt0.copy()
    xt_m[:6] -= wg * d
    Pt_m = Pt0.copy()
    Pt_m[:6, :6] = (1 - wg) * Pt0[:6, :6] + wg * Pg0 + wg * (1 - wg) * np.outer(d, d)
    Pt_m[:6, 6] *= 1 - wg
    Pt_m[6, :6] *= 1 - wg
    a = np.array([0.0, 0.0, -G]) - 0.02 * np.linalg.norm(xg_m[3:]) * xg_m[3:]
    xg_p = np.concatenate([xg_m[:3] + xg_m[3:] * dt + 0.5 * a * dt**2, xg_m[3:] + a * dt])
    F6 = np.block([[np.eye(3), dt * np.eye(3)], [np.zeros((3, 3)), np.eye(3)]])
    Pg_p = F6 @ Pg_m @ F6.T + _cwna(0.3, dt)
    F7 = _turn_jacobian(xt_m, dt)
    Q7 = _cwna(0.3, dt, 7)
    Q7[6, 6] = 0.7 * dt
    xt_p = _turn_mean(xt_m, dt)
    Pt_p = F7 @ Pt_m @ F7.T + Q7
    # a detection of the turn model's prediction, a little off, through the distorting lens
    z = cam.project((xt_p[:3] + np.array([3e-4, -2e-4, 1e-4]))[None])[0][0]

    def update(x, P, n):
        h, J = project_with_jacobian(cam, x[:3][None])
        H = np.hstack([J[0], np.zeros((2, n - 3))])
        S = H @ P @ H.T + 0.4**2 * np.eye(2)
        y = z - h[0]
        K = P @ H.T @ np.linalg.inv(S)
        log_l = -0.5 * y @ np.linalg.solve(S, y) - 0.5 * np.log(np.linalg.det(S))
        return x + K @ y, P - K @ S @ K.T, log_l

    xg_u, Pg_u, lg = update(xg_p, Pg_p, 6)
    xt_u, Pt_u, lt = update(xt_p, Pt_p, 7)
    r = np.clip(lt - lg, -4, 4)
    nu_post = prior / (prior + (1 - prior) * np.exp(-r))
    dd = xt_u[:6] - xg_u
    x_out = xg_u + nu_post * dd
    P_out = (1 - nu_post) * Pg_u + nu_post * Pt_u[:6, :6] + nu_post * (1 - nu_post) * np.outer(
        dd, dd)

    point, quality = flt.push(t1, 0, *z)
    assert flt._nu == pytest.approx(nu_post, rel=1e-9)
    assert nu_post > prior  # the detection favours the turn model
    assert_allclose(flt._x, xg_u, rtol=0, atol=1e-12)
    assert_allclose(np.reshape(flt._P, (6, 6)), Pg_u, rtol=0, atol=1e-12)
    assert_allclose(flt._xt, xt_u, rtol=0, atol=1e-12)
    assert_allclose(np.reshape(flt._Pt, (7, 7)), Pt_u, rtol=0, atol=1e-12)
    assert_allclose(point, x_out[:3], rtol=0, atol=1e-12)
    q = dict(zip(FILTER_QUALITY, quality, strict=True))
    assert q["std_m"] == pytest.approx(np.sqrt(np.trace(P_out[:3, :3])), rel=1e-9)
    _, x, P = flt.state()
    assert_allclose(x, x_out, rtol=0, atol=1e-12)
    assert_allclose(P, P_out, rtol=0, atol=1e-12)


def test_predict_leaves_the_state_alone_and_grows_the_uncertainty():
    rig = lab_rig(3)
    obs, _ = session(rig, get_motion("throw"), 0.5, noise_px=0.3, seed=2)
    flt = BallFilter(rig)
    assert flt.predict(0) is None  # no track yet
    for t, c, (u, v) in zip(obs.time_ns, obs.camera, obs.uv, strict=True):
        flt.push(t, c, u, v)
    before = flt.state()
    now = int(obs.time_ns[-1]) + 20_000_000
    p, v, P = flt.predict(now)
    after = flt.state()
    assert before[0] == after[0]
    assert_array_equal(before[1], after[1])
    assert_array_equal(before[2], after[2])
    assert np.linalg.norm(p - get_motion("throw").position(np.array([now / NS]))[0]) < 0.01
    assert np.trace(P[:3, :3]) > np.trace(before[2][:3, :3])
    assert_allclose(P, P.T, rtol=0, atol=1e-15)


# ---- accuracy: bounds a wrong equation breaks -----------------------------------------------

def _throw_error(options=None) -> float:
    rig = lab_rig(3)
    obs, truth = session(rig, get_motion("throw"), noise_px=0.3, seed=5)
    return evaluate(fuse_filter(obs, rig, None, options), truth).mean_mm


def python_kernels(monkeypatch) -> None:
    """Every compiled kernel of the filter replaced by its pure-Python original (numba's
    ``py_func``), so that a mutation of one of them reaches the whole step."""
    for name, value in list(vars(FM).items()):
        if hasattr(value, "py_func"):
            monkeypatch.setattr(FM, name, value.py_func)


def test_throw_accuracy_bound_fails_for_a_wrong_gravity_or_a_dropped_velocity_update(
        monkeypatch):
    rig = lab_rig(3)
    obs, truth = session(rig, get_motion("throw"), noise_px=0.3, seed=5)
    filt = evaluate(fuse(obs, rig, "filter"), truth)
    type_a = evaluate(fuse(obs, rig, "typeA"), truth)
    # measured 1.87 mm (typeA 4.89 mm); gravity upwards gives 13 mm, an update that leaves
    # the velocity alone 6.2 mm: the bound is tight enough to catch either
    assert filt.mean_mm < 2.4 and filt.mean_mm < 0.5 * type_a.mean_mm, (filt, type_a)
    assert _throw_error(FilterOptions(gravity=(0.0, 0.0, G))) > 2.4

    # the mutation runs the pure-Python originals of the compiled kernels (py_func), the
    # update's replaced by one that leaves the velocity alone
    python_kernels(monkeypatch)
    original = FM._updated

    def position_only(x, P, inn):
        xn, Pn = original(x, P, inn)
        xn = xn.copy()
        xn[3:] = x[3:]
        return xn, Pn

    monkeypatch.setattr(FM, "_updated", position_only)
    assert _throw_error() > 2.4


@pytest.mark.parametrize("noise", [0.0, 0.3, 1.0])
def test_rally_never_worse_than_type_a_and_half_of_it_at_a_third_of_a_pixel(noise):
    rig = lab_rig(3)
    motion, _ = rally(6.0, seed=5, speed=5.0, kick_every_s=0.8)
    obs, truth = session(rig, motion, 6.0, noise_px=noise, seed=8)
    track = fuse(obs, rig, "filter")
    filt = evaluate(track, truth)
    type_a = evaluate(fuse(obs, rig, "typeA"), truth)
    limit = {0.0: 0.6, 0.3: 0.55, 1.0: 0.55}[noise]  # measured 0.36, 0.48, 0.44
    assert filt.mean_mm < limit * type_a.mean_mm, (filt, type_a)
    # a point at every detection but those withheld (after a jump, until confirmed)
    assert filt.n_points + sum(track.dropped.values()) > 0.95 * type_a.n_points
    assert filt.n_points > 0.85 * type_a.n_points


def test_two_cameras_at_60_fps_and_four_cameras():
    for rig in (lab_rig(2, fps=60.0), lab_rig(4)):
        obs, truth = session(rig, get_motion("throw"), noise_px=0.3, seed=1)
        filt = evaluate(fuse(obs, rig, "filter"), truth)
        type_a = evaluate(fuse(obs, rig, "typeA"), truth)
        assert filt.mean_mm < 0.5 * type_a.mean_mm, (rig.name, filt, type_a)  # 0.39, 0.36


@pytest.mark.parametrize("name, limit", [("spiral", 0.5), ("straight", 0.5),
                                         ("turntable", 0.55)])
def test_non_ballistic_motions_are_followed_never_worse_than_type_a(name, limit):
    # no gravity, or a centripetal acceleration of 11-14 m/s²: the ballistic model is wrong;
    # the supported model (no gravity), the turn model and the process noise's adaptation
    # follow them
    rig = lab_rig(3)
    obs, truth = session(rig, get_motion(name), noise_px=0.3, seed=1)
    type_a = evaluate(fuse(obs, rig, "typeA"), truth).mean_mm
    filt = evaluate(fuse(obs, rig, "filter"), truth).mean_mm
    assert filt < limit * type_a, (filt, type_a)  # measured 0.42, 0.40, 0.49
    # the mutation: the ballistic model alone with the process noise held at accel_psd
    # (and without the turn model) fails it (measured 1.59, 2.34, 1.92; with its jumps'
    # covariance their hypotheses' mixture, session 27, the spiral's 1.26: pinned off; with
    # the hold for the next camera, session 30, the spiral's 1.23: pinned off; with the
    # floor bounce only within the floor's reach, session 36, the spiral's 1.29 against
    # 1.36: the floor pinned off, the default filter's ratios unchanged)
    fixed = evaluate(fuse_filter(obs, rig, options=FilterOptions(
        accel_adapt_rate=0.0, model_switch_per_s=0.0, turn_switch_per_s=0.0,
        jump_mixture_cov=False, hold_nis=None, floor_m=None)), truth).mean_mm
    assert fixed > 1.3 * type_a, (fixed, type_a)


@pytest.mark.parametrize("name", ["turntable", "spiral"])
def test_turning_motions_through_a_distorting_lens_need_the_turn_model(name):
    # a ball on a turntable (45 rpm, r = 0.5 m) and on a helix (3 m/s, r = 0.62 m), seen
    # through lenses with radial and tangential distortion: the coordinated-turn model
    # follows the centripetal acceleration the other two models lack
    rig = lab_rig(3)
    assert np.any(rig.cameras[0].dist)
    obs, truth = session(rig, get_motion(name), noise_px=0.3, seed=2)
    type_a = evaluate(fuse(obs, rig, "typeA"), truth).mean_mm
    filt = evaluate(fuse(obs, rig, "filter"), truth).mean_mm
    assert filt < 0.45 * type_a, (filt, type_a)  # measured 0.39, 0.38
    # the mutation: without the turn model (the filter before it) the ratio is 0.81, 0.82
    without = evaluate(fuse_filter(obs, rig, options=FilterOptions(turn_switch_per_s=0.0)),
                       truth).mean_mm
    assert without > 0.7 * type_a, (without, type_a)


def test_the_turn_model_wins_on_a_circle_and_leaves_a_flight():
    rig = lab_rig(3)

    def probabilities(obs):
        flt = BallFilter(rig)
        nus = []
        for t, c, uv in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(),
                            strict=True):
            flt.push(t, c, uv[0], uv[1])
            nus.append(flt._nu)
        return np.array(nus), obs.time_ns / NS

    nus, t = probabilities(session(rig, get_motion("turntable"), noise_px=0.3, seed=3)[0])
    late = nus[t > 0.3]
    assert np.median(late) > 0.95 and late.min() > 0.5, (np.median(late), late.min())
    # a flight: the turn model joins at the track's start and leaves within a few updates
    nus, t = probabilities(session(rig, get_motion("throw"), noise_px=0.3, seed=5)[0])
    assert np.mean(nus > 0) < 0.1 and np.median(nus) == 0.0, (np.mean(nus > 0))


def test_a_ball_rolling_on_the_floor_is_followed_by_the_supported_model():
    # a robot-soccer ball: rolling (no gravity acceleration, rolling friction), kicked along
    # the floor; the supported model wins (μ small) and the filter reaches 0.6 of typeA
    rig = lab_rig(3)
    obs, truth = session(rig, roll(8.0, seed=4), 8.0, noise_px=0.3, seed=2)
    type_a = evaluate(fuse(obs, rig, "typeA"), truth).mean_mm
    filt = evaluate(fuse(obs, rig, "filter"), truth).mean_mm
    assert filt < 0.6 * type_a, (filt, type_a)  # measured 0.43
    # the mutation: the ballistic model alone (the filter before the IMM) misses it
    alone = evaluate(fuse_filter(obs, rig, options=FilterOptions(
        model_switch_per_s=0.0, turn_switch_per_s=0.0)), truth).mean_mm
    assert alone > 0.7 * type_a, (alone, type_a)  # measured 0.78
    flt = BallFilter(rig)
    mus = []
    for t, c, uv in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(), strict=True):
        flt.push(t, c, uv[0], uv[1])
        mus.append(flt._mu)
    assert np.median(mus) < 0.1
    # and a flight keeps the ballistic model
    obs, _ = session(rig, get_motion("throw"), noise_px=0.3, seed=5)
    flt = BallFilter(rig)
    mus = []
    for t, c, uv in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(), strict=True):
        flt.push(t, c, uv[0], uv[1])
        mus.append(flt._mu)
    assert np.median(mus) > 0.9


def test_a_ball_swung_then_released_is_followed_by_the_turn_model_then_the_ballistic_one():
    # the turn model alone while the ball circles (the pair left the model set); at the
    # release the lag grows q, the pair rejoins and the ballistic model takes the flight
    rig = lab_rig(3)
    obs, truth = session(rig, swing(1.0), noise_px=0.3, seed=2)
    flt = BallFilter(rig)
    nus, mus, times, errors = [], [], [], []
    for t, c, uv in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(), strict=True):
        out = flt.push(t, c, uv[0], uv[1])
        nus.append(flt._nu)
        mus.append(flt._mu)
        if out is not None:
            times.append(t)
            errors.append(np.linalg.norm(np.array(out[0]) - truth.at(np.array([t]))[0]))
    t, nus, mus = obs.time_ns / NS, np.array(nus), np.array(mus)
    assert np.all(nus[(t > 0.4) & (t < 1.0)] == 1.0)  # the turn model alone
    flight = t > 1.2
    # the ballistic model takes the flight (μ 0.98-1.0; one detection dips since the floor
    # of q is per detection interval, session 11: a smaller S sharpens the likelihoods; at
    # 1.32 s: 0.81 with q's random walk, 0.76 with its change detector, session 33, which
    # keeps q at its floor there, the flight's mean error 1.98 -> 1.94 mm)
    assert np.all(nus[flight] < 0.1) and np.all(mus[flight] > 0.7), (nus[flight], mus[flight])
    assert np.median(mus[flight]) > 0.95, mus[flight]
    type_a = fuse(obs, rig, "typeA")
    err_a = errors_m(type_a, truth)
    errors, times = np.array(errors), np.array(times) / NS
    # measured 0.42 (0.79 without the turn model), after the release 0.48 (0.69)
    assert errors.mean() < 0.5 * err_a.mean(), (errors.mean(), err_a.mean())
    after = type_a.time_ns / NS > 1.0
    assert errors[times > 1.0].mean() < 0.6 * err_a[after].mean()
    assert errors.max() < 0.015  # measured 7.5 mm


@pytest.mark.parametrize("seed", [0, 2])
def test_no_output_point_of_a_kicked_rally_is_further_than_5_cm(seed):
    # the first detections after a kick fix the new velocity along their rays poorly: those
    # points are withheld (counted in Track.dropped) until another camera confirms the jump
    rig = lab_rig(3)
    motion, _ = rally(8.0, seed=seed)
    obs, truth = session(rig, motion, 8.0, noise_px=0.3, seed=seed)
    track = fuse(obs, rig, "filter")
    err = errors_m(track, truth)
    assert np.all(np.isfinite(err)) and err.max() < 0.05, err.max()  # measured 15, 17 mm
    assert 0 < track.dropped["unconfirmed"] < 0.1 * len(track)
    assert set(track.dropped) <= {"unconfirmed", "uncertain", "held"}
    # the mutation: every point output (withhold off) has points 165 and 220 mm off
    every = fuse_filter(obs, rig, options=FilterOptions(withhold=False))
    assert errors_m(every, truth).max() > 0.05
    assert len(every) == len(track) + sum(track.dropped.values())


# ---- jumps, outliers, losses ----------------------------------------------------------------

def test_a_bounce_is_a_jump_and_the_track_recovers_within_a_few_frames():
    # the jump search (the floor's contact not predicted: floor_m None; predicted, the
    # throw's bounce needs no jump: test_filter_floor.py)
    rig = lab_rig(3)
    obs, truth = session(rig, get_motion("throw"), noise_px=0.3, seed=4)
    # every point, the unconfirmed ones after the jump too (withhold off)
    track = fuse_filter(obs, rig, options=FilterOptions(withhold=False, floor_m=None))
    err = errors_m(track, truth)
    withheld = fuse_filter(obs, rig, options=FilterOptions(floor_m=None))
    assert withheld.dropped.get("unconfirmed", 0) >= 1
    assert np.all(errors_m(withheld, truth) < 0.05)
    # the throw's first floor bounce: z at the ball's radius
    t = np.linspace(0, 1.5, 150001)
    z = get_motion("throw").position(t)[:, 2]
    bounce_ns = int(t[np.argmin(z[: len(t) // 2 + 40000])] * NS)
    after = np.flatnonzero(track.time_ns > bounce_ns)
    assert np.any(track.quality["jump"][after[:3]] == 1)  # found within three detections
    assert np.all(err[after[6:30]] < 0.006)  # recovered after six (two frames per camera)
    assert np.all(err[after[:6]] < 0.06)
    before = np.flatnonzero(track.time_ns < bounce_ns)[-20:]
    assert np.all(track.quality["jump"][before] == 0)


def test_kicks_of_a_rally_are_followed():
    rig = lab_rig(3)
    motion, events = rally(4.0, seed=2, speed=6.0, kick_every_s=0.7)
    obs, truth = session(rig, motion, 4.0, noise_px=0.3, seed=3)
    track = fuse(obs, rig, "filter")
    err = errors_m(track, truth)
    for event in events[events < 3.8]:
        after = np.flatnonzero(track.time_ns > event * NS)[:40]
        settled = after[9:]
        assert np.median(err[settled]) < 0.008, event


def test_an_outlier_is_rejected_and_the_track_goes_on():
    rig = lab_rig(3)
    obs, truth = session(rig, get_motion("throw"), noise_px=0.3, seed=6)
    uv = obs.uv.copy()
    bad = 40
    uv[bad] += [60.0, -45.0]  # a false detection: another orange object
    track = fuse(Observations(obs.time_ns, obs.camera, uv, obs.frame_index), rig, "filter")
    clean = fuse(obs, rig, "filter")
    row = int(np.flatnonzero(track.time_ns == obs.time_ns[bad])[0])
    assert track.quality["rejected"][row] == 1
    assert track.quality["innovation_px"][row] > 50
    assert np.sum(track.quality["rejected"]) == 1
    assert errors_m(track, truth)[row] < 0.01  # the point is the prediction
    # a few points later the tracks agree again (at the detections both output: the hold for
    # the next camera may withdraw another point in one of them)
    later = track.time_ns > track.time_ns[row + 10]
    both, a, b = np.intersect1d(track.time_ns[later], clean.time_ns, return_indices=True)
    assert len(both) >= 0.95 * np.count_nonzero(later)
    assert_allclose(track.position_world[later][a], clean.position_world[b], atol=2e-3)


def test_a_gap_longer_than_max_gap_restarts_the_track_from_a_window():
    rig = lab_rig(3)
    obs, truth = session(rig, get_motion("throw"), noise_px=0.3, seed=7)
    gap = (obs.time_ns > 0.3 * NS) & (obs.time_ns < 0.6 * NS)
    kept = obs.select(~gap)
    track = fuse(kept, rig, "filter")
    later = kept.time_ns[kept.time_ns >= 0.6 * NS]
    restart = int(np.flatnonzero(track.time_ns >= 0.6 * NS)[0])
    assert track.time_ns[restart] == later[3]  # the fourth detection after the gap
    assert track.quality["init"][restart] == 1
    assert np.all(np.isnan(track.quality["innovation_px"][track.quality["init"] == 1]))
    assert errors_m(track, truth)[restart] < 0.02


def test_one_camera_alone_makes_no_point():
    rig = lab_rig(3)
    obs, _ = session(rig, get_motion("throw"), noise_px=0.3, seed=7)
    alone = obs.select(obs.camera == 0)
    assert len(fuse(alone, rig, "filter")) == 0
    uv = obs.uv.copy()
    uv[10] = np.nan  # an unusable pixel: no point, no crash
    track = fuse(Observations(obs.time_ns, obs.camera, uv, obs.frame_index), rig, "filter")
    assert obs.time_ns[10] not in track.time_ns and np.all(np.isfinite(track.position_world))


# ---- quality -----------------------------------------------------------------------------

def test_std_is_honest_and_quality_columns_are_complete():
    rig = lab_rig(3)
    err, std, tracks = [], [], []
    for seed in (9, 10, 11):  # pooled over three sessions: one draw's ratio moves by ±0.15
        motion, _ = rally(5.0, seed=seed, speed=5.0)
        obs, truth = session(rig, motion, 5.0, noise_px=0.5, seed=seed)
        track = fuse(obs, rig, "filter")
        assert list(track.quality) == list(FILTER_QUALITY)
        err.append(errors_m(track, truth))
        std.append(track.quality["std_m"])
        tracks.append(track)
    err, std = np.concatenate(err), np.concatenate(std)
    # std_m = sqrt(trace Σ) is the RMS of the 3-D error the filter expects; for a Gaussian
    # error ‖e‖/std_m has median sqrt(χ²₃ median / 3) = 0.89 and is below 2 for 99 %
    # (measured, pooled: RMS ratio 0.946, median 0.79, 98.2 % inside 2 std_m; per session
    # 0.78 / 0.96 / 1.04 — seed 9 alone was 0.837 before session 29's estimated drag and a
    # plain update's doubt term, each of which widens std_m)
    assert 0.8 < np.sqrt(np.mean(err**2) / np.mean(std**2)) < 1.4
    assert 0.6 < np.median(err / std) < 1.1
    assert np.mean(err <= 2 * std) > 0.95
    track = tracks[0]
    ok = track.quality["rejected"] == 0
    assert 0.3 < np.median(track.quality["residual_px"][ok]) < 0.8
    assert np.nanmedian(track.quality["innovation_px"][ok]) > np.median(
        track.quality["residual_px"][ok])
    assert np.all(track.quality["gap_s"][track.quality["init"] == 0] > 0)


# ---- streaming, causality, registry --------------------------------------------------------

def _stream(rig, logged):
    """Every detection pushed alone, in turn in each form a caller gives one in: numpy
    scalars and a (2,) pixel; Python numbers (the one-detection path of the filter's
    streaming form); one-row arrays, as ``pslog live`` pushes a frame."""
    fuser = StreamFuser(rig, "filter")
    times, cams, uv, frames = (logged.time_ns.tolist(), logged.camera.tolist(),
                               logged.uv.tolist(), logged.frame_index.tolist())
    parts = []
    for i in range(len(logged)):
        if i % 3 == 0:
            args = (logged.time_ns[i], logged.camera[i], logged.uv[i], logged.frame_index[i])
        elif i % 3 == 1:
            args = (times[i], cams[i], uv[i], frames[i])
        else:
            args = (logged.time_ns[i:i + 1], logged.camera[i:i + 1], logged.uv[i:i + 1],
                    logged.frame_index[i:i + 1])
        parts.append(fuser.push(*args))
    parts.append(fuser.flush())
    for p in parts:  # each a Track as the checked constructor leaves one: frozen columns
        columns = [p.time_ns, p.position_world, p.camera, *p.quality.values()]
        assert not any(c.flags.writeable for c in columns)
        assert all(c.flags.c_contiguous for c in columns)
        assert [c.dtype for c in columns[:3]] == [np.int64, np.float64, np.int32]
        assert p.position_world.shape == (len(p), 3) and list(p.quality) == list(
            FILTER_QUALITY) and all(c.shape == (len(p),) for c in columns[3:])
    return parts


@pytest.mark.parametrize("clock, turning", [(False, False), (True, False), (False, True),
                                            (True, True)])
def test_streaming_equals_batch_exactly_with_misses_drops_and_outliers(clock, turning):
    # a rally, and a ball swung then released (the turn model alone, then the pair again)
    base = lab_rig(3)
    a, b, c = base.names
    faults = dict(clock_offset_s={b: 0.0123, c: -0.0071}, clock_drift_ppm={b: 40.0, c: -25.0},
                  readout_s={a: 0.012, b: 0.02, c: 0.015}) if clock else {}
    options = SimulationOptions(noise_px=0.5, miss_rate=0.3, drop_rate=0.1, seed=4, **faults)
    motion, seconds = (swing(1.6), 2.0) if turning else (rally(4.0, seed=4)[0], 4.0)
    detections, _ = simulate(base, motion, seconds, options)
    rig = true_rig(base, options)
    logged = detections.best()
    uv = logged.uv.copy()
    rng = np.random.default_rng(0)
    spurious = rng.choice(len(uv), len(uv) // 20, replace=False)
    uv[spurious] = rng.uniform([0, 0], [800, 600], (len(spurious), 2))
    logged = Observations(logged.time_ns, logged.camera, uv, logged.frame_index)
    corrected = corrected_observations(
        type(detections).from_observations(detections.camera_names, logged), rig)
    batch = fuse(corrected, rig, "filter")
    parts = _stream(rig, logged)
    assert len(batch) > 90 and np.sum(batch.quality["rejected"]) > 0
    if turning:  # the turn model alone for a while, then the pair back after the release
        flt = BallFilter(rig)
        nus = []
        for t, cam, (u, v) in zip(corrected.time_ns.tolist(), corrected.camera.tolist(),
                                  corrected.uv.tolist(), strict=True):
            flt.push(t, cam, u, v)
            nus.append(flt._nu)
        assert max(nus) == 1.0 and nus[-1] < 1.0
    assert_array_equal(np.concatenate([p.time_ns for p in parts]), batch.time_ns)
    assert_array_equal(np.concatenate([p.camera for p in parts]), batch.camera)
    assert_array_equal(np.concatenate([p.position_world for p in parts]), batch.position_world)
    for name in FILTER_QUALITY:
        assert_array_equal(np.concatenate([p.quality[name] for p in parts]),
                           batch.quality[name])
    dropped: dict[str, int] = {}  # the withheld points, counted in the part they fell in
    for p in parts:
        for k, n in p.dropped.items():
            dropped[k] = dropped.get(k, 0) + n
    assert dropped == batch.dropped and sum(dropped.values()) > 0
    if not clock:  # no correction: each point comes out with its own detection or, held for
        # the next camera (session 30), with a later one's, the one that decides it
        own = [np.count_nonzero(p.time_ns == logged.time_ns[i]) for i, p in enumerate(parts[:-1])]
        assert all(np.all(p.time_ns <= logged.time_ns[i]) for i, p in enumerate(parts[:-1]))
        # (some left late; with 30 % misses most points follow a missed slot, held since
        # session 47: hold_gap)
        assert 0 < len(batch) - sum(own) < 0.8 * len(batch)


def test_the_stream_exposes_the_filter_for_prediction_to_now():
    rig = lab_rig(3)
    obs, _ = session(rig, get_motion("throw"), 0.6, noise_px=0.3, seed=1)
    fuser = StreamFuser(rig, "filter")
    for i in range(len(obs)):
        fuser.push(obs.time_ns[i], obs.camera[i], obs.uv[i])
    batch = BallFilter(rig)
    fuse_filter(obs, rig)  # the same points; the state is what matters here
    for t, c, (u, v) in zip(obs.time_ns, obs.camera, obs.uv, strict=True):
        batch.push(t, c, u, v)
    now = int(obs.time_ns[-1]) + 5_000_000
    for ours, theirs in zip(fuser.incremental.filter.predict(now), batch.predict(now),
                            strict=True):
        assert_array_equal(ours, theirs)


def test_filter_is_causal_on_every_prefix():
    rig = lab_rig(3)
    motion, _ = rally(2.0, seed=6)
    obs, _ = session(rig, motion, 2.0, noise_px=0.5, miss_rate=0.2, seed=6)
    full = fuse(obs, rig, "filter")
    for cut in range(5, len(obs), 7):
        prefix = fuse(obs.select(slice(0, cut)), rig, "filter")
        n = len(prefix)
        assert_array_equal(prefix.time_ns, full.time_ns[:n])
        assert_array_equal(prefix.position_world, full.position_world[:n])
        assert_array_equal(prefix.quality["std_m"], full.quality["std_m"][:n])


def test_registered_once_causal_for_every_timing():
    assert list(METHODS).count("filter") == 1
    entry = METHODS["filter"]
    assert entry.causal and not entry.waits_tolerance and entry.needs == frozenset()
    assert entry.streamer is not None and "filter" in causal_methods()
    rig = lab_rig(3)
    obs, _ = session(rig, get_motion("throw"), 0.3)
    assert "filter" in default_methods(obs, rig)
    with pytest.raises(Exception, match="init_detections"):
        FilterOptions(init_detections=2)
