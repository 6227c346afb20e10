# ruff: noqa: E501
"""Issue 10 (session 35): ``lab3`` ``straight`` of ``bench_dirty.py --more --first-seed 44000``
(``--seeds 3``): ``smooth`` 1.21, data 1.13, blackout alone (pooled) 1.03 — a false break.

Session 29's tools on bench_dirty's default three rallies (its ``session`` assumed two):
``decompose``, ``draws``, ``oracle`` (``benchmarks/session29/blackout_draw.py``), and:

``breaks RIG LABEL FIRST [NOISE_SEED]``: ``smooth``'s fit of the ball's own detections, clean,
with the blackout, and without the blind camera all session: knot spacing, breaks, the loose
fit's σ and the break candidates' gains, the final σ, the mean error inside / outside the
blackout; again with the knot spacing fixed at 38.7 and 50 ms.

``falsebreaks N0 N1``: sessions with a break among ``straight``, ``turntable``, ``spiral``
(no velocity jump) on bench_dirty's five rigs, clean, 0.3 px, noise seeds N0..N1-1.

``rallies N0 N1``: ``smooth`` on 20-s library rallies (``rally_motion(seed)``, and with
``restitution=0.35, friction=0.6``: low bounces that end rolling), five rigs, 0.3 and 1 px.

With ``S35_NOCONFIRM=1`` the fit without session 35's confirmation of each break at the
fit under the real prior (``trajectory._confirmed_breaks``: main before it). With
``S35_DOF=1`` the break test runs at the loose fit's σ corrected for its degrees of
freedom (``sqrt(n_res / (n_res - p_eff))``, as the final fit's): the option measured in
docs/methods.md ("`lab3`'s `straight` at 1.21"), not kept. ``python
benchmarks/session35/smooth_straight.py bench ARGS`` runs ``bench_dirty.py ARGS`` so.

Run from the repository root (PYTHONPATH=.)."""
import os
import runpy
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session29")
sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import bench_dirty as bd
import blackout_draw as b29

import pslog.estimation.trajectory as T
from pslog.estimation import SmoothOptions, fit_trajectory
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion._prepare import default_max_gap_s
from pslog.fusion.gating import fuse_detections
from pslog.motion import get_motion, rally_motion
from pslog.records import NS
from pslog.simulation import SimulationOptions, simulate_labelled

SEEDS = 3
_find_breaks = T._find_breaks


def _dof_corrected(problem, control, sigma, r, w, J, *args, **kwargs):
    """The break search at the loose fit's σ corrected for its degrees of freedom."""
    _, dof, _ = T._information(problem, control, sigma, r, J, trace=True)
    return _find_breaks(problem, control, sigma * dof, r, w, J, *args, **kwargs)


if os.environ.get("S35_DOF") == "1":
    T._find_breaks = _dof_corrected
if os.environ.get("S35_NOCONFIRM") == "1":  # the fit before session 35's confirmation
    T._confirmed_breaks = lambda problem, control, sigma, r, w, J, spacing, breaks, options: breaks


def session(rigname, label, first):
    """(rig, motion, duration, bench seed, faults) of one --more session (--seeds 3)."""
    rig = next(r for r in bd.rigs() + bd.more_rigs() if r.name == rigname.split("@")[0])
    if "@" in rigname:
        rig = bd.at_rate(rig, float(rigname.split("@")[1]))
    for seed, (lab, motion, duration, _) in enumerate(bd.more_sessions(SEEDS, 8.0, first), start=first - 300):
        if lab == label:
            span = motion.duration if duration is None else duration
            return rig, motion, duration, seed, bd.faults(rig, seed, span)
    raise SystemExit(f"no session {label!r}")


b29.session = session


def breaks(rigname, label, first, noise_seed=None):
    rig, motion, duration, seed, f = session(rigname, label, first)
    noise_seed = seed if noise_seed is None else noise_seed
    cam, start, length = f["blackouts"][0]
    span = motion.duration if duration is None else duration
    kinds = {"clean": {}, "blackout": {"blackouts": f["blackouts"]},
             "without": {"blackouts": ((cam, 0.0, span + 1.0),)}}
    greedy = T._greedy_breaks

    def shown(tau, gain, free, threshold, apart):
        best = np.argsort(-gain)[:3]
        print(f"    candidates {np.round(tau[best], 4).tolist()} gains {np.round(gain[best], 1).tolist()} (σ² of the loose fit's σ)")
        return greedy(tau, gain, free, threshold, apart)

    def loose(problem, control, sigma, r, *args, **kwargs):
        print(f"    loose fit's σ {sigma:.4f} px")
        return T._find_breaks.__wrapped__(problem, control, sigma, r, *args, **kwargs)

    loose.__wrapped__ = T._find_breaks
    T._greedy_breaks, T._find_breaks = shown, loose
    try:
        for spacing in (None, 0.0387, 0.05):
            for kind, extra in kinds.items():
                _, truth, ball = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=noise_seed, **extra))
                obs = ball.best()
                print(f"  {kind}, knot spacing {'default' if spacing is None else spacing}:")
                fit = fit_trajectory(obs, rig, SmoothOptions(max_gap_s=default_max_gap_s(rig), knot_spacing_s=spacing))
                tr = fit.trajectory
                t = obs.time_ns / NS
                ok = fit.used & np.all(np.isfinite(fit.position), axis=1)
                e = np.linalg.norm(fit.position - truth.at(obs.time_ns), axis=1)
                inside = (t >= start) & (t <= start + length)
                print(f"    h {tr.spacing_s * 1e3:.2f} ms, breaks {np.round(tr.breaks_s, 4).tolist()}, final σ {tr.noise_px:.4f}: "
                      f"mean {1e3 * np.mean(e[ok]):.3f} mm, in the blackout {1e3 * np.mean(e[ok & inside]):.3f}, outside {1e3 * np.mean(e[ok & ~inside]):.3f}")
    finally:
        T._greedy_breaks, T._find_breaks = greedy, loose.__wrapped__


def falsebreaks(n0, n1):
    for rig in bd.rigs() + bd.more_rigs():
        for name in ("straight", "turntable", "spiral"):
            motion = get_motion(name)
            sessions = count = 0
            for ns in range(n0, n1):
                _, _, ball = simulate_labelled(rig, motion, None, SimulationOptions(noise_px=0.3, seed=ns))
                fit = fit_trajectory(ball.best(), rig, SmoothOptions(max_gap_s=default_max_gap_s(rig)))
                sessions += len(fit.trajectory.breaks_s) > 0
                count += len(fit.trajectory.breaks_s)
            print(f"{rig.name} {name}: sessions with a break {sessions} / {n1 - n0}, breaks {count}", flush=True)


def rallies(n0, n1):
    for noise in (0.3, 1.0):
        for kind in ("rally", "rolling"):
            errs = []
            for rig in bd.rigs() + bd.more_rigs():
                for s in range(n0, n1):
                    m = rally_motion(s, 20.0) if kind == "rally" else rally_motion(s, 20.0, restitution=0.35, friction=0.6)
                    det, truth, _ = simulate_labelled(rig, m, 20.0, SimulationOptions(noise_px=noise, seed=s))
                    tr = fuse_detections(det, rig, ["smooth"], FusionOptions(), workers=1)[0]["smooth"]
                    e = errors_m(tr, truth)
                    errs.append(e[np.isfinite(e)])
            e = np.concatenate(errs) * 1e3
            print(f"{noise} px {kind}: points {len(e)} mean {e.mean():.4f} mm p95 {np.percentile(e, 95):.3f} max {e.max():.2f} >50 mm {np.sum(e > 50)}", flush=True)


if __name__ == "__main__":
    what = sys.argv[1]
    if what == "bench":
        sys.argv = ["benchmarks/bench_dirty.py", *sys.argv[2:]]
        runpy.run_path("benchmarks/bench_dirty.py", run_name="__main__")
    elif what == "falsebreaks":
        falsebreaks(int(sys.argv[2]), int(sys.argv[3]))
    elif what == "rallies":
        rallies(int(sys.argv[2]), int(sys.argv[3]))
    else:
        rigname, label, first = sys.argv[2], sys.argv[3], int(sys.argv[4])
        rest = sys.argv[5:]
        if what == "decompose":
            b29.decompose(rigname, label, first, int(rest[0]) if rest else None)
        elif what == "draws":
            b29.draws(rigname, label, first, int(rest[0]), int(rest[1]))
        elif what == "breaks":
            breaks(rigname, label, first, int(rest[0]) if rest else None)
        else:
            b29.oracle(rigname, label, first, [int(x) for x in rest[0].split(",")] if rest else None)
