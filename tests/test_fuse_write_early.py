"""``pslog fuse`` writes each method's track as the method ends, while the others still fuse:
the left-out counts go with each track (its channel's metadata, docs/log-format.md), files
of the old layout (every method's counts in the session metadata record written first)
still read, and a failure or SIGTERM after some track was written leaves no output, no
``.partial`` and an old output untouched."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys

import pytest
from mcap.reader import make_reader

from pslog.cli import main
from pslog.fusion import FusionOptions, for_session
from pslog.fusion.gating import fuse_detections
from pslog.log import copy_session, read_session
from pslog.log._schemas import LEFT_OUT_KEY


@pytest.fixture(scope="module")
def rally(tmp_path_factory):
    """Three seconds of a type-A rally with noise and spurious blobs: typeA and filter
    leave points out (kink, prediction_failed, unconfirmed)."""
    path = tmp_path_factory.mktemp("early") / "rally.mcap"
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                 "--duration", "3", "--noise-px", "1", "--spurious", "0.05", "--seed", "3",
                 "-o", str(path)]) == 0
    return path


def _channels_and_session_meta(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        channels = {c.topic: dict(c.metadata) for c in summary.channels.values()}
        meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return channels, meta["pslog.session"]


def test_left_out_counts_go_with_each_track(rally, tmp_path, capsys):
    out = tmp_path / "f.mcap"
    assert main(["fuse", str(rally), "--method", "typeA,filter,nearest", "-o", str(out)]) == 0
    s = read_session(rally)
    tracks, _ = fuse_detections(s.detections, s.rig, ["typeA", "filter", "nearest"],
                                for_session(FusionOptions(), s.metadata))  # (pslog fuse's)
    expected = {m: dict(t.dropped) for m, t in tracks.items() if t.dropped}
    assert expected.get("typeA"), "the session should make typeA leave points out"
    channels, session_meta = _channels_and_session_meta(out)
    assert LEFT_OUT_KEY not in session_meta  # not in the record written first any more
    for method, track in tracks.items():
        # every fused track's channel holds its own counts (an empty mapping: none)
        assert json.loads(channels[f"/tracks/{method}"][LEFT_OUT_KEY]) == dict(track.dropped)
    assert read_session(out).left_out == expected
    capsys.readouterr()
    assert main(["eval", str(out), "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["method"]: r["left_out"] for r in rows} == {
        m: expected.get(m, {}) for m in tracks}


def test_a_file_in_the_old_layout_still_reads(rally, tmp_path, capsys):
    """The old writer path: every method's counts in the session metadata (what ``pslog
    fuse`` wrote until the tracks went out as each method ended)."""
    s = read_session(rally)
    tracks, _ = fuse_detections(s.detections, s.rig, ["typeA", "nearest"], FusionOptions())
    # without their own counts, which copy_session now writes in the tracks' channels
    tracks = {m: dataclasses.replace(t, dropped={}) for m, t in tracks.items()}
    counts = {"typeA": {"kink": 7, "prediction_failed": 2}, "nearest": {"behind_camera": 1}}
    old = tmp_path / "old.mcap"
    copy_session(rally, old, tracks=list(tracks.values()),
                 metadata={LEFT_OUT_KEY: json.dumps(counts, sort_keys=True)})
    channels, session_meta = _channels_and_session_meta(old)
    assert LEFT_OUT_KEY in session_meta
    assert not any(LEFT_OUT_KEY in c for c in channels.values())  # the old layout indeed
    assert read_session(old).left_out == counts
    capsys.readouterr()
    assert main(["eval", str(old), "--json"]) == 0
    assert {r["method"]: r["left_out"] for r in json.loads(capsys.readouterr().out)} == counts
    # a copy keeping typeA and replacing nearest: typeA's old counts move to its channel,
    # the session key (naming nearest's old counts too) is not copied
    again = tmp_path / "again.mcap"
    copy_session(old, again, tracks=[tracks["nearest"]], replace_tracks=False)
    channels, session_meta = _channels_and_session_meta(again)
    assert LEFT_OUT_KEY not in session_meta
    assert json.loads(channels["/tracks/typeA"][LEFT_OUT_KEY]) == counts["typeA"]
    assert LEFT_OUT_KEY not in channels["/tracks/nearest"]
    assert read_session(again).left_out == {"typeA": counts["typeA"]}
    # a re-fuse of the old file replaces every track and its counts
    refused = tmp_path / "refused.mcap"
    assert main(["fuse", str(old), "--method", "nearest", "-o", str(refused)]) == 0
    assert read_session(refused).left_out == {}
    assert LEFT_OUT_KEY not in _channels_and_session_meta(refused)[1]


def test_a_failure_after_a_track_was_written_leaves_the_old_output(rally, tmp_path, capsys):
    """In turn (``--workers 1``) filter ends and is written before sync fails (a type-A
    session has no shared instants): nothing of the run is left, the old output stays."""
    out = tmp_path / "f.mcap"
    out.write_bytes(b"an old output")
    code = main(["fuse", str(rally), "--method", "filter,sync", "-o", str(out), "--workers",
                 "1", "--force"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and err[0].startswith("pslog fuse: error: method sync needs"), err
    assert out.read_bytes() == b"an old output"
    assert not (tmp_path / "f.mcap.partial").exists()


def test_sigterm_after_a_track_was_written_leaves_nothing(tmp_path):
    """SIGTERM once the output holds more than the session's copy (a track written while
    smooth still fuses): exit 143, one line, no output, no ``.partial``, old output kept."""
    session = tmp_path / "long.mcap"
    subprocess.run([sys.executable, "-m", "pslog.cli", "simulate", "--rig", "paper3",
                    "--timing", "typeA", "--motion", "rally", "--duration", "90",
                    "-o", str(session)], check=True, capture_output=True, timeout=300)
    out = tmp_path / "f.mcap"
    out.write_bytes(b"an old output")
    partial = tmp_path / "f.mcap.partial"
    proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", "fuse", str(session), "-o",
                             str(out), "--force", "--workers", "2"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ, PSLOG_PROGRESS="off"))
    size = session.stat().st_size
    while proc.poll() is None:  # until the partial holds a track beyond the session's copy
        try:
            if partial.stat().st_size > size * 1.5:
                break
        except FileNotFoundError:
            pass
        try:
            proc.wait(0.01)
        except subprocess.TimeoutExpired:
            pass
    if proc.poll() is not None:
        pytest.skip("the command finished before it could be signalled")
    proc.send_signal(signal.SIGTERM)
    err = proc.communicate(timeout=60)[1]
    if proc.returncode == 0:
        pytest.skip("the command finished before the signal reached it")
    lines = [x for x in err.splitlines() if x.strip()]
    assert proc.returncode == 143, err
    assert lines == ["pslog fuse: terminated (SIGTERM)"], lines
    assert not partial.exists()
    if out.read_bytes() != b"an old output":
        # the signal came during the final close, which holds it until the file is complete
        from pslog.log import read_session

        assert len(read_session(out).tracks) > 0


def test_copy_session_keeps_each_tracks_left_out_counts(rally, tmp_path):
    """Review of session 12: ``copy_session`` (the Python API, ``pslog demo``) wrote tracks
    without their left-out counts, so ``eval`` of its files said nothing was left out."""
    s = read_session(rally)
    tracks, _ = fuse_detections(s.detections, s.rig, ["typeA", "nearest"], FusionOptions())
    tracks["typeA"] = dataclasses.replace(tracks["typeA"], dropped={"kink": 3})
    out = tmp_path / "copied.mcap"
    copy_session(rally, out, tracks=list(tracks.values()))
    channels, _ = _channels_and_session_meta(out)
    assert json.loads(channels["/tracks/typeA"][LEFT_OUT_KEY]) == {"kink": 3}
    assert read_session(out).left_out.get("typeA") == {"kink": 3}
