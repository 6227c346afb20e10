# ruff: noqa: E501
"""Session 47's second review: the gap hold (``hold_gap``, 1.5 staggers of ``1 / Σ fps``) on
rigs whose gaps are not even staggers: two cameras 5 ms apart at 30 fps, a camera that never
sees the ball, unequal frame rates, a blackout of the others. Per rig: points, far (> 5 cm),
good points withdrawn against ``hold_gap=None`` (the same options otherwise), ungated
(``det.best()``: the filter's own rejections). Seeds 87000-87999.
Usage: ``PYTHONPATH=.:tests python benchmarks/session47/review47b_rigs.py FIRST N``"""
import sys

import numpy as np
from _rally import rally
from test_filter import lab_rig

from pslog.evaluation import errors_m
from pslog.fusion.filter import FilterOptions, fuse_filter
from pslog.rig import Rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig


def rig_of(kind):
    if kind == "2x30 5ms":
        r = lab_rig(2, 30.0)
        return Rig((r.cameras[0].replace(offset=0.0), r.cameras[1].replace(offset=0.005)), r.name), ()
    if kind == "3x30 one blind":
        r = lab_rig(3, 30.0)
        return r, ((r.names[2], 0.0, 100.0),)
    if kind == "30+60":
        r = lab_rig(2, 30.0)
        return Rig((r.cameras[0], r.cameras[1].replace(fps=60.0, offset=0.004)), r.name), ()
    if kind == "30+30+120":
        r = lab_rig(3, 30.0)
        return Rig((*r.cameras[:2], r.cameras[2].replace(fps=120.0, offset=0.001)), r.name), ()
    if kind == "4x30 even":
        return lab_rig(4, 30.0), ()
    raise ValueError(kind)


KINDS = ("4x30 even", "2x30 5ms", "3x30 one blind", "30+60", "30+30+120")


def main():
    first, n = int(sys.argv[1]), int(sys.argv[2])
    misses = float(sys.argv[3]) if len(sys.argv) > 3 else 0.1
    print(f"seeds {first}..{first + n - 1}, misses {misses}, spurious 0.05, 0.5 px, 3 s rallies")
    print("| rig | mode | points (hold_gap None) | points (1.5) | far None -> 1.5 | good withdrawn (share) | far withdrawn |")
    print("|---|---|---|---|---|---|---|")
    for kind in KINDS:
        tot = {m: np.zeros(6, np.int64) for m in ("ungated",)}
        for seed in range(first, first + n):
            rig, blackouts = rig_of(kind)
            dur = 3.0
            opts = SimulationOptions(noise_px=0.5, seed=seed, miss_rate=misses, spurious_rate=0.05,
                                     blackouts=blackouts)
            det, truth, _ = simulate_labelled(rig, rally(dur, seed=seed, speed=4.0 + seed % 3, kick_every_s=0.6)[0], dur, opts)
            rig = true_rig(rig, opts)
            for mode in ("ungated",):
                obs = det.best()
                a = fuse_filter(obs, rig, options=FilterOptions(hold_gap=None))
                b = fuse_filter(obs, rig, options=FilterOptions())
                ea, eb = errors_m(a, truth), errors_m(b, truth)
                ka, kb = a.time_ns * 8 + a.camera, b.time_ns * 8 + b.camera
                gone = ~np.isin(ka, kb)
                tot[mode] += (len(a), len(b), int(np.sum(ea > 0.05)), int(np.sum(eb > 0.05)),
                              int(np.sum(gone & (ea <= 0.05))), int(np.sum(gone & (ea > 0.05))))
        for mode, t in tot.items():
            if t[0]:
                print(f"| {kind} | {mode} | {t[0]} | {t[1]} | {t[2]} -> {t[3]} | {t[4]} ({100 * t[4] / t[0]:.1f} %) | {t[5]} |", flush=True)


if __name__ == "__main__":
    main()
