"""review41b: motion_period on rigs of 4 and 2 cameras, one looking straight down on the
turntable (seeds 69500-69502). Printed: turntable 1.3335 / 1.3338 s, rally and spiral None."""
import numpy as np

from pslog.camera import Camera
from pslog.estimation.sync import motion_period
from pslog.fusion._prepare import default_max_gap_s
from pslog.motion import MOTIONS
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig

p3 = builtin_rig("paper3")
c = p3.cameras[0]
R = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])
down = Camera(name="cam4", width=640, height=480, K=c.K, dist=c.dist, R=R,
              t=-R @ np.array([1.5, 1.0, 3.0]), fps=30.0, offset=0.0)
for name, rig in (("4 cams (one straight down)", Rig((*p3.cameras, down), "four")),
                  ("2 cams (cam1 + straight down)", Rig((p3.cameras[0], down), "two"))):
    rig = apply_timing(rig, "typeA")
    for seed, m in ((69500, "turntable"), (69501, "rally"), (69502, "spiral")):
        opts = SimulationOptions(noise_px=0.3, miss_rate=0.1, seed=seed)
        _, _, ball = simulate_labelled(rig, MOTIONS[m], 20.0, opts)
        print(name, m, motion_period(ball.best(), true_rig(rig, opts), default_max_gap_s(rig)))
