"""Fault injection: every byte-range corruption class of a real session with images, through
every command that reads a session (issue 8).

The session (written by the real SessionWriter: calibration, truth, three batches of images
and detections in separate chunks, two fused tracks) is damaged one way at a time: a flipped
byte in the magic or Header record, in a detection chunk, in an image chunk (payload, opcode,
length and header fields), in the summary and in each field of the footer; or the file cut at
20 offsets. Each damaged file goes through ``info``, ``fuse``, ``export``, ``eval``, ``view
--save`` and ``recover``. A command that meets the damage fails with one line naming the file
and pointing to ``pslog recover``; any command may succeed on damage it does not read (a
damaged image chunk does not concern ``export``); none leaves a partial output or changes its
input. ``recover`` succeeds (or fails with one line when the rig itself is lost) and keeps
every message of every intact chunk, which is computed here independently of pslog's own
MCAP code, with the ``mcap`` package, from the undamaged file.

Commands run in-process (fast); one case per class also runs as real processes, where an
uncaught traceback or a Python warning would show on the terminal.
"""

from __future__ import annotations

import io
import os
import time
import warnings
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import make_jpeg

from .promises import assert_one_line_error, assert_untouched, fingerprint, run_pslog

COMMANDS = ("info", "fuse", "export", "eval", "view", "recover")
N_CUTS = 20


# ---- the session and its layout, read with the mcap package --------------------------------
@dataclass(frozen=True)
class Layout:
    data: bytes
    header_end: int                     # end of the Header record
    metadata_end: int                   # end of the pslog.session Metadata record
    chunks: list[tuple[int, int, str]]  # (start, end, kind) kind: image/detections/...
    chunk_messages: dict[int, Counter]  # chunk start -> Counter of (topic, log_time)
    messages: dict[tuple[str, int, int], bytes]  # (topic, log_time, sequence) -> data
    summary_start: int


def _build(path: Path) -> None:
    from pslog.fusion import fuse_all
    from pslog.log import SessionWriter
    from pslog.motion import get_motion
    from pslog.rig import apply_timing, builtin_rig
    from pslog.simulation import SimulationOptions, simulate

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    det, truth = simulate(rig, get_motion("spiral"), 1.0, SimulationOptions(noise_px=0.3, seed=1))
    tracks = fuse_all(det, rig, ["typeA", "nearest"])
    # only the explicit flushes write chunks: images and detections of each batch apart
    with SessionWriter(path, rig, timing="typeA", source="faults", flush_interval_s=1e6) as w:
        w.add_truth(truth)
        w.flush()
        for i in range(det.n_frames):
            cands = det.cand_frame == i
            w.add_frame(int(det.frame_camera[i]), int(det.frame_index[i]),
                        int(det.frame_time_ns[i]), uv=det.cand_uv[cands],
                        image=make_jpeg(i % 128))
            if i % 30 == 29:
                w.flush()
        for track in tracks.values():
            w.add_track(track)
            w.flush()


def _layout(path: Path) -> Layout:
    """Where everything is, from the mcap package's reader (not pslog's MCAP code)."""
    from mcap.data_stream import ReadDataStream
    from mcap.reader import SeekingReader
    from mcap.records import MessageIndex

    data = path.read_bytes()
    with open(path, "rb") as f:
        reader = SeekingReader(f)
        summary = reader.get_summary()
        messages = {(channel.topic, m.log_time, m.sequence): m.data
                    for _s, channel, m in reader.iter_messages(log_time_order=False)}
        metadata_end = max(i.offset + i.length for i in summary.metadata_indexes)
    topic = {c.id: c.topic for c in summary.channels.values()}
    chunks, chunk_messages = [], {}
    for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        start = index.chunk_start_offset
        found = Counter()
        for cid, offset in index.message_index_offsets.items():
            body = io.BytesIO(data[offset + 9:])
            for log_time, _ in MessageIndex.read(ReadDataStream(body)).records:
                found[(topic[cid], log_time)] += 1
        kinds = {t.rsplit("/", 1)[-1] for t, _ in found}
        kind = ("image" if kinds == {"image"} else "detections" if kinds == {"detections"}
                else "other")
        chunks.append((start, start + index.chunk_length, kind))
        chunk_messages[start] = found
    header_len = int.from_bytes(data[9:17], "little")
    footer = len(data) - 8 - 29
    summary_start = int.from_bytes(data[footer + 9:footer + 17], "little")
    return Layout(data, 8 + 9 + header_len, metadata_end, chunks, chunk_messages, messages,
                  summary_start)


@pytest.fixture(scope="module")
def layout(tmp_path_factory) -> Layout:
    path = tmp_path_factory.mktemp("session") / "session.mcap"
    _build(path)
    return _layout(path)


# ---- the damage ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    name: str
    kind: str        # header, detections, image, summary, footer, cut
    offset: int      # byte flipped, or length kept

    def apply(self, data: bytes) -> bytes:
        if self.kind == "cut":
            return data[:self.offset]
        damaged = bytearray(data)
        damaged[self.offset] ^= 0x5A
        return bytes(damaged)


def _cases(layout: Layout) -> list[Case]:
    n = len(layout.data)
    cases = [Case("magic", "header", 3), Case("header-opcode", "header", 8),
             Case("header-length", "header", 9),
             Case("header-library", "header", layout.header_end - 2)]
    det = next(c for c in layout.chunks if c[2] == "detections")
    image = [c for c in layout.chunks if c[2] == "image"][1]  # not the one defining channels
    for label, (start, end, kind) in (("detections", det), ("image", image)):
        cases += [Case(f"{label}-payload", kind, (start + end) // 2),
                  Case(f"{label}-opcode", kind, start),
                  Case(f"{label}-length", kind, start + 2),
                  Case(f"{label}-size-or-crc", kind, start + 9 + (16 if kind == "image" else 24))]
    s = layout.summary_start
    footer = n - 8 - 29
    cases += [Case("summary-first", "summary", s + 1),
              Case("summary-middle", "summary", (s + footer) // 2),
              Case("summary-last", "summary", footer - 3)]
    cases += [Case(f"footer-{field}", "footer", footer + k) for field, k in
              (("opcode", 0), ("summary-start", 9), ("summary-offsets", 17), ("crc", 25),
               ("magic", 29 + 4))]
    cases += [Case(f"cut-{k:02d}", "cut", int(n * (k + 0.5) / N_CUTS)) for k in range(N_CUTS)]
    return cases


def _case_ids():
    # ids before the fixture exists: the classes and counts are fixed
    return (["magic", "header-opcode", "header-length", "header-library"]
            + [f"{k}-{f}" for k in ("detections", "image")
               for f in ("payload", "opcode", "length", "size-or-crc")]
            + ["summary-first", "summary-middle", "summary-last"]
            + [f"footer-{f}" for f in ("opcode", "summary-start", "summary-offsets", "crc",
                                       "magic")]
            + [f"cut-{k:02d}" for k in range(N_CUTS)])


def _case(layout: Layout, name: str) -> Case:
    return next(c for c in _cases(layout) if c.name == name)


def _intact_messages(layout: Layout, case: Case) -> Counter:
    """(topic, log_time) of every message in a chunk the damage left whole."""
    kept = Counter()
    for start, end, _kind in layout.chunks:
        hit = (end > case.offset if case.kind == "cut" else start <= case.offset < end)
        if not hit:
            kept.update(layout.chunk_messages[start])
    return kept


def _command(name: str, bad: Path, out_dir: Path) -> tuple[list[str], Path | None]:
    out = {"fuse": "out.mcap", "export": "out.csv", "view": "out.rrd",
           "recover": "fixed.mcap"}.get(name)
    output = out_dir / out if out else None
    args = {"info": ["info", bad], "fuse": ["fuse", bad, "-o", output],
            "export": ["export", bad, "--detections", output], "eval": ["eval", bad],
            "view": ["view", bad, "--save", output, "--frames", "all"],
            "recover": ["recover", bad, "-o", output]}[name]
    return [str(a) for a in args], output


def _may_succeed(command: str, case: Case) -> bool:
    """Whether ``command`` may exit 0 on ``case``: only when it reads nothing damaged."""
    if command == "recover":
        return True
    if case.kind == "header":
        # a damaged Header record is refused by every reader (docs/log-format.md), but a
        # flipped letter inside its library string is still a valid Header: the record has no
        # CRC, and pslog reads nothing in it
        return case.name == "header-library"
    if case.kind == "image":
        return command in ("export", "eval")  # they never read image chunks
    if case.kind == "detections":
        # the detections and truth also sit in the file's columnar tables (whole: CRC-checked,
        # consistent with the summary): these commands read them there, never that chunk;
        # what they print or write is checked against the undamaged file's below
        return command in ("export", "eval", "view")
    return False


# ---- in-process: every case, every command ------------------------------------------------
def _run(cli_main, capsys, args: list[str]) -> tuple[int, str, str, list]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = cli_main(args)
    captured = capsys.readouterr()
    return code, captured.out, captured.err, caught


@pytest.mark.parametrize("name", _case_ids())
def test_every_command_on_damaged_session(layout, name, tmp_path, capsys):
    from pslog.cli import main
    from pslog.log import read_session

    case = _case(layout, name)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(case.apply(layout.data))
    old = time.time() - 3600  # not a file still being recorded
    os.utime(bad, (old, old))
    before = fingerprint(tmp_path)
    for command in COMMANDS:
        args, output = _command(command, bad, tmp_path)
        code, out, err, caught = _run(main, capsys, args)
        where = f"{name}: pslog {' '.join(args)}"
        assert not caught, f"{where}: warnings {[str(w.message) for w in caught]}"
        assert "Traceback" not in out + err, where
        if code == 0:
            assert _may_succeed(command, case), f"{where}: silent success\n{out}"
            assert err == "" or command == "view", f"{where}: {err}"
            if output is not None:
                assert output.is_file(), where
            if command == "recover":
                _check_recovered(layout, case, output, out)
                read_session(output)
            elif case.kind == "detections":  # read from the tables: the very same result
                good = tmp_path.parent / f"{tmp_path.name}-good" / "session.mcap"
                good.parent.mkdir(exist_ok=True)
                good.write_bytes(layout.data)
                good_args, good_output = _command(command, good, good.parent)
                good_code, good_out, _err, _caught = _run(main, capsys, good_args)
                assert good_code == 0, where
                assert out.replace(str(bad), "") == good_out.replace(str(good), "").replace(
                    str(good_output), str(output)), where
                if command == "export":  # (a recording's bytes hold ids and clocks)
                    assert output.read_bytes() == good_output.read_bytes(), where
            if output is not None:
                output.unlink()
        else:
            assert code == 1, f"{where}: exit {code}\n{err}"
            lines = [line for line in err.splitlines() if line.strip()]
            assert len(lines) == 1, f"{where}: {err}"
            line = lines[0]
            assert line.startswith(f"pslog {command}: error: ") and str(bad) in line, where
            lost_rig = case.kind == "cut" and case.offset < layout.metadata_end
            # a cut inside the first chunk leaves the rig but no intact message
            lost_all = case.kind == "cut" and case.offset < min(c[1] for c in layout.chunks)
            if command == "recover" or (command == "info" and lost_rig):
                # nothing recoverable: the cut took the session metadata (the rig) itself
                assert ((lost_rig and "nothing" in line)
                        or (lost_all and "no intact message" in line)), f"{where}: {line}"
            else:
                assert "pslog recover" in line, f"{where}: {line}"
                if case.kind != "cut":
                    assert "byte" in line, f"{where}: no byte offset in {line}"
        assert_untouched(before, tmp_path)  # input unchanged, nothing left behind


def _check_recovered(layout: Layout, case: Case, fixed: Path, report: str) -> None:
    from mcap.reader import SeekingReader

    with open(fixed, "rb") as f:
        got = [(c.topic, m.log_time, m.sequence, m.data)
               for _s, c, m in SeekingReader(f).iter_messages(log_time_order=False)]
    # nothing invented: every message recovered is one of the original file, byte for byte
    for topic, t, seq, data in got:
        assert layout.messages.get((topic, t, seq)) == data, (case.name, topic, t)
    # nothing intact lost: every message of every intact chunk is back
    recovered = Counter((topic, t) for topic, t, _seq, _data in got)
    missing = _intact_messages(layout, case) - recovered
    assert not missing, f"{case.name}: lost {sum(missing.values())} intact messages"
    if case.kind in ("detections", "image"):
        # the damaged chunk is reported with its byte range
        start, end, _ = next(c for c in layout.chunks if c[0] <= case.offset < c[1])
        assert f"damaged chunk at bytes {start}..{end}" in report, report


def test_cases_cover_every_class(layout):
    cases = _cases(layout)
    assert [c.name for c in cases] == _case_ids()
    assert Counter(c.kind for c in cases) == {"header": 4, "detections": 4, "image": 4,
                                              "summary": 3, "footer": 5, "cut": N_CUTS}
    # each flip lands where its class says
    for c in cases:
        inside = [k for s, e, k in layout.chunks if s <= c.offset < e]
        if c.kind in ("detections", "image"):
            assert inside == [c.kind], c
        elif c.kind in ("summary", "footer"):
            assert c.offset >= layout.summary_start, c
        elif c.kind == "header":
            assert c.offset < layout.header_end, c


# ---- as real processes: one case per class ------------------------------------------------
@pytest.mark.parametrize("name", ["magic", "detections-payload", "image-payload",
                                  "summary-middle", "footer-summary-start", "cut-12"])
def test_damaged_session_as_real_processes(layout, name, tmp_path):
    case = _case(layout, name)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(case.apply(layout.data))
    old = time.time() - 3600
    os.utime(bad, (old, old))
    before = fingerprint(tmp_path)
    for command in COMMANDS:
        args, output = _command(command, bad, tmp_path)
        run = run_pslog(*args)
        if run.code == 0:
            assert _may_succeed(command, case), f"{name}: pslog {args}: silent success"
            assert "Traceback" not in run.stderr + run.stdout
            assert "Warning:" not in run.stderr + run.stdout
            if output is not None:
                output.unlink()
        else:
            assert_one_line_error(run, 1, contains=(str(bad), "pslog recover")
                                  if command != "recover" else str(bad))
        assert_untouched(before, tmp_path)


# ---- recovery reports ---------------------------------------------------------------------
def test_recover_reports_each_skipped_chunk_with_times_and_counts(layout, tmp_path):
    """Two damaged chunks, one of each kind: both skipped, both reported (byte range, time
    range and message counts from the chunk index), everything else kept."""
    from pslog.log import read_session, recover_session

    det = next(c for c in layout.chunks if c[2] == "detections")
    image = [c for c in layout.chunks if c[2] == "image"][2]
    damaged = bytearray(layout.data)
    for start, end, _ in (det, image):
        damaged[(start + end) // 2] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(damaged))
    report = recover_session(bad, tmp_path / "fixed.mcap")
    assert [(d["start"], d["end"]) for d in report["damaged"]] == [det[:2], image[:2]]
    for d, (start, _end, kind) in zip(report["damaged"], (det, image), strict=True):
        expected = Counter()
        for (topic, _t), k in layout.chunk_messages[start].items():
            expected[topic] += k
        assert d["messages"] == dict(expected) and all(
            topic.endswith(kind) for topic in expected)
        times = [t for _topic, t in layout.chunk_messages[start]]
        assert (d["start_ns"], d["end_ns"]) == (min(times), max(times))
    lost = sum(sum(layout.chunk_messages[c[0]].values()) for c in (det, image))
    assert report["messages"] == len(layout.messages) - lost
    session = read_session(tmp_path / "fixed.mcap")
    assert session.n_images == 90 - sum(layout.chunk_messages[image[0]].values())
    assert session.detections.n_frames == 90 - sum(layout.chunk_messages[det[0]].values())


def test_recover_without_summary_resynchronises_after_a_damaged_length(layout, tmp_path):
    """No summary to consult (the file was cut after its data), and a chunk's length field
    damaged: the walk finds the next intact chunk by searching, and keeps everything after."""
    from pslog.log import recover_session

    image = [c for c in layout.chunks if c[2] == "image"][1]
    damaged = bytearray(layout.data[:layout.summary_start])
    damaged[image[0] + 3] ^= 0x01  # the chunk's length grows by 64 KiB
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(damaged))
    report = recover_session(bad, tmp_path / "fixed.mcap")
    assert len(report["damaged"]) == 1 and report["damaged"][0]["start"] == image[0]
    # its message indexes, found just before the next chunk, still tell what it held
    assert sum(report["damaged"][0]["messages"].values()) == sum(
        layout.chunk_messages[image[0]].values())
    assert report["messages"] == len(layout.messages) - sum(
        layout.chunk_messages[image[0]].values())


def test_info_counts_damaged_image_chunks(layout, tmp_path, capsys):
    from pslog.cli import main

    image = [c for c in layout.chunks if c[2] == "image"]
    damaged = bytearray(layout.data)
    for start, end, _ in image[1:]:
        damaged[(start + end) // 2] ^= 0x01
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(damaged))
    assert main(["info", str(bad)]) == 1
    out, err = capsys.readouterr()
    assert "DAMAGED: 2 chunk(s)" in out
    for start, end, _ in image[1:]:
        assert f"damaged chunk at bytes {start}..{end}" in out
    assert err.startswith(f"pslog info: error: {bad} has 2 damaged chunks (first at byte "
                          f"{image[1][0]})") and "pslog recover" in err
    # the figures leave the damaged chunks out but still describe the rest
    assert "90 frames" in out


@pytest.mark.parametrize("name", ["header-opcode", "header-length"])
def test_info_reports_a_damaged_header_record_in_its_damage_section(layout, name, tmp_path,
                                                                    capsys):
    from pslog.cli import main

    bad = tmp_path / "bad.mcap"
    bad.write_bytes(_case(layout, name).apply(layout.data))
    old = time.time() - 3600
    os.utime(bad, (old, old))
    code, out, err, _ = _run(main, capsys, ["info", str(bad)])
    assert code == 1, err
    assert "DAMAGED: 1 part(s)" in out and "MCAP Header record" in out, out
    assert "messages per topic" in out  # the rest of the report is there
    assert "damaged part (first at byte 8)" in err and "pslog recover" in err, err
