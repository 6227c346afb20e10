# ruff: noqa: E501
"""Issue 10 (session 38): bench_dirty ``--more``'s sessions one at a time (as
``benchmarks/session37/scan_heldout37.py``, whose options predate ``confirm_breaks``):
``find(rig, label, first, fps)``, ``kinds(faults, span)``, ``simulate(...)``, ``OPTIONS``."""
from __future__ import annotations

import sys

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import bench_dirty as bd

from pslog.fusion import CONFIRM_GAPS, FusionOptions
from pslog.simulation import SimulationOptions, simulate_labelled

SEEDS = 3
#: bench_dirty's options: pslog fuse's defaults (typeA's ``--confirm-gaps kicks``)
OPTIONS = FusionOptions(**dict(zip(("confirm_gaps", "confirm_every", "confirm_sides", "confirm_breaks"),
                                   CONFIRM_GAPS["kicks"], strict=True)))


def all_rigs(fps):
    out = bd.rigs() + bd.more_rigs()
    return out if fps is None else [bd.at_rate(r, fps) for r in out]


def sessions_of(first):
    """(bench seed, (label, motion, duration, kicks)) of ``--more --first-seed first``."""
    return list(enumerate(bd.more_sessions(SEEDS, 8.0, first), start=first - 300))


def simulate(rig, motion, duration, seed, misses, extra):
    return simulate_labelled(rig, motion, duration, SimulationOptions(
        noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2, **extra))


def find(rigname, label, first, fps):
    rig = next(r for r in all_rigs(fps) if r.name == rigname)
    for seed, (lab, motion, duration, kicks) in sessions_of(first):
        if lab == label:
            span = motion.duration if duration is None else duration
            return rig, motion, duration, seed, bd.faults(rig, seed, span), kicks, span
    raise SystemExit(f"no session {label!r}")


def kinds(f, span):
    cam = f["blackouts"][0][0]
    return {"clean": {}, "faults": f, "blackout": {"blackouts": f["blackouts"]},
            "spurious": {"spurious_rate": 0.05}, "object": {"distractors": f["distractors"]},
            "without": {"blackouts": ((cam, 0.0, span + 1.0),)}}
