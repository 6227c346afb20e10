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

``--more``: also 2-minute rallies on ``paper2`` and ``lab4`` (tests/_rigs.py's ring), the
same rallies dirty (bench_dirty's faults: spurious blobs in 5 % of frames, a static second
object seen by one camera, another camera blind for 0.5 s), and bench_match's 90-minute
``paper3`` rally (0.5 px, seed 1; 486,000 detections: minutes per revision).

    python benchmarks/smooth_equality.py [--ref HEAD~1] [--quick] [--more] [--rounding]

Exits 1 if any value differs at all (the algorithm did not change: the outputs must be bit
for bit the same); prints the worst relative difference and the outputs that differ.
``--rounding``: the test of a change that moves only floating-point rounding (sums
re-associated inside a compiled kernel): every integer, boolean and count the same (the
points' times and cameras, the dropped counts, the number of breaks and knots, which
detections the fit rejects: weight 0 or not), NaN where NaN, and the largest differences
printed per kind — points and control points (m), standard deviations and covariances
(relative), residuals (px), breaks and knots (s), weights; exits 1 beyond 1e-9 m for the
points and 1e-9 relative for the standard deviations.
"""

from __future__ import annotations

import argparse
import os
import pickle
from pathlib import Path

import numpy as np

# the old-against-new runs and the rigs of fusion_equality (this folder: the script runs
# itself under the compared revision's pslog, beside this tree's benchmarks)
from _equality import ROOT, dumps, field_pairs
from fusion_equality import _lab_rig, _quad_rig


def _track(t) -> dict:
    return dict(time=t.time_ns, pos=t.position_world, cam=t.camera, dropped=dict(t.dropped),
                **{f"q_{k}": v for k, v in t.quality.items()})


def dump(path: str, quick: bool, more: bool = False) -> None:
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
    if more:
        import sys

        sys.path.insert(0, str(ROOT / "tests"))
        from _rigs import ring_rig
        from bench_dirty import faults as dirty_faults

        rigs["lab4"] = ring_rig(4, "lab4")
        for name in ("paper2", "lab4", "paper3"):
            faults[f"bench_dirty {name}"] = dirty_faults(rigs[name], 300, 120.0)
            cases.append((name, "rally", 120.0, 0.3, "clean"))
            cases.append((name, "rally", 120.0, 0.3, f"bench_dirty {name}"))
        cases.append(("paper3", "rally", 5400.0, 0.5, "match"))
    for case in cases:
        name, motion, duration, noise, fault = case
        rig = rigs[name]
        kw = {"duration": duration} if duration else {}
        if fault == "match":  # bench_match's 90-minute session (pslog simulate's defaults)
            from pslog import simulate

            det, _ = simulate(rig, get_motion(motion), duration, SimulationOptions(
                noise_px=noise, seed=1))
        else:
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
    worst, where, bad, n = 0.0, None, 0, 0
    unlike: list = []
    for key, f, u, v in field_pairs(a, b, unlike):
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
    bad += len(unlike)
    print(f"compared {len(a)} outputs, {n:,} values: worst relative difference {worst:.2e}"
          f" ({where}); {bad} not bit-identical")
    return 1 if bad else 0


#: --rounding: the kind of each float field (how its difference is measured)
_METRES = ("pos", "control")
_RELATIVE = ("q_std_m", "q_std_x_m", "q_std_y_m", "q_std_z_m")


def _kind(field: str) -> str:
    if field in _METRES:
        return "points (m)"
    if field in _RELATIVE:
        return "std (relative)"
    if field.startswith("q_cov_") or field == "band":
        return "covariance (relative)"
    if field in ("q_residual_px", "residual"):
        return "residuals (px)"
    if field in ("breaks", "knots", "q_gap_s"):
        return "times (s)"
    return f"{field} (absolute)"


def compare_rounding(a: dict, b: dict) -> int:
    """The --rounding comparison (module docstring)."""
    worst: dict = {}
    bad = n = 0
    unlike: list = []
    for key, f, u, v in field_pairs(a, b, unlike):
        if isinstance(u, dict) or np.asarray(u).dtype.kind != "f":
            same = u == v if isinstance(u, dict) else np.array_equal(u, v)
            if not same:
                print("DIFF", key, f, "(must be equal)")
                bad += 1
            continue
        u, v = np.asarray(u), np.asarray(v)
        if u.shape != v.shape:
            print("SHAPE", key, f, u.shape, v.shape)
            bad += 1
            continue
        n += u.size
        if not np.array_equal(np.isnan(u), np.isnan(v)):
            print("NAN", key, f, "NaN in different places")
            bad += 1
            continue
        if f == "weight" and not np.array_equal(u == 0, v == 0):
            print("REJECTED", key, "different detections rejected")
            bad += 1
        fin = np.isfinite(u)
        d = np.abs(u[fin] - v[fin])
        kind = _kind(f)
        if "relative" in kind:  # a covariance near 0: relative to the typical size
            typical = np.median(np.abs(u[fin])) if "covariance" in kind else 1e-300
            d = d / np.maximum(np.abs(u[fin]), max(typical, 1e-300))
        value = float(np.max(d, initial=0.0))
        if value > worst.get(kind, (-1.0,))[0]:
            worst[kind] = (value, key, f)
    bad += len(unlike)
    for kind, (value, key, f) in sorted(worst.items()):
        print(f"largest difference, {kind}: {value:.3g} ({key} {f})")
    # (covariances: relative to the larger of the entry and the field's median |entry|)
    limits = {"points (m)": 1e-9, "std (relative)": 1e-9}
    over = [k for k, lim in limits.items() if worst.get(k, (0.0,))[0] > lim]
    print(f"compared {len(a)} outputs, {n:,} floating-point values: "
          f"{bad} with a different count, decision or NaN; beyond 1e-9: {over or 'none'}")
    return 1 if bad or over else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ref", default="HEAD~1", help="git revision to compare with")
    parser.add_argument("--quick", action="store_true", help="fewer sessions")
    parser.add_argument("--more", action="store_true",
                        help="also paper2/lab4 rallies, clean and dirty, and the 90-minute one")
    parser.add_argument("--rounding", action="store_true",
                        help="equal up to rounding (module docstring), not bit for bit")
    parser.add_argument("--dump", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.dump:
        dump(args.dump, args.quick, args.more)
        return 0
    extra = ["--quick"] * args.quick + ["--more"] * args.more
    old_out, new_out = dumps(__file__, args.ref, extra)
    return (compare_rounding if args.rounding else compare)(old_out, new_out)


if __name__ == "__main__":
    raise SystemExit(main())
