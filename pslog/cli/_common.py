"""Argument helpers shared by the CLI commands (no heavy imports at module level)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--force", action="store_true", help="overwrite existing output files")


def add_rig(parser: argparse.ArgumentParser, required: bool = True, help_extra: str = "") -> None:
    parser.add_argument(
        "--rig", required=required, metavar="RIG",
        help="built-in rig name (paper3, paper2) or rig TOML file" + help_extra)


def check_output(path: str | Path, force: bool, inputs=()) -> Path:
    """Refuse a folder, a missing parent folder, one of the ``inputs`` (always), or an
    existing file unless ``force``."""
    from pslog.outputs import check_output_path

    return check_output_path(path, force, inputs)


def _float_arg(text: str, ok, requirement: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not ok(value) or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be {requirement}, got {text!r}")
    return value


def positive_float(text: str) -> float:
    return _float_arg(text, lambda v: v > 0, "a positive number")


def nonnegative_float(text: str) -> float:
    return _float_arg(text, lambda v: v >= 0, "a number >= 0")


def seed(text: str) -> int:
    """A random seed: a whole number >= 0 (numpy's generators take no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return value


#: Largest simulated detection noise, pixels: beyond it a detection says nothing of the ball.
MAX_NOISE_PX = 100.0


def noise_px(text: str) -> float:
    """Simulated detection noise: pixels in [0, 100]."""
    value = nonnegative_float(text)
    if value > MAX_NOISE_PX:
        raise argparse.ArgumentTypeError(
            f"must be at most {MAX_NOISE_PX:g} pixels (noise that large hides the ball's "
            f"position entirely), got {text!r}")
    return value


def number_at_most(limit: float, unit: str, why: str, positive: bool = False):
    """argparse type: a number in [0, limit] (in (0, limit] if ``positive``)."""
    def parse(text: str) -> float:
        value = positive_float(text) if positive else nonnegative_float(text)
        if value > limit:
            raise argparse.ArgumentTypeError(f"must be at most {limit:g} {unit} ({why}), "
                                             f"got {text!r}")
        return value
    parse.__name__ = "number"
    return parse


def seconds_at_most(limit: float, why: str):
    """argparse type: seconds in (0, limit]."""
    def parse(text: str) -> float:
        value = positive_float(text)
        if value > limit:
            raise argparse.ArgumentTypeError(f"must be at most {limit:g} s ({why}), got {text!r}")
        return value
    parse.__name__ = "seconds"
    return parse


def exposure_s(text: str) -> float:
    """A synthetic exposure time: seconds in [0, 1) (the library checks it against the frame
    period: :func:`pslog.simulation.check_exposure`)."""
    value = nonnegative_float(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(
            f"must be below 1 second (an exposure is shorter than a frame), got {text!r}")
    return value


def fraction(text: str) -> float:
    value = nonnegative_float(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text!r}")
    return value


def usage_error(command: str, message: str) -> int:
    """Report a command-line value that is bad only in the light of an input file (a
    tolerance against the rig's frame rate, say) as argparse reports any other bad value:
    one line on stderr; returns exit code 2."""
    import sys

    print(f"pslog {command}: error: {message} (see 'pslog {command} --help')", file=sys.stderr)
    return 2


def positive_int(text: str) -> int:
    """A whole number >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {text!r}")
    return value


def int_in(low: int, high: int):
    """argparse type: a whole number in ``[low, high]``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be in {low}..{high}, got {text!r}")
        return value
    parse.__name__ = "whole number"
    return parse


def fusion_method(text: str) -> str:
    """A fusion method name (``pslog.fusion.METHODS``)."""
    from pslog.fusion import METHODS

    if text not in METHODS:
        raise argparse.ArgumentTypeError(f"unknown fusion method {text!r} "
                                         f"(have {', '.join(METHODS)})")
    return text


def checked_by(parse, what: str):
    """argparse type: the text unchanged if ``parse(text)`` accepts it; the library's own
    message (its :class:`~pslog.errors.PslogError`) as argparse's error otherwise, so that a
    bad value on the command line is exit 2 like any other."""
    from pslog.errors import PslogError

    def check(text: str) -> str:
        try:
            parse(text)
        except PslogError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
        return text
    check.__name__ = what
    return check


def camera_name(text: str) -> str:
    """A camera name usable in CSV and topics (:func:`pslog.camera.check_camera_name`)."""
    from pslog.camera import check_camera_name

    return checked_by(check_camera_name, "camera name")(text)


def motion_name(text: str) -> str:
    from pslog.motion import get_motion

    return checked_by(get_motion, "motion")(text)


def hsv_box(text: str) -> str:
    """``H1,H2,S1,S2,V1,V2`` as :meth:`recorders.detect.HsvRange.parse` accepts it."""
    from recorders.detect import HsvRange

    return checked_by(HsvRange.parse, "HSV box")(text)


def chessboard(text: str) -> str:
    from pslog.calibration.chessboard import parse_pattern

    return checked_by(parse_pattern, "chessboard pattern")(text)


def port(text: str) -> int:
    """A TCP port number, 1..65535."""
    return int_in(1, 65535)(text)
