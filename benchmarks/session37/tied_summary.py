"""Summary of tied_accuracy.py's table (stdin): per group (all; rig; readout spec) the mean
typeA / smooth / filter error (mm) of the true clocks, the per-camera fit, the tied fit and
auto's choice (and auto before the tie: the per-camera fit where auto kept readouts),
smooth's mean NEES, how often tied's smooth is closer than per camera's, and
auto's choices (readouts kept; tied).

    python benchmarks/session37/tied_summary.py < shared.tsv
"""

from __future__ import annotations

import csv
import sys

import numpy as np


def main() -> int:
    rows = list(csv.DictReader(sys.stdin, delimiter="\t"))
    for r in rows:  # auto before the tie: readouts kept were estimated per camera
        for key in ("typeA", "smooth", "filter", "nees"):
            a, p = (f"{key}_auto", f"{key}_percam") if key != "nees" else \
                ("nees_auto", "nees_percam")
            r[f"{key}_before"] = r[p] if r["kept"] == "1" else r[a]
    groups: dict[str, list] = {"all": rows}
    for r in rows:
        groups.setdefault(f"{r['rig']} {r['dur']}s", []).append(r)
        groups.setdefault(f"readout {r['readout']}", []).append(r)
    print("group\tn\tkept\ttied\t" + "\t".join(
        f"{w}(A/s/f)" for w in ("true", "percam", "tied", "before", "auto"))
        + "\tnees p/t/before/a\tsmooth tied<percam")
    for name, rs in groups.items():
        def mean(key, rs=rs):
            return np.mean([float(r[key]) for r in rs])
        cells = ["/".join(f"{mean(f'{m}_{w}'):.2f}" for m in ("typeA", "smooth", "filter"))
                 for w in ("true", "percam", "tied", "before", "auto")]
        nees = "/".join(f"{mean(f'nees_{w}'):.2f}"
                        for w in ("percam", "tied", "before", "auto"))
        closer = sum(float(r["smooth_tied"]) < float(r["smooth_percam"]) for r in rs)
        kept = sum(int(r["kept"]) for r in rs)
        tied = sum(int(r["tied"]) for r in rs)
        print(f"{name}\t{len(rs)}\t{kept}\t{tied}\t" + "\t".join(cells)
              + f"\t{nees}\t{closer}/{len(rs)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
