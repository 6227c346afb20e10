# ruff: noqa: E501
"""Issue 10 (session 36): what ``smooth``'s deletion test leaves out of the fit
(:attr:`pslog.estimation.Fit.excluded`) on ``bench_dirty.py --more``'s sessions, clean and
with the faults: fitted detections, left out, of them the ball's (the frame's ball candidate)
and false ones, each left-out row listed (rig, session, time, camera, its point's error).

    PYTHONPATH=. python benchmarks/session36/left_out.py FIRST[,FIRST...] [--fps 60] [--misses 0.1] [--noise 0.3]
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
    """Keep every Fit smooth makes (which rows it left out is no track column)."""
    import pslog.estimation as est

    inner = est.fit_trajectory

    def fit(obs, rig, options=None, **kw):
        out = inner(obs, rig, options, **kw)
        FITS.append((obs, out))
        return out
    est.fit_trajectory = fit


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first")
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    ap.add_argument("--noise", type=float, default=0.3)
    a = ap.parse_args()
    _capture()
    total = {k: [0, 0, 0, 0, 0] for k in ("clean", "dirty")}  # fitted, left out, ball, false, flagged
    for first in (int(x) for x in a.first.split(",")):
        for rig in rigs() + more_rigs():
            if a.fps:
                rig = at_rate(rig, a.fps)
            for seed, (label, motion, duration, _) in enumerate(more_sessions(3, 8.0, first), start=first - 300):
                span = motion.duration if duration is None else duration
                for kind, extra in (("clean", {}), ("dirty", faults(rig, seed, span))):
                    det, truth, ball = simulate_labelled(rig, motion, duration, SimulationOptions(
                        noise_px=a.noise, seed=seed, miss_rate=a.misses, drop_rate=a.misses / 2, **extra))
                    tr = fuse_detections(det, rig, ["smooth"], FusionOptions(), workers=1)[0]["smooth"]
                    obs, fit = FITS[-1]
                    b = ball.best()
                    key = {(int(t), int(c)): uv for t, c, uv in zip(b.time_ns, b.camera, b.uv, strict=True)}
                    is_ball = np.array([(int(t), int(c)) in key and np.allclose(key[int(t), int(c)], uv)
                                        for t, c, uv in zip(obs.time_ns, obs.camera, obs.uv, strict=True)])
                    ex = fit.excluded if fit.excluded is not None else np.zeros(len(obs), bool)
                    row = total[kind]
                    row[0] += int(fit.used.sum())
                    row[1] += int(ex.sum())
                    row[2] += int((ex & is_ball).sum())
                    row[3] += int((ex & ~is_ball).sum())
                    row[4] += int(fit.rejected.sum())
                    if ex.any():
                        err = errors_m(tr, truth)
                        at = {(int(t), int(c)): e for t, c, e in zip(tr.time_ns, tr.camera, err, strict=True)}
                        for i in np.flatnonzero(ex):
                            e = at.get((int(obs.time_ns[i]), int(obs.camera[i])), np.nan)
                            print(f"  {first} {rig.name} {label} {kind}: t={obs.time_ns[i] / 1e9:.4f} {rig.names[obs.camera[i]]} "
                                  f"{'ball' if is_ball[i] else 'FALSE'} residual {fit.residual_px[i]:.1f} px ({fit.residual_px[i] / fit.trajectory.noise_px:.1f} σ), point {1e3 * e:.1f} mm off", flush=True)
    for kind, (n, out, b, f, flagged) in total.items():
        print(f"{kind}: {n} detections fitted, {out} left out ({b} the ball's, {f} false); {flagged} flagged rejected in all")


if __name__ == "__main__":
    main()
