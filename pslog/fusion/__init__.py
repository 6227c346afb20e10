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
smooth    one continuous trajectory fitted to every ray (offline)       beyond the paper
filter    causal extended Kalman filter, a point at every detection     beyond the paper
========  ============================================================  ===================

:data:`METHODS` is the registry (one :class:`Method` entry per method); the CLI,
:func:`default_methods`, the streaming fuser and the tests read it. :func:`fuse` is the batch
entry point. Every causal method streams through :class:`~pslog.fusion.stream.StreamFuser`
with the same points: a ``typeA``, ``nearest`` or ``filter`` point uses no detection after its
own in (time, camera) order (``filter`` streams through its own incremental form,
:mod:`pslog.fusion.filter`); ``sync``, ``typeB`` and ``linear`` group detections within the
tolerance, so their point at ``t`` may also use detections up to ``t + tolerance``.
``smooth`` (:mod:`pslog.fusion.smooth`) is offline: every point uses every detection.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import TYPE_CHECKING, Literal, cast

import numpy as np

from ..camera import MIN_FUSE_NOISE_PX
from ..errors import FusionError
from ..records import Detections, Observations, Track, matching_rows, point_keys
from ..rig import Rig
from ..timing import ClockCovariance
from ..timing import observations as timed_observations
from ._prepare import Prepared, default_max_gap_s, prepare
from .prediction import fuse_predicted
from .pseudo import PseudoStereoPoints, TypeAConstruction, fuse_type_a, pseudo_stereo_points
from .stereo import Drops, fuse_nearest, fuse_sync, sync_groups

if TYPE_CHECKING:
    from .breaks import SessionFit

#: The filter's hold for the next camera by default (``FilterOptions.hold_nis``,
#: ``FusionOptions.filter_hold_nis``): a plain update's point whose NIS exceeds χ²₂'s mean
#: (its 1 − 1/e quantile) waits for the next camera's detection (docs/methods.md, "A point
#: held for the next camera"; session 30)
FILTER_HOLD_NIS = 2.0

#: Longest time span a fusion method may be asked to bridge, seconds (an hour): a longer
#: one bridges nothing more, and overflows integer nanoseconds for absurd values.
MAX_GAP_S = 3600.0

#: ``pslog fuse --confirm-gaps``'s choices, the first the default offline (session 45;
#: ``kicks`` before): typeA's (``confirm_gaps``, ``confirm_every``, ``confirm_sides``,
#: ``confirm_breaks``) (:class:`FusionOptions`; :func:`confirm_choice` adds the break source)
CONFIRM_GAPS = {"jumps": (True, True, True, True), "kicks": (True, True, True, False),
                "breaks": (True, True, True, True), "all": (True, True, False, False),
                "on": (True, False, False, False), "off": (False, False, False, False)}
#: Where ``confirm_breaks`` takes its kick instants (``FusionOptions.break_source``): the
#: first is the default (session 45: the images'; the fit's before)
BREAK_SOURCES = ("image", "fit")
#: ``pslog fuse --confirm-gaps``'s choices whose break source is not the default
CONFIRM_BREAK_SOURCE = {"breaks": "fit"}


def confirm_choice(name: str) -> dict:
    """:class:`FusionOptions`' typeA confirmation fields for ``pslog fuse --confirm-gaps
    NAME`` (a key of :data:`CONFIRM_GAPS`): ``confirm_gaps``, ``confirm_every``,
    ``confirm_sides``, ``confirm_breaks`` and ``break_source``."""
    fields = ("confirm_gaps", "confirm_every", "confirm_sides", "confirm_breaks")
    return dict(zip(fields, CONFIRM_GAPS[name], strict=True),
                break_source=CONFIRM_BREAK_SOURCE.get(name, BREAK_SOURCES[0]))


@dataclass(frozen=True)
class FusionOptions:
    """Settings shared by the methods.

    Attributes
    ----------
    tolerance_s : float, detections this close in time count as simultaneous (sync, typeB,
        linear), seconds; no group spans more, and the methods refuse a tolerance of a third
        of the rig's shortest frame period or more (:func:`check_tolerance`); ``pslog fuse``
        and :func:`pslog.fuse` without options take :func:`default_tolerance` (this 1 ms, or
        a tenth of the period of cameras faster than 333 fps)
    max_gap_s : float or None, longest time span a method may bridge (brackets, predictions,
        pairing; for smooth, the longest time without a detection inside one trajectory
        piece); None: 3.5 frame periods of the slowest camera
    rate_hz : float or None, smooth only: output points on a regular grid of this rate
        instead of at every detection time
    noise_px : float or None, standard deviation of the detections' pixel noise per axis,
        pixels: the first-order position covariance (``std_m``, ``cov_*_m2``) scales with
        it; None: no covariance (for throughput: it is most of the methods' cost). typeA's
        prediction and kink tests (:mod:`pslog.fusion.innovation`) take it as the least
        noise: they use the larger of it (0.5 px when None) and the noise the session's own
        innovations imply (:class:`~pslog.fusion.innovation.NoiseEstimate`); nearest's
        and typeA's covariance take the noise their detections show once the session has
        enough of them, never below the smaller of it and 0.1 px
        (:func:`pslog.fusion.stereo.detection_noise`, :func:`pslog.fusion.pseudo.
        measured_noise`)
    gating : bool, fusing Detections: choose each frame's ball among its candidates by the
        gates of :mod:`pslog.fusion.gating` (True), or take the best-scored one (False)
    confirm_gaps : bool, typeA: withhold a point whose prediction bridged a gap longer than
        the rig's usual one, or that rests on a camera's first detection after more than
        ``max_gap_s`` without one (a re-acquisition: ``confirm.FRESH_ROWS``), or whose
        innovation across the newest ray exceeds 3 σ (below the refusal's 5: a kick partly
        seen, ``confirm.WAIT_SIGMAS``; with ``noise_px`` set), until the next camera's
        detection confirms it, and drop it when that detection contradicts it
        (:mod:`pslog.fusion.confirm`; a stream outputs it one detection later); False: every
        point at once (``pslog live``: a point per shutter)
    confirm_every : bool or None, typeA, offline only, with ``confirm_gaps``: every point,
        not only the long-gap ones, is tested against the next detection of another camera
        that can check it and dropped as ``contradicted`` when it disagrees (the same test; a
        point nothing can check is kept unless it bridged a long gap): the points just after
        an unseen kick, whose depth eq. (2) took from the motion before it (docs/methods.md,
        "Type A after kicks, confirmed offline (session 29)"). False: only the long-gap
        points wait (the causal form; the paper's points with ``confirm_gaps`` False too).
        None (the default): on where the session's defaults are applied offline
        (:func:`offline_confirmation`, by :func:`for_session`: ``pslog fuse``,
        :func:`pslog.fuse`, ``pslog view``, ``demo``, ``batch``; session 35), off in this
        module's :func:`fuse`, :func:`fuse_all` and :func:`explain_type_a` (the causal form)
        and in a stream.
        True without ``confirm_gaps`` is refused (``FusionError``), as a typeA stream
        refuses True; ``pslog live`` turns both off
    confirm_sides : bool or None, typeA, offline only, with ``confirm_every``: each point is
        tested against every other camera that can check it, each camera's 2D track taken on
        the point's side of a velocity jump the track shows (eq. (1)'s interpolation across
        a kick is no check: ``confirm.sides_test``; docs/methods.md, "Type A after kicks: the
        side of the kick (session 33)"). False: ``confirm_every``'s test. None (the
        default): on where :func:`for_session` turns ``confirm_every`` on from None, off
        otherwise (``confirm_every=True`` alone: ``--confirm-gaps all`` everywhere)
    confirm_breaks : bool or None, typeA, offline only, with ``confirm_sides``: a point
        whose construction spans a kick instant (``break_source``'s) is replaced by type A's
        point on the same detection made from the time-reversed observations (the backward
        pass) when that construction spans no kick, and withheld (``break`` in
        ``Track.dropped``) otherwise; the other points unchanged, to the bit
        (:mod:`pslog.fusion.breaks`; docs/methods.md, "Type A across a break: the backward
        pass (session 37)"). None (the default): on where :func:`for_session` turns
        ``confirm_sides`` on (session 45: ``pslog fuse``'s default ``--confirm-gaps jumps``;
        ``kicks`` before), off otherwise (this module's :func:`fuse`, a stream: there a
        ``break_source`` given with it None is not used)
    break_source : str, typeA with ``confirm_breaks``: where the kick instants come from:
        ``"image"`` (the default, session 45), each camera's image track alone
        (:func:`pslog.fusion.breaks.image_kicks_ns`: the jumps its detections show, no fit;
        ``pslog fuse --confirm-gaps jumps``; docs/methods.md, "Kick instants from the images
        (session 44)"); ``"fit"``, the velocity breaks of ``smooth``'s fit of the session
        (of ``smooth``'s own input: the detections as its offline gate chooses them; one
        fit shared with ``smooth`` when both are fused, :class:`pslog.fusion.breaks.
        SessionFit`; ``pslog fuse --confirm-gaps breaks``)
    max_std_m : float or None, typeA: a point whose ``std_m`` exceeds this is withheld
        (counted in ``Track.dropped`` as ``uncertain``: the filter's rule;
        ``pslog.fusion.pseudo.MAX_STD_M`` is the filter's default, 5 cm / 1.96, issue 10's
        "no point beyond 5 cm"); None (the default, session 26: the decision on the points
        it withholds at a session's start is open): every point (docs/methods.md, "Type A's
        points after an unseen kick (session 26)")
    detector_offset_m : float or None, smooth only: standard deviation (metres, per axis)
        of the detector's constant 3-D offset of the ball's apparent centre (every camera's
        centroid drawn toward the lit side of the ball), a systematic error that smooth's
        averaging of many detections cannot shrink: each point's covariance gains
        ``σ² I₃`` (the points do not move; docs/estimation.md). None: the session's default
        (:func:`detector_bias_for`, applied by ``pslog fuse`` and :func:`pslog.fuse` from the
        session's metadata; 0 for bare detections)
    detector_bias_px : float or None, smooth only: standard deviation (pixels, per image
        axis) of each camera's own constant bias, independent between cameras, through the
        fit's sensitivity to it (:func:`pslog.estimation.trajectory.bias_sensitivity`).
        None: 0
    filter_hold_nis : float or None, filter: its hold for the next camera
        (:attr:`pslog.fusion.filter.FilterOptions.hold_nis`, batch and stream alike: a
        stream emits a held point when the detection that decides it arrives, one stagger
        later; with it, a start's point, a point after a missed slot and a rejected
        detection's are held too, session 47: ``hold_start``, ``hold_gap``,
        ``hold_rejected``); default :data:`FILTER_HOLD_NIS` (session 30); None: no hold, a
        point at its own detection (``pslog live`` turns it off)
    clock_covariance : :class:`pslog.timing.ClockCovariance` or None, the covariance of the
        rig's clock estimates (``pslog sync``'s, read from a synced session by
        :func:`for_session`): every point's covariance gains its consider covariance, the
        points' sensitivity to the clocks (:mod:`pslog.fusion.clock`; the points do not
        move; offline only: a stream refuses it). None: the clocks are taken as exact
    """

    tolerance_s: float = 1e-3
    max_gap_s: float | None = None
    rate_hz: float | None = None
    noise_px: float | None = 0.5
    gating: bool = True
    confirm_gaps: bool = True
    confirm_every: bool | None = None
    confirm_sides: bool | None = None
    confirm_breaks: bool | None = None
    break_source: str = BREAK_SOURCES[0]
    max_std_m: float | None = None
    detector_offset_m: float | None = None
    detector_bias_px: float | None = None
    filter_hold_nis: float | None = FILTER_HOLD_NIS
    clock_covariance: ClockCovariance | None = None

    def __post_init__(self) -> None:
        if not self.tolerance_s >= 0:
            raise FusionError(f"tolerance must be >= 0 seconds, got {self.tolerance_s!r}")
        if self.max_gap_s is not None and not 0 < self.max_gap_s <= MAX_GAP_S:
            raise FusionError(f"max gap must be in (0, {MAX_GAP_S:g}] seconds, got "
                              f"{self.max_gap_s!r}")
        if self.rate_hz is not None and not 1e-3 <= self.rate_hz <= 1e6:
            # (below a point per 1000 s the grid's step overflows to inf ns near 1e-300)
            raise FusionError(f"rate must be in [0.001, 1e6] Hz, got {self.rate_hz!r}")
        if self.confirm_sides and not self.confirm_every:
            raise FusionError("typeA's confirm_sides needs confirm_every (it is the test "
                              "every point takes)")
        if self.confirm_breaks and self.confirm_sides is False:
            raise FusionError("typeA's confirm_breaks needs confirm_sides (it replaces the "
                              "points the kick test keeps)")
        if self.break_source not in BREAK_SOURCES:
            raise FusionError(f"typeA's break source must be one of {', '.join(BREAK_SOURCES)}, "
                              f"got {self.break_source!r}")
        if self.break_source != BREAK_SOURCES[0] and self.confirm_breaks is False:
            raise FusionError(f"typeA's break source {self.break_source!r} needs "
                              "confirm_breaks (it is where that rule takes its kick "
                              "instants: pslog fuse --confirm-gaps breaks)")
        if self.confirm_every and not self.confirm_gaps:
            raise FusionError("typeA's confirm_every needs confirm_gaps (it confirms every "
                              "point as confirm_gaps confirms the long-gap ones)")
        if self.noise_px is not None and not (
                self.noise_px == 0 or MIN_FUSE_NOISE_PX <= self.noise_px <= 1e3):
            # (below MIN_FUSE_NOISE_PX the covariances underflow: typeA's std_m all NaN,
            # as pslog fuse --noise-px refuses)
            raise FusionError(f"pixel noise must be 0 (noise-free) or in "
                              f"[{MIN_FUSE_NOISE_PX:g}, 1000] pixels, got {self.noise_px!r}")
        if self.detector_bias_px is not None and not 0 <= self.detector_bias_px <= 1e3:
            raise FusionError(f"detector bias must be in [0, 1000] pixels, got "
                              f"{self.detector_bias_px!r}")
        if self.filter_hold_nis is not None and (
                isinstance(self.filter_hold_nis, bool)
                or not 0 <= self.filter_hold_nis < float("inf")):
            raise FusionError(f"filter hold NIS must be finite and >= 0, got "
                              f"{self.filter_hold_nis!r}")
        if self.max_std_m is not None and not self.max_std_m > 0:
            raise FusionError(f"max std must be > 0 metres, got {self.max_std_m!r}")
        if self.detector_offset_m is not None and not 0 <= self.detector_offset_m <= 1.0:
            raise FusionError(f"detector offset must be in [0, 1] metres, got "
                              f"{self.detector_offset_m!r}")


#: Standard deviation (metres, per axis) of the constant 3-D offset of the ball's apparent
#: centre for detections found in images (pslog's HSV detector, ``recorders/detect.py``, or
#: an imported detector's): measured on nine rendered sessions of six rigs, the centroid
#: sits 0.7-1.1 mm (3-5 % of a golf ball's radius) toward the light, the same for every
#: camera (RMS 0.52 mm per axis in an unknown direction; docs/estimation.md, "Detector
#: bias"). The default of :func:`detector_bias_for`.
DETECTOR_OFFSET_M = 0.5e-3


def detector_bias_for(metadata) -> float:
    """The default detector offset (metres, per axis) of a session from its metadata
    record: 0 for ``pslog simulate`` sessions (projected truth plus white noise: no bias),
    else :data:`DETECTOR_OFFSET_M` (detections found in images by pslog's detector —
    ``record``, ``record --synthetic``, ``redetect``, ``live`` — or by another, ``import``)."""
    metadata = metadata or {}
    simulated = str(metadata.get("source", "")).startswith("pslog simulate") or any(
        str(k).startswith("simulate.") for k in metadata)
    return 0.0 if simulated else DETECTOR_OFFSET_M


def offline_confirmation(options: FusionOptions) -> FusionOptions:
    """``options`` with typeA's offline confirmation where ``confirm_every``,
    ``confirm_sides`` and ``confirm_breaks`` are None: every point confirmed on each
    camera's side of a kick, with ``confirm_gaps`` (session 35: the points just after an
    unseen kick; a stream cannot wait for it), and the points spanning a kick instant its
    images show replaced by the backward pass's (``confirm_breaks``, session 45), as
    ``pslog fuse`` runs it; an explicit choice kept (``confirm_every`` given alone: its own
    test, ``confirm_sides`` off, as in :func:`fuse` and before session 35;
    ``confirm_breaks`` None follows ``confirm_sides``)."""
    if options.confirm_every is None:
        every = options.confirm_gaps
        sides = every if options.confirm_sides is None else options.confirm_sides
    else:
        every = options.confirm_every
        sides = bool(options.confirm_sides) if options.confirm_sides is not None else False
    breaks = bool(sides) if options.confirm_breaks is None else options.confirm_breaks
    if (every, sides, breaks) == (options.confirm_every, options.confirm_sides,
                                  options.confirm_breaks):
        return options
    return replace(options, confirm_every=every, confirm_sides=sides, confirm_breaks=breaks)


def for_session(options: FusionOptions, metadata, rig: Rig | None = None,
                rig_metadata=None) -> FusionOptions:
    """``options`` with the session's defaults where they are None: the detector offset
    (:func:`detector_bias_for`), typeA's offline confirmation of every point on each
    camera's side of a kick (:func:`offline_confirmation`) and, given the ``rig`` fused
    with, the covariance of its clocks that ``pslog sync`` stored in the metadata
    (:func:`pslog.timing.read_clock_covariance`: the estimates the rig still holds; none
    for a session never synced). ``rig_metadata``: the metadata of the session file ``rig``
    came from (``pslog fuse --rig SYNCED.mcap``, :func:`pslog.rig.resolve_rig`'s
    ``metadata``), whose sync's covariance goes with its clocks where it has one (session
    38: they came without it, and std_m held the pixel noise alone, silently)."""
    if options.detector_offset_m is None:
        options = replace(options, detector_offset_m=detector_bias_for(metadata))
    options = offline_confirmation(options)
    if rig is not None and options.clock_covariance is None:
        from ..timing import read_clock_covariance

        clock = read_clock_covariance(rig, rig_metadata or {})
        if clock is None:
            clock = read_clock_covariance(rig, metadata or {})
        if clock is not None:
            options = replace(options, clock_covariance=clock)
    return options


@dataclass(frozen=True)
class Method:
    """One fusion method: a registry entry (adding a method is adding one).

    Attributes
    ----------
    name : str, as on the command line
    function : ``function(prepared, rig, options) -> Track``; ``options.max_gap_s`` is set;
        a causal method without a ``streamer`` also takes the keyword ``drops`` (a list to
        which it adds each dropped point's reason, time and camera:
        :data:`pslog.fusion.stereo.Drops`): its window stream counts the settled ones
        (:class:`~pslog.fusion.stream.StreamFuser`), so its ``dropped`` equals the batch's
    causal : bool, a point at ``t`` uses no detection after ``t`` (plus the tolerance when
        ``waits_tolerance``): the method can stream (:class:`~pslog.fusion.stream.StreamFuser`);
        False: offline only
    waits_tolerance : bool, a point is settled only once the tolerance has passed (the methods
        that group simultaneous detections)
    needs : frozenset of ``"shared"`` (instants two cameras share) and ``"alone"`` (instants
        only one camera has): the timings the method suits (empty: every timing)
    description : one line
    reference : where the method comes from
    streamer : ``streamer(rig, options)`` -> an object whose ``push(time_ns, camera, uv,
        frame_index) -> Track`` takes each admitted detection once, in order (the method's
        incremental form, which :class:`~pslog.fusion.stream.StreamFuser` then uses instead
        of re-running ``function`` on a window); None: no such form
    kernels : the modules of the numba kernels the method runs (:func:`pslog._jit.preload`
        starts them early; none for a numpy-only method)
    uses_doubt : bool, it takes the doubt of the gate's choices (:attr:`Prepared.doubt_px2`,
        docs/methods.md "A choice in doubt"): in its covariance (``sync``, ``nearest``,
        ``typeB``, ``linear``), by withholding the points resting on a choice in doubt
        (``typeA``), or by leaving such a choice out (``filter``, ``smooth``); the gate makes
        it only for a form such a method fuses
    doubt : which choices' doubt it takes: True, every one's; ``"start"``, only the
        contested choices' and their camera's later choices at their pixel (``smooth``:
        the regular doubt's choices are mostly the ball's own, and its covariance on
        dirty sessions was calibrated without them; docs/methods.md, "A contested start")
    own_clock_consider : its function adds ``options.clock_covariance``'s consider
        covariance itself (``smooth``: through the fit's sensitivity); False: :func:`fuse`
        adds it by re-running the method (:func:`pslog.fusion.clock.with_clock_covariance`)
    """

    name: str
    function: Callable[[Prepared, Rig, FusionOptions], Track]
    causal: bool
    waits_tolerance: bool
    needs: frozenset[str]
    description: str
    reference: str
    streamer: Callable | None = None
    kernels: tuple[str, ...] = ()
    uses_doubt: bool = False
    doubt: Literal[True, "start"] = True
    own_clock_consider: bool = False

    def suits(self, shared: bool, alone: bool) -> bool:
        """True if a session with (or without) shared and lone instants suits the method."""
        have = {"shared"} if shared else set()
        if alone:
            have.add("alone")
        return self.needs <= have


def _gap(options: FusionOptions) -> float:
    """``options.max_gap_s`` as a method gets it: never None (:func:`fuse` resolves it)."""
    return cast(float, options.max_gap_s)


def _sync(prep: Prepared, rig: Rig, options: FusionOptions, *, drops: Drops | None = None
          ) -> Track:
    return fuse_sync(prep, options.tolerance_s, options.noise_px, _gap(options), drops=drops)


def _nearest(prep: Prepared, rig: Rig, options: FusionOptions, *, drops: Drops | None = None
             ) -> Track:
    return fuse_nearest(prep, _gap(options), options.noise_px, drops=drops)


def _type_a(prep: Prepared, rig: Rig, options: FusionOptions, *,
            breaks_ns: np.ndarray | Callable[[], np.ndarray] | None = None,
            wanted: np.ndarray | None = None) -> Track:
    """Type A's offline track (``breaks_ns``: ``confirm_breaks``' kick instants, given or a
    callable giving them; None: ``break_source``'s, the images' jumps or the fit of ``prep``:
    :func:`_across_kicks`). ``wanted`` ((k,) int64 :func:`pslog.records.
    point_keys`, or None: every point): only the points on these detections are kept, each
    with the bits it has in the whole track (the kernel still runs on every detection: its
    tests' noise is a causal median over every point; the confirmation and the covariance's
    rescale are elementwise: :func:`pslog.fusion.confirm.confirm_batch`'s ``only``)."""
    from ._prepare import rays_only
    from .confirm import confirm_batch  # (long-gap points confirmed by the next camera)
    from .pseudo import _fuse_type_a, covariance_noise_px, type_a_noise, withhold_uncertain

    # the covariance made at the stated noise (what the confirmation's test reads), then
    # rescaled to the session's measured noise (docs/methods.md, "Type A's covariance at
    # the measured noise"), in the kernel's quality table when the track is still the one
    # made here (no copy: docs/performance.md); a detection without a ray is a missing one
    prep = rays_only(prep)[0]
    gap = _gap(options)
    table: list = []
    made = _fuse_type_a(prep, gap, options.noise_px, None, None, None, False,
                        covariance_noise_px(options.noise_px), table)[0]
    only = (None if wanted is None
            else matching_rows(point_keys(made.time_ns, made.camera), wanted)[1])
    if options.confirm_gaps:
        track = confirm_batch(prep, made, rig, gap, options.noise_px,
                              every=bool(options.confirm_every),
                              sides=bool(options.confirm_sides), only=only)
    else:
        track = made if only is None else made.select(only)
    track = withhold_uncertain(type_a_noise(prep, track, gap, options.noise_px,
                                            table[0] if table and track is made else None),
                               options.max_std_m)[0]
    if options.confirm_breaks:
        del made, table  # (the kernel's own track and quality table: the backward pass's
        # is made next, and a 90-minute match's are 150 MB)
        track = _across_kicks(prep, track, rig, options, breaks_ns)
    return track


def _across_kicks(prep: Prepared, track: Track, rig: Rig, options: FusionOptions,
                  breaks_ns: np.ndarray | Callable[[], np.ndarray] | None = None) -> Track:
    """Type A's ``track`` from ``prep`` (rays only) under ``confirm_breaks``: each point
    spanning a kick instant replaced by the backward pass's or withheld
    (:func:`pslog.fusion.breaks.across_breaks`); the instants ``breaks_ns``, or the images'
    (``break_source="image"``: :func:`pslog.fusion.breaks.image_kicks_ns`, the track's
    points giving the depths), or the fit of ``prep``."""
    from .breaks import across_breaks, image_kicks_ns

    if options.break_source == "image" and breaks_ns is None:
        breaks_ns = image_kicks_ns(prep, track, rig, options)
    return across_breaks(prep, track, rig, options, _type_a, breaks_ns)


def _type_a_stream(rig: Rig, options: FusionOptions):
    from .confirm import ConfirmedStream
    from .pseudo import MeasuredNoiseStream, TypeAStream, covariance_noise_px

    if options.confirm_breaks:
        raise FusionError("typeA's confirm_breaks is offline only (a point may wait for the "
                          "detections after it as long as the ball flies): fuse the session "
                          "instead")
    if options.confirm_gaps and options.confirm_every:
        raise FusionError("typeA's confirm_every is offline only (a point may wait for the "
                          "next camera as long as a stream pauses): fuse the session instead")
    stream = TypeAStream(rig, options, covariance_noise_px(options.noise_px))
    inner = ConfirmedStream(stream, rig, options) if options.confirm_gaps else stream
    return MeasuredNoiseStream(inner, rig, options)


def _type_b(prep: Prepared, rig: Rig, options: FusionOptions, *, drops: Drops | None = None
            ) -> Track:
    return fuse_predicted(prep, "typeB", options.tolerance_s, _gap(options), options.noise_px,
                          drops=drops)


def _linear(prep: Prepared, rig: Rig, options: FusionOptions, *, drops: Drops | None = None
            ) -> Track:
    return fuse_predicted(prep, "linear", options.tolerance_s, _gap(options), options.noise_px,
                          drops=drops)


def _filter(prep: Prepared, rig: Rig, options: FusionOptions) -> Track:
    from .filter import FilterOptions, fuse_filter

    return fuse_filter(prep.obs, rig, options.max_gap_s,
                       FilterOptions(hold_nis=options.filter_hold_nis), doubt=prep.doubt_px2)


def _filter_stream(rig: Rig, options: FusionOptions):
    from .filter import FilterStream

    return FilterStream(rig, options)


def _smooth(prep: Prepared, rig: Rig, options: FusionOptions, *,
            fitted: Callable[[], tuple] | None = None) -> Track:
    """``smooth``'s track (``fitted``: its session fit made once, shared with type A's
    ``confirm_breaks``, :class:`pslog.fusion.breaks.SessionFit`'s ``fitted``)."""
    from .smooth import fuse_smooth  # scipy is imported only when smooth runs

    return fuse_smooth(prep, rig, options, None if fitted is None else fitted())


_PAPER = "Fujiyoshi et al., RoboCup 2004"
#: The fusion methods by name, in the order tables list them.
METHODS: dict[str, Method] = {m.name: m for m in (
    Method("sync", _sync, True, True, frozenset({"shared"}),
           "ordinary stereo of simultaneous detections (paper: synchronized)",
           f"{_PAPER}, Table 1", uses_doubt=True),
    Method("nearest", _nearest, True, False, frozenset({"alone"}),
           "latest detection of the other cameras, as if simultaneous (paper: unsynchronized)",
           f"{_PAPER}, Table 1", uses_doubt=True),
    Method("typeA", _type_a, True, False, frozenset({"alone"}),
           "pseudo stereo at every detection (paper section 2.2, eqs. 1-4)",
           f"{_PAPER}, section 2.2", streamer=_type_a_stream,
           kernels=("pslog.fusion._pseudo_kernel", "pslog.fusion._confirm_kernel"),
           uses_doubt=True),
    Method("typeB", _type_b, True, True, frozenset({"shared", "alone"}),
           "stereo at common instants + ray-constrained prediction (paper section 2.3)",
           f"{_PAPER}, section 2.3", uses_doubt=True),
    Method("linear", _linear, True, True, frozenset({"shared", "alone"}),
           "stereo at common instants + linear prediction (paper: linear prediction)",
           f"{_PAPER}, Table 1", uses_doubt=True),
    Method("smooth", _smooth, False, False, frozenset(),
           "one continuous trajectory fitted to every detection's ray (offline)",
           "continuous-time batch estimation: Furgale et al. 2013; Singer 1970 motion prior",
           kernels=("pslog.estimation", "pslog.estimation._kernels"), uses_doubt=True,
           doubt="start", own_clock_consider=True),
    Method("filter", _filter, True, False, frozenset(),
           "causal extended Kalman filter with bounce/kick gating, a point at every detection",
           "Bar-Shalom, Li & Kirubarajan 2001 (EKF, NIS gate); docs/methods.md",
           streamer=_filter_stream, kernels=("pslog.fusion.filter",), uses_doubt=True),
)}


def causal_methods() -> list[str]:
    """Names of the methods that can stream, in :data:`METHODS` order."""
    return [name for name, m in METHODS.items() if m.causal]


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


def default_tolerance(rig: Rig) -> float:
    """The tolerance used where none was given, seconds: :class:`FusionOptions`' 1 ms where
    that is below a third of the rig's shortest frame period (cameras up to 333 fps), else a
    tenth of that period (0.2 ms at 500 fps: 1 ms was refused by :func:`check_tolerance`, and
    ``pslog fuse`` of such a session failed without ``--tolerance-ms``)."""
    tolerance = FusionOptions.tolerance_s
    fastest = min(c.frame_period for c in rig.cameras)
    return tolerance if tolerance < fastest / 3 else fastest / 10


def check_method(method: str) -> str:
    if method not in METHODS:
        raise FusionError(f"unknown fusion method {method!r} (have {', '.join(METHODS)})")
    return method


#: Least share of a session's instants (groups of detections within the tolerance) that two
#: or more cameras share for :func:`default_methods` to pick the methods that need shared
#: instants (``sync``, ``typeB``, ``linear``). Measured (tolerance 1 ms, 30 fps): synchronised
#: shutters share 100 % of their instants, the ``typeB`` preset (two of three synchronised)
#: 50 %, three staggered rolling-shutter webcams after ``pslog sync`` 0-2.7 % (six sessions,
#: simulated and rendered; 15-47 chance coincidences of the readout-corrected times), random
#: offsets with 8-30 ms readouts 0-21 % (14 % with two cameras 0.9 ms apart); held out at 60
#: fps 0-50 %: staggered rigs under 3 %, a pair within ~1 ms 14 % or more (docs/timing.md).
SHARED_SHARE_MIN = 0.1


def default_methods(
    observations: Observations | Detections, rig: Rig, options: FusionOptions | None = None,
    *, gated: dict | None = None,
) -> list[str]:
    """The methods worth running on these detections' timing, in :data:`METHODS` order.

    Stereo (``sync``) needs instants that two cameras share; pseudo stereo and its baseline
    (``typeA``, ``nearest``) need instants that only one camera has (with fully synchronised
    shutters they would only repeat each instant); ``typeB`` and ``linear`` need both.
    Shared instants count only when they are at least :data:`SHARED_SHARE_MIN` of the
    session's instants (groups of :func:`~pslog.fusion.stereo.sync_groups`): staggered
    rolling shutters whose corrected times now and then fall within the tolerance share a
    few percent, too few for stereo or for ``typeB``'s predictions between them.

    Given Detections, the instants are each frame's best-scored candidate's; where the
    methods' choice could move them (``options.gating``, a rig with rolling shutters: a
    readout-corrected time is its candidate's row's; frames of several candidates), they
    are those of each frame's ball as the methods choose it
    (:func:`pslog.fusion.gating.gate`), whether the best-scored ones share or not (review39:
    a ``typeB`` pair with 8 ms readouts and a static object in one camera, best-scored 9.8 %
    shared, the ball as chosen 15.4 %: ``sync``, ``typeB`` and ``linear`` were left out).
    (Walk38: a static second orange object, best-scored in most frames of a synced
    three-webcam session, lay at rows whose corrected times fell within 1 ms in two
    cameras: 16-19 % of the instants shared, so sync, typeB and linear ran by default on
    12-29 points up to 0.94 m off, or, on a 4 s session, sync found no shared instant among
    the gate's choices and the whole ``pslog fuse`` stopped, exit 1; the ball's own instants
    share 0-0.6 %.)

    ``gated``: a dict that keeps that gating pass for the fusion
    (:func:`pslog.fusion.gating.start_fusion`'s ``gated``: the causal form without a wait,
    with every choice's doubt, and the forms' shared part), which then gates in that form
    no more; left empty where no pass was made.
    """
    options = options or FusionOptions()
    check_tolerance(rig, options.tolerance_s)
    detections = observations if isinstance(observations, Detections) else None
    timed = timed_observations(detections, rig) if detections is not None else observations

    def shares(obs: Observations) -> tuple[bool, bool]:
        _, n_cameras = sync_groups(obs, len(rig), options.tolerance_s)
        return (bool(len(n_cameras)) and bool(
            np.count_nonzero(n_cameras >= 2) >= SHARED_SHARE_MIN * len(n_cameras)),
            bool(np.any(n_cameras == 1)))

    assert isinstance(timed, Observations)
    shared, alone = shares(timed)
    if (detections is not None and options.gating and len(rig) >= 2
            and any(c.readout for c in rig.cameras)
            and np.any(detections.candidates_per_frame() > 1)):
        # (the gate only where its choice could move the instants; ~0.1 ms a frame of
        # several candidates, the fusion's own causal pass where ``gated`` hands it on)
        from .gating import gate, gate_common, gate_for, gating_key, pregated

        common = gate_common(detections, rig)
        # handed on: smooth's offline pass made meanwhile on a thread (smooth suits every
        # timing: it is fused by default), as its own gate_for makes it (session 40: on a
        # 90-minute dirty match its ~2 s then no longer wait for this pass before smooth)
        offline: dict = {}
        thread = None
        if gated is not None:
            def smooth_pass() -> None:
                try:
                    offline["gated"] = gate_for(detections, rig, "smooth", options,
                                                lambda: common)
                except BaseException as exc:  # (raised again below, on this thread)
                    offline["error"] = exc

            thread = threading.Thread(target=smooth_pass, name="pslog-gate-offline",
                                      daemon=True)
            thread.start()
        try:
            chosen = gate(detections, rig, max_gap_s=options.max_gap_s,
                          common=lambda: common, doubt=gated is not None)
        finally:
            if thread is not None:
                thread.join()
        if "error" in offline:
            raise offline["error"]
        if gated is not None:  # (its doubt made only where the fusion will take it)
            gated.update(pregated(chosen, common))
            key = gating_key("smooth", options)
            gated.update(pregated(offline["gated"], common, key,
                                  METHODS["smooth"].uses_doubt and METHODS["smooth"].doubt))
        shared, alone = shares(chosen.observations)
    return [name for name, m in METHODS.items() if m.suits(shared, alone)]


def fuse(
    observations: Observations | Detections, rig: Rig, method: str,
    options: FusionOptions | None = None, *, prepared: Prepared | None = None,
    smooth_fit: SessionFit | None = None,
) -> Track:
    """Fuse one session's detections into a 3D track.

    Parameters
    ----------
    observations : Observations, or Detections (each frame's ball is chosen among its
        candidates by :func:`pslog.fusion.gating.gate` in the form the method needs, or with
        ``options.gating`` False the best-scored one is used; at its true time by the rig's
        timing model: :func:`pslog.timing.observations`)
    rig : Rig, whose camera order the observations' camera indices refer to
    method : one of :data:`METHODS`
    options : FusionOptions
    prepared : the result of :func:`prepare` for these observations, to share between methods
    smooth_fit : :class:`pslog.fusion.breaks.SessionFit` of ``smooth``'s fit of this
        session, to share between ``smooth`` (its track) and ``typeA`` with
        ``confirm_breaks`` (its kick instants): fitted once (:func:`pslog.fusion.gating.
        start_fusion`); None: ``smooth`` fits here, and typeA's ``confirm_breaks`` fits
        ``smooth``'s input of these observations (Detections: gated as ``smooth`` gates
        them), so its points are the same whether ``smooth`` is fused beside it or not

    Returns
    -------
    Track, sorted by time, without NaN points; the paper's methods drop geometrically
    invalid points (behind or out of view of a camera that made them, near-parallel rays)
    and count them in ``Track.dropped`` (docs/paper.md)
    """
    check_method(method)
    options = options or FusionOptions()
    given = observations
    if isinstance(observations, Detections):
        from .gating import gate_for, prepared_for

        if options.gating and len(rig) >= 2:
            gated = gate_for(observations, rig, method, options)
            observations = gated.observations
            if prepared is None and gated.doubt_px2 is not None:
                prepared = prepared_for(gated, rig)
        else:
            observations = timed_observations(observations, rig)
    if len(rig) < 2:
        raise FusionError(f"fusion needs at least two cameras; rig has {len(rig)}")
    check_tolerance(rig, options.tolerance_s)
    prep = prepared if prepared is not None else prepare(observations, rig)
    resolved = replace(options, max_gap_s=options.max_gap_s or default_max_gap_s(rig))
    function = METHODS[method].function
    if method == "smooth" and smooth_fit is not None:
        function = partial(_smooth, fitted=smooth_fit.fitted)
    elif method == "typeA" and resolved.confirm_breaks and resolved.break_source == "fit":
        fit = (smooth_fit if smooth_fit is not None
               else _smooth_fit_of(given, prep, rig, options))
        # (called once the forward track is made: a fit made meanwhile is not waited for;
        # type A's use of the fit released then: the backward pass does not hold it)
        breaks: np.ndarray | Callable[[], np.ndarray] = fit.take_breaks
        if options.clock_covariance is not None:
            # the breaks of the session's fit are a decision, taken as it was in the
            # clocks' perturbed runs (pslog.fusion.clock): fitted once, not once per run
            # (2 m + 1 fits of smooth for m clock directions otherwise)
            breaks = fit.take_breaks()
        function = partial(_type_a, breaks_ns=breaks)
    elif (method == "typeA" and resolved.confirm_breaks and options.clock_covariance is not None):
        function = type_a_with_kicks_of(prep, rig, resolved)
    track = function(prep, rig, resolved)
    if options.clock_covariance is not None and not METHODS[method].own_clock_consider:
        from .clock import with_clock_covariance

        track = with_clock_covariance(track, method, prep, rig, resolved, function)
    return track


def type_a_with_kicks_of(prep: Prepared, rig: Rig, options: FusionOptions
                         ) -> Callable[[Prepared, Rig, FusionOptions], Track]:
    """Type A under ``confirm_breaks`` with the images' kick instants of ``prep`` taken once
    (``options``: ``max_gap_s`` resolved): the method as the clocks' perturbed runs take it
    (:func:`pslog.fusion.clock.with_clock_covariance`'s ``function``; the instants are a
    decision, taken as it was in those runs, as :func:`fuse` takes the fit's breaks)."""
    from ._prepare import rays_only
    from .breaks import image_kicks_ns

    rays = rays_only(prep)[0]
    forward = _type_a(rays, rig, replace(options, confirm_breaks=False,
                                         break_source=BREAK_SOURCES[0]))
    return partial(_type_a, breaks_ns=image_kicks_ns(rays, forward, rig, options))


def _smooth_fit_of(observations: Observations | Detections, prep: Prepared, rig: Rig,
                   options: FusionOptions):
    """The :class:`~pslog.fusion.breaks.SessionFit` of ``smooth``'s input of a session that
    :func:`fuse` fuses with typeA's ``confirm_breaks`` alone (:func:`pslog.fusion.breaks.
    shared_fit` for type A without ``smooth``: no clocks' consider covariance, the breaks do
    not need it): Detections gated as ``smooth`` gates them (with ``options.gating`` and two
    cameras or more; as :func:`fuse` gates), else ``prep`` (every method's)."""
    from .breaks import shared_fit

    if isinstance(observations, Detections) and options.gating and len(rig) >= 2:
        from .gating import gate_for, prepared_for

        detections = observations
        return shared_fit(("typeA",), rig, options, lambda: prepared_for(
            gate_for(detections, rig, "smooth", options), rig))
    return shared_fit(("typeA",), rig, options, lambda: prep)


def fuse_all(
    observations: Observations | Detections, rig: Rig, methods: Sequence[str],
    options: FusionOptions | None = None,
) -> dict[str, Track]:
    """Several methods over one session, sharing the undistortion and rays (and, for
    Detections, the gating: :func:`pslog.fusion.gating.fuse_detections`, which also returns
    the rejections)."""
    for method in methods:
        check_method(method)
    if isinstance(observations, Detections) and (options or FusionOptions()).gating:
        from .gating import fuse_detections

        if len(rig) < 2:
            raise FusionError(f"fusion needs at least two cameras; rig has {len(rig)}")
        check_tolerance(rig, (options or FusionOptions()).tolerance_s)
        return fuse_detections(observations, rig, methods, options)[0]
    if isinstance(observations, Detections):
        observations = timed_observations(observations, rig)
    if len(rig) < 2:
        raise FusionError(f"fusion needs at least two cameras; rig has {len(rig)}")
    check_tolerance(rig, (options or FusionOptions()).tolerance_s)
    prep = prepare(observations, rig)
    from .breaks import fit_shared, shared_fit  # (typeA's confirm_breaks and smooth)

    resolved = options or FusionOptions()
    fit = (shared_fit(methods, rig, resolved, lambda: prep)
           if fit_shared(methods, rig, resolved) else None)
    tracks = {}
    for m in methods:
        uses = m in ("typeA", "smooth")
        tracks[m] = fuse(observations, rig, m, options, prepared=prep,
                         smooth_fit=fit if uses else None)
        if uses and fit is not None:
            fit.release(m)
    return tracks


def explain_type_a(
    observations: Observations | Detections, rig: Rig, options: FusionOptions | None = None
) -> TypeAConstruction:
    """The paper's Figure 2 construction behind every type-A point (see TypeAConstruction)."""
    options = options or FusionOptions()
    if isinstance(observations, Detections):
        prep = type_a_prepared(observations, rig, options)[1]
    else:
        prep = prepare(observations, rig)
    return type_a_explained(prep, rig, options)[1]


def type_a_prepared(detections: Detections, rig: Rig, options: FusionOptions | None = None
                    ) -> tuple[Observations, Prepared]:
    """The observations type A fuses from ``detections`` as :func:`fuse` chooses them
    (gated with ``options.gating`` and two cameras or more, else the timed best candidates;
    the rows a construction's ``event_row`` indexes) and their preparation, with the doubt
    of the gate's choices (the points resting on one in doubt are left out)."""
    options = options or FusionOptions()
    if options.gating and len(rig) >= 2:
        from .gating import gate_for, prepared_for

        gated = gate_for(detections, rig, "typeA", options)
        return gated.observations, prepared_for(gated, rig)
    observations = timed_observations(detections, rig)
    return observations, prepare(observations, rig)


def type_a_explained(prep: Prepared, rig: Rig, options: FusionOptions
                     ) -> tuple[Track, TypeAConstruction]:
    """``typeA``'s track as :func:`fuse` makes it from ``prep`` (the long-gap confirmation
    of :mod:`pslog.fusion.confirm` included when ``options.confirm_gaps``, and the points
    spanning a kick replaced by the backward pass's with ``options.confirm_breaks``) and the
    construction of each of its points (the points the confirmation drops, and those
    withheld as ``uncertain`` or ``break``, left out too; a point made from the detections
    after it, ``span_s`` < 0, has none: the construction is of the others). With the
    ``"fit"`` break source the instants are the fit of ``prep`` (:func:`fuse` takes
    ``smooth``'s own input's)."""
    from ._prepare import rays_only
    from .pseudo import covariance_noise_px, type_a_noise, withhold_uncertain

    max_gap_s = options.max_gap_s or default_max_gap_s(rig)
    prep, kept_rows = rays_only(prep)  # (as _type_a: a detection without a ray is missing)
    track, construction = fuse_type_a(prep, max_gap_s, options.noise_px,
                                      cov_noise_px=covariance_noise_px(options.noise_px))
    if kept_rows is not None:  # (the construction's rows: of the observations given)
        construction = construction.on_rows(kept_rows)
    if not options.confirm_gaps or not len(track):
        out, kept = withhold_uncertain(type_a_noise(prep, track, max_gap_s, options.noise_px),
                                       options.max_std_m)
        return out, construction if kept is None else construction.select(kept)
    from .confirm import confirm_batch

    confirmed = type_a_noise(prep, confirm_batch(prep, track, rig, max_gap_s, options.noise_px,
                                                 every=bool(options.confirm_every),
                                                 sides=bool(options.confirm_sides)),
                             max_gap_s, options.noise_px)
    confirmed = withhold_uncertain(confirmed, options.max_std_m)[0]
    forward: np.ndarray | slice = slice(None)
    if options.confirm_breaks:
        confirmed = _across_kicks(prep, confirmed, rig, replace(options, max_gap_s=max_gap_s))
        forward = ~(confirmed.quality["span_s"] < 0)
    elif len(confirmed) == len(track):
        return confirmed, construction
    # the construction's rows are the track's points, in order; the confirmation only drops
    # (a point: its time and camera, keyed as one int64)
    kept = np.isin(point_keys(track.time_ns, track.camera),
                   point_keys(confirmed.time_ns[forward], confirmed.camera[forward]))
    return confirmed, construction.select(kept)


__all__ = [
    "DETECTOR_OFFSET_M", "METHODS", "FusionOptions", "Method", "Prepared", "PseudoStereoPoints",
    "TypeAConstruction", "causal_methods", "check_method", "check_tolerance",
    "confirm_choice", "default_methods", "default_tolerance",
    "detector_bias_for", "explain_type_a", "for_session", "fuse", "fuse_all",
    "offline_confirmation", "prepare", "pseudo_stereo_points", "type_a_prepared",
    "type_a_with_kicks_of",
]
