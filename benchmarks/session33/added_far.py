# ruff: noqa: E501
"""Issue 10 (session 33): every point beyond 5 cm that the faults ADD on bench_dirty's
``--more`` sessions (beyond 5 cm with the faults where the clean session's point at that
(time, camera) is within 5 cm or absent), per method, with its cause:

- ``candidate``: the session fused from the ball's own candidates (the faults' blackout
  kept: ``simulate_labelled``'s labels) has that point within 5 cm: a false candidate was
  chosen somewhere (the gate's);
- ``blackout``: the session with the blackout alone has that point beyond 5 cm too (the
  blind camera's lost view; no gating gives it back);
- ``kick``: less than 40 ms after a velocity jump of the truth; ``other``: none of these.

Usage: added_far.py FIRST FPS MISSES OUT.pkl [METHODS] [NSEEDS]"""
import pickle
import sys
import time

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "benchmarks/session28")
sys.path.insert(0, "tests")
from bench_dirty import MAX_ERROR_M, at_rate, faults, more_rigs, more_sessions, rigs
from farpoints import jumps

from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled


def keyed(track, err):
    return {(int(t), int(c)): float(e) for t, c, e in zip(track.time_ns, track.camera, err, strict=True)}


def main():
    first, fps, misses, out = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), sys.argv[4]
    methods = sys.argv[5].split(",") if len(sys.argv) > 5 else ["typeA", "nearest", "smooth", "filter"]
    nseeds = int(sys.argv[6]) if len(sys.argv) > 6 else 3
    opts = FusionOptions()
    rows, totals, sessions = [], {}, []
    t0 = time.time()
    for base in rigs() + more_rigs():
        rig = at_rate(base, fps)
        for seed, (label, motion, duration, _) in enumerate(more_sessions(nseeds, 8.0, first), start=first - 300):
            span = motion.duration if duration is None else duration
            kicks = jumps(motion, span)
            fault = faults(rig, seed, span)
            base_opts = dict(noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2)
            clean, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(**base_opts))
            dirty, _, ball = simulate_labelled(rig, motion, duration, SimulationOptions(**base_opts, **fault))
            black, _, _ = simulate_labelled(rig, motion, duration, SimulationOptions(**base_opts, blackouts=fault["blackouts"]))
            tr = {k: fuse_detections(d, rig, methods, opts)[0] for k, d in
                  (("clean", clean), ("dirty", dirty), ("ball", ball), ("black", black))}
            cam_b, start, length = fault["blackouts"][0]
            for m in methods:
                e = {k: errors_m(tr[k][m], truth) for k in tr}
                kk = {k: keyed(tr[k][m], e[k]) for k in tr}
                tot = totals.setdefault((rig.name, m), dict(points=[0, 0], far=[0, 0], added=0))
                tot["points"][0] += len(e["clean"])
                tot["points"][1] += len(e["dirty"])
                tot["far"][0] += int(np.count_nonzero(e["clean"] > MAX_ERROR_M))
                tot["far"][1] += int(np.count_nonzero(e["dirty"] > MAX_ERROR_M))
                sessions.append((rig.name, label, seed, m, *(float(np.nanmean(e[k])) for k in ("clean", "dirty", "black"))))
                d = tr["dirty"][m]
                for i in np.flatnonzero(e["dirty"] > MAX_ERROR_M):
                    key = (int(d.time_ns[i]), int(d.camera[i]))
                    ce = kk["clean"].get(key)
                    if ce is not None and ce > MAX_ERROR_M:
                        continue
                    tot["added"] += 1
                    t_s = key[0] / 1e9
                    since = t_s - kicks[kicks <= t_s]
                    dk = float(since.min()) if len(since) else np.inf
                    be, oe = kk["ball"].get(key), kk["black"].get(key)
                    if be is not None and be <= MAX_ERROR_M:
                        cause = "candidate"
                    elif oe is not None and oe > MAX_ERROR_M:
                        cause = "blackout"
                    elif dk < 0.04:
                        cause = "kick"
                    else:
                        cause = "other"
                    q = {k: float(v[i]) for k, v in d.quality.items() if np.ndim(v) == 1}
                    rows.append(dict(fps=fps, misses=misses, rig=rig.name, seed=seed, label=label, method=m,
                                     t=t_s, cam=key[1], err=float(e["dirty"][i]), clean_err=ce, ball_err=be,
                                     black_err=oe, since_kick=dk, cause=cause, fault=fault,
                                     in_blackout=start <= t_s <= start + length + 0.2, q=q))
                    print(f"  ADDED {rig.name} {label} seed {seed} {m} t={t_s:.4f} cam={key[1]} "
                          f"err={1e3 * e['dirty'][i]:.1f} mm clean={ce} ball={be} black={oe} kick+{dk:.3f} -> {cause}; "
                          f"blackout {cam_b} {start:.2f}-{start + length:.2f}, static {fault['distractors'][0][0]}", flush=True)
        print(f"{rig.name} done {time.time() - t0:.0f} s, added {len(rows)}", flush=True)
        with open(out, "wb") as f:
            pickle.dump({"rows": rows, "totals": totals, "sessions": sessions, "args": sys.argv}, f)


if __name__ == "__main__":
    main()
