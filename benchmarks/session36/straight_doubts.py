# ruff: noqa: E501
"""Issue 10 (session 36): every choice in doubt ``smooth`` sees on ``bench_dirty.py
--more``'s dirty sessions (five rigs, ``--seeds 3``), and what the re-admission
(``pslog.fusion.smooth._confirmed``) makes of it: its d² against the fit made without the
choices in doubt (re-admitted at most 18.42) and whether it is the ball's (its pixel within
3 px of the truth's; a false candidate is tens of pixels or more off).

``python benchmarks/session36/straight_doubts.py FIRST [FPS] [MISSES]``: per rig, the
choices in doubt: the ball's re-admitted / left out, the others' re-admitted / left out, the
largest d² of a re-admitted ball and the smallest of a left-out other; and every re-admitted
choice that is not the ball's.

Run from the repository root (PYTHONPATH=.)."""
import sys

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "benchmarks/session36")
sys.path.insert(0, "tests")
import bench_dirty as bd
from straight_object import _d2

import pslog.fusion.smooth as S
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.records import NS
from pslog.simulation import SimulationOptions, simulate_labelled

_orig = S._confirmed
SEEN = []


def _seen(trajectory, obs, rows, rig):
    out = _orig(trajectory, obs, rows, rig)
    SEEN.append((obs, rows, _d2(trajectory, obs, rows, rig), out))
    return out


S._confirmed = _seen


def scan(first, fps=None, misses=0.0):
    for rig in bd.rigs() + bd.more_rigs():
        if fps:
            rig = bd.at_rate(rig, fps)
        counts = np.zeros(4, int)  # ball in, ball out, other in, other out
        outside = np.zeros(2, int)  # ball, other: outside the fitted pieces (no d²)
        out_ball = []  # the d² of the balls left out inside the pieces
        worst_ball, least_other, notes = 0.0, np.inf, []
        for seed, (label, motion, duration, _) in enumerate(bd.more_sessions(3, 8.0, first), start=first - 300):
            span = motion.duration if duration is None else duration
            f = bd.faults(rig, seed, span)
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2, **f))
            SEEN.clear()
            fuse_detections(det, rig, ["smooth"], FusionOptions(), workers=1)
            for obs, rows, d2, out in SEEN:
                for r, d, ok in zip(rows, d2, out, strict=True):
                    t = obs.time_ns[r]
                    cam = rig.cameras[obs.camera[r]]
                    uv = cam.project(truth.at(np.array([t])))[0][0]
                    ball = np.linalg.norm(obs.uv[r] - uv) < 3.0
                    counts[(0 if ball else 2) + (0 if ok else 1)] += 1
                    if not np.isfinite(d):
                        outside[0 if ball else 1] += 1
                    elif ball and not ok:
                        out_ball.append(d)
                    if ball and ok:
                        worst_ball = max(worst_ball, d)
                    if not ball:
                        least_other = min(least_other, d)
                        if ok:
                            notes.append(f"{label} t {t / NS:.3f} {rig.names[obs.camera[r]]} d² {d:.1f} {np.linalg.norm(obs.uv[r] - uv):.1f} px off")
        print(f"{rig.name}: ball readmitted {counts[0]}, left out {counts[1]}; others readmitted {counts[2]}, left out {counts[3]}; "
              f"largest d² of a readmitted ball {worst_ball:.2f}, smallest of another {least_other:.1f}; outside the pieces: balls {outside[0]}, others {outside[1]}; "
              f"d² of the balls left out inside {np.round(sorted(out_ball), 1).tolist()}", flush=True)
        for n in notes:
            print("   NOT THE BALL, readmitted:", n)


if __name__ == "__main__":
    scan(int(sys.argv[1]), float(sys.argv[2]) if len(sys.argv) > 2 and float(sys.argv[2]) else None,
         float(sys.argv[3]) if len(sys.argv) > 3 else 0.0)
