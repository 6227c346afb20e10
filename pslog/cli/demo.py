"""pslog demo: the whole pipeline on a synthetic throw, with nothing but this package.

Records a rendered hand-thrown ball seen by the paper's three cameras with type-A timing
(frames included), fuses it with every method the timing allows, prints the accuracy against
ground truth beside the paper's Table 1, and saves a rerun recording to browse it.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

from pslog.errors import shell_word

from ._common import installed_command, seconds_at_most

#: the shortest demo, seconds: three frames of each of its 30 fps cameras (a shorter throw
#: failed after recording it: 'no such file: session.mcap' below a frame period, 'track
#: 'typeA' has no point the ground truth scores' below two frames of each camera)
MIN_DEMO_S = 0.1


def _demo_duration(text: str) -> float:
    value = seconds_at_most(60.0, "the demo is one throw")(text)
    if value < MIN_DEMO_S:
        raise argparse.ArgumentTypeError(
            f"must be at least {MIN_DEMO_S:g} s (three frames of each camera, for the methods "
            f"to fuse and the accuracy to be measured), got {text!r}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=None,
                        metavar="DIR", help="output folder (default: a new "
                                            "demo-output/<date-time>/)")
    parser.add_argument("--duration", default=1.5, metavar="S", type=_demo_duration,
                        help=f"seconds of throw to record, {MIN_DEMO_S:g} to 60 (default "
                             f"%(default)s)")
    parser.add_argument("--realtime", action="store_true",
                        help="render at the cameras' real rate instead of as fast as possible")
    parser.add_argument("--no-view", action="store_true", help="do not build demo.rrd")
    parser.add_argument("--force", action="store_true",
                        help="write into --out even if it holds files")


def _output_folder(out: str | None, force: bool) -> tuple[Path, bool]:
    """The folder to write into and whether this run creates it."""
    from pslog.errors import InputError, OutputExistsError

    if out is None:  # a fresh folder per run: nothing is ever overwritten
        base = Path("demo-output") / time.strftime("%Y-%m-%dT%H-%M-%S")
        folder, n = base, 1
        while folder.exists():
            n += 1
            folder = base.with_name(f"{base.name}-{n}")
    else:
        folder = Path(out)
        if folder.exists() and not folder.is_dir():
            raise InputError(f"--out {folder} is a file, not a folder")
        if folder.exists() and any(folder.iterdir()) and not force:
            raise OutputExistsError(f"{folder} is not empty; use --force to write into it")
    created = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the output folder {folder}: {exc.strerror}") from None
    return folder, created


#: exit code of an interrupted demo (as for Ctrl-C anywhere in pslog)
INTERRUPTED = 130


def kept_outputs(args: argparse.Namespace) -> list[str]:
    """What a run that completed wrote: its folder (--out, or the new demo-output/...)."""
    folder = getattr(args, "folder", None)
    return [os.path.join(folder, "")] if folder is not None else []


def run(args: argparse.Namespace) -> int:
    from recorders.record import RecordWriteError

    folder, created = _output_folder(args.out, args.force)
    args.folder = folder  # (for kept_outputs)
    before = set(folder.iterdir())
    try:
        code = _run(args, folder)
    except RecordWriteError as exc:
        # the recorder's message points at the unfinished session to salvage, which the demo
        # is about to remove: say what is true after the removal instead
        _remove_new_files(folder, before, created)
        session_path = folder / "session.mcap"
        raise RecordWriteError(
            f"cannot write {session_path}: {exc.reason}; stopped the cameras; the demo "
            f"removed what it had written, so nothing was kept (the demo is reproducible: "
            f"run it again where there is space)", exc.reason) from None
    except BaseException:
        _remove_new_files(folder, before, created)
        raise
    if code == INTERRUPTED:
        _remove_new_files(folder, before, created)
    return code


def _remove_new_files(folder: Path, before: set[Path], created: bool) -> None:
    """A failed or interrupted demo leaves nothing of its own (every file it writes can be
    made again); files that were in the folder before stay, and each writer replaces an old
    file only by a complete new one."""
    for path in set(folder.iterdir()) - before:
        if path.is_file() or path.is_symlink():
            path.unlink(missing_ok=True)
    if created:
        try:
            folder.rmdir()
        except OSError:
            pass  # not empty: something else wrote into it meanwhile


def _run(args: argparse.Namespace, folder: Path) -> int:
    import sys

    from pslog import paper
    from pslog.evaluation import evaluate, format_accuracy_table
    from pslog.fusion import METHODS, FusionOptions, default_methods, for_session, fuse_all
    from pslog.log import copy_session, read_session
    from pslog.rig import apply_timing, builtin_rig
    from pslog.timing import observations

    session_path, fused_path = folder / "session.mcap", folder / "fused.mcap"
    rig = apply_timing(builtin_rig("paper3"), "typeA")

    from recorders import record_synthetic

    print(f"1/4 recording a {args.duration:g} s synthetic throw: 3 cameras at 30 fps, shutters "
          f"1/90 s apart (type A) -> {session_path}")
    summary = record_synthetic(rig, "throw", session_path, duration=args.duration,
                               fast=not args.realtime, frames=True, force=args.force,
                               status=sys.stdout)
    if summary.interrupted:
        # the recorder turned Ctrl-C (or SIGTERM) into a clean stop of the recording; the
        # user asked the demo to stop, not to go on with a shortened throw
        print("pslog demo: interrupted during the recording; stopped (nothing kept)",
              file=sys.stderr)
        return INTERRUPTED

    session = read_session(session_path)
    n_obs = len(observations(session.detections, session.rig))
    print(f"2/4 fusing {n_obs} detections with every method type-A timing suits")
    methods = default_methods(session.detections, session.rig)
    skipped = [m for m in METHODS if m not in methods]
    if skipped:
        print(f"    {', '.join(skipped)}: need cameras with a common shutter instant (sync or "
              f"typeB timing), not type A; the paper's table below has them")
    # (as pslog fuse: smooth's detector offset for detections found in images)
    tracks = fuse_all(session.detections, session.rig, methods,
                      for_session(FusionOptions(), session.metadata, session.rig))
    copy_session(session_path, fused_path, tracks=list(tracks.values()), force=args.force)

    print(f"3/4 accuracy against ground truth ({fused_path}):\n")
    truth = session.truth
    assert truth is not None  # the demo's session is simulated: it has its ground truth
    print(format_accuracy_table([evaluate(t, truth) for t in tracks.values()]))
    print("\n    the same methods in the paper's simulation (pslog paper table1):\n")
    print(paper.format_table1(paper.table1()))

    if args.no_view:
        print("\n4/4 skipped the rerun recording (--no-view)")
        return 0
    from viewers import save_rrd

    rrd_path = folder / "demo.rrd"
    save_rrd([fused_path], rrd_path, force=args.force)
    print(f"\n4/4 saved the rerun recording {rrd_path}; open it with\n"
          f"      {shell_word(installed_command('rerun'))} {shell_word(rrd_path)}\n"
          f"    or in a browser:  {shell_word(installed_command('pslog'))} view "
          f"{shell_word(fused_path)} --serve")
    return 0
