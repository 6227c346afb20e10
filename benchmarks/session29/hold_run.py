# ruff: noqa: E501
"""The batch's hold for the next camera (``FilterOptions.hold_nis``, session 29) as built,
against hold_lag.py's measurement of the rule: sessions as surprise.py's, each fused as
`pslog fuse` does (its gated observations captured), then fused again with ``hold_nis`` at
each θ: points output, far (> 5 cm) kept, good points withdrawn (``held``), against the
default. Usage: hold_run.py FIRST NSEEDS FPS,.. MISSES"""
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
sys.path.insert(0, "benchmarks/session29")
from _capture import dirty_sessions, orig

from pslog.evaluation import errors_m
from pslog.fusion import filter as FM

THETAS = (0.0, 2.0, 4.61)


def main():
    first, nseeds = int(sys.argv[1]), int(sys.argv[2])
    fpss = [float(x) for x in sys.argv[3].split(",")]
    misses = float(sys.argv[4])
    tot = {th: np.zeros(4, dtype=np.int64) for th in (None, *THETAS)}
    t0 = time.time()
    for fps, _rig, _label, truth, (obs, r, gap, opts, doubt) in dirty_sessions(
            first, nseeds, fpss, misses):
        opts = opts or FM.FilterOptions()
        base_tr = orig(obs, r, gap, opts, doubt)
        err0 = errors_m(base_tr, truth)
        for th in (None, *THETAS):
            tr = orig(obs, r, gap, replace(opts, hold_nis=th), doubt)
            err = errors_m(tr, truth)
            gone = ~np.isin(base_tr.time_ns, tr.time_ns)
            assert np.all(np.isin(tr.time_ns, base_tr.time_ns))
            tot[th] += (len(tr), int(np.sum(err > 0.05)), int(np.sum(gone & (err0 <= 0.05))), int(tr.dropped.get("held", 0)))
        print(f"{fps:g} fps {time.time() - t0:.0f} s", flush=True)
    for th, (n, far, good, held) in tot.items():
        print(f"hold_nis {th}: points {n}, far {far}, good withdrawn {good}, held count {held}")


if __name__ == "__main__":
    main()
