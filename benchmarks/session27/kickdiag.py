# ruff: noqa: E501, B905
"""Issue 10 (session 27, kicknees): why the first points after a kick are overconfident.
Monte Carlo of a kick drawn from the filter's own prior (N(0, jump_speed² I)) at an instant
uniform over 0.1 s, 3 cameras (tests' lab rig), each detection pushed in turn; NEES (diagonal,
/3) by accepted point index from the jump's point, split by the jump's chosen lag and by
whether the kick lies in the step the jump was put on; variants by options."""
import sys

import numpy as np

sys.path.insert(0, "tests")
from test_filter import lab_rig

from pslog import NS, Motion
from pslog.fusion import filter as FM
from pslog.fusion.filter import BallFilter, FilterOptions
from pslog.motion import G
from pslog.simulation import SimulationOptions, simulate, true_rig
from pslog.timing import observations as corrected_observations


def kick_motion(tk, kick, p0=(0.8, 0.6, 0.9), v0=(2.0, 0.8, 2.5)):
    p0, v0 = np.array(p0), np.array(v0)
    g = np.array([0.0, 0.0, -G])
    pk = p0 + v0 * tk + 0.5 * g * tk ** 2
    v1 = v0 + g * tk + kick

    def position(times):
        t = np.asarray(times, float)[:, None]
        s = np.maximum(t - tk, 0.0)
        return np.where(t < tk, p0 + v0 * t + 0.5 * g * t * t, pk + v1 * s + 0.5 * g * s * s)
    return Motion("kicked", 0.9, position, "kick")


K = 8
ORACLE = {"on": False, "tk": 0.0, "td": 0.0}
_jumped0 = FM._jumped
_replay0 = FM._replay


def _jumped_exact(x, P, dt, O, shape):
    """The jump with its instant known (diagnostic): Δp = Δv s, s = t_d - t_k exactly
    (its variance σ² s², cross σ² s, instead of Δt²/3, Δt/2), when the kick is in the step."""
    if not ORACLE["on"]:
        return _jumped0(x, P, dt, O, shape)
    s = ORACLE["td"] - ORACLE["tk"]
    if not 0.0 <= s <= dt or O[FM._OSHAPES + 4 * shape] != 0.0:
        return _jumped0(x, P, dt, O, shape)
    x = x.copy()
    P = P.copy()
    base = FM._OSHAPES + 4 * shape
    for i in range(3):
        jv = O[base + 1 + i]
        P[7 * i] += jv * s * s
        P[6 * i + 3 + i] += jv * s
        P[6 * (i + 3) + i] += jv * s
        P[7 * (i + 3)] += jv
    return True, x, P


def _replay_exact(S, I, cams, O, t, cam, u, v, lag, shape):
    n = I[FM._IHN]
    ORACLE["td"] = (t if lag == 0 else I[FM._IHT + 3 * (n - lag) + 1]) / NS
    return _replay0(S, I, cams, O, t, cam, u, v, lag, shape)


FM._jumped = _jumped_exact
FM._replay = _replay_exact
_jump0 = FM._jump


def _jump_mse(S, I, cams, O, t, cam, u, v):
    """Diagnostic: the winner's state with the covariance of the hypotheses' mixture about
    the winner's mean, P* = Σ w_k (P_k + (x_k - x*)(x_k - x*)ᵀ), w_k ∝ exp(-score_k/2) over
    every (lag, shape) that passed (the same detections scored)."""
    ok, x, P, inn = _jump0(S, I, cams, O, t, cam, u, v)
    if not ok or not ORACLE.get("mse"):
        return ok, x, P, inn
    n_lags = min(I[FM._IHN] if I[FM._IHN] else 0, FM._JUMP_LAG) + 1
    # _jump0 has reset I[_IHN] to 0: the history count is kept before the call (below)
    n_lags = ORACLE["n_lags"]
    hyps = []
    for lag in range(n_lags):
        for shape in range(int(O[FM._ONSHAPES])):
            passed, xk, Pk, _, score, _, _, _ = _replay0(S, I_before[0], cams, O, t, cam, u, v,
                                                       lag, shape)
            if passed:
                hyps.append((score, xk, Pk))
    if len(hyps) < 2:
        return ok, x, P, inn
    sc = np.array([h[0] for h in hyps])
    w = np.exp(-(sc - sc.min()) / 2)
    w /= w.sum()
    Pm = np.zeros((6, 6))
    for wk, (_, xk, Pk) in zip(w, hyps):
        d = xk - x
        Pm += wk * (Pk.reshape(6, 6) + np.outer(d, d))
    return ok, x, Pm.ravel(), inn


I_before = [None]


def _jump_wrap(S, I, cams, O, t, cam, u, v):
    I_before[0] = I.copy()
    ORACLE["n_lags"] = min(I[FM._IHN], FM._JUMP_LAG) + 1
    return _jump_mse(S, I, cams, O, t, cam, u, v)


FM._jump = _jump_wrap


def run(variants, N, ncam=3, noise=0.3, fps=30.0, seed0=0):
    rng = np.random.default_rng(1)
    rig = lab_rig(ncam, fps)
    res = {name: [] for name in variants}
    for trial in range(N):
        tk = 0.5 + rng.uniform(0, 0.1)
        kick = rng.normal(0, 6.0, 3)
        motion = kick_motion(tk, kick)
        opts = SimulationOptions(noise_px=noise, seed=seed0 + trial)
        det, truth = simulate(rig, motion, None, opts)
        obs = corrected_observations(det, true_rig(rig, opts))
        ORACLE["tk"] = tk
        ORACLE["kick"] = kick
        for name, fo in variants.items():
            ORACLE["on"] = name.startswith("oracle")
            ORACLE["mse"] = name.startswith("mixture")
            flt = BallFilter(rig, fo)
            rows = []
            for i in range(len(obs.time_ns)):
                t = int(obs.time_ns[i])
                r = flt.push(t, int(obs.camera[i]), float(obs.uv[i, 0]), float(obs.uv[i, 1]))
                if r is None:
                    continue
                (p, q) = r
                I, S = flt._I, flt._S
                rows.append((t, p, q, int(q[8]), int(I[FM._IJN]), int(I[FM._IJT0]),
                             int(I[FM._IJBUF]), float(S[FM._SQ]), float(S[FM._SVAR]),
                             int(obs.camera[i]), int(I[FM._IJSHAPE])))
            times = np.array([r[0] for r in rows])
            pos = np.array([r[1] for r in rows])
            sd = np.array([r[2][1:4] for r in rows])
            X = truth.at(times)
            d2 = np.sum((pos - X) ** 2 / sd ** 2, axis=1)
            jumps = [i for i, r in enumerate(rows) if r[3] and r[0] / NS > tk - 0.05]
            after = np.flatnonzero(times / NS > tk)
            first = int(after[0]) if len(after) else -1
            if not jumps:
                res[name].append(dict(found=False, first=first, d2_kick=d2[first:first + K]))
                continue
            j = jumps[0]
            lag = rows[j][4] - 1
            cam = rig.cameras[rows[j][9]]
            centre = -cam.R.T @ np.asarray(cam.t).ravel()
            ray = X[j] - centre
            ray /= np.linalg.norm(ray)
            e = pos[j] - X[j]
            e_ray = float(e @ ray)
            t0, t1 = rows[j][5] / NS, rows[j][6] / NS
            if t1 <= t0:  # no buffer (jump_instant off): taken as lag 0
                lag, t0, t1 = -1, rows[j - 1][0] / NS, rows[j][0] / NS
            res[name].append(dict(
                found=True, j=j, first=first, lag=lag, instep=(t0 < tk <= t1), early=tk <= t0,
                late=tk > t1, step=t1 - t0, s=(tk - t0) / (t1 - t0),
                d2=d2[j:j + K], d2_kick=d2[first:first + K], q=[r[7] for r in rows[j - 1:j + K]],
                var=[r[8] for r in rows[j - 1:j + K]], kick=kick, n_before=j - first,
                shape=rows[j][10] if lag >= 0 else -1, e_ray=e_ray, e_across=float(np.linalg.norm(e - e_ray * ray)),
                std_ray=float(np.sqrt(np.sum((sd[j] * ray) ** 2)))))
    return res


def nees(list_of_d2):
    m = max((len(x) for x in list_of_d2), default=0)
    out = []
    for k in range(min(m, K)):
        v = np.array([x[k] for x in list_of_d2 if len(x) > k])
        out.append(v)
    return out


def report(res):
    for name, rs in res.items():
        found = [r for r in rs if r["found"]]
        print(f"== {name}: trials {len(rs)}, jump found {len(found)}")
        groups = {"all": found,
                  "kick in the jump's step": [r for r in found if r["instep"]],
                  "kick before the step (early)": [r for r in found if r["early"]],
                  "kick after the step": [r for r in found if r["late"]]}
        for sh in range(-1, 3):
            groups[f"shape {sh}"] = [r for r in found if r["shape"] == sh]
        for lag in range(-1, 3):
            groups[f"lag {lag}"] = [r for r in found if r["lag"] == lag]
        for g, rr in groups.items():
            if not rr:
                continue
            ks = nees([r["d2"] for r in rr])
            print(f"  {g:32s} n={len(rr):4d} NEES " + " ".join(f"{np.mean(v)/3:5.2f}" for v in ks)
                  + " | med d²/3 " + " ".join(f"{np.median(v)/3:4.2f}" for v in ks[:4])
                  + " | 2σ% " + " ".join(f"{100*np.mean(v <= 4):3.0f}" for v in ks[:4]))
        ks = nees([r["d2_kick"] for r in rs])
        print("  by index from the first point after the kick: NEES "
              + " ".join(f"{np.mean(v)/3:5.2f}" for v in ks))
        ins = [r for r in found if r["instep"]]
        if ins:
            f = np.array([1 - r["s"] for r in ins])  # the kick's displacement factor (td - tk)/Δt
            d0 = np.array([r["d2"][0] for r in ins]) / 3
            for lo, hi in ((0, .25), (.25, .5), (.5, .75), (.75, 1.01)):
                sel = (f >= lo) & (f < hi)
                if sel.any():
                    print(f"    kick in step, (t_d - t_k)/Δt in [{lo:.2f},{hi:.2f}): n={sel.sum():3d}"
                          f" NEES at the jump's point {d0[sel].mean():5.2f}")
            er = np.array([r["e_ray"] for r in ins])
            ea = np.array([r["e_across"] for r in ins])
            print(f"    at the jump's point: RMS error along its ray {1e3*np.sqrt(np.mean(er**2)):.1f} mm,"
                  f" across {1e3*np.sqrt(np.mean(ea**2)):.2f} mm")
        nb = np.array([r["n_before"] for r in found])
        print("  points between the kick and the jump's point:", np.bincount(nb[nb >= 0]))


if __name__ == "__main__":
    N = int(sys.argv[1]) if len(sys.argv) > 1 else 100
    base = dict(withhold=False, max_std_m=None)
    which = sys.argv[2].split(",") if len(sys.argv) > 2 else ["main"]
    allv = {
        "main": FilterOptions(**base),
        "no drag (the truth's)": FilterOptions(**base, drag_per_m=0.0),
        "noise 0.3 fixed": FilterOptions(**base, drag_per_m=0.0, noise_px=0.3, adapt_rate=0.0),
        "q fixed": FilterOptions(**base, drag_per_m=0.0, accel_adapt_rate=0.0),
        "kick shape only": FilterOptions(**base, drag_per_m=0.0, bounce_shape=False),
        "mixture covariance about the winner": FilterOptions(**base, jump_mixture_cov=False),
        "before (jump_mixture_cov=False)": FilterOptions(**base, jump_mixture_cov=False),
        "oracle instant": FilterOptions(**base, drag_per_m=0.0, jump_instant=False),
        "oracle instant + kick shape only": FilterOptions(**base, drag_per_m=0.0,
                                                          bounce_shape=False, jump_instant=False),
    }
    report(run({k: allv[k] for k in which}, N))
