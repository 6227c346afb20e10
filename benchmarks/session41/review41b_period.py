"""review41b: motion_period on motions that nearly repeat, turntables of other speeds, other
rigs (fps, camera counts), and a long real session's cost.

    python benchmarks/session41/review41b_period.py

Seeds 69000-69099. The ball's own (labelled) detections at the true clocks."""
from __future__ import annotations

import time

import numpy as np

from pslog.estimation.sync import motion_period
from pslog.fusion._prepare import default_max_gap_s
from pslog.motion import MOTIONS, Motion, at_rest_first
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig


def turntable(rpm: float, radius: float = 0.5) -> Motion:
    w = rpm * 2 * np.pi / 60

    def pos(t):
        t = np.asarray(t, dtype=float)
        return np.stack([1.5 + radius * np.cos(w * t), 1.0 + radius * np.sin(w * t),
                         np.full_like(t, 0.66)], axis=1)
    return Motion(f"turntable{rpm:g}", 20.0, pos)


def rolling(tau: float) -> Motion:  # back and forth, damped (a ball in a bowl)
    def pos(t):
        t = np.asarray(t, dtype=float)
        x = 1.5 + 0.8 * np.exp(-t / tau) * np.cos(2 * np.pi * t / 1.7)
        return np.stack([x, np.full_like(t, 1.0), np.full_like(t, 0.0213)], axis=1)
    return Motion(f"rolling{tau:g}", 20.0, pos)


def bouncing(e: float) -> Motion:  # in place, restitution e, from 1 m
    def pos(t):
        t = np.asarray(t, dtype=float)
        g, h, out = 9.81, 1.0, np.zeros_like(t)
        v = np.sqrt(2 * g * h)
        start, rest = 0.0, np.sqrt(2 * h / g)
        z = np.full_like(t, 0.0213)
        first = t < rest
        z[first] = h - 0.5 * g * t[first] ** 2
        start = rest
        for _ in range(200):
            v *= e
            dur = 2 * v / g
            if dur < 1e-3:
                break
            sel = (t >= start) & (t < start + dur)
            s = t[sel] - start
            z[sel] = 0.0213 + v * s - 0.5 * g * s * s
            start += dur
        del out
        return np.stack([np.full_like(t, 1.5), np.full_like(t, 1.0), z], axis=1)
    return Motion(f"bouncing{e:g}", 20.0, pos)


def run(label, rig, motion, dur, seed, **kw):
    opts = SimulationOptions(noise_px=kw.pop("noise", 0.3), miss_rate=kw.pop("miss", 0.1),
                             seed=seed, **kw)
    _, _, ball = simulate_labelled(rig, motion, dur, opts)
    obs = ball.best()
    t0 = time.process_time()
    p = motion_period(obs, true_rig(rig, opts), default_max_gap_s(rig))
    print(f"{label:44s} seed {seed}: period {p}  ({time.process_time() - t0:.2f} CPU s, "
          f"{len(obs)} obs)", flush=True)


def main() -> None:
    p3 = apply_timing(builtin_rig("paper3"), "typeA")
    p2 = apply_timing(builtin_rig("paper2"), "typeA")
    seeds = iter(range(69000, 69100))
    for rpm in (8, 20, 33.3, 45, 78, 120, 200):
        run(f"paper3 turntable {rpm} rpm", p3, turntable(rpm), 20.0, next(seeds))
    run("paper3 turntable 45 rpm noise 1 px", p3, turntable(45), 20.0, next(seeds), noise=1.0)
    run("paper3 turntable 45 rpm, 10 s rest first", p3, at_rest_first(turntable(45), 10), 20.0,
        next(seeds))
    run("paper3 rally, 16 s rest first", p3, at_rest_first(MOTIONS["rally"], 16), 20.0,
        next(seeds))
    for tau in (5, 20, 60, 200):
        run(f"paper3 rolling back and forth tau {tau}", p3, rolling(tau), 20.0, next(seeds))
    for e in (0.8, 0.9, 0.97):
        run(f"paper3 bouncing in place e {e}", p3, bouncing(e), 20.0, next(seeds))
    run("paper3 turntable blackout cam2 5 s", p3, turntable(45), 20.0, next(seeds),
        blackouts=(("cam2", 5.0, 5.0),))
    run("paper3 turntable miss 0.5", p3, turntable(45), 20.0, next(seeds), miss=0.5)
    run("paper3 rally miss 0.5", p3, MOTIONS["rally"], 20.0, next(seeds), miss=0.5)
    for fps in (60.0, 120.0):
        r = apply_timing(Rig(tuple(c.replace(fps=fps, offset=0.0) for c in p3.cameras), "f"),
                         "typeA")
        run(f"paper3@{fps:g} turntable", r, turntable(45), 20.0, next(seeds))
        run(f"paper3@{fps:g} rally", r, MOTIONS["rally"], 20.0, next(seeds))
    run("paper2 turntable", p2, turntable(45), 20.0, next(seeds))
    run("paper2 rally", p2, MOTIONS["rally"], 20.0, next(seeds))


if __name__ == "__main__":
    main()
