"""Hostile probes of ``pslog eval --truth FILE`` (session 40's new surface).

    python benchmarks/session40/hostile/probe_truth.py BASE SCRATCH
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from harness import run_case

base, scratch = Path(sys.argv[1]), Path(sys.argv[2])
only = sys.argv[3:]
TRUTH = (base / "truth.csv").read_text()
TUM = (base / "tum" / "truth.tum").read_text()
rows = TRUTH.splitlines()


def write(name, text, mode="w"):
    def setup(d):
        p = d / name
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            with open(p, mode, newline="") as f:
                f.write(text)
    return setup


def mm(text):
    out = [text.splitlines()[0]]
    for r in text.splitlines()[1:]:
        t, *xyz = r.split(",")
        out.append(",".join([t, *(repr(float(v) * 1000) for v in xyz)]))
    return "\n".join(out) + "\n"


cases = [
    ("missing", None, ["eval", "f.mcap", "--truth", "nope.csv"]),
    ("empty_csv", write("t.csv", ""), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("empty_tum", write("t.tum", ""), ["eval", "f.mcap", "--truth", "t.tum"]),
    ("blank_lines", write("t.csv", "\n\n  \n"), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("header_only", write("t.csv", "t,x,y,z\n"), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("bom_crlf", write("t.csv", "\ufeff" + "\r\n".join(rows) + "\r\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("cr_only", write("t.csv", "\r".join(rows) + "\r"), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("tabs_tsv", write("t.tsv", "\n".join(r.replace(",", "\t") for r in rows) + "\n"),
     ["eval", "f.mcap", "--truth", "t.tsv"]),
    ("tabs_csv", write("t.csv", "\n".join(r.replace(",", "\t") for r in rows) + "\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("semicolons", write("t.csv", "\n".join(r.replace(",", ";") for r in rows) + "\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("decimal_commas", write("t.csv", "\n".join(
        ";".join(c.replace(".", ",") for c in r.split(",")) for r in rows) + "\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("quoted", write("t.csv", "\n".join(",".join(f'"{c}"' for c in r.split(","))
                                        for r in rows) + "\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("dup_header", write("t.csv", "t,x,y,z,x\n" + "\n".join(r + ",0" for r in rows[1:])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("extra_cols", write("t.csv", "id,t,x,y,z,note\n" + "\n".join(
        f"{k},{r},hi" for k, r in enumerate(rows[1:]))), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("upper_header", write("t.csv", "T,X,Y,Z\n" + "\n".join(rows[1:])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("spaces_header", write("t.csv", " t , x , y , z \n" + "\n".join(rows[1:])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("nan_pos", write("t.csv", "\n".join([*rows[:5], "0.5,nan,0,1", *rows[5:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("inf_pos", write("t.csv", "\n".join(
        [*rows[:5], rows[5].rsplit(",", 1)[0] + ",inf", *rows[6:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("huge_pos_one", write("t.csv", "\n".join(
        [*rows[:5], rows[5].rsplit(",", 1)[0] + ",1e308", *rows[6:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("huge_pos_all", write("t.csv", "\n".join([rows[0]] + [r.split(",")[0] + ",1e308,1e308,1e308"
                                                           for r in rows[1:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("huge_pos_json", write("t.csv", "\n".join(
        [*rows[:5], rows[5].rsplit(",", 1)[0] + ",1e308", *rows[6:]])),
     ["eval", "f.mcap", "--truth", "t.csv", "--json"]),
    ("neg_pos", write("t.csv", "\n".join([rows[0]] + [r.split(",")[0] + ",-1,-2,-3"
                                                      for r in rows[1:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("nan_time", write("t.csv", "\n".join([*rows[:5], "nan,0,0,1", *rows[5:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("inf_time", write("t.csv", "\n".join([*rows[:5], "-inf,0,0,1", *rows[5:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("1e308_time", write("t.csv", "\n".join([*rows, "1e308,0,0,1"])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("huge_exp_time", write("t.csv", "\n".join([*rows, "1e999999999999,0,0,1"])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("unordered", write("t.csv", "\n".join([rows[0], rows[3], rows[2], *rows[4:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("duplicated", write("t.csv", "\n".join([*rows[:4], rows[3], *rows[4:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("one_sample", write("t.csv", "\n".join(rows[:2])), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("two_samples", write("t.csv", "\n".join(rows[:3])), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("outside", write("t.csv", "t,x,y,z\n100,0,0,1\n101,0,0,1\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("in_mm", write("t.csv", mm(TRUTH)), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("time_ms", write("t.csv", "\n".join([rows[0]] + [
        f"{float(r.split(',')[0]) * 1000!r},{r.partition(',')[2]}" for r in rows[1:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("short_row", write("t.csv", "\n".join([*rows[:5], "0.5,1,2", *rows[5:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("empty_cell", write("t.csv", "\n".join([*rows[:5], "0.5,1,,2", *rows[5:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("units_in_cells", write("t.csv", "\n".join([*rows[:5], "0.05s,1m,2m,1m", *rows[5:]])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("truncated", write("t.csv", TRUTH[: len(TRUTH) // 2 + 7]),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("binary", write("t.csv", os.urandom(4096)), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("nul_bytes", write("t.csv", b"t,x,y,z\n0,0\x00,0,1\n1,0,0,1\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("zeros_file", write("t.dat", b"\x00" * 100000), ["eval", "f.mcap", "--truth", "t.dat"]),
    ("mcap_as_truth", None, ["eval", "f.mcap", "--truth", "s.mcap"]),
    ("json", write("t.json", '{"t": [0, 1]}'), ["eval", "f.mcap", "--truth", "t.json"]),
    ("detections_csv", None, ["eval", "f.mcap", "--truth", "det.csv"]),
    ("tracks_csv_many", None, ["eval", "f.mcap", "--truth", "tracks.csv"]),
    ("directory", None, ["eval", "f.mcap", "--truth", "tum"]),
    ("fifo", lambda d: os.mkfifo(d / "t.csv"), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("dev_null", None, ["eval", "f.mcap", "--truth", "/dev/null"]),
    ("dev_zero", None, ["eval", "f.mcap", "--truth", "/dev/zero"]),
    ("dangling_link", lambda d: os.symlink("gone.csv", d / "t.csv"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("eq_in_path", write("a=b.csv", TRUTH), ["eval", "f.mcap", "--truth", "a=b.csv"]),
    ("eq_truth_arg", write("t.csv", TRUTH), ["eval", "f.mcap", "--truth=t.csv"]),
    ("dash_path", write("-t.csv", TRUTH), ["eval", "f.mcap", "--truth", "-t.csv"]),
    ("tum_ok", None, ["eval", "f.mcap", "--truth", "tum/truth.tum"]),
    ("tum_7fields", write("t.tum", "\n".join(" ".join(r.split()[:7]) if not r.startswith("#")
                                             else r for r in TUM.splitlines())),
     ["eval", "f.mcap", "--truth", "t.tum"]),
    ("tum_commas", write("t.tum", "\n".join(",".join(r.split()) if not r.startswith("#")
                                            else r for r in TUM.splitlines())),
     ["eval", "f.mcap", "--truth", "t.tum"]),
    ("tum_crlf_bom", write("t.tum", "\ufeff" + TUM.replace("\n", "\r\n")),
     ["eval", "f.mcap", "--truth", "t.tum"]),
    ("tum_tabs", write("t.tum", TUM.replace(" ", "\t")), ["eval", "f.mcap", "--truth", "t.tum"]),
    ("csv_as_tum_suffix", write("t.tum", TRUTH), ["eval", "f.mcap", "--truth", "t.tum"]),
    ("tum_as_csv_suffix", write("t.csv", TUM), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("unfused_session", None, ["eval", "s.mcap", "--truth", "truth.csv"]),
    ("method_missing", None, ["eval", "f.mcap", "--truth", "truth.csv", "--method", "typeB"]),
    ("method_one", None, ["eval", "f.mcap", "--truth", "truth.csv", "--method", "typeA"]),
    ("ok_json", None, ["eval", "f.mcap", "--truth", "truth.csv", "--json"]),
    ("ok", None, ["eval", "f.mcap", "--truth", "truth.csv"]),
    ("underscore_time", write("t.csv", "\n".join([*rows[:3], "0_0.5,0,0,1"])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("sub_ns_dup", write("t.csv", "t,x,y,z\n0.0000000001,0,0,1\n0.0000000002,0,0,1\n1,0,0,1\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("quoted_newline", write("t.csv", 't,x,y,z\n"0.1\n",0,0,1\n1,0,0,1\n'),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("unterminated_quote", write("t.csv", 't,x,y,z\n"0.1,0,0,1\n1,0,0,1\n'),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("latin1", write("t.csv", "t,x,y,z # caf\xe9\n".encode("latin-1") + TRUTH.partition("\n")[2]
                     .encode()), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("utf16", write("t.csv", TRUTH.encode("utf-16")), ["eval", "f.mcap", "--truth", "t.csv"]),
    ("huge_field", write("t.csv", "t,x,y,z\n" + "1" * 200000 + ",0,0,1\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("long_header", write("t.csv", ",".join(f"c{k}" for k in range(100000)) + "\n"),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("partial_overlap", write("t.csv", "\n".join(rows[:20])),
     ["eval", "f.mcap", "--truth", "t.csv"]),
    ("all_nan_tracks?", None, ["eval", "s.mcap", "--truth", "tum/truth.tum"]),
]


def tracks_csv(d):
    import subprocess
    subprocess.run([sys.executable, "-m", "pslog.cli", "export", "f.mcap", "--csv",
                    "tracks.csv"], cwd=d, check=True, capture_output=True)


cases = [(n, tracks_csv if n == "tracks_csv_many" else s, a) for n, s, a in cases]
for name, setup, args in cases:
    if only and name not in only:
        continue
    run_case(base, scratch, name, setup, args)
