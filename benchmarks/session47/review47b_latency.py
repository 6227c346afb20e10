# ruff: noqa: E501
"""Session 47's second review: the stream's latency with the holds (``FilterStream``, one
detection per push): per point, the time of the detection whose push let it leave minus its
own detection's time; hold_gap 1.5 (the default) against None. Rigs: ``lab3`` at 30 fps with
two cameras blacked out 1.0 s (one camera alone), ``lab3`` with one camera never seeing the
ball, ``lab2`` with 30 % misses. Ungated (``det.best()``), misses 0.1 unless said, seeds
87200-. Usage: ``PYTHONPATH=.:tests python benchmarks/session47/review47b_latency.py FIRST N``"""
import sys

import numpy as np
from _rally import rally
from test_filter import lab_rig

from pslog.fusion import FusionOptions
from pslog.fusion.filter import BallFilter, FilterOptions, FilterStream
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig


def case(kind, seed):
    if kind == "lab3 blackout 2 cams 1.0 s":
        r = lab_rig(3, 30.0)
        return r, ((r.names[1], 1.0, 1.0), (r.names[2], 1.0, 1.0)), 0.1
    if kind == "lab3 one blind":
        r = lab_rig(3, 30.0)
        return r, ((r.names[2], 0.0, 100.0),), 0.1
    if kind == "lab2 misses 0.3":
        return lab_rig(2, 30.0), (), 0.3
    raise ValueError(kind)


def latencies(rig, obs, hold_gap):
    fs = FilterStream(rig, FusionOptions())
    fs.filter = BallFilter(rig, FilterOptions(hold_gap=hold_gap))
    lat = []
    for i in range(len(obs.time_ns)):
        t = int(obs.time_ns[i])
        tr = fs.push_one(t, int(obs.camera[i]), float(obs.uv[i, 0]), float(obs.uv[i, 1]))
        lat.extend((t - tr.time_ns).tolist())
    return np.array(lat) / 1e9, len(fs.flush())


def main():
    first, n = int(sys.argv[1]), int(sys.argv[2])
    print("| case | hold_gap | points | median latency ms | p99 ms | max ms | > 100 ms | left at flush |")
    print("|---|---|---|---|---|---|---|---|")
    for kind in ("lab3 blackout 2 cams 1.0 s", "lab3 one blind", "lab2 misses 0.3"):
        for hg in (None, 1.5):
            all_l, flushed = [], 0
            for seed in range(first, first + n):
                rig, bo, misses = case(kind, seed)
                opts = SimulationOptions(noise_px=0.5, seed=seed, miss_rate=misses, spurious_rate=0.05, blackouts=bo)
                det, _, _ = simulate_labelled(rig, rally(3.0, seed=seed, speed=4.0 + seed % 3, kick_every_s=0.6)[0], 3.0, opts)
                rig = true_rig(rig, opts)
                lat, fl = latencies(rig, det.best(), hg)
                all_l.append(lat)
                flushed += fl
            lat = np.concatenate(all_l)
            print(f"| {kind} | {hg} | {len(lat)} | {1e3 * np.median(lat):.1f} | {1e3 * np.quantile(lat, 0.99):.1f} | {1e3 * lat.max():.0f} | {int(np.sum(lat > 0.1))} | {flushed} |", flush=True)


if __name__ == "__main__":
    main()
