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


def write_points_csv(path: Path) -> None:
    """Exact 3D-2D correspondences of paper3's cam1 (what 'calibrate --points' reads): 40
    points in a 3 x 2 x 2 m box."""
    import numpy as np

    from pslog.rig import builtin_rig

    cam = builtin_rig("paper3").cameras[0]
    points = np.random.default_rng(0).uniform([0, 0, 0], [3, 2, 2], (40, 3))
    uv, _ = cam.project(points)
    path.write_text("x,y,z,u,v\n" + "".join(
        f"{x!r},{y!r},{z!r},{u!r},{v!r}\n" for (x, y, z), (u, v) in zip(
            points.tolist(), uv.tolist(), strict=True)), encoding="utf-8")
