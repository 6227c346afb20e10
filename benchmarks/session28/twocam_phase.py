# ruff: noqa: E501
"""Issue 10 (session 28, twocam): from twocam_per.py's ``--dump`` (run with ``--smooth``),
what separates the sessions whose ``filter / typeA`` is above 1/2: per motion the geometric
means of filter/typeA, smooth/typeA, filter/smooth and their correlation, and per group
(above / below 1/2 under the first variant) the mean error by time since the truth's last
velocity jump (kick or bounce), typeA and every variant.

    python benchmarks/session28/twocam_phase.py out.pkl main,drag,step3
"""
import pickle
import sys

import numpy as np

BINS = np.array([0, .033, .067, .1, .15, .2, .3, .5, 1e9])


def since(t: np.ndarray, jumps: np.ndarray) -> np.ndarray:
    if len(jumps) == 0:
        return np.full(len(t), 1e6)
    k = np.searchsorted(jumps, t, side="right") - 1
    return np.where(k >= 0, t - jumps[np.clip(k, 0, None)], 1e6)


def gmean(x) -> float:
    return float(np.exp(np.mean(np.log(x))))


def main() -> None:
    with open(sys.argv[1], "rb") as fh:
        rows = pickle.load(fh)
    names = sys.argv[2].split(",")
    ref = names[0]
    kinds = {"tests' rallies": lambda r: r["label"].startswith("rally-"),
             "library rally": lambda r: r["label"].startswith("library"),
             "straight": lambda r: r["label"] == "straight",
             "turntable": lambda r: r["label"] == "turntable"}
    for kind, pred in kinds.items():
        sel = [r for r in rows if pred(r)]
        F = np.array([r[ref]["F"] / r["A"] for r in sel])
        line = f"{kind:15s} n {len(sel):2d} above {int(np.sum(F > .5)):2d} {ref}/A {gmean(F):.3f}"
        if "S" in sel[0]:
            S = np.array([r["S"] / r["A"] for r in sel])
            line += f" smooth/A {gmean(S):.3f} {ref}/smooth {gmean(F / S):.3f} corr({ref}/A, smooth/A) {np.corrcoef(F, S)[0, 1]:.2f}"
        for name in names[1:]:
            V = np.array([r[name]["F"] / r["A"] for r in sel])
            line += f" | {name} {gmean(V):.3f} ({int(np.sum(V > .5))})"
        print(line)
    print(f"\nmean error (mm) by time since the truth's last jump, ms: {' '.join(f'{1e3 * b:.0f}' for b in BINS[:-1])} (last: no jump in the session)")
    for kind, pred in kinds.items():
        for above in (True, False):
            sel = [r for r in rows if pred(r) and (r[ref]["F"] / r["A"] > .5) == above]
            if not sel:
                continue
            print(f"{kind} {'above' if above else 'below'} 1/2 (n {len(sel)})")
            series = {"typeA": [(r["tA"], r["eA"], r["jumps"]) for r in sel]}
            for name in names:
                series[name] = [(r[name]["t"], r[name]["e"], r["jumps"]) for r in sel]
            means = {}
            for name, parts in series.items():
                per = [[] for _ in range(len(BINS) - 1)]
                for t, e, jumps in parts:
                    ok = np.isfinite(e)
                    b = np.digitize(since(t[ok], jumps), BINS) - 1
                    b = np.minimum(b, len(BINS) - 2)
                    for j in range(len(BINS) - 1):
                        per[j].append(e[ok][b == j])
                means[name] = [np.concatenate(p) for p in per]
            for name, m in means.items():
                cells = " ".join(f"{1e3 * x.mean():5.2f}" if len(x) else "    -" for x in m)
                if name != "typeA":
                    cells += "  ratio " + " ".join(
                        f"{x.mean() / y.mean():.2f}" if len(x) and len(y) else "   -"
                        for x, y in zip(m, means["typeA"], strict=True))
                print(f"   {name:9s} {cells}")


if __name__ == "__main__":
    main()
