"""A test-only rally: a ball kicked around a room, with air drag, floor bounces and kicks.

A stand-in for the ``rally`` motion that another branch adds to ``pslog.motion``: the tests
and benchmark of ``smooth`` build their own rallies, so nothing is tuned to the library's.
Integrated with RK4 at 0.2 ms, each bounce stepped to its exact instant, and interpolated by
cubic Hermite between samples with the velocity's one-sided limits (error well below 1 µm).
"""

from __future__ import annotations

import math

import numpy as np

from pslog.motion import BALL_RADIUS, G, Motion


def rally(duration: float, seed: int = 0, drag_per_m: float = 0.015,
          restitution: float = 0.75, kick_every_s: float = 1.1, speed: float = 7.0,
          center=(1.5, 1.0), floor: float = BALL_RADIUS) -> tuple[Motion, np.ndarray]:
    """The motion over ``[0, duration]`` and the times (s) of its velocity jumps.

    A test process integrates each rally once: parametrised tests (and test files) ask for
    the same rally many times; the samples behind the motion and the jump times are
    read-only, so no test can change another's rally. Rallies longer than a minute (tens of
    MB of samples, asked for once) are not kept, nor more than the last eight."""
    key = (float(duration), seed, drag_per_m, restitution, kick_every_s, speed,
           tuple(center), floor)
    if key in _KEPT:
        return _KEPT[key]
    made = _integrate(*key)
    if duration <= 60.0:
        if len(_KEPT) >= _KEEP:  # the oldest goes (a loop over many seeds asks for each once)
            del _KEPT[next(iter(_KEPT))]
        _KEPT[key] = made
    return made



def dirty_rally(seed: int, duration: float = 8.0) -> tuple[Motion, np.ndarray]:
    """``benchmarks/bench_dirty.py``'s rally of ``seed`` (``--more``'s sessions, the ones its
    held-out runs name ``rally-<seed>``): a kick every 0.9 s at ``4 + seed % 3`` m/s. The
    tests that take one of those sessions make it here, so they make the same one."""
    return rally(duration, seed=seed, speed=4.0 + seed % 3, kick_every_s=0.9)


_KEEP = 8
_KEPT: dict[tuple, tuple[Motion, np.ndarray]] = {}


def _integrate(duration: float, seed: int, drag_per_m: float, restitution: float,
               kick_every_s: float, speed: float, center: tuple, floor: float
               ) -> tuple[Motion, np.ndarray]:
    rng = np.random.default_rng(seed)
    dt = 2e-4

    g = float(G)
    sqrt = math.sqrt

    def step(p, v, h):
        """One RK4 step of (position, velocity) over ``h`` s; plain floats (3-tuples), each
        component written out: a step is ~20 three-vectors, which numpy's per-call cost (and
        then Python's generators) made the tests' slowest part. The arithmetic is the same,
        operation for operation, as ``a = -k v - g ẑ`` with ``k = drag |v|`` in RK4's
        ``p + h/6 (v + 2 v2 + 2 v3 + v4)``: the trajectories are the same bit for bit."""
        px, py, pz = p
        vx, vy, vz = v
        hh = 0.5 * h
        k = drag_per_m * sqrt(vx * vx + vy * vy + vz * vz)
        a1x, a1y, a1z = -k * vx, -k * vy, -g - k * vz
        v2x, v2y, v2z = vx + hh * a1x, vy + hh * a1y, vz + hh * a1z
        k = drag_per_m * sqrt(v2x * v2x + v2y * v2y + v2z * v2z)
        a2x, a2y, a2z = -k * v2x, -k * v2y, -g - k * v2z
        v3x, v3y, v3z = vx + hh * a2x, vy + hh * a2y, vz + hh * a2z
        k = drag_per_m * sqrt(v3x * v3x + v3y * v3y + v3z * v3z)
        a3x, a3y, a3z = -k * v3x, -k * v3y, -g - k * v3z
        v4x, v4y, v4z = vx + h * a3x, vy + h * a3y, vz + h * a3z
        k = drag_per_m * sqrt(v4x * v4x + v4y * v4y + v4z * v4z)
        a4x, a4y, a4z = -k * v4x, -k * v4y, -g - k * v4z
        h6 = h / 6
        p_new = (px + h6 * (vx + 2 * v2x + 2 * v3x + v4x),
                 py + h6 * (vy + 2 * v2y + 2 * v3y + v4y),
                 pz + h6 * (vz + 2 * v2z + 2 * v3z + v4z))
        v_new = (vx + h6 * (a1x + 2 * a2x + 2 * a3x + a4x),
                 vy + h6 * (a1y + 2 * a2y + 2 * a3y + a4y),
                 vz + h6 * (a1z + 2 * a2z + 2 * a3z + a4z))
        return p_new, v_new

    t, p = 0.0, (center[0] - 1.0, center[1], 1.0)
    v = (speed * 0.6, 0.3, 3.0)
    times, pos, v_right, v_left = [t], [p], [v], [v]
    next_kick = kick_every_s * (0.6 + 0.8 * rng.random())
    events = []
    while t < duration + dt:
        h = min(dt, next_kick - t) if next_kick > t else dt
        p_new, v_new = step(p, v, h)
        if p_new[2] < floor:  # shorten the step to the impact (secant on z), then bounce
            lo, hi = 0.0, h
            for _ in range(40):
                mid = (lo + hi) / 2
                if step(p, v, mid)[0][2] < floor:
                    hi = mid
                else:
                    lo = mid
            h = (lo + hi) / 2
            p_new, v_new = step(p, v, h)
            t += h
            after = (0.9 * v_new[0], 0.9 * v_new[1], -restitution * v_new[2])
            if after[2] < 1.0:  # too low a bounce to see: kick it up again
                after = (after[0], after[1], 3.0 + 2 * rng.random())
            events.append(t)
            next_kick = max(next_kick, t + 0.08)  # nobody kicks a ball as it bounces
        else:
            t += h
            after = v_new
            if abs(t - next_kick) < 1e-12:  # a kick towards the room's centre, upwards
                angle = math.atan2(center[1] - p_new[1], center[0] - p_new[0]) + rng.normal(
                    0, 0.6)
                horizontal = speed * (0.5 + 0.5 * rng.random())
                after = (horizontal * math.cos(angle), horizontal * math.sin(angle),
                         2.0 + 3.0 * rng.random())
                next_kick = t + kick_every_s * (0.6 + 0.8 * rng.random())
                events.append(t)
        p, v = p_new, after
        times.append(t)
        pos.append(p)
        v_left.append(v_new)
        v_right.append(after)
    times, pos = np.array(times), np.array(pos)
    v_left, v_right = np.array(v_left), np.array(v_right)
    events = np.array(events)
    for kept in (times, pos, v_left, v_right, events):
        kept.setflags(write=False)

    def position(when: np.ndarray) -> np.ndarray:
        when = np.asarray(when, dtype=np.float64)
        i = np.clip(np.searchsorted(times, when, side="right") - 1, 0, len(times) - 2)
        h = (times[i + 1] - times[i])[:, None]
        s = (when[:, None] - times[i][:, None]) / h
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        return (h00 * pos[i] + h10 * h * v_right[i] + h01 * pos[i + 1]
                + h11 * h * v_left[i + 1])

    return Motion("rally", duration, position, "test rally"), events
