"""``filter``: a plain update's published covariance holds the doubt its NIS casts on "no
jump" (issue 10, session 29; docs/methods.md "A plain update's doubt").

The point of a plain (no jump) accepted update publishes, along its camera's ray, the mean
square error about the no-jump mean of the mixture of "no jump" and "a jump of each shape in
the step before this detection", weighted by the detection's likelihood under each and the
prior ``1 − exp(−λ_j Δt)``: ``Σ_s w_s (P_s⁺ − P₀⁺ + d_s d_sᵀ)``. Checked by hand (each
hypothesis's Kalman update in numpy, the full matrices, its Jacobian by central differences)
and on a flight kicked along a camera's ray, streamed.
"""

from __future__ import annotations

import math

import numpy as np
from test_filter import lab_rig
from test_filter_jump_instant import _jacobian, kicked

from pslog.fusion import filter as FM
from pslog.fusion.filter import BallFilter, FilterOptions
from pslog.simulation import SimulationOptions, simulate, true_rig
from pslog.timing import observations as corrected_observations


def _by_hand(rig, O, cam, x, P, uv, var, dt):
    """The term's variance along the ray, all in numpy: (r̂ᵀ (P* − P₀⁺) r̂, r̂, w's sum)."""
    c = rig.cameras[cam]
    H = np.hstack([_jacobian(c, x[:3]), np.zeros((2, 3))])
    y = uv - c.project(x[:3][None])[0][0]
    lam = O[FM._OSURPRISE]
    prior = 1.0 - math.exp(-lam * dt)
    ns = int(O[FM._ONSHAPES])

    def update(xm, Pm, ym):
        Sm = H @ Pm @ H.T + var * np.eye(2)
        K = Pm @ H.T @ np.linalg.inv(Sm)
        like = math.exp(-0.5 * ym @ np.linalg.solve(Sm, ym)) / (2 * math.pi
                                                                  * math.sqrt(np.linalg.det(Sm)))
        return xm + K @ ym, Pm - K @ H @ Pm, like

    x0, P0, like0 = update(x, P, y)
    hyps = [((1.0 - prior) * like0, x0, P0)]
    for shape in range(ns):
        base = FM._OSHAPES + 4 * shape
        sig = np.diag(O[base + 1:base + 4])
        mu = np.zeros(3)
        if O[base] != 0.0:
            down = O[FM._ODOWN:FM._ODOWN + 3]
            vd = x[3:] @ down
            if not vd > 0:
                continue
            floor = O[FM._OFLOOR]  # a known floor: only within its reach (session 36)
            h = -(x[:3] @ down) - floor
            if floor == floor and h > 0 and h * h > O[FM._OGATE] * (down @ P[:3, :3] @ down):
                continue
            mu = -(1 + O[FM._OREST]) * vd * down - O[FM._OFRIC] * (x[3:] - vd * down)
        xs = x + np.concatenate([mu * dt / 2, mu])
        Ps = P.copy()
        Ps[:3, :3] += sig * dt * dt / 3 + np.outer(mu, mu) * dt * dt / 12
        Ps[:3, 3:] += sig * dt / 2
        Ps[3:, :3] += sig * dt / 2
        Ps[3:, 3:] += sig
        xu, Pu, like = update(xs, Ps, y - H @ (xs - x))
        hyps.append((prior / ns * like, xu, Pu))
    w = np.array([h[0] for h in hyps])
    w /= w.sum()
    Pstar = sum(wk * (Pk + np.outer(xk - x0, xk - x0)) for wk, (_, xk, Pk) in zip(w, hyps,
                                                                               strict=True))
    r = x0[:3] - c.center_world
    r /= np.linalg.norm(r)
    return r @ (Pstar - P0)[:3, :3] @ r, r, 1.0 - w[0]


def test_the_plain_updates_doubt_by_hand():
    rig = lab_rig(3)
    # the floor unknown: falling, the floor bounce is tried too; the default floor: 1 m
    # above it, out of its reach, not (session 36)
    for options in (FilterOptions(floor_m=None), FilterOptions()):
        _the_plain_updates_doubt_by_hand(rig, options)


def _the_plain_updates_doubt_by_hand(rig, options):
    flt = BallFilter(rig, options)
    O, cams = flt._opts, flt._cam_table
    x = np.array([1.2, 0.8, 1.0, 2.0, -1.0, -1.5])
    P = np.diag([4e-6] * 3 + [4e-3] * 3)
    P[0, 3] = P[3, 0] = 1e-5
    var, dt, cam = 0.3 ** 2, 0.011, 1
    p = rig.cameras[cam].project(x[:3][None])[0][0]
    seen = []
    for shift in (0.0, 0.6, 1.2, 2.5):  # the pixel off the prediction: NIS 0 … ~60
        uv = p + np.array([shift, -0.5 * shift])
        ok, inn = FM._innovation(cams, cam, x, P.ravel(), 6, uv[0], uv[1], var)
        assert ok
        xn, _ = FM._updated(x, P.ravel(), inn)
        vx, vy, vz = FM._surprise_term(cams, O, cam, x, P.ravel(), inn, dt, var, xn[0], xn[1],
                                       xn[2], 0.0, 0.0, 0.0)
        hand, r, w = _by_hand(rig, O, cam, x, P, uv, var, dt)
        np.testing.assert_allclose([vx, vy, vz], hand * r * r, rtol=2e-4, atol=1e-13)
        seen.append((inn[5], hand, w))
    nis, term, w = np.array(seen).T
    # the doubt grows with the NIS: a jump's posterior weight and the variance it publishes
    assert np.all(np.diff(nis) > 0) and np.all(np.diff(w) > 0) and np.all(np.diff(term) > 0)
    assert term[0] < 1e-6 < term[-1]  # nothing to speak of at NIS 0, millimetres at ~60
    # no step, no jump in it: nothing
    ok, inn = FM._innovation(cams, cam, x, P.ravel(), 6, p[0] + 2.5, p[1], var)
    assert FM._surprise_term(cams, O, cam, x, P.ravel(), inn, 0.0, var, *x[:3], 1.0, 2.0,
                             3.0) == (1.0, 2.0, 3.0)


def test_a_flight_kicked_along_a_ray_keeps_its_points_and_widens_its_covariance():
    # a kick mostly towards camera 2 mid-air (8 m/s along its ray, 1 m/s across), 10.7 ms
    # before its next detection: that pixel moves by a few tenths of a pixel more than the
    # noise, the update is plain with a large NIS; positions the same with the term off,
    # std_m larger or equal everywhere, larger only at plain updates, and the published
    # matrix's diagonal the published variances
    rig = lab_rig(3)
    options = SimulationOptions(noise_px=0.3, seed=0)
    at = 0.5115
    p_kick = kicked([0.0, 0.0, 0.0], at).position(np.array([at]))[0]
    toward = rig.cameras[2].center_world - p_kick
    toward /= np.linalg.norm(toward)
    side = np.cross(toward, [0.0, 0.0, 1.0])
    motion = kicked(8.0 * toward + side / np.linalg.norm(side), at)
    detections, _ = simulate(rig, motion, None, options)
    obs = corrected_observations(detections, true_rig(rig, options))
    runs = {}
    for cov in (False, True):
        flt = BallFilter(rig, FilterOptions(withhold=False, surprise_cov=cov))
        rows = []
        for i in range(len(obs.time_ns)):
            t, c = int(obs.time_ns[i]), int(obs.camera[i])
            out = flt.push(t, c, float(obs.uv[i, 0]), float(obs.uv[i, 1]))
            if out is None:
                continue
            pos, q = out
            std = np.array(q[1:4])
            if cov:
                m = np.array(flt.point_covariance(t, c, pos, std, bool(q[9])))
                np.testing.assert_array_equal(np.diag(m), std * std)
            rows.append((t, *pos, *std, q[8], q[9], q[10], q[6], c))
        runs[cov] = np.array(rows)
    a, b = runs[False], runs[True]
    np.testing.assert_array_equal(a[:, :4], b[:, :4])
    plain = (a[:, 7] == 0) & (a[:, 8] == 0) & (a[:, 9] == 0)
    va, vb = (a[:, 4:7] ** 2).sum(1), (b[:, 4:7] ** 2).sum(1)
    assert np.all(vb >= va) and np.all(vb[~plain] == va[~plain])
    # the first point after the kick: camera 2's plain update at NIS > 9.21, 8.7 cm off
    # (48 σ); the doubt on "no jump" widens it three times (a jump's posterior weight is a
    # few per cent: still 16 σ, not withheld by its std_m)
    truth = motion.position(a[:, 0] / 1e9)
    err = np.linalg.norm(a[:, 1:4] - truth, axis=1)
    first = np.flatnonzero(a[:, 0] / 1e9 > at)[0]
    assert a[first, 11] == 2 and plain[first] and a[first, 10] > 9.21
    assert err[first] > 0.05 and err[first] > 30 * math.sqrt(va[first])
    assert vb[first] > 6 * va[first]
    # the points before the kick, at NIS mostly in χ²₂'s bulk: hardly a change
    before = (a[:, 0] / 1e9 < at) & plain
    assert np.median(vb[before] / va[before]) < 1.05
