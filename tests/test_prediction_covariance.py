"""The covariance of ``linear``'s and ``typeB``'s predicted points, by hand from the paper's
eqs. (2) and (4) (:mod:`pslog.fusion.prediction`; docs/paper.md, the ``std_m`` row).

For a single detection at ``t`` between the stereo points ``P_1`` (at ``t_1``) and ``P_2``
(at ``t_2 < t_1``), eq. (2) is ``P̂ = (1 + ρ) P_1 − ρ P_2`` with ``ρ = (t − t_1) / (t_1 −
t_2)``; the two stereo points come from distinct detections, so

    Σ_linear = (1 + ρ)² Σ_1 + ρ² Σ_2.

Eq. (4) puts ``P' = T + d dᵀ (P̂ − T)`` (``d`` the unit viewing ray of the single detection,
``T`` its camera's centre): the prediction's covariance seen along the ray, plus the ray's
own turn with the single detection's pixel noise σ (independent of the stereo detections):

    Σ_typeB = (dᵀ Σ_linear d) d dᵀ + σ² J Jᵀ,   J = ∂P'/∂(recorded pixel).

Here ``J`` is made by central differences of :meth:`pslog.camera.Camera.rays` (through the
lens), not by the method's analytic Jacobians, and ``Σ_1``, ``Σ_2`` are read from the stereo
points of the same track."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_allclose

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import FusionOptions, fuse
from pslog.rig import Rig

SIGMA_PX = 0.7
LENS = np.array([-0.25, 0.08, 0.001, -0.001, 0.0])
NAMES = ("xx", "yy", "zz", "xy", "xz", "yz")


def _matrices(quality, rows) -> np.ndarray:
    c = {n: quality[f"cov_{n}_m2"][rows] for n in NAMES}
    return np.stack([np.stack([c["xx"], c["xy"], c["xz"]], -1),
                     np.stack([c["xy"], c["yy"], c["yz"]], -1),
                     np.stack([c["xz"], c["yz"], c["zz"]], -1)], -2)


def _session():
    rig = apply_timing(builtin_rig("paper3"), "typeB")
    rig = Rig(tuple(c.replace(dist=LENS) for c in rig.cameras), rig.name)
    detections, _ = simulate(rig, get_motion("throw"), None,
                             SimulationOptions(noise_px=0.3, seed=4))
    options = FusionOptions(noise_px=SIGMA_PX, gating=False)
    return rig, detections.best(), fuse(detections, rig, "linear", options), \
        fuse(detections, rig, "typeB", options)


def _brackets(track):
    """Rows of the single-camera points (camera 2 of paper3's type B) and of their two
    latest stereo points, and eq. (2)'s ρ."""
    stereo = np.flatnonzero(track.camera != 1)
    single = np.flatnonzero(track.camera == 1)
    at = np.searchsorted(track.time_ns[stereo], track.time_ns[single], side="left") - 1
    keep = at >= 1
    single, k1, k2 = single[keep], stereo[at[keep]], stereo[at[keep] - 1]
    t, t1, t2 = (track.time_ns[r] for r in (single, k1, k2))
    return single, k1, k2, (t - t1) / (t1 - t2)


def test_linear_covariance_is_eq2_applied_to_the_stereo_points():
    _, _, linear, _ = _session()
    single, k1, k2, rho = _brackets(linear)
    assert len(single) > 20 and np.allclose(rho, 0.5, atol=1e-6)  # 1/60 s after, 1/30 apart
    cov = _matrices(linear.quality, single)
    expected = ((1 + rho) ** 2)[:, None, None] * _matrices(linear.quality, k1) \
        + (rho**2)[:, None, None] * _matrices(linear.quality, k2)
    assert_allclose(cov, expected, rtol=1e-12, atol=0)
    assert_allclose(linear.quality["std_m"][single],
                    np.sqrt(np.trace(expected, axis1=1, axis2=2)), rtol=1e-12)


def test_type_b_covariance_is_the_prediction_along_the_ray_plus_the_rays_own_noise():
    rig, obs, linear, type_b = _session()
    single = _brackets(linear)[0]
    predicted = linear.position_world[single]  # linear's point is eq. (2)'s P̂
    cov_pred = _matrices(linear.quality, single)
    cam = rig.cameras[1]
    rows_b = np.searchsorted(type_b.time_ns, linear.time_ns[single])
    assert np.array_equal(type_b.time_ns[rows_b], linear.time_ns[single])
    mine = (obs.camera == 1)
    det = np.searchsorted(obs.time_ns[mine], linear.time_ns[single])
    uv = obs.uv[mine][det]
    assert np.array_equal(obs.time_ns[mine][det], linear.time_ns[single])

    def foot(pixels):  # eq. (4): the point of the single detection's ray nearest to P̂
        origin, direction = cam.rays(pixels)
        d = direction / np.linalg.norm(direction, axis=1, keepdims=True)
        return origin + np.einsum("ij,ij->i", predicted - origin, d)[:, None] * d

    assert_allclose(type_b.position_world[rows_b], foot(uv), rtol=0, atol=1e-12)
    h = 1e-3  # px
    J = np.stack([(foot(uv + h * e) - foot(uv - h * e)) / (2 * h)
                  for e in (np.array([1.0, 0.0]), np.array([0.0, 1.0]))], axis=-1)  # (k, 3, 2)
    _, direction = cam.rays(uv)
    d = direction / np.linalg.norm(direction, axis=1, keepdims=True)
    along = np.einsum("ki,kij,kj->k", d, cov_pred, d)
    expected = along[:, None, None] * d[:, :, None] * d[:, None, :] \
        + SIGMA_PX**2 * J @ J.transpose(0, 2, 1)
    got = _matrices(type_b.quality, rows_b)
    scale = np.trace(expected, axis1=1, axis2=2)[:, None, None]
    assert np.all(np.abs(got - expected) <= 1e-6 * scale)
    # the ray's turn is a real part of it (not a term the test could drop unnoticed)
    assert np.median(np.trace(SIGMA_PX**2 * J @ J.transpose(0, 2, 1), axis1=1, axis2=2)
                     / np.trace(expected, axis1=1, axis2=2)) > 0.05
