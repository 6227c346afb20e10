"""Session 40: three gaps session 39's walkthrough (two cameras, one's own detector's CSVs)
left, through ``pslog`` on files it writes.

- ``pslog eval --truth FILE``: a truth of one's own (motion capture, a measured path), CSV
  ``t,x,y,z`` on the original clock (as ``export --csv`` writes times) or TUM on the session
  clock (as ``export --tum`` writes ``truth.tum``), scored as the session's own truth.
- ``pslog import --detections CAMERA=FILE ...``: one CSV per camera, the session the same as
  from the joined CSV.
- ``check_pattern`` takes a numpy array, ``pslog.fuse`` a numpy bool.
"""

from __future__ import annotations

import csv
import json
from decimal import Decimal

import numpy as np
import pytest

#: seconds added to every time of a simulated session's CSV: Unix-epoch stamps (walk39's)
UNIX_S = Decimal("1764860000.25")


@pytest.fixture
def cli(capsys):
    """Run ``pslog ARGS...`` in-process (pslog.cli.main); returns (exit code, stdout,
    stderr), a command-line error's SystemExit (argparse's, exit 2) as its exit code."""
    from pslog.cli import main

    def run(*args) -> tuple[int, str, str]:
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        captured = capsys.readouterr()
        return code, captured.out, captured.err

    return run


def _ok(cli, *argv) -> str:
    code, out, err = cli(*argv)
    assert code == 0, err
    return out


def _one_line_error(cli, code, *argv) -> str:
    """Run a command that must fail with ``code``: one line on stderr, no traceback."""
    got, out, err = cli(*argv)
    assert got == code, (got, out, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err.strip()


@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    """A simulated rally (type A, false candidates, misses) fused with the default methods:
    (folder, fused session)."""
    from pslog.cli import main

    folder = tmp_path_factory.mktemp("items40")
    raw, fused = folder / "sim.mcap", folder / "fused.mcap"
    assert main(["simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
                 "--duration", "3", "--noise-px", "0.3", "--spurious", "0.1", "--miss-rate",
                 "0.05", "--seed", "61001", "-o", str(raw)]) == 0
    assert main(["fuse", str(raw), "-o", str(fused)]) == 0
    return folder, fused


def _write_truth_csv(path, times_ns, positions, header=("t", "x", "y", "z"), add_s=0):
    from pslog.log.csvio import format_time

    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(header)
        for t, (x, y, z) in zip(times_ns.tolist(), positions.tolist(), strict=True):
            out.writerow([str(Decimal(format_time(t)) + add_s), repr(x), repr(y), repr(z)])


def test_eval_truth_file_scores_as_the_sessions_own_truth(cli, fused):
    from pslog.log import read_session

    folder, session = fused
    own = json.loads(_ok(cli, "eval", session, "--json"))
    assert own and all(row["n_points"] > 0 for row in own)
    # the truth as export --tum writes it (session clock), read back: the same figures to
    # the bit (times exact to the ns, positions repr: the truth's samples are the capture
    # times, so nothing is interpolated differently)
    _ok(cli, "export", session, "--tum", folder / "traj")
    tum = json.loads(_ok(cli, "eval", session, "--truth", folder / "traj" / "truth.tum",
                         "--json"))
    assert tum == own
    # a CSV t,x,y,z of it (the original clock is the session clock here)
    truth = read_session(session).truth
    _write_truth_csv(folder / "truth.csv", truth.time_ns, truth.position_world)
    text = _ok(cli, "eval", session, "--truth", folder / "truth.csv")
    assert text.splitlines()[0].startswith(
        f"truth: {folder / 'truth.csv'} (CSV, original clock = session clock): "
        f"{len(truth)} samples, "), text
    assert text.splitlines()[0].endswith("; the session's own truth not used"), text
    assert json.loads(_ok(cli, "eval", session, "--truth", folder / "truth.csv",
                          "--json")) == own
    # TUM without the .tum suffix (the TUM RGB-D benchmark's groundtruth.txt), no comment
    tum_lines = (folder / "traj" / "truth.tum").read_text().splitlines()[1:]
    (folder / "groundtruth.txt").write_text("\n".join(tum_lines) + "\n")
    assert json.loads(_ok(cli, "eval", session, "--truth", folder / "groundtruth.txt",
                          "--json")) == own
    # a tracks CSV of one method (export --csv's rows of smooth, its quality columns
    # ignored) as the truth of the others: its own track scores 0 against itself
    _ok(cli, "export", session, "--csv", folder / "tracks.csv")
    with open(folder / "tracks.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    method = rows[0].index("method")
    with open(folder / "smooth.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([rows[0], *(r for r in rows[1:] if r[method] == "smooth")])
    self_scored = json.loads(_ok(cli, "eval", session, "--truth", folder / "smooth.csv",
                                 "--method", "smooth", "--json"))
    assert self_scored[0]["max_mm"] == 0.0 and self_scored[0]["n_points"] > 0
    # every third sample left out: interpolated between the others, the figures within
    # the interpolation's error (the ball's path bends little over 1/30 s; the bounces')
    _write_truth_csv(folder / "sparse.csv", truth.time_ns[::3], truth.position_world[::3],
                     header=("time", "x", "y", "z"))
    sparse = json.loads(_ok(cli, "eval", session, "--truth", folder / "sparse.csv", "--json"))
    for a, b in zip(own, sparse, strict=True):
        assert abs(a["median_mm"] - b["median_mm"]) < 1.0, (a, b)
    # the truth moved by 1 m along x, or 10 ms later: other figures (the file is used); each
    # error of the moved truth is within the point's own error of 1000 mm (the triangle
    # inequality), so their mean is within the mean error of 1000 mm
    _write_truth_csv(folder / "moved.csv", truth.time_ns,
                     truth.position_world + np.array([1.0, 0.0, 0.0]))
    moved = json.loads(_ok(cli, "eval", session, "--truth", folder / "moved.csv", "--json"))
    for a, b in zip(own, moved, strict=True):
        assert b["n_points"] == a["n_points"], (a, b)
        assert abs(b["mean_mm"] - 1000) <= a["mean_mm"] + 1e-6, (a, b)
        assert abs(b["max_mm"] - 1000) <= a["max_mm"] + 1e-6, (a, b)
    _write_truth_csv(folder / "late.csv", truth.time_ns + 10_000_000, truth.position_world)
    late = json.loads(_ok(cli, "eval", session, "--truth", folder / "late.csv", "--json"))
    for a, b in zip(own, late, strict=True):
        assert b["mean_mm"] != a["mean_mm"], (a, b)
        assert b["n_points"] <= a["n_points"], (a, b)


def _truth_rows(path, times_ns, positions, blank=None, sep=",", header=("t", "x", "y", "z")):
    """A truth file of ``sep``-separated rows; the rows where ``blank`` (bool) holds written
    with x, y, z empty (a motion capture's lost marker)."""
    from pslog.log.csvio import format_time

    blank = np.zeros(len(times_ns), bool) if blank is None else blank
    lines = [sep.join(header)]
    for t, p, gap in zip(times_ns.tolist(), positions.tolist(), blank.tolist(), strict=True):
        lines.append(sep.join([format_time(t), *(["", "", ""] if gap else map(repr, p))]))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_eval_truth_gaps_are_not_scored_across(cli, fused, tmp_path):
    """A motion capture's lost marker (review40): rows whose x, y, z are empty are a gap in
    the truth, the points between the samples around it not scored (counted as truth_gap),
    every other point scored as against the session's own truth. Before, such a file was
    refused and its message said to leave the rows out, which made the truth a straight
    line across the gap: 0.6 s of a rally left out moves the max error by metres' tenths."""
    from pslog.log import read_session

    _, session = fused
    own = {r["method"]: r for r in json.loads(_ok(cli, "eval", session, "--json"))}
    truth = read_session(session).truth
    t = truth.time_ns
    gap = (t >= 1_000_000_000) & (t < 1_600_000_000)
    blank = _truth_rows(tmp_path / "mocap.csv", t, truth.position_world, blank=gap)
    text = _ok(cli, "eval", session, "--truth", blank)
    assert f"; {int(gap.sum())} gap rows: the points between the samples around them not " \
           f"scored)" in text.splitlines()[0], text
    got = {r["method"]: r for r in json.loads(_ok(cli, "eval", session, "--truth", blank,
                                                  "--json"))}
    lo, hi = t[np.flatnonzero(gap)[0] - 1], t[np.flatnonzero(gap)[-1] + 1]
    tracks = read_session(session).tracks
    for method, row in got.items():
        inside = (tracks[method].time_ns > lo) & (tracks[method].time_ns <= hi)
        assert row["not_scored"].get("truth_gap", 0) == np.count_nonzero(inside) > 0, row
        assert row["n_points"] + np.count_nonzero(inside) == own[method]["n_points"]
        assert row["max_mm"] <= own[method]["max_mm"], (row, own[method])
    # the same rows left out: the truth a straight line across the 0.6 s (what the old
    # message said to do): every point scored, far worse somewhere
    left = _truth_rows(tmp_path / "left.csv", t[~gap], truth.position_world[~gap])
    across = {r["method"]: r for r in json.loads(_ok(cli, "eval", session, "--truth", left,
                                                     "--json"))}
    assert max(across[m]["max_mm"] - own[m]["max_mm"] for m in own) > 50, across
    # TUM: a gap row's tx ty tz NaN; a partial row stays refused, naming it
    tum = tmp_path / "gap.tum"
    tum.write_text("".join(f"{format_s} {'nan nan nan' if g else ' '.join(map(repr, p))}\n"
                           for format_s, p, g in zip((f"{x / 1e9:.9f}" for x in t.tolist()),
                                                     truth.position_world.tolist(),
                                                     gap.tolist(), strict=True)))
    assert json.loads(_ok(cli, "eval", session, "--truth", tum, "--json")) == list(
        got.values())
    err = _one_line_error(cli, 1, "eval", session, "--truth",
                          _lines(tmp_path / "part.csv", "t,x,y,z\n0.5,1,2,0.5\n0.6,,,0.5\n"
                                                        "0.7,1,2,0.5\n"))
    assert "line 3: x value '': empty" in err and "x, y and z all empty" in err, err
    err = _one_line_error(cli, 1, "eval", session, "--truth",
                          _lines(tmp_path / "gaps.csv", "t,x,y,z\n0.5,1,2,0.5\n0.6,,,\n"))
    assert "1 sample with a position (1 gap rows): a truth needs two" in err, err


def test_eval_truth_tab_separated(cli, fused, tmp_path):
    """A tab-separated truth (a .tsv, as Qualisys exports; or a header of tabs without a
    comma) is read as its CSV (review40: it was refused, 'bad header 't\\tx\\ty\\tz''),
    the same figures as the session's own truth."""
    from pslog.log import read_session

    _, session = fused
    own = json.loads(_ok(cli, "eval", session, "--json"))
    truth = read_session(session).truth
    for name in ("mocap.tsv", "mocap.txt"):
        path = _truth_rows(tmp_path / name, truth.time_ns, truth.position_world, sep="\t",
                           header=("time", "x", "y", "z"))
        assert json.loads(_ok(cli, "eval", session, "--truth", path, "--json")) == own, name


def test_eval_truth_on_the_clock_export_writes(cli, fused, tmp_path):
    """An imported session on Unix-epoch times: a CSV truth on that clock (as export --csv
    writes the tracks' times) and a TUM truth on the session clock (as export --tum) give the
    same figures; each on the other clock is refused, naming the origin."""
    from pslog.log import read_session

    folder, session = fused
    _ok(cli, "export", folder / "sim.mcap", "--detections", tmp_path / "det.csv")
    with open(tmp_path / "det.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    col = rows[0].index("time")
    for row in rows[1:]:
        row[col] = str(Decimal(row[col]) + UNIX_S)
    with open(tmp_path / "unix.csv", "w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    imported, fused_unix = tmp_path / "imp.mcap", tmp_path / "impf.mcap"
    said = _ok(cli, "import", "--rig", "paper3", "--timing", "typeA", "--detections",
               tmp_path / "unix.csv", "-o", imported)
    assert "session clock origin 1764860000.000000000 s" in said, said
    _ok(cli, "fuse", imported, "--method", "typeA,smooth", "-o", fused_unix)
    truth = read_session(session).truth
    _write_truth_csv(tmp_path / "unix_truth.csv", truth.time_ns, truth.position_world,
                     add_s=UNIX_S)
    by_csv = json.loads(_ok(cli, "eval", fused_unix, "--truth", tmp_path / "unix_truth.csv",
                            "--json"))
    # the same truth on the session clock: the simulated times + 0.25 s
    with open(tmp_path / "session.tum", "w") as fh:
        for t, (x, y, z) in zip(truth.time_ns.tolist(), truth.position_world.tolist(),
                                strict=True):
            fh.write(f"{Decimal(t) / 10**9 + Decimal('0.25'):.9f} {x!r} {y!r} {z!r} 0 0 0 1\n")
    by_tum = json.loads(_ok(cli, "eval", fused_unix, "--truth", tmp_path / "session.tum",
                            "--json"))
    assert by_csv == by_tum
    assert sorted(r["method"] for r in by_csv) == ["smooth", "typeA"]
    # (the same tracks as the simulated session's, 0.25 s later: its figures)
    own = {r["method"]: r for r in json.loads(_ok(cli, "eval", session, "--json"))}
    assert all(abs(r["mean_mm"] - own[r["method"]]["mean_mm"]) < 1.0 for r in by_csv)
    # the CSV on the session clock, the TUM on the Unix one: refused, the origin named
    _write_truth_csv(tmp_path / "session_truth.csv", truth.time_ns, truth.position_world,
                     add_s=Decimal("0.25"))
    err = _one_line_error(cli, 1, "eval", fused_unix, "--truth",
                          tmp_path / "session_truth.csv")
    assert "span the session clock's, but a CSV truth's are on the original clock" in err, err
    assert "add the session's clock origin 1764860000.000000000 s to every time" in err, err
    with open(tmp_path / "unix.tum", "w") as fh:
        for t, (x, y, z) in zip(truth.time_ns.tolist(), truth.position_world.tolist(),
                                strict=True):
            fh.write(f"{Decimal(t) / 10**9 + UNIX_S:.9f} {x!r} {y!r} {z!r}\n")
    err = _one_line_error(cli, 1, "eval", fused_unix, "--truth", tmp_path / "unix.tum")
    assert "are on the original clock, but a TUM truth's are on the session clock" in err, err
    assert "subtract the session's clock origin 1764860000.000000000 s" in err, err


def _lines(path, text):
    path.write_text(text)
    return path


def test_eval_truth_file_errors(cli, fused, tmp_path):
    folder, session = fused
    good = "t,x,y,z\n0.5,1,2,0.5\n0.6,1,2,0.5\n"
    cases = [
        (tmp_path / "missing.csv", "no such file"),
        (_lines(tmp_path / "empty.csv", ""), "empty file"),
        (_lines(tmp_path / "header.csv", "a,b\n1,2\n"),
         "line 1: bad header 'a,b': expected columns t,x,y,z"),
        (_lines(tmp_path / "order.csv", good + "0.55,1,2,0.5\n"),
         "line 4: time 0.550000000 s is not after line 3's 0.600000000 s"),
        (_lines(tmp_path / "nan.csv", good + "0.7,nan,2,0.5\n"),
         "line 4: x value 'nan': not a finite number"),
        (_lines(tmp_path / "gap.csv", good + "0.7,,2,0.5\n"), "line 4: x value '': empty"),
        (_lines(tmp_path / "word.csv", good + "soon,1,2,0.5\n"),
         "line 4: time 'soon': not a number of seconds"),
        (_lines(tmp_path / "one.csv", "t,x,y,z\n0.5,1,2,0.5\n"), "1 sample: a truth needs two"),
        (_lines(tmp_path / "fields.csv", good + "0.7,1,2\n"), "line 4: expected 4 fields, got 3"),
        (_lines(tmp_path / "bad.tum", "# t x y z\n0.5 1 2 0.5\n0.6 1 2\n"),
         "line 3: 3 fields: a TUM line is"),
        (_lines(tmp_path / "mm.csv", "t,x,y,z\n0,1000,2000,500\n3,1000,2000,500\n"),
         "they look like millimetres"),
        (_lines(tmp_path / "far.csv", "t,x,y,z\n100,1,2,0.5\n101,1,2,0.5\n"),
         "no time in common with the tracks: the truth spans 100.000000000-101.000000000 s, "
         "the tracks 0."),
        (_lines(tmp_path / "det.csv", "camera,time,u,v\ncam1,0.5,1,2\n"), "holds detections"),
        (_lines(tmp_path / "two.csv", "time,x,y,z,camera,method\n0.5,1,2,0.5,cam1,typeA\n"
                                      "0.6,1,2,0.5,cam1,smooth\n"),
         "holds the tracks of 2 methods (typeA, smooth): keep one method's rows"),
        (session, "is an MCAP session, not a truth trajectory"),
        (_lines(tmp_path / "json.csv", '{"t": 0.5}\n'), "holds JSON"),
        (folder, "folder"),
    ]
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"t,x,y,z\n0.5,1,2,\xff\xfe\n")
    cases.append((binary, "not a text file (byte 16 is not UTF-8 text)"))
    for path, words in cases:
        err = _one_line_error(cli, 1, "eval", session, "--truth", path)
        assert words in err, (path, err)
    # one track outside a truth the others overlap: named, with both spans
    err = _one_line_error(cli, 1, "eval", session, "--truth",
                          _lines(tmp_path / "start.csv", "t,x,y,z\n0,1,2,0.5\n0.005,1,2,0.5\n"))
    assert "no time in common with track " in err and "the truth spans 0.000000000-" in err, err


def _split_per_camera(det_csv, folder):
    """The joined detections CSV split into one file per camera: cam1's without the camera
    column, cam2's with it (and its columns in another order), cam3's without."""
    with open(det_csv, newline="") as fh:
        rows = list(csv.reader(fh))
    header, body = rows[0], rows[1:]
    cam = header.index("camera")
    files = {}
    for name in ("cam1", "cam2", "cam3"):
        mine = [r for r in body if r[cam] == name]
        path = folder / f"{name}.csv"
        with open(path, "w", newline="") as fh:
            out = csv.writer(fh)
            if name == "cam2":
                order = [header.index(c) for c in ("u", "v", "camera", "score", "time",
                                                   "frame")]
            else:
                order = [i for i in range(len(header)) if i != cam]
            out.writerows([[r[i] for i in order] for r in [header, *mine]])
        files[name] = path
    return files


def test_import_one_csv_per_camera_equals_the_joined_csv(cli, fused, tmp_path):
    from pslog.log import read_session

    folder, _session = fused
    det = tmp_path / "det.csv"
    _ok(cli, "export", folder / "sim.mcap", "--detections", det)
    with open(det, newline="") as fh:  # (Unix-epoch times: the clock origin too)
        rows = list(csv.reader(fh))
    col = rows[0].index("time")
    for row in rows[1:]:
        row[col] = str(Decimal(row[col]) + UNIX_S)
    with open(det, "w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    assert sum(1 for r in rows[1:] if not r[2]) > 0  # (frames where the ball was missed)
    files = _split_per_camera(det, tmp_path)
    joined, per = tmp_path / "joined.mcap", tmp_path / "per.mcap"
    _ok(cli, "import", "--rig", "paper3", "--detections", det, "-o", joined)
    said = _ok(cli, "import", "--rig", "paper3", "--detections", f"cam3={files['cam3']}",
               "--detections", f"cam1={files['cam1']}", "--detections",
               f"cam2={files['cam2']}", "-o", per)
    assert said.startswith(f"wrote {per}: "), said
    a, b = read_session(joined), read_session(per)
    assert a.detections.n_frames == b.detections.n_frames > 0
    for field in ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
                  "cand_score"):
        assert np.array_equal(getattr(a.detections, field), getattr(b.detections, field),
                              equal_nan=True), field
    assert a.metadata["clock_origin_ns"] == b.metadata["clock_origin_ns"]
    assert a.rig.names == b.rig.names
    # one camera's file alone: imported, the others said
    one = tmp_path / "one.mcap"
    said = _ok(cli, "import", "--rig", "paper3", "--detections", f"cam2={files['cam2']}",
               "-o", one)
    assert "note: no --detections CAMERA=FILE for cameras cam1, cam3: nothing of them to " \
           "fuse" in said, said
    # a camera that saw nothing, its file a header alone (review40: the import was refused,
    # 'no detection rows', the other cameras' rows with it): the session of the joined CSV
    # without that camera's rows, the camera named in a note; every file empty: refused
    blind = tmp_path / "blind.csv"
    blind.write_text(files["cam3"].read_text().splitlines()[0] + "\n")
    with open(det, newline="") as fh:
        rows = list(csv.reader(fh))
    with open(tmp_path / "two.csv", "w", newline="") as fh:
        csv.writer(fh).writerows([rows[0], *(r for r in rows[1:] if r[0] != "cam3")])
    two, per2 = tmp_path / "two.mcap", tmp_path / "per2.mcap"
    _ok(cli, "import", "--rig", "paper3", "--detections", tmp_path / "two.csv", "-o", two)
    said = _ok(cli, "import", "--rig", "paper3", "--detections", f"cam1={files['cam1']}",
               "--detections", f"cam2={files['cam2']}", "--detections", f"cam3={blind}",
               "-o", per2)
    assert f"note: {blind} has no rows of camera cam3: nothing of it to fuse" in said, said
    a, b = read_session(two), read_session(per2)
    assert a.detections.n_frames == b.detections.n_frames > 0
    for field in ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
                  "cand_score"):
        assert np.array_equal(getattr(a.detections, field), getattr(b.detections, field),
                              equal_nan=True), field
    err = _one_line_error(cli, 1, "import", "--rig", "paper3", "--detections",
                          f"cam3={blind}", "-o", tmp_path / "none.mcap")
    assert err.endswith(f"{blind}: no detection rows"), err
    assert not (tmp_path / "none.mcap").exists()


def test_import_per_camera_errors(cli, fused, tmp_path):
    folder, _session = fused
    det = tmp_path / "det.csv"
    _ok(cli, "export", folder / "sim.mcap", "--detections", det)
    files = _split_per_camera(det, tmp_path)
    out = tmp_path / "out.mcap"
    imp = ("import", "--rig", "paper3", "-o", out)
    # a camera column naming another camera: the row named
    err = _one_line_error(cli, 1, *imp, "--detections", f"cam1={files['cam2']}",
                          "--detections", f"cam2={files['cam1']}")
    assert err == (f"pslog import: error: {files['cam2']}: line 2: camera 'cam2', but the "
                   f"file was given as camera cam1's (--detections cam1={files['cam2']}): "
                   f"every row of a camera's own CSV names that camera, or the column is left "
                   f"out"), err
    # the joined file given as one camera's
    err = _one_line_error(cli, 1, *imp, "--detections", f"cam2={det}")
    assert f"{det}: line 2: camera 'cam1', but the file was given as camera cam2's" in err
    # two files without names: how to name them
    err = _one_line_error(cli, 2, *imp, "--detections", files["cam1"], "--detections",
                          f"cam2={files['cam2']}")
    assert "without camera names: name each camera's file, --detections CAMERA=FILE" in err
    for args, words in (
            ((f"left={files['cam1']}", f"cam2={files['cam2']}"),
             f"argument --detections left={files['cam1']}: no camera 'left' in the rig (it "
             f"has cam1, cam2, cam3)"),
            ((f"cam1={files['cam1']}", f"cam1={files['cam2']}"), "camera cam1 given twice"),
            ((f"cam1={files['cam1']}", f"cam2={files['cam1']}"),
             f"{files['cam1']} given for cameras cam1 and cam2"),
            ((f"cam1={files['cam1']}", "cam2="), "argument --detections cam2=: empty file")):
        argv = [a for value in args for a in ("--detections", value)]
        err = _one_line_error(cli, 2, *imp, *argv)
        assert words in err, err
    # a per-camera file needs time,u,v
    bad = _lines(tmp_path / "bad.csv", "frame,u,v\n0,1,2\n")
    err = _one_line_error(cli, 1, *imp, "--detections", f"cam1={bad}")
    assert "bad header 'frame,u,v': expected columns time,u,v and optionally " \
           "frame,score,camera (missing: time)" in err, err
    # one camera's file given alone without its name: the name asked for
    err = _one_line_error(cli, 1, *imp, "--detections", files["cam1"])
    assert err.endswith("(missing: camera); one camera's file: name its camera, --detections "
                        "CAMERA=FILE"), err
    assert not out.exists()
    # the single-file form as before
    _ok(cli, *imp, "--detections", det)


def test_numpy_scalars_and_arrays_where_python_ones_are_taken(fused):
    import pslog
    from pslog.calibration.chessboard import check_pattern
    from pslog.errors import InputError

    assert check_pattern(np.array([9, 6])) == (9, 6)
    assert check_pattern(np.array([9, 6], dtype=np.int32)) == (9, 6)
    assert check_pattern((np.int64(9), np.int64(6))) == (9, 6)
    for bad in (np.array([9.0, 6.0]), np.array([True, True]), np.array([[9, 6]]),
                np.array([9, 6, 4]), np.array(["9", "6"]), "9x6"):
        with pytest.raises(InputError, match="bad chessboard pattern"):
            check_pattern(bad)
    folder, session = fused
    synced = folder / "synced.mcap"  # (a synced session: the flag changes every std_m)
    if not synced.exists():
        from pslog.cli import main

        assert main(["sync", str(folder / "sim.mcap"), "-o", str(synced)]) == 0
    on, off = (pslog.fuse(synced, "typeA", clock_uncertainty=flag)["typeA"]
               for flag in (True, False))
    assert not np.array_equal(on.quality["std_m"], off.quality["std_m"])
    for flag, want in ((np.True_, on), (np.False_, off)):
        got = pslog.fuse(synced, "typeA", clock_uncertainty=flag)["typeA"]
        assert np.array_equal(got.position_world, want.position_world)
        assert np.array_equal(got.quality["std_m"], want.quality["std_m"])
    for bad in ("on", 1, np.int64(1), None, np.array([True])):
        with pytest.raises(InputError, match="give True or False"):
            pslog.fuse(session, "typeA", clock_uncertainty=bad)
