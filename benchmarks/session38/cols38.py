# ruff: noqa: E501
"""Issue 10 (session 38): one camera's candidates in a time window of a bench_dirty ``--more``
session with the faults (causal support): ratios, miss, ``_held``, the point, and ``_static``'s
static / stillness / lone without and with the held flags.

    PYTHONPATH=. python benchmarks/session38/cols38.py RIG LABEL FIRST FPS(0: none) MISSES CAMERA T0 T1
"""
import sys

sys.path.insert(0, "benchmarks/session38")
import numpy as np
import sessions38 as s

from pslog.fusion import gating
from pslog.fusion._prepare import default_max_gap_s
from pslog.fusion.gating import GatingOptions
from pslog.geometry import fundamental_matrices

rigname, label, first, fps, misses, cam, t0, t1 = sys.argv[1], sys.argv[2], int(sys.argv[3]), (float(sys.argv[4]) or None), float(sys.argv[5]), sys.argv[6], float(sys.argv[7]), float(sys.argv[8])
rig, motion, duration, seed, f, _, span = s.find(rigname, label, first, fps)
print(f)
det, _, ball = s.simulate(rig, motion, duration, seed, misses, s.kinds(f, span)["faults"])
c, tables = gating.gate_common(det, rig)
F = fundamental_matrices(rig.cameras)
o = GatingOptions()
k = gating._rig_constants(rig)
ratio, carried, _ = gating._support(c, rig, F, tables, o, round(default_max_gap_s(rig) * 1e9), True, 0)
points, _, miss = gating._points(c, rig, ratio, carried, k)
points[miss > o.track_m] = np.nan
held = gating._held(c, rig, ratio, carried, points, miss, o, k)
a = gating._static(c, tables, rig, o, points, gating._paired(ratio), compiled=False)
b = gating._static(c, tables, rig, o, points, gating._paired(ratio), compiled=False, held=held)
ci = rig.names.index(cam)
for i in np.flatnonzero((c.camera == ci) & (c.time_ns >= t0 * 1e9) & (c.time_ns <= t1 * 1e9)):
    print(f"{c.time_ns[i]/1e9:.4f} uv {np.round(c.uv_und[i],1).tolist()} ratio {np.round(ratio[i],2).tolist()} miss {miss[i]:.3f} held {held[i]} pt {np.isfinite(points[i,0])} | before static {a[0][i]} still {a[1][i]:.2f} lone {a[2][i]:.1f} | after static {b[0][i]} still {b[1][i]:.2f} lone {b[2][i]:.1f}")
