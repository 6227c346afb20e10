"""Live-mode test helpers: a simulated session's frames as detection datagrams."""

from __future__ import annotations

import socket

import numpy as np

from pslog.live.protocol import DetectionDatagram, detection_datagrams, encode_detections
from pslog.motion import get_motion
from pslog.records import Detections
from pslog.rig import apply_timing, builtin_rig
from pslog.simulation import SimulationOptions, simulate

#: A wall-clock epoch for the session clock's zero (ns).
EPOCH = 1_764_470_000_000_000_000


def rally_session(duration: float = 1.5, rig=None, **options) -> tuple:
    """(rig, detections) of the rally seen by the paper's type-A rig: noise, false
    candidates, misses (every candidate case the gates handle)."""
    rig = rig or apply_timing(builtin_rig("paper3"), "typeA")
    opts = dict(noise_px=0.5, seed=3, spurious_rate=0.2, miss_rate=0.05)
    opts.update(options)
    det, _ = simulate(rig, get_motion("rally"), duration, SimulationOptions(**opts))
    return rig, det


def frames(det: Detections, rig, epoch: int = EPOCH) -> list[DetectionDatagram]:
    """Every frame as a DetectionDatagram (sequence per camera from 1; wall clock =
    ``epoch`` + session time, sent 1 ms later), in (time, camera) order."""
    return detection_datagrams(det, epoch, 1_000_000)


def datagrams(det: Detections, rig, epoch: int = EPOCH) -> list[bytes]:
    return [encode_detections(d) for d in frames(det, rig, epoch)]


def subset(det: Detections, keep: np.ndarray) -> Detections:
    """The frames ``keep`` (bool, per frame) of ``det``."""
    rows = np.flatnonzero(keep)
    new_row = np.full(det.n_frames, -1)
    new_row[rows] = np.arange(len(rows))
    cand = keep[det.cand_frame]
    return Detections(det.camera_names, det.frame_time_ns[rows], det.frame_camera[rows],
                      det.frame_index[rows], new_row[det.cand_frame[cand]], det.cand_uv[cand],
                      det.cand_radius[cand], det.cand_score[cand])


def free_port() -> int:
    """A TCP port of 127.0.0.1 free now (the system's pick)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]
