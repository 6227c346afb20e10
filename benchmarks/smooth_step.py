"""One Gauss–Newton step's normal equations of ``smooth``, paired in one process: the three
passes a step made until session 28 (``linear_target``, ``data_terms``,
``points_normal_onto``) against the one pass that replaced them
(``_gauss_newton.linearised_normal_onto``), on the arguments of a real fit's first full step
(``bench_smooth``'s rally on the paper's three 30 fps cameras, 0.5 px, seed 1), inside the
fit's ``_memory.kept``, alternating, CPU best of ``--repeat`` each round; both outputs
checked equal bit for bit first.

    python benchmarks/smooth_step.py [--minutes 90] [--rounds 5] [--repeat 5] [--thread]

``--thread``: on a thread other than the main one (as ``pslog fuse`` runs ``smooth``).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, before numpy loads
os.environ["PSLOG_SMOOTH_THREADS"] = "1"

import argparse  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402


def _step_arguments(minutes: float) -> tuple:
    """The first full-size ``_Problem.linearised_normal`` call of a fit: first, N, J, X, r,
    w, m, the prior's band and rhs."""
    from smooth_stages import session  # (bench_smooth's session; this folder is on the path)

    from pslog.estimation import trajectory as T
    from pslog.fusion import fuse

    obs, true = session(minutes)
    saved: list = []
    original = T._Problem.linearised_normal

    def capture(self, J, X, r, w):
        if not saved and len(J) == len(obs):
            p = self.points
            saved.append((p.first.copy(), p.N.copy(), J.copy(), X.copy(), r.copy(),
                          np.array(w), p.m, self.prior_ab.copy(), self.prior_rhs.copy()))
        return original(self, J, X, r, w)

    T._Problem.linearised_normal = capture  # type: ignore[method-assign]
    try:
        fuse(obs, true, "smooth")
    finally:
        T._Problem.linearised_normal = original  # type: ignore[method-assign]
    return saved[0]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=90.0)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--thread", action="store_true",
                        help="time on a thread other than the main one")
    args = parser.parse_args()
    from pslog.estimation import _kernels
    from pslog.estimation._gauss_newton import linearised_normal_onto
    from pslog.estimation._memory import kept

    first, N, J, X, r, w, m, ab0, rhs0 = _step_arguments(args.minutes)

    def three():
        target = _kernels.linear_target(J, X, r)
        upper, v = _kernels.data_terms(J, target, w)
        return _kernels.points_normal_onto(first, N, upper, v, m, ab0, rhs0)

    def one():
        return linearised_normal_onto(first, N, J, X, r, w, m, ab0, rhs0)

    a, b = three(), one()
    if not all(np.array_equal(x.view(np.uint64), y.view(np.uint64))
               for x, y in zip(a, b, strict=True)):
        raise SystemExit("the one pass does not give the three passes' bits")
    del a, b
    best: dict[str, list[float]] = {"three passes": [], "one pass": []}

    def run() -> None:
        with kept():
            for _ in range(args.rounds):
                for name, fn in (("three passes", three), ("one pass", one)):
                    times = []
                    for _ in range(args.repeat):
                        start = time.thread_time()
                        out = fn()
                        times.append(time.thread_time() - start)
                        del out
                    best[name].append(min(times))

    if args.thread:
        worker = threading.Thread(target=run)
        worker.start()
        worker.join()
    else:
        run()
    load = os.getloadavg()[0]
    print(f"smooth's normal equations, one Gauss-Newton step, {len(first):,} detections "
          f"({args.minutes:g} min), thread CPU ms, best of {args.repeat} per round, "
          f"{args.rounds} rounds alternating{' on a second thread' if args.thread else ''}, "
          f"load {load:.1f}")
    for name, values in best.items():
        print(f"  {name:<13} " + " ".join(f"{1e3 * v:6.1f}" for v in values))
    ratios = [t / o for t, o in zip(best["three passes"], best["one pass"], strict=True)]
    print(f"  ratio three / one per round: {' '.join(f'{x:.2f}' for x in ratios)}; median "
          f"{float(np.median(ratios)):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
