# ruff: noqa: E501
"""Issue 10 (session 28, twocam): the process noise's adaptation and the rays' angle per
session (``paper2`` at 30 fps, 0.3 px, clean), grouped by ``filter / typeA`` above / below
1/2 (twocam_per.py's ``--dump`` of the same first seeds). Each session is fused as ``pslog
fuse`` does to capture the filter's observations, which are then pushed one at a time into
a ``BallFilter`` (the batch filter's kernel) to read ``q`` after every detection.

    PYTHONPATH=. python benchmarks/session28/twocam_q.py out.pkl
"""
import dataclasses
import pickle
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session28")
from twocam_per import bd, rig_of

import pslog.fusion as pf
from pslog.fusion import FusionOptions
from pslog.fusion.filter import BallFilter, FilterOptions, accel_floor
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled


def ray_angle_deg(centres: np.ndarray, points: np.ndarray) -> np.ndarray:
    d0, d1 = points - centres[0], points - centres[1]
    cos = np.sum(d0 * d1, 1) / np.linalg.norm(d0, axis=1) / np.linalg.norm(d1, axis=1)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def main() -> None:
    with open(sys.argv[1], "rb") as fh:
        rows = pickle.load(fh)
    rig = rig_of("paper2", 30.0)
    centres = np.array([c.center_world for c in rig.cameras])
    q_min = accel_floor(rig, FilterOptions())
    print(f"q_min {q_min:g} m²/s³")
    orig = pf.METHODS["filter"]
    captured = {}

    def _capture(prep, rig_, options):
        captured["obs"] = prep.obs
        return orig.function(prep, rig_, options)

    groups: dict = {True: [], False: []}
    pf.METHODS["filter"] = dataclasses.replace(orig, function=_capture)
    try:
        for r in rows:
            runs = bd.more_sessions(2, 8.0, r["fs"])
            k = [run[0] for run in runs].index(r["label"])
            _, motion, duration, _ = runs[k]
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=r["fs"] - 300 + k))
            fuse_detections(det, rig, ["filter"], FusionOptions())
            obs = captured["obs"]
            flt = BallFilter(rig, FilterOptions(max_gap_s=FusionOptions().max_gap_s))
            qs = np.empty(len(obs.time_ns))
            for i in range(len(qs)):
                flt.push(int(obs.time_ns[i]), int(obs.camera[i]), float(obs.uv[i, 0]),
                         float(obs.uv[i, 1]))
                qs[i] = flt._q
            angle = ray_angle_deg(centres, truth.at(obs.time_ns))
            ratio = r["main"]["F"] / r["A"]
            floor = float(np.mean(qs <= 1.05 * q_min))
            groups[ratio > 0.5].append((floor, np.median(qs / q_min), np.mean(qs / q_min),
                                        np.median(angle), angle.min()))
            print(f"{r['fs']} {r['label']:14s} filter/typeA {ratio:.3f} q at its floor {100 * floor:3.0f}% "
                  f"q/q_min median {np.median(qs / q_min):5.2f} mean {np.mean(qs / q_min):5.1f} | "
                  f"rays' angle median {np.median(angle):5.1f} min {angle.min():5.1f} deg", flush=True)
    finally:
        pf.METHODS["filter"] = orig
    for above in (True, False):
        g = np.array(groups[above])
        print(f"{'above' if above else 'below'} 1/2 (n {len(g)}): q at its floor {100 * g[:, 0].mean():.0f}% of the "
              f"detections, q/q_min median {np.median(g[:, 1]):.2f} mean {g[:, 2].mean():.1f}; rays' angle "
              f"median {g[:, 3].mean():.1f} deg, smallest {g[:, 4].min():.1f}")


if __name__ == "__main__":
    main()
