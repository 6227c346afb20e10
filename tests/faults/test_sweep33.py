"""Session 33: one table of file formats behind every output-name check
(``pslog.cli._common.FORMATS``): ``export``'s files, ``view --save``, ``rig export`` and
``rig import -o``, ``calibrate --rig`` and an MCAP session named for another format
(``OTHER_FORMATS``) read their suffixes from it, so that they cannot disagree."""

from __future__ import annotations

import pytest

from pslog.calibration import IMAGE_SUFFIXES
from pslog.cli._common import FORMATS, OTHER_FORMATS, misnamed
from pslog.interchange.rig_formats import OPENCV_SUFFIXES

from .promises import assert_refused
from .test_sweep31 import work  # noqa: F401  (the fixture: pts.csv and rig.toml)


def test_the_table_holds_the_cores_own_lists():
    """The core keeps its own lists (cv2 and numpy behind them, not imported by the CLI's
    table): the table holds them equal, so the CLI refuses exactly what the core reads."""
    assert FORMATS["opencv"][1] == OPENCV_SUFFIXES
    assert FORMATS["image"][1] == IMAGE_SUFFIXES


def test_other_formats_is_every_format_but_mcap():
    expected = {s for fmt, (_, written, also) in FORMATS.items() if fmt != "mcap"
                for s in written + also}
    assert set(OTHER_FORMATS) == expected
    assert ".mcap" not in OTHER_FORMATS
    assert OTHER_FORMATS[".json"] == "a JSON file"  # the first format listed names it
    assert OTHER_FORMATS[".tsv"] == "a CSV file"


@pytest.mark.parametrize("path, fmt, expected", [
    ("t.csv", "csv", None),
    ("dir/T.CSV", "csv", None),  # any case
    ("t.tsv", "csv", "--x t.tsv: a CSV file is named .csv"),  # known as CSV, never written
    ("t.parquet", "csv", "--x t.parquet: a CSV file is named .csv"),
    ("t", "jsonl", "--x t: a JSON Lines file is named .jsonl or .ndjson"),
    (".csv", "csv", "--x .csv: a CSV file is named .csv"),  # a hidden file's name
    ("c.toml", "opencv", "--x c.toml: an OpenCV FileStorage file is named "
                         ".yml, .yaml, .xml or .json"),
])
def test_misnamed(path, fmt, expected):
    assert misnamed("--x", path, fmt) == expected


def test_misnamed_says_subject_and_hint():
    assert misnamed("-o", "a.yml", "toml", "a pslog rig (TOML)", "why") == (
        "-o a.yml: a pslog rig (TOML) is named .toml (why)")


@pytest.mark.parametrize("args, contains", [
    (["rig", "export", "paper3", "--format", "opencv", "-o", "c.toml"],
     "-o c.toml: an OpenCV FileStorage file is named .yml, .yaml, .xml or .json (YAML, XML"),
    (["rig", "import", "rig.toml", "-o", "cams.tsv"],
     "-o cams.tsv: a pslog rig (TOML) is named .toml (for an OpenCV file"),
])
def test_the_clis_messages_come_from_the_table(work, args, contains):  # noqa: F811
    assert_refused(work, 2, args, contains)


def test_an_upper_case_suffix_is_the_format(work):  # noqa: F811
    """``C.YML`` is an OpenCV file and ``R.TOML`` a rig, as the readers take them."""
    from pslog.rig import load_rig

    from .promises import run_pslog

    done = run_pslog("rig", "export", "paper3", "--format", "opencv", "-o", "C.YML", cwd=work)
    assert done.code == 0, done.stderr
    done = run_pslog("rig", "import", "C.YML", "-o", "R.TOML", cwd=work)
    assert done.code == 0, done.stderr
    assert len(load_rig(work / "R.TOML")) == 3
