"""``filter``: the published covariance of an accepted jump's unknown instant (issue 10,
session 25; docs/methods.md "A jump's instant").

A jump ``Δv`` at an instant ``s`` uniform over its step of ``Δt_j`` moves the ball by ``Δv s``;
the filter takes ``E[s] = Δt_j/2`` with the jump's prior (zero mean for a kick), which drops
the term ``m (s − Δt_j/2)`` of the jump ``m`` it then estimates. The points after the jump
publish that term's effect through the filter's gains, ``w ε_p ε_pᵀ`` with ``w = Δt_j²/12``,
``ε = (m, 0)`` on the jump's step, ``ε ← F ε`` at each prediction and ``(I − K H) ε`` at each
update. Checked by hand (numpy, the Jacobian by finite differences of the camera's own
projection), and on a kicked flight: the state and the points are the same, only the
published standard deviations grow, and only after the kick.
"""

from __future__ import annotations

import numpy as np
from test_filter import lab_rig

from pslog import NS, Motion
from pslog.evaluation import errors_m
from pslog.fusion import filter as FM
from pslog.fusion.filter import BallFilter, FilterOptions, fuse_filter
from pslog.motion import G
from pslog.simulation import SimulationOptions, simulate, true_rig
from pslog.timing import observations as corrected_observations


def _jacobian(camera, p):
    """``∂(u, v)/∂p`` of the camera's projection, central differences."""
    J = np.empty((2, 3))
    for k in range(3):
        d = np.zeros(3)
        d[k] = 1e-6
        J[:, k] = (camera.project((p + d)[None])[0][0] - camera.project((p - d)[None])[0][0]) / 2e-6
    return J


def test_the_instant_term_by_hand():
    rig = lab_rig(3)
    # the replay's own covariance after the jump (its mixture's: test_filter_jump_mixture.py)
    flt = BallFilter(rig, FilterOptions(jump_mixture_cov=False))
    S, I, cams, O = flt._S, flt._I, flt._cam_table, flt._opts
    t0 = 1_000_000_000
    x0 = np.array([1.2, 0.8, 1.0, 2.0, -1.0, 1.5])
    P0 = np.diag([1e-5] * 3 + [4e-3] * 3).ravel()
    # the (c, q, σ²) each detection's update used (session 27), not the latest ones
    S[FM._SMU], S[FM._SQ], S[FM._SVAR] = 0.1, 5.0, 1.0 ** 2
    in_force = [(0.9, 0.5, 0.3 ** 2), (0.6, 2.0, 0.4 ** 2), (0.3, 0.1, 0.5 ** 2)]
    S[FM._SJX:FM._SJX + 6], S[FM._SJP:FM._SJP + 36] = x0, P0
    I[FM._IJT0], I[FM._IJSHAPE] = t0, 2  # a kick
    times = [t0 + 11_000_000, t0 + 22_000_000, t0 + 36_000_000]
    kick = np.array([3.0, 4.0, -2.0])
    # the detections: the kicked ball's pixels (a little off: the updates move the state)
    for k, (t, c) in enumerate(zip(times, (0, 1, 2), strict=True)):
        s = (t - t0) / NS
        p = x0[:3] + x0[3:] * s + kick * (s - 0.004)
        uv = rig.cameras[c].project(p[None])[0][0] + [0.4, -0.3]
        I[FM._IJBUF + 2 * k], I[FM._IJBUF + 2 * k + 1] = t, c
        S[FM._SJUV + 2 * k:FM._SJUV + 2 * k + 2] = uv
        S[FM._SJF + 3 * k:FM._SJF + 3 * k + 3] = in_force[k]
    for n in (1, 2, 3):
        I[FM._IJN] = n
        t = times[n - 1]
        x_now = np.concatenate([x0[:3], x0[3:] + kick + [0.1, 0.2, -0.3]])
        ok, ep, w = FM._instant_term(S, I, cams, O, t, x_now)
        assert ok
        # by hand: m the state's velocity against the restart's prediction without the jump
        # (step by step, each with its c)
        xb, tb = x0, t0
        for k in range(n):
            xb, _ = FM._predicted(xb, P0, (times[k] - tb) / NS, in_force[k][0], O, 0.0)
            tb = times[k]
        m = x_now[3:] - xb[3:]
        x, P = x0.copy(), P0.reshape(6, 6).copy()
        tp = t0
        for k in range(n):
            dt = (times[k] - tp) / NS
            ck, qk, vark = in_force[k]
            x, Pf = FM._predicted(x, P.ravel(), dt, ck, O, qk)
            P = Pf.reshape(6, 6)
            if k == 0:
                _, x, Pf = FM._jumped(x, P.ravel(), dt, O, 2)
                P = Pf.reshape(6, 6)
                eps = np.concatenate([m, np.zeros(3)])
                w_hand = dt * dt / 12.0
            else:
                eps = np.concatenate([eps[:3] + dt * eps[3:], eps[3:]])
            c = (0, 1, 2)[k]
            H = np.hstack([_jacobian(rig.cameras[c], x[:3]), np.zeros((2, 3))])
            Sm = H @ P @ H.T + vark * np.eye(2)
            K = P @ H.T @ np.linalg.inv(Sm)
            eps = (np.eye(6) - K @ H) @ eps
            # the state's own update (its mean and covariance) to carry the replay on
            uv = S[FM._SJUV + 2 * k:FM._SJUV + 2 * k + 2]
            _, inn = FM._innovation(cams, c, x, P.ravel(), 6, uv[0], uv[1], vark)
            x, Pf = FM._updated(x, P.ravel(), inn)
            P = Pf.reshape(6, 6)
            tp = times[k]
        assert w == w_hand
        np.testing.assert_allclose(ep, eps[:3], rtol=2e-5, atol=1e-9)
        assert np.linalg.norm(ep) > 0.01 * np.linalg.norm(m)


def kicked(kick, at: float, seconds: float = 0.9) -> Motion:
    """A drag-free flight kicked at ``at`` s by the velocity ``kick``: closed form."""
    p0, v0 = np.array([0.8, 0.6, 0.9]), np.array([2.0, 0.8, 2.5])
    g = np.array([0.0, 0.0, -G])
    pk = p0 + v0 * at + 0.5 * g * at ** 2
    v1 = v0 + g * at + np.asarray(kick, float)

    def position(times: np.ndarray) -> np.ndarray:
        t = np.asarray(times, float)[:, None]
        s = np.maximum(t - at, 0.0)
        before = p0 + v0 * t + 0.5 * g * t * t
        after = pk + v1 * s + 0.5 * g * s * s
        return np.where(t < at, before, after)

    return Motion("kicked", seconds, position, "a flight kicked")


def test_a_kicked_flight_keeps_its_points_and_publishes_the_instant_after_the_kick():
    rig = lab_rig(2)
    at = 0.515  # between two detections: the instant is uncertain over the step
    options = SimulationOptions(noise_px=0.3, seed=0)
    detections, truth = simulate(rig, kicked([-8.0, 2.0, 4.0], at), None, options)
    obs = corrected_observations(detections, true_rig(rig, options))
    # (the jump's covariance its winner's, as when this was written: the mixture's
    # covariance, test_filter_jump_mixture.py, moves the points after the jump)
    old = fuse_filter(obs, rig, options=FilterOptions(withhold=False, jump_instant=False,
                                                      jump_mixture_cov=False))
    new = fuse_filter(obs, rig, options=FilterOptions(withhold=False, jump_mixture_cov=False))
    # the state is the same: every point and every column but the standard deviations
    np.testing.assert_array_equal(new.time_ns, old.time_ns)
    np.testing.assert_array_equal(new.position_world, old.position_world)
    for name in ("innovation_px", "residual_px", "nis", "gap_s", "jump", "rejected", "init"):
        np.testing.assert_array_equal(new.quality[name], old.quality[name])
    t = new.time_ns / NS
    jumps = t[new.quality["jump"] > 0]
    assert len(jumps) == 1 and at < jumps[0] < at + 0.02
    s_old, s_new = old.quality["std_m"], new.quality["std_m"]
    before = t < jumps[0]
    np.testing.assert_array_equal(s_new[before], s_old[before])
    assert np.all(s_new >= s_old)
    grown = np.flatnonzero(s_new > s_old * (1 + 1e-9))
    # at the jump's point (a little: its pixel fixes the position across its ray, and the jump
    # it estimates lies across that ray too) and the points of its next accepted updates
    assert len(grown) >= 3 and t[grown].min() >= jumps[0]
    assert t[grown].max() <= jumps[0] + (FM._JBUF + 0.5) / 30.0
    k = np.flatnonzero(t > jumps[0])[:2]  # the next two points: 55 and 29 mm off
    err = errors_m(new, truth)[k]
    assert s_new[k[0]] > 1.3 * s_old[k[0]]
    # the second: 1.4 σ off before, within 1.1 σ now
    assert err[1] > 1.3 * s_old[k[1]] and err[1] < 1.1 * s_new[k[1]]


def _streamed(rig, motion, options: FilterOptions, before_push=None):
    """Every point of ``motion`` pushed one detection at a time: (time, camera, std_xyz,
    BallFilter.point_covariance, the state's position covariance, the instant's term
    ``w ε_p ε_pᵀ`` the point published or None) per point; ``before_push(flt, time_ns,
    camera)`` runs before each push."""
    sim = SimulationOptions(noise_px=0.3, seed=0)
    detections, _ = simulate(rig, motion, None, sim)
    obs = corrected_observations(detections, true_rig(rig, sim))
    flt = BallFilter(rig, options)
    S, I = flt._S, flt._I
    rows = []
    for t, c, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(),
                            strict=True):
        if before_push is not None:
            before_push(flt, t, c)
        point = flt.push(t, c, u, v)
        if point is None:
            continue
        position, q = point
        std = np.array(q[1:4])
        full = flt.point_covariance(t, c, position, std, q[9] == 1.0)
        term = None
        if int(I[FM._IJTE]) == t and I[FM._IJN] > 0:
            ep, w = S[FM._SJE:FM._SJE + 3], S[FM._SJE + 3]
            term = w * np.outer(ep, ep)
        rows.append((t, c, std, None if full is None else np.array(full),
                     flt.state()[2][:3, :3].copy(), term))
    return rows


def test_the_live_full_covariance_is_the_published_one_after_a_jump():
    """``BallFilter.point_covariance`` (``pslog live``'s ``cov_world``): its diagonal is the
    published variances at every point, and where a jump's instant is published it holds
    the term in full (its correlations too): the matrix less the state's own position
    covariance and the term is what is left of the published variance, the one-camera ray
    term (rank one, along the ray) or nothing, never a negative part (the estimated drag's
    ``V_p V_pᵀ / I_k`` and a plain update's doubt, each a further rank-one part, off; with
    them on, the diagonal is still the published one and what is left still no negative
    part)."""
    motion = kicked([-8.0, 2.0, 4.0], 0.515)
    for extra in (False, True):
        options = (FilterOptions(withhold=False, max_std_m=None) if extra else
                   FilterOptions(withhold=False, max_std_m=None, drag_std_per_m=0.0,
                                 surprise_cov=False))
        terms = 0
        for _t, _c, std, full, P, term in _streamed(lab_rig(2), motion, options):
            assert full is not None
            np.testing.assert_array_equal(np.sqrt(np.diag(full)), std)
            if term is None:
                continue
            terms += 1
            lam = np.linalg.eigvalsh(full - P - term)
            scale = np.trace(term)
            assert lam[0] >= -1e-9 * scale
            assert extra or lam[1] <= 1e-9 * scale
        assert terms >= 3


def test_a_second_detection_at_the_same_time_does_not_reuse_the_first_ones_term():
    """Synchronised cameras (two detections at one time): when the second one's instant
    term cannot be made (its replay fails: forced here by making the jump's restart rise
    for a floor bounce, which :func:`_jumped` refuses), its point publishes none, and the
    live full matrix must not add the first one's (the same time) either."""
    base = lab_rig(3)
    rig = type(base)(tuple(c.replace(offset=0.0) for c in base.cameras), "sync3")
    seen = {}

    def spoil(flt, t, c):
        S, I = flt._S, flt._I
        # the first point after the jump's that published a term, its time's next camera
        if not seen and I[FM._IJN] > 1 and int(I[FM._IJTE]) == t:
            seen["t"], seen["c"] = t, c
            I[FM._IJSHAPE] = 0  # a floor bounce, the restart rising: no replay
            S[FM._SJX + 5] = 5.0

    rows = _streamed(rig, kicked([-8.0, 2.0, 4.0], 0.515),
                     FilterOptions(withhold=False, max_std_m=None), spoil)
    assert seen, "no same-time detection after a published term"
    row = next(r for r in rows if r[0] == seen["t"] and r[1] == seen["c"])
    _t, _c, std, full, P, term = row
    np.testing.assert_array_equal(np.sqrt(np.diag(full)), std)
    np.testing.assert_allclose(full, P, rtol=1e-12, atol=0)
    assert term is None
