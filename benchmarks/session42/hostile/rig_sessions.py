"""Sessions simulated with the hostile rigs ``rig check`` accepts (session 42, helper
hostile42): 1 and 20 cameras, 0.1 and 1e6 fps, a camera behind the scene, k1 = -0.9, unicode and
look-alike names, a rolling shutter of almost a frame... each simulated, then fused (every
method its timing suits) and synced.

Run: python benchmarks/session42/hostile/rig_sessions.py WORKDIR (after rigs.py, whose
WORKDIR/rigcases it reads; the labels are rigs.py's file numbers)."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

from _run import run

work = Path(sys.argv[1])
out = work / "rigsess"
out.mkdir(exist_ok=True)
tally: Counter = Counter()
for rig in sorted((work / "rigcases").glob("r*.toml")):
    if run("rig", "check", rig, timeout=60)[0] != "ok":
        continue
    s, f, y = out / f"{rig.stem}.mcap", out / f"{rig.stem}_f.mcap", out / f"{rig.stem}_y.mcap"
    steps = [("simulate", ["simulate", "--rig", rig, "--timing", "typeA", "--duration", "1",
                           "--noise-px", "0.3", "--seed", "71004", "-o", s, "--force"]),
             ("fuse", ["fuse", s, "-o", f, "--force"]),
             ("sync", ["sync", s, "-o", y, "--force"]),
             ("eval", ["eval", f])]
    for what, args in steps:
        kind, code, so, se = run(*args, timeout=300)
        tally[kind] += 1
        flag = "" if kind in ("ok", "ok-notes", "error1", "error2") else "  <<<<<"
        msg = (se.strip().splitlines() or [""])[-1][:140]
        print(f"{rig.stem} {what:8} {kind:9} {msg}{flag}", flush=True)
        if not kind.startswith("ok") and what == "simulate":
            break
print(dict(tally))
