"""Issue 10: geometrically valid points, quality that means something, streaming that equals
batch on dirty sessions, and fusion tests under lens distortion that catch a wrong equation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _rally import rally
from numpy.testing import assert_allclose, assert_array_equal
from test_fusion import BASELINE, CX, CY, F_PX, K, observations  # one rectified rig
from test_fusion import lens as distorted  # and lens

from pslog import (
    NS,
    Camera,
    Observations,
    Rig,
    SimulationOptions,
    apply_timing,
    builtin_rig,
    get_motion,
    simulate,
)
from pslog.evaluation import CHI2_3D_2SIGMA, evaluate, summarise_quality
from pslog.fusion import (
    METHODS,
    FusionOptions,
    causal_methods,
    explain_type_a,
    fuse,
    prepare,
    pseudo_stereo_points,
)
from pslog.fusion._prepare import default_max_gap_s
from pslog.fusion.stream import StreamFuser
from pslog.geometry import crossing_of_rays, triangulate_two_rays

#: the paper's methods and their baselines, whose points carry the quality columns of issue 10
#: (``camera_mask``, ``residual_*_px``, ``gap_s``, ``std_m``, ``cov_*_m2``)
PAPER_METHODS = [m for m in ("sync", "nearest", "typeA", "typeB", "linear") if m in METHODS]


def rectified_rig(offsets=(0.0, 0.0)) -> Rig:
    """Two cameras looking along +z, the second 0.5 m along +x: epipolar lines are rows and
    the depth is ``f b / disparity``."""
    cam0 = Camera("left", 640, 480, K, np.zeros(5), np.eye(3), np.zeros(3), 30.0, offsets[0])
    cam1 = Camera("right", 640, 480, K, np.zeros(5), np.eye(3), np.array([-BASELINE, 0, 0]),
                  30.0, offsets[1])
    return Rig((cam0, cam1), "rectified")


def dirty_session(timing: str, seed: int, lens: bool = True):
    """The paper rig (with a strong lens) on a throw: 0.5 px noise, 30 % missed detections,
    10 % dropped frames, 0.5 ms jitter, and 5 % of the detections replaced by a random pixel
    (outliers)."""
    rig = apply_timing(builtin_rig("paper3"), timing)
    rig = distorted(rig) if lens else rig
    detections, truth = simulate(rig, get_motion("throw"), options=SimulationOptions(
        noise_px=0.5, miss_rate=0.3, drop_rate=0.1, jitter_s=0.0005, seed=seed))
    obs = detections.best()
    rng = np.random.default_rng(seed)
    uv = obs.uv.copy()
    outlier = rng.random(len(obs)) < 0.05
    uv[outlier] = rng.uniform([0.0, 0.0], [640.0, 480.0], (int(outlier.sum()), 2))
    return rig, Observations(obs.time_ns, obs.camera, uv, obs.frame_index), truth


def streamed(rig, method, obs, options=None):
    fuser = StreamFuser(rig, method, options)
    parts = [fuser.push(obs.time_ns[i], obs.camera[i], obs.uv[i], obs.frame_index[i])
             for i in range(len(obs))]
    parts.append(fuser.flush())
    return [p for p in parts if len(p)]


# ---- geometric validity: hand-made cases --------------------------------------------------

def test_a_negative_disparity_pair_crosses_behind_both_cameras_and_is_no_point():
    # left u = 300, right u = 320: the rays "cross" at Z = f b / (-20 px) = -12.5 m, and they
    # do cross (a miss of ~0), so only the ray parameters tell
    rig = rectified_rig()
    left = np.array([[(300.0 - CX) / F_PX, 0.0, 1.0]])
    right = np.array([[(320.0 - CX) / F_PX, 0.0, 1.0]])
    points, miss, s, k = crossing_of_rays(np.zeros(3), left, np.array([BASELINE, 0, 0]), right)
    assert_allclose(points[0, 2], -12.5, rtol=1e-12)
    assert miss[0] < 1e-12 and s[0] < 0 and k[0] < 0
    assert_allclose(triangulate_two_rays(np.zeros(3), left, np.array([BASELINE, 0, 0]),
                                         right)[0], points)
    obs = observations([(0, 0, 300.0, 240.0), (0, 1, 320.0, 240.0),     # behind
                        (40, 0, 340.0, 240.0), (40, 1, 320.0, 240.0)])  # Z = 12.5 m in front
    for method in ("sync", "nearest"):
        track = fuse(obs, rig, method)
        assert np.all(track.position_world[:, 2] > 0), method
        assert track.dropped.get("behind_camera", 0) >= 1, (method, track.dropped)
    track = fuse(obs, rig, "sync")
    assert_array_equal(track.time_ns, [40_000_000])
    assert_allclose(track.position_world, [[20 * 12.5 / F_PX, 0.0, 12.5]], atol=1e-12)
    assert track.dropped == {"behind_camera": 1}


def test_type_a_refuses_past_points_behind_the_cameras_and_says_so():
    # a static ball the right camera sees at a negative disparity: every pseudo-stereo pair
    # crosses behind both cameras; no point, and the refusals are counted
    rig = rectified_rig(offsets=(0.0, 1 / 60))
    rows = [(10 * i, i % 2, 320.0 if i % 2 == 0 else 380.0, 240.0) for i in range(8)]
    track = fuse(observations(rows), rig, "typeA")
    assert len(track) == 0
    assert track.dropped.get("past_behind_camera", 0) >= 4, track.dropped
    # the same with a positive disparity: points at Z = f b / 60 px on the left axis
    rows = [(10 * i, i % 2, 320.0 if i % 2 == 0 else 260.0, 240.0) for i in range(8)]
    track = fuse(observations(rows), rig, "typeA")
    assert len(track) == 5 and track.dropped == {}
    assert_allclose(track.position_world[:, 2], F_PX * BASELINE / 60.0, rtol=1e-12)


def test_points_outside_the_view_and_from_near_parallel_rays_are_dropped_and_counted():
    rig = rectified_rig()
    obs = observations([
        (0, 0, -300.0, 240.0), (0, 1, -330.0, 240.0),   # in front, 300 px left of the image
        (40, 0, 320.0, 240.0), (40, 1, 320.0, 240.0),   # parallel rays: no depth
        (80, 0, 320.05, 240.0), (80, 1, 320.0, 240.0),  # 0.05 px: 5 km, 0.006 deg apart
        (120, 0, 340.0, 240.0), (120, 1, 320.0, 240.0),  # a good point
    ])
    track = fuse(obs, rig, "sync")
    assert_array_equal(track.time_ns, [120_000_000])
    assert track.dropped == {"outside_view": 1, "parallel_rays": 2}


# ---- geometric validity on dirty sessions --------------------------------------------------

@pytest.mark.parametrize("method", PAPER_METHODS)
def test_no_output_point_is_behind_or_outside_a_camera_that_made_it(method):
    timing = "typeB" if "shared" in METHODS[method].needs else "typeA"
    dropped_any = False
    for seed in (0, 2):
        rig, obs, _ = dirty_session(timing, seed)
        track = fuse(obs, rig, method)
        # (sync: 13 and 15 since the N-view residual test refuses the outliers' points, 0.46-2.5
        # m off: tests/test_fusion_residual.py)
        assert len(track) > 12
        mask = track.quality["camera_mask"].astype(np.int64)
        assert np.all(mask > 0)
        for c, cam in enumerate(rig.cameras):
            rows = (mask >> c) & 1 == 1
            in_cam = track.position_world[rows] @ cam.R.T + cam.t
            assert np.all(in_cam[:, 2] > 0), (method, cam.name)
            ideal = in_cam[:, :2] / in_cam[:, 2:] * F_PX_PAPER + [319.5, 239.5]
            assert np.all(np.abs(ideal - [320, 240]) < [320 + 160 + 160, 240 + 160 + 160])
        dropped_any |= bool(track.dropped)
    if method == "typeA":  # the outliers of these two sessions make invalid type-A points
        assert dropped_any


F_PX_PAPER = 400.0


# ---- quality: hand-computed ---------------------------------------------------------------

def test_sync_quality_hand_computed_residuals_cameras_and_covariance():
    # the left camera sees the ball on its axis, the right one 60 px to the left: Z = 25/6 m
    rig = rectified_rig()
    Z = F_PX * BASELINE / 60.0
    obs = observations([(0, 0, 320.0, 240.0), (0, 1, 260.0, 240.0)])
    track = fuse(obs, rig, "sync", FusionOptions(noise_px=1.0))
    assert_allclose(track.position_world, [[0.0, 0.0, Z]], atol=1e-12)
    q = {k: v[0] for k, v in track.quality.items()}
    assert q["camera_mask"] == 3 and q["n_detections"] == 2 and q["gap_s"] == 0
    assert q["residual_max_px"] < 1e-9
    # first order, 1 px per axis: Z = f b / d with d = u_L - u_R, X = (u_L - cx) Z / f,
    # Y the mean of the two rays' heights (v_L + v_R - 2 cy) Z / (2 f)
    dz = Z**2 / (F_PX * BASELINE)
    assert_allclose(q["cov_zz_m2"], 2 * dz**2, rtol=1e-4)
    assert_allclose(q["cov_xx_m2"], (Z / F_PX) ** 2, rtol=1e-4)
    assert_allclose(q["cov_yy_m2"], (Z / F_PX) ** 2 / 2, rtol=1e-4)
    assert_allclose(q["cov_xz_m2"], -(Z / F_PX) * dz, rtol=1e-4)
    # uncorrelated (up to the forward differences' truncation)
    assert abs(q["cov_xy_m2"]) < 1e-3 * np.sqrt(q["cov_xx_m2"] * q["cov_yy_m2"])
    assert abs(q["cov_yz_m2"]) < 1e-3 * np.sqrt(q["cov_yy_m2"] * q["cov_zz_m2"])
    assert_allclose(q["std_m"], np.sqrt(2 * dz**2 + 1.5 * (Z / F_PX) ** 2), rtol=1e-4)
    # the covariance scales with the pixel noise squared
    half = fuse(obs, rig, "sync", FusionOptions(noise_px=0.5)).quality["cov_zz_m2"][0]
    assert_allclose(half, q["cov_zz_m2"] / 4, rtol=1e-9)
    # 4 px of vertical disagreement: each detection is 2 px from the midpoint's image
    obs = observations([(0, 0, 340.0, 238.0), (0, 1, 320.0, 242.0)])
    q = fuse(obs, rig, "sync").quality
    assert_allclose(q["residual_max_px"], 2.0, rtol=0.03)
    assert_allclose(q["residual_mean_px"], 2.0, rtol=0.03)
    assert_allclose(q["ray_miss_m"], 4 * 12.5 / F_PX / 2, rtol=0.03)  # RMS ray distance


def test_type_a_miss_is_measured_before_the_snap():
    # the interpolated left point (110, 220) is 5 px off the epipolar row 215 of the right
    # detection (90, 215): before the snap the rays miss by about 5 px at Z = 12.5 m; exactly,
    # |b · (d_L x d_R)| / |d_L x d_R| with d = ((u - cx) / f, (v - cy) / f, 1)
    rig = rectified_rig(offsets=(0.0, 1 / 60))
    obs = observations([(0, 0, 100.0, 200.0), (10, 1, 90.0, 215.0), (30, 0, 130.0, 260.0)])
    p = pseudo_stereo_points(prepare(obs, rig), np.array([1]), np.array([2]), max_gap_ns=NS)
    assert_allclose(p.snap_px, [5.0], atol=1e-9)
    assert p.miss_m[0] < 1e-12  # after the snap the rays cross by construction
    d_left = np.array([(110.0 - CX) / F_PX, (220.0 - CY) / F_PX, 1.0])
    d_right = np.array([(90.0 - CX) / F_PX, (215.0 - CY) / F_PX, 1.0])
    normal = np.cross(d_left, d_right)
    miss = abs(np.dot([BASELINE, 0, 0], normal)) / np.linalg.norm(normal)
    assert_allclose(miss, 5.0 * 12.5 / F_PX, rtol=0.04)
    assert_allclose(p.miss_unsnapped_m, [miss], rtol=1e-9)
    # the crossing of the unsnapped rays is about halfway: ~2.5 px from each image point
    assert_allclose(p.residual_obs_px, [2.5], rtol=0.05)
    assert_allclose(p.residual_partner_px, [2.5], rtol=0.05)
    assert p.flags[0] == 0 and p.valid[0]


def test_type_a_quality_columns_agree_with_its_construction():
    # with noise the two past points differ: the track's snap is their larger snap and its
    # ray angle their smaller angle; the miss is before the snap; the newest detection's
    # residual is the prediction's miss of it in pixels
    rig = distorted(apply_timing(builtin_rig("paper3"), "typeA"))
    detections, _ = simulate(rig, get_motion("spiral"), options=SimulationOptions(
        noise_px=1.0, seed=3))
    obs = detections.best()
    track = fuse(obs, rig, "typeA")
    c = explain_type_a(obs, rig)
    p1, p2 = c.past
    assert_array_equal(track.time_ns, obs.time_ns[c.event_row])
    q = track.quality
    assert np.any(p1.snap_px != p2.snap_px) and np.any(p1.angle_rad != p2.angle_rad)
    assert_array_equal(q["snap_px"], np.maximum(p1.snap_px, p2.snap_px))
    assert_array_equal(q["ray_angle_deg"], np.degrees(np.minimum(p1.angle_rad, p2.angle_rad)))
    assert_array_equal(q["ray_miss_m"], np.maximum(p1.miss_unsnapped_m, p2.miss_unsnapped_m))
    assert np.median(q["ray_miss_m"]) > 1e-4  # ~1 px of disagreement, not ~1e-15 m
    assert np.all(q["residual_max_px"] >= q["residual_mean_px"])
    assert 0.3 < np.median(q["residual_mean_px"]) < 3
    assert np.all(q["n_detections"] >= 4) and np.all(q["n_detections"] <= 7)
    assert np.all(q["gap_s"] <= default_max_gap_s(rig) + 1e-12)
    assert np.all(q["span_s"] >= q["gap_s"] - 1e-12)


@pytest.mark.parametrize("method", PAPER_METHODS)
def test_analytic_covariance_equals_differences_through_the_whole_construction(method,
                                                                                 monkeypatch):
    # the analytic Jacobians (least-squares point, viewing direction, snap, eqs. (2) and (4))
    # against forward differences of each method's whole construction, under a strong lens
    from pslog.fusion import _prepare

    timing = "typeB" if "shared" in METHODS[method].needs else "typeA"
    rig = distorted(apply_timing(builtin_rig("paper3"), timing))
    detections, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(
        noise_px=0.5, miss_rate=0.2, seed=1))
    analytic = fuse(detections, rig, method)
    monkeypatch.setattr(_prepare, "FINITE_DIFFERENCES", True)
    reference = fuse(detections, rig, method)
    assert len(analytic) > 20
    assert_array_equal(analytic.position_world, reference.position_world)
    scale = reference.quality["std_m"] ** 2
    for key in ("cov_xx_m2", "cov_yy_m2", "cov_zz_m2", "cov_xy_m2", "cov_xz_m2", "cov_yz_m2"):
        assert np.all(np.abs(analytic.quality[key] - reference.quality[key]) < 1e-5 * scale), key


@pytest.mark.parametrize("timing,method", [("sync", "sync"), ("typeA", "typeA"),
                                           ("typeB", "typeB"), ("typeB", "linear")])
def test_covariance_is_calibrated_against_the_truth(timing, method):
    # 1 px noise (the assumed noise_px): the share of truth inside the 2σ ellipsoid is close
    # to P(χ²₃ <= 4) = 0.739; the motion model's own error (not in the covariance) shows in
    # typeB and linear as a few points less
    rig = distorted(apply_timing(builtin_rig("paper3"), timing))
    inside, nees = [], []
    for seed in range(3):
        detections, truth = simulate(rig, get_motion("spiral"), options=SimulationOptions(
            noise_px=1.0, seed=seed))
        s = summarise_quality(fuse(detections, rig, method, FusionOptions(noise_px=1.0)), truth)
        inside.append(s.within_2sigma)
        nees.append(s.nees)
    assert abs(np.mean(inside) - CHI2_3D_2SIGMA) < 0.1, inside
    assert 0.7 < np.mean(nees) < 1.4, nees


def test_smooth_gives_its_full_covariance_and_it_is_calibrated():
    # its own noise estimate, so no noise_px; the spline's covariance through the basis
    rig = distorted(apply_timing(builtin_rig("paper3"), "typeA"))
    inside = []
    for seed in range(3):
        motion, _ = rally(6.0, seed=seed)  # kicks and bounces, ~450 points each
        detections, truth = simulate(rig, motion, 6.0, SimulationOptions(noise_px=1.0,
                                                                         seed=seed))
        track = fuse(detections, rig, "smooth")
        q = track.quality
        assert_allclose(q["cov_xx_m2"], q["std_x_m"] ** 2, rtol=1e-12)
        assert_allclose(q["cov_zz_m2"] + q["cov_yy_m2"] + q["cov_xx_m2"], q["std_m"] ** 2,
                        rtol=1e-12)
        assert np.any(np.abs(q["cov_xy_m2"]) > 0.1 * q["std_x_m"] * q["std_y_m"])  # full
        inside.append(summarise_quality(track, truth).within_2sigma)
    assert abs(np.mean(inside) - CHI2_3D_2SIGMA) < 0.06, inside


def test_quality_columns_survive_the_fused_mcap_and_eval_reports_them(tmp_path, cli):
    from pslog.log import read_session

    session = tmp_path / "s.mcap"
    assert cli("simulate", "--rig", "paper3", "--timing", "typeB", "--noise", "0.5",
               "-o", session)[0] == 0
    fused = tmp_path / "f.mcap"
    code, out, err = cli("fuse", session, "-o", fused)
    assert code == 0, err
    s = read_session(session)
    expected = {m: fuse(s.detections, s.rig, m) for m in ("typeA", "typeB", "sync")}
    tracks = read_session(fused).tracks
    for method, track in expected.items():
        back = tracks[method]
        assert_array_equal(back.time_ns, track.time_ns)
        for key in ("residual_max_px", "camera_mask", "gap_s", "std_m", "cov_xz_m2"):
            assert_array_equal(back.quality[key], track.quality[key], err_msg=key)
    code, out, err = cli("eval", fused, "--json")
    assert code == 0, err
    report = {r["method"]: r["quality"] for r in json.loads(out)}
    for method in expected:
        assert 0.4 < report[method]["within_2sigma"] < 0.95, report[method]
        assert report[method]["residual_median_px"] > 0
    assert report["smooth"]["within_2sigma"] > 0.4  # from its full covariance
    code, out, _ = cli("eval", fused)
    assert code == 0 and "in 2σ" in out and "NEES" in out
    # the assumed pixel noise scales every standard deviation of sync (nearest's and typeA's
    # take the noise the session's detections show: tests/test_type_a_noise.py)
    code, _, err = cli("fuse", session, "--method", "sync", "--noise-px", "1.0",
                       "-o", tmp_path / "f1.mcap")
    assert code == 0, err
    assert_allclose(read_session(tmp_path / "f1.mcap").tracks["sync"].quality["std_m"],
                    2 * tracks["sync"].quality["std_m"], rtol=1e-12)


# ---- streaming: never raises, equals batch exactly on dirty sessions -----------------------

@pytest.mark.parametrize("method", causal_methods())
def test_stream_equals_batch_exactly_with_misses_drops_outliers_and_a_lens(method):
    timing = "typeB" if "shared" in METHODS[method].needs else "typeA"
    for seed in (0, 1):
        rig, obs, _ = dirty_session(timing, seed)
        batch = fuse(obs, rig, method)
        parts = streamed(rig, method, obs)
        assert len(batch) > 12  # (sync: the outliers' points refused, as above)
        assert_array_equal(np.concatenate([p.time_ns for p in parts]), batch.time_ns)
        assert_array_equal(np.concatenate([p.camera for p in parts]), batch.camera)
        assert_array_equal(np.concatenate([p.position_world for p in parts]),
                           batch.position_world)
        for key, column in batch.quality.items():
            assert_array_equal(np.concatenate([p.quality[key] for p in parts]), column,
                               err_msg=key)


@pytest.mark.parametrize("method", ["sync", "typeB", "linear"])
def test_stream_flush_is_no_error_when_a_synchronised_camera_lost_the_ball(method):
    rig = apply_timing(builtin_rig("paper3"), "typeB")
    detections, _ = simulate(rig, get_motion("throw"), options=SimulationOptions(
        noise_px=0.3, seed=1))
    obs = detections.best()
    # camera 3 (synchronised with camera 1) loses the ball for the last 0.5 s
    keep = ~((obs.camera == 2) & (obs.time_ns > 1.0 * NS))
    obs = obs.select(keep)
    batch = fuse(obs, rig, method)
    parts = streamed(rig, method, obs)
    assert_array_equal(np.concatenate([p.time_ns for p in parts]), batch.time_ns)
    fuser = StreamFuser(rig, method)  # only the lone camera: nothing, and no error
    lone = obs.select(obs.camera == 1)
    for i in range(len(lone)):
        assert len(fuser.push(lone.time_ns[i], 1, lone.uv[i])) == 0
    assert len(fuser.flush()) == 0


# ---- tests that catch a wrong equation, under lens distortion -------------------------------

@pytest.mark.parametrize("motion,bound_mm", [("straight", 0.13), ("spiral", 1.3),
                                             ("fall", 1.4), ("throw", 1.5)])
def test_type_a_under_lens_distortion_is_accurate_to_a_tight_bound(motion, bound_mm):
    # eq. (1) and the snap are exact only on undistorted pixels: run on the recorded
    # (distorted) ones, the lens' 17 % bends every interpolation (bounds: 1.15 x the errors
    # of the equations as published)
    rig = distorted(apply_timing(builtin_rig("paper3"), "typeA"))
    detections, truth = simulate(rig, get_motion(motion))
    accuracy = evaluate(fuse(detections, rig, "typeA"), truth)
    assert accuracy.mean_mm < bound_mm, accuracy
    # (the throw's bounce: the kink test refuses the 3 points whose intervals hold it)
    assert accuracy.rate_hz == pytest.approx(90, rel=0.04 if motion == "throw" else 0.02)


def test_eq4_moves_an_off_ray_prediction_to_the_foot_on_the_newest_ray():
    # on a curved motion the linear prediction misses the newest viewing ray by millimetres;
    # eq. (4) puts the point at the foot of the perpendicular, on the ray
    rig = distorted(apply_timing(builtin_rig("paper3"), "typeA"))
    detections, truth = simulate(rig, get_motion("spiral"))
    obs = detections.best()
    c = explain_type_a(obs, rig)
    track = fuse(obs, rig, "typeA")
    shift = np.linalg.norm(c.predicted_world - c.points_world, axis=1)
    assert np.median(shift) > 5e-4  # the prediction is off the ray by > 0.5 mm
    assert_allclose(track.quality["ray_shift_m"], shift, rtol=1e-12)
    for i, cam in enumerate(rig.cameras):
        rows = obs.camera[c.event_row] == i
        origin, direction = cam.rays(obs.uv[c.event_row[rows]])
        offset = track.position_world[rows] - origin
        assert_allclose(np.linalg.norm(np.cross(offset, direction), axis=1), 0, atol=1e-9)
        foot = c.predicted_world[rows] - track.position_world[rows]
        assert_allclose(np.einsum("ij,ij->i", foot, direction), 0, atol=1e-9)
    # and being on the ray is what makes type A better than its prediction
    err_point = np.linalg.norm(c.points_world - truth.at(obs.time_ns[c.event_row]), axis=1)
    err_pred = np.linalg.norm(c.predicted_world - truth.at(obs.time_ns[c.event_row]), axis=1)
    assert err_point.mean() < 0.6 * err_pred.mean()  # 1.14 mm against 2.20 mm


def test_type_a_eq1_interpolates_undistorted_pixels_under_a_lens():
    rig = distorted(apply_timing(builtin_rig("paper3"), "typeA"))
    detections, _ = simulate(rig, get_motion("throw"))
    obs = detections.best()
    c = explain_type_a(obs, rig)
    for p in c.past:
        for cam_index, cam in enumerate(rig.cameras):
            rows = p.partner == cam_index
            prev = cam.undistort(obs.uv[p.prev_row[rows]])
            nxt = cam.undistort(obs.uv[p.next_row[rows]])
            w = p.weight[rows, None]
            assert_allclose(p.uv_interpolated[rows], (1 - w) * prev + w * nxt, atol=1e-9)


def test_type_b_and_linear_under_a_lens_tight():
    rig = distorted(apply_timing(builtin_rig("paper3"), "typeB"))
    # noise-free stereo is exact; the predictions' errors are the motion's curvature (bounds:
    # 1.15 x the errors of the equations as published)
    for motion, bounds in (("straight", (1e-6, 1e-6)), ("spiral", (2.1, 3.3)),
                           ("fall", (1.05, 2.2))):
        detections, truth = simulate(rig, get_motion(motion))
        for method, bound in zip(("typeB", "linear"), bounds, strict=True):
            accuracy = evaluate(fuse(detections, rig, method), truth)
            assert accuracy.mean_mm < bound, (motion, method, accuracy)


def test_the_default_max_gap_bridges_three_and_a_half_frames_not_more():
    # 3.5 frame periods of the slowest camera: with camera 2 missing four frames, camera 1's
    # detections 2.5 periods after camera 2's latest are paired with it, 4.5 periods not
    rig = apply_timing(builtin_rig("paper2"), "typeA")  # camera 2 half a period after 1
    assert default_max_gap_s(rig) == pytest.approx(3.5 / 30)
    detections, _ = simulate(rig, get_motion("straight"))
    obs = detections.best()
    cut = obs.select(~((obs.camera == 1) & (obs.frame_index >= 10) & (obs.frame_index < 14)))
    track = fuse(cut, rig, "nearest")
    at = cut.time_ns[cut.camera == 0]
    frame = cut.frame_index[cut.camera == 0]
    assert at[frame == 12][0] in track.time_ns  # 2.5 periods after camera 2's frame 9
    assert at[frame == 14][0] not in track.time_ns  # 4.5 periods
    assert at[frame == 15][0] in track.time_ns  # camera 2's frame 14 is back


def test_fuse_prints_the_invalid_points_it_dropped(tmp_path, cli):
    from pslog.log import SessionWriter, read_session
    from pslog.records import Detections

    # a sync session of the rectified pair: one good instant, one behind both cameras
    rig = rectified_rig()
    obs = observations([(0, 0, 300.0, 240.0), (0, 1, 320.0, 240.0),
                        (40, 0, 340.0, 240.0), (40, 1, 320.0, 240.0),
                        (80, 0, 341.0, 240.0), (80, 1, 320.0, 240.0)])
    obs = Observations(obs.time_ns + NS, obs.camera, obs.uv, obs.time_ns // 33_000_000)
    session = tmp_path / "s.mcap"
    with SessionWriter(session, rig) as writer:
        writer.add_detections(Detections.from_observations(rig.names, obs))
    # without gating (which rejects the negative-disparity candidates first) the method
    # meets them and drops its invalid point
    code, out, err = cli("fuse", session, "--method", "sync", "--gating", "off",
                         "-o", tmp_path / "f.mcap")
    assert code == 0, err
    assert "sync           2 points (left out, untrustworthy: behind_camera 1)" in out
    assert len(read_session(tmp_path / "f.mcap").tracks["sync"]) == 2
    # the count is kept in the fused file: eval reports it (no truth here: quality only)
    code, out, err = cli("eval", tmp_path / "f.mcap")
    assert code == 0, err
    assert "sync      behind_camera 1" in out
    code, out, err = cli("eval", tmp_path / "f.mcap", "--json")
    assert json.loads(out)[0]["left_out"] == {"behind_camera": 1}


def test_without_a_pixel_noise_no_covariance_and_the_same_points():
    from pslog import FusionError

    rig = apply_timing(builtin_rig("paper3"), "typeB")
    detections, _ = simulate(rig, get_motion("spiral"), options=SimulationOptions(noise_px=0.5))
    for method in PAPER_METHODS:
        full = fuse(detections, rig, method)
        bare = fuse(detections, rig, method, FusionOptions(noise_px=None))
        assert_array_equal(bare.position_world, full.position_world)
        assert "std_m" in full.quality and "std_m" not in bare.quality
        assert not any(k.startswith("cov_") for k in bare.quality)
        assert_array_equal(bare.quality["residual_max_px"], full.quality["residual_max_px"])
    with pytest.raises(FusionError, match="pixel noise"):
        FusionOptions(noise_px=-1.0)


def test_detections_without_a_ray_are_no_invalid_points():
    # a pixel no ray goes through (NaN) is a missing detection, not a near-parallel pair
    rig = apply_timing(builtin_rig("paper3"), "typeB")
    obs = simulate(rig, get_motion("spiral"))[0].best()
    broken = Observations(obs.time_ns, obs.camera, np.full_like(obs.uv, np.nan),
                          obs.frame_index)
    for method in ("nearest", "typeA"):
        track = fuse(broken, rig, method)
        assert len(track) == 0 and track.dropped == {}, (method, track.dropped)


# ---- the column forms of the fast kernels give the bits of the row-wise forms they replace

def _rows_triangulate(origins, directions, valid):
    """triangulate_rays as first written: (n, m, 3, 3) projectors and einsum."""
    valid = valid & np.all(np.isfinite(directions), axis=2) & np.all(np.isfinite(origins), axis=2)
    norms = np.linalg.norm(directions, axis=2, keepdims=True)
    valid = valid & (norms[..., 0] > 0)
    unit = np.where(valid[..., None], directions / np.where(norms > 0, norms, 1.0), 0.0)
    origins0 = np.where(valid[..., None], origins, 0.0)
    projector = (np.eye(3) - unit[..., :, None] * unit[..., None, :]) * valid[..., None, None]
    A = projector.sum(axis=1)
    rhs = np.einsum("nmij,nmj->ni", projector, origins0)
    n_rays = valid.sum(axis=1)
    ok = (n_rays >= 2) & (np.abs(np.linalg.det(A)) > 1e-12)
    points = np.full((len(A), 3), np.nan)
    points[ok] = np.linalg.solve(A[ok], rhs[ok][..., None])[..., 0]
    offsets = points[:, None, :] - origins0
    perp = offsets - np.einsum("nmi,nmi->nm", offsets, unit)[..., None] * unit
    sq = np.where(valid, np.einsum("nmi,nmi->nm", perp, perp), 0.0)
    return points, np.sqrt(sq.sum(axis=1) / n_rays), n_rays


@pytest.mark.parametrize("m", [2, 3, 4, 9])
def test_column_geometry_equals_the_row_wise_forms_bit_for_bit(m):
    from pslog.geometry import (
        closest_points_on_rays,
        epipolar_lines,
        epipolar_lines_cols,
        ray_angles,
        triangulate_rays,
    )

    rng = np.random.default_rng(m)
    n = 500  # (more than the few points that take the row-wise forms anyway)
    origins = rng.normal(size=(n, m, 3)) * 3
    directions = rng.normal(size=(n, m, 3)) * rng.uniform(0.5, 2, (n, m, 1))
    directions[rng.random((n, m)) < 0.05] = np.nan
    directions[rng.random((n, m)) < 0.03] = 0.0
    valid = rng.random((n, m)) < 0.8
    with np.errstate(all="ignore"):
        for got, want in zip(triangulate_rays(origins, directions, valid),
                             _rows_triangulate(origins, directions, valid), strict=True):
            assert_array_equal(got, want)
        unit = directions / np.linalg.norm(directions, axis=2, keepdims=True)
        cos = np.abs(np.einsum("nai,nbi->nab", unit, unit))
        ok = valid & np.all(np.isfinite(directions), axis=2) & np.any(directions != 0, axis=2)
        pair = ok[:, :, None] & ok[:, None, :] & ~np.eye(m, dtype=bool)
        smallest = np.where(pair, cos, np.inf).min(axis=(1, 2))
        want = np.where(np.isfinite(smallest), np.arccos(np.clip(smallest, 0, 1)), np.nan)
        assert_array_equal(ray_angles(directions, valid), want)
        a, b = directions[:, 0], directions[:, 1]
        oa, ob = origins[:, 0], origins[:, 1]
        points, miss, s, k = crossing_of_rays(oa, a, ob, b)
        w0 = oa - ob
        aa, bb, cc = (np.einsum("ij,ij->i", x, y) for x, y in ((a, a), (a, b), (b, b)))
        d, e = np.einsum("ij,ij->i", a, w0), np.einsum("ij,ij->i", b, w0)
        denom = aa * cc - bb * bb
        par = denom <= 1e-12 * aa * cc
        s_want = np.where(par, np.nan, (bb * e - cc * d) / denom)
        k_want = np.where(par, np.nan, (aa * e - bb * d) / denom)
        foot_a, foot_b = oa + s_want[:, None] * a, ob + k_want[:, None] * b
        assert_array_equal(s, s_want)
        assert_array_equal(k, k_want)
        assert_array_equal(points, 0.5 * (foot_a + foot_b))
        assert_array_equal(miss, np.linalg.norm(foot_a - foot_b, axis=1))
        target = w0 + oa
        t = np.einsum("ij,ij->i", target - oa, a) / np.einsum("ij,ij->i", a, a)
        assert_array_equal(closest_points_on_rays(oa, a, target), t[:, None] * a + oa)
        F = rng.normal(size=(n, 3, 3))
        uv = rng.uniform(0, 640, (n, 2))
        assert_array_equal(epipolar_lines_cols(F.reshape(n, 9).T.copy(), uv),
                           epipolar_lines(F, uv))


def test_column_rays_and_reprojection_equal_the_camera_model_bit_for_bit():
    from pslog.fusion._prepare import reprojection_px

    rig, obs, _ = dirty_session("typeA", seed=3)
    prep = prepare(obs, rig)
    cam = prep.obs.camera
    uv = prep.uv_undistorted
    homogeneous = np.hstack([uv, np.ones((len(uv), 1))])
    rays = np.einsum("nji,nj->ni", prep.R[cam],
                     np.einsum("nij,nj->ni", prep.K_inv[cam], homogeneous))
    with np.errstate(invalid="ignore"):
        assert_array_equal(prep.rays_from_undistorted(cam, uv),
                           rays / np.linalg.norm(rays, axis=1, keepdims=True))
    rng = np.random.default_rng(0)
    points = rng.normal([0, 0, 1], 2, (len(obs), 3))
    got = reprojection_px(prep, points, cam, uv)
    for c, camera in enumerate(rig.cameras):
        rows = cam == c
        with np.errstate(invalid="ignore", over="ignore"):
            projected, in_front = camera.project(points[rows])
            want = np.where(in_front, np.linalg.norm(projected - camera.distort(uv[rows]),
                                                     axis=1), np.nan)
        assert_array_equal(got[rows], want)


def test_covariance_adds_a_detections_slots_and_maps_its_pixel_noise():
    # the six-entry assembly against the plain sum over detections of (J L)(J L)ᵀ
    from pslog.fusion._prepare import covariance

    rng = np.random.default_rng(1)
    k, n_slots = 40, 4
    rows = rng.integers(-1, 3, (k, n_slots))  # repeats: one detection in several slots
    J = [rng.normal(size=(3, 2, k)) for _ in range(n_slots)]
    L = [rng.normal(size=(2, 2, k)) for _ in range(n_slots)]
    got = covariance(rows, J, L, 0.5)
    for p in range(k):
        want = np.zeros((3, 3))
        for det in set(rows[p][rows[p] >= 0].tolist()):
            slots = np.flatnonzero(rows[p] == det)
            JL = sum(J[s][:, :, p] for s in slots) @ L[slots[0]][:, :, p]
            want += JL @ JL.T * 0.25
        for name, (i, j) in (("xx", (0, 0)), ("yy", (1, 1)), ("zz", (2, 2)), ("xy", (0, 1)),
                             ("xz", (0, 2)), ("yz", (1, 2))):
            assert_allclose(got[f"cov_{name}_m2"][p], want[i, j], rtol=1e-12, atol=1e-15)
        assert_allclose(got["std_m"][p], np.sqrt(np.trace(want)), rtol=1e-12)


@pytest.mark.parametrize("seed", [0, 3])
def test_type_a_refuses_a_prediction_the_newest_detection_contradicts(seed):
    """paper3's throw with cam3 blind for 0.5 s from 0.675 s (bench_dirty's blackout): with
    two cameras, type A bridges the throw's bounce with one long gap and eq. (2)'s linear
    prediction crosses the change of motion; eq. (4) put the points at 0.867 and 0.900 s
    9-27 cm off along the newest ray. The newest detection lies 9-27 px from the prediction,
    far beyond the 5 sigma of the detection noise plus gravity's extrapolation error: such a
    point is refused and counted (``prediction_failed``). The clean throw loses none."""
    from pslog.evaluation import errors_m
    from pslog.simulation import simulate_labelled

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion = get_motion("throw")
    det, truth, _ = simulate_labelled(rig, motion, None, SimulationOptions(
        noise_px=0.3, seed=seed, blackouts=(("cam3", 0.675, 0.5),)))
    track = fuse(det, rig, "typeA")
    assert np.nanmax(errors_m(track, truth)) < 0.03
    assert 1 <= track.dropped.get("prediction_failed", 0) <= 3
    clean, truth, _ = simulate_labelled(rig, motion, None, SimulationOptions(noise_px=0.3,
                                                                              seed=seed))
    track = fuse(clean, rig, "typeA")
    assert "prediction_failed" not in track.dropped
    assert np.nanmax(errors_m(track, truth)) < 0.05


def test_type_a_refuses_a_point_whose_partner_interval_holds_a_kick():
    """bench_dirty's paper3 rally 0 at 0.3 px with its faults (cam2 blind 2.1-2.6 s): at
    2.42 s only cam1 and cam3 see the ball, a kick falls inside the partner's eq. (1)
    interval, and the interpolated point lies off the ball along the epipolar line, where
    neither the snap nor the innovation test sees it: the point came out 71 mm off. The
    partner's own 2D track bends there far beyond what gravity and 5 sigma of the detection
    noise allow (innovation.kinked_points): the point is refused and counted (``kink``), and
    the faults add no point beyond 5 cm to those of the clean session (at kicks the kink
    test cannot yet see causally)."""
    import sys
    from pathlib import Path

    from pslog.evaluation import errors_m
    from pslog.fusion.gating import fuse_detections
    from pslog.simulation import simulate_labelled

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_dirty import faults

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion = rally(8.0, seed=100, speed=4.0, kick_every_s=0.9)[0]
    beyond, refused = {}, {}
    for kind, extra in (("clean", {}), ("faults", faults(rig, 0, 8.0))):
        det, truth, _ = simulate_labelled(rig, motion, 8.0,
                                          SimulationOptions(noise_px=0.3, seed=0, **extra))
        track = fuse_detections(det, rig, ["typeA"], FusionOptions())[0]["typeA"]
        err = errors_m(track, truth)
        beyond[kind] = set(track.time_ns[err > 0.05].tolist())
        refused[kind] = (track.dropped.get("kink", 0), len(track))
    assert [t for t in beyond["faults"] if abs(t / NS - 2.42) < 0.02] == []
    assert beyond["faults"] <= beyond["clean"]
    for kink, kept in refused.values():
        assert 0 < kink < 0.07 * kept
