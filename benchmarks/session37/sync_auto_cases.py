"""``--estimate auto``'s choice on bench_sync_auto.py's cases (its seeds: 8 for the 8 s cases,
3 / 2 for the longer ones, as docs/timing.md's table), session 36's rule (the per-camera
test at 0.1 %) beside this session's (the nested one-readout test too, each at 0.05 %): a
case whose choice changed is listed; the tracks of an unchanged choice are the same.

    python benchmarks/session37/sync_auto_cases.py [--only SUBSTRING]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve()
sys.path.insert(0, str(HERE.parents[1]))
sys.path.insert(0, str(HERE.parents[2] / "tests"))

from bench_sync_auto import cases, simulate_case  # noqa: E402
from bench_timing_accuracy import _nominal, _regularize_auto  # noqa: E402
from scipy.stats import chi2  # noqa: E402

from pslog.estimation.sync import AUTO_LEVEL, estimate_clocks  # noqa: E402

SEEDS = {"GS webcams 20 s": 3, "GS drift 2 min own4": 3, "GS no drift 2 min own4": 2,
         "RS webcams 25 ms 20 s": 3, "RS combined 2 min own4": 2}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", default=None)
    args = ap.parse_args(argv)
    lab_rig = str(HERE.parents[1] / "webcams3.toml")
    changed = 0
    for case in cases():
        if args.only and args.only not in case.name:
            continue
        for seed in range(SEEDS.get(case.name, 8 if case.name.startswith("GS") else 3)):
            rig, _, detections, _ = simulate_case(case, seed, lab_rig)
            regular, reports = _regularize_auto(detections)
            res = estimate_clocks(regular.best(), _nominal(rig), "auto", regularized=reports)
            (t,) = [t for t in res.selection if t.parameter == "readout"]
            old = bool(t.dof) and t.statistic > chi2.isf(AUTO_LEVEL, t.dof)
            changed += old != t.kept
            print(f"{case.name:<30} {seed} W {t.statistic:8.1f}/{t.dof} Ws "
                  f"{t.shared_statistic:8.1f}/{t.shared_dof} old {int(old)} new {int(t.kept)}"
                  + ("  CHANGED" if old != t.kept else ""), flush=True)
    print(f"changed: {changed}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
