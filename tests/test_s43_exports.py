"""Session 43: ``pslog export``'s outputs against each other (their order on the command line
changes nothing, none replaces another) and C3D of points of one time; through the real CLI
on real sessions."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
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


def _c3d_frames(path):
    import warnings

    c3d = pytest.importorskip("c3d")
    with open(path, "rb") as f, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "No analog data found in file."
        reader = c3d.Reader(f)
        labels = [s.strip() for s in reader.point_labels]
        frames = np.array([points for _, points, _ in reader.read_frames()])
    return labels, frames


def test_c3d_of_a_track_with_points_of_one_time(tmp_path):
    """Cameras firing together (sync timing): the filter's points of one time made the grid's
    median interval 0 and ``export --c3d`` a ZeroDivisionError traceback."""
    session_path, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    pslog_ok("simulate", "--rig", "paper3", "--duration", "1", "--seed", "75061",
             "-o", session_path)
    pslog_ok("fuse", session_path, "--method", "filter", "-o", fused)
    out = pslog_ok("export", fused, "--c3d", tmp_path / "t.c3d")
    assert "at 30 Hz" in out and "filter" in out, out
    labels, frames = _c3d_frames(tmp_path / "t.c3d")
    assert labels[0] == "filter" and np.count_nonzero(frames[:, 0, 3] != -1) >= 25
