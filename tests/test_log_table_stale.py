"""A columnar table that no longer matches the messages another tool left (docs/log-format.md,
"Columnar tables"): its row count is checked against its message counts, and a second channel
on one of its topics is counted (and read) with the first."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from test_log_table import DET_COLUMNS
from test_log_table import _rewrite as _copy

from pslog.log import read_session

DETECTIONS = "pslog/table/detections"


def _table(path: Path, name: str) -> bytes:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return next(a.data for a in make_reader(f).iter_attachments() if a.name == name)


def _with_topics(data: bytes, topics: dict) -> bytes:
    size = int.from_bytes(data[:4], "little")
    header = json.loads(data[4:4 + size])
    header["topics"] = topics
    raw = json.dumps(header).encode()
    head = len(raw).to_bytes(4, "little") + raw
    return head + bytes(-len(head) % 8) + data[4 + size + (-(4 + size) % 8):]


def _header(data: bytes) -> dict:
    size = int.from_bytes(data[:4], "little")
    return json.loads(data[4:4 + size])


def test_a_table_whose_rows_disagree_with_its_counts_is_not_used(sim_session, tmp_path, cli):
    """Another session's table given this file's message counts (a tool that rewrote the
    messages and patched the counts): its rows are not the messages' frames."""
    from pslog.log import SessionWriter
    from pslog.motion import get_motion
    from pslog.simulation import SimulationOptions, simulate

    other = tmp_path / "other.mcap"
    det, _t = simulate(sim_session.rig, get_motion("spiral"), 0.5, SimulationOptions(seed=9))
    with SessionWriter(other, sim_session.rig) as w:
        w.add_detections(det)
    good_counts = _header(_table(sim_session.path, DETECTIONS))["topics"]
    stale = _with_topics(_table(other, DETECTIONS), good_counts)
    bad = tmp_path / "bad.mcap"
    _copy(sim_session.path, bad, tables={DETECTIONS: stale})
    a, b = read_session(bad).detections, read_session(sim_session.path).detections
    for k in DET_COLUMNS:
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k), err_msg=k)
    code, out, _ = cli("info", bad)
    assert code == 0 and f"columnar table {DETECTIONS} unusable" in out and "rows" in out


def test_a_second_channel_on_a_detection_topic_is_read_not_hidden(sim_session, tmp_path):
    """Another tool adds frames of cam1 on a channel of its own with the same topic and copies
    pslog's table: the table (without them) is not used, and both channels are read."""
    from mcap.reader import make_reader

    from pslog.log import _schemas as S

    topic = S.detections_topic(sim_session.rig.names[0])
    with open(sim_session.path, "rb") as f:
        mine = [(m.log_time, m.data) for _s, c, m in make_reader(f).iter_messages()
                if c.topic == topic]
    end = max(t for t, _d in mine)
    added = [(end + (i + 1) * 1_000_000, data) for i, (_t, data) in enumerate(mine[:5])]
    bad = tmp_path / "two-channels.mcap"
    _copy(sim_session.path, bad, extra=(topic, added))
    original = read_session(sim_session.path).detections
    read = read_session(bad).detections
    cam0 = read.frame_camera == 0
    assert int(cam0.sum()) == int((original.frame_camera == 0).sum()) + 5
    assert set(read.frame_time_ns[cam0].tolist()) >= {t for t, _d in added}
    others = original.frame_camera != 0
    np.testing.assert_array_equal(np.sort(read.frame_time_ns[~cam0]),
                                  np.sort(original.frame_time_ns[others]))
