"""Issue 10 (session 33): type A's time on a 60-s rally (best candidates, 0.3 px) with the
default options, ``confirm_every`` and ``confirm_sides`` (median of 7, alternated; CPU).

    PYTHONPATH=. python benchmarks/session33/sides_time.py
"""
import sys
import time

import numpy as np

sys.path.insert(0, "tests")
from _rigs import ring_rig

from pslog.fusion import FusionOptions, fuse
from pslog.motion import rally_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

VARIANTS = {"default": FusionOptions(), "every": FusionOptions(confirm_every=True),
            "kicks": FusionOptions(confirm_every=True, confirm_sides=True)}


def main():
    for rig in (apply_timing(builtin_rig("paper3"), "typeA"), ring_rig(4, "lab4")):
        det = simulate(rig, rally_motion(5, 60.0), 60.0, SimulationOptions(noise_px=0.3, seed=1))[0]
        obs = det.best()
        times = {k: [] for k in VARIANTS}
        for o in VARIANTS.values():
            fuse(obs, rig, "typeA", o)  # (warm)
        for _ in range(7):
            for k, o in VARIANTS.items():
                t0 = time.perf_counter()
                fuse(obs, rig, "typeA", o)
                times[k].append(time.perf_counter() - t0)
        print(rig.name, {k: f"{1e3 * np.median(v):.1f} ms" for k, v in times.items()})


if __name__ == "__main__":
    main()
