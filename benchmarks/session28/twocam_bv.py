# ruff: noqa: E501
"""Issue 10 (session 28, twocam): bias against variance of ``typeA`` and ``filter`` variants
on ``paper2`` at 30 fps, 0.3 px: every session fused with N noise seeds (the same motion
and shutters); per output time the bias is the mean offset over the seeds and the variance
the rest (both unbiased for N: ``|b|² = |mean|² − σ²/N``), pooled by time since the truth's
last velocity jump, per group of sessions above / below 1/2 (``filter / typeA`` of the
first noise seed, from twocam_per.py's ``--dump`` of the same first seeds).

    PYTHONPATH=. python benchmarks/session28/twocam_bv.py --first-seeds 9600,10000 \
        --noise-seeds 6 --variants "main:|drag:drag_per_m=0.015" --groups out.pkl
"""
import argparse
import pickle
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session28")
from twocam_per import bd, filter_track, jumps_of, rig_of, variants_of

from pslog.evaluation import _offsets
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

BINS = np.array([0, .067, .15, .3, 1e9])
NAMES = ["0-67 ms", "67-150 ms", "150-300 ms", "> 300 ms or no jump"]


def bias_variance(per: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, unbiased |bias|², per-seed variance) at the times most seeds output."""
    n = len(per)
    times = np.unique(np.concatenate([t for t, _ in per.values()]))
    O = np.full((n, len(times), 3), np.nan)
    for i, (t, o) in enumerate(per.values()):
        O[i, np.searchsorted(times, t)] = o
    keep = np.sum(np.all(np.isfinite(O), 2), 0) == n
    mean = O[:, keep].mean(0)
    var = np.sum((O[:, keep] - mean) ** 2, 2).sum(0) / (n - 1)
    return times[keep], np.sum(mean ** 2, 1) - var / n, var


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--first-seeds", default="9600")
    ap.add_argument("--noise-seeds", type=int, default=6)
    ap.add_argument("--variants", default="main:")
    ap.add_argument("--groups", required=True, help="twocam_per.py --dump of these seeds")
    a = ap.parse_args()
    variants = variants_of(a.variants)
    with open(a.groups, "rb") as fh:
        ref = {(r["fs"], r["label"]): r["main"]["F"] / r["A"] for r in pickle.load(fh)}
    rig = rig_of("paper2", 30.0)
    acc = {}
    for fs in [int(x) for x in a.first_seeds.split(",")]:
        runs = bd.more_sessions(2, 8.0, fs)
        for seed, (label, motion, duration, _) in enumerate(runs, start=fs - 300):
            span = motion.duration if duration is None else duration
            jumps = jumps_of(motion, span)
            per: dict = {name: {} for name in ["typeA"] + [v for v, _ in variants]}
            for k in range(a.noise_seeds):
                det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                    noise_px=0.3, seed=seed + 100_000 * k))
                tr = fuse_detections(det, rig, ["typeA"], FusionOptions())[0]["typeA"]
                per["typeA"][k] = (np.asarray(tr.time_ns), _offsets(tr, truth))
                for name, over in variants:
                    f = filter_track(det, rig, over)
                    per[name][k] = (np.asarray(f.time_ns), _offsets(f, truth))
            group = ref[(fs, label)] > 0.5
            line = f"{fs} {label:14s} {'above' if group else 'below'}"
            for name, d in per.items():
                t, b2, var = bias_variance(d)
                s = t / 1e9
                if len(jumps):
                    j = np.searchsorted(jumps, s, side="right") - 1
                    s = np.where(j >= 0, s - jumps[np.clip(j, 0, None)], 1e6)
                else:
                    s = np.full(len(s), 1e6)
                phase = np.minimum(np.digitize(s, BINS) - 1, len(BINS) - 2)
                B, V, N = acc.setdefault((name, group), np.zeros((3, len(BINS) - 1)))
                for p in range(len(BINS) - 1):
                    B[p] += b2[phase == p].sum()
                    V[p] += var[phase == p].sum()
                    N[p] += np.sum(phase == p)
                line += f" | {name} rms {1e3 * np.sqrt(np.mean(b2 + var)):.2f} mm, bias {100 * b2.sum() / (b2 + var).sum():.0f}%"
            print(line, flush=True)
    print("\nrms bias / sd (mm) by time since the truth's last jump (bias's share of the MSE)")
    for (name, group), (B, V, N) in sorted(acc.items(), key=lambda kv: (kv[0][0] != "typeA", kv[0])):
        print(f"{name:9s} {'above' if group else 'below'}: " + " | ".join(
            f"{nm} {1e3 * np.sqrt(max(B[p], 0) / N[p]):.2f} / {1e3 * np.sqrt(V[p] / N[p]):.2f} ({100 * B[p] / (B[p] + V[p]):.0f}%)"
            if N[p] else f"{nm} -" for p, nm in enumerate(NAMES)))


if __name__ == "__main__":
    main()
