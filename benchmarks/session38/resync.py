"""Session 38: a synced copy synced again (``pslog sync`` twice) against one sync.

For each seed: ``pslog simulate`` (paper3, typeA, the rally, 8 s, 0.3 px, offsets cam2 +5 /
cam3 -7 ms, a shared readout of READOUT ms), ``pslog sync`` (auto) once, then ``pslog sync``
(auto) of that copy. Per sync: the parameters estimated, the readout test's verdict, the
clocks' NEES against the truth under the stored covariance (the estimated parameters:
``d Σ⁺ d / rank``), smooth's mean error and NEES after ``pslog fuse``, and the sync's CPU
seconds (user + sys of the process).

    PYTHONPATH=. python benchmarks/session38/resync.py FIRST N [READOUT_MS] [DURATION_S]
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

TRUE_OFFSET_MS = {"cam2": 5.0, "cam3": -7.0}


def run(*argv: str) -> tuple[str, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, "-m", "pslog.cli", *argv], capture_output=True,
                          text=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        raise SystemExit(f"{argv}: {done.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return done.stdout, cpu


def clocks_nees(path: Path, readout_s: float) -> tuple[float, int]:
    from pslog.log import read_session

    session = read_session(path)
    stored = json.loads(session.metadata["clock_std"])
    names = [tuple(n) for n in stored["covariance"]["parameters"]]
    cov = np.array(stored["covariance"]["matrix"])
    cams = {c.name: c for c in session.rig.cameras}
    d = []
    for name, key in names:
        value = float(getattr(cams[name], key))
        truth = (TRUE_OFFSET_MS.get(name, 0.0) * 1e-3 if key == "clock_offset" else
                 readout_s if key == "readout" else 0.0)
        d.append(value - truth)
    d = np.array(d)
    rank = int(np.linalg.matrix_rank(cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov))),
                                     tol=1e-9))
    return float(d @ np.linalg.pinv(cov, rcond=1e-12, hermitian=True) @ d) / rank, rank


def smooth(path: Path, folder: Path) -> tuple[float, float]:
    fused = folder / (path.stem + "-fused.mcap")
    run("fuse", str(path), "--method", "smooth", "-o", str(fused), "--force")
    text, _ = run("eval", str(fused), "--json")
    (m,) = json.loads(text)
    return m["mean_mm"], m["quality"]["nees"]


def main() -> None:
    first, n = int(sys.argv[1]), int(sys.argv[2])
    readout_ms = float(sys.argv[3]) if len(sys.argv) > 3 else 6.0
    duration = sys.argv[4] if len(sys.argv) > 4 else "8"
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for seed in range(first, first + n):
            raw = folder / f"s{seed}.mcap"
            args = ["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                    "--duration", duration, "--noise-px", "0.3", "--seed", str(seed),
                    "--clock-offset", "cam2=5", "--clock-offset", "cam3=-7", "-o", str(raw)]
            if readout_ms:
                args += ["--readout", f"{readout_ms:g}"]
            run(*args)
            current = raw
            for label in ("once", "twice"):
                out = folder / f"s{seed}-{label}.mcap"
                text, cpu = run("sync", str(current), "-o", str(out), "--json")
                report = json.loads(text)
                (test,) = [t for t in report["selection"] if t["parameter"] == "readout"]
                nees, rank = clocks_nees(out, readout_ms * 1e-3)
                mm, snees = smooth(out, folder)
                cams = report["cameras"]
                print(f"{seed} {label:5s} est={','.join(report['estimated']):14s} "
                      f"tied={report['shared_readout']!s:5s} p={test['p_value']:.2g} "
                      f"off2={cams[1]['offset_s'] * 1e3:7.3f}±{cams[1]['offset_std_s'] * 1e3:.3f} "
                      f"off3={cams[2]['offset_s'] * 1e3:7.3f}±{cams[2]['offset_std_s'] * 1e3:.3f} "
                      f"ro1={cams[0]['readout_s'] * 1e3:6.3f}±{cams[0]['readout_std_s'] * 1e3:.3f} "
                      f"clockNEES={nees:6.2f}/{rank} smooth={mm:6.2f}mm NEES={snees:5.2f} "
                      f"cpu={cpu:5.1f}s", flush=True)
                current = out


if __name__ == "__main__":
    os.environ.setdefault("PSLOG_PROGRESS", "off")
    main()
