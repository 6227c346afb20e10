"""Session 39's new-user walkthrough: a user's own two 60 fps cameras, made real.

Writes, for each seed, what a user's own ball detector and calibration would give:

- ``rig.toml``: the user's calibration (two 1280x720 cameras with real lens distortion, 60
  fps, shutter offsets 0: the user does not know the stagger), made from ``pslog rig show
  paper2`` as README's "Rigs and timing" says;
- ``<session>/left.csv``, ``<session>/right.csv``: one CSV per camera, as a detector writes
  it: ``frame,time,u,v,score`` with the time on that camera's own clock (Unix-epoch seconds
  from each camera's host, the hosts NTP-synced within ~10 ms, the right camera's crystal
  30 ppm fast), distorted pixels, sometimes two candidates a frame (a false blob), sometimes
  none (a row with u, v empty);
- ``<session>/truth.csv``: ``time,x,y,z`` on the left camera's clock (the truth a user with a
  motion-capture system would have), and ``truth.tum`` (the same, TUM) for evo.

The truth comes from :func:`pslog.simulation.simulate_labelled` on the *true* rig: the right
camera's shutter fires 4 ms after the left's, its clock offset and drift are the faults below.

Usage: python benchmarks/session39/walk_make_sessions.py OUTDIR [--seeds 60200,60201,60202]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

import pslog
from pslog.motion import rally_motion
from pslog.simulation import SimulationOptions, simulate_labelled

NS = 1_000_000_000
EPOCH_S = 1_764_860_000  # 2025-12-04, a Unix-epoch origin as host clocks give
K = [[820.0, 0.0, 641.3], [0.0, 818.5, 357.9], [0.0, 0.0, 1.0]]
DIST = [-0.291, 0.094, 0.0007, -0.0004, -0.0121]   # a wide-angle lens' barrel distortion


def user_rig_toml() -> str:
    """The user's rig file: paper2's placement, edited as README says (size, K, dist, fps)."""
    base = pslog.builtin_rig("paper2")
    lines = ['name = "mylab"', ""]
    for cam, name in zip(base.cameras, ("left", "right"), strict=True):
        lines += [
            "[[camera]]", f'name = "{name}"', "width = 1280", "height = 720",
            f"K = {json.dumps(K)}", f"dist = {json.dumps(DIST)}",
            f"R = {json.dumps(np.asarray(cam.R).tolist())}",
            f"t = {json.dumps(np.asarray(cam.t).tolist())}",
            "fps = 60.0", "offset = 0.0", "",
        ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("outdir", type=Path)
    parser.add_argument("--seeds", default="60200,60201,60202")
    parser.add_argument("--duration", type=float, default=40.0)
    args = parser.parse_args()
    out = args.outdir
    out.mkdir(parents=True, exist_ok=True)
    (out / "rig.toml").write_text(user_rig_toml())
    user_rig = pslog.load_rig(out / "rig.toml")
    # the true rig: the right shutter 4 ms after the left's
    cams = list(user_rig.cameras)
    cams[1] = dataclasses.replace(cams[1], offset=0.004)
    true_rig = dataclasses.replace(user_rig, cameras=tuple(cams))
    for k, seed in enumerate(int(s) for s in args.seeds.split(",")):
        rng = np.random.default_rng(seed)
        clock_offset = float(rng.uniform(-0.012, 0.012))   # NTP disagreement of the hosts
        drift = float(rng.choice([-1, 1]) * rng.uniform(25.0, 35.0))
        options = SimulationOptions(
            noise_px=0.4, miss_rate=0.04, drop_rate=0.005, seed=seed,
            clock_offset_s={"right": clock_offset}, clock_drift_ppm={"right": drift},
            spurious_rate=0.06,
        )
        motion = rally_motion(seed, duration=args.duration)
        det, truth, ball = simulate_labelled(true_rig, motion, args.duration, options)
        session = out / f"match{k + 1}"
        session.mkdir(exist_ok=True)
        base_ns = (EPOCH_S + 3600 * k) * NS + int(rng.integers(0, NS))
        counts = det.candidates_per_frame()
        for c, name in enumerate(det.camera_names):
            rows = ["frame,time,u,v,score"]
            for f in np.flatnonzero(det.frame_camera == c):
                t = base_ns + int(det.frame_time_ns[f])
                stamp = f"{t // NS}.{t % NS:09d}"
                frame = int(det.frame_index[f])
                if counts[f] == 0:
                    rows.append(f"{frame},{stamp},,,")
                for j in np.flatnonzero(det.cand_frame == f):
                    u, v = det.cand_uv[j]
                    rows.append(f"{frame},{stamp},{u:.2f},{v:.2f},{det.cand_score[j]:.3f}")
            (session / f"{name}.csv").write_text("\n".join(rows) + "\n")
        with open(session / "truth.csv", "w") as fh:
            fh.write("time,x,y,z\n")
            for t, p in zip(truth.time_ns, truth.position_world, strict=True):
                t = base_ns + int(t)
                fh.write(f"{t // NS}.{t % NS:09d},{p[0]:.6f},{p[1]:.6f},{p[2]:.6f}\n")
        with open(session / "truth.tum", "w") as fh:
            for t, p in zip(truth.time_ns, truth.position_world, strict=True):
                t = base_ns + int(t)
                fh.write(f"{t // NS}.{t % NS:09d} {p[0]:.6f} {p[1]:.6f} {p[2]:.6f} 0 0 0 1\n")
        in_view = np.bincount(ball.cand_frame, minlength=ball.n_frames) > 0
        print(f"{session.name}: seed {seed}, right clock {clock_offset * 1e3:+.2f} ms, "
              f"{drift:+.1f} ppm; {det.n_frames} frames, {det.n_candidates} candidates, "
              f"ball in {in_view.mean():.1%} of frames")


if __name__ == "__main__":
    main()
