# ruff: noqa: E501, E702, B905, B007
"""Session 38 probe: the breaks rule (session 37) with its kick instants from smooth's fit
against those from the filter's accepted jumps (an interval: from the filter's third latest
accepted detection before the flagged one up to it). Clean sessions of bench_dirty --more.

    PYTHONPATH=. python benchmarks/session38/jump_source.py FIRST [FPS]
"""
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.fusion import FusionOptions, _filter, _type_a, offline_confirmation, type_a_prepared  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s  # noqa: E402
from pslog.fusion.breaks import fit_breaks_ns, reversed_prepared  # noqa: E402
from pslog.records import matching_rows, point_keys  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def hits(lo, hi, a, b, a_open):
    """(n,) bool: some interval [lo_k, hi_k] meets (a, b] (a_open) or [a, b)."""
    # interval k meets (a, b] iff lo_k <= b and hi_k > a ; meets [a, b) iff lo_k < b and hi_k >= a
    out = np.zeros(len(a), bool)
    for l, h in zip(lo, hi):
        out |= ((l <= b) & (h > a)) if a_open else ((l < b) & (h >= a))
    return out


first = int(sys.argv[1])
fps = float(sys.argv[2]) if len(sys.argv) > 2 else None
opt = offline_confirmation(FusionOptions())
tot = {}
cpu = {"fit": 0.0, "filter": 0.0, "bwd": 0.0}
for base in rigs() + more_rigs():
    rig = base if fps is None else at_rate(base, fps)
    optg = replace(opt, max_gap_s=default_max_gap_s(rig))
    for seed, (label, motion, duration, kicks) in enumerate(more_sessions(3, 8.0, first), start=first - 300):
        det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed))
        _, prep = type_a_prepared(det, rig, opt)
        F = _type_a(prep, rig, optg)
        c = time.process_time(); rp, t0 = reversed_prepared(prep, rig); B = _type_a(rp, rig, optg); cpu["bwd"] += time.process_time() - c
        c = time.process_time(); br = fit_breaks_ns(prep, rig, optg); cpu["fit"] += time.process_time() - c
        c = time.process_time(); flt = _filter(prep, rig, optg); cpu["filter"] += time.process_time() - c
        acc = flt.quality["rejected"] == 0
        ft, fj = flt.time_ns[acc], flt.quality["jump"][acc] > 0
        k = np.flatnonzero(fj)
        j_hi = ft[k]
        j_lo = ft[np.maximum(k - 3, 0)]
        t = F.time_ns
        sf = np.round(F.quality["span_s"] * 1e9).astype(np.int64)
        idx, has = matching_rows(point_keys(t, F.camera), point_keys(t0 - B.time_ns, B.camera))
        sb = np.zeros(len(t), np.int64)
        sb[has] = np.round(B.quality["span_s"][idx[has]] * 1e9).astype(np.int64)
        eF = np.linalg.norm(F.position_world - truth.at(t), axis=1)
        eB = np.full(len(t), np.inf)
        eB[has] = np.linalg.norm(B.position_world[idx[has]] - truth.at(t[has]), axis=1)
        far, good = eF > 0.05, eF <= 0.05
        for name, lo, hi in (("fit", br, br), ("filter", j_lo, j_hi)):
            spanning = hits(lo, hi, t - sf, t, True)
            bsp = ~has | hits(lo, hi, t, t + sb, False)
            use = spanning & ~bsp
            out = spanning & bsp
            new = np.where(use, eB, eF)
            r = tot.setdefault(name, dict.fromkeys(("n", "far0", "far", "good_out", "replaced", "spanning", "err0", "err"), 0.0))
            r["n"] += len(t); r["far0"] += far.sum(); r["far"] += (~out & (new > 0.05)).sum()
            r["good_out"] += (good & out).sum(); r["replaced"] += use.sum(); r["spanning"] += spanning.sum()
            r["err0"] += eF.sum(); r["err"] += new[~out].sum() / max(1, (~out).sum()) * len(t)
            for i in np.flatnonzero(~out & (new > 0.05)):
                print(f"  {name}: {rig.name} {label} far left at {(t[i] - t.min()) / 1e9:.3f} s err {new[i]*1e3:.0f} mm")
    sys.stdout.flush()
for name, r in tot.items():
    print(f"{name}: points {int(r['n'])} far {int(r['far0'])} -> {int(r['far'])}, good withheld {int(r['good_out'])}, replaced {int(r['replaced'])}, spanning {int(r['spanning'])}")
print("CPU s:", {k: round(v, 2) for k, v in cpu.items()})
