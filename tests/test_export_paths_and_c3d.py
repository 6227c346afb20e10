"""Session 43: ``pslog export``'s outputs against each other (their order on the command line
changes nothing, none replaces another) and C3D of times on no common grid; through the real
CLI on real sessions."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from _cli import pslog_ok

from pslog.log import read_session


@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fused")
    session, fused = folder / "s.mcap", folder / "f.mcap"
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.6",
             "--seed", "75030", "-o", session)
    pslog_ok("fuse", session, "--method", "typeA", "--method", "smooth", "-o", fused)
    return fused


def _export_in(folder, *args) -> subprocess.CompletedProcess:
    """``pslog export ARGS`` run in ``folder`` (relative outputs as a user types them)."""
    return subprocess.run([sys.executable, "-m", "pslog", "export", *map(str, args)],
                          cwd=folder, capture_output=True, text=True, timeout=600)


def _files(folder):
    return {str(p.relative_to(folder)): p.read_bytes()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_export_outputs_in_the_tum_folder_in_any_order(fused, tmp_path):
    """Outputs inside an existing ``--tum`` folder: the same files, the same bytes, whichever
    option comes first; the same file twice refused in either order, nothing written."""
    orders = {"tum first": ["--tum", "tum", "--csv", "tum/x.csv", "--detections", "tum/d.csv"],
              "tum last": ["--detections", "tum/d.csv", "--csv", "tum/x.csv", "--tum", "tum"]}
    results = {}
    for label, args in orders.items():
        (tmp_path / label / "tum").mkdir(parents=True)
        done = _export_in(tmp_path / label, fused, *args)
        assert done.returncode == 0, done.stderr
        results[label] = _files(tmp_path / label)
    assert results["tum first"] == results["tum last"]
    assert set(results["tum first"]) == {"tum/x.csv", "tum/d.csv", "tum/typeA.tum",
                                         "tum/smooth.tum", "tum/truth.tum"}
    for args in (["--csv", "y.csv", "--detections", "./y.csv"],
                 ["--detections", "./y.csv", "--csv", "y.csv"]):
        done = _export_in(tmp_path, fused, *args)
        assert done.returncode == 1 and "given as two outputs" in done.stderr
        assert not (tmp_path / "y.csv").exists()


def _c3d_frames(path):
    """``(labels, frames (n, points, 5))`` of a C3D, its own count of frames: ``c3d`` 0.6's
    reader joins TRIAL:ACTUAL_START_FIELD's words as low + 65535 · high and reads one frame
    too many per 65,536 of a start past 65,535 (from the padding: a valid point at the
    origin); the count here is the end's frame less the start's, each high << 16 | low."""
    import itertools
    import warnings

    c3d = pytest.importorskip("c3d")
    with open(path, "rb") as f, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "No analog data found in file."
        reader = c3d.Reader(f)
        labels = [s.strip() for s in reader.point_labels]
        n = reader.frame_count
        start, end = reader.get("TRIAL:ACTUAL_START_FIELD"), reader.get("TRIAL:ACTUAL_END_FIELD")
        if start is not None and end is not None:
            (lo, hi), (end_lo, end_hi) = start.uint16_array, end.uint16_array
            n = (int(end_hi) << 16 | int(end_lo)) - (int(hi) << 16 | int(lo)) + 1
        frames = np.array([points for _, points, _ in itertools.islice(reader.read_frames(),
                                                                         n)])
    assert len(frames) == n
    return labels, frames


def _drifting_rig(tmp_path):
    """paper3, type A phases moved (0 / 15.3 / 25.4 ms), cam2 40 ppm fast and cam3 25 ppm
    slow on the session clock, cam3 a 25 ms rolling shutter: walk42's lab after sync."""
    text = pslog_ok("rig", "show", "paper3")
    head, cam2, cam3 = text.split('name = "cam2"')[0], *text.split('name = "cam2"')[1].split(
        'name = "cam3"')
    cam2 = cam2.replace("fps = 30.0", "fps = 30.0012").replace("offset = 0.0", "offset = 0.0153")
    cam3 = cam3.replace("fps = 30.0", "fps = 29.99925").replace(
        "offset = 0.0", "offset = 0.0254\nreadout = 0.025")
    path = tmp_path / "drift.toml"
    path.write_text(head + 'name = "cam2"' + cam2 + 'name = "cam3"' + cam3)
    return path


def test_c3d_of_times_on_no_grid_resamples_every_frame(tmp_path):
    """Shutters on no common grid (rolling shutter, drifting clocks): the C3D left out 11 %
    of every method's points here ("sharing a frame with a nearer point"; 25-30 % in walk42)
    and put the others at frames up to half a period from their times. Now such a method is
    resampled: at every frame between two of its points at most two periods apart, its
    position there, linear in time; the command says so. Session 44: the gaps the
    detections explain (no point withheld, one frame without the ball at most) up to 50 ms:
    the grid is 138 Hz, whose two periods (14.4 ms) left 35 % of smooth's frames empty
    inside its complete track, whose points come up to 26 ms apart (a rolling shutter's row
    times)."""
    from pslog.interchange.track_formats import _detection_gaps, c3d_grid

    session_path, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    pslog_ok("simulate", "--rig", _drifting_rig(tmp_path), "--motion", "rally", "--duration",
             "36", "--noise-px", "0.3", "--seed", "75060", "-o", session_path)
    pslog_ok("fuse", session_path, "-o", fused)  # (typeA's and filter's gaps: a grid of 91 Hz)
    path = tmp_path / "t.c3d"
    out = pslog_ok("export", fused, "--c3d", path)
    assert "left out" not in out and "resampled onto the" in out, out
    session = read_session(fused)
    rate, first, n_frames = c3d_grid(session)
    labels, frames = _c3d_frames(path)
    frame_ns = first + np.round(np.arange(n_frames) * (1e9 / rate)).astype(np.int64)
    bridge = max(2e9 / rate, 1.5e9 / 30)  # 1.5 frame periods of the 30 fps cameras
    assert bridge > 2e9 / rate * 2  # (the grid: 138 Hz with --confirm-gaps kicks, 116 Hz
    # with the default jumps since session 45; either way the bridge spans more)
    for j, method in enumerate(labels[:-1]):
        track = session.tracks[method]
        t, index = np.unique(track.time_ns, return_index=True)
        assert len(t) == len(track)  # (one point a time here: no mean taken)
        p = track.position_world[index]
        after = np.searchsorted(t, frame_ns)
        inner = (after > 0) & (after < len(t))
        a, b = np.clip(after - 1, 0, len(t) - 1), np.clip(after, 0, len(t) - 1)
        withheld, missed = _detection_gaps(session, method)  # (test_c3d_leftovers.py)
        assert len(missed) == 0  # (every frame sees the ball here)
        kept = np.searchsorted(withheld, t[b]) == np.searchsorted(withheld, t[a], "right")
        want = (inner & (t[b] - t[a] <= bridge) & kept) | (t[b] == frame_ns)
        expect = np.stack([np.interp(frame_ns, t, p[:, k]) for k in range(3)], axis=1)
        # a lone point (no neighbour within two periods) on its nearest frame, as it is
        near = np.round((t - first) * rate / 1e9).astype(int)
        lone = np.flatnonzero(~want[near])
        for i in sorted(lone, key=lambda i: -abs(t[i] - frame_ns[near[i]])):  # nearest wins
            expect[near[i]] = p[i]
        want[near[lone]] = True
        valid = frames[:, j, 3] != -1
        assert np.array_equal(valid, want), method
        assert valid[near].all()  # every point in the file
        assert f"{method} {int(want.sum())} frames from {len(track)} points" in out
        if method == "smooth":  # nothing withheld: its whole span, but for 4 frames
            assert want.sum() >= n_frames - 4
        assert np.abs(frames[valid, j, :3] - expect[valid] * 1000.0).max() < 0.01  # mm


def test_c3d_of_a_track_with_points_of_one_time(tmp_path):
    """Cameras firing together (sync timing): the filter's points of one time made the grid's
    median interval 0 and ``export --c3d`` a ZeroDivisionError traceback."""
    session_path, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    pslog_ok("simulate", "--rig", "paper3", "--duration", "1", "--seed", "75061",
             "-o", session_path)
    pslog_ok("fuse", session_path, "--method", "filter", "-o", fused)
    out = pslog_ok("export", fused, "--c3d", tmp_path / "t.c3d")
    assert "at 30 Hz" in out and "filter" in out, out
    labels, frames = _c3d_frames(tmp_path / "t.c3d")
    assert labels[0] == "filter" and np.count_nonzero(frames[:, 0, 3] != -1) >= 25


def test_c3d_beyond_65535_frames_counts_them_in_its_parameters(tmp_path):
    """A 90-minute session at 90 Hz: 486,000 frames, beyond the header's 16-bit frame numbers.
    Refused before ("beyond the 65535 frames a C3D file holds"); now written as c3d.org
    says: the header's last frame 65535, the count in POINT:LONG_FRAMES (float32) and
    TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD (two 16-bit words each, low first), POINT:
    FRAMES 65535. Read back from the bytes themselves, and every frame with c3d's reader."""
    import struct


    # the same throw 5399 s later, after the first: a session of 90 minutes
    out, path, tracks, (rate, first, n) = late_throw_c3d(tmp_path, 75071, 5399, keep=True)
    assert rate == 90.0 and n > 480_000 and f"wrote {path}: {n} frames at 90 Hz" in out
    start = round(first * rate / 1e9) + 1
    data = path.read_bytes()
    words = struct.unpack("<256H", data[:512])
    assert data[1] == 0x50 and words[1] == 1  # one point: typeA
    assert (words[3], words[4]) == (start, 65535)  # first frame; the last saturated
    assert struct.unpack("<f", data[20:24])[0] == 90.0
    assert len(data) == -(-((words[8] - 1) * 512 + n * 16) // 512) * 512  # n frames, no more

    labels, frames = _c3d_frames(path)
    c3d = pytest.importorskip("c3d")
    with open(path, "rb") as f:
        reader = c3d.Reader(f)
        assert reader.get("POINT:FRAMES").uint16_value == 65535
        assert reader.get("POINT:LONG_FRAMES").float_value == n
        lo, hi = reader.get("TRIAL:ACTUAL_END_FIELD").uint16_array
        assert int(lo) + 65536 * int(hi) == start + n - 1
        lo, hi = reader.get("TRIAL:ACTUAL_START_FIELD").uint16_array
        assert int(lo) + 65536 * int(hi) == start
    assert labels == ["typeA"] and len(frames) == n
    track = tracks.tracks["typeA"]
    at = np.round((track.time_ns - first) * rate / 1e9).astype(int)
    assert at[-1] == n - 1  # the last point on the last frame, 90 minutes on
    assert np.allclose(frames[at, 0, :3], track.position_world * 1000.0, atol=1e-3)
    assert np.count_nonzero(frames[:, 0, 3] != -1) == len(track)


def late_throw_c3d(tmp_path, seed: int, shift_s: int, keep: bool):
    """A one-second throw (paper3, type A timing, ``seed``) moved ``shift_s`` seconds on
    (``keep``: after the original detections, one session that long), imported, fused by
    type A and exported to C3D: (the export's output, the C3D path, the fused tracks,
    :func:`pslog.interchange.track_formats.c3d_grid`'s ``(rate, first, n)``)."""
    from decimal import Decimal

    from pslog.interchange.track_formats import c3d_grid

    burst, rig = tmp_path / "burst.mcap", tmp_path / "rig.toml"
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
             "--duration", "1", "--seed", str(seed), "-o", burst)
    rig.write_text(pslog_ok("rig", "show", burst))
    pslog_ok("export", burst, "--detections", tmp_path / "d.csv")
    lines = (tmp_path / "d.csv").read_text().splitlines()
    late = []
    for line in lines[1:]:
        cells = line.split(",")
        cells[1] = str(Decimal(cells[1]) + shift_s)
        cells[4] = str(int(cells[4]) + shift_s * 30)
        late.append(",".join(cells))
    (tmp_path / "late.csv").write_text("\n".join((lines if keep else lines[:1]) + late) + "\n")
    session, fused, path = tmp_path / "late.mcap", tmp_path / "f.mcap", tmp_path / "t.c3d"
    pslog_ok("import", "--rig", rig, "--detections", tmp_path / "late.csv", "-o", session)
    pslog_ok("fuse", session, "--method", "typeA", "-o", fused)
    out = pslog_ok("export", fused, "--c3d", path)
    tracks = read_session(fused)
    return out, path, tracks, c3d_grid(tracks)
