"""Hostile ``pslog calibrate`` inputs (session 42, helper hostile42): point CSVs (too few,
coplanar, duplicated, NaN, text, huge values...), chessboard options out of range, image folders
holding non-images, empty and special files.

Run: python benchmarks/session42/hostile/calib.py WORKDIR (WORKDIR holds rig.toml; the points
are samples/cam1_points.csv of the tree)."""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from collections import Counter
from pathlib import Path

from _run import TREE, run

work = Path(sys.argv[1]) / "calib"
shutil.rmtree(work, ignore_errors=True)
work.mkdir()
good = (TREE / "samples" / "cam1_points.csv").read_text().splitlines()
head, rows = good[0], good[1:]


def pts(name: str, lines: list[str] | str | bytes) -> Path:
    p = work / f"{name}.csv"
    if isinstance(lines, bytes):
        p.write_bytes(lines)
    else:
        p.write_text(lines if isinstance(lines, str) else "\n".join(lines) + "\n")
    return p


def sub(i: int, col: int, value: str) -> list[str]:
    out = list(rows)
    cells = out[i].split(",")
    cells[col] = value
    out[i] = ",".join(cells)
    return [head, *out]


coplanar = [head] + [f"{x},{y},0,{100 + 40 * x + 3 * y},{200 + 30 * y + x}"
                     for x in range(4) for y in range(4)]
cases = {
    "ok": pts("ok", good),
    "5 points": pts("five", good[:6]),
    "6 points": pts("six", good[:7]),
    "0 points": pts("zero", [head]),
    "empty": pts("empty", ""),
    "coplanar": pts("coplanar", coplanar),
    "collinear": pts("collinear", [head] + [f"{i},0,0,{100 + 10 * i},200" for i in range(12)]),
    "all same": pts("same", [head] + [rows[0]] * 12),
    "duplicates": pts("dup", [head, *rows, *rows]),
    "dup 3D diff px": pts("dup3d", [head, *rows, rows[0].rsplit(",", 2)[0] + ",1,1"]),
    "nan x": pts("nanx", sub(0, 0, "nan")),
    "inf u": pts("infu", sub(0, 3, "inf")),
    "text": pts("text", sub(0, 1, "two")),
    "empty cell": pts("emptycell", sub(0, 2, "")),
    "1e308 x": pts("huge", sub(0, 0, "1e308")),
    "1e300 all": pts("hugeall", [head] + [",".join("1e300" for _ in range(5))] * 12),
    "1e20 u": pts("hugeu", sub(0, 3, "1e20")),
    "-0": pts("negzero", sub(0, 0, "-0")),
    "unicode digit": pts("unidigit", sub(0, 0, "\u0663")),
    "fullwidth": pts("fullwidth", sub(0, 0, "\uff13")),
    "underscore num": pts("underscore", sub(0, 3, "4_56.96")),
    "hex": pts("hex", sub(0, 3, "0x1c8")),
    "extra col": pts("extra", [head + ",w", *(r + ",1" for r in rows)]),
    "missing col": pts("missing", [head, *rows[:-1], rows[-1].rsplit(",", 1)[0]]),
    "no header": pts("nohead", rows),
    "bad header": pts("badhead", ["a,b,c,d,e", *rows]),
    "header order": pts("order", ["u,v,x,y,z", *(",".join(r.split(",")[3:] + r.split(",")[:3])
                                                   for r in rows)]),
    "BOM": pts("bom", "\ufeff" + "\n".join(good) + "\n"),
    "CRLF": pts("crlf", "\r\n".join(good) + "\r\n"),
    "semicolon": pts("semi", [x.replace(",", ";") for x in good]),
    "quoted": pts("quoted", [head, *('"' + r.replace(",", '","') + '"' for r in rows)]),
    "blank lines": pts("blank", [head, "", *rows, "", ""]),
    "comment": pts("comment", ["# survey", *good]),
    "binary": pts("binary", bytes(range(256)) * 8),
    "latin1": pts("latin1", ("x,y,z,u,v\n# caf\xe9\n" + "\n".join(rows)).encode("latin-1")),
    "nul": pts("nul", "\0".join(good)),
    "behind camera": pts("behind", [head] + [f"{-x},{-y},{-z},{u},{v}" for x, y, z, u, v in
                                            (map(float, r.split(",")) for r in rows)]),
    "px outside": pts("outside", [head] + [f"{x},{y},{z},{float(u) + 5000},{v}" for x, y, z, u, v
                                          in (r.split(",") for r in rows)]),
    "100k points": pts("many", [head] + rows * 7000),
    "long line": pts("longline", [head, "1" * 2_000_000 + ",0,0,0,0", *rows]),
}
dev = {"folder": work, "fifo": work / "f.csv", "/dev/zero": Path("/dev/zero")}
os.mkfifo(dev["fifo"])
rig_src = Path(sys.argv[1]) / "rig.toml"
only = set(sys.argv[2:])
tally: Counter = Counter()


def digest(p: Path):
    return hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else None


def show(label, kind, code, err):
    tally[kind] += 1
    flag = "" if kind in ("ok", "ok-notes", "error1", "error2") else "  <<<<<"
    print(f"{label:28} {kind:9} {(err.strip().splitlines() or [''])[-1][:160]}{flag}",
          flush=True)


runs = []
for label, path in {**cases, **dev}.items():
    for mode in ("new", "existing", "fix"):
        if mode == "new":
            args = ["--width", "640", "--height", "480", "--rig", work / "new.toml"]
            (work / "new.toml").unlink(missing_ok=True)
        else:
            shutil.copy(rig_src, work / "rig.toml")
            args = ["--rig", work / "rig.toml"] + (["--fix-intrinsics"] if mode == "fix" else [])
        runs.append((f"{label}/{mode}", ["calibrate", "--points", path, "--name", "cam1",
                                         *args, "--force"], path))
# option values
for opt, vals in {"--width": ["0", "-1", "nan", "1e308", "65537", "", "٦٤٠", "640.0", "1_000"],
                  "--fps": ["0", "-30", "nan", "inf", "1e308", "", "３０", "-0"],
                  "--offset": ["-0.001", "nan", "inf", "1", "-0", "", "1e-400"]}.items():
    for v in vals:
        extra = ["--height", "480"] + (["--width", "640"] if opt != "--width" else [])
        runs.append((f"{opt}={v!r}", ["calibrate", "--points", cases["ok"], "--name", "cam1",
                                      opt, v, *extra, "--rig", work / "o.toml", "--force"], None))
for name in ["", " cam1", "a,b", "a\nb", "a\u2028b", "x" * 65, "cam\u200b1", "-cam1"]:
    runs.append((f"--name={name!r}", ["calibrate", "--points", cases["ok"], "--name", name,
                                      "--width", "640", "--height", "480", "--rig",
                                      work / "n.toml", "--force"], None))
# chessboard
imgs = work / "imgs"
imgs.mkdir()
(imgs / "zero.png").write_bytes(b"")
(imgs / "text.png").write_text("not an image\n")
(imgs / "readme.txt").write_text("hello\n")
(imgs / "dir.png").mkdir()
os.mkfifo(imgs / "fifo.png")
(imgs / "gone.png").symlink_to(imgs / "nothing.png")
(imgs / "half.png").write_bytes(bytes.fromhex("89504e470d0a1a0a0000000d49484452") + b"\0" * 20)
empty_dir = work / "emptyimgs"
empty_dir.mkdir()
for board in ["9x6", "0x0", "1x1", "2x2", "-3x4", "3x4.5", "9x6x2", "9*6", "x", "", "nan x nan",
              "١x٢", "100000x2", "3x3"]:
    runs.append((f"board={board!r}", ["calibrate", "--chessboard", board, "--images", imgs,
                                      "--name", "cam1", "--rig", work / "c.toml", "--force"],
                 None))
for sq in ["0", "-0.025", "nan", "inf", "1e-5", "2", "", "1e308"]:
    runs.append((f"square={sq!r}", ["calibrate", "--chessboard", "9x6", "--square", sq,
                                    "--images", imgs, "--name", "cam1", "--rig", work / "c.toml",
                                    "--force"], None))
for mf in ["0", "-1", "nan", "1e308", "", "99999999999999999999"]:
    runs.append((f"max-frames={mf!r}", ["calibrate", "--chessboard", "9x6", "--images", imgs,
                                        "--max-frames", mf, "--name", "cam1", "--rig",
                                        work / "c.toml", "--force"], None))
for label, where in [("imgs empty dir", empty_dir), ("imgs a file", imgs / "readme.txt"),
                     ("imgs zero png", imgs / "zero.png"), ("imgs fifo", imgs / "fifo.png"),
                     ("imgs missing", work / "nope"), ("imgs /dev/zero", Path("/dev/zero")),
                     ("imgs text video", imgs / "text.png")]:
    runs.append((label, ["calibrate", "--chessboard", "9x6", "--images", where, "--name",
                         "cam1", "--rig", work / "c.toml", "--force"], None))
runs.append(("chessboard without images", ["calibrate", "--chessboard", "9x6", "--name", "cam1",
                                           "--rig", work / "c.toml"], None))

for label, args, watched in runs:
    if only and not any(label.startswith(o) for o in only):
        continue
    before = digest(watched) if watched else None
    kind, code, so, se = run(*args, timeout=120)
    if watched and digest(watched) != before:
        kind = "MODIFIED"
    left = [p.name for p in work.rglob("*.partial*")]
    if left:
        kind += "+PARTIAL"
    show(label, kind, code, se)
print(dict(tally))
