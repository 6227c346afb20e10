"""Hostile timing values through the real CLI (issue 9): clock keys in rigs, clock faults of
``pslog simulate``, times from any clock in ``pslog import`` / ``export``. Each case asserts
the three promises of :mod:`tests.faults.promises`."""

from __future__ import annotations

from pathlib import Path

import pytest

from ._inputs import write_session_and_rig
from .promises import assert_refused


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """A folder with a type-A session, its rig, a session with a malformed clock origin and
    an old simulated output."""
    from pslog.log import SessionWriter, read_session

    folder = tmp_path_factory.mktemp("inputs")
    rig = write_session_and_rig(folder)
    with SessionWriter(folder / "origin.mcap", rig, timing="typeA",
                       metadata={"clock_origin_ns": "12 s"}) as writer:
        writer.add_detections(read_session(folder / "s.mcap").detections)
    (folder / "old.mcap").write_bytes((folder / "s.mcap").read_bytes())
    return folder


@pytest.mark.parametrize("fault, why", [
    (("--clock-offset", "cam1=1"), ("--clock-offset", "'cam1'", "defines the session clock")),
    (("--drift", "cam9=3"), ("--drift", "unknown camera 'cam9'")),
    (("--drift", "cam2=inf"), ("--drift", "finite")),
    (("--readout", "50"), ("--readout", "readout 0.05 s must be in")),
    (("--host-jitter", "17"), ("--host-jitter", "below half a frame period")),
])
def test_bad_simulated_clock_faults_exit_2_and_replace_nothing(work, fault, why):
    assert_refused(work, 2, ["simulate", "--rig", "paper3", *fault, "-o", "old.mcap", "--force"],
                   why)


@pytest.mark.parametrize("line, why", [
    ("clock_offset = 0.002", ("rig.toml", "camera 'cam1'", "defines the session clock")),
    ("readout = 0.04", ("rig.toml", "camera 'cam1'", "readout 0.04 s must be in")),
    ("clock_drift_ppm = nan", ("rig.toml", "camera 'cam1'", "clock_drift_ppm must be finite")),
])
def test_bad_clock_keys_in_a_rig_are_refused_naming_file_and_camera(work, line, why):
    rig = (work / "rig.toml").read_text()
    (work / "rig.toml").write_text(rig.replace("offset = 0.0\n", f"offset = 0.0\n{line}\n", 1))
    assert_refused(work, 1, ["fuse", "s.mcap", "--rig", "rig.toml", "-o", "f.mcap"], why)


def test_times_spanning_beyond_a_session_clock_are_refused(work):
    (work / "wide.csv").write_text("camera,time,u,v\ncam1,-9000000000,1,2\n"
                                   "cam2,9000000000,3,4\n")
    assert_refused(work, 1,
                   ["import", "--rig", "paper3", "--detections", "wide.csv", "-o", "w.mcap"],
                   ("times span", "a session holds at most"))


def test_a_malformed_clock_origin_is_one_line(work):
    assert_refused(work, 1, ["export", "origin.mcap", "--detections", "d.csv"],
                   ("origin.mcap", "clock_origin_ns '12 s' is not an integer"))
