# The pure-Python filter as it was before its step was compiled (session 6), kept verbatim
# (imports made absolute; the jump replay's gravity weight mended as in pslog/fusion/filter.py)
# as the reference benchmarks/filter_equality.py compares the compiled filter with.
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
- two motion models mixed by an interacting multiple model (Blom & Bar-Shalom 1988;
  Bar-Shalom et al. section 11.6): ballistic (the above) and *supported* (the same without
  gravity: a ball rolling on the floor, carried, swung), switching at rate
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
  ``q`` reaches ``turn_on_psd`` (an acceleration the pair lacks), leaves when unlikely or
  its ``ω`` is within 2σ of 0; the pair leaves while the turn model alone explains the
  motion and rejoins when ``q`` grows again or at a jump. So a flight pays for one model
  set and a circle for the other, not both;
- the pixel noise ``σ`` adapts to the detector's (``E[NIS] = 2``); the process noise ``q``
  adapts to the motion: a consistent filter's innovations are white, a lagging one's
  consecutive innovations of a camera agree, so ``q`` grows with their product (a spiral, a
  straight line without gravity, a turntable) and shrinks back to ``accel_psd`` on a flight;
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
  prediction). After ``max_rejects`` consecutive rejections, or a time without an accepted
  detection longer than ``max_gap_s``, the track is lost;
- (re)initialisation: from a short window of the latest detections (at least
  ``init_detections`` of two cameras or more, within ``max_gap_s`` of each other): a
  ballistic least-squares fit (gravity and drag) to their viewing rays, refined by
  Gauss-Newton in distorted pixels; accepted when every detection reprojects inside the gate.
  A window too short in time to pin the velocity (``init_window`` detections at 60 fps and
  above) grows by the next detections until its fit passes (``init_span_s``).

- withheld points (counted in ``Track.dropped`` by reason, the state updated all the same):
  ``unconfirmed``, from a jump (or an update of NIS above ``confirm_nis``) until two more
  accepted updates, one at least from another camera, confirm it (one camera's pixel does
  not fix the new velocity along its rays); ``uncertain``, ``std_m`` above ``max_std_m``.

Causality: the point of a detection uses only the detections up to it in (time, camera)
order; batch (:func:`fuse_filter`) and streaming run the same per-detection code, so the
streaming form (:class:`FilterStream`, used by :class:`~pslog.fusion.stream.StreamFuser`)
gives exactly the batch points.

Per-point quality (columns of the Track, NaN where not applicable):

- ``std_m``: position standard deviation ``sqrt(trace P_pp)`` after the update, metres (as
  ``smooth``); ``std_x_m``, ``std_y_m``, ``std_z_m`` per axis;
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

import math
from dataclasses import dataclass

import numpy as np

from pslog.errors import FusionError
from pslog.motion import Ball, G
from pslog.records import NS, Observations, Track
from pslog.rig import Rig

#: Quality columns of a ``filter`` track, in order (module docstring).
FILTER_QUALITY = ("std_m", "std_x_m", "std_y_m", "std_z_m", "innovation_px", "residual_px",
                  "nis", "gap_s", "jump", "rejected", "init")
#: Pixels farther than this many image sizes from the image are not detections (as prepare).
_FAR_IMAGES = 10
#: A point closer than this to a camera's plane (metres) is not in front of it.
_MIN_DEPTH_M = 1e-3
_NAN = float("nan")
#: A jump is looked for before this many accepted detections back (and at the newest one).
_JUMP_LAG = 2
#: A track whose first detections after its start include a rejected one is dropped (no
#: point from it) until this many were accepted.
_CONFIRM = 2
#: A bounce's velocity jump across the floor's normal, in variance relative to along it.
_BOUNCE_SIDE = 0.05
#: A floor bounce's velocity about its expected reflection: standard deviations along
#: gravity and across, m/s.
_REFLECT_ALONG, _REFLECT_SIDE = 1.0, 0.6
#: The process noise's adaptation statistic is clipped to this (an outlier moves q little).
_R_CLIP = 4.0
#: The ballistic model's probability at a track's start (its window is fitted ballistically).
_INIT_BALLISTIC = 0.9
#: Bound of one detection's log likelihood ratio between the models (an outlier moves μ little).
_LOG_ODDS_CLIP = 4.0
_ZERO6 = (0.0,) * 6
#: What :meth:`BallFilter._fit` returns for a fit whose velocity alone is too uncertain.
_SHORT = "short"
#: A fit whose residuals pass but whose position is too uncertain (session 10).
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
    accel_psd : float, spectral density ``q`` of the white-noise acceleration (drag error,
        spin, model error), m²/s³
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
    adapt_rate : float, step of the pixel noise's adaptation (0: ``noise_px`` fixed)
    min_noise_px, max_noise_px : float, bounds of the adapted pixel noise
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
        bound is ``accel_psd``)
    accel_adapt_rate : float, step ``η`` of ``q``'s adaptation (0: ``q`` fixed at
        ``accel_psd``)
    accel_adapt_target : float, the value ``r₀`` of the whiteness statistic ``q`` settles at
    model_switch_per_s : float, rate ``λ`` of switches between the ballistic model and the
        supported one (no gravity: a ball rolling, carried, on a string), 1/s; the models
        are mixed by an interacting multiple model (0: the ballistic model alone)
    max_init_speed_std : float, a (re)initialisation whose velocity standard deviation
        ``sqrt(trace P_vv)`` exceeds this is refused, m/s
    confirm_nis : float, an accepted update whose NIS exceeds this (99 % quantile of χ²₂)
        must be confirmed like a jump
    max_std_m : float or None, a point whose ``std_m`` exceeds this is withheld, metres
        (None: no bound)
    turn_switch_per_s : float, rate of switches between the turn model (a coordinated turn
        about the vertical: a ball swung, on a turntable, circling) and the other two, 1/s
        (0: no turn model; also none when gravity is not along the world's z)
    turn_on_psd : float, the turn model joins the model set when the adapted process noise
        ``q`` reaches this (an acceleration the other models lack), m²/s³
    turn_rate_psd : float, spectral density of the turn rate's random walk, rad²/s³
    turn_rate_std : float, standard deviation of the turn rate when the model joins, rad/s
    withhold : bool, withhold unconfirmed and uncertain points (counted in
        ``Track.dropped``); False: a point at every detection of a live track
    """

    noise_px: float = 0.5
    noise_prior_weight: float = 1.0
    adapt_rate: float = 0.02
    min_noise_px: float = 0.01
    max_noise_px: float = 5.0
    accel_psd: float = 0.01
    drag_per_m: float = Ball().drag_per_metre
    gravity: tuple[float, float, float] = (0.0, 0.0, -G)
    gate: float = 18.4
    jump_speed: float = 6.0
    bounce_shape: bool = True
    restitution: float = 0.7
    bounce_friction: float = 0.1
    max_rejects: int = 3
    init_detections: int = 4
    init_window: int = 8
    init_max_window: int = 64
    init_span_s: float = 0.03
    max_init_std_m: float = 0.05
    max_init_speed_std: float = 1.0
    confirm_nis: float = 9.21
    withhold: bool = True
    max_gap_s: float | None = None
    max_accel_psd: float = 100.0
    accel_adapt_rate: float = 0.5
    model_switch_per_s: float = 0.5
    accel_adapt_target: float = 0.4
    max_std_m: float | None = 0.03
    turn_switch_per_s: float = 0.5
    turn_on_psd: float = 0.3
    turn_rate_psd: float = 0.1
    turn_rate_std: float = 6.0

    def __post_init__(self) -> None:
        for name in ("noise_px", "accel_psd", "gate", "jump_speed"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise FusionError(f"filter {name} must be finite and > 0, got {value!r}")
        if not (math.isfinite(self.model_switch_per_s) and self.model_switch_per_s >= 0):
            raise FusionError(f"filter model_switch_per_s must be finite and >= 0, got "
                              f"{self.model_switch_per_s!r}")
        for name in ("turn_switch_per_s", "turn_rate_psd", "turn_rate_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise FusionError(f"filter {name} must be finite and >= 0, got {value!r}")
        if not self.turn_on_psd > 0:
            raise FusionError(f"filter turn_on_psd must be > 0, got {self.turn_on_psd!r}")
        if not (math.isfinite(self.drag_per_m) and self.drag_per_m >= 0):
            raise FusionError(f"filter drag_per_m must be finite and >= 0, got "
                              f"{self.drag_per_m!r}")
        if self.init_detections < 3 or self.init_window < self.init_detections:
            raise FusionError("filter init_detections must be >= 3 and init_window >= it, got "
                              f"{self.init_detections} and {self.init_window}")
        if self.init_max_window < self.init_window:
            raise FusionError("filter init_max_window must be >= init_window, got "
                              f"{self.init_max_window} and {self.init_window}")
        if not (math.isfinite(self.init_span_s) and self.init_span_s > 0):
            raise FusionError(f"filter init_span_s must be finite and > 0, got "
                              f"{self.init_span_s!r}")
        if self.max_rejects < 1:
            raise FusionError(f"filter max_rejects must be >= 1, got {self.max_rejects}")


class _Cam:
    """One camera's projection constants as plain floats (no numpy per detection)."""

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

    def project(self, px: float, py: float, pz: float):
        """Distorted pixel ``(u, v)`` of a world point and ``∂(u, v)/∂p`` as two rows of 3;
        None when the point is not in front of the camera."""
        r = self.r
        xc = r[0] * px + r[1] * py + r[2] * pz + self.t[0]
        yc = r[3] * px + r[4] * py + r[5] * pz + self.t[1]
        zc = r[6] * px + r[7] * py + r[8] * pz + self.t[2]
        if not zc > _MIN_DEPTH_M:
            return None
        iz = 1.0 / zc
        x, y = xc * iz, yc * iz
        if self.distorted:
            k1, k2, k3, p1, p2 = self.k1, self.k2, self.k3, self.p1, self.p2
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            dr = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
            xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
            yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
            d00 = radial + 2.0 * x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x
            d01 = 2.0 * x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y
            d11 = radial + 2.0 * y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x
            # A = K₂ · D (D symmetric: d10 = d01)
            a00, a01 = self.fx * d00 + self.s * d01, self.fx * d01 + self.s * d11
            a10, a11 = self.fy * d01, self.fy * d11
        else:
            xd, yd = x, y
            a00, a01, a10, a11 = self.fx, self.s, 0.0, self.fy
        u = self.fx * xd + self.s * yd + self.cx
        v = self.fy * yd + self.cy
        # M = A · ∂(x, y)/∂X_c, then H = M · R
        m00, m01, m02 = a00 * iz, a01 * iz, -(a00 * x + a01 * y) * iz
        m10, m11, m12 = a10 * iz, a11 * iz, -(a10 * x + a11 * y) * iz
        h0 = (m00 * r[0] + m01 * r[3] + m02 * r[6], m00 * r[1] + m01 * r[4] + m02 * r[7],
              m00 * r[2] + m01 * r[5] + m02 * r[8])
        h1 = (m10 * r[0] + m11 * r[3] + m12 * r[6], m10 * r[1] + m11 * r[4] + m12 * r[7],
              m10 * r[2] + m11 * r[5] + m12 * r[8])
        return u, v, h0, h1


class BallFilter:
    """The ``filter`` method's state, updated one detection at a time (the streaming form).

    Parameters
    ----------
    rig : Rig, whose camera order the detections' camera indices refer to
    options : FilterOptions (``max_gap_s`` None: 3.5 frame periods of the slowest camera)

    Detections are pushed with their TRUE (corrected) capture times, in (time, camera)
    order (:class:`~pslog.fusion.stream.StreamFuser` corrects logged times first).

    Examples
    --------
    >>> f = BallFilter(rig)                                        # doctest: +SKIP
    >>> point = f.push(time_ns, camera, u, v)   # None, or (position, quality)  # doctest: +SKIP
    >>> position, velocity, covariance = f.predict(now_ns)        # doctest: +SKIP
    """

    def __init__(self, rig: Rig, options: FilterOptions | None = None) -> None:
        from pslog.fusion._prepare import default_max_gap_s

        self.options = options = options or FilterOptions()
        self._cams = [_Cam(c) for c in rig.cameras]
        self._max_gap_ns = int((options.max_gap_s or default_max_gap_s(rig)) * NS)
        self._var = options.noise_px ** 2
        self._alpha = options.noise_prior_weight
        self._adapt = options.adapt_rate
        self._var_min, self._var_max = options.min_noise_px ** 2, options.max_noise_px ** 2
        self._q = self._q_min = options.accel_psd
        self._q_max = max(options.max_accel_psd, options.accel_psd)
        self._q_rate, self._q_target = options.accel_adapt_rate, options.accel_adapt_target
        # per camera: (time, innovation u, v) of its latest accepted update, for the
        # process noise's adaptation (consecutive innovations of a lagging filter agree)
        self._cam_inn: list = [None] * len(rig)
        self._max_std = options.max_std_m
        self._withhold = options.withhold
        # camera of a jump (or a surprising update) not yet confirmed, else -1; the
        # confirming updates since, and whether one came from another camera
        self._pending, self._confirms, self._other = -1, 0, False
        self._confirm_nis = options.confirm_nis
        #: reason -> number of points withheld (``unconfirmed``, ``uncertain``)
        self.dropped: dict[str, int] = {}
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
        self._restitution, self._friction = options.restitution, options.bounce_friction
        self._k = options.drag_per_m
        self._g = tuple(float(x) for x in options.gravity)
        self._gate = options.gate
        # probability of the ballistic model (else "supported": no gravity, e.g. rolling)
        self._switch = options.model_switch_per_s
        # without switching the ballistic model alone (probability 1)
        self._mu0 = _INIT_BALLISTIC if self._switch else 1.0
        self._mu = self._mu0
        self._e = _ZERO6  # ballistic model's mean minus the supported one's
        # the turn model (coordinated turn about z, turn rate ω in its state): its probability
        # ν (0: not in the model set), mean (7,) and covariance (7 x 7 flat)
        g = options.gravity
        self._turn = bool(options.turn_switch_per_s) and g[0] == 0.0 and g[1] == 0.0
        self._turn_switch = options.turn_switch_per_s
        self._turn_on, self._turn_psd = options.turn_on_psd, options.turn_rate_psd
        self._turn_var = options.turn_rate_std ** 2
        self._nu = self._nu_post = 0.0
        self._turn_age = 0  # accepted updates since the turn model joined
        self._xt: list[float] = []
        self._Pt: list[float] = []
        self.time_ns: int | None = None  # time of the state; None: no track
        self._x = [0.0] * 6
        self._P = [0.0] * 36
        self._last_ns = 0  # time of the last accepted detection
        self._rejects = 0
        self._confirmed = 0  # detections accepted since the track started
        self._cam_last = [-(2**62)] * len(rig)  # last accepted detection per camera
        self._jump_ns, self._jump_camera = -(2**62), -1  # the latest jump accepted
        self._window: list[tuple[int, int, float, float]] = []  # (time, camera, u, v)
        # most detections the window keeps: init_window, more while its fits fail on their
        # velocity alone (a short window at a high frame rate), up to init_max_window
        self._init_cap = options.init_window
        # a window shorter than this whose fit fails on its velocity alone grows; the
        # longest time a window spans: the longest gap bridged, or a grown window's span
        self._init_grow_ns = int(options.init_span_s * NS)
        self._init_span_ns = max(self._max_gap_ns, self._init_grow_ns)
        # the latest accepted updates: (state time, x, P before; time, camera, u, v;
        # NIS + ln det S), for the jump search
        self._history: list[tuple] = []
        self._rays: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}

    # ---- public state access -------------------------------------------------------------
    def set_state(self, time_ns: int, position, velocity, covariance) -> None:
        """Start a track from a given state (tests, or a state handed over)."""
        self.time_ns = self._last_ns = int(time_ns)
        self._x = [float(a) for a in (*position, *velocity)]
        self._P = [float(a) for a in np.asarray(covariance, dtype=np.float64).ravel()]
        self._rejects = 0
        self._confirmed = 0
        self._pending = -1
        self._window = []
        self._init_cap = self.options.init_window
        self._history = []
        self._cam_last = [self._last_ns] * len(self._cam_last)
        self._mu, self._e = self._mu0, _ZERO6
        self._nu = 0.0

    def state(self):
        """``(time_ns, x (6,), P (6, 6))`` of the current track (the mixture of the motion
        models), or None without one."""
        if self.time_ns is None:
            return None
        x, P = self._combined(self._x, self._P, self._xt, self._Pt, self._nu)
        return self.time_ns, np.array(x), np.array(P).reshape(6, 6)

    def predict(self, time_ns: int):
        """The state predicted to ``time_ns`` (the process model; the state is unchanged).

        Returns
        -------
        None without a track; else ``(position (3,), velocity (3,), covariance (6, 6))`` in
        metres, m/s and their squares. An earlier time is retrodicted with the same model
        (process noise of ``|Δt|``).
        """
        if self.time_ns is None:
            return None
        dt = (int(time_ns) - self.time_ns) / NS
        nu = self._nu
        if nu == 1.0:  # the turn model alone
            x, P = self._turn_predicted(self._xt, self._Pt, dt)
            return np.array(x[:3]), np.array(x[3:6]), np.array(_block6(P)).reshape(6, 6)
        x, P = self._predicted(self._x, self._P, dt, self._prior(dt)[0])
        if nu:
            p = min(self._turn_switch * abs(dt), 0.5)
            nu = nu * (1.0 - p) + (1.0 - nu) * p
            xt, Pt = self._turn_predicted(self._xt, self._Pt, dt)
            x, P = self._combined(x, P, xt, Pt, nu)
        return np.array(x[:3]), np.array(x[3:]), np.array(P).reshape(6, 6)

    @staticmethod
    def _combined_point(x, P, xt, Pt, nu):
        """The position (3) and its variances (x, y, z) of :meth:`_combined`."""
        if not nu:
            return x, (P[0], P[7], P[14])
        d0, d1, d2 = xt[0] - x[0], xt[1] - x[1], xt[2] - x[2]
        w, m = nu * (1.0 - nu), 1.0 - nu
        return ((x[0] + nu * d0, x[1] + nu * d1, x[2] + nu * d2),
                (m * P[0] + nu * Pt[0] + w * d0 * d0, m * P[7] + nu * Pt[8] + w * d1 * d1,
                 m * P[14] + nu * Pt[16] + w * d2 * d2))

    @staticmethod
    def _combined(x, P, xt, Pt, nu):
        """The mixture of the ballistic/supported pair ``(x, P)`` (6) and the turn model
        ``(xt, Pt)`` (7) of probability ``nu``: mean and covariance (6, 6 x 6 flat) with
        the spread of the means."""
        if not nu:
            return x, P
        d = [xt[i] - x[i] for i in range(6)]
        xc = [x[i] + nu * d[i] for i in range(6)]
        w = nu * (1.0 - nu)
        Pc = [(1.0 - nu) * P[6 * i + j] + nu * Pt[7 * i + j] + w * d[i] * d[j]
              for i in range(6) for j in range(6)]
        return xc, Pc

    # ---- the filter ----------------------------------------------------------------------
    def _prior(self, dt):
        """Prior probability ``c`` of the ballistic model after ``dt`` seconds: the model
        switches with probability ``p = min(λ |Δt|, 1/2)``, ``c = μ (1 - p) + (1 - μ) p``."""
        p = min(self._switch * abs(dt), 0.5)
        return self._mu * (1.0 - p) + (1.0 - self._mu) * p, p

    def _predicted(self, x, P, dt, c=1.0):
        """Mean and covariance after ``dt`` seconds (new lists), gravity weighted by the
        ballistic model's probability ``c`` (the models' mixture's mean)."""
        px, py, pz, vx, vy, vz = x
        k = self._k
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        gx, gy, gz = self._g
        gx, gy, gz = c * gx, c * gy, c * gz
        ax, ay, az = gx - k * speed * vx, gy - k * speed * vy, gz - k * speed * vz
        h = 0.5 * dt * dt
        xn = [px + vx * dt + ax * h, py + vy * dt + ay * h, pz + vz * dt + az * h,
              vx + ax * dt, vy + ay * dt, vz + az * dt]
        adt = abs(dt)
        q = self._q
        q3, q2, q1 = q * adt ** 3 / 3.0, q * dt * adt / 2.0, q * adt
        dt2 = dt * dt
        Pn = P[:]
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
        return xn, Pn

    def _innovation(self, cam: _Cam, x, P, u, v, n=6):
        """``(y0, y1, PHᵀ columns c0 c1, S⁻¹ entries i00 i01 i11, NIS, det S)``, or None
        if ``x`` is behind the camera; ``n`` states (position first), ``P`` n x n flat."""
        proj = cam.project(x[0], x[1], x[2])
        if proj is None:
            return None
        pu, pv, h0, h1 = proj
        y0, y1 = u - pu, v - pv
        a0, a1, a2 = h0
        b0, b1, b2 = h1
        # PHᵀ: column r is P[:, :3] · h_r (6 rows)
        c0, c1 = [], []
        for i in range(0, n * n, n):
            p0, p1, p2 = P[i], P[i + 1], P[i + 2]
            c0.append(p0 * a0 + p1 * a1 + p2 * a2)
            c1.append(p0 * b0 + p1 * b1 + p2 * b2)
        s00 = a0 * c0[0] + a1 * c0[1] + a2 * c0[2] + self._var
        s01 = a0 * c1[0] + a1 * c1[1] + a2 * c1[2]
        s11 = b0 * c1[0] + b1 * c1[1] + b2 * c1[2] + self._var
        det = s00 * s11 - s01 * s01
        i00, i01, i11 = s11 / det, -s01 / det, s00 / det
        nis = y0 * (i00 * y0 + i01 * y1) + y1 * (i01 * y0 + i11 * y1)
        return y0, y1, c0, c1, i00, i01, i11, nis, det, h0, h1

    @staticmethod
    def _updated(x, P, inn):
        """Kalman update: ``x + K y``, ``P - K (PHᵀ)ᵀ`` with ``K = PHᵀ S⁻¹`` (new lists)."""
        y0, y1, c0, c1, i00, i01, i11 = inn[:7]
        n = len(x)
        k0 = [c0[i] * i00 + c1[i] * i01 for i in range(n)]
        k1 = [c0[i] * i01 + c1[i] * i11 for i in range(n)]
        xn = [x[i] + k0[i] * y0 + k1[i] * y1 for i in range(n)]
        Pn = P[:]
        for i in range(n):
            ki0, ki1, row = k0[i], k1[i], n * i
            for j in range(i, n):
                value = P[row + j] - (ki0 * c0[j] + ki1 * c1[j])
                Pn[row + j] = value
                Pn[n * j + i] = value
        return xn, Pn

    def _turn_predicted(self, x, P, dt):
        """The turn model's mean and covariance after ``dt`` seconds (new lists): a
        coordinated turn at rate ``ω`` about z (the horizontal velocity rotates, speed
        constant), constant vertical velocity, ``ω`` a random walk; ``P⁻ = F P Fᵀ + Q`` with
        the Jacobian ``F`` (7 x 7) and the white-noise acceleration ``q`` (as the other
        models) plus ``q_ω |Δt|`` on ``ω``."""
        px, py, pz, vx, vy, vz, w = x
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
        xn = [px + sw * vx - cw * vy, py + cw * vx + sw * vy, pz + vz * dt, vxn, vyn, vz, w]
        fx, fy = dsw * vx - dcw * vy, dcw * vx + dsw * vy  # ∂p/∂ω
        f3, f4 = -dt * vyn, dt * vxn  # ∂v/∂ω
        # A = F P (rows of P combined by F's sparse rows), then A Fᵀ (A's columns likewise)
        R0, R1, R2, R3, R4, R5, R6 = (P[k:k + 7] for k in range(0, 49, 7))
        Pn = []
        for a0, a1, a2, a3, a4, a5, a6 in (
                [r0 + sw * r3 - cw * r4 + fx * r6
                 for r0, r3, r4, r6 in zip(R0, R3, R4, R6, strict=True)],
                [r1 + cw * r3 + sw * r4 + fy * r6
                 for r1, r3, r4, r6 in zip(R1, R3, R4, R6, strict=True)],
                [r2 + dt * r5 for r2, r5 in zip(R2, R5, strict=True)],
                [c * r3 - s * r4 + f3 * r6 for r3, r4, r6 in zip(R3, R4, R6, strict=True)],
                [s * r3 + c * r4 + f4 * r6 for r3, r4, r6 in zip(R3, R4, R6, strict=True)], R5, R6):
            # row i of A: row i of A Fᵀ is F applied to it
            Pn += (a0 + sw * a3 - cw * a4 + fx * a6, a1 + cw * a3 + sw * a4 + fy * a6,
                   a2 + dt * a5, c * a3 - s * a4 + f3 * a6, s * a3 + c * a4 + f4 * a6, a5, a6)
        adt = abs(dt)
        q = self._q
        q3, q2, q1 = q * adt ** 3 / 3.0, q * dt * adt / 2.0, q * adt
        for i in range(3):
            Pn[8 * i] += q3
            Pn[8 * i + 3] += q2
            Pn[8 * i + 21] += q2
            Pn[8 * i + 24] += q1
        Pn[48] += self._turn_psd * adt
        return xn, Pn

    def push(self, time_ns: int, camera: int, u: float, v: float):
        """Fuse one detection (true capture time, camera index, distorted pixel).

        Returns
        -------
        None when no point is made (no track yet, an unusable pixel, or a point withheld:
        counted in :attr:`dropped`); else ``(position (x, y, z), quality)`` with ``quality``
        a tuple in the order of :data:`FILTER_QUALITY`.
        """
        out = self._push(time_ns, camera, u, v)
        if out is None or not self._withhold:
            return out
        # withhold what the filter cannot vouch for (the state is updated all the same):
        # a velocity jump one camera alone has seen (its component along that camera's rays
        # is a guess) until another camera's detection confirms it, and any point whose
        # standard deviation exceeds the bound
        reason = ("unconfirmed" if self._pending >= 0
                  else "uncertain" if self._max_std is not None and out[1][0] > self._max_std
                  else None)
        if reason is None:
            return out
        self.dropped[reason] = self.dropped.get(reason, 0) + 1
        return None

    def _push(self, time_ns: int, camera: int, u: float, v: float):
        time_ns, camera = int(time_ns), int(camera)
        cam = self._cams[camera]
        u, v = float(u), float(v)
        if not (abs(u) <= cam.far and abs(v) <= cam.far):  # also NaN: no detection
            return None
        if self.time_ns is not None and (
                time_ns - self._last_ns > self._max_gap_ns
                or time_ns - max(t for c, t in enumerate(self._cam_last) if c != camera)
                > self._max_gap_ns
                or (camera == self._jump_camera
                    and max(t for c, t in enumerate(self._cam_last) if c != camera)
                    < self._jump_ns)):
            # nothing bridges so long a time, and one camera alone cannot hold the depth
            # (no other camera's detection within the gap, or since a jump it alone saw):
            # the track is lost
            self.time_ns = None
        if self.time_ns is None:
            return self._initialise(time_ns, camera, u, v)
        dt = (time_ns - self.time_ns) / NS
        gap_s = (time_ns - self._last_ns) / NS
        c, p = self._prior(dt)
        xg, Pg = self._x, self._P
        nu = self._nu
        if nu == 1.0 and self._q >= self._turn_on:
            # an acceleration the turn model lacks (q grew): the pair rejoins at its state
            nu = 1.0 - _TURN_START
            self._mu, self._e = self._mu0, _ZERO6
            self._turn_age = 0
        elif not nu and self._turn and (self._q >= self._turn_on or not self._confirmed):
            # at a track's start, or an acceleration the pair lacks (q grew): the turn model
            # joins at the pair's state, its turn rate unknown (0 ± turn_rate_std)
            nu = _TURN_START
            self._xt, self._Pt = self._turn_start(xg, Pg, 0.0, self._turn_var)
            self._turn_age = 0
        solo = nu == 1.0  # the turn model alone (the pair left the model set)
        mu, e = self._mu, self._e
        jump = 0.0
        accepted = False
        if solo:
            xt, Pt = self._turn_predicted(self._xt, self._Pt, dt)
            x, P = xt[:6], _block6(Pt)
            inn = inn_t = self._innovation(cam, xt, Pt, u, v, 7)
            if inn is not None:
                prior_y0, prior_y1 = inn[0], inn[1]
                accepted = inn[7] <= self._gate
        else:
            if nu:
                nu, xg, Pg, xt, Pt = self._turn_mixed(nu, xg, Pg, dt)
                xt, Pt = self._turn_predicted(xt, Pt, dt)
            x, P = self._predicted(xg, Pg, dt, c)
            inn = self._innovation(cam, x, P, u, v)
        if inn is not None and not solo:
            # the mixture's innovation (the process noise's whiteness statistic)
            prior_y0, prior_y1 = inn[0], inn[1]
            if self._switch:
                x, inn, mu, e, nis_b, nis_s = self._mixed(x, inn, c, p, dt)
                nis_min = min(nis_b, nis_s)
            else:
                nis_b = nis_s = nis_min = inn[7]
            if nu:
                inn_t = self._innovation(cam, xt, Pt, u, v, 7)
                if inn_t is None:  # the turn model's point is behind the camera: it leaves
                    nu = 0.0
                else:
                    nu, nis_t = self._turn_probability(nu, c, nis_b, nis_s, inn[8], inn_t)
                    nis_min = min(nis_min, nis_t)
                    prior_y0 += nu * (inn_t[0] - prior_y0)
                    prior_y1 += nu * (inn_t[1] - prior_y1)
            accepted = nis_min <= self._gate
        nu_post = nu
        if accepted and solo:
            xt, Pt = self._updated(xt, Pt, inn)
            xn, Pn, nis = xt[:6], _block6(Pt), inn[7]
            sy = (inn[0], inn[1], inn[4], inn[5], inn[6])
            xo, pvar = xt, (Pt[0], Pt[8], Pt[16])
        elif accepted:
            xn, Pn = self._updated(x, P, inn)
            nis = inn[7]
            sy = (inn[0], inn[1], inn[4], inn[5], inn[6])
            if nu:
                nu_post = self._nu_post
                xt, Pt = self._updated(xt, Pt, inn_t)
                # the mixture's innovation and S⁻¹ (the models' weighted by ν⁺)
                y0, y1 = inn[0] + nu_post * (inn_t[0] - inn[0]), inn[1] + nu_post * (
                    inn_t[1] - inn[1])
                i00, i01, i11 = (inn[4] + nu_post * (inn_t[4] - inn[4]),
                                 inn[5] + nu_post * (inn_t[5] - inn[5]),
                                 inn[6] + nu_post * (inn_t[6] - inn[6]))
                nis = y0 * (i00 * y0 + i01 * y1) + y1 * (i01 * y0 + i11 * y1)
                sy = (y0, y1, i00, i01, i11)
                xo, pvar = self._combined_point(xn, Pn, xt, Pt, nu_post)
            else:
                xo, pvar = xn, (Pn[0], Pn[7], Pn[14])
        else:
            self._nu = nu  # the turn model's state is its prediction (as the pair's)
            if nu:
                self._xt, self._Pt = xt, Pt
            jumped = self._jump(time_ns, camera, u, v) if inn is not None else None
            if jumped is None:  # rejected: the point is the prediction
                return self._reject(time_ns, camera, u, v, x, P, inn, gap_s)
            xn, Pn, inn = jumped
            xo, pvar, nis = xn, (Pn[0], Pn[7], Pn[14]), inn[7]
            jump = 1.0
            if nu:  # the turn model restarts at the jump's state, keeping its turn rate;
                # the pair is back in the set (a new segment, its motion unknown)
                xt, Pt = self._turn_start(xn, Pn, xt[6], Pt[48])
                nu_post = min(max(nu, _TURN_START), 1.0 - _TURN_START)
                if solo:
                    self._mu = mu = self._mu0
        proj = cam.project(xo[0], xo[1], xo[2])
        if proj is None:  # never a point behind the camera that made it
            self._nu = nu
            if nu:
                self._xt, self._Pt = xt, Pt
            return self._reject(time_ns, camera, u, v, x, P, inn, gap_s)
        if accepted:
            history = self._history
            history.append((self.time_ns, self._x, self._P, time_ns, camera, u, v,
                            inn[7] + math.log(inn[8])))
            if len(history) > _JUMP_LAG + 1:
                del history[0]
            if self._q_rate:  # process noise: a consistent filter's innovations are white
                prev = self._cam_inn[camera]
                if prev is not None and time_ns - prev[0] <= self._max_gap_ns:
                    # yᵀ S⁻¹ y': zero mean for a consistent filter's (white) innovations
                    y0, y1 = prior_y0, prior_y1
                    r = (prev[1] * (inn[4] * y0 + inn[5] * y1)
                         + prev[2] * (inn[5] * y0 + inn[6] * y1))
                    r = min(max(r, -_R_CLIP), _R_CLIP)
                    q = self._q * math.exp(self._q_rate * (r - self._q_target))
                    self._q = min(max(q, self._q_min), self._q_max)
                self._cam_inn[camera] = (time_ns, prior_y0, prior_y1)
            if self._adapt:  # pixel noise: variational Bayes (Särkkä & Nummenmaa 2009)
                y0, y1, i00, i01, i11 = sy
                var, rho = self._var, 1.0 - self._adapt
                a0 = i00 * y0 + i01 * y1
                a1 = i01 * y0 + i11 * y1
                resid2 = var * var * (a0 * a0 + a1 * a1)
                trace = var * (2.0 - var * (i00 + i11))
                alpha = rho * self._alpha + 1.0
                beta = rho * self._alpha * var + 0.5 * (resid2 + trace)
                self._alpha = alpha
                self._var = min(max(beta / alpha, self._var_min), self._var_max)
            if nis > self._confirm_nis:  # a surprising update: confirmed like a jump
                self._pending, self._confirms, self._other = camera, 0, False
            elif self._pending >= 0:
                self._confirms += 1
                self._other |= camera != self._pending
                if self._confirms >= _CONFIRM_UPDATES and self._other:
                    self._pending = -1
            if nu_post:
                # the model set adapts (variable-structure IMM): the turn model leaves when
                # it is unlikely, or its turn rate is not told from 0 (the supported model),
                # once its turn rate has settled and unless q says an acceleration is missing
                self._turn_age += 1
                w = xt[6]
                if self._turn_age >= _TURN_MIN_UPDATES and self._q < self._turn_on:
                    if nu_post < _TURN_OFF or w * w < _TURN_SIGNIFICANT ** 2 * Pt[48]:
                        nu_post = 0.0
                    elif nu_post > 1.0 - _TURN_OFF and not solo:
                        # the pair is unlikely: it leaves, the turn model goes on alone
                        nu_post = 1.0
                        xn, Pn = xt[:6], _block6(Pt)
        else:
            self._jump_ns, self._jump_camera = time_ns, camera
            self._cam_inn = [None] * len(self._cam_inn)  # a new segment
            self._pending, self._confirms, self._other = camera, 0, False
        if accepted:
            self._mu, self._e = mu, e
        else:
            self._e = _ZERO6  # a jump: a new segment, the models start together
        self._nu = nu_post
        if nu_post:
            self._xt, self._Pt = xt, Pt
        self._x, self._P, self.time_ns, self._last_ns = xn, Pn, time_ns, time_ns
        self._rejects = 0
        self._confirmed += 1
        self._cam_last[camera] = time_ns
        self._window.append((time_ns, camera, u, v))
        del self._window[:-self.options.init_window]
        return self._point(xo, pvar, math.hypot(inn[0], inn[1]),
                           math.hypot(u - proj[0], v - proj[1]), nis, gap_s, jump, 0.0, 0.0)

    @staticmethod
    def _turn_start(x, P, w, var):
        """The turn model's state at the pair's ``(x, P)`` with turn rate ``w ± sqrt(var)``
        (uncorrelated)."""
        Pt = []
        for i in range(0, 36, 6):
            Pt += P[i:i + 6]
            Pt.append(0.0)
        return [*x, w], Pt + [0.0] * 6 + [var]

    def _turn_mixed(self, nu, xg, Pg, dt):
        """The interacting multiple model's mixing of the pair (ballistic/supported, mean
        ``xg``, covariance ``Pg``) and the turn model (probability ``nu``) before a step of
        ``dt``: the turn model is left with probability ``p = min(λ_t |Δt|, 1/2)``; each
        model starts from the mixture of both weighted by where it came from, spread of the
        means included (the pair's missing ω is the turn model's).
        Returns ``(ν⁻, pair's x, P, turn model's x, P)``."""
        pt = min(self._turn_switch * abs(dt), 0.5)
        prior = nu * (1.0 - pt) + (1.0 - nu) * pt
        wt = nu * pt / (1.0 - prior) if prior < 1.0 else 0.0  # turn's share of the pair's
        wg = (1.0 - nu) * pt / prior  # the pair's share of the turn model's start
        xt, Pt = self._xt, self._Pt
        d = [xt[i] - xg[i] for i in range(6)]
        x0 = [xg[i] + wt * d[i] for i in range(6)]
        xt0 = [xt[i] - wg * d[i] for i in range(6)]
        xt0.append(xt[6])
        sg, st = wt * (1.0 - wt), wg * (1.0 - wg)
        P0, Pt0 = [], []
        keep = 1.0 - wg
        for i in range(6):
            rg, rt, di = Pg[6 * i: 6 * i + 6], Pt[7 * i: 7 * i + 6], d[i]
            gd, td = sg * di, st * di
            P0 += [a + wt * (b - a) + gd * dj for a, b, dj in zip(rg, rt, d, strict=True)]
            Pt0 += [b + wg * (a - b) + td * dj for a, b, dj in zip(rg, rt, d, strict=True)]
            # the pair's ω: the turn model's, uncorrelated with the pair's state (a
            # covariance that stays positive semi-definite)
            Pt0.append(keep * Pt[7 * i + 6])
        Pt0 += [keep * a for a in Pt[42:48]]
        Pt0.append(Pt[48])
        return prior, x0, P0, xt0, Pt0

    def _turn_probability(self, prior, c, nis_b, nis_s, det, inn_t):
        """The turn model's probability after the detection (kept in ``_nu_post``) from the
        models' likelihoods ``N(y; 0, S)``: the pair's is its models' mixture ``c N_b + (1 -
        c) N_s`` (their common ``det S``); the log ratio is clipped as the pair's.
        Returns ``(ν⁻, NIS_t)``, ``ν⁻`` the prior (the innovations' weight)."""
        low = min(nis_b, nis_s)
        log_pair = (-0.5 * low - 0.5 * math.log(det)
                    + math.log(c * math.exp(0.5 * (low - nis_b))
                               + (1.0 - c) * math.exp(0.5 * (low - nis_s))))
        nis_t = inn_t[7]
        r = -0.5 * nis_t - 0.5 * math.log(inn_t[8]) - log_pair
        r = min(max(r, -_LOG_ODDS_CLIP), _LOG_ODDS_CLIP)
        self._nu_post = prior / (prior + (1.0 - prior) * math.exp(-r))
        return prior, nis_t

    def _mixed(self, x, inn, c, p, dt):
        """The interacting multiple model step with a covariance the two models share.

        ``x``, ``inn``: the mixture's prediction and innovation; ``c``: the ballistic model's
        prior probability, ``p`` the switching probability. The models' means are ``m + (1 -
        c) e`` and ``m - c e`` with ``e`` their difference: the mixing shrinks it by ``1 -
        μ_s p / c - μ_b p / (1 - c)``, the prediction propagates it (``e_p += Δt e_v``) and
        adds gravity's ``d = (g Δt²/2, g Δt)``; the models' innovations are the mixture's
        minus ``H`` of their offsets (linearised), their likelihood ratio (equal ``S``)
        ``exp((NIS_s - NIS_b) / 2)`` gives ``μ⁺``; the mixture is re-weighted with ``μ⁺``
        (``x + (μ⁺ - c) e``) and ``e`` updated to ``(I - K H) e``.
        Returns ``(x, innovation, μ⁺, e⁺, NIS_b, NIS_s)``."""
        y0, y1, c0, c1, i00, i01, i11, _, det, h0, h1 = inn
        mu = self._mu
        e = self._e
        shrink = 1.0 - (1.0 - mu) * p / c - mu * p / (1.0 - c) if 0.0 < c < 1.0 else 1.0
        g = self._g
        half = 0.5 * dt * dt
        e = [shrink * (e[i] + dt * e[3 + i]) + half * g[i] for i in range(3)] + [
            shrink * e[3 + i] + dt * g[i] for i in range(3)]
        hd0 = h0[0] * e[0] + h0[1] * e[1] + h0[2] * e[2]
        hd1 = h1[0] * e[0] + h1[1] * e[1] + h1[2] * e[2]
        b0, b1 = y0 - (1.0 - c) * hd0, y1 - (1.0 - c) * hd1
        s0, s1 = y0 + c * hd0, y1 + c * hd1
        nis_b = b0 * (i00 * b0 + i01 * b1) + b1 * (i01 * b0 + i11 * b1)
        nis_s = s0 * (i00 * s0 + i01 * s1) + s1 * (i01 * s0 + i11 * s1)
        r = min(max(0.5 * (nis_b - nis_s), -_LOG_ODDS_CLIP), _LOG_ODDS_CLIP)
        mu = c / (c + (1.0 - c) * math.exp(r))
        delta = mu - c
        xn = [x[i] + delta * e[i] for i in range(6)]
        y0, y1 = y0 - delta * hd0, y1 - delta * hd1
        nis = y0 * (i00 * y0 + i01 * y1) + y1 * (i01 * y0 + i11 * y1)
        # (I - K H) e with K = PHᵀ S⁻¹
        g0, g1 = i00 * hd0 + i01 * hd1, i01 * hd0 + i11 * hd1
        e = [e[i] - c0[i] * g0 - c1[i] * g1 for i in range(6)]
        return xn, (y0, y1, c0, c1, i00, i01, i11, nis, det, h0, h1), mu, e, nis_b, nis_s

    def _jump(self, time_ns, camera, u, v):
        """A bounce or a kick: a velocity jump (a bounce's, mostly along gravity, then a
        kick's, isotropic; position continuous) at the state before one of the last
        ``_JUMP_LAG + 1`` accepted detections (the first detections after a small jump can
        pass the gate), those detections and this one replayed; the (lag, shape) whose replay
        passes every gate with the least ``Σ NIS + ln det S`` over the same detections wins.
        Returns ``(x, P, innovation of this detection)`` or None when none explains it."""
        history = self._history
        entries = [(self.time_ns, self._x, self._P)]  # state before the current detection
        detections = [(time_ns, camera, u, v)]
        best, best_score = None, math.inf
        c = self._mu  # the replay keeps the models' mixture of the current state
        n = len(history)
        for lag, shape in ((lag, shape) for lag in range(min(n, _JUMP_LAG) + 1)
                           for shape in self._jump_shapes):
            if lag == len(entries):  # restart before the lag-th latest accepted detection
                h = history[n - lag]
                entries.append((h[0], h[1], h[2]))
                detections.insert(0, h[3:7])
            t0, x, P = entries[-1]
            score = sum(h[7] for h in history[n - _JUMP_LAG: n - lag]) if n else 0.0
            first = True
            for t, cam_d, du, dv in detections:
                dt = (t - t0) / NS
                x, P = self._predicted(x, P, dt, c)
                if first:  # the jump Δv at an instant uniform in the interval: Δp = Δv s
                    jumped = self._jumped(x, P, dt, shape)
                    if jumped is None:
                        break
                    (x, P), first = jumped, False
                inn = self._innovation(self._cams[cam_d], x, P, du, dv)
                if inn is None or not inn[7] <= self._gate:
                    break
                score += inn[7] + math.log(inn[8])
                x, P = self._updated(x, P, inn)
                t0 = t
            else:
                if score < best_score:
                    best, best_score = (x, P, inn), score
        if best is not None:
            self._history = []  # a new segment: a later jump is not looked for before it
        return best

    def _jumped(self, x, P, dt, shape):
        """``(x, P)`` after a velocity jump ``Δv ~ N(μ, diag(σ²))`` at an instant ``s``
        uniform over the last ``dt`` (``Δp = Δv s``, ``E[s] = dt/2``, ``E[s²] = dt²/3``,
        ``Var s = dt²/12``); ``shape = (reflect, σ²)``: ``μ = 0``, or for a floor bounce
        ``μ = −(1 + e) v_d ĝ − f (v − v_d ĝ)`` with ``v_d = v·ĝ`` (``ĝ`` gravity's unit
        vector; None when the ball is not falling: no floor bounce then)."""
        reflect, var = shape
        x, P = x[:], P[:]
        if reflect:
            down = self._down
            vd = x[3] * down[0] + x[4] * down[1] + x[5] * down[2]
            if not vd > 0:
                return None
            e, f = self._restitution, self._friction
            mu = [-(1.0 + e) * vd * down[i] - f * (x[3 + i] - vd * down[i]) for i in range(3)]
            for i in range(3):
                x[3 + i] += mu[i]
                x[i] += mu[i] * dt / 2.0
                for j in range(3):  # the jump's unknown instant spreads its mean's shift
                    P[6 * i + j] += mu[i] * mu[j] * dt * dt / 12.0
        for i in range(3):
            jv = var[i]
            P[7 * i] += jv * dt * dt / 3.0
            P[6 * i + 3 + i] += jv * dt / 2.0
            P[6 * (i + 3) + i] += jv * dt / 2.0
            P[7 * (i + 3)] += jv
        return x, P

    def _reject(self, time_ns, camera, u, v, x, P, inn, gap_s):
        """The detection failed the gate: the point is the prediction ``x``; after
        ``max_rejects`` in a row the track restarts from the window."""
        self._rejects += 1
        self._window.append((time_ns, camera, u, v))
        del self._window[:-self.options.init_window]
        if self._confirmed < _CONFIRM:  # a start the next detections deny: no point from it
            self.time_ns = None
            return self._try_window()
        nis = _NAN if inn is None else inn[7]
        inn_px = _NAN if inn is None else math.hypot(inn[0], inn[1])
        self._x, self._P, self.time_ns = x, P, time_ns
        xo, var = self._combined_point(x, P, self._xt, self._Pt, self._nu)
        out = self._point(xo, var, inn_px, inn_px, nis, gap_s, 0.0, 1.0, 0.0)
        if self._rejects >= self.options.max_rejects:  # lost: restart from the window
            self.time_ns = None
            restart = self._try_window()
            if restart is not None:
                return restart
        return out

    @staticmethod
    def _point(x, var, innovation, residual, nis, gap_s, jump, rejected, init):
        """The point and its quality; ``var`` the position's variances (x, y, z)."""
        vx, vy, vz = var
        return ((x[0], x[1], x[2]),
                (math.sqrt(vx + vy + vz), math.sqrt(vx), math.sqrt(vy), math.sqrt(vz),
                 innovation, residual, nis, gap_s, jump, rejected, init))

    # ---- (re)initialisation from a window --------------------------------------------------
    def _initialise(self, time_ns, camera, u, v):
        window = self._window
        if window and time_ns - window[-1][0] > self._max_gap_ns:
            window.clear()
        window.append((time_ns, camera, u, v))
        del window[:-self._init_cap]
        return self._try_window()

    def _try_window(self):
        """Fit the window (newest last), dropping its oldest detection until a fit passes (a
        break or an outlier inside it) or fewer than ``init_detections`` are left (at most
        ``init_window - init_detections + 1`` fits per detection, and only while there is
        no track); a fit that fails on its velocity's uncertainty alone, of a window shorter
        than ``init_span_s``, ends the search and lets the window grow instead (a shorter
        window would pin the velocity still worse: at 60 fps and above ``init_window``
        detections span too short a time; at 30 fps ``init_detections`` of a 3-camera rig
        span a frame period, 33 ms, so nothing grows there); on success start the track at
        the newest detection and return its point, else None."""
        window = self._window
        while window and window[-1][0] - window[0][0] > self._init_span_ns:
            del window[0]  # a fit spans at most the longest gap bridged (or init_span_s)
        while len(window) >= self.options.init_detections:
            if len({w[1] for w in window}) < 2:
                return None
            fit = self._fit(window)
            if fit is _SHORT or fit is _WEAK:
                # session 10: a fit failing on its uncertainty alone ends the search (a
                # shorter window has less information) and keeps the window to grow
                if fit is _SHORT and window[-1][0] - window[0][0] < self._init_grow_ns:
                    self._init_cap = min(max(self._init_cap, len(window) + 1),
                                         self.options.init_max_window)
                return None
            elif fit is not None:
                x, P, residuals = fit
                # session 8 (4efae4a): the noise estimate starts again at each (re)start,
                # from its prior (or the estimate, if larger) and the window's residuals,
                # the start's covariance at the updated variance
                var = self._start_var()
                self._alpha = self.options.noise_prior_weight
                self._var = var
                if self._adapt:  # the window's residuals: a conjugate update of σ²
                    n = len(window)
                    decay = (1.0 - self._adapt) ** n
                    alpha = decay * self._alpha + (n - 3)
                    beta = (decay * self._alpha * self._var
                            + 0.5 * float(np.sum(residuals * residuals)))
                    self._alpha = alpha
                    self._var = min(max(beta / alpha, self._var_min), self._var_max)
                scale = float(self._var) / var
                P = [a * scale for a in P]
                self.set_state(window[-1][0], x[:3], x[3:], P)
                for t, c, _, _ in window:
                    self._cam_last[c] = t
                P = self._P
                return self._point(self._x, (P[0], P[7], P[14]), _NAN, float(residuals[-1]),
                                   _NAN, _NAN,
                                   0.0, 0.0, 1.0)
            del window[0]
        return None

    def _start_var(self) -> float:
        """The pixel variance a (re)start is judged by (session 8, 4efae4a): the estimate,
        or the prior's ``noise_px²`` if larger."""
        var = float(self._var)
        if self._adapt == 0.0:
            return var
        return max(var, min(max(self.options.noise_px ** 2, self._var_min), self._var_max))

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

    def _fit(self, window):
        """Ballistic fit of the window's detections at the newest one's time: ``(x (6,),
        P (6x6 flat list), pixel residuals)``, or None when it is not trustworthy, or
        ``_SHORT`` when it passes every test but the velocity's uncertainty."""
        t_ref = window[-1][0]
        tau = np.array([(w[0] - t_ref) / NS for w in window])
        g = np.array(self._g)
        rays = [self._ray(*w) for w in window]
        O = np.array([o for o, _ in rays])
        D = np.array([d for _, d in rays])
        if not np.all(np.isfinite(D)):
            return None
        # linear start: the path p0 + v0 τ + a τ²/2 on each ray (2 equations per ray: its
        # offsets along two unit directions normal to it), weighted by 1/depth in a 2nd pass
        helper = np.where((np.abs(D[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        E1 = np.cross(D, helper)
        E1 /= np.linalg.norm(E1, axis=1, keepdims=True)
        E = np.concatenate([E1, np.cross(D, E1)])  # (2n, 3)
        T = np.concatenate([tau, tau])
        OO = np.concatenate([O, O])
        accel = g
        weights = np.ones(len(T))
        theta = None
        for _ in range(2):
            A = weights[:, None] * np.hstack([E, T[:, None] * E])
            b = weights * np.einsum("ij,ij->i", E, OO - 0.5 * (T * T)[:, None] * accel)
            theta, _, rank, sv = np.linalg.lstsq(A, b, rcond=None)
            if rank < 6 or sv[-1] < 1e-10 * sv[0]:
                return None
            depth = np.einsum("ij,ij->i", theta[:3] + tau[:, None] * theta[3:] - O, D)
            if not np.all(depth > _MIN_DEPTH_M):
                return None
            weights = np.concatenate([1.0 / depth, 1.0 / depth])
            accel = g - self._k * np.linalg.norm(theta[3:]) * theta[3:]
        # Gauss-Newton in distorted pixels (the filter's measurement model)
        for _ in range(3):
            J, r = self._pixel_system(window, tau, theta, accel)
            if J is None:
                return None
            step = np.linalg.lstsq(J, r, rcond=None)[0]
            theta = theta + step
        J, r = self._pixel_system(window, tau, theta, accel)
        if J is None:
            return None
        residuals = np.hypot(r[0::2], r[1::2])
        # every detection inside the gate, and the whole fit inside the chi-square quantile
        # of its 2n - 6 degrees of freedom (a break inside the window shows in the sum)
        var = self._start_var()
        if not (np.all(residuals ** 2 <= self._gate * var)
                and float(r @ r) <= _chi2_quantile(len(r) - 6) * var):
            return None
        info = J.T @ J
        try:
            cov = var * np.linalg.inv(info)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(cov)) or np.linalg.cond(info) > 1e14:
            return None  # a degenerate geometry (rays nearly parallel): no trustworthy start
        if np.trace(cov[:3, :3]) > self.options.max_init_std_m ** 2:
            return _WEAK  # session 10: too little information (a shorter window has less)
        if np.trace(cov[3:, 3:]) > self.options.max_init_speed_std ** 2:
            return _SHORT  # too short a window (or mostly one camera's): more detections
        cov = 0.5 * (cov + cov.T)
        return [float(a) for a in theta], [float(a) for a in cov.ravel()], residuals

    def _pixel_system(self, window, tau, theta, accel):
        """Jacobian (2n, 6) and residuals (2n,) of the window's pixels at the path
        ``theta``; (None, None) when a point is behind its camera."""
        points = (theta[:3] + tau[:, None] * theta[3:]
                  + 0.5 * (tau * tau)[:, None] * accel).tolist()
        rows, res = [], []
        for (_, camera, u, v), ti, p in zip(window, tau.tolist(), points, strict=True):
            proj = self._cams[camera].project(p[0], p[1], p[2])
            if proj is None:
                return None, None
            pu, pv, h0, h1 = proj
            rows.append([h0[0], h0[1], h0[2], ti * h0[0], ti * h0[1], ti * h0[2]])
            rows.append([h1[0], h1[1], h1[2], ti * h1[0], ti * h1[1], ti * h1[2]])
            res.append(u - pu)
            res.append(v - pv)
        return np.array(rows), np.array(res)


def _block6(P):
    """The position-velocity block (6 x 6 flat) of a 7 x 7 flat covariance."""
    return P[0:6] + P[7:13] + P[14:20] + P[21:27] + P[28:34] + P[35:41]


def _chi2_quantile(dof: int, z: float = 3.09) -> float:
    """The chi-square quantile of ``dof`` degrees of freedom at the normal quantile ``z``
    (3.09: 99.9 %), by the Wilson-Hilferty approximation (within 2 % from 2 dof on)."""
    if dof <= 0:
        return math.inf
    a = 2.0 / (9.0 * dof)
    return dof * (1.0 - a + z * math.sqrt(a)) ** 3


class FilterStream:
    """The streaming form for :class:`~pslog.fusion.stream.StreamFuser`: detections (true
    times, (time, camera) order) in, the Track of their points out; :attr:`filter` is the
    :class:`BallFilter` (``predict`` to "now")."""

    def __init__(self, rig: Rig, options) -> None:
        self.filter = BallFilter(rig, FilterOptions(max_gap_s=options.max_gap_s))

    def push(self, time_ns, camera, uv, frame_index=None) -> Track:
        return _track(self.filter, time_ns, camera, uv)


def _track(flt: BallFilter, time_ns, camera, uv) -> Track:
    times, cams, points, quality = [], [], [], []
    before = dict(flt.dropped)
    push = flt.push
    for t, c, (u, v) in zip(np.asarray(time_ns).tolist(), np.asarray(camera).tolist(),
                            np.asarray(uv, dtype=np.float64).reshape(-1, 2).tolist(),
                            strict=True):
        out = push(t, c, u, v)
        if out is not None:
            times.append(t)
            cams.append(c)
            points.append(out[0])
            quality.append(out[1])
    q = np.array(quality, dtype=np.float64).reshape(-1, len(FILTER_QUALITY))
    return Track("filter", np.array(times, dtype=np.int64),
                 np.array(points, dtype=np.float64).reshape(-1, 3),
                 np.array(cams, dtype=np.int32),
                 {name: q[:, i] for i, name in enumerate(FILTER_QUALITY)},
                 dropped={k: n - before.get(k, 0) for k, n in flt.dropped.items()
                          if n > before.get(k, 0)})


def fuse_filter(obs: Observations, rig: Rig, max_gap_s: float | None = None,
                options: FilterOptions | None = None) -> Track:
    """The ``filter`` track of observations (true times, sorted by (time, camera)): the
    same per-detection code as the streaming form, so the same points."""
    options = options or FilterOptions()
    if max_gap_s is not None and options.max_gap_s is None:
        from dataclasses import replace

        options = replace(options, max_gap_s=max_gap_s)
    return _track(BallFilter(rig, options), obs.time_ns, obs.camera, obs.uv)
