"""Session 39 probe: does pslog sync's offset scan pick a wrong offset when the search is wider
than the cameras' overlap allows (a trial that slides one camera out of the window leaves its
detections unshared, fitted alone at no cost)? Runs pslog.sync on a session with the scan's
cost as it is ("as is") and restricted to the detections shared at the trial's times, per
detection ("shared")."""
import sys
import time

import numpy as np

import pslog
from pslog.estimation import sync as S

original = S._pair_cost


def shared_cost(sub, rig, c, unknowns, theta, j, value, params, options):
    trial = theta.copy()
    trial[j] = value
    t = params.times(sub, trial)
    other = sub.camera == c
    keep = np.zeros(len(t), bool)
    a, b = np.flatnonzero(other), np.flatnonzero(~other)
    ta, tb = np.sort(t[a]), np.sort(t[b])
    keep[a] = S._near(t[a], tb, options.max_gap_s) if len(tb) else False
    keep[b] = S._near(t[b], ta, options.max_gap_s) if len(ta) else False
    n = int(keep.sum())
    if n < S.MIN_DETECTIONS:
        return np.nan
    cost = original(sub.select(np.flatnonzero(keep)), rig, c, unknowns, theta, j, value,
                    params, options)
    return cost / n


path, search_ms = sys.argv[1], float(sys.argv[2])
session = pslog.read_session(path)
for label in ("as is", "shared"):
    S._pair_cost = original if label == "as is" else shared_cost
    t0 = time.perf_counter()
    out = pslog.sync(session, "offset", search_s=search_ms / 1e3 if search_ms > 0 else None)
    cams = out.result.cameras
    print(f"{path} ±{search_ms} ms {label}: " + ", ".join(
        f"{c.name} {c.offset_s * 1e3:.3f} ± {c.offset_std_s * 1e3:.3f} ms" for c in cams[1:])
        + f", residual {out.result.residual_px:.3f} px, {time.perf_counter() - t0:.1f} s")
