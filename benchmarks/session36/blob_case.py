# ruff: noqa: E501
"""Issue 10 (session 36, diagnosis): ``wide3`` rally-46100 with bench_dirty's faults, the
spurious blob ``smooth`` bends to (docs/methods.md, "A spurious blob the fit bends to"):
smooth's far points, each false detection the fit kept, its residual, its leverage (the 2 x 2
hat block ``A = w J Σ Jᵀ / σ²``) and its deleted residual statistic
``rᵀ (I - A)⁻¹ r / σ²`` (the residual against the fit without it, studentized).

    PYTHONPATH=. python benchmarks/session36/blob_case.py [FIRST] [RIG] [--index K] [--fps F]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

FITS = []


def _capture():
    """Keep every Fit smooth makes (its ``deleted`` statistic is no track column)."""
    import pslog.estimation as est

    inner = est.fit_trajectory

    def fit(obs, rig, options=None, **kw):
        out = inner(obs, rig, options, **kw)
        FITS.append((obs, out))
        return out
    est.fit_trajectory = fit


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int, nargs="?", default=46100)
    ap.add_argument("rig", nargs="?", default="wide3")
    ap.add_argument("--index", type=int, default=0)
    ap.add_argument("--fps", type=float, default=None)
    a = ap.parse_args()
    _capture()
    rig = next(r for r in rigs() + more_rigs() if r.name == a.rig)
    if a.fps:
        rig = at_rate(rig, a.fps)
    label, motion, duration, _ = more_sessions(3, 8.0, a.first)[a.index]
    seed = a.first - 300 + a.index
    span = motion.duration if duration is None else duration
    f = faults(rig, seed, span)
    print(label, "faults", f)
    for kind, extra in (("clean", {}), ("dirty", f)):
        det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, **extra))
        tr = fuse_detections(det, rig, ["smooth"], FusionOptions(), workers=1)[0]["smooth"]
        err = errors_m(tr, truth)
        q = tr.quality
        print(f"{kind}: {len(tr)} points, mean {1e3 * np.nanmean(err):.3f} mm, >5cm {int(np.sum(err > 0.05))}, rejected {int(np.nansum(q['rejected']))}")
        obs, fit = FITS[-1]
        d2 = np.where(fit.excluded, np.inf, 0.0) if fit.excluded is not None else np.zeros(len(obs))
        top = np.argsort(np.nan_to_num(d2))[::-1][:8]
        print("   largest d² (deleted residual statistic; level 18.42):")
        for j in top:
            print(f"     t={obs.time_ns[j] / 1e9:.4f} {rig.names[obs.camera[j]]} d² {d2[j]:.1f} res {fit.residual_px[j] / fit.trajectory.noise_px:.2f} σ w {fit.weight[j]:.2f} uv {obs.uv[j].round(1)}")
        print(f"   rows with d² > 18.42: {int(np.sum(d2 > 18.42))}, with res > 4.29 σ: {int(np.sum(fit.rejected))} of {int(fit.used.sum())}")
        for i in np.flatnonzero(err > 0.03):
            print(f"   t={tr.time_ns[i] / 1e9:.4f} {rig.names[tr.camera[i]]} err {1e3 * err[i]:.1f} mm std {1e3 * q['std_m'][i]:.1f} res {q['residual_px'][i]:.2f} px rej {q['rejected'][i]:.0f}")


if __name__ == "__main__":
    main()
