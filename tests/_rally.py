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
    """The motion over ``[0, duration]`` and the times (s) of its velocity jumps."""
    rng = np.random.default_rng(seed)
    dt = 2e-4

    g = float(G)

    def step(p, v, h):
        """One RK4 step of (position, velocity) over ``h`` s; plain floats (3-tuples): a
        step is ~20 three-vectors, which numpy's per-call cost made the tests' slowest part."""
        def accel(vx, vy, vz):
            k = drag_per_m * math.sqrt(vx * vx + vy * vy + vz * vz)
            return -k * vx, -k * vy, -g - k * vz

        vx, vy, vz = v
        a1 = accel(vx, vy, vz)
        v2 = (vx + 0.5 * h * a1[0], vy + 0.5 * h * a1[1], vz + 0.5 * h * a1[2])
        a2 = accel(*v2)
        v3 = (vx + 0.5 * h * a2[0], vy + 0.5 * h * a2[1], vz + 0.5 * h * a2[2])
        a3 = accel(*v3)
        v4 = (vx + h * a3[0], vy + h * a3[1], vz + h * a3[2])
        a4 = accel(*v4)
        p_new = tuple(p[i] + h / 6 * (v[i] + 2 * v2[i] + 2 * v3[i] + v4[i]) for i in range(3))
        v_new = tuple(v[i] + h / 6 * (a1[i] + 2 * a2[i] + 2 * a3[i] + a4[i])
                      for i in range(3))
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

    def position(when: np.ndarray) -> np.ndarray:
        when = np.asarray(when, dtype=np.float64)
        i = np.clip(np.searchsorted(times, when, side="right") - 1, 0, len(times) - 2)
        h = (times[i + 1] - times[i])[:, None]
        s = (when[:, None] - times[i][:, None]) / h
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        return (h00 * pos[i] + h10 * h * v_right[i] + h01 * pos[i + 1]
                + h11 * h * v_left[i + 1])

    return Motion("rally", duration, position, "test rally"), np.array(events)
