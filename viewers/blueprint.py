"""The default layout: the 3D view large, a column of camera views, time series below.

The 3D view shows the latest state (cameras, images in their frustums, the type-A
construction) plus a trailing window of rays, tracks and truth (about half a second), set
per entity with visible-time-range overrides.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from pslog.records import Track

from ._columns import CAPTURE_TIME, FRAME

#: Trailing window of rays, tracks and truth in the 3D view, seconds.
TRAIL_S = 0.5

#: plot name -> (track quality key, scale) for the quality time series.
QUALITY_PLOTS: dict[str, tuple[str, float]] = {
    "snap_px": ("snap_px", 1.0),
    "ray_miss_mm": ("ray_miss_m", 1e3),
    "ray_shift_mm": ("ray_shift_m", 1e3),
    "std_mm": ("std_m", 1e3),  # smooth: the point's position standard deviation
    "residual_px": ("residual_px", 1.0),  # smooth: the detection's reprojection residual
}
_PLOT_TITLES = {
    "error_mm": "error vs truth (mm)",
    "snap_px": "snap distance (px)",
    "ray_miss_mm": "ray miss (mm)",
    "ray_shift_mm": "shift onto ray, eq. 4 (mm)",
    "std_mm": "position std (mm)",
    "residual_px": "reprojection residual (px)",
    # the frames the ball was detected in: a candidate off every static spot (recording.py)
    "detection_rate": "ball detection rate (%, last 0.5 s)",
}
#: the live view's rate: over the last second (live.py; its static spots: of the last 2 s)
_LIVE_RATE_TITLE = "ball detection rate (%, last 1 s)"
# 2D overlays live in image space: kept out of the 3D view so it stays readable
_OVERLAYS = ("detections", "rejected", "epipolar", "typeA")


def quality_plots(tracks: Mapping[str, Track]) -> dict[str, tuple[str, float]]:
    """The quality plots some shown track has data for: not all NaN, not all zero to
    rounding (typeA's ray miss is ~1e-15 m by construction, the snap makes the rays cross)."""
    def informative(values: np.ndarray) -> bool:
        return bool(np.nanmax(np.abs(values), initial=0.0) > 1e-9)

    return {plot: spec for plot, spec in QUALITY_PLOTS.items()
            if any(spec[0] in t.quality and informative(t.quality[spec[0]])
                   for t in tracks.values())}


#: rerun's vertical field of view of the 3D eye (re_view_spatial's DEFAULT_FOV_Y), degrees.
EYE_FOV_Y_DEG = 55.0
#: Elevation of the default eye above the horizontal, degrees: high enough to see the
#: floor under the trajectory, low enough to see the arc's height.
EYE_ELEVATION_DEG = 25.0
#: Spacing of the 3D view's floor grid, metres.
GRID_SPACING_M = 0.5


#: Width / height of the 3D view the eye is framed for (the default layout's, rounded down:
#: a wider view only adds margin left and right).
EYE_ASPECT = 4 / 3
#: Share of the view's half-height (and half-width) the framed box may fill.
EYE_FILL = 0.9


def default_eye(camera_centers_world: np.ndarray, scene_world: np.ndarray
                ) -> rrb.EyeControls3D | None:
    """A 3D viewpoint framed on the trajectory and the floor under it.

    The eye looks at the centre of the box holding ``scene_world`` (n, 3) metres (the truth
    or the tracks) and its shadow on the floor z = 0, from the side: square to the
    trajectory's main horizontal direction (its arc seen side-on), on the side of the
    cameras' mean position ``camera_centers_world`` (c, 3) so the view matches what the
    cameras see, raised by :data:`EYE_ELEVATION_DEG`. Its distance is the smallest at which
    the box's eight corners, in perspective (rerun's :data:`EYE_FOV_Y_DEG`, a view of
    :data:`EYE_ASPECT`), lie within :data:`EYE_FILL` of the view's edges. The cameras are
    left out of the framing: they stand metres away and would shrink the ball's path to a
    corner. None when there is nothing to frame.
    """
    scene = np.asarray(scene_world, dtype=np.float64).reshape(-1, 3)
    scene = scene[np.all(np.isfinite(scene), axis=1)]
    if len(scene) == 0:
        return None
    lo, hi = scene.min(axis=0), scene.max(axis=0)
    lo[2] = min(lo[2], 0.0)  # down to the floor
    # at least 1 m across, so a ball at rest is seen with its surroundings
    pad = np.maximum(0.5 - 0.5 * (hi - lo), 0.0)
    lo, hi = lo - pad * [1, 1, 0], hi + pad * [1, 1, 2]
    target = 0.5 * (lo + hi)
    # main horizontal direction of the path (principal axis), the eye square to it
    xy = scene[:, :2] - scene[:, :2].mean(axis=0)
    if len(scene) >= 2 and np.ptp(xy, axis=0).max() > 1e-6:
        main = np.linalg.svd(xy, full_matrices=False)[2][0]
        side = np.array([-main[1], main[0]])
    else:
        side = np.array([0.0, -1.0])
    centers = np.asarray(camera_centers_world, dtype=np.float64).reshape(-1, 3)
    if len(centers) and float(np.dot(centers.mean(axis=0)[:2] - target[:2], side)) < 0:
        side = -side
    elevation = np.radians(EYE_ELEVATION_DEG)
    back = np.array([*(np.cos(elevation) * side), np.sin(elevation)])  # target -> eye
    right = np.cross(-back, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -back)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                        for z in (lo[2], hi[2])]) - target
    ty = np.tan(0.5 * np.radians(EYE_FOV_Y_DEG)) * EYE_FILL
    tx = ty * EYE_ASPECT

    def fits(distance: float) -> bool:
        depth = distance - corners @ back
        return bool(np.all(depth > 0) and np.all(np.abs(corners @ right) <= tx * depth)
                    and np.all(np.abs(corners @ up) <= ty * depth))

    near, far = 0.0, 1.0
    while not fits(far):
        near, far = far, 2 * far
    for _ in range(40):  # bisection to well under a millimetre
        mid = 0.5 * (near + far)
        near, far = (near, mid) if fits(mid) else (mid, far)
    return rrb.EyeControls3D(position=target + far * back, look_target=target,
                             eye_up=(0.0, 0.0, 1.0))


def _trailing(fps_hint: float = 90.0) -> rrb.VisibleTimeRanges:
    frames = max(1, round(TRAIL_S * fps_hint / 3))  # frames per camera in the window
    return rrb.VisibleTimeRanges([
        rrb.VisibleTimeRange(CAPTURE_TIME,
                             start=rrb.TimeRangeBoundary.cursor_relative(seconds=-TRAIL_S),
                             end=rrb.TimeRangeBoundary.cursor_relative()),
        rrb.VisibleTimeRange(FRAME, start=rrb.TimeRangeBoundary.cursor_relative(seq=-frames),
                             end=rrb.TimeRangeBoundary.cursor_relative()),
    ])


def build_blueprint(camera_names: Sequence[str], methods: Sequence[str], *, has_truth: bool,
                    quality: Mapping[str, tuple[str, float]],
                    eye: rrb.EyeControls3D | None = None,
                    recorded: bool = True) -> rrb.Blueprint:
    """The default blueprint for a session with these cameras, shown tracks and plots
    (``quality`` from :func:`quality_plots`, ``eye`` from :func:`default_eye`).
    ``recorded`` False (the live view): no ball crops and no summary panel, which only a
    recorded session has (viewers/panels.py)."""
    trail = _trailing()
    trailing_paths = [f"world/rays/{c}" for c in camera_names]
    for m in methods:
        trailing_paths += [f"world/tracks/{m}", f"world/tracks/{m}/trail"]
    if has_truth:
        trailing_paths += ["world/truth", "world/truth/trail"]
    contents = ["+ /world/**"] + [f"- /world/cameras/{c}/image/{o}/**"
                                  for c in camera_names for o in _OVERLAYS]
    view3d = rrb.Spatial3DView(origin="/world", name="3D (trail 0.5 s)", contents=contents,
                               overrides={p: trail for p in trailing_paths},
                               eye_controls=eye,
                               line_grid=rrb.LineGrid3D(visible=True, spacing=GRID_SPACING_M,
                                                        plane=rr.components.Plane3D.XY))
    # each camera: the full frame, and beside it the ball large (viewers/panels.py's crop)
    cameras = [rrb.Horizontal(rrb.Spatial2DView(origin=f"/world/cameras/{c}/image", name=c),
                              rrb.Spatial2DView(origin=f"/crops/{c}", name=f"{c} ball"),
                              column_shares=[2, 1]) if recorded
               else rrb.Spatial2DView(origin=f"/world/cameras/{c}/image", name=c)
               for c in camera_names]
    plots = (["error_mm"] if has_truth and methods else []) + list(quality) + ["detection_rate"]
    # a rate lies in 0-100 %: a fixed axis shows a full rate as full, not as a line on a
    # 99-101 axis, and a drop at its true size
    axes = {"detection_rate": rrb.ScalarAxis(range=(0.0, 105.0), zoom_lock=True)}
    titles = _PLOT_TITLES if recorded else {**_PLOT_TITLES, "detection_rate": _LIVE_RATE_TITLE}
    series = {p: rrb.TimeSeriesView(origin=f"/plots/{p}", name=titles.get(p, p),
                                    axis_y=axes.get(p))
              for p in plots}
    legend = rrb.TextDocumentView(origin="/legend", name="legend")
    summary = rrb.TextDocumentView(origin="/summary", name="summary: accuracy, colours, clocks")
    top = rrb.Horizontal(view3d, rrb.Vertical(*cameras), column_shares=[3, 2 if recorded else 1])
    # at a glance: the error and the detection rate; the method's own quality plots share
    # one tabbed view (a row of six plots leaves each too narrow to read)
    first = [series.pop("error_mm")] if "error_mm" in series else []
    rate = series.pop("detection_rate")
    own = [rrb.Tabs(*series.values())] if series else []
    plots_row = [*first, *own, rate]
    text = rrb.Tabs(summary, legend) if recorded else legend
    bottom = rrb.Horizontal(*plots_row, text, column_shares=[1] * len(plots_row) + [2])
    return rrb.Blueprint(
        rrb.Vertical(top, bottom, row_shares=[3, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline=CAPTURE_TIME, playback_speed=0.25),
    )
