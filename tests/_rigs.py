"""Test rigs shared by the tests and ``benchmarks/bench_dirty.py`` (which puts this folder on
its path, as for ``_rally``)."""

from __future__ import annotations

import numpy as np

from pslog import Camera, Rig, look_at


def ring_rig(n: int, name: str, f: float = 520.0, dist=(-0.12, 0.03, 5e-4, -4e-4, 0.0),
             radius: float = 3.4, height: float = 2.4) -> Rig:
    """``n`` 800 x 600 cameras in a ring around the 3 x 2 m floor, type-A shutters."""
    cams = []
    for i in range(n):
        angle = 2 * np.pi * i / n - 1.2
        eye = (1.5 + radius * np.cos(angle), 1.0 + 0.9 * radius * np.sin(angle),
               height + 0.2 * i)
        R, t = look_at(eye, (1.5, 1.0, 0.6))
        fi = f + 10 * i
        K = [[fi, 0.0, 399.5], [0.0, fi, 299.5], [0.0, 0.0, 1.0]]
        cams.append(Camera(f"{name}-{i + 1}", 800, 600, K, np.array(dist), R, t, 30.0,
                           i / (n * 30.0)))
    return Rig(tuple(cams), name)
