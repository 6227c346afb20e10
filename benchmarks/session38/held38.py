# ruff: noqa: E501
"""Issue 10 (session 38): a support whose ray misses, held (docs/methods.md). On one session
(default: ``bench_dirty.py --more --first-seed 52200``'s ``paper3`` ``straight`` with the
faults, bench seed 51904): the ball's candidates rejected as ``motion`` by the gate in both
forms, and whether the stream gate (Python, compiled) gives the causal batch gate's
rejections bit for bit.

    PYTHONPATH=. python benchmarks/session38/held38.py [RIG LABEL FIRST KIND] [--fps F] [--misses M]
"""
import argparse
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session38")
sys.path.insert(0, "tests")
import sessions38 as s
from test_stream_gating import push_frames

from pslog.fusion.gating import MOTION, REASONS, StreamGate, gate


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("args", nargs="*", default=["paper3", "straight", "52200", "faults"])
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    a = ap.parse_args()
    rigname, label, first, kind = a.args
    rig, motion, duration, seed, f, _, span = s.find(rigname, label, int(first), a.fps)
    print(f"{rig.name} {label}: bench seed {seed}, {f}")
    det, _, ball = s.simulate(rig, motion, duration, seed, a.misses, s.kinds(f, span)[kind])
    keys = {(int(t), int(c)): uv for t, c, uv in zip(ball.frame_time_ns[ball.cand_frame], ball.frame_camera[ball.cand_frame], ball.cand_uv, strict=True)}
    for causal in (True, False):
        g = gate(det, rig, causal=causal)
        rej = g.rejections
        ball_motion = [(t / 1e9, rig.names[c]) for t, c, uv, r in zip(rej.frame_time_ns, rej.camera, rej.uv, rej.reason, strict=True)
                       if r == MOTION and (int(t), int(c)) in keys and np.hypot(*(keys[int(t), int(c)] - uv)) < 1e-6]
        print(f"{'causal' if causal else 'offline'}: rejected {dict(zip(*np.unique(np.array(REASONS)[rej.reason], return_counts=True), strict=True))}, "
              f"the ball's as motion {len(ball_motion)}: " + ", ".join(f"{t:.3f} {c}" for t, c in ball_motion))
        if causal:
            for compiled in (False, True):
                st = StreamGate(rig, 0.0, compiled=compiled)
                push_frames(st, det)
                st.flush()
                same = (np.array_equal(st.rejections.reason, rej.reason) and np.array_equal(st.rejections.frame_time_ns, rej.frame_time_ns)
                        and np.array_equal(st.rejections.uv, rej.uv))
                print(f"  stream ({'compiled' if compiled else 'Python'}) = batch: {same}")


if __name__ == "__main__":
    main()
