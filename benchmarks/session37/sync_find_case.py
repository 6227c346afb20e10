"""Find sessions as ``pslog simulate`` writes them (paper3, typeA, the rally, 0.3 px,
offsets +5 / -7 ms, one readout shared by every camera) whose readouts the per-camera test
alone leaves out and the nested one-readout test keeps (the test case of
tests/test_sync_shared_readout.py).

    python benchmarks/session37/sync_find_case.py --first-seed 37000 --seeds 20 --readout-ms 8
"""

from __future__ import annotations

import argparse

from pslog import SimulationOptions, apply_timing, builtin_rig, simulate
from pslog.estimation.sync import estimate_clocks
from pslog.motion import get_motion


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--first-seed", type=int, default=37000)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--readout-ms", type=float, default=8.0)
    ap.add_argument("--duration", type=float, default=8.0)
    ap.add_argument("--rig", default="paper3")
    args = ap.parse_args(argv)
    rig = apply_timing(builtin_rig(args.rig), "typeA")
    for seed in range(args.first_seed, args.first_seed + args.seeds):
        opts = SimulationOptions(noise_px=0.3, seed=seed,
                                 clock_offset_s={"cam2": 5e-3, "cam3": -7e-3},
                                 readout_s={c.name: args.readout_ms / 1e3 for c in rig.cameras})
        det, _ = simulate(rig, get_motion("rally"), args.duration, opts)
        res = estimate_clocks(det.best(), rig, "auto")
        (t,) = [t for t in res.selection if t.parameter == "readout"]
        print(f"{seed} W {t.statistic:.2f}/{t.dof} Ws {t.shared_statistic:.2f}/{t.shared_dof} "
              f"kept {t.kept} old {t.statistic > 16.266}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
