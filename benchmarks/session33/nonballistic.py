# ruff: noqa: E501
"""Issue 10 (session 33, twocam33): the filter's mean error on the motions q's adaptation is
for (``spiral``, ``turntable``, ``straight``, the swung ball), for ``FilterOptions``
variants, per rig and frame rate (fused as ``pslog fuse`` does). Prints one row per session:
typeA's mean error (mm) and each variant's ``filter / typeA``; then per variant the geometric
mean and the largest ratio to the first variant.

    PYTHONPATH=. python benchmarks/session33/nonballistic.py --seeds 31,32 \
        --variants "walk:accel_adapt_threshold=0|cusum:"
"""
import argparse
import os
import sys

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "benchmarks/session28")
sys.path.insert(0, "tests")
from test_filter import swing  # noqa: E402
from twocam_per import filter_track, rig_of, variants_of  # noqa: E402

from pslog import get_motion  # noqa: E402
from pslog.evaluation import _offsets  # noqa: E402
from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="31")
    ap.add_argument("--rigs", default="paper3,lab3,lab4")
    ap.add_argument("--fps", default="120,240")
    ap.add_argument("--noise", default="0,0.3")
    ap.add_argument("--motions", default="spiral,turntable,straight,swing")
    ap.add_argument("--variants", default="walk:accel_adapt_threshold=0|cusum:")
    a = ap.parse_args()
    variants = variants_of(a.variants)
    ratios = {n: [] for n, _ in variants}
    for rig_spec in a.rigs.split(","):
        for fps in [float(x) for x in a.fps.split(",")]:
            rig = rig_of(rig_spec, fps)
            for mname in a.motions.split(","):
                motion = swing(1.0) if mname == "swing" else get_motion(mname)
                for noise in [float(x) for x in a.noise.split(",")]:
                    for seed in [int(x) for x in a.seeds.split(",")]:
                        det, truth, _ = simulate_labelled(rig, motion, None, SimulationOptions(
                            noise_px=noise, seed=seed))
                        tracks, _ = fuse_detections(det, rig, ["typeA"], FusionOptions())
                        eA = np.nanmean(np.linalg.norm(_offsets(tracks["typeA"], truth), axis=1))
                        row = []
                        for name, over in variants:
                            f = filter_track(det, rig, over)
                            e = np.nanmean(np.linalg.norm(_offsets(f, truth), axis=1))
                            ratios[name].append(e / eA)
                            row.append(f"{name} {e / eA:.3f}")
                        print(f"{rig_spec:6s} {fps:4.0f} {mname:10s} {noise:3.1f} {seed:3d} A {1e3 * eA:6.3f} "
                              + " ".join(row), flush=True)
    base = np.array(ratios[variants[0][0]])
    for name, _ in variants:
        q = np.array(ratios[name])
        print(f"{name:8s} n {len(q)} gmean {np.exp(np.mean(np.log(q))):.3f} "
              f"vs {variants[0][0]}: gmean {np.exp(np.mean(np.log(q / base))):.3f} "
              f"max {np.max(q / base):.3f} min {np.min(q / base):.3f}")


if __name__ == "__main__":
    main()
