# ruff: noqa: E501
"""Issue 10 (session 33, diagnosis): the far points (> 5 cm) ``confirm_sides`` keeps on
bench_dirty ``--more``'s clean sessions, with each camera's quantities in
:func:`pslog.fusion.confirm.sides_test` (jump shown, the side, the residual against the
side's line and its bound, the distances to both lines).

    PYTHONPATH=. python benchmarks/session33/sides_diag.py FIRST [--fps 60] [--misses 0.1]
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
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

CAPTURED = []
_orig_sides = confirm.sides_test
_orig_res = confirm.residual_test
RES = []


def _spy_sides(*a):
    CAPTURED.append(a)
    return _orig_sides(*a)


def _spy_res(rows, cam, point, cov, t_ns, a_ns, b_ns, ua, ub, gap_s, span_s, sigma, noise_px):
    out = _orig_res(rows, cam, point, cov, t_ns, a_ns, b_ns, ua, ub, gap_s, span_s, sigma, noise_px)
    RES.append((cam.copy(), t_ns.copy(), a_ns.copy(), b_ns.copy(), ua.copy(), ub.copy(), point.copy(), out.copy(), sigma.copy()))
    return out


confirm.sides_test = _spy_sides
confirm.residual_test = _spy_res


def project(r, P):
    R = r[5:14].reshape(3, 3)
    X = R @ P + r[14:17]
    return np.array([r[0] * X[0] / X[2] + r[1] * X[1] / X[2] + r[2], r[3] * X[1] / X[2] + r[4]])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    a = ap.parse_args()
    opt = FusionOptions(confirm_every=True, confirm_sides=True)
    for base in rigs() + more_rigs():
        rig = base if a.fps is None else at_rate(base, a.fps)
        for seed, (label, motion, duration, _k) in enumerate(more_sessions(3, 8.0, a.first), start=a.first - 300):
            span = motion.duration if duration is None else duration
            kicks = jumps(motion, span)
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=seed, miss_rate=a.misses, drop_rate=a.misses / 2))
            RES.clear()
            tr = fuse(det, rig, "typeA", opt)
            err = errors_m(tr, truth)
            for i in np.flatnonzero(err > 0.05):
                t = int(tr.time_ns[i])
                before = kicks[kicks < t / 1e9 + 1e-9]
                k = before[-1] if len(before) else np.nan
                ptrue = motion.position(np.array([t / 1e9]))[0]
                print(f"{rig.name} {label} t={t / 1e9:.4f} cam{tr.camera[i]} err {1e3 * err[i]:.0f} mm, {1e3 * (t / 1e9 - k):.1f} ms after kick; std_m {1e3 * tr.quality['std_m'][i]:.1f} mm")
                rows = confirm._camera_rows(rig)
                for cam, tn, an, bn, ua, ub, pt, out, sig in RES[1:]:
                    for j in np.flatnonzero(tn == t):
                        c = cam[j]
                        w = (t - an[j]) / (bn[j] - an[j])
                        ref = (1 - w) * ua[j] + w * ub[j]
                        u = project(rows[c], pt[j])
                        utrue = project(rows[c], ptrue)
                        print(f"    cam{c} pair {1e3 * (an[j] / 1e9 - k):+.1f} {1e3 * (bn[j] / 1e9 - k):+.1f} ms from kick, w {w:+.2f}: res {np.linalg.norm(u - ref):.2f} px (truth's {np.linalg.norm(utrue - ref):.2f}, point-truth {np.linalg.norm(u - utrue):.2f}), sigma {sig[j]:.2f} -> {out[j]}")
            sys.stdout.flush()


if __name__ == "__main__":
    main()
