"""Session 41's hostile-input sweep (helper hostile41), through the real CLI on real files:
``pslog import --columns``, damaged sessions and fused files (cut or flipped at random
offsets: benchmarks/session41/hostile/damage.py), ``pslog live`` and ``pslog batch``.

Found and fixed (``--columns``): a column given with a newline, or a header cell holding one
(CSV quotes allow it), printed the error on two lines; a header whose accented name was
written decomposed (NFD: macOS, some editors) was not found by the same name typed composed,
and the error showed two identical names; a column whose name holds a comma could not be
named at all (now ``time="t,unix"``, as CSV quotes it); a mapping onto a name the header
already has (``time=t_unix`` over ``camera,time,t_unix,u,v``), or of a column the header
holds twice, said only "bad header 'camera,time,time,u,v'", a header the file does not
have."""

from __future__ import annotations

import contextlib
import unicodedata
from pathlib import Path

import pytest

import pslog

from .promises import HANG_S, assert_one_line_error, assert_untouched, fingerprint, run_pslog


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sweep41")
    done = run_pslog("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
                     "--noise-px", "0.3", "--seed", "66001", "-o", folder / "s.mcap")
    assert done.code == 0, done.stderr
    done = run_pslog("export", folder / "s.mcap", "--detections", folder / "det.csv")
    assert done.code == 0, done.stderr
    return folder


def _lab_csv(inputs: Path, out: Path, header: str) -> Path:
    """det.csv (``camera,time,u,v,frame,score``) under another header of as many cells (a
    CSV header: quoted cells may hold commas and newlines), its rows cut to that many."""
    import csv
    import io

    width = len(next(csv.reader(io.StringIO(header))))
    rows = (inputs / "det.csv").read_text().splitlines()[1:]
    out.write_text(header + "\n" + "\n".join(",".join(r.split(",")[:width]) for r in rows)
                   + "\n", encoding="utf-8")
    return out


def _import(inputs: Path, tmp_path: Path, csv_file: Path, columns: str):
    return run_pslog("import", "--rig", "paper3", "--detections", csv_file, "--columns",
                     columns, "-o", tmp_path / "out.mcap", "--force")


def _same_detections(a: Path, b: Path) -> None:
    import numpy as np

    x, y = pslog.read_session(a).detections, pslog.read_session(b).detections
    np.testing.assert_array_equal(x.frame_time_ns, y.frame_time_ns)
    np.testing.assert_array_equal(x.cand_uv, y.cand_uv)


@pytest.mark.parametrize("where", ["argument", "header"])
def test_a_newline_in_a_column_name_stays_on_one_line(inputs, tmp_path, where):
    """``--columns 'time=t<newline>unix'`` (a pasted name) against a file without it, or a
    header cell ``"t<newline>unix"`` named by the error: the line was cut in two."""
    header = 'cam,"t\nunix",px,py' if where == "header" else "cam,t_unix,px,py"
    lab = _lab_csv(inputs, tmp_path / "lab.csv", header)
    before = fingerprint(tmp_path)
    run = _import(inputs, tmp_path, lab, "camera=cam,time=t\nunix2,u=px,v=py"
                  if where == "argument" else "camera=cam,time=t_unix,u=px,v=py")
    assert_one_line_error(run, 1, contains=(
        "no column 't\\nunix2'" if where == "argument" else "'t\\nunix'"))
    assert_untouched(before, tmp_path)


def test_a_decomposed_accent_is_the_same_column(inputs, tmp_path):
    """A header written in Unicode's decomposed form (``é`` as ``e`` + U+0301) and the same
    name typed composed: refused as 'no column 'témps'; the header has ... témps'."""
    header = unicodedata.normalize("NFD", "kaméra,témps,ü,v")
    assert header != unicodedata.normalize("NFC", header)
    lab = _lab_csv(inputs, tmp_path / "lab.csv", header)
    run = _import(inputs, tmp_path, lab, unicodedata.normalize(
        "NFC", "camera=kaméra,time=témps,u=ü,v=v"))
    assert run.code == 0, run.stderr
    plain = _lab_csv(inputs, tmp_path / "plain.csv", "camera,time,u,v")
    done = run_pslog("import", "--rig", "paper3", "--detections", plain, "-o",
                     tmp_path / "plain.mcap")
    assert done.code == 0, done.stderr
    _same_detections(tmp_path / "out.mcap", tmp_path / "plain.mcap")


def test_a_column_name_holding_a_comma_is_named_in_quotes(inputs, tmp_path):
    """A header cell ``"t,unix"`` (quoted in the CSV) could not be mapped: the comma split
    ``--columns`` ('unix' is not NAME=COLUMN); quoted as CSV quotes it, it is one column,
    and the unquoted form's error says how."""
    lab = _lab_csv(inputs, tmp_path / "lab.csv", 'camera,"t,unix",u,v')
    run = _import(inputs, tmp_path, lab, 'time=t,unix')
    assert_one_line_error(run, 2, contains='quote it, time=t,unix as time="t,unix"')
    run = _import(inputs, tmp_path, lab, 'time="t,unix",u=u')
    assert run.code == 0, run.stderr
    run = _import(inputs, tmp_path, lab, 'time="t,unix')
    assert_one_line_error(run, 2, contains="unmatched double quote")


@pytest.mark.parametrize("header, said", [
    ("camera,time,t_unix,u,v", "--columns time=t_unix reads 't_unix' as time, but the "
                               "header has a column time too"),
    ("camera,t_unix,t_unix,u,v", "column 't_unix' (--columns time=...) is in the header 2 "
                                 "times")])
def test_a_mapping_that_makes_a_column_twice_is_named(inputs, tmp_path, header, said):
    """The error showed the mapped header, 'bad header 'camera,time,time,u,v'', a header the
    file does not have, without saying which column came twice or why."""
    lab = _lab_csv(inputs, tmp_path / "lab.csv", header)
    before = fingerprint(tmp_path)
    assert_one_line_error(_import(inputs, tmp_path, lab, "time=t_unix"), 1, contains=said)
    assert_untouched(before, tmp_path)


def _looped_folder(tmp_path: Path, inputs: Path) -> Path:
    """A folder of one session and two symbolic links to itself (``ln -s . again``: a
    folder a user links into its own tree for a shorter path, twice)."""
    import shutil

    folder = tmp_path / "season"
    folder.mkdir()
    shutil.copyfile(inputs / "s.mcap", folder / "m1.mcap")
    (folder / "again").symlink_to(".")
    (folder / "also").symlink_to(".")
    return folder


def test_a_batch_over_a_folder_linked_into_itself_runs_each_session_once(inputs, tmp_path):
    """``pslog batch 'season/**/*.mcap'`` with two links to '.' in season/: glob's ``**``
    follows links, so it walked 2^40 paths (the kernel's depth of links): the batch hung
    before planning anything (SIGTERM after 40 s: nothing done). Each folder inside itself
    is now walked once: the one session is fused, once."""
    folder = _looped_folder(tmp_path, inputs)
    pytest.importorskip("ray")
    run = run_pslog("batch", f"{folder}/**/*.mcap", "--do", "fuse", "-o", tmp_path / "out",
                    timeout=20)
    assert run.code == 0, run.stderr
    rows = (tmp_path / "out" / "summary.csv").read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith("m1.mcap,ok"), rows
    assert (tmp_path / "out" / "m1" / "fused.mcap").is_file()


def test_a_folder_linked_into_itself_given_as_the_pattern_is_counted(inputs, tmp_path):
    """The folder itself as the pattern: its sessions counted for the message by the same
    ``**`` walk, which hung as the batch did."""
    folder = _looped_folder(tmp_path, inputs)
    before = fingerprint(tmp_path)
    run = run_pslog("batch", folder, "--do", "fuse", "-o", tmp_path / "out", timeout=20)
    assert_one_line_error(run, 1, contains=("is a folder, not a session file",
                                            "(1 .mcap file there"))
    assert_untouched(before, tmp_path)


@contextlib.contextmanager
def _listening_fuser(tmp_path: Path):
    """``pslog live --rig paper3`` listening on a UDP port of the system's pick, as a real
    process (:class:`test_live_command.LiveRun`): yields the run and the port, then stops it
    with Ctrl-C and checks that it ends with exit 0 and no traceback (killed should the test
    fail first)."""
    import signal

    from test_live_command import LiveRun

    run = LiveRun("--rig", "paper3", "--listen", "udp://127.0.0.1:0", "--status-every", "0.2",
                  cwd=tmp_path)
    try:
        port = int(run.wait_err(r"listening for detection datagrams on "
                                r"udp://127\.0\.0\.1:(\d+)").group(1))
        yield run, port
        run.proc.send_signal(signal.SIGINT)
        assert run.finish(HANG_S) == 0, "\n".join(run.err)
    finally:
        if run.proc.poll() is None:
            run.proc.kill()
            run.proc.wait()


def test_datagrams_a_flood_makes_the_kernel_drop_are_counted(tmp_path):
    """A flood while the fuser is stopped (SIGSTOP: a fuser busy elsewhere, a burst larger
    than its socket's buffer): the kernel dropped what the buffer had no room for, and
    ``pslog live`` said nothing of it (a hostile probe: 60,000 sent, 22,626 received, drops
    listed for those alone). Linux counts them beside each datagram (SO_RXQ_OVFL): the
    status says ``overflow N``, and every datagram sent is received or counted."""
    import re
    import signal
    import socket
    import time

    with _listening_fuser(tmp_path) as (run, port):
        run.proc.send_signal(signal.SIGSTOP)
        sent = 0
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for _ in range(20_000):  # 40 MB: ten times the 4 MB buffer the kernel grants
                tx.sendto(b"NOPE" + bytes(2000), ("127.0.0.1", port))
                sent += 1
            run.proc.send_signal(signal.SIGCONT)
            # the kernel's count comes with the next datagram it queues, once the fuser has
            # read the buffer: one more each 0.25 s until a status says it (on a loaded
            # machine the buffer took longer than the 1 s waited before, and the one
            # datagram sent then found it full: received 1,927, no overflow said)
            deadline = time.monotonic() + HANG_S
            while not any("overflow" in x for x in run.err if x.startswith("live ")):
                assert time.monotonic() < deadline, "\n".join(run.err[-3:])
                tx.sendto(b"NOPE" + bytes(2000), ("127.0.0.1", port))
                sent += 1
                time.sleep(0.25)
            # the datagrams sent are all read or counted: a status after the last one
            n_status = len(run.err)
            run.wait_err(r"^live ", start=n_status)
            time.sleep(0.5)
    err = "\n".join(run.err)
    final = [x for x in err.splitlines() if x.startswith("live ")][-1]
    assert "overflow" in final, final
    received = int(re.search(r"datagrams (\d+)", final).group(1))
    overflow = int(re.search(r"overflow (\d+)", final).group(1))
    assert 0 < received < sent and received + overflow == sent, final
    assert f"foreign {received}" in final, final


def test_matches_that_are_no_session_file_are_named(inputs, tmp_path):
    """A session behind a link to a disk not mounted, a FIFO, a folder named like a session:
    the batch left them out without a word (its summary one session short, exit 0); a
    pattern of such a match alone said 'no session file matches', not why."""
    import os
    import shutil

    folder = tmp_path / "season"
    folder.mkdir()
    shutil.copyfile(inputs / "s.mcap", folder / "m1.mcap")
    (folder / "m2.mcap").symlink_to("/nonexistent/disk/m2.mcap")
    os.mkfifo(folder / "m3.mcap")
    (folder / "m4.mcap").mkdir()
    pytest.importorskip("ray")
    run = run_pslog("batch", f"{folder}/*.mcap", "--do", "fuse", "-o", tmp_path / "out")
    assert run.code == 0, run.stderr
    assert "Traceback" not in run.stderr
    note = [x for x in run.stderr.splitlines() if "no session file" in x]
    assert note and note[0].startswith("pslog batch: note: 3 matches of the patterns are no "
                                       "session file, left out:"), run.stderr
    for said in ("m2.mcap (a link to a missing file)", "m3.mcap (a FIFO)",
                 "m4.mcap (a folder)"):
        assert said in note[0], note
    before = fingerprint(folder)
    run = run_pslog("batch", folder / "m2.mcap", "--do", "fuse", "-o", tmp_path / "out2")
    assert_one_line_error(run, 1, contains="m2.mcap (a link to a missing file)")
    assert_untouched(before, folder)


def test_points_refused_at_out_are_said(tmp_path):
    """``--out`` to a robot that is not listening (not started, or gone mid-run): each
    refused send was counted by the sink and said nowhere, the run ended as if every point
    had reached it. A note says how many were refused."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # (closed again: nothing listens there)
    run = run_pslog("live", "--rig", "paper3", "--synthetic", "--motion", "throw",
                    "--duration", "1", "--out", f"udp://127.0.0.1:{port}", cwd=tmp_path)
    assert run.code == 0, run.stderr
    assert "Traceback" not in run.stderr, run.stderr
    note = [x for x in run.stderr.splitlines() if "refused" in x]
    assert note and note[0].startswith(f"pslog live: note: --out udp://127.0.0.1:{port}: "), \
        run.stderr
    assert "point datagrams refused (nothing listened there" in note[0], note


def test_a_camera_the_rig_lacks_is_named_once(tmp_path):
    """A camera process started with the wrong name (``Cam1`` for ``cam1``, a name with a
    control character): its datagrams were dropped as ``unknown_camera N`` in the status
    line, the name said nowhere, so the user could not tell which sender was wrong. Each
    name is said once, on one line, escaped."""
    import socket
    import time

    from pslog.live.protocol import DetectionDatagram, encode_detections

    with _listening_fuser(tmp_path) as (run, port):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            for k in range(1, 30):
                for name in ("Cam1", "cam\n2"):
                    now = time.time_ns()
                    tx.sendto(encode_detections(DetectionDatagram(
                        name, k, k, now, now, [[320.0, 240.0]])), ("127.0.0.1", port))
                time.sleep(0.01)
        time.sleep(0.6)
    err = "\n".join(run.err)
    lines = err.splitlines()
    for shown in ("'Cam1'", "'cam\\n2'"):
        said = [x for x in lines if f"camera {shown} is not in the rig" in x]
        assert len(said) == 1, err
        assert said[0] == (f"camera {shown} is not in the rig (it has cam1, cam2, "
                           f"cam3): its datagrams are dropped (unknown_camera)"), said
    assert "unknown_camera 58" in [x for x in lines if x.startswith("live ")][-1], err
    # a sender of ever new names does not grow the fuser: 8 remembered, the rest counted
    from pslog.live.fuser import LiveFuser
    from pslog.rig import builtin_rig

    fuser = LiveFuser(builtin_rig("paper3"), "filter", epoch_ns=10**18)
    for k in range(100):
        fuser.feed(encode_detections(DetectionDatagram(f"x{k}", 1, 1, 10**18 + 1, 10**18 + 1,
                                                       [[1.0, 2.0]])), 10**18 + 2)
    assert fuser.unknown_cameras == [f"x{k}" for k in range(8)]
    assert fuser.counters()["unknown_camera"] == 100
