"""``pslog batch --address`` on a real Ray cluster: one started here with ``ray start --head``
(the venv's own ``ray``; token authentication with a token of this test's, so nothing else
on the machine can join it and nothing in ``~/.ray`` is used), the batch run as a real
process against it, its summary compared with the commands run by hand on each session.
The cluster is stopped by SIGTERM to its ``ray start --block`` process, which shuts down the
processes it started (never ``ray stop``, which would stop every Ray cluster of this user on
the machine)."""

from __future__ import annotations

import contextlib
import io
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from _live import free_port

from pslog.batch import read_summary_csv, summary_row
from pslog.cli import main
from tests.faults.promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog

ray = pytest.importorskip("ray")


def pslog(*argv) -> str:
    """``pslog ARGV`` in-process; its standard output."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main([str(a) for a in argv]) == 0
    return out.getvalue()


@pytest.fixture(scope="module")
def cluster():
    """A 2-CPU Ray cluster on 127.0.0.1: (address, environment holding its token)."""
    ray_cli = Path(sys.executable).with_name("ray")
    if not ray_cli.exists():
        pytest.skip(f"no ray executable beside {sys.executable}")
    port = free_port()
    env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(32),
           "PSLOG_PROGRESS": "off"}
    temp = tempfile.mkdtemp(prefix="pslog-rt-")  # short: Ray's socket paths fit 107 bytes
    log = open(Path(temp) / "ray-start.log", "wb")
    head = subprocess.Popen(
        [str(ray_cli), "start", "--head", "--block", "--port", str(port),
         "--node-ip-address", "127.0.0.1", "--num-cpus", "2", "--temp-dir", temp,
         "--include-dashboard=false", "--disable-usage-stats"],
        stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
    try:
        deadline = time.monotonic() + 120  # hang guard: a loaded machine starts slowly
        while True:
            assert head.poll() is None, (Path(temp) / "ray-start.log").read_text()[-2000:]
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port),
                                                                        timeout=1):
                break
            assert time.monotonic() < deadline, "ray start --head did not listen in 120 s"
            time.sleep(0.5)
        yield f"127.0.0.1:{port}", env, Path(temp)
    finally:
        head.send_signal(signal.SIGTERM)  # ray start --block shuts its processes down
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)
            head.wait()
        log.close()
        shutil.rmtree(temp, ignore_errors=True)


def as_csv(row: dict) -> dict:
    """A summary row as summary.csv holds it, without the runtime."""
    def text(v):
        if v is None or (isinstance(v, float) and v != v):
            return ""
        return repr(v) if isinstance(v, float) else str(v)
    return {k: text(v) for k, v in row.items() if k != "runtime_s"}


def test_a_batch_on_a_cluster_equals_the_commands_by_hand(tmp_path, cluster):
    address, env, temp = cluster
    season = tmp_path / "season"
    season.mkdir()
    want = []
    for seed in (1, 2):
        session = season / f"s{seed}.mcap"
        pslog("simulate", "--rig", "paper3", "--timing", "typeB", "--motion", "rally",
              "--duration", "1.5", "--noise-px", "0.3", "--clock-offset", f"cam2={seed}",
              "--seed", seed, "-o", session)
        info = json.loads(pslog("info", session, "--json"))
        sync = json.loads(pslog("sync", session, "-o", tmp_path / f"y{seed}.mcap", "--json"))
        pslog("fuse", tmp_path / f"y{seed}.mcap", "-o", tmp_path / f"f{seed}.mcap",
              "--method", "typeA")
        evaluation = json.loads(pslog("eval", tmp_path / f"f{seed}.mcap", "--json"))
        want.append(as_csv(summary_row(session.name, info, sync, evaluation)))
    out = tmp_path / "results"
    run = subprocess.run([sys.executable, "-m", "pslog.cli", "batch", f"{season}/*.mcap",
                          "--do", "sync,fuse,eval", "--method", "typeA", "-o", str(out),
                          "--address", address], capture_output=True, text=True, env=env,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    rows = read_summary_csv(out / "summary.csv")
    assert [{k: v for k, v in r.items() if k != "runtime_s"} for r in rows] == want
    assert all(r["status"] == "ok" for r in rows)
    # the batch was this cluster's driver (not a local cluster of its own): its log is there
    drivers = list(temp.glob("session_*/logs/python-core-driver-*"))
    assert drivers, sorted(p.name for p in temp.glob("session_*/logs/*"))
    for seed in (1, 2):  # the outputs were written by path, by the cluster's workers
        assert (out / f"s{seed}" / "synced.mcap").is_file()
        assert (out / f"s{seed}" / "done.json").is_file()


def test_a_cluster_that_refuses_the_token(tmp_path, cluster):
    """Ray's core prints a warning a second while it retries (~20 s), then a paragraph: one
    line instead, naming the cause."""
    address, _, _ = cluster
    session = tmp_path / "s.mcap"
    pslog("simulate", "--rig", "paper3", "--duration", "1", "-o", session)
    before = fingerprint(tmp_path)
    run = run_pslog("batch", session, "--do", "fuse", "-o", tmp_path / "out", "--address",
                    address, env={"RAY_AUTH_MODE": "token",
                                  "RAY_AUTH_TOKEN": secrets.token_hex(32)},
                    timeout=120)
    assert_one_line_error(run, 1, contains=(f"the Ray cluster at {address}",
                                            "token authentication", "RAY_AUTH_TOKEN"))
    assert_untouched(before, tmp_path)
    assert not (tmp_path / "out").exists()
