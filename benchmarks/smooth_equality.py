"""Old against new ``smooth`` outputs: every point, quality column (the full covariance, the
residuals), the dropped counts and the fit's breaks, knots and noise estimate, under this
tree's code and under a git revision's, over a matrix of sessions: rigs ``paper3``, ``lab3``
(three 800 x 600 wide-angle cameras with lens distortion, uneven offsets), ``paper2`` (two
cameras) and ``quad4`` (four), detection noise 0, 0.3 and 1 px, each clean, with missed
detections and dropped frames, and with dirty candidates (spurious blobs in 5 % of frames and
a static second object, the frame's ball chosen by the gate); a throw (one bounce) on each,
and a two-minute rally (kicks and floor bounces: many breaks, many pieces) on ``paper3`` and
``lab3``; each also fused on a 60 Hz grid (``rate_hz``) and on 1 and 2 threads
(``PSLOG_SMOOTH_THREADS``).

    python benchmarks/smooth_equality.py [--ref HEAD~1] [--quick]

Exits 1 if any value differs at all (the algorithm did not change: the outputs must be bit
for bit the same); prints the worst relative difference and the outputs that differ.
"""

from __future__ import annotations

import argparse
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


# the rigs of fusion_equality (this folder: the script runs itself under the compared
# revision's pslog, beside this tree's benchmarks)
from fusion_equality import _lab_rig, _quad_rig  # noqa: E402


def _track(t) -> dict:
    return dict(time=t.time_ns, pos=t.position_world, cam=t.camera, dropped=dict(t.dropped),
                **{f"q_{k}": v for k, v in t.quality.items()})


def dump(path: str, quick: bool) -> None:
    """Write every ``smooth`` output of this interpreter's pslog to ``path`` (a pickle)."""
    import pslog
    from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion
    from pslog.estimation import SmoothOptions, fit_trajectory
    from pslog.fusion import FusionOptions, fuse
    from pslog.simulation import simulate_labelled

    print(f"outputs of {Path(pslog.__file__).parent}", flush=True)
    rigs = {"paper3": apply_timing(builtin_rig("paper3"), "typeA"), "lab3": _lab_rig(),
            "paper2": apply_timing(builtin_rig("paper2"), "typeA"), "quad4": _quad_rig()}
    faults = {"clean": {}, "misses": dict(miss_rate=0.2, drop_rate=0.1, jitter_s=0.0005),
              "dirty": dict(miss_rate=0.1, spurious_rate=0.05,
                            distractors=((None, (1.0, 1.5, 0.2)),))}
    out: dict = {}
    cases = []
    for name in rigs:
        for noise in ((0.3,) if quick else (0.0, 0.3, 1.0)):
            for fault in (("misses",) if quick else faults):
                cases.append((name, "throw", 0.0, noise, fault))
    for name in ("paper3", "lab3"):
        cases.append((name, "rally", 30.0 if quick else 120.0, 0.5, "misses"))
    for case in cases:
        name, motion, duration, noise, fault = case
        rig = rigs[name]
        kw = {"duration": duration} if duration else {}
        det, _, _ = simulate_labelled(rig, get_motion(motion), options=SimulationOptions(
            noise_px=noise, seed=len(out), **faults[fault]), **kw)
        for threads in ("1", "2"):
            os.environ["PSLOG_SMOOTH_THREADS"] = threads
            out[(*case, "points", threads)] = _track(fuse(det, rig, "smooth"))
        os.environ.pop("PSLOG_SMOOTH_THREADS")
        out[(*case, "grid")] = _track(fuse(det, rig, "smooth", FusionOptions(rate_hz=60.0)))
        fit = fit_trajectory(det.best(), rig, SmoothOptions())
        tr = fit.trajectory
        out[(*case, "fit")] = dict(control=tr.control, band=tr.band, breaks=tr.breaks_s,
                                   noise=np.array([tr.noise_px]), knots=np.concatenate(tr.knots),
                                   weight=fit.weight, residual=fit.residual_px)
        print(case, "breaks", len(tr.breaks_s), "pieces", len(tr.knots), flush=True)
    with open(path, "wb") as f:
        pickle.dump(out, f)


def compare(a: dict, b: dict) -> int:
    assert a.keys() == b.keys()
    worst, where, bad, n = 0.0, None, 0, 0
    for key in a:
        x, y = a[key], b[key]
        if x.keys() != y.keys():
            print("FIELDS", key, set(x) ^ set(y))
            bad += 1
            continue
        for f in x:
            u, v = x[f], y[f]
            if isinstance(u, dict):
                if u != v:
                    print("DIFF", key, f, u, v)
                    bad += 1
                continue
            u, v = np.asarray(u), np.asarray(v)
            if u.shape != v.shape or u.dtype != v.dtype:
                print("SHAPE", key, f, u.shape, v.shape)
                bad += 1
                continue
            n += u.size
            if np.array_equal(u, v, equal_nan=u.dtype.kind == "f"):
                continue
            bad += 1
            if u.dtype.kind == "f":
                fin = np.isfinite(u) & np.isfinite(v)
                ref = np.maximum(np.abs(u[fin]), np.median(np.abs(u[fin])))
                rel = float(np.max(np.abs(u[fin] - v[fin]) / np.where(ref > 0, ref, 1.0)))
                if rel > worst:
                    worst, where = rel, (key, f)
                print("DIFF", key, f, f"relative {rel:.2e}")
            else:
                print("DIFF", key, f)
    print(f"compared {len(a)} outputs, {n:,} values: worst relative difference {worst:.2e}"
          f" ({where}); {bad} not bit-identical")
    return 1 if bad else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ref", default="HEAD~1", help="git revision to compare with")
    parser.add_argument("--quick", action="store_true", help="fewer sessions")
    parser.add_argument("--dump", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.dump:
        dump(args.dump, args.quick)
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.ref, "pslog"],
                                 check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        old, new = os.path.join(tmp, "old.pkl"), os.path.join(tmp, "new.pkl")
        script = str(Path(__file__).resolve())
        extra = ["--quick"] if args.quick else []
        env = dict(os.environ, PYTHONPATH=tmp)
        subprocess.run([sys.executable, script, "--dump", old, *extra], env=env, check=True,
                       cwd=tmp)
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        subprocess.run([sys.executable, script, "--dump", new, *extra], env=env, check=True,
                       cwd=tmp)
        with open(old, "rb") as f_old, open(new, "rb") as f_new:
            return compare(pickle.load(f_old), pickle.load(f_new))


if __name__ == "__main__":
    raise SystemExit(main())
