"""The README's examples run as written, in order, on a fresh clone.

Every line of a ```sh block in README.md is a command. They run one by one with bash in a
temporary folder holding a copy of ``samples/`` (all a fresh clone has besides the code), with
the ``pslog`` and ``rerun`` of this Python on PATH (as after ``. .venv/bin/activate``), and each
must exit 0 without a traceback. A command that cannot run here (a camera, a display, a server
that runs until Ctrl-C) carries a trailing comment starting ``# needs`` or ``# serves``; that set
is listed below and must stay small. Full commands appear only in those blocks: an inline
`pslog ...` in the prose is a bare command name or repeats a block's command.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"

#: commands the tests cannot run, each marked so in the README; keep this short
NOT_RUN = {
    "pslog record --rig rig.toml --source cam1=0 --source cam2=/dev/video2 "
    "--source cam3=clip.mp4 -o match.mcap": "needs two cameras and a video file",
    "rerun throw.rrd": "needs a display",
    "pslog view fused.mcap --serve": "serves http://localhost:9090 until Ctrl-C",
    "pslog live --rig rig.toml --source cam1=0 --source cam2=1 --source cam3=2 "
    "--out udp://127.0.0.1:10010 --record match-live.mcap": "needs three cameras",
}
#: commands of the set-up block, which this very suite runs inside of
EXCLUDED = {
    "bash run.sh demo": "sets up .venv and runs pslog demo (tests/test_demo.py)",
    "bash run.sh test": "sets up .venv and runs this test suite",
}
_MARK = re.compile(r"\s+#\s*((?:needs|serves)\b.*)$")
_COMMENT = re.compile(r"\s+#.*$")


def fenced_blocks(text: str) -> list[tuple[str, str]]:
    """(language, body) of every fenced code block, in order."""
    return re.findall(r"^```(\w*)\n(.*?)^```", text, flags=re.S | re.M)


def shell_lines(text: str) -> list[str]:
    """Every command line of the ```sh blocks, in order, comments kept."""
    lines = []
    for language, body in fenced_blocks(text):
        if language in ("sh", "bash", "shell", "console"):
            lines += [ln.strip() for ln in body.splitlines()
                      if ln.strip() and not ln.strip().startswith("#")]
    return lines


def split_examples(lines: list[str]) -> tuple[list[str], dict[str, str], list[str]]:
    """(commands to run, marked command -> its reason, excluded commands)."""
    runnable, marked, excluded = [], {}, []
    for line in lines:
        command = _COMMENT.sub("", line)
        mark = _MARK.search(line)
        if command in EXCLUDED:
            excluded.append(command)
        elif mark:
            marked[command] = mark.group(1)
        else:
            runnable.append(command)
    return runnable, marked, excluded


def test_readme_blocks_are_labelled_and_the_not_run_set_is_small_and_listed():
    text = README.read_text(encoding="utf-8")
    languages = [language for language, _ in fenced_blocks(text)]
    assert "" not in languages, "label every fenced block (sh, text, toml, ...)"
    runnable, marked, excluded = split_examples(shell_lines(text))
    assert marked == NOT_RUN
    assert len(marked) <= 4 and len(runnable) >= 20
    assert sorted(excluded) == sorted(EXCLUDED)
    run_sh = (ROOT / "run.sh").read_text(encoding="utf-8")
    assert "    demo)" in run_sh and "    test)" in run_sh


def test_inline_commands_are_names_or_repeat_a_block_command():
    text = README.read_text(encoding="utf-8")
    commands = {_COMMENT.sub("", line) for line in shell_lines(text)}
    prose = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    for span in re.findall(r"`([^`\n]+)`", prose):
        if span.startswith("pslog "):
            assert len(span.split()) <= 2 or span in commands, span
        if span.startswith("python ") and span.split()[1].endswith(".py"):
            assert (ROOT / span.split()[1]).is_file(), span


def test_readme_rig_toml_is_a_valid_rig():
    from pslog.rig import Rig

    blocks = [body for language, body in fenced_blocks(README.read_text(encoding="utf-8"))
              if language == "toml"]
    assert blocks
    for body in blocks:
        rig = Rig.from_toml(body, source="README.md")
        assert rig.names == ("cam1",) and rig.name == "lab"


#: a README line that is one ``pslog`` command and no shell syntax (no pipe, redirection,
#: background job, quoting, glob or expansion)
_PLAIN = re.compile(r"pslog [^|&;<>()'\"`$*?\\]*")

#: the forking runner of the plain ``pslog`` lines (see :class:`_Forks`)
_ZYGOTE = r"""
import importlib, importlib.util, json, os, signal, sys, traceback

from pslog.cli import main  # what the console script imports first

# the third-party libraries only (most of the imports' cost): pslog's own modules are
# imported by each command as a real process imports them (a command that worked only
# because another module of pslog had been imported would pass here, and fail for users)
for name in ("numpy", "numba", "cv2"):
    importlib.import_module(name)
script, hang_s = sys.argv[1], int(sys.argv[2])
# the suite's SystemExit as the interpreter treats it (tests/_exit.py), loaded by its path:
# tests/ is not put on the commands' sys.path
spec = importlib.util.spec_from_file_location("_exit", sys.argv[3])
_exit = importlib.util.module_from_spec(spec)
spec.loader.exec_module(_exit)
print("ready", flush=True)
for line in sys.stdin:
    job = json.loads(line)
    pid = os.fork()
    if pid == 0:  # the command's own process, as if started from its console script
        code = 1
        try:
            signal.alarm(hang_s)  # a hang ends the process (SIGALRM), and fails the test
            os.chdir(job["cwd"])
            for fd, path in ((0, os.devnull), (1, job["out"]), (2, job["err"])):
                f = os.open(path, os.O_RDONLY if fd == 0 else os.O_WRONLY | os.O_CREAT)
                os.dup2(f, fd)
                os.close(f)
            sys.argv = [script, *job["argv"]]
            try:
                code = main(job["argv"])
            except SystemExit as exc:
                code = _exit.exit_status(exc)
            except BaseException:  # uncaught: printed as the interpreter prints it
                traceback.print_exc()
            import atexit, threading
            threading._shutdown()  # the interpreter's exit: threads joined, atexit run
            atexit._run_exitfuncs()
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    print(os.waitstatus_to_exitcode(status), flush=True)
"""


class _Forks:
    """Runs the README's plain ``pslog ARGS`` lines as ``pslog.cli.main(ARGS)`` (what the
    ``pslog`` console script runs) each in its own process, forked from one that imported
    numpy, numba, OpenCV and ``pslog.cli`` once: every command starts in a fresh process, in the
    examples' folder, with their environment and its own standard streams and exit code,
    without paying those imports again (~0.3-1 CPU s per command, a third of the test's
    CPU). The lines with shell syntax run in bash as written, the real ``pslog`` on PATH."""

    def __init__(self, cwd: Path, env: dict, script: Path, hang_s: int) -> None:
        self.cwd = cwd
        # -P: the examples' folder not first on sys.path (a console script's is its bin folder)
        self.proc = subprocess.Popen([sys.executable, "-P", "-c", _ZYGOTE, str(script),
                                      str(hang_s), str(Path(__file__).with_name("_exit.py"))],
                                     cwd=cwd, env=env, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, text=True)
        assert self.proc.stdout.readline() == "ready\n", "the forking runner did not start"

    def run(self, command: str, n: int) -> subprocess.CompletedProcess:
        out, err = self.cwd.parent / f"readme-{n}.out", self.cwd.parent / f"readme-{n}.err"
        argv = command.split()[1:]
        self.proc.stdin.write(json.dumps({"argv": argv, "cwd": str(self.cwd), "out": str(out),
                                          "err": str(err)}) + "\n")
        self.proc.stdin.flush()
        code = int(self.proc.stdout.readline())
        result = subprocess.CompletedProcess(command, code, out.read_text(), err.read_text())
        out.unlink()
        err.unlink()
        return result

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait(60)


def _tracked(paths: list[str]) -> set[str]:
    result = subprocess.run(["git", "-C", str(ROOT), "ls-files", "--", *paths],
                            capture_output=True, text=True, check=True)
    return set(result.stdout.split())


def test_readme_examples_run_in_order_and_their_outputs_are_git_ignored(tmp_path):
    text = README.read_text(encoding="utf-8")
    runnable, _, _ = split_examples(shell_lines(text))
    work = tmp_path / "readme"  # the examples' folder (the forks' stdout and stderr beside it)
    shutil.copytree(ROOT / "samples", work / "samples",
                    ignore=shutil.ignore_patterns("__pycache__"))
    before = {p for p in work.rglob("*")}
    bin_dir = Path(sys.executable).parent
    if not (bin_dir / "pslog").exists():
        pytest.skip(f"pslog is not installed beside {sys.executable}")
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ.get('PATH', '')}",
           "PYTHONWARNINGS": "default"}
    env.pop("DISPLAY", None)
    env.pop("WAYLAND_DISPLAY", None)
    forks = _Forks(work, env, bin_dir / "pslog", 180)
    try:
        for n, command in enumerate(runnable):
            if _PLAIN.fullmatch(command):
                result = forks.run(command, n)
            else:
                result = subprocess.run(["bash", "-o", "pipefail", "-c", command], cwd=work,
                                        env=env, capture_output=True, text=True, timeout=180)
            assert result.returncode == 0 and "Traceback" not in result.stderr, (
                f"README example failed: {command}\nexit {result.returncode}\n"
                f"stdout: {result.stdout[-2000:]}\nstderr: {result.stderr[-2000:]}")
    finally:
        forks.close()
    # most lines ran forked, the others (pipes, redirections, jobs) in bash with the real
    # pslog on PATH: both kinds ran
    plain = sum(bool(_PLAIN.fullmatch(c)) for c in runnable)
    assert 20 <= plain < len(runnable) - 3, plain

    # a fresh clone has what the examples read: the samples they name are in git
    named = sorted({m for c in runnable for m in re.findall(r"samples/[\w./-]+", c)})
    assert named
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout: cannot check what a clone holds and ignores")
    assert _tracked(named) == set(named), "commit the sample files the README uses"

    # what the examples write in the checkout is ignored by git, and the samples are not
    outputs = sorted(str(p.relative_to(work)) for p in work.rglob("*")
                     if p not in before and p.is_file())
    assert len(outputs) >= 15, outputs
    check = subprocess.run(["git", "-C", str(ROOT), "check-ignore", "--no-index", "--",
                            *outputs], capture_output=True, text=True)
    assert sorted(check.stdout.split()) == outputs, (
        f"README outputs not git-ignored: {sorted(set(outputs) - set(check.stdout.split()))}")
    samples = sorted(_tracked(["samples"]))
    check = subprocess.run(["git", "-C", str(ROOT), "check-ignore", "--no-index", "--",
                            *samples], capture_output=True, text=True)
    assert check.stdout == "", f"tracked samples hidden by .gitignore: {check.stdout}"


def test_reliability_counts_the_fault_cases_there_are():
    """README's "Reliability" gives the number of fault cases of ``tests/faults/`` and a
    table of them by kind: the number is what pytest collects there and the table's rows add
    up to it (it was kept by hand; a new fault test now says when it is out of step)."""
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Reliability"):].split("\n## ", 1)[0]
    stated = int(re.search(r"\((\d+) cases, all passing", section).group(1))
    rows = [int(m.group(1)) for m in re.finditer(r"^\|[^\n]*\| (\d+) \|$", section, re.M)]
    run = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p",
                          "no:cacheprovider", str(ROOT / "tests" / "faults")],
                         capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-2000:]
    collected = sum(int(m.group(1)) for m in re.finditer(r"^tests/faults/\S+\.py: (\d+)$",
                                                         run.stdout, re.M))
    assert collected == stated == sum(rows), (collected, stated, rows)
