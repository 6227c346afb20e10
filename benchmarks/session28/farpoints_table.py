# ruff: noqa: E501
"""Tables of farpoints.py's pickles: far points per method and cause, error / std_m, and
type A's withholding. Usage: farpoints_table.py OUT.pkl [...]"""
import pickle
import sys
from collections import Counter, defaultdict

import numpy as np

rows, totals = [], defaultdict(lambda: [0, 0, 0])
for path in sys.argv[1:]:
    d = pickle.load(open(path, "rb"))
    rows += [dict(r, run=path) for r in d["rows"]]
    for k, v in d["totals"].items():
        for i in range(3):
            totals[k][i] += v[i]
methods = sorted({m for _, m in totals})
print("| method | points | far | far by cause | err/std median (max) | far with err > 2 std |")
print("|---|---|---|---|---|---|")
for m in methods:
    n = sum(v[0] for (r, mm), v in totals.items() if mm == m)
    far = sum(v[1] for (r, mm), v in totals.items() if mm == m)
    good = sum(v[2] for (r, mm), v in totals.items() if mm == m)
    rs = [r for r in rows if r["method"] == m]
    c = Counter(r["cause"] for r in rs)
    ratio = np.array([r["err"] / r["std"] for r in rs]) if rs else np.zeros(0)
    rtxt = f"{np.nanmedian(ratio):.1f} ({np.nanmax(ratio):.0f})" if len(ratio) else "-"
    print(f"| {m} | {n} (good {good}) | {far} | {dict(c.most_common())} | {rtxt} | "
          f"{int(np.count_nonzero(ratio > 2))} |")
print()
by = defaultdict(Counter)
for r in rows:
    by[(r["method"], r["rig"])][r["cause"]] += 1
for k in sorted(by):
    print(k, dict(by[k]))
print()
for m in ("smooth", "filter"):
    print(f"-- {m} far points")
    for r in sorted((r for r in rows if r["method"] == m), key=lambda r: (r["rig"], r["seed"], r["t"])):
        q = r["q"]
        extra = ""
        if m == "filter":
            extra = f"jump {q.get('jump', 0):.0f} init {q.get('init', 0):.0f} rej {q.get('rejected', 0):.0f} nis {q.get('nis', np.nan):.1f} gap {1e3 * q.get('gap_s', np.nan):.0f}ms"
        else:
            extra = f"gap {1e3 * q.get('gap_s', np.nan):.0f}ms res {q.get('residual_px', np.nan):.2f}px"
        print(f"{r['rig']:10s} {r['label']:14s} t={r['t']:.4f} cam{r['cam']} err {1e3 * r['err']:.1f} mm std {1e3 * r['std']:.1f} "
              f"cause {r['cause']} since_kick {1e3 * r['since_kick']:.0f} ms ncam {r['ncam']} ang {r['angle']:.0f} "
              f"oracle_far {r['oracle_far']} {extra}")
