"""The dispatcher: lazy loading, layering, help, and errors as one line."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib.util import find_spec
from pathlib import Path

from pslog.cli import COMMANDS


def run(*code_or_args: str, module: bool = True) -> subprocess.CompletedProcess:
    args = [sys.executable, "-m", "pslog.cli", *code_or_args] if module else [
        sys.executable, "-c", code_or_args[0]]
    return subprocess.run(args, capture_output=True, text=True, timeout=120)


def test_help_lists_every_command_without_loading_numpy_or_the_other_layers():
    code = ("import sys; from pslog.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('numpy', 'cv2', 'mcap', 'rerun', 'recorders', 'viewers') "
            "if m in sys.modules]\n"
            "print('HEAVY', heavy)")
    result = run(code, module=False)
    assert "HEAVY []" in result.stdout, result.stdout + result.stderr
    for name in COMMANDS:
        assert name in result.stdout


def test_core_never_imports_recorders_or_viewers():
    code = ("import sys, pslog, pslog.fusion, pslog.log, pslog.evaluation, pslog.paper, "
            "pslog.calibration, pslog.simulation\n"
            "print('LAYERS', sorted({m.split('.')[0] for m in sys.modules} & "
            "{'recorders', 'viewers', 'rerun'}))")
    result = run(code, module=False)
    assert "LAYERS []" in result.stdout, result.stdout + result.stderr


def test_every_command_module_exists_and_has_help(tmp_path):
    from test_readme import _Forks

    for module, _ in COMMANDS.values():
        assert find_spec(f"pslog.cli.{module}") is not None, module
    # one real process of the entry point; each command's parser in a process of its own
    # forked from one that imported no pslog module but pslog.cli (test_readme's runner: a
    # parser that worked only because another pslog module was imported fails; ~0.4 CPU s of
    # interpreter start-up saved per command)
    result = run("fuse", "--help")
    assert result.returncode == 0 and "pslog fuse" in result.stdout, result.stderr
    work = tmp_path / "work"
    work.mkdir()
    forks = _Forks(work, dict(os.environ), Path(sys.executable).parent / "pslog", 120)
    try:
        for n, name in enumerate(COMMANDS):
            got = forks.run(f"pslog {name} --help", n)
            assert got.returncode == 0 and "Traceback" not in got.stderr, (name, got.stderr)
            assert f"pslog {name}" in got.stdout
    finally:
        forks.close()


def test_unknown_command_and_bad_values_are_one_line_usage_errors():
    from faults._inprocess import run_inprocess

    result = run("frobnicate")
    assert result.returncode == 2 and "unknown command 'frobnicate'" in result.stderr
    # the usage errors of one command's values: in this process (the real process of a usage
    # error is the one above), the same exit code and stderr
    for args, name in ((("--duration", "-1"), "--duration"), (("--seed", "-5"), "--seed"),
                       (("--noise-px", "nan"), "--noise-px")):
        got = run_inprocess("simulate", "--rig", "paper3", *args, "-o", "x.mcap")
        assert got.code == 2 and name in got.stderr
        assert got.stderr.count("\n") == 1 and "Traceback" not in got.stderr
    got = run_inprocess("simulate", "--rig", "paper3", "--duration", "1e9", "-o", "x.mcap")
    assert got.code == 2 and "frames" in got.stderr


def test_pslog_error_is_one_line_exit_1(tmp_path):
    result = run("info", str(tmp_path / "nope.mcap"))
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and "nope.mcap" in result.stderr
    assert result.stderr.startswith("pslog info: error:")


def test_package_exports_resolve_lazily_to_the_right_objects():
    import pslog

    assert sorted(pslog.__all__) == sorted([*pslog._MODULE_OF, "__version__"])
    for name in pslog.__all__:
        assert getattr(pslog, name) is not None
    assert callable(pslog.simulate) and pslog.simulate.__module__ == "pslog.simulation"


# ---- help texts: one convention for every command ------------------------------------------

def _parsers():
    """(prog, parser) of every command and sub-action, built as the dispatcher builds them."""
    import argparse
    import importlib

    from pslog.cli import _Parser

    for name, (module_name, text) in COMMANDS.items():
        parser = _Parser(prog=f"pslog {name}", description=text)
        importlib.import_module(f"pslog.cli.{module_name}").add_arguments(parser)
        yield parser.prog, parser
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                yield from ((p.prog, p) for p in action.choices.values())


def test_every_argument_has_help_a_stated_default_and_a_chosen_metavar():
    import argparse
    import re

    file_metavar = re.compile(r"^[A-Z_]+\.(mcap|csv|toml|rrd)$")
    problems = []
    for prog, parser in _parsers():
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction | argparse._SubParsersAction):
                continue
            label = f"{prog} {'/'.join(action.option_strings) or action.dest}"
            if not action.help:
                problems.append(f"{label}: no help text")
                continue
            if action.default not in (None, False, [], argparse.SUPPRESS) \
                    and "default" not in action.help:
                problems.append(f"{label}: default {action.default!r} not stated")
            takes_value = action.nargs != 0
            if takes_value and action.choices is None and action.metavar is None:
                problems.append(f"{label}: no metavar (argparse would show "
                                f"{action.dest.upper()})")
            if action.dest in ("session", "sessions", "output", "save") \
                    and not file_metavar.match(str(action.metavar)):
                problems.append(f"{label}: file metavar {action.metavar!r} is not NAME.ext")
    assert not problems, "\n".join(problems)


def test_help_renders_stated_defaults_as_values():
    result = run("fuse", "--help")
    assert "(default 0.5)" in " ".join(result.stdout.split())  # (--noise-px's %(default)s)
    assert "SESSION.mcap" in result.stdout and "-o FUSED.mcap" in result.stdout
    assert "%(default)" not in result.stdout


# ---- pslog rig --------------------------------------------------------------------------------

def test_rig_show_writes_a_rig_file_that_loads_back_exactly(tmp_path, cli):
    from pslog.rig import apply_timing, builtin_rig, load_rig

    code, out, _ = cli("rig", "show", "paper3", "--timing", "typeA")
    assert code == 0
    path = tmp_path / "rig.toml"
    path.write_text(out)
    assert load_rig(path) == apply_timing(builtin_rig("paper3"), "typeA")
    code, out, _ = cli("rig", "show", "paper2")
    assert code == 0 and out.count("[[camera]]") == 2 and "offset = 0.0" in out


def test_rig_show_of_a_session_prints_its_recorded_rig(sim_session, cli):
    from pslog.rig import Rig

    code, out, _ = cli("rig", "show", sim_session.path)
    assert code == 0 and Rig.from_toml(out) == sim_session.rig


def test_rig_list_and_check(tmp_path, cli):
    code, out, _ = cli("rig", "list")
    assert code == 0 and out.startswith("paper3: 3 cameras") and "paper2: 2 cameras" in out
    good = tmp_path / "rig.toml"
    code, toml, _ = cli("rig", "show", "paper3")
    good.write_text(toml)
    code, out, _ = cli("rig", "check", good)
    assert code == 0 and "a valid rig 'paper3' of 3 cameras" in out
    assert "cam2: 640x480 px, 30 fps, offset 0.000 ms" in out
    bad = tmp_path / "bad.toml"
    bad.write_text(toml.replace("width = 640", "width = -640", 1))
    result = run("rig", "check", str(bad))
    assert result.returncode == 1 and result.stderr.count("\n") == 1
    assert "bad.toml" in result.stderr and "Traceback" not in result.stderr
    result = run("rig", "show", "nowhere")
    assert result.returncode == 1 and "not a file and not a built-in rig" in result.stderr
    result = run("rig")
    assert result.returncode == 2 and "ACTION" in result.stderr


# ---- messages that tell a newcomer what to do --------------------------------------------------

def test_fuse_names_the_timing_a_method_needs_and_the_methods_that_suit(tmp_path, sim_session,
                                                                        cli):
    code, _, err = cli("fuse", sim_session.path, "--method", "typeA", "--method", "typeB",
                       "-o", tmp_path / "f.mcap")
    assert code == 1 and err.count("\n") == 1
    assert "method typeB needs cameras with a common shutter instant (sync or typeB timing)" \
        in err
    assert "methods that suit this session: nearest, typeA, smooth, filter" in err
    assert not (tmp_path / "f.mcap").exists()
    code, _, err = cli("view", sim_session.path, "--method", "linear", "--save",
                       tmp_path / "v.rrd")
    assert code == 1 and "methods that suit this session: nearest, typeA, smooth, filter" in err
    code, out, _ = cli("fuse", sim_session.path, "--method", "typeA", "--method", "nearest",
                       "-o", tmp_path / "f.mcap")
    assert code == 0 and "typeA" in out and "nearest" in out


def test_redetect_on_a_session_without_frames_says_how_to_get_one(tmp_path, sim_session, cli):
    code, _, err = cli("redetect", sim_session.path, "-o", tmp_path / "r.mcap")
    assert code == 1 and err.count("\n") == 1
    assert "has no stored frames" in err and "pslog record --synthetic" in err
    assert "samples/throw.mcap" in err


def test_installed_command_is_the_bare_name_only_when_on_path(monkeypatch, tmp_path):
    import os
    from pathlib import Path

    from pslog.cli._common import installed_command

    bin_dir = Path(sys.executable).parent
    if not (bin_dir / "rerun").exists():
        import pytest

        pytest.skip("rerun is not installed beside this Python")
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}/usr/bin:/bin")
    assert installed_command("rerun") == "rerun"
    monkeypatch.setenv("PATH", "/usr/bin:/bin")
    monkeypatch.chdir(bin_dir.parent.parent)
    command = installed_command("rerun")
    assert command != "rerun" and os.path.samefile(command, bin_dir / "rerun")
    monkeypatch.chdir(tmp_path)
    assert os.path.samefile(installed_command("rerun"), bin_dir / "rerun")


def test_every_command_chooses_methods_one_way():
    """`--method` everywhere a command chooses fusion methods (never `--methods`), repeated or
    as a comma-separated list, each method once in the order given."""
    import argparse

    choosing = 0
    for prog, parser in _parsers():
        options = {o for a in parser._actions for o in a.option_strings}
        assert "--methods" not in options, prog
        method = next((a for a in parser._actions if "--method" in a.option_strings), None)
        if method is None or not isinstance(method.default, (list, type(None))) \
                or method.dest != "methods":
            continue
        choosing += 1
        positional = [a for a in parser._actions if not a.option_strings
                      and not isinstance(a, argparse._SubParsersAction)]
        valid = {"--do": "fuse"}  # a required option's value that parses
        required = [o for a in parser._actions if a.required and a.option_strings
                    for o in (a.option_strings[0], valid.get(a.option_strings[0], "x.mcap"))]
        base = ["x.mcap"] * len(positional) + required
        repeated = parser.parse_args([*base, "--method", "typeA", "--method", "smooth",
                                      "--method", "typeA"])
        listed = parser.parse_args([*base, "--method", "typeA,smooth"])
        assert repeated.methods == listed.methods == ["typeA", "smooth"], prog
    assert choosing >= 2


def test_a_session_file_gives_its_rig_whatever_its_name(tmp_path, sim_session, cli):
    """`fuse --rig` and `rig show/check` take a session's rig from its MCAP magic, not its
    suffix (a session named .bin was read as rig text: "'utf-8' codec can't decode")."""
    import shutil

    from pslog.rig import Rig, resolve_rig

    copy = tmp_path / "session.bin"
    shutil.copyfile(sim_session.path, copy)
    assert resolve_rig(copy) == sim_session.rig
    code, out, _ = cli("rig", "show", copy)
    assert code == 0 and Rig.from_toml(out) == sim_session.rig
    code, _, err = cli("fuse", sim_session.path, "--rig", copy, "--method", "typeA",
                       "-o", tmp_path / "f.mcap")
    assert code == 0, err


def test_rig_check_notes_two_cameras_at_one_centre(tmp_path, cli):
    """Valid (a rig being calibrated) but refused by fuse and sync: check says so."""
    code, toml, _ = cli("rig", "show", "paper2")
    rig = tmp_path / "same.toml"
    from pslog.rig import Rig

    paper2 = Rig.from_toml(toml)
    rig.write_text(Rig((paper2.cameras[0], paper2.cameras[1].replace(
        R=paper2.cameras[0].R, t=paper2.cameras[0].t)), "same").to_toml())
    code, out, _ = cli("rig", "check", rig)
    assert code == 0 and "a valid rig 'same' of 2 cameras" in out
    assert "note:" in out and "same centre" in out and "fuse and sync refuse" in out


def test_rig_check_lists_the_clock_keys_a_synced_rig_holds(tmp_path, cli):
    """A rig carrying ``pslog sync``'s clocks read exactly as its unsynced original in ``rig
    check`` (session 33's walkthrough): each non-zero clock key is listed on its camera's
    line, in the rig file's key names, and a camera without any shows none."""
    from pslog.rig import Rig, builtin_rig

    paper3 = builtin_rig("paper3")
    c1, c2, c3 = paper3.cameras
    synced = Rig((c1.replace(readout=0.0125), c2.replace(clock_offset=0.0021966),
                  c3.replace(clock_offset=-3.4e-4, clock_drift_ppm=-12.5, readout=0.02)),
                 "synced")
    path = tmp_path / "synced.toml"
    path.write_text(synced.to_toml())
    code, out, _ = cli("rig", "check", path)
    assert code == 0
    lines = {line.split(":")[0].strip(): line for line in out.splitlines()[1:]}
    assert lines["cam1"].endswith("m; readout 12.500 ms"), lines["cam1"]
    assert lines["cam2"].endswith("m; clock_offset +2.1966 ms"), lines["cam2"]
    assert lines["cam3"].endswith(
        "m; clock_offset -0.3400 ms, clock_drift_ppm -12.500 ppm, readout 20.000 ms")
    code, out, _ = cli("rig", "check", "paper3")
    assert code == 0 and "clock_" not in out and "readout" not in out


def test_every_json_output_is_one_document_and_its_notes_go_to_stderr(tmp_path, cli):
    """``--json`` is read by programs (``pslog batch`` parses it): standard output holds one
    JSON document and nothing else, whatever the run had to say. ``sync --json`` dropped its
    notes (host stamps regularized, frames left out: session 33's walkthrough); they are now
    on stderr, one line each, as the text report prints them."""
    import json

    session, synced = tmp_path / "s.mcap", tmp_path / "y.mcap"
    code, _, err = cli("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                       "--clock-offset", "cam2=3", "--host-jitter", "1", "--noise-px", "0.5",
                       "--distractor", "1.5,1,0.1", "--seed", "7", "-o", session)
    assert code == 0, err
    code, text, _ = cli("sync", session, "-o", synced)
    assert code == 0
    notes = [line for line in text.splitlines() if "host stamps regularized" in line]
    assert len(notes) == 3  # one per camera in the text report
    code, out, err = cli("sync", session, "-o", synced, "--force", "--json")
    assert code == 0, err
    assert set(json.loads(out)) >= {"cameras", "residual_px", "estimated"}
    assert [line for line in err.splitlines() if "host stamps regularized" in line] == [
        f"pslog sync: {note}" for note in notes]
    code, _, err = cli("fuse", synced, "--method", "typeA", "-o", tmp_path / "f.mcap")
    assert code == 0, err
    for argv in (("info", session, "--json"), ("eval", tmp_path / "f.mcap", "--json"),
                 ("paper", "table1", "--json")):
        code, out, err = cli(*argv)
        assert code == 0, (argv, err)
        json.loads(out)  # the whole of stdout: one document
