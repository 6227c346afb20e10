"""Findings of session 13's hostile sweep: each valid input works or gets one clear line
(no LinAlgError, no RigError for an estimate, no NaN/inf in a table, strict JSON)."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

from pslog.errors import FusionError
from pslog.estimation.sync import estimate_clocks
from pslog.log import SessionWriter
from pslog.motion import get_motion
from pslog.records import Detections, Observations
from pslog.simulation import SimulationOptions, simulate


def _strict_json(text: str):
    def refuse(name):
        raise ValueError(f"not JSON: {name}")
    return json.loads(text, parse_constant=refuse)


def test_sync_names_a_camera_whose_detections_lie_off_every_epipolar_line(rig3):
    # camera 3 sees something else: its pixels mirrored and squashed (the sweep's away.csv),
    # so the joint solve rejects them all; its clock column was empty: Singular matrix
    detections, _ = simulate(rig3, get_motion("spiral"), 1.0,
                             SimulationOptions(noise_px=0.3, seed=1))
    obs = detections.best()
    uv = obs.uv.copy()
    away = obs.camera == 2
    rng = np.random.default_rng(1)
    uv[away, 0] = 600 - 0.5 * uv[away, 0] + 5 * rng.random(np.count_nonzero(away))
    uv[away, 1] = 460 - 0.7 * uv[away, 1]
    obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    with pytest.raises(FusionError, match=r"camera cam\d: none of its detections fits"):
        estimate_clocks(obs, rig3, ("offset",))


def test_sync_refuses_an_offset_search_as_long_as_the_session_up_front(rig3):
    detections, _ = simulate(rig3, get_motion("spiral"), 1.0, SimulationOptions(seed=1))
    obs = detections.best()
    span = (obs.time_ns.max() - obs.time_ns.min()) / 1e9
    with pytest.raises(FusionError, match=r"offset search ±[\d.]+ ms is not shorter than the "
                                          r"session's detections"):
        estimate_clocks(obs, rig3, ("offset",), search_s=span)


def test_an_undetermined_drift_is_reported_as_such_not_as_a_bad_rig_value(rig3):
    # a short straight throw does not determine drift and readout: the estimates may lie
    # beyond ±1000 ppm, which the rig refuses ("clock_drift_ppm ... is beyond"); the message
    # must be the estimate's
    detections, _ = simulate(rig3, get_motion("straight"), 2.0,
                             SimulationOptions(noise_px=0.3, seed=0))
    with pytest.raises(FusionError, match=r"is not determined"):
        estimate_clocks(detections.best(), rig3, ("offset", "drift", "readout"))


def test_info_shows_no_nan_fps_for_a_camera_with_one_frame(tmp_path, rig3, cli):
    detections, _ = simulate(rig3, get_motion("spiral"), 1.0, SimulationOptions(seed=1))
    obs = detections.best()
    cam3 = np.flatnonzero(obs.camera == 2)
    keep = np.ones(len(obs), bool)
    keep[cam3[1:]] = False  # camera 3: one frame
    path = tmp_path / "one.mcap"
    with SessionWriter(path, rig3, timing="typeA", source="test") as writer:
        writer.add_detections(Detections.from_observations(rig3.names, obs.select(keep)))
    code, out, _ = cli("info", path)
    assert code == 0
    assert not re.search(r"\bnan\b", out)
    assert "1 frame" in next(line for line in out.splitlines() if "cam3" in line)


def test_eval_prints_dashes_without_truth_and_strict_json_for_an_infinite_nees(
        tmp_path, rig3, cli):
    detections, truth = simulate(rig3, get_motion("spiral"), 1.0, SimulationOptions(seed=1))
    real = tmp_path / "real.mcap"
    with SessionWriter(real, rig3, timing="typeA", source="test") as writer:
        writer.add_detections(detections)
    code, _, err = cli("fuse", real, "-o", tmp_path / "freal.mcap", "--method", "typeA")
    assert code == 0, err
    code, out, _ = cli("eval", tmp_path / "freal.mcap")
    assert code == 0 and not re.search(r"\bnan\b", out)
    # with truth and no pixel noise assumed, nearest's covariance is zero on noise-free
    # detections: NEES infinite (typeA's is made at the noise its detections show since
    # session 19: the quadratic's model error, not zero)
    sim = tmp_path / "sim.mcap"
    with SessionWriter(sim, rig3, timing="typeA", source="test") as writer:
        writer.add_detections(detections)
        writer.add_truth(truth)
    fused = tmp_path / "fsim.mcap"
    assert cli("fuse", sim, "-o", fused, "--method", "nearest", "--noise-px", "0")[0] == 0
    code, out, _ = cli("eval", fused)
    assert code == 0 and not re.search(r"\b(nan|inf)\b", out)
    code, out, _ = cli("eval", fused, "--json")
    assert code == 0
    rows = _strict_json(out)
    assert rows[0]["quality"]["nees"] is None


@pytest.mark.parametrize("columns, what", [((3, 4), "u,v"), ((0, 1, 2), "x,y,z")])
def test_calibrate_refuses_points_all_at_one_place_before_solving(tmp_path, cli, columns,
                                                                   what):
    from pathlib import Path

    rows = (Path(__file__).parent.parent / "samples" / "cam1_points.csv").read_text().split()
    out = [rows[0]]
    for row in rows[1:]:
        cells = row.split(",")
        for j in columns:
            cells[j] = "7"
        out.append(",".join(cells))
    points = tmp_path / "p.csv"
    points.write_text("\n".join(out) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning on the way
        code, _, err = cli("calibrate", "--points", points, "--name", "c", "--width", 640,
                           "--height", 480, "--rig", tmp_path / "x.toml")
    assert code != 0
    assert f"have the same {what}" in err and "Traceback" not in err


def test_view_says_why_a_method_fused_on_the_fly_gave_no_track(tmp_path, rig3):
    from viewers.data import load_view_data

    detections, _ = simulate(rig3, get_motion("spiral"), 1.0, SimulationOptions(seed=1))
    obs = detections.best()
    path = tmp_path / "one.mcap"
    with SessionWriter(path, rig3, timing="typeA", source="test") as writer:
        writer.add_detections(Detections.from_observations(rig3.names,
                                                           obs.select(obs.camera == 0)))
    data = load_view_data([path], methods="smooth")
    assert not len(data.tracks["smooth"])
    assert ("no track from smooth: only camera cam1 has detections; fusing needs at least "
            "two cameras") in data.notes


def test_a_still_ball_is_said_rejected_causally_and_alone_is_fused_offline(
        tmp_path, rig3, cli):
    """A ball at rest: the causal methods' gate takes a still candidate for a static object
    (docs/methods.md "Stillness": one seen alone before the ball enters is not told from a
    ball at rest), so nearest's candidates are rejected and fuse says so with what to do;
    offline the premise is the whole session's: alone in the scene (no frame of several
    candidates) the ball at rest is the ball, and smooth fuses every detection (session
    29; was 247 of 270 candidates rejected). Beside a second still object (a distractor
    every camera sees) smooth rejects them too."""
    from pslog.motion import Motion

    here = get_motion("spiral").position(np.zeros(1))[0]
    still = Motion("still", 3.0, lambda t: np.tile(here, (len(t), 1)))
    for distractors in ((), ((None, (0.5, 0.5, 0.0)),)):
        detections, _ = simulate(rig3, still, 3.0, SimulationOptions(
            noise_px=0.3, seed=1, distractors=distractors))
        path = tmp_path / f"still{len(distractors)}.mcap"
        with SessionWriter(path, rig3, timing="typeA", source="test") as writer:
            writer.add_detections(detections)
        code, out, _ = cli("fuse", path, "-o", tmp_path / f"f{len(distractors)}.mcap",
                           "--method", "smooth,nearest")
        assert code == 0
        line = next(line for line in out.splitlines() if "still object" in line)
        assert "not told from a static object" in line and "--gating off" in line
        if not distractors:
            assert "smooth       270 points       0 candidates rejected by gating" in out, out
        else:  # (nothing left to fuse)
            assert "no point from smooth" in out, out


def test_a_foreign_channel_on_a_pslog_topic_is_named_not_sent_to_recover(sim_session,
                                                                        tmp_path, cli):
    from mcap.reader import make_reader
    from mcap.writer import Writer

    out = tmp_path / "clash.mcap"
    with open(sim_session.path, "rb") as f, open(out, "wb") as g:
        reader = make_reader(f)
        header = reader.get_header()
        writer = Writer(g)
        writer.start(profile=header.profile, library=header.library)
        for m in reader.iter_metadata():
            writer.add_metadata(m.name, m.metadata)
        foreign = writer.register_channel("/camera/cam1/detections", "json",
                                          writer.register_schema("foo", "jsonschema", b"{}"))
        schemas, channels = {}, {}
        for schema, channel, msg in reader.iter_messages():
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding,
                                                            schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding,
                    schemas.get(channel.schema_id, 0), channel.metadata)
            writer.add_message(channels[channel.id], msg.log_time, msg.data, msg.publish_time)
            writer.add_message(foreign, msg.log_time, b'{"x": 1}', msg.publish_time)
        writer.finish()
    for args in (("info", out), ("fuse", out, "-o", tmp_path / "f.mcap")):
        code, _, err = cli(*args)
        assert code != 0
        assert ("on pslog's topic /camera/cam1/detections has message encoding 'json'" in err
                and "recover" not in err), err
