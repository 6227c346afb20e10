"""A hostile season folder for ``pslog batch`` (session 41, hostile41): two sessions of one
name in subfolders, a folder named like a session, a FIFO, a link to itself and to a gone
file, folder links into the tree itself, an unreadable file (root reads it anyway), a cut
session, an empty one, and -o inside the season; then a --force batch SIGKILLed midway and
re-run with --resume (every session must hold a complete set: its done.json's outputs).

Run: python batch.py WORKDIR SESSION.mcap"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

TREE = Path(__file__).resolve().parents[3]
ENV = {**os.environ, "PYTHONPATH": str(TREE), "PSLOG_PROGRESS": "off"}
work, sample = Path(sys.argv[1]), Path(sys.argv[2])
season = work / "season"
shutil.rmtree(season, ignore_errors=True)
for rel in ("a/m.mcap", "b/m.mcap", "c/d/n.mcap"):
    (season / rel).parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(sample, season / rel)
(season / "x.mcap").mkdir()
os.mkfifo(season / "fifo.mcap")
(season / "loop.mcap").symlink_to("loop.mcap")
(season / "gone.mcap").symlink_to("nowhere.mcap")
(season / "again").symlink_to(".")
(season / "c" / "up").symlink_to("..")
shutil.copyfile(sample, season / "locked.mcap")
os.chmod(season / "locked.mcap", 0)
(season / "cut.mcap").write_bytes(sample.read_bytes()[:5000])
hour = time.time() - 3600
os.utime(season / "cut.mcap", (hour, hour))
(season / "empty.mcap").write_bytes(b"")
os.utime(season / "empty.mcap", (hour, hour))
out = season / "results"
problems = []


def batch(*extra, timeout=900):
    argv = [sys.executable, "-m", "pslog.cli", "batch", f"{season}/**/*.mcap", "--do",
            "sync,fuse,eval", "-o", out, "--workers", "2", *extra]
    return subprocess.run(argv, capture_output=True, text=True, env=ENV, timeout=timeout)


def check(done, label, codes=(0, 1)):
    lines = [x for x in done.stderr.splitlines() if x.strip()]
    print(f"{label}: exit {done.returncode}; stderr last: {lines[-1:]!r}")
    print("  stdout:", done.stdout.strip().splitlines()[:12])
    if "Traceback" in done.stderr or done.returncode not in codes:
        problems.append(f"{label}: exit {done.returncode} {done.stderr[-600:]!r}")


def sets() -> dict[str, str]:
    """Each session folder's state: complete (done.json and its outputs), none, or MIXED."""
    state = {}
    for marker in out.rglob("done.json"):
        folder = marker.parent
        names = {"synced.mcap", "fused.mcap", "eval.json"}
        have = {p.name for p in folder.iterdir()}
        state[str(folder.relative_to(out))] = "complete" if names <= have else f"MIXED {have}"
    for folder in out.rglob("*"):
        if folder.is_dir() and not (folder / "done.json").exists() and any(
                p.suffix in (".mcap", ".json") for p in folder.iterdir() if p.is_file()):
            state[str(folder.relative_to(out))] = f"NO-MARKER {[p.name for p in folder.iterdir()]}"
    return state


t0 = time.monotonic()
check(batch(), "first batch")
print(f"  {time.monotonic() - t0:.0f} s; summary:",
      (out / "summary.csv").read_text().splitlines()[:10] if (out / "summary.csv").exists()
      else None)
print("  sets:", sets())
# a second batch over the same folder with --force, SIGKILLed midway
proc = subprocess.Popen([sys.executable, "-m", "pslog.cli", "batch", f"{season}/**/*.mcap",
                         "--do", "sync,fuse,eval", "-o", out, "--workers", "2", "--force"],
                        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV,
                        start_new_session=True)
time.sleep(float(os.environ.get("KILL_AFTER", "25")))
os.killpg(proc.pid, signal.SIGKILL)
proc.wait()
time.sleep(3)
print("after SIGKILL: sets:", sets())
left = [str(p.relative_to(out)) for p in out.rglob("*") if ".partial" in p.name
        or p.name.startswith(".pslog-batch")]
print("  left:", left)
check(batch("--resume"), "resume")
print("  sets:", sets())
for folder, state in sets().items():
    if state != "complete":
        problems.append(f"{folder}: {state}")
# two patterns giving one name
both = subprocess.run([sys.executable, "-m", "pslog.cli", "batch", f"{season}/a/*.mcap",
                       f"{season}/b/*.mcap", "--do", "fuse", "-o", work / "other"],
                      capture_output=True, text=True, env=ENV, timeout=300)
check(both, "two patterns, one name", codes=(1,))
print("PROBLEMS:", problems or "none")
