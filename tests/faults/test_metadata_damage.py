"""One flipped byte in the session metadata record or the summary of ``samples/throw.mcap``,
through the real CLI (session 28).

The metadata record (bytes 36..1753: opcode, length field, then the name and the key/value
map) has no CRC; the summary, which has one, locates it (offset, length, name). Before:

- a flip in the record's opcode or length field (36..44) passed ``info`` and ``fuse``
  silently (the mcap package read the record from where the summary said and ignored its
  length field: at 40, a read of 4 GB was asked for), or (41..44) was called a "damaged MCAP
  summary (METADATA record has length ... that exceeds limit ...)"; ``recover`` threw the
  record away and rebuilt a rig named "recovered" from the calibrations (the clock
  corrections, detector settings and source lost);
- a flip in its contents was a "damaged MCAP summary ('utf-8' codec can't decode byte ...)".

Now: readers refuse the file in one line naming the record's bytes and what
``pslog recover`` does; ``info`` lists the damage and exits 1; ``recover`` repairs a damaged
opcode or length field exactly (the metadata equal to the original's, key for key).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "throw.mcap"
#: the sample's session metadata record, as its summary's index locates it
RECORD = "bytes 36..1753"


def _flipped(tmp_path: Path, at: int) -> Path:
    data = bytearray(SAMPLE.read_bytes())
    data[at] ^= 0xFF
    path = tmp_path / f"flip{at}.mcap"
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("at", [37, 40, 44])  # the length field's first, 4th, last byte
def test_a_damaged_metadata_record_header_is_refused_then_repaired_exactly(at, tmp_path):
    from pslog.log import read_session

    broken = _flipped(tmp_path, at)
    before = fingerprint(tmp_path)
    run = run_pslog("export", broken, "--detections", tmp_path / "d.csv")
    assert_one_line_error(run, 1, contains=(
        f"{broken}: its session metadata record ({RECORD}) is damaged in its length field",
        "its contents are intact",
        f"run 'pslog recover {broken} -o FIXED.mcap': it repairs the record exactly"))
    run = run_pslog("info", broken)
    assert run.code == 1 and "Traceback" not in run.stderr, run.stderr
    assert f"damaged record at {RECORD} (metadata record 'pslog.session' damaged" in run.stdout
    assert_untouched(before, tmp_path)

    fixed = tmp_path / "fixed.mcap"
    run = run_pslog("recover", broken, "-o", fixed)
    assert run.code == 0 and run.stderr == "", run.stderr
    assert f"repaired the record at {RECORD}" in run.stdout, run.stdout
    assert "rebuilt" not in run.stdout, run.stdout
    got, want = read_session(fixed), read_session(SAMPLE)
    assert got.metadata == want.metadata  # rig, source, detector settings: every key
    assert got.detections.n_frames == want.detections.n_frames == 135
    assert run_pslog("info", fixed).code == 0


@pytest.mark.parametrize("at", [45, 200])
def test_damaged_metadata_contents_are_one_line_in_pslogs_words(at, tmp_path):
    broken = _flipped(tmp_path, at)
    for args in (("export", broken, "--detections", tmp_path / "d.csv"), ("info", broken)):
        line = assert_one_line_error(run_pslog(*args), 1, contains=(
            f"{broken}: its session metadata record ({RECORD}) is damaged in its contents",
            f"run 'pslog recover {broken} -o FIXED.mcap': it rebuilds the rig"))
        assert "codec" not in line and "utf-8" not in line and "summary" not in line, line
    assert not (tmp_path / "d.csv").exists()


def test_a_damaged_summary_is_one_line_in_pslogs_words(tmp_path):
    data = bytearray(SAMPLE.read_bytes())
    start = int.from_bytes(data[-8 - 29 + 9:-8 - 29 + 17], "little")  # the footer says
    data[start + 20] ^= 0xFF
    broken = tmp_path / "s.mcap"
    broken.write_bytes(bytes(data))
    line = assert_one_line_error(run_pslog("export", broken, "--detections",
                                           tmp_path / "d.csv"), 1, contains=(
        f"{broken}: its summary (the index at the end of the file, bytes {start}..",
        f"run 'pslog recover {broken} -o FIXED.mcap': it rebuilds the index"))
    assert "MCAP summary (" not in line, line


def test_a_flipped_metadata_opcode_is_named_as_the_metadata_records_not_the_headers(tmp_path):
    """A flip of the metadata record's opcode (byte 36, right after the intact Header record)
    was blamed on the Header by every reader ("its MCAP Header record (bytes 8..36) is damaged
    (no record follows it (opcode 0xf3))") and listed by ``info`` as two damaged parts (the
    Header and the record). Now the record is named, once; ``recover`` repairs it exactly."""
    from pslog.log import read_session

    broken = _flipped(tmp_path, 36)
    before = fingerprint(tmp_path)
    for args in (("export", broken, "--detections", tmp_path / "d.csv"),
                 ("fuse", broken, "-o", tmp_path / "f.mcap")):
        line = assert_one_line_error(run_pslog(*args), 1, contains=(
            f"{broken}: its session metadata record ({RECORD}) is damaged in its opcode",
            "its contents are intact", "it repairs the record exactly"))
        assert "Header" not in line, line
    run = run_pslog("info", broken)
    assert run.code == 1 and "Traceback" not in run.stderr, run.stderr
    assert "DAMAGED: 1 part(s)" in run.stdout and "Header" not in run.stdout, run.stdout
    assert f"damaged record at {RECORD} (metadata record 'pslog.session' damaged in its " \
           f"opcode" in run.stdout, run.stdout
    assert "1 damaged part (first at byte 36)" in run.stderr, run.stderr
    assert_untouched(before, tmp_path)

    fixed = tmp_path / "fixed.mcap"
    run = run_pslog("recover", broken, "-o", fixed)
    assert run.code == 0 and run.stderr == "", run.stderr
    assert f"repaired the record at {RECORD}" in run.stdout, run.stdout
    assert read_session(fixed).metadata == read_session(SAMPLE).metadata


def test_a_flipped_opcode_after_the_header_of_another_writers_file_names_that_record(tmp_path):
    """Another writer's file whose first record after the Header is a Schema: a flip of its
    opcode names that record (its bytes, by its own length field), not the Header."""
    from mcap.writer import Writer

    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f, use_chunking=False)
        w.start("", "other")
        sid = w.register_schema("s", "jsonschema", b"{}")
        cid = w.register_channel("/t", "json", sid)
        w.add_message(cid, 1, b"{}", 1)
        w.finish()
    data = bytearray(path.read_bytes())
    header_end = 8 + 9 + int.from_bytes(data[9:17], "little")
    assert data[header_end] == 0x03  # a Schema record
    schema_end = header_end + 9 + int.from_bytes(data[header_end + 1:header_end + 9], "little")
    data[header_end] ^= 0xFF
    path.write_bytes(bytes(data))
    line = assert_one_line_error(run_pslog("export", path, "--detections", tmp_path / "d.csv"),
                                 1, contains=(
        f"{path}: its record at bytes {header_end}..{schema_end} (the one after the MCAP "
        f"Header record) is damaged (opcode 0xfc is no record's)", "pslog recover"))
    assert "MCAP Header record (" not in line, line
