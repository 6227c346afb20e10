# ruff: noqa: E501
"""Issue 10 (session 33, diagnosis): type A's far points (> 5 cm) left by ``confirm_every``
on bench_dirty ``--more``'s clean sessions, and where the confirming camera's bracket
[prev, next] lies against the truth's velocity jumps.

    PYTHONPATH=. python benchmarks/session33/far_diag.py FIRST [--fps 60] [--misses 0.1]
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
from bench_dirty import at_rate, more_rigs, more_sessions, rigs  # noqa: E402
from farpoints import jumps  # noqa: E402

import pslog.fusion.confirm as confirm  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, fuse  # noqa: E402

CAPTURED = []
_orig = confirm.residual_test


def _spy(rows, cam, point, cov, t_ns, prev_ns, next_ns, *a, **k):
    out = _orig(rows, cam, point, cov, t_ns, prev_ns, next_ns, *a, **k)
    CAPTURED.append((t_ns.copy(), cam.copy(), prev_ns.copy(), next_ns.copy(), out.copy()))
    return out


confirm.residual_test = _spy


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    a = ap.parse_args()
    opt = FusionOptions(confirm_every=True)
    for base in rigs() + more_rigs():
        rig = base if a.fps is None else at_rate(base, a.fps)
        for seed, (label, motion, duration, _k) in enumerate(more_sessions(3, 8.0, a.first), start=a.first - 300):
            span = motion.duration if duration is None else duration
            kicks = jumps(motion, span)
            from pslog.simulation import SimulationOptions, simulate_labelled
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=seed, miss_rate=a.misses, drop_rate=a.misses / 2))
            CAPTURED.clear()
            tr = fuse(det, rig, "typeA", opt)
            err = errors_m(tr, truth)
            tested = {}
            for t_ns, cam, pv, nx, out in CAPTURED:
                for i in range(len(t_ns)):
                    tested[int(t_ns[i])] = (int(cam[i]), int(pv[i]), int(nx[i]), bool(out[i]))
            for i in np.flatnonzero(err > 0.05):
                t = int(tr.time_ns[i])
                before = kicks[kicks < t / 1e9 + 1e-9]
                k = before[-1] if len(before) else np.nan
                info = tested.get(t)
                if info is None:
                    s = "untested"
                else:
                    c, pv, nx, o = info
                    s = f"cam{c} prev {1e3 * (pv / 1e9 - k):+.1f} next {1e3 * (nx / 1e9 - k):+.1f} ms from kick, contradicted {o}"
                print(f"{rig.name} {label} t={t / 1e9:.4f} cam{tr.camera[i]} err {1e3 * err[i]:.0f} mm, {1e3 * (t / 1e9 - k):.1f} ms after kick; {s}", flush=True)


if __name__ == "__main__":
    main()
