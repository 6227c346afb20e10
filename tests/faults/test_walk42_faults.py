"""Session 42's walkthrough (walk42), the faults a user made: through the real CLI on real
files, each case asserting the three promises (one line, exit code, nothing written).

Found and fixed: `pslog import` of a detector's own CSV (`cam_id,t_unix,x_px,y_px,frame_no,
conf`) without `--columns` said "bad header ... (unknown: ...) (missing: ...)" and not a word
of `--columns`, the option made for it; the line now names it with the missing columns.
"""

from __future__ import annotations

import pytest

from .promises import assert_one_line_error, run_pslog

_ROWS = "cam1,1780000000.000000,320.5,240.25,0,0.9\ncam2,1780000000.011100,300.0,200.0,0,0.8\n"


@pytest.mark.parametrize(("header", "hint"), [
    ("cam_id,t_unix,x_px,y_px,frame_no,conf",
     "--columns camera=COLUMN,time=COLUMN,u=COLUMN,v=COLUMN"),
    ("camera,t_unix,u,v,frame,score", "--columns time=COLUMN"),
])
def test_import_of_a_detectors_own_header_names_columns(tmp_path, header, hint):
    path = tmp_path / "detector.csv"
    path.write_text(header + "\n" + _ROWS)
    out = tmp_path / "lab.mcap"
    run = run_pslog("import", "--rig", "paper3", "--detections", path, "-o", out)
    assert_one_line_error(run, 1, contains=("bad header", hint))
    assert not out.exists() and not list(tmp_path.glob("lab.mcap*"))
