"""What the rerun recording of a session holds, logged column by column.

Entity paths mirror the transform tree (world z up, metres):

==========================================  =============================================
``world``                                   ViewCoordinates RIGHT_HAND_Z_UP (static)
``world/cameras/<cam>``                     Transform3D camera -> world (static)
``world/cameras/<cam>/image``               Pinhole (static), EncodedImage per frame
``.../image/detections``, ``/rejected``     the chosen and the other candidates (rejected
                                            by the gate, or by the first shown track's
                                            method: ``rejected`` = 1), Points2D per frame
``.../image/epipolar/<other>``              epipolar line of ``<other>``'s latest detection
``.../image/typeA/...``                     Figure 2: bracket, interpolated, snap, snapped,
                                            epipolar line of the observed point
``world/rays/<cam>``                        each detection's viewing ray, LineStrips3D
``world/tracks/<method>`` (``/trail``)      fused points and trail segments
``world/tracks/<method>/uncertainty``       a translucent sphere of radius 2 std_m per point
``world/truth`` (``/trail``)                ground truth, when the session has it
``world/typeA/...``                         P_{t-1}, P_{t-2}, prediction (eq. 2), eq. 4
``plots/error_mm/<method>``                 distance to truth, mm
``plots/<quality>/<method>``                snap_px, ray_miss_mm, ray_shift_mm, std_mm;
                                            residual_px (smooth)
``plots/detection_rate/<cam>``              % of frames the ball was detected in (a
                                            candidate off every static spot), last 0.5 s
``events``, ``legend``                      session notes (TextLog), colour legend
``timing``                                  each camera's clock model (TextDocument)
``summary``                                 clocks and each method's accuracy (panels.py)
``crops/<cam>`` (``/detection``)            the ball large: a crop around the detection
==========================================  =============================================

Timelines: ``capture_time`` (the session clock, integer ns) and ``frame`` (frame index).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import rerun as rr

from pslog import palette
from pslog.errors import PslogError, shell_word
from pslog.log import iter_images
from pslog.motion import BALL_RADIUS
from pslog.outputs import check_output_path
from pslog.records import NS, Track

from . import _columns as C
from ._columns import camera_path, image_path
from .blueprint import build_blueprint, default_eye, quality_plots
from .data import UNBOUNDED_NS, DetailChoice, FramesChoice, ViewData, load_view_data
from .overlays import (
    flagged_rejected,
    log_construction,
    log_detections,
    log_epipolar,
    overlay_track,
)
from .panels import CropLogger, log_summary
from .rrd_file import rrd_file

APPLICATION_ID = "pslog"
_MEDIA_TYPES = {"jpeg": "image/jpeg", "jpg": "image/jpeg", "png": "image/png"}
_IMAGE_BATCH_BYTES = 32 << 20  # send images in batches of about this many bytes
_RAY_FALLBACK_M = 5.0  # rays that do not reach the floor are drawn this long
_TRAIL_GAP_S = 0.1  # no trail segment across a gap longer than this
_RATE_WINDOW_S = 0.5  # detection rate over the last half second


def build_recording(session_paths: str | Path | Sequence[str | Path], *,
                    methods: str | Sequence[str] | None = None, frames: str = "all",
                    start: float | None = None, end: float | None = None,
                    detail: str | DetailChoice = DetailChoice.DEFAULT,
                    recording: rr.RecordingStream | None = None) -> rr.RecordingStream:
    """A rerun recording of a session, its fused tracks and the type-A construction.

    Parameters
    ----------
    session_paths : the session MCAP, then optionally fused copies (see
        :func:`viewers.data.load_view_data`)
    methods : tracks to show (None: every stored track, else ``typeA`` fused on the fly)
    frames : ``all``, ``none`` or ``every:N`` — which recorded images to include
    start, end : seconds from the session's first frame
    detail : where every frame's overlays and plot points are kept (:class:`DetailChoice`:
        ``all``, ``S`` the first S seconds shown, ``A:B``); default the first 600 s, then
        one frame in 10
    recording : a stream to log into (with its sink already set, so data streams out);
        None: a new stream that buffers in memory until a sink is set (``rec.save(path)``,
        ``rec.spawn()``, ...)

    Returns
    -------
    The RecordingStream, with the default blueprint sent.
    """
    choice = FramesChoice.parse(frames)
    data = load_view_data(session_paths, methods=methods, start=start, end=end, detail=detail)
    rec = recording if recording is not None else new_stream()
    log_view(rec, data, choice)
    return rec


def save_rrd(session_paths: str | Path | Sequence[str | Path], path: str | Path, *,
             force: bool = False, **options) -> dict[str, int]:
    """Write the recording of :func:`build_recording` (same ``options``) to the .rrd ``path``.

    Refuses an existing ``path`` unless ``force`` (OutputExistsError) and, ``force`` or not,
    a ``path`` that is one of the sessions (InputError). An old ``path`` is replaced only by a
    complete new file; a failed write raises :class:`viewers.rrd_file.RrdWriteError` naming
    the path and the reason. Returns the row counts per kind (``detections``, ``images``,
    ``track_points``, ...).
    """
    paths = [session_paths] if isinstance(session_paths, str | Path) else list(session_paths)
    check_output_path(path, force, inputs=paths)
    choice = FramesChoice.parse(options.pop("frames", "all"))
    options.setdefault("detail", DetailChoice.DEFAULT)
    data = load_view_data(paths, **options)
    rec = new_stream()
    # streamed to the file while logging: images never pile up in memory
    with rrd_file(rec, path, force=force, inputs=paths):
        counts = log_view(rec, data, choice)
    return counts


def new_stream() -> rr.RecordingStream:
    """A fresh, non-global recording stream (a new recording id each time)."""
    return rr.RecordingStream(APPLICATION_ID)


def log_view(rec: rr.RecordingStream, data: ViewData, frames: FramesChoice) -> dict[str, int]:
    """Log everything of ``data`` into ``rec`` and send the default blueprint.

    Returns row counts per kind, for reports.
    """
    session = data.session
    rig = session.rig
    obs = data.observations
    first = int(obs.time_ns.min()) if len(obs) else (
        int(session.detections.frame_time_ns.min()) if session.detections.n_frames else 0)
    clock = C.Clock(first)
    counts: dict[str, int] = {}
    colors = C.method_colors(list(data.tracks))
    quality = quality_plots(data.tracks)
    # the eye frames what is shown: the truth (else the tracks) inside the time window
    scene = (session.truth.position_world[data.in_window(session.truth.time_ns)]
             if session.truth is not None and len(session.truth)
             else np.concatenate([t.position_world[data.in_window(t.time_ns)]
                                  for t in data.tracks.values()] or [np.zeros((0, 3))]))
    rec.send_blueprint(build_blueprint(
        rig.names, list(data.tracks), quality=quality,
        has_truth=session.truth is not None and len(session.truth) > 0,
        eye=default_eye(np.array([c.center_world for c in rig.cameras]), scene)))
    rec.send_recording_name(session.path.stem)
    _log_static(rec, data, colors, quality)

    uv_undistorted = np.empty_like(obs.uv)
    for c, cam in enumerate(rig.cameras):
        rows = obs.camera == c
        uv_undistorted[rows] = cam.undistort(obs.uv[rows])
    # per-frame overlays beyond the detail range: one frame in data.every (DetailChoice)
    thin = data.thinned()
    counts["detections"], counts["rejected_candidates"] = log_detections(rec, data, clock)
    counts["rays"] = _log_rays(rec, thin, clock)
    counts["epipolar_lines"] = log_epipolar(rec, thin, clock, uv_undistorted)
    counts["track_points"] = _log_tracks(rec, data, clock, colors)
    counts["truth_points"] = _log_truth(rec, data, clock)
    counts["typeA_constructions"] = log_construction(rec, thin, clock, uv_undistorted)
    counts["plot_points"] = _log_plots(rec, data, clock, quality)
    counts["events"] = _log_events(rec, data, clock)
    counts["images"] = _log_images(rec, data, clock, frames)
    return counts


# ---- static --------------------------------------------------------------------------------
def log_rig(rec, rig, *, rejected: bool = True) -> None:
    """The rig's static entities, shared by the recorded and the live view: the world's
    axes, each camera's pose and pinhole, and the styles of its detections (and rejected
    candidates) and rays."""
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for c, cam in enumerate(rig.cameras):
        world_from_cam = cam.world_from_cam
        rec.log(camera_path(cam.name), rr.Transform3D(
            translation=world_from_cam[:3, 3], mat3x3=world_from_cam[:3, :3]), static=True)
        K = cam.K.copy()
        K[:2, 2] += C.PIXEL_CENTER
        # rerun's Pinhole camera frame RDF (x right, y down, z forward) is OpenCV's convention
        rec.log(image_path(cam.name), rr.Pinhole(
            image_from_camera=K, resolution=[cam.width, cam.height],
            camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.3,
            color=C.camera_color(c)), static=True)
        rec.log(f"{image_path(cam.name)}/detections", rr.Points2D.from_fields(
            colors=[C.camera_color(c)], radii=[-4.0]), static=True)
        if rejected:
            rec.log(f"{image_path(cam.name)}/rejected", rr.Points2D.from_fields(
                colors=[C.REJECTED_COLOR], radii=[-3.0]), static=True)
        rec.log(f"world/rays/{cam.name}", rr.LineStrips3D.from_fields(
            colors=[C.camera_color(c)], radii=[-0.75]), static=True)


def _log_static(rec, data: ViewData, colors, quality) -> None:
    rig = data.session.rig
    log_rig(rec, rig)
    for c, cam in enumerate(rig.cameras):
        for d, other in enumerate(rig.cameras):
            if d != c:
                rec.log(f"{image_path(cam.name)}/epipolar/{other.name}",
                        rr.LineStrips2D.from_fields(colors=[C.camera_color(d)], radii=[-1.0]),
                        static=True)
    ball = BALL_RADIUS
    for method, color in colors.items():
        rec.log(f"world/tracks/{method}", rr.Points3D.from_fields(
            colors=[color], radii=[0.5 * ball]), static=True)  # gaps show the truth
        rec.log(f"world/tracks/{method}/trail", rr.LineStrips3D.from_fields(
            colors=[color], radii=[-2.5]), static=True)
        # each point's uncertainty: a translucent sphere of radius 2 std_m (issue 10)
        rec.log(f"world/tracks/{method}/uncertainty", rr.Points3D.from_fields(
            colors=[(*color, 48)]), static=True)
        rec.log(f"plots/error_mm/{method}", rr.SeriesLines(colors=[color], names=[method]),
                static=True)
        for plot in quality:
            rec.log(f"plots/{plot}/{method}", rr.SeriesLines(colors=[color], names=[method]),
                    static=True)
    rec.log("world/truth", rr.Points3D.from_fields(colors=[C.TRUTH_COLOR], radii=[0.35 * ball]),
            static=True)
    rec.log("world/truth/trail", rr.LineStrips3D.from_fields(colors=[C.TRUTH_COLOR],
                                                             radii=[-2.0]), static=True)
    for c, name in enumerate(rig.names):
        rec.log(f"plots/detection_rate/{name}",
                rr.SeriesLines(colors=[C.camera_color(c)], names=[name]), static=True)
    rec.log("legend", rr.TextDocument(_legend(data, colors), media_type="text/markdown"),
            static=True)
    timing = timing_text(data.session)
    rec.log("timing", rr.TextDocument(timing, media_type="text/markdown"), static=True)
    # the summary panel: accuracy, colours, clocks
    log_summary(rec, data, timing, _legend(data, colors))


def timing_text(session) -> str:
    """Markdown: each camera's clock model as the session's rig holds it (the times every
    track was fused on: ``pslog sync`` writes its estimates there) — frame rate, shutter
    offset, clock offset, drift, readout — and, for a simulated session with clock faults,
    the true values beside them. The standard deviations ``pslog sync`` stored with its
    estimates (metadata ``clock_std``) show as ``± σ`` beside the values they belong to."""
    from pslog.simulation import read_truth_clock
    from pslog.timing import read_clock_std

    rig = session.rig
    stds = read_clock_std(rig, session.metadata) or [{} for _ in rig.cameras]

    def cell(value, std, fmt):  # "value" or "value ± σ" (σ 0: a parameter not estimated)
        return fmt.format(value) + (" ± " + fmt.format(std) if std else "")
    try:
        truth = read_truth_clock(rig, session.metadata)
    except PslogError:
        truth = None
    head = "| camera | fps | shutter ms | clock offset ms | drift ppm | readout ms |"
    rule = "|---|---:|---:|---:|---:|---:|"
    if truth is not None:
        head += " true offset ms | true drift ppm | true readout ms |"
        rule += "---:|---:|---:|"
    lines = ["**Camera clocks** (true time = logged + offset + drift · 1e-6 · logged "
             "+ readout · row / height)", "", head, rule]
    for i, cam in enumerate(rig.cameras):
        std = stds[i]
        row = (f"| {cam.name} | {cam.fps:g} | {cam.offset * 1e3:.3f} | "
               f"{cell(cam.clock_offset * 1e3, std.get('clock_offset', 0) * 1e3, '{:.4f}')} | "
               f"{cell(cam.clock_drift_ppm, std.get('clock_drift_ppm', 0), '{:.3f}')} | "
               f"{cell(cam.readout * 1e3, std.get('readout', 0) * 1e3, '{:.3f}')} |")
        if truth is not None:
            t = truth.cameras[i]
            row += (f" {t.clock_offset * 1e3:.4f} | {t.clock_drift_ppm:.3f} | "
                    f"{t.readout * 1e3:.3f} |")
        lines.append(row)
    if not any(c.has_clock_correction for c in rig.cameras):
        lines += ["", "No clock correction in the rig: the logged times are used as they are "
                      "(cameras genlocked, or not yet synced: `pslog sync`)."]
    return "\n".join(lines)


def _legend(data: ViewData, colors) -> str:
    name = palette.color_name
    tracks = [f"{m} {name(c)}" for m, c in colors.items()]
    if data.session.truth is not None:
        tracks.append(f"truth {name(C.TRUTH_COLOR)}")
    if any("std_m" in t.quality for t in data.tracks.values()):
        tracks.append("the dim sphere around a point: 2 σ of its position")
    cameras = [f"{n} {name(C.camera_color(c))}" for c, n in enumerate(data.session.rig.names)]
    lines = [f"**Tracks**: {', '.join(tracks)}", "",
             f"**Cameras** (rays, detections, epipolar lines, detection rate): "
             f"{', '.join(cameras)}; {name(C.REJECTED_COLOR)}: rejected candidates"]
    spots = [f"{n} at ({s['u']:.0f}, {s['v']:.0f}) px"
             for n, cam_spots in zip(data.session.rig.names, data.ball_frames[0], strict=True)
             for s in cam_spots]
    lines += ["", f"**Detection rate**: the share of each camera's frames (last "
              f"{_RATE_WINDOW_S:g} s) with a candidate that moves: the ball's" + (
                  f"; a candidate that does not move, left out: {', '.join(spots)} (a static "
                  "object, or the ball at rest)" if spots else "")]
    for method, rej in list(data.rejections.items())[:1]:
        reasons = ", ".join(f"{k} {v}" for k, v in rej.counts().items() if v) or "none"
        lines += ["", f"**Gating** ({method}): {len(rej)} candidates rejected (grey points "
                  f"in the images; {reasons})"]
    # the detections a method rejected itself (its points kept, flagged rejected): the
    # images draw the overlay track's in grey too; another track's are named, not drawn
    flagged = flagged_rejected(data)
    if flagged:
        drawn = overlay_track(data)
        n = flagged.get(drawn, 0) if drawn is not None else 0
        text = (f"**Rejected by the method** (points kept, flagged rejected: the filter's "
                f"gate, smooth's fit): {drawn} {n}, grey in the images too" if n else
                f"**Rejected by the method** (points kept, flagged rejected: the filter's "
                f"gate, smooth's fit): {drawn} none")
        others = [f"{m} {k}" for m, k in flagged.items() if m != drawn]
        if others:
            files = " ".join(shell_word(p) for p in data.paths)
            text += (f"; not drawn: {', '.join(others)} (the images show {drawn}'s; "
                     f"`pslog view {files} --method "
                     f"{next(m for m in flagged if m != drawn)}` draws that track's)")
        lines += ["", text]
    if data.construction is not None:
        lines += ["", f"**Figure 2** (typeA, drawn on the partner camera's image): "
                  f"{name(palette.CONSTRUCTION_COLOR)}, the partner's two detections around "
                  "the instant and the interpolated point (eq. 1); "
                  f"{name(palette.SNAP_COLOR)}, the snap onto the epipolar line (step 2). "
                  f"In 3D: {name(palette.CONSTRUCTION_COLOR)}, P(t-1), P(t-2) and the "
                  f"prediction P^(t) (eq. 2); {name(palette.SNAP_COLOR)}, its move onto the "
                  "ray (eq. 4). Hover a point for its label."]
        # (a stored typeA track of --confirm-gaps breaks: its points made from the
        # detections after them, span_s < 0, have no Figure 2: pslog fuse and eval count them)
        span = data.tracks["typeA"].quality.get("span_s") if "typeA" in data.tracks else None
        n_backward = 0 if span is None else int(np.count_nonzero(span < 0))
        if n_backward:
            lines[-1] += (f" {n_backward} typeA point{'s' if n_backward > 1 else ''} made "
                          f"from the detections after {'them' if n_backward > 1 else 'it'} "
                          "(--confirm-gaps jumps, the default, or breaks: span_s < 0, as "
                          "pslog eval counts them) "
                          f"{'have' if n_backward > 1 else 'has'} none.")
    return "\n".join(lines)


# ---- 3D: rays, tracks, truth ---------------------------------------------------------------
def _frames_at(data: ViewData, time_ns: np.ndarray) -> np.ndarray:
    """Frame index of the latest detection at or before each time (for rows that are not a
    detection of their own, so that they also appear on the ``frame`` timeline)."""
    obs = data.observations
    if len(obs) == 0:
        return np.zeros(len(time_ns), dtype=np.int64)
    i = np.clip(np.searchsorted(obs.time_ns, time_ns, side="right") - 1, 0, len(obs) - 1)
    return obs.frame_index[i]


def _match_observations(data: ViewData, track: Track) -> np.ndarray:
    """(len(track),) observation row of each point's (time, camera), -1 when none."""
    obs = data.observations
    out = np.full(len(track), -1, dtype=np.int64)
    if len(obs) == 0:
        return out
    first = np.searchsorted(obs.time_ns, track.time_ns, side="left")
    for k in range(len(data.session.rig)):  # rows with equal times differ by camera
        i = np.minimum(first + k, len(obs) - 1)
        hit = (out < 0) & (obs.time_ns[i] == track.time_ns) & (obs.camera[i] == track.camera)
        out[hit] = i[hit]
    return out


def _log_rays(rec, data: ViewData, clock: C.Clock) -> int:
    """Each detection's ray from the camera centre to the fused point (the first shown
    track with a point at that detection, ``typeA`` preferred) or else to the floor."""
    rig, obs = data.session.rig, data.observations
    end_world = np.full((len(obs), 3), np.nan)
    order = sorted(data.tracks, key=lambda m: m != "typeA")
    origin = np.empty((len(obs), 3))
    direction = np.empty((len(obs), 3))
    for c, cam in enumerate(rig.cameras):
        rows = obs.camera == c
        origin[rows], direction[rows] = cam.rays(obs.uv[rows])
    for method in order:
        track = data.tracks[method]
        match = _match_observations(data, track)
        fill = (match >= 0) & np.isnan(end_world[np.maximum(match, 0), 0])
        rows = match[fill]
        k = np.einsum("ij,ij->i", track.position_world[fill] - origin[rows], direction[rows])
        end_world[rows] = origin[rows] + k[:, None] * direction[rows]
    todo = np.isnan(end_world[:, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        k_floor = -origin[:, 2] / direction[:, 2]
    k_floor = np.where(np.isfinite(k_floor) & (k_floor > 0), k_floor, _RAY_FALLBACK_M)
    end_world[todo] = origin[todo] + k_floor[todo, None] * direction[todo]
    inside = data.in_window(obs.time_ns)
    n = 0
    for c, cam in enumerate(rig.cameras):
        rows = np.flatnonzero(inside & (obs.camera == c))
        with np.errstate(over="ignore"):  # (beyond float32: infinite, then no ray)
            strips = np.stack([origin[rows], end_world[rows]], axis=1).astype(np.float32)
        ok = np.all(np.isfinite(strips), axis=(1, 2))  # a pixel beyond the lens model: no ray
        n += C.send(rec, f"world/rays/{cam.name}", clock, obs.time_ns[rows],
                    obs.frame_index[rows],
                    rr.LineStrips3D.columns(strips=C.strips_array(strips[ok]))
                    .partition(ok.astype(np.int64)))
    return n


def _trail_lengths(time_ns: np.ndarray) -> np.ndarray:
    """Partition lengths of the segments (previous point -> this point): 0 for the first
    point and after gaps."""
    lengths = np.zeros(len(time_ns), dtype=np.int64)
    lengths[1:] = np.diff(time_ns) <= _TRAIL_GAP_S * NS
    return lengths


def _log_points_and_trail(rec, path: str, clock: C.Clock, time_ns, frames, points) -> int:
    n = C.send(rec, path, clock, time_ns, frames, rr.Points3D.columns(positions=points))
    if n:
        lengths = _trail_lengths(time_ns)
        segments = np.stack([points[:-1], points[1:]], axis=1)[lengths[1:] > 0]
        C.send(rec, f"{path}/trail", clock, time_ns, frames,
               rr.LineStrips3D.columns(strips=C.strips_array(segments)).partition(lengths))
    return n


def _log_tracks(rec, data: ViewData, clock: C.Clock, colors) -> int:
    n = 0
    for method, track in data.tracks.items():
        keep = data.in_window(track.time_ns) & np.all(np.isfinite(track.position_world), axis=1)
        track = track.select(keep)
        match = _match_observations(data, track)
        frames = np.where(match >= 0, data.observations.frame_index[np.maximum(match, 0)],
                          _frames_at(data, track.time_ns))
        n += _log_points_and_trail(rec, f"world/tracks/{method}", clock, track.time_ns, frames,
                                   track.position_world)
        std = track.quality.get("std_m")
        if std is not None:
            shown = np.isfinite(std)  # 2σ, capped at 1 m so a wild one hides nothing
            C.send(rec, f"world/tracks/{method}/uncertainty", clock, track.time_ns[shown],
                   frames[shown], rr.Points3D.columns(
                       positions=track.position_world[shown],
                       radii=np.minimum(2 * std[shown], 1.0).astype(np.float32)))
    return n


def _log_truth(rec, data: ViewData, clock: C.Clock) -> int:
    truth = data.session.truth
    if truth is None:
        return 0
    keep = data.in_window(truth.time_ns)
    t = truth.time_ns[keep]
    return _log_points_and_trail(rec, "world/truth", clock, t, _frames_at(data, t),
                                 truth.position_world[keep])


# ---- time series ---------------------------------------------------------------------------
def _log_plots(rec, data: ViewData, clock: C.Clock, quality: dict[str, tuple[str, float]]) -> int:
    n = 0
    truth = data.session.truth
    for method, track in data.tracks.items():
        track = track.select(data.in_window(track.time_ns))
        frames = _frames_at(data, track.time_ns)
        series = {}
        if truth is not None:
            series["error_mm"] = 1e3 * np.linalg.norm(
                track.position_world - truth.at(track.time_ns), axis=1)
        for plot, (key, scale) in quality.items():
            if key in track.quality:
                series[plot] = scale * track.quality[key]
        for plot, values in series.items():
            ok = np.isfinite(values)
            ok[ok] = _m4_keep(data, track.time_ns[ok], values[ok])
            n += C.send(rec, f"plots/{plot}/{method}", clock, track.time_ns[ok], frames[ok],
                        rr.Scalars.columns(scalars=values[ok]))
    det = data.session.detections
    # the frames the ball was detected in (at most one per frame): a candidate off every
    # static spot, so a second orange object in view, a candidate in every frame, does not
    # read 100 % while the ball is missed (pslog info's "moving" rate)
    detected = data.ball_frames[1]
    inside = data.in_window(det.frame_time_ns)
    for c, cam in enumerate(data.session.rig.cameras):
        rows = np.flatnonzero(det.frame_camera == c)
        window = max(1, round(_RATE_WINDOW_S * cam.fps))
        hits = np.concatenate([[0], np.cumsum(detected[rows])])
        i = np.arange(1, len(rows) + 1)
        lo = np.maximum(i - window, 0)
        rate = 100.0 * (hits[i] - hits[lo]) / (i - lo)
        sel = inside[rows]
        sel[sel] = _m4_keep(data, det.frame_time_ns[rows][sel], rate[sel])
        n += C.send(rec, f"plots/detection_rate/{cam.name}", clock, det.frame_time_ns[rows][sel],
                    det.frame_index[rows][sel], rr.Scalars.columns(scalars=rate[sel]))
    return n


def _m4_keep(data: ViewData, time_ns: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Mask (n,) of a plot's points to log: all of them inside the detail range; beyond it,
    in each bucket of ``data.every`` frame periods, the first, last, smallest and largest
    (M4: Jugel et al., PVLDB 7(10), 2014 — the line drawn keeps its extremes and ends).

    ``time_ns`` (n,) int64 and ``values`` (n,) finite float of one series.
    """
    keep = np.ones(len(time_ns), dtype=bool)
    if data.every <= 1 or len(time_ns) == 0 or not data.thinned_anywhere:
        return keep
    detail = data.in_detail(time_ns)
    out = np.flatnonzero(~detail)
    if len(out) == 0:
        return keep
    bucket_ns, _ = data.bucket_ns
    b = (time_ns[out] - data.first_ns) // bucket_ns
    keep = detail.copy()
    for order in (np.lexsort((time_ns[out], b)), np.lexsort((values[out], b))):
        sb = b[order]
        starts = np.flatnonzero(np.r_[True, sb[1:] != sb[:-1]])
        ends = np.r_[starts[1:], len(sb)] - 1
        keep[out[order[starts]]] = True  # first in time / smallest
        keep[out[order[ends]]] = True  # last in time / largest
    return keep


def _log_events(rec, data: ViewData, clock: C.Clock) -> int:
    events = [(t, text) for t, text in data.session.events
              if data.in_window(np.array([t]))[0]]
    if not events:
        return 0
    t = np.array([e[0] for e in events], dtype=np.int64)
    return C.send(rec, "events", clock, t, _frames_at(data, t),
                  rr.TextLog.columns(text=[e[1] for e in events]))


# ---- images --------------------------------------------------------------------------------
def _log_images(rec, data: ViewData, clock: C.Clock, frames: FramesChoice) -> int:
    """Recorded frames passed through encoded (never decoded), streamed in batches."""
    if frames.every == 0 or data.session.n_images == 0:
        return 0
    lo, hi = data.window_ns
    names = data.session.rig.names
    pending: dict[int, list] = {}
    size = 0
    n = 0
    # the ball large: a crop around the detection, beside each full frame (viewers/panels.py)
    crops = CropLogger(rec, data, clock, _images_per_camera(data, frames))

    def flush() -> int:
        sent = 0
        for cam, items in pending.items():
            t = np.array([i.time_ns for i in items], dtype=np.int64)
            f = np.array([i.frame_index for i in items], dtype=np.int64)
            sent += C.send(rec, image_path(names[cam]), clock, t, f, rr.EncodedImage.columns(
                blob=[i.data for i in items],
                media_type=[_MEDIA_TYPES[i.format.lower()] for i in items]))
        pending.clear()
        crops.flush()
        return sent

    start_ns = None if lo <= -UNBOUNDED_NS else lo
    end_ns = None if hi >= UNBOUNDED_NS else hi
    for image in iter_images(data.paths[0], start_ns=start_ns, end_ns=end_ns):
        if image.frame_index % frames.every or image.format.lower() not in _MEDIA_TYPES:
            continue
        if not lo <= image.time_ns < hi:
            continue
        pending.setdefault(image.camera, []).append(image)
        crops.add(image)
        size += len(image.data)
        if size > _IMAGE_BATCH_BYTES:
            n += flush()
            size = 0
    return n + flush()


def _images_per_camera(data: ViewData, frames: FramesChoice) -> int:
    """Most frames of one camera in the window (an upper bound on its images to show)."""
    det = data.session.detections
    inside = data.in_window(det.frame_time_ns)
    counts = np.bincount(det.frame_camera[inside], minlength=len(data.session.rig))
    return int(counts.max(initial=0)) // max(frames.every, 1)
