"""Input files shared by the fault cases."""

from __future__ import annotations

from pathlib import Path


def write_session_and_rig(folder: Path):
    """Write into ``folder`` a one-second type-A spiral session ``s.mcap`` (paper3, with
    truth) and its rig ``rig.toml``; returns the rig."""
    from pslog import apply_timing, builtin_rig, get_motion, simulate
    from pslog.log import SessionWriter
    from pslog.rig import save_rig

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    detections, truth = simulate(rig, get_motion("spiral"), 1.0)
    with SessionWriter(folder / "s.mcap", rig, timing="typeA") as writer:
        writer.add_detections(detections)
        writer.add_truth(truth)
    save_rig(rig, folder / "rig.toml")
    return rig
