"""Every reason a method leaves a point out for (``Track.dropped``'s keys, which ``pslog eval``
explains through :data:`pslog.evaluation.LEFT_OUT_TEXT`) is listed where docs/log-format.md
says what the ``left_out_points`` key of a track's channel holds. Session 43's review: smooth's
``contradicted_run`` was not there, nor typeA's ``break`` or the filter's ``held``."""

from __future__ import annotations

import re
from pathlib import Path

from pslog.evaluation import LEFT_OUT_TEXT

DOCS = Path(__file__).resolve().parent.parent / "docs"


def test_every_left_out_reason_is_in_the_log_formats_list():
    text = (DOCS / "log-format.md").read_text(encoding="utf-8")
    start = text.index("The reasons:")
    end = text.index("`pslog eval` reports them", start)
    listed = set(re.findall(r"`([a-z_]+)`", text[start:end]))
    missing = sorted(set(LEFT_OUT_TEXT) - listed)
    assert not missing, f"docs/log-format.md does not list {missing}"
