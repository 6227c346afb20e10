"""Hostile probes of ``pslog import --detections CAMERA=FILE`` (one CSV per camera).

    python benchmarks/session40/hostile/probe_import.py BASE SCRATCH [CASE...]
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from harness import run_case

base, scratch = Path(sys.argv[1]), Path(sys.argv[2])
only = sys.argv[3:]
C1 = (base / "cam1.csv").read_text()
rows1 = C1.splitlines()
R = ["--rig", "paper3"]
D3 = ["--detections", "cam1=cam1.csv", "--detections", "cam2=cam2.csv",
      "--detections", "cam3=cam3.csv"]


def imp(*dets, out="o.mcap", extra=()):
    args = ["import", *R]
    for d in dets:
        args += ["--detections", d]
    return [*args, "-o", out, *extra]


def write(name, text):
    def setup(d):
        p = d / name
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            with open(p, "w", newline="") as f:
                f.write(text)
    return setup


def both(*setups):
    def setup(d):
        for s in setups:
            s(d)
    return setup


cases = [
    ("ok3", None, ["import", *R, *D3, "-o", "o.mcap"]),
    ("ok2_note", None, imp("cam1=cam1.csv", "cam2=cam2.csv")),
    ("one_named", None, imp("cam1=cam1.csv")),
    ("missing_file", None, imp("cam1=cam1.csv", "cam2=nope.csv")),
    ("empty_file", write("e.csv", ""), imp("cam1=cam1.csv", "cam2=e.csv")),
    ("header_only", write("e.csv", "time,u,v\n"), imp("cam1=cam1.csv", "cam2=e.csv")),
    ("bom_crlf", write("c.csv", "\ufeff" + "\r\n".join(rows1) + "\r\n"),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("tabs", write("c.csv", "\n".join(r.replace(",", "\t") for r in rows1)),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("quoted", write("c.csv", "\n".join(",".join(f'"{x}"' for x in r.split(","))
                                        for r in rows1)), imp("cam1=c.csv", "cam2=cam2.csv")),
    ("dup_header", write("c.csv", "time,u,v,u\n" + "\n".join(r.rsplit(",", 2)[0] + ",1"
                                                           for r in rows1[1:])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("extra_col", write("c.csv", "time,u,v,note\n" + "\n".join(
        ",".join(r.split(",")[:3]) + ",x" for r in rows1[1:])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("neg_pixel", write("c.csv", "\n".join([*rows1[:3], "0.9,-5,-7,99,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("nan_pixel", write("c.csv", "\n".join([*rows1[:3], "0.9,nan,5,99,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("1e308_pixel", write("c.csv", "\n".join([*rows1[:3], "0.9,1e308,5,99,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("nan_time", write("c.csv", "\n".join([*rows1[:3], "nan,5,5,99,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("1e308_time", write("c.csv", "\n".join([*rows1[:3], "1e308,5,5,99,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("time_span_huge", write("c.csv", "\n".join([*rows1[:3], "-9e9,5,5,99,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("out_of_order", write("c.csv", "\n".join([rows1[0], *rows1[1:][::-1]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("dup_rows", write("c.csv", C1 + "\n".join(rows1[1:])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("dup_time_diff_frame", write("c.csv", "\n".join(
        [*rows1[:3], rows1[2].split(",")[0] + ",5,5,77,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("unknown_camera", None, imp("cam1=cam1.csv", "cam9=cam2.csv")),
    ("case_camera", None, imp("cam1=cam1.csv", "CAM2=cam2.csv")),
    ("space_camera", None, imp("cam1=cam1.csv", " cam2=cam2.csv")),
    ("empty_camera", None, imp("cam1=cam1.csv", "=cam2.csv")),
    ("empty_path", None, imp("cam1=cam1.csv", "cam2=")),
    ("same_camera_twice", None, imp("cam1=cam1.csv", "cam1=cam2.csv")),
    ("same_file_twice", None, imp("cam1=cam1.csv", "cam2=cam1.csv")),
    ("same_file_dotslash", None, imp("cam1=cam1.csv", "cam2=./cam1.csv")),
    ("same_file_symlink", lambda d: os.symlink("cam1.csv", d / "l.csv"),
     imp("cam1=cam1.csv", "cam2=l.csv")),
    ("same_file_hardlink", lambda d: os.link(d / "cam1.csv", d / "h.csv"),
     imp("cam1=cam1.csv", "cam2=h.csv")),
    ("eq_in_path", lambda d: os.rename(d / "cam2.csv", d / "a=b.csv"),
     imp("cam1=cam1.csv", "cam2=a=b.csv")),
    ("eq_in_path_alone", write("a=b.csv", (base / "det.csv").read_text()), imp("a=b.csv")),
    ("eq_in_path_alone_missing", None, imp("x=b.csv")),
    ("cam_eq_in_path_alone", write("cam1=b.csv", (base / "det.csv").read_text()),
     imp("cam1=b.csv")),
    ("mixed_named_unnamed", None, imp("cam1=cam1.csv", "det.csv")),
    ("two_unnamed", None, imp("cam1.csv", "cam2.csv")),
    ("directory", lambda d: os.mkdir(d / "dir"), imp("cam1=cam1.csv", "cam2=dir")),
    ("fifo", lambda d: os.mkfifo(d / "p.csv"), imp("cam1=cam1.csv", "cam2=p.csv")),
    ("dev_zero", None, imp("cam1=cam1.csv", "cam2=/dev/zero")),
    ("binary", write("b.csv", os.urandom(5000)), imp("cam1=cam1.csv", "cam2=b.csv")),
    ("mcap", None, imp("cam1=cam1.csv", "cam2=s.mcap")),
    ("det_with_camera_col", None, imp("cam1=det.csv", "cam2=cam2.csv")),
    ("camera_col_matches", write("c.csv", "camera," + rows1[0] + "\n" + "\n".join(
        "cam1," + r for r in rows1[1:])), imp("cam1=c.csv", "cam2=cam2.csv")),
    ("camera_col_case", write("c.csv", "camera," + rows1[0] + "\n" + "\n".join(
        "CAM1," + r for r in rows1[1:])), imp("cam1=c.csv", "cam2=cam2.csv")),
    ("truncated", write("c.csv", C1[: len(C1) // 2 + 5]), imp("cam1=c.csv", "cam2=cam2.csv")),
    ("ms_times", write("c.csv", "\n".join([rows1[0]] + [
        f"{float(r.split(',')[0]) * 1000!r},{r.partition(',')[2]}" for r in rows1[1:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("unix_one_camera", write("c.csv", "\n".join([rows1[0]] + [
        f"{1764860000 + float(r.split(',')[0])!r},{r.partition(',')[2]}" for r in rows1[1:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("only_missed_frames", write("c.csv", "time,u,v\n0.0,,\n0.0333,,\n0.0666,,\n"),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("all_missed_both", both(write("a.csv", "time,u,v\n0.0,,\n0.0333,,\n"),
                             write("b.csv", "time,u,v\n0.01,,\n0.0433,,\n")),
     imp("cam1=a.csv", "cam2=b.csv")),
    ("output_is_input", None, imp("cam1=cam1.csv", "cam2=cam2.csv", out="cam1.csv")),
    ("output_symlink_input", lambda d: os.symlink("cam1.csv", d / "o.mcap"),
     imp("cam1=cam1.csv", "cam2=cam2.csv", out="o.mcap", extra=["--force"])),
    ("output_hardlink_input", lambda d: os.link(d / "cam1.csv", d / "o.mcap"),
     imp("cam1=cam1.csv", "cam2=cam2.csv", out="o.mcap", extra=["--force"])),
    ("output_is_rig?", None, imp("cam1=cam1.csv", "cam2=cam2.csv", out="s.mcap")),
    ("output_exists", None, imp("cam1=cam1.csv", "cam2=cam2.csv", out="f.mcap")),
    ("output_exists_force", None, imp("cam1=cam1.csv", "cam2=cam2.csv", out="f.mcap",
                                      extra=["--force"])),
    ("output_dir", None, imp("cam1=cam1.csv", "cam2=cam2.csv", out="tum")),
    ("output_in_missing_dir", None, imp("cam1=cam1.csv", "cam2=cam2.csv", out="no/o.mcap")),
    ("output_devfull", None, imp("cam1=cam1.csv", "cam2=cam2.csv", out="/dev/full")),
    ("output_ro_dir", lambda d: os.makedirs(d / "ro") or os.chmod(d / "ro", 0o555),
     imp("cam1=cam1.csv", "cam2=cam2.csv", out="ro/o.mcap")),
    ("output_proc", None, imp("cam1=cam1.csv", "cam2=cam2.csv", out="/proc/o.mcap")),
    ("bad_then_good_force", None, imp("cam1=cam1.csv", "cam2=s.mcap", out="f.mcap",
                                      extra=["--force"])),
    ("timing_preset", None, imp("cam1=cam1.csv", "cam2=cam2.csv", extra=["--timing", "sync"])),
    ("huge_field", write("c.csv", "time,u,v\n" + "1" * 200000 + ",5,5\n"),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("score_out_of_range", write("c.csv", "\n".join([*rows1[:3], "0.9,5,5,99,1.5", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("frame_negative", write("c.csv", "\n".join([*rows1[:3], "0.9,5,5,-1,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("frame_float", write("c.csv", "\n".join([*rows1[:3], "0.9,5,5,3.0,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("frame_huge", write("c.csv", "\n".join(
        [*rows1[:3], "0.9,5,5,99999999999999999999,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("u_only", write("c.csv", "\n".join([*rows1[:3], "0.9,5,,99,1", *rows1[3:]])),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("long_header", write("c.csv", ",".join(f"c{k}" for k in range(50000)) + "\n"),
     imp("cam1=c.csv", "cam2=cam2.csv")),
    ("rig_missing", None, ["import", "--rig", "nope.toml", "--detections", "cam1=cam1.csv",
                           "-o", "o.mcap"]),
    ("detections_missing_arg", None, ["import", *R, "-o", "o.mcap"]),
    ("utf16", write("c.csv", C1.encode("utf-16")), imp("cam1=c.csv", "cam2=cam2.csv")),
    ("nul", write("c.csv", C1.replace("0.0333", "0.03\x0033")), imp("cam1=c.csv", "cam2=cam2.csv")),
]
for name, setup, args in cases:
    if only and name not in only:
        continue
    run_case(base, scratch, name, setup, args)
