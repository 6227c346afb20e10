"""``pslog rig``: list the built-in rigs, print a rig as TOML, check a rig file.

``pslog rig show paper3 > rig.toml`` gives a rig file to start from (edit it, or let
``pslog calibrate`` replace its cameras); ``show`` also takes a rig TOML file (printed as
pslog reads it) or a session MCAP file (the calibration it was recorded with, the starting
point of a corrected rig for ``pslog fuse --rig``).
"""

from __future__ import annotations

import argparse

EXAMPLES = """\
examples:
  pslog rig list
  pslog rig show paper3 --timing typeA > rig.toml
  pslog rig show samples/throw.mcap > corrected.toml
  pslog rig check rig.toml
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


def run(args: argparse.Namespace) -> int:
    if args.action == "list":
        return _list()
    if args.action == "show":
        rig = load_any_rig(args.rig)
        if args.timing:
            from pslog.rig import apply_timing

            rig = apply_timing(rig, args.timing)
        print(rig.to_toml(), end="")
        return 0
    path = args.rig
    rig = load_any_rig(path)
    print(f"{path}: a valid rig{f' {rig.name!r}' if rig.name else ''} of {len(rig)} "
          f"camera{'s' if len(rig) != 1 else ''}")
    for line in describe_cameras(rig):
        print("  " + line)
    return 0


def load_any_rig(name_or_path: str):
    """A built-in rig, a rig TOML file, or the rig stored in a session MCAP file."""
    from pathlib import Path

    from pslog.rig import BUILTIN_RIGS, resolve_rig

    if name_or_path not in BUILTIN_RIGS and Path(name_or_path).suffix.lower() == ".mcap":
        from pslog.log import read_session

        return read_session(name_or_path).rig
    return resolve_rig(name_or_path)


def describe_cameras(rig) -> list[str]:
    """One line per camera: size, rate, shutter offset, centre in the world."""
    lines = []
    for cam in rig.cameras:
        x, y, z = cam.center_world
        lines.append(f"{cam.name}: {cam.width}x{cam.height} px, {cam.fps:g} fps, offset "
                     f"{cam.offset * 1e3:.3f} ms, f {cam.K[0, 0]:.1f} px, centre "
                     f"({x:.3f}, {y:.3f}, {z:.3f}) m")
    return lines


def _list() -> int:
    from pslog.rig import BUILTIN_RIGS, builtin_rig

    for name in BUILTIN_RIGS:
        rig = builtin_rig(name)
        cams = rig.cameras
        print(f"{name}: {len(rig)} cameras ({', '.join(rig.names)}), "
              f"{cams[0].width}x{cams[0].height} px at {cams[0].fps:g} fps, 3 m above a "
              f"3 x 2 m area (the paper's simulation); offsets 0 (use --timing)")
    return 0
