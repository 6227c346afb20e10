"""Session 27's hostile-input sweep, input validation and messages: each a one-line message
naming the problem and the value, through the real CLI on real files."""

from __future__ import annotations

import pytest

from pslog.evaluation import QualitySummary, format_quality_table


def test_fuse_says_every_type_a_point_was_withheld_by_the_std_bound(tmp_path, sim_session,
                                                                       cli):
    """All typeA points above --type-a-max-std-mm: said so with the count and the bound,
    not "too few detections close enough in time"."""
    code, out, _ = cli("fuse", sim_session.path, "--method", "typeA",
                         "--type-a-max-std-mm", "1", "-o", tmp_path / "f.mcap")
    assert code == 1
    line = next(x for x in out.splitlines() if x.startswith("no point from typeA"))
    assert "withheld: std above --type-a-max-std-mm 1 mm" in line, line
    assert int(line.split("all ")[1].split()[0]) > 50, line
    assert "too few detections" not in out
    assert not (tmp_path / "f.mcap").exists()


def test_fuse_says_the_type_a_bound_is_ignored_when_type_a_does_not_run(tmp_path,
                                                                          sim_session, cli):
    code, out, err = cli("fuse", sim_session.path, "--method", "nearest",
                         "--type-a-max-std-mm", "1", "-o", tmp_path / "f.mcap")
    assert code == 0, err
    assert "--type-a-max-std-mm 1 ignored: typeA does not run" in out, out


@pytest.mark.parametrize("value", ["kicks", "all", "on", "off", None])
def test_fuse_says_confirm_gaps_is_ignored_when_type_a_does_not_run(tmp_path, sim_session,
                                                                     cli, value):
    """(session 33's review) ``--confirm-gaps kicks`` without typeA ran without a word; any
    value given is said (session 35: the default, ``kicks``, is no value given)."""
    given = ("--confirm-gaps", value) if value else ()
    code, out, err = cli("fuse", sim_session.path, "--method", "nearest", *given, "-o",
                         tmp_path / "f.mcap")
    assert code == 0, err
    assert ("--confirm-gaps" in out) == bool(value), out
    if value:
        assert f"--confirm-gaps {value} ignored: typeA does not run" in out, out


def test_fuse_says_filter_hold_off_is_ignored_when_the_filter_does_not_run(tmp_path,
                                                                          sim_session, cli):
    """(session 33's walkthrough) ``--method typeA --filter-hold off`` ran without a word."""
    code, out, err = cli("fuse", sim_session.path, "--method", "typeA", "--filter-hold", "off",
                         "-o", tmp_path / "f.mcap")
    assert code == 0, err
    assert "--filter-hold off ignored: filter does not run" in out, out
    code, out, err = cli("fuse", sim_session.path, "--method", "typeA,filter", "--filter-hold",
                         "off", "-o", tmp_path / "g.mcap")
    assert code == 0 and "ignored" not in out, out


def test_fuse_refuses_a_pixel_noise_no_detector_has(tmp_path, sim_session, cli, capsys):
    """1e-300 px: every typeA point's std_m was NaN; 1e-8: sync's NEES a 40-digit number."""
    for value in ("1e-300", "1e-8", "0.0009"):
        with pytest.raises(SystemExit) as exc:
            cli("fuse", sim_session.path, "--noise-px", value, "-o", tmp_path / "f.mcap")
        assert exc.value.code == 2, value
        err = capsys.readouterr().err
        assert "--noise-px" in err and repr(value) in err and "at least 0.001" in err, err
        assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "f.mcap").exists()


def test_eval_prints_a_huge_nees_as_a_short_number():
    row = QualitySummary(method="sync", n_points=3, residual_median_px=0.1,
                         residual_p95_px=0.2, gap_max_ms=0.0, std_median_mm=1e-9,
                         within_2sigma=0.0, nees=2.5e40)
    text = format_quality_table([row])
    assert "2.50e+40" in text and "25000000000" not in text, text


def _opencv_rig(tmp_path, cli):
    import json

    path = tmp_path / "rig.json"
    code, _, err = cli("rig", "export", "paper3", "--format", "opencv", "-o", path)
    assert code == 0, err
    return path, json.loads(path.read_text())


def test_an_opencv_camera_without_its_camera_matrix_is_refused_not_dropped(tmp_path, cli):
    import json

    path, rig = _opencv_rig(tmp_path, cli)
    del rig["camera_0"]["camera_matrix"]
    path.write_text(json.dumps(rig))
    for args in (("rig", "check", path), ("rig", "import", path, "-o", tmp_path / "r.toml")):
        code, out, err = cli(*args)
        assert code == 1, (args, out, err)
        assert f"{path}: camera_0: missing key camera_matrix" in err, err
        assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "r.toml").exists()


def test_an_opencv_image_width_given_as_a_string_is_named(tmp_path, cli):
    import json

    path, rig = _opencv_rig(tmp_path, cli)
    rig["camera_1"]["image_width"] = "640"
    path.write_text(json.dumps(rig))
    code, out, err = cli("rig", "check", path)
    assert code == 1, (out, err)
    assert "camera_1: image_width must be a number of pixels, got '640' (a string)" in err, err
    assert len(err.strip().splitlines()) == 1, err


def test_a_session_given_as_a_rig_file_is_named_as_a_session(tmp_path, sim_session, cli):
    """'rig import s.mcap', 'calibrate --rig s.mcap': "'utf-8' codec can't decode byte 0x89"."""
    points = tmp_path / "p.csv"
    points.write_text("u,v,x,y,z\n")
    before = sim_session.path.read_bytes()
    for args in (("rig", "import", sim_session.path, "-o", tmp_path / "r.toml"),
                 ("calibrate", "--points", points, "--name", "cam1", "--rig",
                  sim_session.path)):
        code, out, err = cli(*args)
        assert code == 1, (args, out, err)
        assert f"{sim_session.path} is a session, not a rig file" in err, err
        assert "pslog rig show" in err and "codec" not in err, err
    assert sim_session.path.read_bytes() == before
    assert not (tmp_path / "r.toml").exists()


def test_python_dash_m_pslog_runs_the_command():
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", "pslog", "--help"], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: pslog")


@pytest.mark.parametrize("option", ["--clock-offset", "--drift"])
def test_simulate_refuses_a_camera_given_twice(tmp_path, cli, option):
    code, _, err = cli("simulate", "--rig", "paper3", option, "cam2=4", option, "cam2=8",
                       "-o", tmp_path / "s.mcap")
    assert code == 2, err
    assert f"argument {option}: camera cam2 given twice (4, 8)" in err, err
    assert not (tmp_path / "s.mcap").exists()


def test_sync_says_a_session_is_too_short_for_a_drift(tmp_path, rig3, cli):
    from pslog.log import SessionWriter
    from pslog.motion import get_motion
    from pslog.simulation import SimulationOptions, simulate

    detections, _ = simulate(rig3, get_motion("straight"), 2.0,
                             SimulationOptions(noise_px=0.3, seed=0))
    path = tmp_path / "s.mcap"
    with SessionWriter(path, rig3, timing="typeA", source="test") as writer:
        writer.add_detections(detections)
    code, out, err = cli("sync", path, "--estimate", "drift", "-o", tmp_path / "y.mcap")
    assert code == 1, (out, err)
    assert "the session (2.0 s) is too short for a drift: it needs at least 30 s" in err, err
    assert "move more" not in err and len(err.strip().splitlines()) == 1, err


def test_info_prints_a_negative_zero_offset_as_zero():
    from pslog.cli.info import _ms

    assert _ms(-0.0) == "0.000 ms" and _ms(-1e-9) == "0.000 ms"
    assert _ms(-2e-6) == "-0.002 ms" and _ms(float("nan")) == "-"


def _points(tmp_path, seed=None):
    """samples/cam1_points.csv, its pixels moved by 80 px noise when ``seed`` is given."""
    from pathlib import Path

    import numpy as np

    sample = Path(__file__).resolve().parent.parent / "samples" / "cam1_points.csv"
    if seed is None:
        return sample
    rows = np.loadtxt(sample, delimiter=",", skiprows=1)
    rows[:, 3:] += np.random.default_rng(seed).normal(0, 80, (len(rows), 2))
    path = tmp_path / f"bad{seed}.csv"
    np.savetxt(path, rows, delimiter=",", header="x,y,z,u,v", comments="", fmt="%.3f")
    return path


def test_calibrate_refuses_an_absurd_square_side(tmp_path, cli, capsys):
    """1e300: a numpy RuntimeWarning and OpenCV's assertion; 1e30: "RMS 32499 px" written."""
    with pytest.raises(SystemExit) as exc:
        cli("calibrate", "--chessboard", "9x6", "--square", "1e30", "--images", tmp_path,
            "--name", "c", "--rig", tmp_path / "r.toml")
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "argument --square: must be at most 1 m" in err, err
    assert "Warning" not in err and len(err.strip().splitlines()) == 1, err


def test_calibrate_refuses_a_reprojection_rms_beyond_the_bound(tmp_path, cli):
    rig = tmp_path / "r.toml"
    code, out, err = cli("calibrate", "--points", _points(tmp_path, seed=0), "--name", "cam1",
                         "--rig", rig, "--width", "640", "--height", "480")
    assert code == 1, (out, err)
    assert "reprojection RMS 75.4 px is beyond 50 px: the calibration failed" in err, err
    assert not rig.exists()


def test_calibrate_names_a_principal_point_outside_the_image(tmp_path, cli):
    code, out, err = cli("calibrate", "--points", _points(tmp_path), "--name", "cam1",
                         "--rig", tmp_path / "r.toml", "--width", "100", "--height", "100")
    assert code == 1, (out, err)
    assert "principal point (320.2, 239.9) px lies outside the 100x100 image" in err, err
    assert "must be within" not in err and len(err.strip().splitlines()) == 1, err


def test_calibrate_says_a_binary_points_file_is_not_text(tmp_path, cli):
    points = tmp_path / "p.csv"
    points.write_bytes(b"\x89MCAP0\r\n\x00\xff" * 10)
    code, out, err = cli("calibrate", "--points", points, "--name", "cam1",
                         "--rig", tmp_path / "r.toml", "--width", "640", "--height", "480")
    assert code == 1, (out, err)
    assert f"{points}: not a text CSV file (byte 0 is not UTF-8 text)" in err, err
    assert "codec" not in err, err


def _damaged_sample(tmp_path, name, flip=None, cut=None):
    from pathlib import Path

    data = bytearray((Path(__file__).resolve().parent.parent / "samples" / "throw.mcap")
                     .read_bytes())
    if flip is not None:
        data[flip] ^= 0xFF
    path = tmp_path / name
    path.write_bytes(bytes(data[:cut]) if cut is not None else bytes(data))
    return path


@pytest.mark.parametrize("flip", [200, 600])  # (40: tests/faults/test_metadata_damage.py)
def test_recover_rebuilds_a_damaged_session_metadata_from_the_calibration_topics(
        tmp_path, cli, flip):
    """One flipped byte in the session metadata record: info said "nothing can be
    recovered", fuse "run 'pslog recover'", recover "nothing usable can be recovered"; every
    message and the /calibration topics were intact."""
    import numpy as np

    from pslog.log import read_session

    original = _damaged_sample(tmp_path, "orig.mcap")
    broken = _damaged_sample(tmp_path, "broken.mcap", flip=flip)
    code, out, err = cli("info", broken)
    assert code == 1 and f"run 'pslog recover {broken}" in err, err
    fixed = tmp_path / "fixed.mcap"
    code, out, err = cli("recover", broken, "-o", fixed)
    assert code == 0, err
    assert "session metadata (rig, cameras) was damaged: rebuilt" in out, out
    got, want = read_session(fixed), read_session(original)
    assert got.rig.names == want.rig.names and got.metadata["timing"] == "typeA"
    for a, b in zip(got.rig.cameras, want.rig.cameras, strict=True):
        assert (a.width, a.height, a.fps) == (b.width, b.height, b.fps)
        np.testing.assert_allclose(a.K, b.K, atol=1e-9)
        np.testing.assert_allclose(a.R, b.R, atol=1e-9)
        np.testing.assert_allclose(a.t, b.t, atol=1e-9)
        assert abs(a.offset - b.offset) < 1e-9
    np.testing.assert_array_equal(got.detections.cand_uv, want.detections.cand_uv)
    assert len(got.truth.time_ns) == len(want.truth.time_ns)
    code, out, err = cli("fuse", fixed, "--method", "typeA", "-o", tmp_path / "f.mcap")
    assert code == 0, err


def test_a_file_cut_in_its_set_up_is_said_to_be_beyond_repair_by_every_command(tmp_path, cli):
    """Cut at 100 bytes: fuse said "run 'pslog recover'", recover "nothing can be"."""
    cut = _damaged_sample(tmp_path, "cut.mcap", cut=100)
    for args in (("info", cut), ("fuse", cut, "-o", tmp_path / "f.mcap"),
                 ("recover", cut, "-o", tmp_path / "r.mcap")):
        code, out, err = cli(*args)
        assert code == 1, (args, out, err)
        assert "beyond repair" in err and "run 'pslog recover" not in err, (args, err)
        assert len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "f.mcap").exists() and not (tmp_path / "r.mcap").exists()


def test_fuse_says_a_calibrations_timing_keys_are_not_applied(tmp_path, sim_session, cli):
    """(session 33's walkthrough) ``fuse --rig cal.toml`` with a pslog-exported aniposelib
    calibration takes its geometry only: its fps/offset/clock keys, when they differ from
    the session's, were left out without a word (documented in --help only)."""
    code, _, err = cli("rig", "export", sim_session.path, "--format", "anipose", "-o",
                       tmp_path / "cal.toml")
    assert code == 0, err
    code, out, err = cli("fuse", sim_session.path, "--rig", tmp_path / "cal.toml", "-o",
                         tmp_path / "a.mcap")
    assert code == 0 and "not applied" not in out, out  # the same timing: nothing to say
    text = (tmp_path / "cal.toml").read_text()
    first = text.index("offset = ")
    end = text.index("\n", first)
    (tmp_path / "other.toml").write_text(text[:first] + "offset = 0.005" + text[end:])
    code, out, err = cli("fuse", sim_session.path, "--rig", tmp_path / "other.toml", "-o",
                         tmp_path / "b.mcap")
    assert code == 0, err
    line = next(x for x in out.splitlines() if "not applied" in x)
    assert "its fps/offset/clock keys are not applied to cam1:" in line, line
    assert "pslog rig import" in line, line
