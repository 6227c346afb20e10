"""Write walk41's rig: four 60 fps cameras at the corners of a 3 x 2 m field.

Two 640x480 wide-angle cameras with strong barrel distortion (cam1, cam3), two 1280x720
with mild distortion (cam2, cam4); shutters not evenly spaced (0 / 2.9 / 7.4 / 12.6 ms of
the 16.7 ms period). The clock offsets are the simulation's faults (walk41_notes.md), not
in this file: a team's rig has no idea of them until `pslog sync`.

    python benchmarks/session41/walk41_rig.py OUT.toml
"""
import sys

import numpy as np

from pslog.camera import Camera, look_at
from pslog.rig import Rig, save_rig

TARGET = (1.5, 1.0, 0.4)
SPECS = [  # name, eye, (w, h), f, dist, shutter offset (s)
    ("cam1", (-0.6, -0.5, 2.3), (640, 480), 330.0, [-0.38, 0.17, 0.0, 0.0, -0.035], 0.0),
    ("cam2", (3.6, -0.6, 2.5), (1280, 720), 820.0, [-0.06, 0.02, 0.0, 0.0, 0.0], 0.0029),
    ("cam3", (3.7, 2.6, 2.2), (640, 480), 320.0, [-0.41, 0.19, 0.001, -0.001, -0.04], 0.0074),
    ("cam4", (-0.5, 2.5, 2.6), (1280, 720), 800.0, [-0.08, 0.03, 0.0, 0.0, 0.0], 0.0126),
]


def main(out: str) -> None:
    cams = []
    for name, eye, (w, h), f, dist, offset in SPECS:
        R, t = look_at(eye, TARGET)
        K = np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])
        cams.append(Camera(name, w, h, K, np.array(dist), R, t, fps=60.0, offset=offset))
    save_rig(Rig(tuple(cams), "robocup4"), out)


if __name__ == "__main__":
    main(sys.argv[1])
