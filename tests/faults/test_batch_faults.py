"""``pslog batch`` under faults (issue 14): every case asserts the three promises.

A pattern matching nothing, an unwritable or non-folder -o, a bad --do / --workers /
--estimate, --workers with --address, existing results without --force, and --resume over
results made with other steps. Each is found before any Ray cluster starts (fast)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from ._mounts import read_only
from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "throw.mcap"


@pytest.fixture
def season(tmp_path) -> Path:
    """season/day1/s.mcap, a copy of the sample session."""
    path = tmp_path / "season" / "day1" / "s.mcap"
    path.parent.mkdir(parents=True)
    shutil.copyfile(SAMPLE, path)
    return tmp_path / "season"


def test_a_pattern_that_matches_nothing(tmp_path, season):
    before = fingerprint(tmp_path)
    run = run_pslog("batch", f"{season}/**/*.mfap", "--do", "fuse", "-o", tmp_path / "out")
    assert_one_line_error(run, 1, contains="no session file matches")
    assert_untouched(before, tmp_path)


def test_an_unwritable_output_folder(tmp_path, season):
    with read_only(tmp_path / "ro") as folder:
        before = fingerprint(tmp_path)
        run = run_pslog("batch", f"{season}/**/*.mcap", "--do", "fuse", "-o", folder / "out")
        assert_one_line_error(run, 1, contains=(str(folder / "out"), "Read-only file system"))
        assert_untouched(before, tmp_path)


def test_an_output_that_is_a_file(tmp_path, season):
    out = tmp_path / "results"
    out.write_text("not a folder")
    before = fingerprint(tmp_path)
    run = run_pslog("batch", f"{season}/**/*.mcap", "--do", "fuse", "-o", out)
    assert_one_line_error(run, 1, contains=(str(out), "not a folder"))
    assert_untouched(before, tmp_path)


@pytest.mark.parametrize(("args", "contains"), [
    (["--do", "sync,fuze"], ("--do", "unknown: fuze")),
    (["--do", ","], "--do"),
    (["--do", "fuse", "--workers", "0"], ("--workers", "must be in 1..256")),
    (["--do", "fuse", "--workers", "two"], ("--workers", "not a whole number")),
    (["--do", "fuse", "--workers", "2", "--address", "auto"], "not allowed with argument"),
    (["--do", "sync", "--estimate", "offsett"], "--estimate"),
    (["--do", "fuse", "--method", "typeC"], "unknown fusion method"),
    (["--do", "view", "--frames", "every:0"], "--frames"),
    (["--do", "fuse", "--address", "head-node"], ("--address", "HOST:PORT")),
    (["--do", "fuse", "--address", "ray://head:99999"], ("--address", "HOST:PORT")),
], ids=["step", "no-step", "workers-0", "workers-text", "workers-and-address", "estimate",
        "method", "frames", "address-no-port", "address-bad-port"])
def test_a_malformed_command_line(tmp_path, season, args, contains):
    before = fingerprint(tmp_path)
    run = run_pslog("batch", f"{season}/**/*.mcap", *args, "-o", tmp_path / "out")
    assert_one_line_error(run, 2, contains=contains)
    assert_untouched(before, tmp_path)


def test_existing_results_are_not_replaced_without_force(tmp_path, season):
    out = tmp_path / "out"
    (out / "day1" / "s").mkdir(parents=True)
    (out / "day1" / "s" / "fused.mcap").write_bytes(b"an earlier result")
    before = fingerprint(tmp_path)
    run = run_pslog("batch", f"{season}/**/*.mcap", "--do", "fuse,eval", "-o", out)
    assert_one_line_error(run, 1, contains=(str(out / "day1" / "s" / "fused.mcap"), "exists",
                                            "--force"))
    assert_untouched(before, tmp_path)


def test_resume_over_results_of_other_steps_is_refused(tmp_path, season):
    out = tmp_path / "out"
    (out / "day1" / "s").mkdir(parents=True)
    (out / "day1" / "s" / "done.json").write_text(json.dumps(
        {"settings": "0123456789abcdef", "steps": ["fuse"], "row": {}}))
    before = fingerprint(tmp_path)
    run = run_pslog("batch", f"{season}/**/*.mcap", "--do", "sync,fuse", "-o", out, "--resume")
    assert_one_line_error(run, 1, contains=(str(out / "day1" / "s" / "done.json"),
                                            "other settings", "--force"))
    assert_untouched(before, tmp_path)


def test_a_cluster_that_does_not_answer(tmp_path, season):
    """Ray itself would retry for minutes, a warning every few seconds."""
    import socket

    with socket.socket() as sock:  # a port nobody listens on: bound, never listening
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
        before = fingerprint(tmp_path)
        run = run_pslog("batch", f"{season}/**/*.mcap", "--do", "fuse", "-o", tmp_path / "out",
                        "--address", f"127.0.0.1:{port}", timeout=30)
    assert_one_line_error(run, 1, contains=(f"cannot reach the Ray cluster at 127.0.0.1:{port}",
                                            "Connection refused"))
    assert_untouched(before, tmp_path)
    assert not (tmp_path / "out").exists()


def test_an_empty_output_folder_name(tmp_path, season):
    before = fingerprint(tmp_path)
    run = run_pslog("batch", f"{season}/**/*.mcap", "--do", "fuse", "-o", "", cwd=tmp_path)
    assert_one_line_error(run, 2, contains=("-o/--output", "empty folder name"))
    assert_untouched(before, tmp_path)


def test_ray_client_without_its_extra(tmp_path, season):
    """``ray://`` is Ray Client, which needs ``ray[client]`` (gRPC): said at once, in one
    line, before anything is looked at (Ray would say it after connecting, in a paragraph)."""
    import importlib.util

    if importlib.util.find_spec("grpc") is not None:
        pytest.skip("ray[client] is installed here")
    before = fingerprint(tmp_path)
    run = run_pslog("batch", f"{season}/**/*.mcap", "--do", "fuse", "-o", tmp_path / "out",
                    "--address", "ray://127.0.0.1:10001")
    assert_one_line_error(run, 1, contains=("--address ray://127.0.0.1:10001",
                                            "Ray Client is not installed", "ray[client]"))
    assert_untouched(before, tmp_path)
    assert not (tmp_path / "out").exists()


def test_a_summary_that_does_not_fit_leaves_the_old_pair(tmp_path):
    """The disk fills between the summary's two files (two 4 KiB pages left: the new CSV,
    one page, and its partial's owner file (pslog.outputs.claim_partial), one page, fit in
    place of the old; its Parquet, three pages of incompressible errors, does not): both
    old files stay as they were and no partial is left (before, the new CSV stood beside
    the last batch's Parquet); the fault is one error naming the file."""
    import random

    from pslog.batch import summary_row, write_summary
    from pslog.errors import PslogError

    from ._mounts import fill, small_tmpfs

    r = random.Random(3)

    def rows() -> list[dict]:
        return [summary_row(f"s{i}.mcap", None, None, None, error=r.randbytes(500).hex())
                for i in range(3)]

    with small_tmpfs(tmp_path / "disk", "128k") as disk:
        write_summary(rows(), disk)
        fill(disk, free=2 * 4096)
        before = fingerprint(disk)
        with pytest.raises(PslogError, match=r"summary\.parquet"):
            write_summary(rows(), disk)
        assert_untouched(before, disk)
