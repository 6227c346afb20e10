"""Hostile outputs (session 42, helper hostile42): an output that is an input through a
symbolic link, a hard link or a ``./`` spelling (also two outputs of one ``export`` naming one
file), an output into an immutable folder (``chattr +i``: root ignores chmod), and a full disk
(a 2 MB tmpfs, as root) for fuse, export, view --save, sync, import, rig import/export:
is the old output intact, nothing half-written left, the message one line?

Run as root: python benchmarks/session42/hostile/outputs.py WORKDIR (WORKDIR holds s.mcap,
f.mcap, det.csv, rig.toml, a.toml as README's commands make them)."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from collections import Counter
from pathlib import Path

from _run import run

work = Path(sys.argv[1])
base = work / "outs"
shutil.rmtree(base, ignore_errors=True)
base.mkdir()
for name in ("s.mcap", "f.mcap", "det.csv", "rig.toml", "a.toml"):
    shutil.copy(work / name, base / name)
tally: Counter = Counter()


def tree(folder: Path) -> dict[str, str]:
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def case(label: str, folder: Path, *args, expect_ok=False):
    before = tree(folder)
    kind, _code, _so, se = run(*args, timeout=120, cwd=folder)
    after = tree(folder)
    changed = [k for k in before if after.get(k) != before[k]]
    added = [k for k in after if k not in before]
    notes = []
    if changed and not expect_ok:
        notes.append(f"CHANGED {changed}")
    if any(".partial" in k for k in added):
        notes.append(f"PARTIAL {added}")
    flag = "" if kind in ("ok", "ok-notes", "error1", "error2") and not notes else "  <<<<<"
    if kind.startswith("ok") and not expect_ok:
        flag = "  (accepted?)"
    tally[kind] += 1
    msg = (se.strip().splitlines() or [""])[-1][:150]
    print(f"{label:40} {kind:9} {' '.join(notes)} {msg}{flag}", flush=True)


# ---- an input as output, in other spellings ----------------------------------------------
os.symlink("s.mcap", base / "link.mcap")
os.link(base / "s.mcap", base / "hard.mcap")
os.symlink("rig.toml", base / "rlink.toml")
os.link(base / "rig.toml", base / "rhard.toml")
os.link(base / "det.csv", base / "dhard.csv")
sub = base / "sub"
sub.mkdir()
for spelling in ("link.mcap", "hard.mcap", "./s.mcap", "sub/../s.mcap", str(base / "s.mcap")):
    case(f"fuse -o {spelling}", base, "fuse", "s.mcap", "--method", "typeA", "-o", spelling,
         "--force")
    case(f"sync -o {spelling}", base, "sync", "s.mcap", "-o", spelling, "--force")
    case(f"recover -o {spelling}", base, "recover", "s.mcap", "-o", spelling, "--force")
    case(f"import -o {spelling}", base, "import", "--rig", "paper3", "--timing", "typeA",
         "--detections", "det.csv", "-o", spelling, "--force")
case("fuse --rig link, -o its mcap", base, "fuse", "s.mcap", "--rig", "link.mcap", "-o",
     "hard.mcap", "--force")
for spelling in ("rlink.toml", "rhard.toml", "./rig.toml"):
    case(f"rig import rig.toml -o {spelling}", base, "rig", "import", "rig.toml", "-o", spelling,
         "--force")
    case(f"rig export rig.toml -o {spelling}", base, "rig", "export", "rig.toml", "--format",
         "anipose", "-o", spelling, "--force")
case("rig import a.toml -o a.toml", base, "rig", "import", "a.toml", "-o", "./a.toml", "--force")
case("export --csv det hardlink", base, "export", "f.mcap", "--detections", "dhard.csv",
     "--force", expect_ok=True)
case("export two outputs one file", base, "export", "f.mcap", "--csv", "x.csv", "--detections",
     "./x.csv", "--force")
os.symlink("y.csv", base / "ylink.csv")
case("export two outputs via link", base, "export", "f.mcap", "--csv", "y.csv", "--detections",
     "ylink.csv", "--force")
case("export --csv into --tum dir", base, "export", "f.mcap", "--tum", "tum", "--csv",
     "tum/x.csv", "--force", expect_ok=True)
case("view --save link to session", base, "view", "f.mcap", "--headless", "--save",
     "link.mcap", "--force")
os.symlink("f.mcap", base / "flink.rrd")
case("view --save .rrd link to session", base, "view", "f.mcap", "--headless", "--method",
     "typeA", "--save", "flink.rrd", "--force")
case("calibrate --rig link", base, "calibrate", "--points", "det.csv", "--name", "cam1",
     "--rig", "link.mcap")
case("simulate -o link to rig", base, "simulate", "--rig", "rlink.toml", "-o", "rlink.toml",
     "--force")
os.symlink("s.mcap", base / "slink.toml")
case("rig export session -o link to it", base, "rig", "export", "s.mcap", "--format",
     "anipose", "-o", "slink.toml", "--force")

# ---- an immutable folder --------------------------------------------------------------------
frozen = base / "frozen"
frozen.mkdir()
shutil.copy(work / "f.mcap", frozen / "old.mcap")
subprocess.run(["chattr", "+i", str(frozen)], check=True)
subprocess.run(["chattr", "+i", str(frozen / "old.mcap")], check=True)
try:
    for label, args in [
        ("fuse", ["fuse", "s.mcap", "--method", "typeA", "-o", "frozen/n.mcap"]),
        ("fuse over immutable", ["fuse", "s.mcap", "--method", "typeA", "-o", "frozen/old.mcap",
                                 "--force"]),
        ("sync", ["sync", "s.mcap", "-o", "frozen/n.mcap"]),
        ("import", ["import", "--rig", "paper3", "--detections", "det.csv", "-o",
                    "frozen/n.mcap"]),
        ("export csv", ["export", "f.mcap", "--csv", "frozen/n.csv"]),
        ("export tum", ["export", "f.mcap", "--tum", "frozen/tum"]),
        ("export parquet+csv", ["export", "f.mcap", "--parquet", "frozen/n.parquet", "--csv",
                                "n.csv"]),
        ("view --save", ["view", "f.mcap", "--headless", "--method", "typeA", "--save",
                         "frozen/n.rrd"]),
        ("rig import", ["rig", "import", "a.toml", "-o", "frozen/n.toml"]),
        ("rig export", ["rig", "export", "rig.toml", "--format", "opencv", "-o",
                        "frozen/n.yml"]),
        ("calibrate new rig", ["calibrate", "--points", str(Path(__file__).resolve().parents[3]
                                                            / "samples/cam1_points.csv"),
                               "--name", "cam1", "--width", "640", "--height", "480", "--rig",
                               "frozen/n.toml"]),
        ("simulate", ["simulate", "--rig", "paper3", "-o", "frozen/n.mcap"]),
        ("recover", ["recover", "s.mcap", "-o", "frozen/n.mcap"]),
        ("redetect", ["redetect", "s.mcap", "-o", "frozen/n.mcap"]),
    ]:
        case(f"immutable: {label}", base, *args)
finally:
    subprocess.run(["chattr", "-i", str(frozen / "old.mcap")], check=True)
    subprocess.run(["chattr", "-i", str(frozen)], check=True)

# ---- a full disk --------------------------------------------------------------------------
small = base / "small"
small.mkdir()
subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(small)], check=True)
try:
    olds = {"f.mcap": ["fuse", "s.mcap", "--method", "typeA", "-o", "small/f.mcap", "--force"],
            "sy.mcap": ["sync", "s.mcap", "-o", "small/sy.mcap", "--force"],
            "i.mcap": ["import", "--rig", "paper3", "--timing", "typeA", "--detections",
                       "det.csv", "-o", "small/i.mcap", "--force"],
            "t.csv": ["export", "f.mcap", "--csv", "small/t.csv", "--force"],
            "v.rrd": ["view", "f.mcap", "--headless", "--method", "typeA", "--save",
                      "small/v.rrd", "--force"],
            "r.toml": ["rig", "import", "a.toml", "-o", "small/r.toml", "--force"],
            "e.yml": ["rig", "export", "rig.toml", "--format", "opencv", "-o", "small/e.yml",
                      "--force"]}
    for out, args in olds.items():  # the old outputs, complete, while there is room
        kind, code, so, se = run(*args, timeout=120, cwd=base)
        assert kind.startswith("ok"), (out, se)
    used = sum(p.stat().st_size for p in small.iterdir())
    for left in (0, 4096, 60000):
        filler = small / "filler"
        filler.unlink(missing_ok=True)
        st = os.statvfs(small)
        free = st.f_bavail * st.f_frsize
        if free > left:
            with open(filler, "wb") as f:
                try:
                    f.write(b"\0" * (free - left))
                except OSError:
                    pass
        for out, args in olds.items():
            case(f"full ({left} B free): {' '.join(args[:1])} -> {out}", base, *args)
        filler.unlink(missing_ok=True)
finally:
    subprocess.run(["umount", str(small)], check=True)
print(dict(tally))
