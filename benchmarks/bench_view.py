"""Viewer throughput: a session MCAP becomes a rerun .rrd (``viewers.save_rrd``).

1. A 10-minute, three-camera type-A session (54,000 detections, no frames, ground truth, no
   stored track: typeA is fused on the fly with its Figure 2 construction). Target: <= 10 s.
2. The 1.5 s sample with frames (``samples/throw.mcap``; a synthetic rendered session when
   the sample is missing).

Baselines measured in the same run on the same files: ``read_session`` alone, and reading
plus fusing (``viewers.load_view_data``), so the logging cost is the difference.

Run: ``python benchmarks/bench_view.py [--minutes 10]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

SAMPLE = Path(__file__).resolve().parent.parent / "samples" / "throw.mcap"


def _timed(fn):
    t0 = time.perf_counter()
    result = fn()
    return result, time.perf_counter() - t0


def _measure(label: str, session: Path, rrd: Path) -> float:
    from pslog.log import read_session
    from viewers import load_view_data, save_rrd

    _, t_read = _timed(lambda: read_session(session))
    _, t_load = _timed(lambda: load_view_data([session]))
    counts, t_total = _timed(lambda: save_rrd([session], rrd, force=True))
    rows = sum(counts.values())
    print(f"{label}")
    print(f"  baseline read_session:                 {t_read:7.2f} s")
    print(f"  baseline read + fuse (load_view_data): {t_load:7.2f} s")
    print(f"  session -> .rrd (save_rrd, total):     {t_total:7.2f} s   "
          f"({t_total - t_load:.2f} s logging, {rows:,} rows, "
          f"{rrd.stat().st_size / 1e6:.1f} MB .rrd)")
    print("  rows: " + ", ".join(f"{k} {v:,}" for k, v in counts.items() if v))
    return t_total


def main() -> None:
    from pslog.log import SessionWriter
    from pslog.motion import get_motion
    from pslog.rig import apply_timing, builtin_rig
    from pslog.simulation import SimulationOptions, simulate

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    args = parser.parse_args()

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    options = SimulationOptions(noise_px=0.5, miss_rate=0.0, seed=1)
    detections, truth = simulate(rig, get_motion("turntable"), args.minutes * 60.0, options)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        long_session = tmp / "long.mcap"
        with SessionWriter(long_session, rig, timing="typeA") as writer:
            writer.add_detections(detections)
            writer.add_truth(truth)
        t_long = _measure(f"{args.minutes:g} min, {len(rig)} cameras, {detections.n_frames:,} "
                          f"frames, {detections.n_candidates:,} detections, no images",
                          long_session, tmp / "long.rrd")
        verdict = "OK" if t_long <= 10.0 * args.minutes / 10.0 else "TOO SLOW"
        print(f"  target <= 10 s for 10 min: {verdict}\n")

        sample = SAMPLE
        if not sample.exists():
            from recorders import record_synthetic

            sample = tmp / "throw.mcap"
            record_synthetic(rig, "throw", sample, duration=1.5, frames=True, status=None)
        _measure(f"1.5 s sample with frames ({sample.name})", sample, tmp / "sample.rrd")


if __name__ == "__main__":
    main()
