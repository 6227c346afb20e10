"""Session 42's hostile-input sweep (helper hostile42), through the real CLI on real files:
rig files and calibration interchange (pslog, anipose, Pose2Sim, OpenCV) in ``rig
check|show|import|export``, ``fuse --rig`` and ``simulate --rig``; ``pslog calibrate``'s
point files, chessboard options and image folders; ``eval --truth`` files; numeric option
values everywhere (the probes: benchmarks/session42/hostile/).

Found and fixed: a rig TOML nested a few hundred arrays deep (``K = [[[[...]]]]``), or holding
an integer of more than 4300 digits, was a traceback (tomllib's RecursionError, Python's
ValueError); an integer beyond int64 (``fps = 1180591620717411303424``, TOML allows it) was
numpy's TypeError traceback, an integer beyond any float (``size = [1e400 as digits, 480]``)
an OverflowError one; a matrix holding a string or a boolean (``K = [["400", ...]]``,
``distortions = [false, ...]``) was read as the number numpy makes of it (400, 0), silently;
a camera named with U+2028 (a line separator: ``str.splitlines`` breaks there) was accepted
and cut ``fuse --rig``'s error in two lines; ``calibrate --points`` of 30,000 points asked
for a 29 GiB matrix (the DLT's full SVD: "out of memory", exit 1), now 3 s. Two cameras named
``café``, one composed and one decomposed (NFD, as macOS writes), were two cameras that look
the same; a camera named decomposed in the rig was not found by the name typed (``import
--detections café=FILE``) or written composed in a CSV's camera column, and the error showed
two identical names (session 41 found the same of ``--columns``' header names). ``pslog
fuse`` of a session of cameras faster than 333 fps (a rig takes up to 1e6) exited 2 blaming
``--tolerance-ms``, not given (its default 1 ms is a third of their period or more), as
``pslog.fuse`` and ``pslog live`` failed: the default is a tenth of the period for them.
``rig export --format opencv`` of a camera (or rig) named ``null`` or ``true`` wrote them
unquoted in YAML (OpenCV's writer), read back as another value (the camera came back named
``camera_1``, silently), and of one named ``'`` a YAML or JSON file no reader reads: refused,
naming the formats that keep the name. ``rig import --offset`` of one camera twice wrote the
last, silently; a Pose2Sim table's ``fisheye = "true"`` (a string) was read as not
fisheye. ``eval --truth`` of a truth whose one gap holds every point said "no point inside the
ground truth's span"."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from .promises import assert_refused, run_pslog

_PAPER3 = None


def _paper3_toml() -> str:
    global _PAPER3
    if _PAPER3 is None:
        done = run_pslog("rig", "show", "paper3")
        assert done.code == 0, done.stderr
        _PAPER3 = done.stdout
    return _PAPER3


def _anipose_toml(tmp_path: Path, fmt: str = "anipose") -> str:
    out = tmp_path / f"exported_{fmt}.toml"
    done = run_pslog("rig", "export", "paper3", "--format", fmt, "-o", out)
    assert done.code == 0, done.stderr
    text = out.read_text()
    out.unlink()
    return text


_K = "K = [[400.0, 0.0, 319.5], [0.0, 400.0, 239.5], [0.0, 0.0, 1.0]]"


@pytest.mark.parametrize("how", ["check", "import --format anipose"])
def test_a_rig_nested_too_deeply_is_one_line(tmp_path, how):
    """``K`` nested 2000 arrays deep: tomllib parses arrays recursively, and its
    RecursionError was a traceback (also read by ``rig import --format anipose``)."""
    text = _paper3_toml()
    assert _K in text
    (tmp_path / "deep.toml").write_text(text.replace(_K, "K = " + "[" * 2000 + "]" * 2000, 1))
    args = (["rig", "check", "deep.toml"] if how == "check" else
            ["rig", "import", "deep.toml", "--format", "anipose", "-o", "out.toml"])
    assert_refused(tmp_path, 1, args, contains=("deep.toml: malformed TOML", "nested too deeply"))


_NUMBERS = {"2**70": str(2 ** 70), "10**400": "1" + "0" * 400, "5001-digits": "1" + "0" * 5000}


@pytest.mark.parametrize("case", ["pslog fps 2**70", "pslog offset 2**70", "anipose fps 2**70",
                                  "anipose size 10**400", "pslog K 10**400",
                                  "pslog fps 5001-digits"])
def test_an_integer_beyond_int64_is_said(tmp_path, case):
    """TOML integers are unbounded in tomllib: ``fps = 1180591620717411303424`` was numpy's
    "ufunc 'isfinite' not supported" traceback; 10**400 as digits in a matrix or a size an
    OverflowError one; 5001 digits Python's "Exceeds the limit (4300 digits)" ValueError."""
    fmt, key, value = case.split()
    number = _NUMBERS[value]
    if fmt == "pslog":
        text = _paper3_toml()
        old = {"fps": "fps = 30.0", "offset": "offset = 0.0", "K": "K = [[400.0,"}[key]
        new = {"fps": f"fps = {number}", "offset": f"offset = {number}",
               "K": f"K = [[{number},"}[key]
    else:
        text = _anipose_toml(tmp_path)
        old, new = {"fps": ("fps = 30.0", f"fps = {number}"),
                    "size": ("size = [640, 480]", f"size = [{number}, 480]")}[key]
    assert old in text
    (tmp_path / "rig.toml").write_text(text.replace(old, new, 1))
    says = {"fps": "fps must be in [0.1, 1e+06], got 1.18059e+21",
            "offset": "offset 1.18059e+21 s must be in", "size": "size is not numeric",
            "K": "K is not numeric"}[key]
    if value == "5001-digits":
        says = "a number of more digits than any rig's"
    assert_refused(tmp_path, 1, ["rig", "check", "rig.toml"], contains=says)


@pytest.mark.parametrize("case", ["pslog K string", "pslog K boolean",
                                  "anipose matrix string", "pose2sim distortions boolean"])
def test_a_string_or_a_boolean_is_not_a_number(tmp_path, case):
    """``K = [["400", ...]]`` or ``[[400.0, false, ...]]``: numpy's float conversion read the
    string as 400 and the boolean as 0, and the rig was accepted (and simulated with)."""
    fmt, key, kind = case.split()
    if fmt == "pslog":
        text = _paper3_toml()
        old = "K = [[400.0, 0.0,"
        new = 'K = [["400", 0.0,' if kind == "string" else "K = [[400.0, false,"
    else:
        text = _anipose_toml(tmp_path, fmt)
        old, new = {"matrix": ("matrix = [[400.0,", 'matrix = [["400",'),
                    "distortions": ("distortions = [0.0,", "distortions = [false,")}[key]
    assert old in text
    (tmp_path / "rig.toml").write_text(text.replace(old, new, 1))
    for args in (["rig", "check", "rig.toml"],
                 ["simulate", "--rig", "rig.toml", "--duration", "0.5", "--seed", "71000",
                  "-o", "s.mcap"]):
        assert_refused(tmp_path, 1, args, contains=f"{key} is not numeric")


@pytest.mark.parametrize("where", ["rig check", "fuse --rig", "calibrate --name"])
def test_a_line_separator_in_a_camera_name_is_refused(tmp_path, where):
    """U+2028 (LINE SEPARATOR) is a line break to ``str.splitlines`` (and to some terminals
    and editors): a camera so named was accepted, and ``fuse --rig``'s "cameras ... differ
    from the session's" error came out on two lines."""
    name = "cam\u20281"
    text = _paper3_toml().replace('name = "cam1"', f'name = "{name}"', 1)
    (tmp_path / "rig.toml").write_text(text)
    if where == "rig check":
        assert_refused(tmp_path, 1, ["rig", "check", "rig.toml"],
                       contains="holds a control character or line break")
    elif where == "fuse --rig":
        done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.5",
                         "--seed", "71000", "-o", tmp_path / "s.mcap")
        assert done.code == 0, done.stderr
        assert_refused(tmp_path, 1, ["fuse", "s.mcap", "--rig", "rig.toml", "-o", "f.mcap"],
                       contains="holds a control character or line break")
    else:
        points = Path(__file__).resolve().parents[2] / "samples" / "cam1_points.csv"
        (tmp_path / "points.csv").write_bytes(points.read_bytes())
        assert_refused(tmp_path, 2, ["calibrate", "--points", "points.csv", "--name", name,
                                     "--width", "640", "--height", "480", "--rig", "new.toml"],
                       contains="holds a control character or line break")


def test_calibrate_takes_a_large_survey(tmp_path):
    """40,000 points (a dense survey, or a tracker's log of a wand): the DLT's SVD computed
    its full 2n x 2n U, 51 GB, and ``calibrate`` said "out of memory" (exit 1); it needs only
    the 12 x 12 V. Now a few seconds, and the camera is the samples' 16 points' own."""
    lines = (Path(__file__).resolve().parents[2] / "samples" / "cam1_points.csv").read_text(
    ).splitlines()
    repeats = -(-40_000 // (len(lines) - 1))
    (tmp_path / "points.csv").write_text("\n".join([lines[0]] + lines[1:] * repeats) + "\n")
    done = run_pslog("calibrate", "--points", "points.csv", "--name", "cam1", "--width", "640",
                     "--height", "480", "--rig", "rig.toml", cwd=tmp_path)
    assert done.code == 0, done.stderr
    assert "out of memory" not in done.stderr
    assert f"calibrated from {repeats * (len(lines) - 1)} points" in done.stdout
    shown = run_pslog("rig", "check", "rig.toml", cwd=tmp_path)
    assert shown.code == 0 and "cam1" in shown.stdout, shown.stderr


_ROS_YML = """%YAML:1.0
---
image_width: 640
image_height: 480
camera_name: cam1
camera_matrix:
  rows: 3
  cols: 3
  data: [{fx}, 0, 319.5, 0, 400, 239.5, 0, 0, 1]
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0, 0, 0, 0, 0]
rvec: [3.14159, 0, 0]
T: [0, 0, {tz}]
"""


@pytest.mark.parametrize("fx, tz, says", [("abc", "3", "camera_matrix is not numeric: item 1 "
                                                        "is 'abc'"),
                                          ("400", '"3"', "T is not numeric: item 3 is '3'")])
def test_an_opencv_sequence_holding_a_string_names_it(tmp_path, fx, tz, says):
    """A ROS ``camera_info``-style matrix (or a plain sequence) holding a string: OpenCV's
    ``FileNode.real()`` of a string is 1.8e308, and the error said "K has an entry of 1.8e+308
    pixels" or "t has an entry of 1.8e+308 m", of a file holding neither."""
    (tmp_path / "cam.yml").write_text(_ROS_YML.format(fx=fx, tz=tz))
    line = assert_refused(tmp_path, 1, ["rig", "check", "cam.yml"], contains=says)
    assert "1.8e+308" not in line
    (tmp_path / "cam.yml").write_text(_ROS_YML.format(fx="400", tz="3"))
    assert run_pslog("rig", "check", "cam.yml", cwd=tmp_path).code == 0


_DECOMPOSED = "cafe\u0301"  # café as macOS writes file names (NFD)
_COMPOSED = "caf\u00e9"  # café as typed (NFC)


def test_one_name_in_two_unicode_spellings_is_a_duplicate(tmp_path):
    """``café`` composed and decomposed as two cameras' names: accepted as two cameras whose
    names look the same (``rig check`` listed 'café' twice), of which a name typed finds one."""
    text = _paper3_toml().replace('name = "cam1"', f'name = "{_DECOMPOSED}"', 1).replace(
        'name = "cam2"', f'name = "{_COMPOSED}"', 1)
    (tmp_path / "rig.toml").write_text(text, encoding="utf-8")
    assert_refused(tmp_path, 1, ["rig", "check", "rig.toml"],
                   contains="are one name in two Unicode spellings")


@pytest.mark.parametrize("how", ["CAMERA=FILE", "camera column"])
def test_a_camera_named_decomposed_is_found_by_its_name_composed(tmp_path, how):
    """A rig file written with ``café`` decomposed (NFD) and its name typed composed in
    ``--detections café=FILE``, or written so in a CSV's camera column: refused as "no camera
    'café' in the rig (it has café, cam2, cam3)", two names that look the same (as session 41
    found for ``--columns``)."""
    text = _paper3_toml().replace('name = "cam1"', f'name = "{_DECOMPOSED}"', 1)
    (tmp_path / "rig.toml").write_text(text, encoding="utf-8")
    done = run_pslog("simulate", "--rig", "rig.toml", "--timing", "typeA", "--duration", "0.5",
                     "--seed", "71005", "-o", "s.mcap", cwd=tmp_path)
    assert done.code == 0, done.stderr
    done = run_pslog("export", "s.mcap", "--detections", "det.csv", cwd=tmp_path)
    assert done.code == 0, done.stderr
    rows = (tmp_path / "det.csv").read_text(encoding="utf-8").splitlines()
    assert rows[0] == "camera,time,u,v,frame,score" and rows[1].startswith(_DECOMPOSED + ",")
    if how == "CAMERA=FILE":
        files = []
        for name in (_DECOMPOSED, "cam2", "cam3"):
            mine = [r.partition(",")[2] for r in rows[1:] if r.startswith(name + ",")]
            typed = _COMPOSED if name == _DECOMPOSED else name
            (tmp_path / f"{name}.csv").write_text("\n".join(["time,u,v,frame,score", *mine])
                                                  + "\n", encoding="utf-8")
            files += ["--detections", f"{typed}={name}.csv"]
    else:
        (tmp_path / "typed.csv").write_text(
            "\n".join(r.replace(_DECOMPOSED + ",", _COMPOSED + ",", 1) for r in rows) + "\n",
            encoding="utf-8")
        files = ["--detections", "typed.csv"]
    done = run_pslog("import", "--rig", "rig.toml", "--timing", "typeA", *files, "-o",
                     "i.mcap", cwd=tmp_path)
    assert done.code == 0, done.stderr
    assert f"3 cameras ({_DECOMPOSED}, cam2, cam3)" in done.stdout
    again = run_pslog("export", "i.mcap", "--detections", "again.csv", cwd=tmp_path)
    assert again.code == 0, again.stderr
    assert (tmp_path / "again.csv").read_text(encoding="utf-8").splitlines() == rows


def test_a_session_of_cameras_faster_than_333_fps_fuses_without_a_tolerance(tmp_path):
    """A rig of 500 fps cameras (``rig check`` takes up to 1e6): ``pslog fuse`` without
    ``--tolerance-ms`` exited 2 blaming "argument --tolerance-ms" (its default 1 ms is above a
    third of the 2 ms period), and ``pslog.fuse`` raised the same; the default is now a tenth
    of the period for such cameras. A tolerance given too wide is still refused."""
    import pslog

    text = _paper3_toml().replace("fps = 30.0", "fps = 500.0")
    (tmp_path / "rig.toml").write_text(text)
    done = run_pslog("simulate", "--rig", "rig.toml", "--timing", "typeA", "--duration", "0.3",
                     "--seed", "71007", "-o", "s.mcap", cwd=tmp_path)
    assert done.code == 0, done.stderr
    done = run_pslog("fuse", "s.mcap", "--method", "typeA", "-o", "f.mcap", cwd=tmp_path)
    assert done.code == 0, done.stderr
    assert "typeA" in done.stdout and (tmp_path / "f.mcap").is_file()
    assert len(pslog.fuse(tmp_path / "s.mcap", methods=["typeA"]).tracks["typeA"]) > 100
    assert_refused(tmp_path, 2, ["fuse", "s.mcap", "--method", "typeA", "--tolerance-ms", "1",
                                 "-o", "g.mcap"],
                   contains="argument --tolerance-ms: tolerance 1 ms must be below a third")


def test_live_of_cameras_faster_than_333_fps_runs(tmp_path):
    """``pslog live`` of a 500 fps rig fused with the default options' 1 ms tolerance and
    stopped at once: "tolerance 1 ms must be below a third of the frame period" (exit 1)."""
    text = _paper3_toml().replace("fps = 30.0", "fps = 500.0")
    (tmp_path / "rig.toml").write_text(text)
    done = run_pslog("live", "--rig", "rig.toml", "--synthetic", "--timing", "typeA",
                     "--duration", "3", "--listen", "udp://127.0.0.1:0", "--jsonl",
                     "--record", "live.mcap", cwd=tmp_path, timeout=120)
    assert done.code == 0, done.stderr
    assert "tolerance" not in done.stderr
    # points, one JSON line each (how many: the load; in 0.5 s a loaded CI machine's camera
    # processes had sent 66 frames of 750 and no point was fused yet)
    assert done.stdout.count("\n") >= 1
    assert (tmp_path / "live.mcap").is_file()


@pytest.mark.parametrize("name, suffix", [("null", ".yml"), ("true", ".yml"), ("'", ".json"),
                                          ("'", ".yml"), ("rig null", ".yml")])
def test_an_opencv_export_never_writes_a_name_it_cannot_read_back(tmp_path, name, suffix):
    """OpenCV's YAML writer leaves ``null`` and ``true`` unquoted, read back as no string and
    as 1: ``rig export --format opencv`` of a camera named ``null`` wrote a file whose import
    named it ``camera_1``, silently; a camera named ``'`` was written as YAML or JSON that
    neither OpenCV nor pslog can read ("malformed OpenCV FileStorage file"). Now refused
    naming the name and the formats that keep it; XML keeps it through a round trip."""
    text = _paper3_toml()
    if name == "rig null":
        text = text.replace('name = "paper3"', 'name = "null"', 1)
        kept = "null"
    else:
        text = text.replace('name = "cam2"', f'name = "{name}"', 1)
        kept = name
    (tmp_path / "rig.toml").write_text(text)
    assert_refused(tmp_path, 1, ["rig", "export", "rig.toml", "--format", "opencv", "-o",
                                 f"out{suffix}"],
                   contains=(f"name {kept!r} does not survive OpenCV's", "or write .xml"))
    done = run_pslog("rig", "export", "rig.toml", "--format", "opencv", "-o", "out.xml",
                     cwd=tmp_path)
    assert done.code == 0, done.stderr
    done = run_pslog("rig", "import", "out.xml", "-o", "back.toml", cwd=tmp_path)
    assert done.code == 0, done.stderr
    back = tomllib.loads((tmp_path / "back.toml").read_text())
    assert (back.get("name"), [c["name"] for c in back["camera"]]) == (
        tomllib.loads(text).get("name"), [c["name"] for c in tomllib.loads(text)["camera"]])


def test_rig_import_refuses_a_camera_offset_given_twice(tmp_path):
    """``rig import --offset cam2=0.01 --offset cam2=0.02``: the last one was written,
    silently (``simulate --clock-offset`` and ``import --detections`` refuse a camera given
    twice)."""
    (tmp_path / "calibration.toml").write_text(_anipose_toml(tmp_path))
    assert_refused(tmp_path, 2, ["rig", "import", "calibration.toml", "--offset", "cam2=0.01",
                                 "--offset", "cam2=0.02", "-o", "rig.toml"],
                   contains="argument --offset: camera cam2 given twice (0.01, 0.02)")
    done = run_pslog("rig", "import", "calibration.toml", "--offset", "cam2=0.01", "--offset",
                     "cam3=0.02", "-o", "rig.toml", cwd=tmp_path)
    assert done.code == 0, done.stderr
    offsets = [c["offset"] for c in tomllib.loads((tmp_path / "rig.toml").read_text())["camera"]]
    assert offsets == [0.0, 0.01, 0.02]


def test_a_pose2sim_fisheye_that_is_no_boolean_is_refused(tmp_path):
    """``fisheye = "true"`` (quoted by hand) in a Pose2Sim camera table: taken as not
    fisheye, and the fisheye lens read as plumb_bob, silently."""
    text = _anipose_toml(tmp_path, "pose2sim")
    assert "fisheye = false" in text
    (tmp_path / "Calib.toml").write_text(text.replace("fisheye = false", 'fisheye = "true"', 1))
    assert_refused(tmp_path, 1, ["rig", "check", "Calib.toml"],
                   contains="[cam_01]: fisheye must be true or false, got 'true'")


def test_eval_of_a_truth_whose_gaps_hold_every_point_says_so(tmp_path):
    """A truth (motion capture) with a position at its first and last rows only, the marker
    lost between: every track point lies inside its span, in its gap, and ``eval --truth``
    said "track 'typeA' has no point inside the ground truth's span"."""
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.5",
                     "--seed", "71009", "-o", "s.mcap", cwd=tmp_path)
    assert done.code == 0, done.stderr
    for args in (["fuse", "s.mcap", "--method", "typeA", "-o", "f.mcap"],
                 ["export", "f.mcap", "--tum", "tum"]):
        done = run_pslog(*args, cwd=tmp_path)
        assert done.code == 0, done.stderr
    rows = [r.split() for r in (tmp_path / "tum" / "truth.tum").read_text().splitlines()
            if not r.startswith("#")]
    lines = ["t,x,y,z"] + [",".join(r[:4]) if i in (0, len(rows) - 1) else f"{r[0]},,,"
                           for i, r in enumerate(rows)]
    (tmp_path / "truth.csv").write_text("\n".join(lines) + "\n")
    line = assert_refused(tmp_path, 1, ["eval", "f.mcap", "--truth", "truth.csv"],
                          contains="or each in a gap of it")
    assert "no point inside the ground truth's span" not in line
