"""``filter``: an accepted jump's covariance is the mean square error about the winning
hypothesis of the mixture of every (lag, shape) hypothesis that passed (issue 10, session 27;
docs/methods.md "A jump's hypotheses").

The jump search keeps the likeliest (lag, shape) replay; a narrow shape (a floor bounce, mostly
along gravity) can win a kick's first pixel, which fixes only the two directions across its
ray, and its covariance then states the narrow shape's spread for a kick's. The state takes
the winner's mean ``x*`` with ``P* = Σ w_k (P_k + (x_k − x*)(x_k − x*)ᵀ)``, ``w_k ∝
exp(−score_k/2)``. Checked by hand (each hypothesis replayed with the filter's own
``_replay``, the mixture in numpy) on a kicked flight, and the replay behind the published
instant term takes that covariance at the jump's detection.
"""

from __future__ import annotations

import numpy as np
from test_filter import lab_rig
from test_filter_jump_instant import _jacobian, kicked

from pslog.fusion import filter as FM
from pslog.fusion.filter import BallFilter, FilterOptions
from pslog.simulation import SimulationOptions, simulate, true_rig
from pslog.timing import observations as corrected_observations


def _jumps_by_hand(kick, at, seed=0, ncam=3):
    """Push a kicked flight; at each accepted jump the state's covariance against the hand
    mixture of the hypotheses replayed from the state before the push."""
    rig = lab_rig(ncam)
    options = SimulationOptions(noise_px=0.3, seed=seed)
    detections, _ = simulate(rig, kicked(kick, at), None, options)
    obs = corrected_observations(detections, true_rig(rig, options))
    flt = BallFilter(rig, FilterOptions(withhold=False))
    found = []
    for i in range(len(obs.time_ns)):
        S0, I0 = flt._S.copy(), flt._I.copy()
        t, c = int(obs.time_ns[i]), int(obs.camera[i])
        u, v = float(obs.uv[i, 0]), float(obs.uv[i, 1])
        out = flt.push(t, c, u, v)
        if out is None or not out[1][8]:
            continue
        hyps = []
        for lag in range(min(int(I0[FM._IHN]), FM._JUMP_LAG) + 1):
            for shape in range(int(flt._opts[FM._ONSHAPES])):
                passed, x, P, _, score, _, _, _ = FM._replay(S0.copy(), I0.copy(),
                                                             flt._cam_table, flt._opts, t, c,
                                                             u, v, lag, shape)
                if passed:
                    hyps.append((score, x.copy(), P.reshape(6, 6).copy()))
        best = min(range(len(hyps)), key=lambda k: hyps[k][0])
        xs = hyps[best][1]
        w = np.exp(-0.5 * (np.array([h[0] for h in hyps]) - hyps[best][0]))
        w /= w.sum()
        hand = sum(wk * (P + np.outer(x - xs, x - xs))
                   for wk, (_, x, P) in zip(w, hyps, strict=True))
        found.append((hyps, best, xs, hand, flt._S[FM._SX:FM._SX + 6].copy(),
                      flt._S[FM._SP:FM._SP + 36].reshape(6, 6).copy()))
    return found


def test_a_jumps_covariance_is_its_hypotheses_mixture_about_the_winner():
    # a kick mostly across gravity, mid-air, 0.5 s in: several hypotheses pass at the jump
    found = _jumps_by_hand([-8.0, 2.0, 4.0], 0.515)
    assert found
    several = 0
    for hyps, best, xs, hand, x, P in found:
        np.testing.assert_array_equal(x, xs)  # the winner's mean, as before
        np.testing.assert_allclose(P, hand, rtol=1e-9, atol=1e-15)
        if len(hyps) > 1:
            several += 1
            # not the winner's own covariance
            assert not np.allclose(P, hyps[best][2], rtol=1e-3, atol=0)
    assert several


def test_a_kick_taken_as_a_bounce_states_the_kicks_spread():
    # a kick along gravity and little across it, falling: a bounce-shaped hypothesis wins
    # its first pixel; the state's position covariance now holds the kick's hypotheses
    found = _jumps_by_hand([0.5, -0.8, 7.0], 0.52, seed=3)
    narrow = [f for f in found if len(f[0]) > 1 and f[1] != len(f[0]) - 1]
    assert narrow, [len(f[0]) for f in found]
    for hyps, best, _xs, hand, _x, P in narrow:
        np.testing.assert_allclose(P, hand, rtol=1e-9, atol=1e-15)
        assert np.trace(P[:3, :3]) > 1.05 * np.trace(hyps[best][2][:3, :3])


def test_the_instant_terms_replay_takes_the_jumps_mixture_covariance():
    # the replay of the published term (_instant_term) carries, after the jump's detection,
    # the covariance the state took (the mixture's), not the winner's: its gains are the
    # filter's own. By hand over two detections (the jump's, then another camera's).
    rig = lab_rig(3)
    t0 = 1_000_000_000
    x0 = np.array([1.2, 0.8, 1.0, 2.0, -1.0, 1.5])
    P0 = np.diag([1e-5] * 3 + [4e-3] * 3).ravel()
    Pm = np.diag([4e-4] * 3 + [9.0] * 3).ravel()
    times = [t0 + 11_000_000, t0 + 22_000_000]
    kick = np.array([3.0, 4.0, -2.0])
    cq = (0.5, 1.0, 0.3 ** 2)
    res = {}
    for mix in (True, False):
        flt = BallFilter(rig, FilterOptions(jump_mixture_cov=mix))
        S, I, cams, O = flt._S, flt._I, flt._cam_table, flt._opts
        S[FM._SJX:FM._SJX + 6], S[FM._SJP:FM._SJP + 36] = x0, P0
        I[FM._IJT0], I[FM._IJSHAPE], I[FM._IJLAG] = t0, 2, 0
        S[FM._SJPM:FM._SJPM + 36] = Pm
        for k, (t, c) in enumerate(zip(times, (0, 1), strict=True)):
            s = (t - t0) / 1e9
            p = x0[:3] + x0[3:] * s + kick * (s - 0.004)
            I[FM._IJBUF + 2 * k], I[FM._IJBUF + 2 * k + 1] = t, c
            S[FM._SJUV + 2 * k:FM._SJUV + 2 * k + 2] = rig.cameras[c].project(p[None])[0][0]
            S[FM._SJF + 3 * k:FM._SJF + 3 * k + 3] = cq
        I[FM._IJN] = 2
        x_now = np.concatenate([x0[:3], x0[3:] + kick])
        ok, ep, _ = FM._instant_term(S, I, cams, O, times[1], x_now)
        assert ok
        xb = x0
        for t, tb in zip(times, (t0, times[0]), strict=True):
            xb, _ = FM._predicted(xb, P0, (t - tb) / 1e9, cq[0], O, 0.0)
        eps = np.concatenate([x_now[3:] - xb[3:], np.zeros(3)])
        x, P, tp = x0.copy(), P0.copy(), t0
        for k, c in enumerate((0, 1)):
            dt = (times[k] - tp) / 1e9
            x, P = FM._predicted(x, P, dt, cq[0], O, cq[1])
            if k == 0:
                _, x, P = FM._jumped(x, P, dt, O, 2)
            else:
                eps = np.concatenate([eps[:3] + dt * eps[3:], eps[3:]])
            Pk = P.reshape(6, 6)
            H = np.hstack([_jacobian(rig.cameras[c], x[:3]), np.zeros((2, 3))])
            K = Pk @ H.T @ np.linalg.inv(H @ Pk @ H.T + cq[2] * np.eye(2))
            eps = (np.eye(6) - K @ H) @ eps
            uv = S[FM._SJUV + 2 * k:FM._SJUV + 2 * k + 2]
            _, inn = FM._innovation(cams, c, x, P, 6, uv[0], uv[1], cq[2])
            x, P = FM._updated(x, P, inn)
            if k == 0 and mix:
                P = Pm.copy()
            tp = times[k]
        np.testing.assert_allclose(ep, eps[:3], rtol=2e-5, atol=1e-9)
        res[mix] = ep
    # the mixture's much wider velocity covariance: the second camera's gain takes more of ε
    assert not np.allclose(res[True], res[False], rtol=1e-2)
