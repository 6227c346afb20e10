"""Ordinary stereo: the paper's "synchronized" and "unsynchronized" rows of Table 1."""

from __future__ import annotations

import numpy as np

from ..errors import FusionError
from ..geometry import ray_angles, triangulate_rays
from ..records import NS, Observations, Track
from ._prepare import Prepared, latest_row_at_or_before


def sync_groups(obs: Observations, n_cams: int, tolerance_s: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Group observations captured within ``tolerance_s`` of each other.

    A group starts at the earliest observation not yet grouped and takes every later one up
    to ``tolerance_s`` after it, so no group spans more than the tolerance. (Chaining
    neighbours within the tolerance instead would let evenly spaced shutters a little closer
    than the tolerance join one by one into a single "simultaneous" group of the whole
    session.)

    Returns
    -------
    group : (n,) int64, group id of each observation (groups in time order)
    n_cameras : (n_groups,) int64, distinct cameras in each group
    """
    time_ns = obs.time_ns
    tol_ns = round(tolerance_s * NS)
    n = len(time_ns)
    starts = np.zeros(n, dtype=bool)
    if n:
        # runs separated by more than the tolerance are groups unless they span more than
        # it (vectorized, the usual case); only those longer runs are split one by one
        starts[0] = True
        starts[1:] = np.diff(time_ns) > tol_ns
        run_start = np.flatnonzero(starts)
        run_end = np.r_[run_start[1:], n]  # exclusive
        long = time_ns[run_end - 1] - time_ns[run_start] > tol_ns
        for a, b in zip(run_start[long].tolist(), run_end[long].tolist(), strict=True):
            times = time_ns[a:b]
            i = 0
            while i < b - a:
                starts[a + i] = True
                i = int(np.searchsorted(times, times[i] + tol_ns, side="right"))
    group = np.cumsum(starts) - 1
    n_groups = int(group[-1]) + 1 if len(group) else 0
    seen = np.zeros((n_groups, n_cams), dtype=bool)
    seen[group, obs.camera] = True
    return group, seen.sum(axis=1)


def triangulate_groups(prep: Prepared, group: np.ndarray, n_groups: int):
    """N-view least-squares point of each group (one ray per camera; a camera seen twice in a
    group keeps its latest ray). Returns points (g, 3), quality {name: (g,)} (``ray_miss_m``,
    ``ray_angle_deg``), time_ns (g,) of the group's latest observation, camera (g,) of that
    observation."""
    n_cams = len(prep.centers)
    origins = np.zeros((n_groups, n_cams, 3))
    dirs = np.zeros((n_groups, n_cams, 3))
    valid = np.zeros((n_groups, n_cams), dtype=bool)
    cam = prep.obs.camera
    origins[group, cam] = prep.ray_origin
    dirs[group, cam] = prep.ray_dir
    valid[group, cam] = True
    points, rms_miss, _ = triangulate_rays(origins, dirs, valid)
    last = np.r_[np.flatnonzero(np.diff(group)), len(group) - 1]  # last row of each group
    quality = {"ray_miss_m": rms_miss, "ray_angle_deg": np.degrees(ray_angles(dirs, valid))}
    return points, quality, prep.obs.time_ns[last], prep.obs.camera[last]


def stereo_at_common_instants(
    prep: Prepared, tolerance_s: float, method: str
) -> tuple[Track, np.ndarray]:
    """N-view points of every instant at which at least two cameras saw the ball.

    Returns
    -------
    track : Track named ``method``, one point per such instant, with ``ray_miss_m``
    alone : (n,) bool, the detections that had no simultaneous partner
    """
    group, n_cameras = sync_groups(prep.obs, len(prep.centers), tolerance_s)
    if not np.any(n_cameras >= 2):
        raise FusionError(
            f"method {method} needs cameras with a common shutter instant (sync or typeB "
            f"timing), but no two cameras captured within {tolerance_s * 1e3:g} ms of each "
            f"other; methods that suit this session: nearest, typeA")
    points, quality, time_ns, camera = triangulate_groups(prep, group, len(n_cameras))
    keep = (n_cameras >= 2) & np.all(np.isfinite(points), axis=1)
    track = Track(method, time_ns[keep], points[keep], camera[keep],
                  {k: v[keep] for k, v in quality.items()})
    return track, n_cameras[group] == 1


def fuse_sync(prep: Prepared, tolerance_s: float = 1e-3) -> Track:
    """``sync``: N-view triangulation of detections captured within ``tolerance_s``.

    One point per instant at which at least two cameras saw the ball.
    """
    if len(prep.obs) == 0:
        return _empty("sync")
    return stereo_at_common_instants(prep, tolerance_s, "sync")[0]


def fuse_nearest(prep: Prepared, max_gap_s: float) -> Track:
    """``nearest``: each detection triangulated with the latest detection of every other camera
    as if they were simultaneous (the paper's "unsynchronized" baseline)."""
    n, n_cams = len(prep.obs), len(prep.centers)
    time_ns, camera = prep.obs.time_ns, prep.obs.camera
    origins = np.zeros((n, n_cams, 3))
    dirs = np.zeros((n, n_cams, 3))
    valid = np.zeros((n, n_cams), dtype=bool)
    max_gap_ns = int(max_gap_s * NS)
    events = np.arange(n)
    for d in range(n_cams):  # loop over cameras, vectorized over events
        rows = latest_row_at_or_before(prep, d, events)
        ok = (rows >= 0) & (camera != d)
        ok &= time_ns - prep.obs.time_ns[np.maximum(rows, 0)] <= max_gap_ns
        origins[ok, d] = prep.ray_origin[rows[ok]]
        dirs[ok, d] = prep.ray_dir[rows[ok]]
        valid[ok, d] = True
    others = valid.sum(axis=1)
    origins[events, camera] = prep.ray_origin
    dirs[events, camera] = prep.ray_dir
    valid[events, camera] = True
    points, rms_miss, _ = triangulate_rays(origins, dirs, valid)
    keep = (others >= 1) & np.all(np.isfinite(points), axis=1)
    angle = np.degrees(ray_angles(dirs, valid))
    return Track("nearest", time_ns[keep], points[keep], camera[keep],
                 {"ray_miss_m": rms_miss[keep], "ray_angle_deg": angle[keep]})


def _empty(method: str) -> Track:
    return Track(method, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32), {})
