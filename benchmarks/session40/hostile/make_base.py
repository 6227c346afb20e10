"""Base artefacts for the hostile40 probes: a simulated throw (seed 63001), its fused
session, the truth as CSV (t,x,y,z) and TUM, and one detections CSV per camera.

    python benchmarks/session40/hostile/make_base.py DIR
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np


def pslog(*args: object) -> None:
    subprocess.run([sys.executable, "-m", "pslog.cli", *map(str, args)], check=True)


def main(folder: str) -> None:
    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
          "--noise-px", "0.3", "--seed", "63001", "-o", d / "s.mcap", "--force")
    pslog("fuse", d / "s.mcap", "-o", d / "f.mcap", "--force")
    pslog("export", d / "f.mcap", "--tum", d / "tum", "--force")
    pslog("export", d / "s.mcap", "--detections", d / "det.csv", "--force")
    import pslog as api
    from pslog.log.csvio import format_time

    truth = api.read_session(d / "s.mcap").truth
    with open(d / "truth.csv", "w") as f:
        f.write("t,x,y,z\n")
        for t, (x, y, z) in zip(truth.time_ns.tolist(), truth.position_world.tolist(),
                                strict=True):
            f.write(f"{format_time(t)},{x!r},{y!r},{z!r}\n")
    lines = (d / "det.csv").read_text().splitlines()
    header, rows = lines[0], lines[1:]
    for cam in sorted({r.split(",")[0] for r in rows}):
        with open(d / f"{cam}.csv", "w") as f:
            f.write(header.partition(",")[2] + "\n")
            f.writelines(r.partition(",")[2] + "\n" for r in rows if r.split(",")[0] == cam)
    print(np.unique([r.split(",")[0] for r in rows], return_counts=True))


if __name__ == "__main__":
    main(sys.argv[1])
