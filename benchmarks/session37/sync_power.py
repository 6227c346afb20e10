"""The power of ``--estimate auto``'s readout test (session 37): per session one fit of
``offset,readout`` (the wide fit auto makes) and, from its estimate and covariance, the
per-camera Wald statistic W (auto's: k = cameras) and the statistic of the nested hypothesis
"one readout shared by the cameras of one model (same width, height and fps)",
W_s = dᵀΣ⁻¹G(GᵀΣ⁻¹G)⁻¹GᵀΣ⁻¹d on as many dof as models (G: camera -> model indicator).
Also the readouts' correlation with the offsets (how much the offsets absorb) and the
readouts' common part's σ.

    python benchmarks/session37/sync_power.py --rigs paper3,own4 --readouts 0,8,16
        --durations 8,20 --seeds 6 --first-seed 50400 [--noise 0.5] [--no-drag] > out.tsv

A readout spec is one value (every camera, ms) or values joined by '/' (per camera, cycled).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parents[1]))
sys.path.insert(0, str(HERE.parents[2] / "tests"))

from bench_timing_accuracy import _nominal, rig_named  # noqa: E402

from pslog import SimulationOptions, apply_timing, simulate  # noqa: E402
from pslog.errors import PslogError  # noqa: E402
from pslog.estimation.sync import estimate_clocks  # noqa: E402
from pslog.motion import Ball, rally_motion  # noqa: E402
from pslog.rig import load_rig  # noqa: E402


def make_rig(name):
    if name == "lab3":
        from _rigs import lab3_rig

        return lab3_rig()
    if name == "webcams":
        return apply_timing(load_rig(HERE.parents[1] / "webcams3.toml"), "typeA")
    return rig_named(name)


def model_groups(rig) -> np.ndarray:
    keys = [(c.width, c.height, c.fps) for c in rig.cameras]
    uniq = list(dict.fromkeys(keys))
    return np.array([uniq.index(k) for k in keys])


def wald(d, cov, G=None):
    P = np.linalg.pinv(cov)
    if G is None:
        return float(d @ P @ d)
    A = G.T @ P @ G
    b = G.T @ P @ d
    return float(b @ np.linalg.solve(A, b))


def run(rig_name, spec, duration, seed, noise, drag=True):
    rig = make_rig(rig_name)
    values = [float(v) for v in spec.split("/")]
    readout = {c.name: values[i % len(values)] / 1e3 for i, c in enumerate(rig.cameras)}
    rng = np.random.default_rng(seed)
    offsets = {c.name: float(rng.uniform(-12, 12)) / 1e3 for c in rig.cameras[1:]}
    opts = SimulationOptions(noise_px=noise, seed=seed, clock_offset_s=offsets,
                             readout_s={k: v for k, v in readout.items() if v})
    extra = {} if drag else {"ball": Ball(drag_coefficient=0.0)}
    det, _ = simulate(rig, rally_motion(seed, duration=duration, **extra), duration, opts)
    try:
        res = estimate_clocks(det.best(), _nominal(rig), ("offset", "readout"))
    except PslogError as exc:
        return f"FAILED {exc}"
    idx = [j for j, (_, p) in enumerate(res.unknowns) if p == "readout"]
    cams = [res.unknowns[j][0] for j in idx]
    cov = res.covariance[np.ix_(idx, idx)]
    d = np.array([res.cameras[c].readout_s for c in cams])
    groups = model_groups(rig)[cams]
    G = (groups[:, None] == np.unique(groups)[None, :]).astype(float)
    w = wald(d, cov)
    ws = wald(d, cov, G)
    one = np.ones((len(d), 1))
    common_sd = float(1 / np.sqrt(one.T @ np.linalg.pinv(cov) @ one)[0, 0])
    # the readouts' largest |correlation| with any offset
    oidx = [j for j, (_, p) in enumerate(res.unknowns) if p == "offset"]
    sd = np.sqrt(np.diag(res.covariance))
    corr = res.covariance / np.outer(sd, sd)
    rho = float(np.max(np.abs(corr[np.ix_(idx, oidx)]))) if oidx else 0.0
    est = "/".join(f"{x * 1e3:.1f}" for x in d)
    sds = "/".join(f"{np.sqrt(cov[i, i]) * 1e3:.1f}" for i in range(len(d)))
    return (f"{w:.2f}\t{len(d)}\t{ws:.2f}\t{G.shape[1]}\t{common_sd * 1e3:.2f}\t{rho:.2f}"
            f"\t{est}\t{sds}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rigs", default="paper3")
    ap.add_argument("--readouts", default="0,8")
    ap.add_argument("--durations", default="8")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=50400)
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--no-drag", action="store_true", help="the rallies without air drag")
    args = ap.parse_args(argv)
    print("rig\tdur\treadout_ms\tseed\tW\tk\tW_shared\tk_shared\tcommon_sd_ms\tmax_rho"
          "\testimates_ms\tsd_ms", flush=True)
    for rig_name in args.rigs.split(","):
        for dur in map(float, args.durations.split(",")):
            for spec in args.readouts.split(","):
                for seed in range(args.first_seed, args.first_seed + args.seeds):
                    line = run(rig_name, spec, dur, seed, args.noise, not args.no_drag)
                    print(f"{rig_name}\t{dur:g}\t{spec}\t{seed}\t{line}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
