# ruff: noqa: E501
"""Issue 10 (session 35, diagnosis): type A's far points (> 5 cm) that ``--confirm-gaps
kicks`` (``confirm_every`` + ``confirm_sides``) leaves, on bench_dirty ``--more``'s
sessions (clean), and what each other camera's test saw: its bracket against the truth's
velocity jumps, whether it showed a jump, the side chosen, the residual, its bounds.

    PYTHONPATH=. python benchmarks/session35/kicks_left.py FIRST [--fps 60] [--misses 0.1] [--seeds 3]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "benchmarks" / "session28"))
sys.path.insert(0, str(_ROOT / "tests"))
import inspect  # noqa: E402
import textwrap  # noqa: E402

from bench_dirty import at_rate, more_rigs, more_sessions, rigs  # noqa: E402
from farpoints import jumps  # noqa: E402

import pslog.fusion.confirm as confirm  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, fuse  # noqa: E402

CAP: list = []
_src = textwrap.dedent(inspect.getsource(confirm.sides_test)).replace(
    "        bad |= (verdict",
    "        CAP.append(dict(c=c, t=t.copy(), can=can, full=full, jump=jump, miss=miss, bound=bound, before=before, wrong=wrong, verdict=verdict, to_f=to_f, to_b=to_b, sep=np.hypot(*(ft - bt).T), sep_bound=sep_bound, excess=excess, per_m=per_m, ta=time_ns[a], tb=time_ns[b]))\n        bad |= (verdict")
_ns = dict(vars(confirm))
_ns["CAP"] = CAP
exec(compile(_src, confirm.__file__, "exec"), _ns)
confirm._sides_compiled = _ns["sides_test"]  # (the numpy statement, instrumented: the same decisions)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("first", type=int)
    ap.add_argument("--fps", type=float, default=None)
    ap.add_argument("--misses", type=float, default=0.0)
    ap.add_argument("--seeds", type=int, default=3)
    a = ap.parse_args()
    opt = FusionOptions(confirm_every=True, confirm_sides=True)
    from pslog.simulation import SimulationOptions, simulate_labelled
    for base in rigs() + more_rigs():
        rig = base if a.fps is None else at_rate(base, a.fps)
        for seed, (label, motion, duration, _k) in enumerate(more_sessions(a.seeds, 8.0, a.first), start=a.first - 300):
            span = motion.duration if duration is None else duration
            kicks = jumps(motion, span)
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                noise_px=0.3, seed=seed, miss_rate=a.misses, drop_rate=a.misses / 2))
            CAP.clear()
            tr = fuse(det, rig, "typeA", opt)
            err = errors_m(tr, truth)
            for i in np.flatnonzero(err > 0.05):
                t = int(tr.time_ns[i])
                before = kicks[kicks < t / 1e9 + 1e-9]
                k = before[-1] if len(before) else np.nan
                ts = t / 1e9
                # the truth at t and the point: the error's direction against each camera's ray
                truth_p = np.array([np.interp(t, truth.time_ns, truth.position_world[:, j]) for j in range(3)])
                p = tr.position_world[i]
                q = tr.quality
                print(f"{rig.name} {label} t={ts:.4f} cam{tr.camera[i]} err {1e3 * err[i]:.0f} mm std {1e3 * q['std_m'][i]:.1f} mm, {1e3 * (ts - k):.1f} ms after kick", flush=True)
                for c, cam in enumerate(rig.cameras):
                    if c == tr.camera[i]:
                        continue
                    has = np.bincount(det.cand_frame, minlength=len(det.frame_time_ns)) > 0
                    times = np.sort(det.frame_time_ns[(det.frame_camera == c) & has])
                    j = np.searchsorted(times, t, side="right")
                    pv = times[max(j - 2, 0):j] / 1e9 - k
                    nx = times[j:j + 2] / 1e9 - k
                    # the error across camera c's ray (what c can see), metres
                    centre = cam.center_world
                    ray = truth_p - centre
                    ray /= np.linalg.norm(ray)
                    d = p - truth_p
                    across = np.linalg.norm(d - ray * (d @ ray))
                    info = ""
                    for cap in CAP:
                        if cap["c"] != c:
                            continue
                        hit = np.flatnonzero(cap["t"] == t)
                        for h in hit:
                            info = (f"can {cap['can'][h]} full {cap['full'][h]} jump {cap['jump'][h]} (miss {cap['miss'][h]:.1f} > {cap['bound'][h]:.1f} px) after-jump {cap['before'][h]} ref [{1e3 * (cap['ta'][h] / 1e9 - k):.1f}, {1e3 * (cap['tb'][h] / 1e9 - k):.1f}] ms; "
                                    f"wrong {cap['wrong'][h]} (to_f {cap['to_f'][h]:.1f} to_b {cap['to_b'][h]:.1f} sep {cap['sep'][h]:.1f} > {cap['sep_bound'][h]:.1f}); verdict {cap['verdict'][h]} excess {cap['excess'][h]:.1f} px vs proven {0.0255 * cap['per_m'][h]:.1f} px (per_m {cap['per_m'][h]:.0f})")
                    print(f"    cam{c}: before kick-rel {np.round(1e3 * pv, 1)} ms, after {np.round(1e3 * nx, 1)} ms; error across its ray {1e3 * across:.0f} mm\n        {info}", flush=True)


if __name__ == "__main__":
    main()
