"""``benchmarks/bench_dirty.py --validity``'s count of geometrically invalid points
(:func:`bench_dirty.invalid_points`) on hand-placed points of two facing cameras."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_dirty import invalid_points

from pslog import Camera, Rig
from pslog.records import Track

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])


def facing_rig() -> Rig:
    """``a`` at the origin looking along +z (640 x 480); ``b`` at z = 10 m looking back
    along -z with a 64 x 48 image (a narrow view: 0.5 m off the axis at 5 m is outside)."""
    a = Camera("a", 640, 480, K, np.zeros(5), np.eye(3), np.zeros(3), 30.0, 0.0)
    k_b = K.copy()
    k_b[0, 2], k_b[1, 2] = 32.0, 24.0
    flip = np.diag([1.0, -1.0, -1.0])
    b = Camera("b", 64, 48, k_b, np.zeros(5), flip, -flip @ np.array([0.0, 0.0, 10.0]),
               30.0, 0.0)
    return Rig((a, b), "facing")


def track(points, cameras, masks=None) -> Track:
    n = len(points)
    quality = {} if masks is None else {"camera_mask": np.asarray(masks, float)}
    return Track("typeA", np.arange(n, dtype=np.int64), np.asarray(points, float),
                 np.asarray(cameras, np.int32), quality)


def test_invalid_points_counts_behind_contributing_cameras_and_outside_the_own_image():
    rig = facing_rig()
    rows = [((0, 0, 5), 0, 0b11),     # in front of both, inside both images: valid
            ((0, 0, -1), 1, 0b11),    # behind a, which contributed: behind
            ((0, 0, -1), 1, 0b10),    # behind a, which did not contribute: valid
            ((10, 0, 5), 0, 0b01),    # in front of a, outside its image: outside
            ((0.5, 0, 5), 0, 0b11),   # outside b's narrow image, b's detection at another
                                      # time: valid (a, its own camera, sees it)
            ((0.5, 0, 5), 1, 0b11)]   # the same point made by b's detection: outside
    points, cams, masks = zip(*rows, strict=True)
    assert invalid_points(track(points, cams, masks), rig) == (1, 2)


def test_without_camera_mask_the_points_own_camera_is_checked():
    # smooth and filter: a point per detection, no camera_mask
    rig = facing_rig()
    points = [(0, 0, -1), (0, 0, -1), (0, 0, 11), (10, 0, 5)]
    assert invalid_points(track(points, [0, 1, 1, 0]), rig) == (2, 1)
    assert invalid_points(track(np.zeros((0, 3)), []), rig) == (0, 0)
