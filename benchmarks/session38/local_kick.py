# ruff: noqa: E501, E702
"""Session 38 probe: type A's kick instants from a *local* two-piece ballistic fit instead of
smooth's whole-session fit (measured, not built).

Where the forward and backward type A points on a detection disagree (``z = |F - B| /
sqrt(std_f^2 + std_b^2) > ZMIN``), the rays of every detection within ``W`` of it are fitted
by one ballistic piece and by two pieces meeting at an instant ``τ`` (position continuous,
the velocity free on each side, gravity known): for each ``τ`` of a 1-ms grid the model
``X(t) = p + v_{1|2} (t - τ) + ½ g (t - τ)²`` is linear in ``(p, v1, v2)``; each ray gives
``P_k X(t_k) = P_k c_k`` (``P_k = I - d_k d_kᵀ``), weighted by ``f / (depth σ)`` (pixels).
A break is kept when the cost falls by more than ``DROP`` px² (χ²₄'s 1 - 1e-4 quantile is
23.5). The rule is session 37's (``breaks``) with these instants: a forward point spanning
one is replaced by the backward point when that spans none, else withheld. Printed per run
against the rule with smooth's breaks: far points (> 5 cm), good points withheld, replaced,
the windows' share of the session and the CPU of the local fits (Python loops: the figure is
an upper bound).

    PYTHONPATH=. python benchmarks/session38/local_kick.py FIRST [FPS|-] [MISSES] [--faults]
"""
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.fusion import FusionOptions, _type_a, offline_confirmation, type_a_prepared  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s  # noqa: E402
from pslog.fusion.breaks import fit_breaks_ns, reversed_prepared  # noqa: E402
from pslog.records import matching_rows, point_keys  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

ZMIN, W, DROP, SIGMA = 2.0, 0.12, 23.5, 0.5
GVEC = np.array([0.0, 0.0, -9.8])


def _cost(P, ts, c, tau, two):
    """The weighted least-squares cost (px²) of one piece or two meeting at ``tau``."""
    s = ts - tau
    before = s < 0
    cols = [P]
    if two:
        cols += [P * (s * before)[:, None, None], P * (s * ~before)[:, None, None]]
    else:
        cols += [P * s[:, None, None]]
    A = np.concatenate(cols, axis=2).reshape(-1, 3 * len(cols))
    b = np.einsum("kij,kj->ki", P, c - 0.5 * GVEC[None] * (s ** 2)[:, None]).reshape(-1)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    r = A @ x - b
    return float(r @ r)


def local_breaks(prep, F, centres_t, focal):
    """Instants (ns) of the two-piece fits' breaks around ``centres_t`` (ns)."""
    t_all = prep.obs.time_ns
    d_all = prep.ray_dir
    c_all = prep.centers[prep.obs.camera]
    # depth of each detection from the forward point on it (else the window's median)
    depth = np.full(len(t_all), np.nan)
    rows, has = matching_rows(point_keys(F.time_ns, F.camera), point_keys(t_all, prep.obs.camera))
    depth[rows[has]] = np.linalg.norm(F.position_world[has] - c_all[rows[has]], axis=1)
    out = []
    done_until = -1
    for tc in np.sort(centres_t):
        if tc <= done_until:
            continue
        lo, hi = np.searchsorted(t_all, [tc - W * 1e9, tc + W * 1e9])
        k = np.arange(lo, hi)
        if len(k) < 8:
            continue
        done_until = tc + 0.02e9
        dep = depth[k]
        dep = np.where(np.isfinite(dep), dep, np.nanmedian(dep) if np.any(np.isfinite(dep)) else 5.0)
        wgt = focal[prep.obs.camera[k]] / (dep * SIGMA)
        d = d_all[k]
        P = np.eye(3)[None] - d[:, :, None] * d[:, None, :]
        P = P * wgt[:, None, None]
        ts = (t_all[k] - tc) / 1e9
        c = c_all[k]

        one = _cost(P, ts, c, 0.0, False)
        grid = np.arange(ts[2], ts[-3], 0.001)
        if not len(grid):
            continue
        costs = np.array([_cost(P, ts, c, tau, True) for tau in grid])
        j = int(np.argmin(costs))
        if one - costs[j] > DROP:
            out.append(tc + round(grid[j] * 1e9))
    return np.unique(np.asarray(out, np.int64))


def rule(br, t, sf, has, sb):
    br = np.sort(br)
    spanning = np.searchsorted(br, t, side="right") > np.searchsorted(br, t - sf, side="right")
    bsp = ~has | (np.searchsorted(br, t + sb, side="left") > np.searchsorted(br, t, side="left"))
    return spanning & ~bsp, spanning & bsp


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    first = int(args[0])
    fps = float(args[1]) if len(args) > 1 and args[1] != '-' else None
    kind = "faults" if "--faults" in sys.argv else "clean"
    misses = float(args[2]) if len(args) > 2 else 0.0
    opt = offline_confirmation(FusionOptions())
    tot = {}
    cpu = 0.0
    cover_n = cover_d = 0.0
    for base in rigs() + more_rigs():
        rig = base if fps is None else at_rate(base, fps)
        optg = replace(opt, max_gap_s=default_max_gap_s(rig))
        focal = np.array([cam.K[0, 0] for cam in rig.cameras])
        for seed, (label, motion, duration, _k) in enumerate(more_sessions(3, 8.0, first), start=first - 300):
            span = motion.duration if duration is None else duration
            extra = {} if kind == "clean" else faults(rig, seed, span)
            det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, miss_rate=misses, **extra))
            _, prep = type_a_prepared(det, rig, opt)
            F = _type_a(prep, rig, optg)
            if not len(F):
                continue
            rp, t0 = reversed_prepared(prep, rig)
            B = _type_a(rp, rig, optg)
            t = F.time_ns
            sf = np.round(F.quality["span_s"] * 1e9).astype(np.int64)
            idx, has = matching_rows(point_keys(t, F.camera), point_keys(t0 - B.time_ns, B.camera))
            sb = np.zeros(len(t), np.int64)
            sb[has] = np.round(B.quality["span_s"][idx[has]] * 1e9).astype(np.int64)
            eF = np.linalg.norm(F.position_world - truth.at(t), axis=1)
            eB = np.full(len(t), np.inf)
            eB[has] = np.linalg.norm(B.position_world[idx[has]] - truth.at(t[has]), axis=1)
            sB = np.full(len(t), np.inf)
            sB[has] = B.quality["std_m"][idx[has]]
            d = np.full(len(t), 0.0)
            d[has] = np.linalg.norm(F.position_world[has] - B.position_world[idx[has]], axis=1)
            z = d / np.sqrt(F.quality["std_m"] ** 2 + sB ** 2)
            screened = has & (z > ZMIN)
            c0 = time.process_time()
            lb = local_breaks(prep, F, t[screened], focal)
            cpu += time.process_time() - c0
            cover_n += screened.sum()
            cover_d += len(t)
            fb = fit_breaks_ns(prep, rig, optg)
            far, good = eF > 0.05, eF <= 0.05
            for name, br in (("fit", fb), ("local", lb)):
                use, out = rule(br, t, sf, has, sb)
                new = np.where(use, eB, eF)
                r = tot.setdefault(name, dict.fromkeys(("n", "far0", "far", "good_out", "replaced", "breaks"), 0))
                r["n"] += len(t); r["far0"] += int(far.sum()); r["far"] += int((~out & (new > 0.05)).sum())
                r["good_out"] += int((good & out).sum()); r["replaced"] += int(use.sum()); r["breaks"] += len(br)
                for i in np.flatnonzero(~out & (new > 0.05)):
                    print(f"  {name}: {rig.name} {label} far left at {(t[i] - t.min()) / 1e9:.3f} s err {new[i] * 1e3:.0f} mm (z {z[i]:.1f}, has B {has[i]})")
        sys.stdout.flush()
    print(f"== first {first} fps {fps or 'rig'} misses {misses} {kind}: screened {cover_n / cover_d * 100:.2f} % of points; local fits CPU {cpu:.1f} s")
    for name, r in tot.items():
        print(f"  {name}: points {r['n']} far {r['far0']} -> {r['far']}, good withheld {r['good_out']}, replaced {r['replaced']}, breaks {r['breaks']}")


if __name__ == "__main__":
    main()
