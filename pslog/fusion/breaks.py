"""Type A across a break of the session's fit: the backward pass (offline; session 37).

Type A's last far points under the offline kick test (``confirm_sides``) are eq. (1)/(4)'s
construction across a kick that one far camera cannot prove: the depth along the newest ray
comes from the motion before the kick (docs/methods.md, "Type A's last far points against the
session's fit"). The same equations run on the time-reversed observations (the *backward
pass*) take each detection's depth from the points after it: right just after a kick, wrong
just before one. Which of the two holds needs the kick's instant, which ``smooth``'s fit of
the same observations has (its velocity breaks, :attr:`pslog.estimation.Trajectory.breaks_s`).

With ``FusionOptions.confirm_breaks`` (``pslog fuse --confirm-gaps breaks``), a type A point
whose construction spans a break (one in ``(t - span_s, t]``) is replaced by the backward
pass's point on the same detection (made with the same options, its own covariance) when
that construction spans none (none in ``[t, t + span_b)``), and is withheld (``break`` in
``Track.dropped``) when both span one or the backward pass has no point there. Every other
point is the forward pass's, to the bit. docs/methods.md, "Type A across a break: the
backward pass (session 37)".
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any, Literal

import numpy as np

from ..records import Observations, Track, matching_rows, point_keys
from ..rig import Rig
from ._prepare import Prepared, prepare


def fit_breaks_ns(prep: Prepared, rig: Rig, options) -> np.ndarray:
    """(k,) int64, sorted: the instants (ns) of the velocity breaks of ``smooth``'s fit of
    ``prep``'s observations (the gate's choices in doubt left out); empty when no stretch
    is seen by two cameras. ``options``: FusionOptions with ``max_gap_s`` set (the fit's;
    the clocks' consider covariance is not needed for the breaks and not made)."""
    from .smooth import _fit

    obs = prep.obs
    if prep.doubt_px2 is not None:
        obs = obs.select(~(prep.doubt_px2 > 0))
    if len(obs) < 2:
        return np.zeros(0, np.int64)
    fit = _fit(obs, rig, replace(options, clock_covariance=None))
    if fit is None:
        return np.zeros(0, np.int64)
    trajectory = fit.trajectory
    return np.sort(trajectory.t0_ns + np.round(np.asarray(trajectory.breaks_s) * 1e9
                                               ).astype(np.int64))


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
                  breaks_ns: np.ndarray | None = None) -> Track:
    """``track`` (type A's from ``prep`` under ``options``, FusionOptions with ``max_gap_s``
    set) with each point spanning a break of the session's fit replaced by the backward
    pass's point on its detection, or withheld (``break``) when that one spans a break too or
    is missing (the module's rule). ``type_a(prep, rig, options)`` makes a type A track (the
    backward pass: ``options`` with ``confirm_breaks`` off). A replaced point takes every
    column of the backward point, its ``span_s`` negated (the point's time minus the latest
    capture it uses). The other points are ``track``'s rows, unchanged. ``breaks_ns``: the
    fit's breaks (:func:`fit_breaks_ns` of ``prep``), given; None: fitted here."""
    if not len(track) or "span_s" not in track.quality:
        return track
    breaks = fit_breaks_ns(prep, rig, options) if breaks_ns is None else breaks_ns
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
