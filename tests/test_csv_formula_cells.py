"""Session 43: camera names a spreadsheet would run as formulas (``=1+2``, ``-cam1``,
``@cam3``: CSV injection) are written to every CSV with a ``'`` before them, as OWASP
advises (they were written as they are), and ``pslog import`` reads them back as the rig's
names: through the real CLI on a real rig and session."""

from __future__ import annotations

import csv

from _cli import pslog_ok

from pslog.batch import read_summary_csv, write_summary
from pslog.log.csvio import csv_text, csv_text_read

_NAMES = {"cam1": "-cam1", "cam2": "=1+2", "cam3": "@cam3"}


def _rig(tmp_path):
    text = pslog_ok("rig", "show", "paper3")
    for old, new in _NAMES.items():
        text = text.replace(f'name = "{old}"', f'name = "{new}"', 1)
    path = tmp_path / "rig.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _text_cells(path, columns):
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    return [row[c] for row in rows for c in columns]


def test_formula_camera_names_are_quoted_in_csv_and_read_back(tmp_path):
    rig = _rig(tmp_path)
    session, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    pslog_ok("simulate", "--rig", rig, "--duration", "0.4", "--seed", "75001", "-o", session)
    pslog_ok("fuse", session, "--method", "sync", "-o", fused)
    det, tracks = tmp_path / "det.csv", tmp_path / "tracks.csv"
    pslog_ok("export", fused, "--csv", tracks, "--detections", det)
    cells = _text_cells(det, ["camera"]) + _text_cells(tracks, ["camera", "method"])
    assert cells and not [c for c in cells if c.startswith(("=", "+", "-", "@"))]
    assert {f"'{n}" for n in _NAMES.values()} == set(_text_cells(det, ["camera"]))
    # export -> import -> export: the same cameras, the same file
    again, det2 = tmp_path / "i.mcap", tmp_path / "det2.csv"
    pslog_ok("import", "--rig", rig, "--detections", det, "-o", again)
    pslog_ok("export", again, "--detections", det2)
    assert det2.read_bytes() == det.read_bytes()


def test_quoting_gives_every_text_back():
    for text in ("cam1", "-x", "=1+2", "@a", "+b", "'=x", "''-y", "'a", "x=1", ""):
        assert csv_text_read(csv_text(text)) == text
        assert not csv_text(text).startswith(("=", "+", "-", "@"))


def test_batch_summary_quotes_formula_sessions_and_cameras(tmp_path):
    rows = [{"session": "=HYPERLINK(1).mcap", "status": "ok", "error": "", "cameras": "-a b",
             "-a_offset_ms": 1.5, "runtime_s": -0.25}]
    (path,) = (p for p in write_summary(rows, tmp_path) if p.suffix == ".csv")
    text = path.read_text(encoding="utf-8")
    assert "'=HYPERLINK(1).mcap" in text and "'-a b" in text and ",'-a_offset_ms" in text
    assert ",-0.25" in text  # a number as it is
    (row,) = read_summary_csv(path)
    assert row["session"] == "=HYPERLINK(1).mcap" and row["-a_offset_ms"] == "1.5"
