# ruff: noqa: E501
import sys

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
sys.path.insert(0, "benchmarks/session28")
import numpy as np
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs
from farpoints import jumps

from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

first, rname = int(sys.argv[1]), sys.argv[2]
fps = float(sys.argv[3]) if len(sys.argv) > 3 else None
method = sys.argv[4] if len(sys.argv) > 4 else "filter"
rig = next(r for r in rigs() + more_rigs() if r.name == rname)
if fps:
    rig = at_rate(rig, fps)
opt = FusionOptions()
for seed, (label, motion, duration, _k) in enumerate(more_sessions(3, 8.0, first), start=first - 300):
    span = motion.duration if duration is None else duration
    kicks = jumps(motion, span)
    f = faults(rig, seed, span)
    res = {}
    for kind, extra in (("clean", {}), ("dirty", f)):
        det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, **extra))
        tr = fuse_detections(det, rig, [method], opt, workers=1)[0][method]
        res[kind] = (tr, errors_m(tr, truth))
    tr, err = res["dirty"]
    for i in np.flatnonzero(err > 0.05):
        t = tr.time_ns[i] / 1e9
        before = kicks[kicks <= t]
        print(f"{label} t={t:.4f} cam {tr.camera[i]} err {err[i]*1e3:.0f} mm std {tr.quality['std_m'][i]*1e3:.1f}; {f['blackouts']} distractor {f['distractors'][0][0]}; {1e3*(t-before[-1]) if len(before) else np.nan:.0f} ms after a jump; " + " ".join(f"{k}={tr.quality[k][i]:.3g}" for k in tr.quality if not k.startswith('cov')))
    print(label, "dirty far", int(np.sum(err > 0.05)), "clean far", int(np.sum(res['clean'][1] > 0.05)), dict(tr.dropped))
