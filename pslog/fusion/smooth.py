"""``smooth``: one continuous trajectory fitted to every detection's ray (offline).

The estimator is :func:`pslog.estimation.fit_trajectory` (its docstring has the model); this
module turns its fit into a :class:`~pslog.records.Track`: a point at every detection time
that a fitted piece covers, or, with ``FusionOptions.rate_hz``, on a regular grid over the
pieces (never inside a gap the model does not bridge). Per-point quality:

- ``std_m``: position standard deviation, ``sqrt(trace Σ)`` (the RMS of the 3-D error the fit
  expects), metres; the full 3 x 3 covariance is :attr:`Fit.covariance`;
- ``std_x_m``, ``std_y_m``, ``std_z_m``: per axis, metres; ``cov_xx_m2`` ... ``cov_yz_m2``:
  the full 3 x 3 covariance (m²);
- ``residual_px``: the detection's reprojection residual, pixels (NaN on grid points);
- ``rejected``: 1 where the fit rejected the point's detection (:attr:`Fit.rejected`: its
  residual beyond χ²₂'s 1 - 1e-4 quantile of the fit's noise σ, the filter's gate's level,
  or left out of the fit by the deletion test: leaving it out lowered the fit's cost
  beyond that level, the fit had bent to it; the residual is then against the fit without
  it), 0 at the others, NaN on grid points. The point stays, the trajectory's at that time as at
  every detection (the fit gave the detection a weight below 0.33: the point is the other
  detections' and the motion model's), as the filter's point at a detection its gate
  rejected is its prediction; the detection's camera did not see the ball there (a spurious
  blob kept where the ball was out of its view: docs/methods.md, "``smooth``'s rejected
  detections");
- withheld where the fit is contradicted (``Track.dropped["contradicted_run"]``): a run of
  consecutive capture times at which the fit rejected every detection, from two cameras or
  more, is the ball where the fit is not (a kick it missed); no point between the fitted
  times around the run (:func:`contradicted_spans`);
- ``gap_s``: the largest time gap bridged: the longest interval between consecutive fitted
  detections (any camera; not those the fit rejected) that touches the point (at a
  detection, the longer of the intervals before and after it; on a grid point and at a
  rejected detection, the interval around it): how far the motion model carries the
  trajectory there, as the other methods' ``gap_s`` says how far they interpolate or
  extrapolate (the filter's: since its last accepted detection).

A detection in an end segment of a piece beyond a bounce or kick that fewer than four
detections of two cameras hold gets no point (its position along the rays is not determined),
nor does a piece's first or last detection that the fit made without it contradicts (its
deleted residual beyond χ²₂'s 1 - 1e-4 quantile: the piece ends at the detection next to it,
:func:`pslog.estimation.trajectory.end_statistic`): counted in
``Track.dropped["underdetermined_end"]``. A detection the gate chose in doubt
(:attr:`Prepared.doubt_px2` > 0) is left out of the fit, counted as ``doubt``, unless the fit
made without the session's choices in doubt predicts it (:func:`_confirmed`): then it is
fitted as any other (docs/methods.md, "`smooth`'s start in doubt, confirmed by the fit").

The fit's search for bounces and kicks runs on two threads where it has at least 4 blocks of
128 candidates (a session of a few minutes or more; a shorter one's on the calling thread);
``PSLOG_SMOOTH_THREADS=1`` forces one (the track is the same, bit for bit, on any number).
"""

from __future__ import annotations

import numpy as np

from ..errors import FusionError
from ..records import NS, Observations, Track
from ..rig import Rig
from ._prepare import Prepared


def fuse_smooth(prep: Prepared, rig: Rig, options, fitted: tuple | None = None) -> Track:
    """The ``smooth`` track of prepared observations (``options``: FusionOptions with
    ``max_gap_s`` set). An empty track when no stretch is seen by two cameras.
    ``fitted``: :func:`session_fit`'s result for the same arguments, made before (shared
    with type A's ``confirm_breaks``, which reads its breaks: :mod:`pslog.fusion.breaks`);
    None: fitted here."""
    fit, obs, n_doubt = session_fit(prep, rig, options) if fitted is None else fitted
    if fit is None:
        return _empty()
    rejected_all = fit.rejected  # (n,) the detections the fit rejected (Fit.rejected)
    spans = contradicted_spans(obs.time_ns, obs.camera, fit.used, rejected_all)
    if options.rate_hz is None:
        # the points with a finite position, gathered once (the covariances of a 90-minute
        # session are 35 MB: gathered and then filtered, they were copied twice); none
        # gathered when every observation has one (the fit's arrays are the track's)
        keep = fit.used & np.all(np.isfinite(fit.position), axis=1)
        n_contradicted = _leave_out_spans(obs.time_ns, keep, spans)
        rejected = rejected_all
        if np.all(keep):
            time_ns, camera = obs.time_ns, obs.camera
            position, cov, residual = fit.position, fit.covariance, fit.residual_px
        else:
            rows = np.flatnonzero(keep)
            time_ns, camera = obs.time_ns[rows], obs.camera[rows]
            position, cov = fit.position[rows], fit.covariance[rows]
            residual, rejected = fit.residual_px[rows], rejected[rows]
        flag = rejected.astype(np.float64)
    else:
        time_ns = _grid(fit, options.rate_hz)
        position, cov = fit.trajectory.evaluate(time_ns)
        residual = np.full(len(time_ns), np.nan)
        # a grid point is attributed to the camera of the nearest detection
        near = np.clip(np.searchsorted(obs.time_ns, time_ns), 0, len(obs) - 1)
        before = np.maximum(near - 1, 0)
        closer = np.abs(obs.time_ns[before] - time_ns) < np.abs(obs.time_ns[near] - time_ns)
        camera = obs.camera[np.where(closer, before, near)]
        keep = np.all(np.isfinite(position), axis=1)
        n_contradicted = _leave_out_spans(time_ns, keep, spans)
        time_ns, camera, position = time_ns[keep], camera[keep], position[keep]
        cov, residual = cov[keep], residual[keep]
        flag = np.full(len(time_ns), np.nan)  # a grid point is no detection
    # a rejected detection holds nothing of the trajectory: the gap runs across it
    gap = _bridged(obs.time_ns[fit.used & ~rejected_all], time_ns)
    var = np.einsum("nii->ni", cov)
    quality = {"std_m": np.sqrt(var.sum(axis=1)), "std_x_m": np.sqrt(var[:, 0]),
               "std_y_m": np.sqrt(var[:, 1]), "std_z_m": np.sqrt(var[:, 2]),
               "residual_px": residual, "rejected": flag, "gap_s": gap}
    # the full covariance, as the paper's methods give it (eval's 2σ share and NEES use it)
    for name, (i, j) in (("xx", (0, 0)), ("yy", (1, 1)), ("zz", (2, 2)), ("xy", (0, 1)),
                         ("xz", (0, 2)), ("yz", (1, 2))):
        quality[f"cov_{name}_m2"] = cov[:, i, j]
    # detections in an end segment beyond a break that too few of them determine
    dropped = {"underdetermined_end": fit.withheld} if fit.withheld else {}
    if n_doubt:
        dropped["doubt"] = n_doubt
    if n_contradicted:
        dropped["contradicted_run"] = n_contradicted
    return Track("smooth", time_ns, position, camera, quality, dropped=dropped)


def contradicted_spans(time_ns: np.ndarray, camera: np.ndarray, used: np.ndarray,
                       rejected: np.ndarray) -> np.ndarray:
    """(k, 2) int64 ns, open intervals ``(a, b)`` where the fit is contradicted: each holds a
    run of consecutive fitted capture times (time order) at which the fit rejected every
    fitted detection, from two cameras or more together, ``a`` the fitted time before the
    run (one nanosecond before the run's first when none), ``b`` the one after (one after
    its last when none). Detections of one time (synchronised shutters) count together, in
    whatever camera order: a time at which some camera's detection agrees with the fit is
    no part of a run (so the spans do not depend on the cameras' order in the rig).

    Why (session 43): the fit rejects a detection of the ball it models with probability
    1e-4 (:attr:`~pslog.estimation.Fit.rejected`); a spurious blob the gate let in is one
    camera's, once. Two cameras' consecutive detections that the fit rejects, each the gate
    found consistent with the others' rays, are the ball where the fit is not: a kick or
    bounce the break search missed (near a piece's start, or where misses and a blind
    camera leave few detections around it), with the fit bending through it on the motion
    of one side. Its points there were 30-740 mm off at a ``std_m`` of 4-9 mm (held-out
    ``bench_dirty.py --more`` runs, docs/methods.md "A run of rejected detections").

    time_ns : (n,) int64, sorted; camera : (n,) int; used, rejected : (n,) bool (Fit's)
    """
    rows = np.flatnonzero(used)
    flag = np.asarray(rejected, bool)[rows]
    if not flag.any():
        return np.zeros((0, 2), np.int64)
    t, cam = time_ns[rows], np.asarray(camera)[rows]
    # the fitted capture times (t sorted: each a run of equal values), each rejected when
    # every detection at it is
    new = np.r_[True, t[1:] != t[:-1]]
    times, group = t[new], np.cumsum(new) - 1
    accepted = np.zeros(len(times), bool)
    accepted[group[~flag]] = True
    edges = np.diff(np.r_[0, (~accepted).astype(np.int8), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)  # [start, end)
    first = np.searchsorted(group, starts)  # (the rows are in time order: each run's rows
    last = np.searchsorted(group, ends)  # are one slice, [first, last))
    out = []
    for a, b, i, j in zip(starts.tolist(), ends.tolist(), first.tolist(), last.tolist(),
                          strict=True):
        if np.all(cam[i:j] == cam[i]):  # one camera's run
            continue
        out.append((times[a - 1] if a > 0 else times[a] - 1,
                    times[b] if b < len(times) else times[b - 1] + 1))
    return np.array(out, np.int64).reshape(-1, 2)


def _leave_out_spans(time_ns: np.ndarray, keep: np.ndarray, spans: np.ndarray) -> int:
    """Clear ``keep`` (n,) bool in place at the times ``time_ns`` (n,) strictly inside one
    of the open intervals ``spans`` (k, 2), sorted and disjoint; returns how many kept
    points that left out."""
    if not len(spans):
        return 0
    j = np.searchsorted(spans[:, 0], time_ns, side="left") - 1  # the span starting before
    jj = np.maximum(j, 0)
    inside = (j >= 0) & (time_ns > spans[jj, 0]) & (time_ns < spans[jj, 1])
    n = int(np.count_nonzero(keep & inside))
    keep &= ~inside
    return n


def session_fit(prep: Prepared, rig: Rig, options):
    """``smooth``'s fit of prepared observations (``options``: FusionOptions with
    ``max_gap_s`` set), the observations it fitted and how many choices in doubt it left
    out: ``(fit or None, observations, n_doubt)``. A choice the gate put in doubt is left
    out, as the filter leaves it out (with chance 1/2 metres from the ball, and the fit's
    covariance cannot say so: docs/methods.md, "A contested start"), unless the fit made
    without it predicts it (:func:`_confirmed`); None when no stretch is seen by two
    cameras."""
    obs = prep.obs
    doubted = None if prep.doubt_px2 is None else prep.doubt_px2 > 0
    if doubted is not None and not np.any(doubted):
        doubted = None
    if doubted is None:
        return _fit(obs, rig, options), obs, 0
    kept = ~doubted
    fit = _fit(obs.select(kept), rig, options)
    if fit is not None:
        rows = np.flatnonzero(doubted)
        confirmed = rows[_confirmed(fit.trajectory, obs, rows, rig)]
        if len(confirmed):
            kept[confirmed] = True
            fit = _fit(obs.select(kept), rig, options)
    return fit, obs.select(kept), len(obs) - int(np.count_nonzero(kept))


def _fit(obs: Observations, rig: Rig, options):
    """:func:`~pslog.estimation.fit_trajectory` of ``obs`` under ``options`` (FusionOptions),
    with the clocks' consider covariance; None when no stretch is seen by two cameras."""
    from ..estimation import SmoothOptions, fit_trajectory

    # the clocks' consider covariance through the fit's own sensitivity (exact, where the
    # other methods re-run: pslog.fusion.clock)
    consider_px = None
    if options.clock_covariance is not None:
        from .clock import pixel_errors

        consider_px = pixel_errors(obs, [np.flatnonzero(obs.camera == c)
                                         for c in range(len(rig))],
                                   rig, options.clock_covariance, options.max_gap_s)
    try:
        return fit_trajectory(obs, rig, SmoothOptions(
            max_gap_s=options.max_gap_s, detector_offset_m=options.detector_offset_m or 0.0,
            detector_bias_px=options.detector_bias_px or 0.0), consider_px=consider_px)
    except FusionError as exc:
        if "two cameras" in str(exc):
            return None
        raise FusionError(f"smooth: {exc}") from None  # the fit's words, in fusion's context


def _confirmed(trajectory, obs: Observations, rows: np.ndarray, rig: Rig) -> np.ndarray:
    """(len(rows),) bool: the detections ``rows`` of ``obs`` (choices in doubt, left out of
    the fit that made ``trajectory``) that this fit predicts: the squared distance of the
    detection from the trajectory's pixel at its time, in the metric of that prediction's
    covariance (the fit's, projected) plus the fit's pixel noise σ² per axis, at most
    χ²₂'s 1 - 1e-4 quantile (18.42, the level at which the fit rejects its own detections,
    :attr:`~pslog.estimation.Fit.rejected`). The gate could judge such a choice by one
    epipolar line alone; the whole trajectory made without it tells the ball from what
    stood beside it. A time outside the fitted pieces predicts nothing."""
    from ..estimation.trajectory import _END_JUMP_SCALED, predicted_d2

    with np.errstate(invalid="ignore"):  # (NaN: outside the pieces, behind the camera)
        return predicted_d2(trajectory, obs, rows, rig) <= _END_JUMP_SCALED ** 2


def _bridged(fitted_ns: np.ndarray, time_ns: np.ndarray) -> np.ndarray:
    """(n,) seconds: the longest interval between consecutive ``fitted_ns`` (sorted) that
    touches each time: at a fitted time the longer of the intervals on either side, between
    two the interval around it (an end's missing side counts 0)."""
    if len(fitted_ns) == 0:
        return np.full(len(time_ns), np.nan)
    t = np.sort(fitted_ns)
    lo = np.searchsorted(t, time_ns, side="left")  # first fitted time >= each
    hi = np.searchsorted(t, time_ns, side="right")  # first fitted time > each
    before = np.where(lo > 0, time_ns - t[np.maximum(lo - 1, 0)], 0)
    after = np.where(hi < len(t), t[np.minimum(hi, len(t) - 1)] - time_ns, 0)
    exact = hi > lo  # the time is a fitted one: the intervals on either side of it
    gap = np.where(exact, np.maximum(before, after), before + after)
    return gap / NS


def _grid(fit, rate_hz: float) -> np.ndarray:
    """Times (ns) of a regular grid at ``rate_hz`` (phase: the session's first detection)
    inside the fitted pieces."""
    tr = fit.trajectory
    step = NS / rate_hz
    times = []
    for knots in tr.knots:
        lo = tr.t0_ns + round(knots[0] * NS)
        hi = tr.t0_ns + round(knots[-1] * NS)
        k0 = np.ceil((lo - tr.t0_ns) / step)
        k1 = np.floor((hi - tr.t0_ns) / step)
        k = np.arange(k0, k1 + 1)
        times.append(tr.t0_ns + np.round(k * step).astype(np.int64))
    out = np.concatenate(times) if times else np.zeros(0, np.int64)
    return out[(out >= tr.t0_ns)]


def _empty() -> Track:
    return Track("smooth", np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32))
