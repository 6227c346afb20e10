"""The estimated drag's honesty (session 29, review item 1 and 2): 40-s rallies on the tests'
``lab_rig`` (2 and 3 cameras, 0.3 px) flown with the drag ``k_true`` 0.015, 0.0084 (the filter's
``k₀``) and 0 /m; per run ``z = (k₀ + δk̂ − k_true) · √I_k`` at the end, pooled per variant
(mean z, its standard error 1/√n for an honest estimate, RMS z, mean error and mean stated sd).

    PYTHONPATH=. python benchmarks/session29/drag_z.py --seeds 5 \
        --variants "none:drag_drift_s=None|600:drag_drift_s=600"
"""
import argparse
import os
import sys

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, "tests")
from _rally import rally  # noqa: E402
from test_filter import lab_rig  # noqa: E402

from pslog import SimulationOptions, simulate  # noqa: E402
from pslog.fusion.filter import BallFilter, FilterOptions  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--cams", default="2,3")
    ap.add_argument("--drags", default="0.015,0.0084,0")
    ap.add_argument("--variants", default="none:drag_drift_s=None|600:")
    a = ap.parse_args()
    variants = []
    for part in a.variants.split("|"):
        name, _, kvs = part.partition(":")
        over = {k: eval(v, {}) for k, v in (kv.split("=") for kv in filter(None, kvs.split(";")))}
        variants.append((name, over))
    res: dict[str, list] = {n: [] for n, _ in variants}
    for ncam in [int(c) for c in a.cams.split(",")]:
        rig = lab_rig(ncam)
        for drag in [float(d) for d in a.drags.split(",")]:
            for seed in range(a.first_seed, a.first_seed + a.seeds):
                motion, _ = rally(a.duration, seed=seed, drag_per_m=drag)
                obs, _ = simulate(rig, motion, a.duration,
                                  SimulationOptions(noise_px=0.3, seed=seed))
                obs = obs.best()
                row = []
                for name, over in variants:
                    flt = BallFilter(rig, FilterOptions(**over))
                    for t, c, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(),
                                            obs.uv.tolist(), strict=True):
                        flt.push(t, c, u, v)
                    k = flt.options.drag_per_m + flt._dk
                    sd = flt._drag_info ** -0.5
                    res[name].append((ncam, drag, seed, k - drag, sd, (k - drag) / sd))
                    row.append(f"{name} {k:.5f} ±{sd:.5f} z {(k - drag) / sd:+.2f}")
                print(f"cams {ncam} k_true {drag:.4f} seed {seed}: " + "; ".join(row),
                      flush=True)
    print("variant  n  mean z (±1/√n)  RMS z  |z|>2  mean err /m  mean sd /m")
    for name, _ in variants:
        r = np.array(res[name])
        for label, sel in [("all", np.ones(len(r), bool))] + [
                (f"k {d:g}", r[:, 1] == d) for d in sorted(set(r[:, 1]), reverse=True)]:
            z = r[sel, 5]
            print(f"{name:8s} {label:8s} {len(z):3d} {z.mean():+.2f} (±{1 / np.sqrt(len(z)):.2f})"
                  f"  {np.sqrt(np.mean(z ** 2)):.2f}  {np.sum(abs(z) > 2):2d}"
                  f"  {r[sel, 3].mean():+.6f}  {r[sel, 4].mean():.6f}")


if __name__ == "__main__":
    main()
