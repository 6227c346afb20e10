"""Camera names that YAML, XML, JSON or TOML could take for something else, through ``rig
export`` and ``rig import`` in every format (session 42, helper hostile42): does each name come
back as it was? ("1", "null", "true", "a: b", "#x", "&a", "*a", "!!str", "<x>", "a&b", "'",
"é", " x" is refused by pslog itself...)

Run: python benchmarks/session42/hostile/name_roundtrip.py WORKDIR"""

from __future__ import annotations

import sys
import tomllib
from collections import Counter
from pathlib import Path

from _run import run

work = Path(sys.argv[1]) / "names"
work.mkdir(parents=True, exist_ok=True)
base = run("rig", "show", "paper3")[2]
NAMES = ["1", "0x10", "1e3", "null", "~", "true", "yes", "NO", "a: b", "a:b", "#x", "x #y",
         "&a", "*a", "!!str", "!x", "%x", "@x", "`x", "<x>", "a&b", "a<b", "]]>", "'", "a'b",
         "{x}", "[x]", "- x", "? x", "|", ">", "x\\y", "é", "cafe\u0301", "日本", "😀", "a\u00a0b",
         "---", "...", "=x", "x=y", "\u200b", "a b", "opencv_storage", "camera_1", "data",
         "rows", "dt"]
tally: Counter = Counter()
for fmt, suffix in [("anipose", ".toml"), ("pose2sim", ".toml"), ("opencv", ".yml"),
                    ("opencv", ".xml"), ("opencv", ".json")]:
    for i, name in enumerate(NAMES):
        rig_text = base.replace('name = "cam2"', "name = " + _q if (
            _q := '"' + name.replace("\\", "\\\\").replace('"', '\\"') + '"') else "", 1)
        rig = work / f"r{i}.toml"
        rig.write_text(rig_text, encoding="utf-8")
        if run("rig", "check", rig)[0] != "ok":
            print(f"{name!r:16} refused by rig check")
            continue
        out = work / f"e{i}{suffix}"
        kind, code, so, se = run("rig", "export", rig, "--format", fmt, "-o", out, "--force")
        if kind != "ok":
            tally[kind] += 1
            print(f"{fmt}{suffix} {name!r:16} export {kind} {se.strip()[-150:]}")
            continue
        back = work / f"b{i}.toml"
        kind, code, so, se = run("rig", "import", out, "-o", back, "--force")
        if kind != "ok":
            tally["import " + kind] += 1
            print(f"{fmt}{suffix} {name!r:16} import {kind} {se.strip()[-150:]}  <<<<<")
            continue
        names = [c["name"] for c in tomllib.loads(back.read_text(encoding="utf-8"))["camera"]]
        same = names[1] == name
        tally["same" if same else "CHANGED"] += 1
        if not same:
            print(f"{fmt}{suffix} {name!r:16} came back as {names[1]!r}  <<<<<")
print(dict(tally))
