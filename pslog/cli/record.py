"""``pslog record``: record a session from cameras, video files or a rendered synthetic rig."""

from __future__ import annotations

import argparse
import re

from pslog.cli._common import (
    add_force,
    add_rig,
    check_output,
    declare_files,
    exposure_s,
    hsv_box,
    int_in,
    motion_name,
    number_at_most,
    positive_float,
    positive_int,
    run_stoppable,
    seed,
    usage_error,
)
from pslog.errors import InputError, shell_word

DESCRIPTION = """\
Record a session: every camera of the rig is captured in its own process (capture, ball
detection, JPEG encoding) and one writer stores the frames, the detections, the calibration
and the timing into an MCAP session. A status line on stderr shows per camera the frames,
the frame rate, the frames with a ball and the drops (rewritten in place on a terminal;
written every 5 s into a log or pipe, the first after 5 s); a summary follows at the end.
Ctrl-C, SIGTERM or SIGHUP (a closed terminal), at any moment, stops the cameras and
finishes the file cleanly: exit code 0 once frames were recorded, 1 (and no file) when
stopped before any camera delivered a frame. A SIGKILL loses at most the last half second
written (the file is flushed every 0.5 s; 'pslog recover' salvages the rest). If the disk fills up,
the cameras are stopped and what was written is kept; the error says where. Detections are
written before the images of the same frames, so a full disk costs images first: every
frame whose image was kept has its detection too.

Sources (one --source per camera of the rig, NAME a camera name of the rig):
  NAME=0, NAME=/dev/video2   a live camera (device index or V4L2 path); capture times from
                             the driver's buffer timestamps when usable, else the host's
                             monotonic clock at grab (the log says which)
  NAME=clip.mp4[@OFFSET]     a video file; capture times are the container's timestamps plus
                             OFFSET seconds (default 0), so files from separate cameras form
                             one session; --offset NAME=SECONDS does the same
Video files are read as fast as they decode; live cameras in real time. A camera that
fails to open or stops delivering is reported and logged; the others keep recording (exit
code 0 if any camera recorded frames, 1 and no file if none did).

--synthetic renders what each camera sees of a ball (shaded sphere, motion blur over the
exposure, lens distortion, sensor noise, a lined green field) following --motion under the
rig's shutter schedule, in real time unless --fast, and stores the ground truth too. A rig
with clock corrections (clock_offset, clock_drift_ppm, readout: a rig from 'pslog sync') is
rendered with those clock errors, as 'pslog live --synthetic' and 'pslog simulate' do: each
shutter fires at the rig's offset on the true clock (docs/timing.md), its camera's clock
stamps it off by the clock model (offset - clock_offset + k / fps without drift; a frame
stamped before 0 is not taken), and the camera sees the ball at the true time of its stamp;
the stored rig corrects them. The summary gives the
session time the frames span and the wall time the recording took (its frame rate), then the
wall time including starting the camera processes (a few seconds).

Ball detection: pixels inside an HSV box (OpenCV scales: hue 0..179, saturation and value
0..255; a hue minimum above the maximum wraps around red), connected components, sub-pixel
centroids; up to --max-candidates per frame, best first.
"""

EXAMPLES = """\
examples:
  pslog record --rig rig.toml --source cam1=0 --source cam2=/dev/video2 -o match.mcap
  pslog record --rig rig.toml --source cam1=a.mp4 --source cam2=b.mp4@0.0167 -o s.mcap
  pslog record --synthetic --rig paper3 --timing typeA --motion throw -o throw.mcap --fast
"""

_SOURCE = re.compile(r"^([^=]+)=(.+)$")

#: before each line the command writes to stderr (the recorder's status line, messages and
#: summary, the notes after it), as every command's lines start
PREFIX = "pslog record: "


class MalformedSource(InputError):
    """A ``--source``/``--offset`` value that is malformed in itself (exit 2, as argparse
    does), as opposed to one naming a camera or file that is not there (exit 1)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.rig import TIMING_PRESETS

    parser.description = DESCRIPTION
    parser.epilog = EXAMPLES
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    add_rig(parser)
    parser.add_argument("-o", "--output", required=True, metavar="SESSION.mcap",
                        help="session file to write")
    parser.add_argument("--source", action="append", default=[], metavar="NAME=SPEC",
                        help="camera NAME records from SPEC: a device index, /dev/videoN, or "
                             "a video file with an optional @OFFSET in seconds (repeat per "
                             "camera)")
    parser.add_argument("--offset", action="append", default=[], metavar="NAME=SECONDS",
                        help="start offset of camera NAME's video file on the session clock, "
                             "seconds (repeat per camera; default 0)")
    parser.add_argument("--synthetic", action="store_true",
                        help="render the rig's cameras instead of reading sources")
    parser.add_argument("--timing", choices=TIMING_PRESETS,
                        help="set the rig's shutter offsets from a preset (default: the "
                             "rig's own offsets)")
    from pslog.motion import MOTIONS

    parser.add_argument("--motion", default="throw", type=motion_name,
                        metavar="MOTION", help=f"synthetic ball motion: {', '.join(MOTIONS)} "
                                               f"(default %(default)s)")
    parser.add_argument("--fast", action="store_true",
                        help="synthetic: render as fast as possible instead of in real time")
    parser.add_argument("--duration", type=positive_float, metavar="S",
                        help="stop after S seconds of session time (synthetic default: the "
                             "motion's duration; otherwise until the sources end or Ctrl-C)")
    parser.add_argument("--noise", default=2.0, metavar="SIGMA",
                        type=number_at_most(255.0, "levels", "the whole 8-bit range"),
                        help="synthetic sensor noise, standard deviation in 8-bit levels "
                             "(default %(default)s)")
    parser.add_argument("--ball-radius", default=0.0215, metavar="M",
                        type=number_at_most(1.0, "m", "a ball, not a wall", positive=True),
                        help="synthetic ball radius in metres (default %(default)s, a golf "
                             "ball)")
    parser.add_argument("--exposure", type=exposure_s, default=0.004, metavar="S",
                        help="synthetic exposure time in seconds, for motion blur "
                             "(default %(default)s; 0 for none)")
    parser.add_argument("--seed", type=seed, default=0, metavar="N",
                        help="synthetic random seed (default %(default)s)")
    parser.add_argument("--no-frames", action="store_true",
                        help="store detections only, not the JPEG frames")
    parser.add_argument("--jpeg-quality", type=int_in(1, 100), default=90, metavar="Q",
                        help="JPEG quality of stored frames, 1..100 (default %(default)s)")
    add_detector_arguments(parser)
    add_force(parser)
    declare_files(parser, inputs=("rig", video_files), outputs=("output",),
                  sessions=("output",))


def add_detector_arguments(parser: argparse.ArgumentParser) -> None:
    """``--hsv`` and ``--max-candidates`` (shared with ``pslog redetect``)."""
    from recorders.detect import HsvRange

    parser.add_argument("--hsv", metavar="H1,H2,S1,S2,V1,V2", type=hsv_box,
                        help="ball colour as an HSV box hmin,hmax,smin,smax,vmin,vmax, "
                             "hue 0..179, saturation and value 0..255; hmin > hmax wraps "
                             "round the hue circle through red (e.g. 170,10,...) "
                             f"(default {HsvRange().text()}, an orange ball)")
    parser.add_argument("--max-candidates", type=positive_int, default=5, metavar="K",
                        help="ball candidates kept per frame, best first "
                             "(default %(default)s)")


def parse_hsv(text: str | None):
    from recorders.detect import HsvRange

    return HsvRange() if text is None else HsvRange.parse(text)


def run(args: argparse.Namespace) -> int:
    # SIGINT and SIGTERM only request a stop from here on (finishing the work cleanly)
    return run_stoppable(_run, args)


def _run(args: argparse.Namespace, stop) -> int:
    from pslog.rig import apply_timing, resolve_rig

    output = check_output(args.output, args.force)
    rig = resolve_rig(args.rig)
    if args.timing:
        rig = apply_timing(rig, args.timing)
    hsv = parse_hsv(args.hsv)
    if args.synthetic:
        if args.source or args.offset:
            return usage_error("record", "--synthetic renders every camera; do not give "
                                         "--source/--offset")
        from pslog.simulation import check_duration, check_exposure

        try:  # values that are bad for this rig: command-line errors like any other
            check_exposure(rig, args.exposure)
            if args.duration is not None:
                check_duration(rig, args.duration)
        except InputError as exc:
            return usage_error("record", str(exc))
        from recorders.synthetic import record_synthetic

        summary = record_synthetic(
            rig, args.motion, output, duration=args.duration, fast=args.fast,
            frames=not args.no_frames, jpeg_quality=args.jpeg_quality, seed=args.seed,
            force=args.force, timing=args.timing, hsv=hsv, max_candidates=args.max_candidates,
            ball_radius=args.ball_radius, exposure_s=args.exposure, noise_sigma=args.noise,
            stop_request=stop, prefix=PREFIX)
    else:
        if not args.source:
            return usage_error("record", "give a --source NAME=SPEC for every camera of the "
                                         "rig, or --synthetic")
        if args.fast:
            return usage_error("record", "--fast applies to --synthetic only (video files are "
                                         "always read as fast as they decode)")
        from recorders.record import record
        from recorders.sources import FileSpec

        try:
            specs = parse_sources(rig, args.source, args.offset)
        except MalformedSource as exc:  # a malformed value: a command-line error (exit 2)
            return usage_error("record", str(exc))
        videos = [spec.path for spec in specs.values() if isinstance(spec, FileSpec)]
        output = check_output(args.output, args.force, inputs=videos)
        summary = record(rig, specs, output, duration_s=args.duration,
                         frames=not args.no_frames, jpeg_quality=args.jpeg_quality, hsv=hsv,
                         max_candidates=args.max_candidates, force=args.force,
                         timing=args.timing, source="record " + " ".join(args.source),
                         stop_request=stop, prefix=PREFIX)
    if summary.n_frames == 0 and summary.interrupted:
        raise InputError(f"stopped before any camera delivered a frame; nothing was written "
                         f"to {output}")
    if summary.n_frames == 0:
        raise InputError(f"no camera delivered a frame; nothing was written to {output}")
    if not args.synthetic:
        _note_offsets(output, rig)
    return 0


def _note_offsets(output, rig) -> None:
    """Say so (on stderr, like the recorder's other messages) when the recorded shutter
    phases are not the rig's offsets (the session's timing label follows the rig's offsets,
    which the user may want to correct). The recording is already complete: a failure to
    read it back here only costs the note."""
    import sys

    from pslog.errors import PslogError
    from pslog.log import read_session
    from pslog.log.info import offset_disagreements
    from pslog.rig import timing_label

    try:
        off = offset_disagreements(read_session(output).detections, rig)
    except PslogError as exc:
        print(f"{PREFIX}note: the recorded shutter offsets could not be compared with the rig's "
              f"({exc}); the recording itself is complete", file=sys.stderr)
        return
    if off:
        # within the frame period, as a rig's offset is (0 <= offset < period): the measured
        # phase may come as -13.6 ms, which the rig refuses, for the 19.7 ms to set
        listed = ", ".join(f"{name} {(measured % rig.camera(name).frame_period) * 1e3:.1f} ms "
                           f"(rig {nominal * 1e3:.1f} ms)" for name, measured, nominal in off)
        # (walk42: three webcams' clips, the rig's offsets 0: the note offered only to set
        # the offsets, which fusion hardly reads (it fuses the logged times; type A's gap
        # rule alone reads them), not the clocks' sync that took the tracks from 10-15 mm
        # to 1.4-3 mm: import's and info's notes name it)
        out = shell_word(output)
        print(f"{PREFIX}note: measured shutter offsets differ from the rig's: {listed}; the "
              f"session keeps the rig's offsets (timing '{timing_label(rig)}') and the times "
              f"as logged: cameras without genlock have clocks of their own, 'pslog sync "
              f"{out} -o synced.mcap' estimates them from the ball, and writes the shutters' "
              f"phases it measures into the copy's rig (then fuse that); if the "
              f"rig's offsets are wrong instead, 'pslog rig show {out} > fixed.toml', set the "
              f"offsets and 'pslog fuse {out} --rig fixed.toml'", file=sys.stderr)


#: largest device index a --source takes: OpenCV's VideoCapture takes a C int (a larger one
#: was OpenCV's own several-line "Overload resolution failed" as the camera's failure)
MAX_DEVICE_INDEX = 2**31 - 1


def parse_sources(rig, sources: list[str], offsets: list[str]) -> dict:
    """``NAME=SPEC`` strings (and ``NAME=SECONDS`` offsets) -> camera name -> source spec."""
    from pathlib import Path

    from pslog.inputs import not_there, special_file
    from recorders.sources import DeviceSpec, FileSpec

    offset_of: dict[str, float] = {}
    for text in offsets:
        match = _SOURCE.match(text)
        name, value = (match.group(1).strip(), match.group(2).strip()) if match else ("", "")
        if not name or not value:
            raise MalformedSource(f"--offset must be NAME=SECONDS, got {text!r}")
        rig.index(name)
        offset_of[name] = _seconds(value, text, name)
    specs: dict = {}
    for text in sources:
        match = _SOURCE.match(text)
        name, spec = (match.group(1).strip(), match.group(2).strip()) if match else ("", "")
        if not name or not spec:
            raise MalformedSource(f"--source must be NAME=SPEC, got {text!r}")
        cam = rig.camera(name)  # RigError naming an unknown camera
        if name in specs:
            raise MalformedSource(f"camera {name!r} has two --source options")
        if _is_device(spec):  # a device index or a V4L2 path
            device = spec if spec.startswith("/dev/") else int(spec)
            if isinstance(device, int) and device > MAX_DEVICE_INDEX:  # OpenCV's C int
                raise MalformedSource(f"camera {name!r}: device index {device} is beyond any "
                                      f"camera (at most {MAX_DEVICE_INDEX}) in {text!r}")
            specs[name] = DeviceSpec(device, cam.width, cam.height, cam.fps)
        else:
            path, offset = spec, offset_of.get(name, 0.0)
            video, at = _video_and_offset(spec)
            if at is not None:
                if name in offset_of:
                    raise MalformedSource(f"camera {name!r}: offset given both with @ and --offset")
                path, offset = video, _seconds(at, text, name)
            if not Path(path).is_file():
                kind = special_file(path) or ("a folder" if Path(path).is_dir() else None)
                why = not_there(path)
                raise InputError(f"camera {name!r}: {path} is {kind}, not a video file" if kind
                                 else f"camera {name!r}: {why}" if why
                                 else f"camera {name!r}: video file not found: {path}")
            from pslog.outputs import same_file

            for other, given in specs.items():
                # (walk42: a command line's source copied for the next camera, its name left:
                # cam1's clip recorded as cam2's too, fused into nonsense without a word)
                if isinstance(given, FileSpec) and same_file(given.path, path):
                    spelled = "" if str(given.path) == str(path) else f" (as {given.path})"
                    raise MalformedSource(f"camera {name!r} and camera {other!r} both read "
                                          f"{path}{spelled}: each camera needs a video "
                                          f"file of its own")
            specs[name] = FileSpec(path, cam.width, cam.height, offset)
    for name in offset_of:
        if not isinstance(specs.get(name), FileSpec):
            raise InputError(f"--offset {name}=...: camera {name!r} has no video file source")
    return specs


def _is_device(spec: str) -> bool:
    return bool(re.fullmatch(r"[0-9]+", spec)) or spec.startswith("/dev/")


def _video_and_offset(spec: str) -> tuple[str, str | None]:
    """``FILE[@OFFSET]`` -> (FILE, OFFSET text or None); a file whose name holds an @ is
    taken whole."""
    from pathlib import Path

    head, sep, tail = spec.rpartition("@")
    return (head, tail) if sep and not Path(spec).exists() else (spec, None)


def video_files(args: argparse.Namespace) -> list[str]:
    """The video files named by ``--source NAME=FILE[@OFFSET]`` (inputs of ``record``, read
    as :func:`parse_sources` reads them)."""
    files = []
    for text in getattr(args, "source", None) or ():
        match = _SOURCE.match(text)
        spec = match.group(2).strip() if match else ""
        if spec and not _is_device(spec):
            files.append(_video_and_offset(spec)[0])
    return files


def _seconds(value: str, text: str, camera: str) -> float:
    try:
        seconds = float(value)
    except ValueError:
        raise MalformedSource(f"camera {camera!r}: offset is not a number of seconds in "
                         f"{text!r}") from None
    if seconds != seconds or abs(seconds) == float("inf"):
        raise MalformedSource(f"camera {camera!r}: offset must be finite in {text!r}")
    if seconds < 0:
        # a frame before the session clock's zero cannot be stored (MCAP times are unsigned)
        raise MalformedSource(f"camera {camera!r}: offset must be >= 0 seconds in {text!r}: the "
                         f"session clock starts at 0 (delay the other cameras instead)")
    if seconds > 1e9:  # int64 nanoseconds of the session clock hold about 292 years
        raise MalformedSource(f"camera {camera!r}: offset must be at most 1e9 seconds (about "
                              f"30 years) in {text!r}")
    return seconds
