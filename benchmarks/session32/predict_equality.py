"""Session 32 (nits32): ``BallFilter.predict``'s outputs bit-equal between two trees.

``filter_equality.py`` compares the points (``_push``'s path); ``predict`` (``_predict``) is
another path (the state predicted to "now", its floor contact and the estimated drag): this
script pushes every detection of a few sessions (``lab`` rig, 3 cameras, lens distortion;
motions ``throw`` and ``fall`` (floor contacts), the library's rally (kicks, bounces),
``turntable`` (the turn model); 0.3 px; two seeds; the default options and the drag not
estimated) and, before each push, predicts the state to the detection's time and to 5, 40,
150 and 400 ms after it (most of a throw's contacts lie within those), collecting position,
velocity and covariance.

    PYTHONPATH=/work/main python benchmarks/session32/predict_equality.py --save ref.npz
    PYTHONPATH=. python benchmarks/session32/predict_equality.py --compare ref.npz

``--compare`` prints the number of predictions, how many crossed a floor contact (velocity's
z negative before, positive after) and the largest difference per output; exit 1 unless
every value is bit-equal (NaN equal to NaN).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from test_filter import lab_rig, session

from pslog.fusion.filter import BallFilter, FilterOptions
from pslog.motion import get_motion

AHEAD_NS = (0, 5_000_000, 40_000_000, 150_000_000, 400_000_000)
MOTIONS = ("throw", "fall", "rally", "turntable")
SEEDS = (32001, 32002)
VARIANTS = {"default": {}, "no drag estimate": {"drag_std_per_m": 0.0}}


def predictions() -> dict[str, np.ndarray]:
    """Every prediction's position (n, 3), velocity (n, 3), covariance (n, 6, 6) and the
    state before it (n, 6)."""
    rig = lab_rig(3)
    out: dict[str, list] = {"p": [], "v": [], "P": [], "before": []}
    for name in MOTIONS:
        for seed in SEEDS:
            obs, _ = session(rig, get_motion(name), noise_px=0.3, seed=seed)
            for kw in VARIANTS.values():
                flt = BallFilter(rig, FilterOptions(**kw))
                for t, cam, (u, v) in zip(obs.time_ns.tolist(), obs.camera.tolist(),
                                          obs.uv.tolist(), strict=True):
                    state = flt.state()
                    if state is not None:
                        before = state[1]
                        for a in AHEAD_NS:
                            p, vel, P = flt.predict(t + a)
                            out["p"].append(np.asarray(p, float))
                            out["v"].append(np.asarray(vel, float))
                            out["P"].append(np.asarray(P, float))
                            out["before"].append(np.asarray(before, float))
                    flt.push(t, cam, u, v)
    return {k: np.array(v) for k, v in out.items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--save", type=Path)
    g.add_argument("--compare", type=Path)
    args = ap.parse_args()
    got = predictions()
    if args.save:
        np.savez(args.save, **got)
        print(f"{len(got['p'])} predictions saved to {args.save}")
        return 0
    ref = np.load(args.compare)
    n = len(got["p"])
    crossed = int(np.sum((got["before"][:, 5] < 0) & (got["v"][:, 2] > 0)))
    print(f"{n} predictions ({crossed} across a floor contact)")
    same = True
    for k in ("p", "v", "P"):
        a, b = got[k], ref[k]
        if a.shape != b.shape:
            print(f"{k}: shapes differ {a.shape} {b.shape}")
            same = False
            continue
        equal = (a == b) | (np.isnan(a) & np.isnan(b))
        diff = np.nanmax(np.abs(a - b)) if a.size else 0.0
        print(f"{k}: {int(np.sum(~equal))} values differ, largest {diff:.3g}")
        same &= bool(np.all(equal))
    print("bit-equal" if same else "DIFFERENT")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
