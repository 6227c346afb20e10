"""``python -m benchmarks``: the aggregator runs each benchmark script as a process, gathers
its JSON rows into one table and JSON file, and a benchmark that fails is an ERROR row, not
a crash. Fake benchmark scripts (real processes, real files) stand in for the slow ones."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.__main__ import main, match_rows, ratio  # noqa: E402

GOOD = '''
import argparse, json
p = argparse.ArgumentParser(); p.add_argument("--json"); a = p.parse_args()
rows = [{"stage": "fake fast", "figure": 2000.0, "unit": "items/s", "target": ">= 1,000",
         "ok": True, "peer": "fake peer", "peer_figure": 500.0, "better": "higher"},
        {"stage": "fake latency", "figure": 4.0, "unit": "ms", "target": "<= 2",
         "ok": False, "peer": "other", "peer_figure": 8.0, "better": "lower"}]
open(a.json, "w").write(json.dumps({"rows": rows}))
'''
CRASH = '''
import sys
print("half a line of output")
raise SystemExit("boom: the fake benchmark broke")
'''
GARBAGE = '''
import argparse
p = argparse.ArgumentParser(); p.add_argument("--json"); a = p.parse_args()
open(a.json, "w").write("{not json")
'''


@pytest.fixture
def scripts(tmp_path) -> dict[str, Path]:
    out = {}
    for name, text in (("good", GOOD), ("crash", CRASH), ("garbage", GARBAGE)):
        path = tmp_path / f"bench_{name}.py"
        path.write_text(text)
        out[name] = path
    return out


def test_table_and_json_from_fake_benchmarks(scripts, tmp_path, capsys):
    out = tmp_path / "suite.json"
    code = main(["--script", str(scripts["good"]), "--script", str(scripts["crash"]),
                 "--script", str(scripts["garbage"]), "--json", str(out)])
    assert code == 1  # a failed target and two broken benchmarks
    table = capsys.readouterr().out
    lines = [ln for ln in table.splitlines() if ln.startswith("|")]
    assert lines[0].split("|")[1:-1] == [" stage ", " figure ", " unit ", " target ",
                                         " peer (same run) ", " peer figure ", " ratio ",
                                         " result "]
    by_stage = {ln.split("|")[1].strip(): [c.strip() for c in ln.split("|")[1:-1]]
                for ln in lines[2:]}
    assert by_stage["fake fast"] == ["fake fast", "2,000", "items/s", ">= 1,000", "fake peer",
                                     "500", "4.00", "PASS"]
    assert by_stage["fake latency"][-2:] == ["2.00", "FAIL"]  # lower is better: 8 / 4
    assert by_stage["bench_crash"][-1] == "ERROR"
    assert by_stage["bench_garbage"][-1] == "ERROR"
    data = json.loads(out.read_text())
    assert set(data) == {"quick", "machine", "rows"} and data["quick"] is False
    assert data["machine"]["cpus"] >= 1
    rows = {r["stage"]: r for r in data["rows"]}
    assert rows["fake fast"]["figure"] == 2000.0 and rows["fake fast"]["bench"] == "bench_good"
    crash = rows["bench_crash"]
    assert crash["error"] and crash["ok"] is False
    assert "boom: the fake benchmark broke" in crash["note"]
    assert "bench_garbage.py failed" in rows["bench_garbage"]["note"]


def test_only_a_passing_benchmark_exits_zero(scripts, tmp_path, capsys):
    good = tmp_path / "bench_ok.py"
    good.write_text(GOOD.replace('"ok": False', '"ok": True'))
    assert main(["--script", str(good)]) == 0
    assert "| fake latency |" in capsys.readouterr().out


def test_unknown_benchmark_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--only", "nosuch"])
    assert exit_info.value.code == 2
    assert "unknown benchmark 'nosuch'" in capsys.readouterr().err


def test_the_suite_runs_as_a_module(scripts, tmp_path):
    done = subprocess.run([sys.executable, "-m", "benchmarks", "--script",
                           str(scripts["good"])], capture_output=True, text=True, cwd=ROOT,
                          timeout=120)
    assert done.returncode == 1, done.stderr  # "fake latency" misses its target
    assert "| fake fast | 2,000 |" in done.stdout


def test_match_rows_judge_90_minutes_only_from_long_runs():
    def run(stage, minutes, seconds, peak=500.0):
        return {"stage": stage, "minutes": minutes, "seconds": seconds, "peak_mb": peak,
                "finished": True}
    long = match_rows({"rows": [run("eval", 10, 0.5), run("eval", 45, 1.2),
                                run("fuse typeA", 10, 1.0), run("fuse typeA", 90, 4.0, 1200)]})
    ev, fa = long
    assert ev["figure"] == pytest.approx(1.2 + 0.7 / 35 * 45) and ev["ok"] is True
    assert "extrapolated from 10 and 45 min" in ev["note"]
    assert fa["figure"] == 4.0 and fa["ok"] is False  # 1200 MB > 1 GB
    short = match_rows({"rows": [run("eval", 0.5, 0.9), run("eval", 1.5, 1.0)]})
    assert short[0]["ok"] is None and short[0]["unit"] == "s at 1.5 min"
    assert ratio({"figure": 3.0, "peer_figure": None}) is None
