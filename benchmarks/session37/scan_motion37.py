# ruff: noqa: E501
"""Issue 10 (session 37, scan37): how often the gate rejects the ball's own detections as
``motion`` in bench_dirty ``--more``'s dirty sessions (``--seeds 3``), against the same
session with the blackout alone and the clean one: per rig, summed over the sessions, in
the causal (filter) and offline (smooth) forms; the sessions with 3 or more such
rejections beyond the blackout alone's are listed with their times.

    PYTHONPATH=. python benchmarks/session37/scan_motion37.py FIRST [--fps F] [--misses M]
"""
import argparse
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session37")
import scan_heldout37 as s

from pslog.fusion.gating import MOTION, fuse_detections


def ball_motion(det, ball, rej):
    """Times and cameras of the ball's own candidates ``rej`` rejected as ``motion``."""
    keys = {(int(t), int(c)): uv for t, c, uv in zip(ball.frame_time_ns[ball.cand_frame], ball.frame_camera[ball.cand_frame], ball.cand_uv, strict=True)}
    out = []
    for t, c, uv, r in zip(rej.frame_time_ns, rej.camera, rej.uv, rej.reason, strict=True):
        k = (int(t), int(c))
        if r == MOTION and k in keys and np.hypot(*(keys[k] - uv)) < 1e-6:
            out.append((t / 1e9, int(c)))
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    a = ap.parse_args()
    for rig in s.all_rigs(a.fps):
        total = {}
        for seed, (label, motion, duration, _) in s.sessions_of(a.first):
            span = motion.duration if duration is None else duration
            f = s.bd.faults(rig, seed, span)
            got = {}
            for kind in ("clean", "blackout", "faults"):
                det, _, ball = s.simulate(rig, motion, duration, seed, a.misses, s._kinds(f, span)[kind])
                rej = fuse_detections(det, rig, ["filter", "smooth"], s.OPTIONS, workers=1)[1]
                for m in ("filter", "smooth"):
                    got[kind, m] = ball_motion(det, ball, rej[m])
                    total[kind, m] = total.get((kind, m), 0) + len(got[kind, m])
            for m in ("filter", "smooth"):
                extra = len(got["faults", m]) - len(got["blackout", m])
                if extra >= 3:
                    print(f"  {rig.name} {label} {m}: the ball's motion rejections clean {len(got['clean', m])}, blackout alone {len(got['blackout', m])}, faults {len(got['faults', m])}: "
                          + ", ".join(f"{t:.3f} {rig.names[c]}" for t, c in got["faults", m][:12]) + f" ({f})", flush=True)
        print(f"{rig.name}: the ball's motion rejections (causal / offline), clean {total['clean', 'filter']} / {total['clean', 'smooth']}, "
              f"blackout alone {total['blackout', 'filter']} / {total['blackout', 'smooth']}, faults {total['faults', 'filter']} / {total['faults', 'smooth']}", flush=True)


if __name__ == "__main__":
    main()
