"""Session 45: type A's points beyond 5 cm under the default (``--confirm-gaps jumps``) in
``bench_dirty.py --more``'s clean sessions (0.3 px, misses as given), each with its time,
camera, error, time since the last kick and quality columns.

    PYTHONPATH=.:tests python benchmarks/session45/type_a_far.py FIRST_SEED MISSES SEEDS
"""

import sys
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1]),
                str(Path(__file__).resolve().parents[2] / "tests")]
import bench_dirty as bd  # noqa: E402

from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, confirm_choice, offline_confirmation  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

first, misses, seeds = int(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
runs = bd.more_sessions(seeds, 8.0, first)
options = offline_confirmation(FusionOptions(gating=True, **confirm_choice("jumps")))
for rig in bd.rigs() + bd.more_rigs():
    for seed, (label, motion, duration, kicks) in enumerate(runs, start=first - 300):
        det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
            noise_px=bd.TARGET_NOISE, seed=seed, miss_rate=misses, drop_rate=misses / 2))
        tr = fuse_detections(det, rig, ["typeA"], options)[0]["typeA"]
        err = errors_m(tr, truth)
        for i in np.flatnonzero(err > 0.05):
            q = {k: float(v[i]) for k, v in tr.quality.items()
                 if k in ("std_m", "span_s", "gap_s", "ray_angle_deg", "snap_px", "ray_miss_m")}
            t = tr.time_ns[i] / 1e9
            kk = np.asarray(kicks) if kicks is not None else np.zeros(0)
            dk = (t - kk[kk <= t].max()) if np.any(kk <= t) else np.nan
            print(rig.name, label, f"t={t:.4f} cam={tr.camera[i]} err={err[i] * 1e3:.1f}mm "
                  f"since_kick={dk * 1e3:.1f}ms", {k: round(v, 5) for k, v in q.items()})
