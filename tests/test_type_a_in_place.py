"""The registry's ``typeA`` rescales its covariance to the measured noise in the kernel's
quality table (``pseudo.with_measured_noise``'s ``table``), where a copy of the six columns
and seven new ones were fresh memory at every call: the same bits as the copying path, and
the output's ``std_m`` and covariance are rows of that table (no new column)."""

from __future__ import annotations

import numpy as np
import pytest
from _rigs import lab3_rig

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import FusionOptions, default_max_gap_s, fuse, prepare, pseudo
from pslog.fusion.pseudo import _COV_COLUMNS, _fuse_type_a, covariance_noise_px


def _bits(a: np.ndarray) -> bytes:
    return np.ascontiguousarray(a).tobytes()


@pytest.mark.parametrize("rig_name", ["paper3", "lab3"])  # (no lens; strong lens)
def test_rescale_in_place_keeps_the_bits(rig_name):
    rig = apply_timing(builtin_rig(rig_name), "typeA") if rig_name == "paper3" else lab3_rig()
    obs = simulate(rig, get_motion("throw"), options=SimulationOptions(noise_px=0.5, seed=5)
                   )[0].best()
    gap = default_max_gap_s(rig)
    px = covariance_noise_px(0.5)
    # the copying path: fuse_type_a's track, rescaled into new columns
    prep = prepare(obs, rig)
    track = pseudo.fuse_type_a(prep, gap, 0.5, explain=False, cov_noise_px=px)[0]
    before = {k: _bits(v) for k, v in track.quality.items()}
    copied = pseudo.type_a_noise(prep, track, gap, 0.5)
    assert {k: _bits(v) for k, v in track.quality.items()} == before  # (its input untouched)
    # in place: the kernel's table, its rows std_m and the covariance overwritten
    table: list = []
    made = _fuse_type_a(prep, gap, 0.5, None, None, None, False, px, table)[0]
    assert len(made) > 100 and len(table) == 1
    in_place = pseudo.type_a_noise(prep, made, gap, 0.5, table[0])
    assert in_place.quality.keys() == copied.quality.keys()
    assert "_model_gravity_m2" not in in_place.quality
    for k in copied.quality:
        assert _bits(in_place.quality[k]) == _bits(copied.quality[k]), k
    # the rescaled columns are the table's rows, not new arrays
    for k in ("std_m", *_COV_COLUMNS):
        assert np.shares_memory(in_place.quality[k], table[0]), k
    # and fuse() (which takes the in-place path) gives the copying path's bits
    fused = fuse(obs, rig, "typeA", FusionOptions(noise_px=0.5, confirm_gaps=False,
                                                    max_std_m=None))
    assert _bits(fused.position_world) == _bits(copied.position_world)
    for k in copied.quality:
        assert _bits(fused.quality[k]) == _bits(copied.quality[k]), k


def test_ray_origin_made_at_first_use():
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    obs = simulate(rig, get_motion("throw"), options=SimulationOptions(noise_px=0.5, seed=5)
                   )[0].best()
    prep = prepare(obs, rig)
    assert "ray_origin" not in prep.__dict__
    assert _bits(prep.ray_origin) == _bits(prep.centers[obs.camera])
