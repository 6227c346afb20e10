"""Session 38's hostile-input sweep of the commands recent sessions touched, through the real
CLI on real files. ``pslog sync`` refused a session whose ball lies still longer than it
moves (``pslog simulate --rest``, a robot-soccer ball on its spot before the kick) with "the
ball barely moves", the median of its speed, although its moving stretch holds the clocks.
The rest are messages that did not name the problem (``--estimate`` lists, ``fuse``'s
no-point line when the gating had rejected the detections, ``import`` of a tracks export,
an empty file or a CSV given as a session, ``readout=shared`` without shared models), a
file shown as nothing without a word (``view`` of a synced copy; ``recover`` losing a
synced session's clocks), a standard output closed at the start (exit 0, nothing printed)
and a traceback (``view --thin-every 1e23``)."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def rest_start(tmp_path_factory) -> Path:
    """A throw after 3 s of rest (the ball still at 2/3 of the detections), cam2's clock 4 ms
    and cam3's -6 ms off."""
    folder = tmp_path_factory.mktemp("sweep38")
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                     "--rest", "3", "--noise-px", "0.3", "--clock-offset", "cam2=4",
                     "--clock-offset", "cam3=-6", "--seed", "38001", "-o", "rest.mcap",
                     cwd=folder)
    assert done.code == 0, done.stderr
    return folder


def test_sync_estimates_the_clocks_of_a_ball_still_most_of_the_session(rest_start, tmp_path):
    before = fingerprint(rest_start)
    run = run_pslog("sync", rest_start / "rest.mcap", "--estimate", "offset", "--json", "-o",
                    tmp_path / "synced.mcap")
    assert run.code == 0, run.stderr
    cameras = {c["name"]: c for c in json.loads(run.stdout)["cameras"]}
    for name, truth_ms in (("cam2", 4.0), ("cam3", -6.0)):
        clock = cameras[name]
        assert abs(clock["offset_s"] * 1e3 - truth_ms) < 4 * clock["offset_std_s"] * 1e3, clock
        assert clock["offset_std_s"] < 1e-3, clock  # the throw determines them
    assert (tmp_path / "synced.mcap").stat().st_size > 0
    assert_untouched(before, rest_start)


def test_sync_still_refuses_a_ball_that_never_moves_naming_the_moving_detections(tmp_path):
    """3 s of rest and a throw's first 0.05 s: still refused, in one line that says how few
    detections see the ball move."""
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                     "--duration", "0.05", "--rest", "3", "--noise-px", "0.3",
                     "--seed", "38002", "-o", tmp_path / "still.mcap")
    assert done.code == 0, done.stderr
    run = run_pslog("sync", tmp_path / "still.mcap", "-o", tmp_path / "synced.mcap")
    line = assert_one_line_error(run, 1, contains="the ball barely moves")
    moving = re.search(r"faster than 0\.5 m/s at (\d+) of \d+ detections, sync needs 30",
                       line)
    assert moving and int(moving.group(1)) < 30, line
    assert not (tmp_path / "synced.mcap").exists()


@pytest.mark.parametrize("command", ["sync", "batch"])
@pytest.mark.parametrize("estimate, says", [
    ("offset,readout=bogus", "unknown item 'readout=bogus'"),
    ("offsett,drif", "unknown items 'offsett', 'drif'"),
    ("offset,readout,readout=shared", "names both readout and readout=shared"),
    ("auto,offset", "'auto' stands alone"),
    (",", "no parameter named")])
def test_a_bad_estimate_list_names_its_bad_item(rest_start, tmp_path, command, estimate,
                                                says):
    """Each refusal said the same "'auto', or name parameters among offset, drift, readout",
    for a list that named only those (``readout`` with ``readout=shared``) too."""
    before = fingerprint(rest_start)
    args = (("sync", rest_start / "rest.mcap", "-o", tmp_path / "s.mcap") if command == "sync"
            else ("batch", f"{rest_start}/*.mcap", "--do", "sync", "-o", tmp_path / "out"))
    run = run_pslog(*args, "--estimate", estimate)
    assert_one_line_error(run, 2, contains=(f"--estimate: {estimate!r}: {says}",))
    assert not (tmp_path / "s.mcap").exists() and not (tmp_path / "out").exists()
    assert_untouched(before, rest_start)


def test_view_says_a_later_file_without_tracks_shows_nothing(rest_start, tmp_path):
    """``pslog view session.mcap synced.mcap``: the synced copy holds no track, and nothing
    of it was shown without a word (its rig's clocks neither): the user believed they saw
    it."""
    before = fingerprint(rest_start)
    copy = tmp_path / "copy of rest.mcap"
    copy.write_bytes((rest_start / "rest.mcap").read_bytes())
    out = tmp_path / "v.rrd"
    run = run_pslog("view", rest_start / "rest.mcap", copy, "--method", "nearest", "--frames",
                    "none", "--save", out)
    assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
    assert f"{copy}: holds no fused track, so nothing of it is shown" in run.stdout, run.stdout
    assert f"'pslog view \"{copy}\"'" in run.stdout, run.stdout  # (a space: quoted)
    assert out.stat().st_size > 0
    assert_untouched(before, rest_start)


def test_a_standard_output_closed_at_the_start_is_said_and_the_output_kept(rest_start,
                                                                          tmp_path):
    """``pslog eval F >&-`` (or info, sync, fuse...) printed into nothing and exited 0: the
    one product of eval lost without a word. Now as a full standard output: the command runs
    to its end, keeps its complete files and exits 1 in one line (view --stdout and live
    --jsonl said it already)."""
    before = fingerprint(rest_start)
    synced = tmp_path / "synced.mcap"
    run = run_pslog("sync", rest_start / "rest.mcap", "--estimate", "offset", "-o", synced,
                    preexec_fn=lambda: os.close(1))
    assert_one_line_error(run, 1, contains=(
        "cannot write to standard output: it is closed", f"{synced} written complete"))
    fused = tmp_path / "fused.mcap"
    run = run_pslog("fuse", synced, "--method", "nearest", "-o", fused)
    assert run.code == 0, run.stderr
    for args in (("eval", fused, "--json"), ("info", synced)):
        run = run_pslog(*args, preexec_fn=lambda: os.close(1))
        assert_one_line_error(run, 1, contains="cannot write to standard output: it is closed")
    assert_untouched(before, rest_start)


def test_recover_says_a_synced_sessions_clocks_went_with_its_metadata(rest_start, tmp_path):
    """A synced session whose metadata record is damaged: ``pslog recover`` rebuilds the rig
    from the calibration messages, which hold no clock; it said "check it" and nothing of
    the clocks, and the copy then fused with the nominal ones without a word."""
    synced = tmp_path / "synced.mcap"
    run = run_pslog("sync", rest_start / "rest.mcap", "--estimate", "offset", "-o", synced)
    assert run.code == 0, run.stderr
    data = bytearray(synced.read_bytes())
    data[400] ^= 0xFF  # inside the session metadata record's strings (it has no CRC)
    damaged = tmp_path / "damaged.mcap"
    damaged.write_bytes(bytes(data))
    fixed = tmp_path / "fixed.mcap"
    run = run_pslog("recover", damaged, "-o", fixed)
    assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
    line = next(x for x in run.stdout.splitlines() if "session metadata" in x)
    assert "lost with it: the clocks pslog sync estimated" in line, line
    assert f"run 'pslog sync {fixed} -o SYNCED.mcap' again" in line, line
    shown = run_pslog("rig", "show", fixed)
    assert shown.code == 0 and "clock_offset" not in shown.stdout  # (what it says: gone)


@pytest.mark.parametrize("every, code", [("99999999999999999999999", 2), ("1000000001", 2),
                                          ("1000000000", 0)])
def test_view_thin_every_beyond_an_int64_bucket_is_refused(rest_start, tmp_path, every, code):
    """``view --thin-every 99999999999999999999999`` was a traceback (OverflowError: the
    thinning bucket, every × a frame period in ns, no int64 holds); bounded as
    ``--frames every:N`` is."""
    before = fingerprint(rest_start)
    out = tmp_path / "v.rrd"
    run = run_pslog("view", rest_start / "rest.mcap", "--method", "nearest", "--frames",
                    "none", "--thin-every", every, "--save", out)
    if code:
        assert_one_line_error(run, 2, contains=(
            "--thin-every: the thinning factor must be a whole number from 1 to 1000000000, "
            f"got {every}"))
        assert not out.exists()
    else:
        assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
        assert out.stat().st_size > 0
    assert_untouched(before, rest_start)


def test_fuse_says_the_gating_rejected_the_detections_a_point_lacked(tmp_path):
    """Two detections 11 ms apart whose rays disagree (a rig or calibration off): no point,
    said as "too few detections close enough in time" alone, which sends a user to the
    clocks; the gating had rejected the second, and --gating off fuses it."""
    (tmp_path / "det.csv").write_text("camera,time,u,v\ncam1,0.0,320,240\n"
                                      "cam2,0.011,300,250\n")
    run = run_pslog("import", "--rig", "paper3", "--timing", "typeA", "--detections",
                    "det.csv", "-o", "s.mcap", cwd=tmp_path)
    assert run.code == 0, run.stderr
    run = run_pslog("fuse", "s.mcap", "--method", "nearest", "-o", "f.mcap", cwd=tmp_path)
    assert_one_line_error(run, 1, contains="no fusion method produced a point")
    assert ("no point from nearest: too few detections close enough in time once the gating "
            "rejected 1 candidate (epipolar 1; --gating off: each frame's best-scored "
            "candidate)") in run.stdout, run.stdout
    assert not (tmp_path / "f.mcap").exists()
    run = run_pslog("fuse", "s.mcap", "--method", "nearest", "--gating", "off", "-o",
                    "f.mcap", cwd=tmp_path)
    assert run.code == 0 and "nearest        1 points" in run.stdout, run.stdout + run.stderr


def test_import_names_a_tracks_export_or_json_given_as_detections(rest_start, tmp_path):
    """``pslog export --csv``'s tracks (or ``--jsonl``'s lines) given to ``pslog import``
    were "bad header '<the whole first line>' ... (unknown: <every column>)": the JSON
    line's message ran to hundreds of characters, twice over, and neither said what the
    file is."""
    fused = tmp_path / "fused.mcap"
    run = run_pslog("fuse", rest_start / "rest.mcap", "--method", "nearest", "-o", fused)
    assert run.code == 0, run.stderr
    run = run_pslog("export", fused, "--csv", tmp_path / "t.csv", "--jsonl", tmp_path / "t.jsonl")
    assert run.code == 0, run.stderr
    for name, says in (("t.csv", "holds fused tracks (time,x,y,z,camera,method: 'pslog "
                                 "export --csv'), not detections"),
                       ("t.jsonl", "holds JSON, not a detections CSV")):
        run = run_pslog("import", "--rig", "paper3", "--detections", tmp_path / name, "-o",
                        tmp_path / "s.mcap")
        line = assert_one_line_error(run, 1, contains=f"{tmp_path / name} {says}")
        assert len(line) < 300, line
    (tmp_path / "wide.csv").write_text(",".join(f"c{i}" for i in range(5000)) + "\n")
    run = run_pslog("import", "--rig", "paper3", "--detections", tmp_path / "wide.csv", "-o",
                    tmp_path / "s.mcap")
    line = assert_one_line_error(run, 1, contains=("line 1: bad header", "c9, ...)"))
    assert len(line) < 600, line
    assert not (tmp_path / "s.mcap").exists()


@pytest.mark.parametrize("command", [("sync", "-o", "out.mcap"), ("fuse", "-o", "out.mcap"),
                                     ("eval",), ("info",), ("view", "--save", "out.rrd"),
                                     ("recover", "-o", "out.mcap")])
def test_an_empty_file_or_a_csv_given_as_a_session_is_named_for_what_it_is(tmp_path,
                                                                          command):
    """A 0-byte file (a recording killed before its first write), the detections CSV a
    session was imported from and a tracks export were each "not an MCAP file: P"."""
    (tmp_path / "empty.mcap").write_bytes(b"")
    (tmp_path / "det.csv").write_text("\ufeffcamera,time,u,v\ncam1,0.0,320,240\n")
    (tmp_path / "tracks.csv").write_text("time,x,y,z,camera,method\n0.1,1,2,3,cam1,typeA\n")
    before = fingerprint(tmp_path)
    name, *rest = command
    for given, says in (("empty.mcap", "empty.mcap is empty (0 bytes): not an MCAP session"),
                        ("det.csv", "det.csv is a detections CSV, not an MCAP session "
                                    "('pslog import --rig RIG --detections det.csv -o "
                                    "SESSION.mcap' makes one)"),
                        ("tracks.csv", "tracks.csv is a CSV of fused tracks ('pslog export "
                                       "--csv'), not an MCAP session")):
        run = run_pslog(name, given, *rest, cwd=tmp_path)
        assert_one_line_error(run, 1, contains=f"pslog {name}: error: {says}")
    assert_untouched(before, tmp_path)


def test_sync_readout_shared_says_which_cameras_share_one(tmp_path):
    """``--estimate readout=shared`` on a rig whose cameras are each a model of their own
    (frame rates 30, 25, 60) said "its cameras share the value" beside three readouts."""
    shown = run_pslog("rig", "show", "paper3", "--timing", "sync")
    assert shown.code == 0, shown.stderr
    head, cam1, cam2, cam3 = shown.stdout.split("[[camera]]")
    cam2, cam3 = cam2.replace("fps = 30.0", "fps = 25.0"), cam3.replace("fps = 30.0",
                                                                       "fps = 60.0")
    (tmp_path / "rig.toml").write_text("[[camera]]".join((head, cam1, cam2, cam3)))
    run = run_pslog("simulate", "--rig", "rig.toml", "--motion", "rally", "--duration", "4",
                    "--noise-px", "0.3", "--readout", "15", "--seed", "38003", "-o", "s.mcap",
                    cwd=tmp_path)
    assert run.code == 0, run.stderr
    run = run_pslog("sync", "s.mcap", "--estimate", "readout=shared", "-o", "y.mcap",
                    cwd=tmp_path)
    assert run.code == 0, run.stderr
    assert ("readouts: one per camera model (readout=shared), and no two cameras here are "
            "of one model (image size and frame rate): one readout per camera, as readout "
            "estimates") in run.stdout, run.stdout
    assert "its cameras share the value" not in run.stdout
