"""``filter``: a turning ball's track lost across one camera's blackout restarts with what its
model says of the time since (session 13).

Two cameras, a turntable, one camera blind for 0.5 s: the other alone cannot hold the depth,
the track is lost after ``max_gap_s`` and restarts from a short window when the camera is
back. The lost track had the turn model (ν ≈ 1, ω known to a few hundredths of rad/s); its
turn rate is a random walk and its probability a Markov chain, so the restart's prior is
``ω ~ N(ω_lost, P_ωω + turn_rate_psd Δ)`` and ``ν₀ = ν (1 - p) + (1 - ν) p``, ``p = min(λ_t
Δ, 1/2)`` — not the first start's ``ν₀ = 0.1``, ``ω ~ N(0, 6²)``, which took 0.2-0.3 s to find
the turn again (``bench_dirty.py --more``'s ``paper2`` ``turntable``).
"""

from __future__ import annotations

import math

import numpy as np

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import filter as FM
from pslog.fusion.filter import BallFilter, FilterOptions
from pslog.simulation import true_rig
from pslog.timing import observations as corrected_observations

BLIND = (1.0, 0.5)  # cam1 blind from 1.0 s for 0.5 s


def _run():
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    options = SimulationOptions(noise_px=0.3, seed=5, blackouts=(("cam1", *BLIND),))
    detections, _ = simulate(rig, get_motion("turntable"), None, options)
    obs = corrected_observations(detections, true_rig(rig, options))
    flt = BallFilter(rig)
    lost = restart = None
    points = []
    for t, c, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(), obs.uv.tolist(),
                            strict=True):
        had = bool(flt._I[FM._IHAS])
        before = (flt._nu, flt._xt[6], flt._Pt[48], int(flt._I[FM._ITIME]))
        out = flt.push(t, c, u, v)
        if had and not flt._I[FM._IHAS] and lost is None:
            lost = before
        if lost is not None and restart is None and flt._I[FM._IHAS]:
            restart = (t, flt._nu, flt._xt[6])
        if out is not None:
            points.append((t, out[0]))
    return lost, restart, points


def test_the_restart_after_a_blackout_keeps_the_turn():
    lost, restart, points = _run()
    assert lost is not None and restart is not None
    nu_lost, w_lost, _, _ = lost
    t_restart, nu, w = restart
    assert nu_lost > 0.9 and abs(w_lost) > 2.0  # the lost track was turning
    assert BLIND[0] + BLIND[1] <= t_restart / 1e9 < BLIND[0] + BLIND[1] + 0.1
    # the restart starts the turn model likely, at the lost turn rate (the first start's
    # prior gave ν = 0.59, ω = 3.99 rad/s against 4.72 here)
    assert nu > 0.8
    assert abs(w - w_lost) < 0.3
    # and its points in the 0.25 s after it nearly as good as the track's before the
    # blackout (3.9 against 3.3 mm; with the first start's prior 4.7)
    t = np.array([p[0] for p in points])
    p = np.array([p[1] for p in points])
    after = (t >= t_restart) & (t < t_restart + 0.25e9)
    before = (t > 0.5e9) & (t < BLIND[0] * 1e9)
    err = np.linalg.norm(p - get_motion("turntable").position(t / 1e9), axis=1)
    assert np.mean(err[after]) < 1.3 * np.mean(err[before])


def test_the_carried_prior_by_hand():
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    options = FilterOptions(turn_rate_psd=0.2, turn_switch_per_s=0.8)
    flt = BallFilter(rig, options)
    # a first start: the start's prior
    assert flt._turn_prior(10**9) == (FM._TURN_START, 0.0, options.turn_rate_std ** 2)
    S, I = flt._S, flt._I
    S[FM._SNU], S[FM._SXT + 6], S[FM._SPT + 48] = 0.97, 4.2, 0.003
    I[FM._ITIME] = 2 * 10**9
    dt = 0.45
    nu0, mean, var = flt._turn_prior(2 * 10**9 + int(dt * 1e9))
    p = 0.8 * dt
    assert math.isclose(nu0, 0.97 * (1 - p) + 0.03 * p, rel_tol=1e-12)
    assert mean == 4.2
    assert math.isclose(var, 0.003 + 0.2 * dt, rel_tol=1e-12)
    # once the chain has mixed (p = λ_t Δ >= 1/2: 0.625 s here) the lost track says nothing:
    # a new ball 3 s later starts from the start's prior, not the old ball's turn rate
    # (review: ω stayed N(4.2, 0.6) for minutes)
    assert flt._turn_prior(2 * 10**9 + int(0.6 * 1e9))[1] == 4.2
    assert flt._turn_prior(2 * 10**9 + int(0.63 * 1e9)) == (
        FM._TURN_START, 0.0, options.turn_rate_std ** 2)
    assert flt._turn_prior(2 * 10**9 + 3 * 10**9) == (
        FM._TURN_START, 0.0, options.turn_rate_std ** 2)
    # so long that the random walk is vaguer than the start's prior: the start's
    assert flt._turn_prior(2 * 10**9 + 400 * 10**9) == (
        FM._TURN_START, 0.0, options.turn_rate_std ** 2)
    # no turn model in the lost track's set: the start's prior
    S[FM._SNU] = 0.0
    assert flt._turn_prior(2 * 10**9 + int(dt * 1e9))[0] == FM._TURN_START
