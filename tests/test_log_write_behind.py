"""A session written to replace an existing file has its bytes' writeback started as it is
written (SessionWriter._write_behind: the move over the old file at close then finds little
left to write out, ext4's auto_da_alloc), in contiguous ranges from its first byte; the file is
the same bytes as one written to a free name; a file that replaces nothing is left to the OS."""

from __future__ import annotations

import os
import struct

import numpy as np
import pytest

from pslog.log import SessionWriter
from pslog.log import writer as W
from pslog.records import Track


def _tracks(rng) -> list[Track]:
    tracks = []
    for method in ("typeA", "nearest", "smooth"):
        n = 3 * W._TRACK_BLOCK + 517  # several blocks a track
        t = np.cumsum(rng.integers(1, 10**7, n))
        tracks.append(Track(method, t, rng.normal(size=(n, 3)),
                            rng.integers(0, 3, n).astype(np.int32),
                            {"ray_miss_m": rng.random(n), "snap_px": rng.random(n)}))
    return tracks


def _write(path, rig, tracks, force: bool) -> None:
    with SessionWriter(path, rig, force=force, on_error="discard",
                       flush_interval_s=float("inf")) as w:
        for track in tracks:
            w.add_track(track, last=True)


def _blanked(path) -> bytes:
    """The file's bytes, the value of its one ``created_utc`` (the time of writing) blanked."""
    data = bytearray(path.read_bytes())
    i = data.find(b"created_utc")
    assert i > 0 and data.find(b"created_utc", i + 1) < 0
    j = i + len(b"created_utc")
    n = struct.unpack_from("<I", data, j)[0]
    data[j + 4:j + 4 + n] = b"_" * n
    return bytes(data)


def _spy(monkeypatch) -> list[tuple[int, int, int]]:
    """os.posix_fadvise called through, its (offset, length, advice) recorded."""
    calls: list[tuple[int, int, int]] = []
    real = os.posix_fadvise

    def spy(fd, offset, length, advice):
        calls.append((offset, length, advice))
        return real(fd, offset, length, advice)

    monkeypatch.setattr(os, "posix_fadvise", spy)
    return calls


@pytest.mark.skipif(not hasattr(os, "posix_fadvise"), reason="no posix_fadvise here")
def test_a_replacing_file_is_written_behind(tmp_path, rig3, monkeypatch):
    rng = np.random.default_rng(89010)
    tracks = _tracks(rng)
    step = 64 << 10
    monkeypatch.setattr(W, "_BEHIND_BYTES", step)
    fresh = tmp_path / "fresh.mcap"
    calls = _spy(monkeypatch)
    _write(fresh, rig3, tracks, force=False)
    assert calls == []  # moved to a free name: nothing to hurry
    old = tmp_path / "old.mcap"
    old.write_bytes(b"an old session" * 1000)
    _write(old, rig3, tracks, force=True)
    size = old.stat().st_size
    assert len(calls) >= 4, calls
    end = 0
    for offset, length, advice in calls:
        assert advice == os.POSIX_FADV_DONTNEED
        assert offset == end and length >= step  # contiguous from byte 0, a step or more
        end = offset + length
    assert size - step * 40 < end <= size  # (the last track's blocks among them)
    assert _blanked(old) == _blanked(fresh)


@pytest.mark.skipif(not hasattr(os, "posix_fadvise"), reason="no posix_fadvise here")
def test_no_write_behind_without_an_old_file(tmp_path, rig3, monkeypatch):
    """A writer in place (keep mode, a new file) and a discard-mode one to a free name."""
    rng = np.random.default_rng(89011)
    tracks = _tracks(rng)
    monkeypatch.setattr(W, "_BEHIND_BYTES", 64 << 10)
    calls = _spy(monkeypatch)
    with SessionWriter(tmp_path / "kept.mcap", rig3) as w:
        for track in tracks:
            w.add_track(track, last=True)
    _write(tmp_path / "derived.mcap", rig3, tracks, force=False)
    assert calls == []


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="no /proc/self/fd here")
def test_the_old_file_is_released_off_the_move(tmp_path, rig3, monkeypatch):
    """The file replaced is held open across the move (its blocks are not given back inside
    it), then closed on a thread of its own: no descriptor of it is left."""
    import threading

    rng = np.random.default_rng(89012)
    old = tmp_path / "old.mcap"
    old.write_bytes(b"an old session" * 1000)
    inode = old.stat().st_ino
    seen: list[tuple[int, int]] = []
    real = W._release

    def release(fd):
        if fd is not None:
            st = os.fstat(fd)
            seen.append((st.st_ino, st.st_nlink))  # the old file, its last name gone
        return real(fd)

    monkeypatch.setattr(W, "_release", release)
    _write(old, rig3, _tracks(rng)[:1], force=True)
    assert seen == [(inode, 0)]
    for thread in threading.enumerate():
        if thread.name == "pslog-release":
            thread.join(10)
    held = [os.readlink(f"/proc/self/fd/{fd}") for fd in os.listdir("/proc/self/fd")
            if os.path.exists(f"/proc/self/fd/{fd}")]
    assert not [link for link in held if link.startswith(str(old))], held
    assert old.stat().st_ino != inode and old.read_bytes().startswith(b"\x89MCAP")
