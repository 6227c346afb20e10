"""The fused tracks' columnar tables (``pslog/table/track/<method>``, docs/log-format.md,
"Columnar tables"): written when a fused session closes, read by read_session when they
agree with the track messages (else the messages are read), readable by a peer tool with
mcap and numpy alone, rebuilt by ``pslog recover``, carried over by ``pslog fuse``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pslog.log import read_session
from tests.test_log_table import _rewrite, peer_read_table

METHODS = ("typeA", "filter")


@pytest.fixture
def fused(sim_session, tmp_path, cli):
    """The sim session fused with two methods (typeA: fixed quality fields; filter: quality
    map keys of its own)."""
    out = tmp_path / "fused.mcap"
    code, _out, err = cli("fuse", sim_session.path, "--method", ",".join(METHODS), "-o", out)
    assert code == 0, err
    return out


def _same_track(a, b) -> None:
    """Bit for bit: every column's dtype, shape and values, the quality keys compared as a
    dict (protobuf's map order is not fixed)."""
    assert a.method == b.method
    for k in ("time_ns", "position_world", "camera"):
        x, y = getattr(a, k), getattr(b, k)
        assert x.dtype == y.dtype and x.shape == y.shape, k
        assert x.tobytes() == y.tobytes(), k
    assert set(a.quality) == set(b.quality)
    for k in a.quality:
        assert a.quality[k].dtype == b.quality[k].dtype, k
        assert a.quality[k].tobytes() == b.quality[k].tobytes(), k  # NaN payloads too
    assert dict(a.dropped) == dict(b.dropped)


def _without_tables(src, dst) -> None:
    """``src`` as an older pslog wrote it: the track tables dropped (the others kept)."""
    from mcap.reader import make_reader

    with open(src, "rb") as f:
        kept = {a.name: a.data for a in make_reader(f).iter_attachments()
                if not a.name.startswith("pslog/table/track/")}
    _rewrite(src, dst, tables=kept)


def test_a_peer_reads_the_track_tables(fused):
    session = read_session(fused)
    assert set(session.tracks) == set(METHODS)
    for method, track in session.tracks.items():
        header, cols = peer_read_table(fused, f"pslog/table/track/{method}")
        assert header["format"] == "pslog.table" and header["version"] == 1
        assert header["topics"] == {f"/tracks/{method}": len(track)}
        np.testing.assert_array_equal(cols["time_ns"], track.time_ns)
        np.testing.assert_array_equal(cols["position_world"], track.position_world)
        np.testing.assert_array_equal(cols["camera"], track.camera)
        quality = {k.removeprefix("quality/"): v for k, v in cols.items()
                   if k.startswith("quality/")}
        assert set(quality) == set(track.quality) and quality
        for k, v in quality.items():
            np.testing.assert_array_equal(v, track.quality[k], err_msg=k)


def test_the_track_table_is_what_the_messages_say(fused, tmp_path, cli):
    """read_session's tracks from the tables equal those of the messages bit for bit, and
    ``eval --json`` says the same of both files."""
    from pslog.log.reader import _Finished

    old = tmp_path / "old.mcap"
    _without_tables(fused, old)
    a, b = read_session(fused), read_session(old)
    with _Finished(fused) as f:
        for method in METHODS:
            assert f.table(f"pslog/table/track/{method}") is not None, f.table_problems
    for method in METHODS:
        _same_track(a.tracks[method], b.tracks[method])
    code_a, out_a, _ = cli("eval", fused, "--json")
    code_b, out_b, _ = cli("eval", old, "--json")
    assert code_a == code_b == 0 and out_a == out_b


def test_recover_rebuilds_the_track_tables(fused, tmp_path, cli):
    from pslog.log.reader import _Finished

    old = tmp_path / "old.mcap"
    _without_tables(fused, old)
    fixed = tmp_path / "fixed.mcap"
    code, _out, err = cli("recover", old, "-o", fixed)
    assert code == 0, err
    with _Finished(fixed) as f:
        for method in METHODS:
            assert f.table(f"pslog/table/track/{method}") is not None, f.table_problems
    a = read_session(fixed)
    for method in METHODS:
        _same_track(a.tracks[method], read_session(fused).tracks[method])
        assert peer_read_table(fixed, f"pslog/table/track/{method}")[0]["topics"] == \
            peer_read_table(fused, f"pslog/table/track/{method}")[0]["topics"]


def test_copying_kept_tracks_carries_their_tables(fused, tmp_path):
    """copy_session keeping the fused tracks (``replace_tracks=False``, as a re-fuse of one
    method): a kept track's table is carried as it is; a replaced one (same length, other
    positions) and an added one get tables of their new tracks, never the old table."""
    from dataclasses import replace

    from pslog.log import copy_session

    old_tracks = read_session(fused).tracks
    moved = replace(old_tracks["typeA"], position_world=old_tracks["typeA"].position_world + 1)
    added = replace(old_tracks["typeA"], method="nearest")
    again = tmp_path / "again.mcap"
    copy_session(fused, again, tracks=[moved, added], replace_tracks=False)
    plain = tmp_path / "plain.mcap"
    _without_tables(again, plain)
    a, b = read_session(again), read_session(plain)
    assert set(a.tracks) == {"nearest", *METHODS}
    for method in a.tracks:
        peer_read_table(again, f"pslog/table/track/{method}")  # there
        _same_track(a.tracks[method], b.tracks[method])
    np.testing.assert_array_equal(a.tracks["typeA"].position_world, moved.position_world)
    # the kept track's table is the original's (same header, same columns)
    h0, c0 = peer_read_table(fused, "pslog/table/track/filter")
    h1, c1 = peer_read_table(again, "pslog/table/track/filter")
    assert h0 == h1 and all(c0[k].tobytes() == c1[k].tobytes() for k in c0)


def _bad_cases(good: bytes) -> dict[str, bytes]:
    size = int.from_bytes(good[:4], "little")
    body = good[4 + size + (-(4 + size) % 8):]

    def with_header(change) -> bytes:
        h = json.loads(good[4:4 + size])
        change(h)
        raw = json.dumps(h).encode()
        head = len(raw).to_bytes(4, "little") + raw
        return head + bytes(-len(head) % 8) + body

    def shorter(h) -> None:  # one column a point short: the columns disagree in length
        d = h["columns"]["camera"]
        d.update(shape=[d["shape"][0] - 1], codec="none", size=4 * (d["shape"][0] - 1))

    return {
        "counts": with_header(lambda h: h["topics"].update(
            {k: v + 1 for k, v in h["topics"].items()})),
        "lengths": with_header(shorter),
        "quality dtype": with_header(lambda h: next(
            d for k, d in h["columns"].items() if k.startswith("quality/")).update(
                dtype="<f4")),
        "missing column": with_header(lambda h: h["columns"].pop("camera")),
        "truncated": good[:len(good) // 2],
    }


@pytest.mark.parametrize("case", ["counts", "lengths", "quality dtype", "missing column",
                                  "truncated"])
def test_a_bad_track_table_falls_back_to_the_messages(fused, tmp_path, case, cli):
    from mcap.reader import make_reader

    name = "pslog/table/track/filter"
    with open(fused, "rb") as f:
        tables = {a.name: a.data for a in make_reader(f).iter_attachments()}
    bad = tmp_path / "bad.mcap"
    if case == "lengths":  # the shorter column stored raw, so it must be raw to begin with
        size = int.from_bytes(tables[name][:4], "little")
        header = json.loads(tables[name][4:4 + size])
        assert header["columns"]["camera"]["codec"] == "none"
    _rewrite(fused, bad, tables={**tables, name: _bad_cases(tables[name])[case]})
    _same_track(read_session(bad).tracks["filter"], read_session(fused).tracks["filter"])
    code, out, err = cli("info", bad)
    assert code == 0 and err == ""
    assert f"columnar table {name} unusable" in out, out


def test_a_writers_track_table_is_what_its_messages_say(tmp_path, rig3):
    """SessionWriter makes a track's table from the Track objects it wrote (not copies of
    their messages): the same as decoding the messages, also for awkward tracks - added
    twice with other quality keys, unsorted times with ties, a fixed field NaN throughout,
    NaN and -0.0 values, long enough for the writer's block path, and empty."""
    from pslog.log import SessionWriter
    from pslog.records import Track

    rng = np.random.default_rng(4)

    def track(method, n, quality_keys, tie=False):
        t = rng.integers(0, 10**9, n).astype(np.int64)
        if tie and n > 3:
            t[1:4] = t[0]
        xyz = rng.normal(size=(n, 3))
        xyz[::5, 1] = -0.0
        quality = {k: rng.random(n) for k in quality_keys}
        for v in quality.values():
            v[::7] = np.nan
        if "ray_shift_m" in quality:
            quality["ray_shift_m"][:] = np.nan  # NaN throughout: the messages leave it out
        return Track(method, t, xyz, rng.integers(0, 3, n).astype(np.int32), quality)

    path = tmp_path / "t.mcap"
    with SessionWriter(path, rig3) as w:
        w.add_track(track("a", 5000, ["ray_miss_m", "std_m", "ray_shift_m"], tie=True))
        w.add_track(track("a", 40, ["snap_px", "n_detections"], tie=True))
        w.add_track(track("a", 0, ["only_in_an_empty_track"]))
        w.add_track(track("b", 0, ["ray_miss_m"]))
        w.add_track(track("c", 3, []))
    plain = tmp_path / "plain.mcap"
    _without_tables(path, plain)
    a, b = read_session(path), read_session(plain)
    assert set(a.tracks) == {"a", "b", "c"}
    for method in a.tracks:
        peer_read_table(path, f"pslog/table/track/{method}")  # there
        _same_track(a.tracks[method], b.tracks[method])
    assert "ray_shift_m" not in a.tracks["a"].quality and len(a.tracks["a"]) == 5040
    assert "only_in_an_empty_track" not in a.tracks["a"].quality
    # (key order: a track added in parts with other keys is equal as a mapping only, see
    # docs/log-format.md; one added whole keeps the messages' order, tested across processes
    # below)
    from pslog.log.reader import _Finished

    with _Finished(path) as f:
        for method in a.tracks:
            assert f.table(f"pslog/table/track/{method}") is not None, f.table_problems


def test_quality_key_order_is_the_messages_across_processes(sim_session, tmp_path):
    """Protobuf iterates a parsed map in an order that varies between processes: a table
    written by another process (fuse, then recover) gives read_session the quality keys in
    the order the messages give in this one."""
    from tests.faults.promises import run_pslog

    fused, fixed = tmp_path / "fused.mcap", tmp_path / "fixed.mcap"
    for args in (("fuse", sim_session.path, "--method", "filter,typeA", "-o", fused),
                 ("recover", fused, "-o", fixed)):
        run = run_pslog(*args)
        assert run.code == 0, run.stderr
    for path in (fused, fixed):
        plain = tmp_path / f"plain-{path.name}"
        _without_tables(path, plain)
        a, b = read_session(path), read_session(plain)
        for method in ("filter", "typeA"):
            _same_track(a.tracks[method], b.tracks[method])
            assert list(a.tracks[method].quality) == list(b.tracks[method].quality), method
