"""Type A's offline confirmation decided by the compiled kernel (session 44:
``confirm._tests_compiled``, :func:`pslog.fusion._confirm_kernel.confirm_kernel`) as by its
numpy statement (``confirm._tests_numpy``: the first confirming camera found by a search
over the rows after each point, ``residual_test``, ``sides_test``): the same confirming
rows, the same contradicted points, bit for bit, on every call of dirty sessions."""

from __future__ import annotations

import numpy as np
from _rigs import ring_rig
from numpy.testing import assert_array_equal

from pslog.fusion import FusionOptions, fuse
from pslog.motion import rally_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate


def test_the_compiled_tests_decide_as_the_numpy_ones(monkeypatch):
    """paper3 at 0.3 px and a distorting 4-camera ring at 1 px with 20 % misses and 10 %
    drops, both with spurious blobs; gated (with the covariance) and best-scored without a
    stated noise (no covariance); every point tested (with and without the side test) and
    only the waiting ones; and again at a threshold of 1 σ, where many decisions lie near
    it (a deviation of a fraction of a pixel shows)."""
    import pslog.fusion.confirm as confirm

    calls = []
    compiled = confirm._tests_compiled

    def both(*args):
        got = compiled(*args)
        calls.append((args[-1], got, confirm._tests_numpy(*args)))
        return got

    monkeypatch.setattr(confirm, "_tests_compiled", both)
    sessions = []
    for rig, noise, misses in ((apply_timing(builtin_rig("paper3"), "typeA"), 0.3, 0.0),
                               (ring_rig(4, "lab4"), 1.0, 0.2)):
        sessions.append((rig, simulate(rig, rally_motion(7, 6.0), 6.0, SimulationOptions(
            noise_px=noise, seed=77044, miss_rate=misses, drop_rate=misses / 2,
            spurious_rate=0.05))[0]))
    for sigmas in (confirm.CONFIRM_SIGMAS, 1.0):
        monkeypatch.setattr(confirm, "CONFIRM_SIGMAS", sigmas)
        for rig, det in sessions:
            for options in (FusionOptions(confirm_every=True, confirm_sides=True),
                            FusionOptions(confirm_every=True, confirm_sides=False),
                            FusionOptions(confirm_every=False)):
                fuse(det, rig, "typeA", options)
            fuse(det.best(), rig, "typeA", FusionOptions(
                confirm_every=True, confirm_sides=True, noise_px=None))
    assert len(calls) == 16
    assert {sides for sides, _, _ in calls} == {True, False}
    # the tests decide something: contradicted points, and points no camera confirms
    assert sum(int(np.count_nonzero(numpy[0])) for _, _, numpy in calls) > 20
    assert sum(int(np.count_nonzero(~numpy[1])) for _, _, numpy in calls) > 0
    for _, (bad, ok), (bad_np, ok_np) in calls:
        assert_array_equal(ok, ok_np)
        assert_array_equal(bad, bad_np)
