# ruff: noqa: E501
"""Table of filter_hold.py's pickles (several: pooled). Usage: filter_hold_table.py OUT.pkl [...]"""
import pickle
import sys

import numpy as np

runs = [pickle.load(open(p, "rb")) for p in sys.argv[1:]]
values = list(runs[0])
base_good = sum(r[values[0]]["good"] for r in runs)
print("| confirm_nis | points | far | good withheld vs 9.21 | far err/std | err²/std² of NIS > 4.61 points (n) |")
print("|---|---|---|---|---|---|")
for v in values:
    pts = sum(r[v]["points"] for r in runs)
    far = sum(r[v]["far"] for r in runs)
    good = sum(r[v]["good"] for r in runs)
    rows = [x for r in runs for x in r[v]["far_rows"]]
    ratio = ", ".join(f"{1e3 * e:.0f}/{1e3 * s:.1f} mm (NIS {n:.1f})" for _, _, _, e, s, n, _ in rows)
    hi = np.concatenate([x for r in runs for x in r[v]["hi_nees"]])
    print(f"| {v:g} | {pts} | {far} | {base_good - good} | {ratio} | {np.mean(hi):.2f} ({len(hi)}) |")
