# ruff: noqa: E501
"""Issue 10 (session 38): bench_dirty ``--more``'s sessions one at a time, clean and with the
faults, for a before/after diff of a gate change: per session, kind and method, the points
output, their mean error (mm), the points beyond 5 cm, a hash of the track (time, camera,
position bits), and the ball's own candidates the gate rejected as ``motion`` (causal:
filter's gate, offline: smooth's).

    PYTHONPATH=. python benchmarks/session38/scan38.py FIRST [--fps F] [--misses M] > out.txt
    diff before.txt after.txt
"""
import argparse
import hashlib
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session38")
import sessions38 as s

from pslog.evaluation import errors_m
from pslog.fusion.gating import MOTION, fuse_detections

METHODS = ["typeA", "smooth", "filter"]


def ball_motion(ball, rej) -> int:
    keys = {(int(t), int(c)): uv for t, c, uv in zip(ball.frame_time_ns[ball.cand_frame], ball.frame_camera[ball.cand_frame], ball.cand_uv, strict=True)}
    n = 0
    for t, c, uv, r in zip(rej.frame_time_ns, rej.camera, rej.uv, rej.reason, strict=True):
        k = (int(t), int(c))
        n += int(r == MOTION and k in keys and np.hypot(*(keys[k] - uv)) < 1e-6)
    return n


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    a = ap.parse_args()
    for rig in s.all_rigs(a.fps):
        for seed, (label, motion, duration, _) in s.sessions_of(a.first):
            span = motion.duration if duration is None else duration
            f = s.bd.faults(rig, seed, span)
            for kind in ("clean", "faults"):
                det, truth, ball = s.simulate(rig, motion, duration, seed, a.misses, s.kinds(f, span)[kind])
                tracks, rej = fuse_detections(det, rig, METHODS, s.OPTIONS, workers=1)
                for m in METHODS:
                    tr = tracks[m]
                    e = errors_m(tr, truth)
                    h = hashlib.sha1(tr.time_ns.tobytes() + tr.camera.tobytes() + np.ascontiguousarray(tr.position_world).tobytes()).hexdigest()[:10]
                    motion_n = ball_motion(ball, rej[m]) if m in rej and rej[m] is not None else -1
                    print(f"{rig.name} {label} {kind} {m}: points {len(tr)} mean {1e3 * np.nanmean(e):.3f} far {int(np.count_nonzero(e > 0.05))} "
                          f"ball-motion {motion_n} hash {h}", flush=True)


if __name__ == "__main__":
    main()
