"""Session 29's leftovers of issue 10 through the real CLI: messages that named the wrong
command or stage."""

from __future__ import annotations

from pathlib import Path

import pytest

from pslog.rig import builtin_rig

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep29")
    (folder / "rig.toml").write_text(builtin_rig("paper3").to_toml(), encoding="utf-8")
    # cam1 sees a moving ball; cam2's and cam3's detections are 60,000 px off their images
    # (accepted by import: within its bound; no detection to a fit)
    rows = ["camera,time,u,v"]
    for i in range(90):
        t, cam = i / 90, f"cam{i % 3 + 1}"
        uv = (300 + 100 * t, 200 + 50 * t) if cam == "cam1" else (60000, 60000)
        rows.append(f"{cam},{t:.6f},{uv[0]!r},{uv[1]!r}")
    (folder / "far.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    done = run_pslog("import", "--rig", folder / "rig.toml", "--detections",
                     folder / "far.csv", "-o", folder / "far.mcap")
    assert done.code == 0, done.stderr
    return folder


@pytest.mark.parametrize("estimate", ["auto", "offset"])
def test_a_sync_whose_track_cannot_be_fitted_says_so_in_syncs_words(estimate, inputs,
                                                                    tmp_path):
    """Was "pslog sync: error: smooth: no stretch of the session is seen by two cameras":
    the trajectory fit's message with the fusion method's name. Now sync's context, and why
    two thirds of the detections were no detection."""
    before = fingerprint(inputs, tmp_path)
    line = assert_one_line_error(run_pslog(
        "sync", inputs / "far.mcap", "-o", tmp_path / "s.mcap", "--estimate", estimate), 1,
        contains=("pslog sync: error: the ball's track, on which the clocks are estimated, "
                  "cannot be fitted: no stretch of the session is seen by two cameras (one "
                  "camera cannot triangulate); 60 of 90 detections lie more than 10 image "
                  "sizes off their image and are no detection",))
    assert "smooth" not in line, line
    assert_untouched(before, inputs, tmp_path)
