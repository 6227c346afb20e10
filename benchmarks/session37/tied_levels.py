"""auto's outcome under other levels of the equal-readouts test, from tied_accuracy.py's
tables (no refit: each row holds the per-camera and the tied fit's scores and the equal
statistic): per table and level, sessions tied, wrong ties (a model whose cameras'
readouts differ: a spec whose values differ within a model), and the mean typeA / smooth /
filter error and smooth's NEES of auto's choice.

    python benchmarks/session37/tied_levels.py shared.tsv differ.tsv
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np
from scipy.stats import chi2

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE.parents[1]))

from sync_power import make_rig, model_groups  # noqa: E402

LEVELS = (1e-3, 1e-2, 0.05, 0.2)
DOF = {10.8: 1, 13.8: 2, 16.3: 3, 3.8: 1, 6.0: 2, 7.8: 3}  # threshold printed (0.1 %, 5 %) -> k - g


def wrong_tie(row) -> bool:
    rig = make_rig(row["rig"])
    values = [float(v) for v in row["readout"].split("/")]
    r = np.array([values[i % len(values)] for i in range(len(rig))])
    groups = model_groups(rig)
    return any(len(set(r[groups == g])) > 1 for g in set(groups))


def main(argv=None) -> int:
    for path in (argv or sys.argv[1:]):
        rows = list(csv.DictReader(open(path), delimiter="\t"))
        print(f"{path}: {len(rows)} sessions")
        for level in LEVELS:
            tied = wrong = 0
            out = {k: [] for k in ("typeA", "smooth", "filter", "nees")}
            for r in rows:
                eq = float(r["equal_chi2"])
                tie = False
                if r["kept"] == "1" and np.isfinite(eq):
                    dof = DOF[round(float(r["equal_thr"]), 1)]
                    tie = not eq > chi2.isf(level, dof)
                tied += tie
                wrong += tie and wrong_tie(r)
                src = "tied" if tie else ("percam" if r["kept"] == "1" else "auto")
                if r["kept"] == "0":
                    src = "auto"
                for m in ("typeA", "smooth", "filter"):
                    out[m].append(float(r[f"{m}_{src}"]))
                out["nees"].append(float(r[f"nees_{src}"]))
            print(f"  level {level:g}: tied {tied}, wrong {wrong}; typeA/smooth/filter "
                  + "/".join(f"{np.mean(out[m]):.2f}" for m in ("typeA", "smooth", "filter"))
                  + f", smooth NEES {np.mean(out['nees']):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
