"""`smooth` marks the detections its robust fit rejected (issue 10, session 30).

``bench_dirty.py --more --validity`` found, in ``lab3``'s rally-302 with the faults, a `smooth`
point attributed to camera ``lab2``'s detection that projects 3.3 px outside ``lab2``'s image:
the ball had just left that view, the gate kept the frame's only candidate (a spurious blob
126 px from the ball) and the Cauchy-robust fit gave it almost no weight, but the output row
said nothing. The row now carries ``rejected`` = 1 (its residual beyond χ²₂'s 1 - 1e-4
quantile of the fit's noise σ, :attr:`pslog.estimation.Fit.rejected`), which ``pslog eval``
counts and ``pslog view`` draws among the camera's rejected candidates; its point stays, the
trajectory's, as the filter's point at a detection its gate rejected is its prediction, and
``gap_s`` runs across it. Fails with the rule removed (run: no row flagged; the benchmark's
count of points outside their camera's image 1), with the bound halved or doubled, with
``gap_s`` over every fitted detection, without the viewer's rule (the blob drawn as lab2's
detection)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from _rally import dirty_rally, rally
from _rigs import lab3_rig
from _rrd import batch_column, capture_times, temporal_chunks
from numpy.testing import assert_array_equal

from pslog.fusion import FusionOptions, fuse
from pslog.log import SessionWriter, read_session
from pslog.records import NS, Observations
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate, simulate_labelled

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_dirty import DISTRACTOR, invalid_points


def _issue_session():
    """bench_dirty's lab3 rally-302 with its faults (spurious blobs in 5 % of frames, the
    static object seen by lab3, lab1 blind 2.2-2.7 s), 0.3 px, simulation seed 2."""
    rig = lab3_rig()
    motion, _ = dirty_rally(302)
    options = SimulationOptions(noise_px=0.3, seed=2, spurious_rate=0.05,
                                distractors=(("lab3", DISTRACTOR),),
                                blackouts=(("lab1", 2.2, 0.5),))
    detections, truth, ball = simulate_labelled(rig, motion, 8.0, options)
    return rig, detections, truth, ball


def test_fuse_marks_the_spurious_blob_the_fit_rejected(tmp_path, cli):
    rig, detections, truth, ball = _issue_session()
    session = tmp_path / "rally302.mcap"
    with SessionWriter(session, rig, timing="custom", source="test") as writer:
        writer.add_detections(detections)
        writer.add_truth(truth)
    code, _, err = cli("fuse", session, "--method", "smooth", "-o", tmp_path / "f.mcap")
    assert code == 0, err
    track = read_session(tmp_path / "f.mcap").tracks["smooth"]
    q = track.quality
    rejected = q["rejected"] == 1
    assert set(np.unique(q["rejected"])) == {0.0, 1.0}
    # the one row whose frame holds no ball candidate (the ball out of lab2's view, the blob
    # kept): rejected, 126 px off the trajectory's projection; every ball detection kept
    ball_frames = {(int(ball.frame_camera[f]), int(ball.frame_time_ns[f]))
                   for f in ball.cand_frame}
    no_ball = np.array([(int(c), int(t)) not in ball_frames
                        for c, t in zip(track.camera, track.time_ns, strict=True)])
    assert_array_equal(rejected, no_ball)
    (row,) = np.flatnonzero(rejected)
    assert track.camera[row] == 1 and q["residual_px"][row] > 100
    # the point is the trajectory's, good (the ball just outside lab2's image), not lab2's
    uv, in_front = rig.cameras[1].project(track.position_world[row:row + 1])
    assert in_front[0] and -10 < uv[0, 0] < 0
    assert np.linalg.norm(track.position_world[row] - truth.at(track.time_ns[row:row + 1])[0]) \
        < 0.02
    # so the point is no camera's that did not see it: none outside its camera's image
    assert invalid_points(track, rig) == (0, 0)
    # gap_s runs across the rejected detection (its neighbours hold the trajectory there)
    t = track.time_ns
    kept = np.flatnonzero(~rejected)
    before, after = kept[kept < row][-1], kept[kept > row][0]
    assert q["gap_s"][row] == (t[after] - t[before]) / NS
    # eval counts it
    code, out, err = cli("eval", tmp_path / "f.mcap")
    assert code == 0, err
    assert f"smooth    1 of {len(track)} points" in out
    code, out, err = cli("eval", tmp_path / "f.mcap", "--json")
    assert code == 0, err
    assert json.loads(out)[0]["rejected_detections"] == 1
    # and the viewer draws it among lab2's rejected candidates, not its detections
    code, _, err = cli("view", tmp_path / "f.mcap", "--method", "smooth", "--frames", "none",
                       "--start", "1.0", "--end", "1.2", "--save", tmp_path / "v.rrd")
    assert code == 0, err
    chunks = temporal_chunks(tmp_path / "v.rrd")
    image = "/world/cameras/lab2/image"
    frame = (detections.frame_camera == 1) & (detections.frame_time_ns == t[row])
    (f,) = np.flatnonzero(frame)
    blob = detections.cand_uv[detections.cand_frame == f]
    assert len(blob) == 1  # the frame's only candidate
    for kind, has_it in (("rejected", True), ("detections", False)):
        batches = chunks[f"{image}/{kind}"]
        at = capture_times(batches) == t[row]
        points = [p for p, here in zip(batch_column(batches, "Points2D:positions"), at,
                                       strict=True) if here]
        assert len(points) == 1 and len(points[0]) == int(has_it), (kind, points)


@pytest.mark.parametrize("shift_px", [1.5, 40.0])
def test_an_outlier_is_rejected_and_its_point_is_the_trajectorys(shift_px):
    """A clean rally on the paper's rig (180 detections, σ 0.28 px), ungated, with one
    detection moved 1.5 px (a residual of 6.9 σ) or 40 px (146 σ): that row alone is
    rejected, none of the clean session's (its largest residual 4.15 σ, below the 4.29 σ of
    χ²₂'s 1 - 1e-4 quantile), its point the trajectory's, ``gap_s`` across it; a grid has no
    flag (no detection). The bound halved or doubled fails it."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion, _ = rally(2.0, seed=8, speed=4.0)
    detections, truth = simulate(rig, motion, 2.0, SimulationOptions(noise_px=0.3, seed=8))
    obs = detections.best()
    k = len(obs) // 2
    uv = obs.uv.copy()
    uv[k] += (shift_px, 0.0)
    moved = Observations(obs.time_ns, obs.camera, uv, obs.frame_index)
    options = FusionOptions(gating=False)
    clean = fuse(obs, rig, "smooth", options)
    track = fuse(moved, rig, "smooth", options)
    assert len(track) == len(clean) == len(obs)
    assert_array_equal(np.flatnonzero(clean.quality["rejected"]), [])
    assert_array_equal(np.flatnonzero(track.quality["rejected"]), [k])
    assert track.quality["residual_px"][k] > shift_px
    # the trajectory there is the other detections': within a few mm of the truth
    err = np.linalg.norm(track.position_world - truth.at(track.time_ns), axis=1)
    assert err[k] < 0.005
    gap = track.quality["gap_s"]
    assert gap[k] == (obs.time_ns[k + 1] - obs.time_ns[k - 1]) / NS
    assert gap[k - 1] == gap[k + 1] == gap[k]
    assert_array_equal(np.delete(gap, [k - 1, k, k + 1]), np.delete(
        clean.quality["gap_s"], [k - 1, k, k + 1]))
    grid = fuse(moved, rig, "smooth", FusionOptions(gating=False, rate_hz=200.0))
    assert len(grid) > 300 and np.all(np.isnan(grid.quality["rejected"]))
    assert grid.quality["gap_s"].max() >= gap[k] - 1e-12


def test_the_viewer_draws_a_method_rejection_with_gating_off(tmp_path, cli):
    """Fused with ``--gating off`` (no gate's rejections stored), a detection smooth's fit
    rejected is drawn among its camera's rejected candidates all the same (it was drawn as a
    detection: only a gated track's method rejections were looked for)."""
    rig, detections, truth, _ = _issue_session()
    session = tmp_path / "s.mcap"
    with SessionWriter(session, rig, timing="custom", source="test") as writer:
        writer.add_detections(detections)
        writer.add_truth(truth)
    code, _, err = cli("fuse", session, "--method", "smooth", "--gating", "off", "-o",
                       tmp_path / "f.mcap")
    assert code == 0, err
    track = read_session(tmp_path / "f.mcap").tracks["smooth"]
    rows = np.flatnonzero(track.quality["rejected"] == 1)
    assert len(rows) >= 1
    row = rows[0]
    t0 = track.time_ns[row] / NS
    start, end = f"{max(t0 - 0.05, 0.0):.6f}", f"{t0 + 0.05:.6f}"
    code, _, err = cli("view", tmp_path / "f.mcap", "--method", "smooth", "--frames", "none",
                       "--start", start, "--end", end, "--save", tmp_path / "v.rrd")
    assert code == 0, err
    chunks = temporal_chunks(tmp_path / "v.rrd")
    cam = int(track.camera[row])
    image = f"/world/cameras/{rig.cameras[cam].name}/image"
    # every candidate of that frame drawn as rejected (the best-scored one, which the fit
    # rejected, too), none as the camera's detection
    (f,) = np.flatnonzero((detections.frame_camera == cam)
                          & (detections.frame_time_ns == track.time_ns[row]))
    n_cand = int(np.count_nonzero(detections.cand_frame == f))
    for kind, drawn in (("rejected", n_cand), ("detections", 0)):
        batches = chunks[f"{image}/{kind}"]
        at = capture_times(batches) == track.time_ns[row]
        points = [p for p, here in zip(batch_column(batches, "Points2D:positions"), at,
                                       strict=True) if here]
        assert len(points) == 1 and len(points[0]) == drawn, (kind, points)
