"""Hostile ``pslog eval --truth`` files, CSV and TUM (session 42, helper hostile42): unsorted,
duplicated times, NaN, one row, empty, header only, huge, wrong column counts, times far
outside the session.

Run: python benchmarks/session42/hostile/truth.py WORKDIR (WORKDIR holds f.mcap, a fused
simulated session, and tum/truth.tum exported from it)."""

from __future__ import annotations

import hashlib
import sys
from collections import Counter
from pathlib import Path

from _run import run

work = Path(sys.argv[1])
out = work / "truth"
out.mkdir(exist_ok=True)
tum = [x for x in (work / "tum" / "truth.tum").read_text().splitlines() if not x.startswith("#")]
csvrows = [",".join(x.split()[:4]) for x in tum]
H = "t,x,y,z"


def w(name, text):
    p = out / name
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    return p


def both(label, rows, header=H):
    """(label, csv path), (label, tum path) from CSV-style rows 't,x,y,z[,...]'."""
    c = w(label.replace(" ", "_") + ".csv", "\n".join(([header] if header else []) + rows) + "\n")
    t = w(label.replace(" ", "_") + ".tum",
          "\n".join(r.replace(",", " ") for r in rows) + "\n")
    return [(label + " csv", c), (label + " tum", t)]


def shift(rows, dt=0.0, scale=1.0):
    out_rows = []
    for r in rows:
        c = r.split(",")
        out_rows.append(",".join([repr(float(c[0]) * scale + dt), *c[1:]]))
    return out_rows


cases = []
cases += both("ok", csvrows)
cases += both("reversed", csvrows[::-1])
cases += both("swapped two", [csvrows[1], csvrows[0], *csvrows[2:]])
cases += both("dup time", [csvrows[0], csvrows[0], *csvrows[1:]])
cases += both("dup time diff pos", [csvrows[0], csvrows[0].rsplit(",", 1)[0] + ",9", *csvrows[1:]])
cases += both("nan row", [csvrows[0], csvrows[1].split(",")[0] + ",nan,nan,nan", *csvrows[2:]])
cases += both("nan one", [csvrows[0], csvrows[1].split(",")[0] + ",nan,1,1", *csvrows[2:]])
cases += both("nan time", ["nan,1,1,1", *csvrows[1:]])
cases += both("inf time", ["inf,1,1,1", *csvrows[1:]])
cases += both("-inf time", ["-inf,1,1,1", *csvrows[1:]])
cases += both("all nan", [r.split(",")[0] + ",nan,nan,nan" for r in csvrows])
cases += both("one row", csvrows[:1])
cases += both("two rows", csvrows[:2])
cases += both("empty", [], header="")
cases += both("header only", [])
cases += both("wrong cols 3", [r.rsplit(",", 1)[0] for r in csvrows])
cases += both("wrong cols ragged", [csvrows[0] + ",1,2", *csvrows[1:]])
cases += both("wrong cols 9", [r + ",0,0,0,1,7" for r in csvrows])
cases += both("far future", shift(csvrows, 1e9))
cases += both("far past", shift(csvrows, -1e9))
cases += both("1e18 s", shift(csvrows, 1e18))
cases += both("1e300 s", shift(csvrows, 1e300))
cases += both("negative", shift(csvrows, -5.0))
cases += both("partial overlap", shift(csvrows, 1.0))
cases += both("ns precision+", [r.split(",")[0] + "0000000001," + r.split(",", 1)[1]
                                for r in csvrows])
cases += both("time e-notation", [repr(float(r.split(",")[0])) .replace(".", "") + "e-9," +
                                  r.split(",", 1)[1] for r in csvrows])
cases += both("unicode digits", ["\u0661" + r for r in csvrows])
cases += both("-0 time", ["-0," + csvrows[0].split(",", 1)[1], *csvrows[1:]])
cases += both("huge position", [r.split(",")[0] + ",1e307,1e307,1e307" for r in csvrows])
cases += both("text", [csvrows[0], "abc,1,2,3", *csvrows[1:]])
cases += both("empty cells", [csvrows[0], ",,,", *csvrows[1:]])
cases += both("time only empty", [csvrows[0], ",1,2,3", *csvrows[1:]])
cases += both("very long line", ["1" * 2_000_000 + ",0,0,0", *csvrows])
cases += both("many rows", csvrows + [repr(2.0 + i * 1e-6) + ",1,1,1" for i in range(2_000_000)])
cases += both("tiny step", [repr(i * 1e-10) + ",1,1,1" for i in range(1000)])
cases.append(("header spaces csv", w("hs.csv", " t , x , y , z \n" + "\n".join(csvrows) + "\n")))
cases.append(("header dup csv", w("hd.csv", "t,x,y,z,x\n" + "\n".join(r + ",5" for r in csvrows)
                                   + "\n")))
cases.append(("header upper csv", w("hu.csv", "T,X,Y,Z\n" + "\n".join(csvrows) + "\n")))
cases.append(("tum tabs", w("tabs.tum", "\n".join(x.replace(" ", "\t") for x in tum) + "\n")))
cases.append(("tum commas", w("commas.tum", "\n".join(x.replace(" ", ",") for x in tum) + "\n")))
cases.append(("tum double spaces", w("dbl.tum", "\n".join(x.replace(" ", "  ") for x in tum)
                                     + "\n")))
cases.append(("tum leading spaces", w("lead.tum", "\n".join("  " + x for x in tum) + "\n")))
cases.append(("tum only comments", w("com.tum", "# a\n# b\n")))
cases.append(("tum crlf", w("crlf.tum", "\r\n".join(tum) + "\r\n")))
cases.append(("tum bom", w("bom.tum", "\ufeff" + "\n".join(tum) + "\n")))
cases.append(("tum nul", w("nul.tum", "\0".join(tum))))
cases.append(("binary .tum", w("bin.tum", bytes(range(256)) * 10)))
cases.append(("binary .csv", w("bin.csv", bytes(range(256)) * 10)))
cases.append(("no suffix", w("truth", "\n".join(tum) + "\n")))
cases.append(("txt suffix csv", w("truth.txt", H + "\n" + "\n".join(csvrows) + "\n")))
cases.append(("session as truth", work / "s.mcap"))
cases.append(("folder", out))
cases.append(("dev null", Path("/dev/null")))

only = set(sys.argv[2:])
tally: Counter = Counter()
for label, path in cases:
    if only and label not in only:
        continue
    before = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None
    kind, code, so, se = run("eval", work / "f.mcap", "--method", "typeA", "--truth", path,
                             timeout=120)
    after = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None
    if before != after:
        kind = "MODIFIED"
    tally[kind] += 1
    flag = "" if kind in ("ok", "ok-notes", "error1", "error2") else "  <<<<<"
    msg = (se.strip().splitlines() or [""])[-1][:170]
    if kind == "ok":
        msg = " | ".join(x for x in so.splitlines() if "typeA" in x)[:170]
    print(f"{label:26} {kind:9} {msg}{flag}", flush=True)
print(dict(tally))
