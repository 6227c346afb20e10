"""Type A's per-rig tables (the kernels' camera tables, prepare's K⁻¹) are made once per rig
geometry and reused: a rig that differs gets its own, and a reused table gives the bits a
fresh one gives."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pslog import Rig, SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
from pslog.fusion import _prepare, fuse, pseudo


def _same(a, b) -> bool:
    return (a.time_ns.tobytes() == b.time_ns.tobytes()
            and a.position_world.tobytes() == b.position_world.tobytes()
            and a.quality.keys() == b.quality.keys()
            and all(a.quality[k].tobytes() == b.quality[k].tobytes() for k in a.quality))


def _fresh(obs, rig):
    pseudo._CAMERA_TABLES.clear()
    _prepare._K_INVERSES.clear()
    return fuse(obs, rig, "typeA")


def test_tables_follow_the_rig_and_keep_the_bits():
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    obs = simulate(rig, get_motion("throw"), options=SimulationOptions(noise_px=0.5, seed=3)
                   )[0].best()
    # the same cameras but the first's focal length 1 % longer (its K, K⁻¹, F and view box)
    K = np.array(rig.cameras[0].K, dtype=np.float64)
    K[0, 0] *= 1.01
    K[1, 1] *= 1.01
    other = Rig((replace(rig.cameras[0], K=K), *rig.cameras[1:]), "other")
    first = _fresh(obs, rig)
    again = fuse(obs, rig, "typeA")  # the tables of the first call, reused
    assert _same(first, again)
    changed = fuse(obs, other, "typeA")  # a rig met after another: its own tables
    assert not _same(first, changed)
    assert _same(changed, _fresh(obs, other))
    assert _same(first, fuse(obs, rig, "typeA"))
