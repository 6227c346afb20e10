"""Ball motions for simulation: positions in metres (world, z up) as functions of time.

The paper's section 3.1 names three motions in a 3 x 2 x 2 m volume and leaves some
parameters open; our choices are stated per motion (and in ``docs/paper.md``):

- ``straight``: from (0, 1.2, 2.0) to (3.0, 1.2, 0) at 3 m/s (3.606 m, 1.202 s). As given.
- ``spiral``: a helix of radius 0.62 m around the vertical axis x = y = 1.0 at 3 m/s total
  speed. *Open*: the vertical motion; we descend from z = 2.0 m at 0.5 m/s (horizontal speed
  sqrt(3² - 0.5²) = 2.958 m/s), starting at angle 0 (x = 1.62, y = 1.0).
- ``fall``: "falls from 2,000 mm, then describes a parabola" under g = 9.8 m/s². *Open*: the
  horizontal speed and start; we launch horizontally from (0.5, 1.0, 2.0) at 3 m/s along x
  (the paper's speed of the other motions); it reaches z = 0 after 0.639 s.
- ``turntable``: the paper's Table 2: radius 0.5 m, 45 rpm (4.712 rad/s; the paper's
  "0.478 radian" per second is a slip), height 0.66 m. *Open*: the centre; we use (1.5, 1.0).
- ``throw``: a hand-thrown ball (the paper's section 4.2, about 1.5 s) with a floor bounce:
  from (0.3, 0.5, 1.0) at (1.6, 0.5, 3.0) m/s, g = 9.8 m/s², bouncing on the floor at the
  radius of a golf ball (0.0215 m) with coefficient of restitution 0.7.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .errors import InputError

G = 9.8  # m/s², as in the paper
BALL_RADIUS = 0.0215  # m, a golf ball (RoboCup small-size league)


@dataclass(frozen=True)
class Motion:
    """A named trajectory ``position(times) -> (n, 3)`` world metres, ``times`` (n,) seconds."""

    name: str
    duration: float  # natural duration in seconds
    position: Callable[[np.ndarray], np.ndarray]
    description: str = ""


def _straight(t: np.ndarray) -> np.ndarray:
    start, end = np.array([0.0, 1.2, 2.0]), np.array([3.0, 1.2, 0.0])
    direction = (end - start) / np.linalg.norm(end - start)
    return start + 3.0 * t[:, None] * direction


_SPIRAL_VZ = 0.5
_SPIRAL_OMEGA = np.sqrt(3.0**2 - _SPIRAL_VZ**2) / 0.62


def _spiral(t: np.ndarray) -> np.ndarray:
    angle = _SPIRAL_OMEGA * t
    return np.stack([1.0 + 0.62 * np.cos(angle), 1.0 + 0.62 * np.sin(angle),
                     2.0 - _SPIRAL_VZ * t], axis=1)


def _fall(t: np.ndarray) -> np.ndarray:
    return np.stack([0.5 + 3.0 * t, np.full_like(t, 1.0), 2.0 - 0.5 * G * t * t], axis=1)


_TURNTABLE_OMEGA = 45.0 * 2.0 * np.pi / 60.0


def _turntable(t: np.ndarray) -> np.ndarray:
    angle = _TURNTABLE_OMEGA * t
    return np.stack([1.5 + 0.5 * np.cos(angle), 1.0 + 0.5 * np.sin(angle),
                     np.full_like(t, 0.66)], axis=1)


def ballistic_with_bounces(
    p0, v0, times: np.ndarray, floor: float = BALL_RADIUS, restitution: float = 0.7,
    max_bounces: int = 50,
) -> np.ndarray:
    """Projectile under gravity bouncing on the plane ``z = floor``.

    Loops over bounces (a handful), never over time samples. Returns (n, 3) metres.
    """
    p0, v0 = np.asarray(p0, dtype=np.float64), np.asarray(v0, dtype=np.float64)
    t = np.asarray(times, dtype=np.float64)
    out = np.empty((len(t), 3))
    start_t, start_p, start_v = 0.0, p0.copy(), v0.copy()
    for _ in range(max_bounces):
        # time to reach the floor: floor = z0 + vz s - g s²/2
        dz = start_p[2] - floor
        s_hit = (start_v[2] + np.sqrt(max(start_v[2] ** 2 + 2 * G * dz, 0.0))) / G
        seg = (t >= start_t) & (t < start_t + s_hit)
        s = t[seg] - start_t
        out[seg] = start_p + s[:, None] * start_v
        out[seg, 2] -= 0.5 * G * s * s
        start_p = start_p + s_hit * start_v
        start_p[2] = floor
        start_v = np.array([start_v[0], start_v[1], -restitution * (start_v[2] - G * s_hit)])
        start_t += s_hit
        if start_v[2] < 0.05:  # at rest: roll along the floor
            break
    rest = t >= start_t
    s = t[rest] - start_t
    out[rest] = start_p + s[:, None] * np.array([start_v[0], start_v[1], 0.0])
    out[rest, 2] = floor
    before = t < 0
    out[before] = p0 + t[before, None] * v0  # extrapolate backwards (no gravity loss)
    return out


def _throw(t: np.ndarray) -> np.ndarray:
    return ballistic_with_bounces((0.3, 0.5, 1.0), (1.6, 0.5, 3.0), t)


MOTIONS: dict[str, Motion] = {
    m.name: m
    for m in (
        Motion("straight", np.hypot(3.0, 2.0) / 3.0, _straight, "line at 3 m/s"),
        Motion("spiral", 1.2, _spiral, "helix r=0.62 m at 3 m/s"),
        Motion("fall", float(np.sqrt(2 * 2.0 / G)), _fall, "horizontal launch from 2 m"),
        Motion("turntable", 2.0, _turntable, "r=0.5 m at 45 rpm, z=0.66 m"),
        Motion("throw", 1.5, _throw, "hand throw with one floor bounce"),
    )
}


def get_motion(name: str) -> Motion:
    try:
        return MOTIONS[name]
    except KeyError:
        raise InputError(f"unknown motion {name!r} (have {', '.join(MOTIONS)})") from None
