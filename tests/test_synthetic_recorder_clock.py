"""Session 43: the synthetic recorder's shutter ``offset`` is a phase on the TRUE clock, as
docs/timing.md defines it and ``pslog simulate`` and ``pslog info`` take it. A camera whose
clock the rig corrects (clock_offset, drift) had frame ``k`` stamped at ``offset + k / fps``
on its LOGGED clock, so its shutter fired at ``offset + clock_offset`` (walk42 item 14:
``info`` read cam2 at 15.3 ms against the rig's 11.1). Now the recorder stamps what the
clock model maps the true schedule onto, the stamps ``pslog simulate`` logs: a sign error
either way moves them by twice the clock offset."""

from __future__ import annotations

import json

import numpy as np
from _cli import pslog_ok

from pslog.log import read_session
from pslog.rig import apply_timing, builtin_rig, save_rig


def test_recorded_stamps_are_simulates_and_the_phases_the_rigs(tmp_path):
    from dataclasses import replace

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    cam1, cam2, cam3 = rig.cameras
    clocks = replace(rig, cameras=(cam1, replace(cam2, clock_offset=0.0042, clock_drift_ppm=40.0),
                                   replace(cam3, clock_offset=-0.0035)))
    save_rig(clocks, tmp_path / "clocks.toml")
    recorded, simulated = tmp_path / "rec.mcap", tmp_path / "sim.mcap"
    pslog_ok("record", "--synthetic", "--rig", tmp_path / "clocks.toml", "--duration", "1",
             "--fast", "--no-frames", "--seed", "75040", "-o", recorded)
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "1",
             "--clock-offset", "cam2=4.2", "--drift", "cam2=40", "--clock-offset", "cam3=-3.5",
             "--seed", "75040", "-o", simulated)
    rec, sim = read_session(recorded).detections, read_session(simulated).detections
    for i in range(3):
        stamps = rec.frame_time_ns[rec.frame_camera == i]
        assert np.array_equal(stamps, sim.frame_time_ns[sim.frame_camera == i]), i
    # cam2's first stamp: 11.111 ms on the true clock, 4.2 ms less (and 40 ppm) on its own
    first = rec.frame_time_ns[rec.frame_camera == 1][0]
    assert abs(first - (1 / 90 - 0.0042) / (1 + 40e-6) * 1e9) < 1.0, first
    info = json.loads(pslog_ok("info", recorded, "--json"))
    for cam in info["cameras"]:  # the measured phases are the rig's (corrected times)
        rig_ms = 1e3 * clocks.camera(cam["name"]).offset
        assert abs(cam["offset_measured_s"] * 1e3 - rig_ms) < 1e-3, cam


def test_simulate_keeps_the_rig_files_own_clock(tmp_path):
    """A rig file with clock keys (cam3 a 25 ms rolling shutter, cam2's clock 3 ms behind: a
    synced rig's): ``pslog simulate`` simulated the cameras with them but wrote the session's
    rig with zeros, silently; fused, smooth was 13.6 mm off the truth (2.0 with the rig's
    clock). Now the session's rig is the rig's own, as ``record --synthetic``'s; faults given
    as options are still hidden from it (the rig's value kept, the truth in truth_clock)."""
    from dataclasses import replace

    from pslog.evaluation import evaluate
    from pslog.simulation import read_truth_clock

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    cam1, cam2, cam3 = rig.cameras
    own = replace(rig, cameras=(cam1, replace(cam2, clock_offset=0.003),
                                replace(cam3, readout=0.025)))
    save_rig(own, tmp_path / "own.toml")
    session, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    pslog_ok("simulate", "--rig", tmp_path / "own.toml", "--motion", "rally", "--duration", "6",
             "--noise-px", "0.3", "--seed", "75041", "-o", session)
    assert read_session(session).rig == own
    said = pslog_ok("fuse", session, "--method", "smooth", "-o", fused)
    assert "note:" not in said  # (not "a clock model no 'pslog sync' estimated on it")
    done = read_session(fused)
    assert evaluate(done.tracks["smooth"], done.truth).mean_mm < 3.0
    faulted = tmp_path / "faulted.mcap"
    pslog_ok("simulate", "--rig", tmp_path / "own.toml", "--duration", "1", "--readout",
             "cam3=20", "--seed", "75042", "-o", faulted)
    s = read_session(faulted)
    assert s.rig == own
    truth = read_truth_clock(s.rig, s.metadata)
    assert [c.readout for c in truth.cameras] == [0.0, 0.0, 0.02]
    assert truth.cameras[1].clock_offset == 0.003
