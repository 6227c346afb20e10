"""Session log throughput: write and read a 10-minute, 3-camera session (54,000 frames).

Prints messages per second for writing (SessionWriter.add_detections) and reading
(read_session: from the columnar table, and from the per-frame messages as a file without
tables reads), and, as a baseline measured in the same run on the same file, a raw
``mcap`` iteration over the detection messages without protobuf decoding.

Run: ``python benchmarks/bench_log.py [--minutes 10]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np


def main() -> None:
    from mcap.reader import make_reader

    from pslog.log import SessionWriter, read_session
    from pslog.motion import get_motion
    from pslog.rig import apply_timing, builtin_rig
    from pslog.simulation import SimulationOptions, simulate

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0)
    args = parser.parse_args()

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    options = SimulationOptions(noise_px=0.5, miss_rate=0.2, seed=1)
    detections, _ = simulate(rig, get_motion("turntable"), args.minutes * 60.0, options)
    n = detections.n_frames
    print(f"session: {args.minutes:g} min, {len(rig)} cameras, {n} frames, "
          f"{detections.n_candidates} candidates")

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.mcap"
        t0 = time.perf_counter()
        with SessionWriter(path, rig, timing="typeA") as writer:
            writer.add_detections(detections)
        t_write = time.perf_counter() - t0

        t0 = time.perf_counter()
        session = read_session(path)
        t_read = time.perf_counter() - t0
        np.testing.assert_array_equal(session.detections.cand_uv, detections.cand_uv)

        from pslog.log.reader import _Finished

        _Finished.use_tables = False  # the per-frame messages, as an older file reads
        t0 = time.perf_counter()
        messages = read_session(path)
        t_messages = time.perf_counter() - t0
        _Finished.use_tables = True
        np.testing.assert_array_equal(messages.detections.cand_uv, detections.cand_uv)

        t0 = time.perf_counter()
        with open(path, "rb") as f:
            topics = [f"/camera/{name}/detections" for name in rig.names]
            count = sum(1 for _ in make_reader(f).iter_messages(topics=topics))
        t_raw = time.perf_counter() - t0
        assert count == n

        size = path.stat().st_size
    print(f"file: {size / 1e6:.1f} MB ({size / n:.0f} bytes/frame)")
    print(f"write  (SessionWriter.add_detections): {n / t_write:12,.0f} messages/s  "
          f"({t_write:.2f} s)")
    print(f"read   (read_session, columnar table): {n / t_read:12,.0f} messages/s  "
          f"({t_read:.2f} s)")
    print(f"read   (read_session, messages):       {n / t_messages:12,.0f} messages/s  "
          f"({t_messages:.2f} s)")
    print(f"baseline (mcap iter_messages, raw):    {n / t_raw:12,.0f} messages/s  "
          f"({t_raw:.2f} s)")
    per_match = 90 * 60 * 90 / (n / t_read)
    print(f"=> a 90-minute 3-camera match (486,000 frames) reads in about {per_match:.1f} s")


if __name__ == "__main__":
    main()
