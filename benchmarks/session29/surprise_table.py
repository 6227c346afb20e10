# ruff: noqa: E501
"""Tables of surprise.py's pickles: scalar NEES (err²/std_m²) of the plain updates by NIS
band (every point of a live track; and the points output), overall, the far points (> 5 cm)
output and their error / std_m, good points withheld; off → on.
Usage: surprise_table.py OUT.pkl [...]"""
import itertools
import pickle
import sys

import numpy as np

BANDS = (0.0, 1.0, 2.0, 4.61, 6.0, 9.21, 18.4, np.inf)


def table(rows):
    cat = {k: np.concatenate([r[k] for r in rows]) for k in ("err", "std_a", "std_b", "nis", "jump", "rejected", "init", "out_a", "out_b")}
    err, sa, sb, nis = cat["err"], cat["std_a"], cat["std_b"], cat["nis"]
    plain = (cat["jump"] == 0) & (cat["rejected"] == 0) & (cat["init"] == 0)
    ok = np.isfinite(err)
    print(f"sessions {len(rows)}, points (withhold off) {ok.sum()}, plain {np.sum(plain & ok)}")
    print("| NIS band | plain points | NEES off → on | median d² off → on | in 2σ off → on | RMS std off → on (mm) | RMS err (mm) |")
    print("|---|---|---|---|---|---|---|")
    for lo, hi in itertools.pairwise(BANDS):
        m = plain & ok & (nis > lo) & (nis <= hi)
        if not m.any():
            continue
        da, db = (err[m] / sa[m]) ** 2, (err[m] / sb[m]) ** 2
        print(f"| {lo:g}–{hi:g} | {m.sum()} | {da.mean():.2f} → {db.mean():.2f} | {np.median(da):.2f} → {np.median(db):.2f} | {np.mean(da <= 4) * 100:.1f} → {np.mean(db <= 4) * 100:.1f} % | {np.sqrt(np.mean(sa[m] ** 2)) * 1e3:.2f} → {np.sqrt(np.mean(sb[m] ** 2)) * 1e3:.2f} | {np.sqrt(np.mean(err[m] ** 2)) * 1e3:.2f} |")
    for name, m in (("all points (withhold off)", ok), ("plain, all", ok & plain), ("output off / on", None)):
        if m is None:
            ma, mb = ok & cat["out_a"], ok & cat["out_b"]
        else:
            ma = mb = m
        da, db = (err[ma] / sa[ma]) ** 2, (err[mb] / sb[mb]) ** 2
        print(f"{name}: NEES {da.mean():.3f} → {db.mean():.3f}, in 2σ {np.mean(da <= 4) * 100:.2f} → {np.mean(db <= 4) * 100:.2f} %, points {ma.sum()} → {mb.sum()}")
    far = err > 0.05
    for tag, o, s in (("off", cat["out_a"], sa), ("on", cat["out_b"], sb)):
        f = ok & o & far
        print(f"{tag}: output {np.sum(ok & o)}, far kept {f.sum()}, good withheld (vs withhold off) {np.sum(ok & ~o & ~far)}, far withheld {np.sum(ok & ~o & far)}; far err/std median {np.median(err[f] / s[f]) if f.any() else 0:.1f} max {np.max(err[f] / s[f]) if f.any() else 0:.1f}")
    f = ok & cat["out_a"] & far
    print("far points of the output off: err mm, std off → on mm, NIS, plain")
    for i in np.flatnonzero(f):
        print(f"  {err[i] * 1e3:6.1f}  {sa[i] * 1e3:5.1f} → {sb[i] * 1e3:5.1f}  nis {nis[i]:5.2f}  plain {int(plain[i])}  output on {int(cat['out_b'][i])}")


if __name__ == "__main__":
    rows = []
    for p in sys.argv[1:]:
        rows += pickle.load(open(p, "rb"))
    table(rows)
