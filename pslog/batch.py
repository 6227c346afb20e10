"""``pslog batch``: re-process many sessions at once, one Ray task per session.

A season of matches is re-synced, re-fused, evaluated and rendered with the very commands a
user would type for one session (``pslog info``, ``redetect``, ``sync``, ``fuse``, ``eval``,
``view``), run in-process (:func:`pslog.cli.main`) inside one Ray task per session
(:func:`run_session`). Tasks read and write files by path: nothing large goes through Ray's
object store, so on a cluster the input and output folders must be on storage every node
sees (docs/batch.md). The summary table is built from the commands' own outputs (``--json``
of info, sync and eval), so it equals what running the commands by hand gives.

Ray is imported only by :func:`run_batch` (``pslog --help`` and every other command never
load it). Layout of the output folder, mirroring the input tree::

    results/<relative path of the session without .mcap>/
        redetected.mcap  synced.mcap  fused.mcap  eval.json  view.rrd   (the steps asked)
        done.json        written last: the session is complete (for --resume)
    results/summary.csv, results/summary.parquet
"""

from __future__ import annotations

import contextlib
import csv
import errno
import fnmatch
import glob
import hashlib
import io
import json
import math
import os
import shutil
import stat
import sys
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from pslog.errors import InputError, PslogError, shell_word
from pslog.records import by_reason

#: every step, in the order a session goes through them
STEPS = ("redetect", "sync", "fuse", "eval", "view")
#: each step's output file in the session's result folder
OUTPUT_NAMES = {"redetect": "redetected.mcap", "sync": "synced.mcap", "fuse": "fused.mcap",
                "eval": "eval.json", "view": "view.rrd"}
#: the marker written last: the session's outputs are complete (``--resume`` skips it)
DONE_NAME = "done.json"
#: the folder (in a session's result folder) where a task makes its new outputs; they
#: replace the old ones only when every one is complete
STAGING_NAME = ".pslog-batch-new"
#: the staging folder once complete (its new ``done.json`` inside), renamed in one step: the
#: commit point of a session's install. From then on the new set is the session's, and
#: whoever finds this folder finishes moving it into place (:func:`settle`)
READY_NAME = ".pslog-batch-ready"
#: in the staging/ready folder: the old outputs (of steps not run now) to remove on install
STALE_NAME = "stale.json"
#: in the ready folder: its move into place has begun (the old done.json may be gone)
MOVING_NAME = "moving"
SUMMARY_NAMES = ("summary.csv", "summary.parquet")
#: the summary's leading columns; per-method, per-camera columns follow
BASE_COLUMNS = ("session", "status", "error", "cameras", "duration_s", "frames", "detections",
                "truth", "runtime_s")
#: figures of ``pslog eval --json`` copied per method as ``<method>_<figure>``
EVAL_FIGURES = ("n_points", "rate_hz", "mean_mm", "median_mm", "p95_mm", "max_mm", "rms_mm")
#: figures of ``pslog sync --json`` copied per camera as ``<camera>_<figure>``, in ms/ppm
SYNC_FIGURES = (("offset_s", "offset_ms", 1e3), ("offset_std_s", "offset_std_ms", 1e3),
                ("drift_ppm", "drift_ppm", 1.0), ("drift_std_ppm", "drift_std_ppm", 1.0),
                ("readout_s", "readout_ms", 1e3), ("readout_std_s", "readout_std_ms", 1e3))
#: test hook: a path; the first task that finds no file there creates it and kills its own
#: worker process (SIGKILL) after its first step, to prove that Ray retries the task
KILL_ONCE_ENV = "PSLOG_BATCH_TEST_KILL_ONCE"
#: seconds between progress lines when standard error is not a terminal
PROGRESS_EVERY_S = 10.0
#: seconds of one wait on Ray's tasks: a signal is acted on, and pslog's SIGTERM handler put
#: back over the one Ray's core installs when it likes (a stack dump, then abort), at least
#: this often
WAIT_S = 0.25
#: seconds an interrupted batch waits for its cancelled tasks' workers to end
CANCEL_WAIT_S = 10.0
#: the lock file in a session's result folder: its task holds it (``flock``) while it works
#: there, and whoever else settles or discards the folder (the batch after an interrupt, the
#: next batch's plan, the discard of a failed session) takes it first: one process at a time
#: changes a session's outputs (a cancelled task's worker outlives the batch's interrupt)
TASK_LOCK_NAME = ".pslog-batch-task.lock"
#: seconds a task waits for a session's folder that another process still works in (a task
#: of a batch stopped just before, whose worker Ray has not ended yet) before it fails
TASK_LOCK_WAIT_S = 300.0
#: seconds the next batch's plan waits, in all, for such folders before it leaves them to
#: their tasks (which wait for them in turn)
PLAN_LOCK_WAIT_S = 60.0
#: the list of the failed sessions whose old outputs a batch is removing (in the results
#: folder, written before the first is removed, removed after the last): a batch stopped
#: meanwhile leaves it, and the next batch in that folder finishes the removal before it
#: plans (:func:`finish_discards`)
DISCARD_NAME = ".pslog-batch-discard.json"
#: test hook: set, the batch process sends itself SIGINT (a Ctrl-C) once it has removed the
#: first failed session's old outputs
INTERRUPT_DISCARD_ENV = "PSLOG_BATCH_TEST_INTERRUPT_DISCARD"
#: Ray's retries of a task whose worker process died (an exception is never retried: the
#: task turns every error into a failed row)
MAX_RETRIES = 3


class StepFailed(PslogError):
    """A command of a session's pipeline failed; the message is its one-line error."""


class StepInterrupted(StepFailed):
    """A command of a session's pipeline was ended by a signal (SIGINT, SIGTERM, SIGHUP:
    its exit code 130 or 128 + the signal's number): the batch is being interrupted (Ray
    ends a cancelled task's worker so), the session did not fail."""


@dataclass(frozen=True)
class Settings:
    """What is done to every session: the steps (in :data:`STEPS` order) and the options
    passed on to their commands."""

    steps: tuple[str, ...]
    methods: tuple[str, ...] = ()
    estimate: tuple[str, ...] = ()
    frames: str = ""

    def key(self) -> str:
        """A digest of the settings: outputs made with other settings are not resumed."""
        return hashlib.sha256(json.dumps(asdict(self), sort_keys=True).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Job:
    """One session: its file (absolute), its name in the summary (path relative to the
    pattern's folder) and its result folder (absolute)."""

    path: str
    session: str
    outdir: str


@dataclass
class Plan:
    """The sessions to run and those already complete (their summary rows, from their
    markers)."""

    run: list[Job] = field(default_factory=list)
    done: list[dict] = field(default_factory=list)


def parse_steps(text: str) -> tuple[str, ...]:
    """``sync,fuse,eval`` -> the steps in :data:`STEPS` order; :class:`InputError` for an
    unknown or missing step."""
    names = [s.strip() for s in text.split(",") if s.strip()]
    bad = [s for s in names if s not in STEPS]
    if not names or bad:
        raise InputError(f"{text!r}: name steps among {', '.join(STEPS)} (comma-separated)"
                         + (f"; unknown: {', '.join(bad)}" if bad else ""))
    return tuple(s for s in STEPS if s in names)


def _glob_root(pattern: str) -> Path:
    """The folder part of ``pattern`` before its first wildcard (the root that the result
    tree mirrors); a plain file's folder."""
    parts = Path(pattern).parts
    for i, part in enumerate(parts):
        if glob.has_magic(part):
            return Path(*parts[:i]) if i else Path(".")
    return Path(pattern).parent


def _not_a_session_file(path: str) -> str | None:
    """What a match that is no session file is, in words (``a FIFO``, ``a link to a missing
    file``, ...), or None: a regular file, or a folder not named like a session (a ``**``'s
    folders are matches too, not misnamed sessions)."""
    try:
        st = os.stat(path)
    except OSError as exc:
        if os.path.islink(path):
            return ("a loop of symbolic links" if exc.errno == errno.ELOOP
                    else "a link to a missing file")
        return f"unreadable: {exc.strerror or exc}"
    if stat.S_ISREG(st.st_mode):
        return None
    if stat.S_ISDIR(st.st_mode):
        return "a folder" if path.endswith(".mcap") else None
    return ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a socket" if stat.S_ISSOCK(st.st_mode)
            else "a device")


def _glob_files(pattern: str, others: list[str] | None = None) -> list[str]:
    """The files ``glob.glob(pattern, recursive=True)`` matches, sorted, but with each
    folder that a ``**`` reaches more than once (through a symbolic link to a folder above
    it: a loop) walked once: two such links in one folder made glob walk 2^40 paths (the
    depth at which the kernel refuses to follow links), and ``pslog batch 'd/**/*.mcap'``
    hung (sweep41). The same rules as glob otherwise: links to folders followed, names
    starting with '.' matched only by a pattern that starts with one, ``**`` not into
    hidden folders, unreadable folders passed over."""
    if "**" not in pattern:  # (each component walks each folder once: no loop to fear)
        matches = glob.glob(pattern, recursive=True)
        if others is not None:  # (matches that are no session file: said by the caller)
            others += [p for p in sorted(matches) if not os.path.isfile(p)]
        return sorted(p for p in matches if os.path.isfile(p))
    parts = pattern.split(os.sep)
    first = next(i for i, part in enumerate(parts) if glob.has_magic(part))
    prefix = os.sep.join(parts[:first]) if first else ""
    if first == 1 and not parts[0]:  # (an absolute pattern: '/**/...')
        prefix = os.sep
    found: set[str] = set()
    chain: list[tuple[int, int, int]] = []  # (component, device, inode) of the folders above

    def names(folder: str, hidden: bool) -> list[tuple[str, bool]]:
        try:
            with os.scandir(folder or ".") as it:
                out = []
                for entry in it:
                    if entry.name.startswith(".") and not hidden:
                        continue
                    try:
                        is_dir = entry.is_dir()  # (follows links, as glob does)
                    except OSError:
                        is_dir = False
                    out.append((entry.name, is_dir))
                return out
        except OSError:
            return []

    def walk(folder: str, k: int) -> None:
        if k == len(parts):
            if os.path.isfile(folder):
                found.add(folder)
            elif others is not None and os.path.lexists(folder):
                missed.add(folder)
            return
        part = parts[k]
        if part == "**":
            try:
                st = os.stat(folder or ".")
            except OSError:
                return
            key = (k, st.st_dev, st.st_ino)
            if key in chain:  # (a folder inside itself: a loop, walked once)
                return
            chain.append(key)
            walk(folder, k + 1)  # (no folder)
            for name, is_dir in names(folder, hidden=False):
                if is_dir:
                    walk(os.path.join(folder, name), k)
                elif k + 1 == len(parts):  # (a trailing '**' matches files too)
                    walk(os.path.join(folder, name), k + 1)
            chain.pop()
            return
        if not glob.has_magic(part):
            path = os.path.join(folder, part)
            if os.path.lexists(path):
                walk(path, k + 1)
            return
        for name, is_dir in names(folder, hidden=part.startswith(".")):
            if fnmatch.fnmatchcase(name, part) and (is_dir or k + 1 == len(parts)):
                walk(os.path.join(folder, name), k + 1)

    missed: set[str] = set()
    walk(prefix, first)
    if others is not None:
        others += sorted(missed)
    return sorted(found)


def _holds_results(folder: Path, cache: dict[Path, bool]) -> bool:
    """Whether ``folder`` holds a batch's results: a ``summary.csv`` whose header is
    pslog's, or a ``done.json`` marker."""
    if folder not in cache:
        held = (folder / DONE_NAME).is_file()
        if not held:
            try:
                with open(folder / "summary.csv", encoding="utf-8") as f:
                    header = f.readline().rstrip("\r\n").split(",")
                held = tuple(header[:len(BASE_COLUMNS)]) == BASE_COLUMNS
            except (OSError, ValueError):
                held = False
        cache[folder] = held
    return cache[folder]


def _inside_results(path: Path, root: Path, cache: dict[Path, bool]) -> bool:
    """Whether ``path`` lies in a folder (its own or one above it, up to the pattern's
    root) that holds a batch's results: an earlier batch's outputs are not sessions."""
    if _holds_results(path.parent, cache):
        return True
    for folder in path.parent.parents:
        if not folder.is_relative_to(root) or folder == root.parent:
            break
        if _holds_results(folder, cache):
            return True
    return False


def find_sessions(patterns: Iterable[str], outdir: str | Path,
                  skipped: list[str] | None = None,
                  not_files: list[str] | None = None) -> list[Job]:
    """The session files matching ``patterns`` (``**`` spans folders), sorted, each with its
    result folder below ``outdir`` mirroring its path below the pattern's root. Files inside
    ``outdir`` and inside any folder holding a batch's results (a ``summary.csv`` with
    pslog's header, or a ``done.json`` beside the file) are left out; those of the latter are
    appended to ``skipped``. Matches that are no session file (a link to a missing file or
    a loop of links, a FIFO, a device, a folder named ``*.mcap``) are left out, and appended
    to ``not_files`` as ``PATH (WHAT)``. :class:`InputError` when a pattern matches no file
    (naming such matches) or two sessions would share a result folder."""
    out = Path(outdir).resolve()
    jobs: dict[str, Job] = {}
    cache: dict[Path, bool] = {}
    for pattern in patterns:
        root = _glob_root(pattern).resolve()
        others: list[str] = []
        matched = _glob_files(pattern, others)
        odd = [f"{p} ({what})" for p in others
               if (what := _not_a_session_file(p)) is not None
               and not Path(os.path.abspath(p)).is_relative_to(out)]
        if not_files is not None:
            not_files += [p for p in odd if p not in not_files]
        found = [p for p in matched if not Path(p).resolve().is_relative_to(out)]
        if matched and not found:
            raise InputError(f"every match of {pattern!r} lies inside -o {outdir} (the "
                             f"results folder); give -o outside the sessions' folder")
        earlier = [p for p in found if _inside_results(Path(p).resolve(), root, cache)]
        if skipped is not None:
            skipped += [p for p in earlier if p not in skipped]
        found = [p for p in found if p not in earlier]
        if not found and not matched and os.path.isdir(pattern):
            # a folder is no pattern of its files: say which pattern is (quoted, as pasted)
            inside = os.path.join(glob.escape(pattern), "**", "*.mcap")
            n = len(_glob_files(inside))
            suggested = shell_word(inside)
            raise InputError(f"{pattern} is a folder, not a session file: give its sessions "
                             f"as the quoted pattern {suggested} ({n} .mcap file"
                             f"{'' if n == 1 else 's'} there and in its subfolders)")
        if not found and odd:
            raise InputError(f"no session file matches {pattern!r}: "
                             f"{', '.join(odd[:3])}{', ...' if len(odd) > 3 else ''}")
        if not found:
            raise InputError(f"no session file matches {pattern!r}"
                             + (f" (every match lies inside an earlier batch's results, e.g. "
                                f"{earlier[0]})" if earlier else ""))
        for p in found:
            path = Path(p).resolve()
            rel = path.relative_to(root) if path.is_relative_to(root) else Path(path.name)
            name = rel.with_suffix("").as_posix() if rel.suffix == ".mcap" else rel.as_posix()
            if name in jobs and jobs[name].path != str(path):
                raise InputError(f"{jobs[name].path} and {path} would share the result folder "
                                 f"{out / name}; give patterns that keep their names apart")
            jobs[name] = Job(str(path), rel.as_posix(), str(out / name))
    return sorted(jobs.values(), key=lambda j: j.session)


def _input_stamp(path: str) -> dict:
    st = os.stat(path)
    return {"size": st.st_size, "mtime_ns": st.st_mtime_ns}


def _outputs(job: Job, settings: Settings) -> list[Path]:
    return [Path(job.outdir) / OUTPUT_NAMES[s] for s in settings.steps]


def read_marker(job: Job) -> dict | None:
    """The session's ``done.json``, or None if missing or unreadable (then not complete)."""
    try:
        with open(Path(job.outdir) / DONE_NAME, encoding="utf-8") as f:
            marker = json.load(f)
    except (OSError, ValueError):
        return None
    return marker if isinstance(marker, dict) else None


def plan_batch(jobs: list[Job], settings: Settings, outdir: str | Path, *, resume: bool,
               force: bool) -> Plan:
    """Which sessions to run. With ``resume``, a session whose marker says its outputs are
    complete, for this input (same size and modification time) and these settings, is not
    run again; the others are run, their leftovers (an interrupted batch's) replaced.
    Without ``resume`` or ``force``, any existing output, marker or summary is refused
    (:class:`~pslog.errors.OutputExistsError` naming the first); with ``resume`` but not
    ``force``, a marker made with other settings is refused."""
    from pslog.errors import OutputExistsError

    plan = Plan()
    key = settings.key()
    conflicts: list[str] = []
    deadline = time.monotonic() + PLAN_LOCK_WAIT_S
    finish_discards(outdir)  # an earlier batch's, cut short
    for job in jobs:
        # an install an interrupted batch committed: finished, then judged (a folder that a
        # stopped batch's worker still holds is left to the session's task, which waits)
        with session_lock(job, wait_s=max(0.0, deadline - time.monotonic())) as held:
            if held is not False:
                settle(job)
        marker = read_marker(job) if resume else None
        if marker is not None and marker.get("settings") != key and not force:
            raise OutputExistsError(
                f"{Path(job.outdir) / DONE_NAME} was made with other settings (steps "
                f"{','.join(marker.get('steps', []))}); give --force to replace those results "
                f"or another -o")
        if (marker is not None and marker.get("settings") == key
                and marker.get("input") == _input_stamp(job.path)
                and all(p.is_file() for p in _outputs(job, settings))
                and isinstance(marker.get("row"), dict)):
            plan.done.append(marker["row"])
            continue
        plan.run.append(job)
        if not force and not resume:
            conflicts += [str(p) for p in [*_outputs(job, settings),
                                           Path(job.outdir) / DONE_NAME] if p.exists()]
    if not force and not resume:
        conflicts += [str(Path(outdir) / n) for n in SUMMARY_NAMES if (Path(outdir) / n).exists()]
    if conflicts:
        more = f" (and {len(conflicts) - 1} more)" if len(conflicts) > 1 else ""
        raise OutputExistsError(f"{conflicts[0]} exists{more}; give --force to replace, or "
                                f"--resume to continue a stopped batch")
    return plan


# --------------------------------------------------------------------------- the task


def _command(argv: list[str]) -> str:
    """Run ``pslog ARGV`` in this process, as typed by a user; its standard output, or
    :class:`StepFailed` with its one-line error."""
    from pslog.cli import main

    out, err = io.StringIO(), io.StringIO()
    # the batch shows its own progress (sessions done/failed/running): not each command's
    shown = os.environ.get("PSLOG_PROGRESS")
    os.environ["PSLOG_PROGRESS"] = "off"
    # a Ray task holds one CPU: smooth's break scan on one thread (unless the user said)
    os.environ.setdefault("PSLOG_SMOOTH_THREADS", "1")
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse (a bad option value passed on): exit 2
            code = exc.code if isinstance(exc.code, int) else 1
        finally:
            if shown is None:
                os.environ.pop("PSLOG_PROGRESS", None)
            else:
                os.environ["PSLOG_PROGRESS"] = shown
    if code != 0:
        lines = [line for line in err.getvalue().splitlines() if line.strip()]
        raise (StepInterrupted if code > 128 else StepFailed)(
            lines[-1] if lines else f"pslog {argv[0]} exited with code {code}")
    return out.getvalue()


def _implicit(argv: list[str]) -> str:
    """:func:`_command` for a command the batch runs for its own needs (``info`` for the
    summary, ``eval`` when --do has fuse but not eval), not a step the user named: its
    error line is said as the batch's (``pslog batch: error: ...``), not as a command the
    user never typed (was ``pslog info: error: ...`` in a batch of --do fuse)."""
    try:
        return _command(argv)
    except StepFailed as exc:
        own, line = f"pslog {argv[0]}: ", str(exc)
        if not line.startswith(own):
            raise
        raise type(exc)("pslog batch: " + line[len(own):]) from None


def _kill_once(marker: str) -> None:
    """The test hook of :data:`KILL_ONCE_ENV`: the worker dies as by the OOM killer."""
    import signal

    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return
    os.close(fd)
    os.kill(os.getpid(), signal.SIGKILL)


def _write_json(path: Path, value) -> None:
    from pslog.outputs import replacing

    with replacing(path, "w", force=True) as f:
        f.write(json.dumps(value, indent=2, allow_nan=False) + "\n")


def _take_lock(path: Path, deadline: float | None) -> int | None:
    """An open descriptor of ``path`` (created) holding its exclusive ``flock``, or None
    once ``time.monotonic()`` passed ``deadline`` (None: no limit) with another process
    holding it. A holder removes the file before it lets go: a lock got on a file the path
    no longer names is let go and taken again on the file it names now."""
    import fcntl

    while True:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            if deadline is not None and time.monotonic() >= deadline:
                return None
            time.sleep(0.05)
            continue
        except BaseException:
            os.close(fd)
            raise
        try:
            here, now = os.fstat(fd), os.stat(path)
            if (here.st_dev, here.st_ino) == (now.st_dev, now.st_ino):
                return fd
        except FileNotFoundError:
            pass
        os.close(fd)


@contextlib.contextmanager
def session_lock(job: Job, *, wait_s: float | None, create: bool = False
                 ) -> Iterator[bool | None]:
    """The session's folder held by this process alone (:data:`TASK_LOCK_NAME`) while the
    block runs: yields True; False when another process (a cancelled task's worker still
    running) held it ``wait_s`` seconds (None: no limit); None when it cannot be taken —
    no folder (``create``: made), or a file system without ``flock`` — where the block then
    runs as before the lock. The lock file is removed at the end."""
    outdir = Path(job.outdir)
    deadline = None if wait_s is None else time.monotonic() + wait_s
    fd = None
    held: bool | None = None
    try:
        if create:
            outdir.mkdir(parents=True, exist_ok=True)
        if outdir.is_dir():
            fd = _take_lock(outdir / TASK_LOCK_NAME, deadline)
            held = fd is not None
    except OSError:  # not writable, or no flock there (a Lustre mount without it)
        held = None
    try:
        yield held
    finally:
        if fd is not None:
            with contextlib.suppress(OSError):
                (outdir / TASK_LOCK_NAME).unlink()
            os.close(fd)


def run_session(job: Job, settings: Settings) -> dict:
    """Process one session with the commands a user would type; its summary row.

    :func:`run_task` (the batch's task), then, if the session failed, its old outputs
    discarded (:func:`discard_failed`): what a batch does for one session in this process.

    Returns
    -------
    row : dict of the summary's columns (:func:`summary_row`)
    """
    row, failed = run_task(job, settings)
    if failed:
        discard_failed(job, settings)
    return row


def run_task(job: Job, settings: Settings) -> tuple[dict, bool]:
    """Process one session with the commands a user would type; its summary row and whether
    the session failed (its old outputs are then to be discarded, by the batch, once it has
    this row: :func:`discard_failed`).

    The task of :func:`run_batch`, a pure function of the session file and the settings to
    the files below ``job.outdir``, holding the session's folder (:func:`session_lock`)
    throughout. The commands write into the staging folder :data:`STAGING_NAME`; only when
    every step is done do the new outputs replace the old ones, in one step
    (:func:`_install`), so a session interrupted at any point keeps its old, complete set
    with its old ``done.json``, or has the new complete set with the new one. The task
    itself never removes an old output but by that install: a session that fails keeps
    none of its old outputs, but only once the batch has its failed row (a failure while
    the batch is being interrupted, a cancelled task's, is no failure of the session).
    Every error becomes the row's ``status`` ``failed`` and ``error`` (the command's
    one-line message); nothing raises.
    """
    start = time.perf_counter()
    outdir = Path(job.outdir)
    staging = outdir / STAGING_NAME
    try:
        with session_lock(job, wait_s=TASK_LOCK_WAIT_S, create=True) as held:
            if held is False:
                error = (f"pslog batch: error: another process still works in {outdir} "
                         f"(a task of a batch stopped {TASK_LOCK_WAIT_S:g} s ago?); run "
                         f"the batch again")
                return summary_row(job.session, None, None, None, error=error,
                                   runtime_s=time.perf_counter() - start), False
            try:
                return _run_staged(job, settings, staging, start)
            finally:
                # whatever happened (an error, Ctrl-C in this process): no staged file
                # stays, and an install past its commit point is finished
                with contextlib.suppress(OSError, ValueError):
                    settle(job)
    finally:
        _remove_empty(_result_folders(job))  # no empty folders left for it


def discard_failed(job: Job, settings: Settings, wait_s: float | None = TASK_LOCK_WAIT_S
                   ) -> None:
    """A failed session's old outputs (and ``done.json``) removed, and its emptied folders:
    none stays beside its failed row. Holding its folder (:func:`session_lock`): one that
    another process still holds after ``wait_s`` keeps its outputs."""
    with session_lock(job, wait_s=wait_s) as held:
        if held is not False:
            _discard(job, settings)
            with contextlib.suppress(OSError, ValueError):
                settle(job)  # a dead attempt's staging folder
    _remove_empty(_result_folders(job))


def discard_all(failed: list[Job], settings: Settings, results: str | Path | None) -> None:
    """:func:`discard_failed` for each of ``failed``, resumable: the list is written first
    into the results folder (:data:`DISCARD_NAME`) and removed after the last, so a batch
    stopped meanwhile (Ctrl-C) leaves the rest to the next batch there
    (:func:`finish_discards`) instead of keeping some failed sessions' old outputs and
    ``done.json`` (``--resume`` would take those for complete). ``results`` None: no list
    (one session, or a caller without a results folder)."""
    journal = None if results is None or not failed else Path(results) / DISCARD_NAME
    if journal is not None:
        try:
            _write_json(journal, {"settings": asdict(settings),
                                  "jobs": [asdict(job) for job in failed]})
        except OSError:  # (a full disk: the removal then goes on without its list)
            journal = None
    for i, job in enumerate(failed):
        discard_failed(job, settings)
        if i == 0 and os.environ.get(INTERRUPT_DISCARD_ENV):
            import signal

            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # (the KeyboardInterrupt is raised here)
    if journal is not None:
        journal.unlink(missing_ok=True)


def finish_discards(results: str | Path) -> None:
    """The removal of failed sessions' old outputs that an earlier batch in ``results``
    began and did not finish (its :data:`DISCARD_NAME` list), finished; a list that cannot
    be read (cut short by a crash: its sessions' removal had not begun) is dropped."""
    journal = Path(results) / DISCARD_NAME
    if not journal.exists():
        return
    try:
        with open(journal, encoding="utf-8") as f:
            listed = json.load(f)
        raw = listed["settings"]
        settings = Settings(steps=tuple(raw["steps"]), methods=tuple(raw["methods"]),
                            estimate=tuple(raw["estimate"]), frames=str(raw["frames"]))
        jobs = [Job(str(j["path"]), str(j["session"]), str(j["outdir"]))
                for j in listed["jobs"]]
    except (OSError, ValueError, TypeError, KeyError, AttributeError):
        jobs = []
    root = Path(results).resolve()
    for job in jobs:
        if Path(job.outdir).resolve().is_relative_to(root):  # (never outside the folder)
            discard_failed(job, settings)
    journal.unlink(missing_ok=True)


def settle_held(jobs: Iterable[Job], wait_s: float) -> None:
    """:func:`settle` for each of ``jobs`` whose folder this process can hold within
    ``wait_s`` seconds in all (a cancelled task's worker may still run there; one still
    holding it is left as it is, to the next batch's settle), and its emptied folders
    removed."""
    deadline = time.monotonic() + wait_s
    for job in jobs:
        with session_lock(job, wait_s=max(0.0, deadline - time.monotonic())) as held:
            if held is not False:
                with contextlib.suppress(OSError, ValueError):
                    settle(job)
        _remove_empty(_result_folders(job))


def _run_staged(job: Job, settings: Settings, staging: Path, start: float
                ) -> tuple[dict, bool]:
    """:func:`run_task`'s steps, writing into ``staging``; the row, and whether the session
    failed (not interrupted)."""
    outdir = Path(job.outdir)
    info = sync = evaluation = None
    error = ""
    kill = os.environ.get(KILL_ONCE_ENV)
    stamp = None
    staged = False  # this task made its staging folder
    interrupted = False  # a command ended by a signal
    try:
        try:
            # the input as it is when the task starts: done.json records this, so a file
            # replaced mid-run is not later taken as done with the old file's outputs
            stamp = _input_stamp(job.path)
        except OSError as exc:
            from pslog.outputs import os_reason

            raise StepFailed(f"pslog batch: error: {job.path}: {os_reason(exc)}") from None
        try:
            outdir.mkdir(parents=True, exist_ok=True)
            settle(job)  # an earlier task's install cut short: finished first
            # the new outputs are made in a staging folder and replace the old ones only
            # when all are complete (_install): an interrupted run keeps the old set
            staging.mkdir()
            staged = True
        except OSError as exc:
            from pslog.outputs import os_reason

            raise StepFailed(f"pslog batch: error: cannot write {outdir}: "
                             f"{os_reason(exc)}") from None
        out = {s: str(staging / OUTPUT_NAMES[s]) for s in settings.steps}
        info = json.loads(_implicit(["info", job.path, "--json"]))
        current = job.path
        if "redetect" in settings.steps:
            _command(["redetect", current, "-o", out["redetect"], "--workers", "1", "--force"])
            current = out["redetect"]
        if "sync" in settings.steps:
            estimate = ["--estimate", ",".join(settings.estimate)] if settings.estimate else []
            sync = json.loads(_command(["sync", current, "-o", out["sync"], "--json", "--force",
                                        *estimate]))
            current = out["sync"]
        if kill:
            _kill_once(kill)
        if "fuse" in settings.steps:
            methods = [a for m in settings.methods for a in ("--method", m)]
            # one thread: a Ray task holds one CPU (as redetect's one worker above)
            _command(["fuse", current, "-o", out["fuse"], "--force", "--workers", "1", *methods])
            current = out["fuse"]
        if "eval" in settings.steps or "fuse" in settings.steps:
            # the summary's points and rates come from eval's figures, asked for or not
            evaluate = _command if "eval" in settings.steps else _implicit
            evaluation = json.loads(evaluate(["eval", current, "--json"]))
            if "eval" in settings.steps:
                _write_json(Path(out["eval"]), evaluation)
        if "view" in settings.steps:
            frames = ["--frames", settings.frames] if settings.frames else []
            _command(["view", current, "--save", out["view"], "--force", *frames])
    except StepFailed as exc:
        error = str(exc)
        interrupted = isinstance(exc, StepInterrupted)
    except Exception as exc:  # a bug: still one line in the summary, the batch goes on
        error = f"pslog batch: error: {type(exc).__name__}: {exc}".splitlines()[0]
    row = summary_row(job.session, info, sync, evaluation, error=error,
                      runtime_s=time.perf_counter() - start, estimate=settings.estimate)
    if not error:
        try:
            changed = _input_stamp(job.path) != stamp
        except OSError:
            changed = True
        if changed:
            error = f"pslog batch: error: {job.path}: input changed during the run"
            row.update(status="failed", error=error)
    if not error:
        try:
            _install(job, settings, staging, {"session": job.session,
                                              "settings": settings.key(),
                                              "steps": list(settings.steps),
                                              "input": stamp, "row": _json_row(row)})
        except (OSError, PslogError, ValueError) as exc:
            from pslog.outputs import os_reason

            reason = os_reason(exc) if isinstance(exc, OSError) else str(exc)
            error = f"pslog batch: error: cannot write {outdir}: {reason}"
            row.update(status="failed", error=error)
    if error and (interrupted or (staged and not staging.is_dir())):
        # a command ended by a signal, or the staging folder removed under this task: not a
        # failure of the session but an interrupted batch (Ray ends a cancelled task's
        # worker by signals, asynchronously; an interrupted batch settles the folder while
        # that worker may still run, and a step then fails on its vanished folder): the old
        # outputs stay, as for any interrupted session
        return row, False
    # failed (not interrupted): none of its old outputs is to stay beside its failed row —
    # removed by the batch once it has the row (discard_failed), never here: a failure while
    # the batch is interrupted (a cancelled task's worker ended under a step in any way) is
    # no failure of the session, and its old outputs stay with the batch's old summary
    return row, bool(error)


def _old_outputs(job: Job, settings: Settings) -> list[Path]:
    """The session's outputs of this batch's steps and of the steps its earlier marker
    names (both the batch's own), ``done.json`` not included."""
    earlier = read_marker(job) or {}
    old = [s for s in earlier.get("steps", []) if s in OUTPUT_NAMES]
    return [Path(job.outdir) / OUTPUT_NAMES[s] for s in dict.fromkeys([*settings.steps, *old])]


def _discard(job: Job, settings: Settings) -> None:
    """The session's old outputs removed (``done.json`` first, so they are never taken for
    complete ones); its folder held (:func:`discard_failed`)."""
    outputs = _old_outputs(job, settings)
    # a committed install that could not be finished: not installed by a later settle()
    shutil.rmtree(Path(job.outdir) / READY_NAME, ignore_errors=True)
    with contextlib.suppress(OSError):
        (Path(job.outdir) / DONE_NAME).unlink(missing_ok=True)
    for path in outputs:
        with contextlib.suppress(OSError):
            path.unlink(missing_ok=True)


#: test hook: called with a word naming each step boundary of an install (:func:`_install`,
#: :func:`_finish_install`), where an interrupt could cut it
_install_step: Callable[[str], None] | None = None


def _step(name: str) -> None:
    if _install_step is not None:
        _install_step(name)


def _install(job: Job, settings: Settings, staging: Path, marker: dict) -> None:
    """Every staged output (all complete) replaces the old ones, as one step: the new
    ``done.json`` and the list of old outputs to remove (of steps not run now) are written
    into ``staging``, which is then renamed to :data:`READY_NAME` — the commit point — and
    :func:`_finish_install` moves its files into place. Cut short before the rename, the
    old outputs are untouched (with their ``done.json``); after it, whoever settles the
    folder next (this task's end, the batch after an interrupt, the next batch) finishes
    the install, and until then no ``done.json`` names a mix of old and new outputs."""
    outdir = Path(job.outdir)
    keep = {OUTPUT_NAMES[s] for s in settings.steps}
    stale = [p.name for p in _old_outputs(job, settings) if p.name not in keep]
    _write_json(staging / STALE_NAME, stale)
    _write_json(staging / DONE_NAME, marker)
    _step("staged")
    shutil.rmtree(outdir / READY_NAME, ignore_errors=True)  # settled before: never committed
    os.rename(staging, outdir / READY_NAME)
    _step("committed")
    _finish_install(outdir)


def _finish_install(outdir: Path) -> None:
    """Move a committed install (the :data:`READY_NAME` folder) into place: the old
    ``done.json`` removed first, then the new outputs renamed over the old ones, the stale
    old outputs removed, the new ``done.json`` moved last and the folder removed. Each
    step can be cut short and done again (a file already moved is not there any more)."""
    ready = outdir / READY_NAME
    if not (ready / DONE_NAME).is_file():  # none, or moved into place but for its folder
        shutil.rmtree(ready, ignore_errors=True)
        return
    plan = _install_plan(ready)
    moving = (ready / MOVING_NAME).exists()
    if plan is None or not (moving or all((ready / n).is_file() for n in plan[0])):
        # damaged (a crash before its files reached the disk) or not one of ours: before
        # the move began the old set and its done.json are intact — kept; once begun, no
        # done.json stands beside the mix: the session is done again
        shutil.rmtree(ready, ignore_errors=True)
        return
    names, stale = plan
    (ready / MOVING_NAME).touch()
    _step("moving")
    (outdir / DONE_NAME).unlink(missing_ok=True)
    _step("old marker removed")
    for name in names:
        if (ready / name).exists():
            os.replace(ready / name, outdir / name)
            _step(f"moved {name}")
    for name in stale:
        (outdir / name).unlink(missing_ok=True)
        _step(f"removed {name}")
    os.replace(ready / DONE_NAME, outdir / DONE_NAME)
    _step("new marker")
    shutil.rmtree(ready, ignore_errors=True)


def _install_plan(ready: Path) -> tuple[list[str], list[str]] | None:
    """The outputs a committed install moves into place and the stale old outputs it
    removes (the batch's own output names only), from its ``done.json`` and
    :data:`STALE_NAME`; None when either is unreadable or not what :func:`_install` wrote."""
    try:
        with open(ready / DONE_NAME, encoding="utf-8") as f:
            marker = json.load(f)
        with open(ready / STALE_NAME, encoding="utf-8") as f:
            stale = json.load(f)
    except (OSError, ValueError):
        return None
    steps = marker.get("steps") if isinstance(marker, dict) else None
    known = set(OUTPUT_NAMES.values())
    if (not isinstance(steps, list) or not all(isinstance(s, str) and s in OUTPUT_NAMES
                                               for s in steps)
            or not isinstance(stale, list) or not all(isinstance(n, str) and n in known
                                                      for n in stale)):
        return None
    return [OUTPUT_NAMES[s] for s in steps], stale


def settle(job: Job) -> None:
    """What an interrupted task left in the session's result folder put right: staged
    outputs (never committed) removed, a committed install finished (:func:`_install`).
    Afterwards the folder holds the old outputs with their ``done.json`` or the new ones
    with theirs. Run where no task of the session runs: at its task's start and end, by
    the batch after an interrupt (its tasks ended) and when planning the next batch."""
    outdir = Path(job.outdir)
    shutil.rmtree(outdir / STAGING_NAME, ignore_errors=True)
    if (outdir / READY_NAME).exists():
        _finish_install(outdir)


def _result_folders(job: Job) -> list[Path]:
    """The session's result folder and those above it, up to (not including) the results
    folder: deepest first."""
    outdir = Path(job.outdir)
    depth = len(Path(job.session).parts)  # the result folder mirrors the session's path
    return [outdir, *list(outdir.parents)[:depth - 1]]


def _remove_empty(folders: Iterable[Path]) -> None:
    """Remove ``folders`` (deepest first) while they are empty."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:  # not empty (another session's results): the folders above too
            return


def _json_row(row: dict) -> dict:
    """``row`` for JSON: NaN (no value) as null, which the summary writes alike."""
    return {k: None if isinstance(v, float) and math.isnan(v) else v for k, v in row.items()}


def summary_row(session: str, info: dict | None, sync: dict | None, evaluation: list | None,
                *, error: str = "", runtime_s: float = math.nan,
                estimate: Iterable[str] = ()) -> dict:
    """One row of the summary from the JSON outputs of ``pslog info``, ``pslog sync`` and
    ``pslog eval`` (each None when not run or failed before).

    Columns: :data:`BASE_COLUMNS` (``duration_s`` in s, ``frames`` detected frames,
    ``detections`` candidates, ``runtime_s`` wall-clock s of the whole task), then per
    camera ``<camera>_offset_ms`` and ``_offset_std_ms`` (and the drift's and readout's when
    ``estimate`` names them) of ``pslog sync``, ``camera_gaps`` (the stretches a camera sent
    no frame, ``pslog info``'s: ``cam3: no frame after t = 3.141 s (to the end, 5.996 s)``;
    empty: none), then per
    method ``<method>_n_points``, the points it left out (:func:`left_out_columns`),
    ``_rate_hz`` and the errors against ground truth in mm (NaN without truth)."""
    row: dict = {"session": session, "status": "failed" if error else "ok", "error": error,
                 "cameras": "", "duration_s": math.nan, "frames": None, "detections": None,
                 "truth": None, "runtime_s": runtime_s}
    if info is not None:
        row.update(cameras=" ".join(c["name"] for c in info.get("cameras", [])),
                   duration_s=info.get("duration_s", math.nan), frames=info.get("frames"),
                   detections=info.get("candidates"), truth=info.get("truth"))
        from pslog.log.info import gap_text

        # a camera unplugged halfway: an "ok" row said nothing of it (walk41)
        row["camera_gaps"] = "; ".join(gap_text(g, short=True)
                                       for g in info.get("camera_gaps", []))
    # what sync estimated: named by --estimate, or chosen by auto (sync's "estimated")
    wanted = {"offset", *estimate, *((sync or {}).get("estimated") or ())}
    for cam in (sync or {}).get("cameras", []):
        for key, column, scale in SYNC_FIGURES:
            if key.split("_")[0] not in wanted:
                continue
            value = cam.get(key)
            row[f"{cam['name']}_{column}"] = math.nan if value is None else value * scale
    if sync is not None:
        row["sync_residual_px"] = sync.get("residual_px", math.nan)
    for method in evaluation or []:
        for key in EVAL_FIGURES:
            value = method.get(key, method.get("quality", {}).get(key))
            row[f"{method['method']}_{key}"] = math.nan if value is None else value
            if key == "n_points":  # beside them, the points it left out (fuse's counts)
                row.update(left_out_columns(method["method"], method.get("left_out") or {}))
    return row


def left_out_columns(method: str, left_out: dict[str, int]) -> dict:
    """The summary's left-out columns of ``method`` from its ``{reason: count}``
    (``Track.dropped``, as ``pslog eval --json`` gives it in ``left_out``):
    ``<method>_left_out``, their total, and ``<method>_left_out_reasons``, the counts by
    reason in ``pslog fuse``'s words (``"contradicted 3, unconfirmed 2"``; empty: none)."""
    return {f"{method}_left_out": int(sum(left_out.values())),
            f"{method}_left_out_reasons": by_reason(left_out)}


# --------------------------------------------------------------------------- the summary


def summary_columns(rows: list[dict]) -> list[str]:
    """:data:`BASE_COLUMNS`, then every other column in order of first appearance."""
    columns = list(BASE_COLUMNS)
    for row in rows:
        columns += [c for c in row if c not in columns]
    return columns


def _csv_value(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)  # repr: exact round trip
    if isinstance(value, str):  # a session, camera or error a spreadsheet would run: '=x
        from pslog.log.csvio import csv_text

        return csv_text(value)
    return str(value)


def write_summary(rows: list[dict], outdir: str | Path) -> list[Path]:
    """``summary.csv`` (always) and ``summary.parquet`` (with pyarrow, which rerun-sdk
    brings) in ``outdir``, both or neither (:func:`pslog.outputs.all_or_nothing`: each
    written as ``.partial``, both renamed once both are complete; a full disk at the second
    left a new CSV beside the last batch's Parquet). Rows sorted by session; a cell a
    session has no value for is empty (CSV) or null (Parquet). Returns the paths written."""
    from pslog.outputs import all_or_nothing, replacing

    rows = sorted(rows, key=lambda r: r["session"])
    columns = summary_columns(rows)
    written = []
    with all_or_nothing():
        path = Path(outdir) / "summary.csv"
        with replacing(path, "w", force=True) as f:
            writer = csv.writer(f, lineterminator="\n")
            writer.writerow([_csv_value(c) for c in columns])  # (<camera>_offset_ms: -x_...)
            for row in rows:
                writer.writerow([_csv_value(row.get(c)) for c in columns])
        written.append(path)
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:  # pragma: no cover - rerun-sdk depends on pyarrow
            return written

        def clean(value):
            return None if isinstance(value, float) and math.isnan(value) else value

        table = pa.table({c: [clean(r.get(c)) for r in rows] for c in columns})
        path = Path(outdir) / "summary.parquet"
        with replacing(path, "wb", force=True) as f:
            pq.write_table(table, f)
        written.append(path)
    return written


def read_summary_csv(path: str | Path) -> list[dict[str, str]]:
    """The rows of a ``summary.csv`` as strings (empty cells as ``""``; text a spreadsheet
    would take for a formula as it was, without the ``'`` written before it)."""
    from pslog.log.csvio import csv_text_read

    def text(cell):
        return csv_text_read(cell) if isinstance(cell, str) else cell

    with open(path, newline="", encoding="utf-8") as f:
        return [{text(k): text(v) for k, v in row.items()} for row in csv.DictReader(f)]


# --------------------------------------------------------------------------- the driver


class Progress:
    """Sessions done / failed / running and the rate: one updating line on a terminal,
    a line every :data:`PROGRESS_EVERY_S` otherwise (logs, CI)."""

    def __init__(self, total: int, skipped: int, stream=None, every_s: float = PROGRESS_EVERY_S,
                 mode: str | None = None):
        self.total, self.skipped = total, skipped
        self.stream = stream if stream is not None else sys.stderr
        # mode: bar, lines or off (pslog.progress.progress_mode); None: by the stream
        if mode is None:
            mode = "bar" if getattr(self.stream, "isatty", lambda: False)() else "lines"
        self.mode = mode
        self.tty = mode == "bar"
        self.every_s = every_s
        self.start = time.monotonic()
        self.last = -math.inf
        self.done = self.failed = 0

    def line(self, running: int) -> str:
        elapsed = time.monotonic() - self.start
        finished = self.done + self.failed
        rate = finished / elapsed * 60 if elapsed > 0 else 0.0
        skipped = f", {self.skipped} already complete" if self.skipped else ""
        return (f"pslog batch: {finished}/{self.total} sessions ({self.done} done, "
                f"{self.failed} failed, {running} running{skipped}), {rate:.1f} sessions/min, "
                f"{elapsed:.0f} s")

    def clear(self) -> None:
        """Wipe the updating line (a bar) before another line is printed."""
        if self.tty:
            self.stream.write("\r\x1b[K")
            self.stream.flush()

    def update(self, running: int, final: bool = False) -> None:
        if self.mode == "off":
            return
        now = time.monotonic()
        if self.tty:
            self.stream.write("\r\x1b[K" + self.line(running) + ("\n" if final else ""))
            self.stream.flush()
        elif final or now - self.last >= self.every_s:
            self.last = now
            print(self.line(running), file=self.stream, flush=True)


#: the lock file that keeps a second batch out of a results folder in use
LOCK_NAME = ".pslog-batch.lock"


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process: alive
        return True
    return True


@contextlib.contextmanager
def results_lock(outdir: str | Path):
    """Hold ``outdir/.pslog-batch.lock`` (created exclusively, holding this process's id)
    while a batch writes there: a second batch on the same folder fails with one line
    naming the lock and its holder. A lock whose process is gone (a batch killed outright)
    is taken over. Removed at the end."""
    from pslog.outputs import write_error

    path = Path(outdir) / LOCK_NAME
    for _attempt in range(4):  # (the last one after a garbage lock was removed)
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                holder = int(path.read_text(encoding="utf-8").split()[0])
            except (OSError, ValueError, IndexError):
                holder = None  # being written right now, or garbage: look again
                time.sleep(0.1)
                if _attempt < 2:
                    continue
            if holder is not None and holder != os.getpid() and _pid_alive(holder):
                raise PslogError(f"{path}: another pslog batch (pid {holder}) is writing to "
                                 f"{outdir}; wait for it to end or give another -o") from None
            with contextlib.suppress(FileNotFoundError):  # stale: its batch is gone
                path.unlink()
            continue
        except OSError as exc:
            raise write_error(path, exc) from None
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(f"{os.getpid()}\n")
        except OSError as exc:  # a full disk: the lock is not taken, and not left behind
            with contextlib.suppress(OSError):
                path.unlink()
            raise write_error(path, exc) from None
        break
    else:
        raise PslogError(f"{path}: cannot take the lock of {outdir} (another batch keeps "
                         f"taking it); give another -o")
    try:
        yield path
    finally:
        with contextlib.suppress(OSError):
            path.unlink()


#: seconds to wait for a cluster's port to answer before saying it cannot be reached
CONNECT_TIMEOUT_S = 5.0


def parse_address(text: str) -> tuple[str, int] | None:
    """``--address``: ``auto`` (None: Ray finds the cluster this node belongs to),
    ``HOST:PORT`` or ``ray://HOST:PORT`` -> (host, port); :class:`InputError` otherwise."""
    if text == "auto":
        return None
    rest = text.removeprefix("ray://")
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")  # an IPv6 address in brackets
    if not host or "/" in host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise InputError(f"{text!r}: give HOST:PORT (a node of the cluster), "
                         f"ray://HOST:PORT (Ray Client, on port 10001 by default) or auto")
    return host, int(port)


def check_reachable(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """One line when nothing answers at ``address`` (Ray itself would retry for minutes,
    printing a warning every few seconds)."""
    import socket

    from pslog.outputs import os_reason

    where = parse_address(address)
    if where is None:
        return
    if address.startswith("ray://"):
        import importlib.util

        # Ray Client talks gRPC: without the ray[client] extra ray.init fails only after
        # the connection, with a paragraph; say it at once, in one line
        if importlib.util.find_spec("grpc") is None:
            raise PslogError(f"--address {address}: Ray Client is not installed here (pip "
                             f"install 'ray[client]'); or run pslog batch on a node of the "
                             f"cluster with --address HOST:PORT (the head's GCS port) or auto")
    try:
        socket.create_connection(where, timeout=timeout_s).close()
    except OSError as exc:
        reason = "no answer" if isinstance(exc, TimeoutError) else os_reason(exc)
        raise PslogError(f"cannot reach the Ray cluster at {address}: {reason} (is "
                         f"'ray start --head' running there?)") from None


@contextlib.contextmanager
def ray_cluster(workers: int | None, address: str | None):
    """A Ray cluster to run on: the one this process already joined (tests), the one at
    ``address``, or a local one of ``workers`` CPUs (a temporary folder, no dashboard,
    quiet logs), shut down and removed at the end. Yields the number of task slots."""
    import logging
    import tempfile

    try:
        import ray
    except ImportError:
        raise PslogError("pslog batch needs Ray: pip install 'pslog[batch]' (or "
                         "pip install ray)") from None
    if ray.is_initialized():
        yield int(ray.cluster_resources().get("CPU", 1))
        return
    temp = None
    watchdog = None  # (the local cluster's: ends what a killed batch leaves, _start_watchdog)
    quiet: dict[str, Any] = {"logging_level": logging.ERROR, "log_to_driver": False,
                             "include_dashboard": False}
    native = io.StringIO()  # what Ray's C++ core wrote while joining a cluster
    handlers = _signal_handlers()  # the command's, which ray.init replaces with Ray's
    from pslog.outputs import native_stderr, signals_held

    try:
        # a Ctrl-C while Ray starts is acted on once it has started (then shut down in
        # full: one cut short left Ray's agents running); never mix Ray's words into stdout
        with signals_held(), contextlib.redirect_stdout(sys.stderr):
            if address is not None:
                # Ray's core logs each failed attempt to join (a wrong token: one warning a
                # second for ~20 s) on the process's standard error: kept aside, the
                # reason is then said in the one line below
                with native_stderr(native):
                    ray.init(address=address, **quiet)
            else:
                # a short private folder: Ray's socket paths must fit in 107 bytes
                temp = tempfile.mkdtemp(prefix="pslog-ray-")
                watchdog = _start_watchdog(temp)
                ray.init(num_cpus=workers or os.cpu_count() or 1, _temp_dir=temp, **quiet)
    except Exception as exc:
        _shutdown(ray, temp, handlers, watchdog)
        where = f"the Ray cluster at {address}" if address else "a local Ray cluster"
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if "InvalidAuthToken" in native.getvalue() or "Unauthenticated" in native.getvalue():
            reason = ("it uses token authentication and refused this machine's token (give "
                      "the cluster's token as RAY_AUTH_TOKEN or in ~/.ray/auth_token: "
                      "docs/batch.md)")
        raise PslogError(f"cannot start or join {where}: {reason}") from None
    except SystemExit as exc:  # ray.init's own SIGTERM handler: sys.exit(15), no word
        _shutdown(ray, temp, handlers, watchdog)
        import signal

        if exc.code == signal.SIGTERM:
            from pslog.cli import Terminated

            raise Terminated(signal.SIGTERM) from None
        raise
    except BaseException:  # Ctrl-C or SIGTERM as the cluster started: none left behind
        _shutdown(ray, temp, handlers, watchdog)
        raise
    try:
        _restore(handlers)  # Ray's SIGTERM handler would exit with code 15 and no word
        yield int(ray.cluster_resources().get("CPU", 1))
    finally:
        _shutdown(ray, temp, handlers, watchdog)


def _signal_handlers() -> dict:
    """SIGINT's and SIGTERM's handlers now (the main thread's; none elsewhere)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return {}
    return {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}


def _restore(handlers: dict) -> None:
    import signal

    for sig, handler in handlers.items():
        if handler is not None:
            signal.signal(sig, handler)


def _shutdown(ray, temp: str | None, handlers: dict, watchdog=None) -> None:
    """The cluster shut down (its local processes ended) and its folder removed, with the
    command's signal handlers back in place of Ray's (whose SIGTERM handler exits with
    code 15 and no word); a Ctrl-C or SIGTERM meanwhile is acted on only once that is
    done (it would leave Ray's processes running). ``watchdog``: the local cluster's
    (:func:`_start_watchdog`), told the batch ended (it then ends what is left)."""
    from pslog.outputs import signals_held

    _restore(handlers)
    with signals_held():
        ray.shutdown()
        if watchdog is not None:
            with contextlib.suppress(OSError):
                watchdog.stdin.close()  # (its end of the pipe: it cleans up, then exits)
            with contextlib.suppress(Exception):
                watchdog.wait(timeout=10)
        if temp is not None:
            shutil.rmtree(temp, ignore_errors=True)


#: The local cluster's watchdog (a process of its own, outside Ray): it waits for the end
#: of its standard input, which the batch holds open, so it wakes when the batch ends,
#: however it ends (SIGKILL included), then kills every process but the batch still holding a
#: file in the cluster's folder (Ray's DashboardAgent and RuntimeEnvAgent outlive a killed driver,
#: orphaned, 80 MB each: seen in session 38's sweep and CI runs; its GCS server and raylet
#: die with the driver) and removes the folder. Linux (/proc); elsewhere the folder only.
_WATCHDOG = """
import os, shutil, signal, sys, time
temp, batch = os.path.realpath(sys.argv[1]), int(sys.argv[2])
sys.stdin.buffer.read()  # until the batch's end of the pipe closes
def holds(pid):
    try:
        for fd in os.listdir(f"/proc/{pid}/fd"):
            if os.readlink(f"/proc/{pid}/fd/{fd}").startswith(temp + os.sep):
                return True
    except OSError:
        pass
    return False
def kill_holders():
    # each process checked and killed in turn, through a pidfd opened before a second
    # check: the process killed is one that holds a file in the folder, never one that took
    # the pid of a holder that ended meanwhile (review39); os.kill where there is no pidfd
    try:
        pids = [int(p) for p in os.listdir("/proc") if p.isdigit()]
    except OSError:
        return 0
    killed = 0
    for pid in pids:
        if pid in (os.getpid(), batch) or not holds(pid):  # (a batch ending well holds logs)
            continue
        try:
            fd = os.pidfd_open(pid)
        except (AttributeError, OSError):
            fd = None
        try:
            if holds(pid):
                if fd is not None:
                    signal.pidfd_send_signal(fd, signal.SIGKILL)
                else:
                    os.kill(pid, signal.SIGKILL)
                killed += 1
        except OSError:
            pass
        finally:
            if fd is not None:
                os.close(fd)
    return killed
for _ in range(3):  # (a process may still be opening its logs as the first pass runs)
    if not kill_holders():
        break
    time.sleep(0.2)
shutil.rmtree(temp, ignore_errors=True)
"""


def _start_watchdog(temp: str):
    """The local cluster's watchdog (:data:`_WATCHDOG`) for its folder ``temp``, started
    in a session of its own (a Ctrl-C to the batch's process group does not reach it), or
    None where it cannot start (the batch runs without it: a killed batch may then leave
    Ray's agents running)."""
    import subprocess

    try:
        return subprocess.Popen([sys.executable, "-c", _WATCHDOG, temp, str(os.getpid())],
                                stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True,
                                close_fds=True)
    except OSError:
        return None


def run_batch(jobs: list[Job], settings: Settings, *, workers: int | None = None,
              address: str | None = None, progress: Progress | None = None,
              on_row: Callable[[dict], None] | None = None,
              results: str | Path | None = None) -> list[dict]:
    """Run :func:`run_task` for every job as a Ray task (1 CPU each; retried up to
    :data:`MAX_RETRIES` times when its worker process dies); the summary rows, in the
    order the sessions finished. Once every task has ended, the sessions that failed lose
    their old outputs (:func:`discard_failed`); an interrupted batch removes none. A task
    lost for good (its worker died every time) is a failed row naming why. A single
    session on the local machine runs in this process, without a cluster (whose start-up
    would cost more than any gain). ``results``: the results folder, where the removal of
    the failed sessions' outputs keeps its list until done (:func:`discard_all`)."""
    import ray

    if len(jobs) == 1 and address is None and not ray.is_initialized():
        # one session: nothing to spread, so no cluster to start (seconds saved); this
        # process runs the task itself, and its death is the batch's (--resume redoes it)
        row, failed_one = run_task(jobs[0], settings)
        discard_all([jobs[0]] if failed_one else [], settings, results)
        if progress is not None:
            progress.done, progress.failed = (1, 0) if row["status"] == "ok" else (0, 1)
            progress.update(0, final=True)
        if on_row is not None:
            on_row(row)
        return [row]
    pending: dict = {}
    lasting = address is not None or ray.is_initialized()  # a cluster that outlives the batch
    try:
        with ray_cluster(workers, address) as slots:
            task = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(run_task)
            pending = {task.remote(job, settings): job for job in jobs}
            try:
                with _signals_noted() as came:
                    rows, failed = _gather(pending, slots, progress, on_row, came)
            except BaseException:
                for ref in pending:  # a cluster that outlives the batch (--address, tests)
                    with contextlib.suppress(Exception):
                        ray.cancel(ref, force=True)
                # a forced cancel kills the workers asynchronously: on a cluster that
                # outlives the batch, wait (bounded) until they are gone (a local
                # cluster's shutdown ends its workers, as asynchronously: the settle below
                # waits for each folder's lock)
                if lasting and pending:
                    with contextlib.suppress(Exception):
                        ray.wait(list(pending), num_returns=len(pending),
                                 timeout=CANCEL_WAIT_S)
                raise
    except BaseException:
        # interrupted: the tasks were ended (their workers killed with the local cluster)
        # and may have left staged outputs, removed (the old, complete ones stay), or an
        # install past its commit point, finished (the new set, complete). A cancelled
        # task's worker can outlive all this (Ray ends it asynchronously): each folder is
        # settled once this process holds it (the task holds it while it runs)
        settle_held(pending.values(), CANCEL_WAIT_S)
        raise
    # every task has ended: the failed sessions' old outputs go (none stays beside a failed
    # row). Not before: a batch interrupted meanwhile keeps every old output (its old
    # summary stays), whatever its tasks met while they were being ended
    discard_all(failed, settings, results)
    return rows


def _gather(pending: dict, slots: int, progress: Progress | None,
            on_row: Callable[[dict], None] | None, came: _Noted
            ) -> tuple[list[dict], list[Job]]:
    """The rows of the ``pending`` tasks (Ray object ref -> job) as they finish, and the
    jobs whose session failed (:func:`run_task`); each finished one leaves ``pending``. A
    signal noted in ``came`` (:func:`_signals_noted`) stops it between two waits:
    KeyboardInterrupt for SIGINT, ``Terminated`` for another (exit 128 + its number)."""
    import ray

    rows = []
    failed: list[Job] = []
    while pending:
        came.again()
        if came:
            import signal

            from pslog.cli import Terminated

            raise KeyboardInterrupt if came[0] == signal.SIGINT else Terminated(came[0])
        ready, _ = ray.wait(list(pending), num_returns=1, timeout=WAIT_S)
        for ref in ready:
            job = pending.pop(ref)
            try:
                row, session_failed = ray.get(ref)
                if session_failed:
                    failed.append(job)
            except Exception as exc:  # the worker died MAX_RETRIES + 1 times
                reason = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
                row = summary_row(job.session, None, None, None,
                                  error=f"pslog batch: error: the task failed "
                                        f"({type(exc).__name__}: {reason})")
            rows.append(row)
            if progress is not None:
                if row["status"] == "ok":
                    progress.done += 1
                else:
                    progress.failed += 1
            if on_row is not None:
                on_row(row)
        if progress is not None:
            progress.update(min(len(pending), slots))
    if progress is not None:
        progress.update(0, final=True)
    return rows, failed


class _Noted(list):
    """The signals that came (their numbers); :meth:`again` re-installs the noting handler
    over one Ray's core installed meanwhile (its C++ failure handler takes SIGTERM some
    seconds into a batch, dumps a stack and aborts the process: exit 134)."""

    def __init__(self) -> None:
        super().__init__()
        self.signals: tuple = ()

    def note(self, signum, _frame) -> None:
        self.append(signum)

    def again(self) -> None:
        import signal

        for sig in self.signals:
            signal.signal(sig, self.note)


@contextlib.contextmanager
def _signals_noted() -> Iterator[_Noted]:
    """SIGINT and SIGTERM noted (the list yielded), not raised, while the block waits on
    Ray: an exception thrown out of Ray's native wait left its core in a state that
    crashed at shutdown now and then (exit 139); the loop stops at its next turn, within
    :data:`WAIT_S`. Also replaces Ray's SIGTERM handlers (ray.init's exits with code 15 and
    no word, its core's aborts)."""
    import signal
    import threading

    came = _Noted()
    if threading.current_thread() is not threading.main_thread():
        yield came
        return
    came.signals = (signal.SIGINT, signal.SIGTERM)
    previous = {sig: signal.signal(sig, came.note) for sig in came.signals}
    try:
        yield came
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
