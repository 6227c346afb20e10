"""The start and the end of a recording: cameras warmed before "ready", no stall before a
camera's first frame, a stop while a camera is still opening, a run where no camera opens,
and what the help texts and the README promise (real camera processes, the real CLI)."""

from __future__ import annotations

import io
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np

from pslog.cli import main
from pslog.log import read_session
from pslog.records import NS
from pslog.rig import builtin_rig, save_rig
from tests._sources import ORANGE_BGR, ScheduledSource, Spec


def _clip(path: Path, n: int = 10) -> str:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
    for k in range(n):
        frame = np.full((480, 640, 3), (60, 120, 70), np.uint8)
        cv2.circle(frame, (300 + k, 240), 6, ORANGE_BGR, -1)
        writer.write(frame)
    writer.release()
    return str(path)


# ---- a camera whose first frame comes late ------------------------------------------------
class _LateSource(ScheduledSource):
    """A live 30 fps camera whose first frame comes 1.6 s after the start (a camera that
    starts slowly), then 10 frames on time."""

    def delay_s(self, k: int) -> float:
        return 1.6

    def end(self, k: int) -> bool:
        return k == 10


def test_a_camera_whose_first_frame_is_late_is_not_stalled(tmp_path):
    """Its first frame 1.6 s after the start: no "no frame for" warning, no stall events (they
    came at 1 s, and the "delivering again" of its first frame was logged at a time before the
    "stopped delivering" one)."""
    from recorders.record import record
    from recorders.sources import FileSpec

    out = tmp_path / "s.mcap"
    said = io.StringIO()
    cameras = {"cam1": FileSpec(_clip(tmp_path / "a.avi"), 640, 480),
               "cam2": Spec(_LateSource, "late test camera")}
    summary = record(builtin_rig("paper2"), cameras, out, status=said)
    assert [c.frames for c in summary.cameras] == [10, 10], said.getvalue()
    assert "no frame" not in said.getvalue() and "STALLED" not in said.getvalue(), said.getvalue()
    events = read_session(out).events
    assert not [text for _t, text in events if "delivering" in text], events
    times = [t for t, _text in events]
    assert times == sorted(times), events


# ---- a camera that never opens --------------------------------------------------------------
class _NeverOpens:
    def describe(self) -> str:
        return "a camera that takes for ever to open"

    def open(self):
        time.sleep(120)
        raise AssertionError("not stopped")


def test_a_stop_while_a_camera_opens_does_not_wait_for_it(tmp_path):
    """A stop before every camera said "ready": the ones still opening (importing OpenCV,
    opening a device: seconds) hold no frame and are ended at once, not waited for up to
    the stop timeout (10 s; 12-15 s seen from the command line)."""
    from recorders.record import _STOP_TIMEOUT_S, StopRequest, record
    from recorders.sources import FileSpec

    out = tmp_path / "s.mcap"
    stop = StopRequest()
    said = io.StringIO()
    stopped_at: list[float] = []

    def press() -> None:
        stopped_at.append(time.monotonic())
        stop.set("SIGINT")

    timer = threading.Timer(1.0, press)
    timer.start()
    try:
        summary = record(builtin_rig("paper2"),
                         {"cam1": FileSpec(_clip(tmp_path / "a.avi"), 640, 480),
                          "cam2": _NeverOpens()}, out, status=said, stop_request=stop)
    finally:
        timer.cancel()
    took = time.monotonic() - stopped_at[0]
    assert summary.interrupted and summary.n_frames == 0
    assert [c.state for c in summary.cameras] == ["stopped", "stopped"], said.getvalue()
    assert took < _STOP_TIMEOUT_S / 2, f"{took:.1f} s to stop\n{said.getvalue()}"
    assert list(tmp_path.iterdir()) == [tmp_path / "a.avi"]  # no session file left


def test_no_camera_opens_leaves_no_file_and_says_so(tmp_path, capsys):
    """Every source fails to open: one error line, exit 1, no calibration-only file (which
    refused the same command the next time: "exists; use --force"), and no camera is said
    to keep recording; with --force an old session stays as it was."""
    rig = tmp_path / "rig.toml"
    save_rig(builtin_rig("paper2"), rig)
    out = tmp_path / "W.mcap"
    argv = ["record", "--rig", str(rig), "--source", "cam1=/dev/video62", "--source",
            "cam2=/dev/video63", "-o", str(out)]
    assert main(argv) == 1
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]
    assert last == f"pslog record: error: no camera delivered a frame; nothing was written " \
                   f"to {out}", err
    assert "keep recording" not in err and "Traceback" not in err, err
    assert "nothing recorded to" in err and "recorded: " not in err, err
    assert sorted(tmp_path.iterdir()) == [rig]  # the same command can run again
    out.write_bytes(b"an old session")
    assert main([*argv, "--force"]) == 1
    assert "nothing was written" in capsys.readouterr().err
    assert out.read_bytes() == b"an old session" and not Path(f"{out}.partial").exists()


# ---- warming up -------------------------------------------------------------------------------
_WARM = """
import sys
import numpy as np, cv2
from recorders import detect
from recorders.record import frame_size, jpeg_params, warm_camera
from recorders.sources import DeviceSpec
spec = DeviceSpec(0, 1280, 720, 30.0)
assert frame_size(spec) == (1280, 720)
detector = detect.BallDetector()
warm_camera(detector, spec, jpeg_params(90))
caches = (detect._bgr_box, detect._nearest_is_stride, detect._wide_bounds)
before = [c.cache_info().misses for c in caches]
frame = np.full((720, 1280, 3), (60, 120, 70), np.uint8)
cv2.circle(frame, (400, 300), 8, (20, 110, 255), -1)
found = detector.detect(frame)
assert len(found) == 1, found
after = [c.cache_info().misses for c in caches]
assert after == before, (before, after)
print("warm")
"""


def test_a_warmed_detector_computes_nothing_lazily_on_the_first_frame():
    """A fresh process (the caches are per process, like a camera's): after the warm-up, the
    first real frame finds every lazily computed table (the colour range's BGR box, about
    0.3 s, that made every real-time camera skip its frames after the first one) ready."""
    run = subprocess.run([sys.executable, "-c", _WARM], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "warm", run.stderr


class _WarmCheckSource:
    """Three frames; the first read fails unless this camera process's detector was warmed
    before (the colour range's BGR box already computed)."""

    clock = "test clock"
    live = False

    def __init__(self) -> None:
        self.k = 0

    def read(self):
        from recorders import detect
        from recorders.sources import SourceError

        if self.k == 0 and not detect._bgr_box.cache_info().currsize:
            raise SourceError("the detector was not warmed before the first frame")
        if self.k == 3:
            return None
        self.k += 1
        return self.k - 1, int((self.k - 1) * NS / 30), np.zeros((480, 640, 3), np.uint8)

    def set_start(self, t0_ns: int) -> None:
        pass

    def close(self) -> None:
        pass


def test_camera_processes_warm_their_detector_before_the_first_frame(tmp_path):
    from recorders.record import record

    summary = record(builtin_rig("paper2"), {name: Spec(_WarmCheckSource, "warm-check test camera")
                                             for name in ("cam1", "cam2")},
                     tmp_path / "s.mcap", status=None)
    assert [(c.frames, c.message) for c in summary.cameras] == [(3, "end of source")] * 2


# ---- what the help texts and the README say -----------------------------------------------
def _help(command: str, capsys) -> str:
    try:
        main([command, "--help"])
    except SystemExit:
        pass
    return " ".join(capsys.readouterr().out.split())


def test_help_and_readme_agree_on_signals_and_what_a_sigkill_loses(capsys):
    from pslog.motion import MOTIONS

    readme = " ".join((Path(__file__).parents[1] / "README.md").read_text().split())
    record_help, live_help = _help("record", capsys), _help("live", capsys)
    for text in (record_help, live_help, readme):
        assert "at most the last half second written" in text
        assert "SIGHUP" in text
    for text in (record_help, live_help):
        assert "flushed every 0.5 s" in text
    for name in MOTIONS:
        assert name in record_help.split("synthetic ball motion:")[1][:120], name
    # record's exit codes on a stop, in the README and in its help
    assert "exits 0 once frames were recorded, 1 (leaving no file) when stopped before any " \
           "camera delivered a frame" in readme
    assert "exit code 0 once frames were recorded, 1 (and no file) when stopped before any " \
           "camera delivered a frame" in record_help
