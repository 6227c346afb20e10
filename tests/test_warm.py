"""``python -m pslog.warm`` (run by ``bash run.sh`` after installing) runs the real commands
that compile every numba kernel, and leaves nothing behind but numba's cache."""

import os
import subprocess
import sys


def test_warm_runs_the_commands_and_leaves_no_file(tmp_path):
    env = dict(os.environ, TMPDIR=str(tmp_path))
    run = subprocess.run([sys.executable, "-m", "pslog.warm"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert "numba kernels ready in" in run.stdout
    assert "Traceback" not in run.stderr
    assert list(tmp_path.iterdir()) == []  # its session files were in a removed folder


_TRACK_WRITER = """
import sys
import numpy as np
from pslog.log import _wire
from pslog.log.copy import open_copy
from pslog.log.writer import _TRACK_BLOCK
from pslog.records import Track
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate
from pslog.motion import rally_motion
from pslog.log import SessionWriter
from pslog.warm import _track_writer

src, out, warmed = sys.argv[1:4]
rig = apply_timing(builtin_rig("paper3"), "typeA")
detections, _ = simulate(rig, rally_motion(seed=1, duration=0.5), 0.5,
                         SimulationOptions(noise_px=0.3, seed=2))
with SessionWriter(src, rig) as w:
    w.add_detections(detections)
_track_writer(warmed, rig)
kernels = (_wire.encode_track, _wire.assemble_records)
print(*(len(k.signatures) for k in kernels))
# a long track as pslog fuse writes it (other column types: the writer converts them), a
# gating rejection queued before the next track's first block
from pslog.fusion.gating import Rejections
n = 2 * _TRACK_BLOCK + 5
rows = np.arange(n)
track = Track("nearest", (rows + 1) * 3_703_704, np.random.default_rng(0).normal(size=(n, 3)),
              (rows % 3).astype(np.int8), {"std_m": np.float32(0.01) * np.ones(n, np.float32)})
first = Track("typeA", track.time_ns[:300], track.position_world[:300], track.camera[:300])
rejected = Rejections.from_rows([(int(track.time_ns[0]), 0, 0, 1.0, 2.0, 0.5, "epipolar")])
k = 1 << 15  # a dirty session's many rejections: one block of payloads over a megabyte
many = Rejections(np.arange(1, k + 1) * 11_111_111, np.arange(k) % 3, np.arange(k),
                  np.full((k, 2), 320.25), np.ones(k), np.ones(k, np.int8))
with open_copy(src, out, new_methods=["typeA", "nearest"]) as w:  # as pslog fuse writes
    w.add_track(first, last=True)
    w.add_rejections("typeA", rejected)
    w.add_track(track, last=True)
    w.add_rejections("nearest", many)
print(*(len(k.signatures) for k in kernels))
"""


def test_warm_compiles_the_track_writers_kernels_in_the_signature_fuse_uses(tmp_path):
    # a long fused track's messages are encoded by pslog.log._wire's kernels, which the
    # short sessions of warm's commands never reach: warm writes one such track itself, in
    # the signatures a long session's pslog fuse then loads (none compiled again)
    run = subprocess.run([sys.executable, "-c", _TRACK_WRITER, str(tmp_path / "s.mcap"),
                          str(tmp_path / "f.mcap"), str(tmp_path / "w.mcap")],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split("\n")[:2] == ["1 1", "1 1"]
