"""Session 38: ``--estimate auto``'s second fit (a group dropped, or the readouts tied) from
the wide fit's converged clocks without the coarse offset scan, against the same fit from
the rig's values with the scan (before session 38).

Per seed (paper3, typeA, the rally, DURATION s, 0.3 px, offsets cam2 +5 / cam3 -7 ms, a
shared readout of READOUT ms: 12 ties, 0 drops the readouts): the CPU seconds of
``select_clocks`` (process time, best of 3), both ways; the largest difference of any clock
estimate in its σ, and of any σ relatively.

    PYTHONPATH=. python benchmarks/session38/tie_refit.py FIRST N READOUT_MS [DURATION_S]
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
    import pslog.estimation.sync as S
    from pslog.api import sync
    from pslog.log import read_session

    first, n, readout = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    duration = sys.argv[4] if len(sys.argv) > 4 else "8"
    original = S.estimate_clocks

    def cold(*args, **kw):  # the second fit as before: from the rig, scanned
        kw.pop("start", None)
        return original(*args[:6], **kw)  # (select_clocks passes start 7th)

    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(first, first + n):
            path = Path(tmp) / f"{seed}.mcap"
            subprocess.run([sys.executable, "-m", "pslog.cli", "simulate", "--rig", "paper3",
                            "--timing", "typeA", "--motion", "rally", "--duration", duration,
                            "--noise-px", "0.3", "--clock-offset", "cam2=5", "--clock-offset",
                            "cam3=-7", "--readout", readout, "--seed", str(seed), "-o",
                            str(path)], check=True, capture_output=True)
            session = read_session(path)
            out = {}
            for label, fn in (("before", cold), ("after", original)):
                S.estimate_clocks = fn
                cpu = []
                for _ in range(3):
                    t = time.process_time()
                    result = sync(session, "auto").result
                    cpu.append(time.process_time() - t)
                out[label] = (min(cpu), result)
            S.estimate_clocks = original
            (cb, rb), (ca, ra) = out["before"], out["after"]
            est = np.array([[c.offset_s, c.drift_ppm, c.readout_s] for c in ra.cameras])
            ref = np.array([[c.offset_s, c.drift_ppm, c.readout_s] for c in rb.cameras])
            std = np.array([[c.offset_std_s, c.drift_std_ppm, c.readout_std_s]
                            for c in rb.cameras])
            on = std > 0
            dz = np.max(np.abs(est - ref)[on] / std[on]) if on.any() else 0.0
            sa = np.array([[c.offset_std_s, c.drift_std_ppm, c.readout_std_s]
                           for c in ra.cameras])
            ds = np.max(np.abs(sa - std)[on] / std[on]) if on.any() else 0.0
            print(f"{seed} readout {readout} ms: {','.join(ra.estimated)} tied="
                  f"{ra.shared_readout} (before: {','.join(rb.estimated)} "
                  f"tied={rb.shared_readout}); cpu {cb:.3f} -> {ca:.3f} s; "
                  f"max |Δ|/σ {dz:.4f}, max |Δσ|/σ {ds:.4f}", flush=True)


if __name__ == "__main__":
    os.environ.setdefault("PSLOG_PROGRESS", "off")
    main()
