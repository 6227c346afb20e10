"""Session 32's hostile-input sweep through the real CLI: an output spelled as a folder
(``-o out.mcap/``) was written as the file ``out.mcap`` (pathlib drops the trailing ``/``;
``open()`` refuses such a name), by every writer; ``export --tum ''`` was "nothing to
export" (exit 1), not a usage error; ``calibrate --rig new.yml`` wrote TOML under an OpenCV
name."""

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


@pytest.mark.parametrize("name", ["new.yml", "new.json", "new"])
def test_calibrate_refuses_a_new_rig_named_for_another_format(name, inputs):  # noqa: F811
    """``calibrate --rig new.yml`` wrote pslog's TOML under an OpenCV name, which pslog then
    read as OpenCV ("malformed OpenCV FileStorage file"): a new rig file is named .toml
    (exit 2, nothing written), as ``rig export -o`` refuses the mismatch."""
    before = fingerprint(inputs)
    line = assert_one_line_error(run_pslog(
        "calibrate", "--points", "pts.csv", "--width", "640", "--height", "480", "--name",
        "cam9", "--rig", name, cwd=inputs), 2,
        contains=f"--rig {name}: calibrate writes a pslog rig, TOML, named .toml")
    assert line.startswith("pslog calibrate: error: "), line
    assert_untouched(before, inputs)
