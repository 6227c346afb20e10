"""pslog batch, review findings of 2026-11-30: earlier results are not sessions, a session
failing now keeps none of its old outputs, an input replaced mid-run is not taken as done,
one batch at a time per results folder, -o inside the pattern's folder, per-session lines
as they finish and PSLOG_PROGRESS, no empty folders, --estimate without sync.

Every batch here has one session, which runs in the test's process without a Ray cluster
(fast); the lock and progress checks run ``pslog batch`` as a real process."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from test_batch import pslog

import pslog.batch as batch
from pslog.batch import DONE_NAME, LOCK_NAME, Job, Settings, find_sessions, read_summary_csv
from tests.faults.promises import assert_one_line_error, run_pslog

pytest.importorskip("ray")

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"


def session(path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(SAMPLE, path)
    return path


def cut(path: Path) -> None:
    """``path`` cut short (a corrupt session), dated an hour ago (not one being written)."""
    path.write_bytes(SAMPLE.read_bytes()[:4000])
    hour_ago = time.time() - 3600
    os.utime(path, (hour_ago, hour_ago))


def test_an_earlier_batchs_results_inside_the_tree_are_not_sessions(tmp_path):
    dt = tmp_path / "dt"
    session(dt / "d1" / "a.mcap")
    code, _, err = pslog("batch", f"{dt}/**/*.mcap", "--do", "sync,fuse", "-o",
                         dt / "results_v1")
    assert code == 0, err
    code, _, err = pslog("batch", f"{dt}/**/*.mcap", "--do", "fuse,eval", "-o",
                           dt / "results_v2")
    assert code == 0, err
    rows = read_summary_csv(dt / "results_v2" / "summary.csv")
    assert [r["session"] for r in rows] == ["d1/a.mcap"]
    assert "skipped 2 file(s) inside earlier batch results" in err
    assert sorted(p.name for p in (dt / "results_v2").iterdir()) == [
        "d1", "summary.csv", "summary.parquet"]


def test_a_file_beside_a_done_marker_or_below_a_summary_is_skipped(tmp_path):
    session(tmp_path / "s" / "real.mcap")
    session(tmp_path / "s" / "old" / "x" / "fused.mcap")
    (tmp_path / "s" / "old" / "x" / DONE_NAME).write_text("{}")
    session(tmp_path / "s" / "res" / "y" / "z" / "synced.mcap")
    batch.write_summary([batch.summary_row("y/z.mcap", None, None, None)],
                        tmp_path / "s" / "res")
    # a summary.csv that is not pslog's does not hide the sessions below it
    session(tmp_path / "s" / "other" / "b.mcap")
    (tmp_path / "s" / "other" / "summary.csv").write_text("team,score\n")
    skipped: list[str] = []
    jobs = find_sessions([f"{tmp_path}/s/**/*.mcap"], tmp_path / "out", skipped)
    assert [j.session for j in jobs] == ["other/b.mcap", "real.mcap"]
    assert sorted(Path(p).name for p in skipped) == ["fused.mcap", "synced.mcap"]


def test_output_inside_the_patterns_folder_is_named(tmp_path):
    session(tmp_path / "res" / "a.mcap")
    run = run_pslog("batch", f"{tmp_path}/res/*.mcap", "--do", "fuse", "-o", tmp_path / "res")
    assert_one_line_error(run, 1, contains=("every match of", "lies inside -o"))


def test_a_session_failing_on_force_keeps_none_of_its_old_outputs(tmp_path):
    a = session(tmp_path / "s" / "d1" / "a.mcap")
    out = tmp_path / "res"
    code, _, err = pslog("batch", f"{tmp_path}/s/**/*.mcap", "--do", "sync,fuse,eval", "-o", out)
    assert code == 0, err
    assert (out / "d1" / "a" / "fused.mcap").is_file()
    cut(a)
    code, stdout, err = pslog("batch", f"{tmp_path}/s/**/*.mcap", "--do", "sync,fuse,eval",
                              "-o", out, "--force")
    assert code == 1
    assert "failed d1/a.mcap" in stdout
    # no old fused.mcap / eval.json beside the failed row, and no empty folders
    assert not (out / "d1").exists()


def test_an_input_replaced_during_the_run_fails_and_is_redone_on_resume(tmp_path, monkeypatch):
    a = session(tmp_path / "s" / "a.mcap")
    out = tmp_path / "res"
    real = batch._command

    def replace_after_sync(argv):
        # the user replaces the session (another copy, another date) while it is fused
        text = real(argv)
        if argv[0] == "sync":
            shutil.copyfile(SAMPLE, a.with_suffix(".new"))
            os.utime(a.with_suffix(".new"), (time.time() - 7200, time.time() - 7200))
            os.replace(a.with_suffix(".new"), a)
        return text

    monkeypatch.setattr(batch, "_command", replace_after_sync)
    job = Job(str(a), "a.mcap", str(out / "a"))
    row = batch.run_session(job, Settings(steps=("sync", "fuse")))
    assert row["status"] == "failed"
    assert "input changed during the run" in row["error"]
    assert not (out / "a" / DONE_NAME).exists()
    monkeypatch.setattr(batch, "_command", real)
    # with the input as it is now, --resume runs it (no marker) and records the new input
    row = batch.run_session(job, Settings(steps=("sync", "fuse")))
    assert row["status"] == "ok", row["error"]
    marker = json.loads((out / "a" / DONE_NAME).read_text())
    assert marker["input"]["mtime_ns"] == a.stat().st_mtime_ns


def test_a_second_batch_on_the_same_results_folder_fails_and_a_stale_lock_is_taken(tmp_path):
    session(tmp_path / "s" / "a.mcap")
    out = tmp_path / "res"
    out.mkdir()
    (out / LOCK_NAME).write_text(f"{os.getpid()}\n")  # a live batch (this test) holds it
    run = run_pslog("batch", f"{tmp_path}/s/*.mcap", "--do", "fuse", "-o", out)
    assert_one_line_error(run, 1, contains=(str(out / LOCK_NAME), f"pid {os.getpid()}"))
    assert not (out / "a").exists()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (out / LOCK_NAME).write_text(f"{dead.pid}\n")  # a batch killed outright
    run = run_pslog("batch", f"{tmp_path}/s/*.mcap", "--do", "fuse", "-o", out)
    assert run.code == 0, run.stderr
    assert not (out / LOCK_NAME).exists()  # released at the end


def test_a_full_disk_names_the_lock_and_leaves_none_and_an_empty_lock_is_taken(tmp_path):
    """On a full results disk the lock file is created but its pid cannot be written: the
    error named no file and the empty lock stayed, and then refused every later batch on
    that folder ("another batch keeps taking it")."""
    from tests.faults._mounts import fill, small_tmpfs

    session(tmp_path / "s" / "a.mcap")
    with small_tmpfs(tmp_path / "disk", "16m") as disk:
        out = disk / "res"
        out.mkdir()
        fill(disk)
        run = run_pslog("batch", f"{tmp_path}/s/*.mcap", "--do", "fuse", "-o", out)
        assert_one_line_error(run, 1, contains=f"cannot write {out / LOCK_NAME}: No space "
                                               f"left on device")
        assert list(out.iterdir()) == []
        (disk / "filler").unlink()
        (out / LOCK_NAME).write_bytes(b"")  # what a batch killed in that moment leaves
        run = run_pslog("batch", f"{tmp_path}/s/*.mcap", "--do", "sync", "-o", out)
        assert run.code == 0, run.stderr
        assert not (out / LOCK_NAME).exists()


def test_each_sessions_line_is_printed_when_it_finishes(tmp_path):
    """The summary cannot be written (a folder in its way): the session's line is out
    already."""
    session(tmp_path / "s" / "a.mcap")
    out = tmp_path / "res"
    (out / "summary.csv").mkdir(parents=True)
    code, stdout, err = pslog("batch", f"{tmp_path}/s/*.mcap", "--do", "fuse", "-o", out,
                              "--force")
    assert code == 1
    assert stdout.splitlines()[0] == "ok     a.mcap", err


@pytest.mark.parametrize(("env", "contains"), [
    ({"PSLOG_PROGRESS": "loud"}, "PSLOG_PROGRESS='loud'"),
    ({"PSLOG_PROGRESS_INTERVAL": "0"}, "PSLOG_PROGRESS_INTERVAL='0'"),
])
def test_bad_progress_settings_are_one_line(tmp_path, env, contains):
    session(tmp_path / "s" / "a.mcap")
    run = run_pslog("batch", f"{tmp_path}/s/*.mcap", "--do", "fuse", "-o", tmp_path / "res",
                    env={**os.environ, **env})
    assert_one_line_error(run, 1, contains=contains)
    assert not (tmp_path / "res").exists()


@pytest.mark.parametrize(("mode", "shown"), [("off", False), ("lines", True)])
def test_pslog_progress_off_and_lines(tmp_path, mode, shown):
    session(tmp_path / "s" / "a.mcap")
    code, _, err = _with_env({"PSLOG_PROGRESS": mode}, "batch", f"{tmp_path}/s/*.mcap",
                             "--do", "fuse", "-o", tmp_path / "res")
    assert code == 0, err
    assert ("sessions/min" in err) is shown, err


def _with_env(env: dict, *argv) -> tuple[int, str, str]:
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        return pslog(*argv)
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def test_estimate_without_sync_is_refused(tmp_path):
    session(tmp_path / "s" / "a.mcap")
    run = run_pslog("batch", f"{tmp_path}/s/*.mcap", "--do", "fuse", "--estimate", "drift",
                    "-o", tmp_path / "res")
    assert_one_line_error(run, 2, contains="--estimate")
    assert not (tmp_path / "res").exists()


def test_a_failed_nested_session_leaves_no_empty_folders(tmp_path):
    cut(session(tmp_path / "s" / "d1" / "d2" / "bad.mcap"))
    session(tmp_path / "keep" / "x.mcap")
    out = tmp_path / "res"
    code, stdout, _ = pslog("batch", f"{tmp_path}/s/**/*.mcap", "--do", "fuse", "-o", out)
    assert code == 1
    assert "failed d1/d2/bad.mcap" in stdout
    assert sorted(p.name for p in out.iterdir()) == ["summary.csv", "summary.parquet"]


def test_a_session_that_cannot_be_read_is_said_as_the_batchs_error(tmp_path):
    """The batch reads each session with ``pslog info`` for its summary, a command the user
    never typed: its failure is said as the batch's, naming the session the user gave
    (was "pslog info: error: ..." for a batch of --do fuse; session 30's walkthrough)."""
    bad = session(tmp_path / "s" / "bad.mcap")
    cut(bad)
    out = tmp_path / "res"
    code, stdout, err = pslog("batch", f"{tmp_path}/s/*.mcap", "--do", "fuse", "-o", out)
    assert code == 1
    said = (f"pslog batch: error: {bad}: the recording did not finish; run 'pslog recover "
            f"{bad} -o FIXED.mcap' to salvage it")
    assert f"failed bad.mcap: {said}" in stdout.splitlines(), stdout
    assert f"(first: bad.mcap: {said}); see {out / 'summary.csv'}" in err, err
    assert read_summary_csv(out / "summary.csv")[0]["error"] == said
    assert "pslog info" not in stdout + err


def _done_once(tmp_path: Path) -> tuple[Job, Settings, dict]:
    """A one-session batch done in this process: its job, settings and its outputs'
    (inode, bytes) by name."""
    a = session(tmp_path / "s" / "a.mcap")
    job = Job(str(a), "a.mcap", str(tmp_path / "res" / "a"))
    settings = Settings(steps=("sync", "fuse", "eval"))
    assert batch.run_session(job, settings)["status"] == "ok"
    return job, settings, _outputs(job)


def _outputs(job: Job) -> dict:
    return {p.name: (p.stat().st_ino, p.read_bytes()) for p in Path(job.outdir).iterdir()}


def test_a_forced_session_interrupted_in_process_keeps_its_old_outputs(tmp_path, monkeypatch):
    """Ctrl-C during a session's fuse (the one-session batch runs in this process): the
    old outputs stay, the new sync made aside is removed."""
    job, settings, before = _done_once(tmp_path)
    real = batch._command

    def interrupted_fuse(argv):
        if argv[0] == "fuse":
            raise KeyboardInterrupt
        return real(argv)

    monkeypatch.setattr(batch, "_command", interrupted_fuse)
    with pytest.raises(KeyboardInterrupt):
        batch.run_session(job, settings)
    assert _outputs(job) == before


def test_a_task_whose_staging_folder_an_interrupted_batch_removed_keeps_the_old_outputs(
        tmp_path, monkeypatch):
    """An interrupted batch settles each session's folder (its staging folder removed) while
    a force-cancelled task's worker may still run (Ray ends it asynchronously): that task's
    next step then fails on the vanished folder — an interruption, not a failure of the
    session: its old outputs stay (seen once in the suite: a whole result folder gone)."""
    job, settings, before = _done_once(tmp_path)
    real = batch._command

    def settled_under_the_fuse(argv):
        if argv[0] == "fuse":  # the interrupted batch's settle(), from another process
            batch.settle(job)
        return real(argv)

    monkeypatch.setattr(batch, "_command", settled_under_the_fuse)
    row = batch.run_session(job, settings)
    assert row["status"] == "failed" and "output folder does not exist" in row["error"], row
    assert _outputs(job) == before



def test_a_task_whose_command_a_signal_ends_keeps_the_old_outputs(tmp_path, monkeypatch):
    """A signal that ends a step's command (Ray ending a cancelled task's worker, a Ctrl-C):
    pslog's command turns it into its exit code (130, 128 + the signal's number) and one
    line, which the task took for a failure of the session, discarding its old outputs
    (seen once in the suite: test_batch's forced batch ended by SIGTERM, a whole result
    folder gone). An interruption: the old outputs stay. A real SIGINT to this process
    while the fuse command runs (when it reads the session: its handler installed)."""
    import signal

    import pslog.log

    job, settings, before = _done_once(tmp_path)
    real = pslog.log.read_session

    def read_then_interrupted(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return real(*args, **kwargs)

    monkeypatch.setattr(pslog.log, "read_session", read_then_interrupted)
    row = batch.run_session(job, settings)
    assert row["status"] == "failed" and "interrupted" in row["error"], row
    assert _outputs(job) == before


def test_the_summary_has_the_readouts_auto_chose_and_only_those():
    """``--estimate`` left at auto: the summary's readout (and drift) columns follow what
    ``pslog sync --json`` says it estimated (``estimated``), not the names given."""
    cam = {"name": "c2", "offset_s": 1e-3, "offset_std_s": 1e-4, "drift_ppm": 0.0,
           "drift_std_ppm": 0.0, "readout_s": 0.025, "readout_std_s": 0.001}
    rolling = batch.summary_row("a.mcap", None, {"cameras": [cam], "residual_px": 0.5,
                                                 "estimated": ["offset", "readout"]}, None)
    assert rolling["c2_readout_ms"] == 25.0 and rolling["c2_readout_std_ms"] == 1.0
    assert "c2_drift_ppm" not in rolling
    still = batch.summary_row("b.mcap", None, {"cameras": [cam], "residual_px": 0.5,
                                               "estimated": ["offset"]}, None)
    assert "c2_readout_ms" not in still and still["c2_offset_ms"] == 1.0


def test_a_folder_given_as_the_pattern_names_the_pattern_that_works(tmp_path):
    """A new user's 'pslog batch "my sessions" ...' (a folder, as other tools take): said
    'no session file matches', as if the folder held none. The message names the quoted
    pattern of its sessions, and that pattern, pasted into a shell, runs the batch."""
    folder = tmp_path / "my sessions"
    session(folder / "a.mcap")
    session(folder / "day 2" / "b.mcap")
    run = run_pslog("batch", folder, "--do", "fuse", "-o", tmp_path / "out")
    line = assert_one_line_error(run, 1, contains=("is a folder, not a session file",
                                                   "2 .mcap files"))
    suggested = line.split("the quoted pattern ", 1)[1].split(" (", 1)[0]
    # the pattern as bash reads it when pasted: one word, not expanded by the shell
    words = subprocess.run(["bash", "-c", f'printf "%s\\n" {suggested}'], capture_output=True,
                           text=True, check=True).stdout.splitlines()
    assert words == [f"{folder}/**/*.mcap"]
    jobs = find_sessions(words, tmp_path / "out")
    assert sorted(j.session for j in jobs) == ["a.mcap", "day 2/b.mcap"]
    # a folder holding no session says so too (not a pattern that would match nothing)
    (tmp_path / "empty").mkdir()
    run = run_pslog("batch", tmp_path / "empty", "--do", "fuse", "-o", tmp_path / "out2")
    assert_one_line_error(run, 1, contains=("is a folder", "0 .mcap files"))
