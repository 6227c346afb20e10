"""pslog batch installs a session's new outputs in one step. A Ctrl-C that reached a Ray task
in the middle of the old install (done.json removed, the new files renamed in one by one,
done.json written last) left a mix of old and new outputs and no done.json. Now, cut at any
step boundary, as a killed worker leaves it, the result folder holds the old outputs with
their done.json, untouched, and once settled (what the batch does after an interrupt, and
every later batch first) the old set or the new complete set with its new done.json; a
done.json never stands beside a mix.

The session runs in the test's process (no Ray cluster): the install is the same code as in
a Ray task."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import pslog.batch as batch
from pslog.batch import Job, Settings

pytest.importorskip("ray")

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"
#: the old run; the new one fuses another method set (fused.mcap, eval.json and done.json
#: differ) and leaves sync out (the old synced.mcap is stale: removed by the install)
OLD = Settings(steps=("sync", "fuse", "eval"), methods=("typeA",))
NEW = Settings(steps=("fuse", "eval"), methods=("typeA", "nearest"))
#: every step boundary of an install of NEW over OLD, in order
STEPS = ["staged", "committed", "moving", "old marker removed", "moved fused.mcap",
         "moved eval.json", "removed synced.mcap", "new marker"]
#: the result folder's files after NEW
NEW_FILES = ["done.json", "eval.json", "fused.mcap"]


def contents(folder: Path) -> dict[str, bytes | None]:
    """Every file (its bytes) and folder (None) below ``folder``, by relative path."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() if p.is_file() else None
            for p in sorted(folder.rglob("*"))}


class Cut(BaseException):
    """An interrupt at an install step (KeyboardInterrupt's kind: not an Exception)."""


@pytest.fixture(scope="module")
def made_with_old(tmp_path_factory) -> Job:
    """A session and its results made with OLD (once for the module)."""
    session = tmp_path_factory.mktemp("install") / "a.mcap"
    shutil.copyfile(SAMPLE, session)
    job = Job(str(session), "a.mcap", str(session.parent / "res" / "a"))
    assert batch.run_session(job, OLD)["status"] == "ok"
    return job


@pytest.fixture
def old_results(made_with_old, tmp_path) -> tuple[Job, dict]:
    """A copy of the OLD results for this test: its job and the result folder's contents."""
    job = Job(made_with_old.path, made_with_old.session, str(tmp_path / "res" / "a"))
    shutil.copytree(made_with_old.outdir, job.outdir)
    old = contents(Path(job.outdir))
    assert sorted(old) == ["done.json", "eval.json", "fused.mcap", "synced.mcap"]
    return job, old


def test_an_install_cut_at_any_step_leaves_the_old_set_or_the_new_one(old_results, tmp_path,
                                                                       monkeypatch):
    job, old = old_results
    outdir = Path(job.outdir)
    cuts: dict[str, Path] = {}  # step -> the result folder as a worker killed there leaves it

    def snapshot(step: str) -> None:
        cuts[step] = tmp_path / "cuts" / f"{len(cuts)}" / "a"
        shutil.copytree(outdir, cuts[step])

    monkeypatch.setattr(batch, "_install_step", snapshot)
    assert batch.run_session(job, NEW)["status"] == "ok"
    monkeypatch.setattr(batch, "_install_step", None)
    new = contents(outdir)
    assert sorted(new) == NEW_FILES
    assert all(new[name] != old[name] for name in NEW_FILES)
    assert list(cuts) == STEPS
    for i, (step, folder) in enumerate(cuts.items()):
        left = contents(folder)
        shown = {k: v for k, v in left.items() if not k.startswith(".pslog-batch-")}
        if "done.json" in shown:  # as left: a marker names its own complete set, old or new
            assert shown in (old, new), step
        if i <= STEPS.index("committed"):  # before the install changed any output
            assert shown == old, step
        # settled (as the batch after an interrupt, or the next batch, does: the lock
        # file the killed worker held removed too)
        batch.settle_held([Job(job.path, job.session, str(folder))], 0.0)
        assert contents(folder) == (old if step == "staged" else new), step


def test_an_install_interrupted_in_process_ends_with_the_whole_new_set(old_results,
                                                                      monkeypatch):
    """A Ctrl-C in the process that runs the session (a one-session batch runs in pslog's
    own process) between two moves: the interrupt goes on, and the task's end leaves the
    whole new set (its install was committed)."""
    job, old = old_results

    def interrupt(at: str) -> None:
        if at == "moved fused.mcap":
            raise Cut

    monkeypatch.setattr(batch, "_install_step", interrupt)
    with pytest.raises(Cut):
        batch.run_session(job, NEW)
    monkeypatch.setattr(batch, "_install_step", None)
    left = contents(Path(job.outdir))
    assert sorted(left) == NEW_FILES
    assert all(left[name] != old[name] for name in NEW_FILES)


@pytest.mark.parametrize("damage", ["empty marker", "marker a list", "unknown step",
                                    "stale not ours", "output missing"])
def test_a_damaged_ready_folder_is_discarded_and_the_old_set_kept(old_results, tmp_path,
                                                                  monkeypatch, damage):
    """A ready folder whose files did not all reach the disk (a power cut) or that a batch
    did not write: settled without a traceback, its move never begun — the old set and
    its done.json stay as they were (no done.json beside a mix)."""
    job, old = old_results
    outdir = Path(job.outdir)
    cut = tmp_path / "cut" / "a"

    def snapshot(step: str) -> None:
        if step == "committed":
            shutil.copytree(outdir, cut)

    monkeypatch.setattr(batch, "_install_step", snapshot)
    assert batch.run_session(job, NEW)["status"] == "ok"
    monkeypatch.setattr(batch, "_install_step", None)
    ready = cut / batch.READY_NAME
    changes = {"empty marker": ("done.json", ""), "marker a list": ("done.json", "[]"),
               "unknown step": ("done.json", '{"steps": ["fuse", "x"]}'),
               "stale not ours": ("stale.json", '["rig.toml"]')}
    if damage == "output missing":
        (ready / "eval.json").unlink()
    else:
        name, text = changes[damage]
        (ready / name).write_text(text)
    batch.settle_held([Job(job.path, job.session, str(cut))], 0.0)
    assert contents(cut) == old


def test_the_settle_after_an_interrupt_waits_for_a_task_still_installing(old_results,
                                                                        tmp_path, monkeypatch):
    """The batch settles each session's folder after an interrupt while a cancelled task's
    worker may still run (Ray ends it asynchronously), maybe in the middle of its install.
    Two installs of one folder at once: this process's settle, past its checks, removed
    the old done.json after the task had moved the new one in: a complete new set left
    without its marker (or, a step earlier, a mix). The task holds the folder while it
    runs (batch.session_lock) and the settle waits for it: one install, with its marker.
    The task runs in a child process (as a Ray worker does), held after its commit until
    this process's settle, past its checks, lets it go — or, with the settle waiting for
    the task's lock, after a second."""
    job, _old = old_results
    outdir = Path(job.outdir)
    held, go = tmp_path / "held", tmp_path / "go"
    code = (
        "import json, sys, time, pathlib\n"
        "import pslog.batch as batch\n"
        "from pslog.batch import Job, Settings\n"
        "held, go = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])\n"
        "def hold(step):\n"
        "    if step == 'committed':\n"
        "        held.touch()\n"
        "        while not go.exists():\n"
        "            time.sleep(0.01)\n"
        "batch._install_step = hold\n"
        "row, failed = batch.run_task(Job(*sys.argv[3:6]), Settings(**json.loads(sys.argv[6])))\n"
        "print(row['status'])\n")
    import json
    import subprocess
    import sys
    import threading
    import time
    from dataclasses import asdict

    child = subprocess.Popen([sys.executable, "-c", code, str(held), str(go), job.path,
                              job.session, job.outdir, json.dumps(asdict(NEW))],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while not held.exists():
            assert child.poll() is None, child.communicate()
            time.sleep(0.01)

        def moving(step: str) -> None:  # this process's settle, past its checks
            if step == "moving":
                go.touch()
                child.wait()

        monkeypatch.setattr(batch, "_install_step", moving)
        settle = threading.Thread(target=batch.settle_held, args=([job], 120.0))
        settle.start()
        settle.join(1.0)  # (not a time limit: lets a settle that does not wait get ahead)
        go.touch()
        out, err = child.communicate(timeout=120)
        settle.join(120)
        assert not settle.is_alive()
    finally:
        go.touch()
        child.kill()
        child.communicate()
    assert out.strip() == "ok", err
    assert sorted(contents(outdir)) == NEW_FILES
