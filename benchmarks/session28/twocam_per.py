# ruff: noqa: E501
"""Issue 10 (session 28, twocam): per session ``filter`` / ``typeA`` (and ``smooth / typeA``)
for several ``FilterOptions`` variants, fused as ``pslog fuse`` does (gating on), on
``bench_dirty.py --more``'s sessions (the tests' rallies, the library's rally, ``straight``,
``turntable``); a rig may be a camera subset (``lab3/0+1``: its cameras 0 and 1). Prints a
row per session and per variant the geometric mean, the largest, the sessions above 1/2,
points beyond 5 cm and NEES; ``--dump`` keeps every point's offset for twocam_phase.py.

    PYTHONPATH=. python benchmarks/session28/twocam_per.py --first-seeds 9600,9800 --smooth \
        --variants "main:|drag:drag_per_m=0.015|step3:accel_step_var=1/200000" --dump out.pkl
"""
import argparse
import dataclasses
import os
import pickle
import sys

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import bench_dirty as bd  # noqa: E402

import pslog.fusion as pf  # noqa: E402
from pslog.evaluation import _mahalanobis_sq, _offsets  # noqa: E402
from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion.filter import FilterOptions, fuse_filter  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def variants_of(spec: str) -> list[tuple[str, dict]]:
    """``name:key=value;key=value|name2:...`` (values Python literals or arithmetic, or None)."""
    out = []
    for part in spec.split("|"):
        name, _, kvs = part.partition(":")
        over = {}
        for kv in filter(None, kvs.split(";")):
            key, value = kv.split("=")
            number = eval(value, {})  # a number, e.g. 1/200000, True/False, or None
            # (a switch stays a bool: FilterOptions refuses 0.0 for True/False)
            over[key] = number if number is None or isinstance(number, bool) else float(number)
        out.append((name, over))
    return out


def rig_of(spec: str, fps: float):
    base, _, sub = spec.partition("/")
    rig = {r.name: r for r in bd.rigs() + bd.more_rigs()}[base]
    if sub:
        rig = rig.subset([rig.names[int(i)] for i in sub.split("+")])
    return bd.at_rate(rig, fps)


def jumps_of(motion, span: float) -> np.ndarray:
    """The truth's velocity jumps (kicks, bounces): |a - g| > 200 m/s² on a 1-ms grid."""
    t = np.arange(0.0, span, 0.001)
    acc = np.diff(motion.position(t), 2, axis=0) / 1e-6 + np.array([0.0, 0.0, 9.81])
    big = np.flatnonzero(np.linalg.norm(acc, axis=1) > 200.0) + 1
    if len(big) == 0:
        return np.array([])
    return t[big[np.r_[True, np.diff(big) > 5]]]


def filter_track(det, rig, over: dict):
    options = FilterOptions(**over)
    orig = pf.METHODS["filter"]

    def _filter(prep, rig_, fusion_options):
        return fuse_filter(prep.obs, rig_, fusion_options.max_gap_s, options=options,
                           doubt=prep.doubt_px2)

    pf.METHODS["filter"] = dataclasses.replace(orig, function=_filter)
    try:
        return fuse_detections(det, rig, ["filter"], FusionOptions())[0]["filter"]
    finally:
        pf.METHODS["filter"] = orig


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--first-seeds", default="9600")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--rigs", default="paper2")
    ap.add_argument("--fps", default="30")
    ap.add_argument("--misses", type=float, default=0.0)
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--duration", type=float, default=8.0)
    ap.add_argument("--dirty", action="store_true", help="bench_dirty's faults too")
    ap.add_argument("--smooth", action="store_true", help="smooth / typeA too")
    ap.add_argument("--variants", default="main:")
    ap.add_argument("--dump", default=None)
    a = ap.parse_args()
    variants = variants_of(a.variants)
    rows = []
    for rig_spec in a.rigs.split(","):
        for fps in [float(x) for x in a.fps.split(",")]:
            rig = rig_of(rig_spec, fps)
            for fs in [int(x) for x in a.first_seeds.split(",")]:
                runs = bd.more_sessions(a.seeds, a.duration, fs)
                for seed, (label, motion, duration, _) in enumerate(runs, start=fs - 300):
                    span = motion.duration if duration is None else duration
                    kinds = [("clean", {})]
                    if a.dirty:
                        kinds.append(("dirty", bd.faults(rig, seed, span)))
                    for kind, extra in kinds:
                        det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                            noise_px=a.noise, seed=seed, miss_rate=a.misses,
                            drop_rate=a.misses / 2, **extra))
                        methods = ["typeA"] + (["smooth"] if a.smooth else [])
                        tracks, _ = fuse_detections(det, rig, methods, FusionOptions())
                        eA = np.linalg.norm(_offsets(tracks["typeA"], truth), axis=1)
                        rec = dict(rig=rig_spec, fps=fps, fs=fs, label=label, kind=kind,
                                   A=np.nanmean(eA), eA=eA, jumps=jumps_of(motion, span),
                                   tA=np.asarray(tracks["typeA"].time_ns) / 1e9)
                        if a.smooth:
                            rec["S"] = np.nanmean(np.linalg.norm(
                                _offsets(tracks["smooth"], truth), axis=1))
                        for name, over in variants:
                            f = filter_track(det, rig, over)
                            off = _offsets(f, truth)
                            e = np.linalg.norm(off, axis=1)
                            rec[name] = dict(F=np.nanmean(e), t=np.asarray(f.time_ns) / 1e9, e=e,
                                             off=off, d2=_mahalanobis_sq(f, off),
                                             std=np.asarray(f.quality["std_m"]))
                        rows.append(rec)
                        print(f"{rig_spec:10s} {fps:4.0f} {fs:5d} {label:14s} {kind:5s} A {1e3 * rec['A']:5.2f} "
                              + (f"S/A {rec['S'] / rec['A']:.3f} " if a.smooth else "")
                              + " ".join(f"{n} {rec[n]['F'] / rec['A']:.3f}" for n, _ in variants),
                              flush=True)
    print()
    for name, _ in variants:
        for kind in ("clean", "dirty"):
            sel = [r for r in rows if r["kind"] == kind]
            if not sel:
                continue
            q = np.array([r[name]["F"] / r["A"] for r in sel])
            d2 = np.concatenate([r[name]["d2"][np.isfinite(r[name]["d2"])] for r in sel])
            far = sum(int(np.sum(r[name]["e"][np.isfinite(r[name]["e"])] > 0.05)) for r in sel)
            print(f"{name:10s} {kind}: n {len(q)} F/A gmean {np.exp(np.mean(np.log(q))):.3f} "
                  f"max {q.max():.3f} >0.5 {int(np.sum(q > 0.5))} far {far} "
                  f"NEES {d2.mean() / 3:.3f} in2s {100 * np.mean(d2 <= 4):.1f}%")
    if a.dump:
        with open(a.dump, "wb") as fh:
            pickle.dump(rows, fh)


if __name__ == "__main__":
    main()
