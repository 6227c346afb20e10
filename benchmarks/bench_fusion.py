"""Fusion throughput: fused points per second for every method, on one core.

Target (issue 3): typeA >= 200,000 points/s. The baseline, measured in the same run, is the
work every method shares (undistortion and viewing rays of every detection, ``prepare``), so
the ratio says how much the method itself costs on top of it. With ``--stream`` it also
times :class:`pslog.fusion.stream.StreamFuser`, detections pushed one at a time (the live
form: a trailing window re-fused at every push), in milliseconds per push.

    python benchmarks/bench_fusion.py [--minutes 10] [--repeat 3] [--stream 10]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core, before numpy loads

import argparse  # noqa: E402
import time  # noqa: E402

from pslog import SimulationOptions, apply_timing, builtin_rig, get_motion, simulate  # noqa: E402
from pslog.fusion import fuse, prepare  # noqa: E402
from pslog.fusion.stream import StreamFuser  # noqa: E402

TARGET_TYPEA = 200_000


def best_of(repeat: int, fn) -> tuple[float, object]:
    best, result = float("inf"), None
    for _ in range(repeat):
        start = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - start)
    return best, result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="session length")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--stream", type=float, default=0.0, metavar="SECONDS",
                        help="also time StreamFuser on a session this long (0: not)")
    parser.add_argument("--json", default=None, help="write the rates as JSON")
    args = parser.parse_args()
    rows = []
    duration = args.minutes * 60
    print(f"fusion benchmark: {args.minutes:g}-minute session, 3 cameras at 30 fps, "
          f"0.5 px noise, best of {args.repeat}")
    worst_ok = True
    for timing, methods in (("typeA", ("typeA", "nearest")),
                            ("typeB", ("typeB", "linear", "sync"))):
        rig = apply_timing(builtin_rig("paper3"), timing)
        detections, _ = simulate(rig, get_motion("turntable"), duration,
                                 SimulationOptions(noise_px=0.5, seed=0))
        obs = detections.best()
        base_s, _ = best_of(args.repeat, lambda obs=obs, rig=rig: prepare(obs, rig))
        print(f"\n{timing} timing, {len(obs):,} detections")
        print(f"  {'baseline (prepare)':<20} {base_s * 1e3:9.1f} ms  "
              f"{len(obs) / base_s:>12,.0f} detections/s")
        for method in methods:
            seconds, track = best_of(args.repeat,
                                     lambda m=method, obs=obs, rig=rig: fuse(obs, rig, m))
            rate = len(track) / seconds
            note = ""
            if method == "typeA":
                ok = rate >= TARGET_TYPEA
                worst_ok &= ok
                note = f"  target {TARGET_TYPEA:,}/s: {'met' if ok else 'MISSED'}"
            rows.append({"stage": f"fusion {method}", "figure": rate, "unit": "points/s",
                         "target": f">= {TARGET_TYPEA:,}" if method == "typeA" else "",
                         "ok": bool(rate >= TARGET_TYPEA) if method == "typeA" else None,
                         "peer": None, "peer_figure": None, "better": "higher",
                         "note": f"{args.minutes:g}-min session, best of {args.repeat}"})
            print(f"  {method:<20} {seconds * 1e3:9.1f} ms  {rate:>12,.0f} points/s  "
                  f"{seconds / base_s:5.1f}x baseline{note}")
    if args.stream > 0:
        stream(args.stream, args.repeat)
    if args.json:
        import json

        with open(args.json, "w") as f:
            json.dump({"rows": rows}, f)
    return 0 if worst_ok else 1


def stream(seconds: float, repeat: int) -> None:
    """Milliseconds per push of StreamFuser, every detection pushed alone."""
    print(f"\nstreamed, one detection per push ({seconds:g}-second session, best of {repeat})")
    for timing, methods in (("typeA", ("typeA", "nearest")),
                            ("typeB", ("typeB", "linear", "sync"))):
        rig = apply_timing(builtin_rig("paper3"), timing)
        detections, _ = simulate(rig, get_motion("turntable"), seconds,
                                 SimulationOptions(noise_px=0.5, seed=0))
        obs = detections.best()
        for method in methods:
            def run(method=method, rig=rig, obs=obs):
                fuser = StreamFuser(rig, method)
                for i in range(len(obs)):
                    fuser.push(obs.time_ns[i:i + 1], obs.camera[i:i + 1], obs.uv[i:i + 1])
            push_s = best_of(repeat, run)[0] / len(obs)
            print(f"  {method:<20} {push_s * 1e3:9.2f} ms per push ({timing} timing)")


if __name__ == "__main__":
    raise SystemExit(main())
