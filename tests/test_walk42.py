"""Session 42's walkthrough (walk42): a robotics lab's three unsynchronised USB webcams,
calibrated, recorded from video files, synced, fused, scored against motion capture and
exported (benchmarks/session42/walk42_notes.md). Each test fails on the code before its fix.
"""

from __future__ import annotations

import cv2
import numpy as np
from _cli import pslog_ok

# ---- chessboard squares small in the image --------------------------------------------------

_K = np.array([[520.0, 0.0, 316.5], [0.0, 520.5, 242.0], [0.0, 0.0, 1.0]])
_DIST = np.array([-0.18, 0.12, 0.0, 0.0, 0.0])


def _board_shot(rng: np.random.Generator, width: int = 640, height: int = 480) -> np.ndarray:
    """A 9x6 (inner corners) board of 25 mm squares 0.5-0.9 m before a webcam of f 520 px:
    squares of 12-25 px. Rendered exactly through the lens (each pixel's ray met with the
    board's plane, 2x2 samples a pixel), as walk42_make.py does."""
    sq, cols, rows = 0.025, 10, 7
    rb = cv2.Rodrigues(rng.uniform(-0.45, 0.45, 3))[0]
    centre = np.array([rng.uniform(-0.12, 0.12), rng.uniform(-0.08, 0.08),
                       rng.uniform(0.5, 0.9)])
    origin = centre - rb @ np.array([cols * sq / 2, rows * sq / 2, 0.0])
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    acc = np.zeros((height, width))
    for dx, dy in ((-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)):
        pix = np.stack([xs + dx, ys + dy], -1).reshape(-1, 1, 2)
        ray = cv2.undistortPoints(pix, _K, _DIST).reshape(-1, 2)
        d = np.c_[ray, np.ones(len(ray))]
        s = (rb[:, 2] @ origin) / (d @ rb[:, 2])
        local = (s[:, None] * d - origin) @ rb
        cx, cy = np.floor(local[:, 0] / sq), np.floor(local[:, 1] / sq)
        inside = (cx >= 0) & (cx < cols) & (cy >= 0) & (cy < rows)
        acc += np.where(inside, np.where((cx + cy) % 2 == 0, 20, 235), 150).reshape(
            height, width) / 4
    return (acc + rng.normal(0, 2, acc.shape)).clip(0, 255).astype(np.uint8)


def test_chessboard_with_small_squares_in_the_image_gives_the_lens(tmp_path):
    """walk42: a webcam's 640x480 views of a 25 mm board a metre away (squares 12-25 px):
    cornerSubPix's fixed 11 px half window reached the neighbouring corners, and `pslog
    calibrate --chessboard` gave f 362 px for a lens of 520 (RMS 1.4 px), accepted. Its
    window is now half the corners' spacing: f within 0.5 %, RMS ~0.1 px."""
    rng = np.random.default_rng(70042)
    folder = tmp_path / "shots"
    folder.mkdir()
    for j in range(14):
        cv2.imwrite(str(folder / f"shot{j:02d}.png"), _board_shot(rng))
    out = pslog_ok("calibrate", "--chessboard", "9x6", "--square", "0.025", "--images",
                   folder, "--name", "cam1", "--rig", tmp_path / "lab.toml")
    fx = float(out.split("fx ")[1].split()[0])
    rms = float(out.split("reprojection RMS ")[1].split()[0])
    assert abs(fx - 520.0) < 2.6, out
    assert rms < 0.2, out


# ---- view: the session beside its synced copy's fused file -----------------------------------

def test_view_says_a_fused_file_of_the_synced_copy_is_shown_on_the_session_clocks(tmp_path):
    """walk42: `pslog view rec.mcap fused-synced.mcap` (the session, then a fused copy, as the
    README reads), the fused file made from `pslog sync`'s copy without regularized stamps:
    the rays, epipolar lines and type A's Figure 2 constructions were drawn on the session's
    unsynced clocks (907 of the walk's 2,804 typeA points explained), nothing said. Now a
    note names it and the command that shows the fused file with its own clocks; the fused
    file alone explains every point."""
    s, synced, fused = (tmp_path / n for n in ("s.mcap", "synced.mcap", "fused.mcap"))
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "throw",
             "--noise-px", "0.3", "--clock-offset", "cam2=4", "--clock-offset", "cam3=-5",
             "--seed", "70042", "-o", s)
    pslog_ok("sync", s, "-o", synced)
    pslog_ok("fuse", synced, "--method", "typeA", "-o", fused)
    said = pslog_ok("view", s, fused, "--frames", "none", "--save", tmp_path / "both.rrd")
    assert f"{fused}: fused from a synced copy of {s}" in said, said
    assert f"'pslog view {fused}' shows it with the clocks it was fused with" in said, said
    alone = pslog_ok("view", fused, "--frames", "none", "--save", tmp_path / "alone.rrd")
    assert "synced copy" not in alone, alone


# ---- a detection beyond the lens model's fold-over: sync and smooth without gating ---------

def _folding_sessions(tmp_path):
    """A 6 s paper3 rally seen through a barrel lens that folds over inside the image
    (k1 -0.5: no ray beyond 326 px from the centre), as a webcam's chessboard calibration
    gave walk42 (k3 -0.46, folding in the image's corner), three of cam1's detections moved
    to its corners (a blob there: no ray); and the same session without those rows."""
    from pslog import Rig, SimulationOptions, apply_timing, builtin_rig, get_motion, simulate
    from pslog.log import SessionWriter
    from pslog.records import Detections, Observations
    from pslog.timing import observations as timed_observations

    rig = apply_timing(builtin_rig("paper3"), "typeA")
    rig = Rig(tuple(c.replace(dist=np.array([-0.5, 0.0, 0.0, 0.0, 0.0])) for c in rig.cameras),
              rig.name)
    det, _ = simulate(rig, get_motion("rally"), 6.0,
                      SimulationOptions(noise_px=0.3, seed=70042))
    obs = timed_observations(det, rig)
    rows = np.flatnonzero(obs.camera == 0)[[20, 70, 120]]
    uv = obs.uv.copy()
    uv[rows] = [[4.0, 3.0], [636.0, 476.0], [5.0, 470.0]]
    assert not np.isfinite(rig.cameras[0].undistort_normalized(uv[rows])).any()
    keep = np.ones(len(obs), dtype=bool)
    keep[rows] = False
    paths = []
    for name, o in (("corners", Observations(obs.time_ns, obs.camera, uv, obs.frame_index)),
                    ("without", obs.select(keep))):
        path = tmp_path / f"{name}.mcap"
        with SessionWriter(path, rig, timing="typeA", source="test") as writer:
            writer.add_detections(Detections.from_observations(rig.names, o))
        paths.append(path)
    return paths


def test_sync_and_smooth_take_a_detection_without_a_ray_as_a_missing_one(tmp_path):
    """walk42: a session imported from a lab's detector, its cam1 calibrated by `pslog
    calibrate --chessboard` with a k3 that folds over in the image's corner: `pslog sync`
    failed ("no stretch of the session is seen by it and camera cam1 together long enough
    to scan its offset", or "information matrix not positive definite"), as did `pslog fuse
    --method smooth --gating off`: the NaN rays of two corner detections entered the fits'
    linear start. Both now leave them out, as every fusion method does (docs/methods.md, "A
    detection without a ray"): sync's clocks are those of the session without them."""
    import json

    corners, without = _folding_sessions(tmp_path)
    got = json.loads(pslog_ok("sync", corners, "-o", tmp_path / "c_synced.mcap", "--estimate",
                              "offset", "--json"))
    want = json.loads(pslog_ok("sync", without, "-o", tmp_path / "w_synced.mcap",
                               "--estimate", "offset", "--json"))
    assert got["cameras"] == want["cameras"]
    said = pslog_ok("fuse", corners, "--method", "smooth", "--gating", "off", "-o",
                    tmp_path / "c_fused.mcap")
    assert said.startswith("smooth"), said


# ---- calibrate: a lens model that folds over inside the image is said ------------------------

def test_calibrate_says_a_lens_model_folding_over_inside_the_image(tmp_path):
    """walk42: cam1's chessboard calibration (the board near the image's centre) gave k3
    -0.46, whose model folds over in the image's corners: detections there have no ray, and
    nothing said so. `pslog calibrate` now names the share of the image without a ray; a
    lens that does not fold (k1 -0.18 alone) gets no such note. And "1 points lie outside"
    is "1 point lies outside"."""
    rig = tmp_path / "lab.toml"
    rig.write_text(
        'name = "lab"\n'
        '[[camera]]\nname = "cam1"\nwidth = 640\nheight = 480\n'
        'K = [[520.86, 0.0, 318.49], [0.0, 521.29, 242.64], [0.0, 0.0, 1.0]]\n'
        'dist = [-0.18281, 0.23814, 0.00038, 0.00099, -0.46121]\n'
        'R = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\nt = [0.0, 0.0, 0.0]\n'
        'fps = 30.0\noffset = 0.0\n')
    from pslog.rig import load_rig

    cam = load_rig(rig).cameras[0]
    # floor points 3 m before the camera (world = camera frame here), one beyond the image
    xs, ys = np.meshgrid(np.linspace(-0.9, 0.9, 5), np.linspace(-0.6, 0.6, 4))
    world = np.c_[xs.ravel(), ys.ravel(), 3.0 + 0.2 * xs.ravel()]
    world = np.r_[world, [[0.0, 2.0, 3.0]]]
    uv = cam.project(world)[0]
    points = tmp_path / "points.csv"
    points.write_text("x,y,z,u,v\n" + "".join(
        ",".join(map(repr, [*map(float, p), *map(float, q)])) + "\n"
        for p, q in zip(world, uv, strict=True)))
    said = pslog_ok("calibrate", "--points", points, "--fix-intrinsics", "--name", "cam1",
                    "--rig", rig)
    assert "note: the lens model folds over inside the image: 1.9% of it" in said, said
    assert "note: 1 point lies outside the 640x480 image" in said, said
    text = rig.read_text().replace("-0.46121", "0.0").replace("0.23814", "0.0")
    rig.write_text(text)
    said = pslog_ok("calibrate", "--points", points, "--fix-intrinsics", "--name", "cam1",
                    "--rig", rig, "--force")
    assert "folds over" not in said, said


# ---- info: a synced session's shutters off the rig's planned offsets -------------------------

def test_info_of_a_synced_session_does_not_call_its_clocks_off(tmp_path):
    """walk42: webcams whose rig planned no phases (offsets 0, as `pslog calibrate` writes
    them), synced: `pslog info synced.mcap` said "shutters off the rig's offsets (...): camera
    clocks off, or the rig's offsets not the cameras'", though its clock model corrects the
    clocks and the phases are measured on the corrected times. It now says the cameras fire
    there, not where the offsets plan, and how to set them; the unsynced session keeps its
    line and the `pslog sync` command. (Since session 48 `pslog sync` writes the phases it
    measures into the copy's rig: info of that copy has nothing to say of its shutters; the
    line is that of a copy synced with `--phases keep`.)"""
    sim, det, rig = tmp_path / "sim.mcap", tmp_path / "det.csv", tmp_path / "rig.toml"
    lab, synced = tmp_path / "lab.mcap", tmp_path / "synced.mcap"
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
             "--duration", "4", "--noise-px", "0.3", "--clock-offset", "cam2=3.4",
             "--seed", "70044", "-o", sim)
    pslog_ok("export", sim, "--detections", det)
    rig.write_text(pslog_ok("rig", "show", "paper3", "--timing", "sync"))  # offsets all 0
    pslog_ok("import", "--rig", rig, "--detections", det, "-o", lab)
    before = pslog_ok("info", lab)
    assert "camera clocks off, or the rig's offsets not the cameras'; 'pslog sync" in before
    pslog_ok("sync", lab, "-o", synced)
    written = pslog_ok("info", synced)
    assert "camera clocks off" not in written and "offsets plan" not in written, written
    kept = tmp_path / "kept.mcap"
    pslog_ok("sync", lab, "-o", kept, "--phases", "keep")
    after = pslog_ok("info", kept)
    assert "camera clocks off" not in after, after
    assert ("measured on the times the rig's clock model corrects: the cameras fire there, "
            "not where the rig's offsets plan") in after, after
    assert f"'pslog rig show {kept} > rig.toml', edit the offsets" in after, after
    # the synced rig carried into a new session (its clocks another session's): said so,
    # with the sync command
    carried, again = tmp_path / "synced.toml", tmp_path / "again.mcap"
    # (the copy kept at offsets 0: the new session's phases off them, as a restarted
    # webcam's are off any earlier session's)
    carried.write_text(pslog_ok("rig", "show", kept))
    pslog_ok("import", "--rig", carried, "--detections", det, "-o", again)
    said = pslog_ok("info", again)
    assert ("a model not estimated on this session (given with its rig, e.g. an earlier "
            "session's 'pslog sync'): the cameras' clocks may have moved since; 'pslog sync "
            f"{again} -o synced.mcap' estimates them on this one") in said, said
    # and `pslog fuse` of it says so too (it fused with the other session's clocks, unsaid)
    fused = pslog_ok("fuse", again, "--method", "smooth", "-o", tmp_path / "again_f.mcap")
    assert (f"note: {again}'s rig holds a clock model no 'pslog sync' estimated on it (cam2 "
            "offset +") in fused, fused
    assert f"'pslog sync {again} -o synced.mcap' estimates them on this one" in fused, fused
    for quiet in (synced, lab):  # synced on itself, or no clock model: nothing said
        said = pslog_ok("fuse", quiet, "--method", "smooth", "-o",
                        tmp_path / f"{quiet.stem}_f.mcap")
        assert "no 'pslog sync' estimated" not in said, said


# ---- sync: a readout estimated below zero is said ----------------------------------------------

def test_sync_says_a_readout_estimated_below_zero(tmp_path):
    """walk42: with the rig from `pslog calibrate` (centres 2-3 mm off) `pslog sync` put
    cam1's readout at -0.700 ± 0.247 ms, 2.8σ below 0 (no sensor reads bottom to top), its
    offsets 2.1-2.4σ off the truth, without a word. A readout estimated more than 2σ below 0
    is now said, with the likely cause. Here cam1's times are moved as a readout of -15 ms
    would move them (its stamps later the lower the row), the rest as simulated (paper3's
    readouts are known to ~3 ms: the ball spans a tenth of its images' height)."""
    import csv

    sim, det, moved = tmp_path / "sim.mcap", tmp_path / "det.csv", tmp_path / "moved.csv"
    pslog_ok("simulate", "--rig", "paper3", "--timing", "typeA", "--motion", "rally",
             "--duration", "6", "--noise-px", "0.3", "--seed", "70045", "-o", sim)
    pslog_ok("export", sim, "--detections", det)
    with det.open() as f:
        rows = list(csv.DictReader(f))
    for row in rows:
        if row["camera"] == "cam1" and row["v"]:
            row["time"] = f"{float(row['time']) + 0.015 * float(row['v']) / 480:.9f}"
    with moved.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    lab = tmp_path / "lab.mcap"
    pslog_ok("import", "--rig", "paper3", "--timing", "typeA", "--detections", moved, "-o", lab)
    said = pslog_ok("sync", lab, "-o", tmp_path / "synced.mcap", "--estimate",
                    "offset,readout", "--regularize", "off")  # (the moved stamps kept)
    assert "note: readout estimated below 0 (cam1 -" in said, said
    assert "which no camera reads" in said, said
    assert "held at 0, the nearest a camera reads, and the clocks fitted again" in said, said
    assert "readout = " not in pslog_ok("rig", "show", tmp_path / "synced.mcap").split(
        'name = "cam2"')[0]  # (cam1's table: no readout key, i.e. 0)
    plain = pslog_ok("sync", sim, "-o", tmp_path / "plain.mcap", "--estimate",
                     "offset,readout")
    assert "below 0" not in plain, plain


# ---- record: shutters off the rig's offsets name pslog sync ------------------------------------

def test_record_of_clips_off_the_rigs_offsets_names_sync(tmp_path):
    """walk42: three webcams' clips started 11.1 and 28.9 ms apart (`@OFFSET`) on a rig
    whose offsets are 0: `pslog record`'s note offered only to set the offsets and fuse
    with them (fusion runs on the logged times; only type A's gap rule reads them), not
    `pslog sync`, which took the walk's tracks from 10-15 mm to 1.4-3 mm. It names both."""
    clips = []
    for i in range(2):
        path = tmp_path / f"c{i}.avi"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30.0, (640, 480))
        for k in range(20):
            image = np.full((480, 640, 3), (40, 110, 45), np.uint8)
            cv2.circle(image, (150 + 12 * k, 240 - 3 * i), 8, (20, 110, 245), -1)
            writer.write(image)
        writer.release()
        clips.append(path)
    rig = tmp_path / "rig.toml"
    rig.write_text(pslog_ok("rig", "show", "paper2", "--timing", "sync"))
    out = tmp_path / "rec.mcap"
    done = pslog_ok_err("record", "--rig", rig, "--source", f"cam1={clips[0]}", "--source",
                        f"cam2={clips[1]}@0.0111", "-o", out)
    note = next(line for line in done.splitlines() if "measured shutter offsets" in line)
    assert "cam2 11.1 ms (rig 0.0 ms)" in note, note
    assert f"'pslog sync {out} -o synced.mcap' estimates them from the ball" in note, note
    assert f"'pslog fuse {out} --rig fixed.toml'" in note, note


def pslog_ok_err(*args) -> str:
    """The standard error of a pslog command that must succeed."""
    from _cli import pslog

    done = pslog(*args)
    assert done.returncode == 0, done.stderr
    return done.stderr
