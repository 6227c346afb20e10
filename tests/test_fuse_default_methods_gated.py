"""``pslog fuse``'s default methods judge the timing on each frame's ball as the gate chooses
it, not on the best-scored candidate (walk38): on a rig of three rolling-shutter webcams
after ``pslog sync``, a static second orange object every camera sees was best-scored in
most frames, and its rows' readout-corrected times fell within 1 ms in two cameras, so a
sixth of the instants looked shared and ``sync``, ``typeB`` and ``linear`` ran by default on
a few dozen points up to 0.94 m off. Through the real CLI on sessions ``pslog simulate``
writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from _cli import pslog as _pslog

from pslog.fusion import FusionOptions, default_methods
from pslog.log import read_session
from pslog.rig import load_rig

WEBCAMS3 = Path(__file__).resolve().parents[1] / "benchmarks" / "webcams3.toml"


def _rig(path: Path, clocks: bool) -> Path:
    """webcams3 with shutter phases 0 / 7.1 / 19.7 ms; ``clocks``: with the session's true
    clocks (25 ms readouts, the offsets below), as ``pslog sync`` would give them."""
    text = WEBCAMS3.read_text()
    head, *cameras = text.split("[[camera]]")
    out = []
    for camera, (phase, offset) in zip(cameras, [(0.0, 0.0), (0.0071, 0.0064),
                                                 (0.0197, -0.0089)], strict=True):
        camera = camera.replace("offset = 0.0\n", f"offset = {phase}\n")
        if clocks:
            camera = camera.rstrip("\n") + (f"\nclock_offset = {offset}\n" if offset else "\n")
            camera += "readout = 0.025\n\n"
        out.append(camera)
    path.write_text(head + "".join("[[camera]]" + c for c in out))
    return path


def test_default_methods_leave_out_stereo_when_only_a_static_object_shares_instants(
        tmp_path):
    rig = _rig(tmp_path / "rig.toml", clocks=False)
    true = _rig(tmp_path / "true.toml", clocks=True)
    session = tmp_path / "lab.mcap"
    done = _pslog("simulate", "--rig", rig, "--motion", "rally", "--duration", "4",
                  "--noise-px", "0.5", "--readout", "25", "--clock-offset", "cam2=6.4",
                  "--clock-offset", "cam3=-8.9", "--distractor", "0.2,1.8,0.1", "--seed", "8",
                  "-o", session)
    assert done.returncode == 0, done.stderr
    # the mechanism: the best-scored candidates (the object's, mostly) share instants, and
    # with gating off (those are what the methods then fuse) stereo is still chosen
    detections, clocks = read_session(session).detections, load_rig(true)
    assert "sync" in default_methods(detections, clocks, FusionOptions(gating=False))
    fused = tmp_path / "fused.mcap"
    done = _pslog("fuse", session, "--rig", true, "-o", fused)
    assert done.returncode == 0, done.stderr
    assert "not run on this timing: sync, typeB, linear" in done.stdout, done.stdout
    assert set(read_session(fused).tracks) == {"nearest", "typeA", "smooth", "filter"}


def test_the_default_methods_gating_pass_is_the_fusions_own(tmp_path, monkeypatch):
    """Where ``default_methods`` gates the session to judge its timing (the case above), the
    fusion takes that pass as its causal form's (typeA, nearest, filter: every choice's
    doubt) instead of gating again: two passes, not three (on these webcams the pass came
    before the fusion, on one thread: about a fifth of a 60-s session's ``pslog fuse``). The
    tracks are those of the methods named, which never make that pass, bit for bit. Fails
    when the pass is not handed on (three calls of the gate)."""
    import pslog
    import pslog.fusion.gating as gating

    rig = _rig(tmp_path / "rig.toml", clocks=False)
    true = _rig(tmp_path / "true.toml", clocks=True)
    session = tmp_path / "lab.mcap"
    done = _pslog("simulate", "--rig", rig, "--motion", "rally", "--duration", "3",
                  "--noise-px", "0.5", "--readout", "25", "--clock-offset", "cam2=6.4",
                  "--clock-offset", "cam3=-8.9", "--distractor", "0.2,1.8,0.1", "--seed",
                  "60203", "-o", session)
    assert done.returncode == 0, done.stderr
    calls = []
    real = gating.gate
    monkeypatch.setattr(gating, "gate", lambda *a, **k: calls.append(k.get("causal", True))
                        or real(*a, **k))
    default = pslog.fuse(session, rig=true)
    assert sorted(calls) == [False, True], calls  # the offline form (smooth's) and one causal
    assert set(default.tracks) == {"nearest", "typeA", "smooth", "filter"}
    named = pslog.fuse(session, list(default.tracks), rig=true)
    for method, track in default.tracks.items():
        other = named.tracks[method]
        np.testing.assert_array_equal(track.time_ns, other.time_ns)
        np.testing.assert_array_equal(track.position_world, other.position_world)
        for name, column in track.quality.items():
            np.testing.assert_array_equal(column, other.quality[name], err_msg=name)
        assert track.dropped == other.dropped
        assert default.rejections[method].counts() == named.rejections[method].counts()


def test_default_methods_keep_stereo_where_only_the_gates_choice_shares_instants():
    """The other direction (review39): a ``typeB`` rig (synchronised pairs) with 8 ms rolling
    shutters and a static orange object in cam1's view best-scored in many of its frames.
    The object's rows' corrected times seldom meet the other cameras', so the best-scored
    instants share less than ``SHARED_SHARE_MIN`` and ``sync``, ``typeB`` and ``linear`` were
    left out; the ball as the gate chooses it shares enough. Fails when the gate judges only
    sessions whose best-scored instants already share."""
    from pslog.fusion import SHARED_SHARE_MIN
    from pslog.fusion.stereo import sync_groups
    from pslog.motion import get_motion
    from pslog.rig import apply_timing, builtin_rig
    from pslog.simulation import SimulationOptions, simulate_labelled
    from pslog.timing import observations as timed

    rig = apply_timing(builtin_rig("paper3"), "typeB")
    rig = rig.__class__(tuple(c.replace(readout=0.008) for c in rig.cameras), rig.name)
    det = simulate_labelled(rig, get_motion("throw"), None, SimulationOptions(
        noise_px=0.3, seed=60210, distractors=(("cam1", (0.5, 1.0, 0.2)),)))[0]
    _, n_cameras = sync_groups(timed(det, rig), len(rig), FusionOptions().tolerance_s)
    assert (n_cameras >= 2).mean() < SHARED_SHARE_MIN  # the premise: best-scored, too few
    assert {"sync", "typeB", "linear"} <= set(default_methods(det, rig))
