"""Accuracy of ``--estimate auto`` before (session 36: the per-camera readout test at 0.1 %)
and after (session 37: the nested one-readout-per-model test and the per-camera one, each
at 0.05 %) on sync_power.py's sessions: per session the auto fit (one wide fit tells both
rules' choices: the model is then offsets alone or the wide fit), each rule's model fused
(typeA, smooth, filter, with the clocks' consider covariance) and scored against the truth
(mean mm, NEES); the true clocks beside them.

    python benchmarks/session37/sync_shared_accuracy.py --rigs paper3 --readouts 4
        --durations 20 --seeds 8 --first-seed 50400
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parents[1]))

from bench_timing_accuracy import _nominal  # noqa: E402
from sync_power import make_rig  # noqa: E402

from pslog import SimulationOptions, simulate  # noqa: E402
from pslog.estimation.sync import AUTO_LEVEL, estimate_clocks  # noqa: E402
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
    ap.add_argument("--readouts", default="4")
    ap.add_argument("--durations", default="20")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--first-seed", type=int, default=50400)
    ap.add_argument("--noise", type=float, default=0.5)
    args = ap.parse_args(argv)
    print("rig\tdur\treadout\tseed\told\tnew\t" + "\t".join(
        f"{m}_{w}" for w in ("true", "old", "new") for m in METHODS) + "\tnees_smooth_old"
          "\tnees_smooth_new", flush=True)
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
                    new = estimate_clocks(det.best(), nominal, "auto")
                    (t,) = [t for t in new.selection if t.parameter == "readout"]
                    old_keeps = t.statistic > chi2.isf(AUTO_LEVEL, t.dof)
                    if old_keeps == t.kept:
                        old = new
                    else:
                        old = estimate_clocks(det.best(), nominal,
                                              ("offset", "readout") if old_keeps else
                                              ("offset",))
                    s_true = score(det, true_rig(rig, opts), truth, None)
                    s_new = score(det, new.rig, truth, new.clock_covariance())
                    s_old = s_new if old is new else score(det, old.rig, truth,
                                                           old.clock_covariance())
                    cells = [f"{s[m][0]:.2f}" for s in (s_true, s_old, s_new) for m in METHODS]
                    print(f"{rig_name}\t{dur:g}\t{spec}\t{seed}\t{int(old_keeps)}\t"
                          f"{int(t.kept)}\t" + "\t".join(cells)
                          + f"\t{s_old['smooth'][1]:.2f}\t{s_new['smooth'][1]:.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
