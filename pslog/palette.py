"""The one colour palette of pslog: every viewer (rerun, the live view) and the Foxglove
``SceneUpdate`` written into a session draw a method, a camera, the truth and each overlay in
the colours defined here, so a colour means the same thing everywhere.

Plain 8-bit RGB tuples, no viewer import (the core never imports ``viewers``).

Families, chosen apart in CIELAB (ΔE*76 ≥ 20 between any two of the families' members,
checked by ``tests/test_viewer_glance.py``):

- methods: saturated, mid-lightness colours (L* 45-70), visible on rerun's light and dark
  themes;
- cameras: light, less saturated tints (L* 73-83): rays, detections, epipolar lines and the
  detection-rate plot of a camera;
- reference and overlays: the truth mid grey (L* 54, contrast on white and on black alike),
  rejected candidates light grey, and the type-A construction (paper Figure 2) in cyan for
  the interpolation (eq. 1, the two past points and the prediction of eq. 2) and yellow for
  the snap onto the epipolar line (step 2) and its 3D counterpart (eq. 4).
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence

RGB = tuple[int, int, int]

#: Fixed colour of each fusion method (pslog.fusion.METHODS), 8-bit RGB.
METHOD_COLORS: dict[str, RGB] = {
    "typeA": (255, 127, 0),  # orange
    "typeB": (30, 110, 255),  # blue
    "sync": (20, 170, 60),  # green
    "nearest": (230, 50, 200),  # magenta (nothing else is magenta)
    "linear": (200, 170, 0),  # ochre
    "smooth": (210, 30, 50),  # crimson
    "filter": (130, 80, 230),  # violet
}
#: Colours of methods outside :data:`METHOD_COLORS` (renamed copies, imported tracks),
#: chosen by a hash of the name so that the viewer and the MCAP agree without sharing state.
EXTRA_METHOD_COLORS: tuple[RGB, ...] = ((0, 150, 150), (150, 90, 40), (255, 120, 170),
                                        (90, 90, 170))
#: Camera ``i`` of a rig has ``CAMERA_COLORS[i % 6]``.
#: The first three stand out on a green field and apart from the construction's cyan.
CAMERA_COLORS: tuple[RGB, ...] = ((200, 165, 235), (240, 165, 125), (225, 205, 150),
                                  (250, 175, 190), (120, 200, 235), (165, 215, 120))
#: Ground truth (3D points, trail, error plots' reference): mid grey, seen on both themes.
TRUTH_COLOR: RGB = (128, 128, 128)
#: Candidates the gating rejected, on the camera images.
REJECTED_COLOR: RGB = (195, 195, 195)
#: Type-A construction, interpolation side: the partner's bracketing detections and the
#: interpolated point (eq. 1) on the images; P(t-1), P(t-2) and the prediction (eq. 2) in 3D.
CONSTRUCTION_COLOR: RGB = (0, 225, 225)
#: Type-A construction, correction side: the snap onto the epipolar line (step 2), that
#: line, and in 3D the move of the prediction onto the ray (eq. 4).
SNAP_COLOR: RGB = (255, 235, 0)

#: Human names of the colours above, for legends.
COLOR_NAMES: dict[RGB, str] = {
    (255, 127, 0): "orange", (30, 110, 255): "blue", (20, 170, 60): "green",
    (230, 50, 200): "magenta", (200, 170, 0): "ochre", (210, 30, 50): "crimson",
    (130, 80, 230): "violet", (0, 150, 150): "teal", (150, 90, 40): "brown",
    (255, 120, 170): "pink", (90, 90, 170): "slate",
    (120, 200, 235): "light blue", (240, 165, 125): "peach", (165, 215, 120): "light green",
    (200, 165, 235): "lilac", (225, 205, 150): "sand", (250, 175, 190): "rose",
    (128, 128, 128): "grey", (195, 195, 195): "light grey", (0, 225, 225): "cyan",
    (255, 235, 0): "yellow",
}


def method_color(method: str) -> RGB:
    """The colour of ``method``: fixed for the known methods, else one of
    :data:`EXTRA_METHOD_COLORS` picked by the CRC-32 of the name (stable across runs)."""
    known = METHOD_COLORS.get(method)
    if known is not None:
        return known
    return EXTRA_METHOD_COLORS[zlib.crc32(method.encode()) % len(EXTRA_METHOD_COLORS)]


def method_colors(methods: Sequence[str]) -> dict[str, RGB]:
    """``{method: method_color(method)}`` in the given order."""
    return {m: method_color(m) for m in methods}


def camera_color(index: int) -> RGB:
    """The colour of the rig's camera number ``index`` (0-based)."""
    return CAMERA_COLORS[index % len(CAMERA_COLORS)]


def color_name(color: Sequence[int]) -> str:
    """A legend's name for ``color`` ("orange"), or its RGB triple when it has none."""
    rgb = tuple(int(c) for c in color[:3])
    return COLOR_NAMES.get(rgb, "rgb({}, {}, {})".format(*rgb))  # type: ignore[arg-type]


def unit_rgb(color: Sequence[int]) -> tuple[float, float, float]:
    """8-bit RGB -> (r, g, b) in [0, 1], as Foxglove's ``Color`` takes it."""
    return (color[0] / 255.0, color[1] / 255.0, color[2] / 255.0)
