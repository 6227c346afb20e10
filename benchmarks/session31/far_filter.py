# ruff: noqa: E501
"""Session 31 (filterfar): every ``filter`` point further than 5 cm from the truth on
bench_dirty ``--more``'s sessions (its five rigs, its three tests' rallies per first seed,
the library's rally, ``straight``, ``turntable``; 0.3 px), clean and with the issue's faults
(spurious blobs 5 %, the static second object, one camera blind 0.5 s), each fused as
``pslog fuse`` does (gating on, the filter's default options, its inputs captured through
session 29's ``_capture``). A far point of the faulted session is ``added`` when the clean
session's point at that (time, camera) was not far (bench_dirty's count).

Each far point is listed with what explains it: time, camera, error and ``std_m`` (mm),
error / std, NIS, gap, its flags (``jump``, ``rejected``, ``init``), from the same session
fused with ``withhold=False`` (every point, the same states) the accepted updates since the
track's latest jump or (re)start and the cameras among them, and the truth's nearest
velocity jump before it (found from the motion, |second difference| on a 1 ms grid, as
session 28's farpoints.py), ``bounce`` when the ball is on the floor then, else ``kick``,
and whether the filter placed a jump or restart after it (``seen``) or not.

Prints, per rig, the faulted sessions' points output, the far ones (clean / added), the
mean error (mm) and NEES (1 if honest), and the good points (<= 5 cm) and far points the
variant withdraws against the filter's defaults (``key=value`` arguments: FilterOptions
fields, e.g. ``hold_jump_p=None``; ``ref:key=value``: the reference's instead of the
defaults, e.g. ``hold_jump_p=0.05 ref:hold_jump_p=None``).

Usage: far_filter.py FIRST[,FIRST..] FPS MISSES [OUT.pkl|-] [key=value ...]"""
import pickle
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "benchmarks/session29")
sys.path.insert(0, "tests")
from _capture import cap, orig  # (importing it wraps fuse_filter)
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs
from hold_lag import stream

from pslog.evaluation import errors_m, mahalanobis_sq
from pslog.fusion import FusionOptions
from pslog.fusion import filter as FM
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

FAR = 0.05
#: the truth's velocity jumps: |second difference| / dt² above this, m/s²
JUMP_ACCEL = 300.0


def truth_jumps(motion, duration):
    """(times s, on the floor) of the motion's velocity jumps (kicks, bounces)."""
    t = np.arange(0.0, duration + 1e-9, 1e-3)
    p = motion.position(t)
    a = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=1) / 1e-6
    hit = np.flatnonzero(a > JUMP_ACCEL) + 1
    if not len(hit):
        return np.zeros(0), np.zeros(0, bool)
    starts = hit[np.r_[True, np.diff(hit) > 3]]
    return t[starts] - 1e-3, p[starts, 2] < 0.035


def since_flags(full):
    """Per point of the every-point track: (accepted updates since its track's latest jump
    or (re)start, the set of cameras among them, the time of that jump or start s)."""
    q = full.quality
    n = len(full)
    count = np.full(n, -1)
    cams = [frozenset()] * n
    t_event = np.full(n, np.nan)
    c, s, te = -1, set(), np.nan
    for i in range(n):
        if q["init"][i] == 1.0 or q["jump"][i] == 1.0:
            c, s, te = 0, {int(full.camera[i])}, full.time_ns[i] / 1e9
        elif q["rejected"][i] != 1.0 and c >= 0:
            c += 1
            s = s | {int(full.camera[i])}
        count[i], cams[i], t_event[i] = c, frozenset(s), te
    return count, cams, t_event


def next_other(a, i):
    """The next detection of another camera after row ``i`` of :func:`hold_lag.stream`'s
    rows ``a`` (t, camera, x, y, z, nis, jump, rejected, init, lag): a string with its delay
    (ms), its flags, the jump's lag and the accepted detections of row i's camera between
    (a jump reaches back to row i when lag >= between + 1: session 29's rule)."""
    between = 0
    for j in range(i + 1, len(a)):
        if a[j, 8] == 1.0:
            return f"restart after {1e3 * (a[j, 0] - a[i, 0]) / 1e9:.1f} ms"
        if a[j, 1] != a[i, 1]:
            verdict = "withdraws" if a[j, 9] >= between + 1 else "placed after it"
            what = (f"jump lag {a[j, 9]:.0f} (between {between}: {verdict})"
                    if a[j, 6] == 1.0 else "rejected" if a[j, 7] == 1.0 else f"plain nis {a[j, 5]:.1f}")
            return f"{1e3 * (a[j, 0] - a[i, 0]) / 1e9:.1f} ms later cam {a[j, 1]:.0f}: {what}"
        if a[j, 7] != 1.0:
            between += 1
    return "none"


def fused(obs, rig, gap, opts, doubt, **change):
    return orig(obs, rig, gap, replace(opts or FM.FilterOptions(), **change), doubt)


def main():
    firsts = [int(x) for x in sys.argv[1].split(",")]
    fps, misses = float(sys.argv[2]), float(sys.argv[3])
    out = sys.argv[4] if len(sys.argv) > 4 and sys.argv[4] != "-" else None
    pairs = [a.split("=", 1) for a in sys.argv[5:]]
    variant = {k: eval(v) for k, v in pairs if not k.startswith("ref:")}
    reference = {k[4:]: eval(v) for k, v in pairs if k.startswith("ref:")}
    rows, totals = [], {}
    t0 = time.time()
    for first in firsts:
        for base in rigs() + more_rigs():
            rig = at_rate(base, fps)
            tot = totals.setdefault(rig.name, dict(n=0, far_clean=0, added=0, sum_err=0.0,
                                                   sum_d2=0.0))
            for seed, (label, motion, duration, _) in enumerate(more_sessions(3, 8.0, first),
                                                                start=first - 300):
                span = motion.duration if duration is None else duration
                tj, floor = truth_jumps(motion, span)
                far_clean = set()
                for kind in ("clean", "faults"):
                    det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                        noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2,
                        **(faults(rig, seed, span) if kind == "faults" else {})))
                    fuse_detections(det, rig, ["filter"], FusionOptions())
                    obs, r, gap, opts, doubt = cap["a"]
                    tr = fused(obs, r, gap, opts, doubt, **variant)
                    if variant:  # the defaults' points: what the variant withdrew
                        ref = fused(obs, r, gap, opts, doubt, **reference)
                        e_ref = errors_m(ref, truth)
                        gone = ~np.isin(ref.time_ns * 8 + ref.camera, tr.time_ns * 8 + tr.camera)
                        tot.setdefault("good_gone", 0)
                        tot.setdefault("far_gone", 0)
                        tot["good_gone"] += int(np.sum(gone & (e_ref <= FAR)))
                        tot["far_gone"] += int(np.sum(gone & (e_ref > FAR)))
                    err = errors_m(tr, truth)
                    ok = np.isfinite(err)
                    if kind == "faults":
                        tot["n"] += int(ok.sum())
                        tot["sum_err"] += float(err[ok].sum())
                        d2 = mahalanobis_sq(tr, truth)
                        tot["sum_d2"] += float(np.nansum(d2))
                    far = np.flatnonzero(err > FAR)
                    if not len(far):
                        continue
                    full = fused(obs, r, gap, opts, doubt, **{**variant, "withhold": False})
                    rows_full = {(int(a), int(b)): i for i, (a, b) in enumerate(
                        zip(full.time_ns, full.camera, strict=True))}
                    count, cams, t_event = since_flags(full)
                    # every point pushed one at a time, with each jump's lag (session 29)
                    lagged = stream(obs, r, gap, opts, doubt)
                    lag_rows = {(int(a[0]), int(a[1])): k for k, a in enumerate(lagged)}
                    for i in far:
                        key = (int(tr.time_ns[i]), int(tr.camera[i]))
                        if kind == "clean":
                            far_clean.add(key)
                            tot["far_clean"] += 1
                        elif key in far_clean:
                            continue
                        else:
                            tot["added"] += 1
                        t_s = key[0] / 1e9
                        before = np.flatnonzero(tj <= t_s)
                        if len(before):
                            k = before[-1]
                            dk, bounce = t_s - tj[k], bool(floor[k])
                        else:
                            dk, bounce = np.inf, False
                        j = rows_full[key]
                        q = {n: float(v[i]) for n, v in tr.quality.items()}
                        seen = bool(np.isfinite(t_event[j]) and len(before)
                                    and t_event[j] >= tj[before[-1]])
                        row = dict(fps=fps, rig=rig.name, seed=seed, label=label, kind=kind,
                                   t=t_s, cam=key[1], err=float(err[i]), std=q["std_m"],
                                   nis=q["nis"], gap=q["gap_s"], jump=q["jump"],
                                   rejected=q["rejected"], init=q["init"],
                                   since_event=int(count[j]), event_cams=sorted(cams[j]),
                                   t_event=float(t_event[j]), since_truth=dk, bounce=bounce,
                                   seen=seen)
                        row["next"] = next_other(lagged, lag_rows[key])
                        rows.append(row)
                        print(f"{rig.name:10s} {label:14s} {kind:6s} t={t_s:7.3f} cam {key[1]} "
                              f"err {1e3 * row['err']:6.1f} mm std {1e3 * row['std']:5.1f} "
                              f"({row['err'] / row['std']:4.1f}σ) nis {row['nis']:6.1f} "
                              f"gap {1e3 * row['gap']:5.1f} ms J{q['jump']:.0f}R{q['rejected']:.0f}"
                              f"I{q['init']:.0f} | {row['since_event']} upd since filter's "
                              f"jump/start at {row['t_event']:.3f} cams {row['event_cams']} | "
                              f"truth {'bounce' if bounce else 'kick'} {1e3 * dk:5.0f} ms before"
                              f" ({'seen' if seen else 'UNSEEN'}) | next other camera: "
                              f"{row['next']}", flush=True)
            print(f"# {rig.name} {time.time() - t0:.0f} s", flush=True)
    print("rig | faults points | far clean | added | faults mean mm | NEES | withdrawn by the "
          "variant (clean + faults): good / far")
    for name, t in totals.items():
        print(f"{name} | {t['n']} | {t['far_clean']} | {t['added']} | "
              f"{1e3 * t['sum_err'] / max(t['n'], 1):.3f} | "
              f"{t['sum_d2'] / max(3 * t['n'], 1):.3f} | {t.get('good_gone', '-')} / "
              f"{t.get('far_gone', '-')}")
    if out:
        with open(out, "wb") as f:
            pickle.dump({"rows": rows, "totals": totals, "args": sys.argv}, f)


if __name__ == "__main__":
    main()
