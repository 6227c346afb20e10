# ruff: noqa: E501
"""Issue 10 (session 36, trap36): one session's filter step by step — each detection's
camera, whether it was a jump / rejected / a start, NIS, q / q_min, the CUSUM g, the turn
model's ν, the pending confirmation's camera, and the error of the point (mm); extra arguments are FilterOptions (key=value, Python literals).

    PYTHONPATH=. python benchmarks/session36/trace.py paper2 turntable 46710 [key=value ...]
"""
from __future__ import annotations

import ast
import dataclasses
import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
import bench_dirty as bd  # noqa: E402

import pslog.fusion as pf  # noqa: E402
import pslog.fusion.filter as F  # noqa: E402
from pslog.fusion import FusionOptions  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.motion import get_motion  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402


def main() -> None:
    rig = {r.name: r for r in bd.rigs() + bd.more_rigs()}[sys.argv[1]]
    motion, seed = get_motion(sys.argv[2]), int(sys.argv[3])
    over = {k: ast.literal_eval(v) for k, v in (a.split("=", 1) for a in sys.argv[4:])}
    det, truth, _ = simulate_labelled(rig, motion, None, SimulationOptions(noise_px=0.3, seed=seed))
    orig, captured = pf.METHODS["filter"], {}

    def _capture(prep, rig_, options):
        captured["obs"] = prep.obs
        return orig.function(prep, rig_, options)

    pf.METHODS["filter"] = dataclasses.replace(orig, function=_capture)
    try:
        fuse_detections(det, rig, ["filter"], FusionOptions())
    finally:
        pf.METHODS["filter"] = orig
    obs = captured["obs"]
    flt = F.BallFilter(rig, F.FilterOptions(max_gap_s=FusionOptions().max_gap_s, **over))
    S, I = flt._S, flt._I
    for i in range(len(obs.time_ns)):
        t = int(obs.time_ns[i])
        pt = flt.push(t, int(obs.camera[i]), float(obs.uv[i, 0]), float(obs.uv[i, 1]))
        err = ""
        if pt is not None:
            err = f"{1e3 * np.linalg.norm(np.array(pt[0]) - truth.at(np.array([t]))[0]):7.2f}"
        print(f"{i:3d} {t / 1e9:7.4f} cam {int(obs.camera[i])} q/qmin {S[F._SQ] / flt._q_min:8.2f} g {S[F._SQG]:6.2f} "
              f"nu {S[F._SNU]:5.3f} pend {I[F._IPEND]:2d} confs {I[F._ICONFS]} jumpT {I[F._IJUMPNS] / 1e9:7.4f} {'point' if pt else '-'} {err}")


if __name__ == "__main__":
    main()
