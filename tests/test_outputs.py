"""Outputs: refused without --force, folders refused, an old file replaced only by a complete
new one (pslog/outputs.py, SessionWriter, save_rrd, record)."""

from __future__ import annotations

import os

import pytest

from pslog.errors import InputError, OutputExistsError
from pslog.log import SessionWriter, read_session
from pslog.outputs import check_output_path


def test_check_output_path(tmp_path):
    assert check_output_path(tmp_path / "new.mcap", force=False) == tmp_path / "new.mcap"
    with pytest.raises(InputError, match="is a folder"):
        check_output_path(tmp_path, force=True)
    with pytest.raises(InputError, match="output folder does not exist"):
        check_output_path(tmp_path / "nope" / "x.mcap", force=True)
    (tmp_path / "old.mcap").write_bytes(b"old")
    with pytest.raises(OutputExistsError, match="--force"):
        check_output_path(tmp_path / "old.mcap", force=False)
    assert check_output_path(tmp_path / "old.mcap", force=True).name == "old.mcap"


def _write(path, rig, detections, **kwargs):
    with SessionWriter(path, rig, force=True, **kwargs) as writer:
        writer.add_detections(detections)


def test_writer_replaces_an_old_session_only_when_complete(tmp_path, sim_session):
    path = tmp_path / "s.mcap"
    path.write_bytes(b"the old session")
    # a run that fails inside `with`: the old file stays, the new data is kept beside it
    with pytest.raises(RuntimeError), SessionWriter(path, sim_session.rig, force=True) as w:
        w.add_detections(sim_session.detections)
        raise RuntimeError("camera fell off")
    assert path.read_bytes() == b"the old session"
    partial = tmp_path / "s.mcap.partial"
    assert read_session(partial).detections.n_frames == sim_session.detections.n_frames
    partial.unlink()
    # an aborted run (nothing worth keeping): the old file stays, no partial left
    writer = SessionWriter(path, sim_session.rig, force=True)
    writer.abort()
    assert path.read_bytes() == b"the old session" and not partial.exists()
    # a complete run replaces it
    _write(path, sim_session.rig, sim_session.detections)
    assert read_session(path).detections.n_frames == sim_session.detections.n_frames
    assert not partial.exists()


@pytest.mark.parametrize("command", [
    ["fuse", "{session}", "--method", "typeA", "-o", "{dir}", "--force"],
    ["export", "{session}", "--detections", "{dir}", "--force"],
    ["view", "{session}", "--save", "{dir}", "--force"],
    ["simulate", "--rig", "paper2", "-o", "{dir}", "--force"],
    ["recover", "{session}", "-o", "{dir}", "--force"],
])
def test_a_folder_as_output_is_one_line_error(tmp_path, sim_session, cli, command):
    folder = tmp_path / "a_folder"
    folder.mkdir()
    args = [a.format(session=sim_session.path, dir=folder) for a in command]
    code, _, err = cli(*args)
    assert code == 1, err
    assert "is a folder" in err and err.count("\n") == 1
    assert list(folder.iterdir()) == []


def test_record_with_force_keeps_the_old_session_when_no_camera_delivers(tmp_path, cli):
    old = tmp_path / "keep.mcap"
    code, _, err = cli("simulate", "--rig", "paper2", "-o", old)
    assert code == 0, err
    before = old.read_bytes()
    bad = tmp_path / "not_a_video.mp4"
    bad.write_bytes(b"no video here")
    code, _, err = cli("record", "--rig", "paper2", "--source", f"cam1={bad}",
                       "--source", f"cam2={bad}", "-o", old, "--force", "--duration", "1")
    assert code == 1
    assert old.read_bytes() == before
    assert not (tmp_path / "keep.mcap.partial").exists()


def test_view_window_past_the_end_is_an_error(tmp_path, sim_session, cli):
    code, _, err = cli("view", sim_session.path, "--save", tmp_path / "x.rrd", "--start", "100")
    assert code == 1 and "no frame between" in err
    assert not (tmp_path / "x.rrd").exists()


def test_an_output_that_is_an_input_is_refused_in_every_spelling(tmp_path, monkeypatch):
    src = tmp_path / "s.mcap"
    src.write_bytes(b"session")
    (tmp_path / "link.mcap").symlink_to(src)
    os.link(src, tmp_path / "hard.mcap")
    (tmp_path / "sub").mkdir()
    monkeypatch.chdir(tmp_path)
    for spelling in ("s.mcap", "./s.mcap", "sub/../s.mcap", str(src), "link.mcap", "hard.mcap"):
        with pytest.raises(InputError, match="is the input"):
            check_output_path(spelling, True, inputs=[src])
    assert src.read_bytes() == b"session"
    assert check_output_path("other.mcap", False, inputs=[src]).name == "other.mcap"
