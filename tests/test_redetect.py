"""Offline re-detection over a session's stored frames (samples/throw.mcap)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from numpy.testing import assert_array_equal

from pslog.cli import main
from pslog.errors import InputError, PslogError
from pslog.log import SessionWriter, iter_images, read_session
from pslog.rig import builtin_rig
from recorders import HsvRange, redetect_session

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"
BLUE = HsvRange(100, 130, 120, 255, 70, 255)


def _raw_messages(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    out: dict[str, list[tuple[int, bytes]]] = {}
    with open(path, "rb") as f:
        for _schema, channel, message in make_reader(f).iter_messages(log_time_order=True):
            out.setdefault(channel.topic, []).append((message.log_time, message.data))
    return out


def test_sample_is_a_small_recorded_throw():
    assert SAMPLE.stat().st_size <= 5_000_000
    session = read_session(SAMPLE)
    assert session.rig.names == ("cam1", "cam2", "cam3") and session.timing == "typeA"
    assert session.n_images == session.detections.n_frames == 135
    assert session.truth is not None and session.metadata["synthetic_motion"] == "throw"


def test_same_settings_reproduce_the_detections(tmp_path):
    out = tmp_path / "same.mcap"
    summary = redetect_session(SAMPLE, out)
    assert summary.images == 135 and summary.kept == 0 and summary.after == summary.before
    old, new = read_session(SAMPLE).detections, read_session(out).detections
    assert_array_equal(new.frame_time_ns, old.frame_time_ns)
    assert_array_equal(new.frame_index, old.frame_index)
    # detected again on the stored JPEGs instead of the raw renders: nearly the same
    shift = np.linalg.norm(new.best().uv - old.best().uv, axis=1)
    assert np.sqrt(np.mean(shift**2)) < 0.3 and shift.max() < 0.75


def test_new_thresholds_change_detections_and_nothing_else(tmp_path):
    out = tmp_path / "blue.mcap"
    rc = main(["redetect", str(SAMPLE), "-o", str(out), "--hsv", BLUE.text()])
    assert rc == 0
    old, new = read_session(SAMPLE), read_session(out)
    assert old.detections.n_candidates == 135 and new.detections.n_candidates == 0
    assert_array_equal(new.detections.frame_time_ns, old.detections.frame_time_ns)
    assert_array_equal(new.detections.frame_camera, old.detections.frame_camera)
    assert new.rig == old.rig and new.timing == old.timing
    # the metadata records the new detector settings, and nothing else changes
    assert new.metadata["detector_hsv"] == BLUE.text() != old.metadata["detector_hsv"]
    ignore = ("derived_from", "derived", "created_utc", "detector_hsv")
    assert {k: v for k, v in new.metadata.items() if k not in ignore} \
        == {k: v for k, v in old.metadata.items() if k not in ignore}
    # frames, calibration, poses, truth and events: byte-identical messages
    raw_old, raw_new = _raw_messages(SAMPLE), _raw_messages(out)
    assert set(raw_old) == set(raw_new)
    for topic in raw_old:
        if topic.endswith("/detections"):
            assert raw_new[topic] != raw_old[topic]
        else:
            assert raw_new[topic] == raw_old[topic], topic
    images_old = [(i.camera, i.frame_index, i.time_ns, i.data) for i in iter_images(SAMPLE)]
    images_new = [(i.camera, i.frame_index, i.time_ns, i.data) for i in iter_images(out)]
    assert images_new == images_old


def test_refusals(tmp_path, capsys):
    out = tmp_path / "x.mcap"
    out.write_bytes(b"keep")
    assert main(["redetect", str(SAMPLE), "-o", str(out)]) == 1
    assert "--force" in capsys.readouterr().err and out.read_bytes() == b"keep"
    assert main(["redetect", str(tmp_path / "none.mcap"), "-o", str(tmp_path / "y.mcap")]) == 1
    assert "none.mcap" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:  # a bad command-line value: argparse, exit 2
        main(["redetect", str(SAMPLE), "-o", str(tmp_path / "y.mcap"), "--hsv", "1,2"])
    assert exit_info.value.code == 2 and "--hsv" in capsys.readouterr().err
    bare = tmp_path / "bare.mcap"  # detections only, no frames
    with SessionWriter(bare, builtin_rig("paper2")) as w:
        w.add_frame(0, 0, 0, np.array([[1.0, 2.0]]))
    with pytest.raises(InputError, match="no stored frames"):
        redetect_session(bare, tmp_path / "z.mcap")


def test_worker_processes_give_the_same_session_as_one_process(tmp_path, monkeypatch):
    """The process pool (used from a few hundred frames on) returns every frame's candidates
    to the right frame: the same detections as detecting in this process."""
    from recorders import redetect

    one, pool = tmp_path / "one.mcap", tmp_path / "pool.mcap"
    redetect_session(SAMPLE, one, workers=1)
    monkeypatch.setattr(redetect, "_PARALLEL_FROM", 0)  # the sample has only 135 frames
    # (the sample's 5 image chunks in 4 tasks (_guided): several in flight, out of order)
    redetect_session(SAMPLE, pool, workers=2)
    a, b = read_session(one).detections, read_session(pool).detections
    assert a.n_candidates >= 135
    for name in ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
                 "cand_radius", "cand_score"):
        assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)


def test_compiled_screen_and_small_windows_give_the_same_session(tmp_path, monkeypatch):
    """Workers reading their own windows of a few chunks each, with the compiled screen (as
    for sessions of thousands of frames), give exactly the detections of one plain process;
    the windows cover the whole session, cut at image chunks."""
    from recorders import redetect

    one, pool = tmp_path / "one.mcap", tmp_path / "pool.mcap"
    redetect_session(SAMPLE, one, workers=1)
    monkeypatch.setattr(redetect, "_PARALLEL_FROM", 0)
    monkeypatch.setattr(redetect, "_COMPILED_FROM", 0)
    monkeypatch.setattr(redetect, "_HEAD_TASKS", 2)  # two short tasks for the first pool,
    monkeypatch.setattr(redetect, "_HEAD", 5)  # the rest for the compiled one
    monkeypatch.setattr(redetect, "_detect_chunks", _recording_detect_chunks)
    monkeypatch.setenv("PSLOG_TEST_TASKS", str(tmp_path / "tasks.txt"))
    plan = redetect._plan(SAMPLE, ("cam1", "cam2", "cam3"), 135, 10)
    assert plan is not None and len(plan.tasks) >= 4
    # every image chunk once, in the order of their first message times
    with open(SAMPLE, "rb") as f:
        summary = make_reader(f).get_summary()
    images = {cid for cid, c in summary.channels.items() if c.topic.endswith("/image")}
    chunks = sorted((c for c in summary.chunk_indexes if images & c.message_index_offsets.keys()),
                    key=lambda c: (c.message_start_time, c.chunk_start_offset))
    assert [(c.chunk_start_offset, c.chunk_length) for c in chunks] == \
        [(offset, length) for task in plan.tasks for _rank, offset, length in task]
    assert set(plan.cameras) == images
    redetect_session(SAMPLE, pool, workers=2)
    a, b = read_session(one).detections, read_session(pool).detections
    for name in ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
                 "cand_radius", "cand_score"):
        assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
    # the first two tasks in a first pool with OpenCV's screen (those its workers started
    # before numba was loaded here: both, unless the load beat the pool's queue), the others
    # in a second one (other processes) with the compiled screen, each task once
    tasks = [line.split() for line in (tmp_path / "tasks.txt").read_text().splitlines()]
    plain = {pid for pid, compiled in tasks if compiled == "False"}
    fast = {pid for pid, compiled in tasks if compiled == "True"}
    assert len(tasks) > 2 and 1 <= sum(c == "False" for _p, c in tasks) <= 2
    assert plain and fast and not plain & fast and str(os.getpid()) not in plain | fast
    # the first pool has one worker fewer (this process loads numba on the other core)
    assert len(plain) == 1


def test_first_pool_tasks_not_started_go_to_the_compiled_pool(tmp_path, monkeypatch):
    """The first pool's tasks that no worker has taken when the compiled screen is loaded
    (here at once) are cancelled there and detected by the second pool, each task once: the
    session of one plain process (a task lost would fail the command)."""
    from recorders import redetect

    one, pool = tmp_path / "one.mcap", tmp_path / "pool.mcap"
    redetect_session(SAMPLE, one, workers=1)
    for name, value in (("_PARALLEL_FROM", 0), ("_COMPILED_FROM", 0), ("_HEAD_TASKS", 6),
                        ("_HEAD", 5), ("_detect_chunks", _recording_detect_chunks),
                        ("_warm_screened", lambda hsv, k: None)):
        monkeypatch.setattr(redetect, name, value)
    monkeypatch.setenv("PSLOG_TEST_TASKS", str(tmp_path / "tasks.txt"))
    redetect_session(SAMPLE, pool, workers=2)
    a, b = read_session(one).detections, read_session(pool).detections
    for name in ("frame_camera", "frame_index", "cand_frame", "cand_uv", "cand_score"):
        assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)
    # 7 chunks, one a task: 6 for the first pool, of which its queue (3) and its two workers
    # take at most 5
    compiled = [c for _p, c in (line.split() for line in
                                (tmp_path / "tasks.txt").read_text().splitlines())]
    assert len(compiled) == 7 and compiled.count("True") >= 2


def _recording_detect_chunks(src, chunks, cameras, hsv, max_candidates, compiled, fast):
    """:func:`redetect._detect_chunks`, noting its process and screen in a file."""
    from recorders import redetect

    with open(os.environ["PSLOG_TEST_TASKS"], "a") as f:
        f.write(f"{os.getpid()} {compiled}\n")
    return redetect._read_and_detect(src, chunks, cameras, redetect._Redetector(
        hsv, max_candidates, compiled, fast))


def _copy_and_its_image_chunk(path: Path):
    """A copy of the sample at ``path`` and the chunk index of its third image chunk."""
    path.write_bytes(SAMPLE.read_bytes())
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    images = {cid for cid, c in summary.channels.items() if c.topic.endswith("/image")}
    return sorted((c for c in summary.chunk_indexes if images & c.message_index_offsets.keys()),
                  key=lambda c: c.chunk_start_offset)[2]


def _damaged_copy(tmp_path: Path) -> Path:
    """The sample with 64 bytes zeroed in the middle of an image chunk."""
    bad = tmp_path / "bad.mcap"
    chunk = _copy_and_its_image_chunk(bad)
    with open(bad, "r+b") as f:
        f.seek(chunk.chunk_start_offset + chunk.chunk_length // 2)
        f.write(bytes(64))
    return bad


def _die(*_args):
    os._exit(3)  # a worker killed (e.g. by the out-of-memory killer)


@pytest.mark.parametrize("fault", ["damaged", "killed"])
def test_a_fault_in_a_worker_is_one_line_and_writes_nothing(tmp_path, monkeypatch, capsys, fault):
    from recorders import redetect

    monkeypatch.setattr(redetect, "_PARALLEL_FROM", 0)
    src = _damaged_copy(tmp_path) if fault == "damaged" else SAMPLE
    if fault == "killed":
        monkeypatch.setattr(redetect, "_detect_chunks", _die)
    out = tmp_path / "out.mcap"
    assert main(["redetect", str(src), "-o", str(out), "--workers", "2"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert ("damaged data at byte" in err) if fault == "damaged" else ("worker" in err)
    assert list(tmp_path.iterdir()) == ([src] if fault == "damaged" else [])


def test_images_read_in_place_are_those_of_iter_images_in_the_same_order():
    """The workers' reading (whole chunks, each image decoded where it lies in the
    decompressed chunk) gives every image of :func:`iter_images`, ordered as it orders them
    once sorted by their keys."""
    from recorders import redetect

    plan = redetect._plan(SAMPLE, ("cam1", "cam2", "cam3"), 135, 10)
    assert plan is not None
    seen = []

    class _Keep:  # a detector that keeps every frame it is given
        def detect(self, frame):
            seen.append(frame)
            return redetect.BallDetector().detect(frame)

    keep = redetect._Redetector(HsvRange(), 5, False)
    keep.detector = _Keep()
    parts = [redetect._read_and_detect(SAMPLE, chunks, plan.cameras, keep)
             for chunks in plan.tasks]
    key = np.concatenate([p.key for p in parts])
    order = np.lexsort(key.T[::-1])
    camera = np.concatenate([p.camera for p in parts])[order]
    index = np.concatenate([p.index for p in parts])[order]
    frames = [seen[i] for i in order.tolist()]
    expected = list(iter_images(SAMPLE))
    assert [(i.camera, i.frame_index, i.time_ns) for i in expected] == \
        list(zip(camera.tolist(), index.tolist(), key[order, 0].tolist(), strict=True))
    import cv2

    for image, frame in zip(expected, frames, strict=True):
        assert_array_equal(frame, cv2.imdecode(np.frombuffer(image.data, np.uint8),
                                               cv2.IMREAD_COLOR))


def test_a_file_without_a_usable_summary_is_read_image_by_image(tmp_path, monkeypatch):
    """Where the summary says nothing of the chunks (:func:`redetect._plan` gives None),
    the images are read by :func:`iter_images`: the same detections."""
    from recorders import redetect

    fast, slow = tmp_path / "fast.mcap", tmp_path / "slow.mcap"
    monkeypatch.setattr(redetect, "_PARALLEL_FROM", 0)
    redetect_session(SAMPLE, fast, workers=2)
    monkeypatch.setattr(redetect, "_plan", lambda *_args: None)
    redetect_session(SAMPLE, slow, workers=2)
    a, b = read_session(fast).detections, read_session(slow).detections
    for name in ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
                 "cand_radius", "cand_score"):
        assert_array_equal(getattr(b, name), getattr(a, name), err_msg=name)


def test_chunks_are_decompressed_as_every_reader_does_damage_included():
    """:func:`chunk_payload` of a chunk read into a reused buffer (a memoryview of it, as
    redetect's workers read, decompressed without a copy) gives the bytes and the one-line
    error it gives of the chunk's own bytes, for every chunk of the sample and a chunk
    damaged in its data, its CRC, its size or cut short."""
    from pslog.errors import LogFormatError
    from pslog.log import _mcapio as io

    raw = SAMPLE.read_bytes()
    with open(SAMPLE, "rb") as f:
        summary = make_reader(f).get_summary()
    chunks = sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    for c in chunks:
        body = memoryview(raw)[c.chunk_start_offset + 9:c.chunk_start_offset + c.chunk_length]
        assert io.chunk_payload(body) == io.chunk_payload(bytes(body))
    c = max(chunks, key=lambda c: c.chunk_length)  # an image chunk
    record = bytearray(raw[c.chunk_start_offset:c.chunk_start_offset + c.chunk_length])
    crc_at = 9 + 24  # message start and end times, uncompressed size, then the CRC
    damaged = {"data": (len(record) // 2, 0xFF), "crc": (crc_at, 0x01),
               "size": (9 + 16, 0x01), "cut": None}
    for what, flip in damaged.items():
        bad = bytearray(record)
        if flip is None:
            bad = bad[:-1000]
        else:
            bad[flip[0]] ^= flip[1]
        body = memoryview(bytearray(bad))[9:]
        with pytest.raises(LogFormatError) as expected:
            io.chunk_payload(bytes(body))
        with pytest.raises(LogFormatError) as got:
            io.chunk_payload(body)
        assert str(got.value) == str(expected.value), what


@pytest.mark.parametrize("n_chunks,n_images,workers,head", [
    (454, 2160, 2, 48), (454, 2160, 2, 0), (30, 135, 2, 48), (7, 7, 4, 0), (1, 5, 2, 48),
    (100, 30, 3, 0)])
def test_tasks_cover_every_chunk_once_in_order_and_shrink_towards_the_end(
        n_chunks, n_images, workers, head):
    """:func:`redetect._guided`: consecutive runs of every chunk, in order; with a head,
    the first runs hold about ``head`` images; then each run is at most the one before it,
    the last ones about ``_TAIL`` images, so the workers finish together."""
    from recorders import redetect

    chunks = [(i, 1000 * i, 10) for i in range(n_chunks)]
    runs = redetect._guided(chunks, n_images, workers, head)
    assert [c for run in runs for c in run] == chunks and all(runs)
    per_chunk = n_images / n_chunks
    heads = min(redetect._HEAD_TASKS, len(runs)) if head else 0
    for run in runs[:max(heads - 1, 0)]:  # (the last head run may be cut short)
        assert len(run) == max(1, round(head / per_chunk))
    rest = [len(run) for run in runs[heads:]]
    assert rest == sorted(rest, reverse=True)
    if rest:
        smallest = max(1, round(redetect._TAIL / per_chunk))
        assert rest[-1] <= smallest and rest[0] <= max(smallest, -(-n_chunks // (2 * workers)))
    if n_chunks == 454 and not head:  # the redetect benchmark's session: a short tail
        assert len(runs) <= 40 and rest[-1] * per_chunk <= 2 * redetect._TAIL


def _crc_damaged_copy(tmp_path: Path) -> Path:
    """The sample with the stored CRC of an image chunk changed: it decompresses, and only
    its CRC says it is damaged."""
    bad = tmp_path / "crc.mcap"
    chunk = _copy_and_its_image_chunk(bad)
    with open(bad, "r+b") as f:
        f.seek(chunk.chunk_start_offset + 9 + 24)  # after start, end, uncompressed size
        crc = f.read(1)
        f.seek(-1, 1)
        f.write(bytes([crc[0] ^ 1]))
    return bad


def test_copy_leaves_the_crc_of_the_chunks_the_caller_checks(tmp_path):
    """``copy_session(checked_chunks=...)``: the CRC of those chunks is not computed (the
    caller checks it: redetect's workers do, and fail the copy), that of every other chunk
    is."""
    from pslog.errors import LogFormatError
    from pslog.log import copy_session

    bad = _crc_damaged_copy(tmp_path)
    with open(bad, "rb") as f:
        summary = make_reader(f).get_summary()
    offsets = [c.chunk_start_offset for c in summary.chunk_indexes]
    with pytest.raises(LogFormatError, match="CRC mismatch"):
        copy_session(bad, tmp_path / "a.mcap")
    assert not (tmp_path / "a.mcap").exists()
    copy_session(bad, tmp_path / "b.mcap", checked_chunks=offsets)
    assert read_session(tmp_path / "b.mcap").n_images == 135


def test_a_damaged_image_chunk_fails_redetect_though_the_copy_leaves_its_crc(tmp_path):
    """The copy leaves the CRC of the image chunks to the workers, which read each of them:
    a chunk whose CRC does not match still fails the command, nothing written, with one
    worker or two."""
    from recorders import redetect

    bad = _crc_damaged_copy(tmp_path)
    for workers in (1, 2):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(redetect, "_PARALLEL_FROM", 0)
            with pytest.raises(PslogError, match="CRC mismatch"):
                redetect_session(bad, tmp_path / "out.mcap", workers=workers)
        assert sorted(tmp_path.iterdir()) == [bad]


def test_an_interrupt_while_numba_loads_stops_the_first_pool_and_writes_nothing(
        tmp_path, monkeypatch):
    """Ctrl-C while the main process loads the compiled screen (the first pool's workers
    already detecting): the interrupt propagates, every worker is ended, nothing written."""
    import multiprocessing

    from recorders import redetect

    main_pid = os.getpid()

    class _Interrupted(redetect.BallDetector):
        def __init__(self, *args, compiled=False, **kwargs):
            if compiled and os.getpid() == main_pid:
                raise KeyboardInterrupt  # as a Ctrl-C landing in numba's import
            super().__init__(*args, compiled=compiled, **kwargs)

    for name, value in (("_PARALLEL_FROM", 0), ("_COMPILED_FROM", 0), ("_HEAD_TASKS", 2),
                        ("_HEAD", 5), ("BallDetector", _Interrupted)):
        monkeypatch.setattr(redetect, name, value)
    with pytest.raises(KeyboardInterrupt):
        redetect_session(SAMPLE, tmp_path / "out.mcap", workers=2)
    assert list(tmp_path.iterdir()) == [] and multiprocessing.active_children() == []


_DIES_WHILE_ANOTHER_WORKS = """
import os, sys, time
from recorders import redetect
from pslog.cli import main

real, flag = redetect._detect_chunks, sys.argv[3]

def task(*args):
    try:  # the first task's worker dies at once; the others are busy meanwhile
        os.close(os.open(flag, os.O_CREAT | os.O_EXCL))
    except FileExistsError:  # a result too big for the pipe: its writer waits for a reader
        time.sleep(1.0)
        return real(*args), bytes(4 << 20)
    os._exit(3)

redetect._PARALLEL_FROM = 0
redetect._detect_chunks = task
sys.exit(main(["redetect", sys.argv[1], "-o", sys.argv[2], "--workers", "2"]))
"""


def test_a_worker_dying_while_another_works_is_one_line_not_a_hang(tmp_path):
    """The pool's clean-up sends SIGTERM to the other workers, which ignore it (Ctrl-C and
    SIGTERM are the main process's to handle): they are killed instead, not waited for."""
    import subprocess
    import sys

    out, flag = tmp_path / "out" / "out.mcap", tmp_path / "died"
    out.parent.mkdir()
    run = subprocess.run([sys.executable, "-c", _DIES_WHILE_ANOTHER_WORKS, str(SAMPLE),
                          str(out), str(flag)], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[1])
    err = run.stderr.strip()
    assert run.returncode == 1, err
    assert "\n" not in err and "Traceback" not in err and "worker process died" in err
    assert flag.exists() and not list(out.parent.iterdir())


def test_fast_is_near_the_exact_detections_and_the_truth(tmp_path, monkeypatch):
    """``pslog redetect --fast`` (frames decoded at half size, regions brought back to full
    size) through the CLI: every frame keeps its candidate, in full-size pixels, near the
    exact re-detection's (0.24 px RMS measured, no bias) and as near the truth as it (0.26
    px RMS both; thresholding the half-size pixels themselves gave 0.49, a missing half
    pixel's offset in the mapping a 0.5 px bias); worker processes with the compiled screen
    give the same."""
    from recorders import redetect

    exact, fast, pool = tmp_path / "exact.mcap", tmp_path / "fast.mcap", tmp_path / "pool.mcap"
    redetect_session(SAMPLE, exact, workers=1)
    assert main(["redetect", str(SAMPLE), "-o", str(fast), "--fast", "--workers", "1"]) == 0
    a, b = read_session(exact), read_session(fast)
    assert b.metadata["detector_decode"].startswith("half size")
    assert "detector_decode" not in a.metadata
    again = tmp_path / "again.mcap"  # an exact re-detection of it no longer says half size
    redetect_session(fast, again, workers=1)
    assert "detector_decode" not in read_session(again).metadata
    da, db = a.detections, b.detections
    assert_array_equal(db.candidates_per_frame() > 0, da.candidates_per_frame() > 0)
    assert np.count_nonzero(db.candidates_per_frame()) == 135
    d = db.best().uv - da.best().uv
    rms = np.sqrt(np.mean(np.sum(d**2, axis=1)))
    assert 0.05 < rms < 0.35  # not the exact path, and close to it
    assert np.all(np.abs(d.mean(axis=0)) < 0.1)  # no offset
    radius = [det.cand_radius[det.best_mask()] for det in (da, db)]
    assert -0.4 < np.mean(radius[1] - radius[0]) < 0.1
    truth = a.truth
    errors = {}
    for name, det in (("exact", da), ("fast", db)):
        first = det.best_mask()
        frame = det.cand_frame[first]
        xyz = np.stack([np.interp(det.frame_time_ns[frame], truth.time_ns,
                                  truth.position_world[:, k]) for k in range(3)], axis=1)
        err = []
        for c, camera in enumerate(a.rig.cameras):
            rows = det.frame_camera[frame] == c
            err.append(det.cand_uv[first][rows] - camera.project(xyz[rows])[0])
        errors[name] = np.sqrt(np.mean(np.sum(np.concatenate(err) ** 2, axis=1)))
    assert errors["exact"] < 0.3 and errors["fast"] < 0.35, errors
    monkeypatch.setattr(redetect, "_PARALLEL_FROM", 0)  # the sample has only 135 frames
    monkeypatch.setattr(redetect, "_COMPILED_FROM", 0)  # and the compiled screen's step 1
    redetect_session(SAMPLE, pool, workers=2, fast=True)
    c = read_session(pool).detections
    for name in ("cand_frame", "cand_uv", "cand_radius", "cand_score"):
        assert_array_equal(getattr(c, name), getattr(db, name), err_msg=name)


def _broken_images_copy(tmp_path: Path, how: str) -> Path:
    """The sample with every third stored JPEG broken (``how``: no bytes, its first third
    only, or zeros after its first 20 bytes), its detections as stored."""
    session = read_session(SAMPLE)
    path = tmp_path / f"broken-{how}.mcap"
    with SessionWriter(path, session.rig, timing=session.timing) as w:
        w.add_detections(session.detections)
        for k, image in enumerate(iter_images(SAMPLE)):
            data = bytes(image.data)
            if k % 3 == 2:
                data = {"empty": b"", "truncated": data[:len(data) // 3],
                        "zeroed": data[:20] + bytes(len(data) - 20)}[how]
            w.add_image(image.camera, image.frame_index, image.time_ns, data)
    return path


@pytest.mark.parametrize("how", ["empty", "truncated", "zeroed"])
@pytest.mark.parametrize("fast", [False, True])
def test_undecodable_images_keep_their_old_detections_and_are_counted(tmp_path, cli, how,
                                                                       fast):
    """A stored frame that does not decode (no bytes: OpenCV raised; truncated or zeroed:
    no frame) is treated as a frame without a stored image: it keeps its old candidates
    and the note counts it -- no traceback, and no detection silently lost."""
    src, out = _broken_images_copy(tmp_path, how), tmp_path / "out.mcap"
    code, text, err = cli("redetect", src, "-o", out, *(["--fast"] if fast else []))
    assert code == 0 and "Traceback" not in err, err
    assert "re-detected 90 frames: 135 -> 135 frames with a ball candidate" in text
    assert ("45 frames have an image that does not decode (empty, truncated or damaged "
            "JPEG) and keep their old detections") in text
    old, new = read_session(src).detections, read_session(out).detections
    broken = [(i.camera, i.frame_index) for k, i in enumerate(iter_images(src)) if k % 3 == 2]
    for camera, index in broken:
        row_old = np.flatnonzero((old.frame_camera == camera) & (old.frame_index == index))
        row_new = np.flatnonzero((new.frame_camera == camera) & (new.frame_index == index))
        assert_array_equal(new.cand_uv[new.cand_frame == row_new[0]],
                           old.cand_uv[old.cand_frame == row_old[0]])
