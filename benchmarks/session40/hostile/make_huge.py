"""A session whose one camera holds N candidates in all (uniform over its image, the ball's
kept), the others as simulated: ``pslog import``'s path without a 5-million-row CSV.

    python make_huge.py SESSION.mcap OUT.mcap N CAMERA [--seed N] [--csv OUT.csv]
"""

from __future__ import annotations

import argparse

import numpy as np

import pslog
from pslog.log import SessionWriter
from pslog.records import Detections

p = argparse.ArgumentParser()
p.add_argument("session")
p.add_argument("out")
p.add_argument("n", type=int)
p.add_argument("camera")
p.add_argument("--seed", type=int, default=63200)
p.add_argument("--csv", help="also write the detections as a CSV (pslog import's)")
a = p.parse_args()
s = pslog.read_session(a.session)
d, rig = s.detections, s.rig
c = rig.names.index(a.camera)
cam = rig.cameras[c]
rng = np.random.default_rng(a.seed)
frames = np.flatnonzero(d.frame_camera == c)
per = a.n // len(frames)
extra_frame = np.repeat(frames, per)
extra_uv = rng.uniform([0, 0], [cam.width, cam.height], size=(len(extra_frame), 2))
det = Detections.from_frames(
    d.camera_names, d.frame_time_ns, d.frame_camera, d.frame_index,
    np.concatenate([d.cand_frame, extra_frame]), np.concatenate([d.cand_uv, extra_uv]),
    None, np.concatenate([d.cand_score, np.full(len(extra_frame), 0.5)]))
with SessionWriter(a.out, rig, force=True, timing=s.timing) as w:
    w.add_detections(det)
print(f"wrote {a.out}: {det.n_candidates} candidates, {per + 1} per frame of {a.camera}")
if a.csv:
    from pslog.log.csvio import write_detections_csv

    write_detections_csv(det, a.csv, force=True)
