"""pslog batch on a local Ray cluster: 1 against 2 workers, the cluster's start-up, a batch
of one against the plain commands, and the summary against the commands run by hand.

Targets (issue 14): on a batch of 40 simulated 2-minute sessions, the summary equals the one
built from running each command by hand on each session (exact, every column but the
runtime), and 2 workers are at least 1.6x faster than 1; a batch of one session is not
slower than the plain commands by more than a few seconds (the cluster's start-up).

Every batch runs as a real ``pslog batch`` process (its own local cluster); "by hand" is
``pslog info --json``, ``pslog fuse`` and ``pslog eval --json`` (plus ``pslog sync --json``
when the steps include sync) as separate processes, one session after another, and the row
built from their outputs (:func:`pslog.batch.summary_row`). Default steps ``fuse,eval`` with
the methods typeA and nearest keep the run to minutes on a shared machine; ``--steps
sync,fuse,eval`` adds the clock estimation (about 10x the work per session).

    python benchmarks/bench_batch.py [--sessions 40] [--minutes 2] [--steps fuse,eval]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pslog.batch import read_summary_csv, summary_row

METHODS = ("--method", "typeA", "--method", "nearest")
TARGET_SPEEDUP = 1.6


def pslog(*argv, env=None) -> tuple[float, str]:
    """``pslog ARGV`` as a process: (wall-clock seconds, stdout); a failure stops here."""
    start = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "pslog.cli", *map(str, argv)],
                         capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - start
    if run.returncode != 0:
        raise SystemExit(f"pslog {' '.join(map(str, argv))} failed: {run.stderr.strip()}")
    return seconds, run.stdout


def by_hand(session: Path, folder: Path, steps: list[str]) -> tuple[float, dict]:
    """The commands a user would type for one session: (seconds, summary row)."""
    folder.mkdir(parents=True)
    total, info = pslog("info", session, "--json")
    sync = None
    current = session
    if "sync" in steps:
        seconds, text = pslog("sync", current, "-o", folder / "synced.mcap", "--json")
        total += seconds
        sync = json.loads(text)
        current = folder / "synced.mcap"
    seconds, _ = pslog("fuse", current, "-o", folder / "fused.mcap", *METHODS)
    total += seconds
    seconds, evaluation = pslog("eval", folder / "fused.mcap", "--json")
    total += seconds
    return total, summary_row(session.name, json.loads(info), sync, json.loads(evaluation))


def as_csv(row: dict) -> dict:
    """A row as summary.csv holds it (strings; floats by repr), without the runtime."""
    import math

    def text(v):
        if v is None or (isinstance(v, float) and math.isnan(v)):
            return ""
        return repr(v) if isinstance(v, float) else str(v)
    return {k: text(v) for k, v in row.items() if k != "runtime_s"}


def differences(got: list[dict], want: list[dict]) -> list[str]:
    """Every cell where ``got`` (a batch's summary.csv) differs from ``want`` (the commands
    by hand), runtime aside: one line per cell naming the session, the column, both values
    and, for numbers, the difference (absolute, and in units of the last place)."""
    import math

    lines = []
    if [r.get("session") for r in got] != [r.get("session") for r in want]:
        lines.append(f"sessions differ: {[r.get('session') for r in got]} vs "
                     f"{[r.get('session') for r in want]}")
    for g, w in zip(got, want, strict=False):
        for column in dict.fromkeys([*w, *g]):
            if column == "runtime_s" or g.get(column) == w.get(column):
                continue
            a, b = g.get(column), w.get(column)
            how = ""
            try:
                x, y = float(a), float(b)
                ulps = abs(x - y) / math.ulp(max(abs(x), abs(y))) if x != y else 0.0
                how = f" (diff {x - y:+.3g}, {ulps:.0f} ulp)"
            except (TypeError, ValueError):
                pass
            lines.append(f"  {w.get('session')}: {column}: batch {a!r}, by hand {b!r}{how}")
    return lines


def batch(pattern: str, out: Path, steps: str, workers: int) -> tuple[float, list[dict]]:
    seconds, _ = pslog("batch", pattern, "--do", steps, *METHODS, "-o", out,
                       "--workers", workers)
    return seconds, read_summary_csv(out / "summary.csv")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=40)
    parser.add_argument("--minutes", type=float, default=2.0, help="length of each session")
    parser.add_argument("--steps", default="fuse,eval", help="fuse,eval or sync,fuse,eval")
    args = parser.parse_args()
    steps = args.steps.split(",")
    work = Path(tempfile.mkdtemp(prefix="pslog-bench-batch-"))
    try:
        season = work / "season"
        season.mkdir()
        t = time.perf_counter()
        for i in range(args.sessions):
            pslog("simulate", "--rig", "paper3", "--timing", "typeB", "--motion", "rally",
                  "--duration", args.minutes * 60, "--noise-px", "0.3", "--clock-offset",
                  f"cam2={1 + i % 5}", "--seed", i, "-o", season / f"match{i:03d}.mcap")
        print(f"batch benchmark: {args.sessions} simulated {args.minutes:g}-minute sessions "
              f"(3 cameras at 30 fps, type B, rally), steps {args.steps}, methods typeA and "
              f"nearest; {os.cpu_count()} cores; simulated in {time.perf_counter() - t:.0f} s")
        pattern = str(season / "*.mcap")
        # the cluster's start-up and shut-down, and a batch of one against its commands
        import ray

        temp = tempfile.mkdtemp(prefix="pslog-ray-")
        t = time.perf_counter()
        ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False,
                 logging_level="ERROR", _temp_dir=temp)
        ray.shutdown()
        startup = time.perf_counter() - t
        shutil.rmtree(temp, ignore_errors=True)
        one = season / "match000.mcap"
        hand_one, _ = by_hand(one, work / "one-hand", steps)
        batch_one, _ = batch(str(one), work / "one", args.steps, 1)
        # the whole season: by hand, then 1 and 2 workers
        hand_s = 0.0
        want = []
        for session in sorted(season.glob("*.mcap")):
            seconds, row = by_hand(session, work / "hand" / session.stem, steps)
            hand_s += seconds
            want.append(as_csv(row))
        one_s, rows1 = batch(pattern, work / "w1", args.steps, 1)
        two_s, rows2 = batch(pattern, work / "w2", args.steps, 2)
        exact = True
        for name, rows in (("--workers 1", rows1), ("--workers 2", rows2)):
            diff = differences(rows, want)
            exact = exact and not diff
            if diff:
                print(f"pslog batch {name}: {len(diff)} cell(s) differ from the commands by "
                      f"hand:")
                print("\n".join(diff))
        speedup = one_s / two_s
        n = args.sessions
        print(f"{'run':<44} {'seconds':>8} {'s/session':>10}")
        for name, s, k in (("local Ray cluster start + shut-down", startup, 0),
                           ("one session, plain commands", hand_one, 1),
                           ("one session, pslog batch --workers 1", batch_one, 1),
                           (f"{n} sessions, plain commands one by one", hand_s, n),
                           (f"{n} sessions, pslog batch --workers 1", one_s, n),
                           (f"{n} sessions, pslog batch --workers 2", two_s, n)):
            print(f"{name:<44} {s:>8.1f} {s / k if k else float('nan'):>10.2f}")
        print(f"2 workers vs 1: {speedup:.2f}x (target >= {TARGET_SPEEDUP}x): "
              f"{'met' if speedup >= TARGET_SPEEDUP else 'NOT met'}")
        print(f"batch of one vs plain commands: {batch_one - hand_one:+.1f} s")
        print(f"summary equals the commands run by hand (every column but runtime, both "
              f"batches): {'yes' if exact else 'NO'}")
        return 0 if exact else 1
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
