"""Session 38: could ``--estimate auto``'s tied readouts come from the wide fit alone? The
constrained GLS projection of the per-camera fit, ``θ_c = θ̂ − ΣAᵀ(AΣAᵀ)⁻¹Aθ̂``,
``Σ_c = Σ − ΣAᵀ(AΣAᵀ)⁻¹AΣ`` (``A``: each camera's readout minus its model's first one's;
exact for a linear model), against the tied fit itself (``offset,readout=shared``).

    PYTHONPATH=. python benchmarks/session38/tie_projection.py FIRST N READOUT_MS
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    from pslog.api import sync
    from pslog.estimation.sync import estimate_clocks
    from pslog.log import read_session

    first, n, readout = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(first, first + n):
            path = Path(tmp) / f"{seed}.mcap"
            subprocess.run([sys.executable, "-m", "pslog.cli", "simulate", "--rig", "paper3",
                            "--timing", "typeA", "--motion", "rally", "--duration", "8",
                            "--noise-px", "0.3", "--clock-offset", "cam2=5", "--clock-offset",
                            "cam3=-7", "--readout", readout, "--seed", str(seed), "-o",
                            str(path)], check=True, capture_output=True)
            outcome = sync(read_session(path), "offset")
            obs, rig = outcome.observations, read_session(path).rig
            t = time.process_time()
            wide = estimate_clocks(obs, rig, ("offset", "readout"))
            t_wide = time.process_time() - t
            t = time.process_time()
            tied = estimate_clocks(obs, rig, ("offset", "readout=shared"))
            t_tied = time.process_time() - t
            names = list(wide.unknowns)
            x = np.array([getattr(wide.cameras[c], {"offset": "offset_s",
                                                    "readout": "readout_s"}[p])
                          for c, p in names])
            cov = wide.covariance
            ro = [j for j, (_, p) in enumerate(names) if p == "readout"]
            A = np.zeros((len(ro) - 1, len(names)))
            for i, j in enumerate(ro[1:]):
                A[i, j], A[i, ro[0]] = 1.0, -1.0
            K = cov @ A.T @ np.linalg.inv(A @ cov @ A.T)
            xc = x - K @ (A @ x)
            cc = cov - K @ A @ cov
            y = np.array([getattr(tied.cameras[c], {"offset": "offset_s",
                                                    "readout": "readout_s"}[p])
                          for c, p in names])
            sy = np.sqrt(np.diag(tied.covariance))
            sc = np.sqrt(np.maximum(np.diag(cc), 0))
            print(f"{seed}: projection - tied fit, in the tied σ: "
                  + " ".join(f"{(a - b) / s:+.3f}" for a, b, s in zip(xc, y, sy, strict=True))
                  + "; σ ratio " + " ".join(f"{a / b:.3f}" for a, b in zip(sc, sy, strict=True))
                  + f"; cpu wide {t_wide:.3f} s, tied fit {t_tied:.3f} s", flush=True)


if __name__ == "__main__":
    os.environ.setdefault("PSLOG_PROGRESS", "off")
    main()
