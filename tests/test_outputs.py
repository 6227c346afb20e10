"""Outputs: refused without --force, folders refused, an old file replaced only by a complete
new one (pslog/outputs.py, SessionWriter, save_rrd, record)."""

from __future__ import annotations

import pytest

from pslog.cli import COMMANDS
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
    bad, bad2 = tmp_path / "not_a_video.mp4", tmp_path / "not_a_video_either.mp4"
    bad.write_bytes(b"no video here")
    bad2.write_bytes(b"no video here")  # (one file for two cameras is refused: exit 2)
    code, _, err = cli("record", "--rig", "paper2", "--source", f"cam1={bad}",
                       "--source", f"cam2={bad2}", "-o", old, "--force", "--duration", "1")
    assert code == 1
    assert old.read_bytes() == before
    assert not (tmp_path / "keep.mcap.partial").exists()


@pytest.mark.parametrize("start", ["100", "1e19", "1e308"])  # 1e308 s: once inf ns, a traceback
def test_view_window_past_the_end_is_an_error(tmp_path, sim_session, cli, start):
    code, _, err = cli("view", sim_session.path, "--save", tmp_path / "x.rrd", "--start", start)
    # exit 2 since session 32: a value that does not fit the session, as fuse's --method
    assert code == 2 and f"no frame from --start {float(start)} s; the session spans 0 to" \
        in err and err.count("\n") == 1 and "None" not in err, err
    assert not (tmp_path / "x.rrd").exists()


def test_view_window_ending_past_any_time_is_the_whole_session(tmp_path, sim_session, cli):
    code, _, err = cli("view", sim_session.path, "--save", tmp_path / "x.rrd", "--end", "1e308")
    assert code == 0, err
    assert (tmp_path / "x.rrd").stat().st_size > 0


# an output that is an input, in every spelling (./, .., absolute, symlink, hard link): for
# every writer in tests/faults/test_writers.py (test_output_that_is_an_input_is_refused)


# ---- one output rule for every command (declare_files + the dispatcher) -----------------

#: options that name a file a command writes
_OUTPUT_OPTIONS = {"-o", "--output", "--save", "--csv"}


def _parser(command):
    import importlib

    from pslog.cli import COMMANDS, _Parser

    parser = _Parser(prog=f"pslog {command}")
    importlib.import_module(f"pslog.cli.{COMMANDS[command][0]}").add_arguments(parser)
    return parser


#: commands that write no file (they print)
_WRITE_NOTHING = {"info", "rig", "eval", "paper"}
#: commands that write files but check them themselves, and why
_OWN_CHECKS = {"demo": "writes a fresh folder of its own outputs (--out)",
               "batch": "writes a folder of results, every file checked before the batch "
                        "starts (pslog.batch.plan_batch)"}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_writing_command_declares_its_files(command):
    from pslog.cli._common import FILES_KEY

    parser = _parser(command)
    files = parser.get_default(FILES_KEY)
    if command in _WRITE_NOTHING or command in _OWN_CHECKS:
        named = {o for a in parser._actions for o in a.option_strings}
        assert command in _OWN_CHECKS or not named & _OUTPUT_OPTIONS, (
            f"pslog {command} has an output option: declare it (declare_files)")
        return
    assert files, f"pslog {command} declares no files (declare_files in add_arguments)"
    outputs = {a.dest for a in parser._actions if _OUTPUT_OPTIONS & set(a.option_strings)}
    if command == "export":
        outputs.add("detections")
    assert outputs <= set(files["outputs"]) | set(files["updates"]), command
    positional = {a.dest for a in parser._actions if not a.option_strings}
    assert positional <= set(files["inputs"]), command
    if any("--rig" in a.option_strings for a in parser._actions) and command != "calibrate":
        assert "rig" in files["inputs"], command


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_session_output_is_declared_a_session(command):
    """An option whose file is an MCAP session (metavar ``*.mcap``) is declared one
    (``declare_files(sessions=...)``), so a name for another format is refused (exit 2)."""
    from pslog.cli._common import FILES_KEY

    parser = _parser(command)
    files = parser.get_default(FILES_KEY) or {}
    writes = set(files.get("outputs", ())) | set(files.get("updates", ()))
    mcap = {a.dest for a in parser._actions
            if a.dest in writes and str(a.metavar or "").lower().endswith(".mcap")}
    assert mcap == set(files.get("sessions", ())), command


@pytest.mark.parametrize("name", ["out", "OUT.MCAP", "take.v2", ".csv", "s.mcap.bak"])
def test_a_session_name_for_no_other_format_is_written(tmp_path, cli, name):
    """Only a suffix that names another format is refused: none, .mcap in any case, or one
    pslog does not know (a version, a backup) is the user's choice."""
    code, _, err = cli("simulate", "--rig", "paper3", "--duration", "0.2", "-o",
                         tmp_path / name)
    assert code == 0 and (tmp_path / name).is_file(), err
    assert cli("info", tmp_path / name)[0] == 0


def test_a_new_command_gets_the_output_rule_for_free(tmp_path, monkeypatch, cli):
    """A command that only declares its files, and then writes naively, cannot replace its
    input or overwrite without --force: the dispatcher checks before run()."""
    import sys
    import types

    from pslog import cli as cli_module
    from pslog.cli._common import add_force, declare_files

    module = types.ModuleType("pslog.cli._naive_copy")

    def add_arguments(parser):
        parser.add_argument("source")
        parser.add_argument("-o", "--output", required=True)
        add_force(parser)
        declare_files(parser, inputs=("source",), outputs=("output",))

    def run(args):
        data = open(args.source, "rb").read()
        with open(args.output, "wb") as f:  # truncates first: would destroy its input
            f.write(data + b" copied")
        return 0

    module.add_arguments, module.run = add_arguments, run
    monkeypatch.setitem(sys.modules, "pslog.cli._naive_copy", module)
    monkeypatch.setitem(cli_module.COMMANDS, "naive", ("_naive_copy", "a naive copy"))
    src = tmp_path / "in.txt"
    src.write_bytes(b"precious")
    (tmp_path / "alias.txt").symlink_to(src)
    monkeypatch.chdir(tmp_path)
    for spelling in ("in.txt", "./in.txt", "alias.txt", str(src)):
        code, _, err = cli("naive", "in.txt", "-o", spelling, "--force")
        assert code == 1 and "is the input" in err and err.count("\n") == 1, err
    assert src.read_bytes() == b"precious"
    (tmp_path / "out.txt").write_bytes(b"old")
    code, _, err = cli("naive", "in.txt", "-o", "out.txt")
    assert code == 1 and "--force" in err
    assert cli("naive", "in.txt", "-o", "out.txt", "--force")[0] == 0
    assert (tmp_path / "out.txt").read_bytes() == b"precious copied"


def test_two_options_naming_one_output_are_refused(tmp_path, sim_session, cli):
    out = tmp_path / "x.csv"
    code, _, err = cli("export", sim_session.path, "--detections", out, "--csv",
                       tmp_path / "sub" / ".." / "x.csv")
    assert code == 1 and "two outputs" in err and not out.exists()


# ---- derived writers leave nothing on failure; stale partials ---------------------------

def test_discard_mode_writes_only_a_partial_and_removes_it_on_failure(tmp_path, sim_session):
    path = tmp_path / "d.mcap"
    partial = tmp_path / "d.mcap.partial"
    with pytest.raises(RuntimeError), \
            SessionWriter(path, sim_session.rig, on_error="discard") as w:
        w.add_detections(sim_session.detections)
        w.flush()
        assert partial.exists() and not path.exists()  # never a half-written d.mcap
        raise RuntimeError("fusion failed")
    assert not path.exists() and not partial.exists()
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError), SessionWriter(path, sim_session.rig, force=True,
                                                    on_error="discard") as w:
        raise RuntimeError("again")
    assert path.read_bytes() == b"old" and not partial.exists()
    with SessionWriter(path, sim_session.rig, force=True, on_error="discard") as w:
        w.add_detections(sim_session.detections)
    assert read_session(path).detections.n_frames == sim_session.detections.n_frames
    assert not partial.exists()


def test_partial_kind_tells_derived_outputs_from_recordings(tmp_path, sim_session, cli):
    from pathlib import Path

    from pslog.outputs import partial_kind

    sample = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"
    fused, sim, csv = tmp_path / "f.mcap", tmp_path / "s.mcap", tmp_path / "d.csv"
    assert cli("fuse", sample, "--method", "typeA", "-o", fused)[0] == 0
    assert cli("simulate", "--rig", "paper2", "-o", sim)[0] == 0
    assert cli("export", sample, "--detections", csv)[0] == 0

    def prefix(path, n):
        out = tmp_path / f"{path.name}.{n}.partial"
        out.write_bytes(path.read_bytes()[:n])
        return out

    assert partial_kind(prefix(sample, 0)) == "empty"
    assert partial_kind(prefix(sample, 5)) == "empty"
    assert partial_kind(prefix(sample, 30_000)) == "recording"  # record --synthetic
    assert partial_kind(prefix(sim_session.path, 3_000)) == "recording"  # source "test"
    assert partial_kind(prefix(fused, 30_000)) == "derived"
    assert partial_kind(prefix(sim, 2_000)) == "derived"
    assert partial_kind(prefix(csv, 100)) == "foreign"  # no proof pslog made it
    assert partial_kind(prefix(fused, fused.stat().st_size)) == "complete"
    # the writer says which it is (metadata "derived"), whatever the free-text source says
    keep, discard = tmp_path / "keep.mcap", tmp_path / "discard.mcap"
    with SessionWriter(keep, sim_session.rig, source="pslog simulate, then edited") as w:
        w.add_detections(sim_session.detections)
    with SessionWriter(discard, sim_session.rig, source="my tool", on_error="discard") as w:
        w.add_detections(sim_session.detections)
    assert partial_kind(prefix(keep, 3_000)) == "recording"
    assert partial_kind(prefix(discard, 3_000)) == "derived"
    assert read_session(discard).metadata.get("derived") == "true"
    assert "derived" not in read_session(keep).metadata


def test_copy_session_rewrites_calibration_only_from_a_corrected_rig(tmp_path, sim_session):
    import numpy as np
    from mcap.reader import make_reader

    from pslog.log import copy_session
    from pslog.rig import Rig

    def static(path):
        with open(path, "rb") as f:
            return {c.topic: m.data for _s, c, m in make_reader(f).iter_messages()
                    if c.topic.endswith(("/calibration", "/transform"))}

    same, moved = tmp_path / "same.mcap", tmp_path / "moved.mcap"
    copy_session(sim_session.path, same)
    assert static(same) == static(sim_session.path)  # byte-identical
    rig = sim_session.rig
    corrected = Rig(tuple(c.replace(t=c.t + np.array([0.02, 0.0, 0.0])) if c.name == "cam2"
                          else c for c in rig.cameras), rig.name)
    copy_session(sim_session.path, moved, rig=corrected)
    old, new = static(sim_session.path), static(moved)
    assert set(old) == set(new)
    assert new["/camera/cam2/transform"] != old["/camera/cam2/transform"]
    assert new["/camera/cam1/transform"] == old["/camera/cam1/transform"]
    assert read_session(moved).rig == corrected


def test_save_rig_replaces_a_rig_file_like_every_other_output(tmp_path):
    """save_rig goes through outputs.replacing: a one-line PslogError (never a raw OSError),
    never over an input, nothing left beside the file."""
    from pslog.errors import PslogError
    from pslog.rig import builtin_rig, load_rig, save_rig

    rig, path = builtin_rig("paper2"), tmp_path / "rig.toml"
    with pytest.raises(PslogError, match="output folder does not exist"):
        save_rig(rig, tmp_path / "nope" / "rig.toml")
    path.write_text("old rig")
    with pytest.raises(InputError, match="is the input"):
        save_rig(rig, path, inputs=[path])
    assert path.read_text() == "old rig"
    save_rig(rig, path)
    assert load_rig(path).names == rig.names
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml"]


def test_a_partial_being_written_is_neither_cleared_nor_written_twice(tmp_path):
    """The lock of open_locked (another process in tests/faults/test_writers.py; a second
    open file here, which flock treats alike)."""
    from pslog.outputs import (
        PartialBusyError,
        PartialRecordingError,
        clear_stale_partial,
        open_locked,
    )

    partial = tmp_path / "d.csv.partial"
    with open_locked(partial, "w") as f:
        f.write("being written")
        f.flush()
        with pytest.raises(PartialBusyError, match=f"another pslog is writing {partial}"):
            clear_stale_partial(tmp_path / "d.csv")
        with pytest.raises(PartialBusyError):
            open_locked(partial)
        assert partial.read_text() == "being written"  # not emptied by the refused open
    # stale now, but text: nothing proves pslog wrote it (a user's file of that name?): kept
    with pytest.raises(PartialRecordingError, match="cannot tell it made it"):
        clear_stale_partial(tmp_path / "d.csv", say=lambda _text: None)
    assert partial.read_text() == "being written"
    partial.write_bytes(b"")  # an empty one holds nothing to lose: removed
    clear_stale_partial(tmp_path / "d.csv", say=lambda _text: None)
    assert not partial.exists()


def test_an_output_locked_by_a_writer_is_refused_even_with_force(tmp_path):
    """flock is per open file: a writer's lock (open_locked) is seen from another open file
    in this process just as from another process."""
    from pslog.outputs import PartialBusyError, open_locked

    out = tmp_path / "w.mcap"
    with open_locked(out) as f:
        f.write(b"recording")
        f.flush()
        with pytest.raises(PartialBusyError, match="being written by another pslog"):
            check_output_path(out, force=True)
    assert check_output_path(out, force=True) == out  # released: --force may replace it


def test_outputs_and_inputs_that_are_not_regular_files(tmp_path):
    import os

    from pslog.inputs import check_input_file

    os.mkfifo(tmp_path / "fifo")
    (tmp_path / "link").symlink_to("missing")
    with pytest.raises(InputError, match="is a named pipe, not a regular file"):
        check_output_path(tmp_path / "fifo", force=True)
    with pytest.raises(InputError, match="is a symbolic link"):
        check_output_path(tmp_path / "link", force=True)  # even a dangling one
    with pytest.raises(InputError, match=r"not a regular file: .*fifo \(a named pipe\)"):
        check_input_file(tmp_path / "fifo")
    (tmp_path / "big.toml").write_bytes(b"#" * 11)
    with pytest.raises(InputError, match=r"rig file .*big\.toml is 11 bytes: too large"):
        check_input_file(tmp_path / "big.toml", "rig file", max_bytes=10)
    assert check_input_file(tmp_path / "big.toml", "rig file", max_bytes=11).name == "big.toml"
