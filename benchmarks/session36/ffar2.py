# ruff: noqa: E501
import sys

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
sys.path.insert(0, "benchmarks/session28")
import numpy as np
from bench_dirty import faults, more_rigs, more_sessions, rigs

from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

rig = next(r for r in rigs() + more_rigs() if r.name == "lab3")
label, motion, duration, _k = list(more_sessions(3, 8.0, 48600))[1]
seed = 48601 - 300
f = faults(rig, seed, duration)
for kind, extra in (("clean", {}), ("blackout only", {"blackouts": f["blackouts"]}), ):
    det, truth, lab = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, **extra))
    tr = fuse_detections(det, rig, ["filter"], FusionOptions(), workers=1)[0]["filter"]
    err = errors_m(tr, truth)
    t = tr.time_ns / 1e9
    sel = (t > 2.0) & (t < 2.75)
    print(kind, "far", int(np.sum(err > 0.05)))
    if kind in ("dirty", "clean", "blackout only"):
        for i in np.flatnonzero(sel):
            print(f"  {t[i]:.4f} c{tr.camera[i]} err {err[i]*1e3:5.1f} std {tr.quality['std_m'][i]*1e3:4.1f} inn {tr.quality['innovation_px'][i]:5.2f} nis {tr.quality['nis'][i]:5.2f} jump {tr.quality['jump'][i]:.0f} gap {tr.quality['gap_s'][i]*1e3:.0f}")
