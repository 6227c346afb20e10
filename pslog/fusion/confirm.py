"""Type A across a long gap: a point withheld until the next camera confirms it.

Type A's output ``P'_t`` takes its depth along the newest viewing ray from eq. (2)'s linear
prediction from ``P_{t-1}`` and ``P_{t-2}``. When the newest detection follows the previous
one by more than the rig's usual interval (a camera blind or out of view, a missed frame),
the prediction bridges that longer gap, and a kick or a bounce inside it puts the point at
the wrong depth, *along the newest ray*: the newest camera cannot see it (the prediction
test of :mod:`pslog.fusion.innovation` sees only the error across its ray), and when the
kick follows the previous detection no other camera has seen the ball since (its kink test
has no triplet to bend). At the point's own time no causal test can see the error; the next
detection of another camera can. So such a point is withheld until then, and then

- *confirmed* (output, one detection later than the others) when it agrees with that
  camera's 2D track: the camera's detections ``prev`` (its latest before ``t``) and ``next``
  (the confirming one) interpolated to ``t`` as eq. (1) does,
  ``u_i = (1 - w) u_prev + w u_next``, ``w = (t - t_prev) / (t_next - t_prev)``, against the
  projection of ``P'_t`` into that camera (undistorted pixels), the residual ``r``;
- ``contradicted`` (dropped, counted in ``Track.dropped``) when

      r > 4 σ_r + e_model

  with ``σ_r²`` the larger eigenvalue of ``J Σ J' + σ² ((1 - w)² + w²) I`` (``Σ``: the point's
  own first-order covariance, the ``cov_*_m2`` columns, from the detection noise ``σ``;
  ``J``: the projection's Jacobian; the interpolation's noise) and ``e_model`` the model's
  bound for a ball in flight, as the prediction test's: eq. (1)'s interpolation error
  ``½ g (t - t_prev) (t_next - t)`` plus eq. (2)'s extrapolation error, at most
  ``½ g δ span`` (``δ`` the gap bridged, ``span`` the point's ``span_s``), times ``f D / Z²``
  pixels per metre (``D``: distance from the camera, ``Z``: depth along its axis);
- ``unconfirmed`` (dropped) when no other camera that can check it detects the ball within
  the longest bridged gap (``max_gap_s``) after ``t``: a camera checks it with a detection
  within ``max_gap_s`` before ``t`` (else the next one is tried; with missed detections the
  first one often has none): nothing can tell.

``σ`` is at least the stated noise (``FusionOptions.noise_px``; 0.5 px when None) and the
noise the session's epipolar snaps imply (:func:`confirm_noise`), so a stated noise below
the detector's real one does not contradict good points in numbers. Four σ, not the
prediction test's five: a 2-D Gaussian residual exceeds ``4 σ_r`` with probability
``exp(-8) ≈ 3e-4``, and only the few percent of points that bridged a long gap are tested
(about 1e-5 of all points), while the covariance, which leaves out the correlation of the
point with the interpolated pixel (both use the confirming camera's earlier detection), is
itself on the large side (``bench_dirty.py --more``: a 77 mm point at 8.3 px against 5 σ_r
of 8.7 px). Without a covariance (``noise_px`` None or 0) ``Σ`` is replaced by ``σ² 14 I``
in the image (the prediction test's largest factor ``1 + (1 + ρ)² + ρ²``, ``ρ <= 2``).

Only points whose newest detection follows the previous detection (of any camera, an
earlier instant) by more than :data:`LONG_FACTOR` times the rig's usual interval (the
largest gap between consecutive shutter instants of its cameras' nominal schedules), or
whose previous instant has no detection of the newest camera within ``max_gap_s`` before it
(eq. (2)'s ``P_{t-1}`` then lies further back: a camera's first detection after a blind
spell), or whose previous instant itself followed the one before it by more than that
(session 17: eq. (2)'s ``P_{t-2}`` lies further back than usual, a camera blind between
the two past points; a kick inside that span makes the past velocity neither the motion
before nor after it, and the newest detection sees the error along its ray: ``lab4``,
``bench_dirty.py --more --first-seed 2000``, 51 mm), or whose two previous instants' rows
(eq. (2)'s ``P_{t-1}`` and ``P_{t-2}``, as a rule) include one that is its camera's first
after a spell of more than ``max_gap_s`` without one (session 31, :data:`FRESH_ROWS`: a
re-acquisition, the camera blind or the ball out of its view before; the gate chose it with
no track of that camera behind it, on the other cameras' epipolar lines and the 3D track,
whose allowances of 8 px and 8 cm let a spurious blob a dozen pixels from where the ball is
but is not seen through: ``lab3``, ``bench_dirty.py --more --first-seed 16200``, ``straight``,
132 mm at ``std_m`` 5.1 mm; ``lab4``, ``--first-seed 16300``, two points 63-127 mm), wait;
and (session 32, :data:`WAIT_SIGMAS`) points whose innovation across the newest ray, the
part gravity explains taken out, is large though below the prediction test's refusal
(:mod:`pslog.fusion.innovation`: ``r > 5 σ_r + e_model``) — a two-level test, a validation
gate and a confirmation, as trackers use: type A's kernel keeps for each point ``|u|²``, the
offset ``q⊥`` of eq. (2)'s ``P̂_t`` across the newest ray plus ``h (g - (rᵀg) r)`` (gravity's
offset ``-h g⊥`` taken out; ``h = ½ δ_pred (δ_pred + δ_prev)``: eq. (2)'s exact error under
gravity alone), and
``c = (factor D / f)²`` (metres² per pixel² of that offset's noise: the innovation's
``σ_r = σ factor`` pixels at distance ``D``, focal ``f``); under the model ``|u|² / (σ² c)``
is a χ² of two degrees of freedom, and the point waits when

    |u|² > WAIT_SIGMAS² σ² c,    WAIT_SIGMAS = 3

(``σ``: :func:`confirm_noise`, the confirmation's own; a valid point waits with probability
``exp(-9/2) ≈ 1.1 %`` at the right ``σ``, fewer at a stated noise above the real one). A
kick whose velocity change lies partly across the newest ray shows there below the
refusal's 5 σ while its part along the ray puts the point centimetres off (the tests' rally
300, paper3, 10 ms after a kick: 56.5 mm at 3-5 σ); one along the ray shows nowhere until
the next camera, which only waiting every point (``every``) catches. Such a point that no
camera can check is dropped (``unconfirmed``), as a long-gap point is.
(The columns are made with the covariance: with ``FusionOptions.noise_px`` None, type A's
throughput form, no point waits for its innovation.) The others are
output at once, as before. Causal: a point's decision uses
the detections up to the confirming one, so :class:`ConfirmedStream` (``StreamFuser``'s
``typeA``) decides as the batch run does, bit for bit (every step elementwise), and outputs
a withheld point with the confirming detection's push. docs/methods.md, "Type A across a
long gap", has the figures.

Offline only (``FusionOptions.confirm_every``, ``confirm_sides``): every point tested, and
with ``confirm_sides`` against every other camera on the point's side of a velocity jump
that camera's track shows (:func:`sides_test`; docs/methods.md, "Type A after kicks: the
side of the kick (session 33)").
"""

from __future__ import annotations

import math

import numpy as np

from ..motion import G
from ..records import NS, Track

#: A point waits for confirmation when its newest detection follows the previous one by
#: more than this many times the rig's usual interval between shutter instants.
LONG_FACTOR = 1.5
#: The test's threshold in standard deviations (module docstring: why 4, not 5).
CONFIRM_SIGMAS = 4.0
#: A point also waits when one of its two previous instants' rows is its camera's first
#: after a spell of ``max_gap_s`` without one (module docstring, session 31).
FRESH_ROWS = True
#: A point also waits when its innovation across the newest ray, eq. (2)'s gravity taken
#: out, exceeds this many standard deviations: ``|u|² > WAIT_SIGMAS² σ² c`` (module
#: docstring, session 32; None: the rule off, as before).
WAIT_SIGMAS: float | None = 3.0
#: :func:`sides_test` also drops a point nearer the other side's motion than its own side's
#: (False: the residual test against its own side only).
SIDES_NEARER = True
#: With :func:`sides_test`, a point the first confirming camera's interpolation contradicts
#: (``confirm_every``'s test) is dropped too.
SIDES_AND_FIRST = True
#: :func:`sides_test` also drops a point that a camera's reference shows further than this
#: from where that camera sees the ball, metres, beyond the reference's noise (None: off).
SIDES_PROVEN_M: float | None = 0.0255
#: ``1 + (1 + ρ)² + ρ²`` at ``ρ = 2`` (eq. (2)'s largest extrapolation): the point's
#: projection noise in σ² when no covariance is made.
_NO_COV_FACTOR2 = 14.0
_NONE = np.iinfo(np.int64).min
_COV = ("cov_xx_m2", "cov_yy_m2", "cov_zz_m2", "cov_xy_m2", "cov_xz_m2", "cov_yz_m2")


def usual_interval_s(rig) -> float:
    """The largest gap between consecutive shutter instants of the rig's cameras' nominal
    schedules (offset + k / fps over one second), seconds: for type-A staggered shutters
    ``1 / (n fps)``; the interval eq. (2) extrapolates across when every camera sees.
    (Made once per schedule: every type A run asks.)"""
    key = tuple((float(c.offset), float(c.fps)) for c in rig.cameras)
    interval = _USUAL_INTERVALS.get(key)
    if interval is None:
        times = np.sort(np.concatenate([
            (offset % (1.0 / fps)) + np.arange(math.ceil(fps) + 1) / fps
            for offset, fps in key]))
        times = times[times <= 1.0 + 1e-9]
        interval = float(np.max(np.diff(times))) if len(times) > 1 else 1.0
        if len(_USUAL_INTERVALS) < 64:  # (a few rigs in a process; bounded regardless)
            _USUAL_INTERVALS[key] = interval
    return interval


#: :func:`usual_interval_s` of the schedules met so far, by (offset, fps) per camera.
_USUAL_INTERVALS: dict[tuple, float] = {}


def _camera_rows(rig) -> np.ndarray:
    """Per camera (m, 17) float: K's fx, skew, cx, fy, cy, then R row-major (9), then t (3)
    (the world-to-camera rotation and translation)."""
    return np.array([[c.K[0, 0], c.K[0, 1], c.K[0, 2], c.K[1, 1], c.K[1, 2],
                      *np.asarray(c.R, dtype=np.float64).ravel(), *np.asarray(c.t).ravel()]
                     for c in rig.cameras], dtype=np.float64)


def residual_test(rows: np.ndarray, cam: np.ndarray, point: np.ndarray, cov: np.ndarray | None,
                  t_ns: np.ndarray, prev_ns: np.ndarray, next_ns: np.ndarray,
                  uv_prev: np.ndarray, uv_next: np.ndarray, gap_s: np.ndarray,
                  span_s: np.ndarray, sigma: np.ndarray, noise_px: float | None
                  ) -> np.ndarray:
    """The test of the module docstring for k withheld points (elementwise: the same bits
    for one point as for many).

    Parameters
    ----------
    rows : (m, 17) float, :func:`_camera_rows` of the rig
    cam : (k,) int, the confirming camera
    point : (k, 3) float, ``P'_t``, world metres
    cov : (k, 6) float or None, its covariance xx, yy, zz, xy, xz, yz, m²
    t_ns, prev_ns, next_ns : (k,) int, the point's time and the confirming camera's
        detections before and after it, ns (or, :func:`sides_test`, two of its detections on
        one side of it, in time order: the line through them extrapolated to ``t``)
    uv_prev, uv_next : (k, 2) float, their undistorted pixels
    gap_s : (k,) float, the gap the point bridged (newest minus previous detection), s
    span_s : (k,) float, the point's ``span_s``, s
    sigma : (k,) float, the detection noise the test assumes per axis, pixels
        (:func:`confirm_noise`)
    noise_px : float or None, the stated noise the covariance ``cov`` was made with

    Returns
    -------
    (k,) bool, True where the confirming camera contradicts the point (NaN: not)
    """
    r = rows[cam]
    stated = 0.0 if noise_px is None else float(noise_px)
    if not stated:  # (no covariance, or one of zero noise: nothing to scale)
        cov = None
    px, py, pz = point[:, 0], point[:, 1], point[:, 2]
    # camera coordinates X = R P + t, written out (no matrix product: the same bits per row)
    x = r[:, 5] * px + r[:, 6] * py + r[:, 7] * pz + r[:, 14]
    y = r[:, 8] * px + r[:, 9] * py + r[:, 10] * pz + r[:, 15]
    z = r[:, 11] * px + r[:, 12] * py + r[:, 13] * pz + r[:, 16]
    fx, s, cx, fy, cy = r[:, 0], r[:, 1], r[:, 2], r[:, 3], r[:, 4]
    with np.errstate(invalid="ignore", divide="ignore"):  # (rows not ok: NaN, never True)
        t = t_ns.astype(np.float64)
        d_prev = (t - prev_ns) / NS
        d_next = (next_ns - t) / NS
        w = d_prev / (d_prev + d_next)
        u_i = (1.0 - w) * uv_prev[:, 0] + w * uv_next[:, 0]
        v_i = (1.0 - w) * uv_prev[:, 1] + w * uv_next[:, 1]
        u = (fx * x + s * y) / z + cx
        v = fy * y / z + cy
        du, dv = u - u_i, v - v_i
        res = np.sqrt(du * du + dv * dv)
        interp = sigma * sigma * ((1.0 - w) * (1.0 - w) + w * w)
        if cov is None:
            a = c = interp + sigma * sigma * _NO_COV_FACTOR2
            b = np.zeros_like(a)
        else:
            # J = Jc R: Jc = [[fx/z, s/z, -(fx x + s y)/z²], [0, fy/z, -fy y/z²]]
            scale = (sigma / stated) ** 2
            ju = [(fx * r[:, 5 + i] + s * r[:, 8 + i]) / z - (fx * x + s * y) * r[:, 11 + i]
                  / (z * z) for i in range(3)]
            jv = [fy * r[:, 8 + i] / z - fy * y * r[:, 11 + i] / (z * z) for i in range(3)]
            cxx, cyy, czz, cxy, cxz, cyz = (cov[:, i] * scale for i in range(6))

            def quad(p, q):
                """p Σ q' for rows p, q of J."""
                return (p[0] * (cxx * q[0] + cxy * q[1] + cxz * q[2])
                        + p[1] * (cxy * q[0] + cyy * q[1] + cyz * q[2])
                        + p[2] * (cxz * q[0] + cyz * q[1] + czz * q[2]))

            a = quad(ju, ju) + interp
            c = quad(jv, jv) + interp
            b = quad(ju, jv)
        half = 0.5 * (a - c)
        sigma_r = np.sqrt(0.5 * (a + c) + np.sqrt(half * half + b * b))
        if cov is not None:  # a point without a finite covariance: tested as without one
            lost = ~np.isfinite(sigma_r)
            sigma_r[lost] = np.sqrt(interp[lost] + sigma[lost] * sigma[lost] * _NO_COV_FACTOR2)
        dist = np.sqrt(x * x + y * y + z * z)
        per_m = np.maximum(fx, fy) * dist / (z * z)
        # (|d_prev d_next|: the same bits for an interpolation, whose product is >= 0; an
        # extrapolation's pair, :func:`sides_test`, has one of them negative)
        model = 0.5 * G * (np.abs(d_prev * d_next) + gap_s * span_s) * per_m
        return res > CONFIRM_SIGMAS * sigma_r + model


def sides_test(rows: np.ndarray, time_ns: np.ndarray, camera: np.ndarray, uv: np.ndarray,
               e: np.ndarray, point: np.ndarray, cov: np.ndarray | None, gap_s: np.ndarray,
               span_s: np.ndarray, sigma: np.ndarray, noise_px: float | None,
               max_gap_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """The kick-aware test of k points against *every* other camera (offline,
    ``FusionOptions.confirm_sides``; docs/methods.md, "Type A after kicks: the side of the
    kick (session 33)"), elementwise.

    For each other camera ``c`` whose detections ``p1`` (its latest up to the point's row)
    and ``n1`` (its first after it) lie within ``max_gap_s`` of the point's time ``t``,
    with ``p2`` and ``n2`` its detections before ``p1`` and after ``n1``: ``f(s)``, the
    line through ``p2, p1`` (forward), and ``b(s)``, through ``n1, n2`` (backward). A velocity
    jump inside ``[p1, n1]`` shows as ``f(t_n1)`` missing ``u_n1`` by more than
    ``4 σ √((1 - w)² + w² + 1) + ½ g (t_n1 - t_p1)(t_n1 - t_p2) f D / Z²`` (``w`` the
    extrapolation's weight); then eq. (1)'s interpolation across ``[p1, n1]`` crosses the
    jump and is no check, and the point is tested against the side of the jump it lies on:
    the jump's instant ``s*`` where ``f`` and ``b`` meet (least squares of
    ``D(s) = f(s) - b(s) = D0 + D1 (s - t)``: ``s* - t = -D0·D1 / |D1|²``), the backward
    line ``b(t)`` when ``s* < t`` (``D0·D1 > 0``), else the forward ``f(t)``. Without a
    jump shown (or without ``p2``/``n2``), the interpolation, as :func:`residual_test`.
    The residual test is :func:`residual_test`'s with that pair (its noise
    ``σ² ((1 - w)² + w²)`` and model bound ``½ g |(t - t_A)(t - t_B)|`` hold for an
    extrapolation too). Two more ways a camera contradicts the point:

    - (:data:`SIDES_NEARER`) a jump shown, the two lines apart at ``t`` by more than
      ``4 σ √((1 - a_f)² + a_f² + (1 - a_b)² + a_b²)`` plus both lines' model bounds, and the
      point's projection nearer the other side's line than its own side's (the point follows
      the motion on the wrong side of the jump: eq. (2)'s depth from before a kick);
    - (:data:`SIDES_PROVEN_M`) the residual against the chosen line, less that line's own
      ``4 σ √((1 - w)² + w²)`` and model bound, exceeds ``SIDES_PROVEN_M f D / Z²`` pixels:
      the camera shows the point further than ``SIDES_PROVEN_M`` from the ball whatever its
      covariance says (type A's is overconfident just after a kick: error / ``std_m`` 3.9 at
      the median of its far points, session 28).

    Parameters
    ----------
    rows : (m, 17) float, :func:`_camera_rows`
    time_ns, camera : (n,) the observations' times (ns) and cameras, (time, camera) order
    uv : (n, 2) float, their undistorted pixels
    e : (k,) int, each point's row
    point, cov, gap_s, span_s, sigma, noise_px : as :func:`residual_test`
    max_gap_ns : int, ``max_gap_s`` in ns

    Returns
    -------
    (contradicted (k,) bool: by any camera; checked (k,) bool: some camera could check)
    """
    k = len(e)
    m = len(rows)
    t = time_ns[e]
    finite = np.all(np.isfinite(uv), axis=1)
    bad = np.zeros(k, dtype=bool)
    checked = np.zeros(k, dtype=bool)
    x, y, z = (rows[:, 5 + 3 * i][None, :] * point[:, 0:1]
               + rows[:, 6 + 3 * i][None, :] * point[:, 1:2]
               + rows[:, 7 + 3 * i][None, :] * point[:, 2:3] + rows[:, 14 + i][None, :]
               for i in range(3))
    for c in range(m):
        rows_c = np.flatnonzero(camera == c)
        nc = len(rows_c)
        if nc == 0:
            continue
        j = np.searchsorted(rows_c, e, side="right")  # rows_c[j]: c's first after the row
        # c's two latest rows up to the point's and two first after it (clipped: masked below)
        p2, p1, n1, n2 = (rows_c[np.clip(j + d, 0, nc - 1)] for d in (-2, -1, 0, 1))
        can = ((camera[e] != c) & (j >= 1) & (j < nc) & (t - time_ns[p1] <= max_gap_ns)
               & (time_ns[n1] - t <= max_gap_ns) & finite[p1] & finite[n1])
        full = (can & (j >= 2) & (j + 1 < nc) & finite[p2] & finite[n2]
                & (time_ns[p1] - time_ns[p2] <= max_gap_ns)
                & (time_ns[n2] - time_ns[n1] <= max_gap_ns))
        tp2, tp1 = time_ns[p2].astype(np.float64), time_ns[p1].astype(np.float64)
        tn1, tn2 = time_ns[n1].astype(np.float64), time_ns[n2].astype(np.float64)
        tt = t.astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            # the forward line's miss at n1: a jump inside [p1, n1] (or [p2, p1])
            wf = (tn1 - tp2) / (tp1 - tp2)
            miss = np.hypot((1 - wf) * uv[p2, 0] + wf * uv[p1, 0] - uv[n1, 0],
                            (1 - wf) * uv[p2, 1] + wf * uv[p1, 1] - uv[n1, 1])
            zc = z[:, c]
            dist = np.sqrt(x[:, c] ** 2 + y[:, c] ** 2 + zc ** 2)
            per_m = np.maximum(rows[c, 0], rows[c, 3]) * dist / (zc * zc)
            bound = (CONFIRM_SIGMAS * sigma * np.sqrt((1 - wf) ** 2 + wf ** 2 + 1)
                     + 0.5 * G * (tn1 - tp1) * (tn1 - tp2) / NS ** 2 * per_m)
            jump = full & (miss > bound)
            # the side: D(s) = f(s) - b(s) = D0 + D1 (s - t), f through p2, p1 and b through
            # n1, n2 (pixels, pixels per ns)
            vf = (uv[p1] - uv[p2]) / (tp1 - tp2)[:, None]
            vb = (uv[n2] - uv[n1]) / (tn2 - tn1)[:, None]
            d0 = (uv[p1] + vf * (tt - tp1)[:, None]) - (uv[n1] + vb * (tt - tn1)[:, None])
            before = np.sum(d0 * (vf - vb), axis=1) > 0  # s* < t: the point after the jump
            # the wrong side: the point's projection nearer the other side's line than its
            # own side's, the two lines apart at t by more than their noise and model bound
            # (a likelihood ratio of the two motions; the point's own covariance, which
            # type A's model term inflates just after a kick, enters neither distance)
            fx, sk, cx, fy, cy = (rows[c, i] for i in range(5))
            u = (fx * x[:, c] + sk * y[:, c]) / zc + cx
            v = fy * y[:, c] / zc + cy
            ft = uv[p1] + vf * (tt - tp1)[:, None]
            bt = uv[n1] + vb * (tt - tn1)[:, None]
            to_f = np.hypot(u - ft[:, 0], v - ft[:, 1])
            to_b = np.hypot(u - bt[:, 0], v - bt[:, 1])
            af = (tt - tp2) / (tp1 - tp2)
            ab = (tt - tn1) / (tn2 - tn1)
            sep_bound = (CONFIRM_SIGMAS * sigma * np.sqrt((1 - af) ** 2 + af ** 2
                                                          + (1 - ab) ** 2 + ab ** 2)
                         + 0.5 * G * ((tt - tp1) * (tt - tp2) + (tn1 - tt) * (tn2 - tt))
                         / NS ** 2 * per_m)
            wrong = (jump & (np.hypot(*(ft - bt).T) > sep_bound)
                     & np.where(before, to_b > to_f, to_f > to_b))
        a = np.where(jump, np.where(before, n1, p2), p1)
        b = np.where(jump, np.where(before, n2, p1), n1)
        verdict = residual_test(rows, np.full(k, c), point, cov, t, time_ns[a], time_ns[b],
                                uv[a], uv[b], gap_s, span_s, sigma, noise_px)
        if SIDES_PROVEN_M is not None:
            # the distance the camera proves: the residual less the reference's own noise
            # and model bound (not the point's covariance: type A's is overconfident just
            # after a kick), over the pixels per metre across its ray
            with np.errstate(invalid="ignore", divide="ignore"):
                ta, tb = time_ns[a].astype(np.float64), time_ns[b].astype(np.float64)
                w = (tt - ta) / (tb - ta)
                ref = (1 - w)[:, None] * uv[a] + w[:, None] * uv[b]
                excess = (np.hypot(u - ref[:, 0], v - ref[:, 1])
                          - CONFIRM_SIGMAS * sigma * np.sqrt((1 - w) ** 2 + w ** 2)
                          - 0.5 * G * np.abs((tt - ta) * (tt - tb)) / NS ** 2 * per_m)
                verdict = verdict | (excess > SIDES_PROVEN_M * per_m)
        bad |= (verdict | (wrong if SIDES_NEARER else False)) & can
        checked |= can
    return bad, checked


def _readonly(a: np.ndarray, dtype) -> np.ndarray:
    """``a`` as a C-contiguous read-only array of ``dtype`` (a view where it is one
    already): :func:`pslog.fusion._confirm_kernel.confirm_kernel` called in one signature
    whoever calls it (numba compiles one per dtype, layout and writability)."""
    a = np.ascontiguousarray(a, dtype=dtype).view()
    a.flags.writeable = False
    return a


def _camera_order(camera: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Each camera's rows in order, camera ``c``'s at ``by_camera[starts[c]:starts[c + 1]]``
    ((n,) int64 and (m + 1,) int64; the rows of a camera index outside ``[0, m)`` left
    out)."""
    per = [np.flatnonzero(camera == c) for c in range(m)]
    starts = np.zeros(m + 1, dtype=np.int64)
    np.cumsum([len(p) for p in per], out=starts[1:])
    by_camera = np.concatenate(per) if per else np.zeros(0, dtype=np.int64)
    return by_camera.astype(np.int64, copy=False), starts


def _run_kernel(rows: np.ndarray, time_ns: np.ndarray, camera: np.ndarray, uv: np.ndarray,
                row: np.ndarray, at: np.ndarray, point: np.ndarray, cov, gap_s: np.ndarray,
                span_s: np.ndarray, sigma: np.ndarray, noise_px: float | None,
                max_gap_ns: int, first: bool, sides: bool) -> tuple[np.ndarray, ...]:
    """:func:`pslog.fusion._confirm_kernel.confirm_kernel`'s call (its arguments as there;
    ``cov`` six columns or None); the module's switches read now. Returns ``(first_bad,
    ok, bad, checked)``, (k,) bool each (the tests not run: unset)."""
    from ._confirm_kernel import confirm_kernel  # (numba: imported at the first use)

    k, m = len(at), len(rows)
    camera = np.asarray(camera)
    by_camera, starts = _camera_order(camera, m)
    f64, i64 = np.float64, np.int64
    columns = (tuple(_readonly(c, f64) for c in cov) if cov is not None
               else (_readonly(np.zeros(0), f64),) * 6)
    out = tuple(np.empty(k, dtype=np.bool_) for _ in range(4))
    confirm_kernel(_readonly(rows, f64), _readonly(time_ns, i64), _readonly(camera, np.int32),
                   _readonly(uv, f64), _readonly(row, i64), _readonly(at, i64),
                   _readonly(point, f64), cov is not None, columns, _readonly(gap_s, f64),
                   _readonly(span_s, f64), _readonly(sigma, f64),
                   0.0 if noise_px is None else float(noise_px), int(max_gap_ns),
                   _readonly(by_camera, i64), _readonly(starts, i64), float(CONFIRM_SIGMAS),
                   bool(first), bool(sides), bool(SIDES_NEARER),
                   np.nan if SIDES_PROVEN_M is None else float(SIDES_PROVEN_M), *out)
    return out


def _sides_compiled(rows: np.ndarray, time_ns: np.ndarray, camera: np.ndarray,
                    uv: np.ndarray, e: np.ndarray, point: np.ndarray, cov: np.ndarray | None,
                    gap_s: np.ndarray, span_s: np.ndarray, sigma: np.ndarray,
                    noise_px: float | None, max_gap_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sides_test`, the same decisions, by the compiled kernel
    (:func:`pslog.fusion._confirm_kernel.confirm_kernel`: a loop over points and cameras
    instead of ~100 column operations per camera); the module's switches read now."""
    k = len(e)
    columns = None if cov is None else [np.asarray(cov)[:, i] for i in range(6)]
    out = _run_kernel(rows, time_ns, camera, uv, e, np.arange(k, dtype=np.int64), point,
                      columns, gap_s, span_s, sigma, noise_px, max_gap_ns, False, True)
    return out[2], out[3]


def _tests_compiled(rows: np.ndarray, time_ns: np.ndarray, camera: np.ndarray,
                    uv: np.ndarray, row: np.ndarray, idx: np.ndarray, point: np.ndarray,
                    cov: list | None, gap_s: np.ndarray, span_s: np.ndarray,
                    sigma: np.ndarray, noise_px: float | None, max_gap_ns: int,
                    sides: bool) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_tests_numpy`'s decisions, by the compiled kernel in one pass over the points
    (no (k,) gathers of the track's columns, no search over all the points at each row
    after them); the same bits (``tests/test_type_a_confirm_compiled.py``)."""
    first_bad, ok, bad = _run_kernel(rows, time_ns, camera, uv, row, idx, point, cov, gap_s,
                                     span_s, sigma, noise_px, max_gap_ns, True, sides)[:3]
    if sides:
        return (first_bad | bad) if SIDES_AND_FIRST else bad, ok
    return first_bad, ok


def _tests_numpy(rows: np.ndarray, time_ns: np.ndarray, camera: np.ndarray, uv: np.ndarray,
                 row: np.ndarray, idx: np.ndarray, point: np.ndarray, cov: list | None,
                 gap_s: np.ndarray, span_s: np.ndarray, sigma: np.ndarray,
                 noise_px: float | None, max_gap_ns: int, sides: bool
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`confirm_batch`'s tests of the k waiting points ``idx`` of a track (numpy: the
    statement :func:`_tests_compiled` follows).

    Parameters
    ----------
    rows : (m, 17) float, :func:`_camera_rows`
    time_ns, camera, uv : the observations' (n,) times (ns), (n,) cameras and (n, 2)
        undistorted pixels, in (time, camera) order
    row : (p,) int, each of the track's points' row
    idx : (k,) int, the points tested, indices into the track
    point, cov, gap_s, span_s, sigma : the track's (p, 3) points, six (p,) covariance
        columns (xx, yy, zz, xy, xz, yz; None: none), (p,) gaps and spans (s) and the
        tests' noise (px): :func:`residual_test`'s
    noise_px : the stated noise; max_gap_ns : int
    sides : :func:`sides_test` as well (``confirm_sides``)

    Returns
    -------
    (contradicted (k,) bool, ok (k,) bool: a confirming detection found)
    """
    n, m = len(time_ns), len(rows)
    e = row[idx]
    # the confirming detection: the first later row of another camera that can check the
    # point (its camera has a row within max_gap_s before the point, both pixels finite),
    # within max_gap_s of the point; the rows are scanned in order, as a stream meets them
    finite = np.all(np.isfinite(uv), axis=1)
    # each row's previous row of its own camera, and each long point's latest row per camera
    last_before = np.full((len(e), m), -1, dtype=np.int64)
    for c in range(m):
        rows_c = np.flatnonzero(camera == c)
        if len(rows_c) == 0:  # a camera with no detection at all: it confirms nothing
            continue
        k = np.searchsorted(rows_c, e, side="left") - 1
        last_before[:, c] = np.where(k >= 0, rows_c[np.maximum(k, 0)], -1)
    nxt = np.full(len(e), -1, dtype=np.int64)
    prev = np.full(len(e), -1, dtype=np.int64)
    pending = np.ones(len(e), dtype=bool)
    r = e + 1
    while pending.any():
        r_c = np.minimum(r, n - 1)
        pending &= (r < n) & (time_ns[r_c] - time_ns[e] <= max_gap_ns)  # else unconfirmed
        before = last_before[np.arange(len(e)), camera[r_c]]
        b_c = np.maximum(before, 0)
        found = (pending & (camera[r_c] != camera[e]) & (before >= 0)
                 & (time_ns[e] - time_ns[b_c] <= max_gap_ns) & finite[b_c] & finite[r_c])
        nxt[found], prev[found] = r_c[found], before[found]
        pending &= ~found
        r += 1
    ok = nxt >= 0
    nxt_c, prev_c = np.maximum(nxt, 0), np.maximum(prev, 0)
    cov_k = None if cov is None else np.stack([c[idx] for c in cov], axis=1)
    contradicted = residual_test(
        rows, camera[nxt_c], point[idx], cov_k, time_ns[e], time_ns[prev_c], time_ns[nxt_c],
        uv[prev_c], uv[nxt_c], gap_s[idx], span_s[idx], sigma[idx], noise_px) & ok
    if sides:
        side = sides_test(rows, time_ns, camera, uv, e, point[idx], cov_k, gap_s[idx],
                          span_s[idx], sigma[idx], noise_px, max_gap_ns)[0]
        contradicted = (contradicted | side) if SIDES_AND_FIRST else side
    return contradicted, ok


#: Median of |N(0, 1)|: a half-normal's median, in σ.
_HALF_NORMAL_MEDIAN = 0.6744897501960817


def confirm_noise(snap_px: np.ndarray, noise_px: float | None, estimate=None) -> np.ndarray:
    """The detection noise the test assumes for each of k points in row order, pixels:
    at least the stated one (0.5 when None) and the noise the points' own epipolar snaps
    imply (a stated noise below the detector's real one would contradict good points in
    numbers, as it refused them in type A's tests: docs/methods.md, "The tests' σ").

    ``snap_px`` is eq. (1)'s interpolated point's distance to the epipolar line: under the
    model a 1-D Gaussian's norm, of about ``σ √((1 - w)² + w² + 1) ≈ σ √1.5`` (the
    interpolation, and the observed point moving the line), whose median is 0.674 times
    that. Each is scaled to the Rayleigh median :class:`~pslog.fusion.innovation.NoiseEstimate`
    takes, which gives each point the causal median of those before it (the same values in
    a stream, ``estimate`` kept across its pushes). Returns (k,) float."""
    from .innovation import RAYLEIGH_MEDIAN, NoiseEstimate

    scale = RAYLEIGH_MEDIAN / (_HALF_NORMAL_MEDIAN * math.sqrt(1.5))
    values = np.asarray(snap_px, dtype=np.float64) * scale
    return (NoiseEstimate() if estimate is None else estimate).sigmas(values, noise_px)


#: type A's kernel's columns the innovation rule reads (:data:`pslog.fusion.pseudo.
#: _MODEL_COLUMNS`): the innovation's across-ray offset less gravity's, m², and its noise's
#: metres² per pixel² ``c = (factor D / f)²``
_ACROSS, _PER_PX2 = "_model_across_m2", "_model_m2_per_px2"


def innovation_waits(across_m2: np.ndarray | float, per_px2: np.ndarray | float,
                     sigma: np.ndarray | float) -> np.ndarray | bool:
    """Which points wait for their innovation (module docstring, session 32), elementwise
    (the same bits for one point as for many): ``|u|² > WAIT_SIGMAS² σ² c``.

    Parameters
    ----------
    across_m2 : (k,) float or float, ``|u|²``, the prediction's offset across the newest
        ray with gravity's part taken out, m² (type A's kernel's ``_model_across_m2``)
    per_px2 : (k,) float or float, ``c = (factor D / f)²``, m² per pixel²
        (``_model_m2_per_px2``)
    sigma : (k,) float or float, the detection noise per axis, pixels
        (:func:`confirm_noise`; the products are monotone in it, so a point that does not
        wait at a σ waits at no smaller one)

    Returns
    -------
    (k,) bool (NaN: False); a bool for floats (:class:`ConfirmedStream`'s one point)
    """
    k = math.inf if WAIT_SIGMAS is None else float(WAIT_SIGMAS)  # (None: no point waits)
    k2 = k * k
    return across_m2 > k2 * (sigma * sigma) * per_px2


def confirm_batch(prep, track: Track, rig, max_gap_s: float, noise_px: float | None,
                  every: bool = False, sides: bool = False, only: np.ndarray | None = None
                  ) -> Track:
    """``track`` (type A's, from ``prep``'s observations) with its waiting points (long gaps,
    re-acquisitions, a large innovation: module docstring) confirmed, contradicted or
    unconfirmed; the dropped ones counted in ``Track.dropped`` (``contradicted``,
    ``unconfirmed``).

    ``every`` (offline only, ``FusionOptions.confirm_every``): every point is tested the same
    way, not only the waiting ones, and dropped when contradicted; a point no other camera
    can check is kept unless it was a waiting one (as without ``every``). The long-gap
    points' decisions are the same bits either way (the test is elementwise).

    ``only`` ((len(track),) bool, or None: every point): the points wanted; the others are
    left out of the result untested and uncounted. Each wanted point's decision is the one
    it has in the whole track's run, bit for bit: the tests are elementwise, and their σ
    (:func:`confirm_noise`, a causal median over every point made) is taken from the
    whole track (type A's backward pass, :func:`pslog.fusion.breaks.across_breaks`, needs
    its points on the few detections a break spans: session 45).

    ``sides`` (with ``every``; ``FusionOptions.confirm_sides``): the test is
    :func:`sides_test`'s, against every other camera that can check the point, each on the
    point's side of a velocity jump its track shows, instead of the first confirming
    camera's interpolation (the waiting points' too); unconfirmed points as before."""
    if not len(track):
        return track
    from . import _pseudo_kernel  # (numba: imported at the first use)
    from .innovation import previous_next_rows
    from .pseudo import _all_brackets

    whole_sigma = None
    if only is not None:
        whole_sigma = confirm_noise(track.quality["snap_px"], noise_px)[only]
        track = _with_drops(track, ~only, 0, 0)
        if not len(track):
            return track

    obs = prep.obs
    time_ns, camera = obs.time_ns, obs.camera
    max_gap_ns = int(max_gap_s * NS)
    long_ns = LONG_FACTOR * usual_interval_s(rig) * NS
    # each point's row (its (time, camera) in the (time, camera)-sorted observations), the
    # gap since the previous instant, and whether the point waits: that gap long, or the
    # previous instant's own (eq. (2)'s P_{t-2} further back than usual: a camera blind
    # between the two past points, the span a kick can hide in; module docstring), or the
    # previous instant of another camera while the point's has no row within max_gap_s
    # before it (a camera's first detection after a blind spell: P_{t-1} an earlier instant
    # still). From the tables type A made of the same rows (each row's previous instant,
    # _all_brackets, and its camera's previous row, previous_next_rows), in one compiled
    # pass (numpy's searchsorted and (n,) gathers were 0.3 of type A's ~10 ms a 2-minute
    # session)
    points = len(track)
    row, gap = np.empty(points, dtype=np.int64), np.empty(points, dtype=np.int64)
    long = np.empty(points, dtype=bool)
    _pseudo_kernel.long_gap_kernel(
        time_ns, camera, len(rig), _all_brackets(prep)[2], previous_next_rows(prep)[0],
        track.time_ns, track.camera, max_gap_ns, float(long_ns), FRESH_ROWS, row, gap, long)
    q = track.quality
    sigma = None
    kick = None
    if WAIT_SIGMAS is not None and _ACROSS in q:
        # (session 32: a large innovation across the newest ray, gravity's part out, waits;
        # σ is at least the stated noise's floor, so no point waits unless one would at the
        # floor: the σ, a causal median over every point, made only then)
        from .innovation import DEFAULT_NOISE_PX

        floor = DEFAULT_NOISE_PX if noise_px is None else float(noise_px)
        if np.any(innovation_waits(q[_ACROSS], q[_PER_PX2], floor)):
            sigma = (confirm_noise(q["snap_px"], noise_px) if whole_sigma is None
                     else whole_sigma)
            kick = innovation_waits(q[_ACROSS], q[_PER_PX2], sigma)
            long = long | kick
    wait = long | every  # (every: all the points)
    if not wait.any():
        return track
    # (the tests' noise, a causal median over every point: made only when some point waits)
    if sigma is None:
        sigma = (confirm_noise(q["snap_px"], noise_px) if whole_sigma is None
                 else whole_sigma)
    idx = np.flatnonzero(wait)
    cov = [q[k] for k in _COV] if all(k in q for k in _COV) else None
    contradicted, ok = _tests_compiled(
        _camera_rows(rig), time_ns, camera, prep.uv_undistorted, row, idx,
        track.position_world, cov, gap / NS, q["span_s"], sigma, noise_px, max_gap_ns, sides)
    # (a point that neither bridged a long gap nor waits for its innovation: kept unchecked)
    unconfirmed = ~ok & long[idx]
    drop = np.zeros(len(track), dtype=bool)
    drop[idx[unconfirmed]] = True
    drop[idx[contradicted]] = True
    return _with_drops(track, drop, int(np.count_nonzero(contradicted)),
                       int(np.count_nonzero(unconfirmed)))


def _with_drops(track: Track, drop: np.ndarray, contradicted: int, unconfirmed: int) -> Track:
    dropped = dict(track.dropped)
    for reason, count in (("contradicted", contradicted), ("unconfirmed", unconfirmed)):
        if count:
            dropped[reason] = dropped.get(reason, 0) + count
    if not drop.any():
        return Track(track.method, track.time_ns, track.position_world, track.camera,
                     track.quality, dropped)
    keep = ~drop
    return Track(track.method, track.time_ns[keep], track.position_world[keep],
                 track.camera[keep], {k: v[keep] for k, v in track.quality.items()}, dropped)


class ConfirmedStream:
    """:class:`~pslog.fusion.pseudo.TypeAStream` with :func:`confirm_batch`'s decisions,
    causally: a waiting point (a long gap, a re-acquisition, a large innovation: the module
    docstring) is held until the first later detection of another camera
    that can check it (a detection of that camera within ``max_gap_s`` before the point)
    (output with that push when confirmed), or dropped when that detection contradicts it,
    when a detection beyond ``max_gap_s`` arrives first, or at :meth:`flush`. The same points
    and counts as the batch run.

    Parameters
    ----------
    inner : the TypeAStream
    rig : Rig
    options : FusionOptions (``max_gap_s`` None: the rig's default)
    """

    def __init__(self, inner, rig, options) -> None:
        from ._prepare import default_max_gap_s

        self.inner = inner
        self.rig = rig
        self._noise_px = options.noise_px
        self._max_gap_ns = int((options.max_gap_s or default_max_gap_s(rig)) * NS)
        self._long_ns = LONG_FACTOR * usual_interval_s(rig) * NS
        self._rows = _camera_rows(rig)
        from .innovation import NoiseEstimate

        self._noise = NoiseEstimate()  # the test's noise, from every point's snap so far
        # the last row of each camera: (time ns, recorded uv (2,)); undistorted when needed
        self._last: list[tuple[int, np.ndarray] | None] = [None] * len(rig)
        self._newest = (_NONE, _NONE)  # the newest time, and the latest before it
        # the latest time before the newest minus the one before it, ns (-1: none): the
        # previous instant's own gap
        self._gap_before = -1
        # (time, camera) of the newest row, and of the last row before the newest instant
        self._latest: tuple[int, int] | None = None
        self._previous_row: tuple[int, int] | None = None
        # whether each of those rows, and the last row of the instant before the previous
        # one, was its camera's first after a spell of max_gap_s without one (FRESH_ROWS)
        self._latest_fresh = self._previous_fresh = self._before_fresh = False
        # the points not yet output, in row order: [one-row Track, status ("wait",
        # "confirmed", "contradicted", "unconfirmed"), (time, camera, gap ns, the last row
        # of each camera then) of a withheld one]
        self._queue: list[list] = []

    def _undistorted(self, cam: int, uv: np.ndarray) -> np.ndarray:
        """prepare's undistorted pixel of one recorded pixel (the same bits, row by row)."""
        from ._prepare import _FAR_IMAGES

        c = self.rig.cameras[cam]
        uv = uv.reshape(1, 2)
        if not np.all(np.abs(uv) <= _FAR_IMAGES * max(c.width, c.height)):
            return np.full((1, 2), np.nan)
        return c.pixels_from_normalized(c.undistort_normalized(uv))

    def push(self, time_ns, camera, uv, frame_index) -> Track:
        """The inner stream's push; returns the points decided (in time order: a point
        behind a withheld one waits with it)."""
        out = self.inner.push(time_ns, camera, uv, frame_index)
        if not len(time_ns):
            return out
        if not self._queue and not len(out):  # (nothing withheld, no point: the rows only)
            self._rows_seen(np.asarray(time_ns, dtype=np.int64).tolist(),
                            np.asarray(camera).tolist(), np.asarray(uv, dtype=np.float64))
            return out
        time_l = np.asarray(time_ns, dtype=np.int64).tolist()
        cam_l = np.asarray(camera).tolist()
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        point_of = {(t, c): i for i, (t, c) in enumerate(zip(out.time_ns.tolist(),
                                                             out.camera.tolist(),
                                                             strict=True))}
        sigma = (confirm_noise(out.quality["snap_px"], self._noise_px, self._noise).tolist()
                 if len(out) else [])
        queue = self._queue
        for j, (t, c) in enumerate(zip(time_l, cam_l, strict=True)):
            for entry in queue:  # the withheld points this row decides
                if entry[1] == "wait":
                    entry[1] = self._decide(entry, t, c, uv[j])
            gap, previous = self._gap(t), self._previous
            i = point_of.get((t, c))
            if i is not None:
                own = self._last[c]
                unbracketed = previous is not None and previous[1] != c and (
                    own is None or previous[0] - own[0] > self._max_gap_ns)
                fresh = FRESH_ROWS and previous is not None and (self._previous_fresh
                                                                 or self._before_fresh)
                kick = False
                if WAIT_SIGMAS is not None and _ACROSS in out.quality:
                    # (innovation_waits on Python floats: the same IEEE products and
                    # comparison as the batch's elementwise ones, no (1,) arrays)
                    kick = bool(innovation_waits(float(out.quality[_ACROSS][i]),
                                                 float(out.quality[_PER_PX2][i]),
                                                 float(sigma[i])))
                if (gap > self._long_ns or unbracketed or self._gap_before > self._long_ns
                        or fresh or kick):
                    queue.append([out.select([i]), "wait",
                                  (t, c, gap, list(self._last), sigma[i])])
                else:
                    queue.append([out.select([i]), "confirmed", None])
            self._record(t, c, uv[j])
        return self._emit(out.dropped, final=False)

    def _rows_seen(self, time_l, cam_l, uv) -> None:
        """The rows' times and pixels recorded (no point to decide)."""
        uv = uv.reshape(-1, 2)
        for j, (t, c) in enumerate(zip(time_l, cam_l, strict=True)):
            self._gap(t)
            self._record(t, c, uv[j])

    def _record(self, t: int, c: int, uv: np.ndarray) -> None:
        """A row seen: the last row of its camera, and of the session (the previous
        instant's row of the rows at later times)."""
        own = self._last[c]
        self._latest_fresh = own is None or t - own[0] > self._max_gap_ns
        self._last[c] = (t, uv)
        self._latest = (t, c)

    @property
    def _previous(self) -> tuple[int, int] | None:
        """(time, camera) of the last row at the latest instant before the newest row's."""
        return self._previous_row

    def _gap(self, t: int) -> int:
        """The new row's time minus the latest earlier instant, ns (-1: none); recorded."""
        newest, before = self._newest
        if t > newest:
            self._gap_before = newest - before if before != _NONE else -1
            before, newest = newest, t
            self._previous_row = self._latest
            # (the previous instant's row's freshness, and its own previous instant's)
            self._before_fresh = self._previous_fresh and self._latest is not None
            self._previous_fresh = self._latest_fresh and self._latest is not None
        self._newest = (newest, before)
        return t - before if before != _NONE else -1

    def _emit(self, dropped, final: bool) -> Track:
        """The decided front of the queue (every entry when ``final``: the withheld ones
        unconfirmed), as one Track with ``dropped`` and this push's drops."""
        parts = [Track("typeA", np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32),
                       dropped=dropped)]
        counts = {"contradicted": 0, "unconfirmed": 0}
        queue = self._queue
        k = 0
        while k < len(queue) and (final or queue[k][1] != "wait"):
            status = queue[k][1]
            if status == "confirmed":
                parts.append(queue[k][0])
            else:
                counts["unconfirmed" if status == "wait" else status] += 1
            k += 1
        del queue[:k]
        if len(parts) == 2 and not dropped and not any(counts.values()):
            return parts[1]
        result = Track.concat(parts)
        return _with_drops(result, np.zeros(len(result), dtype=bool), counts["contradicted"],
                           counts["unconfirmed"])

    def _decide(self, entry, t: int, c: int, uv: np.ndarray) -> str:
        """A withheld point's verdict at a new row (time ``t``, camera ``c``, recorded pixel
        ``uv``): wait, confirmed, contradicted or unconfirmed."""
        point, _, held = entry
        t0, c0, gap, last, sigma = held
        if t - t0 > self._max_gap_ns:
            return "unconfirmed"
        if c == c0:
            return "wait"
        # a camera that cannot check it (no row of its own within max_gap_s before the
        # point, a pixel not undistorted): the next row of another camera may
        before = last[c]
        if before is None or t0 - before[0] > self._max_gap_ns:
            return "wait"
        uv_prev = self._undistorted(c, before[1])
        uv_next = self._undistorted(c, uv)
        if not (np.all(np.isfinite(uv_prev)) and np.all(np.isfinite(uv_next))):
            return "wait"
        q = point.quality
        cov = (np.stack([q[k] for k in _COV], axis=1) if all(k in q for k in _COV) else None)
        bad = residual_test(self._rows, np.array([c]), point.position_world, cov,
                            np.array([t0]), np.array([before[0]]), np.array([t]), uv_prev,
                            uv_next, np.array([gap / NS]), q["span_s"], np.array([sigma]),
                            self._noise_px)
        return "contradicted" if bool(bad[0]) else "confirmed"

    def flush(self) -> Track:
        """The end of the stream: the points still withheld are unconfirmed; those behind
        them are output."""
        return self._emit({}, final=True)
