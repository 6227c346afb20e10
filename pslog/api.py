"""pslog's Python API: a session in, clocks, tracks and accuracy out, in four typed calls.

The command line is built on the same functions; a script that needs more reaches into the
modules they name (:mod:`pslog.fusion`, :mod:`pslog.estimation.sync`, :mod:`pslog.evaluation`,
:mod:`pslog.log`). A walk-through is in docs/python.md::

    import pslog

    session = pslog.read_session("throw.mcap")
    clocks = pslog.sync(session, estimate=("offset", "drift"))
    tracks = pslog.fuse(session, rig=clocks.rig)
    for method, accuracy in pslog.evaluate(tracks, session.truth).items():
        print(method, f"{accuracy.mean_mm:.2f} mm")

Units are SI (metres, seconds; times as integer nanoseconds on the session's clock), as
everywhere in pslog; only :class:`pslog.evaluation.Accuracy` reports millimetres, being a
human-facing summary.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np

from .errors import FusionError, InputError, shown
from .records import NS, Detections, Observations, Track, Truth

if TYPE_CHECKING:  # the heavy modules load when first called, not at `import pslog`
    from .estimation.sync import SyncResult
    from .evaluation import Accuracy
    from .fusion import FusionOptions
    from .fusion.gating import Rejections
    from .log.reader import Session
    from .rig import Rig
    from .timing import ShutterPhases

__all__ = ["FuseResult", "SyncOutcome", "evaluate", "fuse", "read_session", "sync"]

def read_session(path: str | os.PathLike[str]) -> Session:
    """Read a session's MCAP file (its rig, detections, truth, fused tracks; never its images).

    Parameters
    ----------
    path : the session's ``.mcap`` file

    Returns
    -------
    :class:`pslog.log.reader.Session`

    Raises
    ------
    pslog.errors.InputError, pslog.errors.LogFormatError : missing, unreadable or not a session
        (or ``path`` not a file name)
    """
    from .log import read_session as _read

    if not isinstance(path, (str, os.PathLike)):  # (a TypeError from deep inside, before)
        raise InputError(f"read_session: path {shown(path)}: give a file name (str or Path)")
    return _read(path)


def _session(session: Session | str | os.PathLike[str]) -> Session:
    if isinstance(session, (str, os.PathLike)):
        return read_session(session)
    return session


@dataclass(frozen=True)
class FuseResult(Mapping[str, Track]):
    """:func:`fuse`'s tracks by method name (a read-only mapping), with what gating rejected.

    Attributes
    ----------
    tracks : method -> Track (points in metres, times in ns on the session clock)
    rejections : method -> :class:`pslog.fusion.gating.Rejections` (empty without gating)
    """

    tracks: dict[str, Track]
    rejections: dict[str, Rejections] = field(default_factory=dict)

    def __getitem__(self, method: str) -> Track:
        return self.tracks[method]

    def __iter__(self) -> Iterator[str]:
        return iter(self.tracks)

    def __len__(self) -> int:
        return len(self.tracks)


def _names(value: object, what: str) -> list[str] | None:
    """A name list from a comma-separated string or a sequence of names (None: not given):
    the same rule as the command line's ``--method`` / ``--estimate`` (an empty string or list,
    an empty name, or anything but text, is an :class:`InputError` naming the value)."""
    if value is None:
        return None
    if isinstance(value, str):
        names = [name.strip() for name in value.split(",")]
    elif isinstance(value, Sequence) and all(isinstance(v, str) for v in value):
        names = [name.strip() for name in value]
    else:
        raise InputError(f"{what} {value!r}: give a name, a comma-separated string or a "
                         f"list of names")
    if not names or not all(names):
        raise InputError(f"{what} {value!r}: name one, or several separated by commas")
    return list(dict.fromkeys(names))


def fuse(session: Session | str | os.PathLike[str] | Detections,
         methods: str | Sequence[str] | None = None, *,
         rig: Rig | str | os.PathLike[str] | None = None,
         options: FusionOptions | None = None,
         clock_uncertainty: bool = True) -> FuseResult:
    """Fuse a session's detections into one 3D track per method, as ``pslog fuse`` does.

    Parameters
    ----------
    session : a :class:`Session`, its path, or bare :class:`Detections` (then ``rig`` is
        required)
    methods : a method name, several, or a comma-separated list; default every method the
        session's timing suits (:func:`pslog.fusion.default_methods`)
    rig : a corrected rig (same camera names and order) instead of the session's; e.g.
        ``pslog.sync(session).rig``; or, as ``pslog fuse --rig``, a built-in rig's name or a
        rig file (pslog's TOML, its whole rig; or an aniposelib / Pose2Sim / OpenCV
        calibration, its geometry only: the session's frame rates, offsets and clocks stay).
        A synced copy's clocks come with its sync's covariance when ``rig`` is the copy's
        path; a :class:`~pslog.rig.Rig` object carries no metadata, so its clocks count as
        exact unless ``options.clock_covariance`` gives their covariance
        (:func:`pslog.timing.read_clock_covariance` of the rig and the copy's metadata)
    options : :class:`pslog.fusion.FusionOptions` (tolerance, max gap, noise, gating); its
        ``detector_offset_m`` None takes the session's default
        (:func:`pslog.fusion.detector_bias_for`: 0 for simulated sessions and bare
        detections, 0.5 mm per axis for detections found in images); its
        ``confirm_every``, ``confirm_sides`` and ``confirm_breaks`` None turn typeA's
        offline confirmation on (:func:`pslog.fusion.offline_confirmation`: every point
        checked on each other camera's side of a kick, and the points spanning a kick the
        images show made from the detections after them: ``pslog fuse``'s default
        ``--confirm-gaps jumps``, session 45), for bare detections too
    clock_uncertainty : a session synced by ``pslog sync`` (and ``options.clock_covariance``
        None): every point's covariance gains the uncertainty of the clocks it estimated
        and the rig still holds (:mod:`pslog.fusion.clock`), as ``pslog fuse
        --clock-uncertainty on``; False: the clocks taken as exact

    Returns
    -------
    FuseResult : method -> Track, and the gating's rejections

    Raises
    ------
    pslog.errors.FusionError : unknown method, fewer than two cameras, no detection
    pslog.errors.InputError : ``methods`` empty or not names; ``rig``, ``options`` or
        ``clock_uncertainty`` not of a type named above
    pslog.errors.RigError : a rig whose cameras differ from the session's, or a bad rig file
    """
    from . import progress
    from .fusion import (
        FusionOptions,
        check_method,
        default_methods,
        default_tolerance,
        for_session,
        offline_confirmation,
    )
    from .fusion.gating import fuse_detections
    from .rig import Rig, check_baselines, resolve_rig

    names = _names(methods, "methods")
    # (each an AttributeError from inside before; clock_uncertainty="off" was taken as on)
    if rig is not None and not isinstance(rig, (Rig, str, os.PathLike)):
        raise InputError(f"rig {shown(rig)}: give a Rig, a built-in rig's name or a rig file")
    if options is not None and not isinstance(options, FusionOptions):
        raise InputError(f"options {shown(options)}: give a pslog.fusion.FusionOptions")
    # (numpy's bools too, np.True_: a flag taken from an array)
    if not isinstance(clock_uncertainty, (bool, np.bool_)):
        raise InputError(f"clock_uncertainty {shown(clock_uncertainty)}: give True or False")
    clock_uncertainty = bool(clock_uncertainty)
    if isinstance(session, Detections):
        if rig is None:
            raise InputError("fuse(detections): give the rig the detections belong to")
        if isinstance(rig, (str, os.PathLike)):
            rig = resolve_rig(os.fspath(rig))
        detections, used = session, rig
    else:
        read = _session(session)
        rig_metadata: dict[str, str] = {}  # (a session file's: its sync's clock covariance)
        if isinstance(rig, (str, os.PathLike)):
            rig = resolve_rig(os.fspath(rig), timing_from=read.rig,  # a calibration: geometry
                              metadata=rig_metadata)
        detections, used = read.detections, rig or read.rig
        if options is None and isinstance(used, Rig):  # (1 ms, or less for fast cameras)
            options = FusionOptions(tolerance_s=default_tolerance(used))
        options = for_session(options or FusionOptions(), read.metadata,
                              used if clock_uncertainty else None, rig_metadata)
        if rig is not None and rig.names != read.rig.names:
            from .errors import RigError

            raise RigError(f"rig cameras {', '.join(rig.names)} differ from the session's "
                           f"{', '.join(read.rig.names)} (names and order must match)")
    if not isinstance(used, Rig):
        raise InputError(f"rig {used!r}: give a Rig, a built-in rig's name or a rig file")
    check_baselines(used, "rig")
    # (bare detections: typeA's offline confirmation as for a session, pslog fuse's)
    options = offline_confirmation(options or FusionOptions())
    if detections.n_frames == 0:
        raise FusionError("the session has no detection to fuse")
    pass_before: dict = {}  # (default_methods' gating pass, when it makes one: not made again)
    chosen = ([check_method(m) for m in names] if names is not None
              else default_methods(detections, used, options, gated=pass_before))
    progress.step(f"fusing {', '.join(chosen)}")
    tracks, rejections = fuse_detections(detections, used, chosen, options, gated=pass_before)
    return FuseResult(dict(tracks), dict(rejections))


@dataclass(frozen=True)
class SyncOutcome:
    """:func:`sync`'s result.

    Attributes
    ----------
    rig : the session's rig holding the estimated clocks (offset, drift, readout), and the
        shutter offsets measured where ``phases`` (below) was written; what ``pslog sync``
        writes into the copy
    result : :class:`pslog.estimation.sync.SyncResult` (per camera estimates with their
        standard deviations, RMS residual and pixel noise)
    detections : the detections the estimate used, on the session clock: the session's own,
        or with host timestamps regularized (``regularized`` not empty)
    observations : each frame's ball among them (gated when frames hold several candidates),
        at its logged time: what the estimator fitted
    regularized : camera name -> :class:`pslog.timing.RegularizeReport`
    notes : what was done that a user should know (regularized stamps, rejected candidates)
    prior : the clock model before any sync, recorded with the copy for the next sync: the
        session's rig, or, for a copy synced before, the one recorded before its first sync
        (:func:`pslog.timing.recorded_clocks` of every clock parameter); the estimate
        started from it and tested against it for the parameters it estimates (or auto
        tests), the others kept at the copy's values
    prior_estimated : whether ``prior`` holds clock estimates of an earlier sync that did
        not record its own starting model (a pslog before session 38), as known values: said
        in ``notes`` and recorded with the copy, so that every later sync says it too
    motion_period_s : the period (s) with which the ball's motion repeats in every camera's
        view (:func:`pslog.estimation.sync.motion_period`; a turntable), or None: offsets
        whole periods apart then fit alike, and ``notes`` says so
    phases : :class:`pslog.timing.ShutterPhases`, each camera's shutter offset measured from
        its frames' corrected times (None: ``phases="keep"``)
    phases_written : whether ``rig`` holds them (``phases="measure"``, every camera's phase
        steady and some camera's further than :data:`pslog.timing.PHASE_AGREE` of its
        frame period (or :data:`pslog.timing.PHASE_AGREE_MAX_S`) from the session rig's
        ``offset``; ``notes`` says so)
    """

    rig: Rig
    result: SyncResult
    detections: Detections
    observations: Observations
    regularized: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    prior: Rig | None = None
    prior_estimated: bool = False
    motion_period_s: float | None = None
    phases: ShutterPhases | None = None
    phases_written: bool = False


def sync(session: Session | str | os.PathLike[str],
         estimate: str | Sequence[str] = "auto", *, search_s: float | None = None,
         regularize: Literal["auto", "on", "off"] = "auto",
         phases: Literal["measure", "keep"] = "measure") -> SyncOutcome:
    """Estimate every camera's clock from the ball's detections, as ``pslog sync`` does.

    Jittery host timestamps are first replaced by a robust line against frame index
    (``regularize``: ``auto`` when a camera's jitter exceeds
    :data:`pslog.timing.REGULARIZE_AUTO_JITTER_S`); with several candidates per frame the
    ball is chosen by the gating stage; then :func:`pslog.estimation.sync.estimate_clocks`
    fits one smooth trajectory to every ray jointly with the clock parameters (docs/timing.md).

    Parameters
    ----------
    session : a :class:`Session` or its path
    estimate : ``"auto"`` (default: offsets, plus readouts and, on sessions of 30 s or more,
        drifts where a Wald test at the 0.1 % level says the data support them (readouts
        per camera and, for cameras of one model, one shared, each at half the level; a
        shared one kept is estimated one per model unless the cameras' estimates differ at
        5 %);
        ``result.selection`` holds the tests, :func:`pslog.estimation.sync.select_clocks`),
        or clock parameters among ``offset``, ``drift``, ``readout``: a name, a
        comma-separated string (``"offset,drift"``) or a sequence of names;
        ``readout=shared`` instead of ``readout``: one readout per camera model (same image
        size and frame rate), every camera of a model taking it
    search_s : scan each offset over ±search_s seconds around the rig's value (default half
        a frame period)
    regularize : ``auto``, ``on`` or ``off``
    phases : ``measure`` (default): each camera's shutter offset (the rig's ``offset``, where
        in its frame period the shutter fires) is measured from the frames' corrected times
        (:func:`pslog.timing.shutter_phases`) and the returned rig holds the measured ones
        where they differ from the rig's by more than :data:`pslog.timing.PHASE_AGREE` of a
        frame period (or :data:`pslog.timing.PHASE_AGREE_MAX_S`) and every camera's phase is
        steady (free-running cameras, whose rig says 0: type A's and the filter's tests of a
        missed frame count in their spacing; docs/timing.md, "Shutter phases"); ``keep``:
        the rig's offsets kept

    Raises
    ------
    pslog.errors.FusionError : no detection, or the estimate failed (with the likely cause)
    pslog.errors.InputError : ``estimate``, ``search_s``, ``regularize`` or ``phases`` not a
        value named above (``search_s``: seconds in [1e-9, 60])
    """
    from . import progress
    from .estimation.sync import (
        AUTO_DRIFT_MIN_S,
        PARAMETERS,
        RIG_KEY,
        SHARED_READOUT,
        ClockSpanError,
        check_search_s,
        estimate_clocks,
    )
    from .rig import Rig, check_baselines
    from .timing import (
        REGULARIZE_AUTO_JITTER_S,
        recorded_clocks,
        regularize_detections,
        regularize_times,
        shutter_phases,
    )

    try:
        wanted_params = _names(estimate, "estimate")
    except InputError as exc:
        raise InputError(f"{exc} among {', '.join(PARAMETERS)}") from None
    bad = [p for p in wanted_params or () if p not in (*PARAMETERS, SHARED_READOUT)]
    if wanted_params == ["auto"]:
        bad = []
    if {"readout", SHARED_READOUT} <= set(wanted_params or ()):
        bad = [SHARED_READOUT]  # one readout per model, or one per camera: not both
    if bad or not wanted_params:
        raise InputError(f"estimate {estimate!r}: 'auto', or name parameters among "
                         f"{', '.join(PARAMETERS)} (not {', '.join(map(repr, bad))})")
    estimate = wanted_params
    search_s = check_search_s(search_s)  # (before the session is read)
    if regularize not in ("auto", "on", "off"):
        raise InputError(f"regularize {regularize!r}: auto, on or off")
    if phases not in ("measure", "keep"):
        raise InputError(f"phases {phases!r}: measure or keep")
    read = _session(session)
    # a synced copy synced again: from the clock model recorded before its first sync (its
    # estimates are this data's, not known values: docs/timing.md, "Syncing a synced copy")
    # (only the parameters this sync estimates, or auto tests: one it does not keeps the
    # copy's value, as --estimate says)
    def restart(times: np.ndarray) -> tuple[Rig, bool]:
        """The rig the estimate starts from, and whether a recorded value was put back;
        ``times``: the ball's (auto tests drifts where they span AUTO_DRIFT_MIN_S, as
        select_clocks measures it on the observations)."""
        if estimate == ["auto"]:
            span = float(times.max() - times.min()) / NS if len(times) else 0.0
            names = ["offset", "readout", *(["drift"] if span >= AUTO_DRIFT_MIN_S else [])]
        else:
            names = ["readout" if p == SHARED_READOUT else p for p in estimate]
        return recorded_clocks(read.rig, read.metadata,
                               tuple(RIG_KEY[p] for p in PARAMETERS if p in names))

    # (the frames holding a candidate until the ball is chosen: the rig the gate uses)
    rig, resynced = restart(read.detections.frame_time_ns[
        read.detections.candidates_per_frame() > 0])
    check_baselines(rig, str(read.path))
    detections = read.detections
    notes: list[str] = []
    reports: dict = {}
    if regularize != "off":
        progress.step("checking host timestamps")
        wanted = []
        for i, cam in enumerate(rig.cameras):
            rows = np.flatnonzero(detections.frame_camera == i)
            if len(np.unique(detections.frame_index[rows])) < 3:
                continue
            _, report = regularize_times(detections.frame_time_ns[rows],
                                         detections.frame_index[rows])
            astray = _stamps_astray(cam.name, detections.frame_time_ns[rows],
                                    detections.frame_index[rows])
            if astray is not None:
                # (frame numbers that skip no missed frame: a line through them moved every
                # time by up to seconds, in silence; walk40)
                if regularize == "on":
                    raise InputError(f"{read.path}: {astray} cannot be regularized "
                                     f"(--regularize on)")
                notes.append(f"{astray} are not regularized")
                continue
            if regularize == "on" or report.jitter_s > REGULARIZE_AUTO_JITTER_S:
                wanted.append(cam.name)
        if wanted:
            detections, reports = regularize_detections(detections, wanted)
            for name, rep in reports.items():
                notes.append(f"{name}: host stamps regularized (jitter {rep.jitter_s * 1e3:.3f} "
                             f"ms, {rep.n_outliers} outliers, {rep.n_dropped} dropped frames)")
            detections, early = _from_session_start(detections)
            if early:
                notes.append(f"{early} frame(s) regularized to before the session clock's "
                             f"zero left out of the copy")
    progress.step("choosing the ball among candidates")
    obs, gated_note, lost = _ball_candidates(detections, rig)
    found = None  # clocks that gated the ball where the logged ones lost it
    if lost:
        # the gating at the logged clocks lost the ball itself (clocks further apart than its
        # epipolar test allows: walk39, two hosts' clocks 30 ms to 3 s apart): rough clocks
        # from each frame's best-scored candidate first (the robust fit takes a false one as
        # an outlier), and the gating again at them
        # (session 40: offsets of seconds first scanned coarsely, by the agreement of every
        # moving candidate with camera 1's track; the spline scan alone reaches half a
        # frame period, and a wide --search-ms found a wrong offset)
        start, moved, coarse_notes = _coarse_start(detections, rig)
        rough: Rig | None
        try:
            rough = estimate_clocks(detections.best(), start, ("offset",), search_s,
                                    regularized=reports).rig
        except FusionError:
            # (the best-scored candidates may be a static object's, which fix no offset:
            # the coarse scan's, within a quarter of a frame period, gates as well)
            rough = start if moved else None
        again = None if rough is None else _ball_candidates(detections, rough)
        if again is not None and not again[2]:
            gated_note = (f"{again[1]}, at clocks estimated first "
                          + (f"by a coarse scan of the offsets ({moved}) and " if moved else "")
                          + f"from each frame's best-scored candidate: at the logged clocks "
                          f"the gating lost {lost[0]} of {lost[1]} frames with a candidate, "
                          f"the ball's too (clocks further apart than it allows)")
            obs, lost = again[0], None
            found = rough  # (the estimate below starts from its offsets)
        else:
            gated_note += "; " + _LOST_NOTE.format(lost=lost[0], seen=lost[1])
            if coarse_notes:
                gated_note += " (the coarse offset scan: " + "; ".join(coarse_notes) + ")"
    if gated_note:
        notes.append(gated_note)
    if len(obs) == 0 and detections.n_candidates:  # (the gating rejected every one)
        raise FusionError(f"{read.path}: all {detections.n_candidates} candidates rejected "
                          f"by gating, no frame's ball passed its epipolar and motion tests "
                          f"(frames too crowded to tell the ball, or clocks further apart "
                          f"than they allow): nothing to sync on")
    if len(obs) == 0:
        raise FusionError(f"{read.path} has no detection: nothing to sync on")
    # auto's drift test on the ball's observations' span, as select_clocks decides it (the
    # frames' span put a first sync's drift back to the recorded model where auto then did
    # not try drifts: the ball seen 10 s of a 31 s session, its drift lost in silence)
    rig, resynced = restart(obs.time_ns)
    if found is not None:  # the offsets that gated the ball: where the estimate starts
        rig = Rig(tuple(cam.replace(clock_offset=near.clock_offset)
                        for cam, near in zip(rig.cameras, found.cameras, strict=True)),
                  rig.name)
    prior_estimated = _prior_estimated(read.metadata)
    if prior_estimated:  # (a copy of an older pslog's, or synced from one since: each time)
        notes.insert(0, "synced before by a pslog that did not record the clock model it "
                     "started from (before session 38): the copy's clock estimates are "
                     "taken as the rig's values, those not estimated again kept without "
                     "their uncertainty; sync the original session to estimate them again")
    elif resynced:
        notes.insert(0, "synced before: estimated again from the clock model recorded "
                     "before its first sync (that sync's estimates are this data's, not "
                     "known values)")
    progress.step(f"choosing the clock model (auto) of {len(rig)} cameras" if estimate == ["auto"]
                  else f"estimating {', '.join(estimate)} of {len(rig)} clocks")
    try:
        try:
            result = estimate_clocks(obs, rig, tuple(estimate), search_s, regularized=reports)
        except FusionError as exc:
            # offsets beyond the scan's half frame period (two hosts' clocks seconds apart)
            # where the gating did not lose the ball (one candidate a frame): the coarse scan,
            # and the estimate again from its offsets (session 40)
            if found is not None or isinstance(exc, ClockSpanError):
                raise
            start, moved, coarse_notes = _coarse_start(detections, rig)
            if not moved:
                raise
            progress.step("estimating again from a coarse scan of the offsets")
            obs = _ball_candidates(detections, start)[0]
            try:
                result = estimate_clocks(obs, start, tuple(estimate), search_s,
                                         regularized=reports)
            except FusionError:
                raise exc from None
            notes.append(f"estimated from a coarse scan of the offsets ({moved}): from the "
                         f"rig's clocks the estimate failed ({exc})")
    except FusionError as exc:
        # with false candidates (a distractor) the failure may be theirs, not the ball's
        # motion's; say so
        several = int((detections.candidates_per_frame() > 1).sum())
        if not several or isinstance(exc, ClockSpanError):
            raise
        if lost:  # (the gating's loss, said)
            raise FusionError(f"{exc}; note: {gated_note.split('; ', 1)[1]}") from None
        raise FusionError(f"{exc}; note: {several} of {detections.n_frames} frames hold "
                          f"several candidates and a false one the gating kept (a "
                          f"reflection, a second ball) may be the cause") from None
    # a periodic motion (a turntable): offsets whole periods apart fit alike, the estimate
    # took those nearest where it started; said (session 41: a rig 2 s off settled on
    # -666.7 ms, one of the aliases of a 1.333 s turntable, with its ± 0.16 ms, silently)
    period = None
    if "offset" in result.estimated:
        from .estimation.sync import motion_period
        from .fusion._prepare import default_max_gap_s

        period = motion_period(obs, result.rig, default_max_gap_s(result.rig),
                               result.noise_px)
    if period is not None:
        half = period / 2 * 1e3
        offsets = ", ".join(f"{cam.name} {cam.clock_offset * 1e3:+.2f} ms"
                            for cam in result.rig.cameras[1:])
        notes.append(f"the ball's motion repeats every {period * 1e3:.1f} ms in every "
                     f"camera's view (a periodic motion: a turntable, a pendulum): each offset "
                     f"is known only up to whole periods ({offsets}, each ± k·"
                     f"{period * 1e3:.1f} ms, fit alike); sync kept those nearest its start "
                     f"(the rig's clocks): give a camera's clock_offset in the rig within "
                     f"{half:.0f} ms of its truth, or sync a stretch where the ball moves "
                     f"otherwise")
    # the model recorded for the next sync: every parameter's, those this sync kept at the
    # copy's values too (they are an earlier sync's estimates of this data: recording them
    # as the prior lost the model before the first sync; review39)
    measured, written, rig_out = None, False, result.rig
    if phases == "measure":
        measured = shutter_phases(detections.frame_time_ns, detections.frame_camera,
                                  result.rig)
        note, written = _phases_note(measured, result.rig)
        if written:
            rig_out = measured.rig(result.rig)
        if note:
            notes.append(note)
    return SyncOutcome(rig_out, result, detections, obs, reports, tuple(notes),
                       recorded_clocks(read.rig, read.metadata)[0], prior_estimated, period,
                       measured, written)


def _phases_note(measured: ShutterPhases, rig: Rig) -> tuple[str, bool]:
    """What :func:`sync` says of the shutter offsets it measured, and whether it writes them:
    written where the rig's are not where the shutters fire (``""`` and False where they
    are, or a camera has too few frames to tell); kept, and said, where they are not and a
    camera's phase is not steady."""
    from .timing import PHASE_MIN_FRAMES, PHASE_SPREAD

    if not measured.disagree(rig):
        # (the rig's offsets where the shutters fire: nothing to keep or write, whatever the
        # spread; review48: a type-A session met to 0.3 ms, synced --regularize off with 1
        # ms of host jitter, was told its offsets were kept as the rig says)
        return "", False
    unsteady = [f"{cam.name}'s frames spread {spread * 1e3:.2f} ms around one phase"
                for cam, frames, spread in zip(rig.cameras, measured.frames.tolist(),
                                               measured.spread_s.tolist(), strict=True)
                if frames >= PHASE_MIN_FRAMES and spread > PHASE_SPREAD * cam.frame_period]
    if unsteady:
        return (f"shutter offsets kept as the rig says: {'; '.join(unsteady)} (a frame rate "
                f"off the first camera's, each against its nominal one, walks the phase "
                f"through the session; host stamps left jittery spread it)", False)
    if not measured.writable(rig):
        return "", False
    pairs = ", ".join(f"{cam.name} {m * 1e3:.3f} ms (rig {cam.offset * 1e3:.3f})"
                      for cam, m in zip(rig.cameras, measured.offset_s.tolist(), strict=True))
    return (f"shutter offsets measured from the frames' corrected times, where the rig's are "
            f"not: {pairs}; the copy's rig holds them (type A and the filter count a missed "
            f"frame in their spacing; --phases keep keeps the rig's)", True)


def _coarse_start(detections: Detections, rig: Rig) -> tuple[Rig, str, list[str]]:
    """``rig`` with each camera's clock offset moved by sync's coarse scan
    (:func:`pslog.estimation.sync.coarse_offsets` over ±:data:`COARSE_SPAN_S`, at most the
    span of the frames holding a candidate), the moves as said in sync's notes (``cam2
    +3000.0 ms, ...``; empty: none) and the scan's notes."""
    from .estimation.sync import coarse_offsets
    from .fusion._prepare import default_max_gap_s
    from .rig import Rig

    seen = detections.frame_time_ns[detections.candidates_per_frame() > 0]
    span = 0.0 if not len(seen) else (int(seen.max()) - int(seen.min())) / NS
    delta, notes = coarse_offsets(detections, rig, min(COARSE_SPAN_S, max(1.0, span)),
                                  default_max_gap_s(rig))
    if not np.any(delta):
        return rig, "", notes
    moved = ", ".join(f"{cam.name} {d * 1e3:+.1f} ms"
                      for cam, d in zip(rig.cameras, delta.tolist(), strict=True) if d)
    return (Rig(tuple(cam.replace(clock_offset=cam.clock_offset + d)
                      for cam, d in zip(rig.cameras, delta.tolist(), strict=True)), rig.name),
            moved, notes)


#: Steps between a camera's consecutive frame numbers longer than this many frame periods
#: (the median step per number) count as long, shorter than 2 minus it as short.
_LONG_STEP = 1.5


def _stamps_astray(name: str, time_ns: np.ndarray, frame_index: np.ndarray) -> str | None:
    """Why a camera's host stamps cannot be regularized against its frame numbers, or None.

    A line of stamps against frame numbers (:func:`pslog.timing.regularize_times`) assumes
    the numbers count the camera's frames, a dropped one leaving a gap. Numbers that skip
    nothing where frames are missing (a detector's row counter; an import without a
    ``frame`` column before session 40, numbered 0, 1, 2, ...) make steps of two frame
    periods or more per number that no short step makes up for, whereas host jitter makes
    as many short steps as long ones. Such steps in excess (more than 3 and 3 standard
    deviations of the count) say the numbers do not count the frames: the line would move
    every time by up to seconds (walk40: 5 % misses numbered away, 66 ms "jitter", a
    readout of -109 ms and points 12 cm off, nothing said).
    """
    order = np.argsort(frame_index, kind="stable")
    dk = np.diff(frame_index[order]).astype(np.float64)
    dt = np.diff(time_ns[order]).astype(np.float64)
    step = dk > 0
    if np.count_nonzero(step) < 3:
        return None
    per = dt[step] / dk[step]
    period = float(np.median(per))
    if not period > 0:
        return None
    long = int(np.count_nonzero(per > _LONG_STEP * period))
    short = int(np.count_nonzero(per < (2.0 - _LONG_STEP) * period))
    excess = long - short
    if excess <= max(3.0, 3.0 * float(np.sqrt(long + short))):
        return None
    return (f"{name}: {long} of its {len(per)} steps from one frame number to the next span "
            f"{_LONG_STEP:g} frame periods or more (a period: {period / 1e6:.4g} ms, the "
            f"median) and {short} under {2.0 - _LONG_STEP:g}: its frame numbers skip no "
            f"missed frame (host jitter makes as many short steps as long ones; a frame "
            f"column counting the detector's rows, not the camera's frames?), so its host "
            f"stamps")


def _prior_estimated(metadata) -> bool:
    """Whether the session's clock model before any sync is lost: a copy ``pslog sync``
    wrote before it recorded the model it started from (a ``clock_std`` with estimates and
    no ``prior``: :func:`pslog.timing.recorded_clocks` cannot put it back), or one synced
    since from such a copy (its ``prior`` holds that older sync's estimates:
    ``prior_estimated``)."""
    import json

    from .timing import CLOCK_STD_KEY

    try:
        stored = json.loads(metadata.get(CLOCK_STD_KEY) or "{}")
        return bool(stored.get("estimated")) and (
            "prior" not in stored or bool(stored.get("prior_estimated")))
    except (ValueError, AttributeError):
        return False


#: the half-width of sync's coarse offset scan where its gating lost the ball at the logged
#: clocks or its estimate failed from them (:func:`pslog.estimation.sync.coarse_offsets`;
#: at most the span of the session's frames)
COARSE_SPAN_S = 60.0
#: share of the frames with a candidate that losing every candidate to sync's gating (at the
#: logged clocks) says the clocks are likely too far apart for it (walk39: 0.3 % on one clock,
#: 39 % with one camera's clock 30 ms off)
LOST_FRAMES_SHARE = 0.2
_LOST_NOTE = ("{lost} of {seen} frames with a candidate lost every one, the ball's too: the "
              "cameras' logged clocks are likely further apart than the gate allows (a few "
              "ms), and the clocks estimated from what is left may be wrong: give each "
              "camera's approximate clock_offset (seconds) in the rig, where pslog sync "
              "starts (docs/timing.md)")


def _ball_candidates(detections: Detections, rig: Rig):
    """Each frame's ball at its LOGGED time: the best-scored candidate when no frame holds
    more than one, else the one the gating stage chooses (:func:`pslog.fusion.gating.gate`,
    offline, at the rig's clocks: its epipolar gate allows for the ball's motion between
    shutters, so clocks wrong by some milliseconds still pass the ball and stop a static
    second object or a reflection), a note saying how many candidates it rejected, and
    ``(lost, seen)`` when more than :data:`LOST_FRAMES_SHARE` of the ``seen`` frames with a
    candidate lost every one (clocks further apart than the gate allows), else None."""
    per_frame = detections.candidates_per_frame()
    if not np.any(per_frame > 1) or len(rig) < 2:
        return detections.best(), None, None
    from .fusion._prepare import default_max_gap_s
    from .fusion.gating import gate
    from .records import point_keys

    gated = gate(detections, rig, causal=False)
    kept = gated.kept(detections)
    note = (f"{len(gated.rejections)} of {len(gated.chosen)} candidates rejected by gating "
            f"(the ball chosen among each frame's candidates, as `pslog fuse` does)")
    seen = per_frame > 0
    # (frames lost to the epipolar gate: a static object alone in a frame, the ball missed,
    # goes for motion; the ball at clocks too far apart, for epipolar)
    # (review39b: only where another camera saw something moving then, not a static
    # object alone: the ball out of one camera's view loses the other's no partner)
    lost = gated.rejections.frames_lost_to_epipolar(
        point_keys(detections.frame_time_ns, detections.frame_camera), per_frame,
        default_max_gap_s(rig))
    # (walk39: two hosts' clocks 30 ms, 0.25 s, 3 s apart: 39, 87, 90 % of the frames lost,
    # the ball's own detections, against 0.3 % on one clock; the offsets written then 0.4 ms
    # (3.5 σ), 206 ms and 3 s wrong, with a clean-looking table)
    far = lost > LOST_FRAMES_SHARE * np.count_nonzero(seen)
    return kept.best(), note, (lost, int(np.count_nonzero(seen))) if far else None


def _from_session_start(detections: Detections) -> tuple[Detections, int]:
    """``detections`` without the frames whose (regularized) time is before 0, and how many
    were left out: a session's log times start at its clock's zero."""
    keep = detections.frame_time_ns >= 0
    if keep.all():
        return detections, 0
    new_row = np.cumsum(keep) - 1
    cand = keep[detections.cand_frame]
    out = detections.__class__.from_frames(
        detections.camera_names, detections.frame_time_ns[keep], detections.frame_camera[keep],
        detections.frame_index[keep], new_row[detections.cand_frame[cand]],
        detections.cand_uv[cand], detections.cand_radius[cand], detections.cand_score[cand])
    return out, int(np.count_nonzero(~keep))


def evaluate(tracks: Track | Mapping[str, Track] | Session,
             truth: Truth | None = None) -> dict[str, Accuracy]:
    """Accuracy of fused tracks against the ground truth, as ``pslog eval`` prints it.

    Parameters
    ----------
    tracks : one Track, method -> Track (e.g. :func:`fuse`'s result), or a fused Session
        (its tracks, and its truth when ``truth`` is not given)
    truth : the ground truth (simulated sessions carry one: ``session.truth``)

    Returns
    -------
    method -> :class:`pslog.evaluation.Accuracy` (errors in millimetres, output rate in Hz)

    Raises
    ------
    pslog.errors.InputError : no truth, no track, or a track with no point inside the truth's
        time span
    """
    from .evaluation import evaluate as _evaluate
    from .log.reader import Session

    if isinstance(tracks, Session):
        truth = truth if truth is not None else tracks.truth
        tracks = tracks.tracks
    if isinstance(tracks, Track):
        tracks = {tracks.method: tracks}
    if truth is not None and not isinstance(truth, Truth):
        raise InputError(f"evaluate: truth {shown(truth)}: give a Truth (e.g. session.truth)")
    if truth is None or len(truth) == 0:
        raise InputError("evaluate: no ground truth (only sessions of 'pslog simulate', 'pslog "
                         "record --synthetic' and 'pslog demo' have one)")
    if not isinstance(tracks, Mapping):
        raise InputError(f"evaluate: tracks {shown(tracks)}: give a Track, a mapping of "
                         f"method -> Track or a Session")
    if not tracks:
        raise InputError("evaluate: no track to evaluate")
    bad = {k: v for k, v in tracks.items() if not isinstance(v, Track)}
    if bad:
        key, value = next(iter(bad.items()))
        raise InputError(f"evaluate: tracks[{key!r}] is {shown(value)}, not a Track")
    return {method: _evaluate(track, truth) for method, track in tracks.items()}
