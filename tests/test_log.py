"""Tests of pslog.log: the session MCAP written, read back, copied, damaged and recovered."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import make_jpeg
from numpy.testing import assert_allclose, assert_array_equal

from pslog.cli.simulate import drop_before_zero
from pslog.errors import InputError, LogFormatError, OutputExistsError
from pslog.log import (
    SessionWriter,
    copy_session,
    iter_images,
    read_session,
    recover_session,
    session_info,
)
from pslog.log import _schemas as S
from pslog.log.recover import describe_salvage
from pslog.records import NS, Detections, Track, Truth

DET_FIELDS = ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
              "cand_radius", "cand_score")


def assert_same_detections(a: Detections, b: Detections) -> None:
    assert a.camera_names == b.camera_names
    for name in DET_FIELDS:
        assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def _detections(rig) -> Detections:
    """Hand-made frames: empty frames, several candidates, radius and score values."""
    return Detections.from_frames(
        rig.names,
        frame_time_ns=[0, 11_111_111, 22_222_222, 33_333_333, 44_444_444, 55_555_555],
        frame_camera=[0, 1, 2, 0, 1, 2],
        frame_index=[0, 0, 0, 1, 1, 7],
        cand_frame=[0, 0, 2, 3, 5],
        cand_uv=[[1.5, 2.25], [300.125, 1e-7], [639.0, 479.0], [-3.5, 2.0], [1.0 / 3, 2.0 / 3]],
        cand_radius=[4.0, np.nan, 2.5, 3.0, 6.0],
        cand_score=[0.25, 0.75, 1.0, 0.5, 0.0])


def _track(method: str, n: int = 20, quality=("snap_px", "extra_px")) -> Track:
    t = np.arange(n, dtype=np.int64) * 11_111_111
    pos = np.column_stack([np.linspace(0, 1, n), np.full(n, 0.5), np.linspace(2, 0, n)])
    q = {k: np.arange(n) * 0.1 + i for i, k in enumerate(quality)}
    if "snap_px" in q:
        q["snap_px"][::3] = np.nan
    return Track(method, t, pos, np.arange(n, dtype=np.int32) % 3, q)


# ---- round trips -------------------------------------------------------------------------
def test_round_trip_everything(tmp_path, rig3):
    path = tmp_path / "s.mcap"
    det = _detections(rig3)
    truth = Truth(np.array([0, 5, 9]), np.array([[0.0, 1, 2], [3, 4, 5], [6, 7, 8.5]]))
    jpeg = make_jpeg(10)
    with SessionWriter(path, rig3, timing="typeA", source="unit test",
                       metadata={"operator": "ana"}) as w:
        w.add_detections(det)
        w.add_truth(truth)
        w.add_track(_track("typeA"))
        w.add_track(_track("stereo", 7, quality=()))
        w.add_event(44_444_444, "camera cam2 stopped delivering frames", camera=1,
                    level="warning")
        w.add_event(3, "timestamps from host monotonic clock")
        w.add_image(1, 0, 11_111_111, jpeg)
    s = read_session(path)
    assert_same_detections(s.detections, det)
    assert_array_equal(s.truth.time_ns, truth.time_ns)
    assert_array_equal(s.truth.position_world, truth.position_world)
    assert s.rig.to_toml() == rig3.to_toml()
    assert s.timing == "typeA"
    assert s.metadata["operator"] == "ana"
    assert s.metadata["source"] == "unit test"
    assert s.metadata["format_version"] == S.FORMAT_VERSION
    assert s.events == [(3, "timestamps from host monotonic clock"),
                        (44_444_444, "camera cam2 stopped delivering frames")]
    assert s.n_images == 1
    assert sorted(s.tracks) == ["stereo", "typeA"]
    want = _track("typeA")
    got = s.tracks["typeA"]
    assert_array_equal(got.time_ns, want.time_ns)
    assert_array_equal(got.position_world, want.position_world)
    assert_array_equal(got.camera, want.camera)
    assert sorted(got.quality) == ["extra_px", "snap_px"]  # all-NaN fixed fields left out
    for key in want.quality:
        assert_array_equal(got.quality[key], want.quality[key])
    assert s.tracks["stereo"].quality == {}


def test_add_frame_streaming_equals_bulk(tmp_path, sim_session):
    det = sim_session.detections
    path = tmp_path / "stream.mcap"
    counts = det.candidates_per_frame()
    starts = np.concatenate([[0], np.cumsum(counts)])
    with SessionWriter(path, sim_session.rig, flush_interval_s=0.0) as w:
        for row in range(det.n_frames):
            a, b = starts[row], starts[row + 1]
            w.add_frame(int(det.frame_camera[row]), int(det.frame_index[row]),
                        int(det.frame_time_ns[row]), det.cand_uv[a:b], det.cand_radius[a:b],
                        det.cand_score[a:b])
    assert_same_detections(read_session(path).detections, det)
    assert_same_detections(read_session(sim_session.path).detections, det)


def test_images_stored_raw_and_filtered(tmp_path, rig3):
    path = tmp_path / "img.mcap"
    frames = {}
    with SessionWriter(path, rig3) as w:
        for k in range(4):
            for cam in range(3):
                t = k * 33_333_333 + cam * 11_111_111
                frames[(cam, k)] = (t, make_jpeg(20 * k + cam))
                w.add_frame(cam, k, t, uv=[[10.0 + k, 20.0]], image=frames[(cam, k)][1])
    images = list(iter_images(path))
    assert len(images) == 12
    assert [i.time_ns for i in images] == sorted(i.time_ns for i in images)
    for image in images:
        t, data = frames[(image.camera, image.frame_index)]
        assert (image.time_ns, image.data, image.format) == (t, data, "jpeg")
    some = list(iter_images(path, cameras=[2], start_ns=33_333_333, end_ns=99_999_999))
    assert [(i.camera, i.frame_index) for i in some] == [(2, 1), (2, 2)]
    s = read_session(path)
    assert s.n_images == 12 and s.detections.n_frames == 12


def test_foxglove_calibration_and_pose(tmp_path, rig3):
    from mcap.reader import make_reader

    path = tmp_path / "s.mcap"
    with SessionWriter(path, rig3):
        pass
    seen = set()
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            assert channel.message_encoding == "protobuf" and schema.encoding == "protobuf"
            name, kind = S.parse_camera_topic(channel.topic)
            cam = rig3.camera(name)
            if kind == "calibration":
                m = S.CameraCalibration.FromString(message.data)
                assert schema.name == "foxglove.CameraCalibration"
                assert (m.frame_id, m.width, m.height, m.distortion_model) == (
                    name, 640, 480, "plumb_bob")
                assert_array_equal(np.reshape(m.K, (3, 3)), cam.K)
                assert_array_equal(np.reshape(m.P, (3, 4))[:, :3], cam.K)
                assert_array_equal(m.D, cam.dist)
            elif kind == "transform":
                m = S.FrameTransform.FromString(message.data)
                assert (m.parent_frame_id, m.child_frame_id) == ("world", name)
                t = m.translation
                assert_allclose([t.x, t.y, t.z], cam.center_world, atol=1e-12)
                q = m.rotation
                world_from_cam = S.rotation_from_quaternion([q.x, q.y, q.z, q.w])
                assert_allclose(world_from_cam, cam.R.T, atol=1e-12)
            seen.add((name, kind))
    assert seen == {(n, k) for n in rig3.names for k in ("calibration", "transform")}


def test_quaternion_round_trip_for_every_branch():
    rng = np.random.default_rng(0)
    mats = [np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])]
    for _ in range(50):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        mats.append(q * np.sign(np.linalg.det(q)))
    for m in mats:
        assert_allclose(S.rotation_from_quaternion(S.quaternion_xyzw(m)), m, atol=1e-12)


def test_rerun_converts_pinholes_transforms_and_images(tmp_path, rig3):
    exe = shutil.which("rerun") or shutil.which("rerun", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.skip("rerun binary not installed")
    path = tmp_path / "img.mcap"
    with SessionWriter(path, rig3) as w:
        for cam in range(3):
            w.add_frame(cam, 0, cam * 11_111_111, uv=[[5.0, 6.0]], image=make_jpeg(50))
    rrd = tmp_path / "x.rrd"
    env = {**os.environ, "RERUN_ANALYTICS": "0"}
    subprocess.run([exe, "mcap", "convert", str(path), "-o", str(rrd)], check=True,
                   capture_output=True, env=env, timeout=60)
    printed = subprocess.run([exe, "rrd", "print", str(rrd)], check=True, capture_output=True,
                             text=True, env=env, timeout=60).stdout
    for name in rig3.names:
        lines = printed.splitlines()
        assert any(f"/camera/{name}/calibration" in ln and "Pinhole:image_from_camera" in ln
                   for ln in lines), name
        assert any(f"/camera/{name}/transform" in ln and "Transform3D:translation" in ln
                   for ln in lines), name
        assert any(f"/camera/{name}/image" in ln and "EncodedImage:blob" in ln
                   for ln in lines), name


# ---- refusals -----------------------------------------------------------------------------
def test_existing_output_refused_without_force(sim_session):
    before = sim_session.path.read_bytes()
    with pytest.raises(OutputExistsError, match="exists"):
        SessionWriter(sim_session.path, sim_session.rig)
    assert sim_session.path.read_bytes() == before
    with SessionWriter(sim_session.path, sim_session.rig, force=True):
        pass
    assert read_session(sim_session.path).detections.n_frames == 0


def test_reserved_metadata_and_bad_values(tmp_path, rig3):
    with pytest.raises(InputError, match="reserved"):
        SessionWriter(tmp_path / "a.mcap", rig3, metadata={"rig_toml": "x"})
    with SessionWriter(tmp_path / "b.mcap", rig3) as w:
        with pytest.raises(InputError, match="out of range"):
            w.add_frame(3, 0, 0)
        with pytest.raises(InputError, match="level"):
            w.add_event(0, "x", level="loud")


def test_missing_text_and_foreign_files(tmp_path):
    with pytest.raises(LogFormatError, match="no such file"):
        read_session(tmp_path / "nope.mcap")
    text = tmp_path / "notes.mcap"
    text.write_text("hello\n")
    for fn in (read_session, session_info):
        with pytest.raises(LogFormatError, match="not an MCAP"):
            fn(text)
    from mcap.writer import Writer

    foreign = tmp_path / "foreign.mcap"
    with open(foreign, "wb") as f:
        w = Writer(f)
        w.start()
        w.add_metadata("other", {"a": "b"})
        w.finish()
    for fn in (read_session, session_info):
        with pytest.raises(LogFormatError, match="not a pslog session"):
            fn(foreign)
    with pytest.raises(LogFormatError, match="not a pslog session"):
        recover_session(foreign, tmp_path / "out.mcap")


def test_newer_major_version_refused(tmp_path, rig3):
    from mcap.writer import Writer

    path = tmp_path / "v2.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        w.add_metadata(S.SESSION_METADATA, {"format": S.FORMAT_NAME, "format_version": "2.0",
                                             "rig_toml": rig3.to_toml()})
        w.finish()
    with pytest.raises(LogFormatError, match="newer"):
        read_session(path)


# ---- damage and recovery --------------------------------------------------------------------
def _many_chunks(tmp_path, rig3) -> tuple[Path, Detections]:
    """A session with images, flushed after every message: many small chunks."""
    path = tmp_path / "full.mcap"
    times, cams, idx = [], [], []
    with SessionWriter(path, rig3, flush_interval_s=0.0) as w:
        for k in range(10):
            for cam in range(3):
                t = k * 33_333_333 + cam * 11_111_111
                w.add_frame(cam, k, t, uv=[[float(k), float(cam)]], image=make_jpeg(k))
                times.append(t), cams.append(cam), idx.append(k)
    det = Detections.from_frames(rig3.names, times, cams, idx, np.arange(30),
                                 np.column_stack([np.repeat(np.arange(10.0), 3),
                                                  np.tile(np.arange(3.0), 10)]))
    return path, det


@pytest.mark.parametrize("fraction", [0.1, 0.35, 0.6, 0.9, 0.999])
def test_truncated_file_reported_and_recovered(tmp_path, rig3, fraction):
    full, det = _many_chunks(tmp_path, rig3)
    data = full.read_bytes()
    broken = tmp_path / "broken.mcap"
    broken.write_bytes(data[:int(len(data) * fraction)])

    with pytest.raises(LogFormatError, match=r"truncated.*pslog recover"):
        read_session(broken)
    info = session_info(broken)
    assert info["truncated"] is True and "pslog recover" in info["hint"]

    fixed = tmp_path / "fixed.mcap"
    report = recover_session(broken, fixed)
    assert report["was_complete"] is False
    assert report["discarded_bytes"] == len(broken.read_bytes()) - report["kept_bytes"] >= 0
    got = read_session(fixed)  # a proper finished file
    n = got.detections.n_frames
    assert report["detection_frames"] == n
    # what comes back is exactly the first n frames, in writing order
    assert_array_equal(got.detections.frame_time_ns, det.frame_time_ns[:n])
    assert_array_equal(got.detections.cand_uv, det.cand_uv[:n])
    assert got.n_images <= n + 1
    if n:
        assert report["last_time_ns"] >= det.frame_time_ns[n - 1]
    assert got.rig.to_toml() == rig3.to_toml()
    if fraction > 0.9:
        assert n >= 29  # only the tail is lost


def test_recover_and_info_report_each_kind_up_to_where_it_survived(tmp_path,
                                                                   truth_first_session):
    data, ends = truth_first_session
    # cut inside the last detection chunk: images of frame 19 survive, detections end at 9
    broken = tmp_path / "cut.mcap"
    broken.write_bytes(data[:ends[-2] + 20])
    info = session_info(broken)
    report = recover_session(broken, tmp_path / "fixed.mcap")
    for summary in (info, report):
        assert summary["detection_frames"] == 30 and summary["images"] == 60
        assert summary["truth_points"] == 300
        assert summary["last_detection_ns"] == 9 * 33_333_333 + 2 * 11_111_111
        assert summary["last_image_ns"] == 19 * 33_333_333 + 2 * 11_111_111
    assert report["last_time_ns"] == 299 * 3_333_333  # the truth: why per kind matters
    assert describe_salvage(report) == ("30 detection frames (to t = 0.322 s), 60 images "
                                        "(to t = 0.656 s), 300 truth points")
    got = read_session(tmp_path / "fixed.mcap")
    assert got.detections.n_frames == 30 and got.n_images == 60 and len(got.truth) == 300

    # cut inside the first detection chunk: nothing but truth and images
    broken.write_bytes(data[:ends[-4] + 20])
    report = recover_session(broken, tmp_path / "fixed.mcap", force=True)
    assert (report["detection_frames"], report["images"]) == (0, 30)
    assert report["last_detection_ns"] is None
    text = describe_salvage(report)
    assert text.startswith("30 images (to t = 0.322 s), 300 truth points; no detection frame "
                           "survived (")


def test_recover_refuses_output_and_copies_complete_files(tmp_path, sim_session):
    out = tmp_path / "out.mcap"
    out.write_text("keep me")
    with pytest.raises(OutputExistsError):
        recover_session(sim_session.path, out)
    assert out.read_text() == "keep me"
    report = recover_session(sim_session.path, out, force=True)
    assert report["was_complete"] is True and report["discarded_bytes"] == 0
    assert_same_detections(read_session(out).detections, sim_session.detections)


_KILLED_WRITER = textwrap.dedent("""
    import sys, time
    from pslog.log import SessionWriter
    from pslog.rig import apply_timing, builtin_rig
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    w = SessionWriter(sys.argv[1], rig, flush_interval_s=0.1)
    for i in range(100000):
        w.add_frame(i % 3, i // 3, i * 11_111_111, uv=[[float(i), 1.0]])
        print(i, flush=True)
        time.sleep(0.002)
""")


def test_sigkill_mid_recording_loses_at_most_the_last_interval(tmp_path):
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", _KILLED_WRITER, str(path)],
                            stdout=subprocess.PIPE, text=True)
    last = -1
    try:
        for line in proc.stdout:
            last = int(line)
            if last >= 300:
                break
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        proc.stdout.close()
    assert last >= 300
    with pytest.raises(LogFormatError, match="truncated"):
        read_session(path)
    report = recover_session(path, tmp_path / "fixed.mcap")
    det = read_session(tmp_path / "fixed.mcap").detections
    n = det.n_frames
    # 0.1 s flush interval at >= 2 ms per frame: at most ~50 frames unflushed; allow slack
    assert n >= last - 150  # (the child may be ahead of what we read: no upper bound)
    assert_array_equal(det.frame_time_ns, np.arange(n) * 11_111_111)
    assert_array_equal(det.cand_uv[:, 0], np.arange(n))
    assert report["last_time_ns"] == (n - 1) * 11_111_111


def test_timer_flushes_while_the_caller_is_idle(tmp_path, rig3):
    import time

    path = tmp_path / "idle.mcap"
    with SessionWriter(path, rig3, flush_interval_s=0.1) as w:
        w.add_frame(0, 0, 5, uv=[[1.0, 2.0]])
        time.sleep(0.4)  # no further calls: the background flusher must write the frame
        info = session_info(path)  # the unfinished file reads as truncated
        assert info["truncated"] is True
        assert info["topics"]["/camera/cam1/detections"] == 1
    assert session_info(path)["truncated"] is False


# ---- copies -----------------------------------------------------------------------------------
def test_copy_session_replaces_detections_and_tracks(tmp_path, rig3):
    src = tmp_path / "src.mcap"
    with SessionWriter(src, rig3, timing="typeB", metadata={"k": "v"}) as w:
        for cam in range(3):
            w.add_frame(cam, 0, cam * 1000, uv=[[1.0, 2.0]], image=make_jpeg(cam))
        w.add_track(_track("old"))
        w.add_track(_track("keep"))
        w.add_event(5, "note")
        w._add_foreign("/other/raw", None,
                       type("C", (), {"encoding": "json", "metadata": {}})(), 7, b'{"a":1}', 0)
    new_det = Detections.from_frames(rig3.names, [0, 1000, 2000], [0, 1, 2], [0, 0, 0],
                                     [1], [[9.0, 9.5]])
    dst = tmp_path / "dst.mcap"
    copy_session(src, dst, detections=new_det, tracks=[_track("old", 5)], replace_tracks=False)
    s = read_session(dst)
    assert_same_detections(s.detections, new_det)
    assert sorted(s.tracks) == ["keep", "old"] and len(s.tracks["old"]) == 5
    assert s.timing == "typeB" and s.metadata["k"] == "v"
    assert s.metadata["derived_from"] == "src.mcap"
    assert s.events == [(5, "note")]
    assert [i.data for i in iter_images(dst)] == [i.data for i in iter_images(src)]
    assert session_info(dst)["topics"]["/other/raw"] == 1

    dst2 = tmp_path / "dst2.mcap"
    copy_session(dst, dst2, tracks=[_track("new", 3)])  # replace_tracks=True drops the others
    assert sorted(read_session(dst2).tracks) == ["new"]
    with pytest.raises(OutputExistsError):
        copy_session(src, dst)
    with pytest.raises(InputError, match="is the input"):
        copy_session(src, src, force=True)


# ---- info -------------------------------------------------------------------------------------
def test_info_measures_rates_and_offsets_despite_drops_and_jitter(tmp_path, rig3):
    from pslog.motion import get_motion
    from pslog.simulation import SimulationOptions, simulate

    options = SimulationOptions(jitter_s=2e-4, drop_rate=0.2, miss_rate=0.3, seed=5)
    det, truth = simulate(rig3, get_motion("turntable"), 4.0, options)
    with pytest.raises(InputError, match="before the session clock"):
        with SessionWriter(tmp_path / "neg.mcap", rig3) as w:
            w.add_detections(det)  # jitter put the first frame before t = 0
    det, truth, n_early = drop_before_zero(det, truth)
    assert n_early == 1
    path = tmp_path / "j.mcap"
    with SessionWriter(path, rig3, timing="typeA") as w:
        w.add_detections(det)
        w.add_truth(truth)
    info = session_info(path)
    assert info["truncated"] is False and info["truth"] is True and info["tracks"] == {}
    assert info["frames"] == det.n_frames
    for cam, row in zip(rig3.cameras, info["cameras"], strict=True):
        assert abs(row["fps_measured"] - 30.0) < 0.05
        assert abs(row["offset_measured_s"] - (cam.offset - rig3.cameras[0].offset)) < 3e-4
        assert 0.5 < row["detection_rate"] < 0.9
    assert info["topics"]["/truth"] == len(truth)
    assert abs(info["duration_s"] - 4.0) < 0.05
    assert info["start_s"] is not None and info["duration_s"] * NS > 0


def _jittered(rig, jitter_s: float = 5e-4, seed: int = 2) -> Detections:
    from pslog.motion import get_motion
    from pslog.simulation import SimulationOptions, simulate

    det, _truth = simulate(rig, get_motion("turntable"), 3.0,
                           SimulationOptions(jitter_s=jitter_s, seed=seed))
    return det


def _shifted(det: Detections, shift_ns: int) -> Detections:
    import dataclasses

    return dataclasses.replace(det, frame_time_ns=det.frame_time_ns + shift_ns)


@pytest.mark.parametrize("timing", ["sync", "typeA", "typeB"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_measured_offsets_are_signed_and_nearest_the_rigs(timing, seed):
    """0.5 ms shutter jitter on sync/typeB: a camera a hair early reads about -0.1 ms, never
    a frame period minus that (33.3 ms)."""
    from pslog.log.info import timing_table
    from pslog.rig import apply_timing, builtin_rig

    rig = apply_timing(builtin_rig("paper3"), timing)
    rows = timing_table(_jittered(rig, seed=seed), [c.offset for c in rig.cameras])
    assert rows[0]["offset_measured_s"] == rig.cameras[0].offset  # the reference
    for cam, row in zip(rig.cameras, rows, strict=True):
        assert abs(row["offset_measured_s"] - cam.offset) < 4e-4, (cam.name, row)


def test_measured_offsets_of_a_rig_whose_first_camera_is_not_at_zero(tmp_path):
    """The nominal offsets are the rig's as they are (not made relative to camera 0 or
    wrapped); the measured ones sit next to them."""
    from pslog.rig import Rig, builtin_rig

    base = builtin_rig("paper3")
    offsets = [0.030, 0.005, 0.016]  # camera 0 late in the period, the others wrap past it
    rig = Rig(tuple(c.replace(offset=o) for c, o in zip(base.cameras, offsets, strict=True)),
              "late")
    det = _jittered(rig, jitter_s=1e-4)
    path = tmp_path / "late.mcap"
    with SessionWriter(path, rig, timing="custom") as w:
        w.add_detections(det)
    info = session_info(path)
    for o, row in zip(offsets, info["cameras"], strict=True):
        assert row["offset_nominal_s"] == o
        assert abs(row["offset_measured_s"] - o) < 2e-4, row
    assert info["offset_reference"] == rig.names[0]


@pytest.mark.parametrize("dropped", [0, 1, 2])
def test_measured_offsets_of_cameras_of_two_rates(dropped):
    """A 60 fps camera and two 30 fps ones at their rig's offsets, the 60 fps camera's first
    ``dropped`` frames lost: its first frame then fixes the clock's zero only up to its own
    period, half the others'. Every camera reads its rig offset (review48: with one frame
    dropped the 30 fps cameras read 16.7 ms off, and ``pslog info`` said so of the true rig
    and of ``pslog sync``'s copy)."""
    import dataclasses

    from pslog.log.info import offset_disagreements, timing_table
    from pslog.rig import Rig, builtin_rig

    base = builtin_rig("paper3")
    rig = Rig(tuple(c.replace(fps=f, offset=o) for c, f, o in
                    zip(base.cameras, (60.0, 30.0, 30.0), (0.005, 0.020, 0.007), strict=True)),
              "two rates")
    det = _jittered(rig, jitter_s=1e-4)
    keep = ~((det.frame_camera == 0) & (det.frame_index < dropped))
    det = dataclasses.replace(det, frame_time_ns=det.frame_time_ns[keep],
                              frame_camera=det.frame_camera[keep],
                              frame_index=det.frame_index[keep],
                              cand_frame=np.zeros(0, np.int64), cand_uv=np.zeros((0, 2)),
                              cand_radius=np.zeros(0), cand_score=np.zeros(0))
    rows = timing_table(det, [c.offset for c in rig.cameras], rig)
    for cam, row in zip(rig.cameras, rows, strict=True):
        assert abs(row["offset_measured_s"] - cam.offset) < 2e-4, (dropped, cam.name, row)
    assert offset_disagreements(det, rig) == []


def test_measured_offsets_use_the_rigs_clock_model(tmp_path):
    """A session whose rig holds its cameras' clock parameters (as after ``pslog sync``):
    the offsets are measured on corrected times, so they agree with the rig's, though the
    logged times are several ms off."""
    from pslog.motion import get_motion
    from pslog.rig import apply_timing, builtin_rig
    from pslog.simulation import SimulationOptions, simulate, true_rig

    base = apply_timing(builtin_rig("paper3"), "typeA")
    a, b, c = base.names
    faults = SimulationOptions(jitter_s=5e-5, seed=3, clock_offset_s={b: 0.0061, c: -0.0042},
                               clock_drift_ppm={b: 30.0, c: -20.0},
                               readout_s={a: 0.01, b: 0.02, c: 0.015})
    det, _truth, _ = drop_before_zero(*simulate(base, get_motion("turntable"), 3.0, faults))
    synced = true_rig(base, faults)
    path = tmp_path / "synced.mcap"
    with SessionWriter(path, synced, timing="typeA") as w:
        w.add_detections(det)
    info = session_info(path)
    assert info["clock_corrected"]
    for cam, row in zip(base.cameras, info["cameras"], strict=True):
        assert row["offset_nominal_s"] == cam.offset
        assert abs(row["offset_measured_s"] - cam.offset) < 2e-4, (cam.name, row)


def test_phase_measurement_keeps_full_precision_on_epoch_clocks():
    """Times near 1.7e18 ns (Unix epoch) measure exactly as the same times near 0."""
    from pslog.log.info import measure_timing, timing_table
    from pslog.rig import apply_timing, builtin_rig

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det = _jittered(rig, jitter_s=2e-4)
    shift = 1_700_000_000_123_456_789
    near_zero = timing_table(det, [c.offset for c in rig.cameras])
    epoch = timing_table(_shifted(det, shift), [c.offset for c in rig.cameras])
    for a, b in zip(near_zero, epoch, strict=True):
        assert abs(a["offset_measured_s"] - b["offset_measured_s"]) < 1e-12
        assert abs(a["fps_measured"] - b["fps_measured"]) < 1e-9
    t = det.frame_time_ns[det.frame_camera == 1]
    period, phase = measure_timing(t, ref_ns=int(t[0]))
    period_e, phase_e = measure_timing(t + shift, ref_ns=int(t[0]) + shift)
    assert (period_e, phase_e) == (period, phase)


def test_info_on_a_file_being_written_says_it_may_still_be_recording(tmp_path, rig3):
    with SessionWriter(tmp_path / "live.mcap", rig3, flush_interval_s=0.0) as w:
        w.add_frame(0, 0, 5, uv=[[1.0, 2.0]])
        w.flush()
        live = session_info(tmp_path / "live.mcap")  # still open: no summary, no end magic
        assert live["truncated"] and live["still_recording"]
        assert "may still be recording" in live["hint"]
    data = (tmp_path / "live.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 2])
    old = os.stat(cut).st_mtime - 3600
    os.utime(cut, (old, old))
    info = session_info(cut)  # an hour old: a crash, not a recording in progress
    assert info["truncated"] and not info["still_recording"]
    assert "did not finish" in info["hint"] and "may still" not in info["hint"]
    partial = tmp_path / "cut.mcap.partial"
    shutil.copy(cut, partial)
    os.utime(partial, (old, old))
    assert session_info(partial)["still_recording"]  # a writer's .partial file


def test_readers_name_the_byte_offset_of_a_damaged_chunk(tmp_path, rig3):
    """read_session and iter_images check every chunk they read (CRC, decompression,
    framing): a one-line LogFormatError naming the offset and pslog recover, never a zstd or
    protobuf error."""
    from pslog.log import _mcapio as io

    path, _det = _many_chunks(tmp_path, rig3)
    data = path.read_bytes()
    chunks = [(body - 9, end) for op, body, end in io.walk_records(data, len(io.MAGIC))
              if op == io.OP_CHUNK]
    # find an image chunk and a detection chunk through the reader's own index
    with open(path, "rb") as f:
        from mcap.reader import SeekingReader

        summary = SeekingReader(f).get_summary()
    topic = {c.id: c.topic for c in summary.channels.values()}
    kind = {c.chunk_start_offset: {topic[k].rsplit("/", 1)[-1]
                                   for k in c.message_index_offsets}
            for c in summary.chunk_indexes}
    image = next(s for s, e in chunks if kind[s] == {"image"})
    det = next(s for s, e in chunks if kind[s] == {"detections"})
    table = next(a for a in summary.attachment_indexes if a.name.endswith("/detections"))
    for start, reader, table_too in ((image, lambda p: list(iter_images(p)), False),
                                     (det, read_session, True)):
        end = dict(chunks)[start]
        bad = tmp_path / f"bad{start}.mcap"
        damaged = bytearray(data)
        damaged[(start + end) // 2] ^= 0x10
        if table_too:
            # the columnar table holds the detections too: read from it, the detection
            # chunks are not read, and its data is whole (CRC-checked)
            bad.write_bytes(bytes(damaged))
            whole = read_session(path).detections
            np.testing.assert_array_equal(reader(bad).detections.cand_uv, whole.cand_uv)
            # with the table damaged as well, the messages are read: the chunk's offset
            damaged[table.offset + table.length - 8] ^= 0x10
        bad.write_bytes(bytes(damaged))
        with pytest.raises(LogFormatError, match=rf"byte {start} .*pslog recover"):
            reader(bad)
    # images still come in time order across chunks, and a time window selects
    times = [i.time_ns for i in iter_images(path)]
    assert times == sorted(times) and len(times) == 30
    window = [(i.camera, i.time_ns) for i in iter_images(path, cameras=[1], start_ns=33_333_333,
                                                         end_ns=100_000_000)]
    assert window == [(1, 44_444_444), (1, 77_777_777)]


def test_recover_without_summary_rescues_channels_of_a_damaged_chunk(tmp_path):
    """The sample's first image chunk defines the image channels; with no summary to repeat
    them and that chunk damaged, the channel records zstd kept verbatim in it are still read
    (and pslog's schema regenerated), so later intact chunks keep their cam2 images; only the
    damaged chunk's own messages are lost, each counted by topic."""
    from pslog.log import _mcapio as io

    data = (Path(__file__).parents[1] / "samples" / "throw.mcap").read_bytes()
    summary = io.read_summary(data)
    images = {cid for cid, ch in summary.channels.items() if ch.topic.endswith("/image")}
    first_images = next(c for c in summary.chunks if images & set(c.message_index_offsets))
    # the image messages in that chunk, by topic, from the intact file's message indexes
    counts, _ = io.message_index_counts(data, first_images.offset + first_images.length,
                                        len(data))
    lost = {summary.channels[cid].topic: k for cid, k in counts.items() if cid in images}
    assert "/camera/cam2/image" in lost
    damaged = bytearray(data[:summary.start])  # cut where the summary starts
    damaged[first_images.offset + first_images.length // 2] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(damaged))
    report = recover_session(bad, tmp_path / "fixed.mcap")
    assert [d["start"] for d in report["damaged"]] == [first_images.offset]
    assert report["damaged"][0]["messages"]["/camera/cam2/image"] == lost["/camera/cam2/image"]
    assert report["topics"]["/camera/cam2/image"] == 45 - lost["/camera/cam2/image"]
    assert report["detection_frames"] == 135 and report["truth_points"] == 135
    # the sample of session 12 on (detections written before their images) defines each
    # channel where every later chunk's message finds it: none is lost for want of one
    assert report["unknown_channel_messages"] == 0
    assert read_session(tmp_path / "fixed.mcap").n_images == 135 - sum(lost.values())


@pytest.mark.parametrize("walk", ["scan_file", "salvage_file"])
def test_an_error_of_the_message_callback_is_never_taken_for_damaged_input(walk, sim_session):
    """A failure on the output side of a copy (the writer's own LogFormatError, a full disk)
    propagates unchanged: the intact input is not reported as damaged, and a salvage does
    not skip the chunk and go on."""
    from pslog.log import _mcapio as io

    ours = LogFormatError("the writer failed")

    def callback(*_message) -> None:
        raise ours

    with pytest.raises(LogFormatError) as raised:
        getattr(io, walk)(sim_session.path, callback)
    assert raised.value is ours


def test_a_bug_while_reading_the_summary_is_not_reported_as_damage(sim_session, monkeypatch):
    """Only parse errors mean "damaged summary; run pslog recover": a programming error (here
    a TypeError put into the summary check) surfaces as itself."""
    from pslog.log import _mcapio as io

    def broken(*_args):
        raise TypeError("a bug")

    monkeypatch.setattr(io, "summary_span", broken)
    with pytest.raises(TypeError, match="a bug"):
        read_session(sim_session.path)


def test_a_track_added_in_batches_keeps_distinct_scene_ids(tmp_path, rig3):
    """A live recording adds its track a batch at a time: every point's Foxglove sphere keeps
    its own entity id (ids restarting at 0 per batch replaced the earlier batch's markers)."""
    from mcap.reader import make_reader

    path = tmp_path / "batches.mcap"
    with SessionWriter(path, rig3) as w:
        for start in (0, 3):
            t = np.arange(start, start + 3, dtype=np.int64) * 10_000_000 + 1
            w.add_track(Track("filter", t, np.ones((3, 3)), np.zeros(3, np.int32)))
    ids = []
    with open(path, "rb") as f:
        for _, _channel, message in make_reader(f).iter_messages(
                topics=[S.track_scene_topic("filter")]):
            update = S.SceneUpdate.FromString(message.data)
            ids += [e.id for e in update.entities]
    assert ids == [f"filter/{i}" for i in range(6)]


@pytest.mark.parametrize("drop", [0.0, 0.3, 0.5, 0.6, 0.8])
def test_frame_period_and_phase_are_measured_with_most_frames_dropped(drop):
    """New-user sweep: with 60 % of frames dropped the median gap is two periods; taken as the
    period, ``pslog info`` read 13 fps instead of 30 and shutter offsets off by milliseconds."""
    from pslog.log.info import measure_timing

    rng = np.random.default_rng(11)
    period, phase = 1 / 30, 0.0123
    k = np.arange(3000)
    k = k[rng.random(len(k)) >= drop]
    t = np.round((phase + period * k + rng.normal(0, 2e-4, len(k))) * NS).astype(np.int64)
    t.sort()
    measured, measured_phase = measure_timing(t, ref_ns=0)
    assert abs(measured - period) < 1e-6 * period, measured
    off = (measured_phase - phase) / period  # the phase of the first kept frame: any k
    assert abs(off - round(off)) * period < 1e-4, measured_phase


def test_info_measures_30_fps_on_a_session_with_most_frames_dropped(tmp_path, cli):
    code, out, _ = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                       "--duration", "6", "--drop-rate", "0.6", "--seed", "3", "-o",
                       tmp_path / "d.mcap")
    assert code == 0
    code, out, _ = cli("info", tmp_path / "d.mcap")
    rows = [line.split() for line in out.splitlines() if line.split()[:1] in (["cam1"], ["cam2"],
                                                                          ["cam3"])]
    assert [row[2] for row in rows] == ["30.00"] * 3, out
    assert [row[4] for row in rows] == ["0.000", "11.111", "22.222"], out


@pytest.mark.parametrize(("fps", "tick_s", "late_s", "drop", "jitter_s"), [
    (30, 0.010, 0.0, 0.0, 0.0),       # timestamps on 10-ms ticks: not a 100 fps camera
    (15, 0.015625, 0.0, 0.0, 0.0),    # Windows' 15.625-ms clock: not 64 fps
    (30, 0.0, 0.008, 0.0, 0.0),       # randomly 0 or 8 ms late (a busy host): not 120 fps
    (30, 0.0, 0.0, 0.6, 0.003),       # 60 % dropped and 3 ms of jitter
])
def test_frame_period_is_not_a_fraction_of_it_on_coarse_or_late_timestamps(
        fps, tick_s, late_s, drop, jitter_s):
    """Review of session 12: a period shorter than the median gap was taken whenever the gaps
    fit it, and timestamps rounded to a coarse tick or late by a fixed amount fit a fraction of
    the period (30 fps read as 100, 15 as 64). A shorter period now needs single gaps too."""
    from pslog.log.info import measure_timing

    rng = np.random.default_rng(5)
    k = np.arange(1500)
    k = k[rng.random(len(k)) >= drop]
    t = 1.0 + k / fps + rng.normal(0, jitter_s, len(k)) + late_s * rng.integers(0, 2, len(k))
    if tick_s:
        t = np.floor(t / tick_s) * tick_s
    period, _ = measure_timing(np.round(np.sort(t) * NS).astype(np.int64))
    assert abs(1 / period - fps) < 0.02 * fps, 1 / period
