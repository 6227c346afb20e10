"""The break search's estimate of a jump's instant (pslog/estimation/_breaks.py: a grid, then
stages of three trials around parabola vertices): on a path that the spline with a triple
knot at a known ``τ*`` represents exactly, the least cost with the break is 0 there (and
only there), so the search must return ``τ*`` and the gain the whole base cost."""

from __future__ import annotations

import numpy as np
import pytest

from pslog.estimation import _breaks
from pslog.estimation.trajectory import MotionPrior

H = 1 / 30  # knot spacing, s: three detection intervals at 90 Hz
TAU = 0.01234  # the jump, s: off every grid point of the searches below
G = np.array([0.0, 0.0, -9.8])


def _case(C: int = 1):
    """Linearised detections (random 2 x 3 Jacobians, as a ray's) at 90 Hz of a ballistic
    path whose velocity jumps at TAU (position continuous): before, velocity v1, after,
    v2, acceleration g throughout. Prior (2) is then 0 on it (``p'' = g``, no jerk) and the
    data exact: the spline with a triple knot at TAU reproduces it at zero cost."""
    rng = np.random.default_rng(7)
    t = np.arange(-0.4, 0.4, 1 / 90) + 0.0021
    v1, v2 = np.array([3.0, -1.0, -4.0]), np.array([2.4, -0.8, 3.1])
    dt = t - TAU
    p = np.array([1.0, 0.5, 0.1]) + np.where(dt[:, None] < 0, v1, v2) * dt[:, None] \
        + 0.5 * G * dt[:, None] ** 2
    J = rng.normal(size=(len(t), 2, 3)) * 300
    z = np.einsum("nij,nj->ni", J, p)
    w = np.full(len(t), 4.0)  # 1 / σ², σ = 0.5 px
    centers = np.full(C, 0.005)
    limits = np.tile([-np.inf, np.inf], (C, 1))
    return t, J, z, w, centers, limits


def test_the_scan_finds_a_known_jump_time_and_gains_the_whole_base_cost():
    t, J, z, w, centers, limits = _case()
    bounds = np.array([[-0.02, 0.035]])  # five detection intervals, as the first search's
    tau, gain = _breaks.scan(t, J, z, w, centers, bounds, limits, H, 5 * H, MotionPrior())
    assert abs(tau[0] - TAU) < 2e-5  # 20 µs (the grid's step is 9 ms, a polish stage's 2)
    # the base (no break) on knots centre + k·h: its cost is what the break removes
    lo, hi = centers - 5 * H, centers + 5 * H
    index = np.flatnonzero((t >= lo[0]) & (t <= hi[0]))[None, :]
    local = _breaks._local(int(np.ceil(5 * H / H)) + 1, H, MotionPrior(), 1)
    base = _breaks._Base(local, t, J, z, w, index, np.ones_like(index, bool), centers, H)
    assert base.cost[0] > 1e3  # the jump is far from C² on uniform knots
    assert gain[0] == pytest.approx(base.cost[0], rel=1e-6)


@pytest.mark.parametrize("start", [TAU - 0.006, TAU + 0.002])
def test_the_refinement_finds_a_known_jump_time_from_near_it(start):
    t, J, z, w, _, limits = _case()
    centers = np.array([start])
    bounds = np.array([[start - H / 4, start + H / 4]])
    tau, edge = _breaks.scan_near(t, J, z, w, centers, bounds, limits, H, 5 * H,
                                  MotionPrior())
    assert abs(tau[0] - TAU) < 2e-5
    assert edge[0] == 0


def test_the_refinement_flags_a_jump_beyond_its_quarter_spacing():
    t, J, z, w, _, limits = _case()
    start = TAU + 0.6 * H  # the jump lies below the searched quarter spacing
    tau, edge = _breaks.scan_near(t, J, z, w, np.array([start]),
                                  np.array([[start - H / 4, start + H / 4]]), limits, H,
                                  5 * H, MotionPrior())
    assert edge[0] == -1 and tau[0] < start - H / 4 + 1e-3


def test_the_refinement_refuses_bounds_beyond_a_quarter_spacing():
    t, J, z, w, centers, limits = _case()
    with pytest.raises(ValueError, match="h/4"):
        _breaks.scan_near(t, J, z, w, centers, np.array([[0.0, 0.005 + H / 2]]), limits, H,
                          5 * H, MotionPrior())


def test_the_parabola_vertex_of_three_gains():
    # g(x) = 5 - 2 (x - 0.3)²: the vertex 0.3, within [-1, 1]
    g = [5 - 2 * (x - 0.3) ** 2 for x in (-1.0, 0.0, 1.0)]
    assert _breaks.vertex(*(np.array([v]) for v in g))[0] == pytest.approx(0.3)
    # opening upward: the better end; a vertex beyond ±1: clipped
    assert _breaks.vertex(np.array([2.0]), np.array([1.0]), np.array([3.0]))[0] == 1.0
    g = [5 - 2 * (x + 4) ** 2 for x in (-1.0, 0.0, 1.0)]
    assert _breaks.vertex(*(np.array([v]) for v in g))[0] == -1.0
    # a gain that is not finite (a failed solve's NaN, made -inf; no break fits): stay put
    inf = np.array([-np.inf])
    assert _breaks.vertex(inf, np.array([1.0]), np.array([2.0]))[0] == 0.0
    assert _breaks.vertex(inf, inf, inf)[0] == 0.0


@pytest.mark.filterwarnings("ignore:invalid value:RuntimeWarning")
@pytest.mark.parametrize("bad", ["z nan", "w inf"])
def test_a_detection_that_is_not_finite_gives_no_break_and_no_error(bad):
    # a NaN gain (the window's solve failed) is no gain: the search ends without a break
    # (gain -inf) and inside its bounds, rather than trying an instant of NaN
    t, J, z, w, centers, limits = _case()
    i = np.searchsorted(t, 0.005)
    if bad == "z nan":
        z[i] = np.nan
    else:
        w[i] = np.inf
    bounds = np.array([[-0.02, 0.035]])
    tau, gain = _breaks.scan(t, J, z, w, centers, bounds, limits, H, 5 * H, MotionPrior())
    assert gain[0] == -np.inf and bounds[0, 0] <= tau[0] <= bounds[0, 1]
    near = np.array([[0.005 - H / 4, 0.005 + H / 4]])
    tau, _ = _breaks.scan_near(t, J, z, w, centers, near, limits, H, 5 * H, MotionPrior())
    assert near[0, 0] <= tau[0] <= near[0, 1]


@pytest.mark.parametrize("start", [TAU - 0.0009, TAU + 0.0006])
def test_the_narrow_refinement_finds_a_known_jump_time_from_near_it(start):
    # the refinement's first search (session 23): a grid of 3 over h/16 either side of the
    # break, one polishing stage, a last trial at its vertex; within h/32 (1.04 ms) of the
    # jump the grid's middle trial is its best (further, an end is: flagged)
    t, J, z, w, _, limits = _case()
    bounds = np.array([[start - H / 16, start + H / 16]])
    tau, edge = _breaks.scan_near(t, J, z, w, np.array([start]), bounds, limits, H, 5 * H,
                                  MotionPrior(), narrow=True)
    assert abs(tau[0] - TAU) < 2e-5
    assert edge[0] == 0


@pytest.mark.parametrize("side", [-1, 1])
def test_the_narrow_refinement_flags_a_jump_beyond_h16(side):
    # the jump 5 ms (0.15 h) beyond the start: outside the narrow bounds (2.1 ms), whose end
    # nearer the jump must then be the first stage's best (the caller searches the quarter
    # spacing)
    t, J, z, w, _, limits = _case()
    start = TAU - side * 0.15 * H
    bounds = np.array([[start - H / 16, start + H / 16]])
    tau, edge = _breaks.scan_near(t, J, z, w, np.array([start]), bounds, limits, H, 5 * H,
                                  MotionPrior(), narrow=True)
    assert edge[0] == side
    assert abs(tau[0] - bounds[0, (side + 1) // 2]) < 1e-3
    # and the quarter spacing's search from there finds it
    quarter = np.array([[start - H / 4, start + H / 4]])
    tau, edge = _breaks.scan_near(t, J, z, w, np.array([start]), quarter, limits, H, 5 * H,
                                  MotionPrior())
    assert abs(tau[0] - TAU) < 2e-5 and edge[0] == 0
