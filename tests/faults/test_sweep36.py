"""Session 36's hostile-input sweep through the real CLI: values and paths no earlier sweep
tried. ``view --detail 1e300`` (or ``A:B`` with a bound that large) was a traceback (its
nanoseconds, 1e309, a float infinity no int holds)."""

from __future__ import annotations

from pathlib import Path

import pytest

from .promises import assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep36")
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.5",
                     "--seed", "48036", "-o", folder / "s.mcap")
    assert done.code == 0, done.stderr
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
