"""The dispatcher: lazy loading, layering, help, and errors as one line."""

from __future__ import annotations

import subprocess
import sys
from importlib.util import find_spec

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


def test_every_command_module_exists_and_has_help():
    for module, _ in COMMANDS.values():
        assert find_spec(f"pslog.cli.{module}") is not None, module
    for name in COMMANDS:
        result = run(name, "--help")
        assert result.returncode == 0, (name, result.stderr)
        assert f"pslog {name}" in result.stdout


def test_unknown_command_and_bad_values_are_one_line_usage_errors():
    result = run("frobnicate")
    assert result.returncode == 2 and "unknown command 'frobnicate'" in result.stderr
    for args, name in ((("--duration", "-1"), "--duration"), (("--seed", "-5"), "--seed"),
                       (("--noise-px", "nan"), "--noise-px")):
        result = run("simulate", "--rig", "paper3", *args, "-o", "x.mcap")
        assert result.returncode == 2 and name in result.stderr
        assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr
    result = run("simulate", "--rig", "paper3", "--duration", "1e9", "-o", "x.mcap")
    assert result.returncode == 2 and "frames" in result.stderr


def test_pslog_error_is_one_line_exit_1(tmp_path):
    result = run("info", str(tmp_path / "nope.mcap"))
    assert result.returncode == 1
    assert result.stderr.count("\n") == 1 and "nope.mcap" in result.stderr
    assert result.stderr.startswith("pslog info: error:")


def test_package_exports_resolve_lazily_to_the_right_objects():
    import pslog

    assert sorted(pslog.__all__) == sorted(pslog._MODULE_OF)
    for name in pslog.__all__:
        assert getattr(pslog, name) is not None
    assert callable(pslog.simulate) and pslog.simulate.__module__ == "pslog.simulation"
