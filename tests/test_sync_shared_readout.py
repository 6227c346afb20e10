"""``pslog sync --estimate auto``'s nested readout test (session 37): identical cameras share
their sensor's rolling-shutter readout, so besides the per-camera Wald test (k dof) auto
tests one readout per camera model (g dof, ``dᵀΣ⁻¹G (GᵀΣ⁻¹G)⁻¹ GᵀΣ⁻¹d``), each at half of
the 0.1 % level (Bonferroni). Through the real CLI on MCAP sessions ``pslog simulate``
writes."""

from __future__ import annotations

import json

import numpy as np
from scipy.stats import chi2

from pslog import apply_timing, builtin_rig
from pslog.estimation.sync import AUTO_LEVEL, camera_models
from pslog.log import read_session
from pslog.rig import Rig

#: paper3, typeA, the rally, 8 s, 0.3 px, a 6 ms readout on every camera: the per-camera
#: test alone (the session-36 rule, χ²₃ at 0.1 %: 16.27) leaves the readouts out, the
#: one-readout test keeps them (benchmarks/session37/sync_find_case.py)
KEEP_SEED = 37154


def _simulate(cli, path, seed: int, readout_ms: float | None) -> None:
    args = ["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
            "--duration", "8", "--noise-px", "0.3", "--clock-offset", "cam2=5",
            "--clock-offset", "cam3=-7", "--seed", str(seed), "-o", path]
    if readout_ms:
        args += ["--readout", str(readout_ms)]
    code, _, err = cli(*args)
    assert code == 0, err


def _sync_json(cli, path, out, *args) -> dict:
    code, text, err = cli("sync", path, "-o", out, "--json", "--force", *args)
    assert code == 0, err
    return json.loads(text)


def _smooth_mm(cli, synced, fused) -> float:
    code, _, err = cli("fuse", synced, "--method", "smooth", "-o", fused, "--force")
    assert code == 0, err
    code, text, err = cli("eval", fused, "--json")
    assert code == 0, err
    (smooth,) = [m for m in json.loads(text) if m["method"] == "smooth"]
    return smooth["mean_mm"]


def test_cli_auto_keeps_a_readout_every_camera_shares_that_the_per_camera_test_misses(
        tmp_path, cli):
    """A readout shared by paper3's three identical cameras, the ball in a thin band of rows:
    the per-camera statistic stays below χ²₃ at 0.1 % (the session-36 rule dropped the
    readouts), the one-readout statistic is above χ²₁ at 0.05 %: auto keeps the readouts
    and smooth lands closer to the truth than with the offsets alone. Fails without the
    nested test (the readouts dropped, the JSON without its figures)."""
    path = tmp_path / "shared.mcap"
    _simulate(cli, path, KEEP_SEED, 6)
    report = _sync_json(cli, path, tmp_path / "auto.mcap")
    (readout,) = [t for t in report["selection"] if t["parameter"] == "readout"]
    assert report["estimated"] == ["offset", "readout"] and readout["kept"]
    assert readout["dof"] == 3 and readout["shared_dof"] == 1
    assert readout["wald_chi2"] < chi2.isf(AUTO_LEVEL, 3)  # the old rule: dropped
    assert readout["shared_wald_chi2"] > readout["shared_threshold"]
    assert readout["shared_threshold"] == chi2.isf(AUTO_LEVEL / 2, 1)
    assert readout["threshold"] == chi2.isf(AUTO_LEVEL / 2, 3)
    assert readout["p_value"] < AUTO_LEVEL
    auto_mm = _smooth_mm(cli, tmp_path / "auto.mcap", tmp_path / "auto_f.mcap")
    _sync_json(cli, path, tmp_path / "off.mcap", "--estimate", "offset")
    offset_mm = _smooth_mm(cli, tmp_path / "off.mcap", tmp_path / "off_f.mcap")
    assert auto_mm < 0.7 * offset_mm, (auto_mm, offset_mm)
    code, out, err = cli("sync", path, "-o", tmp_path / "t.mcap")
    assert code == 0, err
    assert "model (--estimate auto): offset, readout" in out
    # (what is estimated said before the tests, as the table has it: here one readout per
    # camera model, the three cameras' readouts tied (equal within the model); walk38: it
    # read "one per camera" before the tests' "one readout per model", about one estimate)
    assert report["shared_readout"] and readout["tied"]
    assert len({c["readout_s"] for c in report["cameras"]}) == 1
    assert (f"readouts estimated, one per camera model (a test above its threshold calls for "
            f"them, and a model's cameras do not differ): "
            f"one readout per camera model (one model): Wald χ² "
            f"{readout['shared_wald_chi2']:.1f} on 1 dof > 12.1; per camera: χ² "
            f"{readout['wald_chi2']:.1f} on 3 dof <= 17.7") in out, out
    print(f"one readout χ² {readout['shared_wald_chi2']:.1f}, per camera "
          f"{readout['wald_chi2']:.1f}; smooth auto {auto_mm:.2f} mm, offsets {offset_mm:.2f}")


def test_the_shared_statistic_is_the_wald_statistic_of_one_readout(tmp_path, cli):
    """The figures against the per-camera fit's own estimates and covariance (the
    ``clock_std`` of ``--estimate offset,readout``, auto's wide fit: auto itself then ties
    the readouts, tests/test_sync_tied_readout.py): the per-camera statistic is dᵀΣ⁻¹d over
    the three readouts, the shared one the squared GLS estimate of one readout over its
    variance, (1ᵀΣ⁻¹d)² / 1ᵀΣ⁻¹1 — an independent form of dᵀΣ⁻¹G(GᵀΣ⁻¹G)⁻¹GᵀΣ⁻¹d for one
    model. Fails if the shared statistic leaves out the readouts' correlations or weighs the
    cameras otherwise."""
    path = tmp_path / "shared.mcap"
    _simulate(cli, path, KEEP_SEED, 6)
    report = _sync_json(cli, path, tmp_path / "auto.mcap")
    synced = tmp_path / "wide.mcap"
    _sync_json(cli, path, synced, "--estimate", "offset,readout")
    (readout,) = [t for t in report["selection"] if t["parameter"] == "readout"]
    stored = json.loads(read_session(synced).metadata["clock_std"])
    names = stored["covariance"]["parameters"]
    idx = [i for i, (_, key) in enumerate(names) if key == "readout"]
    cov = np.array(stored["covariance"]["matrix"])[np.ix_(idx, idx)]
    d = np.array([stored["cameras"][names[i][0]]["readout"][0] for i in idx])
    assert len(d) == 3
    inv = np.linalg.inv(cov)
    one = np.ones(3)
    shared = (one @ inv @ d) ** 2 / (one @ inv @ one)
    assert abs(readout["wald_chi2"] - d @ inv @ d) < 1e-6 * readout["wald_chi2"]
    assert abs(readout["shared_wald_chi2"] - shared) < 1e-6 * shared, (readout, shared)
    # the projection onto one direction: never above the per-camera statistic
    assert readout["shared_wald_chi2"] <= readout["wald_chi2"]


def test_cli_auto_keeps_global_shutters_at_offsets_only_with_both_tests(tmp_path, cli):
    """Global shutters on the same rig and rally: both statistics below their thresholds,
    the offsets alone estimated (the result is ``--estimate offset``'s). Fails if the nested
    test keeps readouts regardless of its figure."""
    path = tmp_path / "global.mcap"
    _simulate(cli, path, KEEP_SEED, None)
    report = _sync_json(cli, path, tmp_path / "auto.mcap")
    (readout,) = [t for t in report["selection"] if t["parameter"] == "readout"]
    assert report["estimated"] == ["offset"] and not readout["kept"]
    assert readout["shared_dof"] == 1
    assert readout["shared_wald_chi2"] < readout["shared_threshold"]
    assert readout["wald_chi2"] < readout["threshold"]
    explicit = _sync_json(cli, path, tmp_path / "off.mcap", "--estimate", "offset")
    assert explicit["cameras"] == report["cameras"]


def test_camera_models_group_cameras_by_image_size_and_frame_rate():
    """Cameras of one size and rate are one model (their readouts shared under the nested
    hypothesis); a camera of another size, or another rate, a model of its own; numbered
    in order of first appearance. A rig of all-different cameras has as many models as
    cameras: auto then makes the per-camera test alone, at the whole level."""
    base = apply_timing(builtin_rig("paper3"), "typeA")
    assert camera_models(base, [0, 1, 2]).tolist() == [0, 0, 0]
    c1, c2, c3 = base.cameras
    mixed = Rig((c1.replace(width=1280, height=720), c2, c3.replace(fps=60.0, offset=0.0)))
    assert camera_models(mixed, [0, 1, 2]).tolist() == [0, 1, 2]
    two = Rig((c1, c2.replace(width=1280, height=720), c3))
    assert camera_models(two, [0, 1, 2]).tolist() == [0, 1, 0]
    assert camera_models(two, [1, 2]).tolist() == [0, 1]


def test_the_shared_statistic_of_two_models_is_the_drop_in_the_wald_distance(tmp_path, cli):
    """Two camera models (paper3 with cam3 given a 1280 × 720 sensor: cam1 and cam2 one
    model, cam3 its own; readouts 10 ms on every camera, seed 54402): ``G`` has two columns
    and ``W_s`` is on 2 dof. Against an independent form of the statistic, the drop of the
    Σ⁻¹ distance from the rig's readouts when the readouts may be any ``Gβ``,
    ``W_s = dᵀΣ⁻¹d − min_β (d − Gβ)ᵀΣ⁻¹(d − Gβ)``, read from the estimates and covariance of
    ``--estimate offset,readout``'s synced copy, auto's wide fit (W 40.9, W_s 40.7). Fails if
    ``G`` groups the cameras otherwise (cam1 with cam3: W_s 38.5), or as one model or as
    three (no shared test: ``W``)."""
    from pslog.log import SessionWriter
    from pslog.motion import rally_motion
    from pslog.simulation import SimulationOptions, simulate

    base = apply_timing(builtin_rig("paper3"), "typeA")
    c1, c2, c3 = base.cameras
    rig = Rig((c1, c2, c3.replace(width=1280, height=720)), base.name)
    assert camera_models(rig, [0, 1, 2]).tolist() == [0, 0, 1]
    det = simulate(rig, rally_motion(54402, 8.0), 8.0, SimulationOptions(
        noise_px=0.3, seed=54402, clock_offset_s={"cam2": 5e-3, "cam3": -7e-3},
        readout_s={name: 10e-3 for name in rig.names}))[0]
    path = tmp_path / "two.mcap"
    with SessionWriter(path, rig, timing="typeA", source="test") as writer:
        writer.add_detections(det)
    report = _sync_json(cli, path, tmp_path / "auto.mcap")
    # (the per-camera fit's estimates and covariance: auto's wide fit; auto itself may then
    # tie the readouts of a model, whose stored covariance is singular)
    synced = tmp_path / "wide.mcap"
    _sync_json(cli, path, synced, "--estimate", "offset,readout")
    (readout,) = [t for t in report["selection"] if t["parameter"] == "readout"]
    assert readout["kept"] and readout["dof"] == 3 and readout["shared_dof"] == 2
    assert readout["shared_threshold"] == chi2.isf(AUTO_LEVEL / 2, 2)
    stored = json.loads(read_session(synced).metadata["clock_std"])
    names = stored["covariance"]["parameters"]
    idx = [i for i, (_, key) in enumerate(names) if key == "readout"]
    assert [names[i][0] for i in idx] == list(rig.names)
    cov = np.array(stored["covariance"]["matrix"])[np.ix_(idx, idx)]
    d = np.array([stored["cameras"][names[i][0]]["readout"][0] for i in idx])
    inv = np.linalg.inv(cov)
    G = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    beta = np.linalg.lstsq(np.linalg.cholesky(inv).T @ G, np.linalg.cholesky(inv).T @ d,
                           rcond=None)[0]
    r = d - G @ beta
    shared = d @ inv @ d - r @ inv @ r
    assert abs(readout["shared_wald_chi2"] - shared) < 1e-6 * shared, (readout, shared)
    assert readout["shared_wald_chi2"] < readout["wald_chi2"] * (1 - 1e-9)
