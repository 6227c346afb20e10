# ruff: noqa: E501
"""Issue 10 (session 37): type A's points spanning a break of smooth's fit, replaced by the
backward pass's point on the same detection. Offline, for a type A point (the default kick
test on) whose construction spans a velocity break of ``smooth``'s fit of the same
observations (a break in ``(t - span_s, t]``), take type A's point on the same detection made
from the time-reversed observations (the paper's equations in reversed time, its own
covariance, the same offline confirmation) when that construction spans no break (none in
``[t, t + span_b)``), and withhold the point when both span one. Points spanning no break stay
the paper's. Printed per run (bench_dirty ``--more``'s five rigs, 3 rallies, the library's
rally, ``straight``, ``turntable``; 0.3 px; clean and with the faults, as
``benchmarks/session36/typea_breaks.py``): far points (> 5 cm) before -> after, good points
(<= 5 cm) withheld, good points replaced by a far one, mean error, the NEES (d^T Sigma^-1 d / 3)
of the replaced points under the backward covariance (and of the forward points there), and
the CPU of smooth's fit and the backward pass per 10 minutes of session.
Variants: ``bwd`` the rule; ``keep`` the same but the forward point kept where both span;
``drop`` every spanning point withheld (session 36).

    PYTHONPATH=. python benchmarks/session37/sides_backward.py FIRST [FPS] [MISSES] [--causal-bwd]
"""
from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

_ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(_ROOT / "benchmarks"))
sys.path.insert(0, str(_ROOT / "tests"))
from bench_dirty import at_rate, faults, more_rigs, more_sessions, rigs  # noqa: E402

from pslog.estimation import SmoothOptions, fit_trajectory  # noqa: E402
from pslog.evaluation import errors_m  # noqa: E402
from pslog.fusion import FusionOptions, _type_a, offline_confirmation, prepare, type_a_prepared  # noqa: E402
from pslog.fusion._prepare import default_max_gap_s  # noqa: E402
from pslog.fusion.gating import fuse_detections  # noqa: E402
from pslog.records import Observations  # noqa: E402
from pslog.simulation import SimulationOptions, simulate_labelled  # noqa: E402

_COV = ("xx", "xy", "xz"), ("xy", "yy", "yz"), ("xz", "yz", "zz")


def cov_of(q, rows):
    return np.stack([np.stack([q[f"cov_{a}_m2"][rows] for a in row], -1) for row in _COV], 1)


def breaks_ns(prep, rig):
    o = prep.obs
    if prep.doubt_px2 is not None:
        k = ~(prep.doubt_px2 > 0)
        o = Observations(o.time_ns[k], o.camera[k], o.uv[k], o.frame_index[k])
    fit = fit_trajectory(o, rig, SmoothOptions(max_gap_s=default_max_gap_s(rig)))
    tr = fit.trajectory
    return tr.t0_ns + np.round(tr.breaks_s * 1e9).astype(np.int64)


def reversed_prep(prep, rig):
    """The prepared observations in reversed time (``t0 - t``), doubt carried along."""
    o = prep.obs
    t0 = int(o.time_ns.min() + o.time_ns.max())
    t = t0 - o.time_ns
    order = np.lexsort((o.camera, t))
    rp = prepare(Observations(t[order], o.camera[order], o.uv[order], o.frame_index[order]), rig)
    if prep.doubt_px2 is not None:
        rp = replace(rp, doubt_px2=prep.doubt_px2[order])
    return rp, t0


def nees(d, cov):
    fin = np.all(np.isfinite(d), axis=1) & np.all(np.isfinite(cov), axis=(1, 2))
    return np.einsum("ni,ni->n", d[fin], np.linalg.solve(cov[fin], d[fin][..., None])[..., 0]) / 3


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    causal_bwd = "--causal-bwd" in sys.argv
    first = int(args[0])
    fps = float(args[1]) if len(args) > 1 and args[1] != "-" else None
    misses = float(args[2]) if len(args) > 2 else 0.0
    opt = offline_confirmation(FusionOptions())  # pslog fuse's: the kick test on
    checked = False
    for kind in ("clean", "faults"):
        tot = dict.fromkeys(("points", "far", "spanning", "replaced", "withheld", "bwd_missing",
                             "far_bwd", "far_keep", "far_drop", "good_withheld", "good_to_far",
                             "good_withheld_keep", "good_withheld_drop", "far_fixed", "good_moved_2cm"), 0)
        e_before, e_bwd, e_keep, e_drop = [], [], [], []
        nees_b, nees_f, nees_all = [], [], []
        far_detail = []
        cpu_fit = cpu_bwd = cpu_fwd = span_s = 0.0
        for base in rigs() + more_rigs():
            rig = base if fps is None else at_rate(base, fps)
            gap = default_max_gap_s(rig)
            optg = replace(opt, max_gap_s=gap)
            for seed, (label, motion, duration, _k) in enumerate(more_sessions(3, 8.0, first), start=first - 300):
                span = motion.duration if duration is None else duration
                extra = {} if kind == "clean" else faults(rig, seed, span)
                det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(
                    noise_px=0.3, seed=seed, miss_rate=misses, **extra))
                _, prep = type_a_prepared(det, rig, opt)
                c0 = time.process_time()
                fwd = _type_a(prep, rig, optg)
                c1 = time.process_time()
                if not checked:  # the forward track is pslog fuse's, bit for bit
                    ref = fuse_detections(det, rig, ["typeA"], opt, workers=1)[0]["typeA"]
                    assert np.array_equal(ref.position_world, fwd.position_world) and np.array_equal(ref.time_ns, fwd.time_ns)
                    checked = True
                b = breaks_ns(prep, rig)
                c2 = time.process_time()
                rp, t0 = reversed_prep(prep, rig)
                bwd = _type_a(rp, rig, optg if not causal_bwd else replace(optg, confirm_every=False, confirm_sides=False))
                c3 = time.process_time()
                cpu_fwd += c1 - c0
                cpu_fit += c2 - c1
                cpu_bwd += c3 - c2
                span_s += (prep.obs.time_ns.max() - prep.obs.time_ns.min()) / 1e9
                t = fwd.time_ns
                sp = np.round(fwd.quality["span_s"] * 1e9).astype(np.int64)
                spanning = np.searchsorted(b, t, side="right") > np.searchsorted(b, t - sp, side="right")
                tb = t0 - bwd.time_ns  # forward time of each backward point
                spb = np.round(bwd.quality["span_s"] * 1e9).astype(np.int64)
                spanning_b = np.searchsorted(b, tb + spb, side="left") > np.searchsorted(b, tb, side="left")
                kb = dict(zip((tb * 256 + bwd.camera).tolist(), range(len(bwd)), strict=True))
                idx = np.array([kb.get(k, -1) for k in (t * 256 + fwd.camera).tolist()], dtype=np.int64)
                has = idx >= 0
                bi = np.where(has, idx, 0)
                b_ok = has & ~spanning_b[bi] if len(bwd) else np.zeros(len(t), bool)
                replaced = spanning & b_ok
                withheld = spanning & ~b_ok
                err = errors_m(fwd, truth)
                pos_b = np.where(has[:, None], bwd.position_world[bi] if len(bwd) else np.nan, np.nan)
                off_b = pos_b - truth.at(t)
                err_b = np.linalg.norm(off_b, axis=1)
                ok = np.isfinite(err)
                far = ok & (err > 0.05)
                good = ok & ~far
                new = np.where(replaced, err_b, err)
                new_ok = ok & ~withheld
                tot["points"] += int(ok.sum())
                tot["far"] += int(far.sum())
                tot["spanning"] += int((ok & spanning).sum())
                tot["replaced"] += int((ok & replaced).sum())
                tot["withheld"] += int((ok & withheld).sum())
                tot["bwd_missing"] += int((ok & spanning & ~has).sum())
                tot["far_bwd"] += int((new_ok & (new > 0.05)).sum())
                keep_new = np.where(replaced, err_b, err)
                tot["far_keep"] += int((ok & (keep_new > 0.05)).sum())
                tot["far_drop"] += int((far & ~spanning).sum())
                tot["good_withheld"] += int((good & withheld).sum())
                tot["good_to_far"] += int((good & replaced & (err_b > 0.05)).sum())
                tot["far_fixed"] += int((far & replaced & (err_b <= 0.05)).sum())
                tot["good_moved_2cm"] += int((good & replaced & (err_b > err + 0.02)).sum())
                tot["good_withheld_drop"] += int((good & spanning).sum())
                e_before.append(err[ok])
                e_bwd.append(new[new_ok])
                e_keep.append(keep_new[ok])
                e_drop.append(err[ok & ~spanning])
                r = np.flatnonzero(ok & replaced)
                if len(r):
                    nees_b.append(nees(off_b[r], cov_of(bwd.quality, bi[r])))
                    nees_f.append(nees((fwd.position_world - truth.at(t))[r], cov_of(fwd.quality, r)))
                rr = np.flatnonzero(ok & ~spanning)
                nees_all.append(nees((fwd.position_world - truth.at(t))[rr], cov_of(fwd.quality, rr)))
                for i in np.flatnonzero(far):
                    how = "replaced" if replaced[i] else "withheld" if withheld[i] else "kept (no break)"
                    far_detail.append(f"  {rig.name} {label}: t {(t[i] - t[0]) / 1e9:.3f} s err {err[i] * 1e3:.0f} mm std {fwd.quality['std_m'][i] * 1e3:.0f} -> {how}"
                                      + (f", bwd err {err_b[i] * 1e3:.0f} mm std {bwd.quality['std_m'][bi[i]] * 1e3:.0f}" if has[i] else ", no bwd point"))
        eb, en, ek, ed = (np.concatenate(x) for x in (e_before, e_bwd, e_keep, e_drop))
        print(f"== first {first} fps {fps or 'rig'} misses {misses} {kind}{' (causal bwd)' if causal_bwd else ''}")
        print("  ", tot)
        print(f"   far: paper(kicks) {tot['far']} -> rule {tot['far_bwd']} (keep {tot['far_keep']}, drop {tot['far_drop']}); "
              f"good withheld: rule {tot['good_withheld']} (drop {tot['good_withheld_drop']}); good replaced by a far one {tot['good_to_far']}")
        print(f"   mean mm: {eb.mean() * 1e3:.3f} -> rule {en.mean() * 1e3:.3f} (keep {ek.mean() * 1e3:.3f}, drop {ed.mean() * 1e3:.3f}); points {len(eb)} -> {len(en)}")
        if nees_b:
            nb, nf, na = (np.concatenate(x) for x in (nees_b, nees_f, nees_all))
            print(f"   NEES replaced ({len(nb)}): backward mean {nb.mean():.2f} median {np.median(nb):.2f} within chi2_3 95% {np.mean(3 * nb < 7.815):.3f}; "
                  f"forward there mean {nf.mean():.2f} median {np.median(nf):.2f}; forward not spanning mean {na.mean():.2f} (95%: {np.mean(3 * na < 7.815):.3f})")
        print(f"   CPU per 10 min of session: type A fwd {cpu_fwd / span_s * 600:.3f} s, smooth fit {cpu_fit / span_s * 600:.3f} s, backward (prepare + type A) {cpu_bwd / span_s * 600:.3f} s")
        print("\n".join(far_detail))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
