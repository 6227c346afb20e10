"""``pslog simulate``: a session of a rig watching a moving ball (detections + truth)."""

from __future__ import annotations

import argparse

import numpy as np

from ._common import (
    add_force,
    add_rig,
    check_output,
    declare_files,
    fraction,
    noise_px,
    nonnegative_float,
    positive_float,
    seed,
    usage_error,
)

_TIMINGS = ("sync", "typeA", "typeB", "rig")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.motion import MOTIONS

    add_rig(parser)
    parser.add_argument("--timing", choices=_TIMINGS, default="rig",
                        help="set the rig's shutter offsets from a preset (default: 'rig', the "
                             "rig's own offsets; the built-in rigs' are all zero, i.e. sync)")
    parser.add_argument("--motion", choices=list(MOTIONS), default="spiral",
                        help="ball motion (default %(default)s)")
    parser.add_argument("--duration", type=positive_float, default=None, metavar="S",
                        help="seconds of motion (default: the motion's natural duration)")
    parser.add_argument("--noise-px", type=noise_px, default=0.0, metavar="PX",
                        help="Gaussian detection noise per pixel axis, pixels, "
                             "at most 100 (default %(default)s)")
    parser.add_argument("--jitter", type=nonnegative_float, default=0.0, metavar="S",
                        help="standard deviation of shutter times around the schedule, "
                             "seconds, below half a frame period (default %(default)s)")
    parser.add_argument("--drop-rate", type=fraction, default=0.0, metavar="F",
                        help="fraction of frames lost entirely (default %(default)s)")
    parser.add_argument("--miss-rate", type=fraction, default=0.0, metavar="F",
                        help="fraction of frames with no detection (default %(default)s)")
    parser.add_argument("--seed", type=seed, default=0, metavar="N",
                        help="random seed (default %(default)s)")
    parser.add_argument("-o", "--output", required=True, metavar="SESSION.mcap",
                        help="session file to write")
    add_force(parser)
    declare_files(parser, inputs=("rig",), outputs=("output",))


def run(args: argparse.Namespace) -> int:
    from pslog.errors import InputError
    from pslog.log import SessionWriter
    from pslog.motion import get_motion
    from pslog.records import NS
    from pslog.rig import apply_timing, resolve_rig, timing_label
    from pslog.simulation import (
        SimulationOptions,
        check_duration,
        check_jitter,
        check_noise,
        simulate,
    )

    output = check_output(args.output, args.force)
    rig = resolve_rig(args.rig)
    if args.timing != "rig":
        rig = apply_timing(rig, args.timing)
    timing = timing_label(rig)  # the label always says what the offsets are
    motion = get_motion(args.motion)
    options = SimulationOptions(noise_px=args.noise_px, jitter_s=args.jitter,
                                drop_rate=args.drop_rate, miss_rate=args.miss_rate,
                                seed=args.seed)
    duration = motion.duration if args.duration is None else args.duration
    # command-line values too large for this rig: exit 2, as argparse's own refusals
    for option, check, value in (("--jitter", check_jitter, args.jitter),
                                 ("--noise-px", check_noise, args.noise_px),
                                 ("--duration", check_duration, duration)):
        try:
            check(rig, value)
        except InputError as exc:
            return usage_error("simulate", f"argument {option}: {exc}")
    detections, truth = simulate(rig, motion, duration, options)
    detections, truth, n_early = drop_before_zero(detections, truth)
    settings = {"motion": motion.name, "duration_s": repr(float(duration)),
                "noise_px": repr(args.noise_px), "jitter_s": repr(args.jitter),
                "drop_rate": repr(args.drop_rate), "miss_rate": repr(args.miss_rate),
                "seed": str(args.seed)}
    source = "pslog simulate " + " ".join(f"{k}={v}" for k, v in settings.items())
    with SessionWriter(output, rig, force=args.force, timing=timing, source=source,
                       metadata={f"simulate.{k}": v for k, v in settings.items()},
                       on_error="discard") as writer:
        writer.add_detections(detections)
        writer.add_truth(truth)
    span = (detections.frame_time_ns[-1] - detections.frame_time_ns[0]) / NS \
        if detections.n_frames else 0.0
    print(f"wrote {output}: {len(rig)} cameras ({', '.join(rig.names)}), timing {timing}, "
          f"motion {motion.name}, {detections.n_frames} frames over {span:.3f} s, "
          f"{detections.n_candidates} detections, {len(truth)} truth points"
          + (f" ({n_early} jittered frames before t = 0 dropped)" if n_early else ""))
    return 0


def drop_before_zero(detections, truth):
    """Remove frames (and truth samples) that jitter moved before the session clock's zero:
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
