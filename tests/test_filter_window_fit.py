"""``filter``'s start: the window fit compiled (``_window_fit``, issue 12's live latency: a
start attempt fits up to five windows by two models) is the numpy fit it replaced, bit for
bit (the same LAPACK least squares, numpy's order of summation), on every window a filter
fits on rigs with and without lens distortion, at 30 to 240 fps, noise 0 to 1 px, with
misses; and the kernel equals its pure-Python form."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _bits import blas_is_plain
from _rally import rally
from test_filter import lab_rig

import pslog.fusion.filter as F
from pslog import SimulationOptions, get_motion, simulate
from pslog.fusion.filter import NS, BallFilter
from pslog.rig import apply_timing, builtin_rig


def _numpy_fit(flt, window, ballistic=True):
    """The window fit as it was before it was compiled (``BallFilter._fit`` of session 8,
    numpy), the reference: ``(x, P flat, residuals)``, None or ``"short"``."""
    t_ref = window[-1][0]
    tau = np.array([(w[0] - t_ref) / NS for w in window])
    g = np.array(flt._g) if ballistic else np.zeros(3)
    k = flt._k if ballistic else flt.options.supported_drag_per_m
    rays = [flt._ray(*w) for w in window]
    O = np.array([o for o, _ in rays])
    D = np.array([d for _, d in rays])
    if not np.all(np.isfinite(D)):
        return None
    helper = np.where((np.abs(D[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    E1 = np.cross(D, helper)
    E1 /= np.linalg.norm(E1, axis=1, keepdims=True)
    E = np.concatenate([E1, np.cross(D, E1)])
    T = np.concatenate([tau, tau])
    OO = np.concatenate([O, O])
    accel = g
    weights = np.ones(len(T))
    theta = None
    for _ in range(2):
        A = weights[:, None] * np.hstack([E, T[:, None] * E])
        b = weights * np.einsum("ij,ij->i", E, OO - 0.5 * (T * T)[:, None] * accel)
        theta, _, rank, sv = np.linalg.lstsq(A, b, rcond=None)
        if rank < 6 or sv[-1] < 1e-10 * sv[0]:
            return None
        depth = np.einsum("ij,ij->i", theta[:3] + tau[:, None] * theta[3:] - O, D)
        if not np.all(depth > F._MIN_DEPTH_M):
            return None
        weights = np.concatenate([1.0 / depth, 1.0 / depth])
        accel = g - k * np.linalg.norm(theta[3:]) * theta[3:]

    def system(theta):
        points = (theta[:3] + tau[:, None] * theta[3:]
                  + 0.5 * (tau * tau)[:, None] * accel).tolist()
        rows, res = [], []
        for (_, camera, u, v), ti, p in zip(window, tau.tolist(), points, strict=True):
            ok, pu, pv, *h = F._project(flt._cam_table, camera, p[0], p[1], p[2])
            if not ok:
                return None, None
            h0, h1 = h[:3], h[3:]
            rows.append([h0[0], h0[1], h0[2], ti * h0[0], ti * h0[1], ti * h0[2]])
            rows.append([h1[0], h1[1], h1[2], ti * h1[0], ti * h1[1], ti * h1[2]])
            res.append(u - pu)
            res.append(v - pv)
        return np.array(rows), np.array(res)

    for _ in range(3):
        J, r = system(theta)
        if J is None:
            return None
        theta = theta + np.linalg.lstsq(J, r, rcond=None)[0]
    J, r = system(theta)
    if J is None:
        return None
    residuals = np.hypot(r[0::2], r[1::2])
    var = flt._start_var()
    if not (np.all(residuals ** 2 <= flt._gate * var)
            and float(r @ r) <= F._chi2_quantile(len(r) - 6) * var):
        return None
    info = J.T @ J
    try:
        cov = var * np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(cov)) or np.linalg.cond(info) > 1e14:
        return None
    if np.trace(cov[:3, :3]) > flt.options.max_init_std_m ** 2:
        return "weak"  # consistent, too little information (session 10)
    if np.trace(cov[3:, 3:]) > flt.options.max_init_speed_std ** 2:
        return "short"
    cov = 0.5 * (cov + cov.T)
    return [float(a) for a in theta], [float(a) for a in cov.ravel()], residuals


def _numpy_turn_fit(flt, window, theta, var, turn_prior=None):
    """The turn model's MAP fit as it was before it was compiled (``BallFilter._turn_fit``
    of session 8, numpy; session 13: the prior ``ω ~ N(mean, variance)`` of ``turn_prior``,
    default ``N(0, turn_rate_std²)``), the reference: ``(x_t, P_t flat, residuals)`` or None."""
    mean, turn_var = (0.0, flt._turn_var) if turn_prior is None else turn_prior
    t_ref = window[-1][0]
    tau = np.array([(w[0] - t_ref) / NS for w in window])
    th = np.array([*theta, mean])
    prior = math.sqrt(var / turn_var)
    row = np.zeros((1, 7))
    row[0, 6] = prior

    def system(th):
        vx, vy, vz, w = th[3], th[4], th[5], th[6]
        a = w * tau
        s, c = np.sin(a), np.cos(a)
        small = np.abs(a) <= 1e-3
        wd = np.where(small, 1.0, w)
        a2 = a * a
        sw = np.where(small, tau * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0)), s / wd)
        cw = np.where(small, tau * a * (0.5 - a2 / 24.0), (1.0 - c) / wd)
        dsw = np.where(small, tau * tau * a * (a2 / 30.0 - 1.0 / 3.0), (tau * c - sw) / wd)
        dcw = np.where(small, tau * tau * (0.5 - a2 / 8.0), (tau * s - cw) / wd)
        px = th[0] + sw * vx - cw * vy
        py = th[1] + cw * vx + sw * vy
        pz = th[2] + vz * tau
        D = np.zeros((len(tau), 3, 7))
        D[:, 0, 0] = D[:, 1, 1] = D[:, 2, 2] = 1.0
        D[:, 0, 3], D[:, 0, 4], D[:, 1, 3], D[:, 1, 4] = sw, -cw, cw, sw
        D[:, 2, 5] = tau
        D[:, 0, 6], D[:, 1, 6] = dsw * vx - dcw * vy, dcw * vx + dsw * vy
        rows, res = [], []
        for i, ((_, camera, u, v), X, Y, Z) in enumerate(
                zip(window, px.tolist(), py.tolist(), pz.tolist(), strict=True)):
            ok, pu, pv, *h = F._project(flt._cam_table, camera, X, Y, Z)
            if not ok:
                return None, None
            rows.append(np.array([h[:3], h[3:]]) @ D[i])
            res.append(u - pu)
            res.append(v - pv)
        return np.vstack(rows), np.array(res)

    for _ in range(4):
        J, r = system(th)
        if J is None:
            return None
        th = th + np.linalg.lstsq(np.vstack([J, row]), np.append(r, -prior * (th[6] - mean)),
                                  rcond=None)[0]
    J, r = system(th)
    if J is None:
        return None
    residuals = np.hypot(r[0::2], r[1::2])
    start_var = flt._start_var()
    if not (np.all(residuals ** 2 <= flt._gate * start_var)
            and float(r @ r) <= F._chi2_quantile(len(r) - 7) * start_var):
        return None
    info = J.T @ J
    info[6, 6] += prior * prior
    try:
        cov = var * np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return None
    if (not np.all(np.isfinite(cov)) or np.linalg.cond(info) > 1e14
            or np.trace(cov[:3, :3]) > flt.options.max_init_std_m ** 2
            or np.trace(cov[3:6, 3:6]) > flt.options.max_init_speed_std ** 2):
        return None
    cov = 0.5 * (cov + cov.T)
    return [float(a) for a in th], [float(a) for a in cov.ravel()], residuals


def _windows(rig, motion, seconds, noise):
    """Every (filter, window, ballistic) the filter fits on a session (misses included)."""
    seen = []
    fit, turn_fit = BallFilter._fit, BallFilter._turn_fit

    def record(self, window, ballistic=True):
        seen.append((self, list(window), ballistic))
        return fit(self, window, ballistic)

    def record_turn(self, window, theta, var, prior=None):
        seen.append((self, list(window), (list(theta), var, prior)))
        return turn_fit(self, window, theta, var, prior)

    detections, _ = simulate(rig, motion, seconds, SimulationOptions(
        noise_px=noise, seed=7, miss_rate=0.1))
    obs = detections.best()
    flt = BallFilter(rig)
    BallFilter._fit, BallFilter._turn_fit = record, record_turn
    try:
        for t, c, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(),
                                obs.uv.tolist(), strict=True):
            flt.push(t, c, u, v)
    finally:
        BallFilter._fit, BallFilter._turn_fit = fit, turn_fit
    return seen


def _same(a, b) -> bool:
    """The same fit: bit for bit where this machine's BLAS sums unfused (numpy's lstsq and
    products in the reference; tests/_bits.py), else to rounding (1e-8 relative)."""
    if isinstance(a, tuple) or isinstance(b, tuple):
        if not (isinstance(a, tuple) and isinstance(b, tuple)):
            return False
        if blas_is_plain():
            return a[0] == b[0] and a[1] == b[1] and np.array_equal(a[2], b[2])
        return all(np.allclose(np.asarray(x), np.asarray(y), rtol=1e-8,
                               atol=1e-12 * max(float(np.max(np.abs(y), initial=0.0)), 1e-300))
                   for x, y in zip(a, b, strict=True))
    return a == b


@pytest.mark.parametrize(("rig", "motion"), [
    (apply_timing(builtin_rig("paper3"), "typeA"), "rally"),
    (lab_rig(3), "turntable"),
    (lab_rig(3, fps=240.0), "straight"),
    (lab_rig(2, fps=60.0), "rally"),
])
def test_compiled_window_fit_is_the_numpy_fit_bit_for_bit(rig, motion):
    m = rally(3.0, seed=3)[0] if motion == "rally" else get_motion(motion)
    seen = _windows(rig, m, 3.0, 0.3) + _windows(rig, m, 1.0, 1.0)
    kinds = {"fit": 0, "None": 0, "short": 0, "weak": 0, "turn": 0}
    for flt, window, how in seen:
        if isinstance(how, tuple):  # the turn model's fit from the supported one
            new = flt._turn_fit(window, *how)
            assert _same(new, _numpy_turn_fit(flt, window, *how)), (window, how)
            kinds["turn"] += isinstance(new, tuple)
            continue
        new = flt._fit(window, how)
        assert _same(new, _numpy_fit(flt, window, how)), (window, how)
        kinds["fit" if isinstance(new, tuple) else str(new)] += 1
    # the comparison covers the fits that pass and, on the kicked rallies, ones that fail
    assert kinds["fit"] >= 2 and kinds["turn"] >= 1, kinds
    assert motion != "rally" or kinds["None"] + kinds["short"] + kinds["weak"] >= 1, kinds


def test_window_fit_kernel_equals_its_python_form():
    rig = lab_rig(3)
    seen = _windows(rig, get_motion("turntable"), 2.0, 0.3)
    assert seen
    for flt, window, ballistic in [s for s in seen if not isinstance(s[2], tuple)][:12]:
        n = len(window)
        t_ref = window[-1][0]
        rays = [flt._ray(*w) for w in window]
        args = (flt._cam_table, np.array([w[1] for w in window], dtype=np.int64),
                np.array([w[2:] for w in window]),
                np.array([(w[0] - t_ref) / NS for w in window]),
                np.array([o for o, _ in rays]), np.array([d for _, d in rays]),
                flt._g_array if ballistic else F._ZERO3,
                flt._k if ballistic else 0.0, 0.09, flt._gate,
                F._chi2_quantile(2 * n - 6), 0.05 ** 2, 1.0)
        outs = []
        for fn in (F._window_fit, F._window_fit.py_func):
            theta, cov, res = np.empty(6), np.empty((6, 6)), np.empty(n)
            outs.append((fn(*args, theta, cov, res), theta, cov, res))
        (s0, t0, c0, r0), (s1, t1, c1, r1) = outs
        assert s0 == s1
        assert np.array_equal(t0, t1) and np.array_equal(r0, r1)
        if s0 == F._WFIT_OK:
            assert np.array_equal(c0, c1)
            assert math.isclose(c0[0, 1], c0[1, 0])
