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
- ``rally`` (not in the paper; for clock estimation and continuous-time fusion): 8 s of
  play with a golf ball (the RoboCup small-size league's, as ``throw``): chip kicks at
  floor level (sudden velocity changes), floor bounces (restitution 0.7, 10 % of the
  horizontal speed lost per bounce) and quadratic air drag, integrated by RK4 in 2 ms steps
  with exact bounce instants; it stays inside the 3 x 2 m area below 2 m, where every
  camera of ``paper3`` sees it. Longer durations continue the rally with more kicks. The
  kicks come from a fixed seed (:func:`rally_motion` makes other rallies).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .errors import InputError

G = 9.8  # m/s², as in the paper
BALL_RADIUS = 0.0215  # m, a golf ball (RoboCup small-size league)
#: The fastest ball the gate and the filter's (re)starts believe in, m/s
#: (``GatingOptions.max_speed_m_s``, ``FilterOptions.max_speed_m_s``)
MAX_BALL_SPEED_M_S = 15.0


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


# ---- rally: kicks, bounces and air drag ---------------------------------------------------

@dataclass(frozen=True)
class Ball:
    """A ball's mass and size and the air it flies through; SI units.

    The default is a golf ball (the RoboCup small-size league's ball, as in the paper):
    45.93 g, 42.67 mm, drag coefficient 0.45 (a dimpled ball below its drag crisis, i.e. at
    the few m/s of a rally), air 1.2 kg/m³.
    """

    mass: float = 0.04593
    diameter: float = 0.04267
    drag_coefficient: float = 0.45
    air_density: float = 1.2

    @property
    def drag_per_metre(self) -> float:
        """``k`` of the quadratic drag ``a = -k |v| v``, 1/m: ``rho Cd A / (2 m)``."""
        area = math.pi * (self.diameter / 2) ** 2
        return self.air_density * self.drag_coefficient * area / (2 * self.mass)


#: Area a rally stays in, metres: the paper's 3 x 2 m floor less a margin.
RALLY_AREA = ((0.25, 2.75), (0.25, 1.75))


class Rally:
    """A rally of chip kicks, floor bounces and quadratic drag, integrated on demand.

    The ball starts at rest on the floor at ``start`` and is kicked at t = 0. Each kick
    aims at a landing point in :data:`RALLY_AREA`, with a flight time of 0.35 to 0.85 s
    (a drag-free aim: drag lands it a little short) and a number (0 to 2) of bounces before
    the next kick, chosen so that the bounces stay in the area; the next kick happens at
    the floor contact after them, replacing the ball's velocity (a kick at floor level).
    Between events the equations of motion ``x'' = -g z - k |x'| x'`` are integrated by
    classic RK4 in fixed steps of ``step_s``; floor contacts (ball centre at ``floor``) are
    located within a step by Newton's method on the RK4 state. Positions between steps come
    from cubic Hermite interpolation (positions and velocities at both ends): far below a
    micrometre at 2 ms steps.

    Deterministic: the kicks are drawn from ``numpy.random.default_rng(seed)`` in order,
    and the state is integrated in one fixed sequence of steps however far it is asked, so
    a position does not depend on which times were asked before.
    """

    def __init__(self, seed: int = 0, ball: Ball = Ball(), restitution: float = 0.7,
                 friction: float = 0.9, floor: float = BALL_RADIUS, step_s: float = 2e-3,
                 start=(0.5, 1.0)) -> None:
        self.ball, self.restitution, self.friction = ball, restitution, friction
        self.floor, self.step = floor, step_s
        self._k = ball.drag_per_metre
        self._rng = np.random.default_rng(seed)
        x, y = float(start[0]), float(start[1])
        self._t = 0.0
        self._state = [x, y, floor, *self._kick(x, y)]
        self._nodes_t = [0.0]
        self._nodes = [list(self._state)]
        self.kick_times = [0.0]
        self.bounce_times: list[float] = []
        self._cache: tuple[np.ndarray, np.ndarray] | None = None

    # ---- events ---------------------------------------------------------------------
    def _kick(self, x: float, y: float) -> tuple[float, float, float]:
        """Velocity of a chip kick from (x, y) on the floor; plans the bounces to come."""
        (x0, x1), (y0, y1) = RALLY_AREA
        rng = self._rng
        decay = self.friction * self.restitution  # horizontal travel of each bounce
        for _ in range(200):
            bounces = int(rng.choice(3, p=(0.4, 0.35, 0.25)))
            flight = float(rng.uniform(0.35, 0.85))
            qx, qy = float(rng.uniform(x0 + 0.15, x1 - 0.15)), float(rng.uniform(y0 + 0.15,
                                                                                 y1 - 0.15))
            reach = sum(decay ** (i + 1) for i in range(bounces))
            fx, fy = qx + (qx - x) * reach, qy + (qy - y) * reach
            if x0 <= fx <= x1 and y0 <= fy <= y1 and math.hypot(qx - x, qy - y) > 0.3:
                break
        else:  # pragma: no cover - the area always has room: straight up
            bounces, flight, qx, qy = 0, 0.5, x, y
        self._bounces_left = bounces
        return (qx - x) / flight, (qy - y) / flight, 0.5 * G * flight

    # ---- integration ----------------------------------------------------------------
    def _accel(self, vx: float, vy: float, vz: float) -> tuple[float, float, float]:
        s = self._k * math.sqrt(vx * vx + vy * vy + vz * vz)
        return -s * vx, -s * vy, -G - s * vz

    def _rk4(self, st: list[float], h: float) -> list[float]:
        x, y, z, vx, vy, vz = st
        a1 = self._accel(vx, vy, vz)
        v2 = (vx + 0.5 * h * a1[0], vy + 0.5 * h * a1[1], vz + 0.5 * h * a1[2])
        a2 = self._accel(*v2)
        v3 = (vx + 0.5 * h * a2[0], vy + 0.5 * h * a2[1], vz + 0.5 * h * a2[2])
        a3 = self._accel(*v3)
        v4 = (vx + h * a3[0], vy + h * a3[1], vz + h * a3[2])
        a4 = self._accel(*v4)
        return [x + h / 6 * (vx + 2 * v2[0] + 2 * v3[0] + v4[0]),
                y + h / 6 * (vy + 2 * v2[1] + 2 * v3[1] + v4[1]),
                z + h / 6 * (vz + 2 * v2[2] + 2 * v3[2] + v4[2]),
                vx + h / 6 * (a1[0] + 2 * a2[0] + 2 * a3[0] + a4[0]),
                vy + h / 6 * (a1[1] + 2 * a2[1] + 2 * a3[1] + a4[1]),
                vz + h / 6 * (a1[2] + 2 * a2[2] + 2 * a3[2] + a4[2])]

    def _extend(self, t_end: float) -> None:
        st, t, h, floor = self._state, self._t, self.step, self.floor
        while t < t_end:
            new = self._rk4(st, h)
            if new[2] >= floor or new[5] >= 0:
                st, t = new, t + h
                self._nodes_t.append(t)
                self._nodes.append(new)
                continue
            # floor contact inside this step: Newton on tau for z(tau) = floor
            tau = h * (st[2] - floor) / max(st[2] - new[2], 1e-300)
            for _ in range(30):
                at = self._rk4(st, tau)
                change = (at[2] - floor) / at[5]
                tau = min(max(tau - change, 0.0), h)
                if abs(change) < 1e-15:
                    break
            at = self._rk4(st, tau)
            at[2] = floor
            t = t + tau
            self._nodes_t.append(t)
            self._nodes.append(list(at))
            self.bounce_times.append(t)
            if self._bounces_left == 0:  # the next player kicks it as it lands
                velocity = self._kick(at[0], at[1])
                self.kick_times.append(t)
            else:
                self._bounces_left -= 1
                velocity = (self.friction * at[3], self.friction * at[4],
                            -self.restitution * at[5])
            st = [at[0], at[1], floor, *velocity]
            self._nodes_t.append(t)  # same instant, new velocity: a kink, not a jump
            self._nodes.append(list(st))
        self._state, self._t, self._cache = st, t, None

    # ---- queries ----------------------------------------------------------------------
    def position(self, times) -> np.ndarray:
        """Ball centre (n, 3), metres, at ``times`` (n,) seconds. Before 0: the kick's
        straight line extrapolated backwards (as :func:`ballistic_with_bounces`)."""
        t = np.asarray(times, dtype=np.float64)
        if t.size and not np.all(np.isfinite(t)):
            raise InputError("rally positions need finite times")
        if t.size and t.max() >= self._t:
            self._extend(float(t.max()) + self.step)
        if self._cache is None:
            self._cache = (np.array(self._nodes_t), np.array(self._nodes))
        nodes_t, nodes = self._cache
        # interval [i, i+1] with nodes_t[i] <= t; at a contact (two nodes, one instant)
        # the later node, whose position is the same
        i = np.clip(np.searchsorted(nodes_t, t, side="right") - 1, 0, len(nodes_t) - 2)
        t0, t1 = nodes_t[i], nodes_t[i + 1]
        h = np.where(t1 > t0, t1 - t0, 1.0)
        s = ((t - t0) / h)[:, None]
        p0, v0, p1, v1 = nodes[i, :3], nodes[i, 3:], nodes[i + 1, :3], nodes[i + 1, 3:]
        hh = h[:, None]
        out = ((2 * s**3 - 3 * s**2 + 1) * p0 + (s**3 - 2 * s**2 + s) * hh * v0
               + (-2 * s**3 + 3 * s**2) * p1 + (s**3 - s**2) * hh * v1)
        before = t < 0
        out[before] = nodes[0, :3] + t[before, None] * nodes[0, 3:]
        return out


def rally_motion(seed: int = 0, duration: float = 8.0, **rally_options) -> Motion:
    """A :class:`Rally` as a :class:`Motion` named ``rally`` (seed 0) or ``rally-<seed>``;
    ``rally_options`` go to :class:`Rally` (ball, restitution, friction, ...)."""
    rally = Rally(seed, **rally_options)
    return Motion("rally" if seed == 0 and not rally_options else f"rally-{seed}", duration,
                  rally.position, "chip kicks, floor bounces and air drag (golf ball)")


MOTIONS: dict[str, Motion] = {
    m.name: m
    for m in (
        Motion("straight", np.hypot(3.0, 2.0) / 3.0, _straight, "line at 3 m/s"),
        Motion("spiral", 1.2, _spiral, "helix r=0.62 m at 3 m/s"),
        Motion("fall", float(np.sqrt(2 * 2.0 / G)), _fall, "horizontal launch from 2 m"),
        Motion("turntable", 2.0, _turntable, "r=0.5 m at 45 rpm, z=0.66 m"),
        Motion("throw", 1.5, _throw, "hand throw with one floor bounce"),
        rally_motion(0),
    )
}


def at_rest_first(motion: Motion, rest_s: float) -> Motion:
    """``motion`` after the ball lay still at its start point for ``rest_s`` seconds (a ball
    on the floor before its first kick, ``rally``'s start): ``position(t)`` is
    ``motion.position(max(t - rest_s, 0))``; the duration grows by ``rest_s``."""
    rest = float(rest_s)
    if not np.isfinite(rest) or rest < 0:
        raise InputError(f"rest must be >= 0 seconds, got {rest_s!r}")
    if rest == 0:
        return motion
    base = motion.position

    def position(t: np.ndarray) -> np.ndarray:
        return base(np.maximum(np.asarray(t, dtype=np.float64) - rest, 0.0))

    return Motion(motion.name, motion.duration + rest, position,
                  f"{motion.description}, after {rest:g} s at rest")


def get_motion(name: str) -> Motion:
    try:
        return MOTIONS[name]
    except KeyError:
        raise InputError(f"unknown motion {name!r} (have {', '.join(MOTIONS)})") from None
