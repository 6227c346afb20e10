"""Tests of pslog.motion: the paper's trajectories and the bouncing throw."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from pslog.errors import InputError, PslogError
from pslog.motion import (
    BALL_RADIUS,
    MOTIONS,
    RALLY_AREA,
    Ball,
    G,
    Motion,
    Rally,
    ballistic_with_bounces,
    get_motion,
    rally_motion,
)

DT = 1e-4  # finite-difference step, seconds


def _velocity(motion: Motion, t: np.ndarray) -> np.ndarray:
    """Central-difference velocity (n, 3), m/s."""
    return (motion.position(t + DT) - motion.position(t - DT)) / (2 * DT)


def _acceleration(motion: Motion, t: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """Second difference (n, 3), m/s²."""
    return (motion.position(t + h) - 2 * motion.position(t) + motion.position(t - h)) / h**2


def test_registry():
    assert set(MOTIONS) == {"straight", "spiral", "fall", "turntable", "throw", "rally"}
    for name, motion in MOTIONS.items():
        assert get_motion(name) is motion and motion.name == name
        assert motion.duration > 0 and motion.description
        t = np.linspace(0.0, motion.duration, 50)
        positions = motion.position(t)
        assert positions.shape == (50, 3) and positions.dtype == np.float64
        assert np.all(np.isfinite(positions))
        assert motion.position(np.zeros(0)).shape == (0, 3)
    with pytest.raises(InputError, match="'zigzag'") as info:
        get_motion("zigzag")
    assert isinstance(info.value, PslogError) and "spiral" in str(info.value)


def test_straight_line_from_start_to_end_at_3_m_per_s():
    motion = get_motion("straight")
    length = np.hypot(3.0, 2.0)
    assert motion.duration == pytest.approx(length / 3.0, abs=1e-12)
    assert_allclose(motion.position(np.array([0.0, motion.duration])),
                    [[0.0, 1.2, 2.0], [3.0, 1.2, 0.0]], rtol=0, atol=1e-12)
    t = np.linspace(0.0, motion.duration, 40)
    velocity = _velocity(motion, t)
    assert_allclose(np.linalg.norm(velocity, axis=1), 3.0, rtol=0, atol=1e-9)
    assert_allclose(velocity, np.broadcast_to(velocity[0], velocity.shape), rtol=0, atol=1e-9)
    assert_allclose(motion.position(t)[:, 1], 1.2, rtol=0, atol=1e-15)


def test_spiral_radius_centre_and_speed():
    motion = get_motion("spiral")
    t = np.linspace(0.0, motion.duration, 200)
    positions = motion.position(t)
    radius = np.hypot(positions[:, 0] - 1.0, positions[:, 1] - 1.0)
    assert_allclose(radius, 0.62, rtol=0, atol=1e-12)
    speed = np.linalg.norm(_velocity(motion, t), axis=1)
    assert_allclose(speed, 3.0, rtol=0, atol=1e-6)
    assert_allclose(positions[0], [1.62, 1.0, 2.0], rtol=0, atol=1e-12)
    # it turns (more than half a turn over the motion) and stays in the volume
    angle = np.unwrap(np.arctan2(positions[:, 1] - 1.0, positions[:, 0] - 1.0))
    assert angle[-1] - angle[0] > np.pi
    assert np.all(positions >= 0) and np.all(positions <= [3.0, 2.0, 2.0])


def test_fall_from_two_metres_under_g():
    motion = get_motion("fall")
    assert G == 9.8
    assert_allclose(motion.position(np.array([0.0]))[0, 2], 2.0, rtol=0, atol=0)
    t = np.linspace(0.0, motion.duration, 30)
    acceleration = _acceleration(motion, t)
    assert_allclose(acceleration, np.broadcast_to([0.0, 0.0, -9.8], acceleration.shape),
                    rtol=0, atol=1e-5)
    # it starts horizontally (falls, then describes a parabola) and reaches the floor at
    # the end of its duration
    assert abs(_velocity(motion, np.array([0.0]))[0, 2]) < 1e-9
    assert motion.position(np.array([motion.duration]))[0, 2] == pytest.approx(0.0, abs=1e-12)


def test_turntable_radius_rate_and_height():
    motion = get_motion("turntable")
    t = np.linspace(0.0, motion.duration, 100)
    positions = motion.position(t)
    centre = np.array([1.5, 1.0])  # our choice: the middle of the area
    assert_allclose(np.hypot(*(positions[:, :2] - centre).T), 0.5, rtol=0, atol=1e-12)
    assert_allclose(positions[:, 2], 0.66, rtol=0, atol=0)
    omega = 45 * 2 * np.pi / 60  # 45 rpm
    speed = np.linalg.norm(_velocity(motion, t), axis=1)
    assert_allclose(speed, 0.5 * omega, rtol=0, atol=1e-6)
    # period 60/45 s: back to the start after one turn
    assert_allclose(motion.position(np.array([60 / 45]))[0], positions[0], rtol=0, atol=1e-12)


def test_throw_bounces_once_off_the_floor_with_restitution():
    motion = get_motion("throw")
    t = np.linspace(0.0, motion.duration, 15001)  # 0.1 ms steps
    positions = motion.position(t)
    z = positions[:, 2]
    assert z.min() >= BALL_RADIUS - 1e-12  # never below the floor
    assert_allclose(positions[0], [0.3, 0.5, 1.0], rtol=0, atol=0)
    # exactly one bounce in 1.5 s: one local minimum of z, touching the floor
    minima = np.flatnonzero((z[1:-1] < z[:-2]) & (z[1:-1] <= z[2:])) + 1
    assert len(minima) == 1
    bounce_t = t[minima[0]]
    assert z[minima[0]] == pytest.approx(BALL_RADIUS, abs=1e-3)
    # expected first impact: 1.0 + 3 s - g s²/2 = r
    s_hit = (3.0 + np.sqrt(9.0 + 2 * G * (1.0 - BALL_RADIUS))) / G
    assert bounce_t == pytest.approx(s_hit, abs=2e-4)
    v_before = _velocity(motion, np.array([s_hit - 0.01]))[0]
    v_after = _velocity(motion, np.array([s_hit + 0.01]))[0]
    # extrapolate both to the impact instant (gravity over 10 ms)
    vz_in, vz_out = v_before[2] - G * 0.01, v_after[2] + G * 0.01
    assert vz_in < 0 < vz_out
    assert vz_out / -vz_in == pytest.approx(0.7, abs=1e-6)
    assert_allclose(v_after[:2], [1.6, 0.5], rtol=0, atol=1e-9)  # horizontal kept
    # between bounces: free flight under g
    acceleration = _acceleration(motion, np.array([0.3, 0.6, 1.1, 1.4]))
    assert_allclose(acceleration[:, 2], -G, rtol=0, atol=1e-5)


def test_ballistic_with_bounces_comes_to_rest_and_rolls():
    t = np.linspace(0.0, 20.0, 20001)
    positions = ballistic_with_bounces((0.0, 0.0, 1.0), (1.0, 0.0, 0.0), t, floor=0.0,
                                       restitution=0.5)
    assert positions[:, 2].min() >= 0.0
    assert_allclose(positions[t > 5.0, 2], 0.0, rtol=0, atol=0)  # at rest on the floor
    assert_allclose(positions[:, 0], t, rtol=0, atol=1e-9)  # constant horizontal speed
    # bounce heights fall by restitution² each time
    z = positions[:, 2]
    maxima = np.flatnonzero((z[1:-1] > z[:-2]) & (z[1:-1] >= z[2:])) + 1
    heights = z[maxima[:3]]
    assert_allclose(heights[1:] / heights[:-1], 0.25, rtol=2e-3)


def test_ballistic_before_start_extrapolates_and_unsorted_times():
    t = np.array([0.5, -0.1, 0.0, 0.2])
    positions = ballistic_with_bounces((0.0, 0.0, 1.0), (1.0, 2.0, 3.0), t)
    assert_allclose(positions[1], [-0.1, -0.2, 0.7], rtol=0, atol=1e-12)
    expected = np.array([[s, 2 * s, 1.0 + 3 * s - 0.5 * G * s * s] for s in (0.5, 0.0, 0.2)])
    assert_allclose(positions[[0, 2, 3]], expected, rtol=0, atol=1e-12)


# ---- rally ---------------------------------------------------------------------------------

def test_rally_stays_in_the_area_with_kicks_and_bounces():
    motion = get_motion("rally")
    assert motion.duration == 8.0
    t = np.linspace(0.0, 30.0, 30001)  # longer than its natural duration: more kicks
    p = motion.position(t)
    (x0, x1), (y0, y1) = RALLY_AREA
    assert np.all((p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1))
    assert p[:, 2].min() >= BALL_RADIUS - 1e-12 and p[:, 2].max() < 2.0
    rally = Rally(0)
    rally.position(np.array([30.0]))
    kicks, bounces = np.array(rally.kick_times), np.array(rally.bounce_times)
    assert np.sum(kicks < 8.0) >= 5 and np.sum(kicks < 30.0) >= 20
    assert len(bounces) > len(kicks)  # bounces between kicks too
    # every event is at floor level
    assert_allclose(rally.position(np.concatenate([kicks, bounces]))[:, 2], BALL_RADIUS,
                    rtol=0, atol=1e-12)


def _velocity_at(rally: Rally, t: float, side: int) -> np.ndarray:
    h = 1e-7
    a, b = rally.position(np.array([t + side * h, t + side * 2 * h]))
    return side * (b - a) / h


def test_rally_bounces_with_restitution_and_kicks_change_velocity():
    rally = Rally(0)
    rally.position(np.array([8.0]))
    kicks = set(rally.kick_times)
    bounce = next(b for b in rally.bounce_times if b not in kicks)
    v_in, v_out = _velocity_at(rally, bounce, -1), _velocity_at(rally, bounce, +1)
    assert v_in[2] < 0 and v_out[2] == pytest.approx(-0.7 * v_in[2], rel=1e-4)
    assert_allclose(v_out[:2], 0.9 * v_in[:2], rtol=1e-4)
    kick = rally.kick_times[1]
    v_in, v_out = _velocity_at(rally, kick, -1), _velocity_at(rally, kick, +1)
    assert np.linalg.norm(v_out - v_in) > 1.0  # a sudden change
    assert v_out[2] > 0.5 * G * 0.35 - 1e-6  # a chip: up again, at least the shortest flight


def test_rally_flies_under_gravity_and_quadratic_drag():
    rally = Rally(0)
    t = np.array([0.1, 0.2, 0.25])  # inside the first flight, between events
    rally.position(np.array([1.0]))
    assert t.max() + 1e-3 < rally.bounce_times[0]
    h = 1e-3
    v = (rally.position(t + h) - rally.position(t - h)) / (2 * h)
    a = (rally.position(t + h) - 2 * rally.position(t) + rally.position(t - h)) / h**2
    k = Ball().drag_per_metre
    assert k == pytest.approx(1.2 * 0.45 * np.pi * 0.021335**2 / (2 * 0.04593), rel=1e-12)
    expected = -k * np.linalg.norm(v, axis=1)[:, None] * v - np.array([0.0, 0.0, G])
    assert_allclose(a, expected, rtol=0, atol=1e-3)
    # drag matters: a drag-free ball with the same kicks flies farther
    free = Rally(0, ball=Ball(drag_coefficient=0.0))
    gap = np.linalg.norm(rally.position(np.array([0.5])) - free.position(np.array([0.5])))
    assert gap > 2e-3


def test_rally_integration_is_accurate_and_deterministic():
    t = np.linspace(-0.1, 8.0, 3001)
    a = get_motion("rally").position(t)
    fine = Rally(0, step_s=2.5e-4).position(t)
    assert np.abs(a - fine).max() < 1e-8  # metres: RK4 steps and Hermite interpolation
    # asked piecewise, in any order: the same positions
    other = Rally(0)
    pieces = [other.position(t[i::3]) for i in (2, 0, 1)]
    again = np.empty_like(a)
    for i, piece in zip((2, 0, 1), pieces, strict=True):
        again[i::3] = piece
    assert np.array_equal(again, a)
    assert not np.allclose(rally_motion(1).position(t), a)  # another seed, another rally
    assert rally_motion(1).name == "rally-1"


def test_rally_is_seen_by_every_paper3_camera():
    from pslog.rig import apply_timing, builtin_rig
    from pslog.simulation import simulate

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, _ = simulate(rig, get_motion("rally"), 20.0)
    seen = det.candidates_per_frame() > 0
    for i in range(len(rig)):
        assert seen[det.frame_camera == i].mean() > 0.95
