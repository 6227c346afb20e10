# ruff: noqa: E501
"""Session 36 (ffar36): the filter's per-detection internals on one dirty-session instant.

    PYTHONPATH=. python benchmarks/session36/ffar_trace.py RIG FIRST K [FPS] T0 T1 [--blackout]

Replays the observations ``fuse_detections`` gives the filter through ``BallFilter.push``
one at a time and prints, per detection in [T0, T1] s: the status (point / withheld and
why / none), the error, the kernel's flags (has track, pending confirmation camera,
rejects in a row, latest jump camera) and the dropped counters that moved."""
import sys
from dataclasses import replace

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import numpy as np
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs

import pslog.fusion.filter as F
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

args = [a for a in sys.argv[1:] if not a.startswith("--")]
rname, first, k = args[0], int(args[1]), int(args[2])
fps = float(args[3]) if len(args) > 5 else None
t0, t1 = float(args[-2]), float(args[-1])
rig = next(r for r in rigs() + more_rigs() if r.name == rname)
if fps:
    rig = at_rate(rig, fps)
label, motion, duration, _k = list(more_sessions(3, 8.0, first))[k]
seed = first - 300 + k
span = motion.duration if duration is None else duration
f = faults(rig, seed, span)
extra = {"blackouts": f["blackouts"]} if "--blackout" in sys.argv else f
det, truth, lab = simulate_labelled(rig, motion, duration,
                                    SimulationOptions(noise_px=0.3, seed=seed, **extra))
print(label, seed, f["blackouts"])
cap = {}
orig = F.fuse_filter


def spy(obs, rig_, max_gap_s=None, options=None, doubt=None):
    cap.update(obs=obs, max_gap_s=max_gap_s, options=options, doubt=doubt)
    return orig(obs, rig_, max_gap_s, options, doubt)


F.fuse_filter = spy
tr = fuse_detections(det, rig, ["filter"], FusionOptions(), workers=1)[0]["filter"]
obs = cap["obs"]

opts = cap["options"]
if cap["max_gap_s"] is not None and opts.max_gap_s is None:
    opts = replace(opts, max_gap_s=cap["max_gap_s"])
flt = F.BallFilter(rig, opts)
tt = truth.time_ns.astype(np.int64)


def true_at(t):
    return np.array([np.interp(t, tt, truth.position_world[:, j]) for j in range(3)])


I = flt._I
for i in range(len(obs.time_ns)):
    before = dict(flt.dropped)
    t = int(obs.time_ns[i])
    if cap["doubt"] is not None and cap["doubt"][i] > 0:
        pass
    if "--prior" in sys.argv and t0 <= t / 1e9 <= t1 and I[F._IHAS]:
        pr = flt.predict(t)
        xp = np.concatenate([pr[0], pr[1]])
        xtr = np.concatenate([true_at(t), (true_at(t + 500_000) - true_at(t - 500_000)) / 1e-3])
        d6 = xp - xtr
        w, V = np.linalg.eigh(pr[2])
        z = V.T @ d6 / np.sqrt(w)
        print(f"   prior nees6 {d6 @ np.linalg.solve(pr[2], d6):.1f}; err in P's eigenbasis (sd, z): "
              + " ".join(f"({np.sqrt(a):.3g},{b:.1f})" for a, b in zip(w, z, strict=False)))
    r = flt.push(t, int(obs.camera[i]), float(obs.uv[i, 0]), float(obs.uv[i, 1]))
    ts = t / 1e9
    if t0 <= ts <= t1:
        moved = {kk: v - before.get(kk, 0) for kk, v in flt.dropped.items() if v != before.get(kk, 0)}
        st = f"has={I[F._IHAS]} pend={I[F._IPEND]} rej={I[F._IREJ]} jcam={I[F._IJUMPCAM]} conf={I[F._ICONF]}"
        x = flt._S[F._SX:F._SX + 3]
        P = flt._S[F._SP:F._SP + 36].reshape(6, 6)
        d = x - true_at(t)
        xe = np.linalg.norm(d) * 1e3
        vt = (true_at(t + 500_000) - true_at(t - 500_000)) / 1e-3
        ve = np.linalg.norm(flt._S[F._SX + 3:F._SX + 6] - vt)
        nees = float(d @ np.linalg.solve(P[:3, :3], d))
        st += (f" | state perr {xe:.1f} mm sd {np.sqrt(np.trace(P[:3, :3]))*1e3:.1f} nees {nees:.0f}"
               f" verr {ve:.2f} m/s vsd {np.sqrt(np.trace(P[3:, 3:])):.2f} lag {I[F._IJLAG]} shape {I[F._IJSHAPE]}"
               f" q {flt._S[F._SQ]:.3g} var {flt._S[F._SVAR]:.3g} mu {flt._S[F._SMU]:.2f} nu {flt._S[F._SNU]:.2f}")
        if r is None:
            print(f"{ts:.4f} c{obs.camera[i]} none {moved} {st}")
        else:
            p, q = r
            e = np.linalg.norm(np.array(p) - true_at(t)) * 1e3
            qd = dict(zip(F.FILTER_QUALITY, q, strict=False))
            print(f"{ts:.4f} c{obs.camera[i]} POINT err {e:.1f} std {qd['std_m']*1e3:.1f} inn {qd['innovation_px']:.2f} nis {qd['nis']:.2f} jump {qd['jump']:.0f} rej {qd['rejected']:.0f} init {qd['init']:.0f} {st}")
