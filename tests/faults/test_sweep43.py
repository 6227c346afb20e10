"""Session 43's items left by walk42 and hostile42, the faults a user makes: through the real
CLI, each case asserting the promises (one line naming the value, the exit code, nothing
written).

``simulate --readout cam2=5 --readout cam2=8`` simulated 8 ms, silently (``--clock-offset``,
``--drift`` and ``rig import --offset`` refuse a camera given twice); ``--readout cam2=5
--readout 8`` gave cam2 8 ms, and in the other order 5: now each camera once, a camera's own
value over MS alone in any order. ``--hsv -5,22,...`` (a negative hue, or any value of the
box starting with ``-``) said "argument --hsv: expected one argument", not the value: a
``-`` then a digit is now a value to every pslog command (Python 3.13's rule), and the box's
range check names it.
"""

from __future__ import annotations

import json

import pytest

from pslog.log import read_session

from .promises import assert_refused, run_pslog


@pytest.mark.parametrize(("given", "said"), [
    (("cam2=5", "cam2=8"), "camera cam2 given twice (5, 8)"),
    (("cam2=5", "cam2=5"), "camera cam2 given twice (5, 5)"),
    (("5", "cam3=2", "8"), "a readout for every camera (MS alone) given twice (5, 8)"),
])
def test_simulate_refuses_a_readout_given_twice(tmp_path, given, said):
    args = [a for g in given for a in ("--readout", g)]
    assert_refused(tmp_path, 2, ["simulate", "--rig", "paper3", "--duration", "0.3", *args,
                                 "-o", "s.mcap"], contains=("argument --readout: " + said))


@pytest.mark.parametrize("order", [("cam2=5", "8"), ("8", "cam2=5")])
def test_a_cameras_readout_wins_over_every_cameras_in_any_order(tmp_path, order):
    out = tmp_path / "s.mcap"
    args = [a for g in order for a in ("--readout", g)]
    run = run_pslog("simulate", "--rig", "paper3", "--duration", "0.3", "--seed", "75010",
                    *args, "-o", out)
    assert run.code == 0, run.stderr
    clock = json.loads(read_session(out).metadata["truth_clock"])["cameras"]
    assert {n: c["readout"] for n, c in clock.items()} == {"cam1": 0.008, "cam2": 0.005,
                                                           "cam3": 0.008}


@pytest.mark.parametrize(("command", "box", "said"), [
    ("record", "-5,22,120,255,70,255", "HSV hmin must be an integer in 0..179, got -5"),
    ("live", "-5,22,120,255,70,255", "HSV hmin must be an integer in 0..179, got -5"),
    ("redetect", "-1,22,120,255,70,255", "HSV hmin must be an integer in 0..179, got -1"),
    ("record", "4,22,-120,255,70,255", "HSV smin must be an integer in 0..255, got -120"),
    ("record", "4,180,120,255,70,255", "HSV hmax must be an integer in 0..179, got 180"),
    ("record", "4,22,120,255,70,256", "HSV vmax must be an integer in 0..255, got 256"),
])
def test_an_hsv_box_out_of_range_is_named(tmp_path, command, box, said):
    tail = {"record": ["--synthetic", "--rig", "paper3", "-o", "s.mcap"],
            "live": ["--synthetic", "--rig", "paper3", "--duration", "1"],
            "redetect": ["s.mcap", "-o", "r.mcap"]}[command]
    assert_refused(tmp_path, 2, [command, *tail, "--hsv", box],
                   contains=f"argument --hsv: {said}")


@pytest.mark.parametrize("order", ["csv first", "tum first"])
def test_export_output_inside_a_tum_folder_not_made_yet(tmp_path, order):
    """``export --csv tum/x.csv --tum tum`` with no folder ``tum``: "output folder does not
    exist: tum" (the user named it to be made): now said, in either order, nothing written."""
    run = run_pslog("simulate", "--rig", "paper2", "--duration", "0.3", "--seed", "75020",
                    "-o", tmp_path / "s.mcap")
    assert run.code == 0, run.stderr
    pair = [["--csv", "tum/x.csv"], ["--tum", "tum"]]
    args = [a for p in (pair if order == "csv first" else pair[::-1]) for a in p]
    assert_refused(tmp_path, 1, ["export", "s.mcap", *args], contains=(
        "output tum/x.csv: its folder tum does not exist; --tum tum makes it, but only its "
        "own files"))


def test_c3d_beyond_what_its_frame_count_holds_is_refused(tmp_path):
    """Two throws 190,000 s apart (53 hours at 90 Hz: 17.1 million frames, beyond the 2**24 a
    float32 POINT:LONG_FRAMES counts exactly): refused in one line naming the frames and the
    formats that keep every point, nothing written (up to 2**24 a C3D is written, its count
    in the parameters: tests/test_export_paths_and_c3d.py)."""
    from decimal import Decimal

    burst = tmp_path / "burst.mcap"
    for args in (["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                  "--duration", "1", "--seed", "75072", "-o", burst],
                 ["export", burst, "--detections", tmp_path / "d.csv"]):
        run = run_pslog(*args)
        assert run.code == 0, run.stderr
    (tmp_path / "rig.toml").write_text(run_pslog("rig", "show", burst).stdout)
    lines = (tmp_path / "d.csv").read_text().splitlines()
    late = []
    for line in lines[1:]:
        cells = line.split(",")
        cells[1] = str(Decimal(cells[1]) + 190_000)
        cells[4] = str(int(cells[4]) + 190_000 * 30)
        late.append(",".join(cells))
    (tmp_path / "long.csv").write_text("\n".join(lines + late) + "\n")
    for args in (["import", "--rig", tmp_path / "rig.toml", "--detections",
                  tmp_path / "long.csv", "-o", tmp_path / "s.mcap"],
                 ["fuse", tmp_path / "s.mcap", "--method", "typeA", "-o", tmp_path / "f.mcap"]):
        run = run_pslog(*args)
        assert run.code == 0, run.stderr
    assert_refused(tmp_path, 1, ["export", "f.mcap", "--c3d", "t.c3d"], contains=(
        "frames at 90 Hz: beyond the 16777216 frames a C3D file counts exactly",
        "export --csv, --jsonl or --parquet"))
