"""pslog batch (issue 14) on a real local Ray cluster and the real CLI: the summary equals
the commands run by hand on each session, a corrupted session fails with its one-line error
while the others finish, a worker process killed mid-task is retried with nothing lost, and
a batch killed halfway resumes without redoing what it completed.

One Ray cluster serves the in-process batches of this module (``pslog batch`` joins the
cluster its process already joined); the resume test runs ``pslog batch`` as a real process
(its own local cluster) so that it can be killed."""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from pslog.batch import KILL_ONCE_ENV, READY_NAME, TASK_LOCK_NAME, read_summary_csv
from pslog.cli import main

ray = pytest.importorskip("ray")

METHODS = ("--method", "typeA", "--method", "nearest")


def pslog(*argv) -> tuple[int, str, str]:
    """``pslog ARGV`` in-process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def simulate(path: Path, seed: int, duration: float = 1.5) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    code, _, err = pslog("simulate", "--rig", "paper3", "--timing", "typeB", "--motion", "rally",
                         "--duration", duration, "--noise-px", "0.3", "--clock-offset",
                         f"cam2={seed}", "--seed", seed, "-o", path)
    assert code == 0, err
    return path


@pytest.fixture(scope="module")
def sessions(tmp_path_factory) -> Path:
    """matches/day1/{a,b}.mcap, matches/day2/c.mcap, matches/day2/real.mcap (c's
    detections without ground truth) and matches/day2/bad.mcap (cut short)."""
    root = tmp_path_factory.mktemp("batch") / "matches"
    simulate(root / "day1" / "a.mcap", 1)
    simulate(root / "day1" / "b.mcap", 2)
    c = simulate(root / "day2" / "c.mcap", 3)
    # a "real" session: the detections alone, no ground truth (export, then import)
    code, rig_toml, err = pslog("rig", "show", c)
    assert code == 0, err
    (root.parent / "rig.toml").write_text(rig_toml)
    code, _, err = pslog("export", c, "--detections", root.parent / "det.csv")
    assert code == 0, err
    code, _, err = pslog("import", "--rig", root.parent / "rig.toml", "--detections",
                         root.parent / "det.csv", "-o", root / "day2" / "real.mcap")
    assert code == 0, err
    bad = root / "day2" / "bad.mcap"
    bad.write_bytes(c.read_bytes()[:4000])
    hour_ago = time.time() - 3600  # not a recording still being written: a cut one
    os.utime(bad, (hour_ago, hour_ago))
    return root


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A local Ray cluster of 2 CPUs for the module. Its workers inherit the kill hook
    (:data:`pslog.batch.KILL_ONCE_ENV`) disarmed: the hook's file exists; a test removes
    it to have the next task kill its own worker once."""
    import logging

    folder = tmp_path_factory.mktemp("ray")
    marker = folder / "killed"
    marker.touch()
    old = os.environ.get(KILL_ONCE_ENV)
    os.environ[KILL_ONCE_ENV] = str(marker)
    temp = f"/tmp/pslog-ray-test-{os.getpid()}"  # Ray's socket paths must stay short
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             logging_level=logging.ERROR, _temp_dir=temp)
    try:
        yield marker
    finally:
        ray.shutdown()
        if old is None:
            os.environ.pop(KILL_ONCE_ENV, None)
        else:
            os.environ[KILL_ONCE_ENV] = old
        import shutil

        shutil.rmtree(temp, ignore_errors=True)


def by_hand(session: Path, folder: Path) -> tuple[dict, str]:
    """The summary row of ``session`` built from the commands run by hand (info, sync,
    fuse, eval), as strings as in summary.csv, without the runtime; and the fused file."""
    folder.mkdir(parents=True)
    code, info, err = pslog("info", session, "--json")
    if code != 0:  # (info is the batch's own reading of the session: said as the batch's)
        return {"status": "failed", "error": err.strip().replace("pslog info: ", "pslog batch: ",
                                                                 1)}, ""
    info = json.loads(info)
    code, sync, err = pslog("sync", session, "-o", folder / "synced.mcap", "--json")
    assert code == 0, err
    code, _, err = pslog("fuse", folder / "synced.mcap", "-o", folder / "fused.mcap", *METHODS)
    assert code == 0, err
    code, evaluation, err = pslog("eval", folder / "fused.mcap", "--json")
    assert code == 0, err
    row = {"status": "ok", "error": "", "cameras": "cam1 cam2 cam3",
           "duration_s": repr(info["duration_s"]), "frames": str(info["frames"]),
           "detections": str(info["candidates"]), "truth": str(info["truth"])}
    sync = json.loads(sync)
    for cam in sync["cameras"]:
        row[f"{cam['name']}_offset_ms"] = repr(cam["offset_s"] * 1e3)
        row[f"{cam['name']}_offset_std_ms"] = repr(cam["offset_std_s"] * 1e3)
    row["sync_residual_px"] = repr(sync["residual_px"])
    for m in json.loads(evaluation):
        row[f"{m['method']}_n_points"] = str(m["n_points"])
        row[f"{m['method']}_left_out"] = str(sum(m["left_out"].values()))
        row[f"{m['method']}_left_out_reasons"] = ", ".join(f"{r} {n}" for r, n
                                                           in m["left_out"].items())
        row[f"{m['method']}_rate_hz"] = repr(m["rate_hz"])
        for key in ("mean_mm", "median_mm", "p95_mm", "max_mm", "rms_mm"):
            # errors against ground truth, where there is one
            row[f"{m['method']}_{key}"] = repr(m[key]) if info["truth"] else ""
    return row, str(folder / "fused.mcap")


def same_tracks(a: str, b: str) -> None:
    from pslog.log import read_session

    sa, sb = read_session(a), read_session(b)
    assert list(sa.tracks) == list(sb.tracks)
    for m in sa.tracks:
        np.testing.assert_array_equal(sa.tracks[m].time_ns, sb.tracks[m].time_ns)
        np.testing.assert_array_equal(sa.tracks[m].position_world, sb.tracks[m].position_world)
    assert [c.clock_offset for c in sa.rig.cameras] == [c.clock_offset for c in sb.rig.cameras]


def _in_session(sid: int) -> list[int]:
    """The processes of session ``sid`` (a ``start_new_session`` process and every process
    below it, also those in process groups of their own: Ray puts each worker in one)."""
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError):
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                if int(fields[3]) == sid and fields[0] != "Z":
                    found.append(int(entry.name))
    return found


def _wait_until_gone(pgid: int, deadline: float, message: str) -> None:
    """Poll process group ``pgid`` until none of it is left; fail with ``message`` once
    ``time.monotonic()`` passes ``deadline``."""
    while True:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return
        assert time.monotonic() < deadline, message
        time.sleep(0.05)


def test_summary_equals_the_commands_by_hand_and_the_bad_session_fails(cluster, sessions,
                                                                      tmp_path):
    out = tmp_path / "results"
    code, _, err = pslog("batch", f"{sessions}/**/*.mcap", "--do", "sync,fuse,eval",
                              *METHODS, "-o", out)
    assert code == 1  # one session failed
    assert "1 of 5 sessions failed (first: day2/bad.mcap: pslog batch: error:" in err
    assert "Traceback" not in err
    rows = {r["session"]: r for r in read_summary_csv(out / "summary.csv")}
    assert list(rows) == ["day1/a.mcap", "day1/b.mcap", "day2/bad.mcap", "day2/c.mcap",
                          "day2/real.mcap"]
    assert rows["day2/real.mcap"]["truth"] == "False"
    assert rows["day2/real.mcap"]["typeA_mean_mm"] == ""
    assert float(rows["day2/real.mcap"]["typeA_rate_hz"]) > 80
    for name, row in rows.items():
        want, fused = by_hand(sessions / name, tmp_path / "hand" / name)
        got = {k: v for k, v in row.items() if v != "" or k in want}
        assert float(got.pop("runtime_s")) > 0
        got.pop("session")
        assert got == want, name
        if want["status"] == "ok":
            folder = out / name.removesuffix(".mcap")
            same_tracks(fused, str(folder / "fused.mcap"))
            code, evaluation, _ = pslog("eval", fused, "--json")
            assert json.loads((folder / "eval.json").read_text()) == json.loads(evaluation)
            assert json.loads((folder / "done.json").read_text())["row"]["status"] == "ok"
    bad = rows["day2/bad.mcap"]
    assert "did not finish" in bad["error"] and "\n" not in bad["error"]
    assert not (out / "day2" / "bad").exists()  # nothing half-made for the failed one
    # the Parquet table holds the same rows
    import pyarrow.parquet as pq

    table = pq.read_table(out / "summary.parquet").to_pylist()
    assert [r["session"] for r in table] == list(rows)
    for r in table:
        for key, value in r.items():
            text = rows[r["session"]][key]
            if isinstance(value, float):
                assert value == float(text) or (math.isnan(value) and text == "")
            elif value is None:
                assert text == ""
            else:
                assert str(value) == text
    # a second batch without --force or --resume refuses to replace anything
    code, _, err = pslog("batch", f"{sessions}/**/*.mcap", "--do", "sync,fuse,eval",
                         *METHODS, "-o", out)
    assert code == 1 and "exists" in err and "--force" in err


def test_a_worker_killed_mid_task_is_retried_and_nothing_is_lost(cluster, sessions, tmp_path):
    cluster.unlink()  # arm the hook: the next task kills its own worker after its sync
    out = tmp_path / "results"
    code, _, err = pslog("batch", f"{sessions}/day1/*.mcap", "--do", "sync,fuse,eval",
                         *METHODS, "-o", out)
    assert cluster.exists(), "no worker was killed"
    assert code == 0, err
    rows = read_summary_csv(out / "summary.csv")
    assert [(r["session"], r["status"]) for r in rows] == [("a.mcap", "ok"), ("b.mcap", "ok")]
    for name in ("a", "b"):
        want, fused = by_hand(sessions / "day1" / f"{name}.mcap", tmp_path / "hand" / name)
        row = next(r for r in rows if r["session"] == f"{name}.mcap")
        assert {k: row[k] for k in want} == want
        same_tracks(fused, str(out / name / "fused.mcap"))
        assert sorted(p.name for p in (out / name).iterdir()) == [
            "done.json", "eval.json", "fused.mcap", "synced.mcap"]  # no .partial left


def _first_batch(tmp_path: Path, sessions, do: str):
    """``sessions`` ((seed, duration) each) simulated as ``season/m<i>.mcap`` and batched
    once with ``--do DO`` and the module's methods into ``results`` (on the module's
    cluster), which must succeed: (season folder, results folder, the batch's steps)."""
    root = tmp_path / "season"
    for i, (seed, duration) in enumerate(sessions):
        simulate(root / f"m{i}.mcap", seed, duration=duration)
    out = tmp_path / "results"
    steps = ["--do", do, *METHODS, "-o", out]
    code, _, err = pslog("batch", root / "*.mcap", *steps)
    assert code == 0, err
    return root, out, steps


def _stamps(folder: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(folder)): (p.stat().st_mtime_ns, p.stat().st_ino)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _output_stamps(folder: Path) -> dict[str, tuple[int, int]]:
    """:func:`_stamps` of a session's outputs, without a ready folder left by a kill during
    its install (the resume's settle removes it) nor the task's lock left by a kill between
    its done.json and the lock's removal (the resume takes and removes it: not an output)."""
    return {name: stamp for name, stamp in _stamps(folder).items()
            if not name.startswith(READY_NAME + "/") and name != TASK_LOCK_NAME}


@pytest.fixture
def short_tmpdir():
    """TMPDIR for a ``pslog batch`` process: its killed local cluster's folder goes there
    (and is removed); short, for Ray's socket paths."""
    import shutil
    import tempfile

    folder = tempfile.mkdtemp(prefix="pslog-t")
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _holding(folder: str) -> set[int]:
    """The processes holding a file below ``folder`` open (/proc), this one left out."""
    found = set()
    for pid in (int(p) for p in os.listdir("/proc") if p.isdigit() and int(p) != os.getpid()):
        with contextlib.suppress(OSError):
            for fd in os.listdir(f"/proc/{pid}/fd"):
                if os.readlink(f"/proc/{pid}/fd/{fd}").startswith(folder + os.sep):
                    found.add(pid)
                    break
    return found


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="needs /proc")
def test_a_killed_batch_leaves_no_ray_process_and_no_folder(tmp_path, short_tmpdir):
    """SIGKILL to ``pslog batch`` while its local cluster runs: Ray's GCS server and raylet
    die with it, but its DashboardAgent and RuntimeEnvAgent lived on, orphaned, 80 MB each,
    for a minute or more, and the cluster's folder stayed (session 38's sweep and CI runs).
    The batch's watchdog ends every process still holding a file in that folder and removes
    it, at once."""
    root = tmp_path / "season"
    for i in range(3):
        simulate(root / f"k{i}.mcap", 40 + i, duration=1.0)
    argv = [sys.executable, "-m", "pslog.cli", "batch", str(root / "*.mcap"), "--do",
            "sync,fuse,eval", *METHODS, "-o", str(tmp_path / "results"), "--workers", "1"]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env={**os.environ, "TMPDIR": short_tmpdir})
    deadline = time.monotonic() + 120  # a hang guard only
    folder, agents = None, set()
    while not agents:  # the cluster up: its agents running, with files in its folder
        assert proc.poll() is None, "the batch ended before its cluster was seen"
        assert time.monotonic() < deadline, "no Ray agent seen"
        time.sleep(0.1)
        folders = [os.path.join(short_tmpdir, f) for f in os.listdir(short_tmpdir)
                   if f.startswith("pslog-ray-")]
        if folders:
            folder = os.path.realpath(folders[0])
            agents = {pid for pid in _holding(folder) if b"Agent" in Path(
                f"/proc/{pid}/cmdline").read_bytes()}
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 30  # (the watchdog takes well under a second; unwatched,
    while (left := _holding(folder)) or os.path.exists(folder):  # the agents live 1-2 min)
        assert time.monotonic() < deadline, (
            f"left after the kill: {sorted(left)}, folder {os.path.exists(folder)}")
        time.sleep(0.1)
    assert not any(os.path.exists(f"/proc/{pid}") and b"Agent" in Path(
        f"/proc/{pid}/cmdline").read_bytes() for pid in agents)


def test_resume_after_a_batch_killed_halfway(tmp_path, short_tmpdir):
    root = tmp_path / "season"
    for i in range(6):
        simulate(root / f"m{i}.mcap", 10 + i, duration=1.0)
    out = tmp_path / "results"
    argv = [sys.executable, "-m", "pslog.cli", "batch", str(root / "*.mcap"), "--do",
            "sync,fuse,eval", *METHODS, "-o", str(out), "--workers", "1"]
    # its own process group: the Ray processes it starts are found (and ended) by it below
    env = {**os.environ, "TMPDIR": short_tmpdir}
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, env=env)
    deadline = time.monotonic() + 240  # a hang guard only
    while len(list(out.glob("*/done.json"))) < 2:
        assert proc.poll() is None, proc.stderr.read().decode()
        assert time.monotonic() < deadline, "the batch made no progress"
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    proc.stderr.close()
    # the local cluster's processes notice their driver's death only within a minute or so
    # (a worker may even finish its session first): end them now, all at once, as a machine
    # that loses power would, and wait until none is left. Every one of the batch's session:
    # Ray puts each worker in a process group of its own (a killpg of the batch's group
    # left the workers running, one finishing its session while the resume planned)
    while members := _in_session(proc.pid):
        for pid in members:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        assert time.monotonic() < deadline, "the killed batch's processes do not end"
        time.sleep(0.05)
    # complete: its done.json in place, or its new set committed before the kill (renamed to
    # the ready folder, done.json inside; the resume's settle moves it into place: a kill
    # between the two made the resume find one more complete session than done.json files)
    in_place = sorted(p.parent.name for p in out.glob("*/done.json"))
    committed = sorted(p.parent.parent.name for p in out.glob(f"*/{READY_NAME}/done.json"))
    complete = sorted({*in_place, *committed})
    assert 2 <= len(complete) < 6, "the batch was not killed halfway"
    assert not (out / "summary.csv").exists()
    before = {name: _output_stamps(out / name) for name in in_place}
    run = subprocess.run([*argv, "--resume"], capture_output=True, text=True, timeout=240,
                         env=env)
    assert run.returncode == 0, run.stderr
    assert f"{len(complete)} of 6 sessions already complete (--resume)" in run.stderr
    assert "Traceback" not in run.stderr
    for name in in_place:  # nothing redone that was complete
        assert _output_stamps(out / name) == before[name], name
    rows = read_summary_csv(out / "summary.csv")
    assert [(r["session"], r["status"]) for r in rows] == [(f"m{i}.mcap", "ok")
                                                            for i in range(6)]
    for i in range(6):
        assert sorted(p.name for p in (out / f"m{i}").iterdir()) == [
            "done.json", "eval.json", "fused.mcap", "synced.mcap"]
    # a finished batch resumed again does nothing but rewrite its summary
    again = subprocess.run([*argv, "--resume"], capture_output=True, text=True, timeout=240,
                           env=env)
    assert again.returncode == 0, again.stderr
    assert "6 of 6 sessions already complete" in again.stderr
    assert read_summary_csv(out / "summary.csv") == rows


def test_redetect_and_view_steps_on_a_recorded_session(cluster, tmp_path):
    """--do redetect,fuse,eval,view on the sample recording (it has its frames): each step's
    output is there and the re-detection equals ``pslog redetect`` by hand."""
    import shutil

    sample = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"
    (tmp_path / "rec").mkdir()
    shutil.copyfile(sample, tmp_path / "rec" / "throw.mcap")
    out = tmp_path / "results"
    code, _, err = pslog("batch", tmp_path / "rec" / "throw.mcap", "--do", "view,redetect,fuse",
                         "--method", "typeA", "--frames", "none", "-o", out)
    assert code == 0, err
    folder = out / "throw"
    assert sorted(p.name for p in folder.iterdir()) == [
        "done.json", "fused.mcap", "redetected.mcap", "view.rrd"]
    assert (folder / "view.rrd").stat().st_size > 0
    code, _, err = pslog("redetect", tmp_path / "rec" / "throw.mcap", "-o",
                         tmp_path / "hand.mcap", "--workers", "1")
    assert code == 0, err
    from pslog.log import read_session

    hand, batch = read_session(tmp_path / "hand.mcap"), read_session(folder / "redetected.mcap")
    np.testing.assert_array_equal(hand.detections.cand_uv, batch.detections.cand_uv)
    assert list(read_session(folder / "fused.mcap").tracks) == ["typeA"]
    row = read_summary_csv(out / "summary.csv")[0]
    # no eval asked: no eval.json, but the summary has the points all the same
    assert row["status"] == "ok" and int(row["typeA_n_points"]) > 0


def _reasons(text: str) -> dict[str, int]:
    """``"kink 4, unconfirmed 2"`` as ``{"kink": 4, "unconfirmed": 2}`` (``""``: none)."""
    return {r: int(n) for r, n in (part.rsplit(" ", 1) for part in text.split(", ") if part)}


def _fuse_left_out(line: str) -> dict[str, int]:
    """From one method's line of ``pslog fuse``'s output, the points it left out by
    reason."""
    _, _, why = line.partition("(left out, untrustworthy: ")
    return _reasons(why.split(")")[0])


def test_the_summary_counts_each_methods_left_out_points_as_fuse_does(tmp_path,
                                                                      short_tmpdir):
    """``pslog batch`` as a process (its own local Ray cluster) over three dirty sessions
    (false candidates, kicks: type A and the filter leave points out): each method's
    ``_left_out`` and ``_left_out_reasons`` columns are what ``pslog fuse``, run by hand as
    a process on the same session, prints."""
    root = tmp_path / "season"
    root.mkdir()
    for i, seed in enumerate((21, 22, 23)):
        code, _, err = pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion",
                             "rally", "--duration", "1.2", "--noise-px", "0.3", "--spurious",
                             "0.1", "--seed", seed, "-o", root / f"m{i}.mcap")
        assert code == 0, err
    methods = ["--method", "typeA", "--method", "filter"]
    out = tmp_path / "results"
    env = {**os.environ, "TMPDIR": short_tmpdir}
    done = subprocess.run([sys.executable, "-m", "pslog.cli", "batch", str(root / "*.mcap"),
                           "--do", "fuse", *methods, "-o", str(out), "--workers", "2"],
                          capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    rows = {r["session"]: r for r in read_summary_csv(out / "summary.csv")}
    assert list(rows) == ["m0.mcap", "m1.mcap", "m2.mcap"]
    header = list(rows["m0.mcap"])
    # beside each method's points, in the order of the columns
    assert header.index("typeA_left_out") == header.index("typeA_n_points") + 1
    assert header.index("typeA_left_out_reasons") == header.index("typeA_left_out") + 1
    total = 0
    for name, row in rows.items():
        fused = subprocess.run([sys.executable, "-m", "pslog.cli", "fuse", str(root / name),
                                "-o", str(tmp_path / f"hand-{name}"), *methods],
                               capture_output=True, text=True, timeout=300)
        assert fused.returncode == 0, fused.stderr
        lines = {line.split()[0]: line for line in fused.stdout.splitlines()}
        for method in ("typeA", "filter"):
            why = _fuse_left_out(lines[method])
            assert row[f"{method}_left_out"] == str(sum(why.values())), (name, lines[method])
            assert _reasons(row[f"{method}_left_out_reasons"]) == why, (name, lines[method])
            total += sum(why.values())
    assert total > 0  # (the sessions do leave points out: the columns are not all 0)
    import pyarrow.parquet as pq

    table = {r["session"]: r for r in pq.read_table(out / "summary.parquet").to_pylist()}
    assert table["m0.mcap"]["typeA_left_out"] == int(rows["m0.mcap"]["typeA_left_out"])


def test_ray_is_imported_by_a_running_batch_alone():
    """``pslog --help``, ``pslog batch --help`` and a batch refused before it starts never
    load Ray (seconds of imports)."""
    code = ("import sys, contextlib, io\n"
            "from pslog.cli import main\n"
            "for argv in (['--help'], ['batch', '--help'], ['batch', 'nothing/*.mcap',"
            " '--do', 'fuse', '-o', 'out']):\n"
            "    with contextlib.redirect_stdout(io.StringIO()), "
            "contextlib.redirect_stderr(io.StringIO()):\n"
            "        try:\n"
            "            main(argv)\n"
            "        except SystemExit:\n"
            "            pass\n"
            "print('ray' in sys.modules)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert run.stdout.strip() == "False", run.stderr


@pytest.mark.parametrize(("sig", "exit_code", "said"), [
    (signal.SIGINT, 130, "pslog batch: interrupted"),
    (signal.SIGTERM, 143, "pslog batch: terminated (SIGTERM)")])
def test_a_forced_batch_interrupted_keeps_every_old_output(cluster, tmp_path, short_tmpdir,
                                                           sig, exit_code, said):
    """``--force`` then Ctrl-C or SIGTERM: the new outputs are made aside and replace the
    old ones only when complete, in one step, so every old output stays as it was (or, for
    a session whose install was committed, the new complete set replaced it), the summary
    too, and nothing half-made is left (a sweep found all of them deleted at each task's
    start). The exit code and line say which signal (a SIGTERM was "interrupted",
    exit 130); after Ctrl-C the batch's local cluster is shut down (no process of its group
    is left)."""
    root, out, steps = _first_batch(tmp_path, [(20, 1.5), (21, 1.5)], "sync,fuse,eval")
    before = _stamps(out)
    summary = (out / "summary.csv").read_bytes()
    argv = [sys.executable, "-m", "pslog.cli", "batch", str(root / "*.mcap"),
            *map(str, steps), "--workers", "2", "--force"]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True,
                            env={**os.environ, "TMPDIR": short_tmpdir})
    deadline = time.monotonic() + 240  # a hang guard only
    sessions = {name: _stamps(out / name) for name in ("m0", "m1")}
    # a task has started on a session: something new, changed or gone in its result folder
    while all(_stamps(out / name) == sessions[name]
              and {p.name for p in (out / name).iterdir()} == set(sessions[name])
              for name in sessions):
        assert proc.poll() is None, proc.stderr.read().decode()
        assert time.monotonic() < deadline, "the batch started no task"
        time.sleep(0.01)
    proc.send_signal(sig)
    try:
        assert proc.wait(timeout=120) == exit_code
        err = proc.stderr.read().decode()
        assert [line for line in err.splitlines() if line.strip()][-1] == said, err
        gone_by = time.monotonic() + 30  # Ray's processes end with it, not a minute later
        # (after a SIGTERM Ray's agents sometimes outlive its shutdown: docs/batch.md)
        if sig == signal.SIGINT:
            _wait_until_gone(proc.pid, gone_by, "the batch left processes running")
    finally:
        proc.stderr.close()
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
    # each session: its old files, not rewritten; or, if its task had committed its install
    # when the interrupt came, the new complete set with its new done.json (never a mix)
    for name in ("m0", "m1"):
        now = _stamps(out / name)
        if now != sessions[name]:
            assert sorted(now) == ["done.json", "eval.json", "fused.mcap", "synced.mcap"], now
            assert all(now[f] != sessions[name][f] for f in now), (name, now)
            marker = json.loads((out / name / "done.json").read_text())
            assert marker["row"]["status"] == "ok" and marker["session"] == f"{name}.mcap"
    assert sorted(p.name for p in out.iterdir()) == ["m0", "m1", "summary.csv",
                                                     "summary.parquet"]
    assert _stamps(out)["summary.parquet"] == before["summary.parquet"]
    assert (out / "summary.csv").read_bytes() == summary


def test_a_failed_session_of_a_batch_then_interrupted_keeps_its_old_outputs(
        cluster, tmp_path, short_tmpdir):
    """A ``--force`` batch in which one session fails (its input cut since the last batch)
    and which SIGTERM ends while another session still runs: the failed session keeps every
    old output. Its failed row removes them only once the batch has ended: an interrupted
    batch writes no summary, and the old one, which stays, names them. Before, the task
    removed them as soon as it failed — as it did when a step of a session ended in any
    error while the batch was being interrupted (a cancelled task's worker outlives the
    batch's settling of its folder): a result folder left empty, seen once in the suite."""
    # (m1 still running when m0 has failed)
    root, out, steps = _first_batch(tmp_path, [(30, 1.5), (31, 3.0)], "sync,fuse,eval")
    before = {name: _stamps(out / name) for name in ("m0", "m1")}
    summary = (out / "summary.csv").read_bytes()
    m0 = root / "m0.mcap"
    m0.write_bytes(m0.read_bytes()[:4000])  # cut: `pslog info` fails on it at once
    hour_ago = time.time() - 3600  # (a cut recording, not one still being written)
    os.utime(m0, (hour_ago, hour_ago))
    argv = [sys.executable, "-m", "pslog.cli", "batch", str(root / "*.mcap"),
            *map(str, steps), "--workers", "2", "--force"]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env={**os.environ, "TMPDIR": short_tmpdir})
    lines: list[str] = []

    def read() -> None:
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))

    import threading

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    deadline = time.monotonic() + 240  # a hang guard only
    try:
        while not any(line.startswith("failed m0.mcap") for line in lines):
            assert proc.poll() is None, f"{lines}\n{proc.stderr.read()}"
            assert time.monotonic() < deadline, "the batch did not fail m0"
            time.sleep(0.01)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=120) == 143, proc.stderr.read()
        reader.join(timeout=10)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.stdout.close()
        proc.stderr.close()
    assert not any("m1.mcap" in line for line in lines), lines  # m1 was still running
    assert _stamps(out / "m0") == before["m0"]  # every old output, untouched
    now = _stamps(out / "m1")  # m1: its old set, or the new complete one
    if now != before["m1"]:
        assert sorted(now) == ["done.json", "eval.json", "fused.mcap", "synced.mcap"], now
        assert all(now[f] != before["m1"][f] for f in now), now
    assert (out / "summary.csv").read_bytes() == summary


def test_a_batch_stopped_while_it_removes_failed_sessions_outputs_leaves_it_to_the_next(
        cluster, tmp_path, short_tmpdir):
    """Two sessions fail in a ``--force`` batch (their inputs cut since the last one); a
    Ctrl-C comes once the batch has removed the first one's old outputs (the test hook
    sends it): the batch ends (exit 130) with the list of the removals left in the results
    folder, the second failed session still holding its old outputs and ``done.json``
    (which ``--resume`` would take for complete). The next batch there finishes the
    removal before it plans, even one that runs only the good session."""
    from pslog.batch import DISCARD_NAME, INTERRUPT_DISCARD_ENV

    root, out, steps = _first_batch(tmp_path, [(40 + i, 1.5) for i in range(3)], "fuse")
    hour_ago = time.time() - 3600  # (cut recordings, not ones still being written)
    for name in ("m1", "m2"):
        path = root / f"{name}.mcap"
        path.write_bytes(path.read_bytes()[:4000])
        os.utime(path, (hour_ago, hour_ago))
    argv = [sys.executable, "-m", "pslog.cli", "batch", str(root / "*.mcap"),
            *map(str, steps), "--workers", "2", "--force"]
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True, start_new_session=True,
                            env={**os.environ, "TMPDIR": short_tmpdir,
                                 INTERRUPT_DISCARD_ENV: "1"})
    try:
        assert proc.wait(timeout=240) == 130, proc.stderr.read()
        err = proc.stderr.read()
        assert [line for line in err.splitlines() if line.strip()][-1] == (
            "pslog batch: interrupted"), err
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.stderr.close()
    assert (out / DISCARD_NAME).is_file()
    left = [name for name in ("m1", "m2") if (out / name).exists()]
    assert len(left) == 1, left  # one removed (its folder too), the other not yet
    assert sorted(_stamps(out / left[0])) == ["done.json", "fused.mcap"]
    good = _stamps(out / "m0")  # (made again by the forced batch)
    # the next batch, of the good session alone, complete: skipped (--resume)
    code, _, err = pslog("batch", root / "m0.mcap", *steps, "--resume")
    assert code == 0, err
    assert not (out / left[0]).exists()  # the removal finished
    assert not (out / DISCARD_NAME).exists()
    assert _stamps(out / "m0") == good
