"""``pslog rig``: list the built-in rigs, print a rig as TOML, check a rig file, and convert
calibrations of aniposelib / anipose, Pose2Sim and OpenCV to and from rig files.

``pslog rig show paper3 > rig.toml`` gives a rig file to start from (edit it, or let
``pslog calibrate`` replace its cameras); ``show`` also takes a rig TOML file (printed as
pslog reads it) or a session MCAP file (the calibration it was recorded with, the starting
point of a corrected rig for ``pslog fuse --rig``).
"""

from __future__ import annotations

import argparse

from ._common import add_force, declare_files

EXAMPLES = """\
examples:
  pslog rig list
  pslog rig show paper3 --timing typeA > rig.toml
  pslog rig show samples/throw.mcap > corrected.toml
  pslog rig check rig.toml
  pslog rig import calibration.toml --units mm --fps 120 -o rig.toml
  pslog rig import cameras.yml --timing typeA -o rig.toml
  pslog rig export rig.toml --format anipose -o calibration.toml
  pslog rig export rig.toml --format opencv -o cameras.yml
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.rig import TIMING_PRESETS

    parser.epilog = EXAMPLES
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    actions.add_parser("list", help="the built-in rigs, one line each",
                       description="List the built-in rigs (usable wherever --rig is taken).")
    show = actions.add_parser(
        "show", help="print a rig as TOML (redirect it into a file to start your own)",
        description="Print a rig as TOML on stdout: a built-in rig, a rig TOML file, or the "
                    "calibration stored in a session MCAP file.")
    show.add_argument("rig", metavar="RIG",
                      help="built-in rig name (paper3, paper2), rig TOML file or session MCAP")
    show.add_argument("--timing", choices=TIMING_PRESETS,
                      help="set the shutter offsets from a preset (default: the rig's own; "
                           "the built-in rigs have all offsets 0, i.e. sync)")
    check = actions.add_parser(
        "check", help="validate a rig TOML file and summarise its cameras",
        description="Load a rig TOML file as every command does and summarise it; exit 1 "
                    "with the reason if it is not a valid rig.")
    check.add_argument("rig", metavar="RIG",
                       help="rig TOML file (or built-in rig name, or session MCAP)")
    _add_import(actions)
    _add_export(actions)


def _add_import(actions) -> None:
    from pslog.interchange.rig_formats import (
        DEFAULT_FPS,
        IMPORT_FORMATS,
        M_SUSPECT_M,
        MM_SUSPECT_M,
        UNITS,
    )
    from pslog.rig import TIMING_PRESETS

    imp = actions.add_parser(
        "import", help="convert an anipose / Pose2Sim / OpenCV calibration to a rig TOML",
        description="Read a calibration of aniposelib / anipose (calibration.toml), Pose2Sim "
                    "(Calib*.toml) or OpenCV FileStorage (.yml .yaml .xml .json) and write it "
                    "as a pslog rig TOML. Those files have no frame rate or shutter offset: "
                    "give them here (see docs/interchange.md).")
    imp.add_argument("file", metavar="FILE", help="the calibration file")
    imp.add_argument("--format", default="auto", choices=IMPORT_FORMATS,
                     help="the file's format (default: auto, from its suffix and content)")
    imp.add_argument("--units", choices=tuple(UNITS),
                     help="unit of the file's translations (default: metres, refusing a file "
                          f"whose cameras are a median of more than {MM_SUSPECT_M:g} m from "
                          "the origin as one most likely in millimetres; mm refuses a file "
                          f"whose cameras are a median of less than {M_SUSPECT_M * 100:g} cm "
                          "from the origin and from each other as one in metres; a pslog rig "
                          "TOML is always in metres and takes no --units)")
    imp.add_argument("--fps", type=_positive_float, metavar="FPS",
                     help=f"frame rate of every camera (default: the file's if pslog wrote "
                          f"it, else {DEFAULT_FPS:g})")
    imp.add_argument("--offset", action="append", default=[], metavar="NAME=SECONDS",
                     type=_name_value, help="shutter offset of camera NAME, seconds "
                                            "(repeat per camera; default: the file's, else 0)")
    imp.add_argument("--timing", choices=TIMING_PRESETS,
                     help="set every shutter offset from a preset instead")
    imp.add_argument("-o", "--output", required=True, metavar="RIG.toml",
                     help="the rig TOML to write")
    add_force(imp)
    declare_files(imp, inputs=("file",), outputs=("output",))


def _add_export(actions) -> None:
    from pslog.interchange.rig_formats import EXPORT_FORMATS, UNITS

    exp = actions.add_parser(
        "export", help="write a rig as an anipose / Pose2Sim / OpenCV calibration",
        description="Write a rig (built-in, rig file or session MCAP) as an aniposelib "
                    "calibration.toml, a Pose2Sim Calib.toml or an OpenCV FileStorage file "
                    "(YAML, XML or JSON by the suffix of -o).")
    exp.add_argument("rig", metavar="RIG",
                     help="built-in rig name, rig file (any format) or session MCAP")
    exp.add_argument("--format", required=True, choices=EXPORT_FORMATS,
                     help="the format to write")
    exp.add_argument("--units", default="m", choices=tuple(UNITS),
                     help="unit of the translations written (default: m)")
    exp.add_argument("-o", "--output", required=True, metavar="CALIBRATION.toml",
                     help="the file to write: anipose and pose2sim named .toml, opencv .yml, "
                          ".yaml, .xml or .json")
    add_force(exp)
    declare_files(exp, inputs=("rig",), outputs=("output",))


def _positive_float(text: str) -> float:
    import math

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _name_value(text: str) -> tuple[str, float]:
    import math

    name, sep, value = text.partition("=")
    try:
        number = float(value)
    except ValueError:
        number = math.nan
    if not sep or not name or not math.isfinite(number):
        raise argparse.ArgumentTypeError(f"expected NAME=SECONDS, got {text!r}")
    return name, number


def run(args: argparse.Namespace) -> int:
    if args.action == "list":
        return _list()
    if args.action == "import":
        return _import(args)
    if args.action == "export":
        return _export(args)
    if args.action == "show":
        rig = _resolve(args.rig)
        if args.timing:
            from pslog.rig import apply_timing

            rig = apply_timing(rig, args.timing)
        print(rig.to_toml(), end="")
        return 0
    path = args.rig
    rig = _resolve(path)
    print(f"{path}: a valid rig{f' {rig.name!r}' if rig.name else ''} of {len(rig)} "
          f"camera{'s' if len(rig) != 1 else ''}{_described_format(path)}")
    for line in describe_cameras(rig):
        print("  " + line)
    from pslog.errors import RigError
    from pslog.rig import check_baselines

    try:
        check_baselines(rig, path)
    except RigError as exc:  # valid (a rig being calibrated), but not yet for fusion
        print(f"note: {exc} (fuse and sync refuse it until then)")
    return 0


def _resolve(name_or_path: str):
    """A built-in rig, a rig file, or the rig stored in a session MCAP file."""
    from pslog.rig import resolve_rig

    return resolve_rig(name_or_path)


def _described_format(path: str) -> str:
    """`` (anipose calibration, translations read as m, ...)`` for a foreign rig file."""
    from pathlib import Path

    from pslog.rig import BUILTIN_RIGS, _is_session_file, load_rig_file

    if path in BUILTIN_RIGS or _is_session_file(Path(path)):
        return ""
    loaded = load_rig_file(path)
    if loaded.format == "pslog":
        return ""
    timing = "" if loaded.timed else "; no frame rate or offset in the file: 30 fps, 0 s"
    return f" ({loaded.format} calibration, translations read as {loaded.units}{timing})"


def _import(args: argparse.Namespace) -> int:
    from pslog.interchange.rig_formats import ImportOptions, TimingOptionError
    from pslog.outputs import replacing
    from pslog.rig import apply_timing, load_rig_file

    from ._common import PSLOG_RIG, misnamed, usage_error

    offsets = dict(args.offset)
    twice = sorted({n for n, _ in args.offset if [m for m, _ in args.offset].count(n) > 1})
    if twice:  # (the last taken, silently; as import's --detections, refused)
        given = ", ".join(f"{v:g}" for n, v in args.offset if n == twice[0])
        return usage_error("rig import", f"argument --offset: camera {twice[0]} given twice "
                                         f"({given}): give each camera once")
    if args.timing and offsets:  # (bad command lines: exit 2, as argparse's own)
        return usage_error("rig import", "give --timing or --offset, not both")
    # a pslog rig is TOML: under an OpenCV name ('-o cams.yml') pslog itself would read it
    # back as OpenCV FileStorage and refuse it (calibrate --rig's and rig export's rule)
    wrong = misnamed("-o", args.output, "toml", PSLOG_RIG,
                     "for an OpenCV file: pslog rig export --format opencv")
    if wrong:
        return usage_error("rig import", wrong)
    try:
        loaded = load_rig_file(args.file, args.format,
                               ImportOptions(units=args.units, fps=args.fps, offsets=offsets))
    except TimingOptionError as exc:  # an --offset or --fps that does not fit the file
        option = "--offset" if offsets else "--fps"
        return usage_error("rig import", f"argument {option}: {exc}")
    rig = apply_timing(loaded.rig, args.timing) if args.timing else loaded.rig
    with replacing(args.output, force=args.force, inputs=[args.file]) as f:
        f.write(rig.to_toml())
    timed = loaded.timed or args.fps is not None
    print(f"wrote {args.output}: {len(rig)} camera{'s' if len(rig) != 1 else ''} from the "
          f"{loaded.format} calibration {args.file} (translations read as {loaded.units}"
          + ("" if timed else "; no frame rate in the file: 30 fps, give --fps") + ")")
    return 0


#: what each TOML export format is called in an error (Pose2Sim reads the ``*.toml`` files of
#: its calibration folder; aniposelib and anipose a ``calibration.toml``)
_FORMAT_NAMES = {"anipose": "an aniposelib calibration (TOML)",
                 "pose2sim": "a Pose2Sim calibration (TOML)"}


def _export(args: argparse.Namespace) -> int:
    from pathlib import Path

    from pslog.interchange.rig_formats import rig_to_format
    from pslog.outputs import replacing

    from ._common import misnamed, usage_error

    # -o's name says the format, and a mismatch is a bad command line (exit 2), never a file
    # of one format under another's name: a Pose2Sim calibration named c.yml was written as
    # TOML, which Pose2Sim (it reads its calibration folder's *.toml) never finds and pslog
    # read back as OpenCV YAML ("malformed OpenCV FileStorage file")
    if args.format == "opencv":
        wrong = misnamed("-o", args.output, "opencv", hint="YAML, XML or JSON")
    else:
        wrong = misnamed("-o", args.output, "toml", _FORMAT_NAMES[args.format],
                         "for YAML, XML or JSON: --format opencv")
    if wrong:
        return usage_error("rig export", wrong)
    suffix = Path(args.output).suffix.lower()
    rig = _resolve(args.rig)
    text = rig_to_format(rig, args.format, args.units, suffix)
    with replacing(args.output, force=args.force, inputs=[args.rig]) as f:
        f.write(text)
    print(f"wrote {args.output}: {len(rig)} camera{'s' if len(rig) != 1 else ''} as "
          f"{args.format} (translations in {args.units})")
    return 0


def describe_cameras(rig) -> list[str]:
    """One line per camera: size, rate, shutter offset, centre in the world, and the clock
    keys the rig holds (``clock_offset``, ``clock_drift_ppm``, ``readout``: what ``pslog
    sync`` estimated) when non-zero, so a synced rig is seen to carry its clocks (a
    walkthrough found a synced rig described exactly as its unsynced original, session 33).
    """
    lines = []
    for cam in rig.cameras:
        x, y, z = cam.center_world
        lines.append(f"{cam.name}: {cam.width}x{cam.height} px, {cam.fps:g} fps, offset "
                     f"{cam.offset * 1e3:.3f} ms, f {cam.K[0, 0]:.1f} px, centre "
                     f"({x:.3f}, {y:.3f}, {z:.3f}) m{_clock_keys(cam)}")
    return lines


def _clock_keys(cam) -> str:
    """``"; clock_offset 2.1966 ms, readout 10.000 ms"`` (the keys' TOML names, the values in
    ms / ppm as ``pslog sync`` prints them), or ``""`` when the camera has none."""
    shown = [(key, text) for key, value, text in (
        ("clock_offset", cam.clock_offset, f"{cam.clock_offset * 1e3:+.4f} ms"),
        ("clock_drift_ppm", cam.clock_drift_ppm, f"{cam.clock_drift_ppm:+.3f} ppm"),
        ("readout", cam.readout, f"{cam.readout * 1e3:.3f} ms")) if value != 0]
    return "; " + ", ".join(f"{key} {text}" for key, text in shown) if shown else ""


def _list() -> int:
    from pslog.rig import BUILTIN_RIGS, builtin_rig

    for name in BUILTIN_RIGS:
        rig = builtin_rig(name)
        cams = rig.cameras
        print(f"{name}: {len(rig)} cameras ({', '.join(rig.names)}), "
              f"{cams[0].width}x{cams[0].height} px at {cams[0].fps:g} fps, 3 m above a "
              f"3 x 2 m area (the paper's simulation); offsets 0 (use --timing)")
    return 0
