"""Every camera's clock from the ball itself: the trajectory and the clock parameters as one
sparse least-squares problem.

Model: the continuous-time trajectory of :mod:`pslog.estimation.trajectory` (its cost (1) +
(2)), where a detection of camera ``c`` logged at ``ℓ`` on the session clock at pixel row
``v`` was captured, by the timing model (:mod:`pslog.timing`), at
``t = ℓ + clock_offset_c + clock_drift_ppm_c · 1e-6 · ℓ + readout_c · v / height_c``.
The estimator works in an equivalent parametrisation (:class:`_Clocks`)

    τ = ℓ + o'_c + d_c · 1e-6 · (ℓ - ℓ_m) + r_c · (v / height_c - 1/2),   τ = t - r_1 / 2

(readout referred to the image's centre row, drift to the middle of the logged times; a
common shift of every time is absorbed by the trajectory), which keeps offsets, readouts and
drifts nearly uncorrelated, and maps the estimates and their covariance back exactly. The
clock parameters θ are unknowns next to the control points ``c`` — the way Kalibr estimates a
camera–IMU time offset (Furgale, Rehder & Siegwart, IROS 2013). The reprojection residual
``r = π_c(p(τ)) - z`` depends on θ only through ``τ``, so its Jacobian column is

    ∂r/∂θ_j = ∂π_c/∂X · p'(τ) · ∂τ/∂θ_j,    ∂τ/∂(o', d, r) = [1, 1e-6·(ℓ - ℓ_m), v/h - 1/2]

Gauss–Newton steps solve the bordered system ``[[A, B], [Bᵀ, C]]`` (``A`` banded: the
trajectory; ``B``, ``C``: the few clock columns, sparse) by its Schur complement
``S = C - Bᵀ A⁻¹ B``. The bounces' instants are re-estimated between steps at the current
clocks; in the final step they are extra columns ``∂r/∂τ_b`` (central differences of the
basis), so the clocks' covariance — the clocks' block of ``S⁻¹`` over (clocks, breaks) — has
both the trajectory and the breaks' instants marginalised. Its pixel noise is the
dof-corrected RMS of the inlying residuals. Regularized host stamps (``regularized``): each
line's (start, period) errors are two more columns, not estimated; their effect ``K`` on the
clocks adds ``K Σ_line Kᵀ``. Camera 1 defines the session clock: its offset and drift are 0
and never estimated.

Start: the rig's values, then a coarse scan of each camera's offset over ``±search`` against
camera 1 alone (a two-camera trajectory per trial offset, on a window of the session), so a
start several milliseconds wrong converges.

Limits: offsets need the ball to move (a still ball looks the same at any time); a drift
needs a long session; a readout needs the ball to move along the image's rows (vertical image
motion) — each estimate's standard deviation says how well the data determined it
(docs/timing.md: the Cramér–Rao bounds).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from ..camera import MAX_CLOCK_DRIFT_PPM, MAX_CLOCK_OFFSET_S
from ..errors import FusionError, InputError
from ..records import NS, Observations
from ..rig import Rig
from ..timing import CLOCK_KEYS, ClockCovariance, camera_parameters
from . import _normal
from .bspline import DEGREE, basis
from .trajectory import (
    _CAUCHY,
    MotionPrior,
    SmoothOptions,
    _information,
    _initial_control,
    _knots_with_breaks,
    _Problem,
    _refine_breaks,
    _refit_control,
    _Solver,
    fit_trajectory,
    split_pieces,
)

PARAMETERS = ("offset", "drift", "readout")
#: In an ``estimate`` list instead of ``readout``: one readout per camera model
#: (:func:`camera_models`), every camera of a model taking its value.
SHARED_READOUT = "readout=shared"
#: Each parameter's rig camera key (:data:`pslog.timing.CLOCK_KEYS`).
RIG_KEY = {"offset": "clock_offset", "drift": "clock_drift_ppm", "readout": "readout"}
#: Fewest detections a camera needs (with camera 1's in the same stretches) to be synced.
MIN_DETECTIONS = 30
#: the narrowest offset search, seconds: the session clock's resolution (a nanosecond); a
#: narrower one (``--search-ms 1e-320``) left the scan no step (a division by zero)
MIN_SEARCH_S = 1e-9
#: the widest offset search, seconds: a minute (the scan steps by 1 ms, 1.2e5 costs a camera)
MAX_SEARCH_S = 60.0
#: A ball still for most of the session (the median of its fitted speed below 5 cm/s: a
#: robot-soccer ball lying on its spot, ``pslog simulate --rest``) is synced from its moving
#: stretches when at least MIN_DETECTIONS detections see it this fast (m/s; a still ball's
#: fit under 3 px of noise reaches 0.36 m/s); the σ test then judges what they determine.
MOVING_M_S = 0.5
#: The coarse scan fits at most this long a stretch of the session, seconds.
_SCAN_WINDOW_S = 12.0
#: Stretches the coarse scan tries (each seen by both cameras) before it gives up.
_SCAN_TRIES = 3
#: A session longer than _ALL_UP_TO_S is synced on _N_WINDOWS windows of _WINDOW_S spread
#: over it (a bounded cost; the spread keeps the drift's lever arm).
_ALL_UP_TO_S = 150.0
_N_WINDOWS = 6
_WINDOW_S = 15.0
_ITERATIONS = 10
_ROUNDS = 8
#: ``estimate="auto"``: a group of parameters (every camera's readout; every drift) is kept
#: when its Wald statistic exceeds the χ² quantile at this level (0.1 %: a global-shutter
#: rig keeps readouts in about one session in a thousand); readouts of a rig with two
#: cameras of one model are tested twice (one readout per model; per camera), each test at
#: half of it.
AUTO_LEVEL = 1e-3
#: ``estimate="auto"``: readouts the nested test keeps are estimated one per camera model
#: unless the Wald test of equal readouts within each model rejects at this level (5 %, not
#: :data:`AUTO_LEVEL`: a wrong tie is a wrong model — a rolling camera tied to global ones
#: of its size — and cost smooth 1-3 mm and a NEES of 2.7-5.6 where a missed one costs the
#: per-camera estimate's spread; at 0.1 % 13 of 50 held-out sessions with readouts that
#: differ within a model were tied, at 5 % 3; docs/timing.md)
TIE_LEVEL = 0.05
#: ``estimate="auto"`` tries drifts on sessions at least this long (seconds): a drift of
#: d ppm moves a camera by d · 1e-6 · T, below the offsets' σ on shorter ones.
AUTO_DRIFT_MIN_S = 30.0


def check_search_s(search_s: object) -> float | None:
    """``search_s`` as seconds if it is None or a number in [:data:`MIN_SEARCH_S`,
    :data:`MAX_SEARCH_S`], else :class:`InputError` naming the value (0 left the scan no step,
    a negative one scanned backwards, NaN was called longer than the session)."""
    if search_s is None:
        return None
    # (in whole nanoseconds to 1e-6: --search-ms 1e-6 is 9.999999999999999e-10 s)
    if (isinstance(search_s, bool) or not isinstance(search_s, (int, float, np.number))
            or not (round(float(search_s) / MIN_SEARCH_S, 6) >= 1
                    and float(search_s) <= MAX_SEARCH_S)):
        raise InputError(f"offset search ±{search_s!r} s: give seconds in "
                         f"[{MIN_SEARCH_S:g}, {MAX_SEARCH_S:g}] (or None: half a frame period)")
    return float(search_s)


@dataclass(frozen=True)
class ClockEstimate:
    """One camera's clock parameters with their standard deviations.

    Attributes
    ----------
    name : str
    offset_s, offset_std_s : float, seconds
    drift_ppm, drift_std_ppm : float, parts per million
    readout_s, readout_std_s : float, seconds
    residual_px : float, RMS reprojection residual of the camera's inlying detections
    n_detections : int
    """

    name: str
    offset_s: float
    offset_std_s: float
    drift_ppm: float
    drift_std_ppm: float
    readout_s: float
    readout_std_s: float
    residual_px: float
    n_detections: int


@dataclass(frozen=True)
class ModelTest:
    """``estimate="auto"``: the Wald test of one group of clock parameters (every camera's
    readout, or every drift but camera 1's) against the rig's values; for readouts also the
    nested test of one readout shared by the cameras of each model (:func:`camera_models`).

    Attributes
    ----------
    parameter : "readout" or "drift"
    statistic : Wald χ² = (θ̂ - θ₀)ᵀ Σ⁻¹ (θ̂ - θ₀) over the group (NaN when not fitted)
    dof : the group's size
    threshold : the χ² quantile the statistic is compared with: at :data:`AUTO_LEVEL`, or
        at half of it when the shared test is made too (Bonferroni)
    p_value : the probability of a figure this large when the rig's values are right:
        P(χ²_dof > statistic), or with the shared test ``min(1, 2 min(p, p_shared))`` (the
        Bonferroni-adjusted p-value, a bound on that probability: at 0.1 % the exact one is
        0.076-0.092 % for χ² statistics on three or four cameras of one or two models); the
        group is kept when it is below :data:`AUTO_LEVEL`
    kept : estimated in the result
    reason : why, in words
    shared_statistic : readouts: the Wald χ² of "one readout per camera model" against the
        rig's values, ``dᵀΣ⁻¹G (GᵀΣ⁻¹G)⁻¹ GᵀΣ⁻¹d`` (``G`` camera -> model); NaN when not
        made (drifts; or every camera a model of its own: it would be the same test)
    shared_dof : the models' count (0 when not made)
    shared_threshold : the χ² quantile at half of :data:`AUTO_LEVEL` (NaN when not made)
    equal_statistic : readouts kept by the nested test: the Wald χ² of equal readouts within
        each model, ``(Aθ̂)ᵀ(AΣAᵀ)⁻¹(Aθ̂)`` (``A``: each camera's readout minus its model's
        first camera's); NaN when not made
    equal_dof : k - g (0 when not made)
    equal_threshold : the χ² quantile at :data:`TIE_LEVEL` (NaN when not made)
    tied : the readouts estimated one per camera model (:data:`SHARED_READOUT`): the nested
        test rejected the rig's values and the equality test did not reject
    """

    parameter: str
    statistic: float
    dof: int
    threshold: float
    p_value: float
    kept: bool
    reason: str
    shared_statistic: float = float("nan")
    shared_dof: int = 0
    shared_threshold: float = float("nan")
    equal_statistic: float = float("nan")
    equal_dof: int = 0
    equal_threshold: float = float("nan")
    tied: bool = False


@dataclass(frozen=True)
class SyncResult:
    """:func:`estimate_clocks`' result: per camera in rig order, the rig holding the estimates,
    the overall RMS residual (px) and the estimated pixel noise σ (px); ``estimated`` the
    parameters estimated, ``selection`` (``estimate="auto"``) the tests that chose them;
    ``unknowns`` (camera, parameter) per row of ``covariance`` (rig's parametrisation);
    ``shared_readout``: one readout estimated per camera model (:data:`SHARED_READOUT`),
    each camera holding its model's value and ``covariance`` its rows (identical within a
    model: singular, positive semi-definite); ``held_readouts`` (camera name, readout s, its
    std s) the readouts the free fit put below 0, then held at 0 with the clocks fitted
    again (:func:`_readouts_held`: the rig and ``cameras`` hold that fit)."""

    cameras: tuple[ClockEstimate, ...]
    rig: Rig
    residual_px: float
    noise_px: float
    estimated: tuple[str, ...] = ()
    selection: tuple[ModelTest, ...] = ()
    unknowns: tuple[tuple[int, str], ...] = ()
    covariance: np.ndarray | None = None
    shared_readout: bool = False
    held_readouts: tuple[tuple[str, float, float], ...] = ()

    def clock_covariance(self) -> ClockCovariance | None:
        """The estimates' joint covariance as :class:`pslog.timing.ClockCovariance` (what
        :attr:`pslog.fusion.FusionOptions.clock_covariance` takes), the parameters of zero
        variance left out; None when nothing was estimated (or the matrix is no covariance:
        it is informative, ``pslog sync`` stores it and must not fail for it)."""
        if self.covariance is None or not len(self.unknowns):
            return None
        keep = [j for j in range(len(self.unknowns)) if self.covariance[j, j] > 0]
        if not keep:
            return None
        try:
            return ClockCovariance(
                np.array([self.unknowns[j][0] for j in keep]),
                np.array([CLOCK_KEYS.index(RIG_KEY[self.unknowns[j][1]]) for j in keep]),
                self.covariance[np.ix_(keep, keep)])
        except InputError:
            return None


def estimate_clocks(obs: Observations, rig: Rig, estimate=("offset",),
                    search_s: float | None = None, options: SmoothOptions | None = None,
                    regularized=None, start: Rig | None = None) -> SyncResult:
    """Estimate the clock parameters named in ``estimate`` from detections at their logged
    times (``obs``: best candidate per frame, logged times, sorted by (time, camera)).

    ``regularized``: camera name -> :class:`pslog.timing.Regularization` of the cameras
    whose stamps ``obs`` holds regularized; each line's uncertainty (its start and period)
    moves that camera's times together, so it is added to the standard deviations (camera
    1's line moves the session clock, hence every other camera's offset and drift).

    ``estimate="auto"`` (or ``("auto",)``) chooses the model (:func:`select_clocks`);
    :data:`SHARED_READOUT` in the list estimates one readout per camera model.

    ``start``: a rig whose clocks the fit starts from instead of ``rig``'s, the coarse
    offset scan skipped (:func:`select_clocks`' second fit, from its first fit's converged
    clocks); the parameters not estimated are ``rig``'s all the same.

    Raises
    ------
    FusionError naming what is missing when the ball is seen too little or does not move.
    InputError : ``search_s`` neither None nor seconds in [1 ns, 60 s]
    """
    search_s = check_search_s(search_s)
    return _readouts_held(_estimate_free(obs, rig, estimate, search_s, options, regularized,
                                         start), obs, rig, search_s, options, regularized)


def _estimate_free(obs: Observations, rig: Rig, estimate, search_s: float | None,
                   options: SmoothOptions | None, regularized,
                   start: Rig | None = None, held: tuple[int, ...] = ()) -> SyncResult:
    """:func:`estimate_clocks` without the readouts' bound (``held``: cameras whose readout
    is held at ``rig``'s, not estimated)."""
    if tuple([estimate] if isinstance(estimate, str) else estimate) == ("auto",):
        return select_clocks(obs, rig, search_s, options, regularized)
    try:
        return _estimate_clocks(obs, rig, estimate, search_s, options, regularized, start,
                                held)
    except np.linalg.LinAlgError:
        # a singular system: some clock has no information left (its detections all
        # rejected as outliers, or a motion that cannot tell it apart)
        raise FusionError("the clocks are not determined by the detections (a singular "
                          "system): check that every camera sees the same moving ball"
                          ) from None


def _readouts_held(result: SyncResult, obs: Observations, rig: Rig, search_s: float | None,
                   options: SmoothOptions | None, regularized) -> SyncResult:
    """``result`` where no readout was estimated below 0; else the clocks fitted again with
    those readouts held at 0 (their bound: no sensor reads its rows bottom to top), from
    ``result``'s clocks (no coarse scan), the model otherwise the same, ``selection`` kept
    and the free fit's values in ``held_readouts``. The maximum likelihood under the bound
    (its solution on the boundary, where the free one lies beyond it; a readout held may
    push another below 0, which is then held too): before session 42 the
    rig written held 0 beside offsets fitted with the negative readout (walk42: cam1 at
    -0.700 ± 0.247 ms from a calibrated rig, its times up to 0.7 ms off the written model)."""
    held: dict[int, tuple[str, float, float]] = {}
    fit = result
    while True:  # (a readout held may push another below 0: held in turn, at most all)
        below = [c for c, est in enumerate(fit.cameras)
                 if (c, "readout") in fit.unknowns and est.readout_s < 0]
        if not below:
            break
        for c in below:
            held[c] = (fit.cameras[c].name, fit.cameras[c].readout_s,
                       fit.cameras[c].readout_std_s)
        zero = Rig(tuple(cam.replace(readout=0.0) if c in held else cam
                         for c, cam in enumerate(rig.cameras)), rig.name)
        left = any(p == "readout" and c not in held for c, p in fit.unknowns)
        estimate = tuple(SHARED_READOUT if p == "readout" and result.shared_readout and left
                         else p for p in result.estimated)
        fit = _estimate_free(obs, zero, estimate, search_s, options, regularized,
                             start=fit.rig, held=tuple(sorted(held)))
    if fit is result:
        return result
    return replace(fit, selection=result.selection, estimated=result.estimated,
                   held_readouts=tuple(held[c] for c in sorted(held)))


def _estimate_clocks(obs: Observations, rig: Rig, estimate, search_s: float | None,
                     options: SmoothOptions | None, regularized,
                     start: Rig | None = None, held: tuple[int, ...] = ()) -> SyncResult:
    options = options or SmoothOptions()
    shared = SHARED_READOUT in set(estimate)
    estimate = tuple(p for p in PARAMETERS
                     if p in set(estimate) or (p == "readout" and shared))
    if len(rig) < 2:
        raise FusionError(f"sync needs at least two cameras (one camera cannot triangulate); "
                          f"rig has {len(rig)}")
    unknowns = [(c, p) for c in range(len(rig)) for p in estimate
                if not (c == 0 and p in ("offset", "drift"))
                and not (p == "readout" and c in held)]
    obs = _with_rays(obs, rig)
    _check_coverage(obs, rig, options.max_gap_s)
    span = float(obs.time_ns.max() - obs.time_ns.min()) / NS
    if search_s is not None and "offset" in estimate and not search_s < span:
        # an offset as long as the session leaves the cameras no time in common
        raise FusionError(f"offset search ±{search_s * 1e3:g} ms is not shorter than the "
                          f"session's detections ({span * 1e3:.0f} ms): search less than the "
                          f"session's length")

    obs = _windows(obs)
    logged = obs.time_ns / NS
    tie = None
    if shared:  # one readout per camera model: the readouts' unknowns numbered by model
        readouts = [j for j, (_, p) in enumerate(unknowns) if p == "readout"]
        models = camera_models(rig, [unknowns[j][0] for j in readouts])
        key = [("own", j) for j in range(len(unknowns))]
        for j, g in zip(readouts, models, strict=True):
            key[j] = ("model", int(g))
        first = list(dict.fromkeys(key))
        tie = np.array([first.index(k) for k in key])
    params = _Clocks(rig, unknowns, 0.5 * float(logged.min() + logged.max()), tie)
    theta = params.to_internal(np.array([float(getattr((start or rig).cameras[c], RIG_KEY[p]))
                                         for c, p in unknowns]))
    if "offset" in estimate and start is None:
        theta = _scan_offsets(obs, rig, params.reduced, theta, params, search_s, options)

    # rounds: the bounces are found (and their instants fixed) at the clocks of the round
    # before, then the clocks and the trajectory solved jointly, until the clocks settle
    scale = _scale_of(params.reduced)
    previous_step = None
    for _ in range(_ROUNDS):
        before = theta
        problem, control, theta, sigma, r, w, S, n_t = _solve_joint(
            obs, rig, unknowns, theta, params, options, regularized)
        step = (theta - before) * scale
        if np.max(np.abs(step), initial=0.0) < 2e-6:
            break  # the clocks no longer move the breaks: converged
        std_now = np.sqrt(np.maximum(
            np.diag(np.linalg.inv(S[:n_t, :n_t]))[:len(params.reduced)], 0.0))
        if np.all(np.abs(theta - before) < 0.05 * std_now):
            break  # further rounds would move the clocks by a negligible part of their σ
        if previous_step is not None:
            # the rounds converge geometrically along one direction (the breaks' instants
            # and the clocks pull on each other): jump to the limit of the series (Aitken)
            ratio = float(step @ previous_step) / max(float(previous_step @ previous_step),
                                                      1e-30)
            if 0.3 < ratio < 0.95:
                theta = theta + (theta - before) * ratio / (1 - ratio)
                previous_step = None
                continue
        previous_step = step
    cam = obs.camera[problem.rows]
    q = len(params.reduced)
    # the clocks' covariance with the trajectory and the breaks' instants marginalised, in
    # the rig's parametrisation (T: every unknown's; a tied readout's rows are one, so the
    # matrix is then singular: the cameras' readouts are one parameter)
    T = params.to_external_matrix()
    if q:
        cov_t = np.linalg.inv(S[:n_t, :n_t])
        cov = cov_t
        if len(S) > n_t:  # the regularized lines' errors, which the estimate does not see
            K = cov_t @ S[:n_t, n_t:]
            cov = cov_t + K @ _nuisance_covariance(rig, regularized) @ K.T
        cov = T @ cov[:q, :q] @ T.T
        cov = (cov + cov.T) / 2  # (exactly symmetric: the products leave ~1e-14 of σ_i σ_j)
    else:
        cov = np.zeros((len(unknowns), len(unknowns)))
    theta = params.to_external(theta)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))

    # before the rig takes the values: an undetermined estimate may lie beyond what a rig
    # accepts, and the message is then the estimate's, not a bad rig value's
    _check_motion(problem, control, unknowns, std, rig, theta, span)
    norms = np.linalg.norm(r, axis=1)
    inlier = w > 0.5
    estimates, new_cams = [], []
    for c, camera in enumerate(rig.cameras):
        values = {p: float(getattr(camera, RIG_KEY[p])) for p in PARAMETERS}
        stds = dict.fromkeys(PARAMETERS, 0.0)
        for j, (cj, p) in enumerate(unknowns):
            if cj == c:
                values[p], stds[p] = float(theta[j]), float(std[j])
        mine = (cam == c) & inlier
        estimates.append(ClockEstimate(
            camera.name, values["offset"], stds["offset"], values["drift"], stds["drift"],
            values["readout"], stds["readout"],
            float(np.sqrt(np.mean(norms[mine] ** 2))) if mine.any() else float("nan"),
            int(np.count_nonzero(cam == c))))
        # a readout is physical only in [0, frame period): the rig takes the nearest such
        readout = min(max(values["readout"], 0.0), np.nextafter(camera.frame_period, 0))
        new_cams.append(camera.replace(clock_offset=values["offset"],
                                       clock_drift_ppm=values["drift"], readout=readout))
    return SyncResult(tuple(estimates), Rig(tuple(new_cams), rig.name),
                      float(np.sqrt(np.mean(norms[inlier] ** 2))), float(sigma),
                      estimated=estimate, unknowns=tuple(unknowns), covariance=cov,
                      shared_readout=bool(shared and "readout" in estimate))


def select_clocks(obs: Observations, rig: Rig, search_s: float | None = None,
                  options: SmoothOptions | None = None, regularized=None) -> SyncResult:
    """``estimate="auto"``: offsets always; readouts, and drifts on sessions of at least
    :data:`AUTO_DRIFT_MIN_S`, when the data support them.

    The widest model (offset, readout[, drift]) is fitted first; each group of parameters is
    then tested against the rig's values by the Wald test (Wald 1943; e.g. Seber & Wild,
    *Nonlinear Regression*, 1989, §5.3): W = (θ̂ - θ₀)ᵀ Σ⁻¹ (θ̂ - θ₀), χ² with the group's size
    as degrees of freedom when θ₀ is right, Σ the group's block of the estimate's covariance
    (trajectory, bounces' instants and regularized lines marginalised: honest to about 1σ,
    docs/timing.md). A group is kept when W exceeds the χ² quantile at :data:`AUTO_LEVEL`.
    Readouts of a rig with cameras of one model (:func:`camera_models`) are tested first as
    the nested hypothesis of one readout per model (identical webcams; g dof for g models,
    where the per-camera test has one per camera: more power for a readout they share) and
    per camera, each at half the level (Bonferroni); kept if either rejects. Readouts the
    nested test keeps are estimated one per model (:data:`SHARED_READOUT`: one parameter the
    data determine where the per-camera ones correlate with the offsets) unless the Wald test
    of equal readouts within each model (k - g dof, at :data:`TIE_LEVEL`) rejects; else per
    camera.
    When one is dropped, or the readouts are tied, the model chosen is fitted (two fits),
    else the first fit is the result (one fit). A parameter the ball's motion does not
    determine (the wide fit fails with it: then offsets and readouts without drifts are
    tried) is dropped without a figure, its reason the fit's message."""
    search_s = check_search_s(search_s)
    options = options or SmoothOptions()
    from scipy.stats import chi2

    span = float(obs.time_ns.max() - obs.time_ns.min()) / NS if len(obs) else 0.0
    widest = [("offset", "drift", "readout"), ("offset", "readout")]
    if span < AUTO_DRIFT_MIN_S:
        widest = widest[1:]
    tests: list[ModelTest] = []
    full: SyncResult | None = None
    failure: dict[str, str] = {}  # parameter -> the message of the last wide fit that failed
    for wide in widest:  # with drifts a long session's wide fit may fail: then without
        try:
            full = _estimate_free(obs, rig, wide, search_s, options, regularized)
            break
        except FusionError as exc:
            failure.update((p, str(exc)) for p in wide if p != "offset")
    keep = ["offset"]
    for p in ("readout", "drift"):
        if full is None or p not in full.estimated:
            reason = (f"not determined ({failure[p]})" if p in failure else
                      f"not tried, the session ({span:.0f} s) is shorter than "
                      f"{AUTO_DRIFT_MIN_S:.0f} s")
            tests.append(ModelTest(p, float("nan"), 0, float("nan"), float("nan"), False,
                                   reason))
            continue
        idx = [j for j, (_, q) in enumerate(full.unknowns) if q == p]
        x = np.array([getattr(full.cameras[c], _FIELD[p]) for c, _ in
                      (full.unknowns[j] for j in idx)])
        x0 = np.array([float(getattr(rig.cameras[c], RIG_KEY[p])) for c, _ in
                       (full.unknowns[j] for j in idx)])
        assert full.covariance is not None
        cov = full.covariance[np.ix_(idx, idx)]
        d = x - x0
        w = float(d @ np.linalg.lstsq(cov, d, rcond=None)[0])
        k = len(idx)
        models = camera_models(rig, [full.unknowns[j][0] for j in idx]) if p == "readout" \
            else np.arange(k)
        g = int(models.max()) + 1 if k else 0
        if g >= k:  # drifts, or no two cameras of one model: the one test at the level
            threshold = float(chi2.isf(AUTO_LEVEL, k))
            p_value = float(chi2.sf(w, k))
            kept = w > threshold
            tests.append(ModelTest(p, w, k, threshold, p_value, kept,
                                   f"Wald χ² {w:.1f} on {k} dof "
                                   + (">" if kept else "<=")
                                   + f" {threshold:.1f} (the {AUTO_LEVEL * 100:g} % level)"))
        else:
            # the nested hypothesis first: one readout per camera model (identical webcams
            # share theirs), g dof where the per-camera test has k; each test at half the
            # level (Bonferroni: a global-shutter rig keeps readouts at most at the level)
            G = (models[:, None] == np.arange(g)[None, :]).astype(np.float64)
            b = G.T @ np.linalg.lstsq(cov, d, rcond=None)[0]
            ws = float(b @ np.linalg.lstsq(G.T @ np.linalg.lstsq(cov, G, rcond=None)[0], b,
                                           rcond=None)[0])
            threshold = float(chi2.isf(AUTO_LEVEL / 2, k))
            shared_threshold = float(chi2.isf(AUTO_LEVEL / 2, g))
            p_value = min(1.0, 2 * min(float(chi2.sf(w, k)), float(chi2.sf(ws, g))))
            kept = w > threshold or ws > shared_threshold
            n_models = "one model" if g == 1 else f"{g} models"
            reason = (f"one readout per camera model ({n_models}): Wald χ² {ws:.1f} on {g} "
                      "dof " + (">" if ws > shared_threshold else "<=")
                      + f" {shared_threshold:.1f}; per camera: χ² {w:.1f} on {k} dof "
                      + (">" if w > threshold else "<=") + f" {threshold:.1f} (each at "
                      f"half the {AUTO_LEVEL * 100:g} % level)")
            equal = equal_threshold = float("nan")
            tie = False
            if kept and ws > shared_threshold:
                # the model's readouts kept: estimated as one per model (a parameter the
                # data determine where k free ones correlate with the offsets) unless the
                # cameras of a model differ: the Wald test of equal readouts within each
                # model, (Aθ̂)ᵀ(AΣAᵀ)⁻¹(Aθ̂) on k - g dof (A: each camera's readout minus
                # its model's first camera's), at TIE_LEVEL
                A = np.zeros((k - g, k))
                row = 0
                for c in range(k):
                    first = int(np.flatnonzero(models == models[c])[0])
                    if first != c:
                        A[row, c], A[row, first] = 1.0, -1.0
                        row += 1
                e = A @ x
                equal = float(e @ np.linalg.lstsq(A @ cov @ A.T, e, rcond=None)[0])
                equal_threshold = float(chi2.isf(TIE_LEVEL, k - g))
                tie = not equal > equal_threshold
                reason += (f"; equal within each model: χ² {equal:.1f} on {k - g} dof "
                           + ("<=" if tie else ">") + f" {equal_threshold:.1f} (the "
                           f"{TIE_LEVEL * 100:g} % level): "
                           + ("one readout per model" if tie else "per camera"))
            tests.append(ModelTest(p, w, k, threshold, p_value, kept, reason, ws, g,
                                   shared_threshold, equal,
                                   k - g if np.isfinite(equal) else 0, equal_threshold,
                                   tie))
        if kept:
            keep.append(p)
    chosen = tuple(p for p in PARAMETERS if p in keep)
    tied = any(t.tied for t in tests)
    if full is not None and set(chosen) == set(full.estimated) and not tied:
        result = full
    else:
        # tied readouts: the model chosen fitted from the wide fit's converged clocks (its
        # offsets, readouts and drifts kept; no coarse scan: the tie decision has that fit,
        # session 38: the second fit's CPU 0.39-0.49 -> 0.13-0.24 s on paper3 at 8 s, the
        # clocks within 0.19 σ of the cold fit's: not the rounds' tolerance alone, two
        # fixed points of the rounds on one seed, docs/timing.md); a
        # group dropped: from the rig, as --estimate names it (the same result to the bit;
        # a warm start saved 5-20 % there). The wide fit's rig (its readouts put in [0, frame
        # period) as a rig holds them): a camera's readout estimated beyond its frame period
        # (a full-frame rolling shutter, 32 ms at 30 fps) or below 0 made the start a rig
        # refused, and auto failed (RigError, session 38's review)
        start = None if full is None or not tied else full.rig
        result = _estimate_free(obs, rig, tuple(SHARED_READOUT if tied and p == "readout"
                                                else p for p in chosen),
                                search_s, options, regularized, start)
    return replace(result, selection=tuple(tests))


_FIELD = {"offset": "offset_s", "drift": "drift_ppm", "readout": "readout_s"}


def camera_models(rig: Rig, cameras) -> np.ndarray:
    """Each of ``cameras`` (rig indices) numbered by its model as far as the rig can tell,
    its image size and frame rate, in order of first appearance (n,): cameras of one model
    (identical webcams) share their sensor's rolling-shutter readout, the nested hypothesis
    ``estimate="auto"`` tests first."""
    keys = [(rig.cameras[c].width, rig.cameras[c].height, float(rig.cameras[c].fps))
            for c in cameras]
    order = list(dict.fromkeys(keys))
    return np.array([order.index(key) for key in keys], dtype=np.int64)


def _solve_joint(obs, rig, unknowns, theta, params, options, regularized=None):
    """The trajectory's pieces, knots and breaks at clocks ``theta``, then the joint robust
    Gauss–Newton solve of control points, clocks and the breaks' instants.

    Returns problem, control, theta, σ, residuals, weights and the information ``S`` of
    (clocks, breaks) with the control points eliminated (Schur complement): the clocks'
    covariance is the clocks' block of ``S⁻¹``, so the breaks' uncertainty is in it."""
    logged_s = obs.time_ns / NS
    times = params.times(obs, theta)
    t0 = float(times.min())
    order = np.argsort(times, kind="stable")
    ordered = _observations_at(obs, times, order)
    try:
        fit = fit_trajectory(ordered, rig, options)
    except FusionError as exc:  # the fit's words, in sync's context
        raise FusionError(f"the ball's track, on which the clocks are estimated, cannot be "
                          f"fitted: {exc}") from None
    pieces = [order[p] for p in fit.pieces]  # rows of ``obs``
    # a margin on each piece: the clocks move the times a little beyond the first fit's ends
    margin = 0.02
    spans, breaks = [], []
    for k in fit.trajectory.knots:
        inner = np.unique(k)
        mult = np.array([np.count_nonzero(k == x) for x in inner[1:-1]])
        breaks.append(inner[1:-1][mult >= 3])
        spans.append((inner[0] - margin, inner[-1] + margin))
    spacing = fit.trajectory.spacing_s
    t_ref = (ordered.time_ns[0] / NS) - t0  # fit times are relative to the first ordered time
    spans = [(a + t_ref, b + t_ref) for a, b in spans]
    breaks = [b + t_ref for b in breaks]
    knots = [_knots_with_breaks(a, b, spacing, br) for (a, b), br in zip(spans, breaks,
                                                                         strict=True)]
    problem = _Problem(obs, rig, pieces, knots, options.prior)
    seen = np.bincount(obs.camera[problem.rows], minlength=len(rig))
    for c in sorted({c for c, _ in unknowns}):
        if seen[c] == 0:
            at = [v for (cj, p), v in zip(unknowns, params.to_external(theta), strict=True)
                  if cj == c and p == "offset"]
            raise FusionError(
                f"camera {rig.cameras[c].name}: none of its detections fits the ball's track "
                f"that the other cameras see"
                + (f" at clock offset {at[0] * 1e3:.3f} ms" if at else "")
                + " (they lie off every epipolar line: another object, a wrong pose in the "
                  "rig, or an offset search so wide that it found a wrong offset): its clock "
                  "cannot be estimated")
    problem.set_times(times - t0)
    control = _initial_control(problem, fit.trajectory.noise_px)
    solver = _Solver(problem, options)
    control, sigma, r, w, J = solver.run(control, fit.trajectory.noise_px, 3)
    rows = problem.rows
    cam = obs.camera[rows]
    # (a tied parameter moves each of its cameras' times: M)
    dt_dtheta = params.times_jacobian(logged_s[rows], obs.uv[rows, 1], cam) @ params.M
    estimated = params.reduced
    for _ in range(_ITERATIONS):
        control, theta, sigma, r, w, J, S, moved = _joint_step(
            problem, solver, obs, estimated, theta, params, control, sigma, dt_dtheta, t0)
        if any(len(b) for b in breaks):
            # the bounces' instants follow the clocks (they are on the session clock, which
            # the clocks map the detections onto)
            breaks = _refine_breaks(problem, control, sigma, r, w, J, spacing, breaks,
                                    options)
            X_old = problem.positions(control)
            problem.set_knots([_knots_with_breaks(a, b, spacing, br) for (a, b), br in
                               zip(spans, breaks, strict=True)], options.prior)
            control = _refit_control(problem, X_old)
            control, sigma, r, w, J = solver.run(control, sigma, 1)
        if moved < 1e-7:
            break
    break_cols = _BreakColumns(problem, spacing)
    # each regularized camera's line error, δstart + δperiod · (k - k0), as two more columns
    # (not estimated: they only widen the covariance)
    extra = np.zeros((len(rows), 0))
    for c, camera in enumerate(rig.cameras):
        rep = (regularized or {}).get(camera.name)
        if rep is not None:
            k = (obs.frame_index[rows] - rep.first_index).astype(np.float64)
            extra = np.c_[extra, (cam == c) * 1.0, np.where(cam == c, k, 0.0)]
    # σ corrected for the degrees of freedom the fit absorbs; the covariance there
    _, dof, _ = _information(problem, control, sigma, r, J)
    control, theta, sigma, r, w, J, S, _ = _joint_step(
        problem, solver, obs, estimated, theta, params, control, sigma,
        np.c_[dt_dtheta, extra], t0, dof, break_cols, n_extra=extra.shape[1])
    # the covariance's pixel noise: the RMS of the inlying residuals corrected for the degrees
    # of freedom the fit absorbs (the median-based σ that weighs the solve is robust but
    # noisy: ±8 % on an 8 s session, which the standard deviations would inherit)
    s2 = np.sum(r * r, axis=1) / sigma**2
    inlier = s2 < 2 * _CAUCHY**2
    p_eff = 2 * len(r) * (1 - 1 / dof**2)
    if np.count_nonzero(inlier) * 2 > p_eff + 10:
        sigma_cov = max(float(np.sqrt(np.sum(r[inlier] ** 2)
                                      / (2 * np.count_nonzero(inlier) - p_eff))),
                        options.min_noise_px)
        S = S * (sigma / sigma_cov) ** 2
        sigma = sigma_cov
    return problem, control, theta, sigma, r, w, S, len(estimated) + len(break_cols)


def _nuisance_covariance(rig, regularized) -> np.ndarray:
    """Block-diagonal covariance of the regularized lines' (start, period), rig order."""
    blocks = []
    for camera in rig.cameras:
        rep = (regularized or {}).get(camera.name)
        if rep is not None:
            a, b, c = (x if np.isfinite(x) else 0.0 for x in rep.covariance)
            blocks.append(np.array([[a, b], [b, c]]))
    out = np.zeros((2 * len(blocks), 2 * len(blocks)))
    for i, block in enumerate(blocks):
        out[2 * i:2 * i + 2, 2 * i:2 * i + 2] = block
    return out


class _BreakColumns:
    """The breaks (triple knots) of a problem's pieces as parameters of the covariance: where
    each sits in its piece's knot vector, and the reprojection Jacobian of its instant at
    fixed control points (central differences of the basis: the curve moves only within
    three knot spans of the break). The instants themselves are estimated by
    :func:`pslog.estimation.trajectory._refine_breaks` between the joint steps (a joint step
    on them would need the motion prior's dependence on them, which moves the knot spans)."""

    def __init__(self, problem: _Problem, spacing: float):
        self.problem, self.spacing = problem, spacing
        self.items = []  # (piece, index of the first of its three knots)
        for p, k in enumerate(problem.knots):
            inner = np.unique(k)[1:-1]
            for x in inner:
                idx = np.flatnonzero(k == x)
                if len(idx) >= 3:
                    self.items.append((p, int(idx[0])))
        # each piece's rows, in the problem's row order (problem.rows is their concatenation)
        sizes = [len(r) for r in problem.rows_of_piece]
        self.row0 = np.r_[0, np.cumsum(sizes)].astype(np.int64)

    def __len__(self) -> int:
        return len(self.items)

    def columns(self, control: np.ndarray, J: np.ndarray):
        """Per break: the rows (indices into ``problem.rows``) its instant moves and
        ``∂r/∂τ`` there (n_rows, 2)."""
        problem = self.problem
        out = []
        h = 1e-6
        for p, i in self.items:
            k = problem.knots[p]
            lo, hi = k[max(i - 4, 0)], k[min(i + 6, len(k) - 1)]
            local = np.arange(self.row0[p], self.row0[p + 1])
            t = problem.t[problem.rows[local]]
            local = local[(t >= lo) & (t <= hi)]
            t = problem.t[problem.rows[local]]
            X = []
            for sign in (1.0, -1.0):
                kk = k.copy()
                kk[i:i + 3] += sign * h
                first, N = basis(kk, t, 0)
                index = first[:, None] + np.arange(DEGREE + 1) + problem.offset[p]
                X.append(np.einsum("na,nad->nd", N[:, 0], control[index]))
            dX = (X[0] - X[1]) / (2 * h)
            out.append((local, np.einsum("naj,nj->na", J[local], dX)))
        return out


class _Clocks:
    """The clock parameters as the estimator sees them: each camera's time

        τ = ℓ + o'_c + d_c · 1e-6 · (ℓ - ℓ_m) + r_c · (v / height_c - 1/2)

    i.e. the readout referred to the image's centre row and the drift to the middle ``ℓ_m``
    of the logged times, on a clock ``r_1 / 2`` behind the session clock (a common shift of
    every time is absorbed by the trajectory, so this is the same model). With the rig's
    parametrisation (:mod:`pslog.timing`) a readout moves a camera's mean time by half of
    itself and a drift its mean time by ``d · ℓ_m``: offsets, readouts and drifts are then
    strongly correlated and Gauss–Newton crawls along their valley; here they are nearly
    independent. ``o'_c = o_c + d_c · 1e-6 · ℓ_m + (r_c - r_1) / 2`` (camera 1's ``o'`` is 0)."""

    def __init__(self, rig: Rig, unknowns, l_mid: float, tie=None):
        p = camera_parameters(rig)
        self.height = p["height"]
        self.unknowns, self.l_mid = list(unknowns), l_mid
        self.base = self._internal(np.stack([p["clock_offset"], p["clock_drift_ppm"],
                                             p["readout"]], axis=1))
        self.index = [(c, PARAMETERS.index(name)) for c, name in self.unknowns]
        # the cameras whose offset the rig fixes while a drift or a readout is estimated
        # (``estimate`` without offset): their ``o'`` follows those (the rig's offset
        # ``o_c`` is what stays), else a readout or a drift would move the camera's offset
        # unseen (a fit of the readouts alone, the rig's offsets right, was tens of ms off)
        offsets = {c for c, k in self.index if k == 0}
        self.offset = p["clock_offset"]
        self.follow = ([c for c in range(1, len(self.base)) if c not in offsets]
                       if any(k != 0 for _, k in self.index) else [])
        # tied parameters (one readout per camera model): ``tie`` (q,) numbers each unknown
        # by the estimated parameter it takes, in order of first appearance (None: its own);
        # ``M`` (q, m) expands the m estimated to the q unknowns (0/1: readouts are the same
        # internally and in the rig's parametrisation, so a tie is one in either)
        q = len(self.unknowns)
        tie = np.arange(q) if tie is None else np.asarray(tie, dtype=np.int64)
        self.M = (tie[:, None] == np.arange(int(tie.max(initial=-1)) + 1)[None, :]
                  ).astype(np.float64)
        #: the estimated parameters, each named by its first unknown
        self.reduced = [self.unknowns[int(np.flatnonzero(self.M[:, j])[0])]
                        for j in range(self.M.shape[1])]

    def _internal(self, ext: np.ndarray) -> np.ndarray:
        o, d, r = ext.T
        return np.stack([o + d * 1e-6 * self.l_mid + (r - r[0]) / 2, d, r], axis=1)

    def _external(self, inn: np.ndarray) -> np.ndarray:
        o, d, r = inn.T
        return np.stack([o - d * 1e-6 * self.l_mid - (r - r[0]) / 2, d, r], axis=1)

    def _full(self, theta: np.ndarray) -> np.ndarray:
        inn = self.base.copy()
        for (c, k), value in zip(self.index, self.M @ theta, strict=True):
            inn[c, k] = value
        for c in self.follow:
            inn[c, 0] = (self.offset[c] + inn[c, 1] * 1e-6 * self.l_mid
                         + (inn[c, 2] - inn[0, 2]) / 2)
        return inn

    def to_internal(self, theta_ext: np.ndarray) -> np.ndarray:
        """The estimated parameters (m,) from every unknown's value in the rig's
        parametrisation (q,) (a tied one: the mean of its unknowns')."""
        ext = self._external(self.base)
        for (c, k), value in zip(self.index, theta_ext, strict=True):
            ext[c, k] = value
        inn = self._internal(ext)
        full = np.array([inn[c, k] for c, k in self.index])
        return (self.M.T @ full) / np.maximum(self.M.sum(axis=0), 1.0)

    def to_external(self, theta: np.ndarray) -> np.ndarray:
        """Every unknown's value (q,) in the rig's parametrisation from the estimated (m,)."""
        ext = self._external(self._full(theta))
        return np.array([ext[c, k] for c, k in self.index])

    def to_external_matrix(self) -> np.ndarray:
        """``∂θ_rig / ∂θ`` (q, m) (the map is affine)."""
        q, m = self.M.shape
        zero = self.to_external(np.zeros(m))
        return np.stack([self.to_external(np.eye(m)[j]) - zero for j in range(m)], axis=1) \
            if m else np.zeros((q, 0))

    def times(self, obs: Observations, theta: np.ndarray) -> np.ndarray:
        """Capture times τ (s) of every observation on the estimator's clock."""
        inn = self._full(theta)
        cam = obs.camera
        logged = obs.time_ns / NS
        return (logged + inn[cam, 0] + inn[cam, 1] * 1e-6 * (logged - self.l_mid)
                + inn[cam, 2] * (obs.uv[:, 1] / self.height[cam] - 0.5))

    def jacobian(self, logged_s: np.ndarray, v: np.ndarray, cam: np.ndarray) -> np.ndarray:
        """``∂τ/∂(o', d, r)`` (n, 3)."""
        return np.stack([np.ones_like(logged_s), 1e-6 * (logged_s - self.l_mid),
                         v / self.height[cam] - 0.5], axis=1)

    def times_jacobian(self, logged_s: np.ndarray, v: np.ndarray, cam: np.ndarray
                       ) -> np.ndarray:
        """``∂τ/∂θ`` (n, q) of every unknown (before a tie's ``M``): each moves its own
        camera's times (:meth:`jacobian`), and through ``o'`` a camera's whose offset the
        rig fixes (:attr:`follow`: its drift by ``1e-6 ℓ_m``, its readout by 1/2, camera
        1's readout every such camera's by -1/2)."""
        jac = self.jacobian(logged_s, v, cam)
        out = np.zeros((len(cam), len(self.index)))
        follows = np.isin(cam, self.follow)
        for j, (c, k) in enumerate(self.index):
            out[:, j] = np.where(cam == c, jac[:, k], 0.0)
            if not self.follow:
                continue
            if k == 1 and c in self.follow:
                out[:, j] += np.where(cam == c, 1e-6 * self.l_mid, 0.0)
            elif k == 2 and c in self.follow:
                out[:, j] += np.where(cam == c, 0.5, 0.0)
            elif k == 2 and c == 0:
                out[:, j] -= np.where(follows, 0.5, 0.0)
        return out


def _windows(obs: Observations) -> Observations:
    """A long session's detections in ``_N_WINDOWS`` windows of ``_WINDOW_S`` spread evenly
    over it (all of a shorter one): the clocks are global, so these determine them (the
    windows' spread keeps the drift's lever arm) at a bounded cost."""
    t = obs.time_ns / NS
    span = t[-1] - t[0] if len(t) else 0.0
    if span <= _ALL_UP_TO_S:
        return obs
    starts = t[0] + np.linspace(0.0, span - _WINDOW_S, _N_WINDOWS)
    keep = np.zeros(len(t), dtype=bool)
    for a in starts:
        keep |= (t >= a) & (t < a + _WINDOW_S)
    return obs.select(keep)


def _observations_at(obs: Observations, times_s: np.ndarray, order: np.ndarray
                     ) -> Observations:
    time_ns = np.round(times_s[order] * NS).astype(np.int64)
    cam = obs.camera[order]
    # equal (time, camera) after rounding: one nanosecond apart, as the timing module does
    for _ in range(3):
        same = np.r_[False, (np.diff(time_ns) == 0) & (np.diff(cam) == 0)]
        if not same.any():
            break
        time_ns = time_ns + same
    resort = np.lexsort((cam, time_ns))
    if not np.array_equal(resort, np.arange(len(resort))):
        order[:] = order[resort]
        time_ns, cam = time_ns[resort], cam[resort]
    return Observations(time_ns, cam, obs.uv[order], obs.frame_index[order])


def _joint_step(problem, solver, obs, unknowns, theta, params, control, sigma, dt_dtheta, t0,
                dof: float = 1.0, breaks: _BreakColumns | None = None, n_extra: int = 0):
    """One robust Gauss–Newton step on (control points, clocks) by the Schur complement of
    the banded control-point block; σ is ``dof`` · 1.4826 · median |residual| at the step's
    start. Returns the information ``S`` of (clocks, breaks, extra): the breaks' instants
    (``breaks``) and the ``n_extra`` last columns of ``dt_dtheta`` (time perturbations) are
    not stepped, only kept in ``S`` (their information with the clocks widens the clocks'
    covariance)."""
    q, nb = len(unknowns), (len(breaks) if breaks is not None else 0)
    Q = q + nb + n_extra
    times = params.times(obs, theta) - t0
    problem.set_times(times)
    X = problem.positions(control)
    V = problem.velocities(control)
    r, J = problem.project(X)
    sigma = solver._scale(r, sigma, dof)
    s = np.sum(r * r, axis=1) / sigma**2
    w = 1 / (1 + s / _CAUCHY**2)
    n = 3 * problem.m
    n_obs = len(r)
    start, E, _ = problem.data_rows(J, np.zeros_like(r))
    ww = np.repeat(w, 2) / sigma**2
    ab, rhs_c = _normal.accumulate(start, E, -r.reshape(-1), ww, n, problem.prior_ab.copy(),
                                   np.zeros(n))
    rhs_c -= _banded_matvec(problem.prior_ab, control.reshape(-1)) - problem.prior_rhs
    # bordered columns, sparse: clocks ∂r/∂θ = J · p'(t) · ∂t/∂θ (a camera's rows), breaks
    # ∂r/∂τ (the rows within three knot spans)
    JV = np.einsum("naj,nj->na", J, V)  # (n_obs, 2)
    g_rows, g_cols, g_vals = [], [], []
    for j in range(q + n_extra):
        mine = np.flatnonzero(dt_dtheta[:, j])
        g_rows.append(mine)
        g_cols.append(np.full(len(mine), j if j < q else j + nb))
        g_vals.append(JV[mine] * dt_dtheta[mine, j:j + 1])
    columns = breaks.columns(control, J) if breaks is not None and nb else ()
    for b, (local, dr) in enumerate(columns):
        g_rows.append(local)
        g_cols.append(np.full(len(local), q + b))
        g_vals.append(dr)
    rows_ = np.concatenate(g_rows) if g_rows else np.zeros(0, np.int64)
    cols_ = np.concatenate(g_cols) if g_cols else np.zeros(0, np.int64)
    vals_ = np.concatenate(g_vals) if g_vals else np.zeros((0, 2))
    G = sparse.csr_matrix((vals_.reshape(-1), (np.c_[2 * rows_, 2 * rows_ + 1].reshape(-1),
                                               np.repeat(cols_, 2))), shape=(2 * n_obs, Q))
    D = sparse.csr_matrix((E.reshape(-1), ((np.arange(2 * n_obs)[:, None]
                                            + np.zeros(12, np.int64)).reshape(-1),
                                           (start[:, None] + np.arange(12)).reshape(-1))),
                          shape=(2 * n_obs, n))
    WG = G.multiply(ww[:, None]).tocsr()
    B = (D.T @ WG).toarray()
    C = (G.T @ WG).toarray()
    rhs_t = -(WG.T @ r.reshape(-1))
    U = _normal.factor(ab)
    Y = _normal.solve(U, B) if Q else np.zeros((n, 0))
    # the sums over the n trajectory unknowns as einsum, not BLAS (B.T @ Y, B.T @ z): a
    # threaded BLAS splits long sums by thread, so the last bits of the clocks would depend
    # on the number of BLAS threads (OMP_NUM_THREADS, 1 in a pslog batch's Ray workers)
    S = C - np.einsum("ki,kj->ij", B, Y)
    z = _normal.solve(U, rhs_c)
    d_theta = (np.linalg.solve(S[:q, :q], rhs_t[:q] - np.einsum("ki,k->i", B[:, :q], z))
               if q else np.zeros(0))
    d_c = z - Y[:, :q] @ d_theta
    before = solver.cost(control, r, sigma)
    step, accepted = 1.0, False
    for _ in range(6):  # step halving keeps the robust cost from rising
        trial_c = control + step * d_c.reshape(-1, 3)
        trial_t = theta + step * d_theta
        problem.set_times(params.times(obs, trial_t) - t0)
        r_trial, J_trial = problem.project(problem.positions(trial_c))
        if solver.cost(trial_c, r_trial, sigma) <= before:
            accepted = True
            break
        step /= 2
    if not accepted:  # no descent along this direction: stay (the caller stops)
        step = 0.0
        trial_c, trial_t = control, theta
        problem.set_times(times)
        r_trial, J_trial = r, J
    moved = max(float(np.max(np.abs(step * d_c), initial=0.0)),
                float(np.max(np.abs(step * d_theta) * _scale_of(unknowns), initial=0.0)))
    s = np.sum(r_trial * r_trial, axis=1) / sigma**2
    return (trial_c, trial_t, sigma, r_trial, 1 / (1 + s / _CAUCHY**2), J_trial, S, moved)


def _scale_of(unknowns) -> np.ndarray:
    """Converts each clock step to a comparable size (metres-like: 1 ms ≈ 1 mm of motion)."""
    return np.array([{"offset": 1.0, "drift": 1e-6, "readout": 1.0}[p] for _, p in unknowns])


def _banded_matvec(ab: np.ndarray, x: np.ndarray) -> np.ndarray:
    out = ab[-1] * x
    for d in range(1, _normal.WIDTH):
        out[:-d] += ab[-1 - d, d:] * x[d:]
        out[d:] += ab[-1 - d, d:] * x[:-d]
    return out


def _with_rays(obs: Observations, rig: Rig) -> Observations:
    """``obs`` without the detections whose pixel has no ray (beyond the lens model's
    fold-over: NaN undistorted), as every fusion method takes them: missing ones (walk42: a
    webcam whose chessboard calibration's k3 folds over inside its image's corner; the scan's
    two-camera fits took the NaN rays, every trial cost was undefined, and sync said no
    stretch was "seen by it and camera cam1 together long enough to scan its offset")."""
    keep = np.ones(len(obs), dtype=bool)
    for c, cam in enumerate(rig.cameras):
        rows = np.flatnonzero(obs.camera == c)
        if len(rows) and np.any(cam.dist):
            uv = obs.uv[rows]
            ok = np.all(np.isfinite(uv), axis=1)
            ok[ok] = np.all(np.isfinite(cam.undistort_normalized(uv[ok])), axis=1)
            keep[rows] = ok
    return obs if keep.all() else obs.select(np.flatnonzero(keep))


def _scan_offsets(obs, rig, unknowns, theta, params, search_s, options) -> np.ndarray:
    """Each camera's offset scanned over ``±search`` against camera 1 alone: the offset of
    least robust cost of a two-camera trajectory, refined by a parabola."""
    theta = theta.copy()
    for j, (c, p) in enumerate(unknowns):
        if p != "offset":
            continue
        period = 1 / rig.cameras[c].fps
        half = search_s if search_s is not None else period / 2
        pair = (obs.camera == 0) | (obs.camera == c)
        rows = np.flatnonzero(pair)
        # the scan's stretch, on the clocks' current values: among the stretches both cameras
        # see (a blackout of either leaves the pair's trial costs undefined); the first whose
        # trial costs are defined is scanned
        t = params.times(obs, theta)[rows]
        for mid in _scan_centres(t, obs.camera[rows] == c, options.max_gap_s):
            sub = obs.select(rows[np.abs(t - mid) <= _SCAN_WINDOW_S / 2])
            step = min(1e-3, half / 8)
            grid = theta[j] + np.arange(-half, half + step / 2, step)
            costs = np.array([_pair_cost(sub, rig, c, unknowns, theta, j, value, params,
                                         options) for value in grid])
            if not np.all(np.isnan(costs)):
                break
        else:
            raise FusionError(f"camera {rig.cameras[c].name}: no stretch of the session is "
                              f"seen by it and camera {rig.cameras[0].name} together long "
                              f"enough to scan its offset")
        k = int(np.nanargmin(costs))
        best = grid[k]
        if 0 < k < len(grid) - 1:
            cm, c0, cp = costs[k - 1], costs[k], costs[k + 1]
            curv = cm + cp - 2 * c0
            if curv > 0:
                best += 0.5 * (cm - cp) / curv * step
        theta[j] = best
    return theta


def _scan_centres(t: np.ndarray, other: np.ndarray, max_gap_s: float) -> np.ndarray:
    """Centres (s) of the offset scan's stretch of ``_SCAN_WINDOW_S``, to try in this order.

    Parameters
    ----------
    t : (n,) float
        The pair's detection times (s, session clock at the clocks' current values).
    other : (n,) bool
        True for the scanned camera's detections, False for camera 1's.
    max_gap_s : float
        A detection is *shared* when one of the other camera's is within this (s).

    Returns
    -------
    (m,) float
        First the centre nearest the pair's median time (the session's central stretch:
        enough motion, a bounded cost) among the stretches holding at least 90 % of the most
        shared detections any stretch holds; then, should its trial costs be undefined,
        up to ``_SCAN_TRIES - 1`` further stretches, most shared first, none overlapping one
        before. Empty when no detection is shared. Deterministic: ties go to the earlier.
    """
    mine, first = np.sort(t[other]), np.sort(t[~other])
    shared = np.sort(np.r_[mine[_near(mine, first, max_gap_s)],
                           first[_near(first, mine, max_gap_s)]])
    if not len(shared):
        return np.zeros(0)
    half = _SCAN_WINDOW_S / 2
    mid = float(np.median(t))
    # candidates: the median itself (the stretch scanned when both cameras see it) and each
    # shared detection (every stretch of shared detections has one at its centre's reach)
    centres = np.r_[mid, shared]
    count = (np.searchsorted(shared, centres + half, "right")
             - np.searchsorted(shared, centres - half, "left"))
    good = np.flatnonzero(count >= 0.9 * count.max())
    chosen = [centres[good[np.argmin(np.abs(centres[good] - mid))]]]
    for k in np.lexsort((centres, -count)):
        if len(chosen) == _SCAN_TRIES or count[k] == 0:
            break
        if np.all(np.abs(centres[k] - np.array(chosen)) >= _SCAN_WINDOW_S):
            chosen.append(centres[k])
    return np.array(chosen)


def _near(x: np.ndarray, y: np.ndarray, tol_s: float) -> np.ndarray:
    """(len(x),) bool: the sorted times ``x`` (s) with one of the sorted ``y`` within
    ``tol_s``."""
    if not len(y):
        return np.zeros(len(x), dtype=bool)
    j = np.searchsorted(y, x)
    after = np.abs(y[np.minimum(j, len(y) - 1)] - x)
    before = np.abs(x - y[np.maximum(j - 1, 0)])
    return np.minimum(after, before) <= tol_s


def _pair_cost(sub, rig, c, unknowns, theta, j, value, params, options) -> float:
    """Robust cost of a quick two-camera trajectory with camera ``c``'s offset at ``value``."""
    trial = theta.copy()
    trial[j] = value
    times = params.times(sub, trial)
    order = np.argsort(times, kind="stable")
    ordered = _observations_at(sub, times, order)
    pieces = split_pieces(ordered, np.ones(len(ordered), bool), options.max_gap_s)
    if not pieces:
        return np.nan
    t = (ordered.time_ns - ordered.time_ns[0]) / NS
    spacing = 3 * sum(t[p[-1]] - t[p[0]] for p in pieces) / max(
        sum(len(p) - 1 for p in pieces), 1)
    knots = [_knots_with_breaks(t[p[0]], t[p[-1]] + 1e-9, spacing, np.zeros(0))
             for p in pieces]
    loose = MotionPrior(options.prior.gravity, 10 * options.prior.sigma_accel,
                        options.prior.tau_s)
    problem = _Problem(ordered, rig, pieces, knots, loose)
    solver = _Solver(problem, options)
    try:
        control = _initial_control(problem, 1.0)
        control, _, r, _, _ = solver.run(control, 1.0, 3)
    except FusionError:
        return np.nan
    return solver.cost(control, r, 1.0)  # a fixed σ: costs comparable across trials


class ClockSpanError(FusionError):
    """A camera's detections do not overlap camera 1's in time: the cameras' times are not
    on one clock, or the two never saw the ball at once (the cause is not false
    candidates)."""


def _check_coverage(obs: Observations, rig: Rig, max_gap_s: float) -> None:
    """A one-line :class:`FusionError` naming the camera that is seen too little with camera
    1 to be synced."""
    first = obs.time_ns[obs.camera == 0]
    if len(first) < MIN_DETECTIONS:
        raise FusionError(f"camera {rig.cameras[0].name} (the session clock) has "
                          f"{len(first)} detections; sync needs at least {MIN_DETECTIONS}")
    for c in range(1, len(rig)):
        mine = obs.time_ns[obs.camera == c]
        if len(mine) == 0:
            raise FusionError(f"camera {rig.cameras[c].name} has no detection: its clock "
                              f"cannot be estimated")
        j = np.clip(np.searchsorted(first, mine), 1, len(first) - 1)
        near = np.minimum(np.abs(first[j] - mine), np.abs(first[j - 1] - mine))
        shared = int(np.count_nonzero(near <= max_gap_s * NS))
        if shared < MIN_DETECTIONS and (mine[0] > first[-1] or mine[-1] < first[0]):
            # (walk39: two cameras each stamped by its own clock, times years apart; the
            # "shared" count and the caller's note on false candidates hid the cause)
            raise ClockSpanError(
                f"camera {rig.cameras[c].name}'s detections (t = {mine[0] / NS:.3f} .. "
                f"{mine[-1] / NS:.3f} s on the session clock) and camera "
                f"{rig.cameras[0].name}'s ({first[0] / NS:.3f} .. {first[-1] / NS:.3f} s) "
                f"do not overlap in time: their times are not on one clock, or the two "
                f"never saw the ball at once (each blind while the other saw it); on clocks "
                f"apart, put the cameras' times on one clock first (e.g. shift camera "
                f"{rig.cameras[c].name}'s), as close as you can: pslog sync searches each "
                f"offset within half a frame period (--search-ms widens it)")
        if shared < MIN_DETECTIONS:
            raise FusionError(f"camera {rig.cameras[c].name} has {shared} detections within "
                              f"{max_gap_s * 1e3:g} ms of one of camera {rig.cameras[0].name}"
                              f"'s; sync needs at least {MIN_DETECTIONS} shared in time")


def _check_motion(problem, control, unknowns, std, rig, theta, span_s: float) -> None:
    """A one-line :class:`FusionError` when the ball barely moves, or when an estimate is so
    uncertain that the data did not determine it, or lies beyond what a clock can be (a
    drift beyond ±1000 ppm, an offset beyond a day: ``theta``, the rig's parametrisation);
    an undetermined drift on a session (``span_s``, seconds) shorter than
    :data:`AUTO_DRIFT_MIN_S` is said to be the session's length, not the ball's motion."""
    speed = np.linalg.norm(problem.velocities(control), axis=1)
    moving = int(np.count_nonzero(speed >= MOVING_M_S))
    if np.median(speed) < 0.05 and moving < MIN_DETECTIONS:
        raise FusionError(f"the ball barely moves (median speed {np.median(speed):.3f} m/s; "
                          f"faster than {MOVING_M_S:g} m/s at {moving} of {len(speed)} "
                          f"detections, sync needs {MIN_DETECTIONS}): its track cannot tell "
                          f"the cameras' clocks apart")
    bound = {"offset": MAX_CLOCK_OFFSET_S, "drift": MAX_CLOCK_DRIFT_PPM, "readout": np.inf}
    for (c, p), s, value in zip(unknowns, std, theta, strict=True):
        limit = {"offset": 0.25 / rig.cameras[c].fps, "drift": 1000.0,
                 "readout": 1 / rig.cameras[c].fps}[p]
        if not (s < limit and abs(value) <= bound[p]):
            short = p == "drift" and span_s < AUTO_DRIFT_MIN_S
            raise FusionError(f"camera {rig.cameras[c].name}: the {p} is not determined "
                              + ("" if short else "by the ball's motion ")
                              + f"(estimate {value:.3g}, standard deviation {s:.3g}); "
                              + ("a readout needs the ball to move up or down the image"
                                 if p == "readout" else
                                 f"the session ({span_s:.1f} s) is too short for a drift: "
                                 f"it needs at least {AUTO_DRIFT_MIN_S:.0f} s"
                                 if short else "the ball needs to move more"))


#: the coarse offset scan (:func:`coarse_offsets`): its grid step, as a share of the frame
#: period of the slower camera of each pair; its epipolar tolerance, pixels (on undistorted
#: pixels, camera 1's interpolated to the other's time: a ball at 500 px/s moves 2 px in a
#: step of 30 fps); detections of the scanned camera used at most (evenly spaced)
COARSE_STEP = 0.25
COARSE_TOL_PX = 6.0
_COARSE_DETECTIONS = 3000
#: a coarse offset stands only where its agreeing detections exceed the chance level (the
#: median count over the scanned offsets) by at least this many, by this many times the
#: chance count's own spread (its square root), and by this many times the excess of any
#: offset further than _COARSE_APART_S from the peak's stretch (a second peak)
COARSE_MIN_AGREE = 30
COARSE_OVER_NOISE = 6.0
COARSE_OVER_SECOND = 1.5
_COARSE_APART_S = 0.05
#: still pixels (a static object, a ball at rest): a candidate with this share of its
#: camera's candidates within _STILL_PX of it (they agree with any offset: left out)
_STILL_SHARE = 0.02
_STILL_PX = 3.0


def coarse_offsets(detections, rig: Rig, search_s: float,
                   max_gap_s: float) -> tuple[np.ndarray, list[str]]:
    """Each camera's clock offset against camera 1's to a few milliseconds over
    ``±search_s`` (seconds to a minute: two hosts' clocks), from the ball's pixels alone.

    Every candidate of every frame is used but still ones (a pixel where
    :data:`_STILL_SHARE` of its camera's candidates lie within :data:`_STILL_PX`: a static
    object, a ball at rest, which agree at any offset). Camera 1's track: its first such
    candidate a frame. For a trial offset δ of camera c, its candidates at times ``t + δ``
    (the rig's clocks as they stand, then δ) are compared with that track: camera 1's
    undistorted pixel linearly interpolated to that time (between its two detections around
    it, no further apart than ``max_gap_s``) must lie within :data:`COARSE_TOL_PX` of the
    epipolar line of camera c's undistorted pixel (``x_1ᵀ F_c1 x_c = 0``). The count of
    such agreeing candidates peaks at the true offset (the ball's pixels correspond) and
    stays at chance elsewhere (a pixel near a random line: a few %); false candidates only
    add to chance. δ is scanned on a grid of :data:`COARSE_STEP` frame periods over
    ``±search_s``; the best δ stands where its count's excess over chance (the median
    count) passes :data:`COARSE_MIN_AGREE`, :data:`COARSE_OVER_NOISE` times the chance
    count's square root and :data:`COARSE_OVER_SECOND` times any other peak's excess (a
    periodic motion), else that camera keeps 0 and a note says why. The fine offset is then
    the spline scan's and the joint estimate's (:func:`estimate_clocks` from the shifted
    rig).

    Parameters
    ----------
    detections : pslog.records.Detections, every candidate (LOGGED times)
    rig : Rig, its clock model applied as it stands
    search_s : float, the half-width scanned, s
    max_gap_s : float, the widest pair of camera 1's detections interpolated, s

    Returns
    -------
    delta : (m,) float, s, to add to each camera's ``clock_offset`` (0 for camera 1 and for
        cameras whose offset is not determined)
    notes : list of str, one per camera left at 0
    """
    from ..geometry import fundamental_matrices
    from ..timing import true_times_ns

    m = len(rig)
    delta = np.zeros(m)
    notes: list[str] = []
    p = camera_parameters(rig)
    frame = detections.cand_frame
    cam = detections.frame_camera[frame].astype(np.int64)
    uv = detections.cand_uv
    t = true_times_ns(detections.frame_time_ns[frame], uv[:, 1], p["height"][cam],
                      p["clock_offset"][cam], p["clock_drift_ppm"][cam],
                      p["readout"][cam]) / NS
    und = np.full((len(cam), 2), np.nan)
    keep = np.zeros(len(cam), dtype=bool)
    for c, camera in enumerate(rig.cameras):
        rows = np.flatnonzero(cam == c)
        if not len(rows):
            continue
        und[rows] = camera.undistort(uv[rows])
        keep[rows] = np.all(np.isfinite(und[rows]), axis=1) & ~_still(uv[rows])
    F = fundamental_matrices(rig.cameras)
    first = np.flatnonzero((cam == 0) & keep)
    if len(first):  # camera 1's track: its first kept candidate a frame
        first = first[np.r_[True, frame[first][1:] != frame[first][:-1]]]
    first = first[np.argsort(t[first], kind="stable")]
    t0, u0 = t[first], und[first]
    for c in range(1, m):
        rows = np.flatnonzero((cam == c) & keep)
        name = rig.cameras[c].name
        if len(rows) < COARSE_MIN_AGREE or len(t0) < 2:
            notes.append(f"camera {name}: too few moving detections for the coarse offset "
                         f"scan ({len(rows)}, camera {rig.cameras[0].name} {len(t0)})")
            continue
        rows = rows[np.unique(np.linspace(0, len(rows) - 1, _COARSE_DETECTIONS).astype(int))]
        tc = t[rows]
        # camera c's pixels' epipolar lines in camera 1's image (a u + b v + c = 0, a² + b²
        # = 1: distances in pixels)
        lines = np.column_stack([und[rows], np.ones(len(rows))]) @ F[c, 0].T
        with np.errstate(invalid="ignore", divide="ignore"):
            lines = lines / np.hypot(lines[:, 0], lines[:, 1])[:, None]
        period = max(1 / rig.cameras[0].fps, 1 / rig.cameras[c].fps)
        step = COARSE_STEP * period
        grid = np.arange(-search_s, search_s + step / 2, step)
        counts = np.zeros(len(grid), dtype=np.int64)
        chunk = max(1, 2_000_000 // len(rows))
        for s in range(0, len(grid), chunk):
            at = tc[None, :] + grid[s:s + chunk, None]  # (k, n) camera 1's times
            j = np.clip(np.searchsorted(t0, at), 1, len(t0) - 1)
            ta, tb = t0[j - 1], t0[j]
            inside = (ta <= at) & (at <= tb) & (tb - ta <= max_gap_s)
            with np.errstate(invalid="ignore", divide="ignore"):
                w = np.where(tb > ta, (at - ta) / (tb - ta), 0.0)
                uu = u0[j - 1, 0] + w * (u0[j, 0] - u0[j - 1, 0])
                vv = u0[j - 1, 1] + w * (u0[j, 1] - u0[j - 1, 1])
                d = np.abs(lines[:, 0] * uu + lines[:, 1] * vv + lines[:, 2])
            counts[s:s + chunk] = np.count_nonzero(inside & (d <= COARSE_TOL_PX), axis=1)
        k = int(np.argmax(counts))
        chance = float(np.median(counts))
        excess = counts[k] - chance
        # the peak's own stretch: the offsets around it whose excess is at least half its
        # own (a slow ball agrees over a few steps), and _COARSE_APART_S either side
        half = counts >= chance + 0.5 * excess
        lo, hi = k, k
        while lo > 0 and half[lo - 1]:
            lo -= 1
        while hi < len(grid) - 1 and half[hi + 1]:
            hi += 1
        far = (grid < grid[lo] - _COARSE_APART_S) | (grid > grid[hi] + _COARSE_APART_S)
        second = float(counts[far].max()) - chance if np.any(far) else 0.0
        if excess < COARSE_MIN_AGREE or excess < COARSE_OVER_NOISE * np.sqrt(max(chance, 1.0)):
            notes.append(f"camera {name}: no offset within ±{search_s:g} s makes its "
                         f"detections agree with camera {rig.cameras[0].name}'s "
                         f"({int(counts[k])} of {len(rows)} at best, {chance:.0f} by chance)")
            continue
        if excess < COARSE_OVER_SECOND * second:
            notes.append(f"camera {name}: its offset is ambiguous within ±{search_s:g} s "
                         f"({int(counts[k])} agreeing detections at {grid[k] * 1e3:+.1f} ms, "
                         f"{int(counts[far].max())} at "
                         f"{grid[far][np.argmax(counts[far])] * 1e3:+.1f} ms)")
            continue
        delta[c] = 0.5 * (grid[lo] + grid[hi])  # (the stretch's middle)
    return delta, notes


def _still(uv: np.ndarray) -> np.ndarray:
    """(n,) bool: the pixels ``uv`` (n, 2) of one camera with at least :data:`_STILL_SHARE`
    of them within about :data:`_STILL_PX` (counted on a grid of that size, each pixel's
    cell and its eight neighbours)."""
    cell = np.floor(uv / _STILL_PX)
    ok = np.all(np.isfinite(cell), axis=1)
    still = np.zeros(len(uv), dtype=bool)
    if not ok.any():
        return still
    keys, inverse, counts = np.unique(cell[ok].astype(np.int64), axis=0, return_inverse=True,
                                      return_counts=True)
    total = np.zeros(len(keys), dtype=np.int64)
    for du in (-1, 0, 1):
        for dv in (-1, 0, 1):
            shifted = keys + np.array([du, dv])
            # the count of the cell at ``shifted`` (keys sorted lexicographically)
            at = np.searchsorted(keys[:, 0] * (1 << 32) + keys[:, 1],
                                 shifted[:, 0] * (1 << 32) + shifted[:, 1])
            at = np.minimum(at, len(keys) - 1)
            hit = np.all(keys[at] == shifted, axis=1)
            total += np.where(hit, counts[at], 0)
    still[ok] = total[inverse.ravel()] >= _STILL_SHARE * len(uv)
    return still


#: A motion repeats with period ``L`` (:func:`motion_period`) where, in every camera's view,
#: three quarters of its detections lie within this many pixels of its own track ``L`` later.
PERIOD_TOL_PX = 3.0
#: ... or this many times the pixel noise σ given, where more (review41b: a turntable at
#: 1.5 px noise was no period at 3 px: a noisy pair's distance exceeds it in half the pairs)
PERIOD_TOL_SIGMAS = 4.0
#: ... and the track moves: at some shorter lag, three quarters of them lie further than this.
PERIOD_MOVES_PX = 30.0
#: The lags tried: from this (s) to half the span of a camera's detections, at most
#: :data:`PERIOD_MAX_S`, on a grid of :data:`_PERIOD_STEP_S`, then refined to
#: :data:`_PERIOD_FINE_S`.
PERIOD_MIN_S = 0.1
PERIOD_MAX_S = 20.0
_PERIOD_STEP_S = 2e-3
_PERIOD_FINE_S = 5e-5
#: The close lags from the first searched for the least distance (grid steps).
_PERIOD_RUN = 50
#: Detections of each camera compared at each lag (evenly spaced among its own).
_PERIOD_DETECTIONS = 400


def motion_period(obs: Observations, rig: Rig, max_gap_s: float,
                  noise_px: float = 0.0) -> float | None:
    """The period (s) with which the ball's motion repeats in every camera's view (a
    turntable, a pendulum), or None: the time shift under which each camera's track maps
    onto itself, so that offsets whole periods apart fit the detections equally well and
    no estimate from them can tell them apart (session 41).

    At a lag ``L``, each of (up to :data:`_PERIOD_DETECTIONS` of) a camera's detections at
    time ``t`` (the rig's clock model applied) where its track moves (more than
    the tolerance to its detection :data:`PERIOD_MIN_S` later: a still stretch, the
    same at every lag, fixes no offset and tells no period; a camera whose track never
    moves is not compared) is compared with the camera's own pixel at
    ``t + L``, linearly interpolated between its two detections around it (no further apart
    than ``max_gap_s``). ``L`` is a period where, for every camera compared, at least 30 pairs
    exist (a quarter of those tried) and three quarters of them lie within
    the tolerance (:data:`PERIOD_TOL_PX`, or :data:`PERIOD_TOL_SIGMAS` times ``noise_px``
    where more), while at some shorter lag three quarters lie further than
    :data:`PERIOD_MOVES_PX` (a ball at rest repeats at any lag: no period). The smallest such
    ``L`` of a grid of :data:`_PERIOD_STEP_S` from :data:`PERIOD_MIN_S` to half the shortest
    camera span (at most :data:`PERIOD_MAX_S`), refined at :data:`_PERIOD_FINE_S` to the
    lag of least distance nearby.

    Parameters
    ----------
    obs : Observations, the ball, one per frame, at LOGGED times
    rig : Rig, the clock model (an estimate's) applied to ``obs``
    max_gap_s : float, the widest pair of a camera's detections interpolated, s
    noise_px : float, the detections' pixel noise σ (a sync's ``noise_px``): the tolerance
        :data:`PERIOD_TOL_PX` is widened to :data:`PERIOD_TOL_SIGMAS` σ where that is more

    Returns
    -------
    float or None : the period, s
    """
    from ..timing import true_times_ns

    tol = max(PERIOD_TOL_PX, PERIOD_TOL_SIGMAS * float(noise_px))
    if len(obs) == 0 or len(rig) < 2:
        return None
    p = camera_parameters(rig)
    cam = obs.camera.astype(np.int64)
    t = true_times_ns(obs.time_ns, obs.uv[:, 1], p["height"][cam], p["clock_offset"][cam],
                      p["clock_drift_ppm"][cam], p["readout"][cam]) / NS
    tracks = []
    for c in range(len(rig)):
        rows = np.flatnonzero(cam == c)
        rows = rows[np.argsort(t[rows], kind="stable")]
        if len(rows) < 2 * MIN_DETECTIONS:
            return None  # (a camera seen too little repeats nothing that can be told)
        tc, uc = t[rows], obs.uv[rows]
        # the detections where the track moves: more than the tolerance to its detection
        # PERIOD_MIN_S on (review41b: a turntable after 10 s at rest was no period, its
        # still half close at every lag and never "moved")
        ahead = np.searchsorted(tc, tc + PERIOD_MIN_S)
        there = np.minimum(ahead, len(tc) - 1)
        moving = np.flatnonzero((ahead < len(tc)) & (tc[there] - tc <= PERIOD_MIN_S + max_gap_s)
                                & (np.hypot(*(uc[there] - uc).T) > tol))
        tracks.append((tc, uc, moving[np.unique(np.linspace(
            0, len(moving) - 1, min(len(moving), _PERIOD_DETECTIONS)).astype(int))]))
    span = min(float(tc[-1] - tc[0]) for tc, _, _ in tracks)
    top = min(PERIOD_MAX_S, span / 2)
    # the cameras whose track moves (one seeing the ball still, at every lag the same, tells
    # no period; none: no period)
    active = [c for c, (_, _, rows) in enumerate(tracks) if len(rows) >= 2 * MIN_DETECTIONS]
    if top <= PERIOD_MIN_S or not active:
        return None

    def distances(c: int, lags: np.ndarray) -> np.ndarray:
        """(k, n) camera ``c``'s pixel distances from its detections at ``t`` to its track
        at ``t + lags`` (k,) (NaN: no pair of detections around it within the gap)."""
        tc, uc, rows = tracks[c]
        at = tc[rows][None, :] + lags[:, None]
        j = np.clip(np.searchsorted(tc, at), 1, len(tc) - 1)
        ta, tb = tc[j - 1], tc[j]
        inside = (ta <= at) & (at <= tb) & (tb - ta <= max_gap_s)
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(tb > ta, (at - ta) / (tb - ta), 0.0)
            du = uc[j - 1, 0] + w * (uc[j, 0] - uc[j - 1, 0]) - uc[rows, 0]
            dv = uc[j - 1, 1] + w * (uc[j, 1] - uc[j - 1, 1]) - uc[rows, 1]
        return np.where(inside, np.hypot(du, dv), np.nan)

    def shares(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(k,) the share of each lag's pairs within the tolerance and beyond
        PERIOD_MOVES_PX (0 where too few pairs)."""
        pairs = np.count_nonzero(~np.isnan(d), axis=1)
        enough = pairs >= max(MIN_DETECTIONS, d.shape[1] // 4)
        with np.errstate(invalid="ignore", divide="ignore"):
            close = np.count_nonzero(d <= tol, axis=1) / pairs
            far = np.count_nonzero(d > PERIOD_MOVES_PX, axis=1) / pairs
        return np.where(enough, close, 0.0), np.where(enough, far, 0.0)

    lags = np.arange(PERIOD_MIN_S, top + _PERIOD_STEP_S / 2, _PERIOD_STEP_S)
    chunk = max(1, 2_000_000 // _PERIOD_DETECTIONS)

    def share_at(c: int, at: np.ndarray, which: int) -> np.ndarray:
        """(len(at),) camera ``c``'s close (0) or far (1) share at lags ``at``."""
        return np.concatenate([shares(distances(c, at[s:s + chunk]))[which]
                               for s in range(0, len(at), chunk)] or [np.zeros(0)])

    # camera 1's track first, every lag (a count per lag: cheap); the track's movement on
    # every tenth lag (a ball at rest repeats at any lag: the period must come after the
    # first lag at which some camera's track has moved away); the other cameras only at the
    # lags left
    close = share_at(active[0], lags, 0) >= 0.75
    if not close.any():
        return None
    coarse = lags[::10]
    moved = np.zeros(len(coarse), dtype=bool)
    for c in active:
        moved |= share_at(c, coarse, 1) >= 0.75
    if not moved.any():
        return None
    left = np.flatnonzero(close & (lags > coarse[np.argmax(moved)]))
    for c in active[1:]:
        left = left[share_at(c, lags[left], 0) >= 0.75]
    if not len(left):
        return None
    k = int(left[0])

    # the run of close lags from the first (the tolerance admits a few ms either side of
    # the period: a ball at 500 px/s moves 3 px in 6 ms), its least median distance among
    # every camera's, refined
    def worst(trial: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.max([np.nanmedian(distances(c, trial), axis=1)
                           for c in active], axis=0)

    near = lags[k:k + _PERIOD_RUN]
    run = int(np.argmin(np.r_[close[k:k + _PERIOD_RUN], False]))
    best = near[int(np.nanargmin(worst(near[:max(run, 1)])))]
    fine = best + np.arange(-_PERIOD_STEP_S, _PERIOD_STEP_S + _PERIOD_FINE_S / 2,
                            _PERIOD_FINE_S)
    return float(fine[np.nanargmin(worst(fine))])
