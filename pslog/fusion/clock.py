"""The clocks' uncertainty in the fused points' covariance: a consider covariance.

``pslog sync`` estimates each camera's clock (offset, drift, readout: :mod:`pslog.timing`)
with a covariance Σ_θ; fusion then takes the corrected times as exact. A clock error is one
bias per camera, shared by all its detections, so it does not average out as pixel noise
does: a method's covariance made from the pixel noise alone understates the error (session
33: NEES 2-5 after a sync that estimated readouts). The sound form is Schmidt's *consider*
covariance (Tapley, Schutz & Born, *Statistical Orbit Determination*, 2004, §6.3; Bierman
1977): the estimate is left as it is, and its covariance gains ``S Σ_θ Sᵀ``, ``S = ∂p̂/∂θ``
the sensitivity of each fused point to the clock parameters.

**The clock error as a pixel error.** A detection ``i`` of camera ``c`` logged at ``l_i`` in
pixel ``z_i`` is placed at ``t_i = τ(l_i; θ)`` (:func:`pslog.timing.true_times_s`). With the
estimate off by ``δθ``, the ball was really seen at ``t_i - a_iᵀ δθ``, ``a_i`` the model's
derivatives (:func:`pslog.timing.clock_jacobian`: ``1``, ``1e-6 l_i``, ``v_i / height``).
To first order, the ball at the stated time ``t_i`` is at pixel ``z_i + ż_i a_iᵀ δθ``
(``ż_i`` the ball's image velocity in camera ``c``): the data at the stated times are the
truth's plus the pixel error ``b_i = -ż_i a_iᵀ δθ``. Each point is compared with the truth
at its own stated time (as ``pslog eval`` does), so that is the whole effect, for every
method alike, the point's own time shift included.

**The sensitivity, numerically.** ``S`` is the method's response to those pixel errors:
the method is run again on the same (chosen) detections, their pixels moved by ``±h b``
for each column of a square root of Σ_θ, the times and every other input unchanged, and
``S`` is the central difference (:func:`clock_sensitivity`). It holds for every method of
the registry without a derivative of its own, its decisions (gates, holds, breaks) taken
as they were: the steps move no pixel by more than :data:`STEP_PX`, far below any
threshold's scale; a point whose two one-sided differences disagree (a decision flipped
by the step) takes the smaller, and a point a perturbed run did not make takes the other
side's. ``ż`` comes from the camera's own detections (a central difference of its
neighbours within the method's max gap; one side at a track's end; 0 for a lone
detection; a detection without a pixel, NaN or beyond ten times the image, is no neighbour
and moves nothing): at 0.3 px noise and 30 fps, about 6 px/s of noise on a ball moving hundreds.

The covariance columns gain ``S Sᵀ`` (``cov_*_m2``; the per-axis ``std_*_m`` its diagonal;
``std_m`` the square root of the trace); the points, their decisions and their other
columns are unchanged. Offline only: a stream refuses it (each perturbed run would be a
stream of its own, and the central difference of ``ż`` waits for the next detection).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import FusionError
from ..records import NS, Observations, Track, matching_rows, point_keys
from ..rig import Rig
from ..timing import ClockCovariance, clock_jacobian

#: The largest pixel move of a perturbed run, pixels: small beside every decision's scale
#: (gates of several pixels, NIS thresholds of noise ~0.3 px), large beside float64's
#: resolution of the fit (1e-10 px)
STEP_PX = 1e-2
#: One-sided differences further apart than this share of their mean length: a decision
#: flipped by one step, the smaller one taken
_FLIP_RATIO = 0.5


def image_velocity(obs: Observations, per_camera: list[np.ndarray], max_gap_s: float,
                   usable: np.ndarray | None = None) -> np.ndarray:
    """Each detection's image velocity in its own camera, pixels per second (n, 2): the
    central difference of the camera's neighbouring detections (one side where the other
    is further than ``max_gap_s`` or absent; 0 where both are).

    ``obs``: (n,) rows; ``per_camera``: each camera's rows, in time order; ``usable``: (n,)
    bool, the rows with a pixel (others are no neighbour and have velocity 0; None: all)."""
    velocity = np.zeros((len(obs), 2))
    t = obs.time_ns.astype(np.float64) / NS
    for rows in per_camera:
        if usable is not None:
            rows = rows[usable[rows]]
        if len(rows) < 2:
            continue
        uv, tc = obs.uv[rows], t[rows]
        dt = np.diff(tc)
        step = np.diff(uv, axis=0) / dt[:, None]  # (m - 1, 2): between row j and j + 1
        near = dt <= max_gap_s
        before = np.r_[False, near]  # row j has a near predecessor (step j - 1)
        after = np.r_[near, False]
        prev = np.vstack([np.zeros((1, 2)), step])
        nxt = np.vstack([step, np.zeros((1, 2))])
        both = before & after
        # the central difference over both intervals: (z_{j+1} - z_{j-1}) / (t_{j+1} - t_{j-1})
        span = np.r_[np.nan, tc[2:] - tc[:-2], np.nan]
        central = np.zeros_like(uv)
        central[1:-1] = (uv[2:] - uv[:-2]) / span[1:-1, None]
        v = np.where(both[:, None], central,
                     np.where(before[:, None], prev, np.where(after[:, None], nxt, 0.0)))
        velocity[rows] = v
    return velocity


def pixel_errors(obs: Observations, per_camera: list[np.ndarray], rig: Rig,
                 clock: ClockCovariance, max_gap_s: float,
                 doubtful: np.ndarray | None = None) -> np.ndarray:
    """The pixel error one standard deviation of each clock direction puts on each detection,
    ``b_i = -ż_i a_iᵀ L`` (n, 2, m): ``L`` (k, m) the square root of Σ_θ
    (:meth:`ClockCovariance.factor`), so that the points' consider covariance is ``S Sᵀ`` with
    ``S`` the response to these ``m`` columns.

    ``a_i``: :func:`pslog.timing.clock_jacobian` at the detection's time (on the session
    clock: the logged time, to a part in 1e4 for the drift's derivative) and row; 0 for
    the parameters of the other cameras. ``doubtful``: (n,) bool, the gate's choices in
    doubt (:attr:`Prepared.doubt_px2` > 0): no neighbour of the image velocity (a wrong
    choice would widen its neighbours' covariance; smooth leaves them out of its fit) and
    no velocity of their own (each method leaves such a choice out or withholds its
    point)."""
    if np.any(clock.camera >= len(rig)):
        raise FusionError(f"clock covariance: camera {int(clock.camera.max())} is not in "
                          f"the rig of {len(rig)} cameras")
    height = np.array([c.height for c in rig.cameras], dtype=np.float64)[obs.camera]
    # a detection without a pixel (NaN, or far beyond the image: no detection to any
    # method, as pslog.estimation.trajectory's fit) moves nothing and is no neighbour: its
    # NaN had made every column NaN (smooth's std NaN everywhere, the others' columns
    # skipped), and a pixel 1e5 px off gave its neighbours velocities of 1e6 px/s
    extent = 10 * np.array([max(c.width, c.height) for c in rig.cameras],
                           dtype=np.float64)[obs.camera]
    usable = np.all(np.isfinite(obs.uv), axis=1) & np.all(
        np.abs(np.nan_to_num(obs.uv, nan=np.inf)) <= extent[:, None], axis=1)
    a = clock_jacobian(obs.time_ns.astype(np.float64) / NS, obs.uv[:, 1], height)  # (n, 3)
    dt = np.where((obs.camera[:, None] == clock.camera[None, :]) & usable[:, None],
                  a[:, clock.parameter], 0.0)  # (n, k): seconds per unit of each parameter
    dt_sigma = dt @ clock.factor()  # (n, m): seconds per standard deviation of each column
    velocity = image_velocity(obs, per_camera, max_gap_s,
                              usable if doubtful is None else usable & ~doubtful)
    return -velocity[:, :, None] * dt_sigma[:, None, :]


def _keys(track: Track) -> np.ndarray:
    """One int64 per point, its time and camera (:func:`pslog.records.point_keys`)."""
    return point_keys(track.time_ns, track.camera)


def _matched(keys: np.ndarray, track: Track) -> tuple[np.ndarray, np.ndarray]:
    """Positions of ``track`` at the points ``keys`` (n, 3; NaN where it has none) and which
    it has (n,) bool."""
    rows, found = matching_rows(keys, _keys(track))
    position = np.full((len(keys), 3), np.nan)
    position[found] = track.position_world[rows[found]]
    return position, found


def clock_sensitivity(track: Track, run, obs: Observations, errors: np.ndarray
                      ) -> np.ndarray:
    """``S`` (n, 3, m): each point of ``track`` per standard deviation of each clock
    direction, metres, by central differences of ``run(observations) -> Track`` (the
    method, its other inputs fixed) with the pixels moved by ``±h errors[:, :, j]``, ``h``
    such that no pixel moves by more than :data:`STEP_PX`.

    A point a perturbed run did not make takes the other side's one-sided difference (0
    when neither made it); where the two one-sided differences differ by more than
    :data:`_FLIP_RATIO` of their mean length (a decision flipped by the step) the smaller
    is taken."""
    keys = _keys(track)
    m = errors.shape[2]
    S = np.zeros((len(track), 3, m))
    p0 = track.position_world
    for j in range(m):
        column = errors[:, :, j]
        largest = float(np.max(np.abs(column), initial=0.0))
        if not largest > 0:
            continue
        h = STEP_PX / largest
        sides = []
        for sign in (1.0, -1.0):
            moved = Observations(obs.time_ns, obs.camera, obs.uv + sign * h * column,
                                 obs.frame_index)
            position, found = _matched(keys, run(moved))
            sides.append(((position - p0) * sign / h, found))
        (up, up_ok), (down, down_ok) = sides
        both = up_ok & down_ok
        central = (up + down) / 2
        n_up, n_down = np.linalg.norm(up, axis=1), np.linalg.norm(down, axis=1)
        flipped = both & (np.abs(n_up - n_down) > _FLIP_RATIO * (n_up + n_down) / 2
                          + 1e-300)  # (1e-300: two zero differences agree)
        smaller = np.where((n_up <= n_down)[:, None], up, down)
        out = np.where(flipped[:, None], smaller, central)
        out = np.where((up_ok & ~down_ok)[:, None], up, out)
        out = np.where((down_ok & ~up_ok)[:, None], down, out)
        out[~(up_ok | down_ok)] = 0.0
        S[:, :, j] = out
    return S


def add_covariance(track: Track, S: np.ndarray) -> Track:
    """``track`` with ``S Sᵀ`` (S: (n, 3, m)) added to its covariance columns: the six
    ``cov_*_m2`` where it has them, the per-axis ``std_*_m`` where it has them (the
    diagonal), ``std_m`` (the trace) always; a point whose covariance is NaN stays NaN."""
    added = np.einsum("nik,njk->nij", S, S)
    quality = dict(track.quality)
    pairs = {"xx": (0, 0), "yy": (1, 1), "zz": (2, 2), "xy": (0, 1), "xz": (0, 2),
             "yz": (1, 2)}
    for name, (i, j) in pairs.items():
        key = f"cov_{name}_m2"
        if key in quality:
            quality[key] = quality[key] + added[:, i, j]
    for i, axis in enumerate("xyz"):
        key = f"std_{axis}_m"
        if key in quality:
            quality[key] = np.sqrt(quality[key] ** 2 + added[:, i, i])
    if "std_m" in quality:
        quality["std_m"] = np.sqrt(quality["std_m"] ** 2 + np.trace(added, axis1=1, axis2=2))
    return Track(track.method, track.time_ns, track.position_world, track.camera, quality,
                 track.dropped)


def with_clock_covariance(track: Track, method: str, prep, rig: Rig, options,
                          function=None) -> Track:
    """``track`` (``method``'s, made from ``prep`` with ``options``, ``max_gap_s`` resolved)
    with the consider covariance of ``options.clock_covariance`` added (module docstring).

    Parameters
    ----------
    track : Track, the method's points
    method : name in :data:`pslog.fusion.METHODS`
    prep : :class:`~pslog.fusion.Prepared` the track was made from (its choices' doubt kept
        in the perturbed runs)
    rig : Rig
    options : FusionOptions with ``clock_covariance`` set and ``max_gap_s`` resolved
    function : ``(prep, rig, options) -> Track``, the method as it made ``track`` (None: the
        registry's, ``METHODS[method].function``)
    """
    from . import METHODS
    from ._prepare import prepare

    clock: ClockCovariance = options.clock_covariance
    if not len(track) or not len(clock) or "std_m" not in track.quality:
        return track  # (nothing to add to: noise_px None makes no covariance)
    obs = prep.obs
    errors = pixel_errors(obs, prep.per_camera, rig, clock, options.max_gap_s,
                          None if prep.doubt_px2 is None else prep.doubt_px2 > 0)
    plain = replace(options, clock_covariance=None)
    function = function or METHODS[method].function

    def run(moved: Observations) -> Track:
        again = prepare(moved, rig)
        if prep.doubt_px2 is not None:
            again = replace(again, doubt_px2=prep.doubt_px2)
        return function(again, rig, plain)

    return add_covariance(track, clock_sensitivity(track, run, obs, errors))


__all__ = ["STEP_PX", "add_covariance", "clock_sensitivity", "image_velocity",
           "pixel_errors", "with_clock_covariance"]
