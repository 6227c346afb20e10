"""README documents the progress settings pslog.progress reads (modes, interval, default)."""

from __future__ import annotations

import re
from pathlib import Path

from pslog import progress

README = Path(__file__).resolve().parents[1] / "README.md"


def test_readme_documents_every_progress_mode_and_the_interval():
    text = README.read_text(encoding="utf-8")
    match = re.search(r"\*\*Progress\.\*\*(.*?)\n\n", text, re.S)
    assert match, "README has no **Progress.** paragraph"
    paragraph = " ".join(match.group(1).split())
    assert "`PSLOG_PROGRESS`" in paragraph and "`PSLOG_PROGRESS_INTERVAL`" in paragraph
    for mode in progress._MODES:
        assert f"`{mode}`" in paragraph, mode
    assert f"default {progress.DEFAULT_INTERVAL_S:g}" in paragraph
    assert "standard error" in paragraph
