"""Whether the fused points' uncertainty is honest after ``pslog sync``: each method's
covariance with the clocks taken as exact, and with their consider covariance
(:mod:`pslog.fusion.clock`; issue 10, "Quality that means something").

For every case of ``bench_sync_auto`` (global and rolling shutters, offsets, drifts, host
jitter; 2-4 cameras, 30 and 60 fps) and seed: simulate, regularize the stamps where they
jitter, ``estimate_clocks`` as ``pslog sync --estimate auto`` (or ``--estimate`` as given),
then fuse every method with the synced rig twice: ``clock_covariance`` None (the clocks
exact) and the estimate's covariance. A single session draws one clock error, so the
covariance is judged over all the seeds of a case together: the NEES (mean ``d² / 3``, 1
if honest) and the share of the truth inside 2σ (73.9 % if honest) over every point, and
how many sessions' own NEES exceed 2. The last column is sync's own honesty: the clock
estimates' ``(θ̂ - θ)ᵀ Σ_θ⁻¹ (θ̂ - θ)`` per parameter over the seeds (1 if its covariance is
right); the consider covariance can be no more honest than it.

    python benchmarks/bench_clock_uncertainty.py [--seeds 6] [--first-seed 43100]
        [--only TEXT] [--estimate auto|offset,readout,...] [--spurious 0.05]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from bench_sync_auto import cases, simulate_case
from bench_timing_accuracy import _nominal, _regularize_auto

from pslog.errors import PslogError
from pslog.estimation.sync import estimate_clocks
from pslog.evaluation import errors_m, mahalanobis_sq
from pslog.fusion import FusionOptions, fuse_all
from pslog.simulation import true_rig
from pslog.timing import CLOCK_KEYS

METHODS = ("typeA", "smooth", "filter")


def run(case, seed: int, lab_rig: str | None, estimate, spurious: float) -> dict | str:
    rig, opts, detections, truth = simulate_case(case, seed, lab_rig, spurious)
    regular, reports = _regularize_auto(detections)
    try:
        result = estimate_clocks(regular.best(), _nominal(rig), estimate, regularized=reports)
    except PslogError as exc:
        return f"FAILED: {exc}"
    clock = result.clock_covariance()
    out: dict = {"estimated": ",".join(result.estimated), "cpu": {}}
    # the estimate's own honesty: (θ̂ - θ)ᵀ Σ⁻¹ (θ̂ - θ) against the simulated clocks (its
    # expectation is the parameter count when sync's covariance is right)
    truth_rig = true_rig(_nominal(rig), opts)
    if clock is not None:
        error = np.array([getattr(result.rig.cameras[c], CLOCK_KEYS[p])
                          - getattr(truth_rig.cameras[c], CLOCK_KEYS[p])
                          for c, p in zip(clock.camera, clock.parameter, strict=True)])
        out["clock_chi2"] = (float(error @ np.linalg.solve(clock.matrix, error)),
                             len(error))
    for label, cc in (("exact", None), ("consider", clock)):
        t = time.process_time()
        tracks = fuse_all(regular, result.rig, list(METHODS),
                          FusionOptions(clock_covariance=cc))
        out["cpu"][label] = time.process_time() - t
        for m in METHODS:
            d2 = mahalanobis_sq(tracks[m], truth)
            err = errors_m(tracks[m], truth)
            ok = np.isfinite(d2) & np.isfinite(err)
            out[(label, m)] = (d2[ok], err[ok])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--first-seed", type=int, default=43100)
    ap.add_argument("--only", default=None, help="cases whose name holds this text")
    ap.add_argument("--estimate", default="auto",
                    help="auto, or the parameters to estimate (comma-separated)")
    ap.add_argument("--spurious", type=float, default=0.0,
                    help="share of frames with a false candidate (gated)")
    ap.add_argument("--lab-rig", default=str(Path(__file__).with_name("webcams3.toml")))
    args = ap.parse_args(argv)
    estimate = "auto" if args.estimate == "auto" else tuple(args.estimate.split(","))
    print(f"seeds {args.first_seed}..{args.first_seed + args.seeds - 1}, estimate "
          f"{args.estimate}, spurious {args.spurious}; per method: NEES / % inside 2σ over "
          f"every point of the case's sessions (1 / 73.9 % if honest), sessions with NEES > 2;"
          f" clocks exact -> with their consider covariance")
    print(f"{'case':<30} {'estimated':<16} " + " ".join(f"{m:>30}" for m in METHODS)
          + "  cpu ratio (median)  clock NEES")
    for case in cases():
        if args.only and args.only not in case.name:
            continue
        runs = [run(case, s, args.lab_rig, estimate, args.spurious)
                for s in range(args.first_seed, args.first_seed + args.seeds)]
        good = [r for r in runs if isinstance(r, dict)]
        failed = len(runs) - len(good)
        if not good:
            print(f"{case.name:<30} every seed FAILED: {runs[0]}")
            continue
        cells = []
        for m in METHODS:
            parts = []
            for label in ("exact", "consider"):
                d2 = np.concatenate([r[(label, m)][0] for r in good])
                over = sum(float(np.mean(r[(label, m)][0])) / 3 > 2 for r in good)
                parts.append(f"{np.mean(d2) / 3:.2f}/{100 * np.mean(d2 <= 4):.0f}%/{over}")
            cells.append(" -> ".join(parts))
        ratio = np.median([r["cpu"]["consider"] / max(r["cpu"]["exact"], 1e-9) for r in good])
        chi2 = [r["clock_chi2"] for r in good if "clock_chi2" in r]
        clock_nees = (sum(c for c, _ in chi2) / sum(k for _, k in chi2)) if chi2 else np.nan
        chosen = "/".join(sorted({r["estimated"] for r in good}))
        print(f"{case.name:<30} {chosen:<16} " + " ".join(f"{c:>30}" for c in cells)
              + f"  x{ratio:.1f}  {clock_nees:5.2f}"
              + (f"  ({failed} failed)" if failed else ""), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
