# ruff: noqa: E501
"""Issue 10 (session 31): every ``typeA`` point further than 5 cm from the truth on
``bench_dirty.py --more``'s sessions (its five rigs x 4 rallies, the library's rally,
``straight``, ``turntable``; 0.3 px; its faults: spurious blobs in 5 % of frames, the static
second object, one camera blind 0.5 s), clean and with the faults, each with its cause.

Per far point: the rig, session, time, camera, error, its ``std_m`` (error / std: is its
covariance honest), ``snap_px``, ``ray_miss_m`` and ``gap_s`` (the quality columns), whether
the faults added it (bench_dirty's "added": the clean session's point at that detection is
within 5 cm), whether it lies in the blackout (its start to two bridged gaps after its end),
the time since the last kick or bounce of the rally (ms), and the construction
(``explain_type_a``): for each detection it rests on (the newest, the two past points'
observed detections and their partners' brackets) whether it is the ball's own candidate
(``simulate_labelled``'s label), a false one (``F``), and whether the ball is inside that
camera's image at that time (``out``: it is not). So a wrong candidate, a prediction across an
unseen kick and the blackout's extrapolation are told apart.

    PYTHONPATH=. python benchmarks/session31/typea_far.py FIRST[,FIRST..] [--fps 60]
        [--misses 0.1] [--max-std-mm 25.5] [--clean] [--rigs lab4,paper2] [--no-fresh]

``--wait-sigmas K|off`` (session 32): ``pslog.fusion.confirm.WAIT_SIGMAS`` (the points made
with an innovation above K σ wait; the waits counted below leave them out:
``benchmarks/session32/kick_sweep.py`` counts them). ``--max-std-mm``: typeA fused with ``FusionOptions.max_std_m`` (withholding); ``--clean``:
list the clean sessions' far points too; ``--no-fresh``: without session 31's wait for the
points resting on a re-acquisition (``pslog.fusion.confirm.FRESH_ROWS`` off: as before). Prints one line per far point and a summary:
points, far (clean / added), good (<= 5 cm) points, mean error, and the points output that
waited for the next camera's confirmation (one detection's latency in a stream) without and
with the session-31 rule (``FRESH_ROWS``).
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, type_a_explained  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s  # noqa: E402
from pslog.fusion.gating import gate_for, prepared_for  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

FAR = 0.05


def _ball_of(ball, obs, rows):
    """Per observation row: 'b' the ball's candidate, 'F' a false one."""
    key = {}
    for f, uv in zip(ball.cand_frame.tolist(), ball.cand_uv, strict=True):
        key[(int(ball.frame_camera[f]), int(ball.frame_index[f]))] = uv
    out = []
    for r in rows:
        if r < 0:
            out.append("-")
            continue
        uv = key.get((int(obs.camera[r]), int(obs.frame_index[r])))
        out.append("b" if uv is not None and np.allclose(uv, obs.uv[r], atol=1e-9) else "F")
    return out


def _in_view(rig, truth, cam, t_ns):
    i = int(np.clip(np.searchsorted(truth.time_ns, t_ns), 0, len(truth.time_ns) - 1))
    uv, front = rig.cameras[cam].project(truth.position_world[i:i + 1])
    return bool(front[0] and rig.cameras[cam].in_image(uv)[0])


def _waits(prep, rig, track, gap):
    """(points output that waited for the next camera without the session-31 rule, with
    it): the latency's cost (a waiting point comes one detection later)."""
    from pslog.fusion import _pseudo_kernel
    from pslog.fusion._prepare import rays_only
    from pslog.fusion.confirm import LONG_FACTOR, usual_interval_s
    from pslog.fusion.innovation import previous_next_rows
    from pslog.fusion.pseudo import _all_brackets
    from pslog.records import NS

    if not len(track):
        return 0, 0
    prep = rays_only(prep)[0]
    out = []
    for fresh in (False, True):
        k = len(track)
        row, g, long = np.empty(k, np.int64), np.empty(k, np.int64), np.empty(k, bool)
        _pseudo_kernel.long_gap_kernel(
            prep.obs.time_ns, prep.obs.camera, len(rig), _all_brackets(prep)[2],
            previous_next_rows(prep)[0], track.time_ns, track.camera, int(gap * NS),
            float(LONG_FACTOR * usual_interval_s(rig) * NS), fresh, row, g, long)
        out.append(int(np.count_nonzero(long)))
    return out[0], out[1]


def run(rig, runs, first, options, misses, show_clean):
    gap = options.max_gap_s or default_max_gap_s(rig)
    tot = {"points": [0, 0], "far": [0, 0], "added": 0, "err": [[], []],
           "waits": [[0, 0], [0, 0]]}
    for seed, (label, motion, duration, kicks) in enumerate(runs, start=first - 300):
        span = motion.duration if duration is None else duration
        fault = faults(rig, seed, span)
        _, start, length = fault["blackouts"][0]
        bad_clean = set()
        for i, (kind, extra) in enumerate((("clean", {}), ("dirty", fault))):
            det, truth, ball = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=seed, miss_rate=misses, drop_rate=misses / 2, **extra))
            gated = gate_for(det, rig, "typeA", options)
            prep = prepared_for(gated, rig)
            track, cons = type_a_explained(prep, rig, options)
            obs = gated.observations
            err = errors_m(track, truth)
            tot["points"][i] += len(track)
            waits = _waits(prep, rig, track, gap)
            tot["waits"][i][0] += waits[0]
            tot["waits"][i][1] += waits[1]
            tot["err"][i].append(err[np.isfinite(err)])
            far = np.flatnonzero(err > FAR)
            tot["far"][i] += len(far)
            for j in far:
                t, c = int(track.time_ns[j]), int(track.camera[j])
                if kind == "clean":
                    bad_clean.add((t, c))
                    if not show_clean:
                        continue
                added = kind == "dirty" and (t, c) not in bad_clean
                tot["added"] += added
                p1, p2 = cons.past
                rows = [int(cons.event_row[j]), int(p1.row[j]), int(p1.prev_row[j]),
                        int(p1.next_row[j]), int(p2.row[j]), int(p2.prev_row[j]),
                        int(p2.next_row[j])]
                lab = _ball_of(ball, obs, rows)
                view = ["" if r < 0 or _in_view(rig, truth, int(obs.camera[r]),
                                               int(obs.time_ns[r])) else "out" for r in rows]
                ts = t / 1e9
                since = (1e3 * (ts - kicks[kicks <= ts].max())
                         if kicks is not None and (kicks <= ts).any() else np.nan)
                inb = start <= ts <= start + length + 2 * gap
                q = track.quality
                desc = " ".join(f"{int(obs.camera[r]) if r >= 0 else '-'}:{lb}{v}"
                                for r, lb, v in zip(rows, lab, view, strict=True))
                print(f"{rig.name:10s} {label:14s} {kind:5s} {'ADDED' if added else '     '} "
                      f"t={ts:.4f} cam{c} err={1e3 * err[j]:6.1f}mm std={1e3 * q['std_m'][j]:5.1f}mm "
                      f"snap={q['snap_px'][j]:.2f}px miss={1e3 * q['ray_miss_m'][j]:.1f}mm "
                      f"gap={1e3 * q['gap_s'][j]:.1f}ms kick+{since:.0f}ms "
                      f"{'BLACKOUT' if inb else ''} rows[new|p1 obs,prev,next|p2 obs,prev,next]={desc}",
                      flush=True)
    return tot


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first")
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    ap.add_argument("--max-std-mm", type=float, default=None)
    ap.add_argument("--clean", action="store_true")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--rigs", default=None, help="comma-separated rig names (default all)")
    ap.add_argument("--wait-sigmas", default=None,
                    help="confirm.WAIT_SIGMAS (session 32: a point whose innovation exceeds "
                         "it waits; 'off': the rule off, as before)")
    ap.add_argument("--no-fresh", action="store_true",
                    help="confirm.FRESH_ROWS off: the points resting on a re-acquisition "
                         "output at once (before session 31)")
    a = ap.parse_args()
    if a.no_fresh:
        import pslog.fusion.confirm as confirm

        confirm.FRESH_ROWS = False
    if a.wait_sigmas is not None:
        import pslog.fusion.confirm as confirm

        confirm.WAIT_SIGMAS = None if a.wait_sigmas == "off" else float(a.wait_sigmas)
    options = FusionOptions(max_std_m=None if a.max_std_mm is None else a.max_std_mm / 1e3)
    summary = []
    for first in (int(x) for x in a.first.split(",")):
        runs = more_sessions(a.seeds, 8.0, first)
        for base in rigs() + more_rigs():
            rig = base if a.fps is None else at_rate(base, a.fps)
            if a.rigs and base.name not in a.rigs.split(","):
                continue
            tot = run(rig, runs, first, options, a.misses, a.clean)
            mean = [1e3 * float(np.concatenate(e).mean()) for e in tot["err"]]
            summary.append(f"{first} {rig.name}: points clean/faults {tot['points'][0]}/{tot['points'][1]}, "
                           f">5cm clean {tot['far'][0]}, faults {tot['far'][1]} (added {tot['added']}), "
                           f"mean mm {mean[0]:.3f}/{mean[1]:.3f}, points that waited clean "
                           f"{tot['waits'][0][0]} -> {tot['waits'][0][1]}, faults "
                           f"{tot['waits'][1][0]} -> {tot['waits'][1][1]} (without -> with "
                           f"FRESH_ROWS)")
    print("\n".join(summary))


if __name__ == "__main__":
    main()
