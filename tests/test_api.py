"""The top-level Python API (pslog.read_session, fuse, sync, evaluate, __version__) gives what
the commands give on the same session: the same tracks bit for bit, the same clock estimates,
the same accuracy figures."""

from __future__ import annotations

import json
import re
import tomllib
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_array_equal

import pslog
from pslog.errors import FusionError, InputError, RigError

ROOT = Path(__file__).resolve().parent.parent


def test_version_is_the_installed_and_the_source_version():
    from pslog import _source_version

    declared = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert pslog.__version__ == version("pslog") == declared == _source_version()


def test_fuse_equals_the_fuse_command(sim_session, cli, tmp_path):
    out = tmp_path / "fused.mcap"
    code, _, err = cli("fuse", sim_session.path, "-o", out, "--method", "typeA",
                       "--method", "smooth")
    assert code == 0, err
    by_command = pslog.read_session(out).tracks
    session = pslog.read_session(sim_session.path)
    for methods in (["typeA", "smooth"], "typeA,smooth", ("smooth", "typeA")):
        by_api = pslog.fuse(session, methods)
        assert sorted(by_api) == ["smooth", "typeA"]
        for method, track in by_api.items():
            assert_array_equal(track.time_ns, by_command[method].time_ns)
            assert_array_equal(track.position_world, by_command[method].position_world)
        assert len(by_api.rejections["typeA"]) == len(pslog.read_session(out)
                                                      .rejections["typeA"])
    # a path, and bare detections with their rig, give the same
    assert_array_equal(pslog.fuse(sim_session.path, "typeA")["typeA"].position_world,
                       by_command["typeA"].position_world)
    assert_array_equal(pslog.fuse(sim_session.detections, "typeA",
                                  rig=sim_session.rig)["typeA"].position_world,
                       by_command["typeA"].position_world)


def test_fuse_defaults_to_the_methods_the_timing_suits(sim_session, cli, tmp_path):
    out = tmp_path / "fused.mcap"
    assert cli("fuse", sim_session.path, "-o", out)[0] == 0
    assert sorted(pslog.fuse(sim_session.path)) == sorted(pslog.read_session(out).tracks)


def test_fuse_refuses_what_the_command_refuses(sim_session):
    with pytest.raises(FusionError, match="unknown fusion method 'typeC'"):
        pslog.fuse(sim_session.path, "typeA,typeC")
    with pytest.raises(InputError, match="give the rig"):
        pslog.fuse(sim_session.detections, "typeA")
    from dataclasses import replace

    other = pslog.Rig(tuple(replace(c, name=f"x{i}")
                            for i, c in enumerate(sim_session.rig.cameras)))
    with pytest.raises(RigError, match="differ from the session's"):
        pslog.fuse(sim_session.path, "typeA", rig=other)


def test_sync_equals_the_sync_command(cli, tmp_path):
    raw = tmp_path / "raw.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                       "--duration", "4", "--noise-px", "0.3", "--clock-offset", "cam2=3",
                       "--host-jitter", "0.5", "--seed", "5", "-o", raw)
    assert code == 0, err
    code, out, err = cli("sync", raw, "-o", tmp_path / "s.mcap", "--estimate",
                         "offset,drift", "--json")
    assert code == 0, err
    by_command = json.loads(out)
    # a comma-separated string, as --estimate takes (tuples: the walk-through and below)
    outcome = pslog.sync(raw, "offset,drift")
    assert outcome.regularized and any("regularized" in n for n in outcome.notes)
    assert abs(outcome.rig.cameras[1].clock_offset - 0.003) < 5e-4
    assert outcome.result.residual_px == by_command["residual_px"]
    for est, row in zip(outcome.result.cameras, by_command["cameras"], strict=True):
        assert (est.name, est.offset_s, est.drift_ppm, est.offset_std_s) == (
            row["name"], row["offset_s"], row["drift_ppm"], row["offset_std_s"])
    synced = pslog.read_session(tmp_path / "s.mcap").rig
    for a, b in zip(outcome.rig.cameras, synced.cameras, strict=True):
        assert (a.clock_offset, a.clock_drift_ppm) == (b.clock_offset, b.clock_drift_ppm)
    # the synced rig feeds fuse as the command's --rig would
    assert len(pslog.fuse(raw, "typeA", rig=outcome.rig)["typeA"]) > 0
    with pytest.raises(InputError, match="'skew'"):
        pslog.sync(raw, ("offset", "skew"))


def test_evaluate_equals_the_eval_command(sim_session, cli, tmp_path):
    out = tmp_path / "fused.mcap"
    assert cli("fuse", sim_session.path, "-o", out, "--method", "typeA", "--method",
               "filter")[0] == 0
    code, text, err = cli("eval", out, "--json")
    assert code == 0, err
    by_command = {row["method"]: row for row in json.loads(text)}
    fused = pslog.read_session(out)
    for accuracies in (pslog.evaluate(fused), pslog.evaluate(fused.tracks, fused.truth)):
        assert sorted(accuracies) == ["filter", "typeA"]
        for method, acc in accuracies.items():
            row = by_command[method]
            assert (acc.n_points, acc.mean_mm, acc.p95_mm, acc.max_mm, acc.rate_hz) == (
                row["n_points"], row["mean_mm"], row["p95_mm"], row["max_mm"], row["rate_hz"])
    one = pslog.evaluate(fused.tracks["typeA"], fused.truth)
    assert list(one) == ["typeA"] and one["typeA"].mean_mm == by_command["typeA"]["mean_mm"]
    # errors in millimetres against a hand-computed case: a track 3 mm off the truth in x
    truth = fused.truth
    shifted = pslog.Track("shifted", truth.time_ns,
                          truth.position_world + np.array([0.003, 0, 0]),
                          np.zeros(len(truth), np.int32))
    acc = pslog.evaluate(shifted, truth)["shifted"]
    assert acc.mean_mm == pytest.approx(3.0, abs=1e-9) and acc.max_mm == pytest.approx(3.0)
    with pytest.raises(InputError, match="no ground truth"):
        pslog.evaluate(fused.tracks)


def test_the_python_walk_through_runs_as_written(capsys, monkeypatch):
    """docs/python.md's code blocks run, from the repository's root, and print figures."""
    import re

    monkeypatch.chdir(ROOT)
    text = (ROOT / "docs" / "python.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.DOTALL)
    assert len(blocks) == 2
    for block in blocks:
        exec(compile(block, "docs/python.md", "exec"), {})
    out = capsys.readouterr().out
    assert "offset" in out and "mean" in out and "'typeA'" in out


def test_the_readmes_python_block_runs(capsys, monkeypatch):
    import re

    monkeypatch.chdir(ROOT)
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.DOTALL)
    assert blocks
    for block in blocks:
        exec(compile(block, "README.md", "exec"), {})
    assert "'typeA'" in capsys.readouterr().out


def test_fuse_takes_a_rig_file_as_the_fuse_command_does(sim_session, cli, tmp_path):
    """rig= a path: resolve_rig(path, timing_from=the session's rig), as ``fuse --rig``."""
    from pslog.interchange.rig_formats import rig_to_format

    calib = tmp_path / "calibration.toml"
    text = rig_to_format(sim_session.rig, "anipose", "m")
    # a genuine anipose file has no timing keys: the session's are kept
    calib.write_text(re.sub(r"(?m)^(fps|offset|clock_offset|clock_drift_ppm|readout) = .*\n",
                            "", text), encoding="utf-8")
    assert "offset" not in calib.read_text(encoding="utf-8")
    out = tmp_path / "fused.mcap"
    code, _, err = cli("fuse", sim_session.path, "--rig", calib, "--method", "typeA", "-o", out)
    assert code == 0, err
    by_command = pslog.read_session(out).tracks["typeA"]
    for rig in (calib, str(calib)):
        by_api = pslog.fuse(sim_session.path, "typeA", rig=rig)["typeA"]
        assert_array_equal(by_api.time_ns, by_command.time_ns)
        assert_array_equal(by_api.position_world, by_command.position_world)
    with pytest.raises(RigError, match=r"no rig 'nowhere\.toml'"):
        pslog.fuse(sim_session.path, "typeA", rig="nowhere.toml")


@pytest.mark.parametrize("methods", ["", " , ", [], (), ["typeA", ""], 5, ["typeA", 5], b"x"])
def test_fuse_refuses_empty_or_non_name_methods_naming_them(sim_session, methods):
    with pytest.raises(InputError, match=r"methods .*" + re.escape(repr(methods)[:3])):
        pslog.fuse(sim_session.path, methods)


def test_sync_refuses_empty_or_non_name_estimates(sim_session):
    for bad in ("", "offset,", "offset,skew", 5, ["offset", 5]):
        with pytest.raises(InputError, match=r"estimate .*offset, drift, readout"):
            pslog.sync(sim_session.path, bad)


def test_evaluate_refuses_what_is_not_a_track_or_truth_naming_it(sim_session):
    track = pslog.fuse(sim_session.path, "typeA")["typeA"]
    with pytest.raises(InputError, match=r"tracks\['x'\] is 5, not a Track"):
        pslog.evaluate({"x": 5}, sim_session.truth)
    with pytest.raises(InputError, match=r"truth 'truth.csv': give a Truth"):
        pslog.evaluate(track, "truth.csv")
    with pytest.raises(InputError, match=r"tracks 5: give a Track"):
        pslog.evaluate(5, sim_session.truth)
    assert list(pslog.evaluate({"t": track}, sim_session.truth)) == ["t"]
