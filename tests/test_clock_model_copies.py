"""The one-detection form of the timing model that the gate and the live fuser use
(:func:`pslog.fusion.gating._true_time_ns`, scalar floats for speed) is
:func:`pslog.timing.true_times_ns` to the nanosecond: offset, drift from the session start,
the rolling shutter's ``readout · v / height`` from the top row (docs/timing.md, "The
model"), on rows across the image and on epoch-sized logged times."""

from __future__ import annotations

import numpy as np

from pslog.fusion.gating import _clock_model, _true_time_ns
from pslog.rig import Rig, builtin_rig
from pslog.timing import true_times_ns


def test_the_scalar_clock_model_is_the_timing_modules_to_the_nanosecond():
    rng = np.random.default_rng(23)
    cams = builtin_rig("paper3").cameras
    rig = Rig((cams[0].replace(readout=0.021),
               cams[1].replace(clock_offset=0.0043, clock_drift_ppm=-37.5, readout=0.012),
               cams[2].replace(clock_offset=-0.0117, clock_drift_ppm=81.0)), "clocks")
    model = _clock_model(rig)
    n = 3000
    logged = np.concatenate([rng.integers(0, 7200 * 10**9, n // 2),       # two hours
                             rng.integers(0, 10**9, n // 2) + 1_733_000_000 * 10**9])  # epoch
    cam = rng.integers(0, 3, n)
    v = rng.uniform(-0.5, 479.5, n)
    v[:3] = (0.0, 240.0, 480.0)  # the top row, the middle, the bottom edge
    p = {k: np.array([float(getattr(c, k)) for c in rig.cameras])[cam]
         for k in ("height", "clock_offset", "clock_drift_ppm", "readout")}
    expected = true_times_ns(logged, v, p["height"], p["clock_offset"], p["clock_drift_ppm"],
                             p["readout"])
    got = np.array([_true_time_ns(int(t), float(r), model[c])
                    for t, r, c in zip(logged, v, cam, strict=True)])
    np.testing.assert_array_equal(got, expected)
    # by hand: camera 1 (offset 0, readout 21 ms) at the bottom row is 21 ms late, at the top
    # row on time; camera 2 logged at 2 s on row 120: 2 + 0.0043 - 37.5e-6 · 2 + 0.012 / 4
    assert _true_time_ns(10**9, 480.0, model[0]) == 10**9 + 21_000_000
    assert _true_time_ns(10**9, 0.0, model[0]) == 10**9
    assert _true_time_ns(2 * 10**9, 120.0, model[1]) == 2_007_225_000
