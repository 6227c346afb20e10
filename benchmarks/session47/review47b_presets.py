# ruff: noqa: E501
"""Session 47's second review: the gap hold's unit on the timing presets. The gap counted in
staggers ``1 / Σ fps`` (as first committed: ``hold_gap`` = 1.5 x stagger / regular gap gives
its threshold) against the rig's regular gap (:func:`regular_gap_s`, the default now), each
against ``hold_gap`` None: plain points held for a gap (NIS <= 2), good points (<= 5 cm)
withdrawn, far points withdrawn and left. Ungated (``det.best()``: the filter's rejections),
0.5 px, 5 % spurious, 3 s rallies. Seeds 87000-87999.
Usage: ``PYTHONPATH=.:tests python benchmarks/session47/review47b_presets.py FIRST N MISSES RIG TIMING,..``"""
import sys

import numpy as np
from _rally import rally
from test_filter import lab_rig

from pslog.evaluation import errors_m
from pslog.fusion.filter import FilterOptions, fuse_filter, regular_gap_s
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig


def make(kind: str) -> Rig:
    name, timing = kind.split()
    if timing == "30+60":
        r = builtin_rig(name)
        return Rig((r.cameras[0].replace(offset=0.0), r.cameras[1].replace(fps=60.0, offset=0.004)), r.name)
    r = builtin_rig(name) if name.startswith("paper") else lab_rig(int(name[-1]), 30.0)
    return apply_timing(r, timing)


def main() -> None:
    first, n, misses = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    print(f"seeds {first}..{first + n - 1}, misses {misses}")
    print("| rig | points (None) | far (None) | unit | held for a gap (% of plain) | good withdrawn | far withdrawn |")
    print("|---|---|---|---|---|---|---|")
    for kind in sys.argv[4].split(","):
        rig0 = make(kind)
        stagger, regular = 1.0 / sum(c.fps for c in rig0.cameras), regular_gap_s(rig0)
        units = {"1 / Σ fps": 1.5 * stagger / regular, "regular gap": 1.5}
        c = {u: np.zeros(3, np.int64) for u in units}
        npl = npts = far0 = 0
        for seed in range(first, first + n):
            opts = SimulationOptions(noise_px=0.5, seed=seed, miss_rate=misses, spurious_rate=0.05)
            det, truth, _ = simulate_labelled(rig0, rally(3.0, seed=seed, speed=4.0 + seed % 3, kick_every_s=0.6)[0], 3.0, opts)
            rig = true_rig(rig0, opts)
            obs = det.best()
            a = fuse_filter(obs, rig, options=FilterOptions(hold_gap=None))
            ea = errors_m(a, truth)
            q = a.quality
            plain = (q["jump"] == 0) & (q["rejected"] == 0) & (q["init"] == 0) & (q["nis"] <= 2.0)
            npl += int(plain.sum())
            npts += len(a)
            far0 += int(np.sum(ea > 0.05))
            ka = a.time_ns * 8 + a.camera
            for u, hg in units.items():
                b = fuse_filter(obs, rig, options=FilterOptions(hold_gap=hg))
                gone = ~np.isin(ka, b.time_ns * 8 + b.camera)
                c[u] += (int(np.sum(plain & (q["gap_s"] > hg * regular))), int(np.sum(gone & (ea <= 0.05))),
                         int(np.sum(gone & (ea > 0.05))))
        for u, (held, good, far) in c.items():
            print(f"| {kind} | {npts} | {far0} | {u} | {held} ({100 * held / npl:.0f} %) | {good} ({100 * good / npts:.2f} %) | {far} |", flush=True)


if __name__ == "__main__":
    main()
