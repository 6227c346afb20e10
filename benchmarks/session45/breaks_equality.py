"""Type A's tracks under ``--confirm-gaps jumps`` and ``breaks`` over rigs x noise x faults
(8-s rallies, seeds 79501-79524), pickled, for an old-against-new bit comparison with
``benchmarks/fusion_equality.py``'s ``compare`` (session 45: the backward pass keeping only
the points the rule reads; run under each tree, ``PYTHONPATH=<tree>``; this form needs
``pslog.fusion.confirm_choice``, session 45 on).

    PYTHONPATH=. python benchmarks/session45/breaks_equality.py OUT.pkl
"""

import pickle
import sys
from dataclasses import replace
from pathlib import Path

sys.path[:0] = [str(Path(__file__).resolve().parents[1])]

from fusion_equality import _lab_rig, _quad_rig  # noqa: E402

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion  # noqa: E402
from pslog.fusion import (  # noqa: E402
    FusionOptions,
    confirm_choice,
    fuse,
    offline_confirmation,
)
from pslog.simulation import simulate_labelled  # noqa: E402


def main() -> None:
    out = {}
    rigs = {"paper3": apply_timing(builtin_rig("paper3"), "typeA"), "lab3": _lab_rig(),
            "paper2": apply_timing(builtin_rig("paper2"), "typeA"), "quad4": _quad_rig()}
    faults = {"clean": {}, "misses": dict(miss_rate=0.2, drop_rate=0.1, jitter_s=0.0005),
              "dirty": dict(miss_rate=0.1, spurious_rate=0.05,
                            distractors=((None, (1.0, 1.5, 0.2)),))}
    seed = 79500
    for name, rig in rigs.items():
        for noise in (0.3, 1.0):
            for fault, extra in faults.items():
                seed += 1
                det, _, _ = simulate_labelled(rig, get_motion("rally"), 8.0,
                                              options=SimulationOptions(noise_px=noise,
                                                                        seed=seed, **extra))
                for mode in ("jumps", "breaks"):
                    options = offline_confirmation(FusionOptions(**confirm_choice(mode)))
                    for noise_px in (0.5, None):
                        t = fuse(det, rig, "typeA", replace(options, noise_px=noise_px))
                        out[(name, noise, fault, mode, noise_px)] = dict(
                            time=t.time_ns, pos=t.position_world, cam=t.camera,
                            dropped=dict(t.dropped),
                            **{f"q_{k}": v for k, v in t.quality.items()})
    with open(sys.argv[1], "wb") as f:
        pickle.dump(out, f)
    print(len(out), "outputs")


if __name__ == "__main__":
    main()
