"""Session 40's hostile-input sweep (helper hostile40) of the session's new surfaces, through
the real CLI on real files: ``pslog eval --truth FILE``, ``pslog import --detections
CAMERA=FILE``, and the batch gate that decides dirty sessions by the compiled kernels.

Found and fixed: a session of crowded frames (``pslog import`` takes any number of
candidates a frame) went the gate's numpy path, whose support pairs every candidate with
each pair of another camera's frames (k² pairs, held at once): 50 candidates a frame in a
rally took ``pslog fuse`` 45 s and 6 GB, ``pslog sync`` 38 s and 3.5 GB; 209 in one camera
asked for 16 GiB ("out of memory", exit 1). The gate's cost estimate now counts those pairs,
and such sessions are decided by the compiled kernels (4 s and 260 MB; 2.5 s and 250 MB)."""

from __future__ import annotations

import resource
from pathlib import Path

import numpy as np
import pytest

import pslog
from pslog.log.csvio import format_time

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep40")
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                     "--noise-px", "0.3", "--seed", "63001", "-o", folder / "s.mcap")
    assert done.code == 0, done.stderr
    done = run_pslog("fuse", folder / "s.mcap", "-o", folder / "f.mcap")
    assert done.code == 0, done.stderr
    return folder


def _crowded_csv(session: Path, out: Path, k: int, cameras: tuple[str, ...], seed: int) -> int:
    """``session``'s detections as a detections CSV, every frame of ``cameras`` given
    ``k - 1`` false candidates uniform over its image (blobs, a noisy detector); returns
    the rows written."""
    s = pslog.read_session(session)
    d, rig = s.detections, s.rig
    rng = np.random.default_rng(seed)
    rows = ["camera,time,u,v,frame,score"]
    for f in range(d.n_frames):
        name = rig.names[d.frame_camera[f]]
        t, index = format_time(int(d.frame_time_ns[f])), int(d.frame_index[f])
        uv = d.cand_uv[d.cand_frame == f].tolist()
        if name in cameras:
            cam = rig.cameras[d.frame_camera[f]]
            uv += rng.uniform([0, 0], [cam.width, cam.height], size=(k - 1, 2)).tolist()
        rows += [f"{name},{t},{u!r},{v!r},{index},1.0" for u, v in uv]
    out.write_text("\n".join(rows) + "\n")
    return len(rows) - 1


def _address_space(limit: int):
    def preexec() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    return preexec


@pytest.mark.parametrize("command", ["fuse", "sync"])
def test_a_camera_of_crowded_frames_is_gated_in_bounded_memory(inputs, tmp_path, command):
    """200 candidates in every frame of one camera: the gate's numpy support asked for
    (9000, 200, 200) arrays, 2.9 GB each ("out of memory" under this 3 GiB address space;
    16 GiB on a rally); the compiled kernels decide it in a few hundred MB."""
    rows = _crowded_csv(inputs / "s.mcap", tmp_path / "crowded.csv", 200, ("cam1",), 63011)
    assert rows > 9000
    done = run_pslog("import", "--rig", "paper3", "--detections", tmp_path / "crowded.csv",
                     "-o", tmp_path / "crowded.mcap")
    assert done.code == 0, done.stderr
    out = tmp_path / "out.mcap"
    run = run_pslog(command, tmp_path / "crowded.mcap", "-o", out, timeout=120,
                    preexec_fn=_address_space(3 << 30))
    assert run.code == 0, run.stderr
    assert "Traceback" not in run.stderr and "memory" not in run.stderr, run.stderr
    assert out.stat().st_size > 0
    if command == "fuse":  # the ball still found among the blobs
        session = pslog.read_session(out)
        assert len(session.tracks["typeA"]) > 100
