"""How much a sparser truth file costs ``pslog eval --truth``: a simulated rally's own truth
(samples at every capture time, 90 Hz for type A) written as CSV ``t,x,y,z`` keeping every
k-th sample, scored against the session's fused tracks (the truth linearly interpolated
between the samples kept).

Usage: simulate and fuse first, e.g.

    pslog simulate --rig paper3 --timing typeA --motion rally --duration 3 --noise-px 0.3 \\
        --spurious 0.1 --miss-rate 0.05 --seed 61001 -o DIR/sim.mcap
    pslog fuse DIR/sim.mcap -o DIR/fused.mcap
    python benchmarks/session40/truth_sampling.py DIR

prints, per k, method -> (mean, median, max) mm (session 40's figures in docs/interchange.md).
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys

from pslog.log import read_session
from pslog.log.csvio import format_time


def main(folder: str) -> None:
    fused = f"{folder}/fused.mcap"
    truth = read_session(fused).truth
    for k in (1, 2, 3, 5):
        path = f"{folder}/truth_every_{k}.csv"
        with open(path, "w", newline="") as fh:
            out = csv.writer(fh)
            out.writerow("txyz")
            for t, p in zip(truth.time_ns[::k].tolist(), truth.position_world[::k].tolist(),
                            strict=True):
                out.writerow([format_time(t), *map(repr, p)])
        done = subprocess.run([sys.executable, "-m", "pslog.cli", "eval", fused, "--truth",
                               path, "--json"], capture_output=True, text=True, check=True)
        rows = json.loads(done.stdout)
        print(k, {r["method"]: (round(r["mean_mm"], 3), round(r["median_mm"], 3),
                                round(r["max_mm"], 2)) for r in rows})


if __name__ == "__main__":
    main(sys.argv[1])
