"""One readout per camera model, estimated (session 37): when ``--estimate auto``'s nested
test keeps the readouts of cameras of one model and the Wald test of equal readouts within
each model does not reject, the readouts are estimated as one parameter per model (tied),
every camera of the model taking its value; ``--estimate offset,readout=shared`` asks for
it. The clocks' covariance then has identical readout rows (singular): ``pslog fuse`` takes
it. Through the real CLI on MCAP sessions ``pslog simulate`` writes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import chi2

from pslog.estimation.sync import TIE_LEVEL
from pslog.log import read_session

#: paper3, typeA, the rally, 8 s, 0.3 px, a 6 ms readout on every camera (as
#: tests/test_sync_shared_readout.py): per camera 6.9 / 6.3 / 7.1 ms, tied 6.71 ± 1.80
SHARED_SEED = 37154


def _simulate(cli, path, seed: int, *readout: str, rig: str = "paper3",
              duration: str = "8") -> None:
    args = ["simulate", "--rig", rig, "--timing", "typeA", "--motion", "rally",
            "--duration", duration, "--noise-px", "0.3", "--clock-offset", "cam2=5",
            "--clock-offset", "cam3=-7", "--seed", str(seed), "-o", path]
    for value in readout:
        args += ["--readout", value]
    code, _, err = cli(*args)
    assert code == 0, err


def _sync_json(cli, path, out, *args) -> dict:
    code, text, err = cli("sync", path, "-o", out, "--json", "--force", *args)
    assert code == 0, err
    return json.loads(text)


def _smooth(cli, synced, fused) -> tuple[float, float, str]:
    """smooth's mean error (mm) and NEES against the truth, and fuse's output."""
    code, said, err = cli("fuse", synced, "--method", "smooth", "-o", fused, "--force")
    assert code == 0, err
    code, text, err = cli("eval", fused, "--json")
    assert code == 0, err
    (smooth,) = [m for m in json.loads(text) if m["method"] == "smooth"]
    return smooth["mean_mm"], smooth["quality"]["nees"], said


def _stored(path):
    stored = json.loads(read_session(path).metadata["clock_std"])
    names = [tuple(n) for n in stored["covariance"]["parameters"]]
    return stored, names, np.array(stored["covariance"]["matrix"])


def test_cli_auto_ties_a_readout_every_camera_shares_and_lands_closer(tmp_path, cli,
                                                                      capsys):
    """paper3's three identical cameras, one 6 ms readout: the nested test keeps it, the
    equal-readouts statistic (2 dof) is far below its threshold, so auto estimates one
    readout: every camera the same value and σ, the stored covariance's readout rows
    identical (rank one), fuse takes it (the 3 clock estimates in std_m) and smooth lands
    closer to the truth than with the per-camera readouts (`--estimate offset,readout`).
    The explicit `readout=shared` gives the same clocks (within 0.25 σ: auto's second fit
    starts from its first, session 38). Fails without the tie (auto's
    readouts then differ per camera, and its JSON has no equal test)."""
    path = tmp_path / "shared.mcap"
    _simulate(cli, path, SHARED_SEED, "6")
    auto = _sync_json(cli, path, tmp_path / "auto.mcap")
    (readout,) = [t for t in auto["selection"] if t["parameter"] == "readout"]
    assert auto["shared_readout"] and readout["tied"] and readout["kept"]
    assert readout["equal_dof"] == 2
    assert readout["equal_threshold"] == chi2.isf(TIE_LEVEL, 2)
    assert readout["equal_wald_chi2"] <= readout["equal_threshold"]
    values = {c["readout_s"] for c in auto["cameras"]}
    stds = {c["readout_std_s"] for c in auto["cameras"]}
    assert len(values) == 1 and len(stds) == 1, auto["cameras"]
    (value,), (std,) = values, stds
    assert abs(value - 6e-3) < 2 * std
    _, names, matrix = _stored(tmp_path / "auto.mcap")
    idx = [i for i, (_, key) in enumerate(names) if key == "readout"]
    block = matrix[np.ix_(idx, idx)]
    assert len(idx) == 3 and np.allclose(block, block[0, 0], rtol=1e-9, atol=0)
    assert np.isclose(np.sqrt(block[0, 0]), std, rtol=1e-9)
    tied_mm, tied_nees, said = _smooth(cli, tmp_path / "auto.mcap", tmp_path / "a_f.mcap")
    # (the tied readout said as one estimate, as sync says it; walk38: "the 5 clock
    # estimates", "readout: cam1, cam2, cam3" of a sync that estimated 3)
    assert "std_m includes the uncertainty of the 3 clock estimates" in said, said
    assert "readout: one for cam1, cam2 and cam3 (per camera model)" in said
    percam = _sync_json(cli, path, tmp_path / "pc.mcap", "--estimate", "offset,readout")
    assert not percam["shared_readout"]
    assert len({c["readout_s"] for c in percam["cameras"]}) == 3
    percam_mm, percam_nees, _ = _smooth(cli, tmp_path / "pc.mcap", tmp_path / "pc_f.mcap")
    assert tied_mm < 0.9 * percam_mm, (tied_mm, percam_mm)
    assert 0.2 < tied_nees < 2.0, tied_nees
    explicit = _sync_json(cli, path, tmp_path / "ex.mcap", "--estimate",
                          "offset,readout=shared")
    assert explicit["shared_readout"] and explicit["selection"] is None
    # the same model, fitted from auto's wide fit's clocks (session 38: no second coarse
    # scan) where the explicit list starts from the rig's: the same clocks within the
    # fitting rounds' own tolerance (at most 0.19 σ on five held-out seeds), the same σ
    for a, b in zip(auto["cameras"], explicit["cameras"], strict=True):
        for key in ("offset", "readout"):
            std = b[f"{key}_std_s"]
            assert abs(a[f"{key}_s"] - b[f"{key}_s"]) <= 0.25 * std, (key, a, b)
            assert abs(a[f"{key}_std_s"] - std) <= 0.01 * std, (key, a, b)
    code, out, err = cli("sync", path, "-o", tmp_path / "ex2.mcap", "--force", "--estimate",
                         "offset,readout=shared")
    assert code == 0, err
    assert "readouts: one per camera model (readout=shared)" in out, out
    code, out, err = cli("sync", path, "-o", tmp_path / "t.mcap", "--force")
    assert code == 0, err
    assert "model (--estimate auto): offset, readout (one readout per camera model)" in out
    assert (f"equal within each model: χ² {readout['equal_wald_chi2']:.1f} on 2 dof <= "
            f"6.0 (the 5 % level): one readout per model") in out, out
    code, out, err = cli("info", tmp_path / "auto.mcap")
    assert code == 0, err
    assert out.count(f"readout {value * 1e3:.4f} ms") == 3, out
    with pytest.raises(SystemExit) as stop:  # one readout per model or per camera, not both
        cli("sync", path, "-o", tmp_path / "u.mcap", "--estimate",
            "offset,readout,readout=shared")
    assert stop.value.code == 2
    assert "readout=shared instead of readout" in capsys.readouterr().err
    print(f"equal χ² {readout['equal_wald_chi2']:.2f}; tied {value * 1e3:.2f} ± "
          f"{std * 1e3:.2f} ms; smooth tied {tied_mm:.2f} mm (NEES {tied_nees:.2f}), per "
          f"camera {percam_mm:.2f} (NEES {percam_nees:.2f})")


def test_the_equal_statistic_and_the_tied_estimate_follow_the_per_camera_fit(tmp_path,
                                                                             cli):
    """Against the per-camera fit's own estimates and covariance (``--estimate
    offset,readout``'s stored ``clock_std``: auto's wide fit): the equal-readouts statistic
    is ``W - W_s`` (for the rig's readouts all 0, the per-camera statistic less the
    one-readout statistic: Σ⁻¹'s complement of the projection, an independent form of
    (Aθ̂)ᵀ(AΣAᵀ)⁻¹(Aθ̂)); the tied fit's readout and σ are, to first order, the per-camera
    estimate constrained to equal readouts on its covariance, θ̂ - ΣAᵀ(AΣAᵀ)⁻¹Aθ̂ and
    Σ - ΣAᵀ(AΣAᵀ)⁻¹AΣ. Fails if the tied column is not every camera's readout column (a
    readout that moves one camera's times alone), or the equal statistic leaves out the
    readouts' correlations."""
    path = tmp_path / "shared.mcap"
    _simulate(cli, path, SHARED_SEED, "6")
    auto = _sync_json(cli, path, tmp_path / "auto.mcap")
    (readout,) = [t for t in auto["selection"] if t["parameter"] == "readout"]
    _sync_json(cli, path, tmp_path / "pc.mcap", "--estimate", "offset,readout")
    stored, names, cov = _stored(tmp_path / "pc.mcap")
    theta = np.array([stored["cameras"][name][key][0] for name, key in names])
    r = [i for i, (_, key) in enumerate(names) if key == "readout"]
    inv = np.linalg.inv(cov[np.ix_(r, r)])
    d, one = theta[r], np.ones(len(r))
    w, ws = d @ inv @ d, (one @ inv @ d) ** 2 / (one @ inv @ one)
    assert np.isclose(readout["equal_wald_chi2"], w - ws, rtol=1e-6), (readout, w - ws)
    A = np.zeros((len(r) - 1, len(theta)))
    for i in range(1, len(r)):
        A[i - 1, r[i]], A[i - 1, r[0]] = 1.0, -1.0
    gain = cov @ A.T @ np.linalg.inv(A @ cov @ A.T)
    constrained = theta - gain @ (A @ theta)
    constrained_std = np.sqrt((cov - gain @ A @ cov)[r[0], r[0]])
    tied = auto["cameras"][0]
    assert abs(tied["readout_s"] - constrained[r[0]]) < 0.2 * constrained_std, (
        tied, constrained[r[0]], constrained_std)
    assert abs(tied["readout_std_s"] / constrained_std - 1) < 0.1


def test_cli_auto_does_not_tie_a_rolling_camera_to_global_ones_of_its_model(tmp_path, cli):
    """paper3 with a 16 ms readout on cam1 only (a rolling shutter among global ones of the
    same size and rate, what the grouping assumes away): the nested test keeps readouts,
    but the equal-readouts test rejects, so they are estimated per camera (cam1's near 16
    ms, the others' near 0) — auto's result is then `--estimate offset,readout`'s. Fails if
    the readouts kept by the nested test are tied regardless."""
    path = tmp_path / "one.mcap"
    _simulate(cli, path, ROLLING_SEED, "cam1=16", duration="20")
    auto = _sync_json(cli, path, tmp_path / "auto.mcap")
    (readout,) = [t for t in auto["selection"] if t["parameter"] == "readout"]
    assert readout["kept"] and readout["shared_wald_chi2"] > readout["shared_threshold"]
    assert readout["equal_wald_chi2"] > readout["equal_threshold"]
    assert not readout["tied"] and not auto["shared_readout"]
    percam = _sync_json(cli, path, tmp_path / "pc.mcap", "--estimate", "offset,readout")
    assert auto["cameras"] == percam["cameras"]
    r = [c["readout_s"] for c in auto["cameras"]]
    assert r[0] > 0.010 and abs(r[1]) < 0.004 and abs(r[2]) < 0.004, r


#: a seed whose nested test keeps cam1's lone 16 ms readout (20 s)
ROLLING_SEED = 37160


def test_auto_fits_the_tied_model_from_its_wide_fit(tmp_path, cli, monkeypatch):
    """Session 38: when auto ties the readouts, its second fit (the tied model) starts from
    the wide fit's converged clocks: the coarse offset scan runs once (the wide fit's), not
    twice, and the second fit takes fewer rounds (on paper3 at 8 s its CPU went 0.39-0.49 ->
    0.13-0.24 s: benchmarks/session38/tie_refit.py). A group dropped is still fitted from
    the rig's values (its result the explicit list's to the bit: tests/test_sync.py).
    Fails if the second fit ignores its start."""
    import pslog.estimation.sync as sync_module
    from pslog.api import sync

    path = tmp_path / "shared.mcap"
    _simulate(cli, path, SHARED_SEED, "6")
    scans = []
    scan = sync_module._scan_offsets

    def counted(*args, **kwargs):
        scans.append(1)
        return scan(*args, **kwargs)

    monkeypatch.setattr(sync_module, "_scan_offsets", counted)
    result = sync(read_session(path), "auto").result
    assert result.shared_readout
    assert len(scans) == 1, len(scans)
    scans.clear()
    assert sync(read_session(path), "offset,readout=shared").result.shared_readout
    assert len(scans) == 1  # (a fit of its own scans, as before)


def test_auto_ties_readouts_whose_wide_estimates_pass_the_frame_period(tmp_path, cli):
    """A full-frame rolling shutter (32 ms at 30 fps, the frame period 33.3 ms): the wide
    fit's per-camera readouts scatter by about 2 ms around it (seed 38231: cam1 33.72 ms,
    beyond the period), the tied refit starts from that fit's clocks, and a start holding
    33.72 ms was a rig a rig refuses: auto failed ("RigError: camera 'cam1': readout
    0.03372 s must be in [0, 0.0333333 s)"; found in session 38's review). It starts from
    the wide fit's rig (its readouts in [0, period) as the rig it writes), and the tied fit
    lands near the truth."""
    from pslog.api import sync

    path = tmp_path / "full_frame.mcap"
    _simulate(cli, path, 38231, "32")
    result = sync(read_session(path), "auto").result
    assert result.shared_readout and "readout" in result.estimated
    readouts = [c.readout_s for c in result.cameras]
    assert len(set(readouts)) == 1  # (one readout for the three cameras of one model)
    assert abs(readouts[0] - 0.032) < 3 * result.cameras[0].readout_std_s
    assert 0.0 <= min(c.readout for c in result.rig.cameras)
    assert max(c.readout for c in result.rig.cameras) < 1 / 30
