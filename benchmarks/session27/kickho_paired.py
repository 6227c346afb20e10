# ruff: noqa: E501
"""kickho.py's pickles: the two variants' errors on the points both output (same time and
camera order), all points (no max_std_m), by fps: mean error and how many points moved."""
import pickle
import sys

import numpy as np

rows = []
for f in sys.argv[1].split(","):
    rows += pickle.load(open(f, "rb"))
acc = {}
for row in rows:
    a, b = row["res"]["before"], row["res"]["new"]
    common, ia, ib = np.intersect1d(a["t"], b["t"], return_indices=True)
    ok = np.isfinite(a["err"][ia]) & np.isfinite(b["err"][ib])
    k = (row["fps"], row["noise"])
    s = acc.setdefault(k, [0, 0.0, 0.0, 0, 0, 0])
    ea, eb = a["err"][ia][ok], b["err"][ib][ok]
    s[0] += len(ea)
    s[1] += ea.sum()
    s[2] += eb.sum()
    s[3] += int(np.sum(ea != eb))
    s[4] += int(np.sum(ea > 0.05))
    s[5] += int(np.sum(eb > 0.05))
print("| fps, px | common points | mean error before → new, mm | points moved | beyond 5 cm (no max_std_m) before → new |")
print("|---|---|---|---|---|")
for k, s in sorted(acc.items()):
    print(f"| {k[0]:.0f}, {k[1]} | {s[0]} | {1e3 * s[1] / s[0]:.3f} → {1e3 * s[2] / s[0]:.3f} | {s[3]} | {s[4]} → {s[5]} |")
