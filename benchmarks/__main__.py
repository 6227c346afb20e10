"""``python -m benchmarks``: every benchmark of pslog, one table.

Each benchmark script runs as its own process with ``--json FILE`` and writes rows of the
form ``{"stage", "figure", "unit", "target", "ok", "peer", "peer_figure", "better",
"note"}``; this module only runs them, gathers the rows and prints one table — stage,
figure, target, the peer's figure measured in the same run, the ratio (above 1: pslog is the
better of the two, whichever way "better" goes for that figure) and pass/fail — and writes
it as JSON with ``--json``. A benchmark that crashes, times out or writes no rows shows as
an ERROR row naming its last error line; the others still run. A peer that is not installed
(``pip install '.[bench]'``) shows as "peer not installed" in its row.

``--quick`` runs small sessions with one repeat (under a minute on an idle two-core
machine): a smoke test of the suite, not figures to quote; the 90-minute targets are then
judged on figures extrapolated along the line through the two longest runs.

Run: ``python -m benchmarks [--quick] [--only view,peers] [--json out.json]
[--timeout S]``
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent


@dataclass(frozen=True)
class Bench:
    """One benchmark script and how the suite runs it.

    Attributes
    ----------
    name : short name (``--only``)
    script : path of the script (taking ``--json FILE``)
    full, quick : its arguments in a full and a ``--quick`` run
    stages : the stages it is expected to report (named in its ERROR rows when it fails)
    convert : its JSON -> suite rows, when it does not write suite rows itself
    timeout_s : (full, quick) longest run, seconds
    """

    name: str
    script: Path
    full: list[str] = field(default_factory=list)
    quick: list[str] = field(default_factory=list)
    stages: list[str] = field(default_factory=list)
    convert: Callable[[dict], list[dict]] | None = None
    timeout_s: tuple[float, float] = (3600.0, 120.0)


#: sessions shorter than this (``--quick``) are not held to the 90-minute targets: a
#: process's fixed start-up cost would be extrapolated with its per-minute cost
MIN_EXTRAPOLATE_MIN = 10.0


def _at_90(points: list[tuple[float, float]]) -> tuple[float, str]:
    """``(value at 90 minutes, how)`` from ``(minutes, value)`` pairs: measured, or along the
    line through the two longest runs (the longest at least :data:`MIN_EXTRAPOLATE_MIN`);
    else the longest run's value, ``how`` starting with "at"."""
    points = sorted(points)
    m_b, v_b = points[-1]
    if m_b == 90 or len(points) < 2 or m_b < MIN_EXTRAPOLATE_MIN:
        return v_b, f"at {m_b:g} min"
    m_a, v_a = points[-2]
    return v_b + (v_b - v_a) / (m_b - m_a) * (90 - m_b), \
        f"extrapolated from {m_a:g} and {m_b:g} min"


#: issue 12's targets for a 90-minute session: seconds, and peak MB where there is one
MATCH_TARGETS = {"eval": (3.0, None), "fuse typeA": (5.0, 1000.0), "fuse default": (8.0, None)}


def match_rows(data: dict) -> list[dict]:
    """bench_match.py's rows (stage x minutes) -> one suite row per stage, at 90 minutes."""
    rows = []
    for stage, (target_s, target_mb) in MATCH_TARGETS.items():
        runs = [r for r in data.get("rows", []) if r["stage"] == stage and r["finished"]]
        if not runs:
            continue
        seconds, how = _at_90([(r["minutes"], r["seconds"]) for r in runs])
        longest = max(runs, key=lambda r: r["minutes"])
        peak = longest["peak_mb"]
        ok = seconds <= target_s
        if target_mb is not None and longest["minutes"] == 90:
            ok = ok and peak <= target_mb
        judged = longest["minutes"] >= MIN_EXTRAPOLATE_MIN
        per_min = ", ".join(f"{r['minutes']:g}: {r['seconds'] / r['minutes']:.3f}"
                            for r in sorted(runs, key=lambda r: r["minutes"]))
        rows.append({"stage": stage, "figure": seconds,
                     "unit": "s at 90 min" if judged else f"s {how}",
                     "target": f"<= {target_s:g} s" + (f", <= {target_mb:.0f} MB"
                                                       if target_mb else "") + " at 90 min",
                     "ok": ok if judged else None, "peer": None, "peer_figure": None,
                     "better": "lower",
                     "note": f"{how}; CPU {longest.get('cpu_seconds') or float('nan'):.1f} s "
                             f"and peak {peak:.0f} MB at {longest['minutes']:g} min; "
                             f"s/min {per_min}"})
        steps = [r for r in data.get("rows", []) if r["stage"] == f"{stage} steps"
                 and r["minutes"] == longest["minutes"]]
        if steps:  # where the time goes (bench_match.py's breakdown of the stage)
            rows[-1]["note"] += f"; steps at {longest['minutes']:g} min: {steps[-1]['note']}"
    return rows


def benches() -> list[Bench]:
    """The suite, in the order of the table."""
    b = HERE
    return [
        Bench("match", b / "bench_match.py", ["--base", ""],
              ["--base", "", "--minutes", "1"],
              ["eval", "fuse typeA", "fuse default"], match_rows),
        Bench("peers", b / "bench_peers.py", [], ["--quick"],
              ["read detections", "typeA points/s"]),
        Bench("fusion", b / "bench_fusion.py", [], ["--minutes", "0.5", "--repeat", "1"],
              ["fusion typeA"]),
        # smooth and sync, each its own row, on the same session (bench_smooth.py)
        Bench("smooth", b / "bench_smooth.py", ["--repeat", "2"], ["--minutes", "0.25"],
              ["smooth", "sync"]),
        Bench("filter", b / "bench_filter.py", ["--quick"], ["--quick", "--seconds", "3"],
              ["filter"]),
        Bench("detect", b / "bench_detect.py", [],
              ["--frames", "30", "--repeat", "1", "--accuracy-frames", "6",
               "--hd-frames", "9"], ["detection 640x480", "detection 1280x720"]),
        # (24 s, 2160 frames: a session long enough for redetect's compiled path, which
        # long sessions take: the screened decoder)
        Bench("redetect", b / "bench_redetect.py", ["--seconds", "24"],
              ["--seconds", "1", "--rounds", "1", "--exact-only"],
              ["redetect 1280x720"]),
        Bench("view", b / "bench_view.py", [], ["--minutes", "1"], ["view --save"]),
        Bench("live", b / "bench_live.py", ["--seconds", "20"],
              ["--seconds", "2", "--load", "30", "--method", "typeA", "--candidates", "best"],
              ["live latency"]),
        Bench("dirty", b / "bench_dirty.py", [], ["--quick"], ["dirty accuracy"],
              timeout_s=(3600.0, 180.0)),
    ]


def _error_rows(bench: Bench, why: str) -> list[dict]:
    return [{"stage": stage, "figure": None, "unit": "", "target": "", "ok": False,
             "peer": None, "peer_figure": None, "better": "higher", "error": True,
             "note": f"{bench.script.name} failed: {why}", "bench": bench.name}
            for stage in (bench.stages or [bench.name])]


def run_bench(bench: Bench, quick: bool, timeout_s: float | None = None) -> list[dict]:
    """Run one benchmark as a process; its rows, or ERROR rows when it fails."""
    limit = timeout_s or bench.timeout_s[1 if quick else 0]
    with tempfile.TemporaryDirectory(prefix="pslog-suite-") as tmp:
        out = Path(tmp) / "rows.json"
        cmd = [sys.executable, str(bench.script), *(bench.quick if quick else bench.full),
               "--json", str(out)]
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(
            [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
        t0 = time.perf_counter()
        try:
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=limit,
                                  cwd=tmp, env=env)
        except subprocess.TimeoutExpired:
            return _error_rows(bench, f"no result within {limit:g} s")
        except OSError as exc:
            return _error_rows(bench, f"cannot run it ({exc.strerror or exc})")
        seconds = time.perf_counter() - t0
        try:
            data = json.loads(out.read_text())
            rows = bench.convert(data) if bench.convert else list(data["rows"])
        except (OSError, ValueError, KeyError, TypeError) as exc:
            lines = [ln for ln in (done.stderr or done.stdout).strip().splitlines() if ln]
            why = lines[-1] if lines else f"exit {done.returncode}, no rows ({exc})"
            return _error_rows(bench, f"exit {done.returncode}: {why}"[:300])
    if not rows:
        return _error_rows(bench, f"exit {done.returncode}, no rows")
    for row in rows:
        row.setdefault("note", "")
        row["bench"] = bench.name
        row["bench_seconds"] = seconds
    return rows


def ratio(row: dict) -> float | None:
    """pslog over the peer, above 1 when pslog is better (faster, or lower for "lower")."""
    a, b = row.get("figure"), row.get("peer_figure")
    if a is None or b is None or not a or not b:
        return None
    return a / b if row.get("better", "higher") == "higher" else b / a


def verdict(row: dict) -> str:
    if row.get("error"):
        return "ERROR"
    if row.get("ok") is None:
        return "-"
    return "PASS" if row["ok"] else "FAIL"


def _num(x: float | None) -> str:
    if x is None:
        return "-"
    if abs(x) >= 1000:
        return f"{x:,.0f}"
    return f"{x:.3g}"


def format_table(rows: list[dict]) -> str:
    """The rows as one markdown table."""
    lines = ["| stage | figure | unit | target | peer (same run) | peer figure | ratio | "
             "result |", "|---|---:|---|---|---|---:|---:|---|"]
    for r in rows:
        peer = r.get("peer") or ("peer not installed" if "not installed" in r.get("note", "")
                                 else "-")
        q = ratio(r)
        lines.append(f"| {r['stage']} | {_num(r.get('figure'))} | {r.get('unit', '')} | "
                     f"{r.get('target') or '-'} | {peer} | {_num(r.get('peer_figure'))} | "
                     f"{'-' if q is None else f'{q:.2f}'} | {verdict(r)} |")
    return "\n".join(lines)


def machine() -> dict:
    return {"platform": platform.platform(), "python": platform.python_version(),
            "cpus": os.cpu_count(), "load_average": list(os.getloadavg()),
            "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime())}


def run_suite(suite: list[Bench], quick: bool, timeout_s: float | None = None,
              log=print) -> list[dict]:
    rows = []
    for bench in suite:
        log(f"running {bench.script.name} {'(quick)' if quick else ''}...", flush=True)
        got = run_bench(bench, quick, timeout_s)
        log("  " + "; ".join(f"{r['stage']}: {verdict(r)}" for r in got), flush=True)
        rows += got
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true",
                        help="small sessions, one repeat (under a minute on an idle machine)")
    parser.add_argument("--only", default=None, metavar="A,B",
                        help="run only these benchmarks: " + ", ".join(b.name for b in benches()))
    parser.add_argument("--script", type=Path, action="append", default=[], metavar="FILE",
                        help="run this benchmark script (one taking --json FILE) instead of "
                             "the built-in suite; repeatable")
    parser.add_argument("--json", type=Path, default=None, help="write the table as JSON")
    parser.add_argument("--timeout", type=float, default=None, metavar="S",
                        help="longest run of one benchmark (default 3600 s, quick 120 s)")
    args = parser.parse_args(argv)
    suite = [Bench(p.stem, p.resolve()) for p in args.script] if args.script else benches()
    if args.only:
        wanted = [w.strip() for w in args.only.split(",") if w.strip()]
        unknown = [w for w in wanted if w not in {b.name for b in suite}]
        if unknown:
            parser.error(f"unknown benchmark {unknown[0]!r} (known: "
                         f"{', '.join(b.name for b in suite)})")
        suite = [b for b in suite if b.name in wanted]
    t0 = time.perf_counter()
    rows = run_suite(suite, args.quick, args.timeout, log=lambda *a, **k: print(
        *a, **k, file=sys.stderr))
    info = machine()
    info["seconds"] = time.perf_counter() - t0
    print(format_table(rows))
    load = ", ".join(f"{x:.1f}" for x in info["load_average"])
    print(f"\n{info['cpus']} CPUs, load average {load}; {info['seconds']:.0f} s"
          f"{' (--quick)' if args.quick else ''}; ratio: pslog / peer, "
          f"above 1 when pslog is better")
    if args.json is not None:
        args.json.write_text(json.dumps({"quick": args.quick, "machine": info, "rows": rows},
                                        indent=2))
    return 0 if all(verdict(r) in ("PASS", "-") for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
