"""The columnar tables (pslog.log.table; docs/log-format.md, "Columnar tables"): written by
every session writer, read by read_session when consistent, else the per-frame messages are
read (and ``pslog info`` says why); readable by a peer tool with the mcap package and numpy
alone; rebuilt by ``pslog recover``; carried over by ``pslog fuse``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import zstandard

from pslog.log import read_session

DET_COLUMNS = ("frame_time_ns", "frame_camera", "frame_index", "cand_frame", "cand_uv",
               "cand_radius", "cand_score")


# ---- a peer tool: the mcap package, numpy (and zstandard, which mcap itself needs for its
# zstd chunks); no pslog import -----------------------------------------------------------
def peer_read_table(path, name: str) -> tuple[dict, dict]:
    """(header, columns) of the attachment ``name``, as docs/log-format.md describes it."""
    import zstandard
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        data = next(a.data for a in make_reader(f).iter_attachments() if a.name == name)
    size = int.from_bytes(data[:4], "little")
    header = json.loads(data[4:4 + size])
    body = 4 + size + (-(4 + size) % 8)
    columns = {}
    for col, d in header["columns"].items():
        blob = data[body + d["offset"]:body + d["offset"] + d["size"]]
        if d["codec"] == "zstd":
            blob = zstandard.ZstdDecompressor().decompress(blob)
        columns[col] = np.frombuffer(blob, dtype=d["dtype"]).reshape(d["shape"])
    return header, columns


def _same_detections(a, b) -> None:
    assert a.camera_names == b.camera_names
    for k in DET_COLUMNS:
        x, y = getattr(a, k), getattr(b, k)
        assert x.dtype == y.dtype and x.shape == y.shape, k
        np.testing.assert_array_equal(x, y, err_msg=k)


def _rewrite(src: Path, dst: Path, tables=None, extra=None) -> None:
    """Copy a session with the mcap package (another tool), its pslog tables replaced by
    ``tables`` (name -> attachment data; None: the originals; {}: none, as an older pslog
    wrote it); ``extra``: (topic, [(log_time, data)]) written on a second channel of that
    topic."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        metadata = list(reader.iter_metadata())
        attachments = {a.name: a.data for a in reader.iter_attachments()}
        messages = list(reader.iter_messages(log_time_order=False))
    with open(dst, "wb") as out:
        w = Writer(out, compression=CompressionType.ZSTD)
        w.start()
        schemas = {sid: w.register_schema(s.name, s.encoding, s.data)
                   for sid, s in summary.schemas.items()}
        channels = {cid: w.register_channel(c.topic, c.message_encoding,
                                            schemas.get(c.schema_id, 0), c.metadata)
                    for cid, c in summary.channels.items()}
        for _s, c, m in messages:
            w.add_message(channels[c.id], m.log_time, m.data, m.publish_time, m.sequence)
        if extra is not None:
            topic, added = extra
            c = next(c for c in summary.channels.values() if c.topic == topic)
            second = w.register_channel(topic, c.message_encoding, schemas[c.schema_id],
                                        {"added_by": "another tool"})
            for seq, (t, data) in enumerate(added):
                w.add_message(second, t, data, t, seq)
        for m in metadata:
            w.add_metadata(m.name, m.metadata)
        for name, data in (attachments if tables is None else tables).items():
            w.add_attachment(0, 0, name, "application/vnd.pslog.table", data)
        w.finish()


def test_a_peer_reads_the_tables_with_mcap_and_numpy(sim_session):
    session = read_session(sim_session.path)
    header, cols = peer_read_table(sim_session.path, "pslog/table/detections")
    assert header["format"] == "pslog.table" and header["version"] == 1
    assert header["cameras"] == list(sim_session.rig.names)
    # the counts are the per-frame messages' (the summary's statistics)
    assert sum(header["topics"].values()) == session.detections.n_frames
    for k in DET_COLUMNS:
        np.testing.assert_array_equal(cols[k], getattr(session.detections, k), err_msg=k)
    # and they are the detections written (the per-message reader's result, too)
    np.testing.assert_array_equal(cols["cand_uv"], sim_session.detections.cand_uv)
    np.testing.assert_array_equal(cols["frame_time_ns"],
                                  sim_session.detections.frame_time_ns)
    _h, truth = peer_read_table(sim_session.path, "pslog/table/truth")
    np.testing.assert_array_equal(truth["time_ns"], sim_session.truth.time_ns)
    np.testing.assert_array_equal(truth["position_world"], sim_session.truth.position_world)


def test_the_table_is_what_the_messages_say(sim_session, tmp_path):
    """A file without tables (as an older pslog wrote it) reads the same, from the
    messages; and the table of a recording written frame by frame is the same too."""
    from pslog.log import SessionWriter

    old = tmp_path / "old.mcap"
    _rewrite(sim_session.path, old, tables={})
    a, b = read_session(sim_session.path), read_session(old)
    _same_detections(a.detections, b.detections)
    np.testing.assert_array_equal(a.truth.position_world, b.truth.position_world)
    det = sim_session.detections
    framed = tmp_path / "framed.mcap"
    with SessionWriter(framed, sim_session.rig, flush_interval_s=0.0) as w:
        for i in range(det.n_frames):
            rows = det.cand_frame == i
            w.add_frame(int(det.frame_camera[i]), int(det.frame_index[i]),
                        int(det.frame_time_ns[i]), uv=det.cand_uv[rows],
                        radius=det.cand_radius[rows], score=det.cand_score[rows])
    _h, cols = peer_read_table(framed, "pslog/table/detections")
    for k in DET_COLUMNS:
        np.testing.assert_array_equal(cols[k], getattr(b.detections, k), err_msg=k)


def _corrupt_cases(good: bytes, other: bytes) -> dict[str, bytes]:
    size = int.from_bytes(good[:4], "little")
    header = json.loads(good[4:4 + size])

    def with_header(change) -> bytes:
        h = json.loads(good[4:4 + size])
        change(h)
        raw = json.dumps(h).encode()
        head = len(raw).to_bytes(4, "little") + raw
        return head + bytes(-len(head) % 8) + good[4 + size + (-(4 + size) % 8):]

    return {
        "truncated": good[:len(good) // 2],
        "version": with_header(lambda h: h.update(version=99)),
        "counts": other,  # another session's table: its counts disagree with this file's
        "shape": with_header(lambda h: h["columns"]["cand_uv"].update(
            shape=[header["columns"]["cand_uv"]["shape"][0] + 1, 2])),
        "dtype": with_header(lambda h: h["columns"]["frame_time_ns"].update(dtype="<f8")),
        "offset": with_header(lambda h: h["columns"]["cand_score"].update(offset=10**9)),
        "not json": b"\x10\x00\x00\x00" + b"\xff" * 24,
        "empty": b"",
    }


@pytest.mark.parametrize("case", ["crc", "truncated", "version", "counts", "shape", "dtype",
                                  "offset", "not json", "empty"])
def test_a_bad_table_falls_back_to_the_messages(sim_session, tmp_path, case, cli):
    """Never a traceback, never wrong data: the messages are read, and info says why."""
    from mcap.reader import make_reader

    from pslog.motion import get_motion
    from pslog.simulation import SimulationOptions, simulate

    name = "pslog/table/detections"
    with open(sim_session.path, "rb") as f:
        good = next(a.data for a in make_reader(f).iter_attachments() if a.name == name)
    bad = tmp_path / "bad.mcap"
    if case == "crc":
        # a flipped byte inside the attachment: its CRC fails
        data = bytearray(sim_session.path.read_bytes())
        at = bytes(data).find(good)
        assert at > 0
        data[at + len(good) // 2] ^= 0x01
        bad.write_bytes(bytes(data))
    else:
        from pslog.log import SessionWriter

        other = tmp_path / "other.mcap"
        det, _t = simulate(sim_session.rig, get_motion("spiral"), 0.5,
                           SimulationOptions(seed=9))
        with SessionWriter(other, sim_session.rig) as w:
            w.add_detections(det)
        with open(other, "rb") as f:
            other_data = next(a.data for a in make_reader(f).iter_attachments()
                              if a.name == name)
        _rewrite(sim_session.path, bad, tables={name: _corrupt_cases(good, other_data)[case]})
    _same_detections(read_session(bad).detections, read_session(sim_session.path).detections)
    code, out, err = cli("info", bad)
    assert code == 0 and err == ""
    assert f"columnar table {name} unusable" in out, out
    code, out, _err = cli("info", sim_session.path)
    assert code == 0 and "columnar table" not in out


def test_recover_rebuilds_the_tables(sim_session, tmp_path, cli):
    """A cut file has no tables (they are written at close): recover makes them from the
    messages it salvages, consistent with its own summary."""
    from pslog.log import SessionWriter
    from pslog.log.reader import _Finished

    det = sim_session.detections
    framed = tmp_path / "framed.mcap"
    with SessionWriter(framed, sim_session.rig, flush_interval_s=0.0) as w:  # many chunks
        for i in range(det.n_frames):
            rows = det.cand_frame == i
            w.add_frame(int(det.frame_camera[i]), int(det.frame_index[i]),
                        int(det.frame_time_ns[i]), uv=det.cand_uv[rows])
    data = framed.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[:len(data) // 2])
    fixed = tmp_path / "fixed.mcap"
    code, _out, err = cli("recover", cut, "-o", fixed)
    assert code == 0, err
    with _Finished(fixed) as f:
        table = f.table("pslog/table/detections")
        assert table is not None and not f.table_problems
        n = sum(f.counts.get(f"/camera/{c}/detections", 0) for c in sim_session.rig.names)
    assert 0 < table.n_frames == n < sim_session.detections.n_frames
    old = tmp_path / "old.mcap"
    _rewrite(fixed, old, tables={})
    _same_detections(table, read_session(old).detections)


def test_fuse_carries_the_tables_over(sim_session, tmp_path, cli):
    out = tmp_path / "fused.mcap"
    code, _out, err = cli("fuse", sim_session.path, "--method", "typeA", "-o", out)
    assert code == 0, err
    for name in ("pslog/table/detections", "pslog/table/truth"):
        assert peer_read_table(out, name)[0]["topics"] == \
            peer_read_table(sim_session.path, name)[0]["topics"]
    old = tmp_path / "old.mcap"
    _rewrite(out, old, tables={})
    a, b = read_session(out), read_session(old)
    _same_detections(a.detections, b.detections)
    np.testing.assert_array_equal(a.tracks["typeA"].position_world,
                                  b.tracks["typeA"].position_world)


def test_the_reader_reads_a_table_into_place(sim_session):
    """read_session reads each table into one aligned, writable buffer: its raw columns are
    arrays on it (no copy), equal to the columns of the plain bytes; the same data at an
    odd address decodes to aligned copies (what a misaligned buffer would give)."""
    from pslog.log import table as tables
    from pslog.log.reader import _Finished

    with _Finished(sim_session.path) as f:
        index = f.attachments[tables.DETECTIONS]
        plain = f._attachment(index)
        view = f._attachment_data(index, aligned=True)
    assert isinstance(plain, bytes) and bytes(view) == plain
    names = sim_session.rig.names
    _, expected = tables.decode(plain, tables.DETECTIONS, names)
    _, columns = tables.decode(view, tables.DETECTIONS, names)
    odd = np.empty(len(plain) + 1, np.uint8)
    odd[1:] = np.frombuffer(plain, np.uint8)
    _, copies = tables.decode(odd.data[1:], tables.DETECTIONS, names)
    header = json.loads(plain[4:4 + int.from_bytes(plain[:4], "little")])["columns"]
    raw = [k for k, d in header.items() if d["codec"] == "none"]
    assert "cand_uv" in raw
    for k in DET_COLUMNS:
        for got in (columns[k], copies[k]):
            np.testing.assert_array_equal(got, expected[k], err_msg=k)
            assert got.dtype == expected[k].dtype and got.flags.aligned, k
            assert got.flags.writeable and got.dtype.isnative, k
        assert np.shares_memory(columns[k], view) == (k in raw), k
        assert not np.shares_memory(copies[k], odd), k


def test_long_columns_are_compressed_as_a_sample_of_them_predicts():
    """A long column (>= _SAMPLE_FROM bytes) is compressed whole only when zstd shrinks a
    sample of it (start, middle, end) by 10 %: noise is stored raw, a column that compresses
    (even one whose compressible part is only in the sample's middle) zstd, and one that
    would compress but not where the sample looks stays raw (the sample decides); every
    column decodes to the same values either way."""
    from pslog.log import table as tables

    rng = np.random.default_rng(5)
    n = tables._SAMPLE_FROM // 8 + 1000
    smooth_middle = rng.normal(size=n)
    mid = n // 2
    smooth_middle[mid - 8192:mid + 8192] = 1.5  # only the middle slice is compressible
    hidden = rng.normal(size=n)  # compressible only where the sample does not look
    hidden[tables._SAMPLE_BYTES // 8 + 10:mid - tables._SAMPLE_BYTES // 16 - 10] = 2.5
    # a sample that shrinks by 5-10 % (a run of equal values in each part of it), the rest
    # compressible: raw (the sample decides; compressed whole while the rule was 5 %)
    almost = np.full(n, 3.5)
    for lo in (0, mid - tables._SAMPLE_BYTES // 16, n - tables._SAMPLE_BYTES // 8):
        almost[lo:lo + tables._SAMPLE_BYTES // 8] = rng.normal(size=tables._SAMPLE_BYTES // 8)
        almost[lo + 100:lo + 100 + tables._SAMPLE_BYTES // 8 // 20] = 0.25
    sample = tables._sample(memoryview(almost.tobytes()))
    assert 0.9 < len(zstandard.compress(sample, 1)) / len(sample) < 0.95
    assert len(zstandard.compress(almost.tobytes(), 1)) < 0.9 * almost.nbytes
    columns = {"time_ns": np.arange(n, dtype=np.int64) * 11_111_111,  # compresses
               "position_world": rng.normal(size=(n, 3)),  # noise
               "camera": np.zeros(n, np.int32),
               "quality/noise": rng.normal(size=n),
               "quality/ones": np.ones(n),
               "quality/smooth_middle": smooth_middle, "quality/hidden": hidden,
               "quality/almost": almost}
    name = tables.track_table("typeA")
    data = tables.encode(name, ["a", "b"], {"/tracks/typeA": n}, columns)
    header = json.loads(data[4:4 + int.from_bytes(data[:4], "little")])["columns"]
    codecs = {k: d["codec"] for k, d in header.items()}
    assert codecs == {"time_ns": "zstd", "position_world": "none", "camera": "zstd",
                      "quality/noise": "none", "quality/ones": "zstd",
                      "quality/smooth_middle": "zstd", "quality/hidden": "none",
                      "quality/almost": "none"}, codecs
    _, decoded = tables.decode(data, name, ["a", "b"])
    for k, v in columns.items():
        np.testing.assert_array_equal(decoded[k], v, err_msg=k)
    # the sample is the column's start, middle and end
    raw = np.arange(tables._SAMPLE_FROM, dtype=np.uint8)
    k = tables._SAMPLE_BYTES
    assert tables._sample(memoryview(raw.tobytes())) == (
        raw[:k].tobytes() + raw[(len(raw) - k) // 2:(len(raw) + k) // 2].tobytes()
        + raw[-k:].tobytes())
