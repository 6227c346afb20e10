# ruff: noqa: E501, E702
"""Session 38 probe: can type A's forward/backward disagreement screen where smooth's fit is
needed (so that ``--confirm-gaps breaks`` fits only windows of the session)? Prints, on a
rally of SECONDS (paper3 and lab4, 0.3 px), the CPU of the forward pass, the backward pass
and the fit, and for a screen ``z > k`` (the forward and backward points' distance over
``sqrt(std_f^2 + std_b^2)``) or no backward point, the share of points screened and of the
session covered by windows of +-0.1 s and +-0.2 s around them.

    PYTHONPATH=. python benchmarks/session38/screen_probe.py [SECONDS]
"""
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, "tests")
from _rigs import ring_rig

from pslog.fusion import FusionOptions, _type_a, default_max_gap_s, prepare
from pslog.fusion._prepare import rays_only
from pslog.fusion.breaks import fit_breaks_ns, reversed_prepared, spans_break
from pslog.motion import rally_motion
from pslog.records import matching_rows, point_keys
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

KICKS = FusionOptions(confirm_every=True, confirm_sides=True)
seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 600.0
for rig in (apply_timing(builtin_rig("paper3"), "typeA"), ring_rig(4, "lab4")):
    det, truth = simulate(rig, rally_motion(5, seconds), seconds,
                          SimulationOptions(noise_px=0.3, seed=57301))[:2]
    obs = det.best()
    prep = rays_only(prepare(obs, rig))[0]
    opt = replace(KICKS, max_gap_s=default_max_gap_s(rig))
    c = time.process_time(); F = _type_a(prep, rig, opt); tf = time.process_time() - c
    c = time.process_time(); rprep, t0 = reversed_prepared(prep, rig)
    B = _type_a(rprep, rig, opt); tb = time.process_time() - c
    c = time.process_time(); br = fit_breaks_ns(prep, rig, opt); tfit = time.process_time() - c
    t = F.time_ns; span = np.round(F.quality["span_s"] * 1e9).astype(np.int64)
    spanning = spans_break(br, t - span, t, True)
    tbk = t0 - B.time_ns
    idx, has = matching_rows(point_keys(t, F.camera), point_keys(tbk, B.camera))
    d = np.full(len(t), np.inf)
    d[has] = np.linalg.norm(F.position_world[has] - B.position_world[idx[has]], axis=1)
    err = np.linalg.norm(F.position_world - truth.at(t), axis=1); far = err > 0.05
    print(f"{rig.name}: n {len(t)} F {tf:.3f}s B {tb:.3f}s fit {tfit:.3f}s; breaks {len(br)}; "
          f"spanning {spanning.sum()} no-B {(~has).sum()} spanning&no-B {(spanning & ~has).sum()}")
    sF = F.quality["std_m"]; sB = np.full(len(t), np.inf); sB[has] = B.quality["std_m"][idx[has]]
    z = d / np.sqrt(sF ** 2 + sB ** 2)
    T = (t - t.min()) / 1e9
    for k in (2.0, 3.0, 4.0):
        scr = (z > k) | ~has
        for w in (0.1, 0.2):
            cover = np.zeros(int(T.max() * 100) + 1, bool)
            for c in T[scr]:
                cover[max(0, int((c - w) * 100)):int((c + w) * 100) + 1] = True
            print(f"  z>{k} or no-B: {scr.sum()} ({scr.mean()*100:.2f}%) window ±{w}s covers {cover.mean()*100:.1f}% ; far unscreened {(far & ~scr).sum()} spanning unscreened {(spanning & ~scr).sum()}")
    print("  far z:", np.round(z[far], 2), "far d mm", np.round(d[far] * 1e3), "std", np.round(sF[far] * 1e3), np.round(sB[far] * 1e3))
