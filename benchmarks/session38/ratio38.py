# ruff: noqa: E501
"""Issue 10 (session 38): one bench_dirty ``--more`` session's points and mean error per
method, clean / faults / blackout alone, and the ratios to clean.

    PYTHONPATH=. python benchmarks/session38/ratio38.py RIG LABEL FIRST FPS(0: none) MISSES
"""
import sys

sys.path.insert(0, "benchmarks/session38")
import numpy as np
import sessions38 as s

from pslog.evaluation import errors_m
from pslog.fusion.gating import fuse_detections

rigname, label, first, fps, misses = sys.argv[1], sys.argv[2], int(sys.argv[3]), (float(sys.argv[4]) or None), float(sys.argv[5])
rig, motion, duration, seed, f, _, span = s.find(rigname, label, first, fps)
res = {}
for kind in ("clean", "faults", "blackout"):
    det, truth, _ = s.simulate(rig, motion, duration, seed, misses, s.kinds(f, span)[kind])
    tr = fuse_detections(det, rig, ["typeA", "smooth", "filter"], s.OPTIONS, workers=1)[0]
    res[kind] = {m: (len(tr[m]), np.nanmean(errors_m(tr[m], truth))) for m in tr}
for m in ("typeA", "smooth", "filter"):
    c = res["clean"][m][1]
    print(rigname, label, m, " ".join(f"{k}: {res[k][m][0]} pts {1e3*res[k][m][1]:.3f} mm ({res[k][m][1]/c:.3f})" for k in res))
