# ruff: noqa: E501
"""Issue 10 (session 28, farpoints): the filter's far points (> 5 cm) on held-out dirty
sessions against ``confirm_nis`` — an accepted update whose NIS exceeds it is withheld
until two more accepted updates, one from another camera, confirm it (the filter's
existing "hold for the next camera", in its dropping form). Per value: far points kept,
good points withheld, and the far points' error / std_m; plus err²/std_m² (the scalar
NEES, 1 if honest) of the points whose update NIS exceeded 4.6 (within the gate).
Sessions as bench_dirty --more (faults, optionally misses), fused as `pslog fuse` does
(gating on), the observations captured and refused with each value.
Usage: filter_hold.py FIRST NSEEDS FPS,.. MISSES OUT.pkl"""
import pickle
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs

from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion import filter as FM
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

VALUES = (9.21, 6.0, 4.61, 3.0)
cap = {}
orig = FM.fuse_filter


def capture(obs, rig, max_gap_s=None, options=None, doubt=None):
    cap["a"] = (obs, rig, max_gap_s, options, doubt)
    return orig(obs, rig, max_gap_s, options, doubt)


FM.fuse_filter = capture


def main():
    first, nseeds = int(sys.argv[1]), int(sys.argv[2])
    fpss = [float(x) for x in sys.argv[3].split(",")]
    misses, out = float(sys.argv[4]), sys.argv[5]
    res = {v: {"points": 0, "far": 0, "good": 0, "far_rows": [], "hi_nees": []} for v in VALUES}
    t0 = time.time()
    for fps in fpss:
        for base in rigs() + more_rigs():
            rig = at_rate(base, fps)
            for seed, (label, motion, duration, _) in enumerate(more_sessions(nseeds, 8.0, first), start=first - 300):
                span = motion.duration if duration is None else duration
                det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                    noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2, **faults(rig, seed, span)))
                fuse_detections(det, rig, ["filter"], FusionOptions())
                obs, r, gap, opts, doubt = cap["a"]
                opts = opts or FM.FilterOptions()
                for v in VALUES:
                    tr = orig(obs, r, gap, replace(opts, confirm_nis=v), doubt)
                    err = errors_m(tr, truth)
                    std = tr.quality["std_m"]
                    d = res[v]
                    d["points"] += len(tr)
                    d["far"] += int(np.count_nonzero(err > 0.05))
                    d["good"] += int(np.count_nonzero(err <= 0.05))
                    for i in np.flatnonzero(err > 0.05):
                        d["far_rows"].append((rig.name, label, float(tr.time_ns[i] / 1e9), float(err[i]), float(std[i]), float(tr.quality["nis"][i]), float(tr.quality["jump"][i])))
                    hi = (tr.quality["nis"] > 4.61) & (tr.quality["jump"] == 0)
                    d["hi_nees"].append((err[hi] / std[hi]) ** 2)
            print(f"{rig.name} {time.time() - t0:.0f} s", flush=True)
            with open(out, "wb") as f:
                pickle.dump(res, f)


if __name__ == "__main__":
    main()
