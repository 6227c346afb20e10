# ruff: noqa: E501
"""Issue 10 (session 32): type A with the innovation's wait (``confirm.WAIT_SIGMAS``) at
several levels, on bench_dirty ``--more``'s sessions (five rigs x 4 rallies, the library's
rally, ``straight``, ``turntable``; 0.3 px), clean and with the faults. Per level and kind:
points, far (> 5 cm; "added": far with the faults where the clean session's point at that
detection is within 5 cm), good points (<= 5 cm with the rule off) withdrawn (and how many
of those were > 2 cm off), the points that
wait for the next camera (long gap, re-acquisition or innovation: one detection's latency in
a stream; % of the points made), mean error, refused counts (contradicted, unconfirmed).

    PYTHONPATH=. python benchmarks/session32/kick_sweep.py FIRST[,FIRST..] [--fps 60]
        [--misses 0.1] [--levels off,3,2.5,2] [--every]

``--every``: also ``FusionOptions(confirm_every=True)`` (session 29, offline: every point
tested), for reference.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs  # noqa: E402

import pslog.fusion.confirm as confirm  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, fuse  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s, rays_only  # noqa: E402
from pslog.fusion.gating import gate_for, prepared_for  # noqa: E402
from pslog.fusion.pseudo import _fuse_type_a, covariance_noise_px  # noqa: E402
from pslog.records import NS  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

FAR = 0.05


def _waits(det, rig, options) -> tuple[int, int]:
    """(points made, points that wait) under the current confirm settings."""
    from pslog.fusion import _pseudo_kernel
    from pslog.fusion.innovation import previous_next_rows
    from pslog.fusion.pseudo import _all_brackets

    prep = rays_only(prepared_for(gate_for(det, rig, "typeA", options), rig))[0]
    gap = options.max_gap_s or default_max_gap_s(rig)
    tr = _fuse_type_a(prep, gap, options.noise_px, None, None, None, False,
                      covariance_noise_px(options.noise_px), None)[0]
    k = len(tr)
    if not k:
        return 0, 0
    row, g, long = np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k, bool)
    _pseudo_kernel.long_gap_kernel(
        prep.obs.time_ns, prep.obs.camera, len(rig), _all_brackets(prep)[2],
        previous_next_rows(prep)[0], tr.time_ns, tr.camera, int(gap * NS),
        float(confirm.LONG_FACTOR * confirm.usual_interval_s(rig) * NS), confirm.FRESH_ROWS,
        row, g, long)
    if confirm.WAIT_SIGMAS is not None:
        q = tr.quality
        s = confirm.confirm_noise(q["snap_px"], options.noise_px)
        long |= confirm.innovation_waits(q["_model_across_m2"], q["_model_m2_per_px2"], s)
    return k, int(np.count_nonzero(long))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first")
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--levels", default="off,3")
    ap.add_argument("--every", action="store_true")
    a = ap.parse_args()
    levels = [None if x == "off" else float(x) for x in a.levels.split(",")]
    variants = [(("off" if k is None else f"k={k:g}"), k, False) for k in levels]
    if a.every:
        variants.append(("every", None, True))
    names = [v[0] for v in variants]
    tot = {(nm, kind): dict(points=0, far=0, added=0, withdrawn=0, withdrawn_2cm=0, good=0, made=0, waits=0,
                            err=[], contradicted=0, unconfirmed=0)
           for nm in names for kind in ("clean", "dirty")}
    for first in (int(x) for x in a.first.split(",")):
        runs = more_sessions(a.seeds, 8.0, first)
        for base in rigs() + more_rigs():
            rig = base if a.fps is None else at_rate(base, a.fps)
            for seed, (_label, motion, duration, _kicks) in enumerate(runs, start=first - 300):
                span = motion.duration if duration is None else duration
                fault = faults(rig, seed, span)
                for kind, extra in (("clean", {}), ("dirty", fault)):
                    det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                        noise_px=0.3, seed=seed, miss_rate=a.misses, drop_rate=a.misses / 2,
                        **extra))
                    ref_good = None
                    for nm, k, every in variants:
                        confirm.WAIT_SIGMAS = k
                        options = FusionOptions(confirm_every=every)
                        tr = fuse(det, rig, "typeA", options)
                        err = errors_m(tr, truth)
                        keys = tr.time_ns * 256 + tr.camera
                        far = err > FAR
                        d = tot[(nm, kind)]
                        d["points"] += len(tr)
                        d["far"] += int(np.count_nonzero(far))
                        d["err"].append(err[np.isfinite(err)])
                        d["contradicted"] += tr.dropped.get("contradicted", 0)
                        d["unconfirmed"] += tr.dropped.get("unconfirmed", 0)
                        if ref_good is None:
                            ref_good, ref_err = keys[~far], err[~far]
                        d["good"] += len(ref_good)
                        out = ~np.isin(ref_good, keys)
                        d["withdrawn"] += int(np.count_nonzero(out))
                        d["withdrawn_2cm"] += int(np.count_nonzero(out & (ref_err > 0.02)))
                        if kind == "clean":
                            d.setdefault("clean_far", []).append(set(keys[far].tolist()))
                        else:
                            cf = tot[(nm, "clean")]["clean_far"][-1]
                            d["added"] += sum(1 for x in keys[far].tolist() if x not in cf)
                        if not every:
                            made, waits = _waits(det, rig, options)
                            d["made"] += made
                            d["waits"] += waits
    print(f"first seeds {a.first}, fps {a.fps or 'rig'}, misses {a.misses}")
    for kind in ("clean", "dirty"):
        for nm in names:
            d = tot[(nm, kind)]
            mean = 1e3 * float(np.concatenate(d["err"]).mean())
            w = f"{d['waits']} ({100 * d['waits'] / max(d['made'], 1):.2f} %)" if d["made"] else "every"
            print(f"{kind:5s} {nm:7s} points {d['points']:6d} far {d['far']:3d} added {d['added']:2d} "
                  f"good withdrawn {d['withdrawn']:3d} ({100 * d['withdrawn'] / d['good']:.3f} %; > 2 cm {d['withdrawn_2cm']}) "
                  f"waits {w} mean {mean:.3f} mm contradicted {d['contradicted']} "
                  f"unconfirmed {d['unconfirmed']}")


if __name__ == "__main__":
    main()
