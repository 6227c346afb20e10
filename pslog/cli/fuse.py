"""pslog fuse: fuse a session's detections into 3D tracks, written into a copy of the session."""

from __future__ import annotations

import argparse
import math

from ._common import (
    add_force,
    add_method_option,
    declare_files,
    fuse_noise_px,
    int_in,
    noise_px,
    nonnegative_float,
    number_at_most,
    usage_error,
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.fusion import METHODS

    parser.add_argument("session", metavar="SESSION.mcap", help="session file to fuse")
    listing = "; ".join(f"{m.name}: {m.description}" for m in METHODS.values())
    add_method_option(parser, f"fusion method, repeat or give a comma-separated list for "
                              f"several (default: every method the session's timing suits) "
                              f"-- {listing}")
    parser.add_argument("-o", "--output", required=True, metavar="FUSED.mcap",
                        help="output session: a copy of the input with one topic per track")
    parser.add_argument(
        "--rig", metavar="RIG.toml",
        help="fuse with this corrected rig (same camera names and order; start from 'pslog rig "
             "show SESSION.mcap') instead of the recorded calibration; the output carries it. "
             "An anipose / Pose2Sim / OpenCV calibration replaces the geometry only (its "
             "fps / offset keys, when pslog exported it, are not used: the session's frame "
             "rates, offsets and synced clocks stay); a pslog rig TOML or a session file "
             "gives its whole rig, timing and clocks included (e.g. a synced session's; a "
             "frame rate other than the session's rig's is said in a note)")
    parser.add_argument("--tolerance-ms", type=nonnegative_float, default=None,
                        metavar="MS", help="detections this close in time count as "
                                           "simultaneous, milliseconds, below a third of the "
                                           "frame period (default 1, or a tenth of the frame "
                                           "period for cameras faster than 333 fps)")
    parser.add_argument("--max-gap-ms", default=None,
                        type=number_at_most(3.6e6, "ms", "an hour", positive=True),
                        metavar="MS", help="longest time span a method may bridge, "
                                           "milliseconds, at most an hour (default: 3.5 frame "
                                           "periods)")
    parser.add_argument("--rate", type=number_at_most(1e6, "Hz", "a megahertz", positive=True,
                                                        least=1e-3),
                        default=None, metavar="HZ",
                        help="smooth: points on a regular grid of this rate instead of at "
                             "every detection time")
    parser.add_argument("--noise-px", type=fuse_noise_px, default=0.5, metavar="PX",
                        help="the detections' pixel noise (standard deviation per axis) behind "
                             "each point's std_m and covariance, and the least noise typeA's "
                             "prediction and kink tests assume (they use the larger of it and "
                             "the noise the session's own innovations imply; sync's residual "
                             "test and typeB's and linear's prediction test the larger of it, "
                             "0.5 px and the noise each camera's detections show); nearest's "
                             "and typeA's covariance take the noise their detections show "
                             "once a second of them has (at least the smaller of this and "
                             "0.1 px; typeA's first points, before that, at least this and "
                             "2 px); `pslog sync` prints the estimated noise; 0 (noise-free: zero "
                             "covariances) or at least 0.001 (default %(default)s)")
    parser.add_argument("--detector-offset-mm", type=number_at_most(1000.0, "mm", "a metre"),
                        default=None, metavar="MM",
                        help="smooth: standard deviation per axis of the detector's constant "
                             "3-D offset of the ball's apparent centre (the same for every "
                             "camera: a centroid drawn toward the lit side of the ball), a "
                             "systematic error that smooth's averaging cannot shrink, added "
                             "to its std_m and covariance; the points do not move (default: "
                             "0.5 for detections found in images, 0 for `pslog simulate` "
                             "sessions)")
    parser.add_argument("--detector-bias-px", type=noise_px, default=0.0, metavar="PX",
                        help="smooth: standard deviation per image axis of each camera's own "
                             "constant detection bias, independent between cameras, "
                             "propagated through the fit into std_m and the covariance "
                             "(default %(default)s)")
    parser.add_argument("--clock-uncertainty", choices=("on", "off"), default=None,
                        help="on: a session from `pslog sync` adds the uncertainty of the "
                             "clocks it estimated to every point's std_m and covariance (the "
                             "points' sensitivity to each camera's offset, drift and readout; "
                             "the points do not move; a clock --rig replaced takes none); "
                             "off: the pixel noise alone, the clocks taken as exact "
                             "(default on; a line says when it is not applied: on given "
                             "for a session never synced, every clock replaced by --rig, "
                             "damaged metadata)")
    parser.add_argument("--gating", choices=("on", "off"), default="on",
                        help="on: choose each frame's ball among its candidates by the "
                             "epipolar, track and motion gates and record every rejected "
                             "candidate in the output; off: take each frame's best-scored "
                             "candidate (default %(default)s)")
    parser.add_argument("--confirm-gaps",  # CONFIRM_GAPS
                        choices=("jumps", "kicks", "breaks", "all", "on", "off"),
                        default=None,
                        help="typeA: jumps (the default): kicks, and a point whose construction "
                             "spans a kick instant that the cameras' image tracks show (a "
                             "velocity jump) is replaced by type A's point from the detections "
                             "after it (time reversed) when that one spans none, else left out "
                             "(break); kicks: every point is tested against every other camera's "
                             "track around it, on the point's side of a kick that track shows, "
                             "and left out as contradicted when the camera shows it elsewhere "
                             "(offline: the points just after an unseen kick, whose depth the "
                             "paper's prediction took from the motion before it); breaks: jumps "
                             "with the kick instants taken from the velocity breaks of smooth's "
                             "fit of the session instead (a fit: dearer); all: every point "
                             "tested against the next camera's interpolated track only; on: only "
                             "a point whose prediction bridged a gap longer than the rig's usual "
                             "one, or rests on a camera's first detection after a spell without "
                             "one, waits for the next camera's detection to confirm it (left out "
                             "as contradicted or unconfirmed otherwise: as a stream does); off: "
                             "every point at once, the paper's points, as `pslog live` emits "
                             "them")
    parser.add_argument("--filter-hold", choices=("on", "off"), default="on",
                        help="filter: on: a point whose detection surprised the filter (NIS "
                             "above 2), follows a missed slot, starts a track or was "
                             "rejected waits for another camera's next detection and is left "
                             "out (held) when that detection places a jump before it, is "
                             "rejected, or the track is lost first (or the session ends); "
                             "off: every point at its detection, as `pslog live` emits them "
                             "(default %(default)s)")
    parser.add_argument("--type-a-max-std-mm", default=None,
                        type=number_at_most(1e6, "mm", "a kilometre", positive=True),
                        metavar="MM",
                        help="typeA: withhold a point whose std_m exceeds this, millimetres, "
                             "counted as left out (`uncertain`, the filter's rule; 25.5: the "
                             "filter's bound, 5 cm at 95 %%) (default: none withheld)")
    parser.add_argument("--workers", type=int_in(1, 64), default=None, metavar="N",
                        help="methods fused at once, on threads (the same tracks whatever "
                             "the number; 1..64; 1: one after another, e.g. beside other "
                             "work) (default: the usable cores, at most one per method; "
                             "smooth's own threads: PSLOG_SMOOTH_THREADS, default 2, at "
                             "most the CPUs the process may use)")
    add_force(parser)
    declare_files(parser, inputs=("session", "rig"), outputs=("output",),
                  sessions=("output",))


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from pslog import progress
    from pslog._jit import preload
    from pslog.errors import FusionError, RigError, shell_word
    from pslog.fusion import (
        CONFIRM_GAPS,
        FILTER_HOLD_NIS,
        METHODS,
        FusionOptions,
        check_method,
        check_tolerance,
        confirm_choice,
        default_methods,
        default_tolerance,
        for_session,
    )
    from pslog.fusion._parallel import finishing_order
    from pslog.fusion._prepare import default_max_gap_s
    from pslog.fusion.gating import start_fusion
    from pslog.log import read_session
    from pslog.log.copy import open_copy
    from pslog.records import by_reason, point_keys
    from pslog.rig import check_baselines, resolve_rig
    from pslog.timing import CLOCK_STD_KEY, read_clock_covariance
    from pslog.timing import observations as timed_observations

    output = args.output  # checked before run() (declare_files)
    progress.update(what="reading the session")
    session = read_session(args.session)
    rig = session.rig
    rig_metadata: dict[str, str] = {}  # (--rig a session file: its metadata, clocks' covariance)
    if args.rig is not None:
        unused: list[str] = []  # (a calibration's cameras whose timing keys it replaced)
        rig = resolve_rig(args.rig, timing_from=session.rig, not_applied=unused,
                          metadata=rig_metadata)
        if rig.names != session.rig.names:
            raise RigError(f"{args.rig}: cameras {', '.join(rig.names)} differ from the "
                           f"session's {', '.join(session.rig.names)} (names and order must "
                           f"match)")
        if unused:  # (documented in --help; said, as the other options fuse ignores)
            print(f"--rig {args.rig}: its fps/offset/clock keys are not applied to "
                  f"{', '.join(unused)}: a calibration gives the geometry, the session's timing "
                  f"stays (for the file's: 'pslog rig import {shell_word(args.rig)} -o "
                  f"rig.toml', then --rig rig.toml)")
        _say_other_frame_rates(args.rig, rig, session)
    check_baselines(rig, args.session if args.rig is None else args.rig)
    # (not given: 1 ms, or less for cameras too fast for it, rather than a refusal of an
    # option the command line does not hold)
    tolerance_s = default_tolerance(rig) if args.tolerance_ms is None else args.tolerance_ms / 1e3
    try:
        check_tolerance(rig, tolerance_s)
    except FusionError as exc:
        return usage_error("fuse", f"argument --tolerance-ms: {exc}")
    confirm_name = args.confirm_gaps or next(iter(CONFIRM_GAPS))  # (None: not given;
    # said if unused)
    options = FusionOptions(tolerance_s=tolerance_s,
                            max_gap_s=None if args.max_gap_ms is None else args.max_gap_ms / 1e3,
                            rate_hz=args.rate, noise_px=args.noise_px,
                            gating=args.gating == "on",
                            **confirm_choice(confirm_name),
                            filter_hold_nis=FILTER_HOLD_NIS if args.filter_hold == "on"
                            else None,
                            max_std_m=None if args.type_a_max_std_mm is None
                            else args.type_a_max_std_mm / 1e3,
                            detector_offset_m=None if args.detector_offset_mm is None
                            else args.detector_offset_mm / 1e3,
                            detector_bias_px=args.detector_bias_px)
    # the detector's default offset, and the synced clocks' covariance (a --rig session
    # file's: a synced copy's clocks come with the covariance its sync stored)
    options = for_session(options, session.metadata,
                          rig if args.clock_uncertainty != "off" else None, rig_metadata)
    if args.clock_uncertainty != "off":
        _say_clock_uncertainty(args, session, options.clock_covariance,
                               read_clock_covariance(rig, rig_metadata) is not None)
    _say_borrowed_clocks(args, session)
    observations = timed_observations(session.detections, rig)  # the rig's clock model
    if len(observations) == 0:
        raise FusionError(f"{args.session} has no detection to fuse")
    seen = np.unique(observations.camera)
    if len(seen) < 2:  # say why rather than "too few detections close enough in time"
        raise FusionError(f"{args.session}: only camera {rig.names[int(seen[0])]} has "
                          f"detections; fusing needs at least two cameras")
    pass_before: dict = {}  # (default_methods' gating pass, when it makes one: not made again)
    if args.methods:
        methods = [check_method(m) for m in dict.fromkeys(args.methods)]
    else:  # every method this timing suits
        # (from the candidates: each frame's ball as the methods will choose it)
        methods = default_methods(session.detections, rig, options, gated=pass_before)
        skipped = [m for m in METHODS if m not in methods]
        if skipped:
            print(f"not run on this timing: {', '.join(skipped)} (name them with --method "
                  f"to run them anyway)")
    # numba's start and the kernel modules these methods (and the writer) run, on another
    # core while the detections are gated: not on the way of the first kernel (and the
    # gate's compiled points, pslog.fusion._gate_kernel.points_all)
    preload(*dict.fromkeys(k for m in methods for k in METHODS[m].kernels), "pslog.log._wire",
            *(("pslog.fusion._gate_kernel",) if options.gating else ()))
    if args.type_a_max_std_mm is not None and "typeA" not in methods:
        print(f"--type-a-max-std-mm {args.type_a_max_std_mm:g} ignored: typeA does not run "
              f"(name it with --method typeA)")
    if args.confirm_gaps is not None and "typeA" not in methods:
        print(f"--confirm-gaps {args.confirm_gaps} ignored: typeA does not run (name it with "
              f"--method typeA)")
    if args.filter_hold == "off" and "filter" not in methods:  # (on: the default)
        print("--filter-hold off ignored: filter does not run (name it with --method filter)")
    smooth_only = [f"--{name} {value:g}" for name, value in (
        ("rate", args.rate), ("detector-offset-mm", args.detector_offset_mm),
        ("detector-bias-px", args.detector_bias_px or None)) if value is not None]
    if smooth_only and "smooth" not in methods:  # as silent, they would seem to have worked
        print(f"{', '.join(smooth_only)} ignored: smooth does not run (name it with --method "
              f"smooth)")
    if "smooth" in methods:  # a malformed PSLOG_SMOOTH_THREADS said now, not after gating
        from pslog.estimation._breaks import smooth_threads

        smooth_threads()
    progress.update(total=len(methods) + 2)  # read, each method, write
    # a --max-gap-ms below every camera's frame period: no method may bridge from a camera's
    # frame to its next, which the no-point lines name (they said "too few detections close
    # enough in time", the option that made them so unnamed)
    slowest = max(rig.cameras, key=lambda cam: cam.frame_period)
    whose = ("the" if len({cam.fps for cam in rig.cameras}) == 1
             else f"camera {slowest.name}'s")
    short_gap = (f"--max-gap-ms {args.max_gap_ms:g} is shorter than {whose} "
                 f"{slowest.frame_period * 1e3:.4g} ms frame period: a camera's next frame is "
                 f"farther than that" if args.max_gap_ms is not None
                 and args.max_gap_ms / 1e3 < slowest.frame_period else "")
    n_observations = len(observations)
    detections = session.detections
    n_candidates = detections.n_candidates
    never_synced = not (session.metadata or {}).get(CLOCK_STD_KEY) and args.rig is None
    # (for the frames the gating lost, said below for a session never synced)
    # (those where another camera saw something moving then, within the gate's gap: not
    # the ball out of one camera's view beside a static object; review39b)
    frames = (point_keys(detections.frame_time_ns, detections.frame_camera),
              detections.candidates_per_frame(),
              options.max_gap_s or default_max_gap_s(rig)) if never_synced and options.gating \
        else None
    del observations, session  # freed before fusing (a 90-minute match's columns)
    # the methods fuse on threads while this thread copies the session into the output and
    # writes each method's track as the method ends (its left-out counts go with it, in its
    # channel's metadata: docs/log-format.md); the output appears only once complete
    # (one method, or one usable core: on a thread all the same, the copy going on beside
    # it; --workers 1 keeps everything on this thread, one step after another)
    fusing = start_fusion(detections, rig, methods, options, workers=args.workers,
                          background=args.workers is None, gated=pass_before)
    del pass_before  # (the fusion's now: dropped as it is used)
    del detections  # (held by the gating until the last form is gated)
    # points, left out, gated, flagged, made from the detections after them
    written: dict[str, tuple[int, dict[str, int], int, int, int]] = {}
    empty: dict[str, dict[str, int]] = {}  # method: its left-out counts
    empty_rejected: dict[str, dict[str, int]] = {}  # method: its gating's rejections
    early: dict[str, int] = {}
    still: dict[str, int] = {}  # candidates rejected as a still object, by method
    lost: dict[str, int] = {}  # frames that lost every candidate to the epipolar gate
    try:
        with open_copy(args.session, output, new_methods=methods, force=args.force,
                       rig=None if args.rig is None else rig) as w:
            # written in a fixed order (the expected finishing order: the same file whatever
            # the scheduling), each as soon as it and those before it have ended
            order = finishing_order(methods)
            ended: dict[str, tuple] = {}
            for method, track, rejected in fusing:
                ended[method] = (track, rejected)
                del track, rejected
                while order and order[0] in ended:
                    method = order.pop(0)
                    track, rejected = ended.pop(method)
                    dropped = dict(track.dropped)  # invalid or untrustworthy points
                    if options.gating:
                        still[method] = _still_rejections(rejected)
                    if frames is not None:
                        lost[method] = rejected.frames_lost_to_epipolar(*frames)
                    if len(track) == 0:
                        empty[method] = dropped
                        empty_rejected[method] = rejected.counts() if options.gating else {}
                        continue
                    # a camera whose clock runs behind camera 1's has true times before the
                    # session clock's zero, which a session cannot store: left out, said
                    # below
                    n_early = int(np.count_nonzero(track.time_ns < 0))
                    if n_early:
                        early[method] = n_early
                        track = track.select(track.time_ns >= 0)
                    w.add_track(track, left_out=dropped, last=True,
                                fused_with={"confirm-gaps": confirm_name}
                                if method == "typeA" else None)
                    if options.gating:
                        w.add_rejections(method, rejected)
                    # points kept whose detection the method rejected itself (smooth's fit,
                    # the filter's gate: flagged rejected), as pslog eval and view count them
                    flag = track.quality.get("rejected")
                    n_flagged = 0 if flag is None else int(np.count_nonzero(flag == 1))
                    # type A's points from the detections after them (--confirm-gaps
                    # breaks: span_s < 0), as pslog eval counts them
                    span = track.quality.get("span_s")
                    n_backward = 0 if span is None else int(np.count_nonzero(span < 0))
                    written[method] = (len(track), dropped, len(rejected), n_flagged,
                                       n_backward)
                    del track, rejected
            most = max(still.values(), default=0)
            if most > n_candidates / 2:
                # by design (docs/methods.md, "Stillness"): a still object is not the ball
                # in play (offline, smooth fuses it in a session of one candidate a frame)
                print(f"{most} of {n_candidates} candidates rejected as a still object: a "
                      f"ball that stands still (slower than about 20 cm/s) is not told from "
                      f"a static object (nor from a second orange object in view): if they "
                      f"are the ball, run with --gating off to fuse them")
            for method in (m for m in methods if m in empty):
                print(_no_point(method, empty[method], args.type_a_max_std_mm,
                                empty_rejected.get(method, {}), short_gap))
            if not written:
                raise FusionError(f"no fusion method produced a point from the "
                                  f"{n_observations} detections of {args.session}"
                                  + (f": {short_gap}" if short_gap else ""))
            if early:
                print("left out, being before the session clock's zero after clock "
                      "correction: " + ", ".join(f"{n} {m} point{'s' if n > 1 else ''}"
                                                 for m in methods if (n := early.get(m, 0))))
            progress.step(f"writing {output}")
    except BaseException:
        fusing.stop()  # no method starts after a failure or an interrupt
        raise
    for method in (m for m in methods if m in written):
        n_points, dropped, n_rejected, n_flagged, n_backward = written[method]
        why = by_reason(dropped)
        rejected_text = (f"  {n_rejected:>6d} candidate{'' if n_rejected == 1 else 's'} "
                         "rejected by gating" if options.gating else "")
        what = {"smooth": "fit", "filter": "gate"}.get(method, "method")
        print(f"{method:<8} {n_points:>7d} points{rejected_text}"
              + (f" (left out, untrustworthy: {why})" if why else "")
              + (f"; {n_flagged} flagged rejected (its {what} rejected "
                 + ("their detections, the points kept)" if n_flagged > 1 else
                    "its detection, the point kept)") if n_flagged else "")
              + (f"; {n_backward} {'points' if n_backward > 1 else 'point'} made from the "
                 "detections after "
                 + ("them" if n_backward > 1 else "it")
                 + f" (--confirm-gaps {confirm_name}: the paper's construction spanned "
                 f"{BREAK_WORDS[options.break_source]}; span_s < 0)" if n_backward else ""))
    if options.confirm_breaks and args.confirm_gaps is not None and "typeA" in written:
        _, dropped, _, _, n_backward = written["typeA"]
        if not n_backward and not dropped.get("break"):
            # the option asked for and nothing to show for it: said, not left to be guessed
            # from a line like the default's (session 37's walk: --gating off)
            print(NO_BREAK_SPANNED[options.break_source])
    if frames is not None and lost:
        _say_clocks_apart(args, lost, int(np.count_nonzero(frames[1])))
    print(f"wrote {output}")
    return 0


def _say_clocks_apart(args: argparse.Namespace, lost: dict[str, int], seen: int) -> None:
    """One line, for a session never synced (no clock estimates, no ``--rig``), when more
    than :data:`pslog.api.LOST_FRAMES_SHARE` of the ``seen`` frames with a candidate lost
    every one to the epipolar gate (``lost``: by method): the cameras' clocks are then most
    likely further apart than the gate allows, and ``pslog sync`` is the step skipped
    (walk39: one host's clock 0.25 s off, 4,258 of 4,871 candidates rejected and 473 points
    of nearest's 4,583, without a word on why)."""
    from pslog.api import LOST_FRAMES_SHARE
    from pslog.errors import shell_word

    most = max(lost.values())
    if most > LOST_FRAMES_SHARE * seen:
        print(f"note: the gating lost every candidate of up to {most} of the {seen} frames "
              f"with one, the ball's too (epipolar): the cameras' clocks are likely further "
              f"apart than it allows (a few ms), and {args.session} was never synced: 'pslog "
              f"sync {shell_word(args.session)} -o SYNCED.mcap' first, then fuse that")


#: ``--confirm-gaps breaks`` when no type A point spanned a velocity break of the session's
#: fit (none replaced, none withheld): the fit found no break, or each lies where no point's
#: construction reaches across it (the kink test left those out)
NO_BREAK_SPANNED = {
    "fit": ("typeA: --confirm-gaps breaks changed no point: none spanned a velocity break of "
            "smooth's fit (it found none, or none that a point's construction reaches "
            "across): every point is the paper's"),
    "image": ("typeA: --confirm-gaps jumps changed no point: none spanned a kick the cameras' "
              "images show (they show none, or none that a point's construction reaches "
              "across): every point is the paper's")}
#: what a replaced type A point's construction spanned, by ``FusionOptions.break_source``
BREAK_WORDS = {"fit": "a velocity break of smooth's fit",
               "image": "a kick the cameras' images show"}


def _no_point(method: str, dropped: dict[str, int], max_std_mm: float | None,
              rejected: dict[str, int] | None = None, short_gap: str = "") -> str:
    """The line saying why ``method`` gave no point: every point it found left out (by
    reason, ``uncertain`` naming --type-a-max-std-mm's bound), or none found; the
    candidates the gating rejected (``rejected``: count by reason) said with it: they may be
    the detections a point lacked ("too few detections close enough in time" alone, when
    the gating had rejected them, sent a user to the clocks); ``short_gap``: why a
    --max-gap-ms below the frame period leaves none close enough, said with it."""
    from pslog.records import by_reason

    n = sum((rejected or {}).values())
    gated = (f"the gating rejected {n} candidate{'s' if n > 1 else ''} ("
             + by_reason(rejected or {})
             + "; --gating off: each frame's best-scored candidate)" if n else "")
    if not dropped:
        return (f"no point from {method}: too few detections close enough in time"
                + (f" ({short_gap})" if short_gap else "")
                + (f" once {gated}" if gated else ""))
    total = sum(dropped.values())
    if set(dropped) == {"uncertain"} and max_std_mm is not None:
        return (f"no point from {method}: all {total} {method} points withheld: std above "
                f"--type-a-max-std-mm {max_std_mm:g} mm")
    why = by_reason(dropped)
    bound = (f"; uncertain: std above --type-a-max-std-mm {max_std_mm:g} mm"
             if "uncertain" in dropped and max_std_mm is not None else "")
    return (f"no point from {method}: all {total} points left out, untrustworthy: "
            f"{why}{bound}" + (f"; {gated}" if gated else ""))


#: glibc's mallopt parameter of the most malloc arenas (malloc.h)
_M_ARENA_MAX = -8


def one_malloc_arena() -> bool:
    """glibc: every thread of the process allocates from one malloc arena (``mallopt
    (M_ARENA_MAX, 1)``, as ``MALLOC_ARENA_MAX=1`` would), unless ``MALLOC_ARENA_MAX`` is
    set. A thread of its own arena (glibc gives each new thread one, up to 8 a core)
    keeps the large blocks its numpy arrays freed for its own later ones, and takes fresh
    pages from the OS for what another thread freed: the fuse threads' columns (tens of
    MB each) came as fresh pages again and again. One arena: on the 90-minute three-camera
    session the default ``pslog fuse`` took 27 % fewer page faults (218-234 thousand
    against 305-313 thousand), a 170-200 MB lower peak (1.40-1.45 GB against 1.60-1.62)
    and 0.9 CPU s less (16.3-16.9 against 17.2-17.8, user and system; two alternating
    pairs against ``MALLOC_ARENA_MAX=16`` on a loaded machine; with the variable set
    alone, four more pairs alike). Its outputs do not depend on it. True where set: glibc
    (on another C library, or where the user set ``MALLOC_ARENA_MAX`` or glibc's
    ``arena_max`` tunable, nothing is changed), and only while the process has one thread
    (glibc fixes its arenas' limit once it has more than 8 of them, and threads that have
    one keep it: a process that called :func:`pslog.cli.main` from a busy program, a Ray
    worker or a test runner with threads, is left as it is)."""
    import os
    import platform
    import threading

    if (platform.libc_ver()[0] != "glibc" or "MALLOC_ARENA_MAX" in os.environ
            or "arena_max" in os.environ.get("GLIBC_TUNABLES", "")
            or threading.active_count() != 1):
        return False
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # (no such C library function here)
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_ARENA_MAX, 1))


def before_threads() -> None:
    """Called by :func:`pslog.cli.main` before any thread of the command starts (its
    progress line's): :func:`one_malloc_arena` (a thread that allocated before it keeps an
    arena of its own, which the fusing threads would then share in turn)."""
    one_malloc_arena()


def _still_rejections(rejected) -> int:
    """How many of a method's gating rejections (:class:`pslog.fusion.gating.Rejections`)
    are a still object's: rejected for ``motion`` (the gate's reason for a static object as
    for a point behind a camera) in a camera whose such candidates barely move in the image
    (median step from each to the nearest of the three before it under 2 px: several still
    objects seen by one camera alternate in its rows)."""
    import numpy as np

    from pslog.fusion.gating import MOTION

    count = 0
    for cam in np.unique(rejected.camera):
        rows = (rejected.camera == cam) & (rejected.reason == MOTION)
        uv = rejected.uv[rows]
        if len(uv) < 2:
            continue
        step = np.full(len(uv) - 1, np.inf)
        for lag in (1, 2, 3):
            if len(uv) > lag:
                step[lag - 1:] = np.minimum(step[lag - 1:], np.linalg.norm(
                    uv[lag:] - uv[:-lag], axis=1))
        if np.median(step) < 2.0:
            count += len(uv)
    return count


def _say_clock_uncertainty(args: argparse.Namespace, session, applied,
                           from_rig: bool = False) -> None:
    """One line on whether every point's ``std_m`` holds the clocks' uncertainty: the count of
    estimates it holds, or why it holds none where a user could expect them (asked for on a
    session never synced; every synced clock replaced by ``--rig``; the session's
    ``clock_std`` metadata damaged). A fuse never stops for it: the clocks' part is
    informative, and without it ``std_m`` is the pixel noise's, as with ``off``.
    ``from_rig``: ``applied`` is the ``--rig`` session file's (its sync's estimates)."""
    import numpy as np

    from pslog.timing import CLOCK_STD_KEY, read_clock_covariance, read_clock_std

    metadata = session.metadata or {}
    synced = read_clock_covariance(session.rig, metadata)  # (the session's own clocks)
    stds = read_clock_std(session.rig, metadata)
    damaged = (stds is None and bool(metadata.get(CLOCK_STD_KEY))) or (
        stds is not None and sum(not v >= 0 for row in stds for v in row.values()))
    fix = "run 'pslog sync' again to restore it"
    if applied is not None:
        replaced = 0 if synced is None or from_rig else len(synced) - len(applied)
        names = session.rig.names  # (which ones: a user knows the cameras, not a count)
        # (a readout pslog sync estimated once per camera model, tied: its cameras' rows of
        # the covariance are one, T Σ Tᵀ; said as one estimate, as sync says it; walk38: the
        # "5 clock estimates" of a sync that reported 4)
        groups: list[list[int]] = []
        for i in range(len(applied)):
            same = next((g for g in groups if applied.parameter[g[0]] == applied.parameter[i]
                         and np.allclose(applied.matrix[g[0]], applied.matrix[i], rtol=1e-12,
                                         atol=0.0)), None)
            if same is None:
                groups.append([i])
            else:
                same.append(i)
        def cameras(g: list[int]) -> str:
            listed = [names[applied.camera[i]] for i in g]
            if len(listed) == 1:
                return listed[0]
            return f"one for {', '.join(listed[:-1])} and {listed[-1]} (per camera model)"

        which = "; ".join(
            f"{label}: " + ", ".join(cameras(g) for g in groups if applied.parameter[g[0]] == p)
            for p, label in enumerate(("offset", "drift", "readout"))
            if np.any(applied.parameter == p))
        print(f"std_m includes the uncertainty of the {len(groups)} clock estimates of "
              + (f"the pslog sync of --rig {args.rig}" if from_rig else "pslog sync")
              + f" ({which}; --clock-uncertainty off: the pixel noise alone)"
              + (f"; --rig {args.rig} replaced {replaced} other"
                 + ("s: none for them" if replaced > 1 else ": none for it")
                 if replaced > 0 else "")
              + (f"; {damaged} other{'s' if damaged > 1 else ''} damaged in the session's "
                 f"metadata ({CLOCK_STD_KEY}): none for {'them' if damaged > 1 else 'it'} "
                 f"({fix})" if damaged else ""))
        return
    alone = "std_m holds the pixel noise alone, the clocks taken as exact"
    if damaged:
        print(f"{args.session}: its clock estimates' metadata ({CLOCK_STD_KEY}) is "
              f"damaged: {alone} ({fix})")
    elif not metadata.get(CLOCK_STD_KEY):
        if args.clock_uncertainty == "on":  # (asked for explicitly; silent by default)
            print(f"--clock-uncertainty on ignored: {args.session} holds no clock estimates "
                  f"(never synced: 'pslog sync' estimates them); {alone}")
    elif args.rig is not None and synced is not None:
        print(f"--rig {args.rig} replaces every clock parameter pslog sync estimated "
              f"({len(synced)}): {alone} (the rig's)")


def _say_borrowed_clocks(args: argparse.Namespace, session) -> None:
    """One line when the session's rig holds a clock model that no ``pslog sync`` estimated
    on it (no ``clock_std`` metadata, no ``--rig``): the rig it was recorded or imported with
    brought it, most likely an earlier session's synced rig (walk42: `pslog rig show
    synced.mcap > lab.toml`, the next recording made with it, fused with the old session's
    clocks without a word; webcams' offsets move at every start). Not for a synthetic
    recording or a simulated session, whose rig's clocks are the ones it rendered (its
    ``simulate.*`` metadata; faults beyond them are said by ``pslog simulate``)."""
    from pslog.errors import shell_word
    from pslog.timing import CLOCK_STD_KEY

    metadata = session.metadata or {}
    cams = [c for c in session.rig.cameras if c.has_clock_correction]
    if (args.rig is not None or not cams or metadata.get(CLOCK_STD_KEY)
            or "--synthetic" in str(metadata.get("source", ""))
            or any(str(k).startswith("simulate.") for k in metadata)):
        return
    said = ", ".join(
        f"{c.name} " + " ".join(part for part in (
            f"offset {c.clock_offset * 1e3:+.3f} ms" if c.clock_offset else "",
            f"drift {c.clock_drift_ppm:+.1f} ppm" if c.clock_drift_ppm else "",
            f"readout {c.readout * 1e3:.3f} ms" if c.readout else "") if part)
        for c in cams)
    path = shell_word(args.session)
    print(f"note: {args.session}'s rig holds a clock model no 'pslog sync' estimated on it "
          f"({said}): the rig it was recorded or imported with brought it, an earlier "
          f"session's? Cameras without genlock move their clocks at every start: 'pslog sync "
          f"{path} -o synced.mcap' estimates them on this one")


def _say_other_frame_rates(name, rig, session) -> None:
    """Say (stdout, one line) the cameras whose frame rate a ``--rig`` changes from the
    session's rig (the one it was recorded, simulated or imported with): a rig of another
    recording, or an fps mistyped, was fused without a word (the frame periods set type A's,
    the filter's and the gating's timing). A note, not an error: the change may be meant.
    (The session's rig, not a rate measured from its frames: with frames dropped and
    jittered stamps a measurement is no proof.)"""
    changed = [f"{new.name} ({old.fps:g} -> {new.fps:g} fps)"
               for old, new in zip(session.rig.cameras, rig.cameras, strict=True)
               if not math.isclose(old.fps, new.fps, rel_tol=1e-9)]
    if changed:
        print(f"note: --rig {name} changes the frame rate of {', '.join(changed)} from the "
              f"session's rig: a rig of another recording? The frame periods set the fusion's "
              f"timing")
