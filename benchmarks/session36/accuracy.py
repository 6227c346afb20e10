# ruff: noqa: E501
"""Issue 10 (session 36): ``smooth``'s accuracy per session on ``bench_dirty.py --more``'s
rigs and rallies, as JSON, to compare two trees (the deletion test's before and after):
mean, max error (mm), points beyond 5 cm, points output, rows flagged ``rejected``.

    PYTHONPATH=<tree> python benchmarks/session36/accuracy.py OUT.json FIRST[,FIRST] [--duration 20] [--noise 1] [--fps 60] [--misses 0.1] [--kinds clean,dirty]
    python benchmarks/session36/accuracy.py --compare BEFORE.json AFTER.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))


def measure(a) -> dict:
    from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs

    from pslog.evaluation import errors_m
    from pslog.fusion import FusionOptions
    from pslog.fusion.gating import fuse_detections
    from pslog.simulation import SimulationOptions, simulate_labelled

    out = {}
    for first in (int(x) for x in a.first.split(",")):
        for rig in rigs() + more_rigs():
            if a.fps:
                rig = at_rate(rig, a.fps)
            runs = more_sessions(3, a.duration, first)[:3]  # the rallies
            for seed, (label, motion, duration, _) in enumerate(runs, start=first - 300):
                span = motion.duration if duration is None else duration
                for kind in a.kinds.split(","):
                    extra = faults(rig, seed, span) if kind == "dirty" else {}
                    det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                        noise_px=a.noise, seed=seed, miss_rate=a.misses, drop_rate=a.misses / 2, **extra))
                    tr = fuse_detections(det, rig, ["smooth"], FusionOptions(), workers=1)[0]["smooth"]
                    err = errors_m(tr, truth)
                    err = err[np.isfinite(err)]
                    out[f"{rig.name} {label} {kind}"] = {
                        "mean_mm": 1e3 * float(err.mean()), "max_mm": 1e3 * float(err.max()),
                        "far": int(np.sum(err > 0.05)), "points": len(tr),
                        "rejected": int(np.nansum(tr.quality["rejected"]))}
    return out


def compare(before: dict, after: dict) -> None:
    changed = [k for k in before if before[k] != after.get(k)]
    print(f"{len(before)} sessions, {len(changed)} changed")
    for k in changed:
        b, c = before[k], after[k]
        print(f"  {k}: mean {b['mean_mm']:.4f} -> {c['mean_mm']:.4f} mm, max {b['max_mm']:.1f} -> {c['max_mm']:.1f}, "
              f">5cm {b['far']} -> {c['far']}, points {b['points']} -> {c['points']}, rejected {b['rejected']} -> {c['rejected']}")
    for kind in ("clean", "dirty"):
        keys = [k for k in before if k.endswith(kind)]
        if keys:
            mb = np.mean([before[k]["mean_mm"] for k in keys])
            ma = np.mean([after[k]["mean_mm"] for k in keys])
            print(f"{kind}: mean of session means {mb:.4f} -> {ma:.4f} mm; >5cm {sum(before[k]['far'] for k in keys)} -> {sum(after[k]['far'] for k in keys)}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out", nargs="?")
    ap.add_argument("first", nargs="?")
    ap.add_argument("--duration", type=float, default=8.0)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    ap.add_argument("--kinds", default="clean,dirty")
    ap.add_argument("--compare", nargs=2)
    a = ap.parse_args()
    if a.compare:
        compare(*(json.loads(Path(p).read_text()) for p in a.compare))
        return
    Path(a.out).write_text(json.dumps(measure(a), indent=1))


if __name__ == "__main__":
    main()
