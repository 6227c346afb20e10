"""``pslog sync`` finds clock offsets of seconds (two hosts' clocks, never NTP-synced): a
coarse scan of each camera's offset against camera 1's by the agreement of the ball's
pixels with its epipolar lines (``pslog.estimation.sync.coarse_offsets``), then the spline
scan and the joint estimate from there. Before it, a 3 s offset gave 1.5 ms with a note
(its gating lost the ball at the logged clocks) and a 30 s one "not determined"."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _cli import pslog as _pslog

from pslog import read_session
from pslog.estimation.sync import _still, coarse_offsets
from pslog.fusion._prepare import default_max_gap_s


def _offsets(path) -> dict[str, float]:
    return {cam.name: cam.clock_offset for cam in read_session(path).rig.cameras}


@pytest.fixture(scope="module")
def far_apart(tmp_path_factory):
    """paper3, a static object in view, camera 2's clock 3 s ahead and camera 3's 1.2 s
    behind (the logged times: the gating at them loses the ball)."""
    path = tmp_path_factory.mktemp("far") / "far.mcap"
    done = _pslog("simulate", "--rig", "paper3", "--motion", "rally", "--duration", "20",
                  "--noise-px", "0.5", "--clock-offset", "cam2=3000", "--clock-offset",
                  "cam3=-1200", "--distractor", "0.2,1.8,0.1", "--seed", "61800", "-o", path)
    assert done.returncode == 0, done.stderr
    return path


def test_sync_finds_offsets_of_seconds_with_a_static_object_in_view(far_apart, tmp_path):
    out = tmp_path / "synced.mcap"
    done = _pslog("sync", far_apart, "-o", out)
    assert done.returncode == 0, done.stderr
    assert "coarse scan of the offsets" in done.stdout
    got = _offsets(out)
    assert got["cam2"] == pytest.approx(3.0, abs=1e-3)
    assert got["cam3"] == pytest.approx(-1.2, abs=1e-3)


def test_sync_finds_an_offset_of_thirty_seconds_on_a_clean_pair(tmp_path):
    """Two cameras, one candidate a frame (nothing for the gating to lose): the estimate
    from the logged clocks fails, the coarse scan's offsets give it again."""
    path = tmp_path / "far30.mcap"
    done = _pslog("simulate", "--rig", "paper2", "--motion", "rally", "--duration", "40",
                  "--noise-px", "0.5", "--clock-offset", "cam2=30000", "--seed", "61801",
                  "-o", path)
    assert done.returncode == 0, done.stderr
    out = tmp_path / "synced.mcap"
    done = _pslog("sync", path, "-o", out)
    assert done.returncode == 0, done.stderr
    assert "estimated from a coarse scan of the offsets (cam2 +30000" in done.stdout
    assert _offsets(out)["cam2"] == pytest.approx(30.0, abs=1e-3)


def test_the_coarse_scan_itself(far_apart):
    """Within a quarter frame period (8.3 ms at 30 fps) of the truth on the far session;
    the static object's pixels are still; a camera that only sees it says so."""
    s = read_session(far_apart)
    truth = json.loads(s.metadata["truth_clock"])["cameras"]
    delta, notes = coarse_offsets(s.detections, s.rig, 10.0, default_max_gap_s(s.rig))
    assert notes == []
    assert delta[0] == 0
    assert delta[1] == pytest.approx(truth["cam2"]["clock_offset"], abs=0.25 / 30 + 1e-9)
    assert delta[2] == pytest.approx(truth["cam3"]["clock_offset"], abs=0.25 / 30 + 1e-9)
    # a static object's pixel (noise 0.5 px) in 40 % of frames, the ball moving elsewhere
    rng = np.random.default_rng(61802)
    moving = rng.uniform(0, 640, (800, 2))
    moving = moving[np.hypot(*(moving - [300.0, 200.0]).T) > 20][:600]
    uv = np.r_[rng.normal([300.0, 200.0], 0.5, (400, 2)), moving]
    still = _still(uv)
    assert still[:400].all() and not still[400:].any()
    # only the static object for camera 3: nothing to scan
    det = s.detections
    cam = det.frame_camera[det.cand_frame]
    keep = (cam != 2) | still_rows(det, 2)
    only = type(det)(det.camera_names, det.frame_time_ns, det.frame_camera, det.frame_index,
                     det.cand_frame[keep], det.cand_uv[keep], det.cand_radius[keep],
                     det.cand_score[keep])
    delta, notes = coarse_offsets(only, s.rig, 10.0, default_max_gap_s(s.rig))
    assert delta[2] == 0 and "camera cam3: too few moving detections" in notes[0]


def still_rows(det, camera: int) -> np.ndarray:
    """(C,) bool: the candidates of ``camera`` whose pixels are still (the object's)."""
    cam = det.frame_camera[det.cand_frame]
    out = np.zeros(len(cam), dtype=bool)
    rows = np.flatnonzero(cam == camera)
    out[rows] = _still(det.cand_uv[rows])
    return out
