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

With ``FusionOptions.confirm_breaks`` (``pslog fuse --confirm-gaps breaks``), a type A point
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
from typing import Any, Literal

import numpy as np

from ..records import Observations, Track, matching_rows, point_keys
from ..rig import Rig
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
    ``max_gap_s`` set, ``smooth``'s."""

    def __init__(self, make_input: Callable[[], Prepared], rig: Rig, options,
                 uses: int = 1) -> None:
        self._make_input: Callable[[], Prepared] | None = make_input
        self._rig, self._options = rig, options
        self._lock = threading.Lock()
        self._value: tuple | None = None
        self._uses = uses

    def fitted(self) -> tuple:
        """``session_fit``'s ``(fit or None, observations, n_doubt)``."""
        from .smooth import session_fit

        with self._lock:
            if self._value is None:
                if self._make_input is None:
                    raise RuntimeError("SessionFit used after its last release")
                self._value = session_fit(self._make_input(), self._rig, self._options)
            return self._value

    def release(self) -> bool:
        """One of its ``uses`` done: after the last (True), the fit and its input are
        dropped (a 90-minute match's fit holds hundreds of MB)."""
        with self._lock:
            self._uses -= 1
            if self._uses <= 0:
                self._value, self._make_input = None, None
                return True
            return False

    def breaks_ns(self) -> np.ndarray:
        """(k,) int64, sorted: the fit's break instants (:func:`session_breaks_ns`)."""
        return session_breaks_ns(self.fitted()[0])


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
                  type_a: Callable[[Prepared, Rig, Any], Track],
                  breaks_ns: np.ndarray | Callable[[], np.ndarray] | None = None) -> Track:
    """``track`` (type A's from ``prep`` under ``options``, FusionOptions with ``max_gap_s``
    set) with each point spanning a break of the session's fit replaced by the backward
    pass's point on its detection, or withheld (``break``) when that one spans a break too or
    is missing (the module's rule). ``type_a(prep, rig, options)`` makes a type A track (the
    backward pass: ``options`` with ``confirm_breaks`` off). A replaced point takes every
    column of the backward point, its ``span_s`` negated (the point's time minus the latest
    capture it uses). The other points are ``track``'s rows, unchanged. ``breaks_ns``: the
    fit's breaks, given, or a callable that gives them (a :class:`SessionFit`'s ``breaks_ns``:
    the fit of ``smooth``'s own input, called once the forward track is made); None: the fit
    of ``prep`` (:func:`fit_breaks_ns`)."""
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
    back = type_a(rprep, rig, replace(options, confirm_breaks=False))
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
