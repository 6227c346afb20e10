"""A hostile new user's sweep of issue 10's command-line surface (``simulate --spurious
--spurious-radius --distractor --blackout``, ``fuse --gating --noise-px --method filter``,
``eval``): odd but valid values work, bad ones give one line and the right exit code.

In-process (``pslog.cli.main``) where a subprocess adds nothing; a subprocess where the
terminal output itself (a RuntimeWarning) is the fault.
"""

from __future__ import annotations

import pytest

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog

SHORT = ("--rig", "paper3", "--duration", "0.5")


def test_spurious_rate_of_one_is_a_false_candidate_in_every_frame(cli, tmp_path):
    """--spurious 1 (every frame has a false candidate) is harsh but valid, and fuses."""
    session, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    code, out, err = cli("simulate", *SHORT, "--spurious", "1", "-o", session)
    assert code == 0, err
    n_frames = int(out.split(" frames over")[0].rsplit(" ", 1)[1])
    n_cands = int(out.split(" detections")[0].rsplit(" ", 1)[1])
    assert n_cands == 2 * n_frames  # the ball and one false candidate in every frame
    code, out, err = cli("fuse", session, "-o", fused, "--method", "filter")
    assert code == 0, err
    code, out, err = cli("eval", fused)
    assert code == 0, err
    assert "gating" in out


def test_spurious_above_one_is_refused(tmp_path):
    run = run_pslog("simulate", *SHORT, "--spurious", "1.01", "-o", tmp_path / "s.mcap")
    assert_one_line_error(run, 2, contains=("--spurious", "[0, 1]"))
    assert not list(tmp_path.iterdir())


def test_spurious_radius_refusal_speaks_of_the_radius_not_noise(tmp_path):
    run = run_pslog("simulate", *SHORT, "--spurious-radius", "101", "-o", tmp_path / "s.mcap")
    line = assert_one_line_error(run, 2, contains=("--spurious-radius", "101"))
    assert "noise" not in line


@pytest.mark.parametrize("point", ["1e300,0,0", "cam1=1e300,0,0", "0,-1e308,0"])
def test_a_distractor_absurdly_far_away_is_refused_without_warnings(tmp_path, point):
    """Projecting 1e300 m overflowed the distortion polynomial: RuntimeWarnings on stderr."""
    run = run_pslog("simulate", *SHORT, "--distractor", point, "-o", tmp_path / "s.mcap")
    assert_one_line_error(run, 2, contains=("--distractor", "not in"))
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("blackout", ["cam1=0:1e308", "cam2=0.2:1e300"])
def test_a_blackout_longer_than_any_session_works(cli, tmp_path, blackout):
    """round(inf ns) raised OverflowError (a traceback) for a blackout of 1e308 s. (One
    that starts at 1e308 s is refused since session 30: it would hide nothing,
    tests/faults/test_sweep30.py.)"""
    session = tmp_path / "s.mcap"
    code, _, err = cli("simulate", *SHORT, "--blackout", blackout, "-o", session)
    assert code == 0, err
    assert session.exists()


def test_every_camera_blacked_out_for_the_whole_session(cli, tmp_path):
    """Valid: a session of frames with no detection; fuse then says so in one line."""
    session = tmp_path / "s.mcap"
    blackouts = [a for n in ("cam1", "cam2", "cam3") for a in ("--blackout", f"{n}=0:1e9")]
    code, out, err = cli("simulate", *SHORT, *blackouts, "-o", session)
    assert code == 0, err
    assert " 0 detections" in out
    assert "false candidates from blackouts" not in out  # a blackout adds no candidate
    before = fingerprint(tmp_path)
    run = run_pslog("fuse", session, "-o", tmp_path / "f.mcap", "--method", "filter")
    assert_one_line_error(run, 1, contains="no detection")
    assert_untouched(before, tmp_path)


def test_fusing_a_session_only_one_camera_sees_names_the_camera(tmp_path, cli):
    """Two of three cameras blacked out: the error said 'too few detections close enough
    in time', which is not why; now it names the one camera left."""
    session = tmp_path / "s.mcap"
    code, _, err = cli("simulate", *SHORT, "--blackout", "cam1=0:100", "--blackout",
                       "cam2=0:100", "-o", session)
    assert code == 0, err
    before = fingerprint(tmp_path)
    run = run_pslog("fuse", session, "-o", tmp_path / "f.mcap")
    assert_one_line_error(run, 1, contains=("only camera cam3", "two cameras"))
    assert_untouched(before, tmp_path)


@pytest.mark.parametrize("value", ["1e308", "60001"])
def test_sync_refuses_a_search_span_beyond_a_minute(tmp_path, value):
    """--search-ms 1e308 asked numpy for an endless grid (ValueError traceback); a large
    finite one scans at 1 ms steps for ever."""
    run = run_pslog("sync", tmp_path / "s.mcap", "-o", tmp_path / "y.mcap", "--search-ms", value)
    assert_one_line_error(run, 2, contains=("--search-ms", "a minute"))


def test_eval_of_a_fused_session_without_truth_reports_what_needs_none(cli, tmp_path):
    """An imported (real) session has no truth: eval refused it (exit 1); the quality and
    gating tables need no truth, so it prints them and says why accuracy is missing."""
    import json

    rows = "camera,time,u,v\n" + "".join(
        f"cam{c},{k / 30:.6f},{300 + 2 * k + c},{200 + k}\n" for k in range(30) for c in (1, 2, 3))
    (tmp_path / "det.csv").write_text(rows)
    session, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    code, _, err = cli("import", "--rig", "paper3", "--detections", tmp_path / "det.csv",
                       "-o", session)
    assert code == 0, err
    code, _, err = cli("fuse", session, "-o", fused, "--method", "filter", "--method", "sync",
                       "--noise-px", "0")
    assert code == 0, err
    code, out, err = cli("eval", fused)
    assert code == 0, err
    assert "no ground truth" in out and "resid px" in out and "gating" in out
    # which sessions have one: not a live one, synthetic or not (its recording holds none)
    assert "'pslog live --synthetic' records none" in out, out
    code, out, err = cli("eval", fused, "--json")
    assert code == 0, err
    result = json.loads(out)
    assert {r["method"] for r in result} <= {"filter", "sync"} and result
    assert all(r["quality"]["nees"] is None for r in result)


def test_a_distractor_with_a_negative_first_coordinate_is_a_value(cli, tmp_path):
    """'--distractor -0.3,0.2,0.1' was read as an unknown option ("expected one argument")."""
    code, out, err = cli("simulate", *SHORT, "--distractor", "-0.3,0.2,0.1",
                         "-o", tmp_path / "s.mcap")
    assert code == 0, err
    assert "distractors" in out


def test_a_distractor_behind_the_camera_is_refused(tmp_path):
    """A point one metre behind camera cam1 (along its optical axis): one line, exit 2."""
    import numpy as np

    from pslog.rig import builtin_rig

    cam = builtin_rig("paper3").cameras[0]
    rot, t = np.asarray(cam.R), np.asarray(cam.t)
    behind = -rot.T @ t - rot[2]
    point = ",".join(f"{x:.6f}" for x in behind)
    run = run_pslog("simulate", *SHORT, "--distractor", f"cam1={point}", "-o", tmp_path / "s.mcap")
    assert_one_line_error(run, 2, contains=("--distractor", "not in camera cam1's view"))
    assert not list(tmp_path.iterdir())


def test_sync_on_a_session_with_a_distractor_chooses_the_ball_first(cli, tmp_path):
    """With each frame's best-scored candidate a distractor in every frame made sync fail,
    blaming the ball's motion ("the ball needs to move more"); sync now gates the candidates
    as fuse does, says how many it rejected, and writes its copy."""
    session = tmp_path / "s.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--spurious", "0.5", "--distractor",
                       "0,0,0", "-o", session)
    assert code == 0, err
    code, out, err = cli("sync", session, "-o", tmp_path / "y.mcap")
    assert code == 0, err
    assert "candidates rejected by gating" in out
    assert (tmp_path / "y.mcap").exists()
