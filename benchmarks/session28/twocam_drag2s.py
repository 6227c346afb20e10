# ruff: noqa: E501
"""Issue 10 (session 28, twocam): a prototype, outside the kernel, of the drag estimated by
Friedland's two-stage (separate-bias) filter beside the filter (docs/methods.md, "Two
cameras at 30 fps: what separates the sessions above ½"). Each session is fused as ``pslog
fuse`` does to capture the filter's observations (and doubt), which are pushed one at a time
into a ``BallFilter`` (the batch filter's points); around each push the prior (``_predict``,
the kernel's), the pixel variance and ``μ`` are read, and beside it run

    V⁻ = F V − c ‖v⁻‖ (v⁻ Δt²/2, v⁻ Δt)          (sensitivity of the state to k)
    z  = J V⁻_p,  I_k += zᵀ S⁻¹ z,  δk += zᵀ S⁻¹ (y − z δk) / I_k
    V  = V⁻ − K z                                   (accepted, no jump; 0 at a jump/start)

with ``y = z_px − h(x⁻)``, ``S = J P⁻_pp Jᵀ + σ² I``, ``K = P⁻ Hᵀ S⁻¹``; the point published
is ``p + V_p δk``. ``δk`` starts at 0 with information ``1/σ_k²`` and is kept for the whole
session. Prints filter/typeA with and without the correction, the final ``k₀ + δk``, and
NEES of the points with the filter's published covariance, then widened by ``V_p V_pᵀ / I_k``
(sessions run at the batch filter's own options only).

    PYTHONPATH=. python benchmarks/session28/twocam_drag2s.py --first-seeds 9600 [--sigma-k 0.01]
"""
import argparse
import dataclasses
import sys

import numpy as np

sys.path.insert(0, "benchmarks/session28")
from twocam_per import bd, rig_of

import pslog.fusion as pf
from pslog.evaluation import covariances, errors_m
from pslog.fusion import FusionOptions
from pslog.fusion import filter as FM
from pslog.fusion.filter import BallFilter, FilterOptions
from pslog.fusion.gating import fuse_detections
from pslog.simulation import SimulationOptions, simulate_labelled


def jacobian(camera, p: np.ndarray) -> np.ndarray:
    J = np.empty((2, 3))
    for a in range(3):
        d = np.zeros(3)
        d[a] = 1e-6
        J[:, a] = (camera.project((p + d)[None])[0][0] - camera.project((p - d)[None])[0][0]) / 2e-6
    return J


def run(rig, obs, doubt, sigma_k: float, opts: FilterOptions):
    keep = ~(np.asarray(doubt) > 0) if doubt is not None else np.ones(len(obs.time_ns), bool)
    times, cams, uv = obs.time_ns[keep], obs.camera[keep], obs.uv[keep]
    flt = BallFilter(rig, opts)
    V = np.zeros(6)
    dk, info = 0.0, 1.0 / sigma_k ** 2
    out_t, raw, corr, widen = [], [], [], []
    for t, c, (u, v) in zip(times.tolist(), cams.tolist(), uv.tolist(), strict=True):
        had = flt.time_ns is not None
        if had:
            t0 = flt.time_ns
            xm, Pm = FM._predict(flt._S, flt._I, flt._opts, int(t))
            Pm = Pm.reshape(6, 6)
            var, mu, nu = flt._var, flt._mu, flt._nu
            dt = (t - t0) / 1e9
        res = flt.push(int(t), int(c), float(u), float(v))
        if not had or not flt._I[FM._IHAS]:
            V[:] = 0.0
        elif flt._I[FM._IJUMPNS] == t or nu:
            V[:] = 0.0  # a jump (or the turn model in the set): a new segment
        elif flt.time_ns == t and dt > 0:  # accepted
            p_sw = min(opts.model_switch_per_s * abs(dt), 0.5)
            cw = mu * (1 - p_sw) + (1 - mu) * p_sw
            vel = xm[3:]
            Vm = np.r_[V[:3] + dt * V[3:], V[3:]] - cw * np.linalg.norm(vel) * np.r_[vel * dt * dt / 2, vel * dt]
            camera = rig.cameras[int(c)]
            J = jacobian(camera, xm[:3])
            y = np.array([u, v]) - camera.project(xm[:3][None])[0][0]
            Sm = J @ Pm[:3, :3] @ J.T + var * np.eye(2)
            Si = np.linalg.inv(Sm)
            K = Pm[:, :3] @ J.T @ Si
            z = J @ Vm[:3]
            info += z @ Si @ z
            dk += (z @ Si @ (y - z * dk)) / info
            V = Vm - K @ z
        if res is not None:
            out_t.append(t)
            raw.append(res[0])
            corr.append(np.asarray(res[0]) + V[:3] * dk)
            widen.append(np.outer(V[:3], V[:3]) / info)
    return np.array(out_t, dtype=np.int64), np.array(raw), np.array(corr), dk, np.array(widen)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--first-seeds", default="9600")
    ap.add_argument("--rigs", default="paper2")
    ap.add_argument("--fps", default="30")
    ap.add_argument("--noise", type=float, default=0.3)
    ap.add_argument("--sigma-k", type=float, default=0.01)
    ap.add_argument("--options", default="", help="FilterOptions, key=value;...")
    ap.add_argument("--dirty", action="store_true", help="bench_dirty's faults")
    a = ap.parse_args()
    over = {}
    for kv in filter(None, a.options.split(";")):
        key, value = kv.split("=")
        number = eval(value, {})  # a number, or True/False for a switch (kept a bool)
        over[key] = number if isinstance(number, bool) else float(number)
    opts = FilterOptions(max_gap_s=FusionOptions().max_gap_s, **over)
    orig = pf.METHODS["filter"]
    captured = {}

    def _capture(prep, rig_, options):
        captured["obs"], captured["doubt"] = prep.obs, prep.doubt_px2
        return orig.function(prep, rig_, options)

    ratios = {"raw": [], "corr": []}
    d2s = {"raw": [], "corr": [], "corr, widened": []}
    pf.METHODS["filter"] = dataclasses.replace(orig, function=_capture)
    try:
        for rig_spec in a.rigs.split(","):
            for fps in [float(f) for f in a.fps.split(",")]:
                rig = rig_of(rig_spec, fps)
                for fs in [int(x) for x in a.first_seeds.split(",")]:
                    for seed, (label, motion, duration, _) in enumerate(bd.more_sessions(2, 8.0, fs), start=fs - 300):
                        extra = bd.faults(rig, seed, motion.duration if duration is None else duration) if a.dirty else {}
                        det, truth, _ = simulate_labelled(rig, motion, duration, SimulationOptions(noise_px=a.noise, seed=seed, **extra))
                        tr = fuse_detections(det, rig, ["typeA", "filter"], FusionOptions())[0]
                        mA = np.nanmean(errors_m(tr["typeA"], truth))
                        t, raw, corr, dk, widen = run(rig, captured["obs"], captured["doubt"], a.sigma_k, opts)
                        P = truth.at(t)
                        eR, eC = np.linalg.norm(raw - P, axis=1), np.linalg.norm(corr - P, axis=1)
                        same = len(t) == len(tr["filter"]) and np.allclose(raw, tr["filter"].position_world)
                        ratios["raw"].append(np.nanmean(eR) / mA)
                        if same:
                            C = covariances(tr["filter"])
                            for name, off, cov in (("raw", raw - P, C), ("corr", corr - P, C), ("corr, widened", corr - P, C + widen)):
                                ok = np.all(np.isfinite(off), axis=1)
                                d2s[name].append(np.einsum("ni,ni->n", off[ok], np.linalg.solve(cov[ok], off[ok][..., None])[..., 0]))
                        ratios["corr"].append(np.nanmean(eC) / mA)
                        print(f"{rig_spec:9s} {fs} {label:14s} filter/typeA {ratios['raw'][-1]:.3f} -> {ratios['corr'][-1]:.3f}"
                              f"  k {opts.drag_per_m + dk:.4f} /m  (points as the batch filter's: {same})", flush=True)
    finally:
        pf.METHODS["filter"] = orig
    for name, r in ratios.items():
        r = np.array(r)
        print(f"{name:5s}: n {len(r)} gmean {np.exp(np.mean(np.log(r))):.3f} max {r.max():.3f} above 1/2 {int(np.sum(r > .5))}")
    for name, d in d2s.items():
        if d:
            d = np.concatenate(d)
            print(f"NEES {name}: {d.mean() / 3:.3f}, share in 2 sigma {100 * np.mean(d <= 4):.1f} % ({len(d)} points of the sessions fused at the batch filter's options)")


if __name__ == "__main__":
    main()
