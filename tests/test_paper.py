"""``pslog paper table1 --beyond``: smooth beside the paper's methods, and a session of
cameras without genlock fused with the nominal timing, after sync and with the true timing."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from pslog.paper import BEYOND_OFFSETS_S, PAPER_TABLE1


def test_default_table1_is_the_papers_rows_only(cli):
    code, out, _ = cli("paper", "table1", "--json")
    assert code == 0
    table = json.loads(out)
    assert "beyond" not in table
    assert [(r["cameras"], r["method"], r["timing"]) for r in table["rows"]] == list(PAPER_TABLE1)
    code, out, _ = cli("paper", "table1")
    assert code == 0
    assert "smooth" not in out and "Beyond" not in out and "—" not in out
    assert len(out.strip().splitlines()) == 3 + len(PAPER_TABLE1)  # title, head, rule, rows


def test_beyond_adds_smooth_and_the_faulted_session(cli):
    code, out, _ = cli("paper", "table1", "--beyond", "--json")
    assert code == 0
    table = json.loads(out)
    rows = {(r["cameras"], r["method"]): r for r in table["rows"]}
    assert list(rows)[:len(PAPER_TABLE1)] == [(c, m) for c, m, _ in PAPER_TABLE1]
    for n in (2, 3):
        smooth, type_a = rows[(n, "smooth")], rows[(n, "typeA")]
        assert smooth["paper_fps"] is None and set(smooth["paper_mm"].values()) == {None}
        for motion, err in smooth["error_mm"].items():
            # noise-free: one trajectory through every ray beats the paper's interpolation
            assert err < type_a["error_mm"][motion] / 10 + 0.05, (n, motion)

    beyond = {(r["method"], r["timing"]): r for r in table["beyond"]["rows"]}
    assert set(beyond) == {(m, t) for m in ("typeA", "smooth")
                           for t in ("nominal", "synced", "true")}
    for method in ("typeA", "smooth"):
        nominal, synced, true = (beyond[(method, t)]["mean_mm"]
                                 for t in ("nominal", "synced", "true"))
        assert synced < nominal  # the unknown offsets cost accuracy; sync gives it back
        assert synced <= 1.25 * true  # the target
    assert beyond[("smooth", "synced")]["mean_mm"] < beyond[("typeA", "synced")]["mean_mm"]
    for clock in table["beyond"]["sync"]:
        assert clock["true_offset_ms"] == BEYOND_OFFSETS_S[clock["camera"]] * 1e3
        err = abs(clock["offset_ms"] - clock["true_offset_ms"])
        assert 0 < clock["offset_std_ms"] and err < 4 * clock["offset_std_ms"]

    code, out, _ = cli("paper", "table1", "--beyond")
    assert code == 0
    assert out.count("smooth") >= 3 and "Beyond the paper" in out and "synced" in out


def test_beyond_is_for_table1_only(cli):
    code, out, err = cli("paper", "table2", "--beyond")
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and "--beyond" in err and "table1" in err


@pytest.mark.parametrize("table", ["table1", "table2"])
def test_docs_paper_md_shows_what_the_command_prints(table, cli):
    """docs/paper.md's copy of each table is the command's output (session 30: its Table 2
    still showed type A's 876 points and 274.5 mm² after the command gave 897 and 272.7)."""
    doc = (Path(__file__).resolve().parents[1] / "docs" / "paper.md").read_text(
        encoding="utf-8")
    title = "Table 1:" if table == "table1" else "Table 2:"
    blocks = re.findall(r"```\n(" + re.escape(title) + r".*?)```", doc, re.S)
    assert len(blocks) == 1, blocks
    code, out, _ = cli("paper", table)
    assert code == 0
    assert blocks[0] == out, f"docs/paper.md:\n{blocks[0]}\npslog paper {table}:\n{out}"
