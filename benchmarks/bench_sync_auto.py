"""``pslog sync --estimate auto`` against explicit models, on rigs built here.

For each case and seed: the session simulated with its clock faults, the host stamps
regularized as ``pslog sync`` does, then the clocks estimated from the nominal rig (every
clock 0) three ways: ``auto``, the explicit model that omits readouts (``offset``, or
``offset,drift`` on drifting sessions) and the explicit one with them (``offset,readout`` /
``offset,drift,readout``). Each synced rig is fused (typeA, smooth) and compared with the
truth (mean 3D error, mm); the CPU time of each estimate (process time) is printed, and
auto's choice with its Wald figures.

Global-shutter cases are bench_timing_accuracy's offset and drift cases; rolling-shutter
cases cover readouts of 10-30 ms over rigs where the ball spans a thin band of rows (paper3:
±6 % of the height), a third of them (lab3, the tests' rig), and the session-23 walkthrough's
three webcams (two 640 x 480, one 1280 x 720, calibrated by ``pslog calibrate`` from surveyed
points: ``benchmarks/webcams3.toml``).

    python benchmarks/bench_sync_auto.py [--seeds N] [--first-seed N] [--only SUBSTRING]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from bench_timing_accuracy import _nominal, _regularize_auto, motion_named, rig_named

from pslog import SimulationOptions, simulate
from pslog.errors import PslogError
from pslog.estimation.sync import estimate_clocks
from pslog.evaluation import evaluate
from pslog.fusion import fuse_all
from pslog.rig import Rig, load_rig

METHODS = ("typeA", "smooth")


@dataclass(frozen=True)
class Case:
    name: str
    rig: str
    motion: str
    duration: float
    offset_ms: dict
    readout_ms: dict = field(default_factory=dict)
    drift_ppm: dict = field(default_factory=dict)
    noise_px: float = 0.3
    jitter_ms: float = 0.0


OFF3 = {"cam2": 7.3, "cam3": -12.0}
OFF4 = {"c2": 9.1, "c3": -11.4, "c4": 4.6}
OFFL = {"lab2": 6.4, "lab3": -8.9}
OFFW = {"cam2": 6.4, "cam3": -8.9}


def cases() -> list[Case]:
    return [
        # global shutters (bench_timing_accuracy's offset and drift cases)
        Case("GS offsets paper3", "paper3", "rally", 8.0, OFF3),
        Case("GS offsets paper3 rally-7", "paper3", "rally-7", 8.0, OFF3),
        Case("GS offsets own4", "own4", "rally-7", 8.0, OFF4),
        Case("GS offsets paper2", "paper2", "rally", 8.0, {"cam2": -9.5}),
        Case("GS offsets mixed 30/60", "mixed", "rally", 8.0, OFF3),
        Case("GS offsets lab3", "lab3", "rally", 8.0, OFFL),
        Case("GS webcams 20 s", "webcams", "rally", 20.0, OFFW, jitter_ms=2.0),
        Case("GS drift 2 min own4", "own4", "rally-3", 120.0, OFF4,
             drift_ppm={"c2": 35.0, "c3": -48.0, "c4": 22.0}),
        Case("GS no drift 2 min own4", "own4", "rally-5", 120.0, OFF4),
        # rolling shutters, 10-30 ms
        Case("RS paper3 (thin band) 18-25", "paper3", "rally", 8.0, OFF3,
             {"cam1": 22.0, "cam2": 25.0, "cam3": 18.0}),
        Case("RS paper3 (thin band) 10", "paper3", "rally-7", 8.0, OFF3,
             {"cam1": 10.0, "cam2": 10.0, "cam3": 10.0}),
        Case("RS own4 15-26", "own4", "rally-7", 8.0, OFF4,
             {"c1": 20.0, "c2": 26.0, "c3": 15.0, "c4": 24.0}),
        Case("RS lab3 (third) 30", "lab3", "rally", 8.0, OFFL,
             {"lab1": 30.0, "lab2": 30.0, "lab3": 30.0}),
        Case("RS lab3 (third) 10-20", "lab3", "rally", 8.0, OFFL,
             {"lab1": 10.0, "lab2": 20.0, "lab3": 15.0}),
        Case("RS webcams 25 ms 20 s", "webcams", "rally", 20.0, OFFW,
             {"cam1": 25.0, "cam2": 25.0, "cam3": 25.0}, jitter_ms=2.0, noise_px=0.5),
        Case("RS webcams 12 ms 8 s", "webcams", "rally-7", 8.0, OFFW,
             {"cam1": 12.0, "cam2": 12.0, "cam3": 12.0}, noise_px=0.5),
        Case("RS webcams mixed 0/25/25", "webcams", "rally", 8.0, OFFW,
             {"cam2": 25.0, "cam3": 25.0}, noise_px=0.5),
        Case("RS combined 2 min own4", "own4", "rally-5", 120.0, OFF4,
             {"c1": 20.0, "c2": 26.0, "c3": 15.0, "c4": 24.0},
             {"c2": 35.0, "c3": -48.0, "c4": 22.0}, jitter_ms=1.5),
    ]


def make_rig(name: str, lab_rig: str | None) -> Rig:
    if name == "lab3":
        from _rigs import lab3_rig

        return lab3_rig()
    if name == "webcams":
        if lab_rig is None:
            raise SystemExit("the webcams cases need --lab-rig")
        from pslog import apply_timing

        rig = load_rig(lab_rig)
        return apply_timing(rig, "typeA")
    return rig_named(name)


def _accuracy(detections, rig, truth) -> dict:
    tracks = fuse_all(detections, rig, list(METHODS))
    return {m: evaluate(tracks[m], truth).mean_mm for m in METHODS}


def simulate_case(case: Case, seed: int, lab_rig: str | None, spurious: float = 0.0):
    """``(rig, options, detections, truth)`` of one seed of ``case`` (its clock faults as
    :class:`SimulationOptions`; ``spurious``: the share of frames given a false candidate)."""
    rig = make_rig(case.rig, lab_rig)
    opts = SimulationOptions(
        noise_px=case.noise_px, seed=seed, host_jitter_s=case.jitter_ms / 1e3,
        clock_offset_s={k: v / 1e3 for k, v in case.offset_ms.items()},
        clock_drift_ppm=dict(case.drift_ppm),
        readout_s={k: v / 1e3 for k, v in case.readout_ms.items()},
        spurious_rate=spurious)
    detections, truth = simulate(rig, motion_named(case.motion), case.duration, opts)
    return rig, opts, detections, truth


def run(case: Case, seed: int, lab_rig: str | None) -> list[str]:
    rig, _, detections, truth = simulate_case(case, seed, lab_rig)
    nominal = _nominal(rig)
    regular, reports = _regularize_auto(detections)
    obs = regular.best()
    base = ("offset", "drift") if case.drift_ppm else ("offset",)
    models = {"auto": "auto", "no readout": base, "readouts": (*base, "readout")}
    out = []
    for label, model in models.items():
        t = time.process_time()
        try:
            result = estimate_clocks(obs, nominal, model, regularized=reports)
        except PslogError as exc:
            out.append(f"{case.name:<30} {seed:>2} {label:<10} FAILED: {exc}")
            continue
        cpu = time.process_time() - t
        acc = _accuracy(regular, result.rig, truth)
        chosen = ",".join(result.estimated)
        tests = "; ".join(f"{t.parameter} {'kept' if t.kept else 'no'} "
                          + (f"W={t.statistic:.1f}/{t.dof}" if np.isfinite(t.statistic)
                             else t.reason[:40])
                          for t in result.selection)
        out.append(f"{case.name:<30} {seed:>2} {label:<10} {acc['typeA']:7.2f} "
                   f"{acc['smooth']:7.2f} {cpu:7.1f}  {chosen:<22} {tests}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--only", default=None, help="cases whose name holds this text")
    ap.add_argument("--lab-rig", default=str(Path(__file__).with_name("webcams3.toml")),
                    help="the webcam rig (a rig file; default: webcams3.toml here)")
    args = ap.parse_args(argv)
    print(f"{'case':<30} {'sd':>2} {'model':<10} {'typeA':>7} {'smooth':>7} {'cpu s':>7}  "
          f"{'estimated':<22} auto's tests (Wald χ² / dof)")
    for case in cases():
        if args.only and args.only not in case.name:
            continue
        if case.rig == "webcams" and args.lab_rig is None:
            continue
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            for line in run(case, seed, args.lab_rig):
                print(line, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
