"""Old against new fusion outputs: every paper method's points, quality columns and covariance
on dirty sessions (strong lens or none, 30 % missed detections, 10 % dropped frames, 0.5 ms
jitter, 5 % outliers), under this tree's code and under a git revision's; and ``typeA``
(with its past pseudo-stereo points) over a matrix of sessions: rigs ``paper3``, ``lab3``
(three 800 x 600 wide-angle cameras with lens distortion, uneven offsets), ``paper2`` (two
cameras) and ``quad4`` (four), detection noise 0, 0.3 and 1 px, each clean, with missed
detections and dropped frames, and with dirty candidates (spurious blobs in 5 % of frames
and a static second object, the frame's ball chosen by the gate), with the covariance and
without (``noise_px`` None).

    python benchmarks/fusion_equality.py [--ref HEAD~1]

Exits 1 if any value differs by more than 1e-12 relative (to the value, or to the column's
median magnitude for entries near zero); prints the worst difference and the fields that
are not bit-identical. Type A's internal ``miss_m`` (the snapped rays' distance, rounding
noise around 0) is held to 1e-13 m absolute instead, and reprojection residuals (0 in exact
arithmetic on a noise-free session: their median is rounding noise) to 1e-12 of at least
1 px.
"""

from __future__ import annotations

import argparse
import collections
import pickle
from pathlib import Path

import numpy as np

# (this folder: the script runs itself under the compared revision's pslog, beside this
# tree's benchmarks)
from _equality import ROOT, dumps, field_pairs

LENS = [-0.25, 0.08, 0.001, -0.001, 0.0]


def _base_options():
    """FusionOptions as every tree compared has them: type A's long-gap confirmation
    (session 9, :mod:`pslog.fusion.confirm`) drops points on purpose, so it is off where the
    tree has it and the rest compares bit for bit with older trees (its own decisions:
    tests/test_dirty_confirm.py)."""
    import dataclasses

    from pslog.fusion import FusionOptions

    options = FusionOptions()
    if "confirm_gaps" in FusionOptions.__dataclass_fields__:
        options = dataclasses.replace(options, confirm_gaps=False)
    return options


def dump(path: str) -> None:
    """Write every output of this interpreter's pslog to ``path`` (a pickle)."""
    import pslog
    from pslog import (
        Observations,
        Rig,
        SimulationOptions,
        apply_timing,
        builtin_rig,
        get_motion,
        simulate,
    )
    from pslog.fusion import fuse, prepare, pseudo_stereo_points

    print(f"outputs of {Path(pslog.__file__).parent}")
    base = _base_options()
    out = {}
    for timing in ("typeA", "typeB", "sync"):
        for seed in (0, 1, 2):
            for lens in (True, False):
                rig = apply_timing(builtin_rig("paper3"), timing)
                if lens:
                    rig = Rig(tuple(c.replace(dist=np.array(LENS)) for c in rig.cameras),
                              rig.name)
                options = SimulationOptions(noise_px=0.5, miss_rate=0.3, drop_rate=0.1,
                                            jitter_s=0.0005, seed=seed)
                if seed == 2:
                    det, _ = simulate(rig, get_motion("turntable"), 20.0, options=options)
                else:
                    det, _ = simulate(rig, get_motion("throw"), options=options)
                obs = det.best()
                rng = np.random.default_rng(seed)
                uv = obs.uv.copy()
                outlier = rng.random(len(obs)) < 0.05
                uv[outlier] = rng.uniform([0, 0], [640, 480], (int(outlier.sum()), 2))
                obs = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
                for m in ("sync", "nearest", "typeA", "typeB", "linear"):
                    try:
                        t = fuse(obs, rig, m, base)
                    except Exception as e:  # (sync on type A timing: no common instant)
                        out[timing, seed, lens, m] = repr(e)
                        continue
                    out[timing, seed, lens, m] = dict(
                        time=t.time_ns, pos=t.position_world, cam=t.camera,
                        dropped=dict(t.dropped), **{f"q_{k}": v for k, v in t.quality.items()})
                prep = prepare(obs, rig)
                rows = np.arange(len(obs))
                p = pseudo_stereo_points(prep, rows, rows, int(0.2e9))
                out[timing, seed, lens, "pseudo"] = {f: getattr(p, f)
                                                     for f in p.__dataclass_fields__}
    _type_a_matrix(out)
    with open(path, "wb") as f:
        pickle.dump(out, f)


def _lab_rig():
    """bench_dirty's ``lab3`` (tests/_rigs.py: three 800 x 600 wide-angle cameras, uneven
    offsets). :func:`dump` runs under the compared revision's pslog: that module imports
    nothing but pslog's Camera, Rig and look_at (bench_dirty's own imports may not exist
    there)."""
    import sys

    sys.path.insert(0, str(ROOT / "tests"))
    from _rigs import lab3_rig

    return lab3_rig()


def _quad_rig():
    """``paper3`` and a fourth camera (opposite corner, 2.5 m high), type A offsets."""
    from pslog import Rig, apply_timing, builtin_rig, look_at

    paper = builtin_rig("paper3")
    R, t = look_at((-1.0, -1.5, 2.5), (1.5, 1.0, 1.0))
    extra = paper.cameras[0].replace(name="cam4", R=R, t=t)
    return apply_timing(Rig((*paper.cameras, extra), "quad4"), "typeA")


def _type_a_matrix(out: dict) -> None:
    """``typeA`` and its pseudo-stereo points over rigs x noise x faults (module docstring)."""
    from dataclasses import replace

    from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion
    from pslog.fusion import fuse, prepare, pseudo_stereo_points
    from pslog.simulation import simulate_labelled

    rigs = {"paper3": apply_timing(builtin_rig("paper3"), "typeA"), "lab3": _lab_rig(),
            "paper2": apply_timing(builtin_rig("paper2"), "typeA"), "quad4": _quad_rig()}
    faults = {"clean": {}, "misses": dict(miss_rate=0.2, drop_rate=0.1, jitter_s=0.0005),
              "dirty": dict(miss_rate=0.1, spurious_rate=0.05,
                            distractors=((None, (1.0, 1.5, 0.2)),))}
    for name, rig in rigs.items():
        for noise in (0.0, 0.3, 1.0):
            for fault, extra in faults.items():
                seed = len(out)
                det, _, _ = simulate_labelled(rig, get_motion("throw"), options=SimulationOptions(
                    noise_px=noise, seed=seed, **extra))
                key = ("matrix", name, noise, fault)
                for noise_px in (0.5, None):
                    t = fuse(det, rig, "typeA", replace(_base_options(), noise_px=noise_px))
                    out[(*key, f"typeA/{noise_px}")] = dict(
                        time=t.time_ns, pos=t.position_world, cam=t.camera,
                        dropped=dict(t.dropped), **{f"q_{k}": v for k, v in t.quality.items()})
                obs = det.best()
                prep = prepare(obs, rig)
                rows = np.arange(len(obs))
                p = pseudo_stereo_points(prep, rows, rows, int(0.2e9))
                out[(*key, "pseudo")] = {f: getattr(p, f) for f in p.__dataclass_fields__}


def compare(a: dict, b: dict) -> int:
    worst, where, bad, n = 0.0, None, 0, 0
    not_exact, total = collections.Counter(), collections.Counter()
    unlike: list = []
    for key, f, u, v in field_pairs(a, b, unlike):
        if isinstance(u, dict):
            if u != v:
                print("DIFF", key, f, u, v)
                bad += 1
            continue
        u, v = np.asarray(u), np.asarray(v)
        total[f] += 1
        if u.shape != v.shape or u.dtype != v.dtype:
            print("SHAPE", key, f, u.shape, v.shape, u.dtype, v.dtype)
            bad += 1
            continue
        n += u.size
        if not np.array_equal(u, v, equal_nan=u.dtype.kind == "f"):
            not_exact[f] += 1
        if u.dtype.kind != "f":
            if not np.array_equal(u, v):
                print("DIFF", key, f)
                bad += 1
            continue
        if not np.array_equal(np.isnan(u), np.isnan(v)):
            print("NAN", key, f)
            bad += 1
            continue
        fin = np.isfinite(u)
        if not np.any(fin):
            continue
        diff = np.abs(u[fin] - v[fin])
        if key[-1] == "pseudo" and f == "miss_m":
            if diff.max() > 1e-13:
                print("ABS", key, f, diff.max())
                bad += 1
            continue
        ref = np.maximum(np.maximum(np.abs(u[fin]), np.abs(v[fin])), np.median(np.abs(u[fin])))
        if "residual" in f:  # pixels: 0 in exact arithmetic on noise-free sessions, so
            ref = np.maximum(ref, 1.0)  # relative to 1 px at least (rounding noise)
        rel = float(np.max(diff / np.where(ref > 0, ref, 1.0)))
        if rel > worst:
            worst, where = rel, (key, f)
        if rel > 1e-12:
            at = int(np.argmax(diff / np.where(ref > 0, ref, 1.0)))
            print("REL", key, f, rel, "at", int(np.flatnonzero(fin)[at]), u[fin][at],
                  v[fin][at])
            bad += 1
    bad += len(unlike)
    print(f"compared {len(a)} outputs, {n:,} values: worst relative difference {worst:.2e}"
          f" ({where}); {bad} failing")
    print("not bit-identical (outputs):", {f: f"{not_exact[f]}/{total[f]}" for f in not_exact}
          or "none")
    return 1 if bad else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ref", default="HEAD~1", help="git revision to compare with")
    parser.add_argument("--dump", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.dump:
        dump(args.dump)
        return 0
    return compare(*dumps(__file__, args.ref, []))


if __name__ == "__main__":
    raise SystemExit(main())
