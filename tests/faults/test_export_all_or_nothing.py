"""``pslog export`` with several outputs replaces all of them or none (hostile sweep of
session 13): a full disk, a file-size limit, a signal between two outputs and a C3D the
session cannot give each leave every old output as it was and no partial file; a complete
run replaces them all. Real CLI processes, real OS faults, real signals."""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest

from pslog.cli import main
from pslog.rig import builtin_rig

from ._mounts import fill, small_tmpfs
from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def fused(tmp_path_factory) -> Path:
    """A fused simulated session (two methods and the truth: three TUM files)."""
    folder = tmp_path_factory.mktemp("export")
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                 "--duration", "1.5", "-o", str(folder / "s.mcap")]) == 0
    assert main(["fuse", str(folder / "s.mcap"), "--method", "typeA", "--method", "nearest",
                 "-o", str(folder / "f.mcap")]) == 0
    return folder / "f.mcap"


def _old_tum(folder: Path) -> Path:
    tum = folder / "tum"
    tum.mkdir()
    for name in ("nearest", "typeA", "truth"):
        (tum / f"{name}.tum").write_text(f"old {name}\n")
    return tum


def _ceil_page(n: int) -> int:
    return -(-n // 4096) * 4096


def test_tum_on_a_full_disk_keeps_every_old_file(fused, tmp_path):
    """Room for the first new TUM file and a page, not for the second (even with the page
    of the first's old file freed): before, the first was replaced and the others kept (a
    mix of new and old trajectories)."""
    scratch = tmp_path / "scratch"
    assert main(["export", str(fused), "--tum", str(scratch)]) == 0
    first = _ceil_page((scratch / "nearest.tum").stat().st_size)
    assert (scratch / "typeA.tum").stat().st_size > 2 * 4096
    with small_tmpfs(tmp_path / "full", "256k") as disk:
        tum = _old_tum(disk)
        fill(disk, first + 4096)  # the first file fits; the second no longer does
        before = fingerprint(tum)
        run = run_pslog("export", fused, "--tum", tum, "--force")
        assert_one_line_error(run, 1, contains="No space left on device")
        assert_untouched(before, tum)


def test_a_file_size_limit_on_the_last_output_keeps_the_earlier_ones(fused, tmp_path):
    """The TUM files fit under the limit, the JSON lines do not."""
    scratch = tmp_path / "scratch"
    scratch.mkdir()
    assert main(["export", str(fused), "--tum", str(scratch / "tum"),
                 "--jsonl", str(scratch / "t.jsonl")]) == 0
    limit = max(p.stat().st_size for p in (scratch / "tum").iterdir()) + 1024
    assert (scratch / "t.jsonl").stat().st_size > limit
    out = tmp_path / "out"
    out.mkdir()
    tum = _old_tum(out)
    (out / "t.jsonl").write_text("old\n")
    before = fingerprint(out)

    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    run = run_pslog("export", fused, "--tum", tum, "--jsonl", out / "t.jsonl", "--force",
                    preexec_fn=limited)
    assert_one_line_error(run, 1, contains="File too large")
    assert_untouched(before, out)


#: ``pslog export`` in a child that signals itself once its Parquet file is written (the
#: fourth of five outputs): a Ctrl-C or SIGTERM at that moment, every time
SIGNAL_AFTER_PARQUET = """\
import os, signal, sys
import pslog.interchange.track_formats as formats
real = formats.write_parquet
def write_parquet(*args, **kwargs):
    n = real(*args, **kwargs)
    os.kill(os.getpid(), getattr(signal, sys.argv[1]))
    return n
formats.write_parquet = write_parquet
from pslog.cli import main
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.parametrize(("sig", "code", "said"), [("SIGINT", 130, "interrupted"),
                                                   ("SIGTERM", 143, "terminated (SIGTERM)")])
def test_a_signal_between_outputs_keeps_every_old_one(fused, tmp_path, sig, code, said):
    out = tmp_path / "out"
    out.mkdir()
    tum = _old_tum(out)
    names = ("t.csv", "t.jsonl", "t.parquet", "t.c3d")
    for name in names:
        (out / name).write_text("old\n")
    before = fingerprint(out)
    argv = ["export", str(fused), "--csv", str(out / "t.csv"), "--tum", str(tum), "--jsonl",
            str(out / "t.jsonl"), "--parquet", str(out / "t.parquet"), "--c3d",
            str(out / "t.c3d"), "--force"]
    run = subprocess.run([sys.executable, "-c", SIGNAL_AFTER_PARQUET, sig, *argv],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == code, run.stderr
    assert said in run.stderr and "Traceback" not in run.stderr
    assert_untouched(before, out)
    # the same export, not interrupted, replaces every one of them
    run = subprocess.run([sys.executable, "-m", "pslog.cli", *argv], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    after = fingerprint(out)
    assert sorted(after) == sorted(before)
    assert all(after[p] != before[p] for p in before)


def test_a_c3d_the_session_cannot_give_is_refused_before_anything_is_written(tmp_path):
    """One point (three cameras at one instant, the pixels of one 3D point: the N-view residual
    test keeps it): C3D has no frame rate to set. Before,
    the CSV and JSON lines were written first, then the export failed."""
    (tmp_path / "rig.toml").write_text(builtin_rig("paper3").to_toml(), encoding="utf-8")
    (tmp_path / "d.csv").write_text("camera,time,u,v\ncam1,0.5,395.63,339.29\n"
                                    "cam2,0.5,167.39,270.47\ncam3,0.5,276.71,178.81\n")
    assert main(["import", "--rig", str(tmp_path / "rig.toml"), "--detections",
                 str(tmp_path / "d.csv"), "-o", str(tmp_path / "d.mcap")]) == 0
    assert main(["fuse", str(tmp_path / "d.mcap"), "--method", "sync", "-o",
                 str(tmp_path / "f.mcap")]) == 0
    out = tmp_path / "out"
    out.mkdir()
    for name in ("t.csv", "t.jsonl"):
        (out / name).write_text("old\n")
    before = fingerprint(out)
    run = run_pslog("export", tmp_path / "f.mcap", "--csv", out / "t.csv", "--jsonl",
                    out / "t.jsonl", "--c3d", out / "t.c3d", "--force")
    assert_one_line_error(run, 1, contains="C3D needs a track of at least two points")
    assert_untouched(before, out)
    assert not os.path.exists(out / "t.c3d")
