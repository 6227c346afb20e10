"""Session 43: ``pslog export``'s outputs against each other (their order on the command line
changes nothing, none replaces another) and C3D of times on no common grid; through the real
CLI on real sessions."""

from __future__ import annotations

import subprocess
import sys

import pytest
from _cli import pslog_ok


@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fused")
    session, fused = folder / "s.mcap", folder / "f.mcap"
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.6",
             "--seed", "75030", "-o", session)
    pslog_ok("fuse", session, "--method", "typeA", "--method", "smooth", "-o", fused)
    return fused


def _export_in(folder, *args) -> subprocess.CompletedProcess:
    """``pslog export ARGS`` run in ``folder`` (relative outputs as a user types them)."""
    return subprocess.run([sys.executable, "-m", "pslog", "export", *map(str, args)],
                          cwd=folder, capture_output=True, text=True, timeout=600)


def _files(folder):
    return {str(p.relative_to(folder)): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_export_outputs_in_the_tum_folder_in_any_order(fused, tmp_path):
    """Outputs inside an existing ``--tum`` folder: the same files, the same bytes, whichever
    option comes first; the same file twice refused in either order, nothing written."""
    orders = {"tum first": ["--tum", "tum", "--csv", "tum/x.csv", "--detections", "tum/d.csv"],
              "tum last": ["--detections", "tum/d.csv", "--csv", "tum/x.csv", "--tum", "tum"]}
    results = {}
    for label, args in orders.items():
        (tmp_path / label / "tum").mkdir(parents=True)
        done = _export_in(tmp_path / label, fused, *args)
        assert done.returncode == 0, done.stderr
        results[label] = _files(tmp_path / label)
    assert results["tum first"] == results["tum last"]
    assert set(results["tum first"]) == {"tum/x.csv", "tum/d.csv", "tum/typeA.tum",
                                         "tum/smooth.tum", "tum/truth.tum"}
    for args in (["--csv", "y.csv", "--detections", "./y.csv"],
                 ["--detections", "./y.csv", "--csv", "y.csv"]):
        done = _export_in(tmp_path, fused, *args)
        assert done.returncode == 1 and "given as two outputs" in done.stderr
        assert not (tmp_path / "y.csv").exists()
