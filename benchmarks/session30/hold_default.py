# ruff: noqa: E501
"""Session 30: should the filter's hold for the next camera (``FilterOptions.hold_nis``) be
the default of ``pslog fuse``? bench_dirty ``--more``'s five rigs and sessions (0.3 px), at
one rate, clean or with the issue's faults, the detector missing ``misses`` of the frames
(dropping half as many), each fused as ``pslog fuse`` does (gating on; the filter's gated
observations captured), then fused again with ``hold_nis`` at each θ of a grid of χ²₂
quantiles (θ = -2 ln(1 - p)). Per θ: points output, far (> 5 cm) kept, far removed and good
(<= 5 cm) points withdrawn against no hold, mean error (mm), NEES and the share of truth in
2σ. Usage: hold_default.py FIRST NSEEDS FPS MISSES clean|faults"""
import math
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "benchmarks/session29")
sys.path.insert(0, "tests")
from _capture import dirty_sessions, orig  # (importing it wraps fuse_filter)

from pslog.evaluation import errors_m, mahalanobis_sq
from pslog.fusion import filter as FM

#: χ²₂ quantiles p -> θ = -2 ln(1 - p); 1 - 1/e gives θ = 2 (session 29's θ, χ²₂'s mean)
QUANTILES = (0.5, 1 - math.exp(-1), 0.75, 0.9, 0.95)
THETAS = tuple(round(-2 * math.log(1 - p), 3) for p in QUANTILES)


def main():
    first, nseeds, fps = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
    misses, kind = float(sys.argv[4]), sys.argv[5]
    keys = (None, *THETAS)
    tot = {th: dict(n=0, far=0, far_removed=0, good_withdrawn=0, sum_err=0.0, sum_d2=0.0, n_d2=0, in2=0)
           for th in keys}
    n_sessions = 0
    t0 = time.time()
    last = None
    for _fps, rig, _label, truth, (obs, r, gap, opts, doubt) in dirty_sessions(
            first, nseeds, [fps], misses, with_faults=kind == "faults"):
        if last is not None and rig.name != last:
            print(f"# {last} {time.time() - t0:.0f} s", flush=True)
        last = rig.name
        # (the hold off, the filter as before session 30: the reference of every θ)
        opts = replace(opts or FM.FilterOptions(), hold_nis=None)
        base_tr = orig(obs, r, gap, opts, doubt)
        err0 = errors_m(base_tr, truth)
        n_sessions += 1
        for th in keys:
            tr = base_tr if th is None else orig(obs, r, gap, replace(opts, hold_nis=th), doubt)
            err = errors_m(tr, truth)
            ok = np.isfinite(err)
            kept = np.isin(base_tr.time_ns * 8 + base_tr.camera, tr.time_ns * 8 + tr.camera)
            d2 = mahalanobis_sq(tr, truth)
            t = tot[th]
            t["n"] += int(ok.sum())
            t["far"] += int(np.sum(err[ok] > 0.05))
            t["far_removed"] += int(np.sum(~kept & (err0 > 0.05)))
            t["good_withdrawn"] += int(np.sum(~kept & (err0 <= 0.05)))
            t["sum_err"] += float(np.sum(err[ok]))
            d2 = d2[np.isfinite(d2)]
            t["sum_d2"] += float(np.sum(d2))
            t["n_d2"] += len(d2)
            t["in2"] += int(np.sum(d2 <= 4.0))
    print(f"# {last} {time.time() - t0:.0f} s", flush=True)
    print(f"set first={first} nseeds={nseeds} fps={fps:g} misses={misses} {kind}: {n_sessions} sessions")
    for th in keys:
        t = tot[th]
        print(f"theta {th}: points {t['n']}, far {t['far']}, far removed {t['far_removed']}, "
              f"good withdrawn {t['good_withdrawn']}, mean {1e3 * t['sum_err'] / t['n']:.4f} mm, "
              f"NEES {t['sum_d2'] / t['n_d2'] / 3:.4f}, in 2σ {100 * t['in2'] / t['n_d2']:.2f} %")


if __name__ == "__main__":
    main()
