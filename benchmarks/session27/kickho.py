# ruff: noqa: E501
"""Issue 10 (session 27, kicknees): held-out NEES by accepted point index after the
filter's jumps, split by the jump's chosen shape (0 floor reflection, 1 bounce off an
unknown surface, 2 kick) and by the true height at the jump (near the floor or mid-air).
Each session fused as `pslog fuse` does (gating on; its observations and doubt captured),
then its observations pushed one at a time (the same points as the batch filter) so that
the chosen shape is read after each push. Usage: kickho.py FIRST NSEEDS FPS,.. NOISE,.. OUT"""
import pickle
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs

from pslog.fusion import FusionOptions
from pslog.fusion import filter as FM
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

first, nseeds = int(sys.argv[1]), int(sys.argv[2])
fpss = [float(x) for x in sys.argv[3].split(",")]
noises = [float(x) for x in sys.argv[4].split(",")]
out = sys.argv[5]
variants = {"before": {"jump_mixture_cov": False}, "new": {}}
cap = {}
orig = FM.fuse_filter


def capture(obs, rig, max_gap_s=None, options=None, doubt=None):
    cap["a"] = (obs, rig, max_gap_s, doubt, options)
    return orig(obs, rig, max_gap_s, options, doubt)


FM.fuse_filter = capture
rows = []
t0 = time.time()
for fps in fpss:
    for base in rigs() + more_rigs():
        rig = at_rate(base, fps)
        runs = more_sessions(nseeds, 8.0, first)[:nseeds + 1]
        for seed, (label, motion, duration, _) in enumerate(runs, start=first - 300):
            span = motion.duration if duration is None else duration
            for noise in noises:
                for kind, extra in (("clean", {}), ("dirty", faults(rig, seed, span))):
                    det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                        noise_px=noise, seed=seed, miss_rate=0.1, drop_rate=0.05, **extra))
                    fuse_detections(det, rig, ["filter"], FusionOptions())
                    obs, r, gap, doubt, fopt = cap["a"]
                    fopt = fopt or FM.FilterOptions()
                    if gap is not None and fopt.max_gap_s is None:
                        fopt = replace(fopt, max_gap_s=gap)
                    keep = ~(np.asarray(doubt) > 0) if doubt is not None else np.ones(len(obs.time_ns), bool)
                    res = {}
                    for vname, vopt in variants.items():
                        flt = FM.BallFilter(r, replace(fopt, max_std_m=None, withhold=False,
                                                       **vopt))
                        pts = []
                        for i in np.flatnonzero(keep):
                            t = int(obs.time_ns[i])
                            o = flt.push(t, int(obs.camera[i]), float(obs.uv[i, 0]), float(obs.uv[i, 1]))
                            if o is None:
                                continue
                            p, q = o
                            pts.append((t, *p, *q[:4], q[8], q[9], int(flt._I[FM._IJSHAPE])))
                        a = np.array(pts)
                        X = truth.at(a[:, 0].astype(np.int64))
                        e = a[:, 1:4] - X
                        res[vname] = dict(t=a[:, 0].astype(np.int64), err=np.linalg.norm(e, axis=1),
                                          d2=np.sum(e ** 2 / a[:, 5:8] ** 2, axis=1), std=a[:, 4],
                                          jump=a[:, 8], rej=a[:, 9], shape=a[:, 10].astype(int),
                                          z=X[:, 2])
                    rows.append(dict(rig=rig.name, fps=fps, noise=noise, kind=kind, label=label,
                                     res=res))
            print(rig.name, fps, f"{time.time() - t0:.0f}s", flush=True)
pickle.dump(rows, open(out, "wb"))
