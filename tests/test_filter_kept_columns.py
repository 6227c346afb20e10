"""``filter``: the batch's end makes its Track's columns from the rows it keeps in one
compiled pass (session 44: ``filter._kept_columns``; before, ``_Hold.settle`` copied the kept
rows, times and cameras, and ``_rows_track`` made the columns from the copies). The same
Track, bit for bit: every column, its dtype and layout, the counts left out, on rallies
whose held points are withdrawn (``Track.dropped["held"]``) and whose gate put choices in
doubt."""

from __future__ import annotations

import numpy as np
import pytest
from _rally import rally
from test_filter import lab_rig

from pslog.fusion import filter as FM
from pslog.fusion.filter import FilterOptions, fuse_filter
from pslog.simulation import SimulationOptions, simulate, true_rig
from pslog.timing import observations as corrected_observations


def _same(new, old):
    assert new.dropped == old.dropped
    for name in ("time_ns", "position_world", "camera"):
        a, b = getattr(new, name), getattr(old, name)
        assert a.dtype == b.dtype and a.shape == b.shape
        assert a.flags.c_contiguous and not a.flags.writeable
        np.testing.assert_array_equal(a, b)
    assert list(new.quality) == list(old.quality)
    for name, column in new.quality.items():
        assert column.dtype == old.quality[name].dtype
        assert column.flags.c_contiguous and not column.flags.writeable
        assert np.array_equal(column.view(np.int64), old.quality[name].view(np.int64)), name


@pytest.mark.parametrize(("misses", "spurious", "seed", "theta"),
                         [(0.1, 0.0, 77045, 2.0), (0.4, 0.15, 77046, 0.0)])
def test_the_kept_rows_columns_are_the_settled_rows_columns(monkeypatch, misses, spurious,
                                                            seed, theta):
    assert FM._hypot_compiled()  # (CPython 3.11: the compiled lengths are math.hypot's)
    rig = lab_rig(3)
    motion, _ = rally(6.0, seed=11, speed=5.0, kick_every_s=0.6)
    options = SimulationOptions(noise_px=0.3, seed=seed, miss_rate=misses,
                                spurious_rate=spurious)
    detections, _ = simulate(rig, motion, None, options)
    obs = corrected_observations(detections, true_rig(rig, options))
    doubt = np.zeros(len(obs.time_ns))
    doubt[::37] = 1.0  # (some choices in doubt: left out before the loop)
    runs = []
    for compiled in (True, False):
        # without the compiled lengths, the batch's end takes the settled rows' path
        monkeypatch.setattr(FM, "_hypot_compiled", lambda compiled=compiled: compiled)
        runs.append([fuse_filter(obs, rig, options=FilterOptions(hold_nis=theta)),
                     fuse_filter(obs, rig, options=FilterOptions(hold_nis=theta),
                                 doubt=doubt)])
    for new, old in zip(*runs, strict=True):
        assert new.dropped.get("held", 0) > 0
        _same(new, old)
