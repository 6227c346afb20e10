# ruff: noqa: E501
"""Issue 10 (session 36): ``smooth`` on ``paper3@60`` / ``lab3@60`` ``straight`` of
``bench_dirty.py --more --validity --first-seed 48000 --fps 60`` beyond the data's ratio.

``compare RIG LABEL FIRST [KIND ...]``: ``smooth`` on the session clean and with each fault
(``blackout``, ``object``, ``spurious``, ``faults``): the fit's knot spacing, breaks, σ; the
detections the gate gave the fit that differ from the clean session's (left out / added,
doubt), its rejections of the ball's own detections, and the largest per-point error changes
against the clean session (paired by detection time).

Run from the repository root (PYTHONPATH=.)."""
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session35")
sys.path.insert(0, "benchmarks")
sys.path.insert(0, "tests")
import smooth_straight as s35

import pslog.estimation as E
from pslog.evaluation import errors_m
from pslog.fusion import FusionOptions
from pslog.fusion.gating import REASONS, fuse_detections
from pslog.records import NS
from pslog.simulation import SimulationOptions, simulate_labelled

_fit = E.fit_trajectory
CAPTURED = {}


def _capturing(obs, rig, options=None, consider_px=None):
    fit = _fit(obs, rig, options, consider_px=consider_px)
    CAPTURED["obs"], CAPTURED["fit"] = obs, fit
    return fit


E.fit_trajectory = _capturing


def run(rig, motion, duration, seed, extra):
    det, truth, ball = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=0.3, seed=seed, **extra))
    tracks, rej = fuse_detections(det, rig, ["smooth"], FusionOptions(), workers=1)
    return tracks["smooth"], rej["smooth"], truth, ball, CAPTURED["obs"], CAPTURED["fit"]


def compare(rigname, label, first, kinds=("blackout", "object", "spurious", "faults")):
    rig, motion, duration, seed, f = s35.session(rigname, label, first)
    _, start, length = f["blackouts"][0]
    print(f"{rig.name} {label}, bench seed {seed}: {f}")
    extras = {"clean": {}, "faults": f, "blackout": {"blackouts": f["blackouts"]},
              "spurious": {"spurious_rate": 0.05}, "object": {"distractors": f["distractors"]},
              "blackout+object": {"blackouts": f["blackouts"], "distractors": f["distractors"]}}
    base = None
    for kind in ("clean", *kinds):
        tr, rej, truth, ball, obs, fit = run(rig, motion, duration, seed, extras[kind])
        e = errors_m(tr, truth)
        t = fit.trajectory
        print(f"\n{kind}: points {len(tr)}, mean {1e3 * np.nanmean(e):.3f} mm; h {t.spacing_s * 1e3:.2f} ms, breaks {np.round(t.breaks_s, 4).tolist()}, "
              f"σ {t.noise_px:.4f} px, fit rejected {int(fit.rejected.sum())} at {np.round(obs.time_ns[fit.rejected] / NS, 4).tolist()}, dropped {dict(tr.dropped)}")
        # the ball's own detections the gate rejected
        bt = ball.frame_time_ns[ball.cand_frame]
        bc = ball.frame_camera[ball.cand_frame]
        ball_keys = set(zip(bt.tolist(), bc.tolist(), strict=True))
        lost = [(rej.frame_time_ns[i] / NS, rig.names[rej.camera[i]], REASONS[rej.reason[i]], np.round(rej.uv[i], 1).tolist())
                for i in range(len(rej)) if (int(rej.frame_time_ns[i]), int(rej.camera[i])) in ball_keys]
        print(f"  gate rejections {len(rej)} {rej.counts()}; with the ball's frame: {[(round(a, 4), b, c, d) for a, b, c, d in lost][:12]}")
        if base is None:
            base = (tr, e)
            continue
        tr0, e0 = base
        common, i0, i1 = np.intersect1d(tr0.time_ns, tr.time_ns, return_indices=True)
        only0 = np.setdiff1d(tr0.time_ns, tr.time_ns)
        only1 = np.setdiff1d(tr.time_ns, tr0.time_ns)
        print(f"  clean's points missing {len(only0)}: {np.round(only0[:8] / NS, 4).tolist()}; new {np.round(only1[:8] / NS, 4).tolist()}")
        d = e[i1] - e0[i0]
        outside = (common / NS < start) | (common / NS > start + length)
        print(f"  outside the blackout: Δmean {1e3 * np.nanmean(d[outside]):.3f} mm over {outside.sum()}; largest:")
        for j in np.argsort(-np.abs(np.nan_to_num(d)))[:6]:
            print(f"    t {common[j] / NS:.4f} {rig.names[tr.camera[i1[j]]]} clean {1e3 * e0[i0[j]]:.2f} → {1e3 * e[i1[j]]:.2f} mm")
        # error by time bins
        tb = common / NS
        edges = np.arange(0, tb.max() + 0.1, 0.1)
        row = []
        for a in edges:
            m = (tb >= a) & (tb < a + 0.1)
            if m.any():
                row.append(f"{a:.1f}:{1e3 * np.nanmean(e0[i0][m]):.2f}/{1e3 * np.nanmean(e[i1][m]):.2f}")
        print("  per 0.1 s clean/this: " + " ".join(row))


if __name__ == "__main__":
    what = sys.argv[1]
    if what == "compare":
        kinds = sys.argv[5:] or ("blackout", "object", "spurious", "faults")
        compare(sys.argv[2], sys.argv[3], int(sys.argv[4]), kinds)


def _d2(trajectory, obs, rows, rig, with_cov=True):
    """The squared distances :func:`pslog.fusion.smooth._confirmed` compares with 18.42."""
    from pslog.estimation.projection import project_with_jacobian
    position, cov = trajectory.evaluate(obs.time_ns[rows])
    out = np.full(len(rows), np.nan)
    for i, row in enumerate(rows):
        if not np.all(np.isfinite(position[i])):
            continue
        uv, J = project_with_jacobian(rig.cameras[obs.camera[row]], position[i][None])
        S = (J[0] @ cov[i] @ J[0].T if with_cov else 0) + trajectory.noise_px ** 2 * np.eye(2)
        r = obs.uv[row] - uv[0]
        out[i] = r @ np.linalg.solve(S, r)
    return out


def doubts(rigname, label, first, kind="faults"):
    """Every choice in doubt ``smooth`` saw: time, camera, d² with and without the
    prediction's covariance, the pixel's distance from the truth's."""
    import pslog.fusion.smooth as S
    rig, motion, duration, seed, f = s35.session(rigname, label, first)
    extras = {"faults": f, "object": {"distractors": f["distractors"]}}
    orig = S._confirmed

    def shown(trajectory, obs, rows, rig_):
        d2 = _d2(trajectory, obs, rows, rig_)
        d2n = _d2(trajectory, obs, rows, rig_, with_cov=False)
        tt = obs.time_ns[rows]
        truth_uv = np.array([rig_.cameras[obs.camera[r]].project(motion.position(np.array([t / NS])))[0][0] for r, t in zip(rows, tt, strict=True)])
        for i, r in enumerate(rows):
            print(f"  doubt t {tt[i] / NS:.4f} {rig_.names[obs.camera[r]]}: d² {d2[i]:.2f} (without the prediction's covariance {d2n[i]:.2f}), "
                  f"{np.linalg.norm(obs.uv[r] - truth_uv[i]):.2f} px from the truth's pixel")
        return orig(trajectory, obs, rows, rig_)

    S._confirmed = shown
    try:
        run(rig, motion, duration, seed, extras[kind])
    finally:
        S._confirmed = orig


if __name__ == "__main__" and sys.argv[1] == "doubts":
    doubts(sys.argv[2], sys.argv[3], int(sys.argv[4]), *sys.argv[5:])
