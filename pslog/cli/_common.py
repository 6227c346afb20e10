"""Argument helpers shared by the CLI commands (no heavy imports at module level)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path


def add_force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--force", action="store_true", help="overwrite existing output files")


def add_rig(parser: argparse.ArgumentParser, required: bool = True, help_extra: str = "") -> None:
    parser.add_argument(
        "--rig", required=required, metavar="RIG",
        help="built-in rig name (paper3, paper2), rig TOML file ('pslog rig show paper3 "
             "> rig.toml' writes one to edit) or anipose / Pose2Sim / OpenCV calibration"
             + help_extra)


#: argparse default holding a command's declared files (see :func:`declare_files`)
FILES_KEY = "_pslog_files"


def declare_files(parser: argparse.ArgumentParser, *, inputs=(), outputs=(),
                  updates=(), sessions=(), folders=()) -> None:
    """Declare which options of a command name files it reads and writes.

    The dispatcher (:func:`pslog.cli.main`) checks every declared output before ``run``:
    never one of the inputs in any spelling (``./``, ``..``, symlink, hard link), ``--force``
    or not; no existing file without ``--force``; no folder; a writable folder; distinct
    outputs; a stale ``.partial`` of an interrupted run removed or named. A new command gets
    all of this by declaring its files here. An OS fault while writing becomes one line
    naming the output.

    Parameters
    ----------
    inputs : argparse dests (``"session"``, ``"rig"``, ``"detections"``) or functions
        ``args -> paths`` (e.g. the video files inside ``--source NAME=FILE``)
    outputs : dests of files the command writes (``"output"``, ``"save"``, ``"csv"``)
    updates : dests of files changed in place (``calibrate --rig``): checked as outputs,
        except that they may exist without ``--force``
    sessions : those of ``outputs`` that are MCAP sessions: a name whose suffix names
        another format (``-o sim.csv``) is a usage error, exit 2 (:func:`misnamed_session`)
    folders : dests of folders the command makes (``export --tum DIR``): an output inside
        one that does not exist yet is refused saying so (not only "output folder does not
        exist"), whichever option comes first
    """
    files = dict(parser.get_default(FILES_KEY) or {"inputs": (), "outputs": (), "updates": (),
                                                   "sessions": ()})
    for key, more in (("inputs", inputs), ("outputs", outputs), ("updates", updates),
                      ("sessions", sessions), ("folders", folders)):
        files[key] = (*files.get(key, ()), *more)
    parser.set_defaults(**{FILES_KEY: files})


def empty_file_option(parser: argparse.ArgumentParser, args: argparse.Namespace) -> str | None:
    """The option (``-o/--output``, ``--rig``) given an empty file name on this command line,
    if any: a malformed command line (exit 2), not a file fault."""
    files = getattr(args, FILES_KEY, None) or {}
    dests = {e for key in ("inputs", "outputs", "updates") for e in files.get(key, ())
             if isinstance(e, str)}
    for action in parser._actions:
        if action.dest not in dests:
            continue
        value = getattr(args, action.dest, None)
        values = [value] if isinstance(value, str | Path) else list(value or ())
        if any(v is not None and str(v).strip() == "" for v in values):
            return "/".join(action.option_strings) or str(action.metavar or action.dest)
    return None


#: every file format pslog reads or writes, by the name its code calls it: what a message
#: calls a file of it, the suffixes (lower case) a file pslog writes in it may be named with,
#: and the suffixes it also goes by (recognised, never written: a tab-separated ``.tsv`` is a
#: CSV file to a user, but pslog writes commas). The one table behind every output-name
#: check: ``export``'s files, ``view --save``, ``rig export``/``rig import -o``, ``calibrate
#: --rig`` (:func:`misnamed`) and an MCAP session named for another format
#: (:data:`OTHER_FORMATS`). Where the core keeps its own list (``OPENCV_SUFFIXES``,
#: ``IMAGE_SUFFIXES``: cv2 and numpy, not imported here, so that ``--help`` stays fast) a test
#: holds them equal (tests/faults/test_sweep33.py).
FORMATS: dict[str, tuple[str, tuple[str, ...], tuple[str, ...]]] = {
    "mcap": ("an MCAP session", (".mcap",), ()),
    "csv": ("a CSV file", (".csv",), (".tsv",)),
    "jsonl": ("a JSON Lines file", (".jsonl", ".ndjson"), ()),
    "parquet": ("a Parquet file", (".parquet", ".pq"), ()),
    "c3d": ("a C3D file", (".c3d",), ()),
    "tum": ("a TUM trajectory", (".tum",), ()),
    "rrd": ("a rerun recording", (".rrd",), ()),
    "toml": ("a rig or calibration TOML", (".toml",), ()),
    # (.json: a JSON file to the user and to OTHER_FORMATS, OpenCV's too when rig export
    # writes it: listed first, its name wins in OTHER_FORMATS)
    "json": ("a JSON file", (".json",), ()),
    "opencv": ("an OpenCV FileStorage file", (".yml", ".yaml", ".xml", ".json"), ()),
    "text": ("a text file", (".txt",), ()),
    "video": ("a video", (".mp4", ".avi", ".mkv", ".mov", ".m4v", ".webm"), ()),
    "image": ("an image", (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm",
                           ".webp"), ()),
}

#: suffix -> what it names, for every format but MCAP: an MCAP session under one of them is
#: taken for that format later (``pslog import sim.csv`` reads a CSV, ``--rig s.yml``
#: OpenCV, ``--source cam1=s.mp4`` a video) or by the user's other tools. A name without a
#: suffix, with ``.mcap`` or with any other (``take.v2``, ``s.bak``) is left to the user.
OTHER_FORMATS: dict[str, str] = {}
for _fmt, (_kind, _written, _also) in FORMATS.items():
    if _fmt != "mcap":
        for _suffix in _written + _also:
            OTHER_FORMATS.setdefault(_suffix, _kind)


#: what a message calls the rig file pslog writes (``rig import -o``, ``calibrate --rig``)
PSLOG_RIG = "a pslog rig (TOML)"


def written_suffix(path: str | Path) -> str:
    """The suffix of ``path``'s last component as written, lower case (``t.CSV``: ``.csv``;
    ``.csv`` alone is a hidden file's name, no suffix; ``out.csv/`` a folder's spelling, its
    trailing separator kept: no suffix)."""
    import os

    return os.path.splitext(os.path.basename(os.fspath(path)))[1].lower()


def _either(suffixes: tuple[str, ...]) -> str:
    """``.csv``; ``.parquet or .pq``; ``.yml, .yaml, .xml or .json``."""
    return suffixes[0] if len(suffixes) == 1 else f"{', '.join(suffixes[:-1])} or {suffixes[-1]}"


def misnamed(option: str, path: str | Path, fmt: str, subject: str | None = None,
             hint: str | None = None) -> str | None:
    """The error for an output ``path`` given as ``option`` that pslog writes in format
    ``fmt`` (a key of :data:`FORMATS`) under a name without one of its suffixes (any case),
    else None: ``--csv t.parquet: a CSV file is named .csv``. ``subject`` names the file
    when the format's own name says too little (``a pslog rig (TOML)``), ``hint`` follows
    in parentheses. A file's name says its format to the user's other tools and to pslog
    itself (``--rig s.yml`` is read as OpenCV), so a mismatch is a bad command line (the
    callers' exit 2), never a file of one format under another's name."""
    import os

    kind, written, _also = FORMATS[fmt]
    if written_suffix(path) in written:
        return None
    return (f"{option} {os.fspath(path)}: {subject or kind} is named {_either(written)}"
            + (f" ({hint})" if hint else ""))


def misnamed_session(parser: argparse.ArgumentParser, args: argparse.Namespace) -> str | None:
    """The usage error for an MCAP session output (``declare_files(sessions=...)``) named
    for another format (:data:`OTHER_FORMATS`, any case), if any on this command line:
    ``argument -o/--output: sim.csv names a CSV file; pslog simulate writes an MCAP
    session: name it .mcap``. Checked by the dispatcher after the output checks of
    :func:`check_declared_files` (an output that is an input, a folder, or exists without
    ``--force`` is said as such first, exit 1) and before ``run`` (nothing read or written),
    as ``view --save`` and ``export`` check their names."""
    import os

    files = getattr(args, FILES_KEY, None) or {}
    dests = set(files.get("sessions", ()))
    for action in parser._actions:
        value = getattr(args, action.dest, None) if action.dest in dests else None
        if not isinstance(value, str | Path):
            continue
        # ('out.csv/' is a folder's spelling, said by the output checks)
        suffix = written_suffix(value)
        if suffix in OTHER_FORMATS:
            option = "/".join(action.option_strings) or str(action.metavar or action.dest)
            return (f"argument {option}: {os.fspath(value)} names {OTHER_FORMATS[suffix]}; "
                    f"{parser.prog} writes an MCAP session: name it .mcap")
    return None


def _paths(args: argparse.Namespace, entries) -> list[str]:
    out: list[str] = []
    for entry in entries:
        value = entry(args) if callable(entry) else getattr(args, entry, None)
        if value is None:
            continue
        values = [value] if isinstance(value, str | Path) else list(value)
        out.extend(str(v) for v in values if v is not None and str(v) != "")
    return out


def declared_files(args: argparse.Namespace) -> tuple[list[str], list[str], list[str]]:
    """(inputs, outputs, updates) paths given on this command line."""
    files = getattr(args, FILES_KEY, None) or {}
    return (_paths(args, files.get("inputs", ())), _paths(args, files.get("outputs", ())),
            _paths(args, files.get("updates", ())))


def check_declared_files(args: argparse.Namespace, say=None) -> None:
    """The output checks of :func:`declare_files` for a parsed command line."""
    from pslog.errors import InputError
    from pslog.inputs import special_file
    from pslog.outputs import check_output_path, check_outputs

    inputs, outputs, updates = declared_files(args)
    for path in inputs:  # a device or FIFO would be read for ever (or block)
        kind = special_file(path)
        if kind is not None:
            raise InputError(f"not a regular file: {path} ({kind})")
    for dest in (getattr(args, FILES_KEY, None) or {}).get("folders", ()):
        folder = getattr(args, dest, None)
        if not folder or os.path.exists(folder):
            continue
        inside = next((p for p in outputs
                       if os.path.abspath(os.path.dirname(p)) == os.path.abspath(folder)), None)
        if inside is not None:  # ('--csv tum/x.csv --tum tum', tum new: either order)
            option = "--" + dest.replace("_", "-")
            raise InputError(f"output {inside}: its folder {folder} does not exist; {option} "
                             f"{folder} makes it, but only its own files: give {inside} a "
                             f"folder that exists")
    check_outputs(outputs, bool(getattr(args, "force", False)), inputs, say=say)
    for path in updates:  # may exist: changed in place, but never an input, and writable
        check_output_path(path, True, inputs, say=say)



def check_output(path: str | Path, force: bool, inputs=()) -> Path:
    """Refuse a folder, a missing parent folder, one of the ``inputs`` (always), or an
    existing file unless ``force``. The dispatcher already checks every declared output
    before ``run``; this is for a check again after a command has done slow work (``record``
    and ``view`` use it)."""
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


def _int_arg(text: str, low: int, high: int | None = None) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    if high is None and value < low:
        raise argparse.ArgumentTypeError(f"must be >= {low}, got {text!r}")
    if high is not None and not low <= value <= high:
        raise argparse.ArgumentTypeError(f"must be in {low}..{high}, got {text!r}")
    return value


def seed(text: str) -> int:
    """A random seed: a whole number >= 0 (numpy's generators take no negative seed)."""
    return _int_arg(text, 0)


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


def fuse_noise_px(text: str) -> float:
    """The detections' pixel noise a fusion assumes: 0 (noise-free, a zero covariance) or
    in [:data:`pslog.camera.MIN_FUSE_NOISE_PX`, :data:`MAX_NOISE_PX`] (the rule of
    :class:`pslog.fusion.FusionOptions`, refused here as a usage error)."""
    from pslog.camera import MIN_FUSE_NOISE_PX

    value = noise_px(text)
    if 0 < value < MIN_FUSE_NOISE_PX:
        raise argparse.ArgumentTypeError(
            f"must be 0 (noise-free) or at least {MIN_FUSE_NOISE_PX:g} pixels (a tenth of "
            f"the finest detector's precision), got {text!r}")
    return value


def number_at_most(limit: float, unit: str, why: str, positive: bool = False,
                   least: float | None = None):
    """argparse type: a number in [0, limit] (in (0, limit] if ``positive``; in [least,
    limit] if ``least`` is given)."""
    def parse(text: str) -> float:
        value = positive_float(text) if positive else nonnegative_float(text)
        if least is not None and value < least:
            raise argparse.ArgumentTypeError(f"must be at least {least:g} {unit}, got {text!r}")
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


def closed_fraction(text: str) -> float:
    """A fraction in [0, 1] (1 is meaningful: every frame)."""
    value = nonnegative_float(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"must be in [0, 1], got {text!r}")
    return value


def fraction(text: str) -> float:
    value = nonnegative_float(text)
    if value >= 1:
        raise argparse.ArgumentTypeError(f"must be in [0, 1), got {text!r}")
    return value


def installed_command(name: str) -> str:
    """How to start ``name`` (``rerun``, ``pslog``), installed beside this Python, from this
    shell: the bare name when it is on PATH (e.g. the virtual environment is active), else
    its path (``.venv/bin/rerun`` after ``bash run.sh demo``, which does not activate it)."""
    import os
    import shutil
    import sys

    ours = Path(sys.executable).parent / (name + (".exe" if os.name == "nt" else ""))
    if not ours.exists():
        return name
    found = shutil.which(name)
    if found is not None and os.path.samefile(found, ours):
        return name
    try:
        path = os.path.relpath(ours)
    except ValueError:  # another drive on Windows
        return str(ours)
    if path.startswith(os.pardir):
        return str(ours)
    return path if os.sep in path else os.path.join(os.curdir, path)


def usage_error(command: str, message: str) -> int:
    """Report a command-line value that is bad only in the light of an input file (a
    tolerance against the rig's frame rate, say) as argparse reports any other bad value:
    one line on stderr; returns exit code 2."""
    import sys

    print(f"pslog {command}: error: {message} (see 'pslog {command} --help')", file=sys.stderr)
    return 2


def positive_int(text: str) -> int:
    """A whole number >= 1."""
    return _int_arg(text, 1)


def int_in(low: int, high: int):
    """argparse type: a whole number in ``[low, high]``."""
    def parse(text: str) -> int:
        return _int_arg(text, low, high)
    parse.__name__ = "whole number"
    return parse


def fusion_method(text: str) -> str:
    """A fusion method name (``pslog.fusion.METHODS``)."""
    from pslog.fusion import METHODS

    if text not in METHODS:
        raise argparse.ArgumentTypeError(f"unknown fusion method {text!r} "
                                         f"(have {', '.join(METHODS)})")
    return text


def fusion_methods(text: str) -> list[str]:
    """argparse type of ``--method``: one fusion method or a comma-separated list of them."""
    names = [name.strip() for name in text.split(",")]
    if not any(names) or not all(names):
        raise argparse.ArgumentTypeError(f"{text!r}: name a fusion method, or several "
                                         f"separated by commas")
    return [fusion_method(name) for name in names]


class _ExtendUnique(argparse.Action):
    """Append the parsed list to the destination, each name once, in the order given."""

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        names = list(getattr(namespace, self.dest, None) or [])
        names += [name for name in values if name not in names]
        setattr(namespace, self.dest, names)


def track_names(text: str) -> list[str]:
    """argparse type: one track name or a comma-separated list (any name a session may hold)."""
    names = [name.strip() for name in text.split(",")]
    if not any(names) or not all(names):
        raise argparse.ArgumentTypeError(f"{text!r}: name a method, or several separated by "
                                         f"commas")
    return names


def add_method_option(parser: argparse.ArgumentParser, help: str,
                      known_only: bool = True) -> None:
    """``--method METHOD`` of every command that chooses fusion methods: repeated or a
    comma-separated list (``--method typeA --method smooth`` = ``--method typeA,smooth``),
    into ``args.methods`` (None when not given). ``known_only``: only the registry's methods
    (False: any track name, e.g. the tracks a viewed session holds)."""
    parser.add_argument("--method", action=_ExtendUnique, dest="methods", metavar="METHOD",
                        type=fusion_methods if known_only else track_names, default=None,
                        help=help)


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


def run_stoppable(run, args: argparse.Namespace) -> int:
    """``run(args, stop)`` with SIGINT and SIGTERM turned into a stop request for its whole
    length (the recorders' :class:`~recorders.record.StopRequest`; also one that came before
    the work started), restored at the end for callers of ``main()`` in-process: a command
    that records finishes its file instead of dying with a KeyboardInterrupt traceback or
    silently on SIGTERM."""
    from recorders.record import StopRequest

    stop = StopRequest()
    restore = stop.install()
    try:
        return run(args, stop)
    finally:
        restore()
