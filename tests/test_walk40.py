"""Session 40's new-user walkthrough (walk40: a lab's three webcams, rolling shutters, host
clocks offset and drifting, its own detector writing one CSV per camera and no row for a
frame without a ball, a mocap truth): what the lab stumbled on, through ``pslog`` as a
process on files it writes (benchmarks/session40/walk40_notes.md).

- A CSV without a ``frame`` column: each camera's frames were numbered 0, 1, 2, ... in time
  order, so every frame the detector wrote no row for (a miss) shifted the numbers of all
  later frames; ``pslog sync``'s line of host stamps against frame numbers (``--regularize
  auto``, on for host jitter above 0.2 ms) then moved cam1's times by up to seconds
  ("jitter 66.634 ms"), and sync wrote a readout of -109 ms, offsets 46-47 ms off and points
  12 cm off, without a word. Import now numbers frames from their times (a gap of k frame
  periods skips k - 1 numbers), and the session is the one the frame column gives.
- Frame numbers that skip no missed frame all the same (a ``frame`` column counting the
  detector's rows): sync no longer fits its line through them; it says so and leaves that
  camera's stamps as logged (``--regularize on``: refused in one line).
- The detector's misses, no row each: ``pslog info`` rated cam1's detections at 100 %.
  Import now says which cameras' frame numbers have no row, and how to count them.
"""

from __future__ import annotations

import csv
import json
from decimal import Decimal
from pathlib import Path

import numpy as np
from _cli import pslog as _run
from _cli import pslog_ok as _ok

from pslog.log import read_session


def _lab_csvs(tmp_path: Path, *, frame: str | None, extra: tuple[str, ...] = (),
              seed: int = 64010) -> tuple[dict[str, Path], Path]:
    """A simulated three-camera session with misses, host jitter and cam2's clock 4 ms off,
    as the lab's per-camera CSVs: no row for a frame without a candidate, times on Unix-epoch
    seconds; ``frame``: None (no frame column), ``"camera"`` (the camera's frame numbers)
    or ``"rows"`` (a counter of the rows' frames, skipping no missed frame)."""
    raw, det = tmp_path / "raw.mcap", tmp_path / "det.csv"
    _ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally", "--duration",
        "6", "--noise-px", "0.3", "--miss-rate", "0.1", "--host-jitter", "1",
        "--clock-offset", "cam2=4", *extra, "--seed", seed, "-o", raw)
    _ok("export", raw, "--detections", det)
    with open(det, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["u"] != ""]  # no row for a miss
    files = {}
    for cam in ("cam1", "cam2", "cam3"):
        mine = [r for r in rows if r["camera"] == cam]
        path = tmp_path / f"{cam}.csv"
        with open(path, "w", newline="") as fh:
            out = csv.writer(fh)
            out.writerow((["frame"] if frame else []) + ["time", "u", "v"])
            counter, last = -1, None
            for r in mine:
                if r["time"] != last:
                    counter, last = counter + 1, r["time"]
                number = {"camera": [r["frame"]], "rows": [str(counter)], None: []}[frame]
                unix = Decimal(r["time"]) + Decimal("1764921600.437")
                out.writerow([*number, f"{unix:.6f}", r["u"], r["v"]])
        files[cam] = path
    return files, raw


def _import(files: dict[str, Path], out: Path) -> str:
    args = [a for cam, path in files.items() for a in ("--detections", f"{cam}={path}")]
    return _ok("import", "--rig", "paper3", "--timing", "typeA", *args, "-o", out)


def _frame_numbers(path: Path) -> dict[str, np.ndarray]:
    det = read_session(path).detections
    return {name: np.sort(det.frame_index[det.frame_camera == c])
            for c, name in enumerate(det.camera_names)}


def test_csv_without_frame_column_numbers_frames_by_their_times(tmp_path):
    """The frames of a CSV without a ``frame`` column are numbered as the camera numbered
    them (from the first frame given), misses leaving gaps: fails with the former numbering
    0, 1, 2, ... in time order (each miss shifts the later numbers by one)."""
    files, raw = _lab_csvs(tmp_path, frame=None)
    out = _import(files, tmp_path / "lab.mcap")
    numbers = _frame_numbers(tmp_path / "lab.mcap")
    det = read_session(raw).detections
    seen = det.candidates_per_frame() > 0
    missed_inside = []
    for c, name in enumerate(det.camera_names):
        truth = np.sort(det.frame_index[(det.frame_camera == c) & seen])
        assert np.array_equal(numbers[name], truth - truth[0]), name
        missed_inside.append(int(truth[-1] - truth[0] + 1 - len(truth)))
    assert min(missed_inside) > 10  # (the misses the old numbering shifted the frames by)
    # the same session as with the camera's frame column (numbers from its first frame)
    (tmp_path / "k").mkdir()
    files_k, _ = _lab_csvs(tmp_path / "k", frame="camera")
    _import(files_k, tmp_path / "k.mcap")
    with_column = _frame_numbers(tmp_path / "k.mcap")
    for name, k in with_column.items():
        assert np.array_equal(numbers[name], k - k[0]), name
    # the misses without a row, said (info rates only the frames given)
    note = [line for line in out.splitlines() if line.startswith("note: frame numbers")]
    assert len(note) == 1, out
    for name, gaps in zip(det.camera_names, missed_inside, strict=True):
        assert f"{name} {gaps} of " in note[0], note[0]


def test_sync_of_a_csv_without_frame_column(tmp_path):
    """Imported without a frame column, with misses and host jitter, synced (host stamps
    regularized): cam2's offset within 0.5 ms of the true 4 ms and the stamps' jitter the
    true 1 ms (before session 40: cam1's "jitter" tens of ms, the offsets tens of ms off)."""
    files, _ = _lab_csvs(tmp_path, frame=None)
    _import(files, tmp_path / "lab.mcap")
    done = _run("sync", tmp_path / "lab.mcap", "-o", tmp_path / "synced.mcap",
                "--estimate", "offset", "--json")
    assert done.returncode == 0, done.stderr
    cams = {c["name"]: c for c in json.loads(done.stdout)["cameras"]}
    assert abs(cams["cam2"]["offset_s"] - 0.004) < 0.5e-3, cams["cam2"]
    assert abs(cams["cam3"]["offset_s"]) < 0.5e-3, cams["cam3"]
    jitters = [float(line.split("jitter ")[1].split(" ms")[0])
               for line in done.stderr.splitlines() if "host stamps regularized" in line]
    assert len(jitters) == 3 and all(0.7 < j < 1.4 for j in jitters), done.stderr


def test_sync_says_frame_numbers_that_skip_no_missed_frame(tmp_path):
    """A frame column counting the detector's rows (no gap where the ball was missed): sync
    leaves those stamps as logged and says why (auto), refuses ``--regularize on`` in one
    line, no copy written; the offsets still right. Fails when the line is fitted through
    them (cam2's offset 25 ms off, the note absent)."""
    files, _ = _lab_csvs(tmp_path, frame="rows")
    _import(files, tmp_path / "lab.mcap")
    done = _run("sync", tmp_path / "lab.mcap", "-o", tmp_path / "synced.mcap",
                "--estimate", "offset", "--json")
    assert done.returncode == 0, done.stderr
    astray = [line for line in done.stderr.splitlines() if "skip no missed frame" in line]
    assert len(astray) == 3 and all(line.endswith("host stamps are not regularized")
                                    for line in astray), done.stderr
    cams = {c["name"]: c for c in json.loads(done.stdout)["cameras"]}
    assert abs(cams["cam2"]["offset_s"] - 0.004) < 1e-3, cams["cam2"]
    done = _run("sync", tmp_path / "lab.mcap", "-o", tmp_path / "on.mcap", "--regularize",
                "on")
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "skip no missed frame" in lines[0], done.stderr
    assert "cannot be regularized (--regularize on)" in lines[0]
    assert "Traceback" not in done.stderr and not (tmp_path / "on.mcap").exists()


def test_sync_still_regularizes_dropped_frames_and_heavy_jitter(tmp_path):
    """A camera's frame numbers with real gaps (10 % of frames dropped) and host stamps
    jittering by 12 ms (over a third of a frame period: a step of 1.5 periods or more in
    one of six, and as many under half a period): the
    stamps are regularized, no camera said astray (the test's false alarm)."""
    raw = tmp_path / "raw.mcap"
    _ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally", "--duration",
        "6", "--noise-px", "0.3", "--drop-rate", "0.1", "--host-jitter", "12",
        "--clock-offset", "cam2=4", "--seed", "64011", "-o", raw)
    done = _run("sync", raw, "-o", tmp_path / "synced.mcap", "--estimate", "offset")
    assert done.returncode == 0, done.stderr
    said = done.stdout + done.stderr  # (the notes: stdout with the table)
    assert "skip no missed frame" not in said, said
    assert said.count("host stamps regularized") == 3, said


def _truth_csv(path: Path, session: Path, add_s: str) -> None:
    truth = read_session(session).truth
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["t", "x", "y", "z"])
        for t, p in zip(truth.time_ns.tolist(), truth.position_world.tolist(), strict=True):
            out.writerow([f"{Decimal(t) / 10**9 + Decimal(add_s):.9f}", *map(repr, p)])


def test_eval_says_a_truth_whose_clock_is_off_the_cameras(tmp_path):
    """A mocap truth 4 ms late on the cameras' clock (another host's Unix time): eval scores
    it as given and says in a note that the tracks fit it best with its times moved by
    -4 ms (within 0.3 ms), with the median errors there and as given; the truth on the
    cameras' clock: no note. Fails with the shift's sign flipped (+4 ms said) or no note."""
    raw, fused = tmp_path / "raw.mcap", tmp_path / "fused.mcap"
    _ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally", "--duration",
        "4", "--noise-px", "0.3", "--seed", "64012", "-o", raw)
    _ok("fuse", raw, "--method", "smooth,typeA", "-o", fused)
    _truth_csv(tmp_path / "late.csv", raw, "0.004")
    _truth_csv(tmp_path / "same.csv", raw, "0")
    out = _ok("eval", fused, "--truth", tmp_path / "late.csv")
    notes = [line for line in out.splitlines() if line.startswith("note: the tracks fit")]
    assert len(notes) == 1, out
    moved = float(notes[0].split("moved by ")[1].split(" ms")[0])
    assert abs(moved + 4.0) < 0.3, notes[0]
    given = json.loads(_ok("eval", fused, "--truth", tmp_path / "late.csv", "--json"))
    same = json.loads(_ok("eval", fused, "--truth", tmp_path / "same.csv", "--json"))
    smooth = {r["method"]: r["median_mm"] for r in given}["smooth"]
    assert f"{smooth:.3g} mm as given" in notes[0], notes[0]
    assert smooth > 2 * {r["method"]: r["median_mm"] for r in same}["smooth"]
    done = _run("eval", fused, "--truth", tmp_path / "late.csv", "--json")
    assert "note: the tracks fit this truth best" in done.stderr  # (stdout: the JSON alone)
    assert "note: the tracks fit" not in _ok("eval", fused, "--truth", tmp_path / "same.csv")


def test_truth_on_a_clock_of_its_own_and_in_milliseconds_said(tmp_path):
    """A session imported on Unix-epoch seconds, a mocap CSV whose times count from the
    capture's own start: refused in one line that no longer tells only to add the session's
    origin (which put the truth 0.437 s off here) but names the clock of its own and the
    tracks' span on the original clock; a mocap on Unix milliseconds: refused, the unit
    named (before: only "beyond the range of times")."""
    files, raw = _lab_csvs(tmp_path, frame="camera")
    _import(files, tmp_path / "lab.mcap")
    _ok("fuse", tmp_path / "lab.mcap", "--method", "typeA", "-o", tmp_path / "fused.mcap")
    _truth_csv(tmp_path / "own.csv", raw, "0")  # (0-6 s: the truth's own start)
    done = _run("eval", tmp_path / "fused.mcap", "--truth", tmp_path / "own.csv")
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1 and len(lines) == 1, done.stderr
    assert "if they are session times, add the session's clock origin" in lines[0]
    assert "times counted from the truth's own start" in lines[0]
    assert "the tracks span 17649216" in lines[0], lines[0]
    with open(tmp_path / "ms.csv", "w") as fh:
        fh.write("t,x,y,z\n1764921600440.100,0.5,1.0,0.03\n1764921600448.433,0.5,1.0,0.05\n")
    done = _run("eval", tmp_path / "fused.mcap", "--truth", tmp_path / "ms.csv")
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 1 and len(lines) == 1, done.stderr
    assert "a Unix time in milliseconds or microseconds? give seconds" in lines[0], lines[0]


def test_import_says_shutters_off_the_rigs_offsets(tmp_path):
    """The lab's CSVs (cam2's clock 4 ms off, on a type-A rig: its shutter 4 ms from the
    rig's 11.1 ms) imported: a note names cam2, its phase and the rig's, and the sync
    command; a genlocked session's export imported: no such note. Fails without the note."""
    files, _ = _lab_csvs(tmp_path, frame="camera")
    out = _import(files, tmp_path / "lab.mcap")
    notes = [line for line in out.splitlines() if line.startswith("note: the times put")]
    assert len(notes) == 1 and " ms (rig 11.1 ms)" in notes[0], out
    phase = float(notes[0].split("shutters of cam2 ")[1].split(" ms")[0])
    assert abs(phase - (11.111 - 4.0)) < 0.5, notes[0]  # (host jitter 1 ms, 10 % misses)
    assert "cam3" not in notes[0] and "'pslog sync " in notes[0], notes[0]
    raw, det = tmp_path / "g.mcap", tmp_path / "g.csv"
    _ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "spiral", "--miss-rate",
        "0.1", "--seed", "64013", "-o", raw)
    _ok("export", raw, "--detections", det)
    out = _ok("import", "--rig", "paper3", "--timing", "typeA", "--detections", det, "-o",
              tmp_path / "gi.mcap")
    assert "note: the times put" not in out, out


def test_view_of_the_import_beside_its_synced_fusion(tmp_path):
    """``pslog view lab.mcap fused.mcap``, the fused file made from the synced copy (host
    stamps regularized): the note says they are the same frames at other times and how to
    view the fused file with its clocks, not "may come from another session" (which sent
    the lab looking for one); the .rrd written. Fails with the former note."""
    files, _ = _lab_csvs(tmp_path, frame="camera")
    _import(files, tmp_path / "lab.mcap")
    _ok("sync", tmp_path / "lab.mcap", "-o", tmp_path / "synced.mcap", "--estimate", "offset")
    _ok("fuse", tmp_path / "synced.mcap", "--method", "typeA", "-o", tmp_path / "fused.mcap")
    done = _run("view", tmp_path / "lab.mcap", tmp_path / "fused.mcap", "--frames", "none",
                "--save", tmp_path / "v.rrd")
    assert done.returncode == 0, done.stderr
    said = done.stdout + done.stderr
    assert "fused.mcap: the same frames as " in said, said
    assert "host stamps 'pslog sync' regularized" in said and "'pslog view " in said, said
    assert "may come from another session" not in said, said
    assert (tmp_path / "v.rrd").stat().st_size > 0


def test_frames_numbered_by_the_rigs_period_when_the_ball_was_seen_in_few(tmp_path):
    """A camera that wrote rows for fewer than half its frames (steps of 2 frame periods
    mostly, some of 1 and 3; 0.5 ms of jitter): its frame numbers are its frames' (time /
    period), the median step taken as 2 periods of the rig's 30 fps. Fails when the median
    step is taken as one period (a step of 3 periods, 1.5 of those, numbered 2 or 1)."""
    rng = np.random.default_rng(64014)
    frames = np.cumsum(rng.choice([1, 2, 2, 2, 3], size=200))
    times = frames / 30.0 + rng.normal(0.0, 0.5e-3, len(frames))
    path = tmp_path / "cam1.csv"
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["time", "u", "v"])
        for t in times:
            out.writerow([f"{t + 5.0:.6f}", "320.5", "240.5"])
    _ok("import", "--rig", "paper2", "--detections", f"cam1={path}", "-o", tmp_path / "s.mcap")
    numbers = _frame_numbers(tmp_path / "s.mcap")["cam1"]
    assert np.array_equal(numbers, frames - frames[0])
