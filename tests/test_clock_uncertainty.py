"""The clocks' consider covariance (pslog/fusion/clock.py): a clock error acts as the pixel
error it predicts, the numeric sensitivity's rules, and ``pslog sync`` -> ``pslog fuse``
(``--clock-uncertainty``) on real sessions."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from _rally import rally
from numpy.testing import assert_allclose
from test_estimation import _rig

from pslog.errors import FusionError, InputError
from pslog.fusion import METHODS, FusionOptions, fuse, prepare
from pslog.fusion._prepare import default_max_gap_s
from pslog.fusion.clock import (
    add_covariance,
    clock_sensitivity,
    image_velocity,
    pixel_errors,
    with_clock_covariance,
)
from pslog.fusion.stream import StreamFuser
from pslog.log import read_session
from pslog.records import NS, Observations, Track
from pslog.rig import Rig
from pslog.simulation import SimulationOptions, simulate
from pslog.timing import CLOCK_STD_KEY, ClockCovariance, observations, read_clock_covariance


def _obs(times_s, cameras, uv) -> Observations:
    return Observations.from_unsorted(np.round(np.asarray(times_s) * NS).astype(np.int64),
                                      cameras, np.asarray(uv, dtype=np.float64))


def test_image_velocity_by_hand():
    # camera 0: four detections, the last after a gap beyond max_gap (0.1 s) and one lone
    # detection of camera 1
    t = [0.0, 1 / 30, 3 / 30, 8 / 30, 0.05]
    uv = [[100, 50], [103, 49], [112, 45], [200, 10], [7, 7]]
    obs = _obs(t, [0, 0, 0, 0, 1], uv)
    per_camera = [np.flatnonzero(obs.camera == c) for c in (0, 1)]
    v = image_velocity(obs, per_camera, 0.1)
    rows = per_camera[0]
    assert_allclose(v[rows[0]], [3 * 30, -1 * 30])  # forward: the first
    assert_allclose(v[rows[1]], np.array([12, -5]) / (3 / 30))  # central over both sides
    assert_allclose(v[rows[2]], np.array([9, -4]) / (2 / 30))  # backward: next 5/30 s away
    assert_allclose(v[rows[3]], [0, 0])  # alone within max_gap
    assert_allclose(v[per_camera[1]], [[0, 0]])


def test_pixel_errors_by_hand_with_correlated_parameters():
    # camera 1's offset (σ 2 ms) and readout (σ 4 ms), correlated 0.5; camera 0 untouched
    rig = _rig(2)
    height = rig.cameras[1].height
    obs = _obs([0.0, 0.01, 1 / 30 + 0.01, 2 / 30 + 0.01], [0, 1, 1, 1],
               [[10, 10], [100, 150], [110, 180], [125, 200]])
    sigma = np.array([2e-3, 4e-3])
    cov = np.outer(sigma, sigma) * np.array([[1, 0.5], [0.5, 1]])
    clock = ClockCovariance([1, 1], [0, 2], cov)
    per_camera = [np.flatnonzero(obs.camera == c) for c in (0, 1)]
    b = pixel_errors(obs, per_camera, rig, clock, 0.2)
    velocity = image_velocity(obs, per_camera, 0.2)
    for i in range(len(obs)):
        a = np.array([1.0, obs.uv[i, 1] / height]) * (obs.camera[i] == 1)
        # Σ_j b_ij b_ijᵀ = ż żᵀ (aᵀ Σ a): the clock's time error as pixels
        assert_allclose(b[i] @ b[i].T, np.outer(velocity[i], velocity[i]) * (a @ cov @ a),
                        rtol=1e-12, atol=1e-18)
    assert np.all(b[obs.camera == 0] == 0)
    # each column is -ż times a time: the pixel error points against the image velocity
    row = int(np.flatnonzero(obs.camera == 1)[1])
    for j in range(b.shape[2]):
        assert abs(abs(np.dot(b[row, :, j], velocity[row]))
                   - np.linalg.norm(b[row, :, j]) * np.linalg.norm(velocity[row])) < 1e-9
    with pytest.raises(FusionError, match="camera 5 is not in the rig"):
        pixel_errors(obs, per_camera, rig, ClockCovariance([5], [0], [[1e-6]]), 0.2)


@pytest.mark.parametrize(("method", "median", "p90"), [
    ("typeA", 0.01, 0.05), ("nearest", 0.01, 0.08), ("smooth", 0.08, 0.4),
    ("filter", 0.3, None)])
def test_a_clock_error_moves_the_points_as_the_sensitivity_predicts(method, median, p90):
    # camera c2's clock is 0.2 ms off: the same detections placed 0.2 ms early. The truth at
    # the stated times is a session whose c2 shutter really was 0.2 ms earlier (the rig's
    # phase moved); the points' difference is the clock error's effect, which the
    # sensitivity predicts as -S δ/σ (δ = estimate - truth = -0.2 ms)
    rig = _rig(3, distortion=True)
    motion, _ = rally(4.0, seed=3, speed=4.0, kick_every_s=0.9)
    delta, sigma = 0.2e-3, 2e-3
    faulted, _ = simulate(rig, motion, 4.0,
                          SimulationOptions(seed=1, clock_offset_s={"c2": delta}))
    moved = Rig(tuple(c.replace(offset=c.offset - delta) if c.name == "c2" else c
                      for c in rig.cameras))
    exact, _ = simulate(moved, motion, 4.0, SimulationOptions(seed=1))
    options = replace(FusionOptions(), max_gap_s=default_max_gap_s(rig))
    obs = observations(faulted, rig)
    prep = prepare(obs, rig)
    track = fuse(obs, rig, method, options, prepared=prep)
    reference = fuse(observations(exact, moved), moved, method, options)
    clock = ClockCovariance([1], [0], [[sigma**2]])
    S = clock_sensitivity(
        track, lambda o: METHODS[method].function(prepare(o, rig), rig, options), obs,
        pixel_errors(obs, prep.per_camera, rig, clock, options.max_gap_s))
    keys = track.time_ns * 256 + track.camera
    both, i, j = np.intersect1d(keys, reference.time_ns * 256 + reference.camera,
                                return_indices=True)
    assert len(both) > 0.95 * len(track)
    moved_by = track.position_world[i] - reference.position_world[j]
    predicted = S[i, :, 0] * (-delta) / sigma
    assert np.median(np.linalg.norm(predicted, axis=1)) > 0.1e-3  # a real effect
    deviation = (np.linalg.norm(moved_by - predicted, axis=1)
                 / np.linalg.norm(predicted, axis=1))
    assert np.median(deviation) < median
    if p90 is not None:
        assert np.percentile(deviation, 90) < p90


def _linear_run(A: np.ndarray, times: np.ndarray, *, flip_at=None, drop_when=None):
    """A hand-made estimator: points ``A @ pixels`` at ``times`` (camera 0), with a decision
    that moves point 0 by 1 m once pixel 0's u passes ``flip_at``, and point 1 left out when
    ``drop_when(obs)``."""
    def run(obs: Observations) -> Track:
        p = (A @ obs.uv.ravel()).reshape(-1, 3)
        if flip_at is not None and obs.uv[0, 0] > flip_at:
            p[0] += 1.0
        keep = np.ones(len(p), dtype=bool)
        if drop_when is not None and drop_when(obs):
            keep[1] = False
        return Track("x", times[keep], p[keep], np.zeros(keep.sum(), np.int32))
    return run


def test_clock_sensitivity_rules_on_a_hand_made_estimator():
    rng = np.random.default_rng(4)
    obs = _obs([0.0, 0.1, 0.2], [0, 0, 0], [[10, 20], [30, 40], [50, 60]])
    A = rng.normal(size=(9, 6))
    times = obs.time_ns.copy()
    errors = rng.normal(size=(3, 2, 2))  # two clock directions, pixels per σ
    base = _linear_run(A, times)(obs)
    S = clock_sensitivity(base, _linear_run(A, times), obs, errors)
    for j in range(2):  # linear: exactly A times the column
        assert_allclose(S[:, :, j], (A @ errors[:, :, j].ravel()).reshape(-1, 3), rtol=1e-6)
    # a decision flipped by the +step (pixel 0 sits just below its threshold): the -step's
    # side is taken for that point, the others keep the central difference
    step = 1e-2 / np.max(np.abs(errors[:, :, 0]))
    flip_at = 10 + 0.5 * step * abs(errors[0, 0, 0])
    run = _linear_run(A, times, flip_at=flip_at)
    S_flip = clock_sensitivity(run(obs), run, obs, errors[:, :, :1])
    assert_allclose(S_flip[:, :, 0], S[:, :, 0], rtol=1e-6)
    # a point one perturbed run (either) does not make takes the other side's difference
    for drop_when in (lambda o: o.uv[1, 1] > 40, lambda o: o.uv[1, 1] < 40):
        run = _linear_run(A, times, drop_when=drop_when)
        S_drop = clock_sensitivity(run(obs), run, obs, errors[:, :, :1])
        assert_allclose(S_drop[:, :, 0], S[:, :, 0], rtol=1e-6)
    # none made it: no sensitivity known, 0
    run = _linear_run(A, times, drop_when=lambda o: o.uv[1, 1] != 40)
    assert np.all(clock_sensitivity(run(obs), run, obs, errors[:, :, :1])[1] == 0)


def test_add_covariance_adds_s_st_to_each_form_of_covariance():
    S = np.array([[[1.0, 0.0], [2.0, 1.0], [0.0, 3.0]]]) * 1e-3  # one point, two columns
    added = S[0] @ S[0].T
    cov = np.diag([4.0, 9.0, 1.0]) * 1e-6
    full = Track("a", [0], [[0, 0, 0]], [0], {
        **{f"cov_{k}_m2": [cov[i, j]] for k, (i, j) in {
            "xx": (0, 0), "yy": (1, 1), "zz": (2, 2), "xy": (0, 1), "xz": (0, 2),
            "yz": (1, 2)}.items()},
        "std_m": [np.sqrt(np.trace(cov))]})
    out = add_covariance(full, S)
    assert_allclose(out.quality["cov_xy_m2"], [added[0, 1]])
    assert_allclose(out.quality["cov_yz_m2"], [added[1, 2]])
    assert_allclose(out.quality["cov_zz_m2"], [cov[2, 2] + added[2, 2]])
    assert_allclose(out.quality["std_m"], [np.sqrt(np.trace(cov + added))])
    axes = Track("f", [0], [[0, 0, 0]], [0], {"std_x_m": [2e-3], "std_y_m": [3e-3],
                                               "std_z_m": [1e-3], "std_m": [np.sqrt(14e-6)]})
    out = add_covariance(axes, S)
    assert_allclose(out.quality["std_y_m"], [np.sqrt(9e-6 + added[1, 1])])
    assert_allclose(out.quality["std_m"], [np.sqrt(14e-6 + np.trace(added))])
    assert np.array_equal(out.position_world, axes.position_world)


def test_clock_covariance_is_checked():
    with pytest.raises(InputError, match="symmetric"):
        ClockCovariance([1, 2], [0, 0], [[1e-6, 1e-7], [0.0, 1e-6]])
    with pytest.raises(InputError, match="positive semi-definite"):
        ClockCovariance([1, 2], [0, 0], [[1e-6, 2e-6], [2e-6, 1e-6]])
    with pytest.raises(InputError, match="do not match"):
        ClockCovariance([1], [0, 2], [[1e-6]])
    with pytest.raises(InputError, match="a parameter is 0, 1 or 2"):
        ClockCovariance([1], [3], [[1e-6]])
    # a semi-definite matrix: the square root has a column per positive eigenvalue
    L = ClockCovariance([1, 2], [0, 0], [[1e-6, 1e-6], [1e-6, 1e-6]]).factor()
    assert L.shape == (2, 1) and np.allclose(L @ L.T, 1e-6)


def test_a_session_synced_before_the_covariance_was_stored_takes_the_stds():
    rig = _rig(3)
    stds = {"c1": {"clock_offset": [0.0, 0.0], "clock_drift_ppm": [0.0, 0.0],
                   "readout": [0.0, 3e-3]},
            "c2": {"clock_offset": [0.0, 2e-3], "clock_drift_ppm": [0.0, 0.0],
                   "readout": [0.0, 0.0]},
            "c3": {"clock_offset": [0.5, 2e-3], "clock_drift_ppm": [0.0, 0.0],
                   "readout": [0.0, 0.0]}}  # (c3's offset since replaced: 0.5 != 0)
    clock = read_clock_covariance(rig, {CLOCK_STD_KEY: json.dumps({"cameras": stds})})
    assert clock.camera.tolist() == [0, 1] and clock.parameter.tolist() == [2, 0]
    assert_allclose(clock.matrix, np.diag([9e-6, 4e-6]))
    assert read_clock_covariance(rig, {CLOCK_STD_KEY: "{not json"}) is None
    # a stored matrix that is no covariance (here: not symmetric, and one with NaN) is
    # not used: the standard deviations alone
    for matrix in ([[9e-6, 1e-6], [0.0, 4e-6]], [[float("nan"), 0.0], [0.0, 4e-6]]):
        bad = {"cameras": stds, "covariance": {"parameters": [["c1", "readout"],
                                                               ["c2", "clock_offset"]],
                                               "matrix": matrix}}
        clock = read_clock_covariance(rig, {CLOCK_STD_KEY: json.dumps(bad)})
        assert_allclose(clock.matrix, np.diag([9e-6, 4e-6]))
    good = {"cameras": stds, "covariance": {"parameters": [["c2", "clock_offset"],
                                                            ["c1", "readout"]],
                                            "matrix": [[4e-6, 1e-6], [1e-6, 9e-6]]}}
    clock = read_clock_covariance(rig, {CLOCK_STD_KEY: json.dumps(good)})
    assert_allclose(clock.matrix, [[9e-6, 1e-6], [1e-6, 4e-6]])  # in the rig's order
    assert read_clock_covariance(rig, {}) is None


def test_a_stream_refuses_the_consider_covariance():
    with pytest.raises(FusionError, match="offline only"):
        StreamFuser(_rig(3), "typeA",
                    FusionOptions(clock_covariance=ClockCovariance([1], [0], [[1e-6]])))


def test_sync_then_fuse_widens_std_with_the_clocks_and_leaves_the_points(tmp_path, cli):
    # the paper's rig, rolling shutters of 25 ms and offsets estimated (σ of 2-4 ms): with
    # the clocks taken as exact the covariance is too small (NEES 2-3), with them near 1
    path = tmp_path / "faulted.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                       "rally", "--duration", "6", "--noise-px", "0.3", "--readout", "25",
                       "--clock-offset", "cam2=7", "--clock-offset", "cam3=-4", "--seed",
                       "13", "-o", path)
    assert code == 0, err
    synced = tmp_path / "synced.mcap"
    code, _, err = cli("sync", path, "-o", synced, "--estimate", "offset,readout")
    assert code == 0, err
    on, off = tmp_path / "on.mcap", tmp_path / "off.mcap"
    code, out, err = cli("fuse", synced, "-o", on, "--method", "typeA,smooth,filter")
    assert code == 0, err
    assert ("std_m includes the uncertainty of the 5 clock estimates of pslog sync (offset: "
            "cam2, cam3; readout: cam1, cam2, cam3; --clock-uncertainty off: the pixel noise "
            "alone)") in out, out
    code, out, err = cli("fuse", synced, "-o", off, "--method", "typeA,smooth,filter",
                         "--clock-uncertainty", "off")
    assert code == 0, err
    assert "std_m includes" not in out
    with_clocks, without = read_session(on).tracks, read_session(off).tracks
    nees = {}
    for label, path_ in (("on", on), ("off", off)):
        code, out, err = cli("eval", path_, "--json")
        assert code == 0, err
        nees[label] = {r["method"]: r["quality"]["nees"] for r in json.loads(out)}
    for method in ("typeA", "smooth", "filter"):
        a, b = with_clocks[method], without[method]
        assert np.array_equal(a.position_world, b.position_world)
        assert np.array_equal(a.time_ns, b.time_ns)
        assert np.all(a.quality["std_m"] >= b.quality["std_m"])
        # (typeA's own std is the largest: its extrapolation's; the clocks add least)
        assert np.median(a.quality["std_m"] / b.quality["std_m"]) > (
            1.02 if method == "typeA" else 1.2)
        assert 0.6 < nees["on"][method] < 1.3, (method, nees)
    assert nees["off"]["smooth"] > 2 and nees["off"]["filter"] > 1.5, nees
    # a rig whose clocks replace the synced ones takes no clock uncertainty
    rig_file = tmp_path / "rig.toml"
    code, out, err = cli("rig", "show", path)
    assert code == 0, err
    rig_file.write_text(out)
    code, out, err = cli("fuse", synced, "-o", tmp_path / "other.mcap", "--method",
                         "typeA", "--rig", rig_file)
    assert code == 0, err
    assert "std_m includes" not in out
    assert f"--rig {rig_file} replaces every clock parameter pslog sync estimated (5): std_m " \
           "holds the pixel noise alone" in out, out


def test_smooth_adds_the_clocks_through_its_own_sensitivity_as_a_rerun_measures_it():
    # smooth's consider columns come from the fit's implicit-function sensitivity
    # (pixel_sensitivity); re-running the fit with the pixels moved (what the other methods
    # do) measures the same response: the two agree to the numeric difference's noise
    rig = _rig(3, distortion=True)
    motion, _ = rally(4.0, seed=3, speed=4.0, kick_every_s=0.9)
    detections, _ = simulate(rig, motion, 4.0, SimulationOptions(
        seed=1, noise_px=0.3, readout_s={"c1": 0.02, "c2": 0.02, "c3": 0.02}))
    sigma = np.array([2e-3, 2.5e-3, 3e-3, 3e-3])
    cov = np.outer(sigma, sigma) * (0.7 * np.eye(4) + 0.3)  # correlated 0.3
    clock = ClockCovariance([1, 2, 1, 0], [0, 0, 2, 2], cov)
    options = replace(FusionOptions(clock_covariance=clock), max_gap_s=default_max_gap_s(rig))
    obs = observations(detections, rig)
    prep = prepare(obs, rig)
    plain = METHODS["smooth"].function(prep, rig, replace(options, clock_covariance=None))
    own = fuse(obs, rig, "smooth", options, prepared=prep)
    rerun = with_clock_covariance(plain, "smooth", prep, rig, options)
    assert np.array_equal(own.position_world, plain.position_world)
    added_own = own.quality["std_m"] ** 2 - plain.quality["std_m"] ** 2
    added_rerun = rerun.quality["std_m"] ** 2 - plain.quality["std_m"] ** 2
    ratio = np.sqrt(added_own / added_rerun)
    assert np.median(plain.quality["std_m"]) < 0.5 * np.median(own.quality["std_m"])
    assert abs(np.median(ratio) - 1) < 0.03
    assert np.percentile(ratio, 10) > 0.92 and np.percentile(ratio, 90) < 1.06
    # the full covariance too, not only its trace: the xy and zz entries
    for key in ("cov_xy_m2", "cov_zz_m2"):
        gained = own.quality[key] - plain.quality[key]
        measured = rerun.quality[key] - plain.quality[key]
        scale = np.median(np.abs(measured)) + np.median(added_rerun) * 0.01
        assert np.median(np.abs(gained - measured)) < 0.1 * scale, key


def test_the_square_root_keeps_a_sharp_offset_beside_a_broad_drift():
    # units ~1e10 apart in variance (s² against ppm²): a short session's drift σ of 100-300
    # ppm beside offsets' σ of 0.1-0.7 ms (pslog sync --estimate offset,drift of a 4-s
    # global-shutter session: 0.74 ms, 297 ppm, correlated -0.87). The square root must give
    # back every variance and correlation, the offsets' included
    for so, sd, rho in ((1e-4, 100.0, 0.0), (2e-5, 20.0, 0.9), (7.4e-4, 296.5, -0.869)):
        M = np.array([[so * so, rho * so * sd], [rho * so * sd, sd * sd]])
        L = ClockCovariance([1, 1], [0, 1], M).factor()
        d = np.sqrt(np.diag(M))
        assert_allclose((L @ L.T) / np.outer(d, d), M / np.outer(d, d), atol=1e-9)
    # and an offsets' block that is not positive semi-definite is refused, whatever a drift's
    # variance beside it
    bad = np.diag([1e-8, 1e-8, 1e4])
    bad[0, 1] = bad[1, 0] = 2e-8
    with pytest.raises(InputError, match="positive semi-definite"):
        ClockCovariance([1, 2, 1], [0, 0, 1], bad)


def test_a_near_zero_correlation_rounded_unevenly_is_still_symmetric():
    # pslog sync's T Σ Tᵀ (RS combined 2 min own4, seed 97303): an entry of correlation
    # 4.7e-6 and its transpose differed by 1.8e-9 of themselves, symmetric to 1e-14 of
    # σ_i σ_j. It must be taken (refused, a fuse read no clock covariance and said nothing)
    rig = _rig(3)
    d = np.array([1e-3, 30.0, 2e-3])  # s, ppm, s
    corr = np.array([[1.0, -0.6, 4.7e-6], [-0.6, 1.0, 0.2], [4.7e-6, 0.2, 1.0]])
    M = corr * np.outer(d, d)
    M[0, 2] *= 1 + 1.8e-9
    clock = ClockCovariance([1, 1, 2], [0, 1, 0], M)
    assert np.array_equal(clock.matrix, clock.matrix.T)
    stds = {"c1": {}, "c2": {"clock_offset": [0.0, d[0]], "clock_drift_ppm": [0.0, d[1]]},
            "c3": {"clock_offset": [0.0, d[2]]}}
    stored = {"cameras": stds, "covariance": {
        "parameters": [["c2", "clock_offset"], ["c2", "clock_drift_ppm"], ["c3", "clock_offset"]],
        "matrix": M.tolist()}}
    read = read_clock_covariance(rig, {CLOCK_STD_KEY: json.dumps(stored)})
    assert read is not None and read.matrix[0, 2] != 0
    # an asymmetry that is one, of correlations, is still refused
    M[0, 2] += 1e-6 * d[0] * d[2]
    with pytest.raises(InputError, match="symmetric"):
        ClockCovariance([1, 1, 2], [0, 1, 0], M)


def test_options_with_a_clock_covariance_compare_and_hash_by_value():
    # FusionOptions is frozen and hashable (pslog.live.fuser keys its warm-up by it): with a
    # ClockCovariance the dataclass's own __eq__ compared arrays (ValueError) and hashing
    # failed (TypeError)
    def make(var):
        return FusionOptions(clock_covariance=ClockCovariance([1, 2], [0, 0],
                                                              np.diag([1e-6, var])))
    a, b, c = make(1e-6), make(1e-6), make(2e-6)
    assert a == b and hash(a) == hash(b) and a != c and a != FusionOptions()
    assert len({a, b, c}) == 2


@pytest.mark.parametrize("pixel", [np.nan, 1e5])
def test_a_detection_without_a_pixel_leaves_the_clocks_consider_as_it_was(pixel):
    # a NaN pixel, or one far beyond the image (docs/methods.md, "A detection without a
    # ray"): no data to any method. Its NaN had made every column NaN (smooth's std_m NaN at
    # every point; the other methods' columns skipped, the clocks' share gone) and 1e5 px
    # gave its neighbours image velocities of ~1e6 px/s (std_m of metres)
    rig = _rig(3, distortion=True)
    motion, _ = rally(4.0, seed=3, speed=4.0, kick_every_s=0.9)
    detections, _ = simulate(rig, motion, 4.0, SimulationOptions(seed=2, noise_px=0.3))
    obs = observations(detections, rig)
    clock = ClockCovariance([1, 2, 2], [0, 0, 2], np.diag([2e-3, 3e-3, 4e-3]) ** 2)
    options = FusionOptions(clock_covariance=clock)
    row = int(np.flatnonzero(obs.camera == 1)[40])
    uv = obs.uv.copy()
    uv[row] = pixel
    broken = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    for method in ("smooth", "typeA"):
        clean = fuse(obs, rig, method, options)
        plain = fuse(broken, rig, method, replace(options, clock_covariance=None))
        out = fuse(broken, rig, method, options)
        assert np.all(np.isfinite(out.quality["std_m"])), method
        added = out.quality["std_m"] ** 2 - plain.quality["std_m"] ** 2
        assert np.median(np.sqrt(added)) > 0.3 * np.median(
            np.sqrt(clean.quality["std_m"] ** 2 - fuse(obs, rig, method, replace(
                options, clock_covariance=None)).quality["std_m"] ** 2)), method
        assert out.quality["std_m"].max() < 2 * clean.quality["std_m"].max(), method


def test_pixel_errors_of_a_drift_grow_with_the_session_time():
    # the drift's derivative is 1e-6 * t seconds per ppm (pslog.timing: drift * 1e-6 *
    # logged): 20 ppm of σ at t = 100 s is 2 ms, at 1000 s 20 ms, against the offset's t-free 1 s
    rig = _rig(2)
    t0 = np.array([0.0, 1 / 30, 2 / 30])
    times = np.r_[t0 + 100.0, t0 + 1000.0]
    obs = _obs(times, [1] * 6, [[100 + 3 * k, 200 - k] for k in range(6)])
    per_camera = [np.flatnonzero(obs.camera == c) for c in (0, 1)]
    b = pixel_errors(obs, per_camera, rig, ClockCovariance([1], [1], [[20.0**2]]), 0.2)
    velocity = image_velocity(obs, per_camera, 0.2)
    t = obs.time_ns / NS
    assert_allclose(np.abs(b[:, :, 0]), np.abs(velocity) * (1e-6 * t * 20.0)[:, None],
                    rtol=1e-9)


def test_smooth_with_choices_in_doubt_takes_the_clocks_on_the_rows_it_fits():
    # smooth leaves a doubted choice out (docs/methods.md, "A contested start"): its clock
    # columns must be those of the rows it fits (consider_px[problem.rows] of the kept
    # observations), and agree with the re-run, which keeps the doubt in every run
    rig = _rig(3, distortion=True)
    motion, _ = rally(4.0, seed=3, speed=4.0, kick_every_s=0.9)
    detections, _ = simulate(rig, motion, 4.0, SimulationOptions(seed=5, noise_px=0.3))
    clock = ClockCovariance([1, 2], [0, 0], np.diag([2e-3, 3e-3]) ** 2)
    options = replace(FusionOptions(clock_covariance=clock), max_gap_s=default_max_gap_s(rig))
    obs = observations(detections, rig)
    doubt = np.zeros(len(obs))
    doubt[np.arange(7, len(obs), 37)] = 4.0  # a choice in doubt every 37 rows
    prep = replace(prepare(obs, rig), doubt_px2=doubt)
    plain = METHODS["smooth"].function(prep, rig, replace(options, clock_covariance=None))
    own = fuse(obs, rig, "smooth", options, prepared=prep)
    rerun = with_clock_covariance(plain, "smooth", prep, rig, options)
    assert np.array_equal(own.position_world, plain.position_world)
    ratio = np.sqrt((own.quality["std_m"] ** 2 - plain.quality["std_m"] ** 2)
                    / (rerun.quality["std_m"] ** 2 - plain.quality["std_m"] ** 2))
    assert abs(np.median(ratio) - 1) < 0.05


def _simulated_3s(tmp_path, cli, seed: int):
    """A 3-s paper3 rally, camera cam2's clock 5 ms off, written by ``pslog simulate``."""
    path = tmp_path / "s.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                       "rally", "--duration", "3", "--noise-px", "0.3", "--clock-offset",
                       "cam2=5", "--seed", str(seed), "-o", path)
    assert code == 0, err
    return path


def test_a_damaged_clock_std_never_stops_a_fuse(tmp_path, cli):
    # pslog fuse on a synced session whose clock_std metadata was damaged: not JSON, NaN in
    # the matrix, a list for the cameras, a matrix of the wrong size. Each fuses (exit 0),
    # with the clocks' uncertainty where the stds survive and without it where they do not
    from pslog.log.copy import copy_session

    path, synced = _simulated_3s(tmp_path, cli, 97500), tmp_path / "synced.mcap"
    code, _, err = cli("sync", path, "-o", synced, "--estimate", "offset")
    assert code == 0, err
    stored = json.loads(read_session(synced).metadata[CLOCK_STD_KEY])
    nan_matrix = json.loads(json.dumps(stored))
    nan_matrix["covariance"]["matrix"][0][0] = float("nan")
    wrong_size = json.loads(json.dumps(stored))
    wrong_size["covariance"]["matrix"] = [[1.0]]
    nan_std = json.loads(json.dumps(stored))
    nan_std["cameras"]["cam2"]["clock_offset"][1] = float("nan")
    negative_std = json.loads(json.dumps(stored))
    negative_std["cameras"]["cam2"]["clock_offset"][1] *= -1
    for label, text, said in (("not json", "{oops", False),
                              ("nan", json.dumps(nan_matrix), True),
                              ("list", json.dumps({"cameras": [1, 2]}), False),
                              ("size", json.dumps(wrong_size), True),
                              ("nan std", json.dumps(nan_std), True),
                              ("negative std", json.dumps(negative_std), True)):
        damaged, out_path = tmp_path / f"{label}.mcap", tmp_path / f"{label}-fused.mcap"
        copy_session(synced, damaged, metadata={CLOCK_STD_KEY: text})
        before = damaged.read_bytes()
        code, out, err = cli("fuse", damaged, "-o", out_path, "--method", "typeA,smooth")
        assert code == 0, (label, err)
        assert ("std_m includes the uncertainty" in out) == said, (label, out)
        # where stds are lost, one line says so (silently, std_m would look calibrated):
        # all of them, or one of the two offsets (the other's applied)
        if not said:
            assert (f"{damaged}: its clock estimates' metadata (clock_std) is damaged: std_m "
                    "holds the pixel noise alone") in out, (label, out)
        elif "std" in label:
            assert ("std_m includes the uncertainty of the 1 clock estimates of pslog sync "
                    "(offset: cam3; --clock-uncertainty off: the pixel noise alone); 1 other "
                    "damaged in the session's metadata (clock_std): none for it") in out, (
                        label, out)
        else:
            assert "metadata (clock_std)" not in out, (label, out)
        assert damaged.read_bytes() == before


def test_fuse_says_when_the_clocks_uncertainty_is_not_applied(tmp_path, cli):
    # asked for on a session never synced: one line, exit 0, the input untouched; by default
    # silent; a --rig that replaces one synced clock: the line counts it
    path, synced = _simulated_3s(tmp_path, cli, 97501), tmp_path / "synced.mcap"
    before = path.read_bytes()
    code, out, err = cli("fuse", path, "-o", tmp_path / "on.mcap", "--method", "typeA",
                         "--clock-uncertainty", "on")
    assert code == 0 and err == "", err
    assert (f"--clock-uncertainty on ignored: {path} holds no clock estimates (never synced: "
            "'pslog sync' estimates them); std_m holds the pixel noise alone") in out, out
    assert path.read_bytes() == before
    code, out, err = cli("fuse", path, "-o", tmp_path / "default.mcap", "--method", "typeA")
    assert code == 0, err
    assert "std_m" not in out, out
    code, _, err = cli("sync", path, "-o", synced, "--estimate", "offset")
    assert code == 0, err
    code, out, err = cli("rig", "show", synced)
    assert code == 0, err
    rig = read_session(synced).rig
    moved = f"clock_offset = {rig.cameras[2].clock_offset!r}"
    assert moved in out
    rig_file = tmp_path / "rig.toml"
    other = rig.cameras[2].clock_offset + 1e-4
    rig_file.write_text(out.replace(moved, f"clock_offset = {other!r}"))
    code, out, err = cli("fuse", synced, "-o", tmp_path / "partial.mcap", "--method", "typeA",
                         "--rig", rig_file)
    assert code == 0, err
    assert ("std_m includes the uncertainty of the 1 clock estimates of pslog sync "
            "(offset: cam2; --clock-uncertainty off: the pixel noise alone); "
            f"--rig {rig_file} replaced 1 other: none for it") in out, out


def test_a_choice_in_doubt_is_no_neighbour_of_the_image_velocity():
    # camera 1's middle detection is a choice the gate put in doubt, 80 px off the ball's
    # line: the rows beside it take their velocity from the rows beyond it, not from it
    rig = _rig(2)
    t = np.arange(5) / 30
    uv = np.stack([100 + 300 * t, 200 + 150 * t], axis=1)
    uv[2] += 80.0
    obs = _obs(t + 0.01, [1] * 5, uv)
    per_camera = [np.zeros(0, np.int64), np.arange(5)]
    clock = ClockCovariance([1], [0], [[4e-6]])
    doubtful = np.zeros(5, dtype=bool)
    doubtful[2] = True
    b = pixel_errors(obs, per_camera, rig, clock, 0.2, doubtful)
    assert_allclose(b[[0, 1, 3, 4], :, 0], np.tile([-300 * 2e-3, -150 * 2e-3], (4, 1)))
    assert np.all(b[2] == 0)
    plain = pixel_errors(obs, per_camera, rig, clock, 0.2)
    assert not np.allclose(plain[1, :, 0], b[1, :, 0])  # (without it, the blob's velocity)

