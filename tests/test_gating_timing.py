"""The gate under rolling shutters: a frame's candidates are at different rows, so at
different true times (readout · Δv / height apart); the track gate judges each at its own."""

from __future__ import annotations

import numpy as np
from _rally import rally

from pslog.fusion.gating import gate
from pslog.records import Detections
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate_labelled, true_rig

TOP_ROW = 3.0


def with_top_row_blobs(det: Detections, v_min: float = 380.0) -> Detections:
    """``det`` with, before the ball of every frame low in its image (row > ``v_min``), a
    false candidate on the image's top row, listed first (best first): ~28 ms earlier than
    the ball with a 30 ms readout."""
    uv, frame = [], []
    for f in range(det.n_frames):
        rows = np.flatnonzero(det.cand_frame == f)
        if len(rows) and det.cand_uv[rows[0], 1] > v_min:
            uv.append([det.cand_uv[rows[0], 0], TOP_ROW])
            frame.append(f)
        uv.extend(det.cand_uv[rows].tolist())
        frame.extend([f] * len(rows))
    return Detections(det.camera_names, det.frame_time_ns, det.frame_camera, det.frame_index,
                      np.array(frame), np.array(uv), np.full(len(frame), 3.0),
                      np.ones(len(frame)))


def test_track_gate_predicts_each_candidate_at_its_own_rolling_shutter_time():
    """Two cameras (no candidate is ever confirmed by two others: every ball candidate meets
    the track gate), 30 ms rolling shutters, a fast rally. A false blob on the top row of a
    frame is judged first; the ball, low in the same frame, is 25-30 ms later, when a fast
    ball is 20-30 cm further on. Judged at the blob's time (one prediction per frame), the
    ball is rejected as off the track in several frames; at its own time it is kept as in
    the session without the blobs."""
    rig = apply_timing(builtin_rig("paper2"), "typeA")
    options = SimulationOptions(noise_px=0.3, seed=1, readout_s=dict.fromkeys(rig.names, 0.03))
    det, _, _ = simulate_labelled(rig, rally(6.0, seed=1, speed=9.0, kick_every_s=0.8)[0], 6.0,
                                  options)
    rig = true_rig(rig, options)
    dirty = with_top_row_blobs(det)
    blob = dirty.cand_uv[:, 1] == TOP_ROW
    assert blob.sum() >= 5
    clean = gate(det, rig)
    gated = gate(dirty, rig)
    ball_rejected = np.count_nonzero(~gated.chosen & ~blob)
    assert ball_rejected <= np.count_nonzero(~clean.chosen), (
        ball_rejected, np.count_nonzero(~clean.chosen))
    assert not np.any(gated.chosen & blob)
