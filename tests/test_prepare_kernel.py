"""prepare()'s compiled rays (_prepare_kernel.rays_from_normalized): Camera.rays' directions
bit for bit, from the normalised coordinates prepare inverts the lens for once, and its
pure-Python original the same; on ordinary pixels and on the edge cases Camera.rays handles
(NaN, infinite and far-off pixels, the principal point)."""

from __future__ import annotations

import numpy as np
import pytest

from pslog import builtin_rig
from pslog.fusion import _prepare_kernel
from pslog.fusion._prepare import _rays

LENSES = (None, (-0.25, 0.08, 0.001, -0.001, 0.0), (0.3, -0.1, 0.01, 0.02, 0.05))


@pytest.mark.parametrize("lens", LENSES)
def test_rays_equal_camera_rays_bit_for_bit(lens):
    rng = np.random.default_rng(7)
    for cam in builtin_rig("paper3").cameras:
        if lens is not None:
            cam = cam.replace(dist=np.array(lens))
        cx, cy = cam.K[0, 2], cam.K[1, 2]
        uv = np.concatenate([rng.uniform(-2000, 3000, (3000, 2)),
                             rng.uniform(0, 640, (3000, 2)),
                             [[np.nan, 1.0], [1.0, np.nan], [1e300, 5.0], [-1e300, 1e300],
                              [np.inf, 0.0], [cx, cy], [cx + 1e-9, cy]]])
        with np.errstate(all="ignore"):
            expected = cam.rays(uv)[1]
            xy = cam.undistort_normalized(uv)
            got = _rays(cam, xy)
            python = np.empty_like(got)
            _prepare_kernel.rays_from_normalized.py_func(xy, np.asarray(cam.R, float), python)
        assert np.isnan(expected).any() and np.isfinite(expected).any()
        assert got.tobytes() == expected.tobytes()
        assert np.array_equal(python, expected, equal_nan=True)
        # and prepare's undistorted pixels from the same coordinates: Camera.undistort's
        assert cam.pixels_from_normalized(xy).tobytes() == cam.undistort(uv).tobytes()


def test_rays_hand_computed():
    """The principal point looks along the optical axis, the world's R[2]; a pixel one
    focal length to the right, 45 degrees off it towards R[0]."""
    cam = builtin_rig("paper3").cameras[0]
    out = np.empty((2, 3))
    _prepare_kernel.rays_from_normalized(np.array([[0.0, 0.0], [1.0, 0.0]]),
                                         np.asarray(cam.R, float), out)
    assert np.allclose(out[0], cam.R[2], atol=1e-15)
    assert np.allclose(out[1], (cam.R[0] + cam.R[2]) / np.sqrt(2), atol=1e-15)
