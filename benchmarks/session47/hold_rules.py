# ruff: noqa: E501
"""Session 47's holds of the filter, measured against the filter before them: bench_dirty
``--more``'s sessions (its five rigs, its faults, 0.3 px; session 29's _capture.py: each
fused as ``pslog fuse`` does, its gated observations captured), fused again with each rule
set. Per rule set: points output, far points (> 5 cm), good points withdrawn and far points
withdrawn (against the filter of session 46: no hold of a start, of a point after a missed
slot, of a rejected detection's), and each far point of session 46's with what it is.
Usage: hold_rules.py FIRST NSEEDS FPS,.. MISSES"""
import sys
from dataclasses import replace

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
sys.path.insert(0, "benchmarks/session29")
from _capture import dirty_sessions, orig

from pslog.evaluation import errors_m
from pslog.fusion import filter as FM

RULES = {
    "session 46": {"hold_start": False, "hold_gap": None, "hold_rejected": False},
    "start": {"hold_gap": None, "hold_rejected": False},
    "start + rejected": {"hold_gap": None},
    "start + gap": {"hold_rejected": False},
    "all (default)": {},
    "all, every point held (hold_nis 0)": {"hold_nis": 0.0},
}


def main():
    first, nseeds = int(sys.argv[1]), int(sys.argv[2])
    fpss = [float(x) for x in sys.argv[3].split(",")]
    misses = float(sys.argv[4])
    tot = {k: np.zeros(4, dtype=np.int64) for k in RULES}
    for _fps, rig, label, truth, (obs, r, gap, _opts, doubt) in dirty_sessions(first, nseeds, fpss, misses):
        base = orig(obs, r, gap, replace(FM.FilterOptions(), **RULES["session 46"]), doubt)
        e0 = errors_m(base, truth)
        key0 = base.time_ns * 8 + base.camera
        for i in np.flatnonzero(e0 > 0.05):
            q = base.quality
            kind = "start" if q["init"][i] else "rejected" if q["rejected"][i] else "jump" if q["jump"][i] else "plain"
            print(f"far (session 46): {rig.name} {label} {base.time_ns[i] / 1e9:.4f} s, {1e3 * e0[i]:.0f} mm, std {1e3 * q['std_m'][i]:.1f} mm, {kind}, NIS {q['nis'][i]:.2f}, gap {q['gap_s'][i] * sum(c.fps for c in r.cameras):.2f} staggers", flush=True)
        for k, v in RULES.items():
            tr = orig(obs, r, gap, replace(FM.FilterOptions(), **v), doubt)
            e = errors_m(tr, truth)
            gone = ~np.isin(key0, tr.time_ns * 8 + tr.camera)
            assert np.all(np.isin(tr.time_ns * 8 + tr.camera, key0))
            tot[k] += (len(tr), int(np.sum(e > 0.05)), int(np.sum(gone & (e0 <= 0.05))), int(np.sum(gone & (e0 > 0.05))))
    print(f"sessions {first} x {nseeds}, {sys.argv[3]} fps, misses {misses}")
    print("| rules | points | far | good withdrawn | far withdrawn |")
    print("|---|---|---|---|---|")
    for k, (n, far, good, farw) in tot.items():
        print(f"| {k} | {n} | {far} | {good} | {farw} |")


if __name__ == "__main__":
    main()
