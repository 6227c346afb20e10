"""``pslog calibrate``: calibrate one camera and add or replace it in a rig TOML file.

Two sources:

- ``--points points.csv`` (header ``x,y,z,u,v``, metres and pixels): intrinsics, distortion
  and pose from 3D-2D correspondences (at least 6 non-coplanar points), or, with
  ``--fix-intrinsics``, the pose only with the rig's K and distortion (at least 4 points,
  coplanar allowed).
- ``--chessboard 9x6 --images DIR_OR_VIDEO``: intrinsics from chessboard views. A chessboard
  does not locate the camera in the world, so the camera keeps its pose from the rig (or gets
  identity R and zero t if new); solve the pose afterwards with ``--points ... --fix-intrinsics``.

The rig file is created if missing; other cameras, their order and the rig's name are kept,
and a camera replaced keeps its clock (``clock_offset``, ``clock_drift_ppm``, ``readout`` from
``pslog sync``: a calibration is geometry).
Replacing a camera that is already in the rig needs ``--force`` (its old calibration would be
lost), except with ``--fix-intrinsics``, whose purpose is to update that camera's pose.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from pslog.cli._common import PSLOG_RIG, add_force, declare_files, misnamed, nonnegative_float
from pslog.errors import InputError

#: Largest reprojection RMS a calibration may have to be written into the rig, pixels: the
#: points or corners are then tens of pixels off the model on average, no calibration
#: (a chessboard of 1e30 m squares gave 32499 px).
MAX_RMS_PX = 50.0

_WORST_SHOWN = 5


class BadOption(InputError):
    """A command-line value that is bad in itself, with another option, or against the rig or
    the images (``--offset`` beyond the frame period, ``--width`` other than the images'):
    exit 2 with argparse's one line, as every other command reports a bad value
    (:func:`pslog.cli._common.usage_error`), not exit 1 (a fault of the input files)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.camera import MAX_FPS, MAX_IMAGE_SIZE, MIN_FPS
    from pslog.cli._common import camera_name, chessboard, int_in, number_at_most, positive_int
    parser.epilog = ("examples:\n"
                     "  pslog calibrate --points pts.csv --name cam1 --width 640 --height 480 "
                     "--rig rig.toml\n"
                     "  pslog calibrate --chessboard 9x6 --square 0.025 --images shots/ "
                     "--name cam1 --rig rig.toml\n"
                     "  pslog calibrate --points floor.csv --fix-intrinsics --name cam1 "
                     "--rig rig.toml")
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--points", metavar="POINTS.csv",
                        help="3D-2D correspondences, header x,y,z,u,v (metres, pixels)")
    source.add_argument("--chessboard", metavar="COLSxROWS", type=chessboard,
                        help="chessboard inner corners per row x per column, e.g. 9x6")
    parser.add_argument("--name", required=True, metavar="NAME", type=camera_name,
                        help="camera name in the rig")
    parser.add_argument("--rig", required=True, metavar="RIG.toml",
                        help="rig file to add the camera to (created if missing)")
    # (at most a camera's largest side: 99999999 was refused by the camera, exit 1)
    size = int_in(1, MAX_IMAGE_SIZE)
    parser.add_argument("--width", type=size, metavar="PX", help="image width, pixels, at most "
                        f"{MAX_IMAGE_SIZE} (required for a new camera with --points; checked "
                        "against the images with --chessboard)")
    parser.add_argument("--height", type=size, metavar="PX", help="image height, "
                        "pixels (as --width)")
    # (a rate below the rig's least was refused by the rig, exit 1, one above its most by
    # this, exit 2: both are usage errors)
    parser.add_argument("--fps", type=number_at_most(MAX_FPS, "fps", "beyond any camera",
                                                     positive=True, least=MIN_FPS),
                        metavar="FPS", help="frame rate, frames per second (default: the "
                                            "rig's value for this camera, else 30)")
    parser.add_argument("--offset", type=nonnegative_float,
                        metavar="S", help="shutter offset within the frame period, seconds "
                             "(default: the rig's value, else 0)")
    parser.add_argument("--fix-intrinsics", action="store_true",
                        help="with --points: keep the rig's K and distortion for this camera "
                             "and solve the pose only (coplanar points allowed)")
    parser.add_argument("--model", default="auto",
                        choices=("auto", "none", "k1", "k1k2", "k1k2k3", "full"),
                        help="with --points: distortion terms to estimate (default "
                             "%(default)s: none below 10 points, k1,k2 below 100, all five from "
                             "100)")
    # (the library's bounds, pslog.calibration.chessboard's: 1e-30 was OpenCV's assertion)
    parser.add_argument("--square", type=number_at_most(1.0, "m", "no board's square is "
                                                                  "larger", positive=True,
                                                        least=1e-4),
                        default=0.025, metavar="M", help="chessboard square side, metres, "
                                                         "0.0001 to 1 (default %(default)s)")
    parser.add_argument("--images", metavar="DIR_OR_VIDEO",
                        help="with --chessboard: folder of images or a video file")
    parser.add_argument("--max-frames", type=positive_int, default=60,
                        metavar="N", help="from a video, use at most this many evenly "
                                          "spaced frames (default %(default)s)")
    add_force(parser)
    # the rig file is updated in place by design; it may not be the points or images
    declare_files(parser, inputs=("points", "images"), updates=("rig",))


def run(args: argparse.Namespace) -> int:
    from pslog.cli._common import usage_error

    try:
        return _run(args)
    except BadOption as exc:  # raised before anything is written
        return usage_error("calibrate", str(exc))


def _run(args: argparse.Namespace) -> int:
    from pslog.errors import OutputExistsError
    from pslog.rig import BUILTIN_RIGS, Rig, load_rig, save_rig

    rig_path = Path(args.rig)
    if not rig_path.exists() and str(args.rig) in BUILTIN_RIGS:
        # (a bad command-line value, exit 2, as a new rig file named for another format)
        raise BadOption(f"--rig {args.rig}: calibrate writes a rig file; give a path such as "
                        f"rig.toml (built-in rigs cannot be changed)")
    # a new rig file is pslog's TOML: under another name ('--rig cams.yml') pslog itself
    # then read it as OpenCV ("malformed OpenCV FileStorage file"; session 32), the
    # mismatch 'rig export -o' refuses
    wrong = None if rig_path.exists() else misnamed(
        "--rig", args.rig, "toml", PSLOG_RIG,
        "calibrate writes one; other tools' formats: 'pslog rig export'")
    if wrong:
        raise BadOption(wrong)
    rig = load_rig(rig_path, "pslog") if rig_path.exists() else None  # rewritten as pslog's
    existing = rig.camera(args.name) if rig is not None and args.name in rig.names else None

    if args.fix_intrinsics and args.chessboard:
        raise BadOption("--fix-intrinsics goes with --points (a chessboard gives intrinsics)")
    if args.chessboard and not args.images:
        raise BadOption("--chessboard needs --images DIR_OR_VIDEO")
    if args.images and not args.chessboard:
        raise BadOption("--images goes with --chessboard")
    fps = args.fps if args.fps is not None else (existing.fps if existing else 30.0)
    offset = args.offset if args.offset is not None else (existing.offset if existing else 0.0)
    _check_offset(args, existing, rig_path, fps, offset)
    if existing is not None and not args.fix_intrinsics and not args.force:
        raise OutputExistsError(f"camera {args.name!r} is already in {rig_path}; use --force "
                                f"to replace its calibration")

    if args.chessboard:
        camera, rms_px = _run_chessboard(args, existing, fps, offset)
    else:
        camera, rms_px = _run_points(args, existing, rig_path, fps, offset)

    kept = ""
    if (existing is not None and existing.has_clock_correction
            and camera.fps != existing.fps):
        # a new frame rate is a new clock: the estimated one (its readout within the old
        # frame period) no longer describes it
        kept = (f"; dropped its clock ({existing.fps:g} -> {camera.fps:g} fps): run 'pslog "
                f"sync' again")
    elif existing is not None and existing.has_clock_correction:
        # a calibration is geometry: the clock 'pslog sync' estimated for this camera (a rig
        # from 'pslog rig show SYNCED.mcap', the README's way to correct a calibration and
        # re-fuse) stays; dropped, a re-fuse lost the sync (3 webcams: typeA 29.8 mm, filter
        # 23.7, against 9.0 and 5.2 with the clocks kept)
        camera = camera.replace(clock_offset=existing.clock_offset,
                                clock_drift_ppm=existing.clock_drift_ppm,
                                readout=existing.readout)
        kept = (f"; kept its clock: offset {existing.clock_offset * 1e3:+.4f} ms, drift "
                f"{existing.clock_drift_ppm:+.3f} ppm, readout {existing.readout * 1e3:.4f} ms")
    if not rms_px <= MAX_RMS_PX:  # (NaN too)
        check = "--square and the images" if args.chessboard else "the points"
        raise InputError(f"reprojection RMS {rms_px:.4g} px is beyond {MAX_RMS_PX:g} px: the "
                         f"calibration failed (check {check}); "
                         + (f"{rig_path} not changed" if rig is not None else "nothing written"))
    new_rig = (Rig((camera,), rig_path.stem) if rig is None else rig.with_camera(camera))
    # the old rig is replaced only by a complete new one (full disk: it stays as it was)
    save_rig(new_rig, rig_path, inputs=_inputs(args))
    action = "replaced" if existing is not None else "added"
    print(f"{action} camera {camera.name!r} (camera {new_rig.index(camera.name) + 1} of "
          f"{len(new_rig)}) in {rig_path}{kept}")
    return 0


def _check_offset(args, existing, rig_path: Path, fps: float, offset: float) -> None:
    """The shutter offset within the frame period (``0 <= offset < 1 / fps``, as a rig's
    camera has it), said before the calibration runs: the --offset given, or the rig's kept
    for this camera at a new --fps."""
    period = 1.0 / fps
    if offset < period:
        return
    if args.offset is not None:
        raise BadOption(f"argument --offset: {offset:g} s must be below the frame period, "
                        f"{period:.6g} s at {fps:g} fps")
    raise BadOption(f"argument --fps: the offset of camera {args.name!r} in {rig_path}, "
                    f"{existing.offset:g} s, is beyond the frame period at {fps:g} fps "
                    f"({period:.6g} s); give --offset too")


def _inputs(args) -> list[str]:
    return [p for p in (args.points, args.images) if p]


def _run_points(args, existing, rig_path: Path, fps: float, offset: float):
    import numpy as np

    from pslog.calibration import calibrate_from_points, read_points_csv

    points_world, uv, lines = read_points_csv(args.points, with_lines=True)
    if args.fix_intrinsics:
        if existing is None:
            where = f"not in {rig_path}" if rig_path.exists() else f"{rig_path} does not exist"
            raise InputError(f"--fix-intrinsics needs camera {args.name!r} in the rig ({where}); "
                             f"calibrate it first")
        for key in ("width", "height"):
            value = getattr(args, key)
            if value is not None and value != getattr(existing, key):
                raise BadOption(f"--{key} {value} differs from the {key} of camera "
                                f"{args.name!r} in the rig, {getattr(existing, key)} (its K "
                                f"is for that size)")
        width, height, K, dist = existing.width, existing.height, existing.K, existing.dist
    else:
        width = args.width if args.width is not None else (existing.width if existing else None)
        height = (args.height if args.height is not None
                  else (existing.height if existing else None))
        if width is None or height is None:
            raise BadOption("--width and --height are required for a new camera")
        K = dist = None
    result = calibrate_from_points(points_world, uv, width, height, name=args.name, fps=fps,
                                   offset=offset, K=K, dist=dist, model=args.model)
    camera = result.camera
    n = len(points_world)
    what = ("pose only, K and distortion kept from the rig" if result.fixed_intrinsics
            else f"distortion model {result.model}")
    print(f"{camera.name}: calibrated from {n} points in {args.points} ({what})")
    print(f"  reprojection RMS {result.rms_px:.3f} px, max {result.residuals_px.max():.3f} px")
    _print_intrinsics(camera)
    centre = camera.center_world
    print(f"  camera centre (world): [{centre[0]:.4f}, {centre[1]:.4f}, {centre[2]:.4f}] m")
    worst = result.worst(min(_WORST_SHOWN, n))
    print("  worst points: " + ", ".join(
        f"#{i} (line {lines[i]}) {result.residuals_px[i]:.3f} px" for i in worst))
    outside = int(np.count_nonzero(~camera.in_image(uv)))
    if outside:
        print(f"  note: {outside} point{'s lie' if outside > 1 else ' lies'} outside the "
              f"{width}x{height} image; check --width/--height")
    return camera, result.rms_px


def _run_chessboard(args, existing, fps: float, offset: float):
    from pslog.calibration import calibrate_chessboard, parse_pattern, read_calibration_images
    from pslog.calibration.chessboard import listed

    pattern = parse_pattern(args.chessboard)
    # an image that cannot be read or decoded is skipped and named, not fatal
    unreadable: list[str] = []
    images, labels = read_calibration_images(args.images, max_frames=args.max_frames,
                                             unreadable=unreadable)
    skipped = (f"; {len(unreadable)} unreadable image file(s) skipped: "
               f"{listed(unreadable, 10)}" if unreadable else "")
    height, width = images[0].shape[:2]
    for label, image in zip(labels, images, strict=True):
        if image.shape[:2] != (height, width):
            raise InputError(f"image {label} is {image.shape[1]}x{image.shape[0]}, "
                             f"{labels[0]} is {width}x{height}; all images must have the "
                             f"same size")
    for key, value in (("width", width), ("height", height)):
        given = getattr(args, key)
        if given is not None and given != value:
            raise BadOption(f"--{key} {given} differs from the images' {value}")
    pose = {"R": existing.R, "t": existing.t} if existing is not None else {}
    try:
        result = calibrate_chessboard(images, pattern, args.square, name=args.name, fps=fps,
                                      offset=offset, **pose)
    except InputError as exc:  # too few usable views: say that some files were unreadable
        raise InputError(f"{exc}{skipped}") from None
    camera = result.camera
    if unreadable:
        print(f"pslog calibrate: warning: {len(unreadable)} of {len(labels) + len(unreadable)} "
              f"image files unreadable, skipped: {listed(unreadable, 10)}", file=sys.stderr)
    print(f"{camera.name}: calibrated from a {pattern[0]}x{pattern[1]} chessboard in "
          f"{args.images} ({width}x{height})")
    print(f"  images: {len(result.used)} used, {len(result.rejected)} rejected "
          f"(board not found)" + (f", {len(unreadable)} unreadable (skipped)"
                                  if unreadable else "")
          + f" of {len(images) + len(unreadable)}")
    if result.rejected:
        print(f"  rejected: {listed([labels[i] for i in result.rejected], 10)}")
    print(f"  reprojection RMS {result.rms_px:.3f} px")
    worst = sorted(zip(result.view_rms_px, result.used, strict=True), reverse=True)[:3]
    print("  worst views: " + ", ".join(f"{labels[i]} {rms:.3f} px" for rms, i in worst))
    _print_intrinsics(camera)
    if existing is not None:
        print("  pose: kept from the rig (a chessboard does not locate the camera)")
    else:
        print("  pose: unknown from a chessboard; set to identity R, zero t. Solve it with "
              "--points CSV --fix-intrinsics")
    return camera, result.rms_px


def _print_intrinsics(camera) -> None:
    K, d = camera.K, camera.dist
    print(f"  K: fx {K[0, 0]:.2f}  fy {K[1, 1]:.2f}  cx {K[0, 2]:.2f}  cy {K[1, 2]:.2f} px")
    print(f"  dist: k1 {d[0]:.5f}  k2 {d[1]:.5f}  p1 {d[2]:.5f}  p2 {d[3]:.5f}  k3 {d[4]:.5f}")
    share = _no_ray_share(camera)
    if share > 0:
        # (walk42: a chessboard seen near the image's centre only gave k3 -0.46, folding
        # over in the corners; two detections there had no ray, and sync failed before
        # session 42: said nowhere)
        print(f"  note: the lens model folds over inside the image: {share:.1%} of it (towards "
              f"the corners) has no ray, and detections there are left out; the distortion "
              f"is not known there: calibrate with views reaching the image's corners")


def _no_ray_share(camera, step_px: float = 4.0) -> float:
    """The share of ``camera``'s image whose pixels have no ray (beyond its lens model's
    fold-over), on a grid of ``step_px``."""
    import numpy as np

    if not np.any(camera.dist):
        return 0.0
    u = np.arange(0.0, camera.width, step_px)
    v = np.arange(0.0, camera.height, step_px)
    grid = np.stack(np.meshgrid(u, v), -1).reshape(-1, 2)
    ok = np.all(np.isfinite(camera.undistort_normalized(grid)), axis=1)
    return float(1 - np.count_nonzero(ok) / len(grid))
