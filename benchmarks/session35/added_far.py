# ruff: noqa: E501
"""Issue 10 (session 35, diagnosis): type A's points beyond 5 cm that bench_dirty's faults
add (the clean session's point at that detection within 5 cm or absent), on ``--more``'s
sessions of one rig: when, which camera, the blackout, whether the detection is the ball's.

    PYTHONPATH=. python benchmarks/session35/added_far.py FIRST RIG [--confirm-gaps kicks]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "benchmarks" / "session28"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import faults, more_rigs, more_sessions, rigs  # noqa: E402
from farpoints import jumps  # noqa: E402

from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, confirm_choice  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int)
    ap.add_argument("rig")
    ap.add_argument("--confirm-gaps", default="kicks")
    ap.add_argument("--seeds", type=int, default=3)
    a = ap.parse_args()
    opt = FusionOptions(**confirm_choice(a.confirm_gaps))
    rig = next(r for r in rigs() + more_rigs() if r.name == a.rig)
    for seed, (label, motion, duration, _k) in enumerate(more_sessions(a.seeds, 8.0, a.first), start=a.first - 300):
        span = motion.duration if duration is None else duration
        kicks = jumps(motion, span)
        f = faults(rig, seed, span)
        tr = {}
        for kind, extra in (("clean", {}), ("dirty", f)):
            det, truth, _labels = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, **extra))
            tr[kind] = fuse_detections(det, rig, ["typeA"], opt, workers=1)[0]["typeA"]
            err = errors_m(tr[kind], truth)
            tr[kind + "_err"] = err
        clean_far = {k for k, x in zip(zip(tr["clean"].time_ns.tolist(), tr["clean"].camera.tolist(), strict=True), tr["clean_err"], strict=True) if x > 0.05}
        bo = f["blackouts"][0]
        for i in np.flatnonzero(tr["dirty_err"] > 0.05):
            key = (int(tr["dirty"].time_ns[i]), int(tr["dirty"].camera[i]))
            if key in clean_far:
                continue
            t = key[0] / 1e9
            before = kicks[kicks <= t]
            q = tr["dirty"].quality
            print(f"{label} t={t:.4f} {rig.names[key[1]]} err {1e3 * tr['dirty_err'][i]:.0f} mm std {1e3 * q['std_m'][i]:.1f} mm; "
                  f"blackout {bo[0]} {bo[1]:.2f}-{bo[1] + bo[2]:.2f} s; distractor {f['distractors'][0][0]}; "
                  f"{1e3 * (t - before[-1]) if len(before) else float('nan'):.0f} ms after a jump; in clean: {key in {(int(a_), int(b_)) for a_, b_ in zip(tr['clean'].time_ns, tr['clean'].camera, strict=True)}}; "
                  f"gap {q['gap_s'][i] * 1e3 if 'gap_s' in q else float('nan'):.0f} ms; cams {q.get('cameras', [None] * len(q['std_m']))[i] if 'cameras' in q else ''}")


if __name__ == "__main__":
    main()
