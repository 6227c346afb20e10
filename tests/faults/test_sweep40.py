"""Session 40's hostile-input sweep (helper hostile40) of the session's new surfaces, through
the real CLI on real files: ``pslog eval --truth FILE``, ``pslog import --detections
CAMERA=FILE``, and the batch gate that decides dirty sessions by the compiled kernels.

Found and fixed: a session of crowded frames (``pslog import`` takes any number of
candidates a frame) went the gate's numpy path, whose support pairs every candidate with
each pair of another camera's frames (k² pairs, held at once): 50 candidates a frame in a
rally took ``pslog fuse`` 45 s and 6 GB, ``pslog sync`` 38 s and 3.5 GB; 209 in one camera
asked for 16 GiB ("out of memory", exit 1). The gate's cost estimate now counts those pairs,
and such sessions are decided by the compiled kernels (4 s and 260 MB; 2.5 s and 250 MB); the
numpy form takes the pairs in blocks; a frame of more than 1000 candidates (hours of gating)
is refused naming it. ``pslog sync`` of a session whose every candidate the gate rejects said
it 'has no detection'.

``eval --truth``: 1e308 positions (numpy's overflow warning), times in milliseconds (scored
1.3 m off), a truth on the other clock where the clocks overlap (scored 1.8 m off), a
.tsv truth refused, a video read whole into memory. ``import``: tab-separated files refused,
a file of zeros read whole as one line, a rig camera named ``left=2`` could not be given its
file, ``cam1=x.csv`` of a joined file said 'no such file: x.csv'. csv errors named the line
before theirs; the API named a numpy array on several lines."""

from __future__ import annotations

import json
import resource
from pathlib import Path

import numpy as np
import pytest

import pslog
from pslog.log.csvio import format_time
from pslog.records import NS

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep40")
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                     "--noise-px", "0.3", "--seed", "63001", "-o", folder / "s.mcap")
    assert done.code == 0, done.stderr
    done = run_pslog("fuse", folder / "s.mcap", "-o", folder / "f.mcap")
    assert done.code == 0, done.stderr
    return folder


def _crowded_csv(session: Path, out: Path, k: int, cameras: tuple[str, ...], seed: int,
                 only_frame: int | None = None) -> int:
    """``session``'s detections as a detections CSV, every frame of ``cameras`` (or only
    its frame index ``only_frame``) given ``k - 1`` false candidates uniform over its image
    (blobs, a noisy detector); returns the rows written."""
    s = pslog.read_session(session)
    d, rig = s.detections, s.rig
    rng = np.random.default_rng(seed)
    rows = ["camera,time,u,v,frame,score"]
    for f in range(d.n_frames):
        name = rig.names[d.frame_camera[f]]
        t, index = format_time(int(d.frame_time_ns[f])), int(d.frame_index[f])
        uv = d.cand_uv[d.cand_frame == f].tolist()
        if name in cameras and only_frame in (None, index):
            cam = rig.cameras[d.frame_camera[f]]
            uv += rng.uniform([0, 0], [cam.width, cam.height], size=(k - 1, 2)).tolist()
        rows += [f"{name},{t},{u!r},{v!r},{index},1.0" for u, v in uv]
    out.write_text("\n".join(rows) + "\n")
    return len(rows) - 1


def _address_space(limit: int):
    def preexec() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    return preexec


@pytest.mark.parametrize("command", ["fuse", "sync"])
def test_a_camera_of_crowded_frames_is_gated_in_bounded_memory(inputs, tmp_path, command):
    """200 candidates in every frame of one camera: the gate's numpy support asked for
    (9000, 200, 200) arrays, 2.9 GB each ("out of memory" under this 3 GiB address space;
    16 GiB on a rally); the compiled kernels decide it in a few hundred MB."""
    rows = _crowded_csv(inputs / "s.mcap", tmp_path / "crowded.csv", 200, ("cam1",), 63011)
    assert rows > 9000
    done = run_pslog("import", "--rig", "paper3", "--detections", tmp_path / "crowded.csv",
                     "-o", tmp_path / "crowded.mcap")
    assert done.code == 0, done.stderr
    out = tmp_path / "out.mcap"
    run = run_pslog(command, tmp_path / "crowded.mcap", "-o", out, timeout=120,
                    preexec_fn=_address_space(3 << 30))
    assert run.code == 0, run.stderr
    assert "Traceback" not in run.stderr and "memory" not in run.stderr, run.stderr
    assert out.stat().st_size > 0
    if command == "fuse":  # the ball still found among the blobs
        session = pslog.read_session(out)
        assert len(session.tracks["typeA"]) > 100


def _truth_rows(inputs: Path) -> list[str]:
    """The simulated session's own truth as CSV rows ``t,x,y,z`` (header first)."""
    truth = pslog.read_session(inputs / "s.mcap").truth
    return ["t,x,y,z"] + [f"{format_time(t)},{x!r},{y!r},{z!r}" for t, (x, y, z) in
                          zip(truth.time_ns.tolist(), truth.position_world.tolist(),
                              strict=True)]


@pytest.mark.parametrize("where", ["one", "all"])
def test_a_truth_position_beyond_any_world_is_refused_naming_its_line(inputs, tmp_path,
                                                                     where):
    """``1e308`` is a finite float: eval scored it, numpy's overflow warning on stderr (one
    such row: exit 0 beside the table; every row: the warning, then the millimetre error,
    three lines)."""
    rows = _truth_rows(inputs)
    for k in ([5] if where == "one" else range(1, len(rows))):
        rows[k] = rows[k].rsplit(",", 1)[0] + ",1e308"
    (tmp_path / "truth.csv").write_text("\n".join(rows) + "\n")
    before = fingerprint(inputs, tmp_path)
    run = run_pslog("eval", inputs / "f.mcap", "--truth", tmp_path / "truth.csv")
    assert_one_line_error(run, 1, contains=(
        f"truth.csv: line {6 if where == 'one' else 2}: z value '1e308': beyond any rig's "
        f"world (at most 1e+06 m from the origin)"))
    assert_untouched(before, inputs, tmp_path)


@pytest.mark.parametrize("unit, factor, said", [("milliseconds", 1000, "1000"),
                                               ("microseconds", 10**6, "1e6")])
def test_a_truth_in_milliseconds_is_refused(inputs, tmp_path, unit, factor, said):
    """Times in ms read as seconds: the truth's samples 11 s apart over 1489 s, and every
    track scored 1.3 m off with exit 0 (``pslog import`` refuses detections so far apart)."""
    rows = _truth_rows(inputs)
    scaled = [rows[0]] + [f"{format_time(int(r.split(',')[0].replace('.', '')) * factor)},"
                          f"{r.partition(',')[2]}" for r in rows[1:]]
    (tmp_path / "truth.csv").write_text("\n".join(scaled) + "\n")
    run = run_pslog("eval", inputs / "f.mcap", "--truth", tmp_path / "truth.csv")
    assert_one_line_error(run, 1, contains=(
        "truth.csv: its samples lie a median", f"the times look like {unit}; give seconds "
        f"(divide them by {said})"))
    # (a TUM file alike)
    tum = "\n".join(r.replace(",", " ") for r in scaled[1:]) + "\n"
    (tmp_path / "truth.tum").write_text(tum)
    run = run_pslog("eval", inputs / "f.mcap", "--truth", tmp_path / "truth.tum")
    assert_one_line_error(run, 1, contains=f"the times look like {unit}")


def test_a_sparse_truth_spanning_the_tracks_is_scored(inputs, tmp_path):
    """A truth of two samples 10 s apart (a ball at rest measured twice; the score is the
    user's to judge), 900 times the tracks' steps, spans 7 times the tracks' time, not
    hundreds of times it: scored (the unit check needs both)."""
    rows = _truth_rows(inputs)
    at = rows[1].partition(",")[2]
    (tmp_path / "truth.csv").write_text(f"t,x,y,z\n0,{at}\n10,{at}\n")
    run = run_pslog("eval", inputs / "f.mcap", "--truth", tmp_path / "truth.csv")
    assert run.code == 0, run.stderr
    assert "2 samples" in run.stdout and "typeA" in run.stdout, run.stdout


@pytest.mark.parametrize("command", ["fuse", "sync"])
def test_a_frame_of_more_candidates_than_the_gate_takes_is_refused(inputs, tmp_path,
                                                                    command):
    """A CSV takes any number of candidates a frame, and the gate's work grows as their
    square: one camera's frames of 20,834 (5 million candidates in 8 s) ran for an hour
    without a word. More than 1000 in any frame: one line naming it, nothing written;
    1000 is gated."""
    for k in (1001, 1000):
        _crowded_csv(inputs / "s.mcap", tmp_path / f"c{k}.csv", k, ("cam2",), 63012,
                     only_frame=7)
        done = run_pslog("import", "--rig", "paper3", "--detections", tmp_path / f"c{k}.csv",
                         "-o", tmp_path / f"c{k}.mcap")
        assert done.code == 0, done.stderr
    before = fingerprint(tmp_path)
    run = run_pslog(command, tmp_path / "c1001.mcap", "-o", tmp_path / "out.mcap")
    assert_one_line_error(run, 1, contains=(
        "camera cam2's frame 7 (t = 0.244444444 s) holds 1001 candidates: the gate takes at "
        "most 1000 a frame"))
    assert_untouched(before, tmp_path)
    run = run_pslog(command, tmp_path / "c1000.mcap", "-o", tmp_path / "out.mcap")
    assert run.code == 0, run.stderr
    if command == "fuse":  # (without the gate, each frame's best-scored candidate)
        run = run_pslog("fuse", tmp_path / "c1001.mcap", "--gating", "off", "-o",
                        tmp_path / "off.mcap")
        assert run.code == 0, run.stderr


def test_a_truth_on_the_other_clock_of_a_session_with_a_small_origin_is_refused(inputs,
                                                                                tmp_path):
    """A CSV whose first frame is at -0.5 s imports with a clock origin of -1 s: the two
    clocks overlap, so a truth on the wrong one shared time with the tracks and scored every
    one 1.8 m off with exit 0 (only truths sharing no time were refused as on the other
    clock). Now a truth that fits the tracks ten times better on the other clock is."""
    done = run_pslog("export", inputs / "s.mcap", "--detections", tmp_path / "det.csv")
    assert done.code == 0, done.stderr
    lines = (tmp_path / "det.csv").read_text().splitlines()
    shifted = [lines[0]]
    for row in lines[1:]:
        camera, t, rest = row.split(",", 2)
        shifted.append(f"{camera},{format_time(int(t.replace('.', '')) - NS // 2)},{rest}")
    (tmp_path / "det.csv").write_text("\n".join(shifted) + "\n")
    done = run_pslog("import", "--rig", "paper3", "--detections", tmp_path / "det.csv", "-o",
                     tmp_path / "i.mcap")
    assert done.code == 0 and "origin -1.000000000 s" in done.stdout, done.stdout
    done = run_pslog("fuse", tmp_path / "i.mcap", "-o", tmp_path / "f.mcap")
    assert done.code == 0, done.stderr
    rows = _truth_rows(inputs)

    def moved(by_ns: int, sep: str = ",") -> str:
        return "\n".join(f"{format_time(int(r.split(',')[0].replace('.', '')) + by_ns)}"
                         f"{sep}{r.partition(',')[2].replace(',', sep)}" for r in rows[1:])

    files = {"original.csv": "t,x,y,z\n" + moved(-NS // 2), "session.tum": moved(NS // 2, " "),
             "session.csv": "t,x,y,z\n" + moved(NS // 2), "original.tum": moved(-NS // 2, " ")}
    for name, text in files.items():
        (tmp_path / name).write_text(text + "\n")
    for good in ("original.csv", "session.tum"):
        run = run_pslog("eval", tmp_path / "f.mcap", "--truth", tmp_path / good, "--json")
        assert run.code == 0, run.stderr
        assert all(row["mean_mm"] < 50 for row in json.loads(run.stdout)), run.stdout
    run = run_pslog("eval", tmp_path / "f.mcap", "--truth", tmp_path / "session.csv")
    assert_one_line_error(run, 1, contains=(
        "session.csv: its times (0.500000000-1.988888889 s) are on the session clock, but a "
        "CSV truth's are on the original clock", "add the session's clock origin "
        "-1.000000000 s to every time"))
    run = run_pslog("eval", tmp_path / "f.mcap", "--truth", tmp_path / "original.tum")
    assert_one_line_error(run, 1, contains=(
        "original.tum: its times (-0.500000000-0.988888889 s) are on the original clock, but "
        "a TUM truth's are on the session clock", "subtract the session's clock origin "
        "-1.000000000 s"))


def test_tab_separated_truths_and_detections_are_read(inputs, tmp_path):
    """A .tsv truth (the reader routes .tsv to its CSV form) and a tab-separated camera file
    (a spreadsheet's "text, tab delimited") were refused as a bad header 't\\tx\\ty\\tz'."""
    rows = _truth_rows(inputs)
    (tmp_path / "truth.csv").write_text("\n".join(rows) + "\n")
    (tmp_path / "truth.tsv").write_text("\n".join(r.replace(",", "\t") for r in rows) + "\n")
    scores = []
    for name in ("truth.csv", "truth.tsv"):
        run = run_pslog("eval", inputs / "f.mcap", "--truth", tmp_path / name, "--json")
        assert run.code == 0, run.stderr
        scores.append([(r["method"], r["mean_mm"], r["n_points"]) for r in json.loads(run.stdout)])
    assert scores[0] == scores[1] and len(scores[0]) == 4
    done = run_pslog("export", inputs / "s.mcap", "--detections", tmp_path / "det.csv")
    assert done.code == 0, done.stderr
    lines = (tmp_path / "det.csv").read_text().splitlines()
    sessions = []
    for sep in (",", "\t"):
        args = []
        for camera in ("cam1", "cam2", "cam3"):
            own = [r.partition(",")[2] for r in lines[1:] if r.startswith(camera + ",")]
            path = tmp_path / f"{camera}{'tsv' if sep == chr(9) else ''}.csv"
            path.write_text("\n".join(r.replace(",", sep)
                                      for r in [lines[0].partition(",")[2], *own]) + "\n")
            args += ["--detections", f"{camera}={path}"]
        out = tmp_path / f"i{len(sessions)}.mcap"
        done = run_pslog("import", "--rig", "paper3", *args, "-o", out)
        assert done.code == 0, done.stderr
        d = pslog.read_session(out).detections
        sessions.append((d.frame_time_ns.tolist(), d.frame_camera.tolist(),
                         d.cand_uv.tolist(), d.cand_score.tolist()))
    assert sessions[0] == sessions[1] and len(sessions[0][0]) == 135


def test_semicolon_separated_files_are_told_to_use_commas(inputs, tmp_path):
    """A spreadsheet's CSV where the decimal mark is a comma: 't;x;y;z' named a bad header,
    not why."""
    (tmp_path / "truth.csv").write_text("t;x;y;z\n0;0,3;0,5;1\n1;0,3;0,5;1\n")
    run = run_pslog("eval", inputs / "f.mcap", "--truth", tmp_path / "truth.csv")
    assert_one_line_error(run, 1, contains="bad header 't;x;y;z': expected columns t,x,y,z")
    assert run.stderr.rstrip().endswith("its fields are separated by ';': separate them by "
                                        "commas (or tabs), with decimal points")
    (tmp_path / "cam1.csv").write_text("time;u;v\n0;1,5;2,5\n")
    run = run_pslog("import", "--rig", "paper3", "--detections", f"cam1={tmp_path / 'cam1.csv'}",
                    "-o", tmp_path / "o.mcap")
    assert_one_line_error(run, 1, contains="its fields are separated by ';'")
    assert not (tmp_path / "o.mcap").exists()


def test_a_joined_csv_named_like_camera_equals_file_is_told_how_to_give_it(inputs, tmp_path):
    """A file of every camera's rows named ``cam1=match.csv``, given alone: read as camera
    cam1's file ``match.csv``, the error was 'no such file: match.csv' (exit 1), not which
    file was meant."""
    done = run_pslog("export", inputs / "s.mcap", "--detections", tmp_path / "cam1=match.csv")
    assert done.code == 0, done.stderr
    before = fingerprint(tmp_path)
    run = run_pslog("import", "--rig", "paper3", "--detections", "cam1=match.csv", "-o",
                    "o.mcap", cwd=tmp_path)
    assert_one_line_error(run, 2, contains=(
        "argument --detections cam1=match.csv: read as camera cam1's file match.csv, which "
        "does not exist; for the file cam1=match.csv itself give ./cam1=match.csv"))
    assert_untouched(before, tmp_path)
    run = run_pslog("import", "--rig", "paper3", "--detections", "./cam1=match.csv", "-o",
                    "o.mcap", cwd=tmp_path)
    assert run.code == 0 and "135 detections" in run.stdout, run.stderr


@pytest.mark.parametrize("command", ["eval", "import"])
def test_an_oversized_field_names_its_own_line(inputs, tmp_path, command):
    """The csv module's errors named the line before (the last row read whole): a field of
    200,000 digits on line 3 was said to be on line 2."""
    rows = (["t,x,y,z", "0,0,0,1", "1" * 200_000 + ",0,0,1"] if command == "eval"
            else ["time,u,v", "0,1,2", "1" * 200_000 + ",3,4"])
    (tmp_path / "f.csv").write_text("\n".join(rows) + "\n")
    args = (["eval", inputs / "f.mcap", "--truth", tmp_path / "f.csv"] if command == "eval"
            else ["import", "--rig", "paper3", "--detections", f"cam1={tmp_path / 'f.csv'}",
                  "-o", tmp_path / "o.mcap"])
    assert_one_line_error(run_pslog(*args), 1,
                          contains="f.csv: line 3: field larger than field limit")


_NUMPY_SUPPORT = """
import sys
import numpy as np
import pslog
from pslog.fusion.gating import GatingOptions, _support, gate_common
from pslog.fusion._prepare import default_max_gap_s
from pslog.geometry import fundamental_matrices
from pslog.records import NS
s = pslog.read_session(sys.argv[1])
c, tables = gate_common(s.detections, s.rig)
args = (c, s.rig, fundamental_matrices(s.rig.cameras), tables, GatingOptions(),
        round(default_max_gap_s(s.rig) * NS), False, 0)
mine = _support(*args, compiled=False)
if sys.argv[2] == "compare":
    kernels = _support(*args, compiled=True)
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(mine, kernels))
print("ok", int(np.isfinite(mine[0]).sum()))
"""


@pytest.mark.parametrize("how", ["bounded", "compare"])
def test_the_numpy_support_of_crowded_frames_holds_bounded_memory(inputs, tmp_path, how):
    """The gate's numpy form (where numba cannot start) held every candidate's K² pairs of
    another camera's frames at once: 80 candidates in each frame of one camera asked for
    more than a 1.5 GiB address space; now blocks of 2^20 pairs (131 MB), the same bits as
    the compiled kernels."""
    import subprocess
    import sys

    _crowded_csv(inputs / "s.mcap", tmp_path / "crowded.csv", 80, ("cam1",), 63013)
    done = run_pslog("import", "--rig", "paper3", "--detections", tmp_path / "crowded.csv",
                     "-o", tmp_path / "crowded.mcap")
    assert done.code == 0, done.stderr
    run = subprocess.run([sys.executable, "-c", _NUMPY_SUPPORT, str(tmp_path / "crowded.mcap"),
                          how], capture_output=True, text=True, timeout=300,
                         preexec_fn=_address_space(3 << 29) if how == "bounded" else None)
    assert run.returncode == 0 and run.stdout.startswith("ok"), run.stderr[-800:]


def test_sync_of_a_session_whose_every_candidate_the_gate_rejects_says_so(tmp_path):
    """Two cameras, 40 candidates in every frame: the gate keeps none (the ball cannot be
    told among them), and ``pslog sync`` said the session 'has no detection' (3600 of
    them)."""
    done = run_pslog("simulate", "--rig", "paper2", "--timing", "typeA", "--motion", "throw",
                     "--noise-px", "0.3", "--seed", "63007", "-o", tmp_path / "s.mcap")
    assert done.code == 0, done.stderr
    _crowded_csv(tmp_path / "s.mcap", tmp_path / "c.csv", 40, ("cam1", "cam2"), 63014)
    done = run_pslog("import", "--rig", "paper2", "--detections", tmp_path / "c.csv", "-o",
                     tmp_path / "c.mcap")
    assert done.code == 0, done.stderr
    before = fingerprint(tmp_path)
    run = run_pslog("sync", tmp_path / "c.mcap", "-o", tmp_path / "synced.mcap")
    assert_one_line_error(run, 1, contains=(
        "c.mcap: all 3600 candidates rejected by gating, no frame's ball passed its epipolar "
        "and motion tests", "nothing to sync on"))
    assert_untouched(before, tmp_path)


@pytest.mark.parametrize("first", [b"\xff", b"\0"])
def test_a_huge_binary_file_given_as_the_truth_is_refused_without_reading_it(inputs, tmp_path,
                                                                            first):
    """A video given by mistake: the truth file was read whole into memory (twice: bytes,
    then text) before 'not a text file' (1 GB: 2 GB and 1.7 s); under an 800 MB address
    space a 1.5 GB file was 'out of memory'. Now its first MiB is judged first (a NUL byte:
    no text file either, where a file of zeros read as a header of NULs)."""
    big = tmp_path / "video.mp4"
    with open(big, "wb") as f:  # (sparse: no disk used)
        f.write(first)
        f.truncate(1_500_000_000)
    run = run_pslog("eval", inputs / "f.mcap", "--truth", big,
                    preexec_fn=_address_space(800 << 20))
    why = "is not UTF-8 text" if first == b"\xff" else "is a NUL"
    assert_one_line_error(run, 1, contains=f"video.mp4: not a text file (byte 0 {why})")


def test_a_huge_file_of_zeros_given_as_a_camera_csv_is_refused_without_reading_it(tmp_path):
    """NUL bytes are valid UTF-8: a file of zeros was read whole as one line (1.5 GB: 'out of
    memory' under an 800 MB address space) before the csv module's 'line contains NUL'."""
    zeros = tmp_path / "cam1.csv"
    with open(zeros, "wb") as f:  # (sparse: no disk used)
        f.truncate(1_500_000_000)
    before = fingerprint(tmp_path)
    run = run_pslog("import", "--rig", "paper3", "--detections", f"cam1={zeros}", "-o",
                    tmp_path / "o.mcap", preexec_fn=_address_space(800 << 20))
    assert_one_line_error(run, 1, contains="cam1.csv: not a text CSV file (byte 0 is a NUL)")
    assert_untouched(before, tmp_path)


def test_the_apis_errors_show_a_numpy_array_on_one_line(inputs):
    """``pslog.fuse(clock_uncertainty=np.eye(2, dtype=bool))``, ``read_session(np.eye(3))``,
    ``check_pattern(np.arange(10**6))``: the error named the array by its repr, over several
    lines (a message of one line is the convention of every PslogError)."""
    from pslog.calibration.chessboard import check_pattern
    from pslog.errors import PslogError

    session = pslog.read_session(inputs / "s.mcap")
    calls = [
        (lambda: pslog.fuse(session, "typeA", clock_uncertainty=np.eye(2, dtype=bool)),
         "clock_uncertainty array([[ True, False], [False, True]]): give True or False"),
        (lambda: pslog.read_session(np.eye(2)),
         "read_session: path array([[1., 0.], [0., 1.]]): give a file name"),
        (lambda: pslog.fuse(session, "typeA", rig=np.eye(2)), "rig array([[1., 0.], [0., 1.]])"),
        (lambda: check_pattern(np.arange(10**6)),
         "bad chessboard pattern array([ 0, 1, 2, ..., 999997, 999998, 999999], "
         "shape=(1000000,)): expected COLSxROWS"),
        (lambda: pslog.evaluate(np.eye(2), session.truth), "evaluate: tracks array([[1., 0.],"),
    ]
    for call, says in calls:
        with pytest.raises(PslogError) as error:
            call()
        assert "\n" not in str(error.value) and says in str(error.value), str(error.value)


def test_a_rig_camera_whose_name_holds_an_equals_sign_takes_its_file(inputs, tmp_path):
    """A rig may name a camera ``left=2``; ``--detections left=2=cam2.csv`` was split at the
    first '=', 'no camera 'left' in the rig' (exit 2): that camera's file could not be given."""
    shown = run_pslog("rig", "show", "paper3")
    assert shown.code == 0, shown.stderr
    (tmp_path / "rig.toml").write_text(shown.stdout.replace('name = "cam2"', 'name = "left=2"'))
    done = run_pslog("export", inputs / "s.mcap", "--detections", tmp_path / "det.csv")
    assert done.code == 0, done.stderr
    lines = (tmp_path / "det.csv").read_text().splitlines()
    for camera in ("cam1", "cam2"):
        own = [r.partition(",")[2] for r in lines[1:] if r.startswith(camera + ",")]
        (tmp_path / f"{camera}.csv").write_text(
            "\n".join([lines[0].partition(",")[2], *own]) + "\n")
    run = run_pslog("import", "--rig", "rig.toml", "--detections", "cam1=cam1.csv",
                    "--detections", "left=2=cam2.csv", "-o", "o.mcap", cwd=tmp_path)
    assert run.code == 0, run.stderr
    d = pslog.read_session(tmp_path / "o.mcap").detections
    assert d.camera_names[1] == "left=2" and np.count_nonzero(d.frame_camera == 1) == 45
