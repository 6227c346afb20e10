"""``pslog redetect`` copies the image chunks its workers read byte for byte without
decompressing them in the main process (``copy_session(layouts=...)``): the same file as the
decompressing copy, and a chunk whose indexes do not state what its reader found is copied
the usual way."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from pslog.log import _mcapio as io
from pslog.log import copy as C
from pslog.log import copy_session, read_session
from recorders import redetect_session

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "throw.mcap"


def without_created(path: Path) -> bytes:
    """The file's bytes with its ``created_utc`` metadata value blanked (the only field that
    differs between two runs)."""
    data = bytearray(path.read_bytes())
    at = data.index(b"created_utc") + len(b"created_utc")
    size = int.from_bytes(data[at:at + 4], "little")
    data[at + 4:at + 4 + size] = bytes(size)
    return bytes(data)


def _layouts(path: Path) -> dict[int, np.ndarray | None]:
    """Each chunk's record layout (:func:`pslog.log.copy.record_layout`), decompressed here."""
    out = {}
    with open(path, "rb") as f:
        for c in make_reader(f).get_summary().chunk_indexes:
            f.seek(c.chunk_start_offset)
            record = f.read(c.chunk_length)
            out[c.chunk_start_offset] = C.record_layout(io.chunk_payload(memoryview(record)[9:]))
    return out


def test_redetect_with_workers_copies_image_chunks_undecompressed_and_the_same(
        tmp_path, monkeypatch):
    from recorders import redetect

    monkeypatch.setattr(redetect, "_PARALLEL_FROM", 0)  # workers for the 135-frame sample
    with open(SAMPLE, "rb") as f:
        images = {cid for cid, ch in make_reader(f).get_summary().channels.items()
                  if ch.topic.endswith("/image")}
    taken: dict[str, list] = {"indexed": [], "raw": []}
    originals = {name: getattr(C, name) for name in ("_copy_indexed", "_copy_raw")}

    def watch(name: str, key: str) -> None:
        """Note, per call, whether it copied an image chunk and whether it wrote it."""
        real = originals[name]

        def call(*args, _real=real, _key=key):
            done = _real(*args)
            taken[_key].append((bool(images & set(args[2].message_index_offsets)), done))
            return done

        monkeypatch.setattr(C, name, call)

    def image_chunks(key: str) -> int:
        return sum(done for image, done in taken[key] if image)

    watch("_copy_indexed", "indexed")
    watch("_copy_raw", "raw")
    redetect_session(SAMPLE, tmp_path / "new.mcap", workers=2)
    new = image_chunks("indexed"), image_chunks("raw")
    monkeypatch.setattr(C, "_copy_indexed", lambda *a: False)  # the decompressing copy
    taken = {"indexed": [], "raw": []}
    watch("_copy_raw", "raw")
    redetect_session(SAMPLE, tmp_path / "old.mcap", workers=2)
    # every image chunk the decompressing copy wrote byte for byte (not the first image
    # chunk when it also registers the image channels: written anew either way), now without
    # being decompressed here (small chunks of other messages may still be, the usual way)
    assert new == (image_chunks("raw"), 0) and new[0] >= 4
    assert without_created(tmp_path / "new.mcap") == without_created(tmp_path / "old.mcap")


def test_a_layout_the_indexes_do_not_state_sends_the_chunk_the_usual_way(tmp_path, monkeypatch):
    """The caller's layout of a chunk decides: the one its indexes state copies it without
    decompressing it; a different one (a record moved, another channel or time, a record
    that is no message: None) copies it through its decompressed records, the same file."""
    layouts = _layouts(SAMPLE)
    checked = [o for o, lay in layouts.items() if lay is not None]
    assert len(checked) >= 5  # the sample's image chunks hold messages only
    copy_session(SAMPLE, tmp_path / "plain.mcap", checked_chunks=checked)
    taken = []
    real = C._copy_indexed
    monkeypatch.setattr(C, "_copy_indexed", lambda *a: taken.append(real(*a)) or taken[-1])
    copy_session(SAMPLE, tmp_path / "fast.mcap", checked_chunks=checked,
                 layouts=layouts.get)
    assert sum(taken) >= 4  # written without being decompressed
    wrong = {}
    for k, (o, lay) in enumerate(sorted((o, lay) for o, lay in layouts.items()
                                        if lay is not None)):
        bad = lay.copy()
        bad[-1, k % 3] += 1  # its offset, channel or log time
        wrong[o] = bad if k % 4 != 3 else None
    taken.clear()
    copy_session(SAMPLE, tmp_path / "wrong.mcap", checked_chunks=checked, layouts=wrong.get)
    assert taken and not any(taken)  # each of them decompressed after all
    plain = without_created(tmp_path / "plain.mcap")
    assert without_created(tmp_path / "fast.mcap") == plain
    assert without_created(tmp_path / "wrong.mcap") == plain
    assert read_session(tmp_path / "fast.mcap").n_images == 135


@pytest.mark.parametrize("records, want", [
    (b"", (0, 3)),
    (bytes([io.OP_MESSAGE]) + (22 + 3).to_bytes(8, "little") + (7).to_bytes(2, "little")
     + (1).to_bytes(4, "little") + (99).to_bytes(8, "little") * 2 + b"abc", [[0, 7, 99]]),
])
def test_record_layout(records, want):
    assert C.record_layout(records).tolist() == (np.zeros(want).tolist()
                                                 if isinstance(want, tuple) else want)


def test_record_layout_is_none_for_other_records():
    channel = bytes([0x04]) + (2).to_bytes(8, "little") + b"\0\0"
    assert C.record_layout(channel) is None
    message = bytes([io.OP_MESSAGE]) + (22).to_bytes(8, "little") + bytes(22)
    assert C.record_layout(message + b"\x05") is None  # records do not end with the last


def _messages(path: Path, n: int) -> list[bytes]:
    """The first ``n`` image messages' data of a session (as stored)."""
    with open(path, "rb") as f:
        return [m.data for _s, c, m in make_reader(f).iter_messages()
                if c.topic.endswith("/image")][:n]


def test_image_data_is_the_parsers_without_a_copy():
    """``image_data`` (the frame's bytes found in the stored message, no copy: what redetect's
    workers decode) gives what protobuf's parser gives, on the sample's messages placed
    anywhere in a buffer."""
    from pslog.log.reader import image_data, parse_image

    messages = _messages(SAMPLE, 12)
    assert len(messages) == 12
    for m in messages:
        records = b"\x00" * 7 + m + b"\xff" * 5
        got = image_data(records, 7, 7 + len(m), SAMPLE)
        assert isinstance(got, memoryview)  # a view, not a copy
        assert bytes(got) == parse_image(m, SAMPLE).data
        assert len(got) > 1000


def _field(number: int, payload: bytes) -> bytes:
    return bytes([number << 3 | 2]) + bytes([len(payload)]) + payload


@pytest.mark.parametrize("message", [
    _field(4, b"cam1") + _field(2, b"first") + _field(3, b"jpeg") + _field(2, b"second"),
    _field(1, b"\x08\x05\x10\x07") + _field(2, b"\xff\xd8abc"),
    _field(2, b""),
    b"",
    _field(4, b"\xff\xfe") + _field(2, b"data"),  # frame_id not UTF-8: the parser's error
    _field(1, b"\x18\x05") + _field(2, b"data"),  # a timestamp field 3: the parser's choice
    _field(5, b"x") + _field(2, b"data"),  # an unknown field
    b"\x10\x05" + _field(2, b"data"),  # field 2 as a varint
    b"\x10\x02\x12\x00",  # the same, then an empty data field
    _field(1, b"\x0c\x05") + _field(2, b"data"),  # a group's end in the timestamp
    _field(2, b"data")[:-1],  # cut short
    b"\x12\x80",  # a length varint that does not end
])
def test_image_data_is_the_parsers_on_any_message(message):
    """The last ``data`` field wins, as in protobuf; anything pslog does not write goes to
    the parser, whose bytes or error (one line, LogFormatError) come out unchanged."""
    from pslog.errors import LogFormatError
    from pslog.log.reader import image_data, parse_image

    try:
        want = parse_image(message, "s.mcap").data
    except LogFormatError as exc:
        with pytest.raises(LogFormatError) as got:
            image_data(b"ab" + message, 2, 2 + len(message), "s.mcap")
        assert str(got.value) == str(exc)
        return
    assert bytes(image_data(b"ab" + message + b"cd", 2, 2 + len(message), "s.mcap")) == want
