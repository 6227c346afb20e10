"""Session 38 review: is the tied refit's distance from the explicit ``offset,readout=shared``
fit (up to 0.19 σ, ``tie_refit_12ms.txt``) the fitting rounds' stopping tolerance?

Per seed (paper3, typeA, the rally, 8 s, 0.3 px, offsets cam2 +5 / cam3 -7 ms, 12 ms
readouts: ``tie_refit.py``'s setting): ``--estimate auto`` (its tied refit from the wide
fit's clocks) and the explicit ``offset,readout=shared`` fit (from the rig, scanned), each
with the shipped stopping rule (a round moving every clock by less than 0.05 σ, or by less
than 2e-6 scaled) and with one 100 times tighter (0.0005 σ, 1e-12, up to 60 rounds: a copy
of pslog.estimation.sync with those constants). Prints the largest clock difference in the
explicit fit's σ, the joint solves and CPU of each, and both fits' residuals.

    PYTHONPATH=. python benchmarks/session38/tie_tolerance.py 57340 57341 57342 57343 57344
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np


def _variant(source: str, tol: float):
    """pslog.estimation.sync with the rounds' stopping rule ``tol`` σ (1e-12 scaled, 60
    rounds)."""
    text = (source.replace("< 0.05 * std_now", f"< {tol} * std_now")
            .replace("< 2e-6:", "< 1e-12:").replace("_ROUNDS = 8", "_ROUNDS = 60"))
    assert text.count(f"< {tol} * std_now") == 1 and "_ROUNDS = 60" in text
    name = f"pslog.estimation.sync_tol_{str(tol).replace('.', '_')}"
    module = types.ModuleType(name)
    module.__package__ = "pslog.estimation"
    sys.modules[name] = module
    exec(compile(text, name, "exec"), module.__dict__)
    return module


def _fit(module, obs, rig, estimate, reports):
    """(result, CPU s, joint solves) of module.estimate_clocks."""
    solve = module._solve_joint
    count = [0]

    def counted(*args, **kwargs):
        count[0] += 1
        return solve(*args, **kwargs)

    module._solve_joint = counted
    try:
        t = time.process_time()
        result = module.estimate_clocks(obs, rig, estimate, None, regularized=reports)
        return result, time.process_time() - t, count[0]
    finally:
        module._solve_joint = solve


def main() -> None:
    import pslog.estimation.sync as shipped
    from pslog.api import sync
    from pslog.log import read_session

    tight = _variant(Path(shipped.__file__).read_text(), 0.0005)
    keys = ("offset_s", "readout_s")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in map(int, sys.argv[1:]):
            path = Path(tmp) / f"{seed}.mcap"
            subprocess.run([sys.executable, "-m", "pslog.cli", "simulate", "--rig", "paper3",
                            "--timing", "typeA", "--motion", "rally", "--duration", "8",
                            "--noise-px", "0.3", "--clock-offset", "cam2=5", "--clock-offset",
                            "cam3=-7", "--readout", "12", "--seed", str(seed), "-o",
                            str(path)], check=True, capture_output=True)
            outcome = sync(read_session(path), "offset")  # (its observations and rig)
            obs, rig, reports = outcome.observations, outcome.prior, outcome.regularized
            for label, module in (("shipped 0.05 σ", shipped), ("tight 0.0005 σ", tight)):
                warm, cpu_w, n_w = _fit(module, obs, rig, ("auto",), reports)
                cold, cpu_c, n_c = _fit(module, obs, rig, ("offset", "readout=shared"),
                                        reports)
                sd = np.array([[getattr(c, k.replace("_s", "_std_s")) for k in keys]
                               for c in cold.cameras])
                d = np.abs(np.array([[getattr(c, k) for k in keys] for c in warm.cameras])
                           - np.array([[getattr(c, k) for k in keys] for c in cold.cameras]))
                on = sd > 0
                print(f"{seed} {label}: auto tied={warm.shared_readout} {n_w} solves "
                      f"{cpu_w:.2f} s, explicit {n_c} solves {cpu_c:.2f} s; max |Δ|/σ "
                      f"{np.max(d[on] / sd[on]):.4f}; residual {warm.residual_px:.6f} / "
                      f"{cold.residual_px:.6f} px", flush=True)


if __name__ == "__main__":
    os.environ.setdefault("PSLOG_PROGRESS", "off")
    main()
