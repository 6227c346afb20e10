# ruff: noqa: E501
"""Issue 10 (session 29, farpoints): a plain update's jump/no-jump mixture in the filter's
published covariance (``FilterOptions.surprise_cov``). Sessions as bench_dirty --more (five
rigs x 4 rallies, the library's rally, straight, turntable; its faults; 0.3 px; optionally
misses / drops), fused as `pslog fuse` does (gating on), the gated observations captured and
fused again with ``surprise_cov`` off and on, each with ``withhold`` on (the output) and off
(every point of a live track). Per point: error, std_m off / on, NIS, jump, rejected, init,
whether output off / on. The positions with withhold off must be equal (the state is
unchanged).
Usage: surprise.py FIRST NSEEDS FPS,.. MISSES OUT.pkl"""
import pickle
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


def main():
    first, nseeds = int(sys.argv[1]), int(sys.argv[2])
    fpss = [float(x) for x in sys.argv[3].split(",")]
    misses, out = float(sys.argv[4]), sys.argv[5]
    rows = []
    t0 = time.time()
    for fps, rig, label, truth, (obs, r, gap, opts, doubt) in dirty_sessions(
            first, nseeds, fpss, misses):
        opts = opts or FM.FilterOptions()
        tr = {}
        for cov in (False, True):
            for hold in (False, True):
                tr[cov, hold] = orig(obs, r, gap, replace(opts, surprise_cov=cov, withhold=hold), doubt)
        a, b = tr[False, False], tr[True, False]
        assert np.array_equal(a.time_ns, b.time_ns) and np.array_equal(a.position_world, b.position_world)
        err = errors_m(a, truth)
        q = a.quality
        out_a = np.isin(a.time_ns, tr[False, True].time_ns)
        out_b = np.isin(a.time_ns, tr[True, True].time_ns)
        rows.append(dict(rig=rig.name, fps=fps, label=label, misses=misses, t=a.time_ns / 1e9, camera=a.camera,
                         err=err, std_a=q["std_m"], std_b=b.quality["std_m"], nis=q["nis"],
                         jump=q["jump"], rejected=q["rejected"], init=q["init"], gap=q["gap_s"],
                         out_a=out_a, out_b=out_b))
        print(f"{rig.name} {time.time() - t0:.0f} s", flush=True)
        with open(out, "wb") as f:
            pickle.dump(rows, f)


if __name__ == "__main__":
    main()
