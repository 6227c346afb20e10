"""Review39: default_methods gates only when the best-scored instants share enough
(8fe61a5, "the one case the gate's choice can undo"); the gate's choice can also make them
share. typeB paper3 with rolling shutters, a static object on cam1, a throw (seed 60210):
the share of instants seen by two cameras or more, best-scored and as the gate chooses,
and the default methods. Run: PYTHONPATH=. python benchmarks/session39/review_default_methods.py
(output: review_default_methods.txt beside it)."""

from __future__ import annotations

import numpy as np

from pslog.fusion import default_methods
from pslog.fusion.gating import gate
from pslog.fusion.stereo import sync_groups
from pslog.motion import get_motion
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled
from pslog.timing import observations as timed


def share(obs, rig) -> float:
    _, n = sync_groups(obs, len(rig), 1e-3)
    return np.count_nonzero(n >= 2) / max(len(n), 1)


for readout in (0.004, 0.008, 0.016):
    for spot in ((1.0, 1.5, 0.2), (0.5, 1.0, 0.2), (2.0, 0.5, 0.0)):
        rig = apply_timing(builtin_rig("paper3"), "typeB")
        rig = rig.__class__(tuple(c.replace(readout=readout) for c in rig.cameras), rig.name)
        options = SimulationOptions(noise_px=0.3, seed=60210, distractors=(("cam1", spot),))
        det, _truth, _ball = simulate_labelled(rig, get_motion("throw"), None, options)
        best = share(timed(det, rig), rig)
        gated = share(gate(det, rig, doubt=False).observations, rig)
        print(f"readout {readout * 1e3:4.0f} ms object {spot}: shared best-scored "
              f"{best:.3f} gated {gated:.3f} defaults {','.join(default_methods(det, rig))}")
