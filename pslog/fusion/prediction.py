"""Type B (the paper's section 2.3) and its ablation, plain linear prediction.

With type B timing two cameras (the first and the last) share a shutter instant, so the ball
is triangulated by ordinary stereo at those instants; the cameras in between fire half a
period later. For such an in-between detection at ``t``, the two latest stereo points
``P_{t-1}`` and ``P_{t-3}`` give the linear prediction of eq. (2) (with the actual capture
intervals), and ``typeB`` moves it to the nearest point of the detection's viewing ray,
eqs. (3)-(4); ``linear`` keeps the prediction as it is (Table 1's "linear prediction").
"""

from __future__ import annotations

import numpy as np

from ..geometry import closest_points_on_rays
from ..records import NS, Track
from ._prepare import Prepared
from .stereo import stereo_at_common_instants


def fuse_predicted(prep: Prepared, method: str, tolerance_s: float, max_gap_s: float) -> Track:
    """``typeB`` (ray-constrained, eq. (4)) or ``linear`` (eq. (2) only)."""
    if method not in ("typeB", "linear"):
        raise ValueError(f"method must be typeB or linear, got {method!r}")
    obs = prep.obs
    if len(obs) == 0:
        return Track(method, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32))
    stereo, alone = stereo_at_common_instants(prep, tolerance_s, method)
    points, stereo_ns = stereo.position_world, stereo.time_ns
    single = np.flatnonzero(alone)  # detections with no simultaneous partner
    t_single = obs.time_ns[single]
    k1 = np.searchsorted(stereo_ns, t_single, side="left") - 1  # latest stereo point before
    k2 = k1 - 1
    ok = k2 >= 0  # also false for every detection when no stereo point could be made
    ok[ok] = t_single[ok] - stereo_ns[k2[ok]] <= int(max_gap_s * NS)
    single, t_single, k1, k2 = single[ok], t_single[ok], k1[ok], k2[ok]

    # eq. (2) with the actual intervals
    ratio = ((t_single - stereo_ns[k1]) / (stereo_ns[k1] - stereo_ns[k2])).astype(np.float64)
    predicted = points[k1] + ratio[:, None] * (points[k1] - points[k2])
    if method == "typeB":  # eqs. (3)-(4)
        single_points = closest_points_on_rays(prep.ray_origin[single], prep.ray_dir[single],
                                               predicted)
        shift = np.linalg.norm(single_points - predicted, axis=1)
    else:
        single_points, shift = predicted, np.full(len(single), np.nan)
    finite = np.all(np.isfinite(single_points), axis=1)  # a detection without a usable ray
    single, t_single, single_points, shift = (
        single[finite], t_single[finite], single_points[finite], shift[finite])

    time_ns = np.concatenate([stereo_ns, t_single])
    order = np.argsort(time_ns, kind="stable")
    nan_s, nan_m = np.full(len(single), np.nan), np.full(len(stereo_ns), np.nan)
    quality = {k: np.concatenate([v, nan_s])[order] for k, v in stereo.quality.items()}
    quality["ray_shift_m"] = np.concatenate([nan_m, shift])[order]
    return Track(
        method, time_ns[order], np.concatenate([points, single_points])[order],
        np.concatenate([stereo.camera, obs.camera[single]])[order], quality)
