"""The fusion commands on real files: fuse -> export --csv -> eval, and pslog paper."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog import apply_timing, get_motion, simulate
from pslog.evaluation import evaluate
from pslog.fusion import fuse_all
from pslog.log import read_session
from pslog.records import NS


def test_fuse_export_eval_round_trip(tmp_path, sim_session, cli):
    fused = tmp_path / "fused.mcap"
    code, out, err = cli("fuse", sim_session.path, "--method", "typeA", "--method", "nearest",
                         "-o", fused)
    assert code == 0, err
    assert "typeA" in out and "nearest" in out

    session = read_session(fused)
    assert set(session.tracks) == {"typeA", "nearest"}
    expected = fuse_all(sim_session.detections, sim_session.rig, ["typeA", "nearest"])
    for method, track in expected.items():
        got = session.tracks[method]
        assert_array_equal(got.time_ns, track.time_ns)
        assert_allclose(got.position_world, track.position_world, rtol=0, atol=0)
        assert_array_equal(got.camera, track.camera)
        assert_allclose(got.quality["snap_px" if method == "typeA" else "ray_miss_m"],
                        track.quality["snap_px" if method == "typeA" else "ray_miss_m"])
    # the copy keeps the session: detections and truth unchanged
    assert_array_equal(session.detections.cand_uv, sim_session.detections.cand_uv)
    assert_array_equal(session.truth.position_world, sim_session.truth.position_world)

    out_csv = tmp_path / "tracks.csv"
    code, _, err = cli("export", fused, "--csv", out_csv)
    assert code == 0, err
    with open(out_csv, newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0])[:6] == ["time", "x", "y", "z", "camera", "method"]
    type_a = [r for r in rows if r["method"] == "typeA"]
    track = expected["typeA"]
    assert len(type_a) == len(track)
    # seconds on the session clock, as `pslog import` reads them; metres
    assert_allclose([float(r["time"]) for r in type_a], track.time_ns / NS, atol=1e-9)
    assert_allclose([[float(r[k]) for k in "xyz"] for r in type_a], track.position_world,
                    rtol=0, atol=1e-15)
    assert {r["camera"] for r in type_a} == set(sim_session.rig.names)

    code, out, err = cli("eval", fused, "--json")
    assert code == 0, err
    report = {r["method"]: r for r in json.loads(out)}
    for method, track in expected.items():
        accuracy = evaluate(track, sim_session.truth)
        assert report[method]["mean_mm"] == accuracy.mean_mm
        assert report[method]["rate_hz"] == accuracy.rate_hz
    assert report["nearest"]["mean_mm"] > 3 * report["typeA"]["mean_mm"]
    code, out, _ = cli("eval", fused)
    assert code == 0 and "mean mm" in out and "typeA" in out


def test_fuse_defaults_to_every_applicable_method(tmp_path, sim_session, cli):
    code, out, err = cli("fuse", sim_session.path, "-o", tmp_path / "all.mcap")
    assert code == 0, err
    assert "not run on this timing: sync, typeB, linear" in out
    assert set(read_session(tmp_path / "all.mcap").tracks) == {"typeA", "nearest", "smooth",
                                                                "filter"}


def test_default_methods_follow_the_timing(tmp_path, cli):
    from pslog import builtin_rig
    from pslog.fusion import default_methods

    expected = {"sync": ["sync", "smooth", "filter"],
                "typeA": ["nearest", "typeA", "smooth", "filter"],
                "typeB": ["sync", "nearest", "typeA", "typeB", "linear", "smooth", "filter"]}
    for timing, methods in expected.items():
        rig = apply_timing(builtin_rig("paper3"), timing)
        detections, _ = simulate(rig, get_motion("fall"))
        assert default_methods(detections, rig) == methods, timing
    # on sync timing, the rate counts instants, not the points several cameras give at one
    path = tmp_path / "sync.mcap"
    assert cli("simulate", "--rig", "paper3", "--timing", "sync", "-o", path)[0] == 0
    code, _, err = cli("fuse", path, "--method", "typeA", "--method", "sync",
                       "-o", tmp_path / "f.mcap")
    assert code == 0, err
    report = {r["method"]: r for r in json.loads(cli("eval", tmp_path / "f.mcap", "--json")[1])}
    assert abs(report["sync"]["rate_hz"] - 30.0) < 0.1
    assert abs(report["typeA"]["rate_hz"] - 30.0) < 0.1


def test_fuse_without_detections_is_an_error(tmp_path, sim_session, cli):
    from pslog.log import SessionWriter
    from pslog.records import Detections

    empty = tmp_path / "empty.mcap"
    with SessionWriter(empty, sim_session.rig) as writer:
        d = sim_session.detections
        writer.add_detections(Detections.from_frames(
            d.camera_names, d.frame_time_ns, d.frame_camera, d.frame_index, [], np.zeros((0, 2))))
    code, _, err = cli("fuse", empty, "-o", tmp_path / "f.mcap")
    assert code == 1 and "no detection to fuse" in err
    assert not (tmp_path / "f.mcap").exists()


def test_fuse_refuses_impossible_methods_and_existing_output(tmp_path, sim_session, cli,
                                                            capsys):
    code, _, err = cli("fuse", sim_session.path, "--method", "sync", "-o", tmp_path / "x.mcap")
    assert code == 1 and "needs cameras with a common shutter instant" in err
    assert "Traceback" not in err
    assert not (tmp_path / "x.mcap").exists()
    with pytest.raises(SystemExit) as exit_info:  # a bad command-line value: argparse, exit 2
        cli("fuse", sim_session.path, "--method", "typeC", "-o", tmp_path / "x.mcap")
    assert exit_info.value.code == 2
    assert "unknown fusion method 'typeC'" in capsys.readouterr().err
    existing = tmp_path / "exists.mcap"
    existing.write_bytes(b"keep me")
    code, _, err = cli("fuse", sim_session.path, "--method", "typeA", "-o", existing)
    assert code == 1 and "--force" in err
    assert existing.read_bytes() == b"keep me"
    code, _, err = cli("fuse", sim_session.path, "--method", "typeA", "-o", existing, "--force")
    assert code == 0 and "typeA" in read_session(existing).tracks


def test_eval_needs_truth_and_tracks(tmp_path, sim_session, cli):
    code, _, err = cli("eval", sim_session.path)
    assert code == 1 and "no fused tracks" in err
    code, _, err = cli("eval", tmp_path / "missing.mcap")
    assert code == 1 and "missing.mcap" in err


def test_paper_tables(cli):
    code, out, _ = cli("paper", "table1", "--json")
    assert code == 0
    rows = json.loads(out)["rows"]
    assert len(rows) == 6
    by_key = {(r["cameras"], r["method"]): r for r in rows}
    assert abs(by_key[(3, "typeA")]["fps"] - 90.0) < 1e-6
    assert by_key[(2, "sync")]["error_mm"]["spiral"] < 1e-6
    assert by_key[(3, "typeA")]["paper_mm"]["straight"] == 1.1
    code, out, _ = cli("paper", "table1")
    assert code == 0 and "unsynchronized" not in out and "nearest" in out
    code, out, _ = cli("paper", "table2", "--json", "--noise-px", "0.5")
    assert code == 0
    table2 = {r["method"]: r for r in json.loads(out)["rows"]}
    assert table2["typeB"]["var_z_mm2"] < table2["typeA"]["var_z_mm2"]
    assert abs(table2["typeA"]["mean_z_mm"] - 660.0) < 5.0
    assert np.isclose(table2["typeB"]["paper_var_z_mm2"], 112.0)


def test_fuse_with_a_corrected_rig(tmp_path, sim_session, cli):
    """Re-fuse with corrected calibration, without re-recording: the session was recorded with
    a camera 2 cm off its true place; the corrected rig brings the error back down."""
    from pslog.log import SessionWriter
    from pslog.rig import Rig, save_rig

    true_rig = sim_session.rig
    wrong = Rig(tuple(c.replace(t=c.t + np.array([0.02, 0.0, 0.0])) if c.name == "cam2" else c
                      for c in true_rig.cameras), true_rig.name)
    recorded = tmp_path / "miscalibrated.mcap"
    with SessionWriter(recorded, wrong, timing="typeA") as writer:
        writer.add_detections(sim_session.detections)
        writer.add_truth(sim_session.truth)
    corrected = tmp_path / "corrected.toml"
    save_rig(true_rig, corrected)

    assert cli("fuse", recorded, "--method", "typeA", "-o", tmp_path / "a.mcap")[0] == 0
    code, _, err = cli("fuse", recorded, "--method", "typeA", "--rig", corrected,
                       "-o", tmp_path / "b.mcap")
    assert code == 0, err
    before, after = read_session(tmp_path / "a.mcap"), read_session(tmp_path / "b.mcap")
    assert after.rig == true_rig and before.rig == wrong
    error_before = evaluate(before.tracks["typeA"], sim_session.truth).mean_mm
    error_after = evaluate(after.tracks["typeA"], sim_session.truth).mean_mm
    assert error_after < 0.5 * error_before
    expected = fuse_all(sim_session.detections, true_rig, ["typeA"])["typeA"]
    assert_array_equal(after.tracks["typeA"].position_world, expected.position_world)

    other = tmp_path / "other.toml"
    save_rig(true_rig.subset(["cam1", "cam2"]), other)
    code, _, err = cli("fuse", recorded, "--rig", other, "-o", tmp_path / "c.mcap")
    assert code == 1 and "names and order must match" in err
    assert not (tmp_path / "c.mcap").exists()


def test_fuse_with_a_rig_of_other_offsets_relabels_the_timing(tmp_path, sim_session, cli):
    from pslog.rig import apply_timing, save_rig

    save_rig(apply_timing(sim_session.rig, "sync"), tmp_path / "sync.toml")
    code, _, err = cli("fuse", sim_session.path, "--method", "nearest", "--rig",
                       tmp_path / "sync.toml", "-o", tmp_path / "f.mcap")
    assert code == 0, err
    fused = read_session(tmp_path / "f.mcap")
    assert fused.timing == "sync" and all(c.offset == 0 for c in fused.rig.cameras)
    assert cli("fuse", sim_session.path, "--method", "nearest", "-o", tmp_path / "g.mcap")[0] == 0
    assert read_session(tmp_path / "g.mcap").timing == "typeA"


def test_fuse_tolerance_of_a_third_of_a_period_is_a_usage_error(tmp_path, sim_session, cli):
    code, _, err = cli("fuse", sim_session.path, "--tolerance-ms", "12", "-o", tmp_path / "f.mcap")
    assert code == 2 and "argument --tolerance-ms" in err and "third of the frame period" in err
    assert not (tmp_path / "f.mcap").exists()
    code, _, err = cli("fuse", sim_session.path, "--tolerance-ms", "11", "--method", "sync",
                       "-o", tmp_path / "f.mcap")
    assert code == 1 and "no two cameras captured within 11 ms" in err  # type A: no instants


def test_points_before_the_session_clocks_zero_are_left_out_saying_so(tmp_path, cli):
    """cam3's clock 12 ms behind camera 1's, its first frame logged at 12 ms; a rig that puts
    it 12.5 ms behind (an estimate 0.5 ms off, as `sync` gives) moves that frame to -0.5 ms,
    which a session cannot store. The fuse says so and writes the rest (it used to fail
    after the work)."""
    from pslog.rig import Rig, save_rig

    session = tmp_path / "late.mcap"
    code, _out, err = cli("simulate", "--rig", "paper3", "--motion", "rally", "--duration",
                          "1", "--noise-px", "0.3", "--clock-offset", "cam3=-12", "-o", session)
    assert code == 0, err
    cams = read_session(session).rig.cameras
    save_rig(Rig((*cams[:2], cams[2].replace(clock_offset=-0.0125))), tmp_path / "true.toml")
    fused = tmp_path / "f.mcap"
    code, out, err = cli("fuse", session, "--rig", tmp_path / "true.toml", "--method", "smooth",
                         "-o", fused)
    assert code == 0, err
    assert "before the session clock's zero" in out and "smooth point" in out
    track = read_session(fused).tracks["smooth"]
    assert len(track) > 0 and track.time_ns.min() >= 0


def test_eval_says_what_each_left_out_reason_means(tmp_path, cli):
    # a dirty session: every method leaves points out; eval's legend names each reason it
    # shows (the reasons are the methods' own Track.dropped keys)
    from pslog.evaluation import LEFT_OUT_TEXT, NOT_SCORED_TEXT

    session, fused = tmp_path / "dirty.mcap", tmp_path / "fused.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                       "rally", "--duration", "5", "--noise-px", "0.5", "--miss-rate", "0.2",
                       "--spurious", "0.05", "--seed", "5", "-o", session)
    assert code == 0, err
    code, _, err = cli("fuse", session, "-o", fused, "--method", "nearest,typeA,smooth,filter")
    assert code == 0, err
    code, out, err = cli("eval", fused)
    assert code == 0, err
    # (", and points written but not scored" when a method wrote a point eval cannot score)
    block = re.split(r"points left out \(invalid or untrustworthy\)(?:, and points written "
                     r"but not scored)?, by reason:\n", out)[1]
    lines = block.split("\n\n")[0].splitlines()
    counts = [line for line in lines if not line.startswith("  ")]
    # (a method's points eval could not score follow its left-out ones: "; not scored: ...")
    reasons = {part.rsplit(" ", 1)[0] for line in counts
               for part in line[10:].split("; not scored: ")[0].split(", ")}
    assert reasons and reasons <= set(LEFT_OUT_TEXT), reasons - set(LEFT_OUT_TEXT)
    unscored = {part.rsplit(" ", 1)[0] for line in counts if "; not scored: " in line
                for part in line.split("; not scored: ")[1].split(", ")}
    assert unscored <= set(NOT_SCORED_TEXT), unscored - set(NOT_SCORED_TEXT)
    assert sorted(line for line in lines if line.startswith("  ")) == sorted(
        [f"  {reason}: {LEFT_OUT_TEXT[reason]}" for reason in reasons]
        + [f"  {reason}: {NOT_SCORED_TEXT[reason]}" for reason in unscored])


def test_eval_accounts_for_every_point_the_fuse_wrote(tmp_path, cli):
    """A rolling shutter the rig does not know of (no `pslog sync`): camera 1 reads the
    ball's row milliseconds after its frame's time, so `smooth`'s point at the first
    detection's time lies before the truth's first sample, where eval cannot interpolate
    the truth. Eval scores the rest and names that point with its reason: the points it
    scored and those it could not add up to what the fuse said it wrote."""
    from pslog.evaluation import NOT_SCORED_TEXT, unscored_counts
    from pslog.records import Truth

    session, fused = tmp_path / "rolling.mcap", tmp_path / "fused.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                       "throw", "--readout", "10", "--seed", "13", "-o", session)
    assert code == 0, err
    code, out, err = cli("fuse", session, "-o", fused)
    assert code == 0, err
    written = {line.split()[0]: int(line.split()[1]) for line in out.splitlines()
               if line.split()[2:3] == ["points"]}
    fused_session = read_session(fused)
    tracks, truth = fused_session.tracks, fused_session.truth
    assert written == {m: len(t) for m, t in tracks.items()}
    code, out, err = cli("eval", fused, "--json")
    assert code == 0, err
    report = {r["method"]: r for r in json.loads(out)}
    for method, n in written.items():
        assert report[method]["n_points"] + sum(report[method]["not_scored"].values()) == n
    smooth = tracks["smooth"]
    before = int(np.count_nonzero(smooth.time_ns < truth.time_ns[0]))
    assert before >= 1 and report["smooth"]["not_scored"] == {"outside_truth": before}
    assert report["smooth"]["n_points"] == len(smooth) - before

    code, out, err = cli("eval", fused)
    assert code == 0, err
    block = out.split("points left out (invalid or untrustworthy), and points written but "
                      "not scored, by reason:\n")[1].split("\n\n")[0]
    assert f"smooth    not scored: outside_truth {before}" in block.splitlines()
    assert f"  outside_truth: {NOT_SCORED_TEXT['outside_truth']}" in block.splitlines()

    # the other reasons, on the same track: a gap in the truth, a point not finite
    position = truth.position_world.copy()
    inside = np.flatnonzero(smooth.time_ns >= truth.time_ns[0])
    sample = np.searchsorted(truth.time_ns, smooth.time_ns[inside[5]])
    position[sample] = np.nan  # the truth's gap: the points interpolated from this sample
    gapped = Truth(truth.time_ns, position)
    gap = int(np.count_nonzero(~np.isfinite(gapped.at(smooth.time_ns[inside])).all(axis=1)))
    assert 1 <= gap <= 2
    assert unscored_counts(smooth, gapped) == {"outside_truth": before, "truth_gap": gap}
    assert unscored_counts(smooth, None) == {}
    from dataclasses import replace

    position = smooth.position_world.copy()
    position[inside[-1]] = np.nan
    assert unscored_counts(replace(smooth, position_world=position), truth) == {
        "outside_truth": before, "not_finite": 1}


def test_eval_says_what_contradicted_means_under_the_default_kick_test(tmp_path, cli):
    """`pslog fuse`'s default typeA confirmation (--confirm-gaps jumps, session 45; kicks,
    session 35, whose side test it includes) leaves a
    point out as contradicted when another camera's track around it, on its side of a kick,
    shows the ball elsewhere; eval's legend said only the older test's 'the next camera's
    detection contradicts it', which a new user of the default could not match."""
    session, fused = tmp_path / "rally.mcap", tmp_path / "fused.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                       "rally", "--noise-px", "0.3", "--seed", "45003", "-o", session)
    assert code == 0, err
    code, out, err = cli("fuse", session, "--method", "typeA", "-o", fused)
    assert code == 0, err
    assert "contradicted" in out, out
    code, out, err = cli("eval", fused)
    assert code == 0, err
    legend = [line for line in out.splitlines() if line.startswith("  contradicted: ")]
    assert len(legend) == 1, out
    assert "jumps, the default, and kicks" in legend[0] and "kick the track shows" in legend[0], \
        legend


def test_eval_help_text_names_not_scored(capsys):
    """A new user compares eval's points with the fuse's: the help says they are the
    scored ones, and where the rest are listed."""
    from pslog.cli import main

    with pytest.raises(SystemExit) as exit_info:
        main(["eval", "--help"])
    assert exit_info.value.code == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "the points the truth can score" in text and "not scored" in text, text
