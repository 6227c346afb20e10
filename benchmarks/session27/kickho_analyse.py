# ruff: noqa: E501
"""Analysis of kickho.py's pickles: NEES (diagonal, /3) by accepted point index after each of
the filter's accepted jumps (index 0 the jump's point; up to the next jump or 0.2 s), by the
jump's shape and by the true height at the jump; overall NEES; beyond 5 cm kept; withheld
good (max_std_m applied after)."""
import pickle
import sys

import numpy as np

sys.path.insert(0, ".")
from pslog.fusion import filter as FM

MAXSTD = FM._MAX_ERROR_M / 1.96
rows = []
for f in sys.argv[1].split(","):
    rows += pickle.load(open(f, "rb"))
variant = sys.argv[2] if len(sys.argv) > 2 else "main"
floor_z = float(sys.argv[3]) if len(sys.argv) > 3 else 0.25
K = 6
acc = {}


def add(key, k, d2):
    acc.setdefault(key, [[] for _ in range(K)])[k].append(d2)


tot = {"d2": [], "far": 0, "good_w": 0, "n": 0, "err": [], "aj_all": [[] for _ in range(K)]}
for row in rows:
    r = row["res"][variant]
    keep = ~(r["std"] > MAXSTD)
    fin = np.isfinite(r["d2"])
    tot["d2"].append(r["d2"][keep & fin])
    tot["far"] += int(np.sum(keep & (r["err"] > 0.05)))
    tot["good_w"] += int(np.sum(~keep & (r["err"] <= 0.05)))
    tot["n"] += len(r["t"])
    tot["err"].append(r["err"][keep & np.isfinite(r["err"])])
    acc_pts = r["rej"] == 0
    js = np.flatnonzero(r["jump"] > 0)
    for a, j in enumerate(js):
        end = js[a + 1] if a + 1 < len(js) else len(r["t"])
        idx = [i for i in range(j, end) if acc_pts[i] and r["t"][i] - r["t"][j] <= 0.2e9][:K]
        shape = int(r["shape"][j])
        high = "mid-air" if r["z"][j] > floor_z else "near floor"
        for k, i in enumerate(idx):
            if fin[i]:
                tot["aj_all"][k].append(r["d2"][i])
            if not (keep[i] and fin[i]):
                continue
            for key in (("all",), (f"shape {shape}",), (f"shape {shape}", high), (high,),
                        (f"{row['fps']:.0f} fps",), (row["rig"],)):
                add(key, k, r["d2"][i])
d = np.concatenate(tot["d2"])
print(f"{variant}: {len(rows)} sessions, points {tot['n']}, NEES all {d.mean() / 3:.4f}, in 2σ "
      f"{100 * np.mean(d <= 4):.2f} %, beyond 5 cm kept {tot['far']}, withheld good {tot['good_w']}")
e = np.concatenate(tot["err"])
print(f"  kept points {len(e)}, mean error {1e3 * e.mean():.3f} mm; NEES by index after a jump, "
      "max_std_m not applied (every point of an accepted detection): "
      + " ".join(f"{np.mean(v) / 3:.2f}" for v in tot["aj_all"]) + f" (n at 0: {len(tot['aj_all'][0])})")
print("| jumps | n at the jump | NEES by point index 0..5 after the jump (kept points) | in 2σ 0..2 |")
print("|---|---|---|---|")
for key in sorted(acc, key=str):
    ks = acc[key]
    print(f"| {' '.join(key)} | {len(ks[0])} | " + " ".join(
        f"{np.mean(v) / 3:.2f}" if v else "-" for v in ks) + " | " + " ".join(
        f"{100 * np.mean(np.array(v) <= 4):.0f}" if v else "-" for v in ks[:3]) + " |")
