"""`nearest`'s covariance at a break of the image motion (a bounce, a kick), hand-computed
(docs/methods.md, "nearest at bounces and kicks"): a slot's newest detection whose residual
from the quadratic through its camera's three previous ones exceeds what the noise allows
(``ν_r² > KINK_GATE σ² c``, recorded pixels) inflates every slot with a lag and a velocity by
``KINK_SHARE ν² (1 - KINK_GATE σ² c / ν_r²) ppm_s² / ppm_a²`` pixels² per axis (``ν``
undistorted; ``ppm`` a camera's pixels per metre at the point); a straight segment, whose
residuals the noise explains, leaves the covariance as it was.

Mutations tried (each fails a test here): the noise not subtracted (``excess = ν_r²``);
KINK_GATE 9.21 -> 3; KINK_SHARE 0.2 -> 0.5; no transfer between cameras (``ppm_s`` for
``ppm_a``); the size in recorded pixels (no lens); the point's own slot (no lag) inflated
too; only the point's own camera tested (not the partners'); a slot's previous detection
tested instead of its newest; the last firing slot's break taken instead of the largest."""

from __future__ import annotations

import numpy as np
from test_uncertainty import _pair_jacobian, _pair_point, _rig

from pslog.fusion import FusionOptions, fuse
from pslog.fusion import stereo as S
from pslog.fusion._prepare import prepare
from pslog.records import NS, Observations
from pslog.rig import Rig

SIGMA = 0.4


def _position(t, bounce_s):
    """A ball under gravity whose vertical velocity reverses (restitution 0.8) at
    ``bounce_s`` (None: no bounce)."""
    p0, v, g = np.array([1.2, 0.8, 1.1]), np.array([2.5, -1.5, -3.0]), np.array([0, 0, -9.81])
    if bounce_s is None or t <= bounce_s:
        return p0 + v * t + 0.5 * g * t * t
    pb = p0 + v * bounce_s + 0.5 * g * bounce_s**2
    vb = v + g * bounce_s
    vb = np.array([vb[0], vb[1], -0.8 * vb[2]])
    s = t - bounce_s
    return pb + vb * s + 0.5 * g * s * s


def _session(rows, bounce_s, nudge_px=(0.0, 0.0)):
    """Two cameras of :func:`_rig` (lens distortion): ``rows`` (time s, camera), the last the
    point; the last detection's recorded pixel moved by ``nudge_px``."""
    rig = Rig(_rig(2).cameras)
    t = np.array([r[0] for r in rows])
    cam = np.array([r[1] for r in rows], dtype=np.int32)
    uv = np.stack([rig.cameras[c].project(_position(s, bounce_s)[None])[0][0]
                   for s, c in zip(t, cam, strict=True)])
    uv[-1] += nudge_px
    return rig, Observations(np.round(t * NS).astype(np.int64), cam, uv,
                             np.arange(len(t), dtype=np.int64))


def _lagrange(times, at):
    """Weights of the polynomial through ``times`` evaluated at ``at``."""
    return np.array([np.polyval(np.polyfit(times, np.eye(len(times))[j], len(times) - 1), at)
                     for j in range(len(times))])


def _residual(prep, obs, rows):
    """``(ν², ν_r², c)`` of the last of ``rows`` (one camera's, in order) from the quadratic
    through the three before it, in undistorted and in recorded pixels."""
    t = obs.time_ns[rows] / NS
    w = _lagrange(t[:-1], t[-1])
    nu = prep.uv_undistorted[rows[-1]] - w @ prep.uv_undistorted[rows[:-1]]
    nu_r = obs.uv[rows[-1]] - w @ obs.uv[rows[:-1]]
    return float(nu @ nu), float(nu_r @ nu_r), 1.0 + float(w @ w)


def _size(nu2, nu2_r, c):
    """The break's share beyond the noise, undistorted pixels²: ``ν² (1 - G σ² c / ν_r²)``
    (0 where ``ν_r² <= G σ² c``)."""
    excess = nu2_r - S.KINK_GATE * SIGMA**2 * c
    return nu2 * excess / nu2_r if excess > 0 else 0.0


def _ppm2(rig, cam, point):
    """(f / z)² of camera ``cam`` at ``point``: pixels per metre across its ray, squared."""
    c = rig.cameras[cam]
    z = (np.asarray(c.R) @ point + np.ravel(c.t))[2]
    return (0.5 * (c.K[0, 0] + c.K[1, 1]) / z) ** 2


def _fused(rig, obs):
    track = fuse(obs, rig, "nearest", FusionOptions(noise_px=SIGMA, gating=False))
    q = track.quality
    i = len(track) - 1
    assert track.time_ns[i] == obs.time_ns[-1]
    cov = np.array([[q["cov_xx_m2"][i], q["cov_xy_m2"][i], q["cov_xz_m2"][i]],
                    [q["cov_xy_m2"][i], q["cov_yy_m2"][i], q["cov_yz_m2"][i]],
                    [q["cov_xz_m2"][i], q["cov_yz_m2"][i], q["cov_zz_m2"][i]]])
    return track.position_world[i], cov


def _without_break(prep, obs, e, partner):
    """The covariance of the point made of row ``e`` (camera 0, lag 0) and camera 1's rows
    ``partner`` (its newest last, each within the gap): the extrapolation noise and the
    extrapolated move (tests/test_uncertainty.py), and ``J_d``."""
    uv = prep.uv_undistorted
    d = partner[-1]
    J_c, J_d = _pair_jacobian(prep, e, d, 0), _pair_jacobian(prep, e, d, 1)
    L_all = [prep.pixel_jacobians_t(np.array([r]))[..., 0] for r in range(len(obs))]
    used = partner[-3:]  # the quadratic through the newest three
    w = _lagrange(obs.time_ns[used] / NS, obs.time_ns[e] / NS)
    noise = J_c @ L_all[e] @ L_all[e].T @ J_c.T
    for j, r in enumerate(used):
        noise = noise + w[j] ** 2 * J_d @ L_all[r] @ L_all[r].T @ J_d.T
    move = J_d @ (w @ uv[used] - uv[d])
    return SIGMA**2 * noise + np.outer(move, move), J_d


# the point's own camera (0) sees the bounce at 0.090 s in its last detection (0.100 s); its
# partner (camera 1), last seen at 0.0833 s, has not: extrapolated across it
OWN_SEES = [(0.0, 0), (0.0167, 1), (0.0333, 0), (0.05, 1), (0.0667, 0), (0.0833, 1),
            (0.100, 0)]


def test_a_bounce_the_points_own_camera_sees_inflates_its_partner():
    rig, obs = _session(OWN_SEES, bounce_s=0.090)
    prep = prepare(obs, rig)
    point, got = _fused(rig, obs)
    e, partner = len(obs) - 1, [1, 3, 5]
    assert np.allclose(_pair_point(prep, prep.uv_undistorted[e],
                                   prep.uv_undistorted[partner[-1]]), point, atol=1e-9)
    before, J_d = _without_break(prep, obs, e, partner)
    nu2, nu2_r, c = _residual(prep, obs, [0, 2, 4, 6])
    assert nu2_r > 3 * S.KINK_GATE * SIGMA**2 * c  # the bounce, far beyond the noise
    assert abs(nu2 / nu2_r - 1) > 1e-3  # (the lens matters here, above the tolerance)
    ratio = _ppm2(rig, 1, point) / _ppm2(rig, 0, point)
    assert abs(ratio - 1) > 0.05  # (the transfer between the cameras matters here)
    expected = before + S.KINK_SHARE * _size(nu2, nu2_r, c) * ratio * J_d @ J_d.T
    np.testing.assert_allclose(got, expected, rtol=2e-6, atol=1e-14)
    assert not np.allclose(got, before, rtol=1e-3)
    # and the truth is now inside the point's 2σ ellipsoid (it was far outside)
    err = point - _position(obs.time_ns[e] / NS, 0.090)
    assert err @ np.linalg.solve(before, err) > 9
    assert err @ np.linalg.solve(got, err) < 4


def test_a_bounce_the_partner_has_seen_inflates_its_own_slot():
    """The partner's newest detection (0.100 s) is past the bounce (0.085 s) with three
    before it; the point's own camera has no three previous detections: the break is the
    partner's, in its own image (no transfer)."""
    rows = [(0.0, 1), (0.0333, 1), (0.05, 0), (0.0667, 1), (0.100, 1), (0.117, 0)]
    rig, obs = _session(rows, bounce_s=0.085)
    prep = prepare(obs, rig)
    _, got = _fused(rig, obs)
    e, partner = len(obs) - 1, [0, 1, 3, 4]
    before, J_d = _without_break(prep, obs, e, partner)
    nu2, nu2_r, c = _residual(prep, obs, partner)
    assert nu2_r > 3 * S.KINK_GATE * SIGMA**2 * c
    np.testing.assert_allclose(
        got, before + S.KINK_SHARE * _size(nu2, nu2_r, c) * J_d @ J_d.T, rtol=2e-6,
        atol=1e-14)


def test_a_straight_segment_leaves_the_covariance_as_it_was():
    """No bounce, and the point's own detection off the quadratic by less than the noise
    allows (ν² ≈ 0.7 KINK_GATE σ² c): no break, the covariance without the term."""
    rig, obs = _session(OWN_SEES, bounce_s=None)
    prep = prepare(obs, rig)
    _, _, c = _residual(prep, obs, [0, 2, 4, 6])
    size = np.sqrt(0.7 * S.KINK_GATE * c) * SIGMA
    rig, obs = _session(OWN_SEES, bounce_s=None, nudge_px=(0.6 * size, 0.8 * size))
    prep = prepare(obs, rig)
    _, nu2_r, c = _residual(prep, obs, [0, 2, 4, 6])
    assert 0.5 * S.KINK_GATE * SIGMA**2 * c < nu2_r < 0.9 * S.KINK_GATE * SIGMA**2 * c
    _, got = _fused(rig, obs)
    before, _ = _without_break(prep, obs, len(obs) - 1, [1, 3, 5])
    np.testing.assert_allclose(got, before, rtol=2e-6, atol=1e-14)


def test_the_break_term_fires_on_a_bounce_and_the_compiled_form_is_the_numpy_one():
    """A simulated throw with its floor bounce, 0.3 px noise: the term inflates the points
    just after the bounce and leaves most alone; the compiled kernel gives the numpy form's
    bits, and the points do not move."""
    from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
    from pslog.fusion._prepare import default_max_gap_s

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(noise_px=0.3,
                                                                        seed=4))
    prep = prepare(det.best(), rig)
    gap = default_max_gap_s(rig)
    with np.errstate(all="ignore"):
        got = S.fuse_nearest(prep, gap, 0.5)
        want = S.fuse_nearest(prep, gap, 0.5, compiled=False)
        gate = S.KINK_GATE
        try:
            S.KINK_GATE = np.inf
            off = S.fuse_nearest(prep, gap, 0.5)
        finally:
            S.KINK_GATE = gate
    for name in want.quality:
        assert got.quality[name].tobytes() == want.quality[name].tobytes(), name
    assert got.position_world.tobytes() == off.position_world.tobytes()
    grown = got.quality["std_m"] > off.quality["std_m"]
    assert np.all(got.quality["std_m"] >= off.quality["std_m"])
    assert 0.01 < grown.mean() < 0.3, grown.mean()


def test_the_largest_break_among_the_points_detections_is_taken():
    """Both cameras' newest detections are past the bounce (0.090 s) with three before
    each: κ² is the larger of the two, each in metres across its camera's ray."""
    rows = [(0.0, 1), (0.0167, 0), (0.0333, 1), (0.05, 0), (0.0667, 1), (0.0833, 0),
            (0.100, 1), (0.117, 0)]
    rig, obs = _session(rows, bounce_s=0.090)
    prep = prepare(obs, rig)
    point, got = _fused(rig, obs)
    before, J_d = _without_break(prep, obs, 7, [0, 2, 4, 6])
    own = _size(*_residual(prep, obs, [1, 3, 5, 7])) / _ppm2(rig, 0, point)
    partner = _size(*_residual(prep, obs, [0, 2, 4, 6])) / _ppm2(rig, 1, point)
    assert own > 1.2 * partner > 0  # (the point's own camera's, the first slot's, is larger)
    np.testing.assert_allclose(
        got, before + S.KINK_SHARE * own * _ppm2(rig, 1, point) * J_d @ J_d.T, rtol=2e-6,
        atol=1e-14)


def test_the_share_is_the_mean_squared_extrapolation_error_over_the_largest_residual():
    """KINK_SHARE from its model: a velocity jump at a time uniform over the last four
    frames before the point; a partner's error is its quadratic extrapolation's from its
    last three detections, the largest residual |ν| that of the point's detections'
    (each from its camera's three previous): E[e² / ν²] over the jump's time, three
    cameras at 1/3-frame offsets (frames of 1), is about 0.2."""
    def u(t, tau):
        return np.maximum(t - tau, 0.0)

    def extrapolated(t, tau, newest):  # quadratic through newest, newest - 1, newest - 2
        x = t - newest  # (Lagrange's weights at unit spacing)
        return ((x + 1) * (x + 2) / 2 * u(newest, tau) - x * (x + 2) * u(newest - 1, tau)
                + x * (x + 1) / 2 * u(newest - 2, tau))

    ratios = []
    for own in range(3):
        t = 3.0 + own / 3
        for tau in np.linspace(t - 4, t, 401)[1:-1]:
            newest = [np.floor(t - c / 3 - 1e-9) + c / 3 if c != own else t for c in range(3)]
            nu = max(abs(u(s, tau) - extrapolated(s, tau, s - 1)) for s in newest)
            if nu < 1e-6:
                continue
            for c in range(3):
                if c != own:
                    e = u(t, tau) - extrapolated(t, tau, newest[c])
                    ratios.append(e * e / (nu * nu))
    assert abs(np.mean(ratios) - S.KINK_SHARE) < 0.015, np.mean(ratios)
