"""Issue 10 (session 37): type A's CPU time on a 10-minute rally (best candidates, 0.3 px)
with the offline kick test (``--confirm-gaps kicks``, pslog fuse's default) and with the
backward pass across the session fit's breaks (``--confirm-gaps breaks``), and that fit
alone (``smooth``); median of 3, alternated; process CPU time.

    PYTHONPATH=. python benchmarks/session37/sides_time.py [SECONDS]
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

KICKS = FusionOptions(confirm_every=True, confirm_sides=True)
VARIANTS = {"kicks": ("typeA", KICKS),
            "breaks": ("typeA", FusionOptions(confirm_every=True, confirm_sides=True,
                                              confirm_breaks=True)),
            "smooth": ("smooth", FusionOptions())}


def main():
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 600.0
    for rig in (apply_timing(builtin_rig("paper3"), "typeA"), ring_rig(4, "lab4")):
        det = simulate(rig, rally_motion(5, seconds), seconds,
                       SimulationOptions(noise_px=0.3, seed=1))[0]
        obs = det.best()
        times = {k: [] for k in VARIANTS}
        for _ in range(3):
            for k, (m, o) in VARIANTS.items():
                t0 = time.process_time()
                track = fuse(obs, rig, m, o)
                times[k].append(time.process_time() - t0)
                if k == "breaks":
                    n_rev = int(np.count_nonzero(track.quality["span_s"] < 0))
                    n_out = track.dropped.get("break", 0)
        print(f"{rig.name} {seconds:g} s ({len(obs)} detections): "
              + ", ".join(f"{k} {np.median(v):.3f} s" for k, v in times.items())
              + f"; breaks replaced {n_rev}, withheld {n_out}")


if __name__ == "__main__":
    main()
