"""review41b: c3d_grid before session 41 (main's) against now, on hand-made point times:
the rate, the frames and the points left out (sharing a frame) of each.

    python benchmarks/session41/review41b_c3d.py OLD_TRACK_FORMATS.py

Seeds 69200-69299."""
from __future__ import annotations

import importlib.util
import sys
from types import SimpleNamespace

import numpy as np

from pslog.camera import Camera
from pslog.interchange.track_formats import c3d_grid
from pslog.rig import Rig, builtin_rig

NS = 1_000_000_000


class T:
    def __init__(self, t):
        self.time_ns = np.sort(np.asarray(t, dtype=np.int64))

    def __len__(self):
        return len(self.time_ns)


def cams(*fps_offsets) -> Rig:
    base = builtin_rig("paper3").cameras[0]
    return Rig(tuple(Camera(**{**{k: getattr(base, k) for k in (
        "width", "height", "K", "dist", "R", "t")}, "name": f"cam{i + 1}", "fps": f,
        "offset": o}) for i, (f, o) in enumerate(fps_offsets)), "x")


def shutters(rig, seconds, rng, miss=0.0, jitter=0.0, start=0.0):
    t = np.concatenate([np.arange(start, start + seconds, 1 / c.fps) + c.offset
                        for c in rig.cameras])
    t = t + rng.normal(0, jitter, len(t)) if jitter else t
    return np.round(np.sort(t[rng.random(len(t)) >= miss]) * NS)


def left(tracks, rate, first):
    return sum(len(t) - len(np.unique(np.round((t.time_ns - first) * rate / NS)))
               for t in tracks.values())


def main() -> None:
    spec = importlib.util.spec_from_file_location("old_tf", sys.argv[1])
    old = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(old)
    rng = np.random.default_rng(69200)
    a3 = cams((30, 0), (30, 1 / 90), (30, 2 / 90))
    cases = {}
    cases["typeA 3x30, 10 s"] = (a3, {"typeA": T(shutters(a3, 10, rng))})
    cases["typeA 3x30 miss 0.2 jitter 1 ms"] = (a3, {"typeA": T(shutters(a3, 10, rng, 0.2, 1e-3))})
    mixed = cams((30, 0), (60, 0.005))
    cases["30+60 fps, 5 ms"] = (mixed, {"typeA": T(shutters(mixed, 10, rng))})
    cases["30+60 fps, 5 ms, miss 0.2"] = (mixed, {"typeA": T(shutters(mixed, 10, rng, 0.2))})
    mixed3 = cams((30, 0), (60, 0.004), (60, 0.011))
    cases["30+60+60 fps miss 0.1"] = (mixed3, {"typeA": T(shutters(mixed3, 10, rng, 0.1))})
    for hz in (59, 200):
        cases[f"smooth --rate {hz} + typeA"] = (a3, {
            "smooth": T(np.round(np.arange(0, 10, 1 / hz) * NS)),
            "typeA": T(shutters(a3, 10, rng, 0.1))})
    pair = cams((60, 0), (60, 0.004))
    cases["2x60 4 ms miss 0.2"] = (pair, {"typeA": T(shutters(pair, 10, rng, 0.2))})
    four = cams((60, 0), (60, 0.0029), (60, 0.0074), (60, 0.0126))
    cases["4x60 uneven"] = (four, {"typeA": T(shutters(four, 10, rng))})
    cases["4x60 uneven miss 0.3"] = (four, {"typeA": T(shutters(four, 10, rng, 0.3))})
    cases["typeA + a single-point track"] = (a3, {"typeA": T(shutters(a3, 10, rng)),
                                                 "nearest": T([int(3.3e9)])})
    cases["typeA 3x30 + a 30-fps camera's track"] = (a3, {
        "typeA": T(shutters(a3, 10, rng, 0.1)), "linear": T(shutters(cams((30, 0)), 10, rng))})
    cases["sparse 3x30 (miss 0.7) + dense smooth 90"] = (a3, {
        "typeA": T(shutters(a3, 10, rng, 0.7)),
        "smooth": T(np.round((np.arange(0, 10, 1 / 90) + 0.001) * NS))})
    cases["typeA 3x30, 15 min"] = (a3, {"typeA": T(shutters(a3, 900, rng, 0.1))})
    cases["4x60 uneven, 5 min"] = (four, {"typeA": T(shutters(four, 300, rng, 0.1))})
    cases["2x60 4 ms miss 0.2, 5 min"] = (pair, {"typeA": T(shutters(pair, 300, rng, 0.2))})
    for ms in (3, 1, 0.3):
        r2 = cams((30, 0), (30, ms / 1e3))
        cases[f"2x30 {ms} ms apart"] = (r2, {"typeA": T(shutters(r2, 10, rng))})
        cases[f"2x30 {ms} ms apart miss 0.1"] = (r2, {"typeA": T(shutters(r2, 10, rng, 0.1))})
    b3 = cams((30, 0), (30, 1 / 60), (30, 0))
    cases["typeB 3x30 (0, 1/60, 0): a track per shutter"] = (b3, {"typeB": T(np.unique(
        shutters(b3, 10, rng)))})
    for name, (rig, tracks) in cases.items():
        s = SimpleNamespace(tracks=tracks, rig=rig, path="x", truth=None)
        total = sum(len(t) for t in tracks.values())
        out = []
        for f in (old.c3d_grid, c3d_grid):
            r, first, n = f(s)
            out.append(f"{r:10.4f} Hz {n:7d} frames {left(tracks, r, first):5d} left out")
        print(f"{name:42s} {total:6d} pts | old {out[0]} | new {out[1]}", flush=True)


if __name__ == "__main__":
    main()
