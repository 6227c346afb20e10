"""Hostile numeric option values (session 42, helper hostile42): nan, inf, -0, 1e308, negative,
empty, Unicode digits, subnormals, hex, underscores... for every numeric option of simulate,
fuse, sync, view, record, calibrate-free commands (calibrate's are in calib.py).

Run: python benchmarks/session42/hostile/numeric_options.py WORKDIR [PREFIX...] (WORKDIR
holds s.mcap, a simulated typeA session, and f.mcap, its fused copy). Prints one line per
run; a flagged line (<<<<<) is a traceback, a hang, a multi-line error or a bad exit code.
An 'ok' line shows the command's first output line, to judge whether the value should have
been taken."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

from _run import run

work = Path(sys.argv[1])
out = work / "num"
out.mkdir(exist_ok=True)
VALUES = ["nan", "inf", "-inf", "-0", "0", "-1", "1e308", "-1e308", "1e-320", "", " ",
          "\u0663", "\uff11", "0x10", "1_0", "+2", "2 ", "9" * 400, "1e", "true", "NaN"]
S, F = work / "s.mcap", work / "f.mcap"
sim = ["simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.5", "--seed", "71003",
       "-o", out / "sim.mcap", "--force"]
fuse = ["fuse", S, "--method", "typeA", "-o", out / "fu.mcap", "--force"]
sync = ["sync", S, "-o", out / "sy.mcap", "--force"]
view = ["view", F, "--headless", "--method", "typeA", "--save", out / "v.rrd", "--force"]
plans: list[tuple[str, list, str]] = []
for opt in ["--duration", "--rest", "--noise-px", "--jitter-ms", "--drop-rate", "--miss-rate",
            "--host-jitter", "--spurious", "--spurious-radius", "--seed", "--readout"]:
    plans.append((f"simulate {opt}", sim, opt + "={}"))
for opt, tpl in [("--clock-offset", "cam2={}"), ("--drift", "cam2={}"), ("--readout", "cam2={}"),
                 ("--distractor", "cam2={},1,1"), ("--blackout", "cam2={}:0.1"),
                 ("--blackout", "cam2=0.1:{}")]:
    plans.append((f"simulate {opt} {tpl}", sim, opt + "=" + tpl))
for opt in ["--tolerance-ms", "--max-gap-ms", "--rate", "--noise-px", "--detector-offset-mm",
            "--detector-bias-px", "--type-a-max-std-mm", "--workers"]:
    plans.append((f"fuse {opt}", fuse, opt + "={}"))
plans.append(("sync --search-ms", sync, "--search-ms={}"))
for opt, tpl in [("--start", "{}"), ("--end", "{}"), ("--thin-every", "{}"), ("--detail", "{}"),
                 ("--detail", "0:{}"), ("--frames", "every:{}"), ("--connect-timeout", "{}")]:
    plans.append((f"view {opt} {tpl}", view, opt + "=" + tpl))
plans.append(("batch --workers", ["batch", S, "--do", "eval", "-o", out / "batch", "--force"],
              "--workers={}"))
plans.append(("demo --duration", ["demo", "--out", out / "demo", "--force"], "--duration={}"))

only = sys.argv[2:]
tally: Counter = Counter()
for label, base, tpl in plans:
    if only and not any(label.startswith(o) for o in only):
        continue
    for value in VALUES:
        kind, code, so, se = run(*base, tpl.format(value), timeout=120)
        tally[kind] += 1
        flag = "" if kind in ("ok", "ok-notes", "error1", "error2") else "  <<<<<"
        text = se if kind != "ok" else so
        msg = (text.strip().splitlines() or [""])[-1 if kind != "ok" else 0][:150]
        print(f"{label:32} {value[:8]!r:11} {kind:9} {msg}{flag}", flush=True)
print(dict(tally))
