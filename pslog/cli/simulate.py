"""``pslog simulate``: a session of a rig watching a moving ball (detections + truth)."""

from __future__ import annotations

import argparse

import numpy as np

from ._common import (
    MAX_NOISE_PX,
    add_force,
    add_rig,
    closed_fraction,
    declare_files,
    fraction,
    noise_px,
    nonnegative_float,
    positive_float,
    seed,
    usage_error,
)


def _finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def _camera_value(unit: str, scale: float, all_cameras: bool = False):
    """argparse type: ``CAM=VALUE`` (a camera name and a finite number in ``unit``) ->
    ``(name, value * scale)``; with ``all_cameras`` a bare ``VALUE`` is ``(None, ...)``:
    every camera."""
    def parse(text: str):
        name, sep, value = text.partition("=")
        if not sep:
            if all_cameras:
                return None, _finite(text) * scale
            raise argparse.ArgumentTypeError(f"expected CAM={unit.upper()} (a camera name, "
                                             f"'=', a number of {unit}), got {text!r}")
        if not name.strip():
            raise argparse.ArgumentTypeError(f"no camera name before '=' in {text!r}")
        return name.strip(), _finite(value) * scale
    parse.__name__ = f"CAM={unit}"
    return parse


def _distractor(text: str):
    """argparse type: ``[CAM=]X,Y,Z`` (metres) -> ``(camera name or None, (x, y, z))``."""
    name, sep, point = text.rpartition("=")
    if sep and not name.strip():
        raise argparse.ArgumentTypeError(f"no camera name before '=' in {text!r}")
    parts = point.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"expected [CAM=]X,Y,Z (a world point, metres), "
                                         f"got {text!r}")
    return (name.strip() if sep else None), tuple(_finite(p) for p in parts)


def _spurious_radius(text: str) -> float:
    """argparse type: pixels in [0, 100] (not :func:`noise_px`: its message is about noise)."""
    value = nonnegative_float(text)
    if value > MAX_NOISE_PX:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_NOISE_PX:g} pixels from the "
                                         f"ball, got {text!r}")
    return value


def _blackout(text: str):
    """argparse type: ``CAM=START:DURATION`` (seconds) -> ``(name, start, duration)``."""
    name, sep, span = text.partition("=")
    start_text, colon, duration_text = span.partition(":")
    if not sep or not colon or not name.strip():
        raise argparse.ArgumentTypeError(f"expected CAM=START:DURATION (a camera name, "
                                         f"seconds from the start, seconds), got {text!r}")
    start, duration = _finite(start_text), _finite(duration_text)
    if start < 0:
        raise argparse.ArgumentTypeError(f"start must be >= 0 seconds, got {text!r}")
    if duration <= 0:
        raise argparse.ArgumentTypeError(f"duration must be > 0 seconds, got {text!r}")
    return name.strip(), start, duration


def _renamed_jitter(text: str) -> float:
    """``--jitter`` was in seconds: say what it is now called, with the value it meant."""
    try:
        meant = f" (--jitter {text} is --jitter-ms {float(text) * 1e3:g})"
    except ValueError:
        meant = ""
    raise argparse.ArgumentTypeError(
        f"renamed --jitter-ms, in milliseconds as --host-jitter and --clock-offset{meant}")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.motion import MOTIONS
    from pslog.rig import TIMING_PRESETS

    add_rig(parser)
    parser.add_argument("--timing", choices=(*TIMING_PRESETS, "rig"), default="rig",
                        help="set the rig's shutter offsets from a preset (default: 'rig', the "
                             "rig's own offsets; the built-in rigs' are all zero, i.e. sync)")
    parser.add_argument("--motion", choices=list(MOTIONS), default="spiral",
                        help="ball motion (default %(default)s)")
    parser.add_argument("--duration", type=positive_float, default=None, metavar="S",
                        help="seconds of motion (default: the motion's natural duration)")
    parser.add_argument("--rest", type=nonnegative_float, default=0.0, metavar="S",
                        help="seconds the ball lies still at the motion's start before it "
                             "moves, added before --duration's (rally: on the floor before "
                             "its first kick; default %(default)s)")
    parser.add_argument("--noise-px", type=noise_px, default=0.0, metavar="PX",
                        help="Gaussian detection noise per pixel axis, pixels, "
                             "at most 100 (default %(default)s)")
    parser.add_argument("--jitter-ms", type=nonnegative_float, default=0.0, metavar="MS",
                        help="standard deviation of shutter times around the schedule, "
                             "milliseconds, below half a frame period (default %(default)s)")
    # the former --jitter S (seconds, beside --host-jitter and --clock-offset in ms): refused
    # with the value it meant rather than read in another unit
    parser.add_argument("--jitter", type=_renamed_jitter, default=None, metavar="S",
                        help=argparse.SUPPRESS)
    parser.add_argument("--drop-rate", type=fraction, default=0.0, metavar="F",
                        help="fraction of frames lost entirely (default %(default)s)")
    parser.add_argument("--miss-rate", type=fraction, default=0.0, metavar="F",
                        help="fraction of frames with no detection (default %(default)s)")
    parser.add_argument("--clock-offset", type=_camera_value("ms", 1e-3), action="append",
                        default=[], metavar="CAM=MS",
                        help="fault: camera CAM's clock is off by MS milliseconds (true = "
                             "logged + offset; not the first camera, which defines the clock); "
                             "repeatable. The session's rig keeps the rig's own value (0 for a rig "
                             "without clock keys): 'pslog sync' recovers it")
    parser.add_argument("--drift", type=_camera_value("ppm", 1.0), action="append",
                        default=[], metavar="CAM=PPM",
                        help="fault: camera CAM's clock drifts by PPM parts per million (not "
                             "the first camera); repeatable")
    parser.add_argument("--readout", type=_camera_value("ms", 1e-3, all_cameras=True),
                        action="append", default=[], metavar="[CAM=]MS",
                        help="fault: rolling shutters reading top to bottom row in MS "
                             "milliseconds (below a frame period); MS alone: every camera "
                             "but those given as CAM=MS; repeatable, each camera once")
    parser.add_argument("--host-jitter", type=nonnegative_float, default=0.0, metavar="MS",
                        help="fault: standard deviation of the logged stamps around the "
                             "shutter times, milliseconds (host arrival jitter; frame "
                             "indices stay exact), below half a frame period")
    parser.add_argument("--spurious", type=closed_fraction, default=0.0, metavar="F",
                        help="fault: fraction of frames with one false candidate (a "
                             "reflection, a shirt) besides the ball (default %(default)s)")
    parser.add_argument("--spurious-radius", type=_spurious_radius, default=0.0, metavar="PX",
                        help="where the false candidates are: 0, anywhere in the image; else "
                             "within PX pixels of the ball, at most 100 (default %(default)s)")
    # ('--distractor -2,1,0', a negative X, is a value: pslog.cli._Parser)
    parser.add_argument("--distractor", type=_distractor, action="append", default=[],
                        metavar="[CAM=]X,Y,Z",
                        help="fault: a static second orange object at world point X,Y,Z "
                             "(metres), a candidate in every frame of camera CAM, or without "
                             "CAM of every camera whose view contains it; repeatable")
    parser.add_argument("--blackout", type=_blackout, action="append", default=[],
                        metavar="CAM=START:DURATION",
                        help="fault: camera CAM misses the ball from START for DURATION "
                             "seconds; repeatable")
    parser.add_argument("--seed", type=seed, default=0, metavar="N",
                        help="random seed (default %(default)s)")
    parser.add_argument("-o", "--output", required=True, metavar="SESSION.mcap",
                        help="session file to write")
    add_force(parser)
    declare_files(parser, inputs=("rig",), outputs=("output",),
                  sessions=("output",))


def run(args: argparse.Namespace) -> int:
    from pslog.errors import InputError
    from pslog.log import SessionWriter
    from pslog.motion import at_rest_first, get_motion
    from pslog.records import NS
    from pslog.rig import apply_timing, resolve_rig, timing_label
    from pslog.simulation import (
        TRUTH_CLOCK_KEY,
        SimulationOptions,
        check_candidate_faults,
        check_duration,
        check_jitter,
        check_noise,
        simulate_labelled,
        true_rig,
        truth_clock,
    )

    output = args.output  # checked before run() (declare_files)
    rig = resolve_rig(args.rig)
    if args.timing != "rig":
        rig = apply_timing(rig, args.timing)
    timing = timing_label(rig)  # the label always says what the offsets are
    motion = get_motion(args.motion)
    for option, pairs in (("--clock-offset", args.clock_offset), ("--drift", args.drift),
                          ("--readout", args.readout)):
        names = [name for name, _ in pairs]
        twice = next((n for i, n in enumerate(names) if n in names[:i]), False)
        if twice is not False:  # (the last one silently won; --readout 5 --readout 8 too)
            given = ", ".join(f"{v if option == '--drift' else v * 1e3:g}"
                              for n, v in pairs if n == twice)
            what = (f"camera {twice}" if twice is not None
                    else "a readout for every camera (MS alone)")
            return usage_error("simulate", f"argument {option}: {what} given twice "
                                           f"({given}): give each camera once")
    # MS alone for every camera, CAM=MS for one of them, in any order
    readout = {n: value for name, value in args.readout if name is None for n in rig.names}
    readout.update({name: value for name, value in args.readout if name is not None})
    faults: dict[str, dict] = {"clock_offset_s": dict(args.clock_offset),
                               "clock_drift_ppm": dict(args.drift), "readout_s": readout}
    options = SimulationOptions(noise_px=args.noise_px, jitter_s=args.jitter_ms / 1e3,
                                drop_rate=args.drop_rate, miss_rate=args.miss_rate,
                                seed=args.seed, host_jitter_s=args.host_jitter / 1e3,
                                spurious_rate=args.spurious,
                                spurious_radius_px=args.spurious_radius,
                                distractors=tuple(args.distractor),
                                blackouts=tuple(args.blackout), **faults)
    duration = motion.duration if args.duration is None else args.duration
    if args.rest:  # (the ball still first: the session longer by as much)
        try:
            motion = at_rest_first(motion, args.rest)
        except InputError as exc:
            return usage_error("simulate", f"argument --rest: {exc}")
        duration += args.rest
    # command-line values too large for this rig: exit 2, as argparse's own refusals
    for option, check, value in (
            ("--jitter-ms", check_jitter, args.jitter_ms / 1e3),
            ("--host-jitter", lambda r, v: check_jitter(r, v, "host jitter"),
             args.host_jitter / 1e3),
            ("--noise-px", check_noise, args.noise_px),
            ("--duration" + ("/--rest" if args.rest else ""), check_duration, duration)):
        try:
            check(rig, value)
        except InputError as exc:
            return usage_error("simulate", f"argument {option}: {exc}")
    for option, key in (("--clock-offset", "clock_offset_s"), ("--drift", "clock_drift_ppm"),
                        ("--readout", "readout_s")):
        try:
            true_rig(rig, SimulationOptions(**{key: faults[key]}))  # type: ignore[arg-type]
        except InputError as exc:
            return usage_error("simulate", f"argument {option}: {exc}")
    try:
        true_rig(rig, options)
    except InputError as exc:
        return usage_error("simulate", f"arguments --clock-offset/--drift/--readout: {exc}")
    for option, key in (("--distractor", "distractors"), ("--blackout", "blackouts")):
        try:
            check_candidate_faults(rig, SimulationOptions(**{key: getattr(options, key)}))
        except InputError as exc:
            return usage_error("simulate", f"argument {option}: {exc}")
    for name, start, _ in args.blackout:  # (else a session said to have blackouts, none in it)
        if start >= duration:
            return usage_error("simulate", f"argument --blackout: camera {name}'s blackout "
                                           f"starts at {start:g} s, not before the session "
                                           f"ends ({duration:g} s): it would hide nothing")
    # the session's rig holds the nominal clock, the rig's own (zeros for a rig without
    # clock keys): the faults are for 'pslog sync' to find; their true values are kept in
    # the metadata to score it. (A rig file's own clock keys, a synced rig's, were zeroed
    # too while the cameras were simulated with them: its fused tracks 14-25 mm off a
    # readout of 25 ms, and nothing said; 'record --synthetic' keeps them)
    from pslog import progress

    clock = truth_clock(rig, options)
    progress.update(total=2, what=f"simulating {duration:.1f} s of {motion.name}")
    detections, truth, ball = simulate_labelled(rig, motion, duration, options)
    nominal = rig
    detections, truth, n_early = drop_before_zero(detections, truth)
    ball, _, _ = drop_before_zero(ball, truth)
    settings = {"motion": motion.name, "duration_s": repr(float(duration)),
                "noise_px": repr(args.noise_px), "jitter_s": repr(args.jitter_ms / 1e3),
                "drop_rate": repr(args.drop_rate), "miss_rate": repr(args.miss_rate),
                "seed": str(args.seed)}
    faulted = {k: v for k, v in (
        ("clock_offset_s", args.clock_offset), ("clock_drift_ppm", args.drift),
        ("readout_s", args.readout), ("host_jitter_s", args.host_jitter / 1e3)) if v}
    candidate_faults = {k: v for k, v in (
        ("spurious", args.spurious), ("distractors", args.distractor),
        ("blackouts", args.blackout)) if v}
    if args.rest:
        settings["rest_s"] = repr(args.rest)
    if args.spurious:
        settings["spurious_rate"] = repr(args.spurious)
        settings["spurious_radius_px"] = repr(args.spurious_radius)
    if args.distractor:
        settings["distractors"] = ";".join(f"{'*' if n is None else n}="
                                           + ",".join(repr(x) for x in p)
                                           for n, p in args.distractor)
    if args.blackout:
        settings["blackouts"] = ";".join(f"{n}={s!r}:{d!r}" for n, s, d in args.blackout)
    for key, value in faulted.items():
        settings[key] = (repr(value) if key == "host_jitter_s" else
                         ",".join(f"{'*' if n is None else n}={v!r}" for n, v in value))
    source = "pslog simulate " + " ".join(f"{k}={v}" for k, v in settings.items())
    metadata = {f"simulate.{k}": v for k, v in settings.items()}
    metadata[TRUTH_CLOCK_KEY] = clock
    progress.step(f"writing {output}")
    with SessionWriter(output, nominal, force=args.force, timing=timing, source=source,
                       metadata=metadata, on_error="discard") as writer:
        writer.add_detections(detections)
        writer.add_truth(truth)
        if candidate_faults:  # which candidate is the ball: for 'pslog eval'
            writer.add_ball_truth(ball)
    span = (detections.frame_time_ns[-1] - detections.frame_time_ns[0]) / NS \
        if detections.n_frames else 0.0
    print(f"wrote {output}: {len(rig)} cameras ({', '.join(rig.names)}), timing {timing}, "
          f"motion {motion.name}, {detections.n_frames} frames over {span:.3f} s, "
          f"{detections.n_candidates} detections"
          + (f" ({ball.n_candidates} of the ball; candidate faults: "
             f"{', '.join(candidate_faults)})" if candidate_faults else "")
          + f", {len(truth)} truth points"
          + (f" ({n_early} frame{'' if n_early == 1 else 's'} logged before t = 0 dropped)"
             if n_early else "")
          + (f"; clock faults ({', '.join(faulted)}) kept as {TRUTH_CLOCK_KEY!r} in the "
             f"metadata, the rig holds the nominal clock (its own): run 'pslog sync'"
             if faulted else ""))
    return 0


def drop_before_zero(detections, truth):
    """Remove frames (and truth samples) that jitter or a clock fault moved before the
    session clock's zero:
    the recording starts at t = 0 and MCAP log times cannot be negative.

    Returns (detections, truth, number of frames dropped).
    """
    from pslog.records import Detections, Truth

    keep = detections.frame_time_ns >= 0
    n_early = int(np.count_nonzero(~keep))
    if not n_early:
        return detections, truth, 0
    rows = np.flatnonzero(keep)
    new_row = np.full(detections.n_frames, -1)
    new_row[rows] = np.arange(len(rows))
    cand = keep[detections.cand_frame]
    detections = Detections.from_frames(
        detections.camera_names, detections.frame_time_ns[rows], detections.frame_camera[rows],
        detections.frame_index[rows], new_row[detections.cand_frame[cand]],
        detections.cand_uv[cand], detections.cand_radius[cand], detections.cand_score[cand])
    early = truth.time_ns < 0
    return detections, Truth(truth.time_ns[~early], truth.position_world[~early]), n_early
