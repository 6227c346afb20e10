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

from ..geometry import closest_points_on_rays, ray_depths
from ..records import NS, Track
from . import _prepare
from ._prepare import (
    _SYM6,
    BEHIND,
    Prepared,
    covariance,
    covariance_columns,
    direction_jacobian,
    dot_t,
    finite_difference_jacobians,
    invalid_points,
    reprojection_px,
)
from .innovation import contradicted, failed_counts
from .stereo import (
    Drops,
    count_invalid,
    note_dropped,
    rays_only_shared,
    refusal_noise,
    stereo_at_common_instants,
    with_dropped,
)


def fuse_predicted(prep: Prepared, method: str, tolerance_s: float, max_gap_s: float,
                   noise_px: float | None = 0.5, *, drops: Drops | None = None) -> Track:
    """``typeB`` (ray-constrained, eq. (4)) or ``linear`` (eq. (2) only).

    Geometrically invalid points are dropped and counted in ``Track.dropped``: stereo points
    behind or outside a camera that saw them or from near-parallel rays (never used for a
    prediction either), and predicted points behind or outside the view of a camera that
    contributed (typeB: also a foot behind the single camera, eq. (4)'s ``k <= 0``).
    Quality of a predicted point: ``residual_*_px`` over the stereo detections and the single
    detection against the eq. (2) prediction; ``gap_s``: time from the older stereo point;
    ``std_m`` / ``cov_*``: the stereo points' covariances through eq. (2) (and for typeB the
    projection onto the ray plus the single detection's own noise). A detection without a
    ray is a missing one (:func:`~.stereo.rays_only_shared`). ``drops``: a list to which
    each dropped point's reason, time and camera are added (:data:`~.stereo.Drops`).
    """
    if method not in ("typeB", "linear"):
        raise ValueError(f"method must be typeB or linear, got {method!r}")
    # a detection without a ray is a missing one: not a partner that leaves another
    # detection of its instant without a prediction (docs/methods.md, "A detection without
    # a ray")
    prep, shared = rays_only_shared(prep, tolerance_s)
    obs = prep.obs
    if len(obs) == 0:
        return Track(method, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0, np.int32))
    stereo, alone = stereo_at_common_instants(prep, tolerance_s, method, noise_px, max_gap_s,
                                              shared, drops=drops)
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
    cam = obs.camera[single]
    n_single = len(single)
    q = stereo.quality
    if noise_px is not None:  # the six distinct entries (6, k) of the prediction's covariance
        cov_stereo = np.array([q[f"cov_{name}_m2"] for name, _, _ in _SYM6])
        cov_pred = (1 + ratio) ** 2 * cov_stereo[:, k1] + ratio**2 * cov_stereo[:, k2]
    with np.errstate(invalid="ignore"):
        own = reprojection_px(prep, predicted, cam, prep.uv_undistorted[single])
    flags = np.zeros(n_single, dtype=np.int64)
    if method == "typeB":  # eqs. (3)-(4)
        single_points = closest_points_on_rays(prep.ray_origin[single], prep.ray_dir[single],
                                               predicted)
        shift = np.linalg.norm(single_points - predicted, axis=1)
        with np.errstate(invalid="ignore"):
            depth = ray_depths(predicted, prep.ray_origin[single], prep.ray_dir[single])
        flags[~(depth > 0)] |= BEHIND

        cov = None if noise_px is None else _type_b_covariance(
            prep, single, cam, predicted, cov_pred, noise_px)
    else:
        single_points, shift = predicted, np.full(n_single, np.nan)
        cov = None if noise_px is None else covariance_columns(cov_pred)
    mask_bits = (q["camera_mask"][k1].astype(np.int64) | q["camera_mask"][k2].astype(np.int64)
                 | (1 << cam.astype(np.int64)))
    used = (mask_bits[:, None] >> np.arange(len(prep.centers))) & 1 == 1
    flags |= invalid_points(prep, single_points, used)
    n1, n2 = q["n_detections"][k1], q["n_detections"][k2]
    with np.errstate(invalid="ignore"):
        single_quality = {
            "ray_miss_m": np.full(n_single, np.nan), "snap_px": np.full(n_single, np.nan),
            "ray_angle_deg": np.minimum(q["ray_angle_deg"][k1], q["ray_angle_deg"][k2]),
            "residual_max_px": np.fmax(np.fmax(q["residual_max_px"][k1],
                                               q["residual_max_px"][k2]), own),
            "residual_mean_px": (q["residual_mean_px"][k1] * n1 + q["residual_mean_px"][k2] * n2
                                 + own) / (n1 + n2 + 1),
            "camera_mask": mask_bits.astype(np.float64),
            "n_detections": n1 + n2 + 1,
            "gap_s": (t_single - stereo_ns[k2]) / NS,
            **(cov if cov is not None else {}),
        }
        stereo_span = q["gap_s"]
    made = np.all(np.isfinite(single_points), axis=1)  # a detection without a usable ray
    # the single detection contradicts eq. (2)'s prediction (type A's innovation test,
    # pslog.fusion.innovation): a change of motion inside the extrapolation, or a detection
    # that is not the ball the stereo points saw; eq. (4) would put the point on its ray
    # at the prediction's depth, metres off (docs/paper.md, "Type B's prediction test")
    # (σ: the larger of the least stated noise, max(0.5 px, noise_px), and the detector's
    # noise the detection's own camera shows, stereo.refusal_noise: a stated noise below
    # the real one refused good points in numbers)
    failed = contradicted(prep, single, (t_single - stereo_ns[k1]) / NS,
                          (stereo_ns[k1] - stereo_ns[k2]) / NS, predicted, own,
                          refusal_noise(prep, t_single, max_gap_s, noise_px,
                                        obs.camera[single]))
    failed &= made & (flags == 0)
    keep = made & (flags == 0) & ~failed
    if drops is not None:
        note_dropped(drops, t_single[made], cam[made], flags[made])
        note_dropped(drops, t_single, cam, refused=("prediction_failed", failed))
    single, t_single, single_points, shift = (
        single[keep], t_single[keep], single_points[keep], shift[keep])
    single_quality = {k: v[keep] for k, v in single_quality.items()}
    single_quality["span_s"] = single_quality["gap_s"] + stereo_span[k2[keep]]

    time_ns = np.concatenate([stereo_ns, t_single])
    order = np.argsort(time_ns, kind="stable")
    nan_m = np.full(len(stereo_ns), np.nan)
    nan_s = np.full(len(single), np.nan)
    quality = {k: np.concatenate([q.get(k, nan_m), single_quality.get(k, nan_s)])[order]
               for k in dict.fromkeys([*q, *single_quality])}
    quality["ray_shift_m"] = np.concatenate([nan_m, shift])[order]
    track = Track(
        method, time_ns[order], np.concatenate([points, single_points])[order],
        np.concatenate([stereo.camera, obs.camera[single]])[order], quality)
    return with_dropped(track, stereo.dropped, count_invalid(flags[made]),
                        failed_counts(failed))


def _type_b_covariance(prep: Prepared, single: np.ndarray, cam: np.ndarray,
                       predicted: np.ndarray, cov_pred: np.ndarray, noise_px: float
                       ) -> dict[str, np.ndarray]:
    """Covariance columns of type B's points: the prediction's (six distinct entries (6, k))
    projected onto the single detection's ray (eq. (4)), plus the ray's own turn with its
    detection's noise."""
    with np.errstate(invalid="ignore"):
        if _prepare.FINITE_DIFFERENCES:
            def evaluate(uv):
                return closest_points_on_rays(
                    prep.ray_origin[single], prep.rays_from_undistorted(cam, uv[0]), predicted)

            jacobians = finite_difference_jacobians(
                evaluate, [prep.uv_undistorted[single]], single[:, None])
        else:  # a turn δr of the unit ray moves the foot by ((rᵀq) I + r qᵀ) δr, q = P̂ - T
            d = prep.ray_dir[single].T.copy()
            offset = (predicted - prep.ray_origin[single]).T
            G = direction_jacobian(prep, cam, prep.uv_undistorted[single])
            turn = (d[0] * offset[0] + d[1] * offset[1] + d[2] * offset[2]) * G
            turn += d[:, None] * dot_t(offset, G)
            jacobians = [turn]
        cov = covariance(single[:, None], jacobians, [prep.pixel_jacobians_t(single)],
                         noise_px)
    # the projection onto the ray, eq. (4): d dᵀ C d dᵀ = (dᵀ C d) d dᵀ
    d = prep.ray_dir[single].T
    along = np.zeros(len(single))
    for e, (_, i, j) in enumerate(_SYM6):
        along += (1.0 if i == j else 2.0) * d[i] * d[j] * cov_pred[e]
    out = np.empty((6, len(single)))
    for e, (name, i, j) in enumerate(_SYM6):
        out[e] = along * d[i] * d[j] + cov[f"cov_{name}_m2"]
    return covariance_columns(out)
