"""Issue 10, session 24: no N-view point its own detections contradict, and the shared-instant
methods' tests at the detector's real noise.

- ``sync`` (and the stereo points of ``typeB`` / ``linear``) triangulated whatever the gate
  kept at a common instant: a second orange object chosen in one camera, paired with the
  ball in another 0.5 ms away, made a point 638 mm off with a 70 px residual (session 23's
  webcams). The N-view residual test (``stereo.residual_refused``: the reprojection
  residuals against the noise, χ² of ``2n - 3`` degrees of freedom at type A's level) drops
  it and counts it (``residual_failed``).
- ``typeB`` / ``linear`` applied type A's innovation test at ``max(0.5 px, noise_px)``, the
  stated noise: at 2 px of real noise it refused good points in numbers. They (and the
  residual test) now take the detector's noise the session shows (``stereo.refusal_noise``,
  ``nearest``'s estimator), the stated one a floor.
"""

from __future__ import annotations

import numpy as np
import pytest

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions, fuse
from pslog.fusion._prepare import prepare
from pslog.fusion.stereo import RESIDUAL_FAILED, refusal_noise
from pslog.geometry import epipolar_lines, fundamental_matrices
from pslog.records import Observations
from pslog.timing import observations as timed_observations


def _session(rig_name: str, timing: str, motion: str, noise_px: float, seed: int,
             duration: float | None = None):
    rig = apply_timing(builtin_rig(rig_name), timing)
    detections, truth = simulate(rig, get_motion(motion), duration,
                                 SimulationOptions(noise_px=noise_px, seed=seed))
    return rig, timed_observations(detections, rig), truth


def _moved(obs: Observations, rows: np.ndarray, shift_px) -> Observations:
    uv = obs.uv.copy()
    uv[rows] += np.asarray(shift_px, dtype=np.float64)
    return Observations(obs.time_ns, obs.camera, uv, obs.frame_index)


def _across(rig, obs: Observations, rows: np.ndarray, partner: int, px: float) -> np.ndarray:
    """Shifts (k, 2) of ``px`` pixels moving each detection ``rows`` (one camera; the paper
    rigs have no lens distortion) across the epipolar line of camera ``partner``'s
    detection at the same instant: what two views can see."""
    cam = int(obs.camera[rows[0]])
    F = fundamental_matrices(rig.cameras)[partner, cam]
    other = np.flatnonzero(obs.camera == partner)
    at = other[np.searchsorted(obs.time_ns[other], obs.time_ns[rows])]
    assert np.array_equal(obs.time_ns[at], obs.time_ns[rows])
    lines = epipolar_lines(F, obs.uv[at])
    normal = lines[:, :2] / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)
    return px * normal


@pytest.mark.parametrize("rig_name", ["paper3", "paper2"])
def test_sync_drops_a_point_whose_detections_disagree(rig_name):
    """One camera's detection at a few instants replaced by another object's, 70 px off
    across the epipolar lines (a second orange object the gate kept): each such instant's
    point was decimetres to metres off with every ray parameter positive; now dropped and
    counted, every other point the same."""
    rig, obs, truth = _session(rig_name, "sync", "throw", 0.3, 4)
    clean = fuse(obs, rig, "sync")
    assert RESIDUAL_FAILED not in clean.dropped, clean.dropped  # nothing good refused
    assert errors_m(clean, truth).max() < 0.02
    cam1 = np.flatnonzero(obs.camera == 1)
    bad = cam1[len(cam1) // 3: 2 * len(cam1) // 3: 5]
    moved = _moved(obs, bad, _across(rig, obs, bad, 0, 70.0))
    track = fuse(moved, rig, "sync")
    assert track.dropped.get(RESIDUAL_FAILED) == len(bad), track.dropped
    assert not np.isin(track.time_ns, obs.time_ns[bad]).any()
    assert len(track) == len(clean) - len(bad)
    kept = ~np.isin(clean.time_ns, obs.time_ns[bad])
    np.testing.assert_array_equal(track.position_world, clean.position_world[kept])
    # what the points were: far off (the test's reason), whatever the quality said
    off = fuse(moved, rig, "nearest")  # (no residual test: the same rays at those instants)
    at = np.isin(off.time_ns, obs.time_ns[bad]) & (off.camera == 1)
    assert errors_m(off, truth)[at].min() > 0.1


def test_type_b_does_not_predict_from_a_stereo_point_its_detections_contradict():
    """typeB's prediction from a stereo point one camera's wrong detection made: the stereo
    point and the points predicted from it were off; the stereo point is now refused, and
    the lone detections after it predicted from the stereo points before it."""
    rig, obs, truth = _session("paper3", "typeB", "throw", 0.3, 4)
    clean = {m: fuse(obs, rig, m) for m in ("typeB", "linear")}
    stereo = np.flatnonzero(obs.camera == 0)  # cam1 and cam3 share the instants
    bad = stereo[len(stereo) // 3: 2 * len(stereo) // 3: 7]
    moved = _moved(obs, bad, _across(rig, obs, bad, 2, 70.0))
    for method in ("typeB", "linear"):
        track = fuse(moved, rig, method)
        assert track.dropped.get(RESIDUAL_FAILED) == len(bad), track.dropped
        assert errors_m(track, truth).max() < max(0.05, 1.5 * errors_m(clean[method],
                                                                       truth).max())


@pytest.mark.parametrize("real_px", [1.0, 2.0])
def test_the_tests_take_the_detectors_real_noise(real_px):
    """At 1-2 px of real noise and the default stated 0.5 px, the stated noise refused good
    points in numbers (sync's residual test and typeB / linear's prediction test); at the
    noise the detections show they refuse (almost) none, and a detection 150 px off is
    still refused."""
    rig, obs, truth = _session("paper3", "typeB", "rally", real_px, 7, 6.0)
    options = FusionOptions()  # noise_px 0.5, the default
    tracks = {m: fuse(obs, rig, m, options) for m in ("sync", "typeB", "linear")}
    n_stereo = len(tracks["sync"]) + tracks["sync"].dropped.get(RESIDUAL_FAILED, 0)
    # (at most the session's first ~0.1 s, before any camera's fourth detection shows the
    # noise: the stated one there; 2 of 180 at 2 px)
    assert tracks["sync"].dropped.get(RESIDUAL_FAILED, 0) <= 0.015 * n_stereo
    for m in ("typeB", "linear"):
        assert tracks[m].dropped.get("prediction_failed", 0) <= 0.01 * len(tracks[m]), (
            m, tracks[m].dropped)
    lone = np.flatnonzero(obs.camera == 1)  # the middle camera: half a period off
    bad = lone[len(lone) // 2 - 10: len(lone) // 2 + 10: 4]
    moved = _moved(obs, bad, (150.0, 0.0))
    for m in ("typeB", "linear"):
        track = fuse(moved, rig, m, options)
        assert not np.isin(track.time_ns[track.camera == 1], obs.time_ns[bad]).any(), m
    assert errors_m(tracks["typeB"], truth).max() < 0.2
    # the noise they took: the detector's, where a second of detections shows it
    late = obs.time_ns[obs.time_ns > obs.time_ns[0] + 2 * 10**9]
    sigma = refusal_noise(prepare(obs, rig), late, 3.5 / 30, options.noise_px)
    assert np.median(sigma) == pytest.approx(real_px, rel=0.2)


def test_the_first_frames_point_is_tested_at_the_stated_noise():
    """Before any camera's fourth detection nothing shows the noise: the stated one then
    (2 px there, type A's start for its covariance, kept a 2.1 m sync point whose false
    detection lay 2.8 px from the ball's epipolar line). The first instant's detection of
    one camera moved 6 px across the other's epipolar line: refused; unmoved: kept."""
    rig, obs, _ = _session("paper2", "sync", "throw", 0.3, 4)
    clean = fuse(obs, rig, "sync")
    assert clean.time_ns[0] == obs.time_ns[0] and RESIDUAL_FAILED not in clean.dropped
    first = np.flatnonzero((obs.camera == 1) & (obs.time_ns == obs.time_ns[0]))
    track = fuse(_moved(obs, first, _across(rig, obs, first, 0, 6.0)), rig, "sync")
    assert track.dropped.get(RESIDUAL_FAILED) == 1, track.dropped
    assert track.time_ns[0] > obs.time_ns[0]
    np.testing.assert_array_equal(track.position_world, clean.position_world[1:])


@pytest.mark.parametrize("method", ["sync", "typeB", "linear"])
def test_the_stream_takes_the_batchs_noise(method):
    """At 3 px of real noise the tests' σ is the measured one, from the residuals of the
    second before each checkpoint: the stream keeps that history (StreamFuser's reach for
    sync, typeB and linear) and refuses exactly the batch's points."""
    from pslog.fusion.stream import StreamFuser

    rig, obs, _ = _session("paper3", "typeB", "rally", 3.0, 11, 4.0)
    batch = fuse(obs, rig, method)
    fuser = StreamFuser(rig, method)
    parts = [fuser.push(obs.time_ns[i], obs.camera[i], obs.uv[i], obs.frame_index[i])
             for i in range(len(obs))]
    parts.append(fuser.flush())
    np.testing.assert_array_equal(np.concatenate([p.time_ns for p in parts]), batch.time_ns)
    np.testing.assert_array_equal(np.concatenate([p.position_world for p in parts]),
                                  batch.position_world)


def test_each_camera_is_tested_at_its_own_noise():
    """Webcams mix: one camera 3 px noisier than the others (0.3 px). A σ pooled over the
    cameras (their residuals' lower quartile: the quiet cameras') refused 246 of 600 good
    sync points; each camera at its own σ, at the reprojection-weighted intersection, (almost)
    none, and a detection 70 px off is still refused."""
    rig, obs, _ = _session("paper3", "sync", "rally", 0.3, 2, 10.0)
    noisy = obs.camera == 2
    uv = obs.uv.copy()
    uv[noisy] += np.random.default_rng(2).normal(scale=3.0, size=(int(noisy.sum()), 2))
    obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    track = fuse(obs, rig, "sync")
    n = len(track) + track.dropped.get(RESIDUAL_FAILED, 0)
    assert track.dropped.get(RESIDUAL_FAILED, 0) <= 0.01 * n, track.dropped
    late = obs.time_ns[obs.time_ns > obs.time_ns[0] + 2 * 10**9]
    sigma = refusal_noise(prepare(obs, rig), late, 3.5 / 30, 0.5)
    assert np.median(sigma[:, 2]) == pytest.approx(3.0, rel=0.25)
    assert np.median(sigma[:, 0]) == 0.5  # (0.3 px real: the floor)
    cam0 = np.flatnonzero(obs.camera == 0)
    bad = cam0[len(cam0) // 3: 2 * len(cam0) // 3: 9]
    moved = fuse(_moved(obs, bad, _across(rig, obs, bad, 1, 70.0)), rig, "sync")
    assert not np.isin(moved.time_ns, obs.time_ns[bad]).any()


def test_two_views_have_one_degree_of_freedom():
    """Two rays, 4 pixel coordinates, 3 unknowns: d²/σ² is χ² of 2n - 3 = 1 degree of
    freedom, bound √χ²₁ σ = 4.63 σ = 2.31 px at the stated 0.5 px (2 degrees: 2.50 px; 2n = 4:
    3.07 px). A detection moved 3.4 px across the other camera's epipolar line (a residual of
    3.4 / √2 = 2.40 px at the reprojection minimum, the noise ~0): refused; 3.0 px (2.12 px):
    kept."""
    rig, obs, _ = _session("paper2", "sync", "throw", 0.01, 4)
    cam1 = np.flatnonzero(obs.camera == 1)
    at = cam1[len(cam1) // 2: len(cam1) // 2 + 1]
    for px, refused in ((3.4, 1), (3.0, 0)):
        track = fuse(_moved(obs, at, _across(rig, obs, at, 0, px)), rig, "sync")
        assert track.dropped.get(RESIDUAL_FAILED, 0) == refused, (px, track.dropped)


def test_the_tolerance_motion_allowance_keeps_late_shutters():
    """One camera's shutter 8 ms late (tolerance 10 ms) on a fall: each point's
    detections lie 8 ms apart, the image moved up to ~10 px across the epipolar lines in
    between; the allowance √Σ(e_c/σ_c)² explains it (without it 12 of 32 good points were
    refused)."""
    from pslog import Rig

    rig = apply_timing(builtin_rig("paper3"), "sync")
    cams = list(rig.cameras)
    cams[1] = cams[1].replace(offset=0.008)
    rig = Rig(tuple(cams), rig.name)
    detections, _ = simulate(rig, get_motion("fall"), 6.0,
                                 SimulationOptions(noise_px=0.3, seed=3))
    obs = timed_observations(detections, rig)
    track = fuse(obs, rig, "sync", FusionOptions(tolerance_s=0.01))
    assert RESIDUAL_FAILED not in track.dropped, track.dropped
    assert len(track) == 32


def test_a_lone_detection_is_tested_at_its_own_cameras_noise():
    """typeB / linear: the lone detections (paper3's middle camera, half a period off) from a
    camera 2 px noisier than the synchronised pair: tested at that camera's σ, (almost) none
    refused; at one σ pooled over the cameras (the quiet pair's) many were."""
    rig, obs, _ = _session("paper3", "typeB", "rally", 0.3, 5, 8.0)
    noisy = obs.camera == 1
    uv = obs.uv.copy()
    uv[noisy] += np.random.default_rng(5).normal(scale=2.0, size=(int(noisy.sum()), 2))
    obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    for m in ("typeB", "linear"):
        track = fuse(obs, rig, m)
        lone = int(np.count_nonzero(track.camera == 1))
        assert track.dropped.get("prediction_failed", 0) <= 0.02 * lone, (m, track.dropped)
