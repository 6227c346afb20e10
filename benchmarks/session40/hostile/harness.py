"""A tiny runner for the hostile40 probes: each case a command line run as a real process
(``python -m pslog.cli``) in a fresh copy of the base folder; prints exit code, stderr's
line count and first line, and flags tracebacks, several lines and changed inputs."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path


def digest(folder: Path) -> dict[str, str]:
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def run_case(base: Path, scratch: Path, name: str, setup, args, expect=None, timeout=300,
             show_out=False):
    folder = scratch / name
    if folder.exists():
        shutil.rmtree(folder)
    shutil.copytree(base, folder, symlinks=True)
    if setup is not None:
        setup(folder)
    before = digest(folder)
    env = {**os.environ, "PSLOG_PROGRESS": "off"}
    t0 = time.monotonic()
    try:
        proc = subprocess.run([sys.executable, "-m", "pslog.cli", *map(str, args)], cwd=folder,
                              capture_output=True, text=True, env=env, timeout=timeout)
        code, out, err = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired:
        code, out, err = "TIMEOUT", "", ""
    dt = time.monotonic() - t0
    after = digest(folder)
    changed = [k for k in before if after.get(k) != before[k]]
    lines = [x for x in err.splitlines() if x.strip()]
    flags = []
    if "Traceback" in err or "Traceback" in out:
        flags.append("TRACEBACK")
    if code not in (0, "TIMEOUT") and len(lines) != 1:
        flags.append(f"{len(lines)}LINES")
    if changed:
        flags.append(f"CHANGED:{changed}")
    if expect is not None and code != expect:
        flags.append(f"EXPECTED{expect}")
    first = lines[0] if lines else (out.strip().splitlines() or [""])[-1 if show_out else 0]
    mark = "!!" if flags else "  "
    print(f"{mark} {name:40s} exit {code} {dt:5.1f}s {' '.join(flags)}\n     {first[:400]}",
          flush=True)
    if show_out:
        print("     OUT:", out.strip()[:600].replace("\n", "\n          "))
    if "TRACEBACK" in flags:
        print("     " + err[-1500:].replace("\n", "\n     "))
    return code, out, err
