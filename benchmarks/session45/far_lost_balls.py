"""Session 45: the ball detections the offline gate (`smooth`'s form) keeps in a clean
session of ``bench_dirty.py --more`` and rejects with the faults (not those the blackout
removed), per rig, and how many of
them lie within 45 ms of another camera's frame that is empty clean and holds only rejected
candidates with the faults (rally-79906's case: docs/methods.md, "Held out (session 45, ...
79900 ..."): a co-occurrence, an upper bound of what a gate rule carrying such a frame as
empty could give back, not a count of its effect. Each such detection is listed (the
"blackout cam" tag: the camera the faults blind for 0.5 s, not necessarily then).

    PYTHONPATH=.:tests python benchmarks/session45/far_lost_balls.py FIRST MISSES SEEDS
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
import bench_dirty as bd  # noqa: E402

from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s  # noqa: E402
from pslog.fusion.gating import gate_for  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

NEAR_NS = 45_000_000


def _gated(rig, motion, duration, seed, misses, extra, options):
    """(the ball's kept candidates' (camera, frame index), its candidates' (every one),
    frame -> (time ns, candidates, kept))."""
    det, _, ball = simulate_labelled(rig, motion, duration, SimulationOptions(
        noise_px=bd.TARGET_NOISE, seed=seed, miss_rate=misses, drop_rate=misses / 2, **extra))
    gated = gate_for(det, rig, "smooth", options)
    balls = {(int(ball.frame_camera[f]), int(ball.frame_index[f])): ball.cand_uv[k]
             for k, f in enumerate(ball.cand_frame)}
    keys = [(int(det.frame_camera[f]), int(det.frame_index[f])) for f in det.cand_frame]
    kept = {key for i, key in enumerate(keys)
            if gated.reason[i] < 0 and key in balls and np.allclose(balls[key], det.cand_uv[i])}
    n = np.bincount(det.cand_frame, minlength=det.n_frames)
    n_kept = np.bincount(det.cand_frame[gated.reason < 0], minlength=det.n_frames)
    frames = {(int(det.frame_camera[f]), int(det.frame_index[f])):
              (int(det.frame_time_ns[f]), int(n[f]), int(n_kept[f]))
              for f in range(det.n_frames)}
    return kept, set(balls), frames


def main() -> None:
    first, misses, seeds = int(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
    runs = bd.more_sessions(seeds, 8.0, first)
    total = [0, 0]
    for rig in bd.rigs() + bd.more_rigs():
        options = replace(FusionOptions(gating=True), max_gap_s=default_max_gap_s(rig))
        lost_n = beside_n = 0
        for seed, (label, motion, duration, _) in enumerate(runs, start=first - 300):
            fault = bd.faults(rig, seed, motion.duration if duration is None else duration)
            kept_clean, _, clean = _gated(rig, motion, duration, seed, misses, {}, options)
            kept_dirty, seen, dirty = _gated(rig, motion, duration, seed, misses, fault, options)
            blind = rig.names.index(fault["blackouts"][0][0])
            for cam, index in sorted((kept_clean & seen) - kept_dirty):
                t = dirty[(cam, index)][0]
                beside = any(key[0] != cam and abs(tt - t) <= NEAR_NS and n > 0 and k == 0
                             and clean.get(key, (0, 0, 0))[1] == 0
                             for key, (tt, n, k) in dirty.items())
                lost_n += 1
                beside_n += beside
                if beside:
                    print(f"  {rig.name} {label} camera {cam} {t / 1e9:.4f} s"
                          + (" (blackout cam)" if cam == blind else ""))
        print(f"{rig.name}: ball detections kept clean, rejected with the faults {lost_n}; "
              f"beside another camera's frame empty clean, all rejected with the faults "
              f"(within 45 ms): {beside_n}", flush=True)
        total[0] += lost_n
        total[1] += beside_n
    print(f"all rigs: {total[0]}, beside {total[1]}")


if __name__ == "__main__":
    main()
