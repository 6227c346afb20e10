"""Test rigs shared by the tests and the benchmarks (``bench_dirty.py``, ``fusion_equality.py``
and ``smooth_equality.py`` put this folder on their path, as for ``_rally``)."""

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


def lab3_rig(rise: float = 0.3, focal_step: float = 20.0, prefix: str = "lab",
             name: str = "lab3") -> Rig:
    """bench_dirty's ``lab3``: three 800 x 600 cameras around the 3 x 2 m floor with a wide
    lens, type A offsets of 0, 1/90 and 2/90 s; camera ``i`` (from 0) ``rise * i`` m higher
    than the first and its focal length ``focal_step * i`` px longer (test_estimation's
    ``edge3``: 0.2 and 15, views the ball leaves and re-enters)."""
    dist = np.array([-0.12, 0.03, 5e-4, -4e-4, 0.0])
    cams = []
    for i in range(3):
        angle = 2 * np.pi * i / 3 - 1.2
        eye = (1.5 + 3.4 * np.cos(angle), 1.0 + 3.0 * np.sin(angle), 2.4 + rise * i)
        R, t = look_at(eye, (1.5, 1.0, 0.6))
        f = 520.0 + focal_step * i
        K = [[f, 0.0, 399.5], [0.0, f, 299.5], [0.0, 0.0, 1.0]]
        cams.append(Camera(f"{prefix}{i + 1}", 800, 600, K, dist, R, t, 30.0, i / 90.0))
    return Rig(tuple(cams), name)
