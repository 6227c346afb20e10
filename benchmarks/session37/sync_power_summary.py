"""Summarise sync_power.py's table: per rig, duration and readout, the share of sessions whose
readouts auto keeps under the session-36 rule (W > χ²_k at 0.1 %) and under the nested rule
(W_s > χ²_g at 0.05 % or W > χ²_k at 0.05 %: Bonferroni, size <= 0.1 %).

    python benchmarks/session37/sync_power_summary.py power.tsv [more.tsv ...]
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict

from scipy.stats import chi2

LEVEL = 1e-3


def main(paths) -> int:
    groups = defaultdict(list)
    for path in paths:
        with open(path) as f:
            for row in csv.DictReader(f, delimiter="\t"):
                if row["W"].startswith("FAILED") or not row.get("k"):
                    continue
                groups[(row["rig"], row["dur"], row["readout_ms"])].append(row)
    print(f"{'rig':<8} {'s':>3} {'readout ms':<10} {'n':>3} {'old keeps':>9} {'new keeps':>9}"
          f"  {'median W/k':>10} {'median Ws/g':>11} {'σ common ms':>11}")
    for (rig, dur, spec), rows in groups.items():
        old = new = 0
        for r in rows:
            w, k, ws, g = float(r["W"]), int(r["k"]), float(r["W_shared"]), int(r["k_shared"])
            old += w > chi2.isf(LEVEL, k)
            if g < k:
                new += ws > chi2.isf(LEVEL / 2, g) or w > chi2.isf(LEVEL / 2, k)
            else:
                new += w > chi2.isf(LEVEL, k)
        med = sorted(float(r["W"]) for r in rows)[len(rows) // 2]
        meds = sorted(float(r["W_shared"]) for r in rows)[len(rows) // 2]
        sd = sorted(float(r["common_sd_ms"]) for r in rows)[len(rows) // 2]
        print(f"{rig:<8} {dur:>3} {spec:<10} {len(rows):>3} {old:>9} {new:>9}  "
              f"{med:>6.1f}/{rows[0]['k']:<3} {meds:>7.1f}/{rows[0]['k_shared']:<3} {sd:>11.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
