# ruff: noqa: E501
"""Issue 10 (session 37, scan37): the gate's verdict columns for one camera's candidates in a
time window of a bench_dirty ``--more`` session (``scan_heldout37.py``'s sessions): per
candidate its time, pixel, whether it is the ball's, the support ratios, ``_static``'s
static / stillness / lone, and the reason it was rejected, in the causal (filter) and
offline (smooth) forms.

    PYTHONPATH=. python benchmarks/session37/scan_gate37.py RIG LABEL FIRST KIND CAMERA T0 T1 [--fps F] [--misses M]
"""
import argparse
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session37")
import scan_heldout37 as s

import pslog.fusion.gating as G
from pslog.fusion.gating import REASONS, fuse_detections

_static = G._static
_decided = G._decided
SEEN = {}


def _capture_static(c, tables, rig, options, points, paired=None, compiled=None):
    out = _static(c, tables, rig, options, points, paired, compiled)
    SEEN["static"] = (c, out, paired)
    return out


def _capture_decided(c, rig, options, causal, wait_ns, max_gap_ns, reason, tables=None):
    ratio = _decided(c, rig, options, causal, wait_ns, max_gap_ns, reason, tables)
    SEEN.setdefault("runs", []).append((causal, c, ratio, reason.copy(), SEEN["static"][1], SEEN["static"][2]))
    return ratio


G._static = _capture_static
G._decided = _capture_decided


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("args", nargs=7)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    a = ap.parse_args()
    rigname, label, first, kind, cam, t0, t1 = a.args
    rig, motion, duration, seed, f, _, span = s._find(rigname, label, int(first), a.fps)
    det, _, ball = s.simulate(rig, motion, duration, seed, a.misses, s._kinds(f, span)[kind])
    ci = rig.names.index(cam)
    ball_uv = {(int(t), int(k)): uv for t, k, uv in zip(ball.frame_time_ns[ball.cand_frame], ball.frame_camera[ball.cand_frame], ball.cand_uv, strict=True)}
    SEEN.clear()
    fuse_detections(det, rig, ["filter", "smooth"], s.OPTIONS, workers=1)
    for causal, c, ratio, reason, (static, stillness, lone), paired in SEEN["runs"]:
        print(f"{'causal' if causal else 'offline'} form; {cam} candidates in {t0}-{t1} s:")
        raw_t = det.frame_time_ns[det.cand_frame]
        sel = np.flatnonzero((c.camera == ci) & (c.time_ns / 1e9 >= float(t0)) & (c.time_ns / 1e9 <= float(t1)))
        for i in sel:
            # the candidate's raw row: same camera, nearest raw time, same undistorted order
            j = np.flatnonzero((det.frame_camera[det.cand_frame] == ci) & (np.abs(raw_t - c.time_ns[i]) < 2e6))
            isball = any(np.hypot(*(ball_uv.get((int(raw_t[k]), ci), (np.inf, np.inf)) - det.cand_uv[k])) < 1e-6 and
                         np.hypot(*(rig.cameras[ci].undistort(det.cand_uv[k][None])[0] - c.uv_und[i])) < 1e-3 for k in j) if hasattr(rig.cameras[ci], "undistort") else None
            r = reason[i]
            print(f"  {c.time_ns[i] / 1e9:.4f} uv {np.round(c.uv_und[i], 1).tolist()} ball {isball} ratios {np.round(ratio[i], 2).tolist()} "
                  f"paired {None if paired is None else paired[i]} static {static[i]} stillness {stillness[i]:.2f} lone {lone[i]:.2f} -> {REASONS[r] if r >= 0 else 'kept'}")


if __name__ == "__main__":
    main()
