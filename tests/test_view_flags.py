"""``pslog view``'s rerun flags are built without importing rerun (over a CPU second of
imports in every ``pslog view`` process, ``--help`` and usage errors included): they must
stay rerun's own (``rr.script_add_args``: names, actions, types, defaults), in pslog's
wording, so a rerun upgrade that changes them fails here."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import rerun as rr

from viewers.sinks import _RERUN_FLAGS, add_sink_arguments


def _attributes(action: argparse.Action) -> tuple:
    return (type(action), action.option_strings, action.dest, action.nargs, action.const,
            action.default, action.type, action.choices, action.required, action.metavar,
            action.help)


def test_the_flags_are_rerun_script_add_args_in_our_wording():
    theirs = argparse.ArgumentParser(prog="pslog view")
    rr.script_add_args(theirs)
    for action in theirs._actions:  # what pslog view showed when it called rerun
        if action.dest in _RERUN_FLAGS:
            action.metavar, action.help = _RERUN_FLAGS[action.dest][2:]
    ours = argparse.ArgumentParser(prog="pslog view")
    add_sink_arguments(ours)
    assert [a.dest for a in theirs._actions] == ["help", *_RERUN_FLAGS]
    assert [_attributes(a) for a in ours._actions] == [_attributes(a) for a in theirs._actions]
    assert ours.format_help() == theirs.format_help()
    argv = ["--save", "x.rrd", "--url", "rerun+http://h:1/proxy", "--connect", "--headless"]
    assert ours.parse_args(argv) == theirs.parse_args(argv)
    assert ours.parse_args([]) == theirs.parse_args([])


def test_view_help_and_usage_errors_do_not_import_rerun():
    """``--help``, argparse's errors and the command's own refusals before it reads."""
    sample = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"
    code = ("import sys, contextlib, io\n"
            "from pslog.cli import main\n"
            f"s = {str(sample)!r}\n"
            "for argv in (['view', '--help'], ['view', s, '--frames', 'some'], ['view'],"
            " ['view', s, '--headless'], ['view', s, '--save', 'x.rrd', '--serve'],"
            " ['view', s, '--url', 'rerun+http://127.0.0.1:1/proxy'],"
            " ['view', s, '--start', '2', '--end', '1']):\n"
            "    with contextlib.redirect_stdout(io.StringIO()), "
            "contextlib.redirect_stderr(io.StringIO()):\n"
            "        try:\n"
            "            print(main(argv), file=sys.__stdout__)\n"
            "        except SystemExit as exc:\n"
            "            print(exc.code, file=sys.__stdout__)\n"
            "print(sorted(m for m in ('rerun', 'viewers.recording', 'viewers.blueprint') "
            "if m in sys.modules))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.stdout.split() == ["0", "2", "2", "1", "2", "2", "2", "[]"], run.stderr


def test_every_public_name_of_viewers_is_its_submodules():
    """``viewers``' names are imported on first use (PEP 562), each from its submodule."""
    import importlib

    import viewers

    for name in viewers.__all__:
        module = importlib.import_module(f"viewers.{viewers._WHERE[name]}")
        assert getattr(viewers, name) is getattr(module, name)
    assert set(viewers.__all__) <= set(dir(viewers))
