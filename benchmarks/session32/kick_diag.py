# ruff: noqa: E501
"""Issue 10 (session 32, diagnosis): type A's normalised innovation after the gravity
term, ``nu = sqrt(|u|^2 / (sigma^2 c))`` (the kernel's ``_model_across_m2`` over
``sigma^2 _model_m2_per_px2``, sigma :func:`pslog.fusion.confirm.confirm_noise`), for the
points made (before the confirmation), far (> 5 cm) or good, on bench_dirty ``--more``'s
clean sessions: how well a lower innovation threshold separates the far points.

    PYTHONPATH=. python benchmarks/session32/kick_diag.py FIRST [--fps 60] [--misses 0.1]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, fuse  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s, rays_only  # noqa: E402
from pslog.fusion.confirm import confirm_noise  # noqa: E402
from pslog.fusion.gating import gate_for, prepared_for  # noqa: E402
from pslog.fusion.pseudo import _fuse_type_a, covariance_noise_px  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    a = ap.parse_args()
    options = FusionOptions()
    nus, errs, snaps, kept, suspects = [], [], [], [], []
    for base in rigs() + more_rigs():
        rig = base if a.fps is None else at_rate(base, a.fps)
        for seed, (_label, motion, duration, _kicks) in enumerate(more_sessions(3, 8.0, a.first), start=a.first - 300):
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=seed, miss_rate=a.misses, drop_rate=a.misses / 2))
            prep = rays_only(prepared_for(gate_for(det, rig, "typeA", options), rig))[0]
            gap = default_max_gap_s(rig)
            tr = _fuse_type_a(prep, gap, options.noise_px, None, None, None, False,
                              covariance_noise_px(options.noise_px), None)[0]
            q = tr.quality
            s = confirm_noise(q["snap_px"], options.noise_px)
            nus.append(np.sqrt(q["_model_across_m2"] / (s * s * q["_model_m2_per_px2"])))
            snaps.append(q["snap_px"] / (s * np.sqrt(1.5)))
            # per point: was the point of each of the previous two rows refused (no point,
            # the row not among the session's first 6) or over 3 sigma in innovation
            nu_t = np.sqrt(q["_model_across_m2"] / (s * s * q["_model_m2_per_px2"]))
            point_of = {(int(t), int(c)): i for i, (t, c) in enumerate(zip(tr.time_ns, tr.camera, strict=True))}
            obs = prep.obs
            row_of = {(int(t), int(c)): r for r, (t, c) in enumerate(zip(obs.time_ns, obs.camera, strict=True))}
            sus = np.zeros(len(tr), bool)
            for i, (t, c) in enumerate(zip(tr.time_ns.tolist(), tr.camera.tolist(), strict=True)):
                r = row_of[(t, c)]
                for back in (1, 2):
                    rr = r - back
                    if rr < 6:
                        continue
                    j = point_of.get((int(obs.time_ns[rr]), int(obs.camera[rr])))
                    if j is None or nu_t[j] > 3.0:
                        sus[i] = True
            suspects.append(sus)
            errs.append(errors_m(tr, truth))
            final = fuse(det, rig, "typeA", options)
            kept.append(np.isin(tr.time_ns * 256 + tr.camera, final.time_ns * 256 + final.camera))
    nu, err = np.concatenate(nus), np.concatenate(errs)
    zs, kept = np.concatenate(snaps), np.concatenate(kept)
    far = err > 0.05
    left = far & kept
    print(f"far left after the pipeline {left.sum()}: (nu, snap z)",
          [(round(float(x), 1), round(float(y), 1)) for x, y in zip(nu[left], zs[left], strict=True)])
    sus = np.concatenate(suspects)
    print(f"previous two rows suspect: {sus.sum()} ({100 * sus.mean():.2f} %), far left among them {np.sum(sus & left)}/{left.sum()}, far left with nu<=3 among them {np.sum(sus & left & (nu <= 3))}")
    for k in (2.0, 2.5, 3.0, 3.5):
        w = zs > k
        print(f"snap z>{k}: {w.sum()} ({100 * w.mean():.2f} %), far left among them {np.sum(w & left)}/{left.sum()}")
    print(f"points {len(nu)}, far {far.sum()}")
    print("far nu:", np.round(np.sort(nu[far]), 1).tolist())
    for k in (2.0, 2.5, 3.0, 3.5, 4.0, 5.0):
        w = nu > k
        print(f"k={k}: wait {w.sum()} ({100 * w.mean():.2f} %), far among them {np.sum(w & far)}/{far.sum()}, good 10-50mm among them {np.sum(w & (err > 0.01) & ~far)}")


if __name__ == "__main__":
    main()
