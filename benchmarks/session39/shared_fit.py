# ruff: noqa: E501, E702
"""Session 39 probe: the kick instants of ``--confirm-gaps breaks`` from ``smooth``'s own fit
(the offline gate's choices, smooth's doubt rule: the fit a default ``pslog fuse`` makes
anyway) instead of a fit of type A's causal-gated observations, and the backward pass run on
windows after the spanning points only.

Per run (bench_dirty ``--more``'s five rigs, 3 rallies, the library's rally, ``straight``,
``turntable``; 0.3 px; ``--faults``: bench_dirty's faults): far points (> 5 cm) of the default
``kicks`` -> after the rule, good points (<= 5 cm) withheld, replaced, for the breaks of
(own) type A's fit, (smooth) smooth's fit, and (smooth+win) smooth's breaks with the
backward pass on windows ``[t, t + WIN]`` around the spanning points (merged) instead of
the whole session; CPU of the fits and of the two backward passes.

    PYTHONPATH=. python benchmarks/session39/shared_fit.py FIRST [FPS|-] [MISSES] [--faults]
"""
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.fusion import FusionOptions, _type_a, offline_confirmation, type_a_prepared  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s, prepare  # noqa: E402
from pslog.fusion.breaks import fit_breaks_ns, reversed_prepared, spans_break  # noqa: E402
from pslog.fusion.gating import gate_for, prepared_for  # noqa: E402
from pslog.fusion.smooth import session_fit  # noqa: E402
from pslog.records import Observations, matching_rows, point_keys  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

WIN = 0.3e9


def smooth_breaks(det, rig, opt):
    """smooth's fit as fuse_smooth makes it (offline gate, doubted choices left out unless the
    fit predicts them): its breaks (ns)."""
    gated = gate_for(det, rig, "smooth", opt)
    fit = session_fit(prepared_for(gated, rig), rig, opt)[0]
    if fit is None:
        return np.zeros(0, np.int64)
    tr = fit.trajectory
    return np.sort(tr.t0_ns + np.round(np.asarray(tr.breaks_s) * 1e9).astype(np.int64))


def windowed_backward(prep, rig, opt, starts):
    """The backward points on windows [s, s + WIN] (merged) of the forward observations:
    (time_ns forward, camera, position, span_s) of the points made."""
    t_all = prep.obs.time_ns
    starts = np.sort(starts)
    wins = []
    for s in starts:
        if wins and s <= wins[-1][1]:
            wins[-1][1] = max(wins[-1][1], s + WIN)
        else:
            wins.append([s, s + WIN])
    out_t, out_c, out_p, out_s = [], [], [], []
    covered = 0
    for lo_t, hi_t in wins:
        lo, hi = np.searchsorted(t_all, [lo_t - 1, hi_t], side="left")
        if hi - lo < 4:
            continue
        covered += hi - lo
        sub = prep.obs
        o = Observations(sub.time_ns[lo:hi], sub.camera[lo:hi], sub.uv[lo:hi], sub.frame_index[lo:hi])
        p = prepare(o, rig)
        if prep.doubt_px2 is not None:
            p = replace(p, doubt_px2=prep.doubt_px2[lo:hi])
        rp, t0 = reversed_prepared(p, rig)
        B = _type_a(rp, rig, replace(opt, confirm_breaks=False))
        out_t.append(t0 - B.time_ns); out_c.append(B.camera); out_p.append(B.position_world)
        out_s.append(B.quality["span_s"] if len(B) else np.zeros(0))
    if not out_t:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0), 0
    return (np.concatenate(out_t), np.concatenate(out_c), np.concatenate(out_p),
            np.concatenate(out_s), covered)


def apply_rule(br, t, sf, bt, bc, bp, bs, cam, truth_at, eF):
    idx, has = matching_rows(point_keys(t, cam), point_keys(bt, bc))
    sb = np.zeros(len(t), np.int64)
    sb[has] = np.round(bs[idx[has]] * 1e9).astype(np.int64)
    spanning = spans_break(br, t - sf, t, True)
    bsp = np.ones(len(t), bool)
    bsp[has] = spans_break(br, t[has], t[has] + sb[has], False)
    use = spanning & has & ~bsp
    out = spanning & ~use
    eB = np.full(len(t), np.inf)
    eB[has] = np.linalg.norm(bp[idx[has]] - truth_at[has], axis=1)
    new = np.where(use, eB, eF)
    return use, out, new


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    first = int(args[0])
    fps = float(args[1]) if len(args) > 1 and args[1] != '-' else None
    kind = "faults" if "--faults" in sys.argv else "clean"
    misses = float(args[2]) if len(args) > 2 else 0.0
    opt = offline_confirmation(FusionOptions())
    tot = {}
    cpu = dict.fromkeys(("own fit", "smooth fit", "backward", "backward win"), 0.0)
    cover = [0, 0]
    diff_win = [0, 0]
    for base in rigs() + more_rigs():
        rig = base if fps is None else at_rate(base, fps)
        optg = replace(opt, max_gap_s=default_max_gap_s(rig))
        for seed, (label, motion, duration, _k) in enumerate(more_sessions(3, 8.0, first), start=first - 300):
            span = motion.duration if duration is None else duration
            extra = {} if kind == "clean" else faults(rig, seed, span)
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, miss_rate=misses, **extra))
            _, prep = type_a_prepared(det, rig, opt)
            F = _type_a(prep, rig, optg)
            if not len(F):
                continue
            t = F.time_ns
            sf = np.round(F.quality["span_s"] * 1e9).astype(np.int64)
            truth_at = truth.at(t)
            eF = np.linalg.norm(F.position_world - truth_at, axis=1)
            c0 = time.process_time(); own = fit_breaks_ns(prep, rig, optg); cpu["own fit"] += time.process_time() - c0
            c0 = time.process_time(); sm = smooth_breaks(det, rig, optg); cpu["smooth fit"] += time.process_time() - c0
            c0 = time.process_time()
            rp, t0 = reversed_prepared(prep, rig)
            B = _type_a(rp, rig, replace(optg, confirm_breaks=False))
            cpu["backward"] += time.process_time() - c0
            bt, bc, bp, bs = t0 - B.time_ns, B.camera, B.position_world, B.quality["span_s"] if len(B) else np.zeros(0)
            far, good = eF > 0.05, eF <= 0.05
            spanning_sm = spans_break(sm, t - sf, t, True)
            c0 = time.process_time()
            wt, wc, wp, ws, covered = windowed_backward(prep, rig, optg, t[spanning_sm])
            cpu["backward win"] += time.process_time() - c0
            cover[0] += covered; cover[1] += len(prep.obs)
            # the windowed backward points against the whole pass's, on the spanning points
            i1, h1 = matching_rows(point_keys(t[spanning_sm], F.camera[spanning_sm]), point_keys(bt, bc))
            i2, h2 = matching_rows(point_keys(t[spanning_sm], F.camera[spanning_sm]), point_keys(wt, wc))
            both = h1 & h2
            diff_win[0] += int(np.count_nonzero(both & (np.linalg.norm(bp[i1] - wp[i2], axis=1) > 1e-9) | (h1 != h2)))
            diff_win[1] += int(np.count_nonzero(spanning_sm))
            for name, br, b in (("own", own, (bt, bc, bp, bs)), ("smooth", sm, (bt, bc, bp, bs)), ("smooth+win", sm, (wt, wc, wp, ws))):
                use, out, new = apply_rule(br, t, sf, *b, F.camera, truth_at, eF)
                r = tot.setdefault(name, dict.fromkeys(("n", "far0", "far", "good_out", "replaced", "breaks", "bad_repl"), 0))
                r["n"] += len(t); r["far0"] += int(far.sum()); r["far"] += int((~out & (new > 0.05)).sum())
                r["good_out"] += int((good & out).sum()); r["replaced"] += int(use.sum()); r["breaks"] += len(br)
                r["bad_repl"] += int((good & use & (new > 0.05)).sum())
                for i in np.flatnonzero(~out & (new > 0.05)):
                    print(f"  {name}: {rig.name} {label} far left at {(t[i] - t.min()) / 1e9:.3f} s err {new[i] * 1e3:.0f} mm")
        sys.stdout.flush()
    print(f"== first {first} fps {fps or 'rig'} misses {misses} {kind}: CPU " + ", ".join(f"{k} {v:.2f} s" for k, v in cpu.items())
          + f"; windows cover {cover[0] / max(cover[1], 1) * 100:.1f} % of observations; windowed backward differs on {diff_win[0]} of {diff_win[1]} spanning points")
    for name, r in tot.items():
        print(f"  {name}: points {r['n']} far {r['far0']} -> {r['far']}, good withheld {r['good_out']}, replaced {r['replaced']} (good made far {r['bad_repl']}), breaks {r['breaks']}")


if __name__ == "__main__":
    main()
