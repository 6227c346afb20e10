"""``pslog import --columns``: a detector's own column names read as pslog's (walk40: a lab's
``frame_id,t_unix,px,py,conf`` had to be renamed by hand, its ``conf`` refused)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from pslog import read_session
from pslog.cli import main


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A simulated session's detections as pslog writes them, and as a lab's detector would:
    other names, another column order."""
    d = tmp_path_factory.mktemp("cols")
    session = d / "sim.mcap"
    assert main(["simulate", "--rig", "paper3", "--motion", "rally", "--duration", "2",
                 "--spurious", "0.1", "--seed", "61900", "-o", str(session)]) == 0
    ours = d / "det.csv"
    assert main(["export", str(session), "--detections", str(ours)]) == 0
    with ours.open(newline="") as f:
        rows = list(csv.reader(f))
    names = {"camera": "cam", "time": "t_unix", "u": "px", "v": "py", "frame": "frame_id",
             "score": "conf"}
    header = rows[0]
    order = list(reversed(range(len(header))))
    lab = d / "lab.csv"
    with lab.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow([names[header[i]] for i in order])
        w.writerows([row[i] for i in order] for row in rows[1:])
    return d, ours, lab, ",".join(f"{k}={v}" for k, v in names.items() if k in header)


def _detections(path):
    det = read_session(path).detections
    return (det.frame_time_ns, det.frame_camera, det.frame_index, det.cand_frame, det.cand_uv,
            det.cand_score)


def test_a_detectors_own_names_import_as_pslogs(exported):
    d, ours, lab, mapping = exported
    assert main(["import", "--rig", "paper3", "--detections", str(ours), "-o",
                 str(d / "a.mcap")]) == 0
    assert main(["import", "--rig", "paper3", "--detections", str(lab), "--columns", mapping,
                 "-o", str(d / "b.mcap")]) == 0
    for x, y in zip(_detections(d / "a.mcap"), _detections(d / "b.mcap"), strict=True):
        np.testing.assert_array_equal(x, y)
    # without --columns the lab's names are refused, naming them
    assert main(["import", "--rig", "paper3", "--detections", str(lab), "-o",
                 str(d / "c.mcap")]) == 1


@pytest.mark.parametrize(("columns", "said"), [
    ("time", "'time' is not NAME=COLUMN"),
    ("speed=px", "'speed' is not a detections column"),
    ("time=t_unix,time=t", "'time' given twice"),
    ("u=px,v=px", "'px' given twice"),
])
def test_a_malformed_mapping_is_a_command_line_error(exported, capsys, columns, said):
    d, _, lab, _ = exported
    assert main(["import", "--rig", "paper3", "--detections", str(lab), "--columns", columns,
                 "-o", str(d / "bad.mcap")]) == 2
    err = capsys.readouterr().err
    assert said in err and len(err.strip().splitlines()) == 1, err
    assert not (d / "bad.mcap").exists()


def test_a_mapped_column_the_file_lacks_is_named(exported, capsys):
    d, _, lab, mapping = exported
    assert main(["import", "--rig", "paper3", "--detections", str(lab), "--columns",
                 mapping.replace("conf", "confidence"), "-o", str(d / "bad.mcap")]) == 1
    err = capsys.readouterr().err
    assert "no column 'confidence' (--columns score=confidence)" in err, err
    assert len(err.strip().splitlines()) == 1
