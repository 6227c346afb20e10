# ruff: noqa: E501
"""Issue 10 (session 36, measured, not built): type A's points beyond 5 cm under the default
offline kick test, against ``smooth``'s fit of the same observations. Would withholding the
type A points whose construction spans a break that fit found (a break in ``(t - span_s, t]``)
remove the far ones, and at what cost in good points; how far is each far point from the fit's
position (distance, and Mahalanobis d² under both covariances); what the ``std_m`` bound
25.5 mm (``--type-a-max-std-mm``) would withhold. bench_dirty ``--more``'s rigs and sessions,
clean and with the faults, 0.3 px.

    PYTHONPATH=. python benchmarks/session36/typea_breaks.py FIRST [FPS] [MISSES]
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.estimation import SmoothOptions, fit_trajectory  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, offline_confirmation, type_a_prepared  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.records import Observations  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

_COV = ("xx", "xy", "xz"), ("xy", "yy", "yz"), ("xz", "yz", "zz")


def _breaks_ns(det, rig, opt) -> np.ndarray:
    """The velocity breaks (ns) of smooth's fit of type A's observations (the gate's doubt out)."""
    _, prep = type_a_prepared(det, rig, opt)
    o = prep.obs
    if prep.doubt_px2 is not None:
        k = ~(prep.doubt_px2 > 0)
        o = Observations(o.time_ns[k], o.camera[k], o.uv[k], o.frame_index[k])
    fit = fit_trajectory(o, rig, SmoothOptions(max_gap_s=default_max_gap_s(rig)))
    return fit.trajectory, fit.trajectory.t0_ns + np.round(fit.trajectory.breaks_s * 1e9).astype(np.int64)


def main():
    first = int(sys.argv[1])
    fps = float(sys.argv[2]) if len(sys.argv) > 2 else None
    misses = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    opt = offline_confirmation(FusionOptions())  # pslog fuse's: the kick test on
    tot = dict.fromkeys(("points", "far", "far_spanning", "good_spanning", "far_std", "good_std",
                         "good_std_start"), 0)
    m2_far, d_far, err_all, err_kept, err_spanning = [], [], [], [], []
    for rig in rigs() + more_rigs():
        rig = rig if fps is None else at_rate(rig, fps)
        for seed, (_label, motion, duration, _k) in enumerate(more_sessions(3, 8.0, first), start=first - 300):
            span = motion.duration if duration is None else duration
            for extra in ({}, faults(rig, seed, span)):
                det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                    noise_px=0.3, seed=seed, miss_rate=misses, **extra))
                tr = fuse_detections(det, rig, ["typeA"], opt, workers=1)[0]["typeA"]
                trajectory, b_ns = _breaks_ns(det, rig, opt)
                err = errors_m(tr, truth)
                ok = np.isfinite(err)
                far = ok & (err > 0.05)
                t = tr.time_ns
                sp = np.round(tr.quality["span_s"] * 1e9).astype(np.int64)
                spanning = np.searchsorted(b_ns, t, side="right") > np.searchsorted(b_ns, t - sp, side="right")
                big = tr.quality["std_m"] > 0.05 / 1.96
                q = tr.quality
                cov_a = np.stack([np.stack([q[f"cov_{a}_m2"] for a in row], -1) for row in _COV], 1)
                p_s, cov_s = trajectory.evaluate(t)
                d = tr.position_world - p_s
                fin = np.all(np.isfinite(d), axis=1)
                m2 = np.full(len(t), np.nan)
                m2[fin] = np.einsum("ni,ni->n", d[fin], np.linalg.solve(cov_a[fin] + cov_s[fin], d[fin][..., None])[..., 0])
                tot["points"] += int(ok.sum())
                tot["far"] += int(far.sum())
                tot["far_spanning"] += int((far & spanning).sum())
                tot["good_spanning"] += int((ok & ~far & spanning).sum())
                tot["far_std"] += int((far & big).sum())
                tot["good_std"] += int((ok & ~far & big).sum())
                tot["good_std_start"] += int((ok & ~far & big & (t < t[0] + 300_000_000)).sum())
                m2_far.append(m2[far])
                d_far.append(np.linalg.norm(d[far], axis=1))
                err_all.append(err[ok])
                err_kept.append(err[ok & ~spanning])
                err_spanning.append(err[ok & spanning])
    print(tot)
    ea, ek, es = (np.concatenate(x) for x in (err_all, err_kept, err_spanning))
    print(f"mean error all {ea.mean() * 1e3:.3f} mm; without the spanning points {ek.mean() * 1e3:.3f}; "
          f"the spanning points: mean {es.mean() * 1e3:.2f}, median {np.median(es) * 1e3:.2f}, "
          f"within 10 mm {np.mean(es < 0.01):.2f}")
    print("far points: Mahalanobis d² to smooth's position", np.round(np.concatenate(m2_far), 1),
          "distance mm", np.round(np.concatenate(d_far) * 1e3))


if __name__ == "__main__":
    main()
