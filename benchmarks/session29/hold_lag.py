# ruff: noqa: E501
"""A "hold for the next camera" rule (session 29, measured, not built), with the jump's
lag: sessions as surprise.py's, each fused as `pslog fuse` does to capture its gated
observations, then those pushed one at a time into ``BallFilter`` (``withhold=False``, the
default options else), each point kept with whether the default output has it, and at each
accepted jump the winner's lag (``_IJLAG``: the jump placed before the lag-th latest
accepted detection). A plain update's output point whose NIS exceeds θ is held until the
next detection of another camera; withheld if that detection made a jump placed before the
held detection (its lag reaches back to it), was rejected, or the track restarted (or no
such detection came); else output, one stagger late. Far points (> 5 cm) removed against
good points withheld, per θ; "any jump" withholds at every jump (session 25's form).
Usage: hold_lag.py FIRST NSEEDS FPS,.. MISSES OUT.pkl | hold_lag.py --table OUT.pkl [...]"""
import pickle
import sys
import time
from dataclasses import replace

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
sys.path.insert(0, "benchmarks/session29")
from _capture import dirty_sessions, orig

from pslog.evaluation import errors_m
from pslog.fusion import filter as FM
from pslog.records import Track


def stream(obs, rig, gap, opts, doubt):
    opts = replace(opts or FM.FilterOptions(), withhold=False)
    if gap is not None and opts.max_gap_s is None:
        opts = replace(opts, max_gap_s=gap)
    flt = FM.BallFilter(rig, opts)
    keep = np.ones(len(obs.time_ns), dtype=bool) if doubt is None else ~(np.asarray(doubt) > 0)
    rows = []
    for i in np.flatnonzero(keep):
        t, c = int(obs.time_ns[i]), int(obs.camera[i])
        out = flt.push(t, c, float(obs.uv[i, 0]), float(obs.uv[i, 1]))
        if out is None:
            continue
        pos, q = out
        lag = int(flt._I[FM._IJLAG]) if q[8] == 1.0 else -1
        rows.append((t, c, *pos, q[6], q[8], q[9], q[10], lag))
    return np.array(rows).reshape(-1, 10)


def run():
    first, nseeds = int(sys.argv[1]), int(sys.argv[2])
    fpss = [float(x) for x in sys.argv[3].split(",")]
    misses, out = float(sys.argv[4]), sys.argv[5]
    res = []
    t0 = time.time()
    for fps, rig, label, truth, (obs, r, gap, opts, doubt) in dirty_sessions(
            first, nseeds, fpss, misses):
        default = orig(obs, r, gap, opts, doubt)
        a = stream(obs, r, gap, opts, doubt)
        tns = a[:, 0].astype(np.int64)
        tr = Track("filter", tns, a[:, 2:5].copy(), a[:, 1].astype(np.int32))
        res.append(dict(rig=rig.name, fps=fps, label=label, t=tns / 1e9, camera=a[:, 1],
                        err=errors_m(tr, truth), nis=a[:, 5], jump=a[:, 6], rejected=a[:, 7],
                        init=a[:, 8], lag=a[:, 9], out=np.isin(tns, default.time_ns)))
        print(f"{rig.name} {time.time() - t0:.0f} s", flush=True)
        with open(out, "wb") as f:
            pickle.dump(res, f)


def verdicts(r, lagged):
    n = len(r["t"])
    bad = np.ones(n, dtype=bool)
    delay = np.full(n, np.nan)
    cam, jump, rej, init, t, lag = r["camera"], r["jump"], r["rejected"], r["init"], r["t"], r["lag"]
    for i in range(n):
        between = 0
        for j in range(i + 1, n):
            if init[j] == 1.0:
                break
            if cam[j] != cam[i]:
                if jump[j] == 1.0:
                    bad[i] = (lag[j] >= between + 1) if lagged else True
                else:
                    bad[i] = rej[j] == 1.0
                delay[i] = t[j] - t[i]
                break
            if rej[j] != 1.0:
                between += 1
    return bad, delay


def table():
    rows = []
    for p in sys.argv[2:]:
        rows += pickle.load(open(p, "rb"))
    for lagged in (False, True):
        c = {k: [] for k in ("err", "nis", "plain", "out", "bad", "delay")}
        for r in rows:
            bad, delay = verdicts(r, lagged)
            plain = (r["jump"] == 0) & (r["rejected"] == 0) & (r["init"] == 0)
            for k, v in (("err", r["err"]), ("nis", r["nis"]), ("plain", plain), ("out", r["out"]),
                         ("bad", bad), ("delay", delay)):
                c[k].append(v)
        c = {k: np.concatenate(v) for k, v in c.items()}
        ok = np.isfinite(c["err"]) & c["out"]
        far = c["err"] > 0.05
        print(f"{'jump placed before the held detection' if lagged else 'any jump'}: sessions {len(rows)}, points output {ok.sum()}, far {np.sum(ok & far)}; delay median {np.nanmedian(c['delay'][ok]) * 1e3:.1f} ms, p95 {np.nanpercentile(c['delay'][ok], 95) * 1e3:.1f} ms")
        print("| θ | held | far removed | good withheld | good per far |")
        print("|---|---|---|---|---|")
        for th in (0.0, 1.0, 2.0, 4.61, 6.0):
            held = ok & c["plain"] & (c["nis"] > th)
            w = held & c["bad"]
            fr, gw = np.sum(w & far), np.sum(w & ~far)
            print(f"| NIS > {th:g} | {held.sum()} | {fr} of {np.sum(ok & far)} | {gw} | {gw / fr if fr else float('inf'):.0f} |")


if __name__ == "__main__":
    table() if sys.argv[1] == "--table" else run()
