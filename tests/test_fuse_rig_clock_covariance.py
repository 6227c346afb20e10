"""``pslog fuse SESSION --rig SYNCED.mcap``: a synced copy's clocks come with the covariance
its sync stored (hostile38: they came without it, and std_m held the pixel noise alone,
silently). Real files: a simulated session with clock offsets, ``pslog sync``, then fused
both ways through the CLI."""

from __future__ import annotations

import numpy as np
from numpy.testing import assert_array_equal

from pslog.log import read_session


def test_fuse_with_a_synced_copys_rig_takes_its_clock_covariance(tmp_path, cli):
    session, synced = tmp_path / "s.mcap", tmp_path / "y.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                       "--duration", "6", "--noise-px", "0.3", "--clock-offset", "cam2=4",
                       "--clock-offset", "cam3=-6", "--seed", "57351", "-o", session)
    assert code == 0, err
    code, _, err = cli("sync", session, "-o", synced)
    assert code == 0, err
    methods = ("--method", "smooth", "--method", "typeA")
    code, out_rig, err = cli("fuse", session, "--rig", synced, *methods, "-o",
                             tmp_path / "f_rig.mcap")
    assert code == 0, err
    code, out_synced, err = cli("fuse", synced, *methods, "-o", tmp_path / "f_synced.mcap")
    assert code == 0, err
    code, _, err = cli("fuse", session, "--rig", synced, *methods, "--clock-uncertainty",
                       "off", "-o", tmp_path / "f_off.mcap")
    assert code == 0, err
    assert f"clock estimates of the pslog sync of --rig {synced}" in out_rig
    assert "clock estimates of pslog sync (offset: cam2, cam3" in out_synced
    by_rig = read_session(tmp_path / "f_rig.mcap").tracks
    by_copy = read_session(tmp_path / "f_synced.mcap").tracks
    off = read_session(tmp_path / "f_off.mcap").tracks
    for method in ("smooth", "typeA"):
        # the same detections, clocks and covariance: the same points and std_m
        assert_array_equal(by_rig[method].position_world, by_copy[method].position_world)
        assert_array_equal(by_rig[method].quality["std_m"], by_copy[method].quality["std_m"])
        # and the clocks' part is there: without it every std_m is smaller
        std, std_off = by_rig[method].quality["std_m"], off[method].quality["std_m"]
        assert np.all(std >= std_off) and np.mean(std > std_off * 1.001) > 0.5


def test_the_api_takes_a_synced_copys_clock_covariance_with_its_rig(tmp_path, cli):
    """``pslog.fuse(session, rig=SYNCED.mcap)``, the library's form of ``pslog fuse --rig``:
    the same rule (``for_session``'s ``rig_metadata``), the same std_m as fusing the copy."""
    import pslog

    session, synced = tmp_path / "s.mcap", tmp_path / "y.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                       "--duration", "4", "--noise-px", "0.3", "--clock-offset", "cam2=4",
                       "--seed", "57352", "-o", session)
    assert code == 0, err
    code, _, err = cli("sync", session, "-o", synced)
    assert code == 0, err
    by_rig = pslog.fuse(session, ["typeA"], rig=synced).tracks["typeA"]
    by_copy = pslog.fuse(synced, ["typeA"]).tracks["typeA"]
    exact = pslog.fuse(session, ["typeA"], rig=synced, clock_uncertainty=False).tracks["typeA"]
    assert_array_equal(by_rig.quality["std_m"], by_copy.quality["std_m"])
    assert np.mean(by_rig.quality["std_m"] > exact.quality["std_m"] * 1.001) > 0.5
