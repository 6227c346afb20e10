"""The arguments a stage of ``smooth``'s fit is given, taken from a real fit (shared by the
tests of its break search's stages)."""

from __future__ import annotations

import copy

from pslog.estimation import SmoothOptions, fit_trajectory, trajectory


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
