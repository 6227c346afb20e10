"""The filter's velocity-jump hypotheses by hand (docs/methods.md, "Gating, jumps"): a jump
``Δv ~ N(μ, Σ_j)`` at an instant uniform over the step, ``Δp = Δv s``, so after the step's
prediction

    v += μ,   p += μ Δt/2,
    P_pp += Σ_j Δt²/3 + μ μᵀ Δt²/12,   P_pv += Σ_j Δt/2,   P_vv += Σ_j

(``E[s] = Δt/2``, ``E[s²] = Δt²/3``, ``Var s = Δt²/12``), with the three shapes: a floor
bounce ``μ = −(1 + e) v_d ĝ − f (v − v_d ĝ)`` (``e`` 0.7, ``f`` 0.1) and ``Σ_j = diag(0.6²,
0.6², 1.0²)``, only while falling; a jump mostly along gravity ``Σ_j = σ_j² (0.05 I + 0.95
W)``; a kick ``Σ_j = σ_j² I`` (``σ_j`` 6 m/s). The moments are also checked against sampling
the jump itself."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from pslog.fusion import filter as F
from pslog.rig import builtin_rig

DT = 0.02
P0 = np.diag([1e-6, 2e-6, 3e-6, 0.01, 0.02, 0.03]) + 1e-7
X0 = np.array([1.0, 0.5, 1.2, 2.0, -1.0, -3.0])  # falling at 3 m/s


def _shapes(**options):
    # the floor unknown: the floor bounce tried wherever the ball falls (a known floor,
    # session 36: only within its reach, tests/test_filter_floor.py; X0 is 1.2 m above it)
    flt = F.BallFilter(builtin_rig("paper3"), F.FilterOptions(**{"floor_m": None, **options}))
    O = flt._opts
    assert int(O[F._ONSHAPES]) == 3
    return O


def _by_hand(mu, sigma2):
    x = X0.copy()
    x[3:] += mu
    x[:3] += mu * DT / 2
    S = np.diag(sigma2)
    P = P0.copy()
    P[:3, :3] += S * DT**2 / 3 + np.outer(mu, mu) * DT**2 / 12
    P[:3, 3:] += S * DT / 2
    P[3:, :3] += S * DT / 2
    P[3:, 3:] += S
    return x, P


def test_a_floor_bounce_a_jump_along_gravity_and_a_kick_by_hand():
    O = _shapes()
    # floor bounce: v_d = v · (0, 0, -1) = 3; μ = 1.7 · 3 (0, 0, 1) - 0.1 (2, -1, 0)
    mu = np.array([-0.2, 0.1, 5.1])
    cases = [(0, mu, [0.36, 0.36, 1.0]),
             (1, np.zeros(3), [36 * 0.05, 36 * 0.05, 36.0]),
             (2, np.zeros(3), [36.0, 36.0, 36.0])]
    for shape, mean, var in cases:
        ok, x, P = F._jumped(X0, P0.ravel(), DT, O, shape)
        assert ok
        x_hand, P_hand = _by_hand(mean, np.array(var))
        assert_allclose(x, x_hand, rtol=0, atol=1e-15)
        assert_allclose(np.asarray(P).reshape(6, 6), P_hand, rtol=1e-14, atol=1e-18)
    # the bounce leaves the ball rising at 0.7 of its fall, 10 % slower across
    assert_allclose((X0[3:] + mu), [1.8, -0.9, 2.1], atol=1e-15)
    # no floor bounce of a rising ball
    rising = X0 * [1, 1, 1, 1, 1, -1]
    assert not F._jumped(rising, P0.ravel(), DT, O, 0)[0]
    # nor, the floor known (the default), of a ball 1.2 m above it; the other shapes as above
    O = _shapes(floor_m=F.FilterOptions().floor_m)
    assert not F._jumped(X0, P0.ravel(), DT, O, 0)[0]
    assert F._jumped(X0, P0.ravel(), DT, O, 1)[0] and F._jumped(X0, P0.ravel(), DT, O, 2)[0]


@pytest.mark.parametrize("shape", [0, 2])
def test_the_moments_are_those_of_the_sampled_jump(shape):
    O = _shapes()
    ok, x, P = F._jumped(X0, np.zeros(36), DT, O, shape)
    rng = np.random.default_rng(shape)
    n = 400_000
    mean = x[3:] - X0[3:]
    dv = mean + rng.normal(size=(n, 3)) * np.sqrt(np.diag(np.asarray(P).reshape(6, 6))[3:])
    s = rng.uniform(0.0, DT, n)
    sample = np.hstack([dv * s[:, None], dv])
    cov = np.cov(sample.T)
    P = np.asarray(P).reshape(6, 6)
    assert ok and np.all(np.diag(P) > 0)
    standard_error = np.sqrt(np.diag(P)[:3] / n)
    assert np.all(np.abs(sample.mean(axis=0)[:3] - (x[:3] - X0[:3])) < 5 * standard_error)
    scale = np.sqrt(np.outer(np.diag(P), np.diag(P)))  # each entry against its variances
    assert np.all(np.abs(cov - P) <= 0.02 * scale), np.abs(cov - P) / scale
