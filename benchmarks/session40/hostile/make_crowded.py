"""A detections CSV with extra candidates: every frame of the chosen cameras gets K - 1
false candidates uniform over the image (the ball's kept), or a static blob at a fixed
pixel; for the gate's stress probes.

    python make_crowded.py SESSION.mcap OUT.csv K [CAMERA...] [--seed N] [--static]
"""

from __future__ import annotations

import argparse

import numpy as np

import pslog
from pslog.log.csvio import format_time

p = argparse.ArgumentParser()
p.add_argument("session")
p.add_argument("out")
p.add_argument("k", type=int)
p.add_argument("cameras", nargs="*")
p.add_argument("--seed", type=int, default=63100)
p.add_argument("--static", action="store_true", help="false candidates fixed per camera")
a = p.parse_args()
s = pslog.read_session(a.session)
d, rig = s.detections, s.rig
rng = np.random.default_rng(a.seed)
names = rig.names
chosen = set(a.cameras or names)
fixed = {c: rng.uniform([0, 0], [cam.width, cam.height], size=(a.k - 1, 2))
         for c, cam in zip(names, rig.cameras, strict=True)}
with open(a.out, "w") as f:
    f.write("camera,time,u,v,frame,score\n")
    cand_of = [[] for _ in range(d.n_frames)]
    for i, fr in enumerate(d.cand_frame.tolist()):
        cand_of[fr].append(i)
    for fr in range(d.n_frames):
        c = names[d.frame_camera[fr]]
        t = format_time(int(d.frame_time_ns[fr]))
        k = int(d.frame_index[fr])
        for i in cand_of[fr]:
            f.write(f"{c},{t},{float(d.cand_uv[i, 0])!r},{float(d.cand_uv[i, 1])!r},{k},1.0\n")
        if c in chosen:
            cam = rig.cameras[d.frame_camera[fr]]
            extra = fixed[c] if a.static else rng.uniform(
                [0, 0], [cam.width, cam.height], size=(a.k - 1, 2))
            f.writelines(f"{c},{t},{u!r},{v!r},{k},0.5\n" for u, v in extra.tolist())
        if not cand_of[fr] and c not in chosen:
            f.write(f"{c},{t},,,{k},\n")
