"""Where ``smooth``'s fit spends its time, stage by stage: CPU time of this thread around
each step of ``fit_trajectory`` (the break find and the refine, their local bases and
trials, and the compiled kernels inside them), on ``bench_smooth.py``'s session (the rally
on the paper's three 30 fps cameras, 0.5 px, seed 1), the break scan on one thread.

Each named function is wrapped in place (its module's attribute) by a timer; the figures
are inclusive (a stage's kernels are inside it) and each kernel is also counted per stage
(``find/…``, ``refine/…``). ``--base DIR`` times that tree's code in a child process too,
the two alternating (``--rounds``), on the same pickled session: the per-stage figures of
both, paired. The code under test is the ``pslog`` on ``PYTHONPATH`` (the child runs with
``PYTHONPATH=DIR``).

    python benchmarks/smooth_stages.py [--minutes 90] [--rounds 2] [--base /work/main]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, before numpy loads
os.environ["PSLOG_SMOOTH_THREADS"] = "1"  # thread CPU time is then the scan's whole CPU

import argparse  # noqa: E402
import json  # noqa: E402
import pickle  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

#: (module, attribute, label): the stages (inclusive) and kernels timed
_STAGES = (
    ("trajectory", "_initial_control", "first trajectory"),
    ("trajectory", "_find_breaks", "find"),
    ("trajectory", "_refine_breaks", "refine"),
    ("trajectory", "_refit_linearised", "refit"),
    ("trajectory", "_information", "dof"),
    ("trajectory", "_information_factored", "covariance"),
    ("_breaks", "_scan", "scan"),
    ("_breaks", "_Base.__init__", "bases"),
    ("_breaks", "_gains", "trials"),
    ("_breaks", "detection_terms", "detection_terms"),
    ("_window", "window_terms", "window_terms"),
    ("_kernels", "window_normal_solve", "window_normal_solve"),
    ("_kernels", "window_positions", "window_positions"),
    ("_kernels", "trial_splines", "trial_splines"),
    ("_kernels", "gains_data", "gains_data"),
    ("_kernels", "trial_gather", "trial_gather"),
    ("_kernels", "trial_prior_terms", "trial_prior_terms"),
    ("_kernels", "trial_gains", "trial_gains"),
)
#: labels that set the stage their inner timers are counted under
_OUTER = ("find", "refine")


def _install(seconds: dict, calls: dict) -> None:
    """Wrap every timed function of ``_STAGES`` that this tree has (a missing one is
    skipped: an older or newer tree)."""
    import importlib

    stage: list[str] = []

    def wrap(fn, label):
        def timed(*args, **kwargs):
            outer = label in _OUTER
            if outer:
                stage.append(label)
            key = label if outer or not stage else f"{stage[-1]}/{label}"
            start = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                seconds[key] += time.thread_time() - start
                calls[key] += 1
                if outer:
                    stage.pop()
        return timed

    for module, name, label in _STAGES:
        mod = importlib.import_module(f"pslog.estimation.{module}")
        owner, attr = mod, name
        if "." in name:
            cls, attr = name.split(".")
            owner = getattr(mod, cls, None)
        if owner is None or not hasattr(owner, attr):
            continue
        setattr(owner, attr, wrap(getattr(owner, attr), label))


def run(session: str, repeat: int) -> dict:
    """Per-stage CPU s of ``repeat`` fits (the least of each), and the whole fit's."""
    import pslog
    from pslog.estimation import SmoothOptions, fit_trajectory

    obs, rig = pickle.load(open(session, "rb"))
    warm = obs.select(obs.time_ns < obs.time_ns[0] + 3 * 10**9)
    fit_trajectory(warm, rig, SmoothOptions())  # kernels loaded, first calls made
    best: dict = {}
    seconds: dict = defaultdict(float)
    calls: dict = defaultdict(int)
    _install(seconds, calls)
    for _ in range(repeat):
        seconds.clear()
        calls.clear()
        start = time.thread_time()
        fit_trajectory(obs, rig, SmoothOptions())
        seconds["fit"] = time.thread_time() - start
        calls["fit"] = 1
        for key, value in seconds.items():
            best[key] = min(best.get(key, (value, 0))[0], value), calls[key]
    return {"code": str(Path(pslog.__file__).parent), "n": len(obs), "stages": best}


def session(minutes: float) -> tuple:
    """bench_smooth's session of ``minutes``: (observations on the true clocks, true rig)."""
    from pslog import SimulationOptions, apply_timing, builtin_rig, simulate
    from pslog.motion import get_motion
    from pslog.rig import Rig
    from pslog.timing import observations

    offsets = {"cam2": 2.5e-3, "cam3": -3.5e-3}  # bench_smooth's
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    true = Rig(tuple(c.replace(clock_offset=offsets.get(c.name, 0.0)) for c in rig.cameras),
               rig.name)
    detections, _ = simulate(rig, get_motion("rally"), minutes * 60, SimulationOptions(
        noise_px=0.5, seed=1, clock_offset_s=offsets))
    return observations(detections, true), true


def _session(minutes: float, path: Path) -> None:
    with open(path, "wb") as f:
        pickle.dump(session(minutes), f)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=90.0)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=1, help="fits per child (least kept)")
    parser.add_argument("--base", default=None, metavar="DIR",
                        help="also time the pslog under DIR, alternating")
    parser.add_argument("--session", default=None, help="a pickled (obs, rig) to reuse")
    parser.add_argument("--child", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(run(args.child, args.repeat)))
        return 0
    with tempfile.TemporaryDirectory(prefix="smooth-stages-") as tmp:
        session = Path(args.session) if args.session else Path(tmp) / "session.pkl"
        if not session.exists():
            _session(args.minutes, session)
        here = str(Path(__file__).resolve().parents[1])
        trees = [("this tree", os.environ.get("PYTHONPATH") or here)]
        if args.base:
            trees.append(("base", args.base))
        results: dict = defaultdict(list)
        for _ in range(args.rounds):
            for name, code in trees:
                out = subprocess.run(
                    [sys.executable, str(Path(__file__).resolve()), "--child", str(session),
                     "--repeat", str(args.repeat)], check=True, capture_output=True,
                    text=True, cwd=tmp, env=dict(os.environ, PYTHONPATH=code)).stdout
                got = json.loads(out.splitlines()[-1])
                if not Path(got["code"]).resolve().is_relative_to(Path(code).resolve()):
                    raise RuntimeError(f"the child ran {got['code']}, not {code}")
                results[name].append(got["stages"])
        load = os.getloadavg()
        print(f"smooth stages: {args.minutes:g}-minute rally, thread CPU s (one scan thread), "
              f"{args.rounds} round(s) alternating, load {load[0]:.1f} {load[1]:.1f}")
        keys = sorted({k for runs in results.values() for r in runs for k in r},
                      key=lambda k: -max(r.get(k, (0, 0))[0] for runs in results.values()
                                         for r in runs))
        header = "  ".join(f"{name:>24}" for name in results)
        print(f"{'stage':<34} {'calls':>6}  {header}")
        for key in keys:
            calls = next(r[key][1] for runs in results.values() for r in runs if key in r)
            cells = []
            for runs in results.values():
                text = " ".join(f"{r[key][0]:.3f}" if key in r else "-" for r in runs)
                cells.append(f"{text:>24}")
            print(f"{key:<34} {calls:>6}  {'  '.join(cells)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
