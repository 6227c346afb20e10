"""A hostile user of ``pslog live``: datagrams no camera would send (random bytes of every
length, valid headers with absurd contents, capture times far in the future, sequence
jumps and restarts) never crash the fuser nor stop it fusing the honest cameras; absurd
command lines are one-line usage errors."""

from __future__ import annotations

import math
import os
import random

import numpy as np
import pytest

from pslog.live.fuser import LiveFuser
from pslog.live.protocol import _DET_HEADER, DetectionDatagram, encode_detections
from tests._live import EPOCH, datagrams, frames, rally_session

from ._inprocess import first_case, run_inprocess
from .promises import HANG_S, assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def session():
    return rally_session(1.0)


def _feed(fuser, data, arrival=None):
    """Feed every datagram as if it arrived at its capture time (a real-time sender)."""
    points = []
    for d in data:
        t = int.from_bytes(d[24:32], "little", signed=True) if arrival is None else arrival
        points += fuser.feed(d, t)
    return points


def test_random_bytes_and_hostile_headers_never_crash_the_fuser(session):
    rig, det = session
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    for n in range(3000):  # every length, random contents
        assert fuser.feed(os.urandom(n), EPOCH) == []
    rnd = random.Random(7)
    odd = [0.0, 1e308, -1e308, math.nan, math.inf, 100.0, -5.0]
    for _ in range(2000):
        name = rnd.choice([b"cam1", bytes(rnd.randrange(256) for _ in range(32)), b"\xff" * 32])
        t = rnd.choice([-2**63, 2**63 - 1, EPOCH, 0, EPOCH + 1])
        body_k = rnd.choice([0, 1, 2, 64])
        body = np.array([[rnd.choice(odd) for _ in range(4)] for _ in range(body_k)],
                        "<f8").tobytes()
        data = _DET_HEADER.pack(b"PSLD", 1, rnd.choice([0, 1, 4, 32, 33, 255]),
                                rnd.choice([0, 1, 2, 64, 65, 65535]),
                                rnd.choice([0, 1, 2**64 - 1]), rnd.choice([-2**63, 0, 2**63 - 1]),
                                t, t, name[:32].ljust(32, b"\0")) + body
        fuser.feed(data, EPOCH)
    # and the fuser still fuses the honest session afterwards, as a fresh one does
    honest = datagrams(det, rig, EPOCH + 10**9)
    fresh = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    assert len(_feed(fuser, honest)) == len(_feed(fresh, honest)) > 0


def test_a_capture_time_in_the_far_future_does_not_make_every_later_frame_late(session):
    """One datagram stamped a day ahead (a camera with a wrong clock, or an attacker) must
    not become 'the newest frame' that every honest frame after it is older than."""
    rig, det = session
    honest = datagrams(det, rig)
    half = len(honest) // 2
    clean = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    expected = len(_feed(clean, honest[half:]))
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    _feed(fuser, honest[:half])
    f = frames(det, rig)[half]
    future = DetectionDatagram(f.camera, 10**6, 0, f.t_capture_ns + 86_400 * 10**9,
                               f.t_capture_ns, f.uv, f.radius, f.score)
    fuser.feed(encode_detections(future), f.t_capture_ns)
    after = _feed(fuser, honest[half:])
    assert fuser.counters()["future"] == 1
    assert len(after) >= expected > 0


@pytest.mark.parametrize("args, contains", [
    (("--duration", "1e300"), ("--duration", "at most")),
    (("--duration", "1e300", "--source", "cam1=missing.mp4"), ("--duration", "at most")),
    (("--status-every", "1e300"), ("--status-every", "at most")),
])
def test_absurdly_long_times_are_usage_errors(tmp_path, args, contains, request):
    # the first case as a real process, the others in this one (tests/faults/_inprocess.py)
    run = (run_pslog if first_case(request) else run_inprocess)(
        "live", "--rig", "paper3", "--listen", "udp://127.0.0.1:0", *args, cwd=tmp_path)
    assert_one_line_error(run, 2, contains=contains)
    assert list(tmp_path.iterdir()) == []


def test_a_sender_that_restarts_its_sequence_keeps_the_lost_count_true(session):
    """docs/live.md allows a sender to restart its sequence (new capture times): frames lost
    before the restart stay counted, and frames lost after it are counted too."""
    from dataclasses import replace

    rig, det = session
    fr = frames(det, rig)
    cam1 = [i for i, d in enumerate(fr) if d.camera == "cam1"]
    mid = len(cam1) // 2
    renumber = {i: n for n, i in enumerate(cam1[mid:], start=1)}  # restarts at 1
    skip = {cam1[3], cam1[mid + 4], cam1[mid + 5]}  # one lost before, two after
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    for i, d in enumerate(fr):
        if i not in skip:
            d = replace(d, sequence=renumber[i]) if i in renumber else d
            fuser.feed(encode_detections(d), d.t_capture_ns)
    assert fuser.counters()["lost"] == 3
    assert [c.lost for c in fuser.cameras()] == [3, 0, 0]


def test_jsonl_with_standard_output_closed_is_one_line_before_anything_starts(tmp_path):
    """``pslog live --jsonl >&-``: said at once, no camera started, no session written."""
    run = run_pslog("live", "--rig", "paper3", "--listen", "udp://127.0.0.1:0", "--synthetic",
                    "--duration", "0.5", "--jsonl", "--record", tmp_path / "s.mcap",
                    preexec_fn=lambda: os.close(1))
    assert_one_line_error(run, 1, contains=("standard output", "closed"))
    assert list(tmp_path.iterdir()) == []


def test_sigint_stops_a_run_whose_jsonl_reader_stopped_reading(tmp_path):
    """``pslog live --jsonl | stalled-reader``: the full pipe must not make Ctrl-C hang; the
    run stops, exit 0, the session is complete."""
    import fcntl
    import signal
    import subprocess
    import sys
    import time

    from pslog.log import read_session

    r, w = os.pipe()
    fcntl.fcntl(w, 1031, 4096)  # F_SETPIPE_SZ: a one-page pipe, full after a few points
    proc = subprocess.Popen(
        [sys.executable, "-m", "pslog.cli", "live", "--rig", "paper3", "--timing", "typeA",
         "--synthetic", "--duration", "60", "--listen", "udp://127.0.0.1:0", "--jsonl",
         "--record", "s.mcap"], cwd=tmp_path, stdout=w, stderr=subprocess.PIPE, text=True)
    os.close(w)
    try:
        # Ctrl-C once points came (a pipe of one page is full, to select(), as soon as it
        # holds anything) and a few seconds later, not after a fixed sleep from the start:
        # on a loaded machine the cameras may not even have started by then. A hang guard.
        deadline = time.monotonic() + HANG_S
        while _unread_bytes(r) == 0:
            assert proc.poll() is None, proc.communicate()[1]
            assert time.monotonic() < deadline, f"no point on stdout within {HANG_S} s"
            time.sleep(0.05)
        time.sleep(3.0)  # the run goes on fusing and recording while stdout is full
        proc.send_signal(signal.SIGINT)
        try:
            _, err = proc.communicate(timeout=HANG_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            raise AssertionError("Ctrl-C did not stop a run whose stdout was full") from None
    finally:
        os.close(r)
        if proc.poll() is None:  # a failed wait above: not left running for a minute
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    assert len(read_session(tmp_path / "s.mcap").tracks["filter"].time_ns) > 20


def _unread_bytes(fd: int) -> int:
    """Bytes waiting in the pipe whose read end is ``fd`` (FIONREAD)."""
    import fcntl
    import struct
    import termios

    return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0" * 4))[0]


@pytest.mark.parametrize("sequence, future", [(2**64 - 1, False), (10**6, True)])
def test_a_sequence_jump_no_camera_could_make_is_not_counted_lost(session, sequence, future):
    """One datagram numbered 2**64 - 1 (or a forged future one) must not put 1.8e19 frames
    'lost' on the status line for the rest of the run."""
    from dataclasses import replace

    rig, det = session
    fr = frames(det, rig)
    half = len(fr) // 2
    fuser = LiveFuser(rig, "filter", epoch_ns=EPOCH)
    for i, d in enumerate(fr):
        if i == half:
            d = replace(d, sequence=sequence,
                        t_capture_ns=d.t_capture_ns + (86_400 * 10**9 if future else 0))
            fuser.feed(encode_detections(d), fr[i].t_capture_ns)
            continue
        fuser.feed(encode_detections(d), d.t_capture_ns)
    assert fuser.counters()["lost"] <= 1  # the honest frame replaced by the forged one


def test_an_absurd_video_offset_is_a_usage_error_naming_it(tmp_path):
    """``--source cam1=clip.avi@1e300`` was an OverflowError repr from the camera process."""
    import cv2

    writer = cv2.VideoWriter(str(tmp_path / "clip.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30,
                             (640, 480))
    for _ in range(3):
        writer.write(np.zeros((480, 640, 3), np.uint8))
    writer.release()
    before = fingerprint(tmp_path / "clip.avi")
    run = run_pslog("live", "--rig", "paper3", "--listen", "udp://127.0.0.1:0", "--duration",
                    "1", "--source", "cam1=clip.avi@1e300", "--record", "s.mcap", cwd=tmp_path)
    assert_one_line_error(run, 2, contains=("offset", "1e300"))
    assert_untouched(before, tmp_path / "clip.avi")
    assert not (tmp_path / "s.mcap").exists()
