"""pslog batch: re-sync, re-fuse, evaluate and render many sessions at once on Ray
(:mod:`pslog.batch`; docs/batch.md)."""

from __future__ import annotations

import argparse
import os

from ._common import add_force, add_method_option, checked_by, int_in

DESCRIPTION = """\
Run the same steps on every session a pattern matches, one Ray task per session: on local
processes by default (--workers, default the core count), on an existing Ray cluster with
--address. Each step is the command a user would type (pslog redetect, sync, fuse, eval,
view); the outputs of a session go to OUTDIR/<its path below the pattern's folder>/
(redetected.mcap, synced.mcap, fused.mcap, eval.json, view.rrd), and OUTDIR/summary.csv and
summary.parquet hold one row per session (cameras, duration, detections, per method points,
the points left out with their reasons as pslog fuse counts them, rate and errors against
truth, clock offsets, runtime, status and the one-line error of a failed session). A failed
session does not stop the others; the exit code is 1 if any failed. --resume skips the
sessions a stopped batch completed.
"""

#: most local worker processes (a typo like 1000 would start a thousand Python processes)
MAX_WORKERS = 256


def _steps(text: str) -> tuple[str, ...]:
    from pslog.batch import parse_steps
    from pslog.errors import PslogError

    try:
        return parse_steps(text)
    except PslogError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _estimate(text: str) -> tuple[str, ...]:
    from .sync import _estimate_list

    return _estimate_list(text)


def _frames(text: str) -> str:
    from .view import _frames as parse

    parse(text)
    return text


def _folder(text: str) -> str:
    if not text.strip():  # "" would be the current folder
        raise argparse.ArgumentTypeError("empty folder name")
    return text


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from pslog.batch import parse_address  # (standard library only: no Ray here)

    parser.description = DESCRIPTION
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.add_argument("patterns", nargs="+", metavar="PATTERN",
                        help="session files, or quoted patterns ('matches/**/*.mcap': ** spans "
                             "folders); the result tree mirrors the folders below the part "
                             "before the first wildcard")
    parser.add_argument("--do", required=True, type=_steps, metavar="STEPS",
                        help="steps, comma-separated, run in this order whatever the order "
                             "given: redetect, sync, fuse, eval, view (e.g. sync,fuse,eval)")
    parser.add_argument("-o", "--output", dest="outdir", required=True, metavar="OUTDIR",
                        type=_folder,
                        help="folder of the results (created)")
    add_method_option(parser, "fuse: fusion method, repeat or give a comma-separated list for "
                              "several (default: every method each session's timing suits)")
    parser.add_argument("--estimate", type=_estimate, default=(), metavar="LIST",
                        help="sync: clock parameters to estimate: auto (readouts and drifts "
                             "where a test says the data support them), or offset, drift, "
                             "readout, comma-separated (default: auto, as pslog sync)")
    parser.add_argument("--frames", type=_frames, default=None, metavar="all|none|every:N",
                        help="view: recorded images to include (default: all)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int_in(1, MAX_WORKERS), default=None, metavar="N",
                       help=f"local worker processes, at most {MAX_WORKERS} (default: the "
                            f"number of cores)")
    where.add_argument("--address", metavar="ADDRESS", type=checked_by(parse_address, "address"),
                       help="run on an existing Ray cluster: HOST:PORT (the head's GCS port, "
                            "ray start --head --port) or auto, on a node of the cluster; "
                            "ray://HOST:10001 from elsewhere through Ray Client (needs pip "
                            "install 'ray[client]'); the sessions and OUTDIR must be on "
                            "storage every node sees (docs/batch.md)")
    parser.add_argument("--resume", action="store_true",
                        help="skip the sessions whose outputs a previous batch with the same "
                             "steps completed (and whose input has not changed since); redo "
                             "the others")
    add_force(parser)


def kept_outputs(args: argparse.Namespace) -> list[str]:
    """What a run that completed wrote besides the sessions' results: the summary tables."""
    from pslog.batch import SUMMARY_NAMES

    return [os.path.join(args.outdir, name) for name in SUMMARY_NAMES]


def run(args: argparse.Namespace) -> int:
    import contextlib
    import os
    import sys
    from pathlib import Path

    from pslog.batch import Settings, find_sessions, results_lock
    from pslog.errors import PslogError
    from pslog.outputs import write_error
    from pslog.progress import _interval_s, progress_mode

    if args.estimate and "sync" not in args.do:
        # the estimate is sync's: without a sync step it would be ignored silently
        from ._common import usage_error

        return usage_error("batch", "--estimate is sync's: add sync to --do, or drop "
                                    "--estimate")
    # bad PSLOG_PROGRESS / PSLOG_PROGRESS_INTERVAL: one line, before anything runs
    mode = progress_mode(sys.stderr)
    every_s = _interval_s()
    settings = Settings(steps=args.do, methods=tuple(dict.fromkeys(args.methods or ())),
                        estimate=tuple(args.estimate), frames=args.frames or "")
    if args.address is not None:  # said at once, before any file is looked at
        from pslog.batch import check_reachable

        check_reachable(args.address)
    outdir = Path(args.outdir)
    if outdir.exists() and not outdir.is_dir():
        raise PslogError(f"-o {outdir}: not a folder")
    skipped: list[str] = []
    not_files: list[str] = []
    jobs = find_sessions(args.patterns, outdir, skipped, not_files)
    if not_files:  # (a session behind a broken link was left out without a word: sweep41)
        n = len(not_files)
        print(f"pslog batch: note: {n} match{'es' if n > 1 else ''} of the patterns "
              f"{'are' if n > 1 else 'is'} no session file, left out: "
              f"{', '.join(not_files[:3])}{', ...' if n > 3 else ''}", file=sys.stderr)
    if skipped:
        print(f"pslog batch: skipped {len(skipped)} file(s) inside earlier batch results "
              f"(a folder with pslog's summary.csv or done.json), e.g. {skipped[0]}",
              file=sys.stderr)
    created = not outdir.exists()
    try:  # a folder the workers cannot write is said once here, not once per session
        outdir.mkdir(parents=True, exist_ok=True)
        probe = outdir / f".pslog-batch-{os.getpid()}.probe"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise write_error(outdir, exc) from None
    try:
        with results_lock(outdir):
            return _run_locked(args, settings, jobs, outdir, mode, every_s)
    finally:
        if created:  # a batch that made nothing (refused, or no cluster) leaves no folder
            with contextlib.suppress(OSError):  # not empty: results kept
                outdir.rmdir()


def _run_locked(args: argparse.Namespace, settings, jobs, outdir, mode: str,
                every_s: float) -> int:
    """The batch, with the results folder locked: plan, run, summary."""
    import sys

    from pslog.batch import Progress, plan_batch, run_batch, write_summary
    from pslog.errors import PslogError

    plan = plan_batch(jobs, settings, outdir, resume=args.resume, force=args.force)
    progress = Progress(len(jobs), len(plan.done), every_s=every_s, mode=mode)

    def show(row: dict) -> None:
        """A session's line on standard output as soon as it is finished."""
        progress.clear()
        print(f"{row['status']:<6} {row['session']}" + (f": {row['error']}" if row["error"]
                                                         else ""), flush=True)

    if plan.done:
        print(f"pslog batch: {len(plan.done)} of {len(jobs)} sessions already complete "
              f"(--resume), {len(plan.run)} to run", file=sys.stderr)
    rows = list(plan.done)
    for row in sorted(plan.done, key=lambda r: r["session"]):
        show(row)
    if plan.run:
        rows += run_batch(plan.run, settings, workers=args.workers, address=args.address,
                          progress=progress, on_row=show, results=outdir)
    written = write_summary(rows, outdir)
    failed = sorted((r for r in rows if r["status"] != "ok"), key=lambda r: r["session"])
    print(f"wrote {', '.join(map(str, written))}")
    if failed:
        first = failed[0]
        raise PslogError(f"{len(failed)} of {len(rows)} sessions failed (first: "
                         f"{first['session']}: {first['error']}); see {written[0]}")
    return 0
