"""Fusion: per-camera detections in, 3D tracks with per-point quality out.

Methods (names as on the command line), each from the paper (``../shared/paper``):

========  ============================================================  ===================
name      what                                                          paper
========  ============================================================  ===================
sync      N-view triangulation of simultaneous detections               Table 1 "synchronized"
nearest   each detection with the latest of the other cameras           Table 1 "unsynchronized"
typeA     pseudo stereo, a point at every detection                     section 2.2, eqs. 1-4
typeB     stereo at common instants + ray-constrained prediction        section 2.3
linear    typeB without the ray constraint                              Table 1 "linear prediction"
========  ============================================================  ===================

:func:`fuse` is the batch entry point. Every method is causal, so
:class:`~pslog.fusion.stream.StreamFuser` gives the same points incrementally: a ``typeA`` or
``nearest`` point uses no detection after its own in (time, camera) order; ``sync``, ``typeB``
and ``linear`` group detections within the tolerance, so their point at ``t`` may also use
detections up to ``t + tolerance``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import FusionError
from ..records import Detections, Observations, Track
from ..rig import Rig
from ..timing import observations as timed_observations
from ._prepare import Prepared, default_max_gap_s, prepare
from .prediction import fuse_predicted
from .pseudo import PseudoStereoPoints, TypeAConstruction, fuse_type_a, pseudo_stereo_points
from .stereo import fuse_nearest, fuse_sync, sync_groups

METHODS: dict[str, str] = {
    "sync": "ordinary stereo of simultaneous detections (paper: synchronized)",
    "nearest": "latest detection of the other cameras, as if simultaneous (paper: unsynchronized)",
    "typeA": "pseudo stereo at every detection (paper section 2.2, eqs. 1-4)",
    "typeB": "stereo at common instants + ray-constrained prediction (paper section 2.3)",
    "linear": "stereo at common instants + linear prediction (paper: linear prediction)",
}


#: Longest time span a fusion method may be asked to bridge, seconds (an hour): a longer
#: one bridges nothing more, and overflows integer nanoseconds for absurd values.
MAX_GAP_S = 3600.0


@dataclass(frozen=True)
class FusionOptions:
    """Settings shared by the methods.

    Attributes
    ----------
    tolerance_s : float, detections this close in time count as simultaneous (sync, typeB,
        linear), seconds; no group spans more, and the methods refuse a tolerance of a third
        of the rig's shortest frame period or more (:func:`check_tolerance`)
    max_gap_s : float or None, longest time span a method may bridge (brackets, predictions,
        pairing); None: 3.5 frame periods of the slowest camera
    """

    tolerance_s: float = 1e-3
    max_gap_s: float | None = None

    def __post_init__(self) -> None:
        if not self.tolerance_s >= 0:
            raise FusionError(f"tolerance must be >= 0 seconds, got {self.tolerance_s!r}")
        if self.max_gap_s is not None and not 0 < self.max_gap_s <= MAX_GAP_S:
            raise FusionError(f"max gap must be in (0, {MAX_GAP_S:g}] seconds, got "
                              f"{self.max_gap_s!r}")


def check_tolerance(rig: Rig, tolerance_s: float) -> float:
    """``tolerance_s`` if it is below a third of the shortest frame period of ``rig``, else
    :class:`FusionError` saying why.

    Detections within the tolerance count as one instant. Type-A shutters of three cameras
    are a third of a period apart: a tolerance that wide would take distinct shutters for
    simultaneous ones and triangulate a moving ball seen at different times.
    """
    fastest = max(rig.cameras, key=lambda c: c.fps)
    limit = fastest.frame_period / 3
    if not 0 <= tolerance_s < limit:
        raise FusionError(
            f"tolerance {tolerance_s * 1e3:g} ms must be below a third of the frame period "
            f"({limit * 1e3:.4g} ms at {fastest.fps:g} fps, camera {fastest.name}): shutters "
            f"that far apart are distinct instants (type-A shutters of three cameras are a "
            f"third of a period apart), not simultaneous ones")
    return tolerance_s


def check_method(method: str) -> str:
    if method not in METHODS:
        raise FusionError(f"unknown fusion method {method!r} (have {', '.join(METHODS)})")
    return method


def default_methods(
    observations: Observations | Detections, rig: Rig, options: FusionOptions | None = None,
) -> list[str]:
    """The methods worth running on these detections' timing, in :data:`METHODS` order.

    Stereo (``sync``) needs instants that two cameras share; pseudo stereo and its baseline
    (``typeA``, ``nearest``) need instants that only one camera has (with fully synchronised
    shutters they would only repeat each instant); ``typeB`` and ``linear`` need both.
    """
    options = options or FusionOptions()
    if isinstance(observations, Detections):
        observations = timed_observations(observations, rig)
    check_tolerance(rig, options.tolerance_s)
    _, n_cameras = sync_groups(observations, len(rig), options.tolerance_s)
    shared, alone = bool(np.any(n_cameras >= 2)), bool(np.any(n_cameras == 1))
    usable = {"sync": shared, "nearest": alone, "typeA": alone,
              "typeB": shared and alone, "linear": shared and alone}
    return [m for m in METHODS if usable[m]]


def fuse(
    observations: Observations | Detections, rig: Rig, method: str,
    options: FusionOptions | None = None, *, prepared: Prepared | None = None,
) -> Track:
    """Fuse one session's detections into a 3D track.

    Parameters
    ----------
    observations : Observations, or Detections (their best candidate per frame is used, at
        its true time by the rig's timing model: :func:`pslog.timing.observations`)
    rig : Rig, whose camera order the observations' camera indices refer to
    method : one of :data:`METHODS`
    options : FusionOptions
    prepared : the result of :func:`prepare` for these observations, to share between methods

    Returns
    -------
    Track, sorted by time, without NaN points
    """
    check_method(method)
    options = options or FusionOptions()
    if isinstance(observations, Detections):
        observations = timed_observations(observations, rig)
    if len(rig) < 2:
        raise FusionError(f"fusion needs at least two cameras; rig has {len(rig)}")
    check_tolerance(rig, options.tolerance_s)
    prep = prepared if prepared is not None else prepare(observations, rig)
    max_gap_s = options.max_gap_s or default_max_gap_s(rig)
    if method == "sync":
        return fuse_sync(prep, options.tolerance_s)
    if method == "nearest":
        return fuse_nearest(prep, max_gap_s)
    if method == "typeA":
        return fuse_type_a(prep, max_gap_s)[0]
    return fuse_predicted(prep, method, options.tolerance_s, max_gap_s)


def fuse_all(
    observations: Observations | Detections, rig: Rig, methods: Sequence[str],
    options: FusionOptions | None = None,
) -> dict[str, Track]:
    """Several methods over one session, sharing the undistortion and rays."""
    for method in methods:
        check_method(method)
    if isinstance(observations, Detections):
        observations = timed_observations(observations, rig)
    if len(rig) < 2:
        raise FusionError(f"fusion needs at least two cameras; rig has {len(rig)}")
    check_tolerance(rig, (options or FusionOptions()).tolerance_s)
    prep = prepare(observations, rig)
    return {m: fuse(observations, rig, m, options, prepared=prep) for m in methods}


def explain_type_a(
    observations: Observations | Detections, rig: Rig, options: FusionOptions | None = None
) -> TypeAConstruction:
    """The paper's Figure 2 construction behind every type-A point (see TypeAConstruction)."""
    options = options or FusionOptions()
    if isinstance(observations, Detections):
        observations = timed_observations(observations, rig)
    prep = prepare(observations, rig)
    return fuse_type_a(prep, options.max_gap_s or default_max_gap_s(rig))[1]


__all__ = [
    "METHODS", "FusionOptions", "Prepared", "PseudoStereoPoints", "TypeAConstruction",
    "check_method", "check_tolerance", "default_methods", "explain_type_a", "fuse", "fuse_all",
    "prepare", "pseudo_stereo_points",
]
