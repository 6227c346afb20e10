"""What one readout per camera model, estimated (not only tested), could give (session 37,
a probe, not a feature): from the wide fit (``offset,readout``) the estimate constrained to
equal readouts by the first-order constrained least squares on its own covariance,
θ_c = θ̂ - Σ Aᵀ (A Σ Aᵀ)⁻¹ A θ̂ (A: r_c - r_1 = 0), its rig fused (typeA, smooth; no clock
covariance) beside the per-camera estimate's and the true clocks'. Shared readouts only.

    python benchmarks/session37/sync_tied_probe.py --rigs paper3 --readouts 8 --durations 8
        --seeds 8 --first-seed 50400
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parents[1]))

from bench_timing_accuracy import _nominal  # noqa: E402
from sync_power import make_rig  # noqa: E402

from pslog import SimulationOptions, simulate  # noqa: E402
from pslog.estimation.sync import RIG_KEY, estimate_clocks  # noqa: E402
from pslog.evaluation import evaluate  # noqa: E402
from pslog.fusion import fuse_all  # noqa: E402
from pslog.motion import rally_motion  # noqa: E402
from pslog.rig import Rig  # noqa: E402
from pslog.simulation import true_rig  # noqa: E402

METHODS = ("typeA", "smooth")


def tied(res, rig):
    unk = list(res.unknowns)
    theta = np.array([float(getattr(res.rig.cameras[c], RIG_KEY[p])) for c, p in unk])
    # the rig clamps readouts to [0, period): take the estimates themselves
    for j, (c, p) in enumerate(unk):
        if p == "readout":
            theta[j] = res.cameras[c].readout_s
    r = [j for j, (_, p) in enumerate(unk) if p == "readout"]
    A = np.zeros((len(r) - 1, len(unk)))
    for i in range(1, len(r)):
        A[i - 1, r[i]], A[i - 1, r[0]] = 1.0, -1.0
    S = res.covariance
    theta_c = theta - S @ A.T @ np.linalg.solve(A @ S @ A.T, A @ theta)
    cams = list(rig.cameras)
    for j, (c, p) in enumerate(unk):
        value = float(theta_c[j])
        if p == "readout":
            value = min(max(value, 0.0), np.nextafter(cams[c].frame_period, 0))
        cams[c] = cams[c].replace(**{RIG_KEY[p]: value})
    return Rig(tuple(cams), rig.name), float(theta_c[r[0]])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rigs", default="paper3")
    ap.add_argument("--readouts", default="8")
    ap.add_argument("--durations", default="8")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=50400)
    ap.add_argument("--noise", type=float, default=0.5)
    args = ap.parse_args(argv)
    print("rig\tdur\treadout\tseed\tshared_ms\t" + "\t".join(
        f"{m}_{w}" for w in ("true", "percam", "tied") for m in METHODS), flush=True)
    for rig_name in args.rigs.split(","):
        for dur in map(float, args.durations.split(",")):
            for spec in args.readouts.split(","):
                for seed in range(args.first_seed, args.first_seed + args.seeds):
                    rig = make_rig(rig_name)
                    rng = np.random.default_rng(seed)
                    offsets = {c.name: float(rng.uniform(-12, 12)) / 1e3
                               for c in rig.cameras[1:]}
                    opts = SimulationOptions(
                        noise_px=args.noise, seed=seed, clock_offset_s=offsets,
                        readout_s={c.name: float(spec) / 1e3 for c in rig.cameras})
                    det, truth = simulate(rig, rally_motion(seed, duration=dur), dur, opts)
                    nominal = _nominal(rig)
                    res = estimate_clocks(det.best(), nominal, ("offset", "readout"))
                    tied_rig, shared = tied(res, nominal)
                    cells = []
                    for r in (true_rig(rig, opts), res.rig, tied_rig):
                        tracks = fuse_all(det, r, list(METHODS))
                        cells += [f"{evaluate(tracks[m], truth).mean_mm:.2f}" for m in METHODS]
                    print(f"{rig_name}\t{dur:g}\t{spec}\t{seed}\t{shared * 1e3:.2f}\t"
                          + "\t".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
