"""Image-space overlays on each camera's image: detections, epipolar lines, and the
paper's Figure 2 construction behind each type-A point (plus its 3D counterpart, eqs. 2-4).

Pixels are drawn where they are on the recorded (distorted) image: undistorted geometry
(epipolar lines, the interpolated and snapped points) is re-distorted first.
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from pslog import palette
from pslog.geometry import epipolar_lines, fundamental_matrices
from pslog.motion import BALL_RADIUS

from . import _columns as C
from .data import ViewData, rejected_candidates


def log_detections(rec, data: ViewData, clock: C.Clock) -> tuple[int, int]:
    """Log each camera's candidates, frame by frame: the chosen ones (``detections``) and
    the rejected ones, grey (the gating's and the shown track's method's own). Returns how
    many of each were drawn (the candidates, as ``pslog info`` and ``pslog eval`` count
    them; not the frames)."""
    det = data.session.detections
    if det.n_frames == 0:
        return 0, 0
    counts = det.candidates_per_frame()
    is_best = det.best_mask()
    rejected_mask = gated_rejections(data)
    if rejected_mask is not None:  # the gating's choice, as stored with the shown track
        is_best = ~rejected_mask
    # and the chosen detections the shown track's method rejected itself (filter's gate,
    # smooth's fit: ``rejected`` = 1): drawn as rejected too, with gating on or off
    is_best &= ~method_rejections(data, is_best)
    frame_in = data.in_window(det.frame_time_ns)
    n_kept = n_rejected = 0
    for c, name in enumerate(det.camera_names):
        frames = np.flatnonzero(frame_in & (det.frame_camera == c))
        if len(frames) == 0:
            continue
        keep = frame_in[det.cand_frame] & (det.frame_camera[det.cand_frame] == c)
        t, f = det.frame_time_ns[frames], det.frame_index[frames]
        best = keep & is_best
        kept = np.bincount(det.cand_frame[best], minlength=det.n_frames)[frames]
        # every frame gets a row, an empty one when nothing was detected (clears the point)
        C.send(rec, f"{C.image_path(name)}/detections", clock, t, f,
               rr.Points2D.columns(positions=C.image_space(det.cand_uv[best]))
               .partition(kept))
        rejected = keep & ~is_best
        C.send(rec, f"{C.image_path(name)}/rejected", clock, t, f,
               rr.Points2D.columns(positions=C.image_space(det.cand_uv[rejected]))
               .partition(counts[frames] - kept))
        n_kept += int(np.count_nonzero(best))
        n_rejected += int(np.count_nonzero(rejected))
    return n_kept, n_rejected


def gated_rejections(data: ViewData):
    """(C,) bool over the session's candidates: rejected by the gating of the first shown
    track stored with its rejections (``pslog fuse``); None when none is."""
    if not data.rejections:
        return None
    return rejected_candidates(data.session.detections, next(iter(data.rejections.values())))


def overlay_track(data: ViewData) -> str | None:
    """The shown track whose gating and own rejections the images draw (grey points): the
    first stored with its rejections, else the first shown; None when none is shown."""
    return next(iter(data.rejections or data.tracks), None)


def flagged_rejected(data: ViewData) -> dict[str, int]:
    """Shown track -> how many of its points in the window are flagged ``rejected`` (its
    method rejected the detection: the filter's gate, smooth's fit; ``pslog eval``'s
    'detections the method rejected'); tracks with none left out."""
    out = {}
    for name, track in data.tracks.items():
        flag = track.quality.get("rejected")
        if flag is not None:
            n = int(np.count_nonzero((flag == 1) & data.in_window(track.time_ns)))
            if n:
                out[name] = n
    return out


def method_rejections(data: ViewData, chosen: np.ndarray) -> np.ndarray:
    """(C,) bool over the session's candidates: of the ``chosen`` ones, those whose point in
    the shown track (the first stored with its rejections, else the first shown) is flagged
    ``rejected`` (the method rejected the detection: the filter's gate, smooth's fit); its
    rows matched to the frames by camera and (corrected) capture time through
    ``data.observations``."""
    det = data.session.detections
    out = np.zeros(det.n_candidates, dtype=bool)
    name = overlay_track(data)
    track = None if name is None else data.tracks.get(name)
    flag = None if track is None else track.quality.get("rejected")
    if flag is None or not np.any(flag == 1):
        return out
    obs = data.observations
    rows = set(zip(track.camera[flag == 1].tolist(), track.time_ns[flag == 1].tolist(),
                   strict=True))
    near = np.flatnonzero(np.isin(obs.time_ns, track.time_ns[flag == 1]))  # (a few rows)
    n_cams = max(len(det.camera_names), 1)
    keys = [f * n_cams + c for c, t, f in zip(obs.camera[near].tolist(),
                                              obs.time_ns[near].tolist(),
                                              obs.frame_index[near].tolist(), strict=True)
            if (c, t) in rows]
    cand = det.cand_frame
    hit = np.isin(det.frame_index[cand].astype(np.int64) * n_cams + det.frame_camera[cand],
                  np.asarray(keys, dtype=np.int64))
    return hit & chosen


def log_epipolar(rec, data: ViewData, clock: C.Clock, uv_undistorted: np.ndarray) -> int:
    rig, obs = data.session.rig, data.observations
    F = fundamental_matrices(rig.cameras)
    inside = data.in_window(obs.time_ns)
    n = 0
    for d, src in enumerate(rig.cameras):
        rows = np.flatnonzero(inside & (obs.camera == d))
        if len(rows) == 0:
            continue
        for c, cam in enumerate(rig.cameras):
            if c == d:
                continue
            lines = epipolar_lines(F[d, c], uv_undistorted[rows])
            strips, visible = C.line_polylines(cam, lines)
            n += C.send(rec, f"{C.image_path(cam.name)}/epipolar/{src.name}", clock,
                        obs.time_ns[rows], obs.frame_index[rows],
                        rr.LineStrips2D.columns(strips=strips).partition(visible.astype(np.int64)))
    return n


def hide_construction_labels(rec, camera_names) -> None:
    """The construction's labels (P(t-1), P(t-2), P^(t)) are stored but not drawn: the
    points lie within a few millimetres (pixels) of each other and of the ball, so their
    label boxes would overlap it and each other; they show on hover and in the selection."""
    for path in ["world/typeA/past", "world/typeA/predicted",
                 *(f"{C.image_path(c)}/typeA/interpolated" for c in camera_names)]:
        archetype = rr.Points3D if path.startswith("world/typeA") else rr.Points2D
        rec.log(path, archetype.from_fields(show_labels=False), static=True)


def log_construction(rec, data: ViewData, clock: C.Clock, uv_undistorted: np.ndarray) -> int:
    """The paper's Figure 2 on the partner images and eqs. 2-4 in 3D, per type-A point."""
    con, rig, obs = data.construction, data.session.rig, data.observations
    if con is None or len(con.event_row) == 0:
        return 0
    if data.construction_observations is not None and data.construction_observations is not obs:
        # its rows index the observations type A fused (gated), not the best candidates
        obs = data.construction_observations
        uv_undistorted = np.empty_like(obs.uv)
        for c, cam in enumerate(rig.cameras):
            rows = obs.camera == c
            uv_undistorted[rows] = cam.undistort(obs.uv[rows])
    events = np.flatnonzero(data.in_window(obs.time_ns[con.event_row]))
    if len(events) == 0:
        return 0
    event_row = con.event_row[events]
    t, f = obs.time_ns[event_row], obs.frame_index[event_row]
    past = [{k: getattr(p, k)[events] for k in ("row", "partner", "prev_row", "next_row",
                                                  "uv_interpolated", "uv_snapped",
                                                  "points_world")} for p in con.past]
    stack = {k: np.stack([past[0][k], past[1][k]], axis=1) for k in past[0]}  # (k, 2, ...)
    F = fundamental_matrices(rig.cameras)
    hide_construction_labels(rec, rig.names)
    labels = np.array(["P(t-1)", "P(t-2)"])
    # their own colours (pslog.palette), used by no method and no camera: the interpolation
    # side (eq. 1, eq. 2) in cyan, the snap / correction side (step 2, eq. 4) in yellow
    interp_color, snap_color = palette.CONSTRUCTION_COLOR, palette.SNAP_COLOR
    for c, cam in enumerate(rig.cameras):
        mine = stack["partner"] == c  # (k, 2): constructions drawn on this camera's image
        lengths = C.lengths_of(mine)
        which = np.nonzero(mine)[1]  # 0: P(t-1), 1: P(t-2)
        interp = cam.distort(stack["uv_interpolated"][mine])
        snapped = cam.distort(stack["uv_snapped"][mine])
        prev_uv, next_uv = obs.uv[stack["prev_row"][mine]], obs.uv[stack["next_row"][mine]]
        base = f"{C.image_path(cam.name)}/typeA"
        # labels kept for the selection panel, drawn only on hover/selection: several
        # labels at nearly the same pixel would overlap in one box
        C.send(rec, f"{base}/interpolated", clock, t, f, rr.Points2D.columns(
            positions=C.image_space(interp), labels=labels[which],
            colors=[interp_color] * len(which),
            radii=np.full(len(which), -4.0)).partition(lengths))
        C.send(rec, f"{base}/snapped", clock, t, f, rr.Points2D.columns(
            positions=C.image_space(snapped), colors=[snap_color] * len(which),
            radii=np.full(len(which), -4.0)).partition(lengths))
        bracket = np.stack([prev_uv, interp, next_uv], axis=1).reshape(-1, 2)
        C.send(rec, f"{base}/bracket", clock, t, f, rr.LineStrips2D.columns(
            strips=C.image_space(bracket).reshape(-1, 3, 2), colors=[interp_color] * len(which),
            radii=np.full(len(which), -1.0)).partition(lengths))
        snap = np.stack([interp, snapped], axis=1).reshape(-1, 2)
        C.send(rec, f"{base}/snap", clock, t, f, rr.LineStrips2D.columns(
            strips=C.image_space(snap).reshape(-1, 2, 2), colors=[snap_color] * len(which),
            radii=np.full(len(which), -1.5)).partition(lengths))
        # the epipolar line of the observed point, which the interpolated point snaps to
        observed = stack["row"][mine]
        lines = epipolar_lines(F[obs.camera[observed], c], uv_undistorted[observed])
        strips, visible = C.line_polylines(cam, lines)
        shown = np.zeros(mine.shape, dtype=bool)
        shown[mine] = visible
        C.send(rec, f"{base}/epipolar", clock, t, f, rr.LineStrips2D.columns(
            strips=strips, colors=[snap_color] * int(visible.sum()),
            radii=np.full(int(visible.sum()), -1.0)).partition(C.lengths_of(shown)))

    # 3D: the two pseudo-stereo points, the linear prediction (eq. 2) and eq. 4's correction
    p_world = stack["points_world"]  # (k, 2, 3): P(t-1), P(t-2)
    predicted = con.predicted_world[events]
    final = con.points_world[events]
    C.send(rec, "world/typeA/past", clock, t, f, rr.Points3D.columns(
        positions=p_world.reshape(-1, 3), labels=np.tile(labels, len(events)),
        colors=[interp_color] * (2 * len(events)),
        radii=np.full(2 * len(events), 0.4 * BALL_RADIUS)).partition(np.full(len(events), 2)))
    C.send(rec, "world/typeA/predicted", clock, t, f, rr.Points3D.columns(
        positions=predicted, labels=["P^(t)"] * len(events), colors=[interp_color] * len(events),
        radii=np.full(len(events), 0.4 * BALL_RADIUS)))
    extrapolation = np.stack([p_world[:, 1], p_world[:, 0], predicted], axis=1)
    correction = np.stack([predicted, final], axis=1)
    C.send(rec, "world/typeA/prediction", clock, t, f, rr.LineStrips3D.columns(
        strips=extrapolation, colors=[interp_color] * len(events),
        radii=np.full(len(events), -1.0)))
    C.send(rec, "world/typeA/correction", clock, t, f, rr.LineStrips3D.columns(
        strips=correction, colors=[snap_color] * len(events), radii=np.full(len(events), -1.5)))
    return len(events)
