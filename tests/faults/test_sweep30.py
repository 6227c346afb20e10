"""Session 30's walkthrough and hostile-input sweep through the real CLI: an output spelled
as a folder without a name, an output folder that is a file, a folder as a video source, a
full disk before the demo's first byte, absurd values in a points file, and smooth's options
given to a fuse where smooth does not run."""

from __future__ import annotations

import contextlib
from pathlib import Path

import pytest

from pslog.rig import builtin_rig

from ._inputs import write_points_csv
from ._mounts import fill, small_tmpfs
from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep30")
    (folder / "rig.toml").write_text(builtin_rig("paper3").to_toml(), encoding="utf-8")
    write_points_csv(folder / "pts.csv")
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.5",
                     "-o", folder / "s.mcap")
    assert done.code == 0, done.stderr
    done = run_pslog("export", folder / "s.mcap", "--detections", folder / "det.csv")
    assert done.code == 0, done.stderr
    done = run_pslog("fuse", folder / "s.mcap", "--method", "typeA", "-o",
                     folder / "fused.mcap")
    assert done.code == 0, done.stderr
    (folder / "afile").write_text("not a folder\n", encoding="utf-8")
    (folder / "clips").mkdir()
    return folder


#: every writer, its output given as {o}
WRITERS = {
    "simulate": ["simulate", "--rig", "rig.toml", "--duration", "0.3", "-o", "{o}"],
    "import": ["import", "--rig", "rig.toml", "--detections", "det.csv", "-o", "{o}"],
    "export --csv": ["export", "s.mcap", "--detections", "{o}"],
    "fuse": ["fuse", "s.mcap", "--method", "typeA", "-o", "{o}"],
    "recover": ["recover", "s.mcap", "-o", "{o}"],
    "view --save": ["view", "s.mcap", "--save", "{o}"],
    "rig export": ["rig", "export", "rig.toml", "--format", "anipose", "-o", "{o}"],
    "calibrate": ["calibrate", "--points", "pts.csv", "--name", "cam9", "--width", "640",
                  "--height", "480", "--rig", "{o}"],
    "record": ["record", "--synthetic", "--rig", "rig.toml", "--fast", "-o", "{o}"],
    "live --record": ["live", "--rig", "rig.toml", "--listen", "udp://127.0.0.1:0",
                      "--duration", "1", "--record", "{o}"],
}


@pytest.mark.parametrize("writer, spelling", [(w, ".") for w in WRITERS] + [
    ("simulate", "/"), ("fuse", "/")])  # ('/' takes the path '.' takes)
def test_an_output_spelled_as_a_folder_without_a_name_is_refused_in_one_line(
        writer, spelling, inputs):
    """Was a traceback ending in "ValueError: PosixPath('.') has an empty name" (the
    output's .partial was named before the output was found to be a folder)."""
    before = fingerprint(inputs)
    args = [a.format(o=spelling) for a in WRITERS[writer]]
    assert_one_line_error(run_pslog(*args, cwd=inputs), 1,
                          contains=f"{spelling} is a folder; give a file name")
    assert_untouched(before, inputs)


@pytest.mark.parametrize("args, contains", [
    # was "output folder does not exist: .../afile" (it exists: a file)
    (["simulate", "--rig", "rig.toml", "-o", "afile/x.mcap"],
     "output folder afile is a regular file, not a folder"),
    (["export", "s.mcap", "--detections", "afile/x.csv"],
     "output folder afile is a regular file, not a folder"),
    (["export", "fused.mcap", "--tum", "afile/traj"],
     "--tum afile/traj: afile is a regular file, not a folder"),
    (["simulate", "--rig", "rig.toml", "-o", "nowhere/x.mcap"],
     "output folder does not exist: nowhere"),
])
def test_an_output_folder_that_is_a_file_is_named_as_a_file(args, contains, inputs):
    before = fingerprint(inputs)
    assert_one_line_error(run_pslog(*args, cwd=inputs), 1, contains=contains)
    assert_untouched(before, inputs)


@pytest.mark.parametrize("command", ["record", "live"])
def test_a_folder_given_as_a_video_source_is_named_a_folder(command, inputs, tmp_path):
    """Was "camera 'cam1': video file not found: clips" for a folder that exists."""
    before = fingerprint(inputs)
    out = (["-o", tmp_path / "s.mcap"] if command == "record" else
           ["--listen", "udp://127.0.0.1:0", "--duration", "1"])
    assert_one_line_error(run_pslog(
        command, "--rig", "rig.toml", "--source", "cam1=clips", *out, cwd=inputs), 1,
        contains="camera 'cam1': clips is a folder, not a video file")
    assert_one_line_error(run_pslog(
        command, "--rig", "rig.toml", "--source", "cam1=missing.mp4", *out, cwd=inputs), 1,
        contains="camera 'cam1': video file not found: missing.mp4")
    assert_untouched(before, inputs)
    assert not (tmp_path / "s.mcap").exists()


@pytest.mark.parametrize("command", ["demo", "record"])
def test_a_disk_full_before_the_first_byte_says_cannot_write_once(command, inputs, tmp_path):
    """The demo on a disk already full said "cannot write d/session.mcap: cannot write
    d/session.mcap: No space left on device; nothing was recorded; stopped the cameras; ..."
    (the recorder's whole message taken for the OS's reason)."""
    with contextlib.ExitStack() as stack:
        disk = stack.enter_context(small_tmpfs(tmp_path / "disk", "64k"))
        fill(disk)
        before = fingerprint(disk)
        args = (["demo", "--out", disk / "d", "--duration", "0.3"] if command == "demo" else
                ["record", "--synthetic", "--rig", "rig.toml", "--fast", "--duration", "0.3",
                 "-o", disk / "s.mcap"])
        line = assert_one_line_error(run_pslog(*args, cwd=inputs, timeout=120), 1,
                                     contains="No space left on device")
        assert line.count("cannot write") == 1, line
        assert ": No space left on device; " in line, line
        assert_untouched(before, disk)


@pytest.mark.parametrize("row, contains", [
    # was "the 41 points are coplanar (off-plane spread 3.3e-300 of their extent)"
    ("1e300,1,1,300,200", "x 1e300 is beyond any surveyed point (at most 1e+06 m from"),
    ("1,1,-2e6,300,200", "z -2e6 is beyond any surveyed point"),
    ("1,1,1,1e7,200", "u 1e7 is beyond any image (at most 655360 pixels)"),
    ("1,1,1,300,-7e5", "v -7e5 is beyond any image"),
])
def test_calibrate_names_a_point_value_beyond_any_survey_or_image(row, contains, inputs,
                                                                  tmp_path):
    points = tmp_path / "pts.csv"
    points.write_text((inputs / "pts.csv").read_text(encoding="utf-8") + row + "\n",
                      encoding="utf-8")
    before = fingerprint(inputs, tmp_path)
    assert_one_line_error(run_pslog(
        "calibrate", "--points", points, "--name", "cam1", "--width", "640", "--height", "480",
        "--rig", tmp_path / "r.toml"), 1, contains=(f"pts.csv:42: {contains}",))
    assert_untouched(before, inputs, tmp_path)


def test_fuse_says_smooths_options_are_ignored_when_smooth_does_not_run(inputs, tmp_path):
    """--rate, --detector-offset-mm and --detector-bias-px are smooth's: given to a fuse
    that does not run smooth they were ignored without a word (--type-a-max-std-mm says so)."""
    done = run_pslog("fuse", inputs / "s.mcap", "--method", "typeA", "--rate", "90",
                     "--detector-offset-mm", "0", "--detector-bias-px", "1", "-o",
                     tmp_path / "a.mcap")
    assert done.code == 0 and not done.stderr, done.stderr
    assert ("--rate 90, --detector-offset-mm 0, --detector-bias-px 1 ignored: smooth does "
            "not run (name it with --method smooth)") in done.stdout.splitlines(), done.stdout
    done = run_pslog("fuse", inputs / "s.mcap", "--method", "typeA,smooth", "--rate", "90",
                     "-o", tmp_path / "b.mcap")
    assert done.code == 0 and "ignored" not in done.stdout, done.stdout
    done = run_pslog("fuse", inputs / "s.mcap", "--method", "typeA", "-o", tmp_path / "c.mcap")
    assert done.code == 0 and "ignored" not in done.stdout, done.stdout


def _into_full_stdout(args, tmp_path, cwd=None) -> str:
    """``pslog ARGS`` with standard output a full device of our own: its one error line."""
    import os
    import stat
    import subprocess
    import sys

    from .promises import Run

    full = tmp_path / "full"
    if not full.exists():
        try:
            os.mknod(full, 0o666 | stat.S_IFCHR, os.makedev(1, 7))  # our own /dev/full
        except PermissionError:
            pytest.skip("mknod needs root")
    with open(full, "w") as stdout:
        proc = subprocess.run([sys.executable, "-m", "pslog.cli", *map(str, args)], cwd=cwd,
                              stdout=stdout, stderr=subprocess.PIPE, text=True, timeout=120)
    return assert_one_line_error(Run(tuple(map(str, args)), proc.returncode, "", proc.stderr),
                                 1)


def test_calibrate_into_a_full_standard_output_says_its_rig_was_written(inputs, tmp_path):
    """calibrate updates its --rig in place (an "update", not an "output" of the command
    line): with standard output full it said "cannot write to standard output" alone, the rig
    written all the same; now "...; r.toml written complete", as every other writer says.
    A calibrate that fails keeps its one line about the failure."""
    rig = tmp_path / "r.toml"
    for points, ends in (("pts.csv", f"No space left on device; {rig} written complete"),
                         ("rig.toml", "got name = \"paper3\")")):
        line = _into_full_stdout(["calibrate", "--points", inputs / points, "--name", "cam9",
                                  "--width", "640", "--height", "480", "--rig", rig, "--force"],
                                 tmp_path)
        assert line.endswith(ends), line
    assert "cam9" in rig.read_text(encoding="utf-8")


@pytest.mark.parametrize("command", ["export --tum", "demo", "batch"])
def test_a_full_standard_output_names_the_folders_a_command_wrote(command, inputs, tmp_path):
    """export --tum, demo and batch write folders (and batch its summary tables), which the
    line for a full standard output did not name ("cannot write to standard output: No space
    left on device" alone): now "...; traj/ written complete", as for a file."""
    if command == "export --tum":
        args, made = ["export", inputs / "fused.mcap", "--tum", tmp_path / "traj"], [
            f"{tmp_path / 'traj'}/"]
    elif command == "demo":
        args, made = ["demo", "--out", tmp_path / "d", "--duration", "0.3"], [
            f"{tmp_path / 'd'}/"]
    else:
        args = ["batch", inputs / "s.mcap", "--do", "fuse", "-o", tmp_path / "b", "--workers",
                "1"]
        made = [f"{tmp_path / 'b' / 'summary.csv'}", f"{tmp_path / 'b' / 'summary.parquet'}"]
    line = _into_full_stdout(args, tmp_path, cwd=inputs)
    assert line.endswith(f"No space left on device; {', '.join(made)} written complete"), line
    for path in made:
        assert Path(path).exists(), path


def test_import_of_one_row_says_one_detection_in_one_frame(inputs, tmp_path):
    """Was "wrote s.mcap: 1 detections in 1 frames of 3 cameras"."""
    (tmp_path / "one.csv").write_text("camera,time,u,v\ncam1,0.5,320,240\n", encoding="utf-8")
    done = run_pslog("import", "--rig", inputs / "rig.toml", "--detections",
                     tmp_path / "one.csv", "-o", tmp_path / "s.mcap")
    assert done.code == 0, done.stderr
    assert ": 1 detection in 1 frame of 3 cameras (cam1, cam2, cam3)" in done.stdout, done.stdout


def test_import_refuses_a_candidate_repeated_in_the_csv(inputs, tmp_path):
    """A CSV appended to itself was imported as two candidates per frame (the ball's
    candidate twice, at one pixel): typeA then left 22 of a session's 105 points out as in
    doubt. Now refused, naming the first repeat; distinct candidates of one frame, and a
    frame given twice as missed (u, v empty), stay accepted."""
    rows = (inputs / "det.csv").read_text(encoding="utf-8").splitlines()
    header, body = rows[0], rows[1:]
    doubled = tmp_path / "doubled.csv"
    doubled.write_text("\n".join([header, *body, *body]) + "\n", encoding="utf-8")
    cam, t, u, v = body[0].split(",")[:4]
    before = fingerprint(inputs, tmp_path)
    assert_one_line_error(run_pslog(
        "import", "--rig", inputs / "rig.toml", "--detections", doubled, "-o",
        tmp_path / "s.mcap"), 1, contains=(
        f"doubled.csv: lines 2 and {len(body) + 2} are the same candidate (camera {cam} at "
        f"{t} s, pixel ({float(u):g}, {float(v):g})): rows repeated",))
    assert_untouched(before, inputs, tmp_path)
    # two more candidates, 0.5 px away in u and in v, and a missed frame given twice:
    # accepted
    fields = body[0].split(",")
    beside = ",".join([*fields[:2], repr(float(u) + 0.5), *fields[3:]])
    below = ",".join([*fields[:3], repr(float(v) + 0.5), *fields[4:]])
    missed = f"{cam},{float(t) + 5:.9f},,,999,"
    fine = tmp_path / "fine.csv"
    fine.write_text("\n".join([header, *body, beside, below, missed, missed]) + "\n",
                    encoding="utf-8")
    done = run_pslog("import", "--rig", inputs / "rig.toml", "--detections", fine, "-o",
                     tmp_path / "s.mcap")
    assert done.code == 0, done.stderr
    assert f"{len(body) + 2} detections in {len(body) + 1} frames" in done.stdout, done.stdout


@pytest.mark.parametrize("blackout, starts", [("cam2=100:1", "100"), ("cam1=1e308:1", "1e+308"),
                                              ("cam3=0.5:1", "0.5")])
def test_simulate_refuses_a_blackout_that_starts_after_the_session(blackout, starts, tmp_path):
    """Was accepted: a session that hid nothing, yet said "candidate faults: blackouts" and
    kept the blackout in its metadata. The session here lasts 0.5 s (a blackout from 0.5 s
    on would begin at its end)."""
    before = fingerprint(tmp_path)
    assert_one_line_error(run_pslog(
        "simulate", "--rig", "paper3", "--duration", "0.5", "--blackout", blackout, "-o",
        tmp_path / "s.mcap"), 2, contains=(
        f"argument --blackout: camera {blackout.split('=')[0]}'s blackout starts at {starts} "
        f"s, not before the session ends (0.5 s): it would hide nothing",))
    assert_untouched(before, tmp_path)
    done = run_pslog("simulate", "--rig", "paper3", "--duration", "0.5", "--blackout",
                     "cam3=0.49:1", "-o", tmp_path / "s.mcap")
    assert done.code == 0, done.stderr


@pytest.mark.parametrize("name, text, contains", [
    ("cams.yml", "%YAML:1.0\n---\ncam: [1, 2\n", "line 3: Missing , between the elements"),
    ("cams.xml", '<?xml version="1.0"?>\n<opencv_storage>\n<a>1</b>\n',
     "line 3: Mismatched closing tag"),
    ("det.csv", None, "line 1: Only collections as YAML streams are supported"),
])
def test_a_malformed_opencv_file_is_named_with_its_line_and_reason(name, text, contains,
                                                                   inputs, tmp_path):
    """Was "malformed OpenCV FileStorage file: parse" (OpenCV's function name alone)."""
    path = inputs / name if text is None else tmp_path / name
    if text is not None:
        path.write_text(text, encoding="utf-8")
    before = fingerprint(inputs, tmp_path)
    assert_one_line_error(run_pslog("rig", "import", path, "--format", "opencv", "-o",
                                    tmp_path / "r.toml"), 1,
                          contains=f"{name}: malformed OpenCV FileStorage file: {contains}")
    assert_untouched(before, inputs, tmp_path)


def test_view_to_a_full_standard_output_is_one_line_when_it_fuses_on_the_fly(inputs,
                                                                            tmp_path):
    """view --stdout of a session without tracks printed its note "fused on the fly: typeA"
    on stderr before the write failed: two lines. The notes now follow a complete write."""
    line = _into_full_stdout(["view", inputs / "s.mcap", "--stdout"], tmp_path)
    assert line.endswith("cannot write to standard output: No space left on device"), line
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "pslog.cli", "view", inputs / "s.mcap",
                           "--stdout"], capture_output=True, timeout=120)
    assert done.returncode == 0 and done.stdout[:4] == b"RRF2", done.stdout[:4]
    lines = done.stderr.decode().splitlines()
    assert lines[0] == "fused on the fly: typeA" and lines[1].startswith("logged "), lines


@pytest.mark.parametrize("args", [["--help"], ["--version"], ["fuse", "--help"]])
def test_help_into_a_full_standard_output_is_one_line_and_exit_1(args, tmp_path):
    """``pslog --help`` (``--version``, a command's ``--help``) into a full standard output
    said nothing and exited 0 (argparse swallows its write's OSError): now one line, exit 1;
    into a pipe whose reader took it all, exit 0 and the text as before."""
    line = _into_full_stdout(args, tmp_path)
    assert line.endswith("error: cannot write to standard output: No space left on device"), line
    done = run_pslog(*args)
    assert done.code == 0 and done.stdout.startswith(("usage: pslog", "pslog ")), done
