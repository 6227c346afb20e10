"""The suite's own schedule: the files conftest.py starts first exist (a renamed file would
drop out of the list silently and run last again)."""

from pathlib import Path

from conftest import LONGEST_FIRST


def test_every_file_started_first_exists():
    here = Path(__file__).parent
    assert len(set(LONGEST_FIRST)) == len(LONGEST_FIRST)
    for name in LONGEST_FIRST:
        assert (here / name).is_file(), name
