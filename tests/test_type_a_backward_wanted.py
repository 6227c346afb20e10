"""Type A's backward pass keeps only the points the ``breaks`` rule reads (session 45):
``pslog.fusion._type_a``'s ``wanted`` and :func:`pslog.fusion.confirm.confirm_batch`'s
``only``. Each point kept is the one the whole track has on its detection, bit for bit
(every column, and the same points dropped): the kernel still runs on every detection, and
the confirmation's σ is the causal median over every point made, not over the ones wanted.
The session is dirty (misses, spurious blobs, a static second object) through a lens, so the
confirmation drops points among the wanted ones.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from _rally import dirty_rally
from _rigs import ring_rig
from test_stream_gating import assert_same_track

from pslog.fusion import FusionOptions, _type_a, default_max_gap_s, prepare
from pslog.fusion._prepare import rays_only
from pslog.fusion.breaks import reversed_prepared
from pslog.records import point_keys
from pslog.simulation import SimulationOptions, simulate_labelled

KICKS = FusionOptions(confirm_every=True, confirm_sides=True)


@pytest.fixture(scope="module")
def backward():
    rig = ring_rig(3, "lab3")
    motion, _ = dirty_rally(79001)
    det, _, _ = simulate_labelled(rig, motion, 8.0, options=SimulationOptions(
        noise_px=1.0, seed=79001, miss_rate=0.1, spurious_rate=0.05,
        distractors=((None, (1.0, 1.5, 0.2)),)))
    prep = rays_only(prepare(det.best(), rig))[0]
    return rig, reversed_prepared(prep, rig)[0]


@pytest.mark.parametrize("noise_px", [0.5, None])
@pytest.mark.parametrize("share", [0.03, 0.3])
def test_the_wanted_points_are_the_whole_tracks(backward, noise_px, share):
    rig, prep = backward
    options = replace(KICKS, noise_px=noise_px, max_gap_s=default_max_gap_s(rig))
    whole = _type_a(prep, rig, options)
    made = _type_a(prep, rig, replace(options, confirm_gaps=False, confirm_every=False,
                                      confirm_sides=False))  # (before the tests)
    assert sum(whole.dropped.values()) > sum(made.dropped.values())  # (the tests drop some)
    rng = np.random.default_rng(79002)
    obs = prep.obs
    pick = rng.random(len(obs)) < share
    wanted = point_keys(obs.time_ns[pick], obs.camera[pick])
    part = _type_a(prep, rig, options, wanted=wanted)
    keys = point_keys(whole.time_ns, whole.camera)
    expected = whole.select(np.isin(keys, wanted))
    # some wanted points were made and then dropped by the confirmation: their absence is
    # the whole run's decision too
    made_keys = point_keys(made.time_ns, made.camera)
    assert np.count_nonzero(np.isin(made_keys, wanted) & ~np.isin(made_keys, keys)) > 0
    assert_same_track(part, expected, dropped=False)  # (every column, bit for bit)
