"""A test-only rally: a ball kicked around a room, with air drag, floor bounces and kicks.

A stand-in for the ``rally`` motion that another branch adds to ``pslog.motion``: the tests
and benchmark of ``smooth`` build their own rallies, so nothing is tuned to the library's.
Integrated with RK4 at 0.2 ms, each bounce stepped to its exact instant, and interpolated by
cubic Hermite between samples with the velocity's one-sided limits (error well below 1 µm).
"""

from __future__ import annotations

import numpy as np

from pslog.motion import BALL_RADIUS, G, Motion


def rally(duration: float, seed: int = 0, drag_per_m: float = 0.015,
          restitution: float = 0.75, kick_every_s: float = 1.1, speed: float = 7.0,
          center=(1.5, 1.0), floor: float = BALL_RADIUS) -> tuple[Motion, np.ndarray]:
    """The motion over ``[0, duration]`` and the times (s) of its velocity jumps."""
    rng = np.random.default_rng(seed)
    dt = 2e-4

    def accel(v):
        return np.array([0.0, 0.0, -G]) - drag_per_m * np.linalg.norm(v) * v

    def step(p, v, h):
        k1p, k1v = v, accel(v)
        k2p, k2v = v + 0.5 * h * k1v, accel(v + 0.5 * h * k1v)
        k3p, k3v = v + 0.5 * h * k2v, accel(v + 0.5 * h * k2v)
        k4p, k4v = v + h * k3v, accel(v + h * k3v)
        return (p + h / 6 * (k1p + 2 * k2p + 2 * k3p + k4p),
                v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v))

    t, p = 0.0, np.array([center[0] - 1.0, center[1], 1.0])
    v = np.array([speed * 0.6, 0.3, 3.0])
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
            after = np.array([0.9 * v_new[0], 0.9 * v_new[1], -restitution * v_new[2]])
            if after[2] < 1.0:  # too low a bounce to see: kick it up again
                after[2] = 3.0 + 2 * rng.random()
            events.append(t)
            next_kick = max(next_kick, t + 0.08)  # nobody kicks a ball as it bounces
        else:
            t += h
            after = v_new
            if abs(t - next_kick) < 1e-12:  # a kick towards the room's centre, upwards
                to_center = np.array([center[0] - p_new[0], center[1] - p_new[1]])
                angle = np.arctan2(to_center[1], to_center[0]) + rng.normal(0, 0.6)
                horizontal = speed * (0.5 + 0.5 * rng.random())
                after = np.array([horizontal * np.cos(angle), horizontal * np.sin(angle),
                                  2.0 + 3.0 * rng.random()])
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
