"""One readout per camera model (session 37, tied37): per session the per-camera fit
(``offset,readout``), the tied fit (``offset,readout=shared``) and ``--estimate auto``'s
choice, each rig fused (typeA, smooth, filter, with the clocks' consider covariance) and
scored against the truth (mean mm; smooth's NEES); the true clocks beside them. Readouts
``4`` (every camera), ``0/0/16`` (per camera, cycled over the rig's cameras).

    python benchmarks/session37/tied_accuracy.py --rigs paper3 --readouts 8 --durations 8
        --seeds 4 --first-seed 56000
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
from pslog.estimation.sync import SHARED_READOUT, estimate_clocks  # noqa: E402
from pslog.evaluation import assess  # noqa: E402
from pslog.fusion import FusionOptions, fuse_all  # noqa: E402
from pslog.motion import rally_motion  # noqa: E402
from pslog.simulation import true_rig  # noqa: E402

METHODS = ("typeA", "smooth", "filter")


def score(det, rig, truth, cov):
    tracks = fuse_all(det, rig, list(METHODS), FusionOptions(clock_covariance=cov))
    out = {}
    for m in METHODS:
        acc, q = assess(tracks[m], truth)
        out[m] = (acc.mean_mm, q.nees)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rigs", default="paper3")
    ap.add_argument("--readouts", default="8")
    ap.add_argument("--durations", default="8")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--first-seed", type=int, default=56000)
    ap.add_argument("--noise", type=float, default=0.5)
    args = ap.parse_args(argv)
    print("rig\tdur\treadout\tseed\tkept\ttied\tequal_chi2\tequal_thr\t" + "\t".join(
        f"{m}_{w}" for w in ("true", "percam", "tied", "auto") for m in METHODS)
          + "\tnees_percam\tnees_tied\tnees_auto", flush=True)
    for rig_name in args.rigs.split(","):
        for dur in map(float, args.durations.split(",")):
            for spec in args.readouts.split(","):
                for seed in range(args.first_seed, args.first_seed + args.seeds):
                    rig = make_rig(rig_name)
                    values = [float(v) for v in spec.split("/")]
                    readout = {c.name: values[i % len(values)] / 1e3
                               for i, c in enumerate(rig.cameras)}
                    rng = np.random.default_rng(seed)
                    offsets = {c.name: float(rng.uniform(-12, 12)) / 1e3
                               for c in rig.cameras[1:]}
                    opts = SimulationOptions(noise_px=args.noise, seed=seed,
                                             clock_offset_s=offsets,
                                             readout_s={k: v for k, v in readout.items() if v})
                    det, truth = simulate(rig, rally_motion(seed, duration=dur), dur, opts)
                    nominal = _nominal(rig)
                    obs = det.best()
                    auto = estimate_clocks(obs, nominal, "auto")
                    (t,) = [t for t in auto.selection if t.parameter == "readout"]
                    percam = estimate_clocks(obs, nominal, ("offset", "readout"))
                    tied = estimate_clocks(obs, nominal, ("offset", SHARED_READOUT))
                    s_true = score(det, true_rig(rig, opts), truth, None)
                    s_p = score(det, percam.rig, truth, percam.clock_covariance())
                    s_t = score(det, tied.rig, truth, tied.clock_covariance())
                    s_a = (s_t if auto.shared_readout else
                           s_p if "readout" in auto.estimated else
                           score(det, auto.rig, truth, auto.clock_covariance()))
                    cells = [f"{s[m][0]:.2f}" for s in (s_true, s_p, s_t, s_a)
                             for m in METHODS]
                    print(f"{rig_name}\t{dur:g}\t{spec}\t{seed}\t{int(t.kept)}\t"
                          f"{int(t.tied)}\t{t.equal_statistic:.1f}\t{t.equal_threshold:.1f}\t"
                          + "\t".join(cells)
                          + f"\t{s_p['smooth'][1]:.2f}\t{s_t['smooth'][1]:.2f}"
                          f"\t{s_a['smooth'][1]:.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
