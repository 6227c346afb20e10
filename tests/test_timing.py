"""Tests of pslog.timing: the timing model, its inverse, corrected observations and the
regularisation of jittery host timestamps."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.errors import InputError, RigError
from pslog.fusion import fuse
from pslog.motion import get_motion
from pslog.records import NS, Detections
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate
from pslog.timing import (
    clock_jacobian,
    logged_times_ns,
    observations,
    regularize_detections,
    regularize_times,
    true_times_ns,
    true_times_s,
)

# logged 2.000000 s, offset 1.5 ms, drift 20 ppm, readout 10 ms, row 240 of 480:
# true = 2 + 0.0015 + 20e-6 * 2 + 0.010 * 240 / 480 = 2.00654 s
HAND = dict(logged_ns=2_000_000_000, v_px=240.0, height=480, clock_offset_s=1.5e-3,
            drift_ppm=20.0, readout_s=10e-3)


def test_model_against_hand_computed_numbers():
    assert true_times_ns(**HAND) == 2_006_540_000
    assert true_times_ns(**HAND).dtype == np.int64
    # each term on its own, by hand
    assert true_times_ns(2 * NS, 240.0, 480, 1.5e-3, 0.0, 0.0) == 2_001_500_000
    assert true_times_ns(2 * NS, 240.0, 480, 0.0, 20.0, 0.0) == 2_000_040_000
    assert true_times_ns(2 * NS, 240.0, 480, 0.0, 0.0, 10e-3) == 2_005_000_000
    assert true_times_ns(2 * NS, 480.0, 480, 0.0, 0.0, 10e-3) == 2_010_000_000
    assert true_times_ns(2 * NS, 0.0, 480, 0.0, 0.0, 10e-3) == 2 * NS  # top row: logged
    s = dict(HAND, logged_s=2.0)
    del s["logged_ns"]
    assert true_times_s(**s) == pytest.approx(2.00654, abs=1e-12)


@pytest.mark.parametrize("change", [
    dict(clock_offset_s=1.6e-3), dict(drift_ppm=21.0), dict(readout_s=11e-3),
    dict(v_px=241.0), dict(height=481), dict(logged_ns=2_000_000_001)])
def test_every_term_counts(change):
    assert true_times_ns(**{**HAND, **change}) != 2_006_540_000


def test_a_global_shutter_needs_no_row_and_a_rolling_one_refuses_a_missing_row():
    assert true_times_ns(NS, np.nan, 480, 1e-3, 0.0, 0.0) == NS + 1_000_000
    with pytest.raises(InputError, match="non-finite row"):
        true_times_ns(NS, np.nan, 480, 1e-3, 0.0, 0.01)


def test_a_rolling_shutter_row_far_outside_the_image_is_refused_by_batch_and_stream():
    # a finite row of 1e300 px gave a correction beyond int64: a wrong time in batch, an
    # OverflowError traceback from StreamFuser.push (review, session 15); a row a few
    # images away is still a time
    from dataclasses import replace

    from pslog import Rig, apply_timing, builtin_rig
    from pslog.fusion.stream import StreamFuser

    assert true_times_ns(NS, 5000.0, 480, 0.0, 0.0, 0.01) == NS + 104_166_667
    with pytest.raises(InputError, match="row 1e\\+300, far outside the image"):
        true_times_ns(np.array([NS, NS]), np.array([1.0, 1e300]), 480, 0.0, 0.0, 0.01)
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    rig = Rig(tuple(replace(c, readout=0.01) for c in rig.cameras), rig.name)
    for method in ("nearest", "filter"):
        with pytest.raises(InputError, match="far outside the image"):
            StreamFuser(rig, method).push([NS], [0], [[100.0, 1e300]])


def test_model_broadcasts_per_observation_parameters():
    logged = np.array([0, NS, 2 * NS, 3 * NS], dtype=np.int64)
    offset = np.array([0.0, 1e-3, 0.0, -2e-3])
    drift = np.array([0.0, 0.0, 100.0, 0.0])
    readout = np.array([0.0, 0.0, 0.0, 0.03])
    v = np.array([10.0, 10.0, 10.0, 120.0])
    got = true_times_ns(logged, v, 480, offset, drift, readout)
    assert_array_equal(got, [0, NS + 1_000_000, 2 * NS + 200_000,
                             3 * NS - 2_000_000 + 7_500_000])
    assert_allclose(true_times_s(logged / NS, v, 480, offset, drift, readout), got / NS,
                    atol=1e-12)


def test_derivatives_are_the_documented_ones():
    logged_s, v, h = np.array([0.5, 120.0]), np.array([100.0, 479.0]), 480
    jac = clock_jacobian(logged_s, v, h)
    assert_allclose(jac, [[1.0, 0.5e-6, 100 / 480], [1.0, 120e-6, 479 / 480]])
    base = np.array([2e-3, 30.0, 0.02])
    for j in range(3):  # against finite differences of the model itself
        step = np.zeros(3)
        step[j] = 1e-3
        diff = (true_times_s(logged_s, v, h, *(base + step))
                - true_times_s(logged_s, v, h, *(base - step))) / 2e-3
        assert_allclose(diff, jac[:, j], rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("drift", [0.0, 37.5, -80.0, 999.0])
def test_inverse_round_trip(drift):
    rng = np.random.default_rng(1)
    true = np.sort(rng.integers(0, 10**13, 2000))  # up to 2.8 hours
    v = rng.uniform(-0.5, 479.5, len(true))
    offset, readout = rng.uniform(-0.02, 0.02, len(true)), 0.025
    logged = logged_times_ns(true, v, 480, offset, drift, readout)
    back = true_times_ns(logged, v, 480, offset, drift, readout)
    # exact, except where a positive drift makes the forward map step over a nanosecond
    assert np.abs(back - true).max() <= (1 if drift > 0 else 0)
    assert np.mean(back == true) > 0.99
    expected = (true / NS - offset - readout * v / 480) / (1 + drift * 1e-6)
    assert_allclose(logged / NS, expected, atol=2e-9)


def test_inverse_of_hand_example():
    assert logged_times_ns(2_006_540_000, 240.0, 480, 1.5e-3, 20.0, 10e-3) == 2 * NS


def _session(timing="typeA", seed=0, noise=0.3, duration=None):
    rig = apply_timing(builtin_rig("paper3"), timing)
    det, truth = simulate(rig, get_motion("spiral"), duration, options=SimulationOptions(
        noise_px=noise, miss_rate=0.1, seed=seed))
    return rig, det, truth


def test_observations_with_zero_clocks_are_best_bit_for_bit():
    rig, det, _ = _session()
    obs, best = observations(det, rig), det.best()
    for name in ("time_ns", "camera", "uv", "frame_index"):
        assert_array_equal(getattr(obs, name), getattr(best, name))
    # and fusion through Detections (which uses observations()) gives the same track
    a, b = fuse(det, rig, "typeA"), fuse(best, rig, "typeA")
    assert_array_equal(a.position_world, b.position_world)
    assert_array_equal(a.time_ns, b.time_ns)


def _with_clocks(rig: Rig, params: dict[str, dict[str, float]]) -> Rig:
    return Rig(tuple(c.replace(**params.get(c.name, {})) for c in rig.cameras), rig.name)


def test_observations_apply_each_cameras_model_and_resort():
    rig, det, _ = _session()
    params = {"cam1": {"readout": 0.02},
              "cam2": {"clock_offset": 0.02, "clock_drift_ppm": 50.0},
              "cam3": {"clock_offset": -0.015, "readout": 0.01}}
    synced = _with_clocks(rig, params)
    obs, best = observations(det, synced), det.best()
    assert len(obs) == len(best)
    assert np.all(np.diff(obs.time_ns) >= 0)
    # every observation found again (by camera and frame) at its model time
    key = obs.camera.astype(np.int64) * 10**9 + obs.frame_index
    order = np.argsort(key)
    best_key = best.camera.astype(np.int64) * 10**9 + best.frame_index
    border = np.argsort(best_key)
    assert_array_equal(key[order], best_key[border])
    cam, time_ns, uv = best.camera[border], best.time_ns[border], best.uv[border]
    heights = np.array([c.height for c in synced.cameras])[cam]
    off = np.array([c.clock_offset for c in synced.cameras])[cam]
    drift = np.array([c.clock_drift_ppm for c in synced.cameras])[cam]
    ro = np.array([c.readout for c in synced.cameras])[cam]
    expected = time_ns / NS + off + drift * 1e-6 * time_ns / NS + ro * uv[:, 1] / heights
    assert_allclose(obs.time_ns[order] / NS, expected, atol=1e-9)
    assert_array_equal(obs.uv[order], uv)
    # cam2's 20 ms offset moved its frames across cam1's: the order really changed
    assert not np.array_equal(obs.camera, best.camera)


def test_observations_resolve_a_same_camera_tie_deterministically():
    rig = builtin_rig("paper2")
    rig = Rig((rig.cameras[0].replace(readout=0.03), rig.cameras[1]), rig.name)
    # two frames of cam1 whose corrected times coincide: the second's row is far above the
    # image (an absurd candidate), pulling it back by exactly the 10 ms between them
    det = Detections.from_frames(rig.names, [0, 10_000_000, 5_000_000], [0, 0, 1],
                                 [0, 1, 0], [0, 1, 2],
                                 [[100.0, 0.0], [100.0, -160.0], [50.0, 50.0]])
    obs = observations(det, rig)
    assert_array_equal(obs.time_ns, [0, 1, 5_000_000])
    assert_array_equal(obs.frame_index, [0, 1, 0])
    assert_array_equal(obs.camera, [0, 0, 1])


def test_observations_refuse_detections_of_other_cameras():
    _, det, _ = _session()
    rig = builtin_rig("paper2")
    rig = Rig((rig.cameras[0], rig.cameras[1].replace(clock_offset=1e-3)))
    with pytest.raises(InputError, match="do not match the rig"):
        observations(det, rig)


def test_first_camera_defines_the_clock():
    rig = builtin_rig("paper3")
    cams = rig.cameras
    with pytest.raises(RigError, match=r"'cam1'.*defines the session clock"):
        Rig((cams[0].replace(clock_offset=0.001), *cams[1:]))
    with pytest.raises(RigError, match=r"'cam1'.*defines the session clock"):
        Rig((cams[0].replace(clock_drift_ppm=3.0), *cams[1:]))
    Rig((cams[0].replace(readout=0.02), cams[1].replace(clock_offset=0.001,
                                                           clock_drift_ppm=-4.0), cams[2]))


# ---- regularisation of host stamps ---------------------------------------------------

def _host_stamps(seed=0, n=900, period=1 / 30.0, jitter=2e-3, start=12.345):
    rng = np.random.default_rng(seed)
    k = np.arange(n, dtype=np.int64)
    keep = rng.random(n) > 0.05  # dropped frames: index gaps
    k = k[keep]
    clean = start + period * k
    stamps = clean + rng.normal(0.0, jitter, len(k))
    outliers = rng.choice(len(k), 12, replace=False)
    stamps[outliers] += rng.choice([-1, 1], 12) * rng.uniform(0.03, 0.2, 12)
    return (np.rint(stamps * NS).astype(np.int64), k, np.rint(clean * NS).astype(np.int64),
            n - len(k))


def test_regularize_recovers_the_line_and_counts_outliers_and_drops():
    stamps, k, clean, n_dropped = _host_stamps()
    shuffled = np.random.default_rng(5).permutation(len(k))  # any order
    fitted, report = regularize_times(stamps[shuffled], k[shuffled])
    err = (fitted - clean[shuffled]) / NS
    assert np.abs(err).max() < 0.4e-3  # jitter 2 ms: the line to well under it
    assert report.period_s == pytest.approx(1 / 30.0, abs=1e-6)
    assert report.start_s == pytest.approx(12.345, abs=0.5e-3)
    assert report.jitter_s == pytest.approx(2e-3, rel=0.1)
    assert report.n_outliers == 12
    assert report.n_dropped == n_dropped > 0
    assert report.n_frames == len(k)


def test_regularize_reports_the_lines_covariance_hand_computed():
    # six frames 7..12 whose stamps sit off the line start + period·(k - 7) by
    # [1, 0, -1, -1, 0, 1]·100 µs: those residuals are orthogonal to [1, k] (and the median
    # slope is the period), so the fitted line is that line, the median |residual| 100 µs
    # (jitter 148.26 µs), and with X = [1, k - 7]: (XᵀX)⁻¹ = [[55, -15], [-15, 6]] / 105
    k = np.arange(7, 13, dtype=np.int64)
    line = 2 * NS + (k - 7) * 33_333_333
    fitted, report = regularize_times(line + np.array([1, 0, -1, -1, 0, 1]) * 100_000, k)
    assert np.abs(fitted - line).max() <= 1
    jitter = 1.4826 * 100e-6
    assert report.jitter_s == pytest.approx(jitter, rel=1e-6)
    assert report.first_index == 7 and report.n_outliers == 0
    assert report.covariance == pytest.approx(
        (55 / 105 * jitter**2, -15 / 105 * jitter**2, 6 / 105 * jitter**2), rel=1e-6)


def test_regularize_exact_stamps_are_kept_and_report_no_jitter():
    k = np.arange(100, dtype=np.int64) + 7
    stamps = 5 * NS + k * 33_333_333
    fitted, report = regularize_times(stamps, k)
    assert np.abs(fitted - stamps).max() <= 1
    assert report.jitter_s < 1e-9 and report.n_outliers == 0 and report.n_dropped == 0


def test_regularize_epoch_stamps_keep_their_precision():
    stamps, k, clean, _ = _host_stamps(seed=2, jitter=0.0)
    epoch = 1_700_000_000 * NS
    fitted, report = regularize_times(stamps + epoch, k)
    assert np.abs(fitted - epoch - clean).max() <= 2  # ns
    assert report.n_outliers == 12


def test_regularize_detections_per_camera():
    rig, det, _ = _session(noise=0.0, duration=6.0)
    rng = np.random.default_rng(0)
    jittered = Detections.from_frames(
        det.camera_names, det.frame_time_ns + rng.normal(0, 1e6, det.n_frames).astype(np.int64),
        det.frame_camera, det.frame_index, det.cand_frame, det.cand_uv)
    fixed, reports = regularize_detections(jittered)
    assert set(reports) == set(rig.names)
    assert fixed.n_frames == det.n_frames and fixed.n_candidates == det.n_candidates
    # back on the schedule to well under the 1 ms jitter
    order = np.lexsort((fixed.frame_index, fixed.frame_camera))
    ref = np.lexsort((det.frame_index, det.frame_camera))
    assert np.abs(fixed.frame_time_ns[order] - det.frame_time_ns[ref]).max() < 0.5e6
    for name in rig.names:
        assert reports[name].jitter_s == pytest.approx(1e-3, rel=0.3)


def test_regularize_refuses_one_frame_index():
    with pytest.raises(InputError, match="two distinct frame indices"):
        regularize_times(np.array([1, 2, 3]), np.array([4, 4, 4]))


def test_fusion_of_a_faulted_session_is_repaired_by_the_true_clock_in_the_rig(tmp_path, cli):
    """End to end: simulate clock faults, fuse with the session's nominal rig and with a rig
    holding the true clock keys (what a perfect 'pslog sync' writes): the latter is as good
    as a session without faults."""
    from pslog.evaluation import evaluate
    from pslog.log import read_session
    from pslog.rig import save_rig
    from pslog.simulation import read_truth_clock

    common = ("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
              "--duration", "4", "--noise-px", "0.3", "--seed", "2")
    assert cli(*common, "-o", tmp_path / "clean.mcap")[0] == 0
    assert cli(*common, "--clock-offset", "cam2=4", "--clock-offset", "cam3=-3",
               "--drift", "cam3=60", "--readout", "20", "-o", tmp_path / "faulted.mcap")[0] == 0
    session = read_session(tmp_path / "faulted.mcap")
    save_rig(read_truth_clock(session.rig, session.metadata), tmp_path / "true.toml")
    errors = {}
    for name, path, rig in (("clean", "clean.mcap", ()), ("nominal", "faulted.mcap", ()),
                            ("true", "faulted.mcap", ("--rig", tmp_path / "true.toml"))):
        out = tmp_path / f"fused-{name}.mcap"
        code, _, stderr = cli("fuse", tmp_path / path, "--method", "typeA", *rig, "-o", out)
        assert code == 0, stderr
        fused = read_session(out)
        errors[name] = evaluate(fused.tracks["typeA"], fused.truth).mean_mm
    assert errors["nominal"] > 2 * errors["clean"]
    assert errors["true"] < 1.25 * errors["clean"]


def test_a_session_whose_rig_holds_the_clock_is_fused_and_viewed_on_true_times(tmp_path):
    """The way 'pslog sync' writes its output (a copy with a new rig): fuse and the viewer
    read the correction from the session's own rig."""
    from pslog.cli import main
    from pslog.log import copy_session, read_session
    from pslog.simulation import read_truth_clock
    from viewers.data import load_view_data

    faulted, synced, fused = (tmp_path / n for n in ("f.mcap", "s.mcap", "fused.mcap"))
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "spiral",
                 "--clock-offset", "cam3=5", "--readout", "cam2=25", "-o", str(faulted)]) == 0
    session = read_session(faulted)
    true_rig = read_truth_clock(session.rig, session.metadata)
    copy_session(faulted, synced, rig=true_rig)
    assert read_session(synced).rig == true_rig
    view = load_view_data(synced, methods=["typeA"])
    expected = observations(session.detections, true_rig)
    assert_array_equal(view.observations.time_ns, expected.time_ns)
    assert not np.array_equal(expected.time_ns, session.detections.best().time_ns)
    assert main(["fuse", str(synced), "--method", "typeA", "-o", str(fused)]) == 0
    out = read_session(fused)
    track = out.tracks["typeA"]
    assert np.isin(track.time_ns, expected.time_ns).all()  # points at the true times
    nominal = tmp_path / "nominal.mcap"
    assert main(["fuse", str(faulted), "--method", "typeA", "-o", str(nominal)]) == 0
    from pslog.evaluation import evaluate
    error = evaluate(track, out.truth).mean_mm
    assert error < 0.5 * evaluate(read_session(nominal).tracks["typeA"], out.truth).mean_mm
