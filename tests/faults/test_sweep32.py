"""Session 32's hostile-input sweep through the real CLI: an output spelled as a folder
(``-o out.mcap/``) was written as the file ``out.mcap`` (pathlib drops the trailing ``/``;
``open()`` refuses such a name), by every writer; ``export --tum ''`` was "nothing to
export" (exit 1), not a usage error; ``calibrate --rig new.yml`` wrote TOML under an OpenCV
name; every MCAP writer wrote its session under any name (``simulate -o sim.csv``)."""

from __future__ import annotations

import pytest

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog
from .test_sweep30 import WRITERS, inputs  # noqa: F401 (the fixture)


@pytest.mark.parametrize("writer, spelling", [
    ("fuse", "out.mcap/"), ("simulate", "out.mcap/."), ("view --save", "out.rrd/"),
    ("export --csv", "out.csv/"), ("rig export", "new.toml/"), ("recover", "sub/..")])
def test_an_output_spelled_as_a_folder_is_refused(writer, spelling, inputs):  # noqa: F811
    before = fingerprint(inputs)
    args = [a.format(o=spelling) for a in WRITERS[writer]]
    assert_one_line_error(run_pslog(*args, cwd=inputs), 1,
                          contains=f"{spelling} is spelled as a folder; give a file name")
    assert_untouched(before, inputs)


@pytest.mark.parametrize("value", ["", " "])
def test_an_empty_tum_folder_is_a_usage_error(value, inputs):  # noqa: F811
    """``export --tum ''`` said "nothing to export" (exit 1): an empty name is a malformed
    command line, as ``--csv ''`` is."""
    before = fingerprint(inputs)
    line = assert_one_line_error(run_pslog("export", "fused.mcap", "--tum", value,
                                           cwd=inputs), 2,
                                 contains="argument --tum: empty folder name")
    assert line.startswith("pslog export: error: "), line
    assert_untouched(before, inputs)


def test_calibrate_refuses_a_builtin_rig_as_a_usage_error(inputs):  # noqa: F811
    """``calibrate --rig paper3`` (a built-in name, no such file) is a bad command-line value,
    exit 2 as a new rig named for another format (was 1), nothing written."""
    before = fingerprint(inputs)
    line = assert_one_line_error(run_pslog(
        "calibrate", "--points", "pts.csv", "--width", "640", "--height", "480", "--name",
        "cam9", "--rig", "paper3", cwd=inputs), 2,
        contains="--rig paper3: calibrate writes a rig file")
    assert line.startswith("pslog calibrate: error: "), line
    assert_untouched(before, inputs)


@pytest.mark.parametrize("name", ["new.yml", "new.json", "new"])
def test_calibrate_refuses_a_new_rig_named_for_another_format(name, inputs):  # noqa: F811
    """``calibrate --rig new.yml`` wrote pslog's TOML under an OpenCV name, which pslog then
    read as OpenCV ("malformed OpenCV FileStorage file"): a new rig file is named .toml
    (exit 2, nothing written), as ``rig export -o`` refuses the mismatch."""
    before = fingerprint(inputs)
    line = assert_one_line_error(run_pslog(
        "calibrate", "--points", "pts.csv", "--width", "640", "--height", "480", "--name",
        "cam9", "--rig", name, cwd=inputs), 2,
        contains=f"--rig {name}: a pslog rig (TOML) is named .toml (calibrate writes one")
    assert line.startswith("pslog calibrate: error: "), line
    assert_untouched(before, inputs)



@pytest.mark.parametrize("name", ["cams.yml", "cams.json", "cams"])
def test_rig_import_refuses_a_rig_named_for_another_format(name, inputs):  # noqa: F811
    """``rig import -o cams.yml`` wrote pslog's TOML under an OpenCV name, which pslog then
    read back as OpenCV FileStorage and refused: the rig written is named .toml (exit 2,
    nothing read or written), as ``calibrate --rig`` and ``rig export -o``."""
    before = fingerprint(inputs)
    line = assert_one_line_error(run_pslog("rig", "import", "rig.toml", "-o", name,
                                           cwd=inputs), 2,
                                 contains=f"-o {name}: a pslog rig (TOML) is named .toml")
    assert line.startswith("pslog rig import: error: "), line
    assert_untouched(before, inputs)

#: every writer of an MCAP session, its output given as {o} (WRITERS' and sync, redetect)
SESSION_WRITERS = {**{w: WRITERS[w] for w in ("simulate", "import", "fuse", "recover",
                                              "record", "live --record")},
                   "sync": ["sync", "s.mcap", "-o", "{o}"],
                   "redetect": ["redetect", "s.mcap", "-o", "{o}"]}


@pytest.mark.parametrize("writer, name, kind", [
    ("simulate", "sim.csv", "a CSV file"), ("import", "s.JSONL", "a JSON Lines file"),
    ("fuse", "fused.rrd", "a rerun recording"), ("recover", "fixed.yml", "an OpenCV FileStorage"),
    ("record", "take.mp4", "a video"), ("live --record", "live.toml", "a rig or calibration"),
    ("sync", "synced.parquet", "a Parquet file"), ("redetect", "again.txt", "a text file")])
def test_a_session_named_for_another_format_is_refused(writer, name, kind, inputs):  # noqa: F811
    """``pslog simulate -o sim.csv`` wrote an MCAP under a CSV's name (exit 0), which ``pslog
    import sim.csv`` then misread: every MCAP writer refuses a name whose suffix names another
    format (exit 2, one line, before anything is read or written), as ``view --save`` and
    ``export`` refuse theirs."""
    before = fingerprint(inputs)
    args = [a.format(o=name) for a in SESSION_WRITERS[writer]]
    option = "--record" if writer == "live --record" else "-o/--output"
    line = assert_one_line_error(run_pslog(*args, cwd=inputs), 2, contains=(
        f"argument {option}: {name} names {kind}",
        f"pslog {writer.split()[0]} writes an MCAP session: name it .mcap"))
    assert line.startswith(f"pslog {writer.split()[0]}: error: "), line
    assert_untouched(before, inputs)


def test_a_session_never_replaces_a_file_of_another_format(inputs):  # noqa: F811
    """``fuse s.mcap -o det.csv --force`` replaced the detections CSV with an MCAP (exit 0):
    refused by its name, --force or not, the CSV kept."""
    before = fingerprint(inputs)
    assert_one_line_error(run_pslog("fuse", "s.mcap", "--method", "typeA", "-o", "det.csv",
                                    "--force", cwd=inputs), 2,
                          contains="argument -o/--output: det.csv names a CSV file")
    assert_untouched(before, inputs)
