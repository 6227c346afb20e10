"""Session 36's walkthrough session (paper3, 8 ms readouts on every camera, offsets, a static
distractor): what the unmodelled readout costs. Per seed: ``pslog simulate`` writes the
session; ``pslog.sync`` with ``auto``, ``offset`` and ``offset,readout``; ``pslog.fuse``
(typeA, smooth, filter; with the clocks' consider covariance, as ``pslog fuse``) with each
synced rig and with the true clocks; mean error (mm) and NEES per method.

    python benchmarks/session37/sync_walkthrough.py [--seeds 48001,50400] [--readout-ms 8]
        [--duration 20] [--rig paper3]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import pslog
from pslog.evaluation import assess
from pslog.fusion import FusionOptions
from pslog.simulation import read_truth_clock

METHODS = ("typeA", "smooth", "filter")


def simulate(path: Path, rig: str, seed: int, readout_ms: float, duration: float,
             extra: list[str]) -> None:
    offsets = {"paper3": ["cam2=6.4", "cam3=-8.9"]}.get(rig, [])
    cmd = [sys.executable, "-m", "pslog", "simulate", "--rig", rig, "--timing", "typeA",
           "--motion", "rally", "--duration", str(duration), "--noise-px", "0.5",
           "--seed", str(seed), "-o", str(path), "--force", *extra]
    if readout_ms:
        cmd += ["--readout", str(readout_ms)]
    for o in offsets:
        cmd += ["--clock-offset", o]
    subprocess.run(cmd, check=True, capture_output=True)


def scores(session, rig, cov) -> str:
    opts = FusionOptions(clock_covariance=cov)
    tracks = pslog.fuse(session, list(METHODS), rig=rig, options=opts,
                        clock_uncertainty=cov is not None)
    out = []
    for m in METHODS:
        acc, q = assess(tracks[m], session.truth)
        out.append(f"{acc.mean_mm:6.2f} {q.nees:5.2f}")
    return "  ".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", default="48001")
    ap.add_argument("--readout-ms", type=float, default=8.0)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--rig", default="paper3")
    ap.add_argument("--distractor", default="1.0,2.0,0.1")
    args = ap.parse_args(argv)
    extra = ["--distractor", args.distractor] if args.distractor else []
    print(f"{'seed':>6} {'clocks':<16} " + "  ".join(f"{m + ' mm':>6} {'NEES':>5}"
                                                     for m in METHODS) + "   tests")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in map(int, args.seeds.split(",")):
            path = Path(tmp) / f"s{seed}.mcap"
            simulate(path, args.rig, seed, args.readout_ms, args.duration, extra)
            session = pslog.read_session(path)
            truth_rig = read_truth_clock(session.rig, session.metadata)
            print(f"{seed:>6} {'true':<16} {scores(session, truth_rig, None)}", flush=True)
            for est in ("auto", "offset", "offset,readout"):
                out = pslog.sync(session, est)
                tests = "; ".join(f"{t.parameter} W={t.statistic:.1f}/{t.dof} "
                                  f"Ws={t.shared_statistic:.1f}/{t.shared_dof}"
                                  for t in out.result.selection if t.dof)
                r = " ".join(f"{c.readout_s * 1e3:.1f}±{c.readout_std_s * 1e3:.1f}"
                             for c in out.result.cameras if c.readout_std_s > 0)
                s = replace(session, detections=out.detections) if out.regularized else session
                print(f"{seed:>6} {est:<16} "
                      f"{scores(s, out.rig, out.result.clock_covariance())}   {tests} {r}",
                      flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
