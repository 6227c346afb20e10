"""The arguments a stage of ``smooth``'s fit is given, taken from a real fit (shared by the
tests of its break search's stages)."""

from __future__ import annotations

import copy

import numpy as np
from _rally import dirty_rally

from pslog import apply_timing, builtin_rig
from pslog.estimation import SmoothOptions, fit_trajectory, trajectory
from pslog.simulation import SimulationOptions, simulate


def first_arguments(stage: str, observations, rig) -> tuple:
    """The arguments of the first call of ``pslog.estimation.trajectory.<stage>`` (e.g.
    ``_refine_breaks``, ``_confirmed_breaks``) while ``fit_trajectory`` fits
    ``observations`` with the default options: a deep copy (the fit goes on with its problem
    afterwards) of the positional ones (the keywords, such as the scans' shared ``terms``,
    only save work); the real stage runs as ever."""
    seen = []
    real = getattr(trajectory, stage)

    def capture(*args, **kwargs):
        seen.append(copy.deepcopy(args))
        return real(*args, **kwargs)

    setattr(trajectory, stage, capture)  # (the real stage, its arguments kept)
    try:
        fit_trajectory(observations, rig, SmoothOptions())
    finally:
        setattr(trajectory, stage, real)
    return seen[0]


def rally_arguments(stage: str, rig_name: str, seed: int) -> tuple:
    """:func:`first_arguments` of ``stage`` on bench_dirty's 8-second rally of ``seed``
    (:func:`_rally.dirty_rally`) seen by the built-in rig ``rig_name`` on type A timing, 0.3
    px, 10 % of the detections missed and 5 % of the frames dropped (noise draw ``seed``);
    and the rally's kicks (s)."""
    rig = apply_timing(builtin_rig(rig_name), "typeA")
    motion, kicks = dirty_rally(seed)
    detections, _ = simulate(rig, motion, 8.0, SimulationOptions(
        noise_px=0.3, seed=seed, miss_rate=0.1, drop_rate=0.05))
    return first_arguments(stage, detections.best(), rig), np.asarray(kicks)
