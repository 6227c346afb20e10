"""Type A across a break of the session's fit: the backward pass (offline; session 37).

Type A's last far points under the offline kick test (``confirm_sides``) are eq. (1)/(4)'s
construction across a kick that one far camera cannot prove: the depth along the newest ray
comes from the motion before the kick (docs/methods.md, "Type A's last far points against the
session's fit"). The same equations run on the time-reversed observations (the *backward
pass*) take each detection's depth from the points after it: right just after a kick, wrong
just before one. Which of the two holds needs the kick's instant, which ``smooth``'s fit of
the session has (its velocity breaks, :attr:`pslog.estimation.Trajectory.breaks_s`): since
session 44 the fit of ``smooth``'s own input (the detections as its offline gate chooses
them, its rule for the choices in doubt), made once when both methods are fused
(:class:`SessionFit`), so that type A's points do not depend on whether ``smooth`` is fused
beside it; before, type A fitted its own causal gate's choices, a second whole fit in a
default ``pslog fuse`` (docs/methods.md, "One fit for both (session 44)").

With ``FusionOptions.confirm_breaks`` (``pslog fuse --confirm-gaps breaks``: the fit's breaks;
``jumps``, the offline default since session 45: the kick instants the images show,
:func:`image_kicks_ns`), a type A point
whose construction spans a break (one in ``(t - span_s, t]``) is replaced by the backward
pass's point on the same detection (made with the same options, its own covariance) when
that construction spans none (none in ``[t, t + span_b)``), and is withheld (``break`` in
``Track.dropped``) when both span one or the backward pass has no point there. Every other
point is the forward pass's, to the bit. docs/methods.md, "Type A across a break: the
backward pass (session 37)".
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import replace
from typing import Literal

import numpy as np

from ..records import NS, Observations, Track, matching_rows, point_keys
from ..rig import Rig
from . import BREAK_SOURCES
from ._prepare import Prepared, prepare


def fit_breaks_ns(prep: Prepared, rig: Rig, options) -> np.ndarray:
    """(k,) int64, sorted: the instants (ns) of the velocity breaks of ``smooth``'s fit of
    ``prep``'s observations (:func:`pslog.fusion.smooth.session_fit`: its rule for the
    gate's choices in doubt); empty when no stretch is seen by two cameras. ``options``:
    FusionOptions with ``max_gap_s`` set (the fit's; the clocks' consider covariance is not
    needed for the breaks, which it does not move, and not made)."""
    return SessionFit(lambda: prep, rig, replace(options, clock_covariance=None)).breaks_ns()


def session_breaks_ns(fit) -> np.ndarray:
    """(k,) int64, sorted: the break instants (ns) of a ``smooth`` fit
    (:class:`pslog.estimation.Fit`, or None: none)."""
    if fit is None:
        return np.zeros(0, np.int64)
    trajectory = fit.trajectory
    return np.sort(trajectory.t0_ns + np.round(np.asarray(trajectory.breaks_s) * 1e9
                                               ).astype(np.int64))


class SessionFit:
    """``smooth``'s fit of one session (:func:`pslog.fusion.smooth.session_fit` of the
    prepared observations ``make_input()`` returns: ``smooth``'s own input, its gating form
    and doubt), made once, by whichever asks first: ``smooth``'s fusion (its track) or type
    A's ``confirm_breaks`` (the kick instants); a thread asking while it is made waits for
    it. So a ``pslog fuse`` of both fits once, and type A's breaks are the same whether
    ``smooth`` is fused beside it or not (its breaks do not depend on the clocks' consider
    covariance that only ``smooth``'s own track needs). ``options``: FusionOptions with
    ``max_gap_s`` set, ``smooth``'s. ``users``: the methods that use it (``"smooth"``,
    ``"typeA"``), each releasing its use once (:meth:`release`; type A as soon as it has
    the breaks, :meth:`take_breaks`: its backward pass does not hold the fit); after the
    last, the fit and its input are dropped and ``on_drop`` is called."""

    def __init__(self, make_input: Callable[[], Prepared], rig: Rig, options,
                 users: tuple[str, ...] = ("typeA",),
                 on_drop: Callable[[], object] | None = None) -> None:
        self._make_input: Callable[[], Prepared] | None = make_input
        self._rig, self._options = rig, options
        self._lock = threading.Lock()
        self._value: tuple | None = None
        self._users = set(users)
        self._on_drop = on_drop

    def fitted(self) -> tuple:
        """``session_fit``'s ``(fit or None, observations, n_doubt)``."""
        from .smooth import session_fit

        with self._lock:
            if self._value is None:
                if self._make_input is None:
                    raise RuntimeError("SessionFit used after its last release")
                self._value = session_fit(self._make_input(), self._rig, self._options)
            return self._value

    def release(self, user: str = "typeA") -> bool:
        """``user``'s use done (again: nothing more); after the last user's (True), the fit
        and its input are dropped (a 90-minute match's fit holds hundreds of MB)."""
        with self._lock:
            if user not in self._users:
                return False
            self._users.discard(user)
            if self._users:
                return False
            self._value, self._make_input = None, None
            on_drop, self._on_drop = self._on_drop, None
        if on_drop is not None:
            on_drop()
        return True

    def breaks_ns(self) -> np.ndarray:
        """(k,) int64, sorted: the fit's break instants (:func:`session_breaks_ns`)."""
        return session_breaks_ns(self.fitted()[0])

    def take_breaks(self) -> np.ndarray:
        """:meth:`breaks_ns`, then type A's use released (its backward pass needs no more of
        the fit)."""
        breaks = self.breaks_ns()
        self.release("typeA")
        return breaks


def fit_shared(methods, rig: Rig, options) -> bool:
    """Whether type A's ``confirm_breaks`` takes a fit's breaks (its ``"fit"`` source)
    when ``methods`` fuse one session under ``options`` (FusionOptions): then it and
    ``smooth`` share one :func:`shared_fit`."""
    return bool("typeA" in methods and options.confirm_breaks
                and options.break_source == "fit" and len(rig) >= 2)


def shared_fit(methods, rig: Rig, options, make_input: Callable[[], Prepared],
               on_drop: Callable[[], object] | None = None) -> SessionFit:
    """The :class:`SessionFit` that type A's ``confirm_breaks`` and ``smooth`` share when
    ``methods`` fuse one session (:func:`fit_shared`; ``make_input``: ``smooth``'s prepared
    input; ``options``: the fusion's FusionOptions): with ``smooth`` among the methods the
    fit is its own (its options, the clocks' consider covariance too), without it the
    breaks' alone (no consider)."""
    from ._prepare import default_max_gap_s

    fit_options = replace(options, max_gap_s=options.max_gap_s or default_max_gap_s(rig))
    if "smooth" not in methods:  # (only smooth's own track needs the clocks' consider)
        fit_options = replace(fit_options, clock_covariance=None)
    return SessionFit(make_input, rig, fit_options,
                      ("typeA", "smooth") if "smooth" in methods else ("typeA",), on_drop)


#: ``break_source="image"``: a camera's image track shows a velocity jump between two of its
#: detections ``p1``, ``n1`` where the line through ``p2, p1`` misses ``n1`` by more than this
#: many σ of its noise (plus gravity's bend: :func:`image_kicks_ns`). Chosen on development
#: sessions (seeds 77400-77700: 3.5 and 4 left the same far points at 30 fps, 3.5 one fewer
#: at 60 fps for 10 % more good points withheld) before the held-out runs (docs/methods.md,
#: "Kick instants from the images (session 44)")
IMAGE_KICK_SIGMAS = 3.5
#: Image jumps of the cameras this close in time are one kick (its instant: their mean, each
#: weighted by its precision), seconds: two kicks or bounces of a rally are 80 ms apart or more
IMAGE_KICK_MERGE_S = 0.015


def meeting_instants(up2: np.ndarray, up1: np.ndarray, un1: np.ndarray, un2: np.ndarray,
                     d1: np.ndarray, h: np.ndarray, d2: np.ndarray, a: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Where a camera's image paths on the two sides of a jump meet, elementwise (k rows).

    The forward path through ``up2`` (at ``-d1``) and ``up1`` (at 0) and the backward one
    through ``un1`` (at ``h``) and ``un2`` (at ``h + d2``), times in seconds from ``up1``'s,
    each a parabola of the image acceleration ``a`` (pixels/s²): ``f(s) = up1 + v_f s +
    ½ a s²``, ``v_f = (up1 - up2) / d1 + ½ a d1``; ``b(s) = un1 + v_b (s - h) + ½ a (s -
    h)²``, ``v_b = (un2 - un1) / d2 - ½ a d2``. ``D(s) = f(s) - b(s) = A + B s`` with ``A =
    up1 - un1 + v_b h - ½ a h²``, ``B = v_f - v_b + a h`` (the squares cancel); the least
    squares meeting ``s* = -A·B / |B|²``, clipped to ``[0, h]``.

    up2, up1, un1, un2 : (k, 2) pixels; d1, h, d2 : (k,) seconds; a : (k, 2) pixels/s²

    Returns
    -------
    s : (k,) seconds after ``up1``'s time (NaN where ``B`` is 0); weight : (k,) ``|B|²``,
        (pixels/s)², ``s*``'s precision (its standard deviation ∝ σ / |B|)
    """
    d1, h, d2 = (np.asarray(x, np.float64)[:, None] for x in (d1, h, d2))
    vf = (up1 - up2) / d1 + 0.5 * a * d1  # the forward path's velocity at 0
    vb = (un2 - un1) / d2 - 0.5 * a * d2  # the backward path's at h
    A = up1 - un1 + vb * h - 0.5 * a * h ** 2
    B = vf - vb + a * h
    weight = np.sum(B * B, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.clip(-np.sum(A * B, axis=1) / weight, 0.0, h[:, 0])
    return np.where(weight > 0, s, np.nan), weight


def image_kicks_ns(prep: Prepared, track: Track, rig: Rig, options) -> np.ndarray:
    """(k,) int64, sorted: kick instants (ns) from each camera's image track alone, for the
    ``breaks`` rule without a fit (``FusionOptions.break_source="image"``).

    For each camera and each pair of its consecutive detections ``p1``, ``n1`` with one more
    on each side (``p2`` before, ``n2`` after; every interval within ``max_gap_s``), in
    undistorted pixels ``u``: the forward line through ``p2, p1`` extrapolated to ``n1``
    misses ``u_n1`` by ``m = ‖(1 - w) u_p2 + w u_p1 - u_n1‖`` (``w`` the extrapolation's
    weight); a jump is shown where ``m > k σ √((1 - w)² + w² + 1) + ½ g (t_n1 - t_p1)
    (t_n1 - t_p2) f D / Z²`` (``k`` = :data:`IMAGE_KICK_SIGMAS`; the bound of type A's
    kick-aware test, :func:`pslog.fusion.confirm.sides_test`, ``σ`` the larger of
    ``noise_px`` (0.5 px when None) and the noise the session's detections show,
    :func:`pslog.fusion.stereo.detection_noise`, in undistorted pixels; ``D``, ``Z`` the
    ball's distance and depth from ``track``'s point nearest in time). Its instant: where
    the two sides' paths meet, each a parabola of the image acceleration gravity gives
    there (``a = J R g``, ``J`` the projection's Jacobian at the ball): ``f(s) = u_p1 +
    v_f (s - t_p1) + ½ a (s - t_p1)²`` and ``b(s) = u_n1 + v_b (s - t_n1) + ½ a (s - t_n1)²``
    with ``v_f``, ``v_b`` the chords' velocities moved to ``t_p1`` and ``t_n1``; their
    difference is linear in ``s`` (the squares cancel), ``D(s) = A + B s``, and ``s* = -A·B /
    |B|²``, clipped to ``[t_p1, t_n1]``. A jump at the pair after another (its ``p1`` the
    other's ``n1``) is that kick's echo, not a second one: its forward line runs through the
    kick and its meeting falls at its ``p1``, late; it is left out. The cameras' instants within
    :data:`IMAGE_KICK_MERGE_S` of each other are one kick at their mean weighted by ``|B|²``
    (``s*``'s precision: σ / |B| per axis).

    ``prep``: type A's prepared observations; ``track``: its forward track (the depths);
    ``options``: FusionOptions with ``max_gap_s`` set. A kick whose image jump is within the
    noise in every camera that sees it is not found (docs/methods.md, "Kick instants from
    the images (session 44)")."""
    from ..motion import G
    from .stereo import detection_noise

    obs = prep.obs
    gap_ns = options.max_gap_s * NS
    floor = 0.5 if options.noise_px is None else max(options.noise_px, 0.5)
    # each camera's pairs whose miss could pass the test at all (σ at its floor, gravity's
    # term 0: the bound is at least that), then the test itself on those, with one call
    # for the session's noise at their times (a vectorised pass; the whole test on every
    # pair took 1.7 CPU s at 90 minutes, this 0.2)
    if len(track) < 2:  # (no depths to bound gravity's bend with)
        return np.zeros(0, np.int64)
    found = []
    for c in range(len(prep.cameras)):
        rows = prep.per_camera[c]
        if len(rows) < 4:
            continue
        t = obs.time_ns[rows]
        u = prep.uv_undistorted[rows]
        p1 = np.arange(1, len(rows) - 2)
        p2, n1, n2 = p1 - 1, p1 + 1, p1 + 2
        ok = ((t[p1] - t[p2] <= gap_ns) & (t[n1] - t[p1] <= gap_ns) & (t[n2] - t[n1] <= gap_ns)
              & np.all(np.isfinite(u[p2]) & np.isfinite(u[p1]) & np.isfinite(u[n1])
                       & np.isfinite(u[n2]), axis=1))
        p2, p1, n1, n2 = p2[ok], p1[ok], n1[ok], n2[ok]
        tp2, tn1 = ((t[i] - t[p1]).astype(np.float64) / NS for i in (p2, n1))
        w = (tn1 - tp2) / -tp2  # (t_n1 - t_p2) / (t_p1 - t_p2), t_p1 = 0
        miss = np.hypot(*((1 - w)[:, None] * u[p2] + w[:, None] * u[p1] - u[n1]).T)
        scale = np.ones(len(p1))
        if prep.uv_jacobian is not None:  # (σ per axis, in undistorted pixels)
            jac = prep.uv_jacobian[rows[p1]]
            scale = np.sqrt(np.einsum("nij,nij->n", jac, jac) / 2)
        root = np.sqrt((1 - w) ** 2 + w ** 2 + 1)
        with np.errstate(invalid="ignore"):
            keep = miss > IMAGE_KICK_SIGMAS * (floor * scale) * root
        found.append((c, rows, p2[keep], p1[keep], n1[keep], n2[keep], miss[keep],
                      scale[keep], root[keep]))
    if not found:
        return np.zeros(0, np.int64)
    noise = detection_noise(prep, np.concatenate([obs.time_ns[rows[p1]]
                                                  for _, rows, _, p1, *_ in found]),
                            options.max_gap_s, floor)
    parts = []
    start = 0
    for c, rows, p2, p1, n1, n2, miss, scale, root in found:
        cam = prep.cameras[c]
        sigma = np.maximum(noise[start:start + len(p1)], floor) * scale
        start += len(p1)
        if not len(p1):
            continue
        t = obs.time_ns[rows]
        u = prep.uv_undistorted[rows]
        # the ball in this camera's frame at each detection: the track's point nearest in time
        near = np.clip(np.searchsorted(track.time_ns, t[p1]), 1, len(track) - 1)
        near -= (t[p1] - track.time_ns[near - 1]) < (track.time_ns[near] - t[p1])
        x = track.position_world[near] @ np.asarray(cam.R).T + np.asarray(cam.t)
        z = x[:, 2]
        fx, fy = float(cam.K[0][0]), float(cam.K[1][1])
        with np.errstate(invalid="ignore", divide="ignore"):
            per_m = max(fx, fy) * np.linalg.norm(x, axis=1) / z ** 2
            g_cam = np.asarray(cam.R) @ np.array([0.0, 0.0, -G])
            accel = np.stack([fx * (g_cam[0] - x[:, 0] / z * g_cam[2]) / z,
                              fy * (g_cam[1] - x[:, 1] / z * g_cam[2]) / z], axis=1)
        tp2, tn1, tn2 = ((t[i] - t[p1]).astype(np.float64) / NS for i in (p2, n1, n2))
        with np.errstate(invalid="ignore"):
            bound = IMAGE_KICK_SIGMAS * sigma * root + 0.5 * G * tn1 * (tn1 - tp2) * per_m
            jump = (z > 0) & np.isfinite(per_m) & (miss > bound)
        # a kick between p1 and n1 shows again at the next pair (p1 + 1 its p1), whose
        # forward line runs through the kick: its meeting is that pair's p1 (n1 here), late
        # by n1's time less the kick's; the first of two consecutive pairs is the kick's
        jump[jump] = ~np.isin(p1[jump] - 1, p1[jump])
        if not np.any(jump):
            continue
        a = np.where(np.isfinite(accel), accel, 0.0)[jump]
        s, weight = meeting_instants(u[p2[jump]], u[p1[jump]], u[n1[jump]], u[n2[jump]],
                                     -tp2[jump], tn1[jump], (tn2 - tn1)[jump], a)
        fine = np.isfinite(s) & (weight > 0)
        parts.append((t[p1[jump]][fine] + np.round(s[fine] * NS).astype(np.int64),
                      weight[fine]))
    if not parts:
        return np.zeros(0, np.int64)
    instant = np.concatenate([p[0] for p in parts])
    weight = np.concatenate([p[1] for p in parts])
    order = np.argsort(instant, kind="stable")
    instant, weight = instant[order], weight[order]
    group = np.cumsum(np.r_[True, np.diff(instant) > round(IMAGE_KICK_MERGE_S * NS)]) - 1
    first = instant[np.r_[0, np.flatnonzero(np.diff(group)) + 1]]
    # (offsets from each group's first instant: the weighted mean without float64's ns loss)
    offset = np.bincount(group, weights=(instant - first[group]) * weight) / np.bincount(
        group, weights=weight)
    return first + np.round(offset).astype(np.int64)


def reversed_prepared(prep: Prepared, rig: Rig) -> tuple[Prepared, int]:
    """``prep``'s observations in reversed time, prepared (their doubt carried along), and
    the origin ``t0``: an observation at ``t`` is at ``t0 - t`` there (``t0`` the sum of the
    first and last times: the reversed times span the same interval)."""
    obs = prep.obs
    t0 = int(obs.time_ns.min()) + int(obs.time_ns.max())
    t = t0 - obs.time_ns
    order = np.lexsort((obs.camera, t))
    out = prepare(Observations(t[order], obs.camera[order], obs.uv[order],
                               obs.frame_index[order]), rig)
    if prep.doubt_px2 is not None:
        out = replace(out, doubt_px2=prep.doubt_px2[order])
    return out, t0


def spans_break(breaks_ns: np.ndarray, start_ns: np.ndarray, end_ns: np.ndarray,
                forward: bool) -> np.ndarray:
    """(n,) bool: a break lies in ``(start, end]`` (``forward``: a construction from the
    points before ``end``) or in ``[start, end)`` (a backward one from the points after
    ``start``); ``breaks_ns`` sorted."""
    side: Literal["left", "right"] = "right" if forward else "left"
    return (np.searchsorted(breaks_ns, end_ns, side=side)
            > np.searchsorted(breaks_ns, start_ns, side=side))


def across_breaks(prep: Prepared, track: Track, rig: Rig, options,
                  type_a: Callable[..., Track],
                  breaks_ns: np.ndarray | Callable[[], np.ndarray] | None = None) -> Track:
    """``track`` (type A's from ``prep`` under ``options``, FusionOptions with ``max_gap_s``
    set) with each point spanning a kick instant (a break of the session's fit, or a jump the
    images show: ``breaks_ns``) replaced by the backward
    pass's point on its detection, or withheld (``break``) when that one spans a break too or
    is missing (the module's rule). ``type_a(prep, rig, options, wanted=keys)`` makes a type A
    track (the backward pass: ``options`` with ``confirm_breaks`` off) of the points on the
    detections ``keys`` names (:func:`pslog.records.point_keys`; :func:`pslog.fusion._type_a`).
    A replaced point takes every column of the backward point, its ``span_s`` negated (the
    point's time minus the latest capture it uses). The other points are ``track``'s rows,
    unchanged. ``breaks_ns``: the instants (the images' or the fit's), given, or a callable
    that gives them (a
    :class:`SessionFit`'s ``take_breaks``: the fit of ``smooth``'s own input, called once the
    forward track is made); None: the fit of ``prep`` (:func:`fit_breaks_ns`)."""
    if not len(track) or "span_s" not in track.quality:
        return track
    breaks = (fit_breaks_ns(prep, rig, options) if breaks_ns is None
              else breaks_ns() if callable(breaks_ns) else breaks_ns)
    t = track.time_ns
    span = np.round(track.quality["span_s"] * 1e9).astype(np.int64)
    spanning = spans_break(breaks, t - span, t, forward=True)
    if not np.any(spanning):
        return track
    rprep, t0 = reversed_prepared(prep, rig)
    # (the backward points on the spanning points' detections alone, each the bits it has
    # in the whole backward track: the confirmation's tests are elementwise; 0.2 of type
    # A's 1.4 CPU s at 90 minutes, session 45)
    back = type_a(rprep, rig, replace(options, confirm_breaks=False,
                                      break_source=BREAK_SOURCES[0]),
                  wanted=point_keys(t0 - t[spanning], track.camera[spanning]))
    tb = t0 - back.time_ns  # each backward point's time, forward
    # the backward point on each forward point's detection (its time and camera)
    idx, has = matching_rows(point_keys(t, track.camera), point_keys(tb, back.camera))
    span_b = (np.round(back.quality["span_s"] * 1e9).astype(np.int64) if len(back)
              else np.zeros(0, np.int64))
    b_spans = np.ones(len(t), bool)
    b_spans[has] = spans_break(breaks, t[has], t[has] + span_b[idx[has]], forward=False)
    use = spanning & has & ~b_spans
    keep = ~spanning | use
    rows = np.flatnonzero(use)
    position = track.position_world.copy()
    position[rows] = back.position_world[idx[rows]]
    quality = {}
    for name, column in track.quality.items():
        column = column.copy()
        if name in back.quality:
            column[rows] = back.quality[name][idx[rows]]
        if name == "span_s":
            column[rows] = -column[rows]
        quality[name] = column[keep]
    dropped = dict(track.dropped)
    n_out = len(t) - int(np.count_nonzero(keep))
    if n_out:
        dropped["break"] = dropped.get("break", 0) + n_out
    return Track(track.method, t[keep], position[keep], track.camera[keep], quality, dropped)
