"""Fuzz the batch gate's two deciders against each other (session 40, review40).

``gating._decided`` decides the frames in order either by the Python decider
(``_decide_in_order``) or by the compiled kernels over the whole session
(``_gate_kernel.gate_session``); the claim is: the same reason codes and decided ratios bit
for bit, in both forms, any wait, gap, clock model, lens, camera count, candidates per frame.
This script forces ``gating.WHOLE_COMPILED`` True / False on many random sessions (random
rigs, faults, forms) plus hand-made edge cases (a camera with no frames, a one-camera rig,
one frame, crowded frames, equal times across and within cameras, pixels far outside the
image, Unix-epoch clocks, 240 fps, an offline gate given a wait) and prints every session
where they differ, then the counts.

Run from the worktree root::

    PYTHONPATH=. .venv/bin/python benchmarks/session40/gate_whole_fuzz.py [--sessions N]
        [--first-seed 62000]

Seeds 62000-62999 (review40's range).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from _rally import rally
from _rigs import lab3_rig, ring_rig

import pslog.fusion._gate_kernel  # noqa: F401  (loaded: the compiled forms)
from pslog.fusion import gating
from pslog.fusion._prepare import default_max_gap_s
from pslog.motion import at_rest_first
from pslog.rig import Rig, apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig

LENS = np.array([-0.25, 0.08, 0.001, -0.001, 0.0])


def decided(det, rig, whole: bool, causal: bool, wait_ns: int, gap_ns: int):
    c, tables = gating.gate_common(det, rig)
    reason = np.full(len(c.camera), -1, dtype=np.int8)
    if len(c.camera) == 0:
        return reason, np.zeros((0, len(rig)))
    old = gating.WHOLE_COMPILED
    gating.WHOLE_COMPILED = whole
    try:
        ratio = gating._decided(c, rig, gating.GatingOptions(), causal, wait_ns, gap_ns,
                                reason, tables)
    finally:
        gating.WHOLE_COMPILED = old
    return reason, ratio


def compare(det, rig, causal: bool, wait_ns: int = 0, gap_s: float | None = None):
    """None where both ways agree, else a one-line description of the first difference."""
    gap_ns = round((gap_s or default_max_gap_s(rig)) * 1e9)
    python, r_python = decided(det, rig, False, causal, wait_ns, gap_ns)
    whole, r_whole = decided(det, rig, True, causal, wait_ns, gap_ns)
    bad = np.flatnonzero(python != whole)
    same_r = (r_python == r_whole) | (np.isnan(r_python) & np.isnan(r_whole))
    bad_r = np.flatnonzero(~np.all(same_r, axis=1))
    if len(bad) == 0 and len(bad_r) == 0:
        return None, python
    first = bad[0] if len(bad) else bad_r[0]
    return (f"{len(bad)} reasons / {len(bad_r)} ratios differ; first row {first}: reason "
            f"python {python[first]} whole {whole[first]}, ratio python "
            f"{r_python[first].tolist()} whole {r_whole[first].tolist()}"), python


# ---- rigs -------------------------------------------------------------------------------

def some_rig(rng) -> Rig:
    kind = rng.integers(0, 6)
    if kind == 0:
        rig = builtin_rig("paper3")
    elif kind == 1:
        rig = builtin_rig("paper2")
    elif kind == 2:
        rig = lab3_rig()
    else:
        rig = ring_rig(int(rng.integers(2, 6)), f"ring{kind}")
    timings = ["typeA", "sync", "typeB"] if len(rig) >= 3 else ["typeA", "sync"]
    rig = apply_timing(rig, str(rng.choice(timings)))
    fps = float(rng.choice([30.0, 30.0, 60.0, 240.0]))
    lens = rng.random() < 0.4
    cams = []
    for c in rig.cameras:
        change: dict = {}
        if fps != 30.0:
            change.update(fps=fps, offset=c.offset * 30.0 / fps)
        if lens:
            change["dist"] = LENS
        cams.append(c.replace(**change) if change else c)
    return Rig(tuple(cams), rig.name)


def some_faults(rng, rig: Rig) -> dict:
    names = rig.names
    f: dict = {}
    if rng.random() < 0.7:
        f["miss_rate"] = float(rng.uniform(0, 0.5))
    if rng.random() < 0.5:
        f["drop_rate"] = float(rng.uniform(0, 0.3))
    if rng.random() < 0.7:
        f["spurious_rate"] = float(rng.uniform(0, 0.5))
        if rng.random() < 0.5:
            f["spurious_radius_px"] = float(rng.uniform(5, 60))
    if rng.random() < 0.6:
        f["distractors"] = tuple(
            (str(rng.choice(names)) if rng.random() < 0.6 else None,
             (float(rng.uniform(0.3, 2.7)), float(rng.uniform(0.3, 1.7)),
              float(rng.uniform(0.1, 1.0))))
            for _ in range(int(rng.integers(1, 3))))
    if rng.random() < 0.4:
        f["blackouts"] = ((str(rng.choice(names)), float(rng.uniform(0, 1.5)),
                           float(rng.uniform(0.1, 0.8))),)
    period = 1.0 / max(c.fps for c in rig.cameras)
    if rng.random() < 0.4 and len(names) > 1:
        f["clock_offset_s"] = {n: float(rng.uniform(-0.02, 0.02)) for n in names[1:]}
    if rng.random() < 0.3 and len(names) > 1:
        f["clock_drift_ppm"] = {n: float(rng.uniform(-200, 200)) for n in names[1:]}
    if rng.random() < 0.4:
        f["readout_s"] = {n: float(rng.uniform(0, 0.9 * period)) for n in names}
    if rng.random() < 0.2:
        f["jitter_s"] = float(rng.uniform(0, 0.002))
    if rng.random() < 0.2:
        f["host_jitter_s"] = float(rng.uniform(0, 0.002))
    return f


def simulated(rig: Rig, seed: int, duration: float, faults: dict, rest_s: float = 0.0):
    options = SimulationOptions(noise_px=0.3 + seed % 3 * 0.4, seed=seed, **faults)
    motion = rally(duration, seed=seed, speed=4.0 + seed % 5, kick_every_s=0.7)[0]
    if rest_s:
        motion = at_rest_first(motion, rest_s)
    det, _, _ = simulate_labelled(rig, motion, duration, options)
    return det, true_rig(rig, options)


# ---- edits of a session -------------------------------------------------------------------

def keep_frames(det, keep: np.ndarray):
    """The session with only the frames ``keep`` (bool (F,)) and their candidates."""
    new_row = np.cumsum(keep) - 1
    ck = keep[det.cand_frame]
    return dataclasses.replace(
        det, frame_time_ns=det.frame_time_ns[keep], frame_camera=det.frame_camera[keep],
        frame_index=det.frame_index[keep], cand_frame=new_row[det.cand_frame[ck]],
        cand_uv=det.cand_uv[ck], cand_radius=det.cand_radius[ck],
        cand_score=det.cand_score[ck])


def crowd(det, rng, every: int, extra: int):
    """``extra`` random candidates after the first of every ``every``-th frame with any."""
    starts = np.flatnonzero(np.r_[True, np.diff(det.cand_frame) != 0])
    add = starts[::every]
    at = np.repeat(add + 1, extra)
    uv = np.insert(det.cand_uv, at, rng.uniform(0, 700, (len(at), 2)), axis=0)
    frames = np.insert(det.cand_frame, at, np.repeat(det.cand_frame[add], extra))
    return dataclasses.replace(det, cand_uv=uv, cand_frame=frames,
                               cand_score=np.insert(det.cand_score, at, 0.0),
                               cand_radius=np.insert(det.cand_radius, at, np.nan))


def far_pixels(det, rng, share: float):
    uv = det.cand_uv.copy()
    pick = rng.random(len(uv)) < share
    uv[pick] = rng.choice([-1e7, 1e7, 1e12], (pick.sum(), 2))
    return dataclasses.replace(det, cand_uv=uv)


def shifted(det, shift_ns: int):
    return dataclasses.replace(det, frame_time_ns=det.frame_time_ns + shift_ns)


def retimed(det, rng, period_ns: int):
    """Frame times rounded to a coarse grid: equal times across and within cameras."""
    t = det.frame_time_ns // period_ns * period_ns
    order = np.lexsort((det.frame_camera, t))
    # (frames sorted by (time, camera); candidates follow their frames)
    inverse = np.empty_like(order)
    inverse[order] = np.arange(len(order))
    new_frame = inverse[det.cand_frame]
    c_order = np.argsort(new_frame, kind="stable")
    return dataclasses.replace(
        det, frame_time_ns=t[order], frame_camera=det.frame_camera[order],
        frame_index=det.frame_index[order], cand_frame=new_frame[c_order],
        cand_uv=det.cand_uv[c_order], cand_radius=det.cand_radius[c_order],
        cand_score=det.cand_score[c_order])


# ---- the run --------------------------------------------------------------------------------

def random_case(seed: int, long: bool = False):
    rng = np.random.default_rng(seed)
    rig = some_rig(rng)
    duration = float(rng.uniform(0.5, 2.5)) * (30.0 / max(c.fps for c in rig.cameras)) ** 0.5
    if long:
        duration *= 10
    faults = some_faults(rng, rig)
    rest = float(rng.uniform(0.2, 0.8)) if rng.random() < 0.2 else 0.0
    det, true = simulated(rig, seed, duration, faults, rest)
    # the clock model a sync estimated (the true one), or none (cameras' clocks uncorrected:
    # far apart where the faults' offsets are large)
    unsynced = bool(faults.get("clock_offset_s")) and rng.random() < 0.3
    rig = rig if unsynced else true
    tags = [rig.name, f"{len(rig)}cams", f"{rig.cameras[0].fps:g}fps",
            ",".join(sorted(faults)) or "clean"] + (["unsynced"] if unsynced else [])
    edit = rng.integers(0, 9)
    if edit == 0 and len(rig) > 1:
        gone = int(rng.integers(0, len(rig)))
        det = keep_frames(det, det.frame_camera != gone)
        tags.append(f"no-frames-of-{gone}")
    elif edit == 1:
        det = crowd(det, rng, int(rng.integers(2, 30)), int(rng.integers(1, 9)))
        tags.append("crowded")
    elif edit == 2:
        det = far_pixels(det, rng, float(rng.uniform(0.01, 0.2)))
        tags.append("far-pixels")
    elif edit == 3:
        det = shifted(det, int(rng.choice([1_700_000_000, -1_000_000_000, 4_000_000_000]))
                      * 1_000_000_000)
        tags.append("epoch-clock")
    elif edit == 4:
        det = retimed(det, rng, int(rng.choice([1_000_000, 11_111_111, 33_333_333])))
        tags.append("equal-times")
    elif edit == 5:
        n = int(rng.integers(1, 4))
        det = keep_frames(det, np.isin(np.arange(det.n_frames),
                                       rng.choice(det.n_frames, n, replace=False)))
        tags.append(f"{n}-frames")
    causal = bool(rng.random() < 0.5)
    wait_ns = (int(rng.choice([0, 0, 4_000_000, 20_000_000, 1_000_000_000]))
               if rng.random() < 0.5 else 0)
    gap_s = None if rng.random() < 0.7 else float(rng.uniform(0.01, 0.2))
    tags.append(("causal" if causal else "offline") + (f" wait {wait_ns}" if wait_ns else "")
                + (f" gap {gap_s:.3f}" if gap_s else ""))
    return det, rig, causal, wait_ns, gap_s, tags


def fixed_cases():
    """The hand-made edge cases, (name, det, rig, causal, wait_ns, gap_s)."""
    out = []
    one = builtin_rig("paper3")
    solo = Rig((one.cameras[0],), "solo")
    det, rig = simulated(solo, 62900, 1.0, {"spurious_rate": 0.3,
                                            "distractors": ((None, (1.0, 1.5, 0.2)),)})
    for causal in (True, False):
        out.append(("one-camera rig", det, rig, causal, 0, None))
    p3 = apply_timing(builtin_rig("paper3"), "typeA")
    det, rig = simulated(p3, 62901, 1.0, {"spurious_rate": 0.3})
    first = keep_frames(det, np.arange(det.n_frames) == np.flatnonzero(
        det.candidates_per_frame() > 0)[0])
    for causal in (True, False):
        out.append(("one frame", first, rig, causal, 0, None))
    b3 = apply_timing(builtin_rig("paper3"), "sync")  # every camera's shutter at once
    det, rig = simulated(b3, 62902, 2.0, {"spurious_rate": 0.4, "miss_rate": 0.2,
                                          "distractors": ((None, (1.0, 1.5, 0.2)),)})
    for causal in (True, False):
        out.append(("sync: equal times", det, rig, causal, 0, None))
        out.append(("offline given a wait" if not causal else "causal wait", det, rig,
                    causal, 20_000_000, None))
    return out


def mutate(kind: str) -> None:
    """Wrap gate_session with a deliberate fault: ``several`` always True (the offline
    stillness premise), or ``wait`` 0 (the causal wait dropped)."""
    import pslog.fusion._gate_kernel as gk

    real = gk.gate_session

    def broken(c, tables, rig, options, wait_ns, max_gap_ns, F, constants, lags, gravity,
               causal, several, frames, reason):
        if kind == "several":
            several = True
        else:
            wait_ns = 0
        return real(c, tables, rig, options, wait_ns, max_gap_ns, F, constants, lags, gravity,
                    causal, several, frames, reason)

    gk.gate_session = broken


def main(argv=None) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--sessions", type=int, default=200)
    parser.add_argument("--first-seed", type=int, default=62000)
    parser.add_argument("--long", action="store_true", help="sessions ten times longer")
    parser.add_argument("--no-fixed", action="store_true", help="the random sessions only")
    parser.add_argument("--mutate", choices=["several", "wait"],
                        help="break the whole-session path on purpose (the harness must see it)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    sessions = candidates = rejected = failures = 0
    if args.mutate:
        mutate(args.mutate)
    for name, det, rig, causal, wait_ns, gap_s in ([] if args.no_fixed else fixed_cases()):
        try:
            diff, reason = compare(det, rig, causal, wait_ns, gap_s)
        except Exception as exc:
            diff, reason = f"raised {type(exc).__name__}: {exc}", np.zeros(0)
        sessions += 1
        candidates += det.n_candidates
        rejected += int(np.count_nonzero(reason >= 0))
        if diff:
            failures += 1
            print(f"DIFF fixed '{name}' ({'causal' if causal else 'offline'}): {diff}",
                  flush=True)
    for seed in range(args.first_seed, args.first_seed + args.sessions):
        det, rig, causal, wait_ns, gap_s, tags = random_case(seed, args.long)
        try:
            diff, reason = compare(det, rig, causal, wait_ns, gap_s)
        except Exception as exc:
            diff, reason = f"raised {type(exc).__name__}: {exc}", np.zeros(0)
        sessions += 1
        candidates += det.n_candidates
        rejected += int(np.count_nonzero(reason >= 0))
        if diff:
            failures += 1
            print(f"DIFF seed {seed} [{' '.join(tags)}]: {diff}", flush=True)
    print(f"{sessions} sessions, {candidates} candidates ({rejected} rejected by the Python "
          f"decider) compared; {failures} differ; {time.perf_counter() - start:.0f} s")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
