# ruff: noqa: E501
"""Issue 10 (session 37, scan37): a held-out scan of ``bench_dirty.py --more --validity``,
per session rather than per row, and each miss decomposed by fault.

``scan FIRST [--fps F] [--misses M]``: bench_dirty's ``--more`` sessions (``--seeds 3``) on
its five rigs, clean / faults / blackout alone / without the blind camera, as
``measure_more`` fuses them; prints every session whose faults / clean ratio exceeds its
method's target (with its data ratio, ``_data_ratio``, and the blackout alone's), and every
output point beyond 5 cm (clean, or added by the faults), with its class: in the blackout
(its start to two bridged gaps after its end), < 40 ms after a kick or bounce of the tests'
rallies, in the session's first or last 0.2 s.

``decompose RIG LABEL FIRST [--fps F] [--misses M]``: one session's mean error (before / in /
after the blackout) per method with each fault alone and in pairs, with the ball's own
candidates fused without gating (the gate's oracle), and without the blind camera all
session; with ``smooth``'s knot spacing, breaks, σ and left-out detections per kind.

``far RIG LABEL FIRST T [--fps F] [--misses M]``: the points near time T (±60 ms) of every
kind, per method, with their error; for one far point's cause.

Run from the repository root (PYTHONPATH=.)."""
from __future__ import annotations

import argparse
import dataclasses
import sys

import numpy as np

sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import bench_dirty as bd

import pslog.estimation as E
from pslog.evaluation import errors_m
from pslog.fusion import CONFIRM_GAPS, FusionOptions
from pslog.fusion._prepare import default_max_gap_s
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled

METHODS = ["typeA", "smooth", "filter"]
SEEDS = 3
NS = 1e9
#: bench_dirty's options: pslog fuse's defaults (typeA's ``--confirm-gaps kicks``)
OPTIONS = FusionOptions(**dict(zip(("confirm_gaps", "confirm_every", "confirm_sides",
                                    "confirm_breaks"),
                                   CONFIRM_GAPS["kicks"], strict=True)))

_fit = E.fit_trajectory
FITS: list = []


def _capturing(obs, rig, options=None, consider_px=None):
    fit = _fit(obs, rig, options, consider_px=consider_px)
    FITS.append(fit)
    return fit


def all_rigs(fps):
    out = bd.rigs() + bd.more_rigs()
    return out if fps is None else [bd.at_rate(r, fps) for r in out]


def sessions_of(first):
    return list(enumerate(bd.more_sessions(SEEDS, 8.0, first), start=first - 300))


def simulate(rig, motion, duration, seed, misses, extra):
    return simulate_labelled(rig, motion, duration, SimulationOptions(
        noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2, **extra))


def _classes(t, start, length, gap, kicks, span):
    c = []
    if start <= t <= start + length + 2 * gap:
        c.append("blackout")
    if kicks is not None:
        since = t - kicks[kicks <= t]
        if len(since) and since.min() < bd.KICK_WINDOW_S:
            c.append("after kick")
    if t < 0.2:
        c.append("start")
    if t > span - 0.2:
        c.append("end")
    return ",".join(c) or "-"


def scan(first, fps, misses):
    options = OPTIONS
    for rig in all_rigs(fps):
        gap = default_max_gap_s(rig)
        for seed, (label, motion, duration, kicks) in sessions_of(first):
            span = motion.duration if duration is None else duration
            fault = bd.faults(rig, seed, span)
            cam, start, length = fault["blackouts"][0]
            kinds = {"clean": {}, "dirty": fault, "blackout": {"blackouts": fault["blackouts"]},
                     "without": {"blackouts": ((cam, 0.0, span + 1.0),)}}
            tracks, truth = {}, None
            for kind, extra in kinds.items():
                det, truth, _ = simulate(rig, motion, duration, seed, misses, extra)
                tracks[kind] = bd._fused(det, rig, METHODS, options)
            desc = f"blind {cam} {start:.3f}-{start + length:.3f} s, object on {fault['distractors'][0][0]}, span {span:.2f} s"
            for m in METHODS:
                err = {k: errors_m(tracks[k][m], truth) for k in kinds}
                ratio = np.nanmean(err["dirty"]) / np.nanmean(err["clean"])
                data = bd._data_ratio(tracks, m, err, start, length)
                alone = np.nanmean(err["blackout"]) / np.nanmean(err["clean"])
                if ratio > bd.TARGETS[m]:
                    print(f"RATIO {rig.name} {m} {label}: {ratio:.3f} (data {data:.3f}, blackout alone {alone:.3f}; {desc})", flush=True)
                bad_clean = set()
                for kind in ("clean", "dirty"):
                    tr = tracks[kind][m]
                    far = np.flatnonzero(err[kind] > bd.MAX_ERROR_M)
                    for i in far:
                        key = (int(tr.time_ns[i]), int(tr.camera[i]))
                        if kind == "clean":
                            bad_clean.add(key)
                            what = "clean"
                        elif key in bad_clean:
                            continue
                        else:
                            what = "ADDED"
                        t = tr.time_ns[i] / NS
                        print(f"FAR {what} {rig.name} {m} {label} t {t:.4f} {rig.names[tr.camera[i]]} {1e3 * err[kind][i]:.1f} mm "
                              f"[{_classes(t, start, length, gap, kicks, span)}] ({desc})", flush=True)
        print(f"-- {rig.name} done", flush=True)


def _find(rigname, label, first, fps):
    rig = next(r for r in all_rigs(fps) if r.name == rigname)
    for seed, (lab, motion, duration, kicks) in sessions_of(first):
        if lab == label:
            span = motion.duration if duration is None else duration
            return rig, motion, duration, seed, bd.faults(rig, seed, span), kicks, span
    raise SystemExit(f"no session {label!r}")


def _kinds(f, span):
    cam = f["blackouts"][0][0]
    return {"clean": {}, "faults": f, "blackout": {"blackouts": f["blackouts"]},
            "spurious": {"spurious_rate": 0.05}, "object": {"distractors": f["distractors"]},
            "spurious+object": {"spurious_rate": 0.05, "distractors": f["distractors"]},
            "blackout+object": {"blackouts": f["blackouts"], "distractors": f["distractors"]},
            "blackout+spurious": {"blackouts": f["blackouts"], "spurious_rate": 0.05},
            "without": {"blackouts": ((cam, 0.0, span + 1.0),)}}


def decompose(rigname, label, first, fps, misses, methods=METHODS):
    rig, motion, duration, seed, f, _, span = _find(rigname, label, first, fps)
    _, start, length = f["blackouts"][0]
    print(f"{rig.name} {label}, bench seed {seed}, misses {misses}: {f}, span {span:.3f} s")
    E.fit_trajectory = _capturing
    res, fits = {}, {}
    for kind, extra in _kinds(f, span).items():
        det, truth, ball = simulate(rig, motion, duration, seed, misses, extra)
        FITS.clear()
        res[kind] = (fuse_detections(det, rig, methods, OPTIONS, workers=1)[0], truth)
        fits[kind] = FITS[-1] if FITS else None
        if kind == "faults":
            FITS.clear()
            res["ball, no gating"] = (fuse_detections(ball, rig, methods, dataclasses.replace(OPTIONS, gating=False), workers=1)[0], truth)
            fits["ball, no gating"] = FITS[-1] if FITS else None
    for m in methods:
        clean = np.nanmean(errors_m(res["clean"][0][m], res["clean"][1]))
        print(f"{m}: | kind | points | mean mm | / clean | before | in the blackout | after |" + (" h ms, breaks, σ, dropped |" if m == "smooth" else ""))
        for kind, (tracks, truth) in res.items():
            e = errors_m(tracks[m], truth)
            t = tracks[m].time_ns / NS
            parts = [e[t < start], e[(t >= start) & (t <= start + length)], e[t > start + length]]
            extra = ""
            if m == "smooth" and fits.get(kind) is not None:
                tr = fits[kind].trajectory
                extra = f" {tr.spacing_s * 1e3:.1f}, {np.round(tr.breaks_s, 3).tolist()}, {tr.noise_px:.3f}, {dict(tracks[m].dropped)} |"
            print(f"  | {kind} | {len(e)} | {1e3 * np.nanmean(e):.3f} | {np.nanmean(e) / clean:.3f} | "
                  + " | ".join(f"{len(p)}: {1e3 * np.nanmean(p) if len(p) else np.nan:.3f}" for p in parts) + " |" + extra)
    return res


def far(rigname, label, first, t0, fps, misses, methods=METHODS):
    rig, motion, duration, seed, f, kicks, span = _find(rigname, label, first, fps)
    print(f"{rig.name} {label}, bench seed {seed}: {f}; kicks near: "
          f"{[] if kicks is None else np.round(kicks[np.abs(kicks - t0) < 0.3], 3).tolist()}")
    for kind, extra in _kinds(f, span).items():
        det, truth, _ = simulate(rig, motion, duration, seed, misses, extra)
        tracks = fuse_detections(det, rig, methods, OPTIONS, workers=1)[0]
        for m in methods:
            tr = tracks[m]
            e = errors_m(tr, truth)
            sel = np.flatnonzero(np.abs(tr.time_ns / NS - t0) < 0.06)
            print(f"  {kind:18s} {m:6s} " + " ".join(f"{tr.time_ns[i] / NS:.3f}:{rig.names[tr.camera[i]][-1]}:{1e3 * e[i]:.0f}" for i in sel))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("what")
    ap.add_argument("args", nargs="*")
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--base", default="clean")
    a = ap.parse_args()
    methods = a.methods.split(",")
    if a.what == "scan":
        scan(int(a.args[0]), a.fps, a.misses)
    elif a.what == "decompose":
        decompose(a.args[0], a.args[1], int(a.args[2]), a.fps, a.misses, methods)
    elif a.what == "diff":
        diff(a.args[0], a.args[1], int(a.args[2]), a.args[3], a.fps, a.misses, methods, a.base)
    elif a.what == "far":
        far(a.args[0], a.args[1], int(a.args[2]), float(a.args[3]), a.fps, a.misses, methods)


def choices(det, ball, rej, rig, limit=12):
    """The gate's errors in one method's form: the ball's own candidates it rejected (and
    why), and the frames where a candidate that is not the ball's was kept (chosen)."""
    from pslog.fusion.gating import REASONS
    ball_uv = {(int(t), int(c)): uv for t, c, uv in zip(
        ball.frame_time_ns[ball.cand_frame], ball.frame_camera[ball.cand_frame], ball.cand_uv, strict=True)}
    rejected = {(int(t), int(c), round(float(u), 6), round(float(v), 6)): REASONS[r] for t, c, (u, v), r in zip(
        rej.frame_time_ns, rej.camera, rej.uv, rej.reason, strict=True)}
    lost, false = [], []
    for t, c, (u, v) in zip(det.frame_time_ns[det.cand_frame], det.frame_camera[det.cand_frame], det.cand_uv, strict=True):
        key = (int(t), int(c))
        is_ball = key in ball_uv and np.hypot(*(ball_uv[key] - (u, v))) < 1e-6
        why = rejected.get((*key, round(float(u), 6), round(float(v), 6)))
        if is_ball and why is not None:
            lost.append(f"{t / NS:.4f} {rig.names[c]} {why}")
        elif not is_ball and why is None:
            d = np.hypot(*(ball_uv[key] - (u, v))) if key in ball_uv else np.nan
            false.append(f"{t / NS:.4f} {rig.names[c]} ({d:.0f} px from the ball)")
    return (f"rejections {len(rej)}; the ball's rejected {len(lost)}: {lost[:limit]}; "
            f"false kept {len(false)}: {false[:limit]}")


def diff(rigname, label, first, kind, fps, misses, methods=METHODS, base="clean"):
    """``kind`` against ``base``: the points each lacks, the largest error changes, and the
    gate's rejections of the ball's own candidates."""
    rig, motion, duration, seed, f, _, span = _find(rigname, label, first, fps)
    kinds = _kinds(f, span)
    out = {}
    for k in (base, kind):
        det, truth, ball = simulate(rig, motion, duration, seed, misses, kinds[k])
        tracks, rej = fuse_detections(det, rig, methods, OPTIONS, workers=1)
        out[k] = (tracks, truth)
        for m in methods:
            print(f"{k} {m}: " + choices(det, ball, rej[m], rig))
    for m in methods:
        (t0, tr0), (t1, tr1) = (out[base][0][m], out[base][1]), (out[kind][0][m], out[kind][1])
        e0, e1 = errors_m(t0, tr0), errors_m(t1, tr1)
        k0 = t0.time_ns.astype(np.int64) * 8 + t0.camera
        k1 = t1.time_ns.astype(np.int64) * 8 + t1.camera
        _, i0, i1 = np.intersect1d(k0, k1, return_indices=True)
        miss = np.setdiff1d(k0, k1)
        new = np.setdiff1d(k1, k0)
        print(f"{m}: {base} {len(t0)} {1e3 * np.nanmean(e0):.3f} mm, {kind} {len(t1)} {1e3 * np.nanmean(e1):.3f} mm; "
              f"missing {len(miss)} {np.round((miss // 8) / NS, 4).tolist()[:15]}; new {len(new)} {np.round((new // 8) / NS, 4).tolist()[:15]}")
        d = e1[i1] - e0[i0]
        for j in np.argsort(-np.abs(np.nan_to_num(d)))[:8]:
            print(f"    t {t1.time_ns[i1[j]] / NS:.4f} {rig.names[t1.camera[i1[j]]]} {1e3 * e0[i0[j]]:.2f} → {1e3 * e1[i1[j]]:.2f} mm")
        tb = t1.time_ns[i1] / NS
        row = []
        for a in np.arange(0, tb.max() + 0.1, 0.1):
            sel = (tb >= a) & (tb < a + 0.1)
            if sel.any():
                row.append(f"{a:.1f}:{1e3 * np.nanmean(e0[i0][sel]):.2f}/{1e3 * np.nanmean(e1[i1][sel]):.2f}")
        print("  per 0.1 s, common points: " + " ".join(row))



if __name__ == "__main__":
    main()
