"""A continuous-time ball trajectory fitted to every detection's viewing ray.

Model
-----
The ball's position is a clamped cubic B-spline per *piece* of the session,
``p(t) = Σ_k N_k(t) c_k`` (:mod:`pslog.estimation.bspline`), with uniform knots
``knot_spacing`` apart. A piece ends where no camera saw the ball for longer than
``max_gap_s`` (a detection with no other camera's within a third of that is left out: one
camera cannot triangulate): nothing bridges such a gap and no point is output inside it.
Inside a piece, a bounce or a kick is a knot of multiplicity 3 at its instant ``τ``: the
position stays continuous, the velocity jumps (found automatically, below).

Why a B-spline: its local support makes every residual touch 4 consecutive control points, so
the normal equations are banded and the solve is linear in the session's length (Furgale,
Rehder & Siegwart, *Unified temporal and spatial calibration for multi-sensor systems*, IROS
2013, the estimator of Kalibr); a parabola and every cubic are represented exactly, and a
triple knot represents a velocity jump exactly.

The estimate minimises, over the control points ``c``,

    Σ_i ρ(‖π_c(i)(p(t_i)) - z_i‖² / σ²)                               (1) reprojection
  + ∫ ‖p''(t) - g‖² / q_a dt + ∫ ‖p'''(t)‖² / q_j dt                  (2) motion prior

(1): ``π_c`` is camera ``c``'s projection to *distorted* pixels with its lens model
(:mod:`pslog.estimation.projection`, analytic Jacobian), ``z_i`` the detection, ``σ`` the
pixel noise (estimated: 1.4826 · median absolute residual, corrected for the degrees of freedom
the fit uses), ``ρ(s) = c² log(1 + s / c²)`` the Cauchy kernel with ``c = 3`` (a detection
3σ off counts half; a gross outlier barely counts), solved by iteratively reweighted
Gauss–Newton.

(2): the acceleration's deviation from gravity ``g = (0, 0, -9.8) m/s²`` — air drag, spin,
model error — is a first-order Gauss–Markov (Ornstein–Uhlenbeck) process of standard deviation
``σ_a`` and correlation time ``τ_a`` (the Singer model: R. A. Singer, *Estimating optimal
tracking filter performance for manned maneuvering targets*, IEEE Trans. AES 6(4), 1970). Its
spectral density ``2σ_a²τ_a / (1 + ω²τ_a²)`` makes the negative log prior of a path, up to
end terms, the two integrals of (2) with ``q_a = 2σ_a²τ_a`` and ``q_j = 2σ_a²/τ_a``. Inside a
knot span ``p''`` is linear and ``p'''`` constant, so a 2-point Gauss–Legendre rule and the
midpoint integrate (2) exactly. Velocity jumps at triple knots are not penalised.

Uncertainty: the Gauss–Newton information matrix ``H = Σ w_i J_iᵀJ_i / σ² + P`` at the
solution (``w_i`` the robust weights, ``P`` the prior's) is the inverse covariance of ``c``;
its banded inverse (Takahashi recurrence, :func:`pslog.estimation._normal.covariance_band`)
gives, through the basis, the marginal covariance of ``p(t)`` at any ``t``.

Bounces and kicks: a first fit under a prior ten times looser (it follows a velocity jump
closely, so σ is estimated right and each jump is a sharp peak); every span where
``‖p'' - g‖`` peaks above ``break_accel`` is a candidate. Around each, the problem linearised
at that fit is solved on a local window under the prior (2), on uniform knots ``t_c + k·h``
(the *base*, C² everywhere); a break at a trial instant ``τ`` inserts a triple knot at ``τ``
into those knots, which adds exactly three B-splines to the base's, so the least cost with
the break is the base's minus ``gᵀ S⁻¹ g``, a 9 x 9 Schur complement on the base's solution
and inverse information (:mod:`pslog.estimation._breaks` has the equations; each trial instant
is tested on knots at least ``h/4`` from it: a second base shifted by ``h/2``). All
candidates and instants of a scan stage are one batched computation: a grid of 7 instants
over the five detection intervals around the peak, then two stages of three trials around
parabola vertices and a last trial (14 in all); the break is kept when it lowers the cost
by more than ``break_threshold`` (in units of σ², a likelihood-ratio test). Rounds repeat
until no new break (a later round tests only the peaks within reach of the local problems of
the breaks the round before added: further away the fit, and so the test, is unchanged); a
fit under the real prior follows, then each break's instant is re-estimated at that fit within
a quarter knot spacing (one local base, 12 trials; the whole spacing again where the best of
the first 5 was at an end of the quarter) and the session refitted. A break leaves
detections of two cameras between it and a piece's end (a segment's velocity is otherwise
free along a ray), and an end segment that fewer than four detections of two cameras hold
gives no point: its 6 unknowns (position, velocity) are not determined by 2–3 pixels, and
the linearised covariance there would not say so (``Fit.withheld``;
``Track.dropped["underdetermined_end"]``). A piece's first or last detection whose deleted
residual (the fit made again without it, :func:`end_statistic`) is beyond χ²₂'s 1 - 1e-4
quantile ends the piece before it, its row without a point, counted there too: the fit
extrapolates an end to whatever detection is there, a spurious one included.

Why knots every three detection intervals: 8 pixel coordinates per 3 unknowns keep the pixel
noise estimable from the residuals, and a cubic spline with knots that close represents
ballistic flight with drag far below a micrometre (error ~ h⁴·max‖p⁗‖/384).

Limits: one camera cannot triangulate, so a piece seen by fewer than two cameras gives no
point; the prior assumes ballistic flight between breaks (a rolling ball, with no gravity
acceleration, is fitted with a small bias; air drag is absorbed by σ_a, not modelled); a
velocity change spread over more than a few knot spans (a ball rolling to a stop) is smoothed
rather than broken. numpy and scipy, with compiled per-point loops
(:mod:`pslog.estimation._kernels`, numba; the first trajectory's in
:mod:`pslog.estimation._initial`, the break windows' gathers in
:mod:`pslog.estimation._window`, the hat matrix's trace in :mod:`pslog.estimation._hat`, a
Gauss–Newton step's normal equations from the Jacobians in one pass in
:mod:`pslog.estimation._gauss_newton`):
the B-spline basis, the projection with its
residual and Jacobian, each detection's quadratic form and the normal equations summed per
control point (:class:`pslog.estimation._normal.Points`), the covariance band's Takahashi
recurrence, the noise scale's median, the break test's local normal equations and solves
and its per-trial terms, the 9 x 9 Schur complement and solve included (``trial_gains``),
and the banded Cholesky factorisation and solve (LAPACK's ``dpbtrf``/``dpbtrs``
step for step: the same bits as scipy's). ~110,000 detections per second on one core at 10
minutes (``benchmarks/bench_smooth.py``, ``--base`` for a paired comparison). The break
search runs its candidates in blocks on ``PSLOG_SMOOTH_THREADS`` threads (default 2; the
same bits on any count, :func:`pslog.estimation._breaks.smooth_threads`).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from ..errors import FusionError
from ..motion import G
from ..records import NS, Observations
from ..rig import Rig
from . import _breaks, _normal
from .bspline import DEGREE, basis, basis_derivative, basis_pieces, clamped_knots, n_control


@dataclass(frozen=True)
class MotionPrior:
    """The Singer model of the ball's acceleration between bounces (see module docstring).

    Attributes
    ----------
    gravity : (3,) m/s², the mean acceleration
    sigma_accel : float, m/s², standard deviation of the acceleration's deviation from
        gravity (air drag of a fast ball is a few m/s²)
    tau_s : float, seconds, its correlation time
    """

    gravity: tuple[float, float, float] = (0.0, 0.0, -G)
    sigma_accel: float = 4.0
    tau_s: float = 0.2

    @property
    def q_accel(self) -> float:
        """Spectral density of the acceleration deviation, m²/s³: ``2σ_a²τ_a``."""
        return 2 * self.sigma_accel**2 * self.tau_s

    @property
    def q_jerk(self) -> float:
        """Weight of the jerk integral, m²/s⁵: ``2σ_a²/τ_a``."""
        return 2 * self.sigma_accel**2 / self.tau_s


@dataclass(frozen=True)
class SmoothOptions:
    """Settings of :func:`fit_trajectory`.

    Attributes
    ----------
    prior : MotionPrior
    max_gap_s : float, longest time without any detection inside one piece
    knot_spacing_s : float or None, seconds between knots; None: three mean intervals
        between detections (all cameras together): 8 pixel coordinates per 3 unknowns keep
        the pixel noise estimable, and a cubic spline with knots that close represents
        ballistic flight with drag to far below a micrometre (error ~ h⁴·max‖p⁗‖ / 384)
    min_noise_px : float, floor of the estimated pixel noise (a noise-free session still
        weighs the prior a little)
    break_accel : float, m/s², ``‖p'' - g‖`` above which a span is tested for a break
    break_threshold : float, cost decrease (units of σ²) that keeps a break
    iterations : int, Gauss–Newton iterations per fit; the refit after the breaks'
        refinement runs this many in all (the first of them the refit onto the new knots
        itself), its last two after σ is corrected for the fit's degrees of freedom
    detector_offset_m : float, standard deviation (metres, per axis) of the detector's
        constant 3-D offset ``δ ~ N(0, σ_δ² I₃)`` of the ball's apparent centre, the same for
        every detection of every camera (a centroid drawn toward the lit side of the ball):
        every fitted point moves by exactly ``δ``, so each point's covariance gains
        ``σ_δ² I₃``. A systematic error the fit can neither average away nor see in its
        residuals (a consider parameter); the points do not move. 0: none
    detector_bias_px : float, standard deviation (pixels, per image axis) of each camera's
        own constant detector bias ``b_c ~ N(0, σ_b² I₂)``, independent between cameras (a
        camera's own systematic error: threshold, lens, calibration); added as consider
        parameters through the fit's sensitivity to them (:func:`bias_sensitivity`). 0: none
    """

    prior: MotionPrior = MotionPrior()
    max_gap_s: float = 0.12
    knot_spacing_s: float | None = None
    min_noise_px: float = 0.005
    break_accel: float = 15.0
    break_threshold: float = 25.0
    iterations: int = 4
    detector_offset_m: float = 0.0
    detector_bias_px: float = 0.0

    def __post_init__(self) -> None:
        if not 0 <= self.detector_bias_px <= 1e3:
            raise FusionError(f"detector bias must be in [0, 1000] pixels, got "
                              f"{self.detector_bias_px!r}")
        if not 0 <= self.detector_offset_m <= 1.0:
            raise FusionError(f"detector offset must be in [0, 1] metres, got "
                              f"{self.detector_offset_m!r}")


#: Cauchy kernel scale, in units of σ on the 2-D residual norm
_CAUCHY = 3.0
#: Half-width of the local window of the break test, in knot spans
_WINDOW_SPANS = 5
#: The first fit's prior is this much looser (σ_a times this)
_LOOSE = 10.0
#: A detection whose residual norm exceeds this many σ contradicts the fit (χ²₂'s 1 - 1e-4
#: quantile, √18.42, the level of the filter's gate): the fit has rejected it
#: (:attr:`Fit.rejected`), and at a piece's end a run of them is a jump the fit did not find
#: (:func:`_underdetermined_ends`)
_END_JUMP_SCALED = float(np.sqrt(-2.0 * np.log(1e-4)))
#: A piece's end detection whose one-step deletion gain exceeds χ²₂'s 1 - 1e-2 quantile is
#: tested by the fit made without it (:func:`_ends_refitted`)
_END_SCREEN = float(-2.0 * np.log(1e-2))
#: Rounds of the deletion test (:func:`_left_out`): each leaves out the detections the fit
#: bent to most, the next tests the fit made without them
_DELETION_ROUNDS = 3
#: Fewest detections (of at least two cameras) that make an end segment beyond a break
#: trustworthy: 8 pixel coordinates for its 6 unknowns (:func:`_underdetermined_ends`)
_END_DETECTIONS = 4
#: The refinement's searches around each break (:func:`_refine_breaks`), in knot spacings
#: either side: the first narrow (a grid of 3, one polishing stage, a final trial: 7
#: trials), the next only for the breaks whose best first-stage trial was at an end of the
#: last (5 + 6 + 1 trials), then the whole spacing. Session 23: ``1 / 16`` first, where
#: the quarter's 12 trials were the first search (the find's instants are within 1 ms,
#: h/32, of the refined ones for 9 breaks in 10; 1 in 10 then needs the quarter; ``1 / 8``
#: placed the instants less precisely: docs/methods.md)
_REFINE_STAGES = (1 / 16, 1 / 4)
#: After two breaks merged, the refine searches again the breaks its pass moved by more
#: than this many knot spacings (and the merged one's neighbours): :func:`_refine_breaks`
_REFINE_AGAIN = 1 / 32
#: Rounds of break detection (each finds the jumps the previous fit still hides)
_BREAK_ROUNDS = 3
#: two refined breaks this many knot spacings apart or less are tested against one
#: (:func:`_two_against_one`)
_CLOSE_SPANS = 2.0
#: the grid of the pairs tested against one break (:func:`_one_against_two`): steps per
#: knot spacing
_ONE_GRID = 4
#: then the best pair's stages of 3 x 3 trials around it, each step half the last's (to
#: h/64)
_ONE_POLISH = 4
#: Gauss–Newton iterations of the first loose fit, of the next rounds' (from the previous
#: fit, refitted to the new knots: the refit is their one iteration since session 23,
#: :func:`_refit_linearised`), and of the fit under the real prior at which the breaks'
#: instants are refined (the session is refitted in full after): more change the fits by
#: micrometres, not the breaks found (a third loose one, dropped in session 18, changed
#: the held-out sessions' errors by far less than their seed-to-seed spread)
_LOOSE_ITERATIONS = 2
_NEXT_LOOSE_ITERATIONS = 1
_REFINE_ITERATIONS = 2
#: Gauss–Newton iterations after σ is corrected for the fit's degrees of freedom
_DOF_ITERATIONS = 2


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A fitted trajectory: pieces of cubic B-splines with triple knots at breaks.

    Attributes
    ----------
    t0_ns : int, the time origin of the spline parameter (seconds since ``t0_ns``)
    knots : list of (K_p,) float64 per piece, seconds since ``t0_ns``
    offset : (n_pieces,) int64, first control point of each piece in ``control``
    control : (m, 3) float64, control points, metres
    band : (m, 4, 3, 3) float64, band of the control points' covariance, m²
    breaks_s : (b,) float64, seconds since ``t0_ns``, the velocity jumps found
    noise_px : float, the estimated pixel noise σ
    spacing_s : float, the uniform knot spacing, seconds
    valid_s : (n_pieces, 2) float64 or None, seconds since ``t0_ns``: the part of each piece
        the detections determine (an end segment beyond a break that too few detections
        hold is left out, :func:`_underdetermined_ends`); None: every piece whole
    consider : (m, 3, k) float64 or None, metres: the control points' sensitivity to each
        consider parameter times its standard deviation: each camera's detector bias (per
        image axis, 2·cameras columns, :func:`bias_sensitivity`), then the columns of
        ``fit_trajectory``'s ``consider_px`` (the clocks', :func:`pixel_sensitivity`); the
        covariance of a point ``p = Σ N_a c_a`` gains ``S Sᵀ``, ``S = Σ N_a consider_a``
        (:func:`consider_points`). None: no such term
    offset_m : float, metres, the standard deviation per axis of the detector's common 3-D
        offset: every point's covariance gains ``offset_m² I₃`` (its sensitivity is ``I₃``,
        :func:`_add_consider`)
    """

    t0_ns: int
    knots: list[np.ndarray]
    offset: np.ndarray
    control: np.ndarray
    band: np.ndarray
    breaks_s: np.ndarray
    noise_px: float
    spacing_s: float = 0.0
    valid_s: np.ndarray | None = None
    consider: np.ndarray | None = None
    offset_m: float = 0.0

    def piece_of(self, time_ns: np.ndarray) -> np.ndarray:
        """Index of the piece covering each time (n,), -1 outside every piece."""
        t = (np.asarray(time_ns, dtype=np.int64) - self.t0_ns) / NS
        starts = np.array([k[0] for k in self.knots])
        ends = np.array([k[-1] for k in self.knots])
        p = np.searchsorted(starts, t, side="right") - 1
        inside = (p >= 0) & (t <= ends[np.maximum(p, 0)])
        if self.valid_s is not None:
            span = self.valid_s[np.maximum(p, 0)]
            inside &= (t >= span[:, 0]) & (t <= span[:, 1])
        return np.where(inside, p, -1)

    def evaluate(self, time_ns: np.ndarray, derivative: int = 0
                 ) -> tuple[np.ndarray, np.ndarray]:
        """Position (or derivative) and position covariance at times inside the pieces.

        Returns
        -------
        value : (n, 3), metres (per second^derivative); NaN outside every piece
        covariance : (n, 3, 3), m², the marginal covariance of the position; NaN outside
        """
        time_ns = np.asarray(time_ns, dtype=np.int64)
        value = np.full((len(time_ns), 3), np.nan)
        cov = np.full((len(time_ns), 3, 3), np.nan)
        piece = self.piece_of(time_ns)
        t = (time_ns - self.t0_ns) / NS
        for p in np.unique(piece[piece >= 0]):
            rows = np.flatnonzero(piece == p)
            first, N = basis(self.knots[p], t[rows], derivative)
            first = first + self.offset[p]
            index = first[:, None] + np.arange(DEGREE + 1)
            value[rows] = np.einsum("na,nad->nd", N[:, derivative], self.control[index])
            cov[rows] = _normal.marginal(self.band, first, N[:, 0])
            _add_consider(cov, rows, self, first, N[:, 0])
        return value, cov

    def sensitivity(self, time_ns: np.ndarray) -> np.ndarray:
        """``S(t)`` (n, 3, k), metres: how the position at each time moves per standard
        deviation of each consider parameter — the detector's 3-D offset (3 columns,
        ``offset_m I₃``, when ``offset_m`` > 0), then the columns of ``consider`` when it is
        set (each camera's pixel bias per axis, 2 per camera, then the clocks' columns of
        ``fit_trajectory``'s ``consider_px``); NaN outside every piece. The position
        covariance holds ``S Sᵀ`` beside the white noise's."""
        time_ns = np.asarray(time_ns, dtype=np.int64)
        k = (3 if self.offset_m > 0 else 0) + (
            0 if self.consider is None else self.consider.shape[2])
        out = np.full((len(time_ns), 3, k), np.nan)
        piece = self.piece_of(time_ns)
        t = (time_ns - self.t0_ns) / NS
        for p in np.unique(piece[piece >= 0]):
            rows = np.flatnonzero(piece == p)
            first, N = basis(self.knots[p], t[rows], 0)
            parts = [np.broadcast_to(self.offset_m * np.eye(3), (len(rows), 3, 3))] \
                if self.offset_m > 0 else []
            if self.consider is not None:
                parts.append(consider_points(self.consider, first + self.offset[p], N[:, 0]))
            if parts:
                out[rows] = np.concatenate(parts, axis=2)
        return out


@dataclass(frozen=True, eq=False)
class Fit:
    """:func:`fit_trajectory`'s result.

    Attributes
    ----------
    trajectory : Trajectory
    used : (n,) bool, observations inside a fitted piece (with a usable pixel)
    position : (n, 3) float64, metres, the trajectory at each observation's time (NaN if not
        ``used``)
    covariance : (n, 3, 3) float64, m², its marginal covariance
    residual_px : (n,) float64, reprojection residual of each observation, pixels
    weight : (n,) float64, final robust weight of each observation (0: not in the fit;
        :attr:`rejected` says which the fit rejected)
    pieces : list of (n_p,) int64, the observation rows of each fitted piece
    withheld : int, observations inside a piece left without a point: an end segment beyond
        a break that fewer than ``_END_DETECTIONS`` detections of two cameras hold, or an
        end detection the fit made without it contradicts (:func:`end_statistic`: the
        piece ends at the detection before it)
    excluded : (n,) bool or None, the observations the deletion test left out of the fit
        (:func:`deletion_gain`, :func:`_left_out`): weight 0, their point the trajectory's
        made without them, their residual against it; :attr:`rejected` holds them too
    """

    trajectory: Trajectory
    used: np.ndarray
    position: np.ndarray
    covariance: np.ndarray
    residual_px: np.ndarray
    weight: np.ndarray
    pieces: list = field(default_factory=list)
    withheld: int = 0
    excluded: np.ndarray | None = None

    @property
    def rejected(self) -> np.ndarray:
        """(n,) bool, the ``used`` observations the fit has rejected: residual norm beyond
        :data:`_END_JUMP_SCALED` σ (``trajectory.noise_px``), χ²₂'s 1 - 1e-4 quantile, which
        a detection of the fitted ball exceeds with probability 1e-4 (its Cauchy weight
        below 0.33, and its pull on the fit falling as it lies further), or left out of the
        fit by the deletion test (:attr:`excluded`: the fit had bent to it). The trajectory
        there is the other detections' and the motion model's."""
        with np.errstate(divide="ignore", invalid="ignore"):
            beyond = self.residual_px / self.trajectory.noise_px > _END_JUMP_SCALED
        if self.excluded is not None:
            beyond |= self.excluded
        return self.used & beyond


class _Problem:
    knots: list[np.ndarray]
    prior_ab: np.ndarray
    """The observations, the pieces' knots and the design (basis values) that follow."""

    def __init__(self, obs: Observations, rig: Rig, rows_of_piece: list[np.ndarray],
                 knots: list[np.ndarray], prior: MotionPrior, t0_ns: int | None = None):
        self.obs, self.rig, self.prior = obs, rig, prior
        self.t0_ns = int(obs.time_ns[0]) if t0_ns is None else t0_ns
        self.t = (obs.time_ns - self.t0_ns) / NS
        self.rows_of_piece = rows_of_piece
        self.rows = np.concatenate(rows_of_piece)  # observation rows in the fit
        # each row's camera parameters (built on first use)
        self._cameras: dict[str, np.ndarray] | None = None
        self._piece_of_row = np.repeat(np.arange(len(rows_of_piece)),
                                       [len(r) for r in rows_of_piece])
        self.set_knots(knots, prior)

    def set_knots(self, knots: list[np.ndarray], prior: MotionPrior) -> None:
        # the same knot vectors (only the prior changes): the design stays as it is
        same = (hasattr(self, "knots") and len(knots) == len(self.knots)
                and all(a is b for a, b in zip(knots, self.knots, strict=True)))
        self.knots, self.prior = knots, prior
        sizes = np.array([n_control(k) for k in knots])
        self.offset = np.zeros(len(sizes), np.int64)
        np.cumsum(sizes[:-1], out=self.offset[1:])
        self.m = int(sizes.sum())
        if not same:
            self.set_times(self.t)
        if hasattr(self, "prior_ab"):
            del self.prior_ab  # freed first: its memory serves the new one
        self.prior_ab, self.prior_rhs, self.prior_const, self.prior_values = _prior_normal(
            knots, self.offset, self.m, self.prior)

    def set_times(self, t: np.ndarray) -> None:
        """Observation times (n,) s since ``t0_ns`` (the clock estimator moves them); the
        basis at each, its value ``N`` (n_fit, 4) (its first derivative :attr:`N1` when
        first asked for: only the clock estimator's velocities read it)."""
        self.t = t
        # the design changes: no projection of it is known
        self._last: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None \
            = None
        # the values alone: the recurrence's values do not depend on how many derivatives
        # follow them (the same bits)
        self.first, N = basis_pieces(self.knots, self._piece_of_row, t[self.rows], 0)
        self.N = np.ascontiguousarray(N[:, 0])
        self._N1: np.ndarray | None = None
        self.points = _normal.Points(self.first, self.N, self.m)

    @property
    def N1(self) -> np.ndarray:
        """The first derivative (n_fit, 4) of the basis at each observation (per second)."""
        if self._N1 is None:
            _, N = basis_pieces(self.knots, self._piece_of_row, self.t[self.rows], 1)
            self._N1 = np.ascontiguousarray(N[:, 1])
        return self._N1

    def velocities(self, control: np.ndarray) -> np.ndarray:
        index = self.first[:, None] + np.arange(DEGREE + 1)
        return np.einsum("na,nad->nd", self.N1, control[index])

    def positions(self, control: np.ndarray) -> np.ndarray:
        return self.points.positions(control)

    def positions_known(self, control: np.ndarray) -> np.ndarray:
        """:meth:`positions` of ``control``, the last :meth:`remember`-ed projection's array
        when ``control`` is that array (the same values: the stages after a run read the
        positions the run ended at; ~5 ms a call at 90 minutes). Read only: the array may be
        the remembered one."""
        if self._last is not None and self._last[0] is control:
            return self._last[1]
        return self.positions(control)

    def project(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (n, 2) pixels and ``∂uv/∂X`` (n, 2, 3) of the fitted observations.

        A point at or behind its camera (a wild iterate) has no projection: its row is set to
        0 with a zero Jacobian (it adds nothing to the normal equations) and flagged in
        ``self.invalid``, which the cost charges as a gross outlier."""
        from ._kernels import project_residuals

        if self._cameras is None:
            cams = self.rig.cameras
            self._cameras = {
                "camera": np.ascontiguousarray(self.obs.camera[self.rows], dtype=np.int64),
                "R": np.array([c.R for c in cams], dtype=np.float64),
                "t": np.array([c.t for c in cams], dtype=np.float64),
                "K": np.array([[c.K[0, 0], c.K[0, 1], c.K[0, 2], c.K[1, 1], c.K[1, 2]]
                               for c in cams], dtype=np.float64),
                "dist": np.array([c.dist for c in cams], dtype=np.float64)}
            self._uv = np.ascontiguousarray(self.obs.uv[self.rows], dtype=np.float64)
        p = self._cameras
        # the formulas of project_stacked, one compiled pass (residual and validity fused)
        r, J, self.invalid = project_residuals(p["camera"], p["R"], p["t"], p["K"], p["dist"],
                                               np.ascontiguousarray(X, dtype=np.float64),
                                               self._uv)
        return r, J

    def project_control(self, control: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions (n, 3), residuals and Jacobians (:meth:`project`) of control points;
        those of the last :meth:`remember`-ed control points when ``control`` is that array
        (one run's end is often the next one's start: the same design, the same point)."""
        if self._last is not None and self._last[0] is control:
            _, X, r, J, self.invalid = self._last
            return X, r, J
        X = self.positions(control)
        r, J = self.project(X)
        return X, r, J

    def remember(self, control: np.ndarray, X: np.ndarray, r: np.ndarray, J: np.ndarray
                 ) -> None:
        """Keep the projection of ``control`` (positions, residuals, Jacobians, invalid) on
        this design for :meth:`project_control`."""
        self._last = (control, X, r, J, self.invalid)

    def normal(self, J: np.ndarray, target: np.ndarray, w: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """Normal equations of the prior plus ``Σ_i w_i ‖J_i p(t_i) - target_i‖²``
        (:func:`_normal.accumulate_points`; the same sums as :meth:`data_rows` fed to
        :func:`_normal.accumulate`). J (n, 2, 3), target (n, 2), w (n,)."""
        from ._kernels import data_terms

        # each detection's upper triangle of w JᵀJ (n, 6) and Jᵀ (w z) (n, 3), one pass
        M, v = data_terms(np.ascontiguousarray(J, dtype=np.float64),
                          np.ascontiguousarray(target, dtype=np.float64),
                          np.ascontiguousarray(w, dtype=np.float64))
        return self.points.normal_onto(M, v, self.prior_ab, self.prior_rhs)

    def linearised_normal(self, J: np.ndarray, X: np.ndarray, r: np.ndarray, w: np.ndarray
                          ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`normal` of the measurements linearised at positions ``X`` (n, 3) with
        residuals ``r`` (n, 2), ``target = J X - r`` (:func:`_linear_target`): the same
        values in one compiled pass that forms no target or quadratic form array
        (:func:`pslog.estimation._gauss_newton.linearised_normal_onto`)."""
        from ._gauss_newton import linearised_normal_onto

        points = self.points
        return linearised_normal_onto(
            points.first, points.N, np.ascontiguousarray(J, dtype=np.float64),
            np.ascontiguousarray(X, dtype=np.float64), np.ascontiguousarray(r, dtype=np.float64),
            np.ascontiguousarray(w, dtype=np.float64), points.m,
            np.ascontiguousarray(self.prior_ab, dtype=np.float64),
            np.ascontiguousarray(self.prior_rhs, dtype=np.float64))

    def data_rows(self, J: np.ndarray, target: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows ``E c[start:start+12] - b`` of the linearised reprojection (2 per detection):
        ``E[3a + d] = N_a ∂uv/∂X_d``."""
        E = (self.N[:, None, :, None] * J[:, :, None, :]).reshape(-1, 12)
        start = np.repeat(3 * self.first, 2)
        return start, E, target.reshape(-1)


def _prior_normal(knots: list[np.ndarray], offset: np.ndarray, m: int, prior: MotionPrior
                  ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Normal equations of the motion prior (2), integrated exactly per knot span: the band
    (12, 3m), rhs, constant, and the band's distinct entries (m, 4) (for :func:`_prior_cost`:
    :func:`pslog.estimation._kernels.prior_band_sums`)."""
    key = (m, offset.tobytes(), tuple(np.asarray(k, dtype=np.float64).tobytes() for k in knots))
    parts = _PRIOR_CACHE.pop(key, None)
    if parts is None:
        # the entries the new one will push out go first: their memory then serves it
        _trim_prior_cache(2 * 4 * (m + 3) * 8)
        parts = _prior_parts(knots, offset, m)
    _PRIOR_CACHE[key] = parts  # most recent last
    _trim_prior_cache(0)
    sums_accel, sums_jerk, pull, length = parts
    g = np.asarray(prior.gravity, dtype=np.float64)
    from ._kernels import prior_band_sums

    # the band ab_accel / q_a + ab_jerk / q_j, from the parts' compact sums in one pass
    ab, values = prior_band_sums(sums_accel, sums_jerk, m, prior.q_accel, prior.q_jerk)
    rhs = (pull[:, None] * g).reshape(-1) / prior.q_accel
    return ab, rhs, float(length * (g @ g) / prior.q_accel), values


def _trim_prior_cache(coming: int) -> None:
    """Keep the few most recent prior parts, and of a long session's (12 MB each at 90
    minutes) the latest two only (a fit comes back to the knots it just left, never to older
    ones); ``coming``: bytes of an entry about to be added (0: none), counted as the latest
    (the rule then leaves what it would leave once the entry is in)."""
    def too_many() -> bool:
        count = len(_PRIOR_CACHE) + (coming > 0)
        size = sum(p[0].nbytes + p[1].nbytes for p in _PRIOR_CACHE.values()) + coming
        return count > 4 or (count > 1 and size > _PRIOR_CACHE_BYTES)

    while _PRIOR_CACHE and too_many():
        del _PRIOR_CACHE[next(iter(_PRIOR_CACHE))]


#: the prior's parts per knot pattern (:func:`_prior_parts`), the few most recent
_PRIOR_CACHE: dict = {}
#: the cache's bound beyond its latest entry, bytes
_PRIOR_CACHE_BYTES = 32 * 2**20


def _prior_parts(knots: list[np.ndarray], offset: np.ndarray, m: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The prior's normal equations for ``q_a = q_j = 1`` and ``g`` one: the banded matrices
    of ``∫ ‖p''‖²`` and of ``∫ ‖p'''‖²`` in compact form (m + 3, 4) each (their 4 distinct
    numbers per control point: :func:`pslog.estimation._kernels.prior_sums`; the band is
    :func:`pslog.estimation._kernels.prior_band_sums`), ``∫ N_k''`` per control point (the
    rhs is that times ``g / q_a``) and the total length (the constant is that times
    ``‖g‖² / q_a``)."""
    firsts, accel, jerk, weights, lengths = [], [], [], [], 0.0
    node = 1 / np.sqrt(3.0)  # 2-point Gauss-Legendre, weights 1
    for p, k in enumerate(knots):
        lo, hi = k[:-1], k[1:]
        nonempty = hi > lo
        lo, hi = lo[nonempty], hi[nonempty]
        half, mid = (hi - lo) / 2, (hi + lo) / 2
        # ∫ ‖p''‖² over the span at its two Gauss nodes; ∫ ‖p'''‖², constant over the
        # span, at its midpoint
        s = len(mid)
        # the second derivative at the Gauss nodes, the third at the midpoints: only those
        # rows of the basis
        first, N = basis_derivative(k, np.concatenate(
            [mid - node * half, mid + node * half, mid]), np.repeat([2, 3], [2 * s, s]))
        firsts.append((first[:2 * s] + offset[p], first[2 * s:] + offset[p]))
        accel.append(N[:2 * s])
        jerk.append(N[2 * s:])
        weights.append((np.r_[half, half], 2 * half))
        lengths += float(np.sum(2 * half))
    from ._kernels import prior_pull, prior_sums

    wa = np.concatenate([w for w, _ in weights])
    wj = np.concatenate([w for _, w in weights])
    fa = np.concatenate([f for f, _ in firsts])
    fj = np.concatenate([f for _, f in firsts])
    Na = np.concatenate(accel)
    # the terms' quadratic forms w I: the band accumulate_points forms for the upper
    # triangles (w, 0, 0, w, 0, w), each pair's sum once, kept as those sums (prior_sums:
    # 4 numbers per control point; the band is points_normal_isotropic's)
    sums_accel = prior_sums(np.ascontiguousarray(fa, dtype=np.int64),
                            np.ascontiguousarray(Na, dtype=np.float64),
                            np.ascontiguousarray(wa, dtype=np.float64), m)
    sums_jerk = prior_sums(np.ascontiguousarray(fj, dtype=np.int64),
                           np.ascontiguousarray(np.concatenate(jerk), dtype=np.float64),
                           np.ascontiguousarray(wj, dtype=np.float64), m)
    # ∫ N_k'' per control point: the terms added in order (as np.add.at did)
    pull = prior_pull(np.ascontiguousarray(fa), np.ascontiguousarray(wa),
                      np.ascontiguousarray(Na), m)
    return sums_accel, sums_jerk, pull[:m], lengths


def _prior_cost(problem: _Problem, c: np.ndarray) -> float:
    """Value of (2) at ``c`` from the prior's normal equations: xᵀAx - 2 rhsᵀx + const."""
    from ._kernels import prior_matvec

    x = np.ascontiguousarray(c, dtype=np.float64).reshape(-1)
    # A x in one compiled pass (the nonzero terms of the numpy passes per diagonal, in their
    # order) from the band's 4 distinct entries per control point
    Ax = prior_matvec(problem.prior_values, x)
    # einsum, not a BLAS dot: the value must not depend on the number of BLAS threads
    return float(np.einsum("i,i->", x, Ax) - 2 * np.einsum("i,i->", problem.prior_rhs, x)
                 + problem.prior_const)


def _scaled_norms(r: np.ndarray, sigma: float) -> np.ndarray:
    """``‖r_i‖² / σ²`` (n,) of residuals (n, 2): ``np.sum(r * r, axis=1) / sigma**2`` in one
    compiled pass (the same bits)."""
    from ._kernels import scaled_norms

    return scaled_norms(np.ascontiguousarray(r, dtype=np.float64), float(sigma**2))


def _linear_target(J: np.ndarray, X: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The linearised measurements ``J X - r`` (n, 2) (``np.einsum("naj,nj->na", J, X) - r``,
    one compiled pass: :func:`pslog.estimation._kernels.linear_target`)."""
    from ._kernels import linear_target

    return linear_target(np.ascontiguousarray(J, dtype=np.float64),
                         np.ascontiguousarray(X, dtype=np.float64),
                         np.ascontiguousarray(r, dtype=np.float64))


def split_pieces(obs: Observations, usable: np.ndarray, max_gap_s: float
                 ) -> list[np.ndarray]:
    """Rows of the usable observations in pieces that the model may bridge.

    One camera cannot triangulate: a detection with no detection of another camera within
    ``max_gap_s / 3`` of it is left out, and the rest is split where no detection came for
    ``max_gap_s``. Pieces of fewer than 6 detections or seen by one camera are dropped.
    """
    rows = np.flatnonzero(usable)
    if len(rows) == 0:
        return []
    time_ns, camera = obs.time_ns[rows], obs.camera[rows]
    gap_ns = max_gap_s * NS
    paired = np.zeros(len(rows), dtype=bool)
    for c in np.unique(camera):
        mine, others = camera == c, time_ns[camera != c]
        if len(others) == 0:
            continue
        t = time_ns[mine]
        after = np.searchsorted(others, t, side="left")
        nearest = np.minimum(
            np.abs(others[np.minimum(after, len(others) - 1)] - t),
            np.abs(t - others[np.maximum(after - 1, 0)]))
        # a piece's ends seen by one camera only: at most a third of the gap (a velocity
        # jump there could not be seen)
        paired[mine] = nearest <= gap_ns / 3
    rows, time_ns = rows[paired], time_ns[paired]
    gaps = np.flatnonzero(np.diff(time_ns) > gap_ns) + 1
    return [piece for piece in np.split(rows, gaps)
            if len(piece) >= 6 and len(np.unique(obs.camera[piece])) >= 2]


def _uniform_breaks(t_lo: float, t_hi: float, spacing: float) -> np.ndarray:
    n_spans = max(1, int(np.ceil((t_hi - t_lo) / spacing - 1e-9)))
    return np.linspace(t_lo, t_hi, n_spans + 1)


def _knots_with_breaks(t_lo: float, t_hi: float, spacing: float, breaks: np.ndarray
                       ) -> np.ndarray:
    """Uniform knots on ``[t_lo, t_hi]`` and a triple knot at every break (uniform knots
    closer than a quarter spacing to a break are dropped)."""
    grid = _uniform_breaks(t_lo, t_hi, spacing)
    breaks = np.asarray(breaks, dtype=np.float64)
    breaks = breaks[(breaks > t_lo + 1e-6) & (breaks < t_hi - 1e-6)]
    if len(breaks):
        breaks = np.sort(breaks)
        inner = grid[1:-1]
        j = np.searchsorted(breaks, inner)  # the nearest break is j - 1 or j
        nearest = np.minimum(np.abs(inner - breaks[np.maximum(j - 1, 0)]),
                             np.abs(breaks[np.minimum(j, len(breaks) - 1)] - inner))
        grid = np.concatenate([grid[:1], inner[nearest >= spacing / 4], grid[-1:]])
    points = np.concatenate([grid, breaks])
    mult = np.ones(len(points), np.int64)
    mult[len(grid):] = 3
    order = np.argsort(points, kind="stable")
    points, mult = points[order], mult[order]
    return clamped_knots(points, mult[1:-1])


def _normalised_rows(problem: _Problem) -> tuple[np.ndarray, np.ndarray]:
    """The camera (n,) and the undistorted normalised ``(x, y)`` (n, 2) of each of
    ``problem``'s detections (:func:`_initial_control`'s linear form)."""
    obs, rows = problem.obs, problem.rows
    cams = obs.camera[rows]
    xy = np.empty((len(rows), 2))
    for i, cam in enumerate(problem.rig.cameras):
        sel = cams == i
        if np.any(sel):
            xy[sel] = cam.undistort_normalized(obs.uv[rows[sel]])
    return cams, xy


def _initial_control(problem: _Problem, sigma_px: float) -> np.ndarray:
    """A first trajectory from the linear (DLT) form of the projection: undistorted normalised
    ``(x, y)`` gives ``f (R₀ - x R₂)·X + f (t₀ - x t₂) = 0`` (and likewise for ``y``), scaled by
    ``1/Z`` to approximate pixels; solved twice, the second time with the depths and robust
    weights of the first. The rows' quadratic forms, residuals and depths are compiled
    passes reading each detection's camera by index (:mod:`pslog.estimation._initial`; the
    bits of :func:`_initial_control_numpy`)."""
    from ._initial import dlt_residuals, dlt_terms

    cams, xy = _normalised_rows(problem)
    camera = np.ascontiguousarray(cams, dtype=np.int64)
    R = np.array([c.R for c in problem.rig.cameras], dtype=np.float64)
    tt = np.array([c.t for c in problem.rig.cameras], dtype=np.float64)
    f = np.array([[c.K[0, 0], c.K[1, 1]] for c in problem.rig.cameras], dtype=np.float64)
    depth = np.full(len(cams), _scene_depth(problem.rig))
    weight = np.ones(len(cams))
    control = np.empty((0, 3))  # set by the first of the two passes
    for _ in range(2):
        wz = weight / sigma_px**2
        upper, v = dlt_terms(camera, R, tt, f, xy, depth, wz)
        ab, rhs = problem.points.normal_onto(upper, v, problem.prior_ab, problem.prior_rhs)
        U = _normal.factor(ab, rebuild=lambda upper=upper, v=v: problem.points.normal_onto(
            upper, v, problem.prior_ab, problem.prior_rhs)[0])
        control = _normal.solve(U, rhs).reshape(-1, 3)
        X = problem.positions(control)
        r, depth = dlt_residuals(camera, R, tt, f, xy, depth, X)
        s = max(1.4826 * _abs_median(r), sigma_px)
        weight = 1 / (1 + np.sum(r * r, axis=1) / (_CAUCHY * s) ** 2)
    return control


def _initial_control_numpy(problem: _Problem, sigma_px: float) -> np.ndarray:
    """:func:`_initial_control` in numpy's gathers and einsums (the form its compiled passes
    repeat, :mod:`pslog.estimation._initial`: the tests compare the two, bit for bit)."""
    cams, xy = _normalised_rows(problem)
    R = np.array([c.R for c in problem.rig.cameras])[cams]
    tt = np.array([c.t for c in problem.rig.cameras])[cams]
    f = np.array([[c.K[0, 0], c.K[1, 1]] for c in problem.rig.cameras])[cams]
    # row a of the linear form: (R_a - xy_a R_2)·X + (t_a - xy_a t_2)
    A = R[:, :2, :] - xy[:, :, None] * R[:, 2:3, :]  # (n, 2, 3)
    a0 = tt[:, :2] - xy * tt[:, 2:3]
    depth = np.full((len(cams), 1), _scene_depth(problem.rig))
    weight = np.ones(len(cams))
    control = np.empty((0, 3))  # set by the first of the two passes
    for _ in range(2):
        scale = f / np.maximum(depth, 1e-3)
        J = A * scale[:, :, None]
        target, wz = -(a0 * scale), weight / sigma_px**2
        ab, rhs = problem.normal(J, target, wz)
        U = _normal.factor(ab, rebuild=lambda J=J, target=target, wz=wz:
                           problem.normal(J, target, wz)[0])
        control = _normal.solve(U, rhs).reshape(-1, 3)
        X = problem.positions(control)
        depth = np.maximum(np.einsum("nj,nj->n", R[:, 2], X) + tt[:, 2], 1e-3)[:, None]
        r = np.einsum("naj,nj->na", J, X) + a0 * scale
        s = max(1.4826 * _abs_median(r), sigma_px)
        weight = 1 / (1 + np.sum(r * r, axis=1) / (_CAUCHY * s) ** 2)
    return control


def _abs_median(r: np.ndarray) -> float:
    """``np.median(np.abs(r))``: by the compiled selection when every entry is finite (the
    same value, :func:`pslog.estimation._kernels.abs_median_finite_rows`), else numpy's."""
    from ._kernels import abs_median_finite_rows

    r = np.ascontiguousarray(r, dtype=np.float64)
    if r.size and np.all(np.isfinite(r)):
        return float(abs_median_finite_rows(r)[0])
    return float(np.median(np.abs(r)))


def _scene_depth(rig: Rig) -> float:
    """Typical depth of the scene: distance from the cameras to the point nearest every
    optical axis (1 m if the axes are parallel)."""
    centers = np.array([c.center_world for c in rig.cameras])
    axes = np.array([c.R[2] for c in rig.cameras])
    M = np.zeros((3, 3))
    v = np.zeros(3)
    for c, a in zip(centers, axes, strict=True):
        P = np.eye(3) - np.outer(a, a)
        M += P
        v += P @ c
    if np.linalg.cond(M) > 1e8:
        return 1.0
    point = np.linalg.solve(M, v)
    depth = float(np.median(np.einsum("nj,nj->n", axes, point - centers)))
    return depth if depth > 0 else 1.0


class _Solver:
    """Iteratively reweighted Gauss–Newton on (1) + (2) for one set of knots."""

    def __init__(self, problem: _Problem, options: SmoothOptions):
        self.problem, self.options = problem, options

    def cost(self, control: np.ndarray, r: np.ndarray, sigma: float,
             prior: float | None = None, s: np.ndarray | None = None) -> float:
        """The robust cost (1) + (2) of ``control`` whose residuals are ``r`` (``prior``: its
        prior cost (2), if already known; ``s``: ``‖r‖² / σ²`` per row, if known)."""
        if s is None:
            s = _scaled_norms(r, sigma)
        c2 = _CAUCHY**2
        data = c2 * np.log1p(s / c2)
        # a point behind its camera costs as a detection 1000 σ off
        penalty = np.count_nonzero(self.problem.invalid) * c2 * np.log1p(1e6 / c2)
        if prior is None:
            prior = _prior_cost(self.problem, control)
        return float(np.sum(data) + penalty + prior)

    def run(self, control: np.ndarray, sigma: float, iterations: int, dof: float = 1.0
            ) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, np.ndarray]:
        """Returns control, σ, residuals (n, 2), weights (n,), Jacobians (n, 2, 3); σ is
        re-estimated at every iteration as ``dof`` · 1.4826 · median |residual|."""
        problem = self.problem
        X, r, J = problem.project_control(control)
        prior = None  # the prior cost (2) of ``control``: it does not depend on σ
        for _ in range(iterations):
            sigma = self._scale(r, sigma, dof)
            s = _scaled_norms(r, sigma)
            w = 1 / (1 + s / _CAUCHY**2)  # Cauchy IRLS weight
            # linearised: J X_new ≈ J X - r (the targets formed where they are summed)
            ab, rhs = problem.linearised_normal(J, X, r, w / sigma**2)
            # factored in place (the band is this step's own); rebuilt only if a pivot fails
            U = _normal.factor(ab, rebuild=lambda J=J, X=X, r=r, w=w, sigma=sigma:
                               problem.linearised_normal(J, X, r, w / sigma**2)[0])
            new = _normal.solve(U, rhs).reshape(-1, 3)
            if prior is None:
                prior = _prior_cost(problem, control)
            before = self.cost(control, r, sigma, prior, s)
            step = 1.0
            for _ in range(6):  # step halving keeps the robust cost from rising
                trial = control + step * (new - control)
                X_trial = problem.positions(trial)
                r_trial, J_trial = problem.project(X_trial)
                prior_trial = _prior_cost(problem, trial)
                s_trial = _scaled_norms(r_trial, sigma)
                if self.cost(trial, r_trial, sigma, prior_trial, s_trial) <= before:
                    break
                step /= 2
            moved = float(np.max(np.abs(trial - control), initial=0.0))
            control, X, r, J, prior = trial, X_trial, r_trial, J_trial, prior_trial
            s_last = s_trial  # ‖r‖² / σ² of the new residuals (σ is kept until the next step)
            if moved < 1e-7:  # 0.1 µm: converged
                break
        problem.remember(control, X, r, J)
        s = s_last if iterations > 0 else _scaled_norms(r, sigma)
        return control, sigma, r, 1 / (1 + s / _CAUCHY**2), J

    def _scale(self, r: np.ndarray, sigma: float, dof: float) -> float:
        """``dof`` · 1.4826 · the median absolute residual of the finite rows (one compiled
        pass and selection: :func:`pslog.estimation._kernels.abs_median_finite_rows`, the
        value ``np.median`` gives); ``sigma`` if no row is finite."""
        from ._kernels import abs_median_finite_rows

        median, rows = abs_median_finite_rows(np.ascontiguousarray(r, dtype=np.float64))
        if rows == 0:
            return sigma
        return max(dof * 1.4826 * float(median), self.options.min_noise_px)


def fit_trajectory(obs: Observations, rig: Rig, options: SmoothOptions | None = None, *,
                   consider_px: np.ndarray | None = None) -> Fit:
    """Fit one continuous trajectory to every observation's ray (module docstring).

    Parameters
    ----------
    obs : Observations, sorted by (time, camera), times already corrected to true capture times
    rig : Rig, with at least two cameras
    options : SmoothOptions
    consider_px : (n, 2, k) float64 or None, pixels: the error one standard deviation of
        each of ``k`` independent consider parameters puts on each observation's pixel (e.g.
        the clocks', :func:`pslog.fusion.clock.pixel_errors`): the covariance gains their
        ``S Sᵀ`` through the fit's sensitivity (:func:`pixel_sensitivity`); the points do
        not move

    Returns
    -------
    Fit; a :class:`FusionError` if no piece of the session is seen by two cameras
    """
    from ._memory import kept

    with kept():  # the iterations' large temporaries reused, not faulted in again
        return _fit_trajectory(obs, rig, options or SmoothOptions(), consider_px)


def _fit_trajectory(obs: Observations, rig: Rig, options: SmoothOptions,
                    consider_px: np.ndarray | None = None) -> Fit:
    """:func:`fit_trajectory`."""
    if consider_px is not None and (np.ndim(consider_px) != 3 or len(consider_px) != len(obs)
                                    or np.shape(consider_px)[1] != 2):
        raise FusionError(f"consider_px must be (n, 2, k) for {len(obs)} observations, got "
                          f"shape {np.shape(consider_px)}")
    if len(rig) < 2:
        raise FusionError(f"a trajectory fit needs at least two cameras (one camera cannot "
                          f"triangulate); rig has {len(rig)}")
    n = len(obs)
    usable = np.all(np.isfinite(obs.uv), axis=1)
    for i, cam in enumerate(rig.cameras):  # a pixel far off the image is no detection
        sel = obs.camera == i
        usable[sel] &= np.all(np.abs(obs.uv[sel]) <= 10 * max(cam.width, cam.height), axis=1)
        # nor is one beyond the lens model's fold-over, which has no ray (walk42: a webcam's
        # calibrated k3 folded over in the image's corner; its NaN made the DLT start's
        # normal matrix "not positive definite", and `smooth --gating off` and `pslog sync`
        # failed: docs/methods.md, "A detection without a ray")
        rows = np.flatnonzero(sel & usable)
        if len(rows) and np.any(cam.dist):
            usable[rows] = np.all(np.isfinite(cam.undistort_normalized(obs.uv[rows])), axis=1)
    pieces = split_pieces(obs, usable, options.max_gap_s)
    if not pieces:
        # no command's name here: smooth (fusion) and sync (clocks) each say whose fit it is
        off = n - int(np.count_nonzero(usable))
        raise FusionError("no stretch of the session is seen by two cameras (one camera "
                          "cannot triangulate)" + (
                              f"; {off} of {n} detections lie more than 10 image sizes off "
                              f"their image and are no detection" if off else ""))
    # seconds since the first usable detection: rows without one (a first detection beyond
    # the image, NaN) are not in the fit and do not move its time origin (each time's
    # rounding: the fit's bits, and through the break search's decisions up to 14 mm at a
    # point, session 26), as if they were not in the session
    t0_ns = int(obs.time_ns[np.argmax(usable)])
    t = (obs.time_ns - t0_ns) / NS
    spans = [(t[p[0]], t[p[-1]]) for p in pieces]
    if options.knot_spacing_s is None:
        total = sum(hi - lo for lo, hi in spans)
        count = sum(len(p) - 1 for p in pieces)
        spacing = 3 * total / max(count, 1)
    else:
        spacing = options.knot_spacing_s
    spacing = max(spacing, 1e-4)
    # fits under a loose prior follow the velocity jumps closely enough that the pixel noise
    # is estimated right and each jump shows as a sharp acceleration peak: each round tests
    # the peaks that the breaks found so far do not explain
    loose = replace(options.prior, sigma_accel=_LOOSE * options.prior.sigma_accel)
    breaks = [np.zeros(0) for _ in pieces]
    made: dict = {}

    def piece_knots(breaks: list[np.ndarray]) -> list[np.ndarray]:
        """Each piece's knots with its breaks (a piece whose breaks did not change keeps
        its knot vector)."""
        out = []
        for i, ((lo, hi), b) in enumerate(zip(spans, breaks, strict=True)):
            key = (i, np.asarray(b, dtype=np.float64).tobytes())
            if key not in made:
                made[key] = _knots_with_breaks(lo, hi + 1e-9, spacing, b)
            out.append(made[key])
        return out

    knots = piece_knots(breaks)
    problem = _Problem(obs, rig, pieces, knots, loose, t0_ns)
    control = _initial_control(problem, 1.0)
    sigma, iterations = 1.0, min(options.iterations, _LOOSE_ITERATIONS)
    rounds, found = 0, None
    for _ in range(_BREAK_ROUNDS):
        control, sigma, r, w, J = _Solver(problem, options).run(control, sigma, iterations)
        found = _find_breaks(problem, control, sigma, r, w, J, spacing, breaks, options,
                             near=found if rounds else None)
        rounds += 1
        if not any(len(f) for f in found):
            break
        breaks = [np.sort(np.r_[b, f]) for b, f in zip(breaks, found, strict=True)]
        knots = piece_knots(breaks)
        X_old = problem.positions_known(control)
        problem.set_knots(knots, loose)
        # the next Gauss-Newton step, taken on the new knots (:func:`_refit_linearised`)
        control = _refit_linearised(problem, X_old, r, J, w, sigma)
        iterations = _NEXT_LOOSE_ITERATIONS - 1
    problem.set_knots(knots, options.prior)  # same knots: the control points stay valid
    refine = any(len(b) for b in breaks)
    # with breaks, this fit is only where their instants are refined: the full fit follows
    control, sigma, r, w, J = _Solver(problem, options).run(
        control, sigma, min(options.iterations, _REFINE_ITERATIONS) if refine
        else options.iterations)
    if refine:  # each break's time again, at the fit under the real prior
        # every fitted detection's w J and w JᵀJ at this fit, formed once for the refine's
        # and the confirmation's scans (each formed those of its windows' detections: ~8
        # times the same at 90 minutes; session 44)
        terms = _scan_terms(J, w, sigma)
        breaks = _refine_breaks(problem, control, sigma, r, w, J, spacing, breaks, options,
                                terms=terms)
        # two close breaks tested against one in their place
        breaks = _two_against_one(problem, control, sigma, r, w, J, spacing, breaks, options,
                                  terms=terms)
        # and each break the fit bends around tested against two in its place; a pair put
        # there is tested against one as any (the best one may lie elsewhere than the break
        # it replaced: then it stays one, there)
        paired = _one_against_two(problem, control, sigma, r, w, J, spacing, breaks,
                                  options, terms=terms)
        if paired is not breaks:
            breaks = _two_against_one(problem, control, sigma, r, w, J, spacing, paired,
                                      options, terms=terms)
        # each break kept only where it pays its way under the real prior too
        breaks = _confirmed_breaks(problem, control, sigma, r, w, J, spacing, breaks,
                                   options, terms=terms)
        del terms
        knots = piece_knots(breaks)
        X_old = problem.positions_known(control)
        problem.set_knots(knots, options.prior)
        control = _refit_linearised(problem, X_old, r, J, w, sigma)
        # the dof-corrected run below continues these iterations (the refit above the first
        # of them): together they are the ``options.iterations`` of the full fit
        control, sigma, r, w, J = _Solver(problem, options).run(
            control, sigma, max(options.iterations - _DOF_ITERATIONS, 1) - 1)

    # σ corrected for the degrees of freedom the fit absorbs, then the covariance there;
    # then each detection's deletion test (:func:`deletion_gain`): a detection the fit bent
    # to, which leaving out lowers the fit's cost beyond the level, leaves the fit, and the
    # fit is made again without it (:func:`_left_out`; docs/methods.md, "A spurious blob
    # the fit bends to")
    left_out = np.zeros(0, np.int64)
    end_out = np.zeros(0, np.int64)
    for round_ in range(_DELETION_ROUNDS + 1):
        _, dof, _ = _information(problem, control, sigma, r, J, trace=True)
        control, sigma, r, w, J = _Solver(problem, options).run(control, sigma,
                                                                _DOF_ITERATIONS, dof)
        band, _, p_eff, U = _information_factored(problem, control, sigma, r, J, trace=True)
        # the covariance at the noise the residuals show (the M-estimator's sandwich,
        # :func:`variance_factor`); the robust scale σ above still weighs the fit: the
        # points do not move
        k_var = variance_factor(r, w, sigma, p_eff)
        band *= k_var  # in place: the band is this fit's own
        cov_rows = problem.points.marginal(band)
        # (σ at its floor: noise-free detections, whose residuals are the model's own error
        # at a kick it did not find, not noise that a level of σ can sort into outliers)
        if round_ == _DELETION_ROUNDS or sigma <= options.min_noise_px:
            break
        inside = _inside(problem)
        gain = deletion_gain(J, cov_rows, r, w, sigma, k_var)
        testable = _end_testable(problem)
        out = _left_out(problem.t[problem.rows], gain, _WINDOW_SPANS * spacing,
                        inside | testable)
        if not len(out):
            # an end whose one-step gain is near the level: the robust weights of its
            # neighbours change without it, which the one-step formula keeps fixed
            out = _ends_refitted(problem, options, control, sigma, k_var, spacing,
                                 np.flatnonzero(testable & (gain > _END_SCREEN)))
        if not len(out):
            break
        # an end detection the fit bent to ends the piece at the detection before it: its
        # row gets no point (the fit carried there only follows it), as an end beyond a jump
        end_out = np.union1d(end_out, problem.rows[out[~inside[out]]])
        left_out = np.union1d(left_out, problem.rows[out[inside[out]]])
        kept_rows = [rows[~np.isin(rows, left_out) & ~np.isin(rows, end_out)]
                     for rows in pieces]
        problem = _Problem(obs, rig, kept_rows, knots, options.prior, t0_ns)
        control, sigma, r, w, J = _Solver(problem, options).run(control, sigma,
                                                                _REFINE_ITERATIONS)
        # a break the left-out detection made (the search ran with it) must pay its way
        # without it (:func:`_confirmed_breaks`)
        if any(len(b) for b in breaks):
            kept = _confirmed_breaks(problem, control, sigma, r, w, J, spacing, breaks,
                                     options)
            if sum(len(b) for b in kept) < sum(len(b) for b in breaks):
                breaks = kept
                knots = piece_knots(breaks)
                X_old = problem.positions_known(control)
                problem.set_knots(knots, options.prior)
                control = _refit_linearised(problem, X_old, r, J, w, sigma)
                _, r, J = problem.project_control(control)
    consider = (options.detector_bias_px * bias_sensitivity(problem, U, J, r, sigma)
                if options.detector_bias_px > 0 else None)
    if consider_px is not None and consider_px.shape[2]:
        shifted = pixel_sensitivity(problem, U, J, r, sigma,
                                    np.asarray(consider_px, np.float64)[problem.rows])
        consider = shifted if consider is None else np.concatenate([consider, shifted], axis=2)
    del U
    out_rows, valid_s = _underdetermined_ends(problem, breaks, np.linalg.norm(r, axis=1) / sigma)
    trajectory = Trajectory(problem.t0_ns, problem.knots, problem.offset, control, band,
                            np.concatenate([np.asarray(b) for b in breaks]) if breaks
                            else np.zeros(0), sigma, spacing, valid_s, consider,
                            options.detector_offset_m)
    residual = np.full(n, np.nan)
    weight = np.zeros(n)
    if len(problem.rows) == n:
        # every observation in a piece (the rows ascending: all of them, in order): the
        # points' arrays are the outputs, not copied into NaN-filled ones (a 90-minute
        # session's covariances are 35 MB, written twice and faulted in page by page)
        position = problem.positions(control)
        covariance = cov_rows
        _add_consider(covariance, slice(None), trajectory, problem.first, problem.N)
    else:
        position = np.full((n, 3), np.nan)
        covariance = np.full((n, 3, 3), np.nan)
        position[problem.rows] = problem.positions(control)
        covariance[problem.rows] = cov_rows
        _add_consider(covariance, problem.rows, trajectory, problem.first, problem.N)
    del cov_rows
    residual[problem.rows] = np.linalg.norm(r, axis=1)
    weight[problem.rows] = w
    used = np.zeros(n, dtype=bool)
    used[problem.rows] = True
    excluded = np.zeros(n, dtype=bool)
    if len(left_out):
        # a detection left out keeps its row: the trajectory there (the others' and the
        # prior's), its residual against it (its deleted residual), weight 0
        position[left_out], covariance[left_out] = trajectory.evaluate(obs.time_ns[left_out])
        for c, cam in enumerate(rig.cameras):
            rows = left_out[obs.camera[left_out] == c]
            if len(rows):
                uv, _ = cam.project(position[rows])
                residual[rows] = np.linalg.norm(uv - obs.uv[rows], axis=1)
        used[left_out] = np.all(np.isfinite(position[left_out]), axis=1)
        excluded[left_out] = True
    out_rows = np.union1d(out_rows, end_out).astype(np.int64)
    used[out_rows] = False
    position[out_rows] = np.nan
    covariance[out_rows] = np.nan
    return Fit(trajectory, used, position, covariance, residual, weight, pieces,
               len(out_rows), excluded)


def _inside(problem: _Problem) -> np.ndarray:
    """(n_fit,) bool, in ``problem.rows``' order: the fitted detections strictly inside their
    piece's time span, which detections on both sides hold. A piece's first or last
    detection is the end of what the piece covers: the others only extrapolate to it, and
    left out it would take the end of the piece (and its point) with it."""
    out = []
    for rows in problem.rows_of_piece:
        t = problem.t[rows]
        out.append((t > t.min()) & (t < t.max()))
    return np.concatenate(out)


def _ends_refitted(problem: _Problem, options: SmoothOptions, control: np.ndarray,
                   sigma: float, k_var: float, spacing: float, candidates: np.ndarray
                   ) -> np.ndarray:
    """Indices (into ``problem.rows``) of the ``candidates`` (end detections) whose deleted
    residual statistic (:func:`end_statistic`) exceeds :data:`_END_JUMP_SCALED` ² (χ²₂'s
    1 - 1e-4 quantile, the level of the fit's other tests)."""
    stats = [end_statistic(problem, options, control, sigma, k_var, spacing, int(k))
             for k in candidates]
    return np.asarray([int(k) for k, s in zip(candidates, stats, strict=True)
                       if s > _END_JUMP_SCALED**2], np.int64)


class _FixedScaleSolver(_Solver):
    """The fit's solver at a given noise σ (not re-estimated from the residuals): the
    refit of one piece (:func:`end_statistic`), whose few residuals would estimate σ
    poorly, at the session's σ, which leaving one detection out does not move."""

    def _scale(self, r: np.ndarray, sigma: float, dof: float) -> float:
        return sigma


def end_statistic(problem: _Problem, options: SmoothOptions, control: np.ndarray,
                  sigma: float, k_var: float, spacing: float, k: int) -> float:
    """The deleted residual statistic of fitted detection ``k`` (index into
    ``problem.rows``), made by fitting its piece again without it (from ``control``,
    ``_REFINE_ITERATIONS`` Gauss-Newton steps at the session's noise σ: the neighbours'
    robust weights change then — a detection of the ball the fit rejected while it
    followed a spurious end returns — which the one-step :func:`deletion_gain` keeps
    fixed; the pieces share nothing but σ, so the other pieces' fit is unchanged):

        d = uv_k - π(X̂(t_k)),   T = dᵀ (σ² I + J Σ Jᵀ)⁻¹ d

    ``X̂(t_k)`` and ``Σ`` the position that fit predicts at the detection's time and its
    covariance (times the session fit's :func:`variance_factor` ``k_var``), ``J = ∂π/∂X``
    there: χ²₂ when the detection is of the fitted ball. NaN when the fit does not reach
    the detection's time or the point is behind its camera."""
    obs = problem.obs
    row = problem.rows[k]
    p = int(problem._piece_of_row[k])
    rows = problem.rows_of_piece[p]
    knots = problem.knots[p]
    first = int(problem.offset[p])
    trial = _Problem(obs, problem.rig, [rows[rows != row]], [knots], options.prior,
                     problem.t0_ns)
    c, _, r, _w, J = _FixedScaleSolver(trial, options).run(
        control[first:first + n_control(knots)], sigma, _REFINE_ITERATIONS)
    band, _, _, _ = _information_factored(trial, c, sigma, r, J, trace=False)
    band *= k_var
    traj = Trajectory(trial.t0_ns, trial.knots, trial.offset, c, band, np.zeros(0), sigma,
                      spacing)
    return float(predicted_d2(traj, obs, np.array([row]), problem.rig)[0])


def predicted_d2(trajectory: Trajectory, obs: Observations, rows: np.ndarray, rig: Rig
                 ) -> np.ndarray:
    """(len(rows),) the squared distance of each detection ``rows`` of ``obs`` from
    ``trajectory``'s pixel at its time, in the metric of that prediction:

        d = uv - π(X̂(t)),   d² = dᵀ (σ² I + J Σ Jᵀ)⁻¹ d

    ``X̂(t)``, ``Σ`` the trajectory's position and covariance there, ``J = ∂π/∂X``
    (:func:`~pslog.estimation.projection.project_with_jacobian`), σ its ``noise_px``: χ²₂
    for a detection of the fitted ball the fit did not use. NaN outside the pieces or
    behind the camera. The end test's statistic (:func:`end_statistic`) and ``smooth``'s
    confirmation of a choice in doubt (``pslog.fusion.smooth._confirmed``)."""
    from .projection import project_with_jacobian

    position, cov = trajectory.evaluate(obs.time_ns[rows])
    out = np.full(len(rows), np.nan)
    for c, cam in enumerate(rig.cameras):
        sel = np.flatnonzero((obs.camera[rows] == c) & np.all(np.isfinite(position), axis=1))
        if not len(sel):
            continue
        uv, J = project_with_jacobian(cam, position[sel])
        S = (np.einsum("nij,njk,nlk->nil", J, cov[sel], J)
             + trajectory.noise_px ** 2 * np.eye(2))
        r = obs.uv[rows[sel]] - uv
        with np.errstate(invalid="ignore"):
            out[sel] = np.einsum("ni,ni->n", r, np.linalg.solve(S, r[..., None])[..., 0])
    return out


def _end_testable(problem: _Problem) -> np.ndarray:
    """(n_fit,) bool, in ``problem.rows``' order: a piece's first and last detections whose
    deletion test may end the piece before them (:func:`_left_out`; the piece then ends at
    the detection next to it, and the row gets no point): only where the piece keeps at
    least ``2 * _END_DETECTIONS`` detections of two cameras without it.

    The fit extrapolates a piece's end to whatever its last (first) detection is: a spurious
    blob there (a static distractor the gate chose where only one other camera still sees
    the ball, session 36) takes the end with it, metres off, with a residual near zero; its
    deleted residual (against the fit made without it) is the test's."""
    out = []
    cams = problem.obs.camera
    for rows in problem.rows_of_piece:
        t = problem.t[rows]
        ends = (t == t.min()) | (t == t.max())
        ok = (len(rows) - 1 >= 2 * _END_DETECTIONS
              and len(np.unique(cams[rows[~(t == t.max())]])) >= 2
              and len(np.unique(cams[rows[~(t == t.min())]])) >= 2)
        out.append(ends & ok)
    return np.concatenate(out)


def _left_out(t: np.ndarray, gain: np.ndarray, window_s: float, inside: np.ndarray
              ) -> np.ndarray:
    """Indices (into ``t``) of the detections to leave out of the fit: those ``inside`` their
    piece (:func:`_inside`) whose deletion gain (:func:`deletion_gain`) exceeds
    :data:`_END_JUMP_SCALED` ² (χ²₂'s 1 - 1e-4 quantile, the level of the fit's other tests),
    taken largest first, none within ``window_s`` of one already taken. A detection the fit
    bends to also spoils its neighbours' fit, and raises their gains: the largest is the one
    to leave out first, the others' gains are measured again at the fit without it."""
    over = np.flatnonzero((gain > _END_JUMP_SCALED**2) & inside)
    if not len(over):
        return over
    order = np.argsort(-gain[over], kind="stable")
    chosen: list[int] = []
    for k in over[order]:
        if all(abs(t[k] - t[c]) > window_s for c in chosen):
            chosen.append(int(k))
    return np.sort(np.asarray(chosen, np.int64))


def deletion_gain(J: np.ndarray, cov_X: np.ndarray, r: np.ndarray, w: np.ndarray,
                  sigma: float, scale: float = 1.0) -> np.ndarray:
    """(n,) ``T_i``: how much the cost of the fit's weighted least-squares problem (its last
    reweighted step: each detection at its robust weight ``w_i``, the prior) falls when
    detection ``i`` leaves it and the rest are fitted again, in units of ``σ²``:

        T_i = w_i r_iᵀ (I - A_i)⁻¹ r_i / σ²,   A_i = w_i J_i Σ_X,i J_iᵀ / σ²

    (the deletion formula of least squares: Cook & Weisberg, *Residuals and Influence in
    Regression*, 1982, §2.2, for a 2-D observation; ``A_i`` the detection's 2 x 2 block of
    the hat matrix, ``Σ_X,i = cov_X_i / scale`` the position's covariance ``H⁻¹`` with the
    detection in it). A detection the fit agrees with (``w ≈ 1``) has ``T_i`` its deleted,
    studentized residual squared — its residual against the fit made without it, over that
    residual's standard deviation — χ²₂ when the fit is right. One the robust weights
    already discount cannot exceed ``c² = 9`` by its residual alone (``w s = s / (1 + s / c²)
    < c²``): it only can through its leverage, the fit bending to follow it (``A_i`` near
    ``I``), which the deleted residual sees and the plain one hides.

    One compiled pass with the einsums' sums where a probe finds their bits
    (:mod:`pslog.estimation._deletion`, session 44), else numpy's passes."""
    from ._deletion import deletion_numpy, deletion_terms, usable

    if usable(J, cov_X, r, w):
        return deletion_terms(J, cov_X, r, w, scale * sigma**2, sigma**2)
    return deletion_numpy(J, cov_X, r, w, sigma, scale)


def _underdetermined_ends(problem: _Problem, breaks: list[np.ndarray],
                          scaled: np.ndarray | None = None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Observation rows of the end segments the detections do not determine, and the span
    (n_pieces, 2) of each piece that they do (seconds since ``t0_ns``).

    Between a piece's end and its nearest break the segment's position and velocity are 6
    unknowns that only that segment's detections fix (the prior ties its acceleration, not
    its velocity, to the rest): two pixels of two cameras leave a two-dimensional family of
    paths, three fix it with nothing to spare, so one noisy pixel can move the end by metres
    while the covariance, linearised at that fit, stays small. Such a segment (fewer than
    ``_END_DETECTIONS`` detections, or one camera's) gives no point; its detections still
    weigh in the fit (they pull nothing the rest determines).

    The same holds where no break was placed because too few detections follow the jump
    (session 28, issue 10): a kick in the last frames of a piece (the ball then leaves the
    view, or a blackout starts) leaves one or two detections after it, and a break needs
    detections of two cameras between it and the piece's end (:func:`_end_limits`), so the
    fit carries the motion before the kick through them, metres per second off, with the
    small covariance of a well-determined segment. Their residuals show it: ``scaled``
    (the rows' residual norms over σ, in ``problem.rows``' order), the run of a piece's
    last (first) detections each beyond :data:`_END_JUMP_SCALED` (χ²₂'s 1 - 1e-4 quantile)
    is an end segment beyond an unfound jump; fewer than ``_END_DETECTIONS`` of them give
    no point either (a longer run is left to the break search)."""
    out = []
    valid = np.empty((len(problem.knots), 2))
    cams = problem.obs.camera
    start = 0
    for p, rows in enumerate(problem.rows_of_piece):
        t = problem.t[rows]
        lo, hi = float(t.min()), float(t.max())
        b = np.sort(np.asarray(breaks[p], dtype=np.float64)) if len(breaks[p]) else None
        if b is not None:
            head = t < b[0]
            if (np.count_nonzero(head) < _END_DETECTIONS
                    or len(np.unique(cams[rows[head]])) < 2):
                out.append(rows[head])
                lo = float(b[0])
            tail = t >= b[-1]
            if (np.count_nonzero(tail) < _END_DETECTIONS
                    or len(np.unique(cams[rows[tail]])) < 2):
                out.append(rows[tail])
                hi = float(np.nextafter(b[-1], -np.inf))
        if scaled is not None:
            order = np.argsort(t, kind="stable")
            bad = scaled[start + order] > _END_JUMP_SCALED
            start += len(rows)
            for run, at in ((bad[::-1], order[::-1]), (bad, order)):  # the last, the first
                k = len(run) if run.all() else int(np.argmin(run))
                if 0 < k < _END_DETECTIONS and k < len(run):
                    out.append(rows[at[:k]])
                    edge = float(t[at[k]])  # the nearest detection the fit agrees with
                    lo, hi = (lo, min(hi, edge)) if run is not bad else (max(lo, edge), hi)
        valid[p] = lo, hi
    rows_out = np.unique(np.concatenate(out)) if out else np.zeros(0, np.int64)
    return rows_out.astype(np.int64), valid


def _refit_control(problem: _Problem, X: np.ndarray) -> np.ndarray:
    """Control points on new knots closest to positions ``X`` at the observations (with the
    prior): the starting point after breaks are inserted."""
    # each position's x, y, z at weight 1e6 (x twice: the rows pair (x, y) and (z, x))
    # as the upper triangles (00, 01, 02, 11, 12, 22) of diag(2e6, 1e6, 1e6): no (n, 3, 3)
    # copy to take them from
    M = np.broadcast_to(np.array([2e6, 0.0, 0.0, 1e6, 0.0, 1e6]), (len(X), 6))
    ab, rhs = problem.points.normal_onto(M, X * [2e6, 1e6, 1e6], problem.prior_ab,
                                         problem.prior_rhs)
    U = _normal.factor(ab, rebuild=lambda: problem.points.normal_onto(
        M, X * [2e6, 1e6, 1e6], problem.prior_ab, problem.prior_rhs)[0])
    return _normal.solve(U, rhs).reshape(-1, 3)


def _refit_linearised(problem: _Problem, X: np.ndarray, r: np.ndarray, J: np.ndarray,
                      w: np.ndarray, sigma: float) -> np.ndarray:
    """Control points on new knots after breaks were inserted or moved: the Gauss–Newton
    step of the fit on the old knots, taken on the new ones — the normal equations of the
    measurements linearised at the old fit (its positions ``X``, residuals ``r``, Jacobians
    ``J`` and weights ``w`` at ``σ``) and of the prior, on the new design. It costs what
    :func:`_refit_control` (the old positions as measurements) costs and is one iteration
    of the fit that follows (session 23: one factorisation and projection fewer per knot
    change; :func:`_refit_control` remains ``sync``'s, whose clocks move the design)."""
    ab, rhs = problem.linearised_normal(J, X, r, w / sigma**2)
    U = _normal.factor(ab, rebuild=lambda: problem.linearised_normal(J, X, r, w / sigma**2)[0])
    return _normal.solve(U, rhs).reshape(-1, 3)


def variance_factor(r: np.ndarray, w: np.ndarray, sigma: float, p_eff: float) -> float:
    """``k``, the factor that scales the covariance ``H⁻¹`` (made at the robust scale ``σ``
    that weighs the fit) to the noise the residuals show, by the sandwich covariance of an
    M-estimator (Huber, *Robust Statistics*, 1981, §7.6: ``K² [Σψ² / (n - p)] / [Σψ' / n]²
    (JᵀJ)⁻¹``, ``K`` ≈ 1 for ``p`` ≪ ``n``). ``H⁻¹`` is made with the Cauchy weights ``w``
    (``H ≈ mean(w) JᵀJ / σ²``), ``ψ = w r / σ`` per row, and ``ψ'`` the derivative of the radial
    Cauchy influence averaged over a row's two pixel directions: ``w (2w - 1)`` along the
    residual, ``w`` across it, ``w²`` on average. So

        k = [Σ_i w_i² ‖r_i‖² / (n_res - p_eff)] / σ² · mean(w) / mean(w²)²,

    which is the plain weighted residual variance when every ``w`` is 1. (Session 12's review:
    ``w`` in place of ``ψ'`` understated the variance of a scale mixture by ~13 %.)
    ``n_res - p_eff`` the residual degrees of freedom of the penalised fit, ``p_eff`` the
    trace of its hat matrix (Wahba 1983, JRSS B 45: σ̂² = RSS / (n - tr A)). Noise the weights
    take out of the points (a scale mixture's noisy detections) does not count in full:
    ``w ‖r‖`` is bounded. Never below 1: a fit at the ``min_noise_px`` floor, or one whose
    weights cut more than the noise, is not made surer than its own information says. Rows
    with a non-finite residual (a point behind its camera) are left out."""
    fin = np.all(np.isfinite(r), axis=1)
    n_res = 2 * int(np.count_nonzero(fin))
    if n_res == 0 or sigma <= 0:
        return 1.0
    wf = w[fin]
    score = float(np.sum(wf * wf * np.einsum("ni,ni->n", r[fin], r[fin])))
    k = (score / (sigma**2 * max(n_res - p_eff, 1.0)) * float(np.mean(wf))
         / float(np.mean(wf * wf)) ** 2)
    return max(k, 1.0)


def _information(problem: _Problem, control: np.ndarray, sigma: float, r: np.ndarray,
                 J: np.ndarray, trace: bool = False) -> tuple[np.ndarray, float, float]:
    """The band of the control points' covariance ``H⁻¹`` at the solution, the factor
    ``sqrt(n_res / (n_res - p_eff))`` that corrects the median-based noise scale for the
    fit's effective number of parameters, and ``p_eff = Σ w tr(J Σ_X Jᵀ) / σ²`` itself (the
    trace of the hat matrix). ``trace``: ``p_eff`` as ``3m - tr(H⁻¹ P)`` (the same number
    to ~1e-14 relative, one pass over the unknowns: :mod:`pslog.estimation._hat`; ``smooth``
    since session 19), else by the detections' marginal covariances (``sync``'s)."""
    band, dof, p_eff, _ = _information_factored(problem, control, sigma, r, J, trace)
    return band, dof, p_eff


def _information_factored(problem: _Problem, control: np.ndarray, sigma: float,
                          r: np.ndarray, J: np.ndarray, trace: bool = False
                          ) -> tuple[np.ndarray, float, float, np.ndarray]:
    """:func:`_information`, and the banded Cholesky factor ``U`` of ``H`` (``H = UᵀU``, for
    :func:`bias_sensitivity`)."""
    X = problem.positions_known(control)
    s = _scaled_norms(r, sigma)
    w = 1 / (1 + s / _CAUCHY**2)
    ab, _ = problem.linearised_normal(J, X, r, w / sigma**2)
    loads: list[float] = []
    U = _normal.factor(ab, rebuild=lambda: problem.linearised_normal(J, X, r, w / sigma**2)[0],
                       loads=loads)
    band = _normal.covariance_band(U)
    if trace:
        from ._hat import hat_trace

        # tr(H⁻¹ H_data) = 3m - tr(H⁻¹ P) (- λ tr(H⁻¹) under factor's diagonal load): the
        # covariance band against the prior's
        p_eff = hat_trace(band, problem.prior_ab, loads[0] if loads else 0.0)
    else:
        cov_X = problem.points.marginal(band)
        from ._kernels import hat_diagonal

        # w tr(J Σ_X Jᵀ) per row, one compiled pass (the einsum's terms in its order)
        p_eff = float(np.sum(hat_diagonal(np.ascontiguousarray(J, dtype=np.float64), cov_X,
                                          np.ascontiguousarray(w, dtype=np.float64)))
                      / sigma**2)
    n_res = 2 * len(r)
    return band, float(np.sqrt(n_res / max(n_res - p_eff, 1.0))), p_eff, U


def bias_sensitivity(problem: _Problem, U: np.ndarray, J: np.ndarray, r: np.ndarray,
                     sigma: float) -> np.ndarray:
    """``∂ĉ/∂b`` (m, 3, 2·cameras): how the fitted control points move per pixel of a
    constant offset ``b_c`` (per camera ``c`` and image axis ``a``, column ``2c + a``) added
    to every detection of camera ``c`` — the sensitivity of a Schmidt *consider* parameter
    (Tapley, Schutz & Born, *Statistical Orbit Determination*, 2004, §6.3; Bierman,
    *Factorization Methods for Discrete Sequential Estimation*, 1977).

    The fit minimises ``Σ_i ρ(r_i) + prior``, ``r_i = π(X_i) - z_i``; at its minimum the
    implicit function theorem gives, for ``z_i → z_i + b_c`` on every detection of camera
    ``c``, ``Δĉ = H_ψ⁻¹ Σ_{i∈c} (N_i ⊗ J_iᵀ) W_i b_c / σ²`` with ``W_i`` the Hessian of the
    Cauchy cost in the residual, ``w_i I - 2 w_i² r_i r_iᵀ / (c σ)²`` (``w_i (2w_i - 1)``
    along the residual, ``w_i`` across: the M-estimator's ψ', Huber 1981 §7.6), and ``H_ψ =
    Σ (N_i N_iᵀ) ⊗ J_iᵀ W_i J_i / σ² + P``. (The IRLS weights ``w_i`` alone, the fit's own
    ``H``, miss how the weights follow the moved residuals: 23 % off the fit's response on
    a 0.3 px session.) One right-hand side per camera and axis, two banded solves per camera;
    ``U`` (the factor of ``H``) serves if ``H_ψ`` is not positive definite (residuals beyond
    ``c σ`` make ``W_i`` indefinite along them)."""
    N = problem.N
    camera = np.asarray(problem.obs.camera[problem.rows], np.int64)
    k = 2 * len(problem.rig)
    # W_i J_i / σ² (n, 2, 3): the Cauchy cost's Hessian in r_i times ∂r/∂X; row (n, 4, 3):
    # the unknown of (control point a, coord d)
    WJ, factor, row, n3 = _consider_system(problem, U, J, r, sigma)
    rhs = np.zeros(n3 * k)
    for a in range(2):  # column 2c + a: Σ_{i∈c} N_i ⊗ (J_iᵀ W_i e_a) / σ²
        value = N[:, :, None] * WJ[:, a, None, :]  # (n, 4, 3); W symmetric
        rhs += np.bincount((row * k + (2 * camera + a)[:, None, None]).ravel(), value.ravel(),
                           minlength=n3 * k)
    return _normal.solve(factor, rhs.reshape(n3, k)).reshape(-1, 3, k)


def pixel_sensitivity(problem: _Problem, U: np.ndarray, J: np.ndarray, r: np.ndarray,
                      sigma: float, shifts: np.ndarray) -> np.ndarray:
    """``∂ĉ/∂β`` (m, 3, k): how the fitted control points move per unit of each of ``k``
    consider parameters ``β_j`` that add ``shifts[i, :, j] β_j`` pixels to detection ``i``
    (``shifts``: (n, 2, k), the problem's rows) — :func:`bias_sensitivity`'s implicit
    function theorem with any per-detection shift: ``Δĉ_j = H_ψ⁻¹ Σ_i (N_i ⊗ J_iᵀ W_i
    shifts_ij) / σ²``, ``W_i`` the Cauchy cost's Hessian in the residual and ``H_ψ`` its
    normal matrix (there; ``U`` where ``H_ψ`` is not positive definite). The clocks' columns
    (:func:`pslog.fusion.clock.pixel_errors`): a clock error is the pixel error it makes at
    the stated times."""
    WJ, factor, row, n3 = _consider_system(problem, U, J, r, sigma)
    g = np.einsum("naj,nak->njk", WJ, shifts)  # (n, 3, k): J_iᵀ W_i shifts_i / σ²
    k = shifts.shape[2]
    rhs = np.zeros((n3, k))
    flat = row.ravel()
    for j in range(k):
        rhs[:, j] = np.bincount(flat, (problem.N[:, :, None] * g[:, None, :, j]).ravel(),
                                minlength=n3)
    return _normal.solve(factor, rhs).reshape(-1, 3, k)


def _consider_system(problem: _Problem, U: np.ndarray, J: np.ndarray, r: np.ndarray,
                     sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """What :func:`pixel_sensitivity` and :func:`bias_sensitivity` solve with: ``W_i J_i /
    σ²`` (n, 2, 3), the factor of ``H_ψ`` (or ``U``), each detection's unknowns' rows
    (n, 4, 3) and their count."""
    first = problem.first
    n3 = U.shape[1]
    s = np.sum(r * r, axis=1) / sigma**2
    w = 1 / (1 + s / _CAUCHY**2)
    W = (w[:, None, None] * np.eye(2)
         - (2 * w * w / (_CAUCHY * sigma) ** 2)[:, None, None] * r[:, :, None] * r[:, None, :])
    WJ = np.einsum("nab,nbj->naj", W, J) / sigma**2
    ab, _ = problem.points.normal_onto(np.einsum("nai,naj->nij", J, WJ),
                                       np.zeros((len(J), 3)), problem.prior_ab,
                                       problem.prior_rhs)
    try:
        factor = _normal.factor(ab)
    except FusionError:
        factor = U
    row = 3 * (np.asarray(first, np.int64)[:, None, None] + np.arange(4)[None, :, None]) \
        + np.arange(3)[None, None, :]
    return WJ, factor, row, n3


def _add_consider(cov: np.ndarray, rows: np.ndarray | slice, trajectory: Trajectory,
                  first: np.ndarray, N: np.ndarray) -> None:
    """Add the consider parameters' covariance to ``cov[rows]`` (``rows`` an index array or
    a slice; points ``Σ_a N_a c[first + a]``): the detector's common 3-D offset,
    ``offset_m² I₃`` — a constant shift of every
    detection's ball moves the fit by exactly that shift (the B-splines sum to one, the
    prior (2) sees only the path's second and third derivatives, the robust weights the
    same residuals), so its sensitivity is ``I₃`` at every point — and each camera's pixel
    bias, ``S Sᵀ`` (:func:`bias_sensitivity`, :func:`consider_points`)."""
    if trajectory.offset_m > 0:
        diagonal = np.arange(3)
        where = rows if isinstance(rows, slice) else rows[:, None]
        cov[where, diagonal, diagonal] += trajectory.offset_m**2
    if trajectory.consider is not None:
        S = consider_points(trajectory.consider, first, N)
        cov[rows] += np.einsum("nik,njk->nij", S, S)


def consider_points(consider: np.ndarray, first: np.ndarray, N: np.ndarray) -> np.ndarray:
    """``S_i = Σ_a N_ia A[first_i + a]`` (n, 3, k): the points' sensitivities to the consider
    parameters from the control points' ``A`` (m, 3, k); the points' covariance gains
    ``S_i S_iᵀ`` (with ``A`` already scaled by the parameters' standard deviations)."""
    S = np.zeros((len(first), 3, consider.shape[2]))
    for a in range(DEGREE + 1):
        S += N[:, a, None, None] * consider[first + a]
    return S


def _find_breaks(problem: _Problem, control: np.ndarray, sigma: float, r: np.ndarray,
                 w: np.ndarray, J: np.ndarray, spacing: float, known: list[np.ndarray],
                 options: SmoothOptions, near: list[np.ndarray] | None = None
                 ) -> list[np.ndarray]:
    """Times of new velocity jumps in each piece (seconds since the first observation), none
    within a knot spacing of a ``known`` one (and, with ``near``, the breaks the previous
    round added, only peaks within reach of their local problems: a peak further away sees
    the same local fit as in that round, which rejected it): the peaks of ``‖p'' - g‖`` above
    ``break_accel``, each kept if a break near it gains more than ``break_threshold``."""
    X = problem.positions_known(control)
    target = _linear_target(J, X, r)  # the linearised measurements
    weight = w / sigma**2
    t_obs = problem.t[problem.rows]
    mids, devs = _span_deviations(problem, control, options)
    jobs = []
    row0 = 0
    for p, dev in enumerate(devs):
        # the piece's rows in time order (the clock estimator moves the times)
        here = row0 + np.argsort(t_obs[row0:row0 + len(problem.rows_of_piece[p])],
                                 kind="stable")
        row0 += len(problem.rows_of_piece[p])
        peak = dev > options.break_accel
        peak[1:] &= dev[1:] >= dev[:-1]
        peak[:-1] &= dev[:-1] > dev[1:]
        centers = mids[p][peak]
        t = t_obs[here]
        if near is not None:  # after the first round: only peaks a new break's fit moved
            reach = (_WINDOW_SPANS + 2) * spacing
            centers = centers[_nearest_distance(centers, near[p]) <= reach]
        if len(t) < 8 or len(centers) == 0:
            continue
        # the jump lies near the peak: search two detections beyond its neighbours, leaving
        # detections of two cameras in the piece at either end (:func:`_end_limits`)
        j = np.searchsorted(t, centers)
        first_ok, last_ok = _end_limits(t, problem.obs.camera[problem.rows][here])
        a = np.maximum(t[np.clip(j - 3, 0, len(t) - 1)], first_ok)
        b = np.minimum(t[np.clip(j + 2, 0, len(t) - 1)], last_ok)
        side = _neighbours(centers, known[p])
        a, b = _free_bounds(a, b, side, spacing)
        ok = a < b
        centers, a, b, side = centers[ok], a[ok], b[ok], side[ok]
        if len(centers) == 0:
            continue
        jobs.append((p, here, centers, np.stack([a, b], axis=1), side))
    results = _scan_pieces(jobs, t_obs, J, target, weight, spacing, options)
    out = [np.zeros(0) for _ in problem.knots]
    for (p, *_), (tau, gain) in zip(jobs, results, strict=True):
        # (a spacing to the rounding of the bounds, which leave one exactly: the best
        # instant at that end is free, whatever ``side + h``'s last bit)
        free = _free_of(tau, known[p], spacing)
        out[p] = _greedy_breaks(tau, gain, free, options.break_threshold, 1.5 * spacing)
    return out


def _span_deviations(problem: _Problem, control: np.ndarray, options: SmoothOptions
                     ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per piece, every span's midpoint (s) and ``‖p'' - g‖`` there (m/s²) of the fit
    ``control`` on ``problem``'s knots: the find's peaks (:func:`_find_breaks`) and the
    screen of :func:`_one_against_two`."""
    g = np.asarray(options.prior.gravity)
    # ‖p'' - g‖ at every span's midpoint of every piece, in one pass (the second
    # derivative's basis alone, and its sums in one compiled pass: the bits of every
    # derivative's basis and numpy's einsum over its row, which they replaced in session 24)
    mids = [((k[:-1] + k[1:]) / 2)[k[1:] > k[:-1]] for k in problem.knots]
    piece = np.repeat(np.arange(len(mids)), [len(x) for x in mids])
    from ._kernels import points_positions

    first, N2 = basis_pieces(problem.knots, piece, np.concatenate(mids), only=2)
    accel = points_positions(np.ascontiguousarray(first, dtype=np.int64), N2,
                             np.ascontiguousarray(control, dtype=np.float64))
    devs = np.split(np.linalg.norm(accel - g, axis=1), np.cumsum([len(x) for x in mids])[:-1])
    return mids, devs


def _free_bounds(a: np.ndarray, b: np.ndarray, side: np.ndarray, spacing: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A candidate's search bounds ``[a, b]`` without the instants a knot spacing or less
    from its neighbouring known breaks ``side`` (C, 2) (no new break may lie there).

    Session 25 (issue 10): the candidates were the peaks of ``‖p'' − g‖`` at knot spans'
    midpoints more than a spacing from every known break. Where two velocity jumps are
    1.5–2 spacings apart (a bounce and a kick 80 ms apart, ``h`` 40–50 ms), the loose fit
    with the first break shows the second as a peak 1–1.2 ``h`` from it: whether that
    midpoint fell beyond ``h`` depended on the knot grid's phase, which a fault seconds away
    moves, and the second jump was then not searched at all (its points 5–15 cm off). The
    peak is now searched wherever it lies, over the instants a new break may take."""
    return np.maximum(a, side[:, 0] + spacing), np.minimum(b, side[:, 1] - spacing)


def _free_of(tau: np.ndarray, known: np.ndarray, spacing: float) -> np.ndarray:
    """(C,) bool: whether each instant ``tau`` (C,) s is a knot spacing or more from every
    ``known`` break — to a relative 1e-9 of the spacing: :func:`_free_bounds` leaves an
    instant exactly a spacing from a neighbour (``side + h``), and whether ``|τ - side|``
    then exceeds ``h`` was the rounding's last bit (session 43: ``paper2`` rally-72701 of
    ``bench_dirty.py --more --first-seed 72700 --misses 0.1``, the second of two kicks 81 ms
    apart found at that end, 61.1 ms = ``h`` from the first's break: not free, the kick
    without a break and 6 points to 119 mm; clean, the same candidate 61.5 ms away, found)."""
    return _nearest_distance(tau, known) > spacing * (1 - 1e-9)


def _greedy_breaks(tau: np.ndarray, gain: np.ndarray, free: np.ndarray, threshold: float,
                   apart: float) -> np.ndarray:
    """The breaks kept (sorted): greedily by gain, each above ``threshold``, ``free`` (a knot
    spacing from every known break) and more than ``apart`` from every one kept before.

    A candidate whose nearest rivals in time (the others above the threshold and free) are
    all more than ``apart`` away is kept whatever the order (and blocks none): only the
    rest, in clusters, go through the greedy loop (nearly all of a session's candidates
    are alone: the loop over every one took ~10 ms per 10,000). The same breaks as the
    loop over all of them (``|x - y|`` is monotone in ``y``: the nearest rival decides)."""
    order = np.argsort(-gain)
    isolated = np.zeros(len(tau), dtype=bool)
    if np.any(np.isnan(gain)) or np.any(np.isnan(tau)):  # (the scan gives none) the loop
        loop = order
    else:
        rival = (gain > threshold) & free
        where = np.flatnonzero(rival)
        ts = tau[where]
        by_time = np.argsort(ts, kind="stable")
        sorted_t = ts[by_time]
        alone = np.ones(len(where), dtype=bool)
        if len(where) > 1:
            near = np.abs(sorted_t[1:] - sorted_t[:-1]) <= apart
            alone[1:] &= ~near
            alone[:-1] &= ~near
        isolated[where[by_time[alone]]] = True
        loop = order[rival[order] & ~isolated[order]]  # (gains above the threshold, free)
    found: list[float] = []  # in time order: the clustered candidates kept
    for i in loop:
        if gain[i] <= threshold:
            break
        k = bisect.bisect_left(found, tau[i])
        if free[i] and (k == len(found) or abs(tau[i] - found[k]) > apart) and (
                k == 0 or abs(tau[i] - found[k - 1]) > apart):
            found.insert(k, float(tau[i]))
    return np.sort(np.r_[tau[isolated], np.array(found)])


def _scan_terms(J: np.ndarray, w: np.ndarray, sigma: float) -> tuple:
    """:func:`_breaks.detection_terms` of every fitted detection (``J`` (n, 2, 3), weights
    ``w`` (n,) at ``σ``, the scans' ``w / σ²``): the ``terms`` of :func:`_scan_pieces`."""
    empty = np.zeros(0, np.int64)
    return _breaks.detection_terms(J, w / sigma**2, empty, empty)


def _scan_pieces(jobs: list, t_obs: np.ndarray, J: np.ndarray, target: np.ndarray,
                 weight: np.ndarray, spacing: float, options: SmoothOptions,
                 near: bool = False, narrow: bool = False, gains: bool = False,
                 terms: tuple | None = None) -> list:
    """:func:`_breaks.scan` (``near``: :func:`_breaks.scan_near`, with ``narrow`` its
    narrow form) of every piece's candidates in one batched call.

    jobs : list of (piece, rows in time order, centres (C,), bounds (C, 2), limits (C, 2));
    each window is also cut at its piece's first and last detection, so the pieces' rows
    laid end to end (in time order: the pieces follow each other in time) serve as one.
    ``gains``: :func:`_breaks.gain_at` (each job's bounds ``[τ, τ]``), the gain of a break at
    each centre. ``terms``: :func:`_breaks.detection_terms` of every fitted detection's
    ``J``, ``weight`` (the refine's and the confirmation's scans of one linearisation
    share them), or None. Returns a (tau, gain) per job (``near``: (tau, edge))."""
    if not jobs:
        return []
    search = (_breaks.gain_at if gains else
              partial(_breaks.scan_near, narrow=narrow) if near else _breaks.scan)
    order = np.concatenate([here for _, here, *_ in jobs])
    rows: np.ndarray | slice = order
    if len(order) and np.array_equal(order, np.arange(order[0], order[0] + len(order))):
        # the rows in order already (a session's pieces in time order): views, not copies
        # of a whole session's Jacobians, targets and weights (the same values)
        rows = slice(int(order[0]), int(order[0]) + len(order))
    t = t_obs[rows]
    if np.any(np.diff(t) < 0):  # moved times made pieces overlap: one piece at a time
        return [_scan_pieces([job], t_obs, J, target, weight, spacing, options, near,
                             narrow, gains)[0] for job in jobs] if len(jobs) > 1 else [search(
                    t, J[rows], target[rows], weight[rows], jobs[0][2], jobs[0][3],
                    jobs[0][4], spacing, _WINDOW_SPANS * spacing, options.prior)]
    limits = np.concatenate([np.stack([np.maximum(lim[:, 0], t_obs[here[0]]),
                                       np.minimum(lim[:, 1], t_obs[here[-1]])], axis=1)
                             for _, here, _, _, lim in jobs])
    # the shared terms of these rows (a slice of them: a row's terms are the same whichever
    # rows are formed with it)
    held = (terms[0][rows], terms[1], terms[2]) if (
        terms is not None and isinstance(rows, slice)) else None
    tau, gain = search(t, J[rows], target[rows], weight[rows],
                       np.concatenate([c for _, _, c, _, _ in jobs]),
                       np.concatenate([b for _, _, _, b, _ in jobs]), limits, spacing,
                       _WINDOW_SPANS * spacing, options.prior, terms=held)
    cuts = np.cumsum([len(c) for _, _, c, _, _ in jobs])[:-1]
    return list(zip(np.split(tau, cuts), np.split(gain, cuts), strict=True))


def _end_limits(t: np.ndarray, camera: np.ndarray) -> tuple[float, float]:
    """Earliest and latest instants a break may take in a piece: the segment it leaves at
    either end must hold two detections of two cameras (its velocity is otherwise free along a
    ray)."""
    first_two = np.flatnonzero(camera != camera[0])
    last_two = np.flatnonzero(camera != camera[-1])
    lo = t[max(int(first_two[0]) if len(first_two) else len(t) - 1, 1)]
    hi = t[min(int(last_two[-1]) if len(last_two) else 0, len(t) - 2)]
    # a detection at the break's instant belongs to the segment after it
    return float(lo) + 1e-6, float(hi)


def _nearest_distance(x: np.ndarray, known: np.ndarray) -> np.ndarray:
    """``min_k |x_i - known_k|`` (n,) (inf where ``known`` is empty), in O((n + k) log k):
    the nearest of a sorted set is one of the two around ``x_i``, and ``fl(x - k)`` is
    monotone in ``k``, so this is bit for bit the minimum over every pair (a session of
    10,000 breaks would otherwise compare every candidate with every break)."""
    if len(known) == 0:
        return np.full(len(x), np.inf)
    known = np.sort(known)
    j = np.searchsorted(known, x)
    below = np.abs(x - known[np.maximum(j - 1, 0)])
    above = np.abs(known[np.minimum(j, len(known) - 1)] - x)
    return np.minimum(below, above)


def _neighbours(centers: np.ndarray, known: np.ndarray) -> np.ndarray:
    """(C, 2) the nearest known break below and above each centre (±inf if none)."""
    known = np.sort(known)
    j = np.searchsorted(known, centers)
    below = np.where(j > 0, known[np.maximum(j - 1, 0)] if len(known) else 0.0, -np.inf)
    above = np.where(j < len(known), known[np.minimum(j, len(known) - 1)]
                     if len(known) else 0.0, np.inf)
    return np.stack([below, above], axis=1)


def _refine_breaks(problem: _Problem, control: np.ndarray, sigma: float, r: np.ndarray,
                   w: np.ndarray, J: np.ndarray, spacing: float, breaks: list[np.ndarray],
                   options: SmoothOptions, terms: tuple | None = None) -> list[np.ndarray]:
    """Each break's time re-estimated on the problem linearised at the final fit, the
    neighbouring breaks held (the first estimate was linearised at the loose fit): within
    ``_REFINE_STAGES[0]`` spacings of it (:func:`_breaks.scan_near` ``narrow``: one base,
    3 + 3 + 1 trials), then for the breaks whose best first-stage trial was at an end of
    that interval (the optimum may lie beyond it) within a quarter knot spacing
    (:func:`_breaks.scan_near`: 5 + 6 + 1 trials), and for those whose best first-stage
    trial was at an end of that, within a knot spacing (:func:`_breaks.scan`). Each stage's
    bounds lie inside the whole spacing's; an end that is the whole spacing's sends no
    break further.

    Two breaks the refinement brought within a knot spacing merge into one
    (:func:`_one_per_span`); then the breaks are searched again from where the pass left
    them (their neighbours held there), the one dropped gone — only those beside it (their
    neighbour held in their search is gone) and those the pass moved by more than
    ``_REFINE_AGAIN`` spacings (a second search moves the others by a median 0.1 µs); the
    rest keep their instants (session 29: before, every break was searched again, a
    90-minute match's 10,224 for its one merge: the refine 1.01 → 0.63 CPU s; docs/methods.md,
    "`smooth` at 90 minutes (session 29)")."""
    out, dropped = _refine_pass(problem, control, sigma, r, w, J, spacing, breaks, options,
                                None, terms)
    while any(len(d) for d in dropped):
        only = []
        for known, gone, old in zip(out, dropped, breaks, strict=True):
            mask = np.zeros(len(known), dtype=bool)
            if len(gone) and len(known):  # the breaks either side of each dropped one
                j = np.searchsorted(known, gone)
                mask[j[j < len(known)]] = True
                mask[j[j > 0] - 1] = True
            if len(known) and len(old):  # and those this pass moved far (old: its input)
                k = np.searchsorted(old, known)
                below = old[np.maximum(k - 1, 0)]
                above = old[np.minimum(k, len(old) - 1)]
                moved = np.minimum(np.abs(known - below), np.abs(known - above))
                mask |= moved > _REFINE_AGAIN * spacing
            only.append(mask)
        breaks = out
        out, dropped = _refine_pass(problem, control, sigma, r, w, J, spacing, out, options,
                                    only, terms)
    return out


def _pieces_with_breaks(problem: _Problem, t_obs: np.ndarray, breaks: list[np.ndarray]):
    """Per piece with breaks, for the searches of its breaks on the fitted rows ``t_obs``
    (``problem.t[problem.rows]``): ``(piece, its rows in time order (the clock estimator
    moves the times), its breaks, the first and last instants a break may take
    (:func:`_end_limits`), each break's limits (C, 2): its neighbours, ±inf at the ends)``."""
    cameras = problem.obs.camera[problem.rows]
    row0 = 0
    for p, known in enumerate(breaks):
        n = len(problem.rows_of_piece[p])
        if len(known) == 0:  # (its rows' order is not needed)
            row0 += n
            continue
        here = row0 + np.argsort(t_obs[row0:row0 + n], kind="stable")
        row0 += n
        first_ok, last_ok = _end_limits(t_obs[here], cameras[here])
        limits = np.stack([np.r_[-np.inf, known[:-1]], np.r_[known[1:], np.inf]], axis=1)
        yield p, here, known, first_ok, last_ok, limits


def _refine_pass(problem: _Problem, control: np.ndarray, sigma: float, r: np.ndarray,
                 w: np.ndarray, J: np.ndarray, spacing: float, breaks: list[np.ndarray],
                 options: SmoothOptions, only: list[np.ndarray] | None,
                 terms: tuple | None = None) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """One pass of :func:`_refine_breaks` over the breaks ``only`` marks (per piece, a
    mask over its breaks; None: all), the others kept where they are: ``(breaks, dropped)``
    per piece, the breaks sorted, at most one per knot spacing, and the instants that
    merged into a neighbour (dropped)."""
    X = problem.positions_known(control)
    target = _linear_target(J, X, r)
    weight = w / sigma**2
    t_obs = problem.t[problem.rows]
    # per piece with breaks to search: (piece, rows in time order, breaks, whole spacing's
    # bounds, limits); per piece with breaks: (piece, its breaks, which are searched)
    wide, kept = [], []
    for p, here, known, first_ok, last_ok, limits in _pieces_with_breaks(problem, t_obs,
                                                                         breaks):
        a = np.maximum(known - spacing, first_ok)
        b = np.minimum(known + spacing, last_ok)
        ok = a < b
        search = ok if only is None else ok & only[p]
        kept.append((p, here, known[ok], search[ok]))
        if np.any(search):
            wide.append((p, here, known[search], np.stack([a[search], b[search]], axis=1),
                         limits[search]))
    taus = [job[2].copy() for job in wide]  # the breaks, each replaced once searched
    # which of each job's breaks the next stage searches (all, at first)
    todo = [np.arange(len(job[2])) for job in wide]
    for stage in (*_REFINE_STAGES, None):
        reach = None if stage is None else stage * spacing
        jobs, at = [], []
        for k, ((p, here, known, full, limits), idx) in enumerate(zip(wide, todo,
                                                                      strict=True)):
            if len(idx) == 0:
                continue
            full = full[idx]
            if reach is None:  # the whole spacing, around the break as the find left it
                jobs.append((p, here, known[idx], full, limits[idx]))
            else:
                # around each break, inside the whole spacing's bounds (which a break the
                # moved detections no longer allow may lie outside of)
                centre = np.clip(known[idx], full[:, 0], full[:, 1])
                jobs.append((p, here, centre,
                             np.stack([np.maximum(centre - reach, full[:, 0]),
                                       np.minimum(centre + reach, full[:, 1])], axis=1),
                             limits[idx]))
            at.append((k, idx))
        if not jobs:
            break
        results = _scan_pieces(jobs, t_obs, J, target, weight, spacing, options,
                               near=stage is not None, narrow=stage == _REFINE_STAGES[0],
                               terms=terms)
        todo = [np.zeros(0, np.int64) for _ in wide]
        for (k, rows), job, (tau, edge) in zip(at, jobs, results, strict=True):
            taus[k][rows] = tau
            if reach is not None:
                # the first stage peaked at an end that is not the whole spacing's
                bounds, full = job[3], wide[k][3][rows]
                redo = (((edge < 0) & (bounds[:, 0] > full[:, 0]))
                        | ((edge > 0) & (bounds[:, 1] < full[:, 1])))
                todo[k] = rows[redo]
    searched = {job[0]: tau for job, tau in zip(wide, taus, strict=True)}
    out = [np.zeros(0) for _ in breaks]
    dropped = [np.zeros(0) for _ in breaks]
    refined, moved = [], []
    for p, here, known, search in kept:
        tau = known.copy()
        if p in searched:
            tau[search] = searched[p]
        refined.append((p, here, tau))
        moved.append(np.abs(tau - known))
    # (the gains of the breaks within a spacing of another: which of them stays)
    gains = _crowded_gains(refined, t_obs, J, target, weight, spacing, options, terms)
    for (p, _, tau), how_far, gain in zip(refined, moved, gains, strict=True):
        # a break the moved detections no longer allow (too near a piece's end) is dropped
        out[p] = _one_per_span(tau, how_far, spacing, gain)
        if len(out[p]) < len(tau):  # merged: the instants that went
            dropped[p] = np.setdiff1d(tau, out[p])
    return out, dropped


def _crowded_gains(refined: list, t_obs: np.ndarray, J: np.ndarray, target: np.ndarray,
                   weight: np.ndarray, spacing: float, options: SmoothOptions,
                   terms: tuple | None = None) -> list[np.ndarray]:
    """Per piece ``(piece, rows in time order, refined breaks (b,))`` of ``refined``: the
    gain (b,) (σ² units, :func:`_breaks.gain_at`) of each break that lies within a knot
    spacing of a neighbour, on the problem linearised at the fit the refine ran at, its
    window cut at the nearest breaks *outside* its crowd (a run of breaks each within a
    spacing of the next: of those only one stays, :func:`_one_per_span`, so none of the
    others bounds the test of its rivals); NaN for the breaks alone (their gain decides
    nothing). Each crowded break's gain is the likelihood ratio of that break alone in the
    crowd's place: the same test for each rival, on the same detections."""
    jobs, where = [], []
    out = []
    for k, (p, here, tau) in enumerate(refined):
        out.append(np.full(len(tau), np.nan))
        order = np.argsort(tau)
        s = tau[order]
        close = np.diff(s) <= spacing
        if not np.any(close):
            continue
        crowded = np.zeros(len(s), dtype=bool)
        crowded[1:] |= close
        crowded[:-1] |= close
        crowd = np.cumsum(np.r_[True, ~close])  # (sorted breaks' runs, numbered from 1)
        first = np.searchsorted(crowd, crowd, side="left")
        last = np.searchsorted(crowd, crowd, side="right") - 1
        lo = np.where(first > 0, s[np.maximum(first - 1, 0)], -np.inf)
        hi = np.where(last < len(s) - 1, s[np.minimum(last + 1, len(s) - 1)], np.inf)
        m = np.flatnonzero(crowded)
        jobs.append((p, here, s[m], np.stack([s[m], s[m]], axis=1),
                     np.stack([lo[m], hi[m]], axis=1)))
        where.append((k, order[m]))
    results = _scan_pieces(jobs, t_obs, J, target, weight, spacing, options, gains=True,
                           terms=terms)
    for (k, idx), (_, gain) in zip(where, results, strict=True):
        out[k][idx] = gain
    return out


def _confirmed_breaks(problem: _Problem, control: np.ndarray, sigma: float, r: np.ndarray,
                      w: np.ndarray, J: np.ndarray, spacing: float, breaks: list[np.ndarray],
                      options: SmoothOptions, terms: tuple | None = None
                      ) -> list[np.ndarray]:
    """The refined ``breaks`` that gain more than ``break_threshold`` on the problem
    linearised at the fit under the real prior (``control``, ``sigma``: the fit the refine
    ran at), each at its refined instant (the refine's optimum on the same linearisation),
    its neighbours held (:func:`_breaks.gain_at`: one trial); the others dropped. A break
    the piece's end limits no longer allow (:func:`_end_limits`), or whose solve failed, is
    kept.

    Session 35 (issue 10): the find tests each break at the loose fit (σ_a ten times the
    real prior's), whose freedom lets a noise pattern pass for a velocity jump: a
    constant-velocity line got one (``lab3`` ``straight`` with a camera blind: the blackout's
    points 12 % worse than the two remaining cameras give; 16 breaks in 300 jump-free
    sessions). The break is a model choice of the trajectory output, which is fitted under
    the real prior: it must lower that fit's cost by the same 25 σ² (docs/methods.md,
    "`lab3`'s `straight` at 1.21")."""
    X = problem.positions_known(control)
    target = _linear_target(J, X, r)
    t_obs = problem.t[problem.rows]
    jobs, ok_of = [], {}
    for p, here, known, first_ok, last_ok, limits in _pieces_with_breaks(problem, t_obs,
                                                                         breaks):
        ok = (known >= first_ok) & (known <= last_ok)
        if not np.any(ok):
            continue
        jobs.append((p, here, known[ok], np.stack([known[ok], known[ok]], axis=1),
                     limits[ok]))
        ok_of[p] = ok
    results = _scan_pieces(jobs, t_obs, J, target, w / sigma**2, spacing, options,
                           gains=True, terms=terms)
    out = [np.asarray(b, dtype=np.float64) for b in breaks]
    reach = _WINDOW_SPANS * spacing
    for (p, here, known, _, limits), (_, gain) in zip(jobs, results, strict=True):
        # (a failed solve's gain, -inf, says nothing against the break: kept)
        passed = (gain > options.break_threshold) | ~np.isfinite(gain)
        # a break whose window a neighbour cut: tested again with its neighbours in it
        cut = ~passed & ((known - limits[:, 0] < reach) | (limits[:, 1] - known < reach))
        t_here = t_obs[here] if np.any(cut) else t_obs[:0]
        for i in np.flatnonzero(cut):
            passed[i] = _gain_in_context(problem, X, r, J, w, sigma, spacing, here, t_here,
                                         out[p], float(known[i])) > options.break_threshold
        keep = np.ones(len(out[p]), dtype=bool)
        keep[ok_of[p]] = passed
        out[p] = out[p][keep]
    return out


def _two_against_one(problem: _Problem, control: np.ndarray, sigma: float, r: np.ndarray,
                     w: np.ndarray, J: np.ndarray, spacing: float, breaks: list[np.ndarray],
                     options: SmoothOptions, terms: tuple | None = None
                     ) -> list[np.ndarray]:
    """The refined ``breaks`` with each two of them less than ``_CLOSE_SPANS`` knot spacings
    apart tested against one break in their place: the one's best instant searched
    (:func:`_breaks.scan` on the problem linearised at the fit, over ``[b₁ − h/4, b₂ + h/4]``
    at least a spacing from the breaks beyond the pair, its window cut at them), then both
    models' least costs on the same detections with every near break in the model
    (:func:`_region_costs`, as :func:`_gain_in_context`): the pair stays only where its
    second break gains more than ``break_threshold`` over the one (σ² units, the likelihood
    ratio every break must pass). Only where the one lies at neither of the pair's instants
    (farther than the refine's first stage, ``h/16``, from both): a one at one of them asks
    whether the other break is needed, which :func:`_confirmed_breaks` decides (held out:
    ``wide3`` rally-72507 of ``--first-seed 72500``, a weak kick 80 ms after another, its
    break 17.6 σ² over the one in context; dropped here, a point 44 mm off). Of pairs that
    share a break or lie side by side, the one whose second break gains least is merged.

    Session 45: a kick between two breaks the fit kept, on neither (``paper3`` rally-78502
    of ``bench_dirty.py --more --first-seed 78500`` with the faults: kick 5.5820 s, breaks
    5.5505 and 5.6000, h 37.56 ms; a point 54 mm off): each break alone explained part of
    the jump, so each passed its test with the other held, and the refine, which moves one
    break at a time, could not bring either onto the kick."""
    close_in = [len(b) > 1 and bool(np.any(np.diff(b) <= _CLOSE_SPANS * spacing))
                for b in breaks]
    if not any(close_in):  # (nearly every session: no rows formed)
        return breaks
    reach = _WINDOW_SPANS * spacing
    t_obs = problem.t[problem.rows]
    pairs = []
    for p, here, known, first_ok, last_ok, _ in _pieces_with_breaks(problem, t_obs, [
            b if c else b[:0] for b, c in zip(breaks, close_in, strict=True)]):
        if len(known) < 2:
            continue
        close = np.flatnonzero((np.diff(known) <= _CLOSE_SPANS * spacing)
                               & (known[:-1] >= first_ok) & (known[1:] <= last_ok))
        if len(close):
            pairs.append((p, here, known, first_ok, last_ok, close))
    if not pairs:
        return breaks
    X = problem.positions_known(control)
    target = _linear_target(J, X, r)
    jobs = []
    for p, here, known, first_ok, last_ok, close in pairs:
        b1, b2 = known[close], known[close + 1]
        b0 = np.where(close > 0, known[np.maximum(close - 1, 0)], -np.inf)
        b3 = np.where(close + 2 < len(known), known[np.minimum(close + 2, len(known) - 1)],
                      np.inf)
        a = np.maximum.reduce([b1 - spacing / 4, b0 + spacing, np.full(len(b1), first_ok)])
        b = np.minimum.reduce([b2 + spacing / 4, b3 - spacing, np.full(len(b1), last_ok)])
        jobs.append((p, here, (a + b) / 2, np.stack([a, np.maximum(a, b)], axis=1),
                     np.stack([b0, b3], axis=1)))
    results = _scan_pieces(jobs, t_obs, J, target, w / sigma**2, spacing, options,
                           terms=terms)
    out = [np.asarray(x, dtype=np.float64) for x in breaks]
    for (p, here, known, _, _, close), job, (tau, _) in zip(pairs, jobs, results,
                                                            strict=True):
        t_here = t_obs[here]
        second = []  # (what the pair's second break gains over the one, pair, the one)
        for k, i in enumerate(close):
            pair = known[i:i + 2]
            if not job[3][k, 0] < job[3][k, 1] or not np.isfinite(tau[k]) or np.min(
                    np.abs(pair - tau[k])) <= _REFINE_STAGES[0] * spacing:
                continue
            near = known[(known > pair[0] - reach) & (known < pair[1] + reach)]
            cost = _region_costs(problem, X, r, J, w, sigma, spacing, here, t_here,
                                 float(near.min()) - reach, float(near.max()) + reach, known,
                                 [(np.zeros(0), np.zeros(0)), (pair, tau[k:k + 1])])
            if cost is not None and cost[1] - cost[0] <= options.break_threshold:
                second.append((cost[1] - cost[0], i, float(tau[k])))
        used = np.zeros(len(known), dtype=bool)
        keep = np.ones(len(known), dtype=bool)
        one = []
        for _, i, t_one in sorted(second):
            if used[i] or used[i + 1]:
                continue
            # (the pairs beside it searched their one with this pair's breaks as bounds)
            used[max(i - 1, 0):i + 3] = True
            keep[i:i + 2] = False
            one.append(t_one)
        if one:
            out[p] = np.sort(np.r_[known[keep], one])
    return out


def _one_against_two(problem: _Problem, control: np.ndarray, sigma: float, r: np.ndarray,
                     w: np.ndarray, J: np.ndarray, spacing: float, breaks: list[np.ndarray],
                     options: SmoothOptions, terms: tuple | None = None
                     ) -> list[np.ndarray]:
    """The refined ``breaks`` with each one tested against two breaks in its place (the
    converse of :func:`_two_against_one`): pairs ``τ₁ ≤ b ≤ τ₂`` around the break ``b``,
    more than a knot spacing and at most ``_CLOSE_SPANS`` spacings apart, on a grid of
    ``h/_ONE_GRID``, each more than a spacing from the breaks beside ``b`` and within the
    piece's end limits (:func:`_end_limits`); every pair's least cost and the one's on the
    same detections with every near break in the model (:func:`_region_costs`, as
    :func:`_two_against_one`). The best pair replaces ``b`` where its second break gains more
    than ``break_threshold`` over the one (σ² units: the threshold every break must pass, and
    the one :func:`_two_against_one` merges a pair below, so the two rules cannot undo each
    other), its instants polished in the same context (``_ONE_POLISH`` stages of 3 x 3
    trials, to h/64: the refine moves one break with its neighbour held, and of two breaks
    with a gap of detections between them either is free anywhere in it). Only the breaks
    the fit bends around are tested: a span midpoint within ``_CLOSE_SPANS`` spacings of
    ``b`` where ``‖p'' - g‖`` of the fit exceeds ``break_accel`` (the find's peak level,
    :func:`_span_deviations`); of breaks side by side, the one whose pair gains most.

    Session 46: two kicks 80 ms apart (``paper3`` rally 74069 with misses, cut to
    2.49-3.77 s, h 49.85 ms; kicks 3.0873 and 3.1673 s): the loose fit's first break sat
    between them (3.1311), within a spacing of both, so the find could search no second;
    the refine moved it onto the later kick, and the earlier (1.6 spacings before it) had
    no break: points to 83 mm. The pair gains 204 σ² over the one there."""
    span = _CLOSE_SPANS * spacing
    mids, devs = _span_deviations(problem, control, options)
    hot = []
    for known, m, d in zip(breaks, mids, devs, strict=True):
        peaks = m[d > options.break_accel]
        hot.append(_nearest_distance(known, peaks) < span if len(known) and len(peaks)
                   else np.zeros(len(known), dtype=bool))
    if not any(np.any(h) for h in hot):  # (nearly every break: no rows formed)
        return breaks
    reach = _WINDOW_SPANS * spacing
    t_obs = problem.t[problem.rows]
    X = problem.positions_known(control)
    steps = np.arange(int(_ONE_GRID * _CLOSE_SPANS) + 1)
    back, ahead = (a.ravel() for a in np.meshgrid(steps, steps, indexing="ij"))
    apart = ((back + ahead) > _ONE_GRID) & ((back + ahead) <= _CLOSE_SPANS * _ONE_GRID)
    before, after = back[apart] * spacing / _ONE_GRID, ahead[apart] * spacing / _ONE_GRID
    # the polishing trials: the 8 neighbours of the best pair on a grid of its step
    d1, d2 = (a.ravel() for a in np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0],
                                             indexing="ij"))
    d1, d2 = d1[(d1 != 0) | (d2 != 0)], d2[(d1 != 0) | (d2 != 0)]
    found = []  # (the pair's second break's gain over the one, piece, index, pair)
    for p, here, known, first_ok, last_ok, _ in _pieces_with_breaks(problem, t_obs, [
            b if np.any(h) else b[:0] for b, h in zip(breaks, hot, strict=True)]):
        t_here = t_obs[here]
        for i in np.flatnonzero(hot[p]):
            one = float(known[i])
            # the pairs may lie more than a spacing from the breaks beside the one (as
            # :func:`_free_of`), and inside the piece's end limits
            side = (float(known[i - 1]) + spacing * (1 - 1e-9) if i > 0 else -np.inf,
                    float(known[i + 1]) - spacing * (1 - 1e-9) if i + 1 < len(known)
                    else np.inf)
            bounds = (max(side[0], first_ok), min(side[1], last_ok))
            near = known[(known > one - span - reach) & (known < one + span + reach)]
            region = (min(one - span, float(near.min())) - reach,
                      max(one + span, float(near.max())) + reach)
            t1, t2 = one - before, one + after
            ok = (t1 >= bounds[0]) & (t2 <= bounds[1])
            if not np.any(ok):
                continue
            cost = _pair_costs(problem, X, r, J, w, sigma, spacing, here, t_here, region,
                               known, one, t1[ok], t2[ok])
            if cost is None:
                continue
            best = int(np.argmin(cost[1:]))
            if cost[0] - cost[1 + best] <= options.break_threshold:
                continue
            # the pair's instants polished in the same context: 3 x 3 trials around the
            # best, each stage's step half the last's, to h/64 (the refine moves one break
            # with its neighbour held, and of two breaks with a gap of detections between
            # them either is free anywhere in it: it cannot place them)
            pair, least = (float(t1[ok][best]), float(t2[ok][best])), cost[1 + best]
            step = spacing / _ONE_GRID
            for _ in range(_ONE_POLISH):
                step /= 2
                u1, u2 = pair[0] + step * d1, pair[1] + step * d2
                fine = ((u2 - u1 > spacing * (1 + 1e-9)) & (u2 - u1 <= span * (1 + 1e-9))
                        & (u1 >= bounds[0]) & (u2 <= bounds[1]))
                trial = _pair_costs(problem, X, r, J, w, sigma, spacing, here, t_here,
                                    region, known, one, u1[fine], u2[fine]
                                    ) if np.any(fine) else None
                if trial is not None and min(trial[1:]) < least:
                    at = int(np.argmin(trial[1:]))
                    pair, least = (float(u1[fine][at]), float(u2[fine][at])), trial[1 + at]
            found.append((cost[0] - least, p, int(i), pair))
    if not found:
        return breaks
    # of breaks side by side, the one whose pair gains most (each pair was kept a spacing
    # from the breaks beside its one, which stay)
    out = [np.asarray(x, dtype=np.float64) for x in breaks]
    used = [np.zeros(len(b), dtype=bool) for b in breaks]
    gone: dict[int, list[tuple[int, tuple[float, float]]]] = {}
    for _, p, at, pair in sorted(found, key=lambda f: -f[0]):
        if used[p][max(at - 1, 0):at + 2].any():
            continue
        used[p][at] = True
        gone.setdefault(p, []).append((at, pair))
    for p, items in gone.items():
        out[p] = np.sort(np.r_[np.delete(out[p], [at for at, _ in items]),
                               [t for _, pair in items for t in pair]])
    return out


def _pair_costs(problem: _Problem, X: np.ndarray, r: np.ndarray, J: np.ndarray,
                w: np.ndarray, sigma: float, spacing: float, here: np.ndarray,
                t_here: np.ndarray, region: tuple[float, float], known: np.ndarray,
                one: float, t1: np.ndarray, t2: np.ndarray) -> list[float] | None:
    """:func:`_region_costs` over ``region`` of the break ``one`` (of ``known``, s) as it
    is, then of each pair ``t1``, ``t2`` (P,) in its place (:func:`_one_against_two`): P + 1
    least costs (σ² units), or None."""
    drop = np.array([one])
    return _region_costs(problem, X, r, J, w, sigma, spacing, here, t_here, region[0],
                         region[1], known, [(np.zeros(0), np.zeros(0))] + [
                             (drop, np.array([a, b])) for a, b in zip(t1, t2, strict=True)])


def _gain_in_context(problem: _Problem, X: np.ndarray, r: np.ndarray, J: np.ndarray,
                     w: np.ndarray, sigma: float, spacing: float, here: np.ndarray,
                     t_here: np.ndarray, known: np.ndarray, tau: float) -> float:
    """The gain (σ² units) of the break at ``tau`` with its neighbours in the model: on the
    problem linearised at the fit (positions ``X`` (n, 3), residuals ``r`` (n, 2),
    Jacobians ``J`` (n, 2, 3), weights ``w`` (n,) at ``σ``), over the detections within
    ``_WINDOW_SPANS`` spacings of it and of the breaks of ``known`` (its piece's, s) less
    than that from it (``here``: the piece's rows in time order, ``t_here`` their times), on
    uniform knots with a
    triple knot at every break there: the least cost without the break minus the least
    cost with it. The likelihood-ratio test of :func:`_confirmed_breaks`, whose local test
    (:func:`_breaks.gain_at`) cuts its window at the neighbouring breaks.

    Session 43 (issue 10): two kicks 80 ms apart (1.3 spacings; ``paper2`` rally-72702 of
    ``bench_dirty.py --more --first-seed 72700 --misses 0.1``, once the find took the
    second), each with its break: the one's window, cut at the other 72 ms on, left the
    detections between them to a free end in both of its models, and its gain was 24.2 σ²
    (threshold 25); here 620 (the whole session's linearised problem refitted without it:
    620 too). Dropped, the other break moved between the two kicks: points to 238 mm."""
    reach = _WINDOW_SPANS * spacing
    near = known[np.abs(known - tau) < reach]
    lo = min(tau - reach, float(near.min()) - reach)
    hi = max(tau + reach, float(near.max()) + reach)
    cost = _region_costs(problem, X, r, J, w, sigma, spacing, here, t_here, lo, hi, known,
                         [(np.zeros(0), np.zeros(0)), (np.array([tau]), np.zeros(0))])
    if cost is None:  # (undetermined: nothing against the break)
        return np.inf
    return cost[1] - cost[0]


def _region_costs(problem: _Problem, X: np.ndarray, r: np.ndarray, J: np.ndarray,
                  w: np.ndarray, sigma: float, spacing: float, here: np.ndarray,
                  t_here: np.ndarray, lo: float, hi: float, known: np.ndarray,
                  models: list[tuple[np.ndarray, np.ndarray]]) -> list[float] | None:
    """The least cost (σ² units) of the problem linearised at the fit (:func:`_gain_in_context`'s
    ``X``, ``r``, ``J``, ``w``, ``σ``) over the detections of ``here`` (a piece's rows in
    time order, ``t_here`` their times) within ``[lo, hi]`` s, on uniform knots from its
    first detection with a triple knot at each break, per model ``(drop, add)`` of
    ``models``: the breaks of ``known`` (s) inside the region without those of ``drop``,
    with those of ``add``. None where a model is undetermined (its banded solve failed, or
    the region holds fewer than two detections: a piece's detections may lie further apart
    than ``_WINDOW_SPANS`` spacings where the spacing is under ``max_gap_s / 10``)."""
    i0 = int(np.searchsorted(t_here, lo, side="left"))
    i1 = int(np.searchsorted(t_here, hi, side="right"))
    if i1 - i0 < 2:
        return None
    sel = here[i0:i1]
    t_sel = t_here[i0:i1]
    inside = known[(known > t_sel[0]) & (known < t_sel[-1])]
    weight = w[sel] / sigma**2
    target = _linear_target(J[sel], X[sel], r[sel])
    # the region's observations alone (a problem over the session's would form the whole
    # session's times: ~3 ms a test at 90 minutes), at the fit's times
    rows = problem.rows[sel]
    if np.all(np.diff(rows) > 0):
        obs, rows = problem.obs.select(rows), np.arange(len(rows))
    else:  # (times moved out of the rows' order: the session's observations)
        obs = problem.obs
    cost = []
    for drop, add in models:
        held = inside[~np.isin(inside, drop)] if len(drop) else inside
        if len(add):
            held = np.sort(np.r_[held, add])
        knots = _knots_with_breaks(float(t_sel[0]), float(t_sel[-1]) + 1e-9, spacing, held)
        sub = _Problem(obs, problem.rig, [rows], [knots], problem.prior, problem.t0_ns)
        if not np.array_equal(sub.t[rows], t_sel):
            t = sub.t.copy()
            t[rows] = t_sel
            sub.set_times(t)
        ab, rhs = sub.linearised_normal(J[sel], X[sel], r[sel], weight)
        try:
            c = _normal.solve(_normal.factor(ab), rhs).reshape(-1, 3)
        except FusionError:
            return None
        res = np.einsum("naj,nj->na", J[sel], sub.positions(c)) - target
        cost.append(float(np.sum(weight * np.sum(res**2, axis=1))) + _prior_cost(sub, c))
    return cost


def _one_per_span(tau: np.ndarray, moved: np.ndarray, spacing: float,
                  gain: np.ndarray | None = None) -> np.ndarray:
    """The refined breaks ``tau`` sorted, never two within a knot spacing: of two that the
    refinement brought that close, the one with the larger ``gain`` (each alone in the
    pair's place, :func:`_crowded_gains`; session 43), on equal gains (or without them)
    the one it ``moved`` less (session 25; before, the earlier).

    Session 25: a break the refine moved onto its neighbour is explaining the neighbour's
    jump: a break the find added beside a known one that the loose fit had placed a few ms
    off (its residual passing for a second jump by just over the threshold) moved 17 ms onto
    it while the known one stayed, and keeping the earlier put the kick 11 ms off
    (`wide3` rally-6600 of ``bench_dirty.py --more --first-seed 6600``: 45 mm). Session 43:
    the converse: a break the loose fit's third round added one spacing beside one it had
    placed 7 ms off a kick (a noise pattern at 28 σ², threshold 25) did not move, the
    misplaced one moved 5.5 ms onto the kick, and the one moved less — the spurious one —
    stayed; its neighbour's search then pulled the kick 80 ms before onto it too, and that
    jump lost its break (``paper3`` rally-72703 of ``bench_dirty.py --more --first-seed
    72700 --misses 0.1``: 54 mm; whether the noise pattern passed depended on the knot
    grid's phase, which a blackout 4 s earlier moved). How far a break moved says which
    one the refine found better only where one of them explains a jump; the likelihood
    ratio says it wherever they are: 1934 σ² for the break on the kick, 947 for the other."""
    order = np.argsort(tau)
    new, moved = tau[order], moved[order]
    if np.all(np.diff(new) > spacing):
        return new
    score = np.zeros(len(new)) if gain is None else np.nan_to_num(
        np.asarray(gain, dtype=np.float64)[order], nan=-np.inf)
    keep = np.ones(len(new), dtype=bool)
    last = 0
    for i in range(1, len(new)):
        if new[i] - new[last] > spacing:
            last = i
        elif score[i] > score[last] or (score[i] == score[last] and moved[i] < moved[last]):
            keep[last] = False
            last = i
        else:
            keep[i] = False
    return new[keep]
