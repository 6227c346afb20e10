"""Every writer under every operating-system fault, and with its output = its input in every
spelling: one line on stderr, exit 1, no input changed, no partial output, the old output kept.

Faults (we run as root, so permissions alone do not stop a write):

- unwritable folder: a mode-555 folder, the command run without CAP_DAC_OVERRIDE;
- read-only file system: a read-only bind mount;
- full disk: a 64 KiB tmpfs filled to a few KiB (or nothing) free;
- file-size limit: ``RLIMIT_FSIZE`` in the child (the CLI ignores SIGXFSZ, so writes fail
  with EFBIG instead of killing it).

The mount cases are skipped with the reason where mounting is not permitted; the others
always run. Every mount is undone by a fixture finalizer, also when a test fails.
"""

from __future__ import annotations

import contextlib
import os
import resource
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from pslog.cli import main
from pslog.rig import builtin_rig

from ._inprocess import first_case, run_inprocess
from ._inputs import write_points_csv
from ._mounts import CAP_DAC_OVERRIDE, drop_capability, fill, read_only, small_tmpfs
from .promises import Run, assert_one_line_error, assert_untouched, fingerprint, run_pslog

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "throw.mcap"
FULL_TMPFS = 64 * 1024


# ---- inputs, shared by every case -------------------------------------------------------

@pytest.fixture(scope="module")
def inputs():
    folder = Path(tempfile.mkdtemp(prefix="pslog-faults-in-"))
    try:
        folder.chmod(0o755)
        shutil.copyfile(SAMPLE, folder / "s.mcap")  # a recorded session with frames
        (folder / "rig.toml").write_text(builtin_rig("paper3").to_toml(), encoding="utf-8")
        assert main(["fuse", str(folder / "s.mcap"), "--method", "typeA",
                     "-o", str(folder / "fused.mcap")]) == 0
        assert main(["export", str(folder / "s.mcap"), "--detections",
                     str(folder / "det.csv")]) == 0
        write_points_csv(folder / "pts.csv")
        for f in folder.iterdir():
            f.chmod(0o644)
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# ---- the writers ------------------------------------------------------------------------

#: writer -> (arguments; {i} the inputs folder, {o} the output folder), output (relative to
#: {o}), bytes of an old output there (None: b"old output"), free bytes on the full disk,
#: file-size limit in bytes. Every output is far larger than the free space and the limit.
WRITERS = {
    "simulate": (["simulate", "--rig", "{i}/rig.toml", "--duration", "2", "-o", "{o}/s.mcap"],
                 "s.mcap", None, 4096, 2048),
    "import": (["import", "--rig", "{i}/rig.toml", "--detections", "{i}/det.csv",
                "-o", "{o}/i.mcap"], "i.mcap", None, 4096, 2048),
    "export --detections": (["export", "{i}/s.mcap", "--detections", "{o}/d.csv"], "d.csv",
                            None, 4096, 2048),
    "export --csv": (["export", "{i}/fused.mcap", "--csv", "{o}/t.csv"], "t.csv", None, 4096,
                     2048),
    "fuse": (["fuse", "{i}/s.mcap", "--method", "typeA", "-o", "{o}/f.mcap"], "f.mcap", None,
             4096, 2048),
    "recover": (["recover", "{i}/s.mcap", "-o", "{o}/r.mcap"], "r.mcap", None, 4096, 2048),
    "redetect": (["redetect", "{i}/s.mcap", "--workers", "1", "-o", "{o}/r.mcap"], "r.mcap",
                 None, 4096, 2048),
    # adds cam9 to an existing two-camera rig file, rewritten in place
    "calibrate": (["calibrate", "--points", "{i}/pts.csv", "--name", "cam9", "--width", "640",
                   "--height", "480", "--rig", "{o}/rig.toml"], "rig.toml",
                  builtin_rig("paper2").to_toml().encode(), 0, 200),
    # writes a folder of outputs; an old session in it with --force
    "demo": (["demo", "--out", "{o}/demo", "--duration", "0.3", "--no-view"],
             "demo/session.mcap", None, 4096, 2048),
}


def _args(writer: str, i: Path, o: Path) -> list[str]:
    return [a.format(i=i, o=o) for a in WRITERS[writer][0]] + ["--force"]


def _old_output(writer: str, out: Path) -> Path:
    """Put an old output where ``writer`` writes (it must survive the failed run)."""
    _, name, old, _, _ = WRITERS[writer]
    path = out / name
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(b"old output" if old is None else old)
    return path


# ---- faults -----------------------------------------------------------------------------

@pytest.fixture
def mounts():
    """Mounts (:mod:`tests.faults._mounts` context managers) undone at teardown, whatever
    happened."""
    with contextlib.ExitStack() as stack:
        yield stack


def _limit_file_size(limit: int):
    def preexec() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


FAULTS = {
    "unwritable folder": "Permission denied",
    "read-only file system": "Read-only file system",
    "full disk": "No space left on device",
    "file-size limit": "File too large",
}


@pytest.mark.parametrize("writer", list(WRITERS))
@pytest.mark.parametrize("fault", list(FAULTS))
def test_os_fault_is_one_line_and_leaves_nothing(fault, writer, inputs, mounts, tmp_path):
    _, name, _, free, limit = WRITERS[writer]
    preexec = None
    if fault == "unwritable folder":
        out = tmp_path / "locked"
        out.mkdir()
        old = _old_output(writer, out)
        for folder in {out, old.parent}:
            folder.chmod(0o555)  # root too, once CAP_DAC_OVERRIDE is dropped
        preexec = drop_capability(CAP_DAC_OVERRIDE) if os.geteuid() == 0 else None
    elif fault == "read-only file system":
        out = tmp_path / "ro"
        out.mkdir()
        _old_output(writer, out)
        mounts.enter_context(read_only(out))
    elif fault == "full disk":
        out = mounts.enter_context(small_tmpfs(tmp_path / "full", f"{FULL_TMPFS}"))
        _old_output(writer, out)
        fill(out, free)
    else:
        out = tmp_path / "limited"
        out.mkdir()
        _old_output(writer, out)
        preexec = _limit_file_size(limit)
    before = fingerprint(inputs, out)
    started = time.monotonic()
    # a fault of the file system alone (no preexec) and a writer without processes of its
    # own (not demo's cameras, not redetect's forked workers): in this process
    # (tests/faults/_inprocess.py); the first writer of each fault as a real process
    here = (preexec is None and writer not in ("demo", "redetect")
            and writer != next(iter(WRITERS)))
    run = (run_inprocess(*_args(writer, inputs, out), cwd=inputs) if here else
           run_pslog(*_args(writer, inputs, out), cwd=inputs, preexec_fn=preexec))
    took = time.monotonic() - started
    line = assert_one_line_error(run, 1, contains=FAULTS[fault])
    assert str(out) in line, f"the error does not name the output: {line}"
    assert_untouched(before, inputs, out)
    assert took < 30, f"took {took:.0f} s to fail"
    assert (out / name).exists()


# ---- output = input, in every spelling --------------------------------------------------

#: writer -> (arguments with {o} the output, the input file {o} is made to name)
SAME = {
    "simulate": (["simulate", "--rig", "rig.toml", "--duration", "0.3", "-o", "{o}"],
                 "rig.toml"),
    "import": (["import", "--rig", "rig.toml", "--detections", "det.csv", "-o", "{o}"],
               "det.csv"),
    "export --detections": (["export", "s.mcap", "--detections", "{o}"], "s.mcap"),
    "export --csv": (["export", "fused.mcap", "--csv", "{o}"], "fused.mcap"),
    "fuse": (["fuse", "s.mcap", "-o", "{o}"], "s.mcap"),
    "fuse --rig": (["fuse", "s.mcap", "--rig", "rig.toml", "-o", "{o}"], "rig.toml"),
    "recover": (["recover", "s.mcap", "-o", "{o}"], "s.mcap"),
    "redetect": (["redetect", "s.mcap", "-o", "{o}"], "s.mcap"),
    "calibrate": (["calibrate", "--points", "pts.csv", "--name", "cam9", "--width", "640",
                   "--height", "480", "--rig", "{o}"], "pts.csv"),
}
SPELLINGS = ("./{x}", "sub/../{x}", "{abs}", "symlink", "hard link")


@pytest.fixture(scope="module")
def aliased(inputs):
    """The inputs folder with a symbolic and a hard link to each input and a sub-folder."""
    (inputs / "sub").mkdir(exist_ok=True)
    for x in {x for _, x in SAME.values()}:
        for kind, make in (("symlink", os.symlink), ("hard link", os.link)):
            link = inputs / f"{kind.replace(' ', '-')}-{x}"
            if not link.exists():
                make(x if kind == "symlink" else inputs / x, link)
    return inputs


@pytest.mark.parametrize("spelling", SPELLINGS)
@pytest.mark.parametrize("writer", list(SAME))
def test_output_that_is_an_input_is_refused(writer, spelling, aliased, monkeypatch, capsys):
    template, x = SAME[writer]
    monkeypatch.chdir(aliased)
    out = (f"{spelling.replace(' ', '-')}-{x}" if spelling in ("symlink", "hard link")
           else spelling.format(x=x, abs=aliased / x))
    args = [a.format(o=out) for a in template] + ["--force"]
    before = fingerprint(aliased)
    capsys.readouterr()
    code = main(args)
    captured = capsys.readouterr()
    run = Run(tuple(args), code, captured.out, captured.err)
    assert_one_line_error(run, 1, contains=("is the input", out))
    assert_untouched(before, aliased)


# ---- an input named like the output's partial ------------------------------------------

@pytest.mark.parametrize("command", [
    ["export", "{o}.partial", "--detections", "{o}"],  # a derived session's partial
    ["recover", "{o}.partial", "-o", "{o}"],  # a recording's partial
])
def test_an_input_that_is_the_outputs_partial_is_refused(command, inputs, tmp_path, request):
    """The partial is cleared before, and written over while, making the output: an input
    with that name would be deleted before it is read."""
    out = tmp_path / "g.mcap"
    source = inputs / ("fused.mcap" if command[0] == "export" else "s.mcap")
    shutil.copyfile(source, tmp_path / "g.mcap.partial")
    before = fingerprint(tmp_path)
    # the first case as a real process, the other in this one (tests/faults/_inprocess.py)
    run = (run_pslog if first_case(request) else run_inprocess)(
        *[a.format(o=out) for a in command], "--force")
    assert_one_line_error(run, 1, contains=(f"output {out} is written via {out}.partial, "
                                            f"which is an input", "choose another name"))
    assert_untouched(before, tmp_path)


def test_recover_session_never_writes_over_its_input(inputs, tmp_path):
    from pslog.errors import InputError
    from pslog.log import recover_session

    src = tmp_path / "g.mcap.partial"
    shutil.copyfile(inputs / "s.mcap", src)
    os.link(src, tmp_path / "hard.mcap")
    before = fingerprint(tmp_path)
    for dst in (tmp_path / "g.mcap", src, tmp_path / "hard.mcap"):
        with pytest.raises(InputError, match=r"which is an input|is the input"):
            recover_session(src, dst, force=True)
    assert_untouched(before, tmp_path)


# ---- two runs writing one output at once ------------------------------------------------

#: a pslog writer that opens its output, says so, and finishes when told (stdin)
_HOLDER = r"""
import sys
kind, path = sys.argv[1:]
if kind == "session":
    from pslog.log import SessionWriter
    from pslog.rig import builtin_rig

    with SessionWriter(path, builtin_rig("paper3"), force=True, on_error="discard",
                       source="pslog simulate (a test)",
                       flush_interval_s=0) as w:
        w.add_frame(0, 0, 0, uv=[[1.0, 2.0]])
        w.flush()
        print("writing", flush=True)
        sys.stdin.readline()
else:
    from pslog.outputs import replacing

    with replacing(path, force=True) as f:
        f.write("first run\n")
        f.flush()
        print("writing", flush=True)
        sys.stdin.readline()
print("done", flush=True)
"""


@contextlib.contextmanager
def _writer_holding(script: str, kind: str, out: Path):
    """A real process running ``script`` (a writer of ``out`` that pauses mid-write) for the
    ``with`` block; afterwards it completes, and must complete cleanly."""
    import sys

    first = subprocess.Popen([sys.executable, "-c", script, kind, str(out)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert first.stdout.readline().strip() == "writing"
        yield
        rest, _ = first.communicate("\n", timeout=60)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    assert first.returncode == 0 and rest.strip() == "done"


@pytest.mark.parametrize("kind", ["session", "text"])
def test_a_second_run_leaves_the_partial_of_a_running_one_alone(kind, inputs, tmp_path):
    """Two real processes: while the first writes <out>.partial, a second run of a command
    writing <out> (--force) is refused and touches nothing; the first then completes."""

    out = tmp_path / ("r.mcap" if kind == "session" else "d.csv")
    second = (["simulate", "--rig", "paper3", "--duration", "0.3", "-o", out, "--force"]
              if kind == "session" else
              ["export", inputs / "s.mcap", "--detections", out, "--force"])
    with _writer_holding(_HOLDER, kind, out):
        before = fingerprint(tmp_path)
        run = run_pslog(*second)
        assert_one_line_error(run, 1, contains=f"another pslog is writing {out}.partial")
        assert_untouched(before, tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]
    if kind == "session":
        from pslog.log import read_session

        assert read_session(out).detections.n_frames == 1
    else:
        assert out.read_text() == "first run\n"


# ---- a run killed with --force leaves <file>.partial: the next run deals with it --------

def test_stale_partial_of_a_derived_output_is_removed_with_a_notice(inputs, tmp_path):
    out = tmp_path / "f.mcap"
    # what a killed 'fuse' leaves: the first part of the file it was writing
    stale = (inputs / "fused.mcap").read_bytes()[:50_000]
    (tmp_path / "f.mcap.partial").write_bytes(stale)
    run = run_pslog("fuse", inputs / "s.mcap", "--method", "typeA", "-o", out)
    assert run.code == 0, run.stderr
    assert run.stderr.strip() == (f"pslog fuse: removed {out}.partial left by an interrupted "
                                  f"run")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.mcap"]


def test_a_killed_force_run_leaves_a_partial_that_the_next_run_removes(inputs, tmp_path):
    """A real SIGKILL in the middle of 'redetect --force' (the session copy under way)."""
    import signal
    import sys

    out, partial = tmp_path / "r.mcap", tmp_path / "r.mcap.partial"
    out.write_bytes(b"old output")
    args = [sys.executable, "-m", "pslog.cli", "redetect", str(inputs / "s.mcap"),
            "--workers", "1", "-o", str(out), "--force"]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while not partial.exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.001)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait()
    if proc.returncode != -signal.SIGKILL:
        pytest.skip("redetect finished before it could be killed")
    assert out.read_bytes() == b"old output" and partial.exists()
    run = run_pslog("redetect", inputs / "s.mcap", "--workers", "1", "-o", out, "--force")
    assert run.code == 0, run.stderr
    assert f"removed {partial} left by an interrupted run" in run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.mcap"]
    assert out.read_bytes() != b"old output"


def test_a_file_pslog_cannot_prove_it_made_is_never_taken_for_a_stale_partial(inputs,
                                                                              tmp_path):
    """A user's notes.csv.partial (no MCAP: pslog cannot tell it wrote it) and a complete
    session named s3.mcap.partial are kept and the write refused, naming them; an output
    named *.partial (which a later run would take for its stale partial) is refused."""
    (tmp_path / "notes.csv.partial").write_text("my notes\n")
    shutil.copyfile(inputs / "fused.mcap", tmp_path / "s3.mcap.partial")
    before = fingerprint(tmp_path)
    for args, contains in (
            (["export", inputs / "fused.mcap", "--csv", tmp_path / "notes.csv"],
             (f"{tmp_path / 'notes.csv.partial'} exists", "cannot tell it made it")),
            (["simulate", "--rig", "paper3", "--duration", "0.3", "-o", tmp_path / "s3.mcap"],
             (f"{tmp_path / 's3.mcap.partial'} exists and is a complete session",)),
            (["fuse", inputs / "s.mcap", "-o", tmp_path / "new.mcap.partial"],
             ("ends in .partial", "choose another name"))):
        assert_one_line_error(run_pslog(*args), 1, contains=contains)
        assert_untouched(before, tmp_path)


@pytest.mark.parametrize("args", [
    ["export", "{i}/fused.mcap", "--csv", "-"],
    ["export", "{i}/fused.mcap", "--tum", "-"],
    ["fuse", "{i}/s.mcap", "--method", "typeA", "-o", "-"],
    ["simulate", "--rig", "paper3", "--duration", "0.3", "-o", "-"],
])
def test_dash_as_an_output_is_refused_not_written_as_a_file_named_dash(args, inputs, tmp_path,
                                                                      request):
    """'-' means standard output elsewhere: pslog wrote a file (or folder) named '-'."""
    argv = [a.format(i=inputs) for a in args]
    if first_case(request):  # a real process, run in tmp_path
        run = run_pslog(*argv, cwd=tmp_path)
    else:  # in this process (tests/faults/_inprocess.py), from tmp_path
        old = os.getcwd()
        os.chdir(tmp_path)
        try:
            run = run_inprocess(*argv)
        finally:
            os.chdir(old)
    assert_one_line_error(run, 1, contains=("'-'", "not standard output", "./-"))
    assert list(tmp_path.iterdir()) == []


def test_stale_partial_that_may_hold_a_recording_is_kept_and_named(inputs, tmp_path):
    out = tmp_path / "s.mcap"
    out.write_bytes(b"old session")
    # what a killed 'record --force' leaves: the first part of a recording
    recording = SAMPLE.read_bytes()[:200_000]
    (tmp_path / "s.mcap.partial").write_bytes(recording)
    before = fingerprint(tmp_path)
    for i, args in enumerate((["fuse", inputs / "s.mcap", "-o", out, "--force"],
                              ["simulate", "--rig", "paper3", "--duration", "0.3", "-o", out,
                               "--force"])):
        # the first as a real process, the other in this one (tests/faults/_inprocess.py)
        run = (run_inprocess if i else run_pslog)(*args)
        assert_one_line_error(run, 1, contains=(f"{out}.partial", "recording", "pslog recover"))
        assert_untouched(before, tmp_path)


# ---- the writer's background flush thread meets a full disk -----------------------------

def test_background_flush_on_a_full_disk_is_one_error_in_the_callers_thread(tmp_path, mounts,
                                                                           rig3):
    """The flusher thread meets the full disk while the caller is idle; the caller's next
    call raises that error, even though the disk has room again by then (so the error can
    only be the one the flusher met, not one of the call's own writes)."""
    from pslog.log import SessionWriter
    from pslog.outputs import WriteError

    out = mounts.enter_context(small_tmpfs(tmp_path / "full", f"{FULL_TMPFS}"))
    path = out / "s.mcap"
    thread_errors = []
    old_hook = threading.excepthook
    threading.excepthook = thread_errors.append
    try:
        with pytest.raises(WriteError, match=f"cannot write {path}: No space left on device"), \
                SessionWriter(path, rig3, flush_interval_s=0.2, on_error="discard") as w:
            fill(out)
            image = os.urandom(8192)  # incompressible: needs pages the disk no longer has
            for k in range(3):
                w.add_frame(k, k, k * 11_111_111, uv=[[1.0, 2.0]], image=image)
            time.sleep(1.0)  # past the interval, the writer left alone: the flusher's turn
            (out / "filler").unlink()  # room again: the next call could write
            w.add_frame(0, 3, 33_333_333, uv=[[1.0, 2.0]])
            pytest.fail("the error the flusher met was not raised by the next call")
    finally:
        threading.excepthook = old_hook
    assert thread_errors == []
    assert list(out.iterdir()) == []


# ---- outputs that are not regular files: never replaced, --force or not -------------------

def _make_node(path: Path, kind: str) -> None:
    """A special file of ``kind`` at ``path`` (made here: never a real /dev path)."""
    import socket
    import stat

    if kind == "character device":
        try:
            os.mknod(path, 0o666 | stat.S_IFCHR, os.makedev(1, 3))  # a null device
        except PermissionError:
            pytest.skip("mknod needs root")
    elif kind == "named pipe":
        os.mkfifo(path)
    elif kind == "socket":
        with socket.socket(socket.AF_UNIX) as s:
            s.bind(str(path))
    else:  # a symbolic link to a file
        (path.parent / "target.mcap").write_bytes(b"old output")
        path.symlink_to("target.mcap")


@pytest.mark.parametrize("kind", ["character device", "named pipe", "socket", "symbolic link"])
@pytest.mark.parametrize("writer", ["simulate", "export --detections"])
def test_an_output_that_is_not_a_regular_file_is_refused_even_with_force(kind, writer, inputs,
                                                                          tmp_path, request):
    out = tmp_path / "o"
    out.mkdir()
    node = out / WRITERS[writer][1]
    _make_node(node, kind)
    before_mode = os.lstat(node).st_mode
    before = fingerprint(out)
    # each kind's first case as a real process, the other in this one (tests/faults/
    # _inprocess.py; an output opened for ever, a named pipe's, fails there as a hang too)
    run = (run_pslog if first_case(request, per=("kind",)) else run_inprocess)(
        *_args(writer, inputs, out))
    assert_one_line_error(run, 1, contains=(str(node), kind))
    assert_untouched(before, out)
    assert os.lstat(node).st_mode == before_mode  # still the same node, not a regular file
    if kind == "symbolic link":
        assert (out / "target.mcap").read_bytes() == b"old output"


def test_an_output_being_recorded_into_is_refused_even_with_force(inputs, tmp_path):
    """A real process records straight into a new file (it holds the writer's lock on the
    file itself, not on a .partial): a --force run writing that file is refused, and the
    recording completes into the file the user named."""

    out = tmp_path / "w.mcap"
    holder = _HOLDER.replace("force=True, on_error=\"discard\"", "on_error=\"keep\"")
    assert holder != _HOLDER
    with _writer_holding(holder, "session", out):
        assert not (tmp_path / "w.mcap.partial").exists()  # written in place
        before = fingerprint(tmp_path)
        for args in (["simulate", "--rig", "paper3", "--duration", "0.3", "-o", out, "--force"],
                     ["export", inputs / "s.mcap", "--detections", out, "--force"]):
            run = run_pslog(*args)
            assert_one_line_error(run, 1, contains=(f"{out} is being written by another pslog",
                                                    "recording in progress"))
            assert_untouched(before, tmp_path)
        # a reader meeting the unfinished file says it may still be recording
        run = run_pslog("fuse", out, "--method", "typeA", "-o", tmp_path / "f.mcap")
        assert_one_line_error(run, 1, contains=("may still be recording",
                                                "another pslog is writing it"))
        assert_untouched(before, tmp_path)
    from pslog.log import read_session

    assert read_session(out).detections.n_frames == 1


# ---- standard output full or closed: never blamed on (or costing) a complete output ------

def test_a_full_standard_output_is_named_and_the_complete_output_kept(inputs, tmp_path):
    import stat
    import sys

    full = tmp_path / "full"
    try:
        os.mknod(full, 0o666 | stat.S_IFCHR, os.makedev(1, 7))  # our own /dev/full
    except PermissionError:
        pytest.skip("mknod needs root")
    out = tmp_path / "o"
    out.mkdir()
    # fuse prints as each method's track is written, before its output is complete: it too
    # runs to its end and keeps it (it used to stop there and leave nothing)
    for args, made in ((["export", inputs / "s.mcap", "--detections", out / "d.csv"], "d.csv"),
                       (["fuse", inputs / "s.mcap", "-o", out / "f.mcap"], "f.mcap"),
                       (["info", inputs / "s.mcap"], None)):
        with open(full, "w") as stdout:
            proc = subprocess.run([sys.executable, "-m", "pslog.cli", *map(str, args)],
                                  stdout=stdout, stderr=subprocess.PIPE, text=True, timeout=60)
        run = Run(tuple(map(str, args)), proc.returncode, "", proc.stderr)
        assert_one_line_error(run, 1, contains="cannot write to standard output: No space "
                                               "left on device")
        if made == "d.csv":
            text = (out / made).read_text()
            assert text.count("\n") > 100 and text == (inputs / "det.csv").read_text()
        if made == "f.mcap":
            from pslog.log import read_session

            assert sorted(read_session(out / made).tracks) == ["filter", "nearest", "smooth",
                                                               "typeA"]
        if made:  # said to be complete, never blamed
            assert run.stderr.rstrip().endswith(f"; {out / made} written complete")


def test_a_closed_standard_output_is_no_traceback(inputs):
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", "info", str(inputs / "s.mcap")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # the reader is gone before pslog writes a byte (``| head -c0``)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert err == "", err  # no traceback, no "Exception ignored" at the interpreter's exit


def test_force_onto_a_session_being_recorded_is_refused(tmp_path):
    """The tester's case with a real recording: 'pslog record' writes a new session in place
    (no .partial); a 'simulate --force' onto it meanwhile is refused, and the recording
    completes into the file the user named.

    The recording is long (60 s of frames) and stopped by a Ctrl-C once the refusal is seen:
    a short one could end, on a loaded machine, before the refused command had even started
    (and that command then rightly replaced it). What the file must hold is what the
    recorder says it recorded, not a share of a duration."""
    import re
    import signal
    import sys

    from pslog.log import read_session
    from pslog.outputs import locked_by_another

    out = tmp_path / "w.mcap"
    inode = None
    rec = subprocess.Popen([sys.executable, "-m", "pslog.cli", "record", "--synthetic", "--rig",
                            "paper3", "--timing", "typeA", "--duration", "60", "-o", str(out)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                           start_new_session=True)  # (its own group: Ctrl-C as from a terminal)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(rec.stderr), daemon=True)
    reader.start()

    def every_camera_delivered() -> bool:  # a status line: "[ 1.2 s] cam1: 36 fr ..."
        return any(re.search(r"\] cam1: [1-9]", line) and len(re.findall(
            r"cam\d: [1-9]\d* fr", line)) == 3 for line in list(lines))

    try:
        deadline = time.monotonic() + 60  # a hang guard, not a timing assertion
        while not (out.exists() and locked_by_another(out)):
            assert rec.poll() is None, "record ended early: " + "".join(lines)
            assert time.monotonic() < deadline, "record never started writing"
            time.sleep(0.05)
        inode = out.stat().st_ino
        run = run_pslog("simulate", "--rig", "paper3", "--duration", "0.3", "-o", out, "--force")
        assert_one_line_error(run, 1, contains=(str(out), "being written by another pslog"))
        # out grows as the cameras deliver: untouched means not replaced (same inode) and no
        # partial of the refused run
        assert sorted(p.name for p in tmp_path.iterdir()) == ["w.mcap"]
        deadline = time.monotonic() + 120  # (a hang guard)
        while not every_camera_delivered():  # the stop then leaves a session, not nothing
            assert rec.poll() is None, "record ended early: " + "".join(lines)
            assert time.monotonic() < deadline, "no frame from every camera:\n" + "".join(lines)
            time.sleep(0.05)
        os.killpg(rec.pid, signal.SIGINT)
        rec.wait(timeout=120)
        reader.join(10)
        err = "".join(lines)
    finally:
        if rec.poll() is None:
            os.killpg(rec.pid, signal.SIGKILL)
            rec.wait()
    assert rec.returncode == 0, err
    assert "recording stopped by SIGINT" in err, err
    assert out.stat().st_ino == inode  # never replaced: the recorder's file is the output
    session = read_session(out)  # the recording is in the file named, complete
    # every frame the recorder's summary counts, each camera's (none failed)
    counted = {m.group(1): int(m.group(2)) for m in re.finditer(
        r"^  (cam\d) +(\d+) frames .*\[stopped\]", err, re.M)}
    assert sorted(counted) == ["cam1", "cam2", "cam3"] and min(counted.values()) > 0, err
    names = [camera.name for camera in session.rig.cameras]
    held = np.bincount(session.detections.frame_camera, minlength=len(names))
    assert dict(zip(names, held.tolist(), strict=True)) == counted, err
    assert session.metadata["source"].startswith("record"), session.metadata["source"]
