"""``filter``: a causal extended Kalman filter, a point at every detection it can vouch for.

Each detection updates the ball's state at its own (corrected, :mod:`pslog.timing`) capture
time; the state can be predicted to any later instant (:meth:`BallFilter.predict`). The
equations, exactly as implemented, are in ``docs/methods.md`` (section ``filter``); in short:

- state ``x = (p, v)``: position (m) and velocity (m/s), world frame, with covariance ``P``
  (6 x 6);
- process model over ``Δt``: constant acceleration ``a = g - k ‖v‖ v`` (gravity and quadratic
  air drag, ``k`` of a golf ball by default) for the mean; the covariance is propagated with
  the drag-free transition ``F = [[I, Δt I], [0, I]]`` and continuous white-noise
  acceleration of spectral density ``q`` (Bar-Shalom, Li & Kirubarajan, *Estimation with
  Applications to Tracking and Navigation*, 2001, section 6.2.2): the drag's Jacobian term,
  ``k ‖v‖ Δt``, is below 1e-3 at a rally's speeds and frame rates and is left to ``q``;
- a floor contact predicted (session 31, ``floor_m``): a step whose mean path reaches the
  floor (the ball's centre at ``floor_m``) falling faster than 0.05 m/s is split at the
  contact; the velocity is reflected there (``restitution``, ``bounce_friction``) and the
  covariance goes through the hybrid system's saltation matrix (Kong, Payne, Council &
  Johnson, "The Salted Kalman Filter", Automatica 131, 2021) plus the reflection's
  uncertainty (:func:`_bounced`);
- two motion models mixed by an interacting multiple model (Blom & Bar-Shalom 1988;
  Bar-Shalom et al. section 11.6): ballistic (the above) and *supported* (without gravity
  and, by default, without air drag, ``supported_drag_per_m``: a ball rolling on the floor,
  carried, swung, or on a line), switching at rate
  ``model_switch_per_s``. Their covariances are equal (same ``F``, ``q``, ``H``), so the
  filter carries one covariance, the mixture's mean, the ballistic model's probability ``μ``
  and the difference ``e`` of the models' means; the models' likelihoods (equal ``S``)
  differ only by their innovations, ``e`` accumulating gravity's effect over the updates;
- a third model, a *coordinated turn* about the vertical with the turn rate ``ω`` in its
  state (7 states, its own covariance; Bar-Shalom et al. chapter 11; Li & Jilkov, "Survey
  of maneuvering target tracking. Part I: Dynamic models", IEEE Trans. AES 39(4), 2003,
  section 4): the horizontal velocity turns by ``ω Δt`` per step, speed kept, constant
  vertical velocity, no gravity (a ball swung, on a turntable, circling), process noise
  the adapted ``q`` plus ``turn_rate_psd`` on ``ω``. It is mixed with the pair (ballistic,
  supported) by a second interacting multiple model (switching at ``turn_switch_per_s``)
  in a *variable* model set (Li & Bar-Shalom, "Multiple-model estimation with variable
  structure", IEEE Trans. AC 41(4), 1996): it joins at a track's start and when the adapted
  ``q`` reaches ``turn_on_accel2 / Σ fps`` (an acceleration the pair lacks, the same on
  every rig: :func:`turn_on_threshold`), leaves when unlikely or
  its ``ω`` is within 2σ of 0; the pair leaves while the turn model alone explains the
  motion and rejoins when ``q`` grows again or at a jump. So a flight pays for one model
  set and a circle for the other, not both;
- the pixel noise ``σ`` is estimated: an inverse-gamma posterior of ``σ²`` updated by
  variational Bayes at every accepted detection (Särkkä & Nummenmaa, IEEE Trans. AC 54(3),
  2009; forgetting ``1 - adapt_rate``), its weak prior (``noise_px``, weight
  ``noise_prior_weight``) updated at each start by the window fit's residuals (conjugate
  least-squares update); the process noise ``q`` adapts to the motion: a consistent
  filter's innovations are white, a lagging one's consecutive innovations of a camera
  agree, so ``q`` grows with their product (a spiral, a straight line without gravity, a
  turntable) once their one-sided CUSUM passes a threshold (a change detector, session 33:
  white innovations leave it at its floor) and returns to its floor on a flight
  (``accel_step_var`` times the rig's detections per second: the same velocity variance
  per detection interval,
  :func:`accel_floor`; or ``accel_psd``);
- measurement: the detection's *distorted* pixel, ``z = π_c(p) + w``, ``w ~ N(0, σ² I)``,
  through camera ``c``'s projection with its lens model; ``H = [∂π_c/∂p, 0]`` (2 x 6).
  Pixels, not rays: the detector's noise is isotropic in the recorded image, no detection is
  undistorted (no Newton iterations per detection), and the innovation is in pixels, where
  a user judges it;
- gating (Bar-Shalom et al., section 5.4): the normalised innovation squared
  ``NIS = yᵀ S⁻¹ y`` is compared with the chi-square quantile of 2 degrees of freedom
  (``gate``). A detection outside the gate is first tried as a bounce or a kick: a velocity
  jump at an instant within the step, position continuous (three hypotheses: a floor
  bounce reflecting the velocity along gravity, a jump mostly along gravity, a kick of
  standard deviation ``jump_speed`` on every axis), placed before one of the last three
  accepted detections (the most likely pair wins); accepted if then inside the gate
  (``jump`` = 1). Otherwise it is rejected (``rejected`` = 1; the point is the
  prediction, its published covariance with the jumps its gap may hide). After
  ``max_rejects`` consecutive rejections, or a time without an accepted detection longer
  than ``max_gap_s``, the track is lost;
- (re)initialisation: from a short window of the latest detections (at least
  ``init_detections`` of two cameras or more, within ``max_gap_s`` of each other): a
  least-squares fit per model (ballistic, supported: to their viewing rays, refined by
  Gauss-Newton in distorted pixels; the coordinated turn by Gauss-Newton in pixels under its
  turn rate's prior), accepted when every detection reprojects inside the gate and the path
  is no faster than a ball (``max_speed_m_s``, the gate's bound, to three standard
  deviations); each model starts at its own fit, its probability from the fits'
  likelihoods (``start_models``).
  A window too short in time to pin the velocity (``init_window`` detections at 60 fps and
  above) grows by the next detections until its fit passes (``init_span_s``).

- withheld points (counted in ``Track.dropped`` by reason, the state updated all the same):
  ``unconfirmed``, from a jump (or an update of NIS above ``confirm_nis``, or the first
  update after a predicted floor contact) until two more
  accepted updates, one at least from another camera, confirm it (one camera's pixel does
  not fix the new velocity along its rays); ``uncertain``, ``std_m`` above ``max_std_m``;
  ``held`` (the batch and :class:`FilterStream`, ``hold_nis``): a point held for the next
  detection of another camera — a plain update's of NIS above ``hold_nis`` or after a
  missed slot (``hold_gap``), a start's (``hold_start``: its window's fit can absorb one
  wrong detection) and a rejected detection's (``hold_rejected``) — withdrawn when that
  detection is rejected or made a jump placed before it (a start's and a rejected one's:
  anywhere the jump search reaches back to, since the accepted detection before it), or the
  track is lost first.

Causality: the point of a detection uses only the detections up to it in (time, camera)
order; batch (:func:`fuse_filter`) and streaming run the same per-detection code, so the
streaming form (:class:`FilterStream`, used by :class:`~pslog.fusion.stream.StreamFuser`)
gives exactly the batch points.

Implementation: the per-detection step (prediction, innovation, update, the models' mixing,
the gate, the jump search, the noise adaptations, withholding) is compiled with numba
(:func:`pslog._jit.kernel`) over the state kept in two preallocated arrays (float64 and
int64, layout below); :func:`fuse_filter` runs one compiled loop over every detection and
:meth:`BallFilter.push` the same compiled step for one. The (re)initialisation's window
fits (least squares on rays, then Gauss-Newton in pixels, per model) are compiled too
(:func:`_window_fit`, :func:`_turn_window_fit`: the same LAPACK least squares as numpy's);
their search over windows and the models' weighing stay in Python, while there is no
track. Every equation keeps the pure-Python filter's order of operations
(IEEE arithmetic, no fastmath, ``x ** 3.0`` through libm's ``pow`` as Python's ``**``, the
pixel lengths by CPython's ``math.hypot``), so the points are bit for bit that filter's
(``benchmarks/filter_equality.py``).

Per-point quality (columns of the Track, NaN where not applicable):

- ``std_m``: position standard deviation ``sqrt(trace P_pp)`` after the update, metres (as
  ``smooth``), ``P_pp`` the reported covariance: the mixture's with the turn model in the set
  (:func:`_combined_point`), plus an unseen jump's while one camera goes on alone
  (:func:`_unseen_jump`), at a rejected detection (the prediction) the jumps of the gap
  since the latest accepted one (:func:`_unseen_gap_jump`), and at an accepted jump's point
  and the next 10–12 accepted ones (the jump's replay holds ``_JBUF``) the error of the
  jump's unknown instant
  (:func:`_instant_term`); ``std_x_m``, ``std_y_m``,
  ``std_z_m`` per axis (its diagonal);
- ``innovation_px``: distance of the detection from the predicted point's projection, pixels;
- ``residual_px``: its distance from the updated point's projection, pixels;
- ``nis``: the normalised innovation squared the gate tested (with the jump's covariance
  when ``jump`` is 1);
- ``gap_s``: time since the previous accepted detection, the span bridged by prediction;
- ``jump``: 1 where a velocity jump (bounce, kick) was accepted, else 0;
- ``rejected``: 1 where the detection failed the gate and the point is the prediction;
- ``init``: 1 where the track was (re)initialised from the window at this detection.
"""

from __future__ import annotations

import functools
import math
import sys
from dataclasses import dataclass

import numpy as np

from .._jit import cython_linalg_by_file, kernel
from ..errors import FusionError
from ..motion import BALL_RADIUS, MAX_BALL_SPEED_M_S, Ball, G
from ..records import NS, Observations, Track
from ..rig import Rig
from . import FILTER_HOLD_NIS

# (the window fits' LAPACK without scipy.linalg's import: pslog._jit.cython_linalg_by_file)
cython_linalg_by_file()

#: Quality columns of a ``filter`` track, in order (module docstring).
FILTER_QUALITY = ("std_m", "std_x_m", "std_y_m", "std_z_m", "innovation_px", "residual_px",
                  "nis", "gap_s", "jump", "rejected", "init")
#: Pixels farther than this many image sizes from the image are not detections (as prepare).
_FAR_IMAGES = 10
#: A point closer than this to a camera's plane (metres) is not in front of it.
_MIN_DEPTH_M = 1e-3
_NAN = float("nan")
#: The largest error a point may have, with 95 % probability, to be output (issue 10: "no
#: output point further than 5 cm from the truth"): ``max_std_m``'s default is this / 1.96.
_MAX_ERROR_M = 0.05
#: A jump is looked for before this many accepted detections back (and at the newest one).
_JUMP_LAG = 2
#: accepted updates after a jump whose points publish its instant's term
#: (:func:`_instant_term`), at least; the buffer: the jump's replay (its detection and its
#: lag's, 1 to ``_JUMP_LAG + 1``) and these, so 10 to 12 after a jump
_JUMP_RELIN = 10
_JBUF = _JUMP_LAG + 1 + _JUMP_RELIN
#: A track whose first detections after its start include a rejected one is dropped (no
#: point from it) until this many were accepted.
_CONFIRM = 2
#: A bounce's velocity jump across the floor's normal, in variance relative to along it.
_BOUNCE_SIDE = 0.05
#: A floor bounce's velocity about its expected reflection: standard deviations along
#: gravity and across, m/s.
_REFLECT_ALONG, _REFLECT_SIDE = 1.0, 0.6
#: A predicted floor contact (``floor_m``) reflects the velocity only when the mean falls
#: onto the floor faster than this, m/s: slower, the ball rolls or rests on it (the threshold
#: of :func:`pslog.motion.bouncing`), so a ball on the floor does not bounce forever.
_BOUNCE_MIN_SPEED = 0.05
#: The process noise's adaptation statistic is clipped to this (an outlier moves q little).
_R_CLIP = 4.0
#: The ballistic model's probability at a track's start (its window is fitted ballistically).
_INIT_BALLISTIC = 0.9
#: Bound of one detection's log likelihood ratio between the models (an outlier moves μ little).
_LOG_ODDS_CLIP = 4.0
_ZERO6 = (0.0,) * 6
_ZERO3 = np.zeros(3)  # the supported model's gravity in the window fit
#: What :meth:`BallFilter._fit` returns for a fit whose velocity alone is too uncertain.
_SHORT = "short"
#: What :meth:`BallFilter._fit` returns for a fit that passes the residual tests but whose
#: position is too uncertain (too little information: a shorter window has still less).
_WEAK = "weak"
#: Accepted updates (one at least from another camera) that confirm a jump.
_CONFIRM_UPDATES = 2
#: The turn model's probability when it joins the model set, and below which it leaves it.
_TURN_START, _TURN_OFF = 0.1, 0.03
#: Accepted updates the turn model stays in the set after joining (its turn rate settles).
_TURN_MIN_UPDATES = 12
#: The turn model also leaves when its turn rate is within this many standard deviations
#: of 0 (it is then the supported model).
_TURN_SIGNIFICANT = 2.0


@dataclass(frozen=True)
class FilterOptions:
    """Settings of the ``filter`` method.

    Attributes
    ----------
    noise_px : float, standard deviation of a detection's pixel, per axis, pixels
    accel_psd : float or None, spectral density ``q`` of the white-noise acceleration (drag
        error, spin, model error), m²/s³: the adapted ``q``'s start and floor; None (the
        default): ``accel_step_var`` times the rig's detection rate ``R = Σ fps``
    accel_step_var : float, m²/s², the velocity variance the floor of ``q`` adds per
        detection interval (``q T`` with ``T = 1/R``) when ``accel_psd`` is None: 0.001
        m²/s³ at two cameras at 30 fps, 0.0015 at three, 0.012 at three at 240 fps (session
        11; before, 0.01 on every rig)
    drag_per_m : float, ``k`` of the quadratic drag ``a = -k ‖v‖ v``, 1/m (a golf ball's)
    gravity : (3,) m/s²
    gate : float, chi-square gate on the normalised innovation (2 degrees of freedom;
        18.4 is the 99.99 % quantile)
    jump_speed : float, m/s, standard deviation of the velocity jump of a bounce or a kick
    bounce_shape : bool, also try a floor bounce (the velocity along gravity reflected) and
        a jump mostly along gravity (variance ``σ_j²`` along, 5 % of it across) besides a
        kick (``σ_j²`` on every axis)
    restitution, bounce_friction : float, a floor bounce's expected reflection: the velocity
        along gravity times ``-restitution``, the rest times ``1 - bounce_friction`` (a golf
        ball on a floor)
    floor_m : float or None, height of the ball's centre at a floor contact, metres, along
        ``−ĝ`` (the world's z when gravity is along −z): the plane ``−ĝ·p = floor_m``; the
        default, a golf ball's radius, is for a world whose ``z = 0`` is the floor. When a
        prediction's mean path crosses it falling faster than 0.05 m/s, the prediction
        stops at the contact, reflects the velocity (``restitution``, ``bounce_friction``)
        and goes on; the covariance through the hybrid system's saltation matrix plus the
        reflection's uncertainty (Kong, Payne, Council & Johnson, Automatica 131, 2021;
        :func:`_bounced`; session 31); the first update after a contact is confirmed
        like a jump's (``unconfirmed``: a kick at the contact passes the gate with the
        bounced prediction); the jump search's floor bounce is tried only within the
        floor's reach (the step's end predicted at most ``sqrt(gate)`` standard deviations
        above it; session 36). None: no predicted contact (before session 31): a bounce is
        only found by the jump search, whose floor bounce is tried wherever the ball falls
    restitution_std, bounce_friction_std : float, standard deviations of a predicted floor
        contact's ``restitution`` and ``bounce_friction`` (process noise of the reflection:
        ``σ_e² v_d² ĝĝᵀ + σ_f² v_h v_hᵀ`` on the velocity); 0.1 each: a golf ball's
        restitution on hard floors spans about 0.6–0.85 with speed and surface, and the
        horizontal speed kept 0.8–1.0 with spin
    noise_prior_weight : float, shape ``α₀`` of the pixel variance's inverse-gamma prior
        ``IG(α₀, α₀ noise_px²)`` (so ``β/α = 1/E[σ⁻²] = noise_px²``, the variance the
        filter uses; with ``α₀ <= 1`` the prior has no mean): the prior counts as ``α₀``
        detections (each adds 1 to ``α``)
    adapt_rate : float, forgetting ``1 - ρ`` of the pixel variance's variational-Bayes
        estimate (its memory: about ``1 / adapt_rate`` detections; 0: ``noise_px`` fixed)
    min_noise_px, max_noise_px : float, bounds of the adapted pixel noise (the lower one
        reached on noise-free detections, where 0.05 px kept the filter behind type A at
        120 fps and above)
    max_rejects : int, consecutive rejected detections after which the track is lost
    init_detections : int, detections (of at least two cameras) a (re)initialisation fits
    init_window : int, most detections kept for a (re)initialisation, unless a fit of a
        window spanning less than ``init_span_s`` failed on its velocity alone
        (``max_init_speed_std``: too short a window, as at 60 fps and above): the window
        then grows by the next detections (up to ``init_max_window``) until a fit passes or
        it spans ``init_span_s``
    init_max_window : int, most detections of a grown (re)initialisation window
    init_span_s : float, seconds: a window spanning less whose fit fails on its velocity
        alone grows; a window spans at most this or ``max_gap_s``, the longer
    max_init_std_m : float, a (re)initialisation whose position standard deviation
        ``sqrt(trace P_pp)`` exceeds this is refused (a degenerate geometry), metres
    max_gap_s : float or None, longest time without an accepted detection the track bridges;
        None: :func:`pslog.fusion._prepare.default_max_gap_s` of the rig
    max_accel_psd : float, upper bound of the adapted process noise ``q``, m²/s³ (its lower
        bound is the floor: ``accel_psd``, or ``accel_step_var R``)
    accel_adapt_rate : float, step ``η`` of ``q``'s adaptation (0: ``q`` fixed at
        the floor)
    accel_adapt_target : float, the value ``r₀`` of the whiteness statistic ``q`` settles at
    accel_adapt_threshold : float, ``h`` of ``q``'s change detector (session 33): the one-sided
        CUSUM ``g ← clip(g + r − r₀, 0, h + ln(q_max/q_min)/η)`` of the whiteness statistic
        ``r`` and ``q = q_min exp(η max(0, g − h))``: ``q`` stays at its floor until the
        innovations' lag is significant (0: ``log q`` the random walk before session 33,
        ``q ← q exp(η (r − r₀))``)
    chained_jump_restart : bool, a third velocity jump found before the first is confirmed
        is taken for a motion model that fails, not for a third kick: the track restarts
        from its window since the previous jump, each model fitted (the turn model at the
        start's prior), ``q`` kept (session 36; False: the jump accepted, as before)
    model_switch_per_s : float, rate ``λ`` of switches between the ballistic model and the
        supported one (no gravity: a ball rolling, carried, on a string), 1/s; the models
        are mixed by an interacting multiple model (0: the ballistic model alone)
    max_init_speed_std : float, a (re)initialisation whose velocity standard deviation
        ``sqrt(trace P_vv)`` exceeds this is refused, m/s
    max_speed_m_s : float or None, a (re)initialisation whose speed exceeds this by more
        than three standard deviations (along its velocity) is refused like a fit that
        fails (the window loses its oldest detection): no ball is that fast, and a
        spurious blob on a lone camera's epipolar line makes such paths (session 43); the
        gate's bound (``GatingOptions.max_speed_m_s``) by default; None: no bound, m/s
    confirm_nis : float, an accepted update whose NIS exceeds this (99 % quantile of χ²₂)
        must be confirmed like a jump
    max_std_m : float or None, a point whose ``std_m`` exceeds this is withheld, metres
        (None: no bound); default ``0.05 / 1.96``: a point is output when its error is
        within 5 cm (issue 10's bound) with 95 % probability, whatever the shape of its
        covariance (for a Gaussian error of ``trace P = std_m²``, ``P(‖e‖ > 1.96 std_m) <=
        5 %``, the one-dimensional error being the extreme: Székely & Bakirov 2003)
    turn_switch_per_s : float, rate of switches between the turn model (a coordinated turn
        about the vertical: a ball swung, on a turntable, circling) and the other two, 1/s
        (0: no turn model; also none when gravity is not along the world's z)
    turn_on_psd : float or None, the turn model joins the model set when the adapted
        process noise ``q`` reaches this (an acceleration the other models lack), m²/s³;
        None (the default): ``turn_on_accel2 / R``, ``R = Σ fps`` (:func:`turn_on_threshold`)
    turn_on_accel2 : float, m²/s⁴, ``q R`` at which the turn model joins when
        ``turn_on_psd`` is None: the ``q`` the adaptation settles at for an acceleration
        the model lacks falls as ``1/R`` (:func:`turn_on_threshold`); 27 is 0.3 m²/s³
        at three cameras at 30 fps (the fixed value before session 12)
    turn_rate_psd : float, spectral density of the turn rate's random walk, rad²/s³
    turn_rate_std : float, standard deviation of the turn rate when the model joins, rad/s
    withhold : bool, withhold unconfirmed and uncertain points (counted in
        ``Track.dropped``); False: a point at every detection of a live track (none held
        either: ``hold_nis``)
    supported_drag_per_m : float, ``k_s`` of the supported model's quadratic drag, 1/m (0: a
        ball held, rolling or guided, whose support's forces dwarf the air's; the ballistic
        model keeps ``drag_per_m``); ``drag_per_m`` gives the filter before session 8
    start_models : bool, a (re)start fits its window by every model of the set (ballistic,
        supported, coordinated turn) and starts each at its own fit with a probability from
        the fits' likelihoods; False: the ballistic fit alone starts the pair (``μ = 0.9``)
        and the turn model joins at the next detection at ``ω = 0`` (before session 8)
    window_noise_prior : bool, a (re)start's noise prior is scaled by the smaller of the
        stated (or estimated) variance and the start window's 99.9 % upper confidence bound
        of its residual variance (``‖r‖² / χ²_{0.001}(2n - 6)``; empirical
        Bayes: the stated noise stands unless the window shows it too large beyond doubt);
        False: the stated variance alone (before session 10)
    restart_prior : bool, a restart after a track loss takes the lost track's prediction
        to the window's newest detection (each model's: the pair's and, when it was in the
        set, the turn model's position and velocity with their covariance) as a prior of
        the window's fit, when the two agree (:func:`_with_prior`); False: the window's fit
        alone (before session 14)
    jump_instant : bool, an accepted jump's point and the points of the next 10–12
        accepted detections (``_JBUF`` in the jump's replay) publish the error the jump's
        unknown instant leaves (:func:`_instant_term`: ``ε_p ε_pᵀ Δt_j²/12``, the term
        ``m (s − Δt_j/2)`` relinearised at the jump ``m`` the state estimates, through the
        filter's gains); the state is unchanged; False: none (before session 25)
    jump_mixture_cov : bool, an accepted jump's state takes the winning (lag, shape)
        hypothesis's mean with the mean square error about it of the mixture of every
        hypothesis that passed, ``Σ w_k (P_k + (x_k − x*)(x_k − x*)ᵀ)``, ``w_k ∝
        exp(−score_k/2)`` (:func:`_mixture_about`): a narrow shape (a bounce) that wins a
        kick's one pixel no longer states the narrow shape's covariance; False: the
        winner's covariance alone (before session 27)
    iterate_update : bool, an accepted update whose first (extended Kalman) step leaves its
        own point more than ``3 σ`` (the pixel noise's) off the pixel the linearisation
        predicted is iterated to the posterior's mode (Gauss-Newton, :func:`_iterated`;
        the gate's NIS is still the prior's); False: one step (before session 30)
    surprise_cov : bool, a plain (not jump) accepted update's point publishes the mixture of
        "no jump" and "a jump (each shape) in the step before this detection", weighted by
        their likelihoods of the detection and the prior ``1 − exp(−λ_j Δt)``, about the
        no-jump mean, along its camera's ray (:func:`_surprise_term`): a large NIS makes
        the jump likely; the state is unchanged; False: none (before session 29)
    hold_nis : float or None, a plain update's output point whose NIS exceeds this waits
        for the next detection of another camera, and is withheld (``held``) if that
        detection made a jump placed before it (the jump's lag reaches back to it), was
        rejected, or the track was lost first (or no such detection came: the session's
        end); :func:`fuse_filter` and the stream (:class:`FilterStream`, whose held points
        wait across pushes and leave when decided) alike; :meth:`BallFilter.push` does not
        hold (its point leaves at its detection). Default 2 (:data:`pslog.fusion.
        FILTER_HOLD_NIS`, χ²₂'s mean; session 30); None: no hold (``pslog live``); none
        either with ``withhold`` False
    hold_jump_p : float or None, a held point (``hold_nis``) is also withheld when the next
        camera's detection made a jump whose hypotheses placing it before the held
        detection (their lags reaching back to it) carry at least this posterior
        probability among those that passed (weights ``∝ exp(−score/2)``, as the jump's
        mixture, ``jump_mixture_cov``), even when the winner placed it after: a kick along
        the held camera's ray leaves its pixel unmoved, so the winner's lag is often the
        later one (session 31). Default 0.05; None: the winner's lag alone (before session
        31)
    hold_start : bool, with the hold (``hold_nis`` not None, ``withhold``) a start's point
        (``init`` 1) is held as a point of large NIS is: it waits for the next detection
        of another camera and is withdrawn (``held``) when that detection is rejected, made
        a jump reaching back to the start's detection (the jump search reaches no further
        back than a start: a jump there is the fitted path missing the next camera; the
        session-47 review), or the track was lost first (session 47). A start's window
        fit has ``2n - 6`` degrees of freedom (2 for the 4 detections of a first start) and
        can bend to absorb one wrong detection within the gate (``paper3`` in
        ``bench_dirty.py --more --first-seed 83100 --misses 0.1``, rally-83107: a static
        object kept in the session's first frame, before anything could judge it, made a
        first point 107 mm off with residuals of 1.1 and 1.3 px; the next three detections
        were rejected). The next camera's detection is the first test the window did not
        make. Default True; False: a start's point leaves at its detection (before session
        47)
    hold_gap : float or None, with the hold a plain update's point whose gap (``gap_s``,
        since the previous accepted detection) exceeds this many of the rig's regular gaps
        (:func:`regular_gap_s`: the longest time between consecutive frame instants of its
        cameras, ``1 / Σ fps`` on evenly staggered cameras of one rate, ``1 / fps`` on
        synchronised ones; session 47's review: ``1 / Σ fps`` held a third of the points of
        ``sync`` and ``typeB`` rigs, no slot missed) is held too, whatever its NIS (session
        47): a slot missed before it (a
        detection missed or rejected, or a camera going on alone) leaves a longer span in
        which a kick along the camera's ray passes its gate unseen (its probability ``λ_j T``
        and the displacement it hides both grow with the span ``T``), and the next camera's
        detection tells. Default 1.5 (above 1, a gap beyond it has a frame instant inside: a
        missed slot; any value in (1, 2) gives the same on evenly staggered cameras of one
        rate); None: by NIS alone (before session 47)
    hold_rejected : bool, with the hold a rejected detection's point (the prediction) is held
        too, and withdrawn when the next camera's detection is rejected or made a jump
        anywhere since the latest accepted detection before it (its instant is unknown
        against the rejected detection's; session 47). Default True
    jump_rate_per_s : float, expected rate ``λ_j`` of velocity jumps (kicks, bounces), 1/s:
        a point's reported covariance adds the variance ``λ_j T σ_j² T² / 3`` along its
        camera's ray of a jump no other camera has seen in the time ``T`` since another
        camera's latest accepted detection (one camera's pixels do not fix the depth), and
        the point of a rejected detection (the prediction) ``λ_j σ_j² T³ / 3`` on every axis
        over the time ``T`` since the latest accepted detection (:func:`_unseen_gap_jump`),
        and a (re)start's point the error its window's fit makes of the jumps inside the
        window (:func:`window_jump_cov`); 0: none of these
    drag_std_per_m : float, 1/m, prior standard deviation ``σ_k`` of the ballistic model's
        drag offset ``δk`` from ``drag_per_m``, estimated for the session beside the filter
        (Friedland's two-stage filter, :func:`_drag_update`): each point published is ``p +
        V_p δk̂`` with the covariance ``P_pp + V_p V_pᵀ / I_k``; the filter's own state
        (gating, jumps, ``q``, σ²) is unchanged; 0: the drag not estimated (before session
        29)
    drag_drift_s : float or None, seconds ``T_k`` over which the drag offset ``δk`` may
        drift by ``σ_k`` (``drag_std_per_m``): a random walk of spectral density ``q_k =
        σ_k² / T_k``, so that ``I_k ← I_k / (1 + I_k q_k Δt)`` before each drag update
        (``Δt`` since the latest); its information stays bounded (a ball may be changed, wet
        or scuffed within a session); None: no drift (before session 29's review)
    """

    noise_px: float = 0.5
    noise_prior_weight: float = 1.0
    adapt_rate: float = 0.02
    min_noise_px: float = 0.01
    max_noise_px: float = 5.0
    accel_psd: float | None = None
    accel_step_var: float = 1.0 / 60_000
    drag_per_m: float = Ball().drag_per_metre
    gravity: tuple[float, float, float] = (0.0, 0.0, -G)
    gate: float = 18.4
    jump_speed: float = 6.0
    bounce_shape: bool = True
    restitution: float = 0.7
    bounce_friction: float = 0.1
    floor_m: float | None = BALL_RADIUS
    restitution_std: float = 0.1
    bounce_friction_std: float = 0.1
    max_rejects: int = 3
    init_detections: int = 4
    init_window: int = 8
    init_max_window: int = 64
    init_span_s: float = 0.03
    max_init_std_m: float = 0.05
    max_init_speed_std: float = 1.0
    max_speed_m_s: float | None = MAX_BALL_SPEED_M_S
    confirm_nis: float = 9.21
    withhold: bool = True
    max_gap_s: float | None = None
    max_accel_psd: float = 100.0
    accel_adapt_rate: float = 0.5
    model_switch_per_s: float = 0.5
    accel_adapt_target: float = 0.4
    accel_adapt_threshold: float = 6.0
    chained_jump_restart: bool = True
    max_std_m: float | None = _MAX_ERROR_M / 1.96
    turn_switch_per_s: float = 0.5
    turn_on_psd: float | None = None
    turn_on_accel2: float = 27.0
    turn_rate_psd: float = 0.1
    turn_rate_std: float = 6.0
    jump_rate_per_s: float = 1.0
    supported_drag_per_m: float = 0.0
    start_models: bool = True
    window_noise_prior: bool = True
    restart_prior: bool = True
    jump_instant: bool = True
    jump_mixture_cov: bool = True
    drag_std_per_m: float = 0.01
    drag_drift_s: float | None = 600.0
    surprise_cov: bool = True
    iterate_update: bool = True
    hold_nis: float | None = FILTER_HOLD_NIS
    hold_jump_p: float | None = 0.05
    hold_start: bool = True
    hold_gap: float | None = 1.5
    hold_rejected: bool = True

    def __post_init__(self) -> None:
        from dataclasses import fields

        # the switches (every field annotated bool, a new one too): True or False only (a
        # numpy bool too); a string such as "no" or a None was taken as truthy or falsy
        for name in (f.name for f in fields(self) if f.type in ("bool", bool)):
            value = getattr(self, name)
            if not isinstance(value, bool | np.bool_):
                raise FusionError(f"filter {name} must be True or False, got {value!r}")
        for name in ("noise_px", "accel_psd", "accel_step_var", "gate", "jump_speed",
                     "noise_prior_weight"):
            value = getattr(self, name)
            if name == "accel_psd" and value is None:
                continue
            if not (math.isfinite(value) and value > 0):
                raise FusionError(f"filter {name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.model_switch_per_s) and self.model_switch_per_s >= 0):
            raise FusionError(f"filter model_switch_per_s must be finite and >= 0, got "
                              f"{self.model_switch_per_s!r}")
        for name in ("turn_switch_per_s", "turn_rate_psd", "turn_rate_std", "jump_rate_per_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise FusionError(f"filter {name} must be finite and >= 0, got {value!r}")
        if not (math.isfinite(self.adapt_rate) and 0.0 <= self.adapt_rate < 1.0):
            raise FusionError(f"filter adapt_rate must be in [0, 1), got {self.adapt_rate!r}")
        if self.max_speed_m_s is not None and not (math.isfinite(self.max_speed_m_s)
                                                   and self.max_speed_m_s > 0):
            raise FusionError(f"filter max_speed_m_s must be finite and > 0 or None, got "
                              f"{self.max_speed_m_s!r}")
        if self.turn_on_psd is not None and not (math.isfinite(self.turn_on_psd)
                                                 and self.turn_on_psd > 0):
            raise FusionError(f"filter turn_on_psd must be finite and > 0, got "
                              f"{self.turn_on_psd!r}")
        if not (math.isfinite(self.turn_on_accel2) and self.turn_on_accel2 > 0):
            raise FusionError(f"filter turn_on_accel2 must be finite and > 0, got "
                              f"{self.turn_on_accel2!r}")
        for name in ("drag_per_m", "supported_drag_per_m", "drag_std_per_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise FusionError(f"filter {name} must be finite and >= 0, got {value!r}")
        if self.drag_std_per_m != 0 and not 1e-9 <= self.drag_std_per_m <= 1e3:
            # (its prior information 1/σ_k² must be a finite number above 0)
            raise FusionError(f"filter drag_std_per_m must be 0 (not estimated) or in "
                              f"[1e-9, 1000] 1/m, got {self.drag_std_per_m!r}")
        if self.drag_drift_s is not None and not (
                not isinstance(self.drag_drift_s, bool)
                and math.isfinite(self.drag_drift_s) and self.drag_drift_s > 0):
            raise FusionError(f"filter drag_drift_s must be None (no drift) or finite and > 0 "
                              f"s, got {self.drag_drift_s!r}")
        if isinstance(self.accel_adapt_threshold, bool) or not (
                math.isfinite(self.accel_adapt_threshold) and self.accel_adapt_threshold >= 0):
            raise FusionError(f"filter accel_adapt_threshold must be finite and >= 0, got "
                              f"{self.accel_adapt_threshold!r}")
        if self.init_detections < 3 or self.init_window < self.init_detections:
            raise FusionError("filter init_detections must be >= 3 and init_window >= it, got "
                              f"{self.init_detections} and {self.init_window}")
        if self.init_max_window < self.init_window:
            raise FusionError("filter init_max_window must be >= init_window, got "
                              f"{self.init_max_window} and {self.init_window}")
        if not (math.isfinite(self.init_span_s) and self.init_span_s > 0):
            raise FusionError(f"filter init_span_s must be finite and > 0, got "
                              f"{self.init_span_s!r}")
        if self.hold_nis is not None and (isinstance(self.hold_nis, bool) or not (
                math.isfinite(self.hold_nis) and self.hold_nis >= 0)):
            raise FusionError(f"filter hold_nis must be finite and >= 0, got "
                              f"{self.hold_nis!r}")
        if self.hold_gap is not None and (isinstance(self.hold_gap, bool) or not (
                isinstance(self.hold_gap, (int, float)) and 0 <= self.hold_gap < math.inf)):
            # (a NaN held nothing, a string failed in BallFilter with a TypeError)
            raise FusionError(f"filter hold_gap must be None (by NIS alone) or finite and >= 0 "
                              f"regular gaps, got {self.hold_gap!r}")
        if self.hold_jump_p is not None and (isinstance(self.hold_jump_p, bool) or not (
                isinstance(self.hold_jump_p, (int, float)) and 0 <= self.hold_jump_p <= 1)):
            raise FusionError(f"filter hold_jump_p must be None (the winner's lag alone) or a "
                              f"probability in [0, 1], got {self.hold_jump_p!r}")
        if self.floor_m is not None and (isinstance(self.floor_m, bool) or not isinstance(
                self.floor_m, (int, float)) or not math.isfinite(self.floor_m)):
            raise FusionError(f"filter floor_m must be None (no floor) or a finite height in "
                              f"metres, got {self.floor_m!r}")
        for name in ("restitution", "bounce_friction", "restitution_std",
                     "bounce_friction_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise FusionError(f"filter {name} must be in [0, 1], got {value!r}")
        if self.max_rejects < 1:
            raise FusionError(f"filter max_rejects must be >= 1, got {self.max_rejects}")


class _Cam:
    """One camera's projection constants as plain floats (a row of the filter's camera
    table, :func:`_project`)."""

    __slots__ = ("camera", "cx", "cy", "distorted", "far", "fx", "fy", "k1", "k2", "k3",
                 "p1", "p2", "r", "s", "t")

    def __init__(self, camera) -> None:
        self.camera = camera
        self.r = [float(x) for x in np.asarray(camera.R).ravel()]
        self.t = [float(x) for x in camera.t]
        K = camera.K
        self.fx, self.s, self.cx = float(K[0, 0]), float(K[0, 1]), float(K[0, 2])
        self.fy, self.cy = float(K[1, 1]), float(K[1, 2])
        self.k1, self.k2, self.p1, self.p2, self.k3 = (float(x) for x in camera.dist)
        self.distorted = bool(np.any(camera.dist))
        self.far = _FAR_IMAGES * max(camera.width, camera.height)


# ---- the compiled per-detection step (numba, pslog._jit.kernel) ------------------------------
# The state lives in two preallocated arrays, so that the batch loop and the streaming form run
# the same compiled code on the same memory: ``S`` (float64) and ``I`` (int64), laid out below.
# Every equation is written in the same order of operations as the pure-Python filter it
# replaced (IEEE arithmetic, no fastmath): the points are bit for bit those of that filter.

#: ``S``: the pair's mean x (6) and covariance P (6 x 6), the turn model's mean (7) and
#: covariance (7 x 7), the models' difference e (6), μ, ν, ν⁺, q, σ², α (σ²'s
#: inverse-gamma shape), the jump search's history (_HISTORY entries: x, P, u, v, score),
#: per camera the latest innovation (y0, y1), then the window's pixels (u, v)
_SX, _SP, _SXT, _SPT, _SE = 0, 6, 42, 49, 98
_SMU, _SNU, _SNUPOST, _SQ, _SVAR, _SALPHA = 104, 105, 106, 107, 108, 109
_HISTORY = _JUMP_LAG + 1
_SHX = 110
_SHP = _SHX + 6 * _HISTORY
_SHUV = _SHP + 36 * _HISTORY
_SHSC = _SHUV + 2 * _HISTORY
#: the latest jump's restart state (x, P), its instant's published term at the latest point
#: (ε_p (3), Δt_j²/12: :func:`_instant_term`), the pixels of its detections (_JBUF x (u, v)),
#: the (c, q, σ²) each of those detections' updates used (_JBUF x 3)
_SJX = _SHSC + _HISTORY
_SJP = _SJX + 6
_SJE = _SJP + 36
_SJUV = _SJE + 4
_SJF = _SJUV + 2 * _JBUF  # per buffered detection the (c, q, σ²) its update used
#: the latest jump's covariance of its hypotheses' mixture about the winner (session 27)
_SJPM = _SJF + 3 * _JBUF
#: the drag's two-stage estimate (session 29; :func:`_drag_update`): the state's sensitivity
#: to the ballistic model's drag ``V = ∂x/∂k`` (6), the drag's offset ``δk̂`` and its
#: information ``I_k`` (kept for the session)
_SJLW = _SJPM + 36
#: the latest jump's posterior probability per lag (_HISTORY): the weights ``w_k`` of the
#: hypotheses that passed, summed per lag (session 31: a held point withdrawn when the jump
#: may lie before it, ``hold_jump_p``)
_SV = _SJLW + _HISTORY
_SDK, _SIK = _SV + 6, _SV + 7
#: q's change detector (session 33): the one-sided CUSUM ``g`` of the whiteness statistic
#: ``r − r₀`` (``q = q_min exp(η max(0, g − h))``; unused when ``h`` = 0)
_SQG = _SV + 8
_SCAM = _SV + 9  # then 2 per camera, then 2 per window slot
#: ``I``: track flag, state time, last accepted time, rejections in a row, updates since the
#: start, camera of a pending jump, its confirming updates, whether one came from another
#: camera, the turn model's age, the latest jump's time and camera, history length, window
#: length, window cap, withheld counts and which reason came first, the history's times and
#: cameras, then per camera: last accepted time, latest innovation's time and flag; then the
#: window's (time, camera)
_IHAS, _ITIME, _ILAST, _IREJ, _ICONF, _IPEND, _ICONFS, _IOTHER, _IAGE = range(9)
_IJUMPNS, _IJUMPCAM, _IHN, _IWN, _ICAP, _IDROPC, _IDROPU, _IDROPFIRST = range(9, 17)
_IHT = 17  # _HISTORY x (state time, time, camera)
#: the latest jump's restart time, its detections buffered (0: none), its shape, the time
#: of the point that published its instant's term; the buffer's (time, camera)
_IJT0 = _IHT + 3 * _HISTORY
_IJN, _IJSHAPE, _IJTE = _IJT0 + 1, _IJT0 + 2, _IJT0 + 3
_IJLAG = _IJT0 + 4  # the winner's lag: its buffered detection at this index is the jump's
_IJBUF = _IJT0 + 5
#: the time of the drag's latest update (its random walk's start; -2**62: none yet)
_IDRAGT = _IJBUF + 2 * _JBUF
#: the jumps accepted since the latest confirmation (or start): a chain of them (session 36)
_ICHAIN = _IDRAGT + 1
_ICAM = _IDRAGT + 2  # then 3 per camera, then 2 per window slot
#: ``O`` (float64 options): k, g (3), gravity's unit vector (3), gate, adapt_rate, σ² bounds,
#: q bounds, q's rate and target, max_std (inf: none), withhold, confirm_nis, λ, μ₀, turn
#: model on, λ_t, turn_on_psd, turn_rate_psd, turn_rate_std², restitution, friction, number
#: of jump shapes, then the shapes (reflect, 3 variances), the unseen jump's coefficient
_OK, _OG, _ODOWN, _OGATE, _OADAPT, _OVMIN, _OVMAX = 0, 1, 4, 7, 8, 9, 10
_OQMIN, _OQMAX, _OQRATE, _OQTARGET, _OMAXSTD, _OWITHHOLD, _OCONFNIS = range(11, 18)
_OSWITCH, _OMU0, _OTURN, _OTSWITCH, _OTON, _OTPSD, _OTVAR, _OREST, _OFRIC = range(18, 27)
_ONSHAPES, _OSHAPES = 27, 28
_OUNSEEN = _OSHAPES + 4 * 3  # λ_j σ_j² / 3: an unseen jump's variance along a ray per T³
_OKS = _OUNSEEN + 1  # the supported model's drag coefficient (0 by default)
_OINSTANT = _OKS + 1  # 1: an accepted jump's instant published (_instant_term)
_OJMIX = _OINSTANT + 1  # 1: a jump's covariance is its hypotheses' mixture's about the winner
_ODRAG = _OJMIX + 1  # the drag's prior information 1/σ_k² (0: the drag not estimated)
_OSURPRISE = _ODRAG + 1  # λ_j of a plain update's jump/no-jump mixture (0: none; session 29)
_OHOLD = _OSURPRISE + 1  # the hold for the next camera: its NIS (inf: none; sessions 29, 30)
_ODRAGQ = _OHOLD + 1  # the drag's random walk q_k = σ_k² / T_k, (1/m)²/s (0: none)
_OITER = _ODRAGQ + 1  # 1: an update far from its linearisation iterated (session 30)
#: the floor's height ``floor_m`` (NaN: no predicted contact), the variances of the
#: restitution and of the friction at a predicted contact (session 31)
_OFLOOR, _OESTD2, _OFSTD2 = _OITER + 1, _OITER + 2, _OITER + 3
#: the hold's withdrawal at a jump whose hypotheses placing it before the held detection
#: carry this posterior probability or more (2: never; session 31)
_OHOLDP = _OFSTD2 + 1
#: q's change detector's threshold ``h`` (0: the random walk before session 33) and the
#: CUSUM's cap ``h + ln(q_max / q_min) / η`` (session 33)
_OQDEAD, _OQGMAX = _OHOLDP + 1, _OHOLDP + 2
#: 1: a third jump found before the first is confirmed restarts the track from its window
#: (session 36, ``chained_jump_restart``)
_OCHAIN = _OHOLDP + 3
#: the hold's further points (session 47): a plain update's whose gap exceeds this (seconds:
#: ``hold_gap`` regular gaps, :func:`regular_gap_s`; inf: none), and a rejected detection's (1:
#: held)
_OHOLDGAP, _OHOLDREJ = _OHOLDP + 4, _OHOLDP + 5
_OSIZE = _OHOLDP + 6
#: the held points at most at once (a camera alone past them: the later ones output)
_HOLD_MAX = 8
#: a held start's ``pb`` (:func:`_held`): one below a plain point's 0, so that a jump whose
#: lag reaches back to the start's detection withdraws it (the jump search reaches no
#: further back than a start, whose history it resets: with 0 no jump could, and a start
#: the next camera's detection disagrees with by a jump left; review of session 47)
_START_PB = -1
#: ``N`` (int64 options): max gap, window span, init_window, init_detections, max_rejects,
#: window capacity
_NMAXGAP, _NSPAN, _NINITWIN, _NINITDET, _NMAXREJ, _NWCAP = range(6)
#: ``cams`` (float64, one row per camera): R (9), t (3), fx, s, cx, fy, cy, k1, k2, k3, p1,
#: p2, distorted, far
_CAM_COLS = 24
#: one output row: position (3), std_m (4), innovation (y0, y1), residual (u, v): their
#: lengths are CPython's ``math.hypot``'s, as the pure-Python filter took them (numba's
#: hypot is libm's, which differs in the last bit now and then: :func:`_py_hypot` repeats
#: CPython's), nis, gap_s, jump, rejected, init
_OUT_COLS = 16
#: step results: no point; a point in ``out``; a window fit needed (Python), without or
#: with a point in ``out`` for when it finds no start
_NONE, _POINT, _FIT, _FIT_OR_POINT = 0, 1, 2, 3
_INN_C0 = 13  # innovation array: y0 y1 i00 i01 i11 nis det h0 (3) h1 (3) c0 (n) c1 (n)


@kernel
def _q_walk(S, O):
    """The ``q`` the model set's tests compare with ``turn_on_psd`` (session 33): with q's
    change detector (``h`` > 0) the random walk's ``min(q_min exp(η g), q_max)`` (its
    CUSUM ``g`` is that walk's ``ln(q / q_min) / η``), so that the turn model joins and leaves
    as it did; the process noise itself is ``S[_SQ]``, held at its floor below ``h``."""
    if O[_OQDEAD] == 0.0:
        return S[_SQ]
    return _pmin(O[_OQMIN] * math.exp(O[_OQRATE] * S[_SQG]), O[_OQMAX])


@kernel
def _pmin(a, b):
    """Python's ``min(a, b)`` (``a`` unless ``b < a``; NaN as Python orders it)."""
    return b if b < a else a


@kernel
def _pmax(a, b):
    """Python's ``max(a, b)``."""
    return b if b > a else a


@kernel
def _project(cams, ci, px, py, pz):
    """Distorted pixel of a world point and ``∂(u, v)/∂p`` (two rows of 3) through camera
    ``ci`` (a row of the filter's camera table); ``ok`` False when the point is not in
    front of it.
    Returns ``(ok, u, v, h00, h01, h02, h10, h11, h12)``."""
    r = cams[ci]
    xc = r[0] * px + r[1] * py + r[2] * pz + r[9]
    yc = r[3] * px + r[4] * py + r[5] * pz + r[10]
    zc = r[6] * px + r[7] * py + r[8] * pz + r[11]
    if not zc > _MIN_DEPTH_M:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    fx, s, cx, fy, cy = r[12], r[13], r[14], r[15], r[16]
    iz = 1.0 / zc
    x, y = xc * iz, yc * iz
    if r[22] != 0.0:
        k1, k2, k3, p1, p2 = r[17], r[18], r[19], r[20], r[21]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        dr = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        d00 = radial + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x
        d01 = 2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y
        d11 = radial + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x
        # A = K₂ · D (D symmetric: d10 = d01)
        a00, a01 = fx * d00 + s * d01, fx * d01 + s * d11
        a10, a11 = fy * d01, fy * d11
    else:
        xd, yd = x, y
        a00, a01, a10, a11 = fx, s, 0.0, fy
    u = fx * xd + s * yd + cx
    v = fy * yd + cy
    # M = A · ∂(x, y)/∂X_c, then H = M · R
    m00, m01, m02 = a00 * iz, a01 * iz, -(a00 * x + a01 * y) * iz
    m10, m11, m12 = a10 * iz, a11 * iz, -(a10 * x + a11 * y) * iz
    return (True, u, v,
            m00 * r[0] + m01 * r[3] + m02 * r[6], m00 * r[1] + m01 * r[4] + m02 * r[7],
            m00 * r[2] + m01 * r[5] + m02 * r[8],
            m10 * r[0] + m11 * r[3] + m12 * r[6], m10 * r[1] + m11 * r[4] + m12 * r[7],
            m10 * r[2] + m11 * r[5] + m12 * r[8])


@kernel
def _innovation(cams, ci, x, P, n, u, v, var):
    """The innovation of pixel ``(u, v)`` of camera ``ci`` against the state ``(x, P)`` of
    ``n`` states (position first, ``P`` n x n flat) with pixel variance ``var``: ``y = z -
    π(p)``, ``PHᵀ`` (columns c0, c1), ``S = H P Hᵀ + σ² I``, ``S⁻¹``, ``NIS = yᵀ S⁻¹ y``.
    Returns ``(ok, inn)``, ``inn`` = (y0, y1, i00, i01, i11, NIS, det S, h0 (3), h1 (3),
    c0 (n), c1 (n)); ``ok`` False when ``x`` is behind the camera."""
    ok, pu, pv, a0, a1, a2, b0, b1, b2 = _project(cams, ci, x[0], x[1], x[2])
    inn = np.empty(_INN_C0 + 2 * n)
    if not ok:
        return False, inn
    y0, y1 = u - pu, v - pv
    # PHᵀ: column r is P[:, :3] · h_r (n rows)
    for k in range(n):
        i = k * n
        p0, p1, p2 = P[i], P[i + 1], P[i + 2]
        inn[_INN_C0 + k] = p0 * a0 + p1 * a1 + p2 * a2
        inn[_INN_C0 + n + k] = p0 * b0 + p1 * b1 + p2 * b2
    c0, c1 = _INN_C0, _INN_C0 + n
    s00 = a0 * inn[c0] + a1 * inn[c0 + 1] + a2 * inn[c0 + 2] + var
    s01 = a0 * inn[c1] + a1 * inn[c1 + 1] + a2 * inn[c1 + 2]
    s11 = b0 * inn[c1] + b1 * inn[c1 + 1] + b2 * inn[c1 + 2] + var
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    inn[0], inn[1], inn[2], inn[3], inn[4] = y0, y1, i00, i01, i11
    inn[5] = y0 * (i00 * y0 + i01 * y1) + y1 * (i01 * y0 + i11 * y1)
    inn[6] = det
    inn[7], inn[8], inn[9], inn[10], inn[11], inn[12] = a0, a1, a2, b0, b1, b2
    return True, inn


@kernel
def _noise_update(S, O, y0, y1, i00, i01, i11):
    """One variational-Bayes step of the pixel variance ``σ² = β/α`` (inverse-gamma
    ``IG(α, β)``; Särkkä & Nummenmaa, "Recursive noise adaptive Kalman filtering by
    variational Bayesian approximations", IEEE Trans. AC 54(3), 2009, one fixed-point
    iteration, isotropic ``R = σ² I₂``) after an update with innovation ``y`` and ``S⁻¹ =
    [[i00, i01], [i01, i11]]`` (``S = H P⁻ Hᵀ + σ² I``): forgetting ``ρ = 1 - adapt_rate``,

        α ← ρ α + 1,   β ← ρ β + (‖z − H x⁺‖² + tr(H P⁺ Hᵀ)) / 2,

    with, for the Kalman update with ``R = σ² I``, ``z − H x⁺ = σ² S⁻¹ y`` and ``H P⁺ Hᵀ =
    σ² (I − σ² S⁻¹)``; the new ``σ² = β/α`` is clipped to its bounds (β with it). In place
    in ``S`` (σ² at ``_SVAR``, α at ``_SALPHA``)."""
    var, rho = S[_SVAR], 1.0 - O[_OADAPT]
    a0 = i00 * y0 + i01 * y1  # S⁻¹ y
    a1 = i01 * y0 + i11 * y1
    resid2 = var * var * (a0 * a0 + a1 * a1)
    trace = var * (2.0 - var * (i00 + i11))
    alpha = rho * S[_SALPHA] + 1.0
    beta = rho * S[_SALPHA] * var + 0.5 * (resid2 + trace)
    S[_SALPHA] = alpha
    S[_SVAR] = _pmin(_pmax(beta / alpha, O[_OVMIN]), O[_OVMAX])


@kernel
def _updated(x, P, inn):
    """Kalman update: ``x + K y``, ``P - K (PHᵀ)ᵀ`` with ``K = PHᵀ S⁻¹`` (new arrays; ``n =
    len(x)`` states, the innovation's). The standard form, not Joseph's ``(I - KH) P (I -
    KH)ᵀ + K R Kᵀ`` (equal for this optimal gain; docs/methods.md, "Measurement model and
    Jacobian"): the upper triangle is computed and mirrored, so ``P`` stays symmetric."""
    n = x.shape[0]
    y0, y1, i00, i01, i11 = inn[0], inn[1], inn[2], inn[3], inn[4]
    c0, c1 = _INN_C0, _INN_C0 + n
    k0 = np.empty(n)
    k1 = np.empty(n)
    xn = np.empty(n)
    for i in range(n):
        k0[i] = inn[c0 + i] * i00 + inn[c1 + i] * i01
        k1[i] = inn[c0 + i] * i01 + inn[c1 + i] * i11
        xn[i] = x[i] + k0[i] * y0 + k1[i] * y1
    Pn = P.copy()
    for i in range(n):
        ki0, ki1, row = k0[i], k1[i], n * i
        for j in range(i, n):
            value = P[row + j] - (ki0 * inn[c0 + j] + ki1 * inn[c1 + j])
            Pn[row + j] = value
            Pn[n * j + i] = value
    return xn, Pn


#: the iterated update (session 30): it runs when the first step's own point reprojects more
#: than this many σ (the pixel noise's) off the pixel its linearisation predicted
_ITER_SIGMAS = 3.0
#: the iterated update's most Gauss-Newton steps after the first
_ITER_MAX = 10
#: the iterated update stops when a step moves the position less than this, metres
_ITER_TOL_M = 1e-7


@kernel
def _iterated(cams, cam, x, P, inn, u, v, var, O):
    """The update of ``(x, P)`` (``n`` states, position first) by pixel ``(u, v)`` of
    camera ``cam``, ``inn`` its innovation at ``x`` (:func:`_innovation`), pixel variance
    ``var``: the Kalman step (:func:`_updated`), iterated when it is far from linear
    (session 30; ``O[_OITER]``). Linearised at a prior hundreds of pixels from the
    detection, the step is not the posterior's mode: its point's reprojection error ``r =
    z − π(x⁺)`` differs from the linear prediction ``σ² S⁻¹ y``. When by more than
    ``_ITER_SIGMAS σ``, the iterated extended Kalman update (Bell & Cathey, "The iterated
    Kalman filter update as a Gauss-Newton method", IEEE Trans. AC 38(2), 1993):

        x_{i+1} = x⁻ + K_i (z − h(x_i) − H_i (x⁻ − x_i)),   P_{i+1} = P⁻ − K_i H_i P⁻,

    ``K_i`` from ``H_i`` at ``x_i``, each step kept while it lowers the posterior's cost
    ``(x − x⁻)ᵀ P⁻⁻¹ (x − x⁻) + ‖z − h(x)‖²/σ²`` (the prior term ``y'ᵀ S_i⁻¹ y' −
    σ² ‖S_i⁻¹ y'‖²`` for ``x − x⁻ = K_i y'``: no inverse), at most ``_ITER_MAX`` steps,
    until a step moves the position less than ``_ITER_TOL_M`` (that step kept: ``P⁺``
    from ``H`` at the mode). Otherwise (and when a point is behind the camera) the first
    step, bit for bit. Returns ``(x⁺, P⁺)`` (new arrays)."""
    xn, Pn = _updated(x, P, inn)
    if O[_OITER] == 0.0:
        return xn, Pn
    ok, pu, pv, _, _, _, _, _, _ = _project(cams, cam, xn[0], xn[1], xn[2])
    if not ok:
        return xn, Pn
    y0, y1, i00, i01, i11 = inn[0], inn[1], inn[2], inn[3], inn[4]
    a0, a1 = i00 * y0 + i01 * y1, i01 * y0 + i11 * y1  # S⁻¹ y
    r0, r1 = u - pu, v - pv
    l0, l1 = r0 - var * a0, r1 - var * a1  # the linearisation's error at x⁺
    if not l0 * l0 + l1 * l1 > _ITER_SIGMAS * _ITER_SIGMAS * var:
        return xn, Pn
    n = x.shape[0]
    best = y0 * a0 + y1 * a1 - var * (a0 * a0 + a1 * a1) + (r0 * r0 + r1 * r1) / var
    xi = xn
    for _ in range(_ITER_MAX):
        ok, ii = _innovation(cams, cam, xi, P, n, u, v, var)
        if not ok:
            break
        # z − h(x_i) − H_i (x⁻ − x_i): the innovation at x⁻ of the linearisation at x_i
        d0, d1, d2 = x[0] - xi[0], x[1] - xi[1], x[2] - xi[2]
        y0 = ii[0] - (ii[7] * d0 + ii[8] * d1 + ii[9] * d2)
        y1 = ii[1] - (ii[10] * d0 + ii[11] * d1 + ii[12] * d2)
        ii[0], ii[1] = y0, y1
        xj, Pj = _updated(x, P, ii)
        ok, pu, pv, _, _, _, _, _, _ = _project(cams, cam, xj[0], xj[1], xj[2])
        if not ok:
            break
        a0, a1 = ii[2] * y0 + ii[3] * y1, ii[3] * y0 + ii[4] * y1
        r0, r1 = u - pu, v - pv
        cost = y0 * a0 + y1 * a1 - var * (a0 * a0 + a1 * a1) + (r0 * r0 + r1 * r1) / var
        s0, s1, s2 = xj[0] - xi[0], xj[1] - xi[1], xj[2] - xi[2]
        done = s0 * s0 + s1 * s1 + s2 * s2 < _ITER_TOL_M * _ITER_TOL_M
        if not (cost < best or done):  # a step that does not descend: the last one kept
            break
        # (converged: its covariance from the H at the mode, though rounding may have made
        # the cost a hair higher)
        best, xn, Pn = cost, xj, Pj
        xi = xj
        if done:
            break
    return xn, Pn


@kernel
def _predicted(x, P, dt, c, O, q):
    """Mean and covariance after ``dt`` seconds (new arrays), gravity and the ballistic
    model's drag weighted by its probability ``c`` (the models' mixture's mean: drag
    ``k_s + c (k - k_s)``, ``k_s`` the supported model's), white-noise acceleration ``q``
    (Bar-Shalom et al. 2001, 6.2.2). When the mean path crosses the floor (``O[_OFLOOR]``,
    :func:`_contact`), the step is split at the contact instant ``s``: predicted to it, reset
    by :func:`_bounced` (the reflection, the saltation matrix), predicted over ``dt - s``
    (session 31)."""
    return _predicted_at(x, P, dt, c, O, q, _contact(x, dt, c, O))


@kernel
def _predicted_at(x, P, dt, c, O, q, s):
    """:func:`_predicted` with its floor contact's instant ``s`` given (−1: none)."""
    if s < 0.0:
        return _predicted_mean(x, dt, c, O), _cov_predicted(P, dt, q)
    xc, Pc = _predicted_mean(x, s, c, O), _cov_predicted(P, s, q)
    xb, Pb = _bounced(xc, Pc, c, O)
    rest = dt - s
    return _predicted_mean(xb, rest, c, O), _cov_predicted(Pb, rest, q)


@kernel
def _cov_predicted(P, dt, q):
    """``F P Fᵀ + Q`` over ``dt`` seconds (a new array): ``F = [[I, Δt I], [0, I]]``, ``Q``
    the white-noise acceleration's of density ``q`` (Bar-Shalom et al. 2001, 6.2.2)."""
    adt = abs(dt)
    q3, q2, q1 = q * adt ** 3.0 / 3.0, q * dt * adt / 2.0, q * adt  # 3.0: libm's pow
    dt2 = dt * dt
    Pn = P.copy()
    for i in range(3):
        ri, vi = 6 * i, 6 * (i + 3)
        for j in range(3):
            # P_pp' = P_pp + dt (P_pv + P_vp) + dt² P_vv ; P_pv' = P_pv + dt P_vv
            Pn[ri + j] = (P[ri + j] + dt * (P[ri + 3 + j] + P[vi + j])
                          + dt2 * P[vi + 3 + j])
            Pn[ri + 3 + j] = P[ri + 3 + j] + dt * P[vi + 3 + j]
            Pn[vi + j] = P[vi + j] + dt * P[vi + 3 + j]
        Pn[ri + i] += q3
        Pn[ri + 3 + i] += q2
        Pn[vi + i] += q2
        Pn[vi + 3 + i] += q1
    return Pn


@kernel
def _acceleration(v0, v1, v2, c, O):
    """The models' mixture's acceleration ``c g − (k_s + c (k − k_s)) ‖v‖ v`` at velocity
    ``v`` (m/s², three floats; :func:`_predicted_mean`'s, :func:`_contact`'s and
    :func:`_bounced`'s)."""
    # written so that k_s = k gives k exactly (the filter before the drag-free supported model)
    k = O[_OKS] + c * (O[_OK] - O[_OKS])
    speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    gx, gy, gz = c * O[_OG], c * O[_OG + 1], c * O[_OG + 2]
    return gx - k * speed * v0, gy - k * speed * v1, gz - k * speed * v2


@kernel
def _contact(x, dt, c, O):
    """The instant ``s`` in ``[0, dt]`` (seconds) at which the mean path of
    :func:`_predicted_mean` (constant acceleration ``a``) reaches the floor ``h(p) = −ĝ·p =
    floor_m`` from above, falling faster than ``_BOUNCE_MIN_SPEED`` there; −1 when it does
    not (no floor, ``dt <= 0``, the mean already below the floor, not reaching it, or
    slower: a ball rolling or at rest). ``s`` is the least root of ``h₀ − floor + w s +
    a_h s²/2 = 0`` (``w = −ĝ·v``, ``a_h = −ĝ·a``; the quadratic's stable form)."""
    floor = O[_OFLOOR]
    if not (dt > 0.0) or floor != floor:
        return -1.0
    d0, d1, d2 = O[_ODOWN], O[_ODOWN + 1], O[_ODOWN + 2]
    h0 = -(x[0] * d0 + x[1] * d1 + x[2] * d2) - floor
    if not h0 >= 0.0:
        return -1.0
    w = -(x[3] * d0 + x[4] * d1 + x[5] * d2)
    a0, a1, a2 = _acceleration(x[3], x[4], x[5], c, O)
    ah = -(a0 * d0 + a1 * d1 + a2 * d2)
    if not h0 + w * dt + 0.5 * ah * dt * dt < 0.0:
        return -1.0
    A, B, C = 0.5 * ah, w, h0
    s = dt
    if A == 0.0:
        if B < 0.0:
            s = -C / B
    else:
        disc = B * B - 4.0 * A * C
        root = math.sqrt(disc) if disc > 0.0 else 0.0
        qq = -0.5 * (B + (root if B >= 0.0 else -root))
        for r in (qq / A, C / qq if qq != 0.0 else math.inf):
            if 0.0 <= r < s:
                s = r
    # the speed towards the floor at the contact
    if not -(w + ah * s) > _BOUNCE_MIN_SPEED:
        return -1.0
    return s


@kernel
def _reflected(vm, O):
    """The floor's reset of the velocity ``vm`` (3, m/s, just before a contact): ``v_d =
    ĝ·v⁻`` (float), ``v_h = v⁻ − v_d ĝ`` and ``v⁺ = (1 − f) v_h − e v_d ĝ`` (new (3,)
    arrays; ``e`` ``restitution``, ``f`` ``bounce_friction``): :func:`_bounced`'s and
    :func:`_hybrid_mean`'s."""
    d = O[_ODOWN:_ODOWN + 3]
    e, f = O[_OREST], O[_OFRIC]
    vd = vm[0] * d[0] + vm[1] * d[1] + vm[2] * d[2]
    vh = np.empty(3)
    vp = np.empty(3)
    for i in range(3):
        vh[i] = vm[i] - vd * d[i]
        vp[i] = (1.0 - f) * vh[i] - e * vd * d[i]
    return vd, vh, vp


@kernel
def _bounced(x, P, c, O):
    """The state just after a floor contact from ``(x, P)`` just before it (new arrays;
    session 31). The reset ``R``: position kept, velocity ``v⁺ = D v⁻``, ``D = (1 − f)(I −
    ĝĝᵀ) − e ĝĝᵀ`` (``e`` ``restitution``, ``f`` ``bounce_friction``). The covariance
    through the saltation matrix of the hybrid system (Kong, Payne, Council & Johnson, "The
    Salted Kalman Filter: Kalman filtering on hybrid dynamical systems", Automatica 131,
    2021, eq. (7)): ``Ξ = D_xR + (f⁺ − D_xR f⁻) D_xg / (D_tg + D_xg f⁻)`` with the guard
    ``g(x) = −ĝ·p − floor`` (``D_xg = (−ĝᵀ, 0)``, ``D_tg = 0``), ``f = (v, a(v))`` the
    flow (the mixture's acceleration, :func:`_acceleration`), so with ``v_d = ĝ·v⁻ > 0``
    ``Ξ = [[I + (v⁺ − v⁻) ĝᵀ / v_d, 0], [(a⁺ − D a⁻) ĝᵀ / v_d, D]]``; then ``P⁺ = Ξ P Ξᵀ
    + Q_b``, ``Q_b`` the reflection's uncertainty on the velocity: ``σ_e² v_d² ĝĝᵀ + σ_f²
    v_h v_hᵀ`` (``v_h = v⁻ − v_d ĝ``; ``∂v⁺/∂e = −v_d ĝ``, ``∂v⁺/∂f = −v_h``)."""
    d = O[_ODOWN:_ODOWN + 3]
    e, f = O[_OREST], O[_OFRIC]
    vm = x[3:6]
    vd, vh, vp = _reflected(vm, O)
    am = np.empty(3)
    am[0], am[1], am[2] = _acceleration(vm[0], vm[1], vm[2], c, O)
    ap = np.empty(3)
    ap[0], ap[1], ap[2] = _acceleration(vp[0], vp[1], vp[2], c, O)
    ad = am[0] * d[0] + am[1] * d[1] + am[2] * d[2]
    da = np.empty(3)  # a⁺ − D a⁻
    for i in range(3):
        da[i] = ap[i] - ((1.0 - f) * (am[i] - ad * d[i]) - e * ad * d[i])
    X = np.zeros((6, 6))
    for i in range(3):
        for j in range(3):
            X[i, j] = (1.0 if i == j else 0.0) + (vp[i] - vm[i]) * d[j] / vd
            X[3 + i, j] = da[i] * d[j] / vd
            X[3 + i, 3 + j] = (1.0 - f) * ((1.0 if i == j else 0.0) - d[i] * d[j]) \
                - e * d[i] * d[j]
    A = np.zeros((6, 6))  # Ξ P (loops: no BLAS, a fixed order of operations)
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for k in range(6):
                acc += X[i, k] * P[6 * k + j]
            A[i, j] = acc
    Pp = np.empty(36)
    for i in range(6):
        for j in range(6):
            acc = 0.0
            for k in range(6):
                acc += A[i, k] * X[j, k]
            Pp[6 * i + j] = acc
    se2, sf2 = O[_OESTD2], O[_OFSTD2]
    for i in range(3):
        for j in range(3):
            Pp[6 * (3 + i) + 3 + j] += se2 * vd * vd * d[i] * d[j] + sf2 * vh[i] * vh[j]
    for i in range(6):  # (exactly symmetric)
        for j in range(i):
            Pp[6 * i + j] = Pp[6 * j + i] = 0.5 * (Pp[6 * i + j] + Pp[6 * j + i])
    xn = x.copy()
    xn[3], xn[4], xn[5] = vp[0], vp[1], vp[2]
    return xn, Pp


@kernel
def _turn_predicted(x, P, dt, q, turn_psd):
    """The turn model's mean and covariance after ``dt`` seconds (new arrays): a coordinated
    turn at rate ``ω`` about z (the horizontal velocity rotates, speed constant), constant
    vertical velocity, ``ω`` a random walk; ``P⁻ = F P Fᵀ + Q`` with the Jacobian ``F`` (7 x
    7) and the white-noise acceleration ``q`` (as the other models) plus ``q_ω |Δt|`` on ``ω``
    (Li & Jilkov 2003, section 4)."""
    px, py, pz, vx, vy, vz, w = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
    a = w * dt
    s, c = math.sin(a), math.cos(a)
    if abs(a) > 1e-3:
        sw, cw = s / w, (1.0 - c) / w  # sin(ωΔt)/ω, (1 - cos(ωΔt))/ω
        dsw, dcw = (dt * c - sw) / w, (dt * s - cw) / w  # their derivatives in ω
    else:  # their series (ω → 0: a straight line)
        a2 = a * a
        sw = dt * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0))
        cw = dt * a * (0.5 - a2 / 24.0)
        dsw = dt * dt * a * (a2 / 30.0 - 1.0 / 3.0)
        dcw = dt * dt * (0.5 - a2 / 8.0)
    vxn, vyn = c * vx - s * vy, s * vx + c * vy
    xn = np.empty(7)
    xn[0], xn[1], xn[2] = px + sw * vx - cw * vy, py + cw * vx + sw * vy, pz + vz * dt
    xn[3], xn[4], xn[5], xn[6] = vxn, vyn, vz, w
    fx, fy = dsw * vx - dcw * vy, dcw * vx + dsw * vy  # ∂p/∂ω
    f3, f4 = -dt * vyn, dt * vxn  # ∂v/∂ω
    # A = F P (rows of P combined by F's sparse rows), then A Fᵀ (A's rows likewise)
    A = np.empty(49)
    for j in range(7):
        r0, r1, r2, r3, r4, r5, r6 = P[j], P[7 + j], P[14 + j], P[21 + j], P[28 + j], \
            P[35 + j], P[42 + j]
        A[j] = r0 + sw * r3 - cw * r4 + fx * r6
        A[7 + j] = r1 + cw * r3 + sw * r4 + fy * r6
        A[14 + j] = r2 + dt * r5
        A[21 + j] = c * r3 - s * r4 + f3 * r6
        A[28 + j] = s * r3 + c * r4 + f4 * r6
        A[35 + j] = r5
        A[42 + j] = r6
    Pn = np.empty(49)
    for i in range(7):
        b = 7 * i
        a0, a1, a2, a3, a4, a5, a6 = A[b], A[b + 1], A[b + 2], A[b + 3], A[b + 4], A[b + 5], \
            A[b + 6]
        Pn[b] = a0 + sw * a3 - cw * a4 + fx * a6
        Pn[b + 1] = a1 + cw * a3 + sw * a4 + fy * a6
        Pn[b + 2] = a2 + dt * a5
        Pn[b + 3] = c * a3 - s * a4 + f3 * a6
        Pn[b + 4] = s * a3 + c * a4 + f4 * a6
        Pn[b + 5] = a5
        Pn[b + 6] = a6
    adt = abs(dt)
    q3, q2, q1 = q * adt ** 3.0 / 3.0, q * dt * adt / 2.0, q * adt
    for i in range(3):
        Pn[8 * i] += q3
        Pn[8 * i + 3] += q2
        Pn[8 * i + 21] += q2
        Pn[8 * i + 24] += q1
    Pn[48] += turn_psd * adt
    return xn, Pn


@kernel
def _block6(P):
    """The position-velocity block (6 x 6 flat) of a 7 x 7 flat covariance (a new array)."""
    out = np.empty(36)
    for i in range(6):
        for j in range(6):
            out[6 * i + j] = P[7 * i + j]
    return out


@kernel
def _turn_start(x, P, w, var):
    """The turn model's state at the pair's ``(x, P)`` with turn rate ``w ± sqrt(var)``
    (uncorrelated)."""
    xt = np.zeros(7)
    Pt = np.zeros(49)
    for i in range(6):
        xt[i] = x[i]
        for j in range(6):
            Pt[7 * i + j] = P[6 * i + j]
    xt[6] = w
    Pt[48] = var
    return xt, Pt


@kernel
def _turn_mixed(nu, xg, Pg, xt, Pt, dt, turn_switch):
    """The interacting multiple model's mixing of the pair (ballistic/supported, mean ``xg``,
    covariance ``Pg``) and the turn model (``xt``, ``Pt``, probability ``nu``) before a step
    of ``dt``: the turn model is left with probability ``p = min(λ_t |Δt|, 1/2)``; each model
    starts from the mixture of both weighted by where it came from, spread of the means
    included (the pair's missing ω is the turn model's) (Blom & Bar-Shalom 1988).
    Returns ``(ν⁻, pair's x, P, turn model's x, P)``."""
    pt = _pmin(turn_switch * abs(dt), 0.5)
    prior = nu * (1.0 - pt) + (1.0 - nu) * pt
    wt = nu * pt / (1.0 - prior) if prior < 1.0 else 0.0  # turn's share of the pair's
    wg = (1.0 - nu) * pt / prior  # the pair's share of the turn model's start
    d = np.empty(6)
    x0 = np.empty(6)
    xt0 = np.empty(7)
    for i in range(6):
        d[i] = xt[i] - xg[i]
    for i in range(6):
        x0[i] = xg[i] + wt * d[i]
        xt0[i] = xt[i] - wg * d[i]
    xt0[6] = xt[6]
    sg, st = wt * (1.0 - wt), wg * (1.0 - wg)
    P0 = np.empty(36)
    Pt0 = np.empty(49)
    keep = 1.0 - wg
    for i in range(6):
        di = d[i]
        gd, td = sg * di, st * di
        for j in range(6):
            a, b = Pg[6 * i + j], Pt[7 * i + j]
            P0[6 * i + j] = a + wt * (b - a) + gd * d[j]
            Pt0[7 * i + j] = b + wg * (a - b) + td * d[j]
        # the pair's ω: the turn model's, uncorrelated with the pair's state (a covariance
        # that stays positive semi-definite)
        Pt0[7 * i + 6] = keep * Pt[7 * i + 6]
    for j in range(6):
        Pt0[42 + j] = keep * Pt[42 + j]
    Pt0[48] = Pt[48]
    return prior, x0, P0, xt0, Pt0


@kernel
def _turn_probability(prior, c, nis_b, nis_s, det, nis_t, det_t):
    """The turn model's probability ``ν⁺`` after the detection from the models' likelihoods
    ``N(y; 0, S)``: the pair's is its models' mixture ``c N_b + (1 - c) N_s`` (their common
    ``det S``); the log ratio is clipped as the pair's."""
    low = _pmin(nis_b, nis_s)
    log_pair = (-0.5 * low - 0.5 * math.log(det)
                + math.log(c * math.exp(0.5 * (low - nis_b))
                           + (1.0 - c) * math.exp(0.5 * (low - nis_s))))
    r = -0.5 * nis_t - 0.5 * math.log(det_t) - log_pair
    r = _pmin(_pmax(r, -_LOG_ODDS_CLIP), _LOG_ODDS_CLIP)
    return prior / (prior + (1.0 - prior) * math.exp(-r))


@kernel
def _mixed(x, inn, c, p, dt, mu, e, O):
    """The interacting multiple model step with a covariance the two models share.

    ``x``, ``inn``: the mixture's prediction and innovation; ``c``: the ballistic model's
    prior probability, ``p`` the switching probability. The models' means are ``m + (1 -
    c) e`` and ``m - c e`` with ``e`` their difference: the mixing shrinks it by ``1 -
    μ_s p / c - μ_b p / (1 - c)``, the prediction propagates it (``e_p += Δt e_v``) and
    adds gravity's ``d = (g Δt²/2, g Δt)``; the models' innovations are the mixture's
    minus ``H`` of their offsets (linearised), their likelihood ratio (equal ``S``)
    ``exp((NIS_s - NIS_b) / 2)`` gives ``μ⁺``; the mixture is re-weighted with ``μ⁺``
    (``x + (μ⁺ - c) e``) and ``e`` updated to ``(I - K H) e``.
    Returns ``(x, innovation, μ⁺, e⁺, NIS_b, NIS_s)`` (new arrays)."""
    y0, y1, i00, i01, i11 = inn[0], inn[1], inn[2], inn[3], inn[4]
    shrink = 1.0 - (1.0 - mu) * p / c - mu * p / (1.0 - c) if 0.0 < c < 1.0 else 1.0
    half = 0.5 * dt * dt
    # the models' accelerations differ by gravity and the drag's difference (at the
    # mixture's predicted velocity): g - (k - k_s) ‖v‖ v (g exactly when k_s = k)
    dk = O[_OK] - O[_OKS]
    speed = math.sqrt(x[3] * x[3] + x[4] * x[4] + x[5] * x[5])
    en = np.empty(6)
    for i in range(3):
        en[i] = shrink * (e[i] + dt * e[3 + i]) + half * (O[_OG + i] - dk * speed * x[3 + i])
    for i in range(3):
        en[3 + i] = shrink * e[3 + i] + dt * (O[_OG + i] - dk * speed * x[3 + i])
    hd0 = inn[7] * en[0] + inn[8] * en[1] + inn[9] * en[2]
    hd1 = inn[10] * en[0] + inn[11] * en[1] + inn[12] * en[2]
    b0, b1 = y0 - (1.0 - c) * hd0, y1 - (1.0 - c) * hd1
    s0, s1 = y0 + c * hd0, y1 + c * hd1
    nis_b = b0 * (i00 * b0 + i01 * b1) + b1 * (i01 * b0 + i11 * b1)
    nis_s = s0 * (i00 * s0 + i01 * s1) + s1 * (i01 * s0 + i11 * s1)
    r = _pmin(_pmax(0.5 * (nis_b - nis_s), -_LOG_ODDS_CLIP), _LOG_ODDS_CLIP)
    mu = c / (c + (1.0 - c) * math.exp(r))
    delta = mu - c
    xn = np.empty(6)
    for i in range(6):
        xn[i] = x[i] + delta * en[i]
    y0, y1 = y0 - delta * hd0, y1 - delta * hd1
    out = inn.copy()
    out[0], out[1] = y0, y1
    out[5] = y0 * (i00 * y0 + i01 * y1) + y1 * (i01 * y0 + i11 * y1)
    # (I - K H) e with K = PHᵀ S⁻¹
    g0, g1 = i00 * hd0 + i01 * hd1, i01 * hd0 + i11 * hd1
    c0, c1 = _INN_C0, _INN_C0 + 6
    for i in range(6):
        en[i] = en[i] - inn[c0 + i] * g0 - inn[c1 + i] * g1
    return xn, out, mu, en, nis_b, nis_s


@kernel
def _jumped(x, P, dt, O, shape):
    """``(ok, x, P)`` after a velocity jump ``Δv ~ N(μ, diag(σ²))`` at an instant ``s``
    uniform over the last ``dt`` (``Δp = Δv s``, ``E[s] = dt/2``, ``E[s²] = dt²/3``,
    ``Var s = dt²/12``); shape ``shape`` of ``O``'s (reflect, σ² (3)): ``μ = 0``, or for a
    floor bounce ``μ = −(1 + e) v_d ĝ − f (v − v_d ĝ)`` with ``v_d = v·ĝ`` (``ĝ`` gravity's
    unit vector; ``ok`` False when the ball is not falling, or with a known floor
    ``O[_OFLOOR]`` out of its reach: the height ``h`` above it at the step's end, predicted
    without a bounce (a falling ball's lowest in the step), beyond the gate's quantile of
    its spread, ``h² > γ ĝᵀP_ppĝ`` (session 36: a kick in mid-air taken for a floor bounce,
    whose velocity spread is a tenth of a kick's, was confirmed 15 σ off))."""
    base = _OSHAPES + 4 * shape
    x = x.copy()
    P = P.copy()
    if O[base] != 0.0:
        d0, d1, d2 = O[_ODOWN], O[_ODOWN + 1], O[_ODOWN + 2]
        vd = x[3] * d0 + x[4] * d1 + x[5] * d2
        if not vd > 0:
            return False, x, P
        floor = O[_OFLOOR]
        if floor == floor:  # a known floor (session 36): the bounce needs it within reach
            # the height above the floor at the step's end, predicted without a bounce
            # (falling: the step's lowest), against the gate's quantile of its spread
            h = -(x[0] * d0 + x[1] * d1 + x[2] * d2) - floor
            var_h = 0.0
            for i in range(3):
                for j in range(3):
                    var_h += O[_ODOWN + i] * P[6 * i + j] * O[_ODOWN + j]
            if h > 0.0 and h * h > O[_OGATE] * var_h:
                return False, x, P
        e, f = O[_OREST], O[_OFRIC]
        mu = np.empty(3)
        for i in range(3):
            di = O[_ODOWN + i]
            mu[i] = -(1.0 + e) * vd * di - f * (x[3 + i] - vd * di)
        for i in range(3):
            x[3 + i] += mu[i]
            x[i] += mu[i] * dt / 2.0
            for j in range(3):  # the jump's unknown instant spreads its mean's shift
                P[6 * i + j] += mu[i] * mu[j] * dt * dt / 12.0
    for i in range(3):
        jv = O[base + 1 + i]
        P[7 * i] += jv * dt * dt / 3.0
        P[6 * i + 3 + i] += jv * dt / 2.0
        P[6 * (i + 3) + i] += jv * dt / 2.0
        P[7 * (i + 3)] += jv
    return True, x, P


@kernel
def _replay(S, I, cams, O, t, cam, u, v, lag, shape):
    """One (lag, shape) of :func:`_jump`: the state before the ``lag``-th latest accepted
    detection (the current state when 0), the jump on its step (:func:`_jumped`), the
    accepted detections since and this one updated in turn, each within the gate.
    Returns ``(passed, x, P, innovation of this detection, score, restart time, restart
    state, its covariance)``, the score the ``Σ NIS + ln det S`` of the history before the
    lag and of the replay."""
    n = I[_IHN]
    start = max(n - _JUMP_LAG, 0)
    if lag == 0:  # the state before the current detection
        t0 = I[_ITIME]
        x = S[_SX:_SX + 6]
        P = S[_SP:_SP + 36]
    else:  # restart before the lag-th latest accepted detection
        h = n - lag
        t0 = I[_IHT + 3 * h]
        x = S[_SHX + 6 * h:_SHX + 6 * h + 6]
        P = S[_SHP + 36 * h:_SHP + 36 * h + 36]
    ts, xs, Ps = t0, x, P
    score = 0.0
    for k in range(start, n - lag):
        score += S[_SHSC + k]
    first = True
    inn = np.empty(_INN_C0 + 12)
    for d in range(lag + 1):
        if d < lag:  # the accepted detections since, oldest first
            h = n - lag + d
            td, cd = I[_IHT + 3 * h + 1], I[_IHT + 3 * h + 2]
            ud, vd = S[_SHUV + 2 * h], S[_SHUV + 2 * h + 1]
        else:
            td, cd, ud, vd = t, cam, u, v
        dt = (td - t0) / NS
        x, P = _predicted(x, P, dt, S[_SMU], O, S[_SQ])
        if first:  # the jump Δv at an instant uniform in the interval: Δp = Δv s
            ok, x, P = _jumped(x, P, dt, O, shape)
            if not ok:
                return False, x, P, inn, score, ts, xs, Ps
            first = False
        ok, inn = _innovation(cams, cd, x, P, 6, ud, vd, S[_SVAR])
        if not ok or not inn[5] <= O[_OGATE]:
            return False, x, P, inn, score, ts, xs, Ps
        score += inn[5] + math.log(inn[6])
        x, P = _updated(x, P, inn)
        t0 = td
    return True, x, P, inn, score, ts, xs, Ps


@kernel
def _jump(S, I, cams, O, t, cam, u, v):
    """A bounce or a kick: a velocity jump (a bounce's, mostly along gravity, then a kick's,
    isotropic; position continuous) at the state before one of the last ``_JUMP_LAG + 1``
    accepted detections (the first detections after a small jump can pass the gate), those
    detections and this one replayed; the (lag, shape) whose replay passes every gate with
    the least ``Σ NIS + ln det S`` over the same detections wins.
    The winner's restart and detections are kept (``O[_OINSTANT]``, session 25), with the
    ``(c, q, σ²)`` its replay used (session 27), for the published covariance of its instant
    (:func:`_instant_term`).
    Returns ``(ok, x, P, innovation of this detection)``; ``ok`` False when none explains
    it. The replay's prediction weights gravity by the ballistic model's probability of
    the current state (the models' mixture), as the step's own prediction does."""
    n = I[_IHN]
    best_x = np.empty(6)
    best_P = np.empty(36)
    best_inn = np.empty(_INN_C0 + 12)
    found = False
    best_score = math.inf
    best_lag = best_shape = 0
    best_t0 = I[_ITIME]
    best_x0 = S[_SX:_SX + 6]
    best_P0 = S[_SP:_SP + 36]
    n_lags = min(n, _JUMP_LAG) + 1
    n_shapes = int(O[_ONSHAPES])
    hsc = np.empty(n_lags * n_shapes)
    hlag = np.empty(n_lags * n_shapes, dtype=np.int64)
    hx = np.empty((n_lags * n_shapes, 6))
    hP = np.empty((n_lags * n_shapes, 36))
    nh = 0
    for lag in range(n_lags):
        for shape in range(n_shapes):
            passed, x, P, inn, score, ts, xs, Ps = _replay(S, I, cams, O, t, cam, u, v, lag,
                                                           shape)
            if passed:
                hlag[nh] = lag
                hsc[nh] = score
                hx[nh] = x
                hP[nh] = P
                nh += 1
            if passed and score < best_score:
                best_x, best_P, best_inn, best_score, found = x, P, inn, score, True
                best_lag, best_shape, best_t0, best_x0, best_P0 = lag, shape, ts, xs, Ps
    if found and nh > 1 and O[_OJMIX] != 0.0:
        # the winner's mean with the mean square error of the hypotheses' mixture about it
        # (session 27): P* = Σ w_k (P_k + (x_k − x*)(x_k − x*)ᵀ), w_k ∝ exp(−score_k/2)
        best_P = _mixture_about(hsc[:nh], hx[:nh], hP[:nh], best_x, best_score)
    if found:
        # each lag's posterior probability among the hypotheses that passed (the mixture's
        # weights, w_k ∝ exp(−score_k/2), summed per lag; session 31)
        total = 0.0
        for k in range(_HISTORY):
            S[_SJLW + k] = 0.0
        for k in range(nh):
            total += math.exp(-0.5 * (hsc[k] - best_score))
        for k in range(nh):
            S[_SJLW + hlag[k]] += math.exp(-0.5 * (hsc[k] - best_score)) / total
    if found and O[_OINSTANT] != 0.0:
        # the jump's restart and the detections its replay took, for its instant's spread
        S[_SJX:_SJX + 6] = best_x0
        S[_SJP:_SJP + 36] = best_P0
        I[_IJT0], I[_IJSHAPE] = best_t0, best_shape
        for d in range(best_lag):
            h = n - best_lag + d
            I[_IJBUF + 2 * d], I[_IJBUF + 2 * d + 1] = I[_IHT + 3 * h + 1], I[_IHT + 3 * h + 2]
            S[_SJUV + 2 * d], S[_SJUV + 2 * d + 1] = S[_SHUV + 2 * h], S[_SHUV + 2 * h + 1]
        I[_IJBUF + 2 * best_lag], I[_IJBUF + 2 * best_lag + 1] = t, cam
        S[_SJUV + 2 * best_lag], S[_SJUV + 2 * best_lag + 1] = u, v
        I[_IJN] = best_lag + 1
        I[_IJLAG] = best_lag
        S[_SJPM:_SJPM + 36] = best_P
        for d in range(best_lag + 1):  # the values the replay used
            S[_SJF + 3 * d], S[_SJF + 3 * d + 1] = S[_SMU], S[_SQ]
            S[_SJF + 3 * d + 2] = S[_SVAR]
    if found:
        I[_IHN] = 0  # a new segment: a later jump is not looked for before it
    return found, best_x, best_P, best_inn


@kernel
def _mixture_about(sc, hx, hP, x, best):
    """The mean square error about ``x`` (the winning hypothesis's mean, its score
    ``best``) of the mixture of a jump's hypotheses that passed: ``Σ w_k (P_k + d_k d_kᵀ)``,
    ``d_k = x_k − x``, ``w_k = exp(−(score_k − best)/2) / Σ`` (each score the ``Σ NIS + ln
    det S`` of the same detections: a likelihood's −2 ln up to one constant)."""
    n = sc.shape[0]
    w = np.empty(n)
    total = 0.0
    for k in range(n):
        w[k] = math.exp(-0.5 * (sc[k] - best))
        total += w[k]
    P = np.zeros(36)
    for k in range(n):
        wk = w[k] / total
        for i in range(6):
            di = hx[k, i] - x[i]
            for j in range(6):
                P[6 * i + j] += wk * (hP[k, 6 * i + j] + di * (hx[k, j] - x[j]))
    return P


@kernel
def _predicted_mean(x, dt, c, O):
    """:func:`_predicted`'s mean (6,): gravity weighted by ``c`` and the drag ``k_s + c (k −
    k_s)``, constant acceleration over ``dt`` seconds (also the instant term's replay)."""
    px, py, pz, vx, vy, vz = x[0], x[1], x[2], x[3], x[4], x[5]
    ax, ay, az = _acceleration(vx, vy, vz, c, O)
    h = 0.5 * dt * dt
    xn = np.empty(6)
    xn[0], xn[1], xn[2] = px + vx * dt + ax * h, py + vy * dt + ay * h, pz + vz * dt + az * h
    xn[3], xn[4], xn[5] = vx + ax * dt, vy + ay * dt, vz + az * dt
    return xn


@kernel
def _hybrid_mean(x, dt, c, O):
    """:func:`_predicted`'s mean alone (6,), its floor contact included."""
    s = _contact(x, dt, c, O)
    if s < 0.0:
        return _predicted_mean(x, dt, c, O)
    xb = _predicted_mean(x, s, c, O)
    xb[3:6] = _reflected(xb[3:6], O)[2]  # (_bounced's reset, its covariance not needed)
    return _predicted_mean(xb, dt - s, c, O)


@kernel
def _drag_predicted(V, x, dt, c):
    """The state's sensitivity ``V = ∂x/∂k`` (6) to the ballistic model's drag ``k`` after
    ``dt`` seconds (a new array; session 29): ``V⁻ = F V − c ‖v‖ (v Δt²/2, v Δt)``, ``F``
    the constant-velocity transition, ``v`` the predicted velocity ``x[3:]``, ``c`` the
    ballistic model's weight (the mixture's drag is ``k_s + c (k − k_s)``: ``∂/∂k = c``)."""
    a = c * math.sqrt(x[3] * x[3] + x[4] * x[4] + x[5] * x[5])
    h = 0.5 * dt * dt
    Vn = np.empty(6)
    for i in range(3):
        Vn[i] = V[i] + dt * V[3 + i] - a * x[3 + i] * h
        Vn[3 + i] = V[3 + i] - a * x[3 + i] * dt
    return Vn


@kernel
def _drag_update(S, inn, y0, y1, Vm):
    """The drag's offset ``δk̂`` and the sensitivity ``V`` after an accepted update
    (Friedland, "Treatment of bias in recursive filtering", IEEE Trans. AC 14(4), 1969: the
    two-stage, separate-bias filter; in place in ``S``): with the update's pixel Jacobian
    ``H`` (``inn``'s h0, h1), ``S⁻¹``, ``PHᵀ`` and the prior innovation ``y`` of the filter
    run at ``k₀``, ``z = H V⁻_p``,

        I_k ← I_k + zᵀ S⁻¹ z,   δk̂ ← δk̂ + zᵀ S⁻¹ (y − z δk̂) / I_k,   V = V⁻ − K z,

    ``K = PHᵀ S⁻¹`` (for a constant ``δk`` and a linear model: the filter with ``k`` in its
    state, the state ``x + V δk̂``)."""
    z0 = inn[7] * Vm[0] + inn[8] * Vm[1] + inn[9] * Vm[2]
    z1 = inn[10] * Vm[0] + inn[11] * Vm[1] + inn[12] * Vm[2]
    g0, g1 = inn[2] * z0 + inn[3] * z1, inn[3] * z0 + inn[4] * z1  # S⁻¹ z
    info = S[_SIK] + z0 * g0 + z1 * g1
    dk = S[_SDK]
    S[_SDK] = dk + (g0 * (y0 - z0 * dk) + g1 * (y1 - z1 * dk)) / info
    S[_SIK] = info
    c0, c1 = _INN_C0, _INN_C0 + 6
    for i in range(6):
        S[_SV + i] = Vm[i] - inn[c0 + i] * g0 - inn[c1 + i] * g1


@kernel
def _drag_forget(S, I, O, t):
    """The drag's random walk since its latest update (in place; session 29, the review):
    ``1/I_k ← 1/I_k + q_k Δt``, ``q_k = σ_k² / T_k`` (``O[_ODRAGQ]``), ``Δt`` the time since
    the latest drag update (none before the first); ``I[_IDRAGT] ← t``."""
    last = I[_IDRAGT]
    q = O[_ODRAGQ]
    if q > 0.0 and last > -(2 ** 61) and t > last:
        info = S[_SIK]
        S[_SIK] = info / (1.0 + info * q * ((t - last) / NS))
    I[_IDRAGT] = t


@kernel
def _drag_point(S, px, py, pz, vx, vy, vz):
    """A published point and its variances (x, y, z) with the estimated drag: ``p + V_p
    δk̂`` and ``diag(P_pp) + V_p² / I_k`` (``S``'s current ``V``)."""
    V0, V1, V2, dk = S[_SV], S[_SV + 1], S[_SV + 2], S[_SDK]
    w = 1.0 / S[_SIK]
    return (px + V0 * dk, py + V1 * dk, pz + V2 * dk, vx + V0 * V0 * w, vy + V1 * V1 * w,
            vz + V2 * V2 * w)


@kernel
def _instant_term(S, I, cams, O, t, x):
    """The error an accepted jump's unknown instant leaves in the state ``x`` at ``t``
    (the jump's buffered detections, the latest at ``t``, all updated; session 25): the
    jump ``Δv`` at an instant ``s`` uniform over its step of ``Δt_j`` moves the ball by
    ``Δv s``, which the filter takes at ``E[s] = Δt_j/2`` with ``Δv``'s prior (zero mean
    for a kick): linearised about the jump the state now estimates, ``m = v − v̄`` (``v̄``
    the restart state's velocity predicted to ``t`` without the jump, step by step), the term
    ``m (s − Δt_j/2)`` of variance ``m mᵀ Δt_j²/12`` that the prior's linearisation (at
    ``m = μ``) dropped. Its effect on the state at ``t`` through the filter's own gains
    (a consider covariance: Bar-Shalom et al. 2001, §5.4; Schmidt's): ``ε`` from
    ``(m, 0)`` on the jump's step, ``ε ← F ε`` each prediction (``ε_p += Δt ε_v``),
    ``ε ← (I − K H) ε`` each update, along the jump's replay from its restart, each step
    with the gravity weight ``c``, process noise ``q`` and pixel variance ``σ²`` in force at
    its update (kept per buffered detection, ``_SJF``: the jump's own replay's for the
    detections it took, then each later step's own; session 27: before, the latest values
    for every step). The term is added on top of the jump's prior, which already holds
    ``μ μᵀ Δt_j²/12`` (a floor bounce's mean, also in ``m``) and ``Σ_j Δt_j²/12``:
    deliberately (measured, docs/methods.md "A jump's instant"). Returns ``(ok, ε_p (3),
    Δt_j²/12)``: the published covariance gains ``ε_p ε_pᵀ Δt_j²/12``."""
    # the restart predicted to t without the jump, each step with the c its update used
    xb = S[_SJX:_SJX + 6]
    tb = I[_IJT0]
    for d in range(I[_IJN]):
        td = I[_IJBUF + 2 * d]
        xb = _hybrid_mean(xb, (td - tb) / NS, S[_SJF + 3 * d], O)
        tb = td
    e = np.zeros(6)
    for i in range(3):
        e[i] = x[3 + i] - xb[3 + i]
    t0 = I[_IJT0]
    x = S[_SJX:_SJX + 6]
    P = S[_SJP:_SJP + 36]
    w = 0.0
    c0, c1 = _INN_C0, _INN_C0 + 6
    for d in range(I[_IJN]):
        td, cd = I[_IJBUF + 2 * d], I[_IJBUF + 2 * d + 1]
        ud, vd = S[_SJUV + 2 * d], S[_SJUV + 2 * d + 1]
        dt = (td - t0) / NS
        # the (c, q, σ²) in force at this detection's update (the jump's replay: those of
        # the jump's step; later ones: their own steps')
        cf, qf, vf = S[_SJF + 3 * d], S[_SJF + 3 * d + 1], S[_SJF + 3 * d + 2]
        x, P = _predicted(x, P, dt, cf, O, qf)
        if d == 0:
            ok, x, P = _jumped(x, P, dt, O, I[_IJSHAPE])
            if not ok:
                return False, e[:3], w
            w = dt * dt / 12.0
        else:
            for i in range(3):
                e[i] += dt * e[3 + i]
        ok, inn = _innovation(cams, cd, x, P, 6, ud, vd, vf)
        if not ok:
            return False, e[:3], w
        hd0 = inn[7] * e[0] + inn[8] * e[1] + inn[9] * e[2]
        hd1 = inn[10] * e[0] + inn[11] * e[1] + inn[12] * e[2]
        g0, g1 = inn[2] * hd0 + inn[3] * hd1, inn[3] * hd0 + inn[4] * hd1
        for i in range(6):
            e[i] = e[i] - inn[c0 + i] * g0 - inn[c1 + i] * g1
        x, P = _updated(x, P, inn)
        if d == I[_IJLAG] and O[_OJMIX] != 0.0:  # the jump's covariance as the state took it
            P = S[_SJPM:_SJPM + 36].copy()
        t0 = td
    return True, e[:3], w


@kernel
def _combined_point(x, P, xt, Pt, nu):
    """The position (3) and its variances (x, y, z) of the mixture of the pair ``(x, P)``
    and the turn model ``(xt, Pt)`` of probability ``nu``."""
    if not nu:
        return x[0], x[1], x[2], P[0], P[7], P[14]
    d0, d1, d2 = xt[0] - x[0], xt[1] - x[1], xt[2] - x[2]
    w, m = nu * (1.0 - nu), 1.0 - nu
    return (x[0] + nu * d0, x[1] + nu * d1, x[2] + nu * d2,
            m * P[0] + nu * Pt[0] + w * d0 * d0, m * P[7] + nu * Pt[8] + w * d1 * d1,
            m * P[14] + nu * Pt[16] + w * d2 * d2)


@kernel
def _combined(x, P, xt, Pt, nu):
    """The mixture of the pair ``(x, P)`` (6) and the turn model ``(xt, Pt)`` (7) of
    probability ``nu``: mean and covariance (6, 6 x 6 flat; new arrays) with the spread of
    the means."""
    if not nu:
        return x.copy(), P.copy()
    d = np.empty(6)
    xc = np.empty(6)
    for i in range(6):
        d[i] = xt[i] - x[i]
        xc[i] = x[i] + nu * d[i]
    w = nu * (1.0 - nu)
    Pc = np.empty(36)
    for i in range(6):
        for j in range(6):
            Pc[6 * i + j] = (1.0 - nu) * P[6 * i + j] + nu * Pt[7 * i + j] + w * d[i] * d[j]
    return xc, Pc


@kernel
def _point(out, px, py, pz, vx, vy, vz, y0, y1, r0, r1, nis, gap_s, jump, rejected, init):
    """Write a point and its quality into ``out`` (``_OUT_COLS``)."""
    out[0], out[1], out[2] = px, py, pz
    out[3] = math.sqrt(vx + vy + vz)
    out[4], out[5], out[6] = math.sqrt(vx), math.sqrt(vy), math.sqrt(vz)
    out[7], out[8], out[9], out[10] = y0, y1, r0, r1
    out[11], out[12], out[13], out[14], out[15] = nis, gap_s, jump, rejected, init


@kernel
def _window_append(I, S, N, ncam, t, cam, u, v, keep):
    """Append a detection to the (re)initialisation window, keeping its ``keep`` latest."""
    wt, wf = _ICAM + 3 * ncam, _SCAM + 2 * ncam
    n = I[_IWN]
    if n == N[_NWCAP]:  # full (never while keep < capacity): the oldest goes
        for k in range(n - 1):
            I[wt + 2 * k], I[wt + 2 * k + 1] = I[wt + 2 * k + 2], I[wt + 2 * k + 3]
            S[wf + 2 * k], S[wf + 2 * k + 1] = S[wf + 2 * k + 2], S[wf + 2 * k + 3]
        n -= 1
    I[wt + 2 * n], I[wt + 2 * n + 1] = t, cam
    S[wf + 2 * n], S[wf + 2 * n + 1] = u, v
    n += 1
    if n > keep:
        drop = n - keep
        for k in range(keep):
            I[wt + 2 * k], I[wt + 2 * k + 1] = I[wt + 2 * (k + drop)], I[wt + 2 * (k + drop) + 1]
            S[wf + 2 * k], S[wf + 2 * k + 1] = S[wf + 2 * (k + drop)], S[wf + 2 * (k + drop) + 1]
        n = keep
    I[_IWN] = n


@kernel
def _window_trim(I, S, N, ncam):
    """Drop the window's detections older than its span (``_try_window``'s first loop);
    True when a fit is then worth trying: at least ``init_detections`` of two cameras or
    more (else ``_try_window`` returns None before any fit)."""
    wt, wf = _ICAM + 3 * ncam, _SCAM + 2 * ncam
    n = I[_IWN]
    drop = 0
    while drop < n and I[wt + 2 * (n - 1)] - I[wt + 2 * drop] > N[_NSPAN]:
        drop += 1
    if drop:
        for k in range(n - drop):
            I[wt + 2 * k], I[wt + 2 * k + 1] = I[wt + 2 * (k + drop)], I[wt + 2 * (k + drop) + 1]
            S[wf + 2 * k], S[wf + 2 * k + 1] = S[wf + 2 * (k + drop)], S[wf + 2 * (k + drop) + 1]
        n -= drop
        I[_IWN] = n
    if n < N[_NINITDET]:
        return False
    first = I[wt + 1]
    for k in range(1, n):
        if I[wt + 2 * k + 1] != first:
            return True
    return False


@kernel
def _withheld(I, O, std):
    """Withhold what the filter cannot vouch for (the state is updated all the same): a
    velocity jump one camera alone has seen (its component along that camera's rays is a
    guess) until another camera's detection confirms it, and any point whose standard
    deviation exceeds the bound; counted by reason. True when withheld."""
    if O[_OWITHHOLD] == 0.0:
        return False
    if I[_IPEND] >= 0:
        I[_IDROPC] += 1
        if I[_IDROPFIRST] == 0:
            I[_IDROPFIRST] = 1
        return True
    if std > O[_OMAXSTD]:
        I[_IDROPU] += 1
        if I[_IDROPFIRST] == 0:
            I[_IDROPFIRST] = 2
        return True
    return False


@kernel(inline=True)
def _ray_direction(r, px, py, pz):
    """The direction in the world (not unit) of the ray from camera row ``r`` (the
    filter's camera table) to the world point ``(px, py, pz)``: ``Rᵀ`` of the point in the
    camera's frame, ``Rᵀ (R p + t)``."""
    xc = r[0] * px + r[1] * py + r[2] * pz + r[9]
    yc = r[3] * px + r[4] * py + r[5] * pz + r[10]
    zc = r[6] * px + r[7] * py + r[8] * pz + r[11]
    return (r[0] * xc + r[3] * yc + r[6] * zc, r[1] * xc + r[4] * yc + r[7] * zc,
            r[2] * xc + r[5] * yc + r[8] * zc)


@kernel
def _unseen_jump(I, cams, O, t, cam, before, px, py, pz, vx, vy, vz):
    """The point's variances (x, y, z) with those of a velocity jump no other camera has
    seen, when camera ``cam`` goes on alone (its previous accepted detection, at ``before``
    ns, came after every other camera's): since another camera's latest accepted detection
    (``T`` s ago) only ``cam`` has fixed the point, and its pixels do not see a jump's
    component along its ray ``d`` (a kick towards the camera passes every gate). With
    jumps at a rate ``λ_j`` (a Poisson process: one in ``T`` with probability ``≈ λ_j T``)
    of ``σ_j²`` per axis at an
    instant uniform in ``T`` (``E[s²] = T²/3``), the mixture's covariance (Bar-Shalom, Li &
    Kirubarajan, "Estimation with Applications to Tracking and Navigation", 2001, eq.
    1.4.16-4: the moments of a mixture; a zero-mean jump adds no spread of the means) gains
    ``λ_j T σ_j² T² / 3 · d dᵀ``, the dominant term when one camera alone goes on. Not
    while the cameras take turns (the first detection after another camera's): the jump's
    mixture is heavy-tailed, its second moment there (T of one stagger) overstated the
    typical error (the lab rig's std_m 1.8 times its RMS error). The state is unchanged
    (the term makes the reported uncertainty honest; ``max_std_m`` then withholds the
    point)."""
    other = -(2 ** 62)
    for k in range(cams.shape[0]):
        if k != cam and I[_ICAM + k] > other:
            other = I[_ICAM + k]
    if other == -(2 ** 62) or other >= before:
        return vx, vy, vz
    dt = (t - other) / NS
    a = O[_OUNSEEN] * dt * dt * dt
    d0, d1, d2 = _ray_direction(cams[cam], px, py, pz)
    n2 = d0 * d0 + d1 * d1 + d2 * d2
    if not n2 > 0.0:
        return vx, vy, vz
    return vx + a * d0 * d0 / n2, vy + a * d1 * d1 / n2, vz + a * d2 * d2 / n2


@kernel
def _surprise_term(cams, O, cam, x, P, inn, dt, var, px, py, pz, vx, vy, vz):
    """The variance along camera ``cam``'s ray at the point ``(px, py, pz)`` of a plain
    update's doubt (session 29): the mixture of "no jump" (the update made) and "a jump of
    shape ``s`` in the ``dt`` s before this detection" (:func:`_jumped`, every shape the
    jump search tries), weighted by the detection's likelihood under each, ``N(y_s; 0,
    S_s)`` (``y_s = y − H (x_s⁻ − x⁻)``, ``S_s = H P_s⁻ Hᵀ + σ² I``: one linearisation,
    ``H`` the update's, ``σ²`` = ``var``), and the prior ``π = 1 − exp(−λ_j dt)`` (a jump
    in the step, shared equally by the shapes, as the search's choice assumes), about the
    no-jump mean (the state's and the point's): ``P* − P₀⁺ = Σ_s w_s (P_s⁺ − P₀⁺ + d_s
    d_sᵀ)``, ``d_s = x_s⁺ − x₀⁺`` (the session 27 mixture, :func:`_mixture_about`); the
    no-jump weight ``w₀ ∝ (1 − π) N(y; 0, S)``, ``w_s ∝ π/n N(y_s; 0, S_s)``, ``Σ w = 1``
    (docs/methods.md, "A plain update's doubt"). A jump's likelihood
    grows with the NIS of the no-jump update: a large NIS says the model "no jump" is in
    doubt. Published along the ray ``r̂`` alone (``r̂ᵀ (·) r̂``: across it the pixel fixes
    the point under every hypothesis). ``x``, ``P`` the pair's prediction (6, 36), ``inn``
    its innovation (:func:`_innovation`). Returns the point's variances (x, y, z) with it
    (unchanged when ``dt <= 0``)."""
    lam = O[_OSURPRISE]
    if not dt > 0.0:
        return vx, vy, vz
    prior = -math.expm1(-lam * dt)
    y0, y1, i00, i01, i11, nis, det = inn[0], inn[1], inn[2], inn[3], inn[4], inn[5], inn[6]
    c0, c1 = _INN_C0, _INN_C0 + 6
    # the ray's unit direction in the world
    d0, d1, d2 = _ray_direction(cams[cam], px, py, pz)
    n = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if not n > 0.0:
        return vx, vy, vz
    d0, d1, d2 = d0 / n, d1 / n, d2 / n
    # no jump: the update made, K₀ = PHᵀ S⁻¹ (position rows), its along-ray pieces
    rc0 = d0 * inn[c0] + d1 * inn[c0 + 1] + d2 * inn[c0 + 2]  # r̂ᵀ PHᵀ
    rc1 = d0 * inn[c1] + d1 * inn[c1 + 1] + d2 * inn[c1 + 2]
    rk0, rk1 = rc0 * i00 + rc1 * i01, rc0 * i01 + rc1 * i11  # r̂ᵀ K₀
    rP0 = -(rk0 * rc0 + rk1 * rc1)  # r̂ᵀ (P₀⁺ − P⁻) r̂
    rx0 = rk0 * y0 + rk1 * y1  # r̂ᵀ (x₀⁺ − x⁻)
    h0, h1, h2, h3, h4, h5 = inn[7], inn[8], inn[9], inn[10], inn[11], inn[12]
    # r̂ᵀ P⁻ r̂
    rPr = (d0 * (P[0] * d0 + P[1] * d1 + P[2] * d2) + d1 * (P[6] * d0 + P[7] * d1 + P[8] * d2)
           + d2 * (P[12] * d0 + P[13] * d1 + P[14] * d2))
    total = (1.0 - prior)  # the weights' sum, the no-jump likelihood's factor 1
    acc = 0.0
    ns = int(O[_ONSHAPES])
    for shape in range(ns):
        ok, xs, Ps = _jumped(x, P, dt, O, shape)
        if not ok:
            continue
        # the shape's prediction: its mean shift, H's rows applied to it, PHᵀ, S
        dx0, dx1, dx2 = xs[0] - x[0], xs[1] - x[1], xs[2] - x[2]
        e0 = y0 - (h0 * dx0 + h1 * dx1 + h2 * dx2)
        e1 = y1 - (h3 * dx0 + h4 * dx1 + h5 * dx2)
        # P_s⁻ Hᵀ (position rows; H has no velocity columns)
        ca0 = Ps[0] * h0 + Ps[1] * h1 + Ps[2] * h2
        ca1 = Ps[6] * h0 + Ps[7] * h1 + Ps[8] * h2
        ca2 = Ps[12] * h0 + Ps[13] * h1 + Ps[14] * h2
        cb0 = Ps[0] * h3 + Ps[1] * h4 + Ps[2] * h5
        cb1 = Ps[6] * h3 + Ps[7] * h4 + Ps[8] * h5
        cb2 = Ps[12] * h3 + Ps[13] * h4 + Ps[14] * h5
        t00 = h0 * ca0 + h1 * ca1 + h2 * ca2 + var
        t01 = h0 * cb0 + h1 * cb1 + h2 * cb2
        t11 = h3 * cb0 + h4 * cb1 + h5 * cb2 + var
        dj = t00 * t11 - t01 * t01
        if not dj > 0.0:
            continue
        j00, j01, j11 = t11 / dj, -t01 / dj, t00 / dj
        nis_s = e0 * (j00 * e0 + j01 * e1) + e1 * (j01 * e0 + j11 * e1)
        # likelihood ratio to no jump: exp(−(NIS_s − NIS)/2) sqrt(det S / det S_s)
        lr = math.exp(-0.5 * (nis_s - nis)) * math.sqrt(det / dj)
        ws = prior / ns * lr
        if not ws > 0.0:
            continue
        rca = d0 * ca0 + d1 * ca1 + d2 * ca2
        rcb = d0 * cb0 + d1 * cb1 + d2 * cb2
        ka, kb = rca * j00 + rcb * j01, rca * j01 + rcb * j11  # r̂ᵀ K_s
        rPs = (d0 * (Ps[0] * d0 + Ps[1] * d1 + Ps[2] * d2)
               + d1 * (Ps[6] * d0 + Ps[7] * d1 + Ps[8] * d2)
               + d2 * (Ps[12] * d0 + Ps[13] * d1 + Ps[14] * d2)
               - rPr - (ka * rca + kb * rcb))  # r̂ᵀ (P_s⁺ − P⁻) r̂
        ds = d0 * dx0 + d1 * dx1 + d2 * dx2 + ka * e0 + kb * e1 - rx0  # r̂ᵀ d_s
        acc += ws * (rPs - rP0 + ds * ds)
        total += ws
    a = acc / total
    return vx + a * d0 * d0, vy + a * d1 * d1, vz + a * d2 * d2


@kernel
def _unseen_gap_jump(O, gap_s, vx, vy, vz):
    """The variances (x, y, z) of a prediction published at a rejected detection, ``gap_s``
    seconds after the track's latest accepted one, with those of the velocity jumps (kicks,
    bounces) no detection has shown since: jumps a Poisson process of rate ``λ_j``, each
    ``Δv ~ N(0, σ_j² I)`` (the kick's shape) at an instant ``s`` in the gap, moving the ball
    by ``Δv (T − s)`` by the detection's time: a compound Poisson process, whose position
    variance per axis is ``λ_j ∫₀ᵀ σ_j² u² du = λ_j σ_j² T³ / 3`` exactly (any number of
    jumps; zero mean: no spread of the means). Any direction: the rejected pixel fixes none.
    The state is unchanged (the term makes the published uncertainty honest; ``max_std_m``
    then withholds the point: from ``T`` ≈ 26 ms with the defaults)."""
    a = O[_OUNSEEN] * gap_s * gap_s * gap_s
    return vx + a, vy + a, vz + a


@kernel
def _reject(S, I, cams, O, N, t, cam, u, v, x, P, inn_ok, inn, gap_s, out):
    """The detection failed the gate: the point is the prediction ``x``; after
    ``max_rejects`` in a row the track restarts from the window. Returns a step result."""
    ncam = cams.shape[0]
    I[_IREJ] += 1
    _window_append(I, S, N, ncam, t, cam, u, v, N[_NINITWIN])
    if I[_ICONF] < _CONFIRM:  # a start the next detections deny: no point from it
        I[_IHAS] = 0
        return _FIT if _window_trim(I, S, N, ncam) else _NONE
    if inn_ok:
        nis, y0, y1 = inn[5], inn[0], inn[1]
    else:
        nis = y0 = y1 = _NAN
    S[_SX:_SX + 6] = x
    S[_SP:_SP + 36] = P
    I[_ITIME] = t
    px, py, pz, vx, vy, vz = _combined_point(x, P, S[_SXT:_SXT + 7], S[_SPT:_SPT + 49],
                                             S[_SNU])
    if O[_ODRAG] != 0.0:  # the estimated drag (V: the prediction's, set by the caller)
        px, py, pz, vx, vy, vz = _drag_point(S, px, py, pz, vx, vy, vz)
    if O[_OUNSEEN] != 0.0:  # the prediction's published covariance: a jump in the gap
        vx, vy, vz = _unseen_gap_jump(O, gap_s, vx, vy, vz)
    _point(out, px, py, pz, vx, vy, vz, y0, y1, y0, y1, nis, gap_s, 0.0, 1.0, 0.0)
    if I[_IREJ] >= N[_NMAXREJ]:  # lost: restart from the window
        I[_IHAS] = 0
        if _window_trim(I, S, N, ncam):
            return _FIT_OR_POINT
    return _POINT


@kernel
def _push(S, I, cams, O, N, t, cam, u, v, out):
    """One detection (true time ``t`` ns, camera index, distorted pixel) into the state:
    ``BallFilter._push`` of the pure-Python filter, statement for statement. Returns a step
    result (``_NONE``, ``_POINT`` with the point in ``out``, ``_FIT``/``_FIT_OR_POINT``: the
    window must be fitted in Python)."""
    ncam = cams.shape[0]
    far = cams[cam, 23]
    if not (abs(u) <= far and abs(v) <= far):  # also NaN: no detection
        return _NONE
    clast = _ICAM
    maxgap = N[_NMAXGAP]
    if I[_IHAS]:
        other = -(2 ** 62)  # the latest accepted detection of another camera
        for k in range(ncam):
            if k != cam and I[clast + k] > other:
                other = I[clast + k]
        if (t - I[_ILAST] > maxgap or t - other > maxgap
                or (cam == I[_IJUMPCAM] and other < I[_IJUMPNS])):
            # nothing bridges so long a time, and one camera alone cannot hold the depth
            # (no other camera's detection within the gap, or since a jump it alone saw):
            # the track is lost
            I[_IHAS] = 0
    if not I[_IHAS]:  # (re)initialisation from the window
        wt = _ICAM + 3 * ncam
        n = I[_IWN]
        if n and t - I[wt + 2 * (n - 1)] > maxgap:
            I[_IWN] = 0
        _window_append(I, S, N, ncam, t, cam, u, v, I[_ICAP])
        return _FIT if _window_trim(I, S, N, ncam) else _NONE
    dt = (t - I[_ITIME]) / NS
    gap_s = (t - I[_ILAST]) / NS
    mu0 = S[_SMU]
    p = _pmin(O[_OSWITCH] * abs(dt), 0.5)
    c = mu0 * (1.0 - p) + (1.0 - mu0) * p
    xg = S[_SX:_SX + 6]
    Pg = S[_SP:_SP + 36]
    nu = S[_SNU]
    q_walk = _q_walk(S, O)
    if nu == 1.0 and q_walk >= O[_OTON]:
        # an acceleration the turn model lacks (q grew): the pair rejoins at its state
        nu = 1.0 - _TURN_START
        S[_SMU] = O[_OMU0]
        S[_SE:_SE + 6] = 0.0
        I[_IAGE] = 0
    elif not nu and O[_OTURN] != 0.0 and (q_walk >= O[_OTON] or not I[_ICONF]):
        # at a track's start, or an acceleration the pair lacks (q grew): the turn model
        # joins at the pair's state, its turn rate unknown (0 ± turn_rate_std)
        nu = _TURN_START
        xs, Ps = _turn_start(xg, Pg, 0.0, O[_OTVAR])
        S[_SXT:_SXT + 7] = xs
        S[_SPT:_SPT + 49] = Ps
        I[_IAGE] = 0
    solo = nu == 1.0  # the turn model alone (the pair left the model set)
    mu = S[_SMU]
    e = S[_SE:_SE + 6].copy()
    var, gate, q = S[_SVAR], O[_OGATE], S[_SQ]
    jump = 0.0
    accepted = False
    xt = S[_SXT:_SXT + 7]
    Pt = S[_SPT:_SPT + 49]
    prior_y0 = prior_y1 = 0.0
    inn_t = np.empty(0)
    bounced = False
    if solo:
        xt, Pt = _turn_predicted(xt, Pt, dt, q, O[_OTPSD])
        x, P = xt[:6], _block6(Pt)
        inn_ok, inn = _innovation(cams, cam, xt, Pt, 7, u, v, var)
        inn_t = inn
        if inn_ok:
            prior_y0, prior_y1 = inn[0], inn[1]
            accepted = inn[5] <= gate
    else:
        if nu:
            nu, xg, Pg, xt, Pt = _turn_mixed(nu, xg, Pg, xt, Pt, dt, O[_OTSWITCH])
            xt, Pt = _turn_predicted(xt, Pt, dt, q, O[_OTPSD])
        contact = _contact(xg, dt, c, O)
        x, P = _predicted_at(xg, Pg, dt, c, O, q, contact)
        inn_ok, inn = _innovation(cams, cam, x, P, 6, u, v, var)
        if contact >= 0.0:
            # a predicted floor contact (session 31): the models start together after it,
            # as after a jump (the difference e, gravity's since the contact alone; the
            # drag's sensitivity V anew)
            bounced = True
            S[_SE:_SE + 6] = 0.0
            e[:] = 0.0
            S[_SV:_SV + 6] = 0.0
    # the drag estimated (session 29) while the pair alone is in the set: V⁻ at the prior
    drag = O[_ODRAG] != 0.0 and not nu
    Vm = _drag_predicted(S[_SV:_SV + 6], x, dt, c) if drag else np.zeros(6)
    if inn_ok and not solo:
        # the mixture's innovation (the process noise's whiteness statistic)
        prior_y0, prior_y1 = inn[0], inn[1]
        if O[_OSWITCH] != 0.0:
            x, inn, mu, e, nis_b, nis_s = _mixed(x, inn, c, p, dt, S[_SMU], S[_SE:_SE + 6], O)
            nis_min = _pmin(nis_b, nis_s)
        else:
            nis_b = nis_s = nis_min = inn[5]
        if nu:
            ok_t, inn_t = _innovation(cams, cam, xt, Pt, 7, u, v, var)
            if not ok_t:  # the turn model's point is behind the camera: it leaves
                nu = 0.0
            else:
                S[_SNUPOST] = _turn_probability(nu, c, nis_b, nis_s, inn[6], inn_t[5],
                                                inn_t[6])
                nis_min = _pmin(nis_min, inn_t[5])
                prior_y0 += nu * (inn_t[0] - prior_y0)
                prior_y1 += nu * (inn_t[1] - prior_y1)
        accepted = nis_min <= gate
    nu_post = nu
    if accepted and solo:
        xt, Pt = _iterated(cams, cam, xt, Pt, inn, u, v, var, O)
        xn, Pn, nis = xt[:6], _block6(Pt), inn[5]
        sy0, sy1, s00, s01, s11 = inn[0], inn[1], inn[2], inn[3], inn[4]
        xo0, xo1, xo2 = xt[0], xt[1], xt[2]
        v0, v1, v2 = Pt[0], Pt[8], Pt[16]
    elif accepted:
        xn, Pn = _iterated(cams, cam, x, P, inn, u, v, var, O)
        nis = inn[5]
        sy0, sy1, s00, s01, s11 = inn[0], inn[1], inn[2], inn[3], inn[4]
        if nu:
            nu_post = S[_SNUPOST]
            xt, Pt = _iterated(cams, cam, xt, Pt, inn_t, u, v, var, O)
            # the mixture's innovation and S⁻¹ (the models' weighted by ν⁺); for the noise
            # update an approximation: the mixture's posterior residual is σ² Σ ν_j S_j⁻¹ y_j
            # plus the spread of the models' means, equal to this when one model holds
            # the weight (ν⁺ near 0 or 1, most of the time)
            y0 = inn[0] + nu_post * (inn_t[0] - inn[0])
            y1 = inn[1] + nu_post * (inn_t[1] - inn[1])
            i00 = inn[2] + nu_post * (inn_t[2] - inn[2])
            i01 = inn[3] + nu_post * (inn_t[3] - inn[3])
            i11 = inn[4] + nu_post * (inn_t[4] - inn[4])
            nis = y0 * (i00 * y0 + i01 * y1) + y1 * (i01 * y0 + i11 * y1)
            sy0, sy1, s00, s01, s11 = y0, y1, i00, i01, i11
            xo0, xo1, xo2, v0, v1, v2 = _combined_point(xn, Pn, xt, Pt, nu_post)
        else:
            xo0, xo1, xo2, v0, v1, v2 = xn[0], xn[1], xn[2], Pn[0], Pn[7], Pn[14]
    else:
        sy0 = sy1 = s00 = s01 = s11 = 0.0  # (a jump: σ² is not adapted)
        S[_SNU] = nu  # the turn model's state is its prediction (as the pair's)
        if nu:
            S[_SXT:_SXT + 7] = xt
            S[_SPT:_SPT + 49] = Pt
        found = False
        if inn_ok:
            found, xn, Pn, inn_j = _jump(S, I, cams, O, t, cam, u, v)
        if not found:  # rejected: the point is the prediction
            S[_SV:_SV + 6] = Vm
            return _reject(S, I, cams, O, N, t, cam, u, v, x, P, inn_ok, inn, gap_s, out)
        if O[_OCHAIN] != 0.0 and I[_IPEND] >= 0 and I[_ICHAIN] >= 2:
            # a third jump before the first is confirmed: one camera's jump fixes the
            # velocity only across its ray, a second (another camera's) may fix the rest,
            # but jumps that keep following each other say the motion model fails (a turn,
            # an acceleration the pair lacks), not that the ball is kicked every frame; and
            # each jump forgets the innovations q's whiteness statistic compares, so q could
            # never rise. The track restarts from its window, each model fitted (session
            # 36), the turn model at the start's prior (0 ± turn_rate_std: the lost set's
            # turn rate is what the jumps kept from being learned)
            I[_IHAS] = 0
            S[_SNU] = 0.0
            # the window starts at the previous jump's detection: what came before it is
            # another segment (a kick the second jump corrects: a fit across it is wrong)
            wt, wf = _ICAM + 3 * ncam, _SCAM + 2 * ncam
            n = I[_IWN]
            drop = 0
            while drop < n and I[wt + 2 * drop] < I[_IJUMPNS]:
                drop += 1
            for k in range(n - drop):
                j = k + drop
                I[wt + 2 * k], I[wt + 2 * k + 1] = I[wt + 2 * j], I[wt + 2 * j + 1]
                S[wf + 2 * k], S[wf + 2 * k + 1] = S[wf + 2 * j], S[wf + 2 * j + 1]
            I[_IWN] = n - drop
            _window_append(I, S, N, ncam, t, cam, u, v, N[_NINITWIN])
            return _FIT if _window_trim(I, S, N, ncam) else _NONE
        inn = inn_j
        xo0, xo1, xo2, v0, v1, v2, nis = xn[0], xn[1], xn[2], Pn[0], Pn[7], Pn[14], inn[5]
        jump = 1.0
        if nu:  # the turn model restarts at the jump's state, keeping its turn rate;
            # the pair is back in the set (a new segment, its motion unknown)
            xt, Pt = _turn_start(xn, Pn, xt[6], Pt[48])
            nu_post = _pmin(_pmax(nu, _TURN_START), 1.0 - _TURN_START)
            if solo:
                S[_SMU] = mu = O[_OMU0]
    ok, pu, pv, _, _, _, _, _, _ = _project(cams, cam, xo0, xo1, xo2)
    if not ok:  # never a point behind the camera that made it
        S[_SNU] = nu
        if nu:
            S[_SXT:_SXT + 7] = xt
            S[_SPT:_SPT + 49] = Pt
        S[_SV:_SV + 6] = Vm
        return _reject(S, I, cams, O, N, t, cam, u, v, x, P, inn_ok, inn, gap_s, out)
    if accepted and drag:  # δk̂ from this update (the prior innovation, before the mixing)
        _drag_forget(S, I, O, t)
        _drag_update(S, inn, prior_y0, prior_y1, Vm)
        c0, c1, c2, w0, w1, w2 = _drag_point(S, xo0, xo1, xo2, v0, v1, v2)
        ok, qu, qv, _, _, _, _, _, _ = _project(cams, cam, c0, c1, c2)
        if ok:  # (the point moved by millimetres: never behind the camera in practice)
            xo0, xo1, xo2, v0, v1, v2, pu, pv = c0, c1, c2, w0, w1, w2, qu, qv
    else:  # a jump, or the turn model in the set: a new segment (δk̂ is kept)
        S[_SV:_SV + 6] = 0.0
    if I[_IJN] > 0 and O[_OINSTANT] != 0.0:  # the latest jump's instant (published)
        k = I[_IJN]
        if accepted and k < _JBUF:
            I[_IJBUF + 2 * k], I[_IJBUF + 2 * k + 1] = t, cam
            S[_SJUV + 2 * k], S[_SJUV + 2 * k + 1] = u, v
            S[_SJF + 3 * k], S[_SJF + 3 * k + 1], S[_SJF + 3 * k + 2] = c, q, var
            I[_IJN] = k + 1
        elif accepted:
            I[_IJN] = 0
        I[_IJTE] = -(2 ** 62)  # (this point's term not published yet: no earlier one's kept)
        if I[_IJN] > 0:
            ok, ep, w = _instant_term(S, I, cams, O, t, xn)
            if ok:
                v0, v1, v2 = v0 + w * ep[0] * ep[0], v1 + w * ep[1] * ep[1], v2 + w * ep[2] * ep[2]
                S[_SJE:_SJE + 3] = ep
                S[_SJE + 3] = w
                I[_IJTE] = t
    cinn_t, cinn_has = _ICAM + ncam, _ICAM + 2 * ncam
    if accepted:
        h = I[_IHN]
        if h == _HISTORY:  # the oldest goes
            for k in range(h - 1):
                I[_IHT + 3 * k:_IHT + 3 * k + 3] = I[_IHT + 3 * k + 3:_IHT + 3 * k + 6]
                S[_SHX + 6 * k:_SHX + 6 * k + 6] = S[_SHX + 6 * k + 6:_SHX + 6 * k + 12]
                S[_SHP + 36 * k:_SHP + 36 * k + 36] = S[_SHP + 36 * k + 36:_SHP + 36 * k + 72]
                S[_SHUV + 2 * k:_SHUV + 2 * k + 2] = S[_SHUV + 2 * k + 2:_SHUV + 2 * k + 4]
                S[_SHSC + k] = S[_SHSC + k + 1]
            h -= 1
        I[_IHT + 3 * h], I[_IHT + 3 * h + 1], I[_IHT + 3 * h + 2] = I[_ITIME], t, cam
        S[_SHX + 6 * h:_SHX + 6 * h + 6] = S[_SX:_SX + 6]
        S[_SHP + 36 * h:_SHP + 36 * h + 36] = S[_SP:_SP + 36]
        S[_SHUV + 2 * h], S[_SHUV + 2 * h + 1] = u, v
        S[_SHSC + h] = inn[5] + math.log(inn[6])
        I[_IHN] = h + 1
        if O[_OQRATE] != 0.0:  # process noise: a consistent filter's innovations are white
            if I[cinn_has + cam] and t - I[cinn_t + cam] <= maxgap:
                # yᵀ S⁻¹ y': zero mean for a consistent filter's (white) innovations
                y0, y1 = prior_y0, prior_y1
                py0, py1 = S[_SCAM + 2 * cam], S[_SCAM + 2 * cam + 1]
                r = py0 * (inn[2] * y0 + inn[3] * y1) + py1 * (inn[3] * y0 + inn[4] * y1)
                r = _pmin(_pmax(r, -_R_CLIP), _R_CLIP)
                if O[_OQDEAD] == 0.0:  # log q a random walk reflected at the floor
                    qn = S[_SQ] * math.exp(O[_OQRATE] * (r - O[_OQTARGET]))
                    S[_SQ] = _pmin(_pmax(qn, O[_OQMIN]), O[_OQMAX])
                else:
                    # a change detector (Page's one-sided CUSUM, Basseville & Nikiforov 1993
                    # §2.2): g sums r − r₀ (reflected at 0); q leaves its floor only once g
                    # passes h, so that white innovations (E[r] = 0 < r₀) keep it there
                    g = _pmin(_pmax(S[_SQG] + (r - O[_OQTARGET]), 0.0), O[_OQGMAX])
                    S[_SQG] = g
                    qn = O[_OQMIN] * math.exp(O[_OQRATE] * _pmax(g - O[_OQDEAD], 0.0))
                    S[_SQ] = _pmin(qn, O[_OQMAX])
            I[cinn_has + cam] = 1
            I[cinn_t + cam] = t
            S[_SCAM + 2 * cam], S[_SCAM + 2 * cam + 1] = prior_y0, prior_y1
        if O[_OADAPT] != 0.0:  # pixel noise: variational Bayes (Särkkä & Nummenmaa 2009)
            _noise_update(S, O, sy0, sy1, s00, s01, s11)
        if nis > O[_OCONFNIS] or bounced:
            # a surprising update, or the first after a predicted floor contact (a kick at
            # the contact is as likely as a jump: one camera's pixel does not tell it from
            # the bounce): confirmed like a jump
            I[_IPEND], I[_ICONFS], I[_IOTHER] = cam, 0, 0
        elif I[_IPEND] >= 0:
            I[_ICONFS] += 1
            if cam != I[_IPEND]:
                I[_IOTHER] = 1
            if I[_ICONFS] >= _CONFIRM_UPDATES and I[_IOTHER]:
                I[_IPEND] = -1
                I[_ICHAIN] = 0
        if nu_post:
            # the model set adapts (variable-structure IMM): the turn model leaves when it
            # is unlikely, or its turn rate is not told from 0 (the supported model), once
            # its turn rate has settled and unless q says an acceleration is missing
            I[_IAGE] += 1
            w = xt[6]
            if I[_IAGE] >= _TURN_MIN_UPDATES and _q_walk(S, O) < O[_OTON]:
                if nu_post < _TURN_OFF or w * w < _TURN_SIGNIFICANT ** 2 * Pt[48]:
                    nu_post = 0.0
                elif nu_post > 1.0 - _TURN_OFF and not solo:
                    # the pair is unlikely: it leaves, the turn model goes on alone
                    nu_post = 1.0
                    xn, Pn = xt[:6], _block6(Pt)
    else:
        I[_IJUMPNS], I[_IJUMPCAM] = t, cam
        I[_ICHAIN] += 1
        for k in range(ncam):  # a new segment
            I[cinn_has + k] = 0
        I[_IPEND], I[_ICONFS], I[_IOTHER] = cam, 0, 0
    if accepted:
        S[_SMU] = mu
        S[_SE:_SE + 6] = e
    else:
        S[_SE:_SE + 6] = 0.0  # a jump: a new segment, the models start together
    S[_SNU] = nu_post
    if nu_post:
        S[_SXT:_SXT + 7] = xt
        S[_SPT:_SPT + 49] = Pt
    S[_SX:_SX + 6] = xn
    S[_SP:_SP + 36] = Pn
    I[_ITIME] = I[_ILAST] = t
    I[_IREJ] = 0
    I[_ICONF] += 1
    before = I[clast + cam]  # this camera's previous accepted detection
    I[clast + cam] = t
    _window_append(I, S, N, ncam, t, cam, u, v, N[_NINITWIN])
    if O[_OUNSEEN] != 0.0:
        v0, v1, v2 = _unseen_jump(I, cams, O, t, cam, before, xo0, xo1, xo2, v0, v1, v2)
    if O[_OSURPRISE] != 0.0 and accepted and not solo:  # a plain update's doubt (session 29)
        v0, v1, v2 = _surprise_term(cams, O, cam, x, P, inn, dt, var, xo0, xo1, xo2, v0, v1,
                                    v2)
    _point(out, xo0, xo1, xo2, v0, v1, v2, inn[0], inn[1], u - pu, v - pv, nis, gap_s, jump,
           0.0, 0.0)
    return _POINT


#: :func:`_lengths` may take the lengths where this interpreter's ``math.hypot`` is the one
#: :func:`_py_hypot` repeats (CPython 3.11's; 3.12 changed its arithmetic), else
#: ``math.hypot`` itself takes them; :func:`_hypot_compiled` also checks the bits
_HYPOT_COMPILED = sys.implementation.name == "cpython" and sys.version_info[:2] == (3, 11)


@functools.cache
def _hypot_compiled() -> bool:
    """Whether :func:`_lengths` gives ``math.hypot``'s bits here: CPython 3.11, and the
    compiled kernel agrees on probe pairs (random magnitudes over 2**±60, zeros, signed
    zeros, subnormals, inf/NaN, huge ratios) — a compiler or CPU that fused the kernel's
    products into multiply-adds, or a CPython built so, would differ: ``math.hypot`` then."""
    if not _HYPOT_COMPILED:
        return False
    rng = np.random.default_rng(311)
    pairs = rng.standard_normal((512, 4)) * np.exp2(rng.integers(-60, 61, (512, 4)))
    pairs[:6] = [[0.0, 0.0, 3.0, 4.0], [math.inf, math.nan, math.nan, -math.inf],
                 [5e-324, 1e-310, 1e308, 1e308], [-0.0, 1.0, 2.0 ** -1030, 2.0 ** -1074],
                 [1e300, 1e-300, 1.0, 1e-17], [0.1, 0.2, 0.3, 0.7]]
    rows = np.zeros((len(pairs), _OUT_COLS))
    rows[:, 7:11] = pairs
    q = np.zeros((len(FILTER_QUALITY), len(pairs)))
    _lengths(rows, q)
    want = np.array([[math.hypot(a, b) for a, b in pairs[:, :2].tolist()],
                     [math.hypot(a, b) for a, b in pairs[:, 2:].tolist()]])
    return bool(np.array_equal(q[4:6].view(np.int64), want.view(np.int64)))
#: Veltkamp's splitting constant, 2**27 + 1: ``x * _SPLIT`` splits a double into two halves
#: of 26 bits whose products are exact
_SPLIT = 134217729.0


@kernel(inline=True)
def _py_hypot(x, y):
    """CPython 3.11's ``math.hypot(x, y)``, bit for bit (``vector_norm`` of
    Modules/mathmodule.c for two coordinates): the squares summed without loss (each
    coordinate scaled by a power of two below 1, split in halves whose products are exact,
    the sums' rounding errors kept in three registers), a square root, then one Newton step
    taken in the same arithmetic; coordinates whose larger one is below 2**-1024 are
    divided by it instead. Inf wins over NaN, as in CPython. (tests/test_filter_lengths.py
    compares it with ``math.hypot`` on random and edge inputs.)"""
    a, b = abs(x), abs(y)
    big = a if a > b else b  # (NaN never taken: inf wins over it below)
    if math.isinf(a) or math.isinf(b):
        return math.inf
    if math.isnan(a) or math.isnan(b):
        return math.nan
    if big == 0.0:
        return big
    e = math.frexp(big)[1]
    if e < -1023:  # 2**e would overflow: CPython divides by the larger instead
        total, low = 1.0, 0.0
        for c in (a, b):
            q = c / big
            q = q * q
            was = total
            total += q
            low += (was - total) + q
        return big * math.sqrt(total - 1.0 + low)
    scale = math.ldexp(1.0, -e)
    total, low1, low2, low3 = 1.0, 0.0, 0.0, 0.0
    for c in (a, b):
        q = c * scale  # (exact: a power of two)
        t = q * _SPLIT
        hi = t - (t - q)
        lo = q - hi
        q = hi * hi
        was = total
        total += q
        low1 += (was - total) + q
        q = 2.0 * hi * lo
        was = total
        total += q
        low2 += (was - total) + q
        low3 += lo * lo
    h = math.sqrt(total - 1.0 + (low1 + low2 + low3))
    t = h * _SPLIT
    hi = t - (t - h)
    lo = h - hi
    q = -hi * hi
    was = total
    total += q
    low1 += (was - total) + q
    q = -2.0 * hi * lo
    was = total
    total += q
    low2 += (was - total) + q
    q = -lo * lo
    was = total
    total += q
    low3 += (was - total) + q
    q = total - 1.0 + (low1 + low2 + low3)
    return (h + q / (2.0 * h)) / scale


@kernel
def _lengths(rows, q):
    """The filter's length columns of its output ``rows`` (n, _OUT_COLS) into ``q``
    (FILTER_QUALITY rows, n): ``innovation_px`` the innovation's and ``residual_px`` the
    residual's length, by :func:`_py_hypot` (CPython's ``math.hypot``, as the pure-Python
    filter took them), a start's residual as its fit gave it."""
    for i in range(rows.shape[0]):
        q[4, i] = _py_hypot(rows[i, 7], rows[i, 8])
        q[5, i] = rows[i, 9] if rows[i, 15] == 1.0 else _py_hypot(rows[i, 9], rows[i, 10])


@kernel
def _kept_columns(rows, index, times, cameras, q, position, time, camera):
    """:func:`_rows_track`'s columns of the rows a batch's end keeps, in one pass (session
    44: :meth:`_Hold.settle`'s copies of the kept rows, times and cameras, then the columns
    made from them, were two passes over ~130 bytes a point of fresh memory): for each row
    ``i`` of ``rows`` (n, _OUT_COLS) whose ``index[i]`` is not negative (withdrawn), in order,
    its detection's ``times`` and ``cameras`` at ``index[i]``, its position into ``position``
    (k, 3), its quality into ``q`` (FILTER_QUALITY rows, k; the lengths as :func:`_lengths`
    takes them) and its time and camera into ``time``, ``camera`` (k,). Returns k."""
    j = 0
    for i in range(rows.shape[0]):
        src = index[i]
        if src < 0:
            continue
        position[j, 0], position[j, 1], position[j, 2] = rows[i, 0], rows[i, 1], rows[i, 2]
        q[0, j], q[1, j], q[2, j], q[3, j] = rows[i, 3], rows[i, 4], rows[i, 5], rows[i, 6]
        q[4, j] = _py_hypot(rows[i, 7], rows[i, 8])
        q[5, j] = rows[i, 9] if rows[i, 15] == 1.0 else _py_hypot(rows[i, 9], rows[i, 10])
        for c in range(5):
            q[6 + c, j] = rows[i, 11 + c]
        time[j] = times[src]
        camera[j] = cameras[src]
        j += 1
    return j


@kernel
def _step(S, I, cams, O, N, t, cam, u, v, out):
    """:func:`_push`, then withhold the point (``_POINT`` becomes ``_NONE``) as
    ``BallFilter.push`` does; ``_FIT``/``_FIT_OR_POINT`` are left to Python."""
    status = _push(S, I, cams, O, N, t, cam, u, v, out)
    if status == _POINT and _withheld(I, O, out[3]):
        return _NONE
    return status


@kernel
def _held(S, I, O, out, cam, pr, pc, pb, pn, index):
    """The held points (rows ``pr[:pn]``, cameras ``pc``, accepted detections of
    their own camera since ``pb``) against the point of camera ``cam`` just made (``out``):
    the first point of another camera releases a held one, or withdraws it (its ``index``
    made negative, ``-1 - index``) when it made a jump placed before the held detection (the
    winner's lag reaches back to it; every jump when the lag is not kept), or a jump whose
    hypotheses placing it before the held detection carry a posterior probability of at
    least ``O[_OHOLDP]`` (``hold_jump_p``, session 31: the held camera's pixel does not see
    a kick along its ray, so the winner's lag may be the wrong one), or was rejected. A held
    start's and a held rejected detection's ``pb`` begins at ``_START_PB`` (-1): a jump
    reaching back to the start's detection, or anywhere since the accepted detection
    before the rejected one, withdraws it.
    Returns the number still held (compacted in place)."""
    jump, rejected = out[13] == 1.0, out[14] == 1.0
    lag = I[_IJLAG] if O[_OINSTANT] != 0.0 else _JBUF
    m = 0
    for k in range(pn):
        if pc[k] != cam:
            before = 0.0
            if jump:
                for j in range(pb[k] + 1, _HISTORY):
                    before += S[_SJLW + j]
            if rejected or (jump and (lag >= pb[k] + 1 or before >= O[_OHOLDP])):
                index[pr[k]] = -1 - index[pr[k]]
            continue
        if not rejected:
            pb[k] += 1
        pr[m], pc[m], pb[m] = pr[k], pc[k], pb[k]
        m += 1
    return m


@kernel
def _to_hold(O, out, pn):
    """Whether the output point ``out`` waits for the next camera (``hold_nis``), while
    fewer than ``_HOLD_MAX`` points are held (``pn``): a plain update's (no jump, not
    rejected, no start) whose NIS exceeds ``O[_OHOLD]`` or whose gap exceeds
    ``O[_OHOLDGAP]`` (``hold_gap``), and a rejected detection's (the prediction;
    ``hold_rejected``). (A start's is held in Python: ``hold_start``.)"""
    if out[13] != 0.0 or out[15] != 0.0 or pn >= _HOLD_MAX or O[_OHOLD] == math.inf:
        return False
    if out[14] != 0.0:
        return O[_OHOLDREJ] != 0.0
    return out[11] > O[_OHOLD] or out[12] > O[_OHOLDGAP]


@kernel(inline=True)
def _held_count(out):
    """A held point's first count of its camera's accepted detections since it (``pb``,
    :func:`_held`): 0, or ``_START_PB`` (-1) for a rejected detection's (the prediction), which
    is not in the jump's buffer: a jump the next camera's detection places anywhere after
    the latest accepted detection before it (``lag >= 0``: every lag's probability) may lie
    before the held instant, and withdraws it (as a held start's, set in Python)."""
    return _START_PB if out[14] == 1.0 else 0


@kernel
def _push_held(S, I, cams, O, N, t, cam, u, v, out, pr, pc, pb, pn, index):
    """:func:`_push` of one detection with the hold's ``pn`` points waiting (rows ``pr``,
    cameras ``pc``, accepted detections of their camera since ``pb``): a point decides them
    (:func:`_held`), a window fit (the track lost) withdraws them all (``index`` ``-1 -
    index``). Returns ``(status, points still held)``; the batch's loop and the stream's
    one-detection step alike."""
    status = _push(S, I, cams, O, N, t, cam, u, v, out)
    if pn and status == _POINT:
        pn = _held(S, I, O, out, cam, pr, pc, pb, pn, index)
    elif pn and status != _NONE:  # a window fit: the track was lost
        for k in range(pn):
            index[pr[k]] = -1 - index[pr[k]]
        pn = 0
    return status, pn


@kernel
def _run(S, I, cams, O, N, times, cameras, uv, start, rows, index, n_out, pr, pc, pb, pn):
    """The batch loop: detections ``start:`` into the state, the points into ``rows`` (one
    row per point) and their detection's index into ``index``, from row ``n_out``; with
    ``hold_nis`` a held point later withdrawn keeps its row, its index ``-1 - index``
    (:func:`_held`; the points held at a window fit — the track lost — are withdrawn).
    The points still held, ``pn`` of them (rows ``pr``, cameras ``pc``, accepted
    detections of their camera since ``pb``: ``_HOLD_MAX`` each), are the caller's, kept
    across calls (:class:`_Hold`): the end of the detections decides nothing.
    Returns ``(next detection, rows filled, status, points held)``: status ``_NONE`` at the
    end, else a window fit is needed for detection ``next`` (Python), which continues after
    it."""
    out = np.empty(_OUT_COLS)
    for i in range(start, times.shape[0]):
        cam = cameras[i]
        status, pn = _push_held(S, I, cams, O, N, times[i], cam, uv[i, 0], uv[i, 1], out,
                                pr, pc, pb, pn, index)
        if status == _POINT and _withheld(I, O, out[3]):  # as _step
            status = _NONE
        if status == _POINT:
            rows[n_out] = out
            index[n_out] = i
            if _to_hold(O, out, pn):
                pr[pn], pc[pn], pb[pn] = n_out, cam, _held_count(out)
                pn += 1
            n_out += 1
        elif status != _NONE:  # (a fit: pn is 0, every held point withdrawn above)
            rows[n_out] = out
            return i, n_out, status, pn
    return times.shape[0], n_out, _NONE, pn


@kernel
def _step_held(S, I, cams, O, N, t, cam, u, v, out, P, R, T):
    """:func:`_run`'s step for one detection (``t``, ``cam``, ``u``, ``v``: the stream's
    one-detection path with ``hold_nis``), with the points waiting from earlier pushes
    (``H`` = [held, waiting, leaving, withdrawn]: the held ones ``pr``, ``pc``, ``pb``
    (:func:`_held`) among the ``H[1]`` waiting rows ``rows``, ``time``, ``camera``): the
    held ones decided by this detection's point, the point (unless withheld) waiting
    behind them or held too, and the rows no held one precedes any more, the withdrawn
    left out (counted in ``H[3]``), moved to ``emit``, ``etime``, ``ecam`` (``H[2]`` of
    them); ``index`` (capacity) is scratch. The arrays hold one row more than waits.
    Returns ``(status, leaving, withdrawn, waiting, own)``, ``own`` True when the one row
    leaving is this detection's point; on a window fit (``_FIT``, ``_FIT_OR_POINT``) only
    the held points are decided (withdrawn: the track lost), their rows' ``index`` negative, and
    Python goes on (:meth:`FilterStream._held_fit`). The arrays are packed in three (the
    fewer a compiled call's arguments, the cheaper the call): ``P`` = (H, pr, pc, pb),
    ``R`` = (rows, emit), ``T`` = (time, camera, index, etime, ecam) (:class:`_Hold`)."""
    M = _HOLD_MAX
    H, pr, pc, pb = P[0:4], P[4:4 + M], P[4 + M:4 + 2 * M], P[4 + 2 * M:4 + 3 * M]
    rows, emit = R[0], R[1]
    time, camera, index, etime, ecam = T[0], T[1], T[2], T[3], T[4]
    pn, k = H[0], H[1]
    for j in range(k):
        index[j] = j
    status, pn = _push_held(S, I, cams, O, N, t, cam, u, v, out, pr, pc, pb, pn, index)
    H[0] = pn
    if status != _POINT and status != _NONE:
        return status, 0, 0, k, False
    if status == _POINT and _withheld(I, O, out[3]):
        status = _NONE
    if status == _POINT:
        rows[k] = out
        time[k], camera[k], index[k] = t, cam, k
        if _to_hold(O, out, pn):
            pr[pn], pc[pn], pb[pn] = k, cam, _held_count(out)
            pn += 1
        k += 1
    first = k
    for j in range(pn):
        first = min(first, pr[j])
    n_emit = n_gone = 0
    for j in range(first):
        if index[j] < 0:
            n_gone += 1
        else:
            emit[n_emit] = rows[j]
            etime[n_emit], ecam[n_emit] = time[j], camera[j]
            n_emit += 1
    m = 0
    for j in range(first, k):
        if index[j] < 0:
            n_gone += 1
            continue
        for h in range(pn):
            if pr[h] == j:
                pr[h] = m
        if m != j:
            rows[m] = rows[j]
            time[m], camera[m] = time[j], camera[j]
        m += 1
    H[0], H[1], H[2], H[3] = pn, m, n_emit, n_gone
    # (one point leaving, this detection's own: the caller takes it from ``out``)
    own = n_emit == 1 and status == _POINT and first == k and m == 0
    return status, n_emit, n_gone, m, own


# ---- the start's window fit (compiled: a start attempt runs it up to 2 x 5 times) -------------
#: :func:`_window_fit`'s results: not trustworthy, too short (the velocity's uncertainty
#: alone fails), a fit, too weak (the residuals pass, the position's uncertainty fails)
_WFIT_NONE, _WFIT_SHORT, _WFIT_OK, _WFIT_WEAK = 0, 1, 2, 3


@kernel
def _dot3(a0, a1, a2, b0, b1, b2):
    """``a · b`` of two 3-vectors summed as numpy's ``einsum("ij,ij->i")`` summed a row of
    three in the fit this replaced (two SIMD lanes: ``(a0 b0 + a2 b2) + a1 b1``), so that the
    start is the same bit for bit."""
    return (a0 * b0 + a2 * b2) + a1 * b1


@kernel
def _pixel_rows(cams, cam, uv, tau, theta, accel, J, r):
    """:meth:`BallFilter._fit`'s pixel system into ``J`` (2n x 6) and ``r`` (2n) at the path
    ``theta`` (6) with the constant acceleration ``accel`` (3); False when a point is behind
    its camera."""
    for i in range(tau.shape[0]):
        ti = tau[i]
        h = 0.5 * (ti * ti)
        ok, pu, pv, a0, a1, a2, b0, b1, b2 = _project(
            cams, cam[i], theta[0] + ti * theta[3] + h * accel[0],
            theta[1] + ti * theta[4] + h * accel[1], theta[2] + ti * theta[5] + h * accel[2])
        if not ok:
            return False
        J[2 * i, 0], J[2 * i, 1], J[2 * i, 2] = a0, a1, a2
        J[2 * i, 3], J[2 * i, 4], J[2 * i, 5] = ti * a0, ti * a1, ti * a2
        J[2 * i + 1, 0], J[2 * i + 1, 1], J[2 * i + 1, 2] = b0, b1, b2
        J[2 * i + 1, 3], J[2 * i + 1, 4], J[2 * i + 1, 5] = ti * b0, ti * b1, ti * b2
        r[2 * i] = uv[i, 0] - pu
        r[2 * i + 1] = uv[i, 1] - pv
    return True


@kernel
def _window_fit(cams, cam, uv, tau, O, D, g, k, var, gate, chi2, max_std2, max_speed2,
                theta_out, cov_out, res_out):
    """The start's fit of a window of ``n`` detections (camera ``cam`` (n,), distorted
    pixel ``uv`` (n, 2), time ``tau`` (n,) s before the newest, viewing ray origin ``O`` and
    unit direction ``D`` (n, 3)) on the path ``p0 + v0 τ + a τ²/2`` with ``a = g - k‖v‖v``
    (``g`` (3), m/s²; ``k`` 1/m): the linear start on the rays (unit weights, then
    ``1/depth`` with the drag at the first pass's speed), three Gauss-Newton steps in
    pixels, and the start's tests at pixel variance ``var`` (px²): every residual within
    ``gate`` (χ²₂), their sum within ``chi2`` (χ² of ``2n - 6``), a well-conditioned normal
    matrix, ``trace P_pp <= max_std2`` (m²) and ``trace P_vv <= max_speed2`` ((m/s)²).
    Writes ``θ = (p0, v0)`` into ``theta_out`` (6), ``P = var (JᵀJ)⁻¹`` into ``cov_out``
    (6 x 6) and the pixel residuals' lengths into ``res_out`` (n). Returns ``_WFIT_OK``,
    ``_WFIT_SHORT`` (every test passed but the velocity's) or ``_WFIT_NONE``.

    The operations are numpy's in :meth:`BallFilter._fit`'s former form, in the same order
    (the same LAPACK least squares, ``einsum``'s and ``norm``'s sums as written below), so the
    fit is the same bit for bit (``tests/test_filter_start.py``)."""
    n = tau.shape[0]
    m = 2 * n
    for i in range(n):
        if not (np.isfinite(D[i, 0]) and np.isfinite(D[i, 1]) and np.isfinite(D[i, 2])):
            return _WFIT_NONE
    # two unit vectors normal to each ray: E (2n x 3), the offsets' directions
    E = np.empty((m, 3))
    for i in range(n):
        d0, d1, d2 = D[i, 0], D[i, 1], D[i, 2]
        if abs(d0) < 0.9:
            h0, h1, h2 = 1.0, 0.0, 0.0
        else:
            h0, h1, h2 = 0.0, 1.0, 0.0
        c0 = d1 * h2 - d2 * h1
        c1 = d2 * h0 - d0 * h2
        c2 = d0 * h1 - d1 * h0
        nrm = math.sqrt(c0 * c0 + (c1 * c1 + c2 * c2))  # numpy's reduce: a0 + (a1 + a2)
        c0, c1, c2 = c0 / nrm, c1 / nrm, c2 / nrm
        E[i, 0], E[i, 1], E[i, 2] = c0, c1, c2
        E[n + i, 0] = d1 * c2 - d2 * c1
        E[n + i, 1] = d2 * c0 - d0 * c2
        E[n + i, 2] = d0 * c1 - d1 * c0
    a0, a1, a2 = g[0], g[1], g[2]
    w = np.ones(m)
    A = np.empty((m, 6))
    b = np.empty(m)
    theta = np.empty(6)
    rcond = np.finfo(np.float64).eps * m  # numpy's rcond=None
    for _ in range(2):
        for j in range(m):
            i = j - n if j >= n else j
            t = tau[i]
            e0, e1, e2 = E[j, 0], E[j, 1], E[j, 2]
            wj = w[j]
            A[j, 0], A[j, 1], A[j, 2] = wj * e0, wj * e1, wj * e2
            A[j, 3], A[j, 4], A[j, 5] = wj * (t * e0), wj * (t * e1), wj * (t * e2)
            h = 0.5 * (t * t)
            b[j] = wj * _dot3(e0, e1, e2, O[i, 0] - h * a0, O[i, 1] - h * a1,
                              O[i, 2] - h * a2)
        theta, _, rank, sv = np.linalg.lstsq(A, b, rcond)
        if rank < 6 or sv[5] < 1e-10 * sv[0]:
            return _WFIT_NONE
        for i in range(n):
            t = tau[i]
            depth = _dot3(theta[0] + t * theta[3] - O[i, 0], theta[1] + t * theta[4] - O[i, 1],
                          theta[2] + t * theta[5] - O[i, 2], D[i, 0], D[i, 1], D[i, 2])
            if not depth > _MIN_DEPTH_M:
                return _WFIT_NONE
            w[i] = w[n + i] = 1.0 / depth
        vel = theta[3:].copy()
        kv = k * math.sqrt(np.dot(vel, vel))
        a0, a1, a2 = g[0] - kv * vel[0], g[1] - kv * vel[1], g[2] - kv * vel[2]
    accel = np.array([a0, a1, a2])
    # Gauss-Newton in distorted pixels (the filter's measurement model)
    J = np.empty((m, 6))
    r = np.empty(m)
    for _ in range(3):
        if not _pixel_rows(cams, cam, uv, tau, theta, accel, J, r):
            return _WFIT_NONE
        theta = theta + np.linalg.lstsq(J, r, rcond)[0]
    if not _pixel_rows(cams, cam, uv, tau, theta, accel, J, r):
        return _WFIT_NONE
    ok = True
    for i in range(n):
        res_out[i] = np.hypot(r[2 * i], r[2 * i + 1])
        if not res_out[i] ** 2 <= gate * var:
            ok = False
    theta_out[:] = theta
    if not (ok and np.dot(r, r) <= chi2 * var):
        return _WFIT_NONE
    info = J.T @ J
    cov = var * np.linalg.solve(info, np.eye(6))  # numpy's inv: LAPACK gesv on I
    sv = np.linalg.svd(info)[1]
    if not np.all(np.isfinite(cov)) or sv[0] / sv[5] > 1e14:
        return _WFIT_NONE  # a degenerate geometry (rays nearly parallel)
    if cov[0, 0] + (cov[1, 1] + cov[2, 2]) > max_std2:
        return _WFIT_WEAK  # consistent, but too little information to place the ball
    if cov[3, 3] + (cov[4, 4] + cov[5, 5]) > max_speed2:
        return _WFIT_SHORT
    cov_out[:, :] = 0.5 * (cov + cov.T)
    return _WFIT_OK


@kernel
def _turn_rows(cams, cam, uv, tau, th, J, r):
    """:meth:`BallFilter._turn_fit`'s system into ``J`` (2n x 7) and ``r`` (2n): the
    window's pixels on the coordinated turn through ``th`` (7: p, v, ω) at ``τ = 0`` (the
    closed form of :func:`_turn_predicted` over ``Δt = τ``, its series below ``|ωτ| =
    1e-3``); False when a point is behind its camera. numpy's operations of the fit this
    replaced, in their order (``H @ D`` by the same BLAS product)."""
    vx, vy, vz, w = th[3], th[4], th[5], th[6]
    Di = np.zeros((3, 7))
    H = np.empty((2, 3))
    for i in range(tau.shape[0]):
        t = tau[i]
        a = w * t
        s, c = np.sin(a), np.cos(a)
        a2 = a * a
        if np.abs(a) <= 1e-3:
            sw = t * (1.0 - a2 / 6.0 * (1.0 - a2 / 20.0))
            cw = t * a * (0.5 - a2 / 24.0)
            dsw = t * t * a * (a2 / 30.0 - 1.0 / 3.0)
            dcw = t * t * (0.5 - a2 / 8.0)
        else:
            sw = s / w
            cw = (1.0 - c) / w
            dsw = (t * c - sw) / w
            dcw = (t * s - cw) / w
        ok, pu, pv, h00, h01, h02, h10, h11, h12 = _project(
            cams, cam[i], th[0] + sw * vx - cw * vy, th[1] + cw * vx + sw * vy,
            th[2] + vz * t)
        if not ok:
            return False
        Di[0, 0] = Di[1, 1] = Di[2, 2] = 1.0
        Di[0, 3], Di[0, 4], Di[1, 3], Di[1, 4] = sw, -cw, cw, sw
        Di[2, 5] = t
        Di[0, 6], Di[1, 6] = dsw * vx - dcw * vy, dcw * vx + dsw * vy
        H[0, 0], H[0, 1], H[0, 2] = h00, h01, h02
        H[1, 0], H[1, 1], H[1, 2] = h10, h11, h12
        J[2 * i:2 * i + 2, :] = H @ Di
        r[2 * i] = uv[i, 0] - pu
        r[2 * i + 1] = uv[i, 1] - pv
    return True


@kernel
def _turn_window_fit(cams, cam, uv, tau, theta, var, start_var, turn_var, gate, chi2,
                     th_out, J_out, res_out, turn_mean=0.0):
    """The coordinated turn's MAP fit of the window (:meth:`BallFilter._turn_fit`; arrays as
    :func:`_window_fit`'s) from the supported fit ``theta`` (6) and ``ω = turn_mean``: four
    Gauss-Newton steps in pixels of variance ``var`` with the prior ``ω ~ N(turn_mean,
    turn_var)`` as one more residual row, then the start's tests of the residuals at ``start_var``
    (every residual within ``gate``, their sum within ``chi2``, of ``2n - 7`` degrees of
    freedom). Writes ``(p, v, ω)`` into ``th_out`` (7), the pixel Jacobian at it into
    ``J_out`` (2n x 7: the caller forms ``JᵀJ`` with numpy, whose symmetric product is not
    numba's in the last bit) and the residuals' lengths into ``res_out`` (n); returns
    ``_WFIT_OK`` or ``_WFIT_NONE``. numpy's operations of the fit this replaced, in their
    order: the same bits (``tests/test_filter_window_fit.py``)."""
    n = tau.shape[0]
    m = 2 * n
    th = np.zeros(7)
    th[:6] = theta
    th[6] = turn_mean
    prior = math.sqrt(var / turn_var)  # the prior's row, in pixels per rad/s
    J = np.empty((m, 7))
    r = np.empty(m)
    A = np.zeros((m + 1, 7))
    b = np.empty(m + 1)
    rcond = np.finfo(np.float64).eps * (m + 1)  # numpy's rcond=None
    for _ in range(4):
        if not _turn_rows(cams, cam, uv, tau, th, J, r):
            return _WFIT_NONE
        A[:m] = J
        A[m, :] = 0.0
        A[m, 6] = prior
        b[:m] = r
        b[m] = -prior * (th[6] - turn_mean)
        th = th + np.linalg.lstsq(A, b, rcond)[0]
    if not _turn_rows(cams, cam, uv, tau, th, J, r):
        return _WFIT_NONE
    th_out[:] = th
    ok = True
    for i in range(n):
        res_out[i] = np.hypot(r[2 * i], r[2 * i + 1])
        if not res_out[i] ** 2 <= gate * start_var:
            ok = False
    J_out[:, :] = J
    if not (ok and np.dot(r, r) <= chi2 * start_var):
        return _WFIT_NONE
    return _WFIT_OK


@kernel
def _predict(S, I, O, t):
    """The state predicted to ``t`` ns (``BallFilter.predict``): mean (6) and covariance
    (6 x 6 flat) of the models' mixture, new arrays."""
    dt = (t - I[_ITIME]) / NS
    nu = S[_SNU]
    q = S[_SQ]
    if nu == 1.0:  # the turn model alone
        xt, Pt = _turn_predicted(S[_SXT:_SXT + 7], S[_SPT:_SPT + 49], dt, q, O[_OTPSD])
        return xt[:6].copy(), _block6(Pt)
    mu = S[_SMU]
    p = _pmin(O[_OSWITCH] * abs(dt), 0.5)
    c = mu * (1.0 - p) + (1.0 - mu) * p
    xs = S[_SX:_SX + 6]
    contact = _contact(xs, dt, c, O)  # (once: _push's order)
    x, P = _predicted_at(xs, S[_SP:_SP + 36], dt, c, O, q, contact)
    if O[_ODRAG] != 0.0 and not nu and contact < 0.0:
        # the estimated drag: x + V δk̂, P + V Vᵀ / I_k (none across a floor contact: V
        # starts anew there, as the step's)
        V = _drag_predicted(S[_SV:_SV + 6], x, dt, c)
        dk, w = S[_SDK], 1.0 / S[_SIK]
        for i in range(6):
            x[i] += V[i] * dk
            for j in range(6):
                P[6 * i + j] += V[i] * V[j] * w
    if nu:
        pt = _pmin(O[_OTSWITCH] * abs(dt), 0.5)
        nu = nu * (1.0 - pt) + (1.0 - nu) * pt
        xt, Pt = _turn_predicted(S[_SXT:_SXT + 7], S[_SPT:_SPT + 49], dt, q, O[_OTPSD])
        x, P = _combined(x, P, xt, Pt, nu)
    return x, P


def _state_scalar(index: int, doc: str) -> property:
    """A property of ``BallFilter`` reading and writing ``_S[index]``."""

    def get(self):
        return float(self._S[index])

    def set_(self, value):
        self._S[index] = value

    return property(get, set_, doc=doc)


def _state_vector(index: int, size: int, doc: str) -> property:
    """A property of ``BallFilter`` reading (a list) and writing ``_S[index:index + size]``."""

    def get(self):
        return self._S[index:index + size].tolist()

    def set_(self, value):
        self._S[index:index + size] = value

    return property(get, set_, doc=doc)


def regular_gap_s(rig: Rig) -> float:
    """The rig's regular gap, seconds: the longest time between consecutive frame instants
    of its cameras (their nominal shutter times ``offset + k / fps``, as
    :func:`~pslog.simulation.shutter_times`; a rolling shutter's readout left out), the
    time a detection follows the one before it when no slot was missed: ``1 / Σ fps`` on
    evenly staggered cameras of one rate (``typeA``), ``1 / fps`` on synchronised ones,
    ``0.5 / fps`` on ``typeB``. Measured over a minute of instants: rates whose pattern
    repeats within it exactly, others (close rates, 29.97 and 30 fps, beat: their instants
    pass through one another) at the longest gap of that minute. ``hold_gap``'s unit."""
    return _regular_gap_s(tuple((float(c.fps), float(c.offset)) for c in rig.cameras))


#: most frame instants :func:`regular_gap_s` lays out, all cameras together (a rig of fast
#: cameras is measured over less than a minute: 256 cameras at 1e6 fps, the rig's bounds,
#: would be 1.5e10 instants)
_GAP_INSTANTS = 4_000_000


@functools.lru_cache(maxsize=64)
def _regular_gap_s(cameras: tuple[tuple[float, float], ...]) -> float:
    """:func:`regular_gap_s` of the cameras' (fps, first instant) (hashable: cached): their
    instants over a minute after the slowest camera's first period (every camera's begun by
    then), each camera's at most ``_GAP_INSTANTS / len(cameras)`` of them, over the span all
    of them cover."""
    span = 60.0
    period = max(1.0 / fps for fps, _ in cameras)  # (every camera's instants begun by then)
    most = max(_GAP_INSTANTS // len(cameras), 16)
    each = [(first % (1.0 / fps))
            + np.arange(min(math.ceil((span + 2 * period) * fps) + 1, most)) / fps
            for fps, first in cameras]
    end = min(float(a[-1]) for a in each)
    instants = np.sort(np.concatenate(each))
    inside = instants[(instants >= (period if period < end else 0.0)) & (instants <= end)]
    return float(np.max(np.diff(inside)))


class BallFilter:
    """The ``filter`` method's state, updated one detection at a time (the streaming form).

    Parameters
    ----------
    rig : Rig, whose camera order the detections' camera indices refer to
    options : FilterOptions (``max_gap_s`` None: 3.5 frame periods of the slowest camera)

    Detections are pushed with their TRUE (corrected) capture times, in (time, camera)
    order (:class:`~pslog.fusion.stream.StreamFuser` corrects logged times first).

    The per-detection work (prediction, innovation, update, the models' mixing, the gate,
    the jump search, withholding) is one compiled kernel (:func:`_push`, numba) over the
    state arrays; the (re)initialisation's search over windows (only while there is no
    track) is Python (:meth:`_try_window`), its fits compiled (:func:`_window_fit`).

    Examples
    --------
    >>> f = BallFilter(rig)                                        # doctest: +SKIP
    >>> point = f.push(time_ns, camera, u, v)   # None, or (position, quality)  # doctest: +SKIP
    >>> position, velocity, covariance = f.predict(now_ns)        # doctest: +SKIP
    """

    def __init__(self, rig: Rig, options: FilterOptions | None = None) -> None:
        from ._prepare import default_max_gap_s

        self.options = options = options or FilterOptions()
        self._cams = [_Cam(c) for c in rig.cameras]
        n_cams = len(rig)
        cams = np.zeros((n_cams, _CAM_COLS))
        for i, c in enumerate(self._cams):
            cams[i] = [*c.r, *c.t, c.fx, c.s, c.cx, c.fy, c.cy, c.k1, c.k2, c.k3, c.p1, c.p2,
                       float(c.distorted), float(c.far)]
        self._cam_table = cams
        # each camera's centre in the world, -Rᵀ t (point_covariance's rays)
        self._centres = [tuple((-(np.asarray(c.r).reshape(3, 3).T @ np.asarray(c.t))).tolist())
                         for c in self._cams]
        # the latest start's (time, 3 x 3 window_jump_cov position block): point_covariance's
        self._start_jump: tuple[int, np.ndarray] | None = None
        self._max_gap_ns = int((options.max_gap_s or default_max_gap_s(rig)) * NS)
        self._var_min, self._var_max = options.min_noise_px ** 2, options.max_noise_px ** 2
        self._q_min = accel_floor(rig, options)
        self._q_max = max(options.max_accel_psd, self._q_min)
        self._max_std = options.max_std_m
        self._jump_var = options.jump_speed ** 2
        # the jump hypotheses (reflect, variance per axis): a floor bounce (the velocity
        # along gravity reflected with the restitution, some of the rest lost), a jump
        # mostly along gravity (a bounce off an unknown surface) and a kick (any direction)
        g_axis = np.abs(np.asarray(options.gravity, dtype=np.float64))
        g_axis = g_axis / g_axis.max() if g_axis.max() > 0 else np.ones(3)
        jv = self._jump_var
        self._jump_shapes = ([
            (True, tuple(float(_REFLECT_SIDE ** 2 + (_REFLECT_ALONG ** 2 - _REFLECT_SIDE ** 2)
                               * a) for a in g_axis)),
            (False, tuple(float(jv * (_BOUNCE_SIDE + (1 - _BOUNCE_SIDE) * a))
                          for a in g_axis))] if options.bounce_shape else []) + [
            (False, (jv, jv, jv))]
        norm = math.sqrt(sum(a * a for a in options.gravity)) or 1.0
        self._down = tuple(float(a) / norm for a in options.gravity)
        self._k = options.drag_per_m
        self._g = tuple(float(x) for x in options.gravity)
        self._g_array = np.array(self._g)
        self._gate = options.gate
        self._switch = options.model_switch_per_s
        # without switching the ballistic model alone (probability 1)
        self._mu0 = _INIT_BALLISTIC if self._switch else 1.0
        # the turn model (coordinated turn about z, turn rate ω in its state)
        g = options.gravity
        self._turn = bool(options.turn_switch_per_s) and g[0] == 0.0 and g[1] == 0.0
        self._turn_switch = options.turn_switch_per_s
        self._turn_psd = options.turn_rate_psd
        self._turn_var = options.turn_rate_std ** 2
        # a window shorter than this whose fit fails on its velocity alone grows; the
        # longest time a window spans: the longest gap bridged, or a grown window's span
        self._init_grow_ns = int(options.init_span_s * NS)
        self._init_span_ns = max(self._max_gap_ns, self._init_grow_ns)
        capacity = max(options.init_window, options.init_max_window) + 1
        O = np.zeros(_OSIZE)
        O[_OK], O[_OG:_OG + 3], O[_ODOWN:_ODOWN + 3] = self._k, self._g, self._down
        O[_OGATE], O[_OADAPT] = self._gate, options.adapt_rate
        O[_OVMIN], O[_OVMAX], O[_OQMIN], O[_OQMAX] = (self._var_min, self._var_max,
                                                      self._q_min, self._q_max)
        O[_OQRATE], O[_OQTARGET] = options.accel_adapt_rate, options.accel_adapt_target
        O[_OMAXSTD] = math.inf if self._max_std is None else self._max_std
        O[_OWITHHOLD], O[_OCONFNIS] = float(options.withhold), options.confirm_nis
        O[_OSWITCH], O[_OMU0], O[_OTURN] = self._switch, self._mu0, float(self._turn)
        O[_OTSWITCH], O[_OTON], O[_OTPSD], O[_OTVAR] = (
            self._turn_switch, turn_on_threshold(rig, options), self._turn_psd, self._turn_var)
        O[_OREST], O[_OFRIC] = options.restitution, options.bounce_friction
        O[_ONSHAPES] = len(self._jump_shapes)
        for i, (reflect, var) in enumerate(self._jump_shapes):
            O[_OSHAPES + 4 * i:_OSHAPES + 4 * i + 4] = (float(reflect), *var)
        O[_OUNSEEN] = options.jump_rate_per_s * self._jump_var / 3.0
        O[_OKS] = options.supported_drag_per_m
        O[_OINSTANT] = float(options.jump_instant)
        O[_OJMIX] = float(options.jump_mixture_cov)
        sk = options.drag_std_per_m
        O[_ODRAG] = 1.0 / (sk * sk) if sk > 0.0 else 0.0
        O[_OSURPRISE] = options.jump_rate_per_s if options.surprise_cov else 0.0
        # (withhold off: a point at every detection of a live track, none held either)
        O[_OHOLD] = (math.inf if options.hold_nis is None or not options.withhold
                     else options.hold_nis)
        # (a start's point held as those: FilterStream and fuse_filter, with the hold)
        self._hold_start = options.hold_start and math.isfinite(O[_OHOLD])
        O[_ODRAGQ] = (sk * sk / options.drag_drift_s
                      if sk > 0.0 and options.drag_drift_s is not None else 0.0)
        O[_OITER] = float(options.iterate_update)
        O[_OFLOOR] = math.nan if options.floor_m is None else float(options.floor_m)
        O[_OESTD2] = options.restitution_std ** 2
        O[_OFSTD2] = options.bounce_friction_std ** 2
        O[_OHOLDP] = 2.0 if options.hold_jump_p is None else options.hold_jump_p
        O[_OQDEAD] = options.accel_adapt_threshold
        O[_OCHAIN] = float(options.chained_jump_restart)
        # (the regular gap laid out only where something is held: pslog live holds nothing)
        O[_OHOLDGAP] = (math.inf if options.hold_gap is None or O[_OHOLD] == math.inf
                        else options.hold_gap * regular_gap_s(rig))
        O[_OHOLDREJ] = float(options.hold_rejected)
        O[_OQGMAX] = (options.accel_adapt_threshold
                      + (math.log(self._q_max / self._q_min) / options.accel_adapt_rate
                         if options.accel_adapt_rate > 0.0 else 0.0))
        self._opts = O
        self._nopts = np.array([self._max_gap_ns, self._init_span_ns, options.init_window,
                                options.init_detections, options.max_rejects, capacity],
                               dtype=np.int64)
        # the state (layout: the _S* and _I* offsets)
        self._S = np.zeros(_SCAM + 2 * n_cams + 2 * capacity)
        self._I = np.zeros(_ICAM + 3 * n_cams + 2 * capacity, dtype=np.int64)
        self._S[_SMU], self._S[_SQ] = self._mu0, self._q_min
        self._S[_SVAR] = options.noise_px ** 2
        self._S[_SALPHA] = options.noise_prior_weight
        self._S[_SIK] = O[_ODRAG]  # δk̂ = 0 with the prior's information
        self._I[_IPEND], self._I[_IJUMPNS], self._I[_IJUMPCAM] = -1, -(2**62), -1
        self._I[_ICAP] = options.init_window
        self._I[_IDRAGT] = -(2**62)  # no drag update yet
        self._I[_ICAM:_ICAM + n_cams] = -(2**62)  # last accepted detection per camera
        self._out = np.empty(_OUT_COLS)
        self._rays: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    # ---- the state, as the pure-Python filter named it (tests, inspection) ---------------
    _mu = _state_scalar(_SMU, "probability of the ballistic model (else supported)")
    _nu = _state_scalar(_SNU, "probability of the turn model (0: not in the model set)")
    _q = _state_scalar(_SQ, "the adapted process noise's spectral density, m²/s³")
    _q_cusum = _state_scalar(_SQG, "q's change detector's CUSUM g (accel_adapt_threshold)")
    _var = _state_scalar(_SVAR, "the adapted pixel variance, px²")
    _alpha = _state_scalar(_SALPHA, "the pixel variance's inverse-gamma shape α (σ² = β/α)")
    _x = _state_vector(_SX, 6, "the pair's mean (position, velocity)")
    _P = _state_vector(_SP, 36, "the pair's covariance (6 x 6 flat)")
    _xt = _state_vector(_SXT, 7, "the turn model's mean (position, velocity, ω)")
    _Pt = _state_vector(_SPT, 49, "the turn model's covariance (7 x 7 flat)")
    _e = _state_vector(_SE, 6, "the ballistic model's mean minus the supported one's")
    _V = _state_vector(_SV, 6, "the state's sensitivity to the drag, ∂x/∂k (m, m/s per 1/m)")
    _dk = _state_scalar(_SDK, "the estimated drag's offset δk̂ from drag_per_m, 1/m")
    _drag_info = _state_scalar(_SIK, "the information I_k of δk̂, (1/m)⁻²")

    def __getattr__(self, name):
        # a filter made by __new__ (tests of the turn model's pieces) gets its state arrays
        # when first set
        if name in ("_S", "_I"):
            value = (np.zeros(_SCAM) if name == "_S"
                     else np.zeros(_ICAM, dtype=np.int64))
            object.__setattr__(self, name, value)
            return value
        raise AttributeError(name)

    @property
    def time_ns(self) -> int | None:
        """Time of the state (ns); None without a track."""
        return int(self._I[_ITIME]) if self._I[_IHAS] else None

    @property
    def dropped(self) -> dict[str, int]:
        """Reason -> number of points withheld (``unconfirmed``, ``uncertain``)."""
        counts = {"unconfirmed": int(self._I[_IDROPC]), "uncertain": int(self._I[_IDROPU])}
        order = ("uncertain", "unconfirmed") if self._I[_IDROPFIRST] == 2 else tuple(counts)
        return {k: counts[k] for k in order if counts[k]}

    # ---- public state access -------------------------------------------------------------
    def set_state(self, time_ns: int, position, velocity, covariance) -> None:
        """Start a track from a given state (tests, or a state handed over)."""
        S, I = self._S, self._I
        I[_IHAS] = 1
        I[_ITIME] = I[_ILAST] = int(time_ns)
        S[_SX:_SX + 6] = [float(a) for a in (*position, *velocity)]
        S[_SP:_SP + 36] = np.asarray(covariance, dtype=np.float64).ravel()
        I[_IREJ] = I[_ICONF] = 0
        I[_IPEND] = -1
        I[_ICHAIN] = 0
        I[_IWN] = 0
        I[_ICAP] = self.options.init_window
        I[_IHN] = 0
        I[_IJN] = 0
        I[_IJTE] = -(2 ** 62)
        I[_ICAM:_ICAM + len(self._cams)] = I[_ILAST]
        S[_SMU], S[_SE:_SE + 6] = self._mu0, 0.0
        S[_SNU] = 0.0
        S[_SV:_SV + 6] = 0.0  # a (re)start: a new segment (δk̂ is kept)

    def state(self):
        """``(time_ns, x (6,), P (6, 6))`` of the current track (the mixture of the motion
        models), or None without one."""
        if not self._I[_IHAS]:
            return None
        S = self._S
        x, P = _combined(S[_SX:_SX + 6], S[_SP:_SP + 36], S[_SXT:_SXT + 7],
                         S[_SPT:_SPT + 49], S[_SNU])
        return int(self._I[_ITIME]), x, P.reshape(6, 6)

    def predict(self, time_ns: int):
        """The state predicted to ``time_ns`` (the process model; the state is unchanged),
        its covariance with the velocity jumps (kicks, bounces) the gap since the latest
        accepted detection may hide, as a rejected detection's point publishes them.

        The jumps: a Poisson process of rate ``λ_j`` (``jump_rate_per_s``), each ``Δv ~
        N(0, σ_j² I)`` (``jump_speed``) at an instant ``s`` in the gap, so by ``time_ns``,
        ``T`` seconds after the latest accepted detection, the position has moved by
        ``Σ Δv_k (T − s_k)`` and the velocity by ``Σ Δv_k``: a compound Poisson process,
        whose covariance per axis is exactly (any number of jumps; zero mean)

            P_pp += λ_j σ_j² T³/3,   P_pv += λ_j σ_j² T²/2,   P_vv += λ_j σ_j² T

        (the position's term is :func:`_unseen_gap_jump`'s: at a rejected detection's time
        the position block is that point's published covariance). ``T ≤ 0`` (at or before
        the latest accepted detection) adds nothing.

        Returns
        -------
        None without a track; else ``(position (3,), velocity (3,), covariance (6, 6))`` in
        metres, m/s and their squares. An earlier time is retrodicted with the same model
        (process noise of ``|Δt|``).
        """
        if not self._I[_IHAS]:
            return None
        x, P = _predict(self._S, self._I, self._opts, int(time_ns))
        a = self._opts[_OUNSEEN]  # λ_j σ_j² / 3
        gap = (int(time_ns) - int(self._I[_ILAST])) / NS
        if a != 0.0 and gap > 0.0:  # the jumps the gap may hide (a new array: add in place)
            P[0:15:7] += a * gap * gap * gap  # the 6 x 6's diagonals, flat: pp
            P[3:18:7] += 1.5 * a * gap * gap  # pv
            P[18:33:7] += 1.5 * a * gap * gap  # vp
            P[21:36:7] += 3.0 * a * gap  # vv
        return x[:3], x[3:], P.reshape(6, 6)

    def point_covariance(self, time_ns: int, camera: int, position, std_xyz,
                         rejected: bool) -> tuple | None:
        """The full 3 x 3 covariance of the point just published at ``time_ns`` by
        ``camera`` (``position``, its ``std_x_m``, ``std_y_m``, ``std_z_m`` and whether its
        detection was rejected), for :mod:`pslog.live`: its diagonal is the published
        variances (``std²``: the quality columns, to the bit through ``sqrt``), its
        correlations those of the state's position covariance plus the term the point
        published on top of it (in full, where the columns keep only its diagonal): after an
        accepted jump its instant's term (:func:`_instant_term`, ``w ε_p ε_pᵀ``), at a
        rejected detection the gap's jumps (:func:`_unseen_gap_jump`: isotropic, ``Δ I``),
        at a start's point the jumps its window may hide (:func:`window_jump_cov`'s position
        block, in full), else the unseen jump of one camera going on alone
        (:func:`_unseen_jump`) and a plain update's doubt (:func:`_surprise_term`), both
        along the camera's ray ``d``, ``Δ d dᵀ / |d|²``, ``Δ`` the published variance minus
        the state's. Rows as three tuples of floats; None when the
        state is not at ``time_ns`` (a later detection moved it: the point's correlations are
        not at hand)."""
        S, I = self._S, self._I
        if not I[_IHAS] or int(I[_ITIME]) != time_ns:
            return None
        if S[_SNU]:  # the models' mixture (state()'s)
            P = _combined(S[_SX:_SX + 6], S[_SP:_SP + 36], S[_SXT:_SXT + 7],
                          S[_SPT:_SPT + 49], S[_SNU])[1][:15]
        else:  # the pair alone
            P = S[_SP:_SP + 15]
        p00, p01, p02, _, _, _, _, p11, p12, _, _, _, _, _, p22 = P.tolist()
        sx, sy, sz = std_xyz
        vx, vy, vz = sx * sx, sy * sy, sz * sz
        if self._opts[_ODRAG] != 0.0 and not S[_SNU]:
            # the estimated drag's term V_p V_pᵀ / I_k (:func:`_drag_point`), in full
            e0, e1, e2 = S[_SV:_SV + 3].tolist()
            w = 1.0 / float(S[_SIK])
            p00, p11, p22 = p00 + w * e0 * e0, p11 + w * e1 * e1, p22 + w * e2 * e2
            p01, p02, p12 = p01 + w * e0 * e1, p02 + w * e0 * e2, p12 + w * e1 * e2
        extra = vx + vy + vz - (p00 + p11 + p22)
        if not rejected and int(I[_IJTE]) == time_ns and I[_IJN] > 0 and S[_SJE + 3] > 0.0:
            # an accepted jump's instant (:func:`_instant_term`): w ε_p ε_pᵀ, in full
            e0, e1, e2, w = S[_SJE:_SJE + 4].tolist()
            p00, p11, p22 = p00 + w * e0 * e0, p11 + w * e1 * e1, p22 + w * e2 * e2
            p01, p02, p12 = p01 + w * e0 * e1, p02 + w * e0 * e2, p12 + w * e1 * e2
            extra -= w * (e0 * e0 + e1 * e1 + e2 * e2)
        start = self._start_jump
        if extra > 0.0 and not rejected and start is not None and start[0] == time_ns:
            # a start's point: the jumps its window may hide (:func:`window_jump_cov`), in full
            q = start[1]
            p00, p11, p22 = p00 + q[0, 0], p11 + q[1, 1], p22 + q[2, 2]
            p01, p02, p12 = p01 + q[0, 1], p02 + q[0, 2], p12 + q[1, 2]
        elif extra > 0.0:
            if rejected:
                a = extra / 3.0
                p00, p11, p22 = p00 + a, p11 + a, p22 + a
            else:
                px, py, pz = position
                c0, c1, c2 = self._centres[camera]
                # the ray's direction in the world: the point minus the camera's centre
                d0, d1, d2 = px - c0, py - c1, pz - c2
                n2 = d0 * d0 + d1 * d1 + d2 * d2
                if n2 > 0.0:
                    a = extra / n2
                    p00, p11, p22 = p00 + a * d0 * d0, p11 + a * d1 * d1, p22 + a * d2 * d2
                    p01, p02, p12 = p01 + a * d0 * d1, p02 + a * d0 * d2, p12 + a * d1 * d2
        # the published variances on the diagonal, the correlations above (always a
        # covariance: a correlation matrix scaled)
        f0 = sx / math.sqrt(p00) if p00 > 0.0 else 0.0
        f1 = sy / math.sqrt(p11) if p11 > 0.0 else 0.0
        f2 = sz / math.sqrt(p22) if p22 > 0.0 else 0.0
        c01, c02, c12 = p01 * f0 * f1, p02 * f0 * f2, p12 * f1 * f2
        return (vx, c01, c02), (c01, vy, c12), (c02, c12, vz)

    # ---- pieces of the step, for tests (the compiled kernels on lists) ---------------------
    def _turn_predicted(self, x, P, dt):
        """The turn model's mean and covariance after ``dt`` (:func:`_turn_predicted`)."""
        return _turn_predicted(np.asarray(x, dtype=np.float64),
                               np.asarray(P, dtype=np.float64), float(dt), float(self._q),
                               float(self._turn_psd))

    def _turn_mixed(self, nu, xg, Pg, dt):
        """The mixing of the pair and the turn model (:func:`_turn_mixed`)."""
        return _turn_mixed(float(nu), np.asarray(xg, dtype=np.float64),
                           np.asarray(Pg, dtype=np.float64), self._S[_SXT:_SXT + 7],
                           self._S[_SPT:_SPT + 49], float(dt), float(self._turn_switch))

    # ---- the filter ----------------------------------------------------------------------
    def push(self, time_ns: int, camera: int, u: float, v: float):
        """Fuse one detection (true capture time, camera index, distorted pixel).

        Returns
        -------
        None when no point is made (no track yet, an unusable pixel, or a point withheld:
        counted in :attr:`dropped`); else ``(position (x, y, z), quality)`` with ``quality``
        a tuple in the order of :data:`FILTER_QUALITY`. The point leaves at its detection:
        no hold for the next camera here (``hold_nis``: :class:`FilterStream` and
        :func:`fuse_filter` hold).
        """
        out = self._out
        status = _step(self._S, self._I, self._cam_table, self._opts, self._nopts,
                       int(time_ns), int(camera), float(u), float(v), out)
        if status == _NONE:
            return None
        if status != _POINT and not self._fitted(status, out):
            return None
        o = out.tolist()
        init = o[15] == 1.0
        return ((o[0], o[1], o[2]),
                (o[3], o[4], o[5], o[6], math.hypot(o[7], o[8]),
                 o[9] if init else math.hypot(o[9], o[10]), o[11], o[12], o[13], o[14],
                 o[15]))

    def _holds_start(self, out: np.ndarray, held: int) -> bool:
        """Whether the point in ``out`` (a window fit's, not withheld) is a start's held for
        the next camera (``hold_start``), ``held`` points held already."""
        return self._hold_start and out[15] == 1.0 and held < _HOLD_MAX

    def _fitted(self, status: int, out: np.ndarray) -> bool:
        """The rare path of a step (``_FIT``, ``_FIT_OR_POINT``): fit the window; the point
        (a start, or the step's own point when no start) into ``out``, withheld as
        :meth:`push` withholds. True when a point is in ``out``."""
        if not self._try_window(out):
            if status != _FIT_OR_POINT:
                return False
        return not _withheld(self._I, self._opts, out[3])

    # ---- (re)initialisation from a window --------------------------------------------------
    def _window(self) -> list[tuple[int, int, float, float]]:
        n_cams, n = len(self._cams), int(self._I[_IWN])
        t = self._I[_ICAM + 3 * n_cams:].reshape(-1, 2)[:n].tolist()
        f = self._S[_SCAM + 2 * n_cams:].reshape(-1, 2)[:n].tolist()
        return [(a[0], a[1], b[0], b[1]) for a, b in zip(t, f, strict=True)]

    def _set_window(self, window) -> None:
        n_cams, n = len(self._cams), len(window)
        self._I[_IWN] = n
        if n:
            self._I[_ICAM + 3 * n_cams:_ICAM + 3 * n_cams + 2 * n] = [
                a for w in window for a in w[:2]]
            self._S[_SCAM + 2 * n_cams:_SCAM + 2 * n_cams + 2 * n] = [
                a for w in window for a in w[2:]]

    def _try_window(self, out: np.ndarray) -> bool:
        """Fit the window (newest last), dropping its oldest detection until a fit passes (a
        break or an outlier inside it) or fewer than ``init_detections`` are left (at most
        ``init_window - init_detections + 1`` fits per detection, and only while there is
        no track); a fit that passes the residual tests but fails on its uncertainty alone
        (``_WEAK``: the position's; ``_SHORT``: the velocity's) ends the search and keeps
        the window whole (a shorter window has still less information: cut, it kept
        ``init_detections - 1`` detections and every later fit failed the same way, a
        two-camera track at 1 px never started again), and a ``_SHORT`` window spanning
        less than ``init_span_s`` may grow beyond ``init_window`` (at 60 fps and above
        ``init_window`` detections span too short a time; at 30 fps ``init_detections``
        of a 3-camera rig span a frame period, 33 ms, so nothing grows there); on success
        start the track at the newest detection, write its point into ``out`` and return
        True.

        The kernel has already dropped the detections older than the window's span and
        found at least ``init_detections`` of two cameras (:func:`_window_trim`)."""
        window = self._window()
        while len(window) >= self.options.init_detections:
            if len({w[1] for w in window}) < 2:
                break
            fit, mu, e, turn = self._fit_models(window)
            if fit is _SHORT or fit is _WEAK:
                if fit is _SHORT and window[-1][0] - window[0][0] < self._init_grow_ns:
                    self._I[_ICAP] = min(max(int(self._I[_ICAP]), len(window) + 1),
                                         self.options.init_max_window)
                break
            elif fit is not None:
                x, P, residuals = fit
                # the noise estimate starts again at each (re)start, from its prior (or the
                # estimate, if larger) and the window's residuals: a lost track may mean
                # the detector's noise changed, and an estimate that had shrunk below it
                # would gate out the very detections that could raise it again
                var = self._start_var()
                noise = (float(self._S[_SALPHA]), float(self._S[_SVAR]))
                self._S[_SALPHA] = self.options.noise_prior_weight
                self._S[_SVAR] = self._prior_var(len(window), residuals, var)
                self._window_noise(len(window), residuals)
                # the fit's covariance was σ² (JᵀJ)⁻¹ at the start's σ²: at the updated one
                scale = float(self._S[_SVAR]) / var
                P = [a * scale for a in P]
                if self._too_fast(x, P):  # (at the updated σ²: the window's own noise)
                    # refused like a fit failing its tests: the noise estimate as it was
                    self._S[_SALPHA], self._S[_SVAR] = noise
                    del window[0]
                    continue
                lost = self._lost_prediction(window)
                if lost is not None:
                    x, P = _with_prior(x, P, *lost[0])
                    if turn is not None and lost[1] is not None:
                        turn = (*_with_prior(turn[0], turn[1], *lost[1]), turn[2])
                self.set_state(window[-1][0], x[:3], x[3:], P)
                self._S[_SMU] = mu
                self._S[_SE:_SE + 6] = e
                for t, c, _, _ in window:
                    self._I[_ICAM + c] = t
                vx, vy, vz = P[0], P[7], P[14]
                if turn is not None:
                    # the turn model starts at its own fit (turn rate and all) with its
                    # probability: the point is the mixture (as _combined_point)
                    xt, Pt, nu = turn
                    S = self._S
                    S[_SXT:_SXT + 7] = xt
                    S[_SPT:_SPT + 49] = Pt  # at the updated σ² already
                    S[_SNU] = nu
                    self._I[_IAGE] = 0
                    *x, vx, vy, vz = _combined_point(S[_SX:_SX + 6], S[_SP:_SP + 36],
                                                     S[_SXT:_SXT + 7], S[_SPT:_SPT + 49], nu)
                if self._opts[_OUNSEEN] != 0.0:
                    # the published covariance: with the jumps the window cannot rule out
                    qx, qy, qz = self._window_jump_var(window)
                    vx, vy, vz = vx + qx, vy + qy, vz + qz
                _point(out, x[0], x[1], x[2], vx, vy, vz, _NAN, _NAN,
                       float(residuals[-1]), 0.0, _NAN, _NAN, 0.0, 0.0, 1.0)
                return True
            del window[0]
        self._set_window(window)
        return False

    def _too_fast(self, x, P) -> bool:
        """Whether a start's fit is faster than any ball: its speed ``|v̂|`` exceeds
        ``max_speed_m_s`` by more than three standard deviations of the speed, ``σ² =
        v̂ᵀ P_vv v̂ / |v̂|²`` (the speed's variance to first order). ``x`` (6,) position and
        velocity, ``P`` (36,) their covariance, row-major (the fit's at the pixel variance
        the window's residuals updated, as the start takes it)."""
        bound = self.options.max_speed_m_s
        if bound is None:
            return False
        v = np.asarray(x[3:6], dtype=np.float64)
        speed2 = float(v @ v)
        if speed2 <= bound * bound:
            return False
        Pvv = np.asarray(P, dtype=np.float64).reshape(6, 6)[3:, 3:]
        sigma = math.sqrt(max(float(v @ Pvv @ v) / speed2, 0.0))
        return math.sqrt(speed2) - bound > 3.0 * sigma

    def _window_jump_var(self, window) -> tuple[float, float, float]:
        """The variances (x, y, z) a start's point gains from the velocity jumps (kicks,
        bounces) inside its window, which the window's fit assumed away: jumps a Poisson
        process of rate ``λ_j``, each ``Δv ~ N(0, σ_j² I)`` at an instant ``s`` in the
        window (:func:`window_jump_cov`, at the state just set: the pixel Jacobians of the
        fitted path). The state keeps the fit's covariance."""
        S = self._S
        t_ref = window[-1][0]
        tau = np.array([(w[0] - t_ref) / NS for w in window])
        cam = np.array([w[1] for w in window], dtype=np.int64)
        uv = np.array([w[2:] for w in window])
        n = len(window)
        J, r = np.empty((2 * n, 6)), np.empty(2 * n)
        theta = np.array(S[_SX:_SX + 6], dtype=np.float64)
        if not _pixel_rows(self._cam_table, cam, uv, tau, theta, self._g_array, J, r):
            return 0.0, 0.0, 0.0
        Q = window_jump_cov(J, tau, 3.0 * float(self._opts[_OUNSEEN]))
        self._start_jump = (int(t_ref), Q[:3, :3].copy())  # (point_covariance's, in full)
        return float(Q[0, 0]), float(Q[1, 1]), float(Q[2, 2])

    def _lost_prediction(self, window):
        """What a lost track says of a restart's window (newest at ``window[-1]``): the pair's
        and the turn model's predicted means and covariances at the newest detection's time
        (6, 6 x 6 flat each; the turn model's ``None`` when it was not in the lost track's
        model set), or None at a first start, after a start its next detections denied
        (never confirmed: review, session 14) and when the window holds a detection the lost
        track already used (at or before its last accepted one: its information is in
        both). The prediction is the process model's own (:func:`_predicted` with the
        models' mixing, :func:`_turn_predicted`), from the lost state."""
        S, I = self._S, self._I
        if (not self.options.restart_prior or not np.any(S[_SP:_SP + 36])
                or I[_ICONF] < _CONFIRM  # (a start its next detections denied: no track)
                or window[0][0] <= I[_ILAST]):
            return None
        t = window[-1][0]
        dt = (t - int(I[_ITIME])) / NS
        mu = float(S[_SMU])
        p = min(self._switch * abs(dt), 0.5)
        c = mu * (1.0 - p) + (1.0 - mu) * p
        pair = _predicted(S[_SX:_SX + 6], S[_SP:_SP + 36], dt, c, self._opts, float(S[_SQ]))
        turn = None
        if S[_SNU]:
            xt, Pt = _turn_predicted(S[_SXT:_SXT + 7], S[_SPT:_SPT + 49], dt, float(S[_SQ]),
                                     self._turn_psd)
            turn = (xt[:6], _block6(Pt))
        return pair, turn

    def _start_var(self) -> float:
        """The pixel variance a (re)start is judged by: the estimate, or the prior's
        ``noise_px²`` if larger (an estimate that shrank on a clean stretch must not refuse
        every window once the detector got noisier)."""
        var = float(self._var)
        if self.options.adapt_rate == 0.0:
            return var
        return max(var, min(max(self.options.noise_px ** 2, self._var_min), self._var_max))

    def _window_noise(self, n: int, residuals) -> None:
        """The pixel variance's conjugate update by a window fit of ``n`` detections with
        these pixel residuals (``2n - 6`` degrees of freedom: the least-squares residual
        variance, Gelman et al., *Bayesian Data Analysis*, 3rd ed., 2013, §14.2): after
        ``n`` steps of forgetting ``ρ``, ``α ← ρⁿ α + (2n - 6)/2``, ``β ← ρⁿ β + ‖r‖²/2``,
        ``σ² = β/α`` clipped to its bounds."""
        if self.options.adapt_rate == 0.0:
            return
        S = self._S
        decay = (1.0 - self.options.adapt_rate) ** n
        alpha = decay * S[_SALPHA] + (n - 3)
        beta = decay * S[_SALPHA] * S[_SVAR] + 0.5 * float(np.sum(residuals * residuals))
        S[_SALPHA] = alpha
        S[_SVAR] = min(max(beta / alpha, self._var_min), self._var_max)

    def _ray(self, time_ns: int, camera: int, u: float, v: float):
        key = (time_ns, camera)
        ray = self._rays.get(key)
        if ray is None:
            if len(self._rays) > 4 * self.options.init_max_window:
                self._rays.clear()
            # one pixel at a time, so the ray never depends on what else is undistorted
            origin, direction = self._cams[camera].camera.rays(np.array([[u, v]]))
            ray = self._rays[key] = (origin, direction[0])
        return ray

    def _fit_models(self, window):
        """The start's fits of the window, one per model: ``(fit, μ, e, turn)``, ``fit`` as
        :meth:`_fit` gives it (the pair's mixture's mean), ``μ`` the ballistic model's
        probability, ``e`` the ballistic fit's state minus the supported one's, ``turn``
        None or the turn model's start ``(x_t (7,), P_t (7x7 flat), ν)``.

        The interacting multiple model's start (Bar-Shalom et al. 2001, §11.6): each
        model's state is its own fit of the window, its probability the prior updated by
        the fits' likelihoods (σ² the noise estimate after the best fit's residuals).
        Ballistic against supported (the same number of parameters): ``μ`` the prior ``μ₀``
        times ``exp((‖r_s‖² - ‖r_b‖²) / 2σ²)``, the mixture's mean ``x_s + μ e``; a fit only
        one model passes starts that model alone (``μ = μ₀`` or ``1 - μ₀``, ``e = 0``). The
        coordinated turn (:meth:`_turn_fit`) nests the supported model (``ω = 0``), so its
        better fit is weighed with the Occam factor of its extra parameter under the
        prior ``ω ~ N(0, turn_rate_std²)`` (Laplace's approximation of the Bayes factor,
        Kass & Raftery 1995, §4.1): ``log B_ts = (‖r_s‖² - ‖r_t‖²) / 2σ² + ½ log(V_ω /
        turn_rate_std²) - ω̂² / (2 turn_rate_std²)`` against the supported fit, and the
        pair's evidence relative to the supported fit's, ``μ₀ exp((‖r_s‖² - ‖r_b‖²) / 2σ²)
        + 1 - μ₀`` (1 when the ballistic fit failed), divided out: ``log B = log B_ts -
        log(that)``, from the prior odds ``ν₀ = 0.1``. Both probabilities are bounded to
        ``[0.1, 0.9]`` (a window's evidence starts the Markov chain, it does not end it).

        Why: a ballistic start of a ball that is not falling (on a line, rolling,
        carried) began with gravity's curvature absorbed into its velocity (a straight line
        at 0 px: 1.8 mm off 0.09 s after the start, 0.45 mm now), and a turning ball's turn
        model joined at ``ω = 0 ± 6 rad/s`` and took 0.1-0.2 s to settle (0.4-0.9 mm errors
        on noise-free detections at 240 fps, where type A is at 0.01-0.02 mm)."""
        mu0 = self._mu0
        ballistic = self._fit(window)
        if mu0 == 1.0 or not self.options.start_models:
            return ballistic, mu0, _ZERO6, None
        supported = self._fit(window, ballistic=False)
        if not isinstance(supported, tuple):
            return ballistic, mu0, _ZERO6, None
        if not isinstance(ballistic, tuple):
            fit, mu, e = supported, 1.0 - mu0, _ZERO6
            ssp = float(np.sum(supported[2] ** 2))
        else:
            rb, rs = ballistic[2], supported[2]
            ssb, sss = float(np.sum(rb * rb)), float(np.sum(rs * rs))
            ssp = min(ssb, sss)
            var = self._window_var(len(window), rb if ssb <= sss else rs)
            mu = _posterior(mu0, 0.5 * (sss - ssb) / var, 1.0 - mu0, mu0)
            xb, xs = ballistic[0], supported[0]
            x = [s + mu * (b - s) for b, s in zip(xb, xs, strict=True)]
            e = tuple(b - s for b, s in zip(xb, xs, strict=True))
            fit = (x, *(ballistic if ssb <= sss else supported)[1:])
        if not self._turn:
            return fit, mu, e, None
        var = self._window_var(len(window), fit[2])
        nu0, mean, turn_var = self._turn_prior(window[-1][0])
        turn = self._turn_fit(window, supported[0], var, (mean, turn_var))
        if turn is None:
            return fit, mu, e, None
        xt, Pt, rt = turn
        sst = float(np.sum(rt * rt))
        if sst < ssp:  # the noise evidence from the best fit's residuals
            fit = (fit[0], fit[1], rt)
            scale = self._window_var(len(window), rt) / var
            var *= scale
            Pt = [a * scale for a in Pt]
        w = xt[6]
        # against the model it nests (supported: ω = 0), then against the pair's evidence,
        # the ballistic and supported fits' mixture at the prior μ₀
        sss = float(np.sum(supported[2] * supported[2]))
        log_b = (0.5 * (sss - sst) / var + 0.5 * math.log(Pt[48] / turn_var)
                 - 0.5 * (w - mean) * (w - mean) / turn_var)
        if isinstance(ballistic, tuple):
            ssb = float(np.sum(ballistic[2] * ballistic[2]))
            log_b -= float(np.logaddexp(math.log(mu0) + 0.5 * (sss - ssb) / var,
                                        math.log(1.0 - mu0)))
        nu = _posterior(nu0, log_b, _TURN_START, 1.0 - _TURN_START)
        return fit, mu, e, (xt, Pt, nu)

    def _turn_prior(self, t_ns: int) -> tuple[float, float, float]:
        """The turn model's prior at a (re)start at ``t_ns``: ``(ν₀, ω mean, ω variance)``.

        At a first start, or when the lost track's model set had no turn model (ν = 0),
        the start's prior: ``ν₀ = 0.1`` and ``ω ~ N(0, turn_rate_std²)``. A track lost
        with the turn model in its set (a camera blind, the other alone for longer than
        ``max_gap_s``) leaves what its model says of the time since: its turn rate is a
        random walk of density ``turn_rate_psd`` (:func:`_turn_predicted`), so ``ω ~
        N(ω_lost, P_ωω + turn_rate_psd Δ)`` (Δ: from the lost state's time to ``t_ns``), and
        its probability moves by the Markov chain of the switches (:func:`_turn_mixed`):
        ``ν₀ = ν (1 - p) + (1 - ν) p``, ``p = λ_t Δ``, within the bounds of a start's
        probability, ``[0.1, 0.9]``. Where that variance reaches ``turn_rate_std²``, or
        the chain has mixed (``p >= 1/2``: ν no longer says anything of the lost track; a
        new ball seconds later must not start from the old one's turn rate — inside a track
        the turn model rejoins with ω unknown too), the start's prior is kept.
        Before session 13 every restart took the start's prior: a turning ball's track,
        lost across one camera's half-second blackout, started again at ``ν = 0.1`` and
        ``ω = 0 ± 6 rad/s``, and took 0.2-0.3 s to find the turn again (``paper2``
        ``turntable``: 6.3 mm over the 0.3 s after the blackout against 3.2 mm clean)."""
        S = self._S
        nu = float(S[_SNU])
        if not self._turn or nu == 0.0:
            return _TURN_START, 0.0, self._turn_var
        dt = abs(t_ns - int(self._I[_ITIME])) / NS
        turn_var = float(S[_SPT + 48]) + self._turn_psd * dt
        if not turn_var < self._turn_var:
            return _TURN_START, 0.0, self._turn_var
        p = self._turn_switch * dt
        if p >= 0.5:  # the chain has forgotten the lost model: so has its turn rate
            return _TURN_START, 0.0, self._turn_var
        nu0 = min(max(nu * (1.0 - p) + (1.0 - nu) * p, _TURN_START), 1.0 - _TURN_START)
        return nu0, float(S[_SXT + 6]), turn_var

    def _turn_fit(self, window, theta, var: float, prior: tuple[float, float] | None = None):
        """Fit of the coordinated turn (:func:`_turn_predicted`'s mean, the turn rate ``ω``
        in the state) to the window at the newest detection's time: maximum a posteriori
        under the turn model's prior ``ω ~ N(0, turn_rate_std²)`` (a pseudo-observation of
        ``ω``: a short window leaves ``ω`` to the prior, where the turn model joined before),
        by Gauss-Newton in distorted pixels of variance ``var`` from the supported model's
        fit ``theta`` (6) and ``ω = 0``: ``(x_t (7,), P_t (7x7 flat list, at ``var``),
        pixel residuals)``, or None when it fails the start's tests (:meth:`_fit`).
        Regularised least squares (the prior as an extra residual row) is the Gaussian
        MAP estimate (Bar-Shalom et al. 2001, §3.4: the prior as a measurement). Compiled:
        :func:`_turn_window_fit`."""
        t_ref = window[-1][0]
        n = len(window)
        tau = np.array([(w[0] - t_ref) / NS for w in window])
        cam = np.array([w[1] for w in window], dtype=np.int64)
        uv = np.array([w[2:] for w in window])
        th, J, residuals = np.empty(7), np.empty((2 * n, 7)), np.empty(n)
        mean, turn_var = (0.0, self._turn_var) if prior is None else prior
        prior_row = math.sqrt(var / turn_var)
        try:
            status = _turn_window_fit(
                self._cam_table, cam, uv, tau, np.asarray(theta, dtype=np.float64), var,
                self._start_var(), turn_var, self._gate, _chi2_quantile(2 * n - 7),
                th, J, residuals, mean)
        except np.linalg.LinAlgError:  # a non-finite system
            return None
        if status != _WFIT_OK:
            return None
        info = J.T @ J
        info[6, 6] += prior_row * prior_row
        try:
            cov = var * np.linalg.inv(info)
        except np.linalg.LinAlgError:
            return None
        if (not np.all(np.isfinite(cov)) or np.linalg.cond(info) > 1e14
                or np.trace(cov[:3, :3]) > self.options.max_init_std_m ** 2
                or np.trace(cov[3:6, 3:6]) > self.options.max_init_speed_std ** 2):
            return None
        cov = 0.5 * (cov + cov.T)
        return th.tolist(), cov.ravel().tolist(), residuals

    def _prior_var(self, n: int, residuals, var: float) -> float:
        """The scale of the pixel variance's prior at a start: the start's variance
        ``var``, or (``window_noise_prior``) the window's own upper confidence bound of its
        residual variance if that is smaller: ``‖r‖² / χ²_{0.001}(2n - 6)`` (99.9 %, the
        level of the start's own χ² test; :func:`_chi2_lower`, exact), within the noise
        bounds (empirical Bayes). The stated noise stands unless the window shows it too
        large beyond doubt: on noise-free detections the prior's 0.5 px held the estimate
        near 0.16 px for ~0.2 s (worse than type A at 120-240 fps); a 95 % bound fell below a
        0.3 px detector's noise on some starts (one in twenty), whose detections the
        estimate then gated out."""
        if not self.options.window_noise_prior or n <= 3:
            return var
        bound = float(np.sum(residuals * residuals)) / _chi2_lower(2 * n - 6)
        return min(var, max(bound, self._var_min))

    def _window_var(self, n: int, residuals) -> float:
        """The pixel variance :meth:`_window_noise` would give after a start of ``n``
        detections with these residuals (the state unchanged)."""
        var = self._start_var()
        if self.options.adapt_rate == 0.0:
            return var
        var = self._prior_var(n, residuals, var)
        decay = (1.0 - self.options.adapt_rate) ** n
        alpha = decay * self.options.noise_prior_weight + (n - 3)
        beta = (decay * self.options.noise_prior_weight * var
                + 0.5 * float(np.sum(residuals * residuals)))
        return min(max(beta / alpha, self._var_min), self._var_max)

    def _fit(self, window, ballistic: bool = True):
        """Fit of the window's detections at the newest one's time, ballistic (gravity and
        drag) or supported (the supported model's drag alone): ``(x (6,), P (6x6 flat
        list), pixel residuals)``, or None when it is not trustworthy, or ``_SHORT`` when it
        passes every test but the velocity's uncertainty (:func:`_window_fit`, compiled)."""
        t_ref = window[-1][0]
        n = len(window)
        tau = np.array([(w[0] - t_ref) / NS for w in window])
        rays = [self._ray(*w) for w in window]
        O = np.array([o for o, _ in rays])
        D = np.array([d for _, d in rays])
        cam = np.array([w[1] for w in window], dtype=np.int64)
        uv = np.array([w[2:] for w in window])
        theta, cov, residuals = np.empty(6), np.empty((6, 6)), np.empty(n)
        var = self._start_var()
        try:
            status = _window_fit(
                self._cam_table, cam, uv, tau, O, D,
                self._g_array if ballistic else _ZERO3,
                self._k if ballistic else self.options.supported_drag_per_m,
                var, self._gate, _chi2_quantile(2 * n - 6), self.options.max_init_std_m ** 2,
                self.options.max_init_speed_std ** 2, theta, cov, residuals)
        except np.linalg.LinAlgError:  # a singular normal matrix, a non-finite system
            return None
        if status == _WFIT_NONE:
            return None
        if status == _WFIT_SHORT:
            return _SHORT  # too short a window (or mostly one camera's): more detections
        if status == _WFIT_WEAK:
            return _WEAK
        return theta.tolist(), cov.ravel().tolist(), residuals



def window_jump_cov(J, tau, rate_var: float) -> np.ndarray:
    """The position covariance (3 x 3, m²) of a window fit's error at its newest detection
    from velocity jumps inside the window. ``J`` (2n x 6): the fit's pixel Jacobian, rows
    ``2j, 2j + 1`` ``[B_j, τ_j B_j]`` (``B_j`` the pixel's derivative by the position);
    ``tau`` (n,): the detections' times before the newest (ascending, the newest 0);
    ``rate_var``: ``λ_j σ_j²`` (m²/s³).

    A jump ``Δv`` at ``s`` (``u = t_n - s``) moves detection ``j``'s pixel by ``B_j Δv (τ_j +
    u)`` where ``τ_j > -u`` (after the jump), and the state at ``t_n`` by ``(u Δv, Δv)``; the
    least-squares fit ``θ̂ = G Jᵀ z`` (``G = (JᵀJ)⁻¹``) is then off by ``A(u) Δv``,

        A(u) = G Σ_{τ_j > -u} J_jᵀ B_j (τ_j + u) − [u I; I],

    zero before the window's first detection (the whole window sees the new velocity, a
    path the fit represents exactly), linear in ``u`` between two detections. Jumps a
    Poisson process of rate ``λ_j`` with ``Δv ~ N(0, σ_j² I)`` (the kick's shape: the
    compound Poisson process's second moment, any number of jumps) give

        Q = λ_j σ_j² ∫_0^{-τ_0} A(u) A(u)ᵀ du,

    integrated exactly per interval (``A = A0 + u A1`` there); the position block returned.
    One detection after the jump (the newest alone, ``u`` < its gap) gives the unseen
    jump of one camera alone, ``λ_j σ_j² T³/3 · d dᵀ`` along its ray ``d``, less what the
    fit's other detections pull back."""
    n = tau.shape[0]
    G = np.linalg.inv(J.T @ J)
    B = J[:, :3]
    # C_j = J_jᵀ B_j (6 x 3) per detection
    C = np.einsum("jai,jak->jik", J.reshape(n, 2, 6), B.reshape(n, 2, 3))
    Q = np.zeros((3, 3))
    eye = np.eye(3)
    sum_c = np.zeros((6, 3))
    sum_ct = np.zeros((6, 3))
    for k in range(n - 1, 0, -1):  # jumps between detections k - 1 and k: k.. see it
        sum_c += C[k]
        sum_ct += C[k] * tau[k]
        ua, ub = -tau[k], -tau[k - 1]
        if not ub > ua:
            continue
        a0 = (G @ sum_ct)[:3]          # position rows of A0 (its [0; I] term is velocity's)
        a1 = (G @ sum_c)[:3] - eye     # and of A1
        Q += (a0 @ a0.T * (ub - ua) + (a0 @ a1.T + a1 @ a0.T) * (ub * ub - ua * ua) / 2.0
              + a1 @ a1.T * (ub ** 3 - ua ** 3) / 3.0)
    return rate_var * 0.5 * (Q + Q.T)


#: A restart's fit takes the lost track's prediction as a prior when the two agree: their
#: difference's NIS at most this (χ²₆'s 99.9 % quantile, :func:`_with_prior`).
_PRIOR_GATE = 22.458


def _with_prior(x, P, prior, prior_P):
    """A restart's window fit ``(x, P)`` (``x`` of 6 or 7 values, ``P`` flat) with the lost
    track's prediction ``prior`` (position, velocity; 6 and 6 x 6 flat) as a pseudo-
    measurement of its position and velocity (Bar-Shalom, Li & Kirubarajan 2001, §3.4:
    a prior is a measurement; the window's detections and the lost track's are distinct,
    so the two are independent): ``H = [I₆ 0]``, ``K = P Hᵀ (H P Hᵀ + P_prior)⁻¹``,
    ``x += K (prior - H x)``, ``P -= K H P``, when they agree: ``dᵀ (H P Hᵀ + P_prior)⁻¹ d
    <= _PRIOR_GATE`` (``d = prior - H x``; a kick or a bounce while the track was lost
    makes them disagree, and the window's fit stands alone). Returns ``(x, P)`` as lists
    (unchanged when they disagree or the sum is singular)."""
    n = len(x)
    xa = np.asarray(x, dtype=np.float64)
    Pa = np.asarray(P, dtype=np.float64).reshape(n, n)
    Pr = np.asarray(prior_P, dtype=np.float64).reshape(6, 6)
    d = np.asarray(prior, dtype=np.float64) - xa[:6]
    Sd = Pa[:6, :6] + Pr
    try:
        Si = np.linalg.inv(Sd)
    except np.linalg.LinAlgError:
        return x, P
    nis = float(d @ Si @ d)
    if not (np.all(np.isfinite(Si)) and nis <= _PRIOR_GATE):
        return x, P
    K = Pa[:, :6] @ Si
    xn = xa + K @ d
    Pn = Pa - K @ Pa[:6, :]
    Pn = 0.5 * (Pn + Pn.T)
    return xn.tolist(), Pn.ravel().tolist()


def accel_floor(rig: Rig, options: FilterOptions) -> float:
    """The floor (and start) of the adapted process noise ``q``, m²/s³: ``accel_psd``, or
    when it is None ``accel_step_var R``, ``R = Σ fps`` the rig's detections per second.

    Session 11 (issue 10, ``docs/methods.md``, "The floor of q"): ``q``'s floor is the
    model error the filter allows while its innovations look white; with continuous white
    noise acceleration of density ``q`` the velocity variance added between two detections
    is ``q T`` (Bar-Shalom, Li & Kirubarajan 2001, §6.2.2), so this floor allows the same
    velocity variance per mean detection interval ``T = 1 / Σ fps`` on every rig (per actual
    interval on staggered shutters; synchronised shutters' detections share an instant, so
    each instant gets the variance of its cameras' intervals together). A fixed 0.01 m²/s³ left the
    filter at 0.52-0.61 of ``typeA`` on two cameras at 30 fps (the floor, not the jumps or
    the start, per phase); a fixed 0.001 fixed those and cost the turning motions at 120-240
    fps up to 2.4 x (the turn model's set switches on ``q``)."""
    if options.accel_psd is not None:
        return float(options.accel_psd)
    rate = sum(float(c.fps) for c in rig.cameras)
    return options.accel_step_var * rate


def turn_on_threshold(rig: Rig, options: FilterOptions) -> float:
    """The adapted process noise ``q`` at which the turn model joins the model set (and the
    pair rejoins it, and below which the turn model may leave), m²/s³: ``turn_on_psd``, or
    when it is None ``turn_on_accel2 / R``, ``R = Σ fps`` the rig's detections per second.

    Session 12 (issue 10, ``docs/methods.md``, "The turn model's switch and the rate"): the
    switch is meant for an acceleration the pair lacks, but ``q`` is no acceleration: the
    adaptation raises ``q`` until consecutive innovations stop agreeing, i.e. until the
    lag a missing acceleration ``a`` causes is a fixed fraction of the pixel noise. For a
    white-noise-acceleration filter in steady state the lag under a constant ``a`` is
    ``b = a T² / β`` (Bar-Shalom, Li & Kirubarajan 2001, section 6.5, steady-state α-β
    filters; Kalata, "The tracking index: a generalized parameter for α-β and α-β-γ target
    trackers", IEEE Trans. AES 20(2), 1984), with ``β ≈ Λ`` for a small tracking index
    ``Λ = sqrt(q T³) / σ``
    (``T = 1/R`` the detection interval, ``σ`` the measurement noise): ``b ∝ σ`` gives
    ``q ∝ a² T``, the same acceleration settling at a ``q`` eight times smaller at 240 fps
    than at 30. A fixed threshold switched on at accelerations growing as ``sqrt(R)``:
    two cameras at 240 fps gave the turntable to the pair alone (0.52 of ``typeA``)."""
    if options.turn_on_psd is not None:
        return float(options.turn_on_psd)
    rate = sum(float(c.fps) for c in rig.cameras)
    return options.turn_on_accel2 / rate


def _posterior(prior: float, log_ratio: float, low: float, high: float) -> float:
    """A model's probability from its prior and its log likelihood ratio against the
    alternative, bounded to ``[low, high]``."""
    odds = prior / (1.0 - prior) * math.exp(min(max(log_ratio, -50.0), 50.0))
    return min(max(odds / (1.0 + odds), low), high)


@functools.lru_cache(maxsize=256)
def _chi2_lower(dof: int, p: float = 0.001) -> float:
    """The ``p`` quantile of the chi-square distribution of an even number ``dof`` of degrees
    of freedom, exact: ``P(χ²_{2m} <= x) = 1 - e^{-x/2} Σ_{j<m} (x/2)^j / j!`` (Abramowitz
    & Stegun 1964, 26.4.21) solved by bisection to a relative 1e-12."""
    m = dof // 2

    def cdf(x: float) -> float:
        h, term, total = 0.5 * x, 1.0, 1.0
        for j in range(1, m):
            term *= h / j
            total += term
        return 1.0 - math.exp(-h) * total

    lo, hi = 0.0, float(dof)
    while cdf(hi) < p:
        hi *= 2.0
    while hi - lo > 1e-12 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < p else (lo, mid)
    return 0.5 * (lo + hi)


def _chi2_quantile(dof: int, z: float = 3.09) -> float:
    """The chi-square quantile of ``dof`` degrees of freedom at the normal quantile ``z``
    (3.09: 99.9 %), by the Wilson-Hilferty approximation: above the exact quantile at
    every dof, by 2.3 % at 2 dof (14.13 against 13.82), 1.4 % at 4 and below 1 % from 6 on
    (``tests/test_chi2_thresholds.py``; before session 23 this said "within 2 % from 2 dof
    on")."""
    if dof <= 0:
        return math.inf
    a = 2.0 / (9.0 * dof)
    return dof * (1.0 - a + z * math.sqrt(a)) ** 3


class FilterStream:
    """The streaming form for :class:`~pslog.fusion.stream.StreamFuser`: detections (true
    times, (time, camera) order) in, the Track of their points out; :attr:`filter` is the
    :class:`BallFilter` (``predict`` to "now").

    With ``hold_nis`` (``FusionOptions.filter_hold_nis``) a held point stays pending across
    pushes (:class:`_Hold`) until the detection that decides it arrives, and every later
    point waits behind it, so the points leave in the batch's order; :meth:`flush` decides
    what is still pending as the batch decides it at the session's end (withdrawn): every
    push's and the flush's Tracks joined are :func:`fuse_filter`'s, for any chunking."""

    def __init__(self, rig: Rig, options) -> None:
        hold_nis = options.filter_hold_nis
        self.filter = BallFilter(rig, FilterOptions(max_gap_s=options.max_gap_s,
                                                    hold_nis=hold_nis))
        # the points held for the next camera and those behind them (None: no hold)
        self._hold = None if hold_nis is None else _Hold()
        # the gate's doubt of the rows of the next push (StreamFuser sets it; None: none): a
        # choice in doubt is left out, as the batch leaves it out (:func:`fuse_filter`)
        self.next_doubt: np.ndarray | None = None
        # the Track of a detection without a point and nothing withheld (Tracks are frozen:
        # one, shared; the empty columns of a withheld point's Track, push_one's)
        time, position, camera, quality = _NO_POINT
        self._none = Track._of_frozen("filter", time, position, camera, dict(quality), {})

    def push(self, time_ns, camera, uv, frame_index=None) -> Track:
        doubt, self.next_doubt = self.next_doubt, None
        return _track(self.filter, time_ns, camera, uv, doubt, self._hold, final=False)

    def flush(self) -> Track:
        """The points still held or waiting behind a held one (end of stream): the held ones
        withdrawn (``held``), as the batch withdraws them at the end of its detections."""
        hold = self._hold
        if hold is None or not hold.k:
            return self._none
        return _track(self.filter, np.zeros(0, np.int64), np.zeros(0, np.int64),
                      np.zeros((0, 2)), None, hold, final=True)

    def push_one(self, time_ns: int, camera: int, u: float, v: float) -> Track:
        """One detection (Python int, int, float, float; checked by the caller): the Track
        :meth:`push` gives for it (the same columns, the same bits: ``_run``'s step, then a
        one-row Track built from Python floats, not from a table of rows)."""
        flt = self.filter
        if self.next_doubt is not None:
            doubt, self.next_doubt = self.next_doubt, None
            if doubt[0] > 0:  # a choice in doubt: left out (_track)
                time, position, camera_, quality = _NO_POINT
                return Track._of_frozen("filter", time, position, camera_, dict(quality),
                                        {DOUBT: 1})
        I, out = flt._I, flt._out
        dropped = int(I[_IDROPC]), int(I[_IDROPU])
        if self._hold is not None:
            return self._held_one(time_ns, camera, u, v, dropped)
        status = _step(flt._S, I, flt._cam_table, flt._opts, flt._nopts, time_ns, camera, u,
                       v, out)
        point = status == _POINT or (status != _NONE and flt._fitted(status, out))
        if dropped != (int(I[_IDROPC]), int(I[_IDROPU])):  # a point withheld (counted)
            counts = _withheld_since(flt, dropped)
        elif not point:
            return self._none
        else:
            counts = {}
        if not point:
            time, position, camera_, quality = _NO_POINT
            return Track._of_frozen("filter", time, position, camera_, dict(quality), counts)
        return _one_point(time_ns, camera, out.tolist(), counts)

    def _held_one(self, time_ns: int, camera: int, u: float, v: float,
                  dropped: tuple[int, int]) -> Track:
        """:meth:`push_one` with the hold (:func:`_step_held`): the points that leave with
        this detection (the held ones it released, and the points behind them; its own
        unless held), the withdrawn ones counted (``held``)."""
        flt, hold = self.filter, self._hold
        assert hold is not None
        I, out = flt._I, flt._out
        status, n_emit, n_gone, k, own = _step_held(
            flt._S, I, flt._cam_table, flt._opts, flt._nopts, time_ns, camera, u, v, out,
            hold.P, hold.R, hold.T)
        if status != _POINT and status != _NONE:  # (a window fit: the rare path)
            if k + 2 > hold.capacity:  # (room for the next one's row)
                hold.grow()
            return self._held_fit(time_ns, camera, status, dropped)
        counts: dict[str, int] = {}
        if dropped != (int(I[_IDROPC]), int(I[_IDROPU])):  # a point withheld (counted)
            counts = _withheld_since(flt, dropped)
        if n_gone:
            counts[HELD] = n_gone
        if own:  # (as without the hold)
            track = _one_point(time_ns, camera, out.tolist(), counts)
        elif n_emit == 1:
            track = _one_point(int(hold.etime[0]), int(hold.ecam[0]),
                               hold.emit[0].tolist(), counts)
        elif n_emit:
            track = _rows_track(hold.emit[:n_emit].copy(), hold.etime[:n_emit].copy(),
                                hold.ecam[:n_emit].copy(), 0, counts)
        elif not counts:
            track = self._none
        else:
            time, position, camera_, quality = _NO_POINT
            track = Track._of_frozen("filter", time, position, camera_, dict(quality), counts)
        # (room for the next one's row: grown after the rows leaving were read, as grow
        # copies only the waiting ones)
        if k + 2 > hold.capacity:
            hold.grow()
        return track

    def _held_fit(self, time_ns: int, camera: int, status: int,
                  dropped: tuple[int, int]) -> Track:
        """:meth:`_held_one`'s window fit: the held points withdrawn (the kernel's
        ``index``), the fit's point (if any) behind the waiting rows, then as a push."""
        flt, hold = self.filter, self._hold
        assert hold is not None
        out = flt._out
        point = flt._fitted(status, out)
        k = hold.k
        rows, time, cams = (np.concatenate([a, b]) for a, b in zip(
            hold.waiting(), (out[None, :] if point else np.zeros((0, _OUT_COLS)),
                             np.array([time_ns] * point, np.int64),
                             np.array([camera] * point, np.int64)), strict=True))
        index = np.concatenate([hold.index[:k], np.arange(k, k + point, dtype=np.int64)])
        if point and flt._holds_start(out, hold.n):  # (row k: behind those waiting)
            n = hold.n
            hold.pr[n], hold.pc[n], hold.pb[n] = k, camera, _START_PB
            hold.n = n + 1
        return _rows_track(*hold.settle(rows, time, cams, index, final=False),
                           _withheld_since(flt, dropped))


def _withheld_since(flt: BallFilter, dropped: tuple[int, int]) -> dict[str, int]:
    """The points ``flt`` withheld since its counts were ``dropped`` (unconfirmed,
    uncertain), by reason."""
    before = dict(zip(("unconfirmed", "uncertain"), dropped, strict=True))
    return {k: n - before[k] for k, n in flt.dropped.items() if n > before[k]}


class _Hold:
    """The points a streaming filter holds for the next camera (``hold_nis``), kept across
    pushes: the held ones' rows ``pr[:n]`` (among the waiting rows), cameras ``pc`` and
    accepted detections of their camera since ``pb`` (:func:`_held`), and the output rows
    from the first held one on (the first :attr:`k` of :attr:`rows`, (capacity,
    _OUT_COLS); their detections' :attr:`time` and :attr:`camera`), which leave in order
    once no held point precedes them. ``H``: [held, waiting, leaving, withdrawn] of the
    one-detection step (:func:`_step_held`, whose ``emit`` rows are those leaving)."""

    def __init__(self) -> None:
        m = _HOLD_MAX
        # (packed for :func:`_step_held`: P = (H, pr, pc, pb), R = (rows, emit), T = (time,
        # camera, index, etime, ecam); the names below are views)
        self.P = np.zeros(4 + 3 * m, np.int64)
        self.H, self.pr = self.P[0:4], self.P[4:4 + m]
        self.pc, self.pb = self.P[4 + m:4 + 2 * m], self.P[4 + 2 * m:]
        self.capacity = 0
        self.R: np.ndarray = np.empty((2, 0, _OUT_COLS))
        self.T: np.ndarray = np.empty((5, 0), np.int64)
        self.rows: np.ndarray = self.R[0]
        self.time: np.ndarray = self.T[0]
        self.grow(16)

    @property
    def n(self) -> int:
        """The points held."""
        return int(self.H[0])

    @n.setter
    def n(self, value: int) -> None:
        self.H[0] = value

    @property
    def k(self) -> int:
        """The rows waiting (the held ones and those behind them)."""
        return int(self.H[1])

    def grow(self, capacity: int | None = None) -> None:
        """Room for ``capacity`` rows (None: twice the present), the waiting ones kept."""
        k = self.k if self.capacity else 0
        capacity = capacity or 2 * self.capacity
        R, T = np.empty((2, capacity, _OUT_COLS)), np.empty((5, capacity), np.int64)
        if k:
            R[0, :k], T[:2, :k] = self.R[0, :k], self.T[:2, :k]
        self.R, self.T = R, T
        self.capacity = capacity
        self.rows, self.emit = R[0], R[1]
        self.time, self.camera, self.index, self.etime, self.ecam = T[0], T[1], T[2], T[3], T[4]

    def waiting(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The waiting rows (k, _OUT_COLS), their detections' times and cameras (k,)."""
        k = self.k
        return self.rows[:k], self.time[:k], self.camera[:k]

    def settle_all(self, index: np.ndarray) -> int:
        """:meth:`settle` with ``final`` of a push's rows whose ``index`` (n,) is given:
        the held ones withdrawn (``index`` made negative), none left waiting; returns how
        many are withdrawn (every row with a negative ``index``; the others leave)."""
        for k in range(self.n):
            index[self.pr[k]] = -1 - index[self.pr[k]]
        self.n = 0
        self.H[1] = 0
        return int(np.count_nonzero(index < 0))

    def settle(self, rows: np.ndarray, time: np.ndarray, camera: np.ndarray,
               index: np.ndarray, final: bool
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """The rows (n, _OUT_COLS) of a push (the waiting ones first), their detections'
        ``time`` and ``camera`` (n,) and ``index`` (n,: negative for a withdrawn one): those
        before the first still held leave (``final``: every one, the held ones withdrawn),
        the rest wait. Returns ``(rows, time, camera, withdrawn)`` of those leaving."""
        if final:
            for k in range(self.n):
                index[self.pr[k]] = -1 - index[self.pr[k]]
            self.n = 0
        n = self.n
        withdrawn = index < 0
        n_held = int(np.count_nonzero(withdrawn))
        first = int(self.pr[:n].min()) if n else len(index)
        wait = first + np.flatnonzero(~withdrawn[first:])
        # (a held row is never withdrawn: its new place among those waiting)
        self.pr[:n] = np.searchsorted(wait, self.pr[:n])
        if len(wait) + 2 > self.capacity:
            self.grow(2 * (len(wait) + 2))
        k = len(wait)
        self.rows[:k], self.time[:k], self.camera[:k] = rows[wait], time[wait], camera[wait]
        self.H[1] = k
        keep = ~withdrawn[:first]
        if n_held or first < len(index):
            rows, time, camera = rows[:first][keep], time[:first][keep], camera[:first][keep]
        return rows, time, camera, n_held


def _frozen_empty() -> tuple:
    """Empty columns of a filter Track, read-only (as Track freezes them), shared."""
    columns: list[np.ndarray] = [np.zeros(0, np.int64), np.zeros((0, 3)),
                                 np.zeros(0, np.int32), np.zeros(0)]
    for c in columns:
        c.setflags(write=False)
    return (*columns[:3], dict.fromkeys(FILTER_QUALITY, columns[3]))


_NO_POINT = _frozen_empty()


def _one_point(time_ns: int, camera: int, o: list, dropped: dict) -> Track:
    """The Track of one point: ``o`` the step's output row (``out.tolist()``), its columns
    as :func:`_track` makes them (lengths by ``math.hypot``, a start's residual as its fit
    gave it), every column a read-only view of one array of 14 floats."""
    init = o[15] == 1.0
    values = np.array((o[0], o[1], o[2], o[3], o[4], o[5], o[6], math.hypot(o[7], o[8]),
                       o[9] if init else math.hypot(o[9], o[10]), o[11], o[12], o[13], o[14],
                       o[15]))
    values.setflags(write=False)  # (its views inherit it)
    time = np.array((time_ns,), np.int64)
    time.setflags(write=False)
    cam = np.array((camera,), np.int32)
    cam.setflags(write=False)
    return Track._of_frozen(
        "filter", time, values[:3].reshape(1, 3), cam,
        {"std_m": values[3:4], "std_x_m": values[4:5], "std_y_m": values[5:6],
         "std_z_m": values[6:7], "innovation_px": values[7:8], "residual_px": values[8:9],
         "nis": values[9:10], "gap_s": values[10:11], "jump": values[11:12],
         "rejected": values[12:13], "init": values[13:14]}, dropped)


#: Track.dropped's reason for a detection left out as a choice the gate put in doubt.
DOUBT = "doubt"
#: ``Track.dropped``'s reason for a point the batch held for the next camera and withdrew
HELD = "held"


def _track(flt: BallFilter, time_ns, camera, uv, doubt: np.ndarray | None = None,
           hold: _Hold | None = None, final: bool = True) -> Track:
    """The Track of the points of detections pushed into ``flt``: one compiled loop
    (:func:`_run`) over them, back in Python only for a window fit. ``doubt`` (n,) the
    gate's doubt of each detection (:func:`pslog.fusion.gating.choice_doubt`; None: none):
    a detection in doubt is left out, counted in ``dropped`` as ``doubt`` (docs/methods.md,
    "The filter and a choice in doubt"). ``hold``: the points held for the next camera
    (``hold_nis``) and those waiting behind them, kept across calls (the stream's; None: a
    new one, the batch's); ``final`` False leaves those still held waiting in it, True
    withdraws them (the end of the session)."""
    times = np.ascontiguousarray(time_ns, dtype=np.int64).reshape(-1)
    cameras = np.ascontiguousarray(camera, dtype=np.int64).reshape(-1)
    uv = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
    if not len(times) == len(cameras) == len(uv):
        raise ValueError("time_ns, camera and uv differ in length")
    n_doubt = 0
    if doubt is not None:
        doubted = np.asarray(doubt, dtype=np.float64).reshape(-1) > 0
        if len(doubted) != len(times):
            raise ValueError("doubt differs in length from the detections")
        n_doubt = int(np.count_nonzero(doubted))
        if n_doubt:
            keep = ~doubted
            times, cameras = np.ascontiguousarray(times[keep]), np.ascontiguousarray(
                cameras[keep])
            uv = np.ascontiguousarray(uv[keep])
    if hold is None:  # (the batch's: every point decided at its end)
        hold, final = _Hold(), True
    waiting = hold.k
    if waiting:  # the rows still waiting from earlier pushes, first (their detections done)
        w_rows, w_time, w_camera = hold.waiting()
        times = np.concatenate([w_time, times])
        cameras = np.concatenate([w_camera, cameras])
        uv = np.concatenate([np.zeros((waiting, 2)), uv])
    # (read-only views, whoever's the arrays: _run is given one type of them, so one
    # compiled signature serves fuse, the stream and the library's callers, and pslog.warm
    # compiles it)
    times, cameras, uv = times.view(), cameras.view(), uv.view()
    times.flags.writeable = cameras.flags.writeable = uv.flags.writeable = False
    n = len(times)
    before = flt.dropped
    rows = np.empty((n, _OUT_COLS))
    index = np.empty(n, dtype=np.int64)
    if waiting:
        rows[:waiting] = w_rows
        index[:waiting] = np.arange(waiting)
    i = n_out = waiting
    pn = hold.n
    args = (flt._S, flt._I, flt._cam_table, flt._opts, flt._nopts, times, cameras, uv)
    while i < n:
        i, n_out, status, pn = _run(*args, i, rows, index, n_out, hold.pr, hold.pc, hold.pb,
                                    pn)
        if status == _NONE:
            break
        if flt._fitted(status, rows[n_out]):  # the rare path: a window fit
            index[n_out] = i
            if flt._holds_start(rows[n_out], pn):  # (pn 0: the fit withdrew the held ones)
                hold.pr[pn], hold.pc[pn], hold.pb[pn] = n_out, cameras[i], _START_PB
                pn += 1
            n_out += 1
        i += 1
    hold.n = pn
    rows, index = rows[:n_out], index[:n_out]
    dropped = {k: n - before.get(k, 0) for k, n in flt.dropped.items()
               if n > before.get(k, 0)}
    if n_doubt:
        dropped[DOUBT] = n_doubt
    if final and _hypot_compiled():
        # (the end: every row leaves but the withdrawn; their columns made in one pass)
        return _kept_track(rows, index, times, cameras, hold.settle_all(index), dropped)
    source = np.abs(index) - (index < 0)  # each row's detection (a withdrawn one's -1 - i: i)
    rows, time, cams, n_held = hold.settle(rows, times[source], cameras[source], index, final)
    return _rows_track(rows, time, cams, n_held, dropped)


def _kept_track(rows: np.ndarray, index: np.ndarray, times: np.ndarray, cameras: np.ndarray,
                n_held: int, dropped: dict[str, int]) -> Track:
    """:func:`_rows_track` of the rows (n, _OUT_COLS) whose ``index`` (n,) is not negative,
    their detections' times and cameras at ``index`` of ``times``, ``cameras``: the same
    Track (its columns made by :func:`_kept_columns`, where :func:`_hypot_compiled`)."""
    k = len(index) - n_held
    q = np.empty((len(FILTER_QUALITY), k))
    position, time, cams = np.empty((k, 3)), np.empty(k, np.int64), np.empty(k, np.int32)
    made = _kept_columns(np.ascontiguousarray(rows), np.ascontiguousarray(index, np.int64),
                         times, cameras, q, position, time, cams)
    assert made == k
    return _frozen_track(time, position, cams, q, n_held, dropped)


def _frozen_track(time: np.ndarray, position: np.ndarray, cams: np.ndarray, q: np.ndarray,
                  n_held: int, dropped: dict[str, int]) -> Track:
    """The filter's Track of its columns (``q``: (len(FILTER_QUALITY), n), one row per
    quality column), made read-only as Track keeps them (no check, no copy), with ``n_held``
    points withdrawn (``held``) added to ``dropped``."""
    for c in (time, position, cams, q):
        c.setflags(write=False)
    if n_held:
        dropped = {**dropped, HELD: n_held}
    return Track._of_frozen("filter", time, position, cams,
                            dict(zip(FILTER_QUALITY, q, strict=True)), dropped)


def _rows_track(rows: np.ndarray, time: np.ndarray, camera: np.ndarray, n_held: int,
                dropped: dict[str, int]) -> Track:
    """The Track of the filter's output ``rows`` (n, _OUT_COLS), their detections' ``time``
    and ``camera`` (n,), with ``dropped`` and ``n_held`` points withdrawn (``held``)."""
    n_out = len(rows)
    # one row per quality column: each column a contiguous array, read-only as Track keeps
    # it (made here as Track's checks would leave it: no check, no copy)
    q = np.empty((len(FILTER_QUALITY), n_out))
    q[0:4] = rows[:, 3:7].T
    # lengths as CPython's math.hypot takes them, as the pure-Python filter did; a start's
    # residual as its fit gave it
    if _hypot_compiled():
        _lengths(rows, q)
    else:  # another CPython's hypot (the kernel repeats 3.11's): its own, mapped
        hypot = math.hypot
        q[4] = np.fromiter(map(hypot, rows[:, 7].tolist(), rows[:, 8].tolist()), np.float64,
                           n_out)
        q[5] = np.fromiter(map(hypot, rows[:, 9].tolist(), rows[:, 10].tolist()), np.float64,
                           n_out)
        init = rows[:, 15] == 1.0
        q[5, init] = rows[init, 9]
    q[6:] = rows[:, 11:16].T
    time, position = np.array(time, np.int64), np.ascontiguousarray(rows[:, :3])
    cams = camera.astype(np.int32)
    return _frozen_track(time, position, cams, q, n_held, dropped)


def fuse_filter(obs: Observations, rig: Rig, max_gap_s: float | None = None,
                options: FilterOptions | None = None, doubt: np.ndarray | None = None
                ) -> Track:
    """The ``filter`` track of observations (true times, sorted by (time, camera)): the
    same per-detection code as the streaming form, so the same points. ``doubt`` (n,):
    the gate's doubt of each observation (:attr:`pslog.fusion.Prepared.doubt_px2`; None:
    none): a choice in doubt is left out (:func:`_track`)."""
    options = options or FilterOptions()
    if max_gap_s is not None and options.max_gap_s is None:
        from dataclasses import replace

        options = replace(options, max_gap_s=max_gap_s)
    return _track(BallFilter(rig, options), obs.time_ns, obs.camera, obs.uv, doubt)


def _preload() -> None:
    """The batch filter's kernels loaded from numba's cache (or compiled) now, in the
    signatures :func:`_track` and its window fits call them with (read-only detection
    columns; C-contiguous float64 and int64 arrays; Python floats and ints): called by
    :func:`pslog._jit.preload` on its thread while ``pslog fuse`` reads its session, so that
    the filter's first calls do not pay the eight loads (~0.3 s of wall on a busy machine,
    where the compiler lock makes a load wait; the loads of the window fits bring in
    scipy's LAPACK bindings). Nothing runs: ``compile`` of a signature only loads it
    (tests/test_kernel_signatures.py: a filter run afterwards adds no signature)."""
    from numba import types

    f8, i8 = types.float64, types.int64

    def a(dtype, ndim: int, readonly: bool = False):
        return types.Array(dtype, ndim, "C", readonly=readonly)

    v, m, iv = a(f8, 1), a(f8, 2), a(i8, 1)
    _run.compile((v, iv, m, v, iv, a(i8, 1, True), a(i8, 1, True), a(f8, 2, True), i8, m,
                  iv, i8, iv, iv, iv, i8))
    _window_fit.compile((m, iv, m, v, m, m, v, f8, f8, f8, f8, f8, f8, v, m, v))
    _turn_window_fit.compile((m, iv, m, v, v, f8, f8, f8, f8, f8, v, m, v, f8))
    _pixel_rows.compile((m, iv, m, v, v, v, m, v))
    _combined_point.compile((v, v, v, v, f8))
    _point.compile((v, *(f8,) * 15))
    _withheld.compile((iv, v, f8))
    _lengths.compile((m, m))
    _kept_columns.compile((m, iv, a(i8, 1, True), a(i8, 1, True), m, m, iv,
                           a(types.int32, 1)))
