"""The default layout: the 3D view large, a column of camera views, time series below.

The 3D view shows the latest state (cameras, images in their frustums, the type-A
construction) plus a trailing window of rays, tracks and truth (about half a second), set
per entity with visible-time-range overrides.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
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
    "detection_rate": "detection rate (%)",
}
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


def default_eye(camera_centers_world: np.ndarray, scene_world: np.ndarray
                ) -> rrb.EyeControls3D | None:
    """A 3D viewpoint that frames the scene: from outside the cameras, above and behind
    their mean position, looking at the centre of ``scene_world`` (n, 3) metres."""
    scene = np.asarray(scene_world, dtype=np.float64).reshape(-1, 3)
    scene = scene[np.all(np.isfinite(scene), axis=1)]
    if len(scene) == 0 or len(camera_centers_world) == 0:
        return None
    target = 0.5 * (scene.min(axis=0) + scene.max(axis=0))
    centers = np.asarray(camera_centers_world, dtype=np.float64)
    away = centers.mean(axis=0)[:2] - target[:2]
    away = away / np.linalg.norm(away) if np.linalg.norm(away) > 1e-6 else np.array([0.0, -1.0])
    reach = max(np.max(np.linalg.norm(centers[:, :2] - target[:2], axis=1)), 1.0)
    position = target + np.array([*(1.3 * reach * away), 0.75 * reach])
    return rrb.EyeControls3D(position=position, look_target=target, eye_up=(0.0, 0.0, 1.0))


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
                    eye: rrb.EyeControls3D | None = None) -> rrb.Blueprint:
    """The default blueprint for a session with these cameras, shown tracks and plots
    (``quality`` from :func:`quality_plots`, ``eye`` from :func:`default_eye`)."""
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
                               eye_controls=eye)
    cameras = [rrb.Spatial2DView(origin=f"/world/cameras/{c}/image", name=c)
               for c in camera_names]
    plots = (["error_mm"] if has_truth and methods else []) + list(quality) + ["detection_rate"]
    series = [rrb.TimeSeriesView(origin=f"/plots/{p}", name=_PLOT_TITLES.get(p, p))
              for p in plots]
    legend = rrb.TextDocumentView(origin="/legend", name="legend")
    timing = rrb.TextDocumentView(origin="/timing", name="camera clocks")
    top = rrb.Horizontal(view3d, rrb.Vertical(*cameras), column_shares=[3, 1])
    bottom = rrb.Horizontal(*series, legend, timing)
    return rrb.Blueprint(
        rrb.Vertical(top, bottom, row_shares=[3, 1]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed", timeline=CAPTURE_TIME, playback_speed=0.25),
    )
