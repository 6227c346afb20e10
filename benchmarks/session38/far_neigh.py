# ruff: noqa: E501
"""Session 38 diagnosis: type A's far points under the default kick test, with their
neighbourhood: each nearby detection's forward and backward point errors, their along-ray
difference, and smooth's fit breaks.

    PYTHONPATH=. python benchmarks/session38/far_neigh.py FIRST [FPS]
"""
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.fusion import FusionOptions, _type_a, offline_confirmation, type_a_prepared  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s  # noqa: E402
from pslog.fusion.breaks import fit_breaks_ns, reversed_prepared  # noqa: E402
from pslog.records import matching_rows, point_keys  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

first = int(sys.argv[1])
fps = float(sys.argv[2]) if len(sys.argv) > 2 else None
opt = offline_confirmation(FusionOptions())
for base in rigs() + more_rigs():
    rig = base if fps is None else at_rate(base, fps)
    optg = replace(opt, max_gap_s=default_max_gap_s(rig))
    for seed, (label, motion, duration, kicks) in enumerate(more_sessions(3, 8.0, first), start=first - 300):
        det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed))
        _, prep = type_a_prepared(det, rig, opt)
        F = _type_a(prep, rig, optg)
        rp, t0 = reversed_prepared(prep, rig)
        B = _type_a(rp, rig, optg)
        t = F.time_ns
        idx, has = matching_rows(point_keys(t, F.camera), point_keys(t0 - B.time_ns, B.camera))
        eF = np.linalg.norm(F.position_world - truth.at(t), axis=1)
        PB = np.full_like(F.position_world, np.nan)
        PB[has] = B.position_world[idx[has]]
        eB = np.linalg.norm(PB - truth.at(t), axis=1)
        sB = np.full(len(t), np.nan)
        sB[has] = B.quality["std_m"][idx[has]]
        spB = np.full(len(t), np.nan)
        spB[has] = B.quality["span_s"][idx[has]]
        d = np.linalg.norm(F.position_world - PB, axis=1)
        far = np.flatnonzero(eF > 0.05)
        if not len(far):
            continue
        br = fit_breaks_ns(prep, rig, optg)
        T0 = int(prep.obs.time_ns.min())
        for i in far:
            print(f"{rig.name} {label} far at {(t[i] - T0) / 1e9:.3f} s cam {F.camera[i]} err {eF[i]*1e3:.0f} mm; fit breaks near: "
                  + " ".join(f"{(b - T0) / 1e9:.3f}" for b in br if abs(b - t[i]) < 0.15e9)
                  + ("; true kicks " + " ".join(f"{k:.3f}" for k in kicks if abs(k - (t[i] - T0) / 1e9) < 0.3) if kicks is not None else ""))
            for j in np.flatnonzero(np.abs(t - t[i]) < 0.1e9):
                print(f"   {(t[j] - T0) / 1e9:.4f} c{F.camera[j]} spanF {F.quality['span_s'][j]*1e3:5.1f} spanB {spB[j]*1e3:5.1f} eF {eF[j]*1e3:6.1f} eB {eB[j]*1e3:6.1f} d {d[j]*1e3:6.1f} sF {F.quality['std_m'][j]*1e3:5.1f} sB {sB[j]*1e3:5.1f}")
        sys.stdout.flush()
