"""The coarse screen of :class:`recorders.detect.BallDetector` as one compiled loop.

Imported only by a detector built with ``compiled=True`` (numba costs about half a second
to load per process, repaid after a few thousand 1280 x 720 frames).
"""

from __future__ import annotations

import numpy as np

from pslog._jit import kernel


@kernel
def screen_samples(frame: np.ndarray, step: int, rows: int, cols: int, lo: np.ndarray,
                   hi: np.ndarray, xy: np.ndarray, bgr: np.ndarray) -> int:
    """Pixels ``frame[i * step, j * step]`` (i < rows, j < cols) inside the BGR box
    ``[lo, hi]`` (inclusive), in row-major order (as :func:`cv2.findNonZero`).

    Parameters
    ----------
    frame : (H, W, 3) uint8 BGR
    step : subsampling of the coarse grid, full-resolution pixels
    rows, cols : size of the coarse grid
    lo, hi : (3,) uint8, the box's corners
    xy : (m, 2) int32, out: coarse column and row of the first m pixels that pass
    bgr : (m, 3) uint8, out: their colours

    Returns
    -------
    n : int, how many pixels pass (all of them counted; only the first m stored)
    """
    n = 0
    cap = xy.shape[0]
    lb, lg, lr = lo[0], lo[1], lo[2]
    hb, hg, hr = hi[0], hi[1], hi[2]
    for i in range(rows):
        row = frame[i * step]
        for j in range(cols):
            b = row[j * step, 0]
            g = row[j * step, 1]
            r = row[j * step, 2]
            # bitwise &: no branch per comparison (most pixels fail one of them at random)
            if (b >= lb) & (b <= hb) & (g >= lg) & (g <= hg) & (r >= lr) & (r <= hr):
                if n < cap:
                    xy[n, 0] = j
                    xy[n, 1] = i
                    bgr[n, 0] = b
                    bgr[n, 1] = g
                    bgr[n, 2] = r
                n += 1
    return n
