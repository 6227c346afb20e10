# ruff: noqa: E501
"""Session 36 (ffar36): where `paper2`'s `straight` (bench_dirty --more --first-seed 48300,
30 fps) loses accuracy to its faults: the filter's mean error clean, with each fault alone and
all faults, and the excess error by time (the blackout's span, after it, elsewhere).

    PYTHONPATH=. python benchmarks/session36/ffar_straight.py [FIRST [RIG [K]]]"""
import sys

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import numpy as np
from bench_dirty import faults, more_rigs, more_sessions, rigs

from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

first = int(sys.argv[1]) if len(sys.argv) > 1 else 48300
rname = sys.argv[2] if len(sys.argv) > 2 else "paper2"
k = int(sys.argv[3]) if len(sys.argv) > 3 else 4
rig = next(r for r in rigs() + more_rigs() if r.name == rname)
label, motion, duration, _ = list(more_sessions(3, 8.0, first))[k]
seed = first - 300 + k
span = motion.duration if duration is None else duration
f = faults(rig, seed, span)
print(label, seed, {a: b for a, b in f.items() if a != "distractors"}, "distractor cam", f["distractors"][0][0])
(bcam, b0, blen), = f["blackouts"]
variants = [("clean", {}), ("faults", f)] + [(key, {key: f[key]}) for key in f]
for name, extra in variants:
    det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, **extra))
    for method in ("filter", "smooth"):
        tr = fuse_detections(det, rig, [method], FusionOptions(), workers=1)[0][method]
        err = errors_m(tr, truth) * 1e3
        t = tr.time_ns / 1e9
        parts = {"blackout": (t >= b0) & (t < b0 + blen), "0.5 s after": (t >= b0 + blen) & (t < b0 + blen + 0.5)}
        parts["elsewhere"] = ~(parts["blackout"] | parts["0.5 s after"])
        print(f"  {name:12} {method:6} mean {err.mean():.3f} mm n {len(err)} | " + ", ".join(
            f"{p} n {m.sum()} sum {err[m].sum():.0f} mean {err[m].mean():.2f}" for p, m in parts.items()))

# the points the distractor variant keeps against the clean run's at the same detections
res = {}
for name, extra in (("clean", {}), ("distractors", {"distractors": f["distractors"]})):
    det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, **extra))
    tr = fuse_detections(det, rig, ["filter"], FusionOptions(), workers=1)[0]["filter"]
    res[name] = (tr, errors_m(tr, truth) * 1e3)
(tc, ec), (td, ed) = res["clean"], res["distractors"]
kc = dict(zip(zip(tc.time_ns.tolist(), tc.camera.tolist(), strict=True), ec, strict=True))
kd = dict(zip(zip(td.time_ns.tolist(), td.camera.tolist(), strict=True), ed, strict=True))
common = sorted(set(kc) & set(kd))
print(f"distractor alone: dropped {dict(td.dropped)} (clean {dict(tc.dropped)}); points clean {len(kc)}, "
      f"with it {len(kd)}, common {len(common)}: mean there clean {np.mean([kc[c] for c in common]):.2f} with {np.mean([kd[c] for c in common]):.2f};"
      f" clean's points it lacks: mean {np.mean([kc[c] for c in set(kc) - set(kd)]):.2f} at "
      + " ".join(f"{c[0] / 1e9:.3f}c{c[1]}" for c in sorted(set(kc) - set(kd))))
