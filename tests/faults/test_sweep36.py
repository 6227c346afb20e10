"""Session 36's hostile-input sweep through the real CLI: values and paths no earlier sweep
tried. ``view --detail 1e300`` (or ``A:B`` with a bound that large) was a traceback (its
nanoseconds, 1e309, a float infinity no int holds). A loop of symbolic links given as an
input was "no such file" (``Path.exists`` is False for it), and so was a link whose target
is gone: the user looks for a file that is there; each is now named for what it is. The
commands messages suggest (``run 'pslog recover P -o FIXED.mcap'``, ``open it with: rerun
P``) held a path with a space or a ``$`` unquoted: pasted into a shell, two arguments."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep36")
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.5",
                     "--seed", "48036", "-o", folder / "s.mcap")
    assert done.code == 0, done.stderr
    done = run_pslog("fuse", "s.mcap", "--method", "typeA", "-o", "fused.mcap", cwd=folder)
    assert done.code == 0, done.stderr
    (folder / "loop1").symlink_to("loop2")
    (folder / "loop2").symlink_to("loop1")
    (folder / "gone.mcap").symlink_to("moved-away.mcap")
    (folder / "link.mcap").symlink_to("fused.mcap")
    return folder


@pytest.mark.parametrize("detail, note", [
    ("1e300", None), ("0:1e300", None),
    ("1e300:2e300", "the full-detail range 1e+300 to 2e+300 s holds no frame shown")])
def test_a_detail_range_beyond_any_clock_is_everything_from_its_start(detail, note, inputs,
                                                                        tmp_path):
    before = fingerprint(inputs)
    out = tmp_path / "v.rrd"
    run = run_pslog("view", inputs / "s.mcap", "--save", out, "--detail", detail)
    assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
    assert out.stat().st_size > 0
    if note:  # the seconds given, not the clamped nanoseconds
        assert note in run.stdout, run.stdout
    else:
        assert "full-detail range" not in run.stdout, run.stdout
    assert_untouched(before, inputs)


#: every kind of input, given as {p}
READERS = {
    "info": ["info", "{p}"],
    "fuse": ["fuse", "{p}", "-o", "out.mcap"],
    "recover": ["recover", "{p}", "-o", "out.mcap"],
    "view": ["view", "{p}", "--save", "out.rrd"],
    "rig show": ["rig", "show", "{p}"],
    "simulate --rig": ["simulate", "--rig", "{p}", "-o", "out.mcap"],
    "import --detections": ["import", "--rig", "paper3", "--detections", "{p}", "-o",
                            "out.mcap"],
    "calibrate --points": ["calibrate", "--points", "{p}", "--name", "cam9", "--width", "640",
                           "--height", "480", "--rig", "out.toml"],
    "calibrate --images": ["calibrate", "--chessboard", "9x6", "--square", "0.025",
                           "--images", "{p}", "--name", "cam9", "--rig", "out.toml"],
    "record --source": ["record", "--rig", "paper3", "--source", "cam1={p}", "-o", "out.mcap"],
}


@pytest.mark.parametrize("link, says", [
    ("loop1", "loop1: a loop of symbolic links"),
    ("gone.mcap", "gone.mcap is a symbolic link to moved-away.mcap, which does not exist")])
@pytest.mark.parametrize("reader", list(READERS))
def test_a_link_that_leads_nowhere_is_named_for_what_it_is(reader, link, says, inputs):
    before = fingerprint(inputs)
    args = [a.format(p=link) for a in READERS[reader]]
    line = assert_one_line_error(run_pslog(*args, cwd=inputs), 1, contains=says)
    assert "no such file" not in line and "not found" not in line, line
    assert_untouched(before, inputs)


def _pasted(line: str, cwd: Path, env=None) -> subprocess.CompletedProcess:
    """``line`` run as a user pasting it runs it: read by bash as a line of input, with its
    history expansion on (an interactive shell's: ``!`` in double quotes is expanded)."""
    return subprocess.run(["bash"], input=f"set -o history -H\n{line}\n", cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=120)


def _words(command: str, cwd: Path) -> list[str]:
    """The arguments bash makes of ``command`` (as a user pasting it would run it)."""
    run = _pasted(f'set -- {command}; printf "%s\\n" "$@"', cwd)
    assert run.returncode == 0 and not run.stderr, run.stderr
    return run.stdout.splitlines()


def test_the_recover_command_a_message_suggests_can_be_pasted_into_a_shell(inputs, tmp_path):
    name = "my $match!x \u00fc.mcap"
    data = (inputs / "s.mcap").read_bytes()
    (tmp_path / name).write_bytes(data[:len(data) - 3000])  # cut short, as by a crash
    line = assert_one_line_error(run_pslog("info", name, cwd=tmp_path), 1)
    command = line.split("run '", 1)[1].split("'", 1)[0]
    assert _words(command, tmp_path) == ["pslog", "recover", name, "-o", "FIXED.mcap"], line
    # and run as pasted, it salvages the file
    env = {**os.environ, "PSLOG_PY": sys.executable}
    done = _pasted(f'pslog() {{ "$PSLOG_PY" -m pslog.cli "$@"; }}; {command}', tmp_path, env)
    assert done.returncode == 0 and (tmp_path / "FIXED.mcap").stat().st_size > 0, done.stderr


def test_the_rerun_command_view_suggests_can_be_pasted_into_a_shell(inputs, tmp_path):
    name = "my view!x \u00fc.rrd"
    run = run_pslog("view", inputs / "s.mcap", "--save", name, cwd=tmp_path)
    assert run.code == 0, run.stderr
    line = next(x for x in run.stdout.splitlines() if "open it with: " in x)
    assert _words(line.split("open it with: ", 1)[1], tmp_path)[1:] == [name], line


def _clip(path: Path, frames: int = 60) -> None:
    """An MJPEG AVI of ``frames`` 640x480 frames of an orange ball crossing a green field."""
    import cv2
    import numpy as np

    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, (640, 480))
    for i in range(frames):
        image = np.full((480, 640, 3), (40, 120, 40), np.uint8)
        cv2.circle(image, (100 + 4 * i, 200), 10, (0, 128, 255), -1)
        writer.write(image)
    writer.release()


@pytest.mark.parametrize("command", ["record", "live"])
def test_a_video_source_cut_short_is_said_not_ended_as_if_whole(command, tmp_path):
    """A video file cut short (a full disk or a crash while it was written): the decoder
    stops at its first unreadable frame exactly as at the end, and the recording said
    "0 dropped ... end of source" with half the frames, after FFmpeg's own line; it says, in
    its words alone, how many of the frames the file declares were read, and a whole file
    still ends plainly."""
    _clip(tmp_path / "whole.avi")
    _clip(tmp_path / "cut.avi")
    size = (tmp_path / "cut.avi").stat().st_size
    with open(tmp_path / "cut.avi", "r+b") as f:
        f.truncate(size // 2)
    args = ["--rig", "paper2", "--source", "cam1=whole.avi", "--source", "cam2=cut.avi"]
    args += ["-o", "rec.mcap"] if command == "record" else ["--duration", "3"]
    run = run_pslog(command, *args, cwd=tmp_path, timeout=120)
    assert run.code == 0 and "Traceback" not in run.stderr, run.stderr
    said = [line for line in run.stderr.splitlines() if "frames its header declares" in line]
    assert said and all("cam2" in line and "of the 60 frames" in line for line in said), \
        run.stderr
    assert not any("cam1" in line for line in said), run.stderr
    # and in pslog's words alone: not FFmpeg's ("[mjpeg @ 0x...] overread 2")
    assert " @ 0x" not in run.stderr and "overread" not in run.stderr, run.stderr


@pytest.mark.parametrize("link, says", [
    ("loop1", "--tum loop1 is a loop of symbolic links"),
    ("gone.mcap", "--tum gone.mcap is a symbolic link to moved-away.mcap, which does not "
                  "exist")])
def test_a_tum_folder_that_is_a_link_leading_nowhere_is_named(link, says, inputs):
    """``export --tum LINK`` said "cannot write LINK: File exists" (mkdir on the link)."""
    before = fingerprint(inputs)
    line = assert_one_line_error(run_pslog("export", "fused.mcap", "--tum", link, cwd=inputs),
                                 1, contains=says)
    assert "File exists" not in line, line
    assert_untouched(before, inputs)


@pytest.mark.parametrize("second", ["fused.mcap", "./fused.mcap", "link.mcap"])
def test_view_refuses_a_session_file_given_twice(second, inputs, tmp_path):
    """``view fused.mcap fused.mcap`` showed every track twice (``typeA`` and
    ``typeA_fused``) without a word of why; ``batch`` takes a file once however often given."""
    before = fingerprint(inputs)
    run = run_pslog("view", "fused.mcap", second, "--save", tmp_path / "v.rrd", cwd=inputs)
    line = assert_one_line_error(run, 1, contains=(f"{Path(second)} is given twice",
                                                   "give each session file once"))
    if second == "link.mcap":
        assert "(as fused.mcap and link.mcap)" in line, line
    assert not (tmp_path / "v.rrd").exists()
    assert_untouched(before, inputs)


@pytest.mark.parametrize("command", ["record", "live"])
def test_a_device_index_beyond_a_c_int_is_a_usage_error(command, tmp_path):
    """``--source cam1=99999999999999999999`` was the camera's failure in OpenCV's words, a
    several-line "Overload resolution failed" (VideoCapture takes a C int), and the others
    recorded on."""
    args = ["--rig", "paper2", "--source", "cam1=99999999999999999999", "--source", "cam2=0"]
    args += ["-o", "rec.mcap"] if command == "record" else ["--duration", "1"]
    line = assert_one_line_error(run_pslog(command, *args, cwd=tmp_path, timeout=60), 2,
                                 contains=("device index 99999999999999999999 is beyond any "
                                           "camera (at most 2147483647)"))
    assert "Overload" not in line, line
    assert not (tmp_path / "rec.mcap").exists()


def test_fuse_says_a_rig_that_changes_the_frame_rate(inputs, tmp_path):
    """``fuse --rig`` with a rig of another recording (60 fps for a 30-fps session) fused
    without a word, its tracks changed (the frame periods set the fusion's timing)."""
    from pslog.rig import builtin_rig

    text = builtin_rig("paper3").to_toml()
    (tmp_path / "same.toml").write_text(text, encoding="utf-8")
    (tmp_path / "fast.toml").write_text(text.replace("fps = 30.0", "fps = 60.0", 1),
                                        encoding="utf-8")
    before = fingerprint(inputs)
    for rig, said in (("same.toml", None), ("fast.toml", "cam1 (30 -> 60 fps)")):
        run = run_pslog("fuse", inputs / "s.mcap", "--method", "nearest", "--rig", rig, "-o",
                        f"{rig}.mcap", cwd=tmp_path)
        assert run.code == 0, run.stderr
        notes = [x for x in run.stdout.splitlines() if "changes the frame rate" in x]
        if said is None:
            assert not notes, run.stdout
        else:
            assert len(notes) == 1 and said in notes[0] and "cam2" not in notes[0], run.stdout
    assert_untouched(before, inputs)


def _suggested(line: str, start: str) -> str:
    """The command in quotes that ``line`` suggests, from ``start`` (``'pslog ...'``) to its
    closing quote, a shell redirection ``> FILE`` at its end cut off."""
    command = line.split(f"'{start}", 1)[1].split("'", 1)[0]
    return start + command.split(" > ", 1)[0]


def test_the_other_commands_messages_suggest_can_be_pasted_into_a_shell(inputs, tmp_path):
    """Four more messages held a path unquoted in the command they suggest (the walk of
    session 36): import given a session ('pslog export P --detections DET.csv'), a rig
    reader given a session ('pslog rig show P > rig.toml'), fuse --rig with a calibration
    whose timing keys fuse does not apply ('pslog rig import P -o rig.toml') and record's
    note on measured offsets ('pslog rig show P > fixed.toml', 'pslog fuse P --rig
    fixed.toml'): pasted, a path with a space was two arguments."""
    name = "my $match \u00fc.mcap"
    (tmp_path / name).write_bytes((inputs / "s.mcap").read_bytes())
    line = assert_one_line_error(run_pslog("import", "--rig", "paper3", "--detections", name,
                                           "-o", "x.mcap", cwd=tmp_path), 1)
    assert _words(_suggested(line, "pslog export "), tmp_path) == [
        "pslog", "export", name, "--detections", "DET.csv"], line
    line = assert_one_line_error(run_pslog("rig", "import", name, "-o", "r.toml",
                                           cwd=tmp_path), 1)
    assert _words(_suggested(line, "pslog rig show "), tmp_path) == [
        "pslog", "rig", "show", name], line

    # a calibration (anipose) whose offset is not the session's: its keys are not applied
    cal = "my cal.toml"
    done = run_pslog("rig", "export", name, "--format", "anipose", "-o", cal, cwd=tmp_path)
    assert done.code == 0, done.stderr
    text = (tmp_path / cal).read_text()
    first = text.index("offset = ")
    (tmp_path / cal).write_text(text[:first] + "offset = 0.005"
                                + text[text.index("\n", first):])
    done = run_pslog("fuse", name, "--rig", cal, "--method", "typeA", "-o", "f.mcap",
                     cwd=tmp_path)
    assert done.code == 0, done.stderr
    line = next(x for x in done.stdout.splitlines() if "not applied" in x)
    assert _words(_suggested(line, "pslog rig import "), tmp_path) == [
        "pslog", "rig", "import", cal, "-o", "rig.toml"], line


def test_records_note_on_measured_offsets_suggests_commands_that_paste(tmp_path):
    import cv2
    import numpy as np

    writer = cv2.VideoWriter(str(tmp_path / "clip.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30,
                             (640, 480))
    for i in range(20):  # an orange ball crossing the image
        image = np.full((480, 640, 3), 40, np.uint8)
        cv2.circle(image, (100 + 20 * i, 240), 12, (0, 128, 255), -1)
        writer.write(image)
    writer.release()
    rig = run_pslog("rig", "show", "paper3", "--timing", "typeA", cwd=tmp_path)
    (tmp_path / "rig.toml").write_text(rig.stdout)
    name = "my rec.mcap"
    for i in (2, 3):  # a file each (one file for two cameras is refused since session 42)
        shutil.copyfile(tmp_path / "clip.avi", tmp_path / f"clip{i}.avi")
    done = run_pslog("record", "--rig", "rig.toml", "--source=cam1=clip.avi",
                     *(f"--source=cam{i}=clip{i}.avi" for i in (2, 3)),
                     "-o", name, cwd=tmp_path)
    assert done.code == 0, done.stderr
    # three copies of one video: every shutter offset measured 0, the rig's type A differs
    line = next(x for x in done.stderr.splitlines() if "measured shutter offsets" in x)
    assert _words(_suggested(line, "pslog rig show "), tmp_path) == [
        "pslog", "rig", "show", name], line
    assert _words(_suggested(line, "pslog fuse "), tmp_path) == [
        "pslog", "fuse", name, "--rig", "fixed.toml"], line


def test_the_rig_import_commands_a_calibration_file_suggests_can_be_pasted(tmp_path):
    """calibrate --rig given an anipose or OpenCV calibration ('convert it with 'pslog rig
    import P -o rig.toml''), rig import of a metres file with --units mm ('... --units m
    -o rig.toml'): the path with a space was two arguments."""
    from pslog.interchange.rig_formats import rig_to_format
    from pslog.rig import builtin_rig

    points = Path(__file__).resolve().parents[2] / "samples" / "cam1_points.csv"
    for fmt, name in (("anipose", "my cal.toml"), ("opencv", "my cal.yml")):
        (tmp_path / name).write_text(rig_to_format(builtin_rig("paper3"), fmt, "m",
                                                   Path(name).suffix), encoding="utf-8")
        before = fingerprint(tmp_path)
        line = assert_one_line_error(run_pslog(
            "calibrate", "--points", points, "--name", "cam1", "--width", "640", "--height",
            "480", "--rig", name, cwd=tmp_path), 1)
        assert _words(_suggested(line, "pslog rig import "), tmp_path) == [
            "pslog", "rig", "import", name, "-o", "rig.toml"], line
        assert_untouched(before, tmp_path)
        line = assert_one_line_error(run_pslog("rig", "import", name, "--units", "mm", "-o",
                                               "r.toml", cwd=tmp_path), 1)
        assert _words(_suggested(line, "pslog rig import "), tmp_path) == [
            "pslog", "rig", "import", name, "--units", "m", "-o", "rig.toml"], line


# ---- the sweep's leftovers, fixed by the lead (session 36) --------------------------------
def test_import_names_the_csv_whose_times_span_too_long(tmp_path):
    """``session_clock`` judges the times, not the file: the one-line error named no file."""
    (tmp_path / "far times.csv").write_text("camera,time,u,v\ncam1,-5e9,1,2\ncam1,5e9,1,2\n")
    done = run_pslog("import", "--detections", "far times.csv", "--rig", "paper2", "-o",
                     "s.mcap", cwd=tmp_path)
    assert_one_line_error(done, contains=("far times.csv: times span", "9.22e+09 s"))
    assert not (tmp_path / "s.mcap").exists()


def test_export_counts_one_detection_in_the_singular(tmp_path):
    (tmp_path / "one.csv").write_text("camera,time,u,v\ncam1,0.1,1,2\n")
    done = run_pslog("import", "--detections", "one.csv", "--rig", "paper2", "-o", "one.mcap",
                     cwd=tmp_path)
    assert done.code == 0, done.stderr
    done = run_pslog("export", "one.mcap", "--detections", "out.csv", cwd=tmp_path)
    assert done.code == 0, done.stderr
    assert "wrote out.csv: 1 detection\n" in done.stdout, done.stdout


def test_redetect_never_suggests_its_own_input_as_the_new_recording(tmp_path):
    """A session without frames: the suggested ``record ... -o NAME`` must not be the
    session given (pasted, it would be refused, or with --force replace the input)."""
    (tmp_path / "one.csv").write_text("camera,time,u,v\ncam1,0.1,1,2\n")
    assert run_pslog("import", "--detections", "one.csv", "--rig", "paper2", "-o", "s.mcap",
                     cwd=tmp_path).code == 0
    done = run_pslog("redetect", "s.mcap", "-o", "again.mcap", cwd=tmp_path)
    line = assert_one_line_error(done, contains="no stored frames")
    assert "-o s.mcap" not in line and "-o with_frames.mcap" in line, line
