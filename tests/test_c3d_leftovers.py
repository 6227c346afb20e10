"""Session 44: the three limits ``pslog export --c3d`` documented in session 43 (docs/
interchange.md, C3D). Through the real CLI on real fused sessions, read back with ``c3d``.

- A resampled method's bridge filled the spans the method withheld (type A's ``kink`` /
  ``contradicted`` points, the filter's ``held``): a point it refused, invented by the export.
- Of two lone points nearest one frame the nearer was kept and the other dropped in silence
  (and lone points were many: the bridge, two periods of a 110-138 Hz grid, was shorter than
  the rolling-shutter track's own spacing).
- ``c3d``'s reader counts one frame too many per 65,536 of a start frame past 65,535: our
  read-back must not take its count.
"""

from __future__ import annotations

import re
import struct
import warnings

import numpy as np
import pytest
from _cli import pslog, pslog_ok
from test_export_paths_and_c3d import _c3d_frames, _drifting_rig, late_throw_c3d

from pslog.log import read_session
from pslog.timing import camera_parameters, true_times_ns


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """walk42's lab (rolling shutter, drifting clocks), 5 % of the frames missed: fused with
    the default methods, exported as C3D; (session, out, labels, frames, frame_ns)."""
    from pslog.interchange.track_formats import c3d_grid

    pytest.importorskip("c3d")
    folder = tmp_path_factory.mktemp("leftovers")
    session_path, fused, path = folder / "s.mcap", folder / "f.mcap", folder / "t.c3d"
    pslog_ok("simulate", "--rig", _drifting_rig(folder), "--motion", "rally", "--duration",
             "36", "--noise-px", "0.3", "--miss-rate", "0.05", "--seed", "77002",
             "-o", session_path)
    pslog_ok("fuse", session_path, "-o", fused)
    out = pslog_ok("export", fused, "--c3d", path)
    session = read_session(fused)
    rate, first, n_frames = c3d_grid(session)
    labels, frames = _c3d_frames(path)
    assert len(frames) == n_frames and labels[-1] == "truth"
    frame_ns = first + np.round(np.arange(n_frames) * (1e9 / rate)).astype(np.int64)
    return session, out, labels, frames, frame_ns


def _seen_times(session, method) -> np.ndarray:
    """The true capture times of the detections the method's gate kept (one candidate a
    frame here: a frame whose candidate it rejected holds none)."""
    d = session.detections
    assert np.array_equal(d.cand_frame, np.unique(d.cand_frame))  # one candidate a frame
    frame = d.cand_frame
    camera = d.frame_camera[frame]
    rejected = session.rejections.get(method)
    keep = np.ones(len(frame), bool)
    if rejected is not None:
        for cam, index in zip(rejected.camera.tolist(), rejected.frame_index.tolist(),
                              strict=True):
            keep &= ~((camera == cam) & (d.frame_index[frame] == index))
    p = camera_parameters(session.rig)
    return np.unique(true_times_ns(d.frame_time_ns[frame], d.cand_uv[:, 1],
                                   p["height"][camera], p["clock_offset"][camera],
                                   p["clock_drift_ppm"][camera], p["readout"][camera])[keep])


def test_c3d_bridges_no_span_the_method_withheld(exported):
    """Type A left out 189 points here (kink, contradicted, ...): the detections they would
    have been made from are in the session, the points are not in the track. The gaps they
    leave: 7 within two frame periods (18 ms at 110.9 Hz, the bridge before), 12 frames
    the C3D filled linearly with the points type A refused. Now no frame inside such a gap
    holds an interpolation (empty, or a lone point of its ends as it is), while a gap with
    one frame without the ball and nothing withheld is bridged, up to 50 ms (1.5 frame
    periods of the 30 fps cameras: a sync rig's points come a frame period apart); within
    50 ms, the gaps the methods left hold 132 of type A's frames and 311 of the filter's
    (its ``unconfirmed`` runs)."""
    session, out, labels, frames, frame_ns = exported
    assert "no detection the method withheld and at most one frame without" in out
    d = session.detections
    empty = np.ones(len(d.frame_time_ns), bool)
    empty[d.cand_frame] = False
    p = camera_parameters(session.rig)
    cam = d.frame_camera[empty]
    no_ball = np.sort(true_times_ns(d.frame_time_ns[empty], 0.0, p["height"][cam],
                                    p["clock_offset"][cam], p["clock_drift_ppm"][cam],
                                    p["readout"][cam]))
    checked, unbridged = {}, 0
    for method in ("typeA", "filter", "smooth"):
        track = session.tracks[method]
        j = labels.index(method)
        t, index = np.unique(track.time_ns, return_index=True)
        p = track.position_world[index] * 1000.0
        seen = _seen_times(session, method)
        assert np.isin(t, seen).all()  # every point at a detection's time
        withheld = seen[~np.isin(seen, t)]
        a, b = t[:-1], t[1:]
        inside = np.searchsorted(withheld, b) - np.searchsorted(withheld, a, "right")
        lo, hi = np.searchsorted(frame_ns, a, "right"), np.searchsorted(frame_ns, b)
        valid = frames[:, j, 3] != -1
        refused = 0
        for i in np.flatnonzero((b - a <= 0.05e9) & (inside > 0) & (hi > lo)):
            for k in range(lo[i], hi[i]):  # a frame strictly inside the gap
                refused += 1
                assert not valid[k] or np.allclose(frames[k, j, :3], p[i], atol=1e-3) or \
                    np.allclose(frames[k, j, :3], p[i + 1], atol=1e-3), (method, k)
        # nothing withheld, one frame without the ball at most, within 50 ms: bridged; two
        # or more frames without it: not
        missed = np.searchsorted(no_ball, b) - np.searchsorted(no_ball, a, "right")
        for i in np.flatnonzero((b - a <= 0.05e9) & (inside == 0) & (missed > 1) & (hi > lo)):
            for k in range(lo[i], hi[i]):
                unbridged += 1
                assert not valid[k] or np.allclose(frames[k, j, :3], p[i], atol=1e-3) or \
                    np.allclose(frames[k, j, :3], p[i + 1], atol=1e-3), (method, k)
        bridged = (b - a <= 0.05e9) & (inside == 0) & (missed <= 1) & (hi > lo)
        assert all(valid[lo[i]:hi[i]].all() for i in np.flatnonzero(bridged))
        checked[method] = (refused, int(np.count_nonzero(bridged & (missed == 1))))
    assert checked["typeA"][0] >= 100 and checked["filter"][0] >= 100, checked
    assert checked["smooth"][0] == 0 and unbridged > 10, (checked, unbridged)
    assert min(n for _r, n in checked.values()) > 100, checked  # missed frames bridged
    assert session.left_out["typeA"]["kink"] > 100


def test_c3d_says_the_lone_points_a_nearer_one_displaced(exported):
    """A lone point (no frame bridged beside it) goes on its nearest frame as it is; two
    nearest one frame: the one nearer its time is kept, the other was dropped without a
    word. Now the command counts them per method ("not in the file: ..."), and the count
    is the file's: the points whose nearest frame holds another point as it is."""
    session, out, labels, frames, frame_ns = exported
    said = {}
    line = next((x for x in out.splitlines() if x.strip().startswith("not in the file:")), "")
    assert line, out
    for method, n in re.findall(r"(\w+) (\d+) points?\b", line):
        said[method] = int(n)
    period = float(frame_ns[1] - frame_ns[0])
    found = {}
    for method in session.tracks:
        j = labels.index(method)
        t, index = np.unique(session.tracks[method].time_ns, return_index=True)
        p = (session.tracks[method].position_world[index] * 1000.0).astype(np.float32)
        near = np.round((t - frame_ns[0]) / period).astype(int)
        assert (frames[near, j, 3] != -1).all()  # every point's nearest frame holds one
        as_is = np.all(frames[near, j, :3] == p, axis=1)  # the point itself is there
        displaced = []
        for i in np.flatnonzero(~as_is):  # its frame holds another lone point, as it is?
            others = np.flatnonzero((near == near[i]) & as_is)
            if len(others):
                assert abs(t[others[0]] - frame_ns[near[i]]) <= abs(t[i] - frame_ns[near[i]])
                displaced.append(i)
        if displaced:
            found[method] = len(displaced)
    assert found == said and sum(said.values()) >= 10, (found, said)


def test_c3d_past_frame_65535_read_back_by_its_own_count(tmp_path):
    """A track starting at 1000 s (frame 90,001 at 90 Hz): its start frame is in TRIAL:
    ACTUAL_START_FIELD only, two 16-bit words, low first. ``c3d`` 0.6's reader joins them as
    low + 65535 · high and counts one frame too many (the last read from the file's padding:
    a valid point at the origin). pslog has no C3D reader; the tests take the file's own
    count (high << 16 | low, as btk): these frames are the track's, none more. And ``c3d``'s
    writer took its start frame back through the same join: the file said 90,003, one frame
    (11 ms) early to btk and Mokka; now 90,004; and the frame c3d's reader reads beyond holds
    an invalid point, not the padding's valid one at the origin."""
    # the same throw 1000 s on, alone
    _out, path, tracks, (rate, first, n) = late_throw_c3d(tmp_path, 77003, 1000, keep=False)
    start = round(first * rate / 1e9) + 1
    assert rate == 90.0 and start > 65535 and n < 200
    c3d = pytest.importorskip("c3d")
    with open(path, "rb") as f, warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        reader = c3d.Reader(f)
        lo, hi = map(int, reader.get("TRIAL:ACTUAL_START_FIELD").uint16_array)
        end_lo, end_hi = map(int, reader.get("TRIAL:ACTUAL_END_FIELD").uint16_array)
        assert (hi << 16 | lo, end_hi << 16 | end_lo) == (start, start + n - 1)
        # the package's own count (0.6: as many frames too many as the start's high word):
        # those beyond the file's count hold no valid point (the block's zero padding did:
        # a point at the origin, residual 0)
        read = np.array([points for _, points, _ in reader.read_frames()])
    assert hi == 1 and len(read) in (n, n + hi) and (read[n:, :, 3] == -1).all()
    data = path.read_bytes()
    assert struct.unpack("<H", data[6:8])[0] == 65535  # the header's first frame: saturated
    end = 512 * (struct.unpack("<H", data[16:18])[0] - 1) + n * 16  # one point a frame
    assert struct.unpack("<4f", data[end:end + 16]) == (0.0, 0.0, 0.0, -1.0)
    assert len(data) % 512 == 0 and not any(data[end + 16:])
    labels, frames = _c3d_frames(path)
    assert labels == ["typeA"] and len(frames) == n
    track = tracks.tracks["typeA"]
    at = np.round((track.time_ns - first) * rate / 1e9).astype(int)
    assert at[0] == 0 and at[-1] == n - 1
    assert np.allclose(frames[at, 0, :3], track.position_world * 1000.0, atol=1e-3)
    assert np.count_nonzero(frames[:, 0, 3] != -1) == len(track)


def test_import_and_eval_name_the_export_formats_they_do_not_read(tmp_path):
    """Session 44's walk: a new user giving ``pslog import --detections`` or ``pslog eval
    --truth`` a file ``pslog export`` wrote in another format. A TUM trajectory was a "bad
    header '# timestamp tx ty ...'" with a --columns hint; a C3D or Parquet file "not a text
    (CSV) file (byte 8 ...)". Each is now named, with what reads it, in one line."""
    pytest.importorskip("c3d")
    pytest.importorskip("pyarrow")
    session, fused = tmp_path / "s.mcap", tmp_path / "f.mcap"
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--duration", "0.6",
             "--seed", "77021", "-o", session)
    pslog_ok("fuse", session, "--method", "typeA", "-o", fused)
    pslog_ok("export", fused, "--tum", tmp_path / "traj", "--c3d", tmp_path / "t.c3d",
             "--parquet", tmp_path / "t.parquet")
    rig = tmp_path / "rig.toml"
    rig.write_text(pslog_ok("rig", "show", session))
    for name, said in (("traj/typeA.tum", "holds a TUM trajectory"),
                       ("t.c3d", "is a C3D file"), ("t.parquet", "is a Parquet file")):
        done = pslog("import", "--rig", rig, "--detections", tmp_path / name,
                     "-o", tmp_path / "x.mcap")
        assert done.returncode == 1 and said in done.stderr, done.stderr
        assert len(done.stderr.splitlines()) == 1
        assert "not a detections CSV" in done.stderr or "not detections" in done.stderr
        assert not (tmp_path / "x.mcap").exists()
    for name, said in (("t.c3d", "is a C3D file: --truth reads a CSV t,x,y,z"),
                       ("t.parquet", "is a Parquet file, not a truth trajectory")):
        done = pslog("eval", fused, "--truth", tmp_path / name)
        assert done.returncode == 1 and said in done.stderr, done.stderr
        assert len(done.stderr.splitlines()) == 1
