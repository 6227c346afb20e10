"""Session 39's walkthrough: score exported tracks against the user's own truth, as a user must.

``pslog eval`` scores only a session that carries its truth (simulated ones); a user with a
motion-capture truth of an imported session has the exported tracks (``pslog export --csv``,
times on the CSV's original clock) and the truth CSV ``time,x,y,z``. This interpolates the
truth linearly at each point's time and prints each method's mean / median / p95 error (mm).

Usage: python benchmarks/session39/walk_eval.py TRACKS.csv TRUTH.csv
"""

from __future__ import annotations

import csv
import sys
from decimal import Decimal

import numpy as np


def _ns(text: str) -> int:
    return int(Decimal(text) * 1_000_000_000)


def main() -> None:
    tracks_path, truth_path = sys.argv[1:3]
    with open(truth_path) as fh:
        rows = list(csv.DictReader(fh))
    t_truth = np.array([_ns(r["time"]) for r in rows], np.int64)
    p_truth = np.array([[float(r[k]) for k in "xyz"] for r in rows])
    base = int(t_truth[0])
    with open(tracks_path) as fh:
        rows = list(csv.DictReader(fh))
    for method in sorted({r["method"] for r in rows}):
        mine = [r for r in rows if r["method"] == method]
        t = np.array([_ns(r["time"]) for r in mine], np.int64) - base
        p = np.array([[float(r[k]) for k in "xyz"] for r in mine])
        inside = (t >= 0) & (t <= t_truth[-1] - base)
        truth = np.stack([np.interp(t[inside], t_truth - base, p_truth[:, k]) for k in range(3)],
                         axis=1)
        err = np.linalg.norm(p[inside] - truth, axis=1) * 1e3
        print(f"{method:<8} {inside.sum():6d} points  mean {err.mean():7.2f} mm  median "
              f"{np.median(err):6.2f}  p95 {np.percentile(err, 95):7.2f}  max {err.max():8.1f}"
              + (f"  ({(~inside).sum()} outside the truth's span)" if (~inside).any() else ""))


if __name__ == "__main__":
    main()
