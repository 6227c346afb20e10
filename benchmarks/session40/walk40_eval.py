"""Session 40's walkthrough (walk40): each method's accuracy on the lab's session, against
the mocap CSV (``pslog eval --truth``), with the clocks as logged, after ``pslog sync``
(auto, offsets only, every parameter) and with the simulation's true clocks; and the
simulated session's own truth beside the mocap's. Run after ``walk40_make.py DIR`` and
the import of the walk (``DIR/lab.mcap``, see walk40_notes.md).

Usage: ``python benchmarks/session40/walk40_eval.py DIR``; prints one table (mean / median /
max mm per method) and each sync's clock estimates against the true ones.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from decimal import Decimal
from pathlib import Path

from pslog.log import read_session

UNIX0 = Decimal("1764921600.437")


def cli(*args: str) -> tuple[str, float]:
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pslog.cli", *args], capture_output=True,
                          text=True)
    if done.returncode:
        raise SystemExit(f"{' '.join(args)}: {done.stderr.strip()}")
    return done.stdout, time.perf_counter() - t0


def scores(fused: Path, truth: Path | None) -> dict:
    args = ["eval", str(fused), "--json"] + (["--truth", str(truth)] if truth else [])
    rows = json.loads(cli(*args)[0])
    return {r["method"]: (r["mean_mm"], r["median_mm"], r["max_mm"], r["n_points"])
            for r in rows}


def walk(d: Path) -> None:
    """The lab's commands in order, each timed: the lab's CSVs with their header renamed to
    pslog's (``frame_id,t_unix,px,py,conf`` -> ``frame,time,u,v,score``), import, sync,
    fuse, eval against the mocap (and the mocap on a late clock), export, view --save."""
    files = []
    for cam in ("cam1", "cam2", "cam3"):
        lines = (d / "lab" / f"{cam}.csv").read_text().splitlines(keepends=True)
        (d / f"{cam}.csv").write_text("frame,time,u,v,score\n" + "".join(lines[1:]))
        files += ["--detections", f"{cam}={d / f'{cam}.csv'}"]
    steps = [
        ("import", ["import", "--rig", str(d / "rig.toml"), *files, "-o", str(d / "lab.mcap"),
                    "--force"]),
        ("sync", ["sync", str(d / "lab.mcap"), "-o", str(d / "lab-synced.mcap"), "--force"]),
        ("fuse", ["fuse", str(d / "lab-synced.mcap"), "-o", str(d / "lab-fused.mcap"),
                  "--force"]),
        ("eval --truth", ["eval", str(d / "lab-fused.mcap"), "--truth",
                          str(d / "lab" / "mocap.csv")]),
        ("eval --truth (late mocap)", ["eval", str(d / "lab-fused.mcap"), "--truth",
                                       str(d / "lab" / "mocap_late.csv")]),
        ("export", ["export", str(d / "lab-fused.mcap"), "--csv", str(d / "tracks.csv"),
                    "--tum", str(d / "traj"), "--force"]),
        ("view --save", ["view", str(d / "lab-fused.mcap"), "--save", str(d / "lab.rrd"),
                         "--force"]),
    ]
    for label, args in steps:
        out, dt = cli(*args)
        said = [line for line in out.splitlines() if line.startswith("note")]
        print(f"{label}: {dt:.2f} s" + "".join(f"\n    {n}" for n in said))


def main(d: Path) -> None:
    walk(d)
    truth_clock = json.loads(read_session(d / "sim.mcap").metadata["truth_clock"])["cameras"]
    # the true clocks as a rig file (what a perfect sync would write)
    lines = (d / "rig_true.toml").read_text().splitlines()
    out, cam = [], None
    for line in lines:
        out.append(line)
        if line.startswith("name = \"cam"):
            cam = line.split('"')[1]
        if line.startswith("offset = ") and cam:
            c = truth_clock[cam]
            out += [f"clock_offset = {c['clock_offset']!r}",
                    f"clock_drift_ppm = {c['clock_drift_ppm']!r}", f"readout = {c['readout']!r}"]
    (d / "rig_trueclock.toml").write_text("\n".join(out) + "\n")
    # the mocap on the simulated session's clock (it has no origin)
    with open(d / "lab" / "mocap.csv") as fh, open(d / "mocap_session.csv", "w") as g:
        g.write(fh.readline())
        for line in fh:
            t, rest = line.split(",", 1)
            g.write(f"{Decimal(t) - UNIX0},{rest}")
    mocap = d / "lab" / "mocap.csv"
    table = {}
    clocks = {}
    for label, est in (("sync auto", "auto"), ("sync offset", "offset"),
                       ("sync offset,drift,readout", "offset,drift,readout")):
        synced = d / f"v-{est.replace(',', '_')}.mcap"
        js, dt = cli("sync", str(d / "lab.mcap"), "-o", str(synced), "--force", "--json",
                     "--estimate", est)
        clocks[label] = (json.loads(js)["cameras"], dt)
        fused = synced.with_suffix(".fused.mcap")
        cli("fuse", str(synced), "-o", str(fused), "--force")
        table[label] = scores(fused, mocap)
    cli("fuse", str(d / "lab.mcap"), "-o", str(d / "v-nominal.fused.mcap"), "--force")
    table["as logged"] = scores(d / "v-nominal.fused.mcap", mocap)
    cli("fuse", str(d / "lab.mcap"), "--rig", str(d / "rig_trueclock.toml"),
        "-o", str(d / "v-true.fused.mcap"), "--force")
    table["true clocks"] = scores(d / "v-true.fused.mcap", mocap)
    cli("sync", str(d / "sim.mcap"), "-o", str(d / "sim-synced.mcap"), "--force")
    cli("fuse", str(d / "sim-synced.mcap"), "-o", str(d / "sim-fused.mcap"), "--force")
    table["sim, synced, own truth"] = scores(d / "sim-fused.mcap", None)
    table["sim, synced, mocap 120 Hz"] = scores(d / "sim-fused.mcap", d / "mocap_session.csv")
    methods = ["typeA", "smooth", "filter", "nearest"]
    print("| clocks | " + " | ".join(methods) + " |")
    print("|---|" + "---:|" * len(methods))
    for label, row in table.items():
        cells = [("{:.2f} / {:.2f} / {:.1f}".format(*row[m][:3]) if m in row else "-")
                 for m in methods]
        print(f"| {label} | " + " | ".join(cells) + " |")
    print("\nclock estimates (ms, ppm) against the truth:")
    for label, (cams, dt) in clocks.items():
        print(f"{label} ({dt:.1f} s):")
        for c in cams:
            name = c["name"] if "name" in c else c.get("camera")
            t = truth_clock[name]
            print(f"  {name}: {json.dumps({k: v for k, v in c.items() if k != 'name'})}"
                  f"  true offset {t['clock_offset'] * 1e3:.3f} ms, drift "
                  f"{t['clock_drift_ppm']:.1f} ppm, readout {t['readout'] * 1e3:.1f} ms")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
