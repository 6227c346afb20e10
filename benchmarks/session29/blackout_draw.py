# ruff: noqa: E501
"""Issue 10 (session 29): what makes a bench_dirty ``--more`` session's faults cost its ratio
(``lab4`` ``straight`` of ``--first-seed 12000``: the filter 1.21, "data 1.19").

``decompose RIG LABEL FIRST [NOISE_SEED]``: the session's mean error with each fault alone
and together, with the ball's own candidates fused without gating (the gate's oracle), and
with the blind camera absent all session (bench_dirty's "data"), inside and outside the
blackout, per method.

``draws RIG LABEL FIRST N0 N1``: the same session and faults with the detection noise (and
the spurious blobs) redrawn from seeds N0..N1-1: per draw, faults / clean, blackout alone /
clean, and the ratio of the mean stated ``std_m``, per method.

``oracle RIG LABEL FIRST [NOISE_SEEDS]``: what the ball's own detections hold, for any
method: the truth's motion known exactly, each detection's pixel moved to the point's time by
the truth's own image motion, the point at every detection triangulated (Gauss-Newton on
pixels) from every ball detection within +-k camera periods (k = 0.5, 1, 2); clean and with
the blackout, the same draws. And the per-cycle Cramer-Rao bound of the cameras' geometry
along the truth with and without the blind camera.

Run from the repository root (PYTHONPATH=.)."""
import sys

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import bench_dirty as bd

from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

METHODS = ["typeA", "smooth", "filter"]


def session(rigname, label, first):
    """(rig, motion, duration, bench seed, faults) of one --more session."""
    rig = next(r for r in bd.rigs() + bd.more_rigs() if r.name == rigname.split("@")[0])
    if "@" in rigname:
        rig = bd.at_rate(rig, float(rigname.split("@")[1]))
    for seed, (lab, motion, duration, _) in enumerate(bd.more_sessions(2, 8.0, first), start=first - 300):
        if lab == label:
            span = motion.duration if duration is None else duration
            return rig, motion, duration, seed, bd.faults(rig, seed, span)
    raise SystemExit(f"no session {label!r}")


def decompose(rigname, label, first, noise_seed=None):
    rig, motion, duration, seed, f = session(rigname, label, first)
    noise_seed = seed if noise_seed is None else noise_seed
    cam, start, length = f["blackouts"][0]
    span = motion.duration if duration is None else duration
    kinds = {"clean": {}, "faults": f, "blackout": {"blackouts": f["blackouts"]},
             "spurious": {"spurious_rate": 0.05}, "object": {"distractors": f["distractors"]},
             "spurious+object": {"spurious_rate": 0.05, "distractors": f["distractors"]},
             "without": {"blackouts": ((cam, 0.0, span + 1.0),)}}
    res = {}
    for kind, extra in kinds.items():
        det, truth, ball = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=noise_seed, **extra))
        res[kind] = (fuse_detections(det, rig, METHODS, FusionOptions(), workers=1)[0], truth)
        if kind == "faults":  # the gate's oracle: the ball's own candidates only
            res["ball labels"] = (fuse_detections(ball, rig, METHODS, FusionOptions(gating=False), workers=1)[0], truth)
    print(f"{rig.name} {label}, bench seed {seed}, noise seed {noise_seed}: {f}")
    for m in METHODS:
        clean = np.nanmean(errors_m(*((res["clean"][0][m], res["clean"][1]))))
        print(f"{m}: | kind | points | mean mm | / clean | before | in the blackout | after |")
        for kind, (tracks, truth) in res.items():
            e = errors_m(tracks[m], truth)
            t = tracks[m].time_ns / 1e9
            parts = [e[t < start], e[(t >= start) & (t <= start + length)], e[t > start + length]]
            print(f"  | {kind} | {len(e)} | {1e3 * np.nanmean(e):.3f} | {np.nanmean(e) / clean:.3f} | "
                  + " | ".join(f"{len(p)}: {1e3 * np.nanmean(p):.3f}" for p in parts) + " |")


def draws(rigname, label, first, n0, n1):
    rig, motion, duration, seed, f = session(rigname, label, first)
    print(f"{rig.name} {label}, faults of bench seed {seed}: {f}")
    print("draw | " + " | ".join(f"{m} faults, blackout, std" for m in METHODS))
    for ns in range(n0, n1):
        out = {}
        for kind, extra in (("clean", {}), ("faults", f), ("blackout", {"blackouts": f["blackouts"]})):
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=ns, **extra))
            tracks = fuse_detections(det, rig, METHODS, FusionOptions(), workers=1)[0]
            for m in METHODS:
                out[m, kind] = (np.nanmean(errors_m(tracks[m], truth)), np.nanmean(tracks[m].quality["std_m"]))
        print(ns, " | ".join(f"{out[m, 'faults'][0] / out[m, 'clean'][0]:.3f} {out[m, 'blackout'][0] / out[m, 'clean'][0]:.3f} "
                             f"{out[m, 'faults'][1] / out[m, 'clean'][1]:.3f}" for m in METHODS), flush=True)


def _jacobian(cam, p):
    J = np.zeros((2, 3))
    for i in range(3):
        d = np.zeros(3)
        d[i] = 1e-6
        J[:, i] = (cam.project((p + d)[None])[0][0] - cam.project((p - d)[None])[0][0]) / 2e-6
    return J


def oracle(rigname, label, first, noise_seeds=None):
    rig, motion, duration, seed, f = session(rigname, label, first)
    blind = rig.names.index(f["blackouts"][0][0])
    _, start, length = f["blackouts"][0]
    end = start + length
    period = 1 / rig.cameras[0].fps
    noise_seeds = noise_seeds or [seed]
    res = {}
    for ns in noise_seeds:
        for kind, extra in (("clean", {}), ("blackout", {"blackouts": f["blackouts"]})):
            _, _, ball = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=ns, **extra))
            ft = ball.frame_time_ns[ball.cand_frame] / 1e9
            fc = ball.frame_camera[ball.cand_frame]
            # each detection's pixel as the ball's at time t: moved by the truth's image motion
            own = np.array([rig.cameras[c].project(motion.position(np.array([t])))[0][0] for t, c in zip(ft, fc, strict=True)])
            for k in (0.5, 1.0, 2.0):
                err_in, err_all = [], []
                for i in range(len(ft)):
                    x_t = motion.position(np.array([ft[i]]))[0]
                    near = np.flatnonzero(np.abs(ft - ft[i]) <= k * period + 1e-9)
                    if len(set(fc[near].tolist())) < 2:
                        continue
                    obs = [(fc[j], ball.cand_uv[j] + rig.cameras[fc[j]].project(x_t[None])[0][0] - own[j]) for j in near]
                    x = x_t + 0.01
                    for _ in range(5):
                        J = np.vstack([_jacobian(rig.cameras[c], x) for c, _ in obs])
                        r = np.concatenate([uv - rig.cameras[c].project(x[None])[0][0] for c, uv in obs])
                        x = x + np.linalg.lstsq(J, r, rcond=None)[0]
                    e = np.linalg.norm(x - x_t)
                    err_all.append(e)
                    if start <= ft[i] <= end:
                        err_in.append(e)
                res.setdefault((kind, k), []).append((np.mean(err_in), np.mean(err_all)))
    print(f"{rig.name} {label}, bench seed {seed}, noise seeds {noise_seeds}")
    for k in (0.5, 1.0, 2.0):
        c, b = np.array(res["clean", k]), np.array(res["blackout", k])
        print(f"+-{k:g} periods: in the blackout {1e3 * c[:, 0].mean():.3f} -> {1e3 * b[:, 0].mean():.3f} mm, ratio "
              f"{np.mean(b[:, 0] / c[:, 0]):.3f} (per draw {np.round(b[:, 0] / c[:, 0], 3).tolist()}); whole session "
              f"{np.mean(b[:, 1] / c[:, 1]):.3f} (per draw {np.round(b[:, 1] / c[:, 1], 3).tolist()})")
    ratios = []
    for t in np.linspace(start, end, 20):
        p = motion.position(np.array([t]))[0]
        infos = []
        for c, cam in enumerate(rig.cameras):
            uv, front = cam.project(p[None])
            if front[0] and cam.in_image(uv)[0]:
                J = _jacobian(cam, p)
                infos.append((c, J.T @ J / 0.3 ** 2))
        every = sum(i for _, i in infos)
        others = sum(i for c, i in infos if c != blind)
        ratios.append(np.sqrt(np.trace(np.linalg.inv(others)) / np.trace(np.linalg.inv(every))))
    print(f"Cramer-Rao bound per camera cycle in the blackout, without / with {rig.names[blind]}: {np.mean(ratios):.3f}")


if __name__ == "__main__":
    what, rigname, label, first = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
    rest = sys.argv[5:]
    if what == "decompose":
        decompose(rigname, label, first, int(rest[0]) if rest else None)
    elif what == "draws":
        draws(rigname, label, first, int(rest[0]), int(rest[1]))
    else:
        oracle(rigname, label, first, [int(x) for x in rest[0].split(",")] if rest else None)
