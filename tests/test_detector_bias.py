"""The detector's systematic error in `smooth`'s covariance (issue 10): consider parameters
that the fit can neither average away nor see in its residuals — a common 3-D offset of the
ball's apparent centre (every camera's centroid drawn toward the lit side of the ball) and
each camera's own pixel bias — with the session's default chosen from its metadata."""

from __future__ import annotations

import numpy as np
import pytest
from _rigs import ring_rig

from pslog.errors import FusionError
from pslog.estimation import SmoothOptions, fit_trajectory
from pslog.fusion import DETECTOR_OFFSET_M, FusionOptions, detector_bias_for, fuse
from pslog.log import read_session
from pslog.motion import get_motion
from pslog.records import Observations
from pslog.simulation import SimulationOptions, simulate


def _session(seed: int = 3, noise: float = 0.3):
    """Three distorted 800 x 600 cameras, a 1-s spiral (no bounce, no break): observations
    and truth."""
    rig = ring_rig(3, "r3")
    detections, truth = simulate(rig, get_motion("spiral"), 1.0,
                                 SimulationOptions(noise_px=noise, seed=seed))
    return rig, detections.best(), truth


def _fit(obs, rig, **options):
    fit = fit_trajectory(obs, rig, SmoothOptions(max_gap_s=0.12, **options))
    assert len(fit.trajectory.breaks_s) == 0  # one smooth piece: the linearisation holds
    return fit


def test_camera_bias_sensitivity_is_the_fits_response_to_that_cameras_offset():
    """Adding a constant offset to every detection of one camera (one image axis) moves the
    fitted points by the sensitivity's column of that camera and axis times the offset: the
    sign, the scale and the correlation (one offset shared by the camera's detections, none
    by the others') of :func:`bias_sensitivity`. Fails with the column negated, doubled,
    taken from another camera or axis, built from one detection instead of all, or with the
    IRLS weights in place of the robust cost's Hessian (the M-estimator's ψ')."""
    rig, obs, _ = _session()
    # σ held at 0.3 px (the floor, above the 0.26 px the residuals give): the sensitivity is
    # the robust fit's at its noise scale (the scale's own response to a bias is left out)
    base = _fit(obs, rig, detector_bias_px=1.0, min_noise_px=0.3)  # the columns per pixel
    used = base.used
    S = base.trajectory.sensitivity(obs.time_ns[used])
    assert S.shape == (int(used.sum()), 3, 2 * len(rig))
    step = 0.02  # px: small against the noise (the second-order terms ~0.4 % of the first)
    for camera, axis in ((0, 1), (2, 0)):
        uv = obs.uv.copy()
        uv[obs.camera == camera, axis] += step
        moved = _fit(Observations(obs.time_ns, obs.camera, uv, obs.frame_index), rig,
                     min_noise_px=0.3)
        got = moved.position[used] - base.position[used]
        expected = step * S[:, :, 2 * camera + axis]
        scale = np.max(np.abs(expected))
        assert scale > 2e-5  # tens of micrometres: a real effect, far above the fit's 0.1 µm
        # (the IRLS weights alone in place of the Cauchy cost's Hessian: ~20 % off)
        np.testing.assert_allclose(got, expected, rtol=0, atol=0.02 * scale)
        for other in range(2 * len(rig)):  # every other column is another effect
            if other != 2 * camera + axis:
                assert np.max(np.abs(got - step * S[:, :, other])) > 0.2 * scale


def test_a_common_offset_of_the_apparent_centre_moves_the_fit_by_that_offset():
    """The model behind the 3-D offset term: detections of a ball whose apparent centre is
    off its centre by δ (every camera alike) are the detections of a trajectory shifted by
    δ, and the fit — B-splines summing to one, a prior on the second and third derivatives
    only — moves by δ exactly (to the projection's curvature): its sensitivity to δ is I₃ at
    every point, which is what the covariance adds."""
    rig, obs, truth = _session(seed=5)
    delta = np.array([0.4e-3, -0.3e-3, 0.9e-3])
    X = truth.at(obs.time_ns)
    uv = obs.uv.copy()
    for c, cam in enumerate(rig.cameras):
        sel = obs.camera == c
        uv[sel] += cam.project(X[sel] + delta)[0] - cam.project(X[sel])[0]
    base = _fit(obs, rig)
    moved = _fit(Observations(obs.time_ns, obs.camera, uv, obs.frame_index), rig)
    u = base.used
    np.testing.assert_allclose(moved.position[u] - base.position[u],
                               np.broadcast_to(delta, (int(u.sum()), 3)), rtol=0, atol=2e-5)


def test_consider_terms_add_to_the_covariance_and_never_move_the_points():
    """The offset adds σ_δ² I₃ to every point's covariance (at detections and on a rate
    grid), the camera biases S Sᵀ; positions, residuals and gaps are bit for bit those
    without (fails when the term is dropped, squared twice or not squared)."""
    rig, obs, _ = _session(seed=7)
    sd, px = 0.5e-3, 0.08
    for rate in (None, 60.0):
        plain = fuse(obs, rig, "smooth", FusionOptions(detector_offset_m=0.0, rate_hz=rate))
        offset = fuse(obs, rig, "smooth", FusionOptions(detector_offset_m=sd, rate_hz=rate))
        both = fuse(obs, rig, "smooth", FusionOptions(detector_offset_m=sd,
                                                      detector_bias_px=px, rate_hz=rate))
        for track in (offset, both):
            np.testing.assert_array_equal(track.time_ns, plain.time_ns)
            np.testing.assert_array_equal(track.position_world, plain.position_world)
            np.testing.assert_array_equal(track.quality["gap_s"], plain.quality["gap_s"])
            np.testing.assert_array_equal(track.quality["residual_px"],
                                          plain.quality["residual_px"])
        for axis in "xyz":
            np.testing.assert_allclose(offset.quality[f"cov_{axis}{axis}_m2"]
                                       - plain.quality[f"cov_{axis}{axis}_m2"], sd**2,
                                       rtol=1e-9)
        for pair in ("xy", "xz", "yz"):
            np.testing.assert_allclose(offset.quality[f"cov_{pair}_m2"],
                                       plain.quality[f"cov_{pair}_m2"], rtol=0, atol=1e-18)
        np.testing.assert_allclose(offset.quality["std_m"] ** 2,
                                   plain.quality["std_m"] ** 2 + 3 * sd**2, rtol=1e-9)
        # the cameras' biases: S Sᵀ with S the fit's sensitivity per pixel times σ_b
        fit = fit_trajectory(obs, rig, SmoothOptions(max_gap_s=0.12, detector_bias_px=1.0))
        S = px * fit.trajectory.sensitivity(both.time_ns)
        extra = np.einsum("nik,njk->nij", S, S)
        for name, (i, j) in (("xx", (0, 0)), ("yy", (1, 1)), ("zz", (2, 2)),
                             ("xy", (0, 1)), ("yz", (1, 2))):
            np.testing.assert_allclose(both.quality[f"cov_{name}_m2"]
                                       - offset.quality[f"cov_{name}_m2"], extra[:, i, j],
                                       rtol=1e-6, atol=1e-15)
        assert np.all(extra[:, 2, 2] > 1e-10)  # a real term: tenths of a millimetre squared


def test_bias_options_are_checked():
    for bad in (-1e-3, float("nan"), 2.0):
        with pytest.raises(FusionError, match="detector offset"):
            FusionOptions(detector_offset_m=bad)
        with pytest.raises(FusionError, match="detector offset"):
            SmoothOptions(detector_offset_m=bad)
    for bad in (-0.1, float("nan"), 1e4):
        with pytest.raises(FusionError, match="detector bias"):
            FusionOptions(detector_bias_px=bad)


def test_the_default_offset_follows_where_the_detections_came_from(tmp_path, cli):
    """``pslog fuse``: a ``pslog simulate`` session (projected truth plus white noise) gets
    no offset; the same detections imported from a CSV (a detector's, unknown) and a
    recorded session (the shipped sample, pslog's image detector) get 0.5 mm per axis;
    ``--detector-offset-mm`` overrides either; the points never move."""
    assert detector_bias_for({"source": "pslog simulate motion=spiral"}) == 0.0
    assert detector_bias_for({"source": "record --synthetic motion=throw",
                              "detector_hsv": "4,22,120,255,70,255"}) == DETECTOR_OFFSET_M
    assert detector_bias_for({}) == DETECTOR_OFFSET_M
    assert DETECTOR_OFFSET_M == 0.5e-3
    sim, csv, imported = tmp_path / "s.mcap", tmp_path / "d.csv", tmp_path / "i.mcap"
    for args in (("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                  "--noise-px", "0.3", "-o", sim),
                 ("export", sim, "--detections", csv),
                 ("import", "--rig", "paper3", "--timing", "typeA", "--detections", csv,
                  "-o", imported)):
        code, _, err = cli(*args)
        assert code == 0, err

    def smooth(session, *extra):
        out = tmp_path / f"f{len(list(tmp_path.iterdir()))}.mcap"
        code, _, err = cli("fuse", session, "--method", "smooth", *extra, "-o", out)
        assert code == 0, err
        return read_session(out).tracks["smooth"]

    default_sim, zero_sim = smooth(sim), smooth(sim, "--detector-offset-mm", "0")
    np.testing.assert_array_equal(default_sim.quality["cov_zz_m2"], zero_sim.quality["cov_zz_m2"])
    default_imp, zero_imp = smooth(imported), smooth(imported, "--detector-offset-mm", "0")
    np.testing.assert_array_equal(default_imp.position_world, zero_imp.position_world)
    np.testing.assert_allclose(default_imp.quality["cov_zz_m2"] - zero_imp.quality["cov_zz_m2"],
                               0.25e-6, rtol=1e-9)
    two = smooth(imported, "--detector-offset-mm", "2")
    np.testing.assert_allclose(two.quality["cov_xx_m2"] - zero_imp.quality["cov_xx_m2"], 4e-6,
                               rtol=1e-9)
    with pytest.raises(SystemExit) as exc:  # a malformed command line: argparse's exit 2
        cli("fuse", sim, "--detector-offset-mm", "-1", "-o", tmp_path / "x.mcap")
    assert exc.value.code == 2
