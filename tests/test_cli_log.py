"""Tests of the session-log commands: simulate, import, export, info, recover, bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from decimal import Decimal

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from pslog.log import SessionWriter, copy_session, read_session
from pslog.records import NS, Track
from pslog.rig import apply_timing, builtin_rig, save_rig


# ---- simulate ---------------------------------------------------------------------------------
def test_simulate_writes_detections_truth_rig_and_metadata(tmp_path, cli):
    out = tmp_path / "session.mcap"
    code, stdout, stderr = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                               "spiral", "--duration", "1.2", "--noise-px", "0.0", "--seed", "0",
                               "-o", out)
    assert code == 0, stderr
    assert len(stdout.strip().splitlines()) == 1 and "108 frames" in stdout
    s = read_session(out)
    assert s.timing == "typeA" and s.rig.names == ("cam1", "cam2", "cam3")
    assert_allclose([c.offset for c in s.rig.cameras], [0, 1 / 90, 2 / 90])
    assert s.detections.n_frames == 108 and s.truth is not None and len(s.truth) == 108
    assert s.metadata["simulate.motion"] == "spiral" and s.metadata["simulate.seed"] == "0"
    # noise-free: every candidate is the exact projection of the truth
    det = s.detections
    obs = det.best()
    for i, cam in enumerate(s.rig.cameras):
        rows = obs.camera == i
        uv, _ = cam.project(s.truth.at(obs.time_ns[rows]))
        assert_allclose(obs.uv[rows], uv, atol=1e-9)

    code, _, stderr = cli("simulate", "--rig", "paper3", "-o", out)
    assert code == 1 and "exists" in stderr and "--force" in stderr


def test_simulate_clock_faults_keep_the_nominal_rig_and_store_the_truth(tmp_path, cli):
    from pslog.simulation import read_truth_clock
    from pslog.timing import observations

    out = tmp_path / "f.mcap"
    code, stdout, stderr = cli(
        "simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
        "--clock-offset", "cam2=3.5", "--clock-offset", "cam3=-1.25", "--drift", "cam3=40",
        "--readout", "20", "--readout", "cam2=25", "--host-jitter", "0", "-o", out)
    assert code == 0, stderr
    assert "run 'pslog sync'" in stdout
    s = read_session(out)
    nominal = apply_timing(builtin_rig("paper3"), "typeA")
    assert s.rig == nominal  # nominal clock: zeros
    assert s.timing == "typeA"
    truth_rig = read_truth_clock(s.rig, s.metadata)
    got = [(c.clock_offset, c.clock_drift_ppm, c.readout) for c in truth_rig.cameras]
    assert got == [(0.0, 0.0, 0.02), (0.0035, 0.0, 0.025), (-0.00125, 40.0, 0.02)]
    assert json.loads(s.metadata["truth_clock"])["host_jitter_s"] == 0.0
    # the true clock makes the detections land on the truth (noise-free), the nominal not
    good = observations(s.detections, truth_rig)
    near = np.abs(s.truth.time_ns[np.searchsorted(s.truth.time_ns, good.time_ns) - 1]
                  - good.time_ns) <= 1
    near |= np.isin(good.time_ns, s.truth.time_ns)
    assert near.all()
    assert not np.isin(s.detections.best().time_ns, s.truth.time_ns).all()


@pytest.mark.parametrize("args, message", [
    (["--clock-offset", "cam1=2"], "argument --clock-offset: camera 'cam1' is the first of "
                                   "the rig and defines the session clock"),
    (["--drift", "cam1=10"], "argument --drift: camera 'cam1' is the first"),
    (["--clock-offset", "cam7=2"], "argument --clock-offset: clock_offset for unknown camera "
                                   "'cam7' (rig has cam1, cam2, cam3)"),
    (["--clock-offset", "cam2"], "expected CAM=MS"),
    (["--clock-offset", "cam2=nan"], "must be a finite number"),
    (["--clock-offset", "=3"], "no camera name before '='"),
    (["--drift", "cam2=2000"], "argument --drift: camera 'cam2': clock_drift_ppm 2000 is "
                               "beyond"),
    (["--readout", "40"], "argument --readout: camera 'cam1': readout 0.04 s must be in "
                          "[0, 0.0333333 s)"),
    (["--readout", "cam2=-1"], "argument --readout: camera 'cam2': readout -0.001 s"),
    (["--host-jitter", "20"], "argument --host-jitter: host jitter 0.02 s must be below half "
                              "a frame period"),
    (["--host-jitter", "-1"], "argument --host-jitter: must be a number >= 0"),
])
def test_simulate_bad_fault_values_exit_2_in_one_line(tmp_path, cli, capsys, args, message):
    out = tmp_path / "f.mcap"
    try:
        code, _, stderr = cli("simulate", "--rig", "paper3", *args, "-o", out)
    except SystemExit as exc:  # refused by argparse itself: exit 2 too
        code, stderr = exc.code, capsys.readouterr().err
    assert code == 2, stderr
    assert message in stderr and len(stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_simulate_with_rig_timing_and_imperfections(tmp_path, cli):
    rig_path = tmp_path / "rig.toml"
    rig = builtin_rig("paper2")
    rig = type(rig)(tuple(c.replace(offset=0.005 * i) for i, c in enumerate(rig.cameras)), "r")
    save_rig(rig, rig_path)
    out = tmp_path / "s.mcap"
    code, _, stderr = cli("simulate", "--rig", rig_path, "--timing", "rig", "--motion",
                               "throw", "--jitter-ms", "0.5", "--drop-rate", "0.1",
                               "--miss-rate", "0.2", "--noise-px", "0.5", "--seed", "4",
                               "-o", out)
    assert code == 0, stderr
    s = read_session(out)
    assert s.timing == "custom" and s.rig.to_toml() == rig.to_toml()
    assert (s.detections.frame_time_ns >= 0).all()
    assert 0 < s.detections.n_candidates < s.detections.n_frames < 2 * 46


# ---- info ----------------------------------------------------------------------------------
def test_info_text_and_json(sim_session, cli):
    code, stdout, stderr = cli("info", sim_session.path)
    assert code == 0, stderr
    for text in ("cam1", "cam3", "/truth", "timing typeA", "11.111 ms", "22.222 ms"):
        assert text in stdout
    code, stdout, _ = cli("info", sim_session.path, "--json")
    info = json.loads(stdout)
    assert info["frames"] == sim_session.detections.n_frames
    assert info["topics"]["/camera/cam2/detections"] == int(
        np.count_nonzero(sim_session.detections.frame_camera == 1))
    assert info["truth"] is True and info["tracks"] == {}


def test_info_on_truncated_file_points_to_recover(sim_session, tmp_path, cli):
    data = sim_session.path.read_bytes()
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(data[: len(data) // 2])
    code, stdout, stderr = cli("info", broken)
    assert code == 1
    assert "TRUNCATED" in stdout and "pslog recover" in stderr
    assert stderr.count("\n") == 1 and "Traceback" not in stderr


def test_info_on_a_recent_truncated_file_says_it_may_still_be_recording(sim_session, tmp_path,
                                                                        cli):
    import os

    data = sim_session.path.read_bytes()
    live = tmp_path / "live.mcap"
    live.write_bytes(data[: len(data) // 2])  # just written: as a recorder leaves it
    code, stdout, stderr = cli("info", live)
    assert code == 1 and "TRUNCATED or still being written" in stdout
    assert "may still be recording" in stderr and "pslog recover" in stderr
    old = os.stat(live).st_mtime - 600
    os.utime(live, (old, old))
    code, stdout, stderr = cli("info", live)
    assert code == 1 and "may still" not in stdout + stderr
    assert "did not finish" in stderr


@pytest.mark.parametrize("timing", ["sync", "typeB"])
def test_info_shows_signed_offsets_next_to_the_rigs(tmp_path, cli, timing):
    """Jittered sync/typeB shutters: measured offsets near the rig's (never ~33.3 ms), the
    rig's offsets as they are, the timing label beside them."""
    out = tmp_path / "s.mcap"
    code, _, stderr = cli("simulate", "--rig", "paper3", "--timing", timing, "--jitter-ms", "0.5",
                          "--seed", "4", "-o", out)
    assert code == 0, stderr
    code, stdout, stderr = cli("info", out, "--json")
    assert code == 0, stderr
    info = json.loads(stdout)
    nominal = {"sync": [0.0, 0.0, 0.0], "typeB": [0.0, 1 / 60, 0.0]}[timing]
    for row, o in zip(info["cameras"], nominal, strict=True):
        assert row["offset_nominal_s"] == pytest.approx(o, abs=1e-12)
        assert abs(row["offset_measured_s"] - o) < 5e-4, row
    code, stdout, _ = cli("info", out)
    assert f"rig ({timing})" in stdout and "offset measured" in stdout and "33.3" not in stdout


# ---- recover -----------------------------------------------------------------------------------
def test_info_shows_the_clock_model_when_the_rig_has_one(sim_session, tmp_path, cli):
    code, stdout, _ = cli("info", sim_session.path)
    assert code == 0 and "clock model" not in stdout  # all zero: not shown
    rig = sim_session.rig
    synced = type(rig)((rig.cameras[0].replace(readout=0.012),
                        rig.cameras[1].replace(clock_offset=-0.00325, clock_drift_ppm=12.5),
                        rig.cameras[2]), rig.name)
    out = tmp_path / "synced.mcap"
    copy_session(sim_session.path, out, rig=synced)
    code, stdout, _ = cli("info", out)
    assert code == 0
    assert "cam1     offset +0.0000 ms, drift +0.000 ppm, readout 12.0000 ms" in stdout
    assert "cam2     offset -3.2500 ms, drift +12.500 ppm, readout 0.0000 ms" in stdout
    code, stdout, _ = cli("info", out, "--json")
    cams = json.loads(stdout)["cameras"]
    assert [(c["clock_offset_s"], c["clock_drift_ppm"], c["readout_s"]) for c in cams] == [
        (0.0, 0.0, 0.012), (-0.00325, 12.5, 0.0), (0.0, 0.0, 0.0)]


def test_recover_command(sim_session, tmp_path, cli):
    data = sim_session.path.read_bytes()
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(data[: int(len(data) * 0.7)])
    fixed = tmp_path / "fixed.mcap"
    code, stdout, stderr = cli("recover", broken, "-o", fixed)
    assert code == 0, stderr
    assert "recovered" in stdout
    s = read_session(fixed)
    assert s.detections.n_frames > 0 and s.rig.names == sim_session.rig.names
    code, _, stderr = cli("recover", broken, "-o", fixed)
    assert code == 1 and "exists" in stderr


def test_recover_and_info_report_detections_images_and_truth_separately(tmp_path, cli,
                                                                        truth_first_session):
    data, chunk_ends = truth_first_session
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(data[:chunk_ends[-2] + 20])  # inside the last detection chunk
    code, stdout, _ = cli("info", broken)
    assert code == 1
    assert ("30 detection frames (to t = 0.322 s), 60 images (to t = 0.656 s), "
            "300 truth points") in stdout
    assert "0.997" not in stdout  # the end of the truth is not where the recording stopped
    code, stdout, stderr = cli("recover", broken, "-o", tmp_path / "fixed.mcap")
    assert code == 0, stderr
    assert stdout.splitlines()[0] == (
        f"recovered into {tmp_path / 'fixed.mcap'}: 30 detection frames (to t = 0.322 s), "
        f"60 images (to t = 0.656 s), 300 truth points")

    broken.write_bytes(data[:chunk_ends[-4] + 20])  # inside the first detection chunk
    for command in ("info", "recover"):
        args = (broken, "-o", tmp_path / "fixed2.mcap") if command == "recover" else (broken,)
        code, stdout, _ = cli(command, *args)
        assert "30 images (to t = 0.322 s), 300 truth points; no detection frame survived" \
            in stdout


# ---- import / export ---------------------------------------------------------------------------
_CSV = """camera,time,u,v,frame,score
cam2,0.011111111,100.5,200.25,0,0.5
cam1,0.000000000,10.0,20.0,0,1.0
cam2,0.011111111,101.5,201.25,0,0.75
cam3,0.022222222,0.1,0.2,0,1.0
cam1,1700000000.123456789,1e-05,479.99999999999994,51,0.3333333333333333
"""


def _rows(text: str) -> set[tuple]:
    lines = text.strip().splitlines()
    return {tuple(line.split(",")) for line in lines[1:]}, lines[0]


def test_import_export_round_trip_every_row(tmp_path, cli):
    det_csv = tmp_path / "det.csv"
    det_csv.write_text(_CSV)
    out = tmp_path / "s.mcap"
    code, stdout, stderr = cli("import", "--rig", "paper3", "--detections", det_csv, "-o", out)
    assert "5 detections in 4 frames" in stdout
    assert code == 0, stderr
    s = read_session(out)
    assert s.detections.n_frames == 4 and s.detections.n_candidates == 5
    assert s.detections.frame_time_ns[-1] == 1_700_000_000_123_456_789  # exact, no float
    back = tmp_path / "back.csv"
    code, _, stderr = cli("export", out, "--detections", back)
    assert code == 0, stderr
    rows_in, header_in = _rows(_CSV)
    rows_out, header_out = _rows(back.read_text())
    assert header_out == header_in
    # floats compare by value (repr may spell them differently), everything else exactly
    parse = lambda rows: {(c, t, float(u), float(v), f, float(s)) for c, t, u, v, f, s in rows}  # noqa: E731
    assert parse(rows_out) == parse(rows_in)
    # and a second round trip is byte-identical
    again = tmp_path / "again.mcap"
    assert cli("import", "--rig", "paper3", "--detections", back, "-o", again)[0] == 0
    back2 = tmp_path / "back2.csv"
    assert cli("export", again, "--detections", back2)[0] == 0
    assert back2.read_text() == back.read_text()


_EPOCH_CSV = """camera,time,u,v,frame,score
cam1,1732912345.000123,100.5,200.25,7,1.0
cam2,1732912345.011234,101.5,201.25,7,1.0
cam3,1732912345.022345,102.5,202.25,7,1.0
cam1,1732912345.033456,103.5,203.25,8,1.0
cam2,1732912345.044567,104.5,204.25,8,0.5
"""


@pytest.mark.parametrize("name, text, origin_ns, first_ns", [
    # Unix-epoch times with microsecond digits: origin the whole second below the first
    ("epoch", _EPOCH_CSV, 1_732_912_345 * NS, 123_000),
    # a jittered first frame at -0.4 ms
    ("negative", "camera,time,u,v,frame,score\ncam1,-0.000400,10.0,20.0,0,1.0\n"
                 "cam2,0.011111,11.0,21.0,0,1.0\ncam1,0.033333,12.0,22.0,1,1.0\n",
     -NS, NS - 400_000),
    ("all negative", "camera,time,u,v,frame,score\ncam1,-12.5,10.0,20.0,0,1.0\n"
                     "cam2,-12.488889,11.0,21.0,0,1.0\n", -13 * NS, 500_000_000),
])
def test_import_export_round_trip_of_times_from_any_clock(tmp_path, cli, name, text,
                                                          origin_ns, first_ns):
    det_csv = tmp_path / "det.csv"
    det_csv.write_text(text)
    out = tmp_path / "s.mcap"
    code, stdout, stderr = cli("import", "--rig", "paper3", "--detections", det_csv, "-o", out)
    assert code == 0, stderr
    assert "session clock origin" in stdout
    s = read_session(out)
    assert s.metadata["clock_origin_ns"] == str(origin_ns)
    assert s.detections.frame_time_ns[0] == first_ns  # session times >= 0, from the origin
    assert np.all(s.detections.frame_time_ns >= 0)
    back = tmp_path / "back.csv"
    code, _, stderr = cli("export", out, "--detections", back)
    assert code == 0, stderr
    # the original times, to the nanosecond (so to the microsecond given)
    want = {(c, Decimal(t), float(u), float(v), k) for c, t, u, v, k, _ in
            (line.split(",") for line in text.strip().splitlines()[1:])}
    got = {(c, Decimal(t), float(u), float(v), k) for c, t, u, v, k, _ in
           (line.split(",") for line in back.read_text().strip().splitlines()[1:])}
    assert got == want
    # the origin survives a copy (fuse writes one), and the tracks CSV speaks the same clock
    fused = tmp_path / "f.mcap"
    copy_session(out, fused, tracks=[Track("typeA", s.detections.frame_time_ns[:1],
                                           np.zeros((1, 3)), np.zeros(1, np.int32))])
    assert read_session(fused).metadata["clock_origin_ns"] == str(origin_ns)
    tracks_csv = tmp_path / "t.csv"
    assert cli("export", fused, "--csv", tracks_csv)[0] == 0
    first_row = tracks_csv.read_text().splitlines()[1]
    assert Decimal(first_row.split(",")[0]) == min(t for _, t, *_ in want)


def test_import_keeps_times_of_a_session_clock_as_they_are(tmp_path, cli):
    # times in [0, 1e6 s): stored unchanged, no origin recorded (as before)
    det_csv = tmp_path / "det.csv"
    det_csv.write_text("camera,time,u,v\ncam1,5.5,1,2\ncam2,999999.25,3,4\n")
    out = tmp_path / "s.mcap"
    code, stdout, _ = cli("import", "--rig", "paper2", "--detections", det_csv, "-o", out)
    assert code == 0 and "origin" not in stdout
    s = read_session(out)
    assert "clock_origin_ns" not in s.metadata
    assert_array_equal(s.detections.frame_time_ns, [5_500_000_000, 999_999_250_000_000])


def test_a_malformed_clock_origin_is_one_line(tmp_path, cli, rig3):
    path = tmp_path / "s.mcap"
    with SessionWriter(path, rig3, metadata={"clock_origin_ns": "1.5e9"}) as w:
        w.add_detections(_one_frame(rig3))
    code, _, stderr = cli("export", path, "--detections", tmp_path / "d.csv")
    assert code == 1 and "clock_origin_ns '1.5e9' is not an integer" in stderr
    assert len(stderr.strip().splitlines()) == 1


def _one_frame(rig):
    from pslog.records import Detections

    return Detections.from_frames(rig.names, [0], [0], [0], [0], [[1.0, 2.0]])


def test_import_without_frame_column_numbers_frames_from_their_times(tmp_path, cli):
    # (cam1's two frames 0.1 s apart at 30 fps: 3 frame periods, frames 0 and 3 since
    # session 40, 0 and 1 before: tests/test_walk40.py)
    det_csv = tmp_path / "det.csv"
    det_csv.write_text("time,camera,v,u\n0.2,cam1,5,6\n0.1,cam1,3,4\n0.1,cam1,3.5,4.5\n"
                       "0.15,cam2,1,2\n\n")
    out = tmp_path / "s.mcap"
    code, _, stderr = cli("import", "--rig", "paper2", "--detections", det_csv, "-o", out)
    assert code == 0, stderr
    d = read_session(out).detections
    assert_array_equal(d.frame_time_ns, [100_000_000, 150_000_000, 200_000_000])
    assert_array_equal(d.frame_camera, [0, 1, 0])
    assert_array_equal(d.frame_index, [0, 0, 3])
    assert_array_equal(d.candidates_per_frame(), [2, 1, 1])
    assert_array_equal(d.cand_uv[-1], [6.0, 5.0])


def test_import_candidates_of_one_frame_share_camera_time_and_frame(tmp_path, cli):
    # several rows with the same camera and time are candidates of one frame, also with a
    # frame column; the same frame index on another camera is another frame
    det_csv = tmp_path / "det.csv"
    det_csv.write_text("camera,time,u,v,frame,score\ncam1,0,1,2,0,1\ncam1,0,3,4,0,0.5\n"
                       "cam2,0.0111,5,6,0,1\ncam1,0.0333,7,8,1,1\n")
    out = tmp_path / "s.mcap"
    code, _, stderr = cli("import", "--rig", "paper3", "--detections", det_csv, "-o", out)
    assert code == 0, stderr
    d = read_session(out).detections
    assert_array_equal(d.frame_index, [0, 0, 1])
    assert_array_equal(d.candidates_per_frame(), [2, 1, 1])


def test_export_sim_session_round_trips_through_import(sim_session, tmp_path, cli):
    csv_path = tmp_path / "d.csv"
    assert cli("export", sim_session.path, "--detections", csv_path)[0] == 0
    save_rig(sim_session.rig, tmp_path / "rig.toml")
    out = tmp_path / "i.mcap"
    code, _, stderr = cli("import", "--rig", tmp_path / "rig.toml", "--detections", csv_path,
                          "-o", out)
    assert code == 0, stderr
    a, b = sim_session.detections, read_session(out).detections
    # frames without candidates (the ball missed) come back too: one row, u and v empty
    missed = a.candidates_per_frame() == 0
    assert missed.sum() > 5 and csv_path.read_text().count(",,,") == missed.sum()
    assert_array_equal(b.frame_time_ns, a.frame_time_ns)
    assert_array_equal(b.frame_camera, a.frame_camera)
    assert_array_equal(b.frame_index, a.frame_index)
    assert_array_equal(b.cand_frame, a.cand_frame)
    assert_array_equal(b.cand_uv, a.cand_uv)
    assert_array_equal(b.cand_score, a.cand_score)
    # and the CSV again, byte for byte
    assert cli("export", out, "--detections", tmp_path / "d2.csv")[0] == 0
    assert (tmp_path / "d2.csv").read_bytes() == csv_path.read_bytes()


def test_export_tracks_csv(sim_session, tmp_path, cli):
    truth = sim_session.truth
    track = Track("typeA", truth.time_ns, truth.position_world,
                  np.arange(len(truth), dtype=np.int32) % 3,
                  {"ray_miss_m": np.full(len(truth), 0.001)})
    fused = tmp_path / "fused.mcap"
    copy_session(sim_session.path, fused, tracks=[track])
    out = tmp_path / "tracks.csv"
    code, _, stderr = cli("export", fused, "--csv", out)
    assert code == 0, stderr
    lines = out.read_text().splitlines()
    assert lines[0] == "time,x,y,z,camera,method,ray_miss_m"
    table = np.array([[float(x) for x in ln.split(",")[:4]] for ln in lines[1:]])
    assert_allclose(table[:, 0], truth.time_ns / NS, atol=1e-12)
    assert_array_equal(table[:, 1:], truth.position_world)
    assert lines[2].split(",")[4:6] == ["cam2", "typeA"]

    code, _, stderr = cli("export", sim_session.path, "--csv", tmp_path / "none.csv")
    assert code == 1 and "no fused tracks" in stderr
    assert not (tmp_path / "none.csv").exists()


# ---- bad input: one line, exit 1, no traceback ---------------------------------------------
@pytest.fixture
def bad_files(tmp_path, sim_session):
    from mcap.writer import Writer

    (tmp_path / "notes.txt").write_text("not an mcap\n")
    with open(tmp_path / "foreign.mcap", "wb") as f:
        w = Writer(f)
        w.start()
        w.finish()
    (tmp_path / "bad.toml").write_text("[[camera]\nname = 'x'\n")
    (tmp_path / "ok.csv").write_text("camera,time,u,v\ncam1,0.1,1,2\n")
    (tmp_path / "badrow.csv").write_text("camera,time,u,v\ncam1,0.1,1,2\ncam1,0.2,abc,2\n")
    # u and v both empty is a missed frame; one of them alone is a bad value
    (tmp_path / "halfmiss.csv").write_text("camera,time,u,v\ncam1,0.1,,\ncam1,0.2,,2\n")
    (tmp_path / "nan.csv").write_text("camera,time,u,v\ncam1,0,1,2\ncam1,0,nan,100\n")
    (tmp_path / "inf.csv").write_text("camera,time,u,v\ncam1,0,1,-inf\n")
    (tmp_path / "badscore.csv").write_text("camera,time,u,v,score\ncam1,0,1,2,1.5\n")
    (tmp_path / "badframe.csv").write_text("camera,time,u,v,frame\ncam1,0,1,2,0\n"
                                           "cam1,0.1,1,2,1.0\n")
    (tmp_path / "hugetime.csv").write_text("camera,time,u,v\ncam1,1e999999999,1,2\n")
    head = "camera,time,u,v,frame,score\n"
    (tmp_path / "twotimes.csv").write_text(head + "cam1,0,1,2,0,1\ncam2,0,1,2,0,1\n"
                                           "cam1,0.0333,3,4,0,1\n")
    (tmp_path / "twoframes.csv").write_text(head + "cam1,0,1,2,0,1\ncam1,0,3,4,1,1\n")
    (tmp_path / "short.csv").write_text("camera,time,u,v\ncam1,0.1,1,2\n\ncam1,0.2,1\n")
    (tmp_path / "badhead.csv").write_text("cam,time,u,v\ncam1,0.1,1,2\n")
    (tmp_path / "unknown.csv").write_text("camera,time,u,v\ncam1,0.1,1,2\ncam9,0.2,1,2\n")
    (tmp_path / "exists.mcap").write_text("keep")
    return tmp_path


@pytest.mark.parametrize("args, message", [
    (["info", "{d}/missing.mcap"], "no such file"),
    (["info", "{d}/notes.txt"], "not an MCAP"),
    (["info", "{d}/foreign.mcap"], "not a pslog session"),
    (["export", "{d}/foreign.mcap", "--detections", "{d}/x.csv"], "not a pslog session"),
    (["export", "{d}/missing.mcap", "--detections", "{d}/x.csv"], "no such file"),
    (["export", "{d}/sim.mcap"], "nothing to export"),
    (["recover", "{d}/notes.txt", "-o", "{d}/x.mcap"], "not an MCAP"),
    (["recover", "{d}/foreign.mcap", "-o", "{d}/x.mcap"], "not a pslog session"),
    (["import", "--rig", "{d}/bad.toml", "--detections", "{d}/ok.csv", "-o", "{d}/x.mcap"],
     "malformed TOML"),
    (["import", "--rig", "{d}/nope.toml", "--detections", "{d}/ok.csv", "-o", "{d}/x.mcap"],
     "nope.toml"),
    (["simulate", "--rig", "{d}/bad.toml", "-o", "{d}/x.mcap"], "malformed TOML"),
    (["import", "--rig", "paper3", "--detections", "{d}/badrow.csv", "-o", "{d}/x.mcap"],
     "line 3: bad u value 'abc'"),
    (["import", "--rig", "paper3", "--detections", "{d}/halfmiss.csv", "-o", "{d}/x.mcap"],
     "halfmiss.csv: line 3: bad u value ''"),
    (["import", "--rig", "paper3", "--detections", "{d}/nan.csv", "-o", "{d}/x.mcap"],
     "nan.csv: line 3: bad u value 'nan': not a finite number"),
    (["import", "--rig", "paper3", "--detections", "{d}/inf.csv", "-o", "{d}/x.mcap"],
     "inf.csv: line 2: bad v value '-inf': not a finite number"),
    (["import", "--rig", "paper3", "--detections", "{d}/badscore.csv", "-o", "{d}/x.mcap"],
     "line 2: bad score value '1.5': not in [0, 1]"),
    (["import", "--rig", "paper3", "--detections", "{d}/badframe.csv", "-o", "{d}/x.mcap"],
     "line 3: bad frame value '1.0': not an integer"),
    (["import", "--rig", "paper3", "--detections", "{d}/hugetime.csv", "-o", "{d}/x.mcap"],
     "line 2: bad time value '1e999999999': beyond the range of times (±9.22e+09 s)"),
    (["import", "--rig", "paper3", "--detections", "{d}/twotimes.csv", "-o", "{d}/x.mcap"],
     "twotimes.csv: lines 2 and 4: camera cam1 frame 0 at two times (0.000000000 s and "
     "0.033300000 s)"),
    (["import", "--rig", "paper3", "--detections", "{d}/twoframes.csv", "-o", "{d}/x.mcap"],
     "lines 2 and 3: rows of camera cam1 at time 0.000000000 s disagree on frame (0 and 1)"),
    (["import", "--rig", "paper3", "--detections", "{d}/short.csv", "-o", "{d}/x.mcap"],
     "line 4: expected 4 fields"),
    (["import", "--rig", "paper3", "--detections", "{d}/badhead.csv", "-o", "{d}/x.mcap"],
     "line 1: bad header"),
    (["import", "--rig", "paper3", "--detections", "{d}/unknown.csv", "-o", "{d}/x.mcap"],
     "line 3: unknown camera 'cam9'"),
    (["import", "--rig", "paper3", "--detections", "{d}/missing.csv", "-o", "{d}/x.mcap"],
     "no such file"),
    (["import", "--rig", "paper3", "--detections", "{d}/ok.csv", "-o", "{d}/exists.mcap"],
     "exists"),
    (["simulate", "--rig", "paper3", "-o", "{d}/exists.mcap"], "exists"),
    (["export", "{d}/sim.mcap", "--detections", "{d}/exists.mcap"], "exists"),
    (["recover", "{d}/sim.mcap", "-o", "{d}/exists.mcap"], "exists"),
])
def test_bad_input_is_one_line_and_exit_1(bad_files, cli, args, message):
    code, _, stderr = cli(*[a.format(d=bad_files) for a in args])
    assert code == 1
    assert message in stderr
    assert stderr.startswith(f"pslog {args[0]}: error: ")
    assert stderr.count("\n") == 1 and "Traceback" not in stderr
    if args[0] == "import":  # (the walk of session 37: "rest.csv: rest.csv: line 2: ...")
        csv = args[args.index("--detections") + 1].format(d=bad_files)
        assert stderr.count(csv) <= 1, stderr
    assert (bad_files / "exists.mcap").read_text() == "keep"
    assert not (bad_files / "x.mcap").exists()


def test_cli_subprocess_error_has_no_traceback(tmp_path):
    text = tmp_path / "t.mcap"
    text.write_text("hello")
    result = subprocess.run([sys.executable, "-m", "pslog.cli", "info", str(text)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert result.stderr.strip() == f"pslog info: error: not an MCAP file: {text}"


def test_writer_used_by_other_commands_keeps_session_readable(tmp_path, rig3):
    # a writer left by an exception inside `with` still finishes the file
    path = tmp_path / "e.mcap"
    with pytest.raises(RuntimeError), SessionWriter(path, rig3) as w:
        w.add_frame(0, 0, 5, uv=[[1.0, 2.0]])
        raise RuntimeError("boom")
    assert read_session(path).detections.n_frames == 1


# ---- timing labels agree with the offsets (issue 8) -----------------------------------------
def test_import_timing_applies_the_preset_and_the_label_follows_the_offsets(tmp_path, cli):
    det_csv = tmp_path / "det.csv"
    det_csv.write_text("camera,time,u,v\ncam1,0.0,1,2\ncam2,0.0111,3,4\ncam3,0.0222,5,6\n")
    typea = tmp_path / "a.mcap"
    assert cli("import", "--rig", "paper3", "--detections", det_csv, "--timing", "typeA",
               "-o", typea)[0] == 0
    s = read_session(typea)
    assert s.timing == "typeA"
    assert_allclose([c.offset for c in s.rig.cameras], [0, 1 / 90, 2 / 90])
    # no --timing: the rig's own offsets, labelled by what they are
    plain = tmp_path / "p.mcap"
    assert cli("import", "--rig", "paper3", "--detections", det_csv, "-o", plain)[0] == 0
    assert read_session(plain).timing == "sync"
    rig = builtin_rig("paper3")
    rig = type(rig)(tuple(c.replace(offset=0.004 * i) for i, c in enumerate(rig.cameras)))
    save_rig(rig, tmp_path / "rig.toml")
    custom = tmp_path / "c.mcap"
    assert cli("import", "--rig", tmp_path / "rig.toml", "--detections", det_csv,
               "-o", custom)[0] == 0
    s = read_session(custom)
    assert s.timing == "custom" and s.rig == rig


def test_simulate_without_timing_keeps_a_custom_rigs_offsets(tmp_path, cli):
    rig = builtin_rig("paper3")
    rig = type(rig)(tuple(c.replace(offset=0.004 * i) for i, c in enumerate(rig.cameras)))
    save_rig(rig, tmp_path / "rig.toml")
    out = tmp_path / "s.mcap"
    code, stdout, stderr = cli("simulate", "--rig", tmp_path / "rig.toml", "--motion", "straight",
                               "-o", out)
    assert code == 0, stderr
    s = read_session(out)
    assert s.rig == rig and s.timing == "custom" and "timing custom" in stdout
    # a preset named on the command line sets the offsets, and the label says so
    out2 = tmp_path / "b.mcap"
    assert cli("simulate", "--rig", tmp_path / "rig.toml", "--timing", "typeB", "--motion",
               "straight", "-o", out2)[0] == 0
    s = read_session(out2)
    assert s.timing == "typeB"
    assert_allclose([c.offset for c in s.rig.cameras], [0, 1 / 60, 0])


def test_import_accepts_a_byte_order_mark_in_csv_and_rig(tmp_path, cli):
    det_csv = tmp_path / "det.csv"  # as Excel's "CSV UTF-8" saves it
    det_csv.write_bytes(b"\xef\xbb\xbfcamera,time,u,v\r\ncam1,0.0,1,2\r\ncam2,0.0111,3,4\r\n")
    rig_path = tmp_path / "rig.toml"
    rig_path.write_bytes(b"\xef\xbb\xbf" + builtin_rig("paper3").to_toml().encode())
    out = tmp_path / "s.mcap"
    code, _, stderr = cli("import", "--rig", rig_path, "--detections", det_csv, "-o", out)
    assert code == 0, stderr
    assert read_session(out).detections.n_candidates == 2


@pytest.mark.parametrize("time,why", [
    ("nan", "not a finite number of seconds"), ("-inf", "not a finite number of seconds"),
    ("1e30", "beyond the range of times (±9.22e+09 s)"),
])
def test_import_time_errors_speak_seconds_and_name_file_and_line(tmp_path, cli, time, why):
    det_csv = tmp_path / "det.csv"
    det_csv.write_text(f"camera,time,u,v\ncam2,0.5,3,4\ncam1,{time},1,2\n")
    code, _, stderr = cli("import", "--rig", "paper3", "--detections", det_csv,
                          "-o", tmp_path / "s.mcap")
    assert code == 1 and f"det.csv: line 3: bad time value '{time}': {why}" in stderr
    assert " ns" not in stderr and not (tmp_path / "s.mcap").exists()


def test_info_detection_rate_leaves_a_static_distractors_candidates_out(tmp_path, cli):
    """A second orange object in view is a candidate in every frame: 'detected' read 100 %
    though the ball was missed in half the frames (session 33's walkthrough). 'any cand.'
    still says that (frames with a candidate), 'moving' leaves the still candidate out and
    reads the ball's rate (against the simulation's ball labels, to a frame), and each
    still spot is named at the distractor's pixel; a clean session has no spot."""
    path = tmp_path / "d.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                       "--miss-rate", "0.5", "--distractor", "0.5,0.3,0.1", "--distractor",
                       "cam2=2.5,1.5,0.2", "--noise-px", "0.5", "--seed", "3", "-o", path)
    assert code == 0, err
    session = read_session(path)
    ball = session.ball_truth
    code, stdout, err = cli("info", path, "--json")
    assert code == 0, err
    cameras = json.loads(stdout)["cameras"]
    for i, (row, cam) in enumerate(zip(cameras, session.rig.cameras, strict=True)):
        frames = int(np.count_nonzero(session.detections.frame_camera == i))
        seen = len(np.unique(ball.cand_frame[ball.frame_camera[ball.cand_frame] == i]))
        assert row["detection_rate"] == 1.0  # every frame has the distractor
        assert 0.3 < seen / frames < 0.7
        assert abs(row["moving_rate"] * frames - seen) <= 1, (row, seen)
        points = [(0.5, 0.3, 0.1)] + ([(2.5, 1.5, 0.2)] if cam.name == "cam2" else [])
        assert len(row["static_spots"]) == len(points)
        for spot in row["static_spots"]:
            assert spot["share"] == 1.0
            uv, _ = cam.project(np.array(points))
            assert np.min(np.hypot(*(uv - [spot["u"], spot["v"]]).T)) < 1.0, (spot, uv)
    code, text, _ = cli("info", path)
    assert "any cand." in text and "moving" in text and "detected" not in text
    assert text.count("a candidate that does not move, at (") == 4
    clean = tmp_path / "c.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                       "--miss-rate", "0.5", "--seed", "3", "-o", clean)
    assert code == 0, err
    code, stdout, _ = cli("info", clean, "--json")
    for row in json.loads(stdout)["cameras"]:
        assert row["static_spots"] == [] and row["moving_rate"] == row["detection_rate"] < 0.7
