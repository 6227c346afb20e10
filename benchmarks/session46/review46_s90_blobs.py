"""review46: CPU of the smooth (offline) gate on the 90-minute session with candidates dropped
and blobs added. Paired runs: ``PYTHONPATH=<tree>`` for main and the branch, A B A B.

    python review46_s90_blobs.py DROPPED BLOBS REPEATS [MINUTES]   (WHOLE=1 / 0: force the
    compiled / the Python decider)
"""

import dataclasses
import os
import sys
import time

import numpy as np

import pslog.fusion._gate_kernel  # noqa: F401  (loaded, as pslog fuse preloads it)
from pslog import read_session
from pslog.fusion import FusionOptions, gating
from pslog.fusion._prepare import default_max_gap_s

dropped, blobs, repeats = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
minutes = float(sys.argv[4]) if len(sys.argv) > 4 else 90.0
if os.environ.get("WHOLE"):
    gating.WHOLE_COMPILED = os.environ["WHOLE"] == "1"
s = read_session("/work/m90/s90.mcap")
det, rig = s.detections, s.rig
rng = np.random.default_rng(82777)
keep = rng.random(det.n_candidates) >= dropped
keep &= det.frame_time_ns[det.cand_frame] - det.frame_time_ns[0] < minutes * 60e9
uv, fr = det.cand_uv[keep], det.cand_frame[keep]
score, radius = det.cand_score[keep], det.cand_radius[keep]
add = np.flatnonzero(rng.random(len(fr)) < blobs) + 1  # a blob after a frame's candidate
det = dataclasses.replace(
    det, cand_uv=np.insert(uv, add, rng.uniform(0, 600, (len(add), 2)), axis=0),
    cand_frame=np.insert(fr, add, fr[add - 1]),
    cand_score=np.insert(score, add, np.zeros(len(add))),
    cand_radius=np.insert(radius, add, np.full(len(add), np.nan)))
c, tables = gating.gate_common(det, rig)
starts = np.flatnonzero(np.r_[True, c.frame[1:] != c.frame[:-1]])
ends = np.r_[starts[1:], len(c.camera)]
whole, python_s = gating._decide_compiled(c, starts, ends, tables,
                                          round(default_max_gap_s(rig) * 1e9))
options = FusionOptions()
gated = gating.gate_for(det, rig, "smooth", options)
cpu = []
for _ in range(repeats):
    t0 = time.process_time()
    gated = gating.gate_for(det, rig, "smooth", options)
    cpu.append(time.process_time() - t0)
print(gating.__file__, len(c.camera), "compiled" if whole else "python",
      f"est {python_s:.2f}", " ".join(f"{x:.3f}" for x in cpu), "rejected",
      int(np.sum(gated.rejections.reason >= 0)))
