"""Hostile ``pslog import --columns`` values and headers (session 41, helper hostile41).

Run: python benchmarks/session41/hostile/columns.py WORKDIR (a det.csv exported from a
simulated paper3 session in WORKDIR)."""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

from _run import run

work = Path(sys.argv[1])
rows = (work / "det.csv").read_text().splitlines()
body = rows[1:]


def csv_with(header: str, name: str, per_camera: str | None = None) -> Path:
    path = work / name
    lines = [r for r in body if per_camera is None or r.startswith(per_camera + ",")]
    if per_camera is not None:  # drop the camera column
        lines = [r.partition(",")[2] for r in lines]
    import csv
    import io
    width = len(next(csv.reader(io.StringIO(header))))
    lines = [",".join(r.split(",")[:width]) for r in lines]
    path.write_text(header + "\n" + "\n".join(lines) + "\n", encoding="utf-8")
    return path


cases = []
lab = csv_with("cam,t_unix,px,py,frame_id,conf", "lab.csv")
ok_map = "camera=cam,time=t_unix,u=px,v=py,frame=frame_id,score=conf"
cases += [
    ("plain", lab, ok_map),
    ("duplicate name", lab, "time=t_unix,time=px"),
    ("two names one column", lab, "u=px,v=px"),
    ("same pair twice", lab, "u=px,u=px"),
    ("empty", lab, ""),
    ("comma alone", lab, ","),
    ("trailing comma", lab, ok_map + ","),
    ("leading comma", lab, "," + ok_map),
    ("empty name", lab, "=px"),
    ("empty column", lab, "time="),
    ("spaces", lab, " camera = cam , time = t_unix ,u=px,v=py"),
    ("no eq", lab, "time"),
    ("unknown name", lab, "x=px"),
    ("name case", lab, "Time=t_unix"),
    ("column absent", lab, "time=T_UNIX"),
    ("column with newline", lab, "time=t\nunix"),
    ("column with invalid utf8", lab, "time=t\udcffunix"),
    ("huge value", lab, "time=" + "x" * 100000),
    ("quoted column arg", lab, 'time="t_unix"'),
    ("identity", csv_with("camera,time,u,v,frame,score", "plain.csv"), "time=time"),
    ("swap", csv_with("camera,time,v,u,frame,score", "swap.csv"), "u=v,v=u"),
    ("rename onto existing", csv_with("camera,time,t_unix,u,v", "both.csv")
     if False else lab, "frame=cam"),
]
uni = csv_with("kamera,tëmps,ü,v̈,frame,score", "uni.csv")
cases += [("unicode", uni, "camera=kamera,time=tëmps,u=ü,v=v̈")]
nfd = csv_with("camera,te\u0301mps,u,v", "nfd.csv")
cases += [("unicode NFC vs NFD", nfd, "time=t\u00e9mps")]
eqh = csv_with("camera,t=unix,u,v", "eq.csv")
cases += [("= inside column", eqh, "time=t=unix")]
commah = csv_with('camera,"t,unix",u,v', "comma.csv")
cases += [("comma inside column", commah, "time=t,unix"),
          ("comma inside column, unmatched quote", commah, 'time="t,unix'),
          ("comma inside column quoted", commah, 'time="t,unix"')]
quoted = csv_with('"cam","t_unix","px","py"', "quoted.csv")
cases += [("quoted header", quoted, "camera=cam,time=t_unix,u=px,v=py")]
nlh = csv_with('camera,"t\nunix",u,v', "nl.csv")
cases += [("newline inside header column", nlh, "time=nothere"),
          ("newline inside header, mapped", nlh, "time=t\nunix")]
dup = csv_with("camera,time,t_unix,u,v", "dup.csv")
cases += [("map onto a column already named so", dup, "time=t_unix")]
dup2 = csv_with("camera,t_unix,t_unix,u,v", "dup2.csv")
cases += [("header column twice, mapped", dup2, "time=t_unix")]
bom = work / "bom.csv"
bom.write_bytes(b"\xef\xbb\xbf" + lab.read_bytes())
cases += [("BOM header", bom, ok_map)]
tab = work / "tab.csv"
tab.write_text(lab.read_text().replace(",", "\t"))
cases += [("tab separated", tab, ok_map)]
space = csv_with("cam, t_unix , px ,py", "space.csv")
cases += [("header with spaces", space, "camera=cam,time=t_unix,u=px,v=py")]

results = Counter()
for label, path, mapping in cases:
    args = ["import", "--rig", "paper3", "--detections", path, "--columns", mapping,
            "-o", work / "out.mcap", "--force"]
    kind, code, out, err = run(*args)
    results[kind] += 1
    print(f"[{kind}] {label}: {err.strip()[:300] or out.strip()[:150]!r}")
# per camera files
pc = {c: csv_with("t_unix,px,py,frame_id,conf", f"{c}.csv", per_camera=c)
      for c in ("cam1", "cam2", "cam3")}
for label, mapping, extra in [
        ("per camera", "time=t_unix,u=px,v=py,frame=frame_id,score=conf", {}),
        ("per camera, camera mapped", "camera=cam,time=t_unix,u=px,v=py", {}),
        ("per camera, one file lacks", "time=t_unix,u=px,v=py,frame=frame_id,score=conf",
         {"cam3": csv_with("t_unix,px,py", "cam3b.csv", per_camera="cam3")}),
]:
    files = {**pc, **extra}
    args = ["import", "--rig", "paper3", "--columns", mapping, "-o", work / "out.mcap",
            "--force"]
    for c, p in files.items():
        args += ["--detections", f"{c}={p}"]
    kind, code, out, err = run(*args)
    results[kind] += 1
    print(f"[{kind}] {label}: {err.strip()[:300] or out.strip()[:150]!r}")
print(dict(results), sum(results.values()))
