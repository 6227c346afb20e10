"""Session 37 (start37): the stream's per-frame cost of the unmoved-start doubt.
``StreamFuser(paper3, METHOD, candidates=True).push_frame`` over a dirty 4 s rally (the
library's, 0.3 px, 5 % spurious blobs, a static object every camera sees, 2 % misses),
CPU time per push: median and p99 over the frames, best of three passes. Run with the tree
to measure on PYTHONPATH (before / after).

    python benchmarks/session37/start_latency.py [filter]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from pslog.fusion import FusionOptions
from pslog.fusion.stream import StreamFuser
from pslog.motion import get_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled


def main() -> None:
    method = sys.argv[1] if len(sys.argv) > 1 else "filter"
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, _, _ = simulate_labelled(rig, get_motion("rally"), 4.0, SimulationOptions(
        noise_px=0.3, seed=50400, spurious_rate=0.05, miss_rate=0.02,
        distractors=((None, (1.0, 2.0, 0.1)),)))
    starts = np.flatnonzero(np.r_[True, np.diff(det.cand_frame) != 0])
    ends = np.r_[starts[1:], det.n_candidates]
    frames = [(int(det.frame_time_ns[det.cand_frame[lo]]),
               int(det.frame_camera[det.cand_frame[lo]]), det.cand_uv[lo:hi].copy(),
               int(det.frame_index[det.cand_frame[lo]]))
              for lo, hi in zip(starts, ends, strict=True)]
    best = None
    for _ in range(3):
        fuser = StreamFuser(rig, method, FusionOptions(), candidates=True)
        cost = []
        for t, c, uv, i in frames:
            t0 = time.process_time_ns()
            fuser.push_frame(t, c, uv, i)
            cost.append(time.process_time_ns() - t0)
        fuser.flush()
        cost = np.array(cost) / 1e3
        row = (float(np.median(cost)), float(np.percentile(cost, 99)))
        best = row if best is None or row[0] < best[0] else best
    print(f"{method}: {len(frames)} frames, CPU per push_frame median {best[0]:.1f} us, "
          f"p99 {best[1]:.1f} us")


if __name__ == "__main__":
    main()
