"""Is ``pslog sync``'s reported ± an honest 1σ? (session 41, review41)

One motion held fixed per setting, only the pixel noise (and the shutter draw) redrawn per
seed: the spread (standard deviation) of the estimates over the seeds is the estimator's
real 1σ, to be compared with the mean σ it reports. Also the RMS of err/σ (1 when honest)
and the largest |err|/σ. Seeds 67000.. (session 41's range).

    python benchmarks/session41/sync_sigma.py [--seeds 30] [--setting NAME]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from pslog import SimulationOptions, apply_timing, builtin_rig, simulate
from pslog.estimation.sync import estimate_clocks
from pslog.motion import rally_motion
from pslog.rig import Rig
from pslog.simulation import true_rig

SETTINGS = {
    # name: (rig, motion seed, duration, estimate, offsets ms, readouts ms, drifts ppm)
    "paper3-offsets": ("paper3", 67000, 8.0, ("offset",),
                       {"cam2": 7.3, "cam3": -12.0}, {}, {}),
    "paper2-offsets": ("paper2", 67001, 8.0, ("offset",), {"cam2": -9.5}, {}, {}),
    "paper3-readouts": ("paper3", 67002, 8.0, ("offset", "readout"),
                        {"cam2": 7.3, "cam3": -12.0},
                        {"cam1": 22.0, "cam2": 25.0, "cam3": 18.0}, {}),
    "paper3-drifts-30s": ("paper3", 67003, 30.0, ("offset", "drift"),
                          {"cam2": 7.3, "cam3": -12.0}, {}, {"cam2": 35.0, "cam3": -25.0}),
}


def _nominal(rig: Rig) -> Rig:
    return Rig(tuple(c.replace(clock_offset=0.0, clock_drift_ppm=0.0, readout=0.0)
                     for c in rig.cameras), rig.name)


def run(setting: str, seeds: int) -> None:
    rig_name, motion_seed, duration, estimate, off, ro, dr = SETTINGS[setting]
    rig = apply_timing(builtin_rig(rig_name), "typeA")
    motion = rally_motion(motion_seed, duration=duration)
    faults = dict(clock_offset_s={k: v / 1e3 for k, v in off.items()},
                  readout_s={k: v / 1e3 for k, v in ro.items()}, clock_drift_ppm=dict(dr))
    rows: dict[tuple[str, str], list[tuple[float, float]]] = {}
    t0 = time.perf_counter()
    for seed in range(67000, 67000 + seeds):
        opts = SimulationOptions(noise_px=0.3, seed=seed, **faults)
        detections, _ = simulate(rig, motion, duration, opts)
        truth = true_rig(rig, opts)
        res = estimate_clocks(detections.best(), _nominal(rig), estimate)
        for i, est in enumerate(res.cameras):
            cam = truth.cameras[i]
            if i > 0 and "offset" in estimate:
                rows.setdefault((cam.name, "offset ms"), []).append(
                    ((est.offset_s - cam.clock_offset) * 1e3, est.offset_std_s * 1e3))
            if i > 0 and "drift" in estimate:
                rows.setdefault((cam.name, "drift ppm"), []).append(
                    (est.drift_ppm - cam.clock_drift_ppm, est.drift_std_ppm))
            if "readout" in estimate:
                rows.setdefault((cam.name, "readout ms"), []).append(
                    ((est.readout_s - cam.readout) * 1e3, est.readout_std_s * 1e3))
        print(f"  seed {seed} done ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    print(f"{setting}: {rig_name}, rally_motion({motion_seed}), {duration} s, 0.3 px, "
          f"estimate {','.join(estimate)}, {seeds} noise seeds from 67000")
    print(f"{'camera':<6} {'param':<11} {'mean err':>9} {'spread':>8} {'mean σ':>8} "
          f"{'spread/σ':>8} {'rms z':>6} {'max|z|':>6} {'|z|>2':>5}")
    for (cam, p), v in rows.items():
        e, s = np.array(v).T
        z = e / s
        print(f"{cam:<6} {p:<11} {e.mean():>+9.4f} {e.std(ddof=1):>8.4f} {s.mean():>8.4f} "
              f"{e.std(ddof=1) / s.mean():>8.2f} {np.sqrt(np.mean(z**2)):>6.2f} "
              f"{np.abs(z).max():>6.2f} {np.sum(np.abs(z) > 2):>5d}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=30)
    ap.add_argument("--setting", choices=list(SETTINGS), action="append")
    a = ap.parse_args()
    for s in a.setting or list(SETTINGS):
        run(s, a.seeds)


if __name__ == "__main__":
    main()
