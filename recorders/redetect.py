"""Offline re-detection: run the ball detector again over a session's stored frames.

The new session is a stream copy of the old one (frames, calibration, poses, truth, events
and metadata kept as stored) with every frame's detections replaced, so it fuses like any
session; its fused tracks are dropped (fused from the old detections). A frame without a
stored image, or whose image does not decode, keeps its old detections.

Where the time goes (1280 x 720 JPEGs of quality 90, about 250 kB each with the renderer's
sensor noise; ``benchmarks/bench_redetect.py``, CPU time per frame): ``cv2.imdecode`` 3.4 ms
(libjpeg-turbo with SIMD; most of it entropy decoding, which no reduced-size decode avoids:
``IMREAD_REDUCED_COLOR_8`` still costs 2.3 ms, and its pixels are not the full decode's, so
the detector's candidates would change); detection about 1.1 ms of a frame just decoded
(the coarse pixels screened in place, :meth:`BallDetector._coarse_cells_strided`; 0.1 ms
less than subsampling the frame first), 0.85 ms with the compiled screen,
used from :data:`_COMPILED_FROM` frames on, once numba's half second of loading is repaid);
reading the frames from the file 0.12 ms (0.6 ms when each worker parsed the summary with
``mcap``'s reader and read its window with :func:`pslog.log.iter_images`: the same images);
copying the session into the new file about 0.2 ms in the main process, which also imports
OpenCV and numpy once (about 0.12 s, before the workers are forked: they inherit them). So:

- each worker reads its own runs of whole image chunks from the file, located once by this
  process from the summary section (:func:`_plan`: no worker parses the summary, and no
  chunk is read twice): each chunk is read into one reused buffer, decompressed and
  checked as every reader checks it, and each image decoded where it lies in the
  decompressed records (no Python object or copy per message but the image's protobuf,
  and the compressed bytes decompressed where they were read):
  no frame is pickled between processes, and the main process never reads the images;
- the workers are forked as soon as the chunks are located; with the compiled screen, a
  first pool detects a few short tasks with OpenCV's screen while this process loads numba
  (about 0.5 s of one core, once), then a second pool forked with numba loaded detects the
  rest, the first pool's tasks not started by then included (:func:`_detecting`): no core
  waits for numba, and only what the first pool's workers took meanwhile is detected the
  dearer way (about 2 ms more a frame). The first pool has one worker fewer than the
  second: this process takes a core meanwhile (with as many, three processes shared two
  cores: 216 frames of 2,160 went the dearer way at load 8-15, 107-143 with one worker);
- the tasks shrink towards the end (:func:`_guided`), so the workers finish together;
- every task is queued at once and the main process copies the session meanwhile
  (``copy_session`` takes the detections as a callable, called once the rest is copied),
  leaving the CRC of the image chunks to the workers, which check it as they read them;
- the workers keep freed memory (:func:`_keep_freed_memory`): no page faults per frame.

With the compiled screen (from :data:`_COMPILED_FROM` frames on), a frame is not decoded
whole: :class:`recorders._jpeg.ScreenedDecoder` entropy-decodes it, bounds each 8 x 8
block's colours from its coefficients, and inverse-transforms only the blocks that may hold
a pixel in the colour range (about 2 % of a recorded frame), bit-exactly as libjpeg does;
the detector runs on those: the candidates of the frame decoded whole, to the last bit
(the tests compare them), for about 60 % of a whole decode's CPU (the entropy decoding,
which every exact decode pays, is most of what is left). A worker's CPU per frame (session
21, 2,160 frames of 1280 x 720, one process, load 10-15): reading the chunk 0.05 ms,
decompressing 0.06, its CRC 0.10, the frame's bytes 0.01 (found in place,
:func:`pslog.log.reader.image_data`: the protobuf parser's copy cost 0.10), the header 0.03,
entropy decoding and the bound 3.3-3.4, decoding the ~340 blocks that pass the bound again
0.2, their transforms and second screen on their exact values (~15 blocks left, drawn)
0.2-0.3, the detector 0.25-0.7 (0.36-0.75 before its pooled mask was labelled from its
set cells only); returning the results 0.015. A frame it does not take
(progressive, subsampled, EXIF, damaged, ...) is decoded whole by ``cv2.imdecode``.
The main process's CPU (session 24, 2,160 frames, 547 MB, load 8-15; process CPU of each
stage): its imports (numpy, OpenCV, pslog.log) 0.19-0.24 s, numba for the workers 0.45-0.61
(``import numba`` 0.19-0.22, its typing and target set up at the first kernel's load
0.17-0.19, the colour table 0.06-0.07, the other kernels 0.02), the copy of the session
0.30-0.48 (the kernel's write of 547 MB into the page cache and the read of the image
chunks, 0.2-0.36 of system time; writing the chunks from the file mapped instead: 0.37 s
in three paired runs, no clear saving; ``copy_file_range`` alone costs as much as reading
and writing), the summary parsed three times 0.045, the BGR box 0.05, closing the new file
0.04-0.05, the forks 0.02, the rest (the detections merged and written, the session read)
0.04: about 0.7 s fixed and 0.15-0.2 ms a frame.
Otherwise every frame is decoded whole and detected: the decode and detection alone bound
two cores to about 450 frames/s, before the session is read and written.

Faster exact decoders were measured and none is (session 19, CPU per 1280 x 720 frame,
one process, load 12-20): ``simplejpeg`` (libjpeg-turbo bundled) gives the same pixels at
the same cost as ``cv2.imdecode`` once freed memory is kept (4.5-5.4 ms both; without
:func:`_keep_freed_memory` OpenCV's page faults doubled its cost), Pillow 6.3 ms; the
frames are 4:4:4 (no half-size chroma to keep). What no DCT scaling removes is the entropy
decoding: the 1/8 decode (the blocks' means) still costs 2.8-3.3 ms, 60-70 % of a full
one. ``fast`` (:class:`_Redetector`) trades exactness for the 1/2 decode's saving.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import os
import signal
import threading
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pslog.errors import InputError, LogFormatError, PslogError
from pslog.outputs import check_output_path
from pslog.records import Detections

from .detect import BallDetector, HsvRange

_BATCH = 64  # images per batch when one process decodes and detects
# images per task of the first pool while this process loads the compiled screen, and how
# many such tasks at most (more than it can start meanwhile; those it has not started when
# numba is loaded go to the compiled pool: a frame costs it ~1.7 ms more, 1280 x 720)
_HEAD = 16
_HEAD_TASKS = 18
_TAIL = 12  # images in the last, shortest tasks (every worker then finishes at once)
_PARALLEL_FROM = 400  # images; below this one process is faster than starting a pool
# images from which the detector's compiled screen is used: loading numba costs about 0.5 s
# of CPU once, the screen saves about 0.35 ms per 1280 x 720 frame
_COMPILED_FROM = 2000
#: Most ball candidates kept per frame: beyond a handful they are noise, and each costs work.
MAX_CANDIDATES = 100
#: Most worker processes: more than the cores only adds memory and start-up time.
MAX_WORKERS = 64


@dataclass(frozen=True)
class RedetectSummary:
    """What re-detection did.

    Attributes
    ----------
    output : the new session
    frames : frame records in the session
    images : frames decoded and re-detected
    kept : frames without a stored image, which keep their old candidates
    before, after : frames with at least one candidate, before and after
    undecodable : frames whose stored image does not decode (no bytes, truncated, damaged),
        which keep their old candidates too
    """

    output: Path
    frames: int
    images: int
    kept: int
    before: int
    after: int
    undecodable: int = 0

    def text(self) -> str:
        line = (f"re-detected {self.images} frames: {self.before} -> {self.after} frames with "
                f"a ball candidate; written {self.output}")
        if self.kept:
            line += f"\n{self.kept} frames have no stored image and keep their old detections"
        if self.undecodable:
            line += (f"\n{self.undecodable} frames have an image that does not decode (empty, "
                     f"truncated or damaged JPEG) and keep their old detections")
        return line


def redetect_session(src: str | Path, dst: str | Path, hsv: HsvRange | None = None, *,
                     max_candidates: int = 5, force: bool = False,
                     workers: int | None = None, fast: bool = False) -> RedetectSummary:
    """Write ``dst``: session ``src`` with detections recomputed from its stored frames.

    Parameters
    ----------
    hsv : colour range (default :class:`HsvRange`'s orange ball)
    max_candidates : K, candidates kept per frame
    force : overwrite ``dst``
    workers : processes decoding and detecting (default: all cores for large sessions)
    fast : detect in each frame decoded at half its size (:class:`_Redetector`): 10-20 %
        less CPU, not the same candidates (centroids 0.14-0.27 px RMS apart)
    """
    from pslog.log import copy_session, read_session

    if not 1 <= max_candidates <= MAX_CANDIDATES:
        raise InputError(f"max_candidates must be in 1..{MAX_CANDIDATES}, got {max_candidates}")
    if workers is not None and not 1 <= workers <= MAX_WORKERS:
        raise InputError(f"workers must be in 1..{MAX_WORKERS}, got {workers}")
    dst = check_output_path(dst, force, inputs=[src])
    session = read_session(src)
    if session.n_images == 0:
        raise InputError(f"{src} has no stored frames, nothing to re-detect (sessions from "
                         f"'pslog simulate', 'pslog import' or 'record --no-frames' hold "
                         f"detections only); record one with frames, e.g. 'pslog record "
                         f"--synthetic --rig paper3 --fast -o with_frames.mcap', or use "
                         f"samples/throw.mcap")
    old = session.detections
    hsv = hsv or HsvRange()
    row_of = {(int(c), int(i)): r for r, (c, i) in
              enumerate(zip(old.frame_camera, old.frame_index, strict=True))}

    from pslog import progress

    progress.update(0, total=session.n_images, unit="frames", what="detecting")
    done: dict[str, object] = {}

    def detections() -> Detections:
        """The new detections, once the rest of the session is copied (the workers detect
        meanwhile)."""
        rows, results = [], []
        for batch_rows, batch_results in batches:
            rows.extend(batch_rows)
            results.extend(batch_results)
        done["undecodable"] = [row for row, found in zip(rows, results, strict=True)
                               if found is None]
        done["redone"], done["new"] = _merged(old, rows, results)
        return done["new"]

    with _detecting(src, session.rig.names, row_of, hsv, max_candidates, workers,
                    session.n_images, fast) as (batches, checked, layout_of):
        # (the image chunks the workers read: copied without decompressing them here)
        # says how the candidates were made (a re-detection of a --fast output drops it)
        metadata = {"detector_hsv": hsv.text(),
                    "detector_decode": "half size (pslog redetect --fast)" if fast else None}
        copy_session(src, dst, detections=detections, metadata=metadata,
                     checked_chunks=checked, layouts=layout_of, force=force)
    redone, new = done["redone"], done["new"]
    bad = np.zeros(old.n_frames, dtype=bool)
    bad[done["undecodable"]] = True
    undecodable = int(np.count_nonzero(bad & ~redone))
    return RedetectSummary(dst, old.n_frames, int(redone.sum()),
                           int((~redone).sum()) - undecodable,
                           int(np.count_nonzero(old.candidates_per_frame())),
                           int(np.count_nonzero(new.candidates_per_frame())), undecodable)


def _merged(old: Detections, rows: list, results: list) -> tuple[np.ndarray, Detections]:
    """(re-detected (n_frames,) bool, the new detections): the new candidates of the
    re-detected frames, the old ones of the others (a result None: the frame's image does
    not decode, the frame is not re-detected)."""
    decoded = [(row, found) for row, found in zip(rows, results, strict=True)
               if found is not None]
    rows, results = [row for row, _f in decoded], [found for _r, found in decoded]
    redone = np.zeros(old.n_frames, dtype=bool)
    redone[rows] = True
    cand_frame, cand_uv, cand_radius, cand_score = [], [], [], []
    keep_old = ~redone[old.cand_frame]
    cand_frame.append(old.cand_frame[keep_old])
    cand_uv.append(old.cand_uv[keep_old])
    cand_radius.append(old.cand_radius[keep_old])
    cand_score.append(old.cand_score[keep_old])
    for row, (uv, radius, score) in zip(rows, results, strict=True):
        cand_frame.append(np.full(len(score), row, dtype=np.int64))
        cand_uv.append(uv)
        cand_radius.append(radius)
        cand_score.append(score)
    new = Detections.from_frames(
        old.camera_names, old.frame_time_ns, old.frame_camera, old.frame_index,
        np.concatenate(cand_frame), np.concatenate(cand_uv).reshape(-1, 2),
        np.concatenate(cand_radius), np.concatenate(cand_score))
    return redone, new


@contextlib.contextmanager
def _detecting(src, rig_names, row_of: dict, hsv: HsvRange, max_candidates: int,
               workers: int | None, n_images: int, fast: bool = False
               ) -> Iterator[tuple[Iterator[tuple[list, list]], frozenset[int], Any]]:
    """Start re-detecting (worker processes start at once, on every part of the session);
    give an iterator of (rows, [(uv, radius, score), ...]) batches for every stored image
    with a frame record, the images in their time order overall, and the byte offsets of
    the chunks whose CRC is checked while the batches are made (an iterator that ends
    has checked them all), and, with worker processes, ``layout_of(offset)``: the layout
    of such a chunk's records as its worker read them (waiting for its task; for
    :func:`pslog.log.copy_session`), else None. On leaving, work not started is
    cancelled."""
    import cv2

    # one OpenCV thread in this process too, before any worker is forked: a worker inherits
    # OpenCV's thread pool if this process had started one (a large conversion, e.g. by
    # _bgr_box), without its threads, and hangs in its first call into OpenCV
    cv2.setNumThreads(1)
    workers = workers or (os.cpu_count() or 1)
    compiled = n_images >= _COMPILED_FROM
    parallel = workers > 1 and n_images >= _PARALLEL_FROM
    if not parallel:  # runs of about _BATCH images, each told to the progress as it is done
        plan = _plan(src, rig_names, n_images, _BATCH)
        detector = _Redetector(hsv, max_candidates, compiled, fast)
        if plan is None:
            yield _serial(src, row_of, detector), frozenset(), None
        else:
            yield _in_order((_read_and_detect(src, chunks, plan.cameras, detector)
                             for chunks in plan.tasks), row_of), _offsets(plan), None
        return
    plan = _plan(src, rig_names, n_images, 1)  # one chunk a task: regrouped below
    if plan is not None:
        plan = _Plan(_guided([c for task in plan.tasks for c in task], n_images, workers,
                             _HEAD if compiled else 0), plan.cameras)
    # each task is a run of whole image chunks (or, for a file whose summary does not say
    # where they are, the whole session) that a worker reads from the file itself: nothing
    # but a few numbers per frame crosses between the processes, so every task is queued at
    # once (the workers stay busy while this process copies the session)
    from concurrent.futures.process import BrokenProcessPool

    from .detect import _bgr_box

    _bgr_box(hsv)  # (about 40 ms, cached) made here once, inherited by every worker

    def submit(pool: ProcessPoolExecutor, i: int, compiled: bool):
        if plan is None:
            return pool.submit(_detect_window, str(src), None, None, hsv, max_candidates,
                               compiled, fast)
        return pool.submit(_detect_chunks, str(src), plan.tasks[i], plan.cameras, hsv,
                           max_candidates, compiled, fast)

    pools: list[ProcessPoolExecutor] = []
    try:
        # the workers are forked while the submissions go, with Ctrl-C and SIGTERM blocked
        # here, so that none comes to a worker before it ignores them (a terminal's Ctrl-C
        # goes to the whole process group: a worker interrupted while holding the task
        # queue's lock hung the pool's shutdown, or printed its traceback); this process
        # gets the signal once they are unblocked, and stops them by shutting the pools down
        # with the compiled screen: the workers forked at once detect the first few short
        # tasks with OpenCV's screen while this process loads numba's (about 0.5 s of one
        # core: loaded once, here, instead of once per worker or before any worker starts),
        # and a second pool forked then, inheriting it, detects the rest
        two = compiled and plan is not None
        n_tasks = 1 if plan is None else len(plan.tasks)
        first = min(_HEAD_TASKS, n_tasks) if two else n_tasks
        with _stop_signals_blocked():
            # while this process loads numba it takes a core itself: one worker fewer here
            pools.append(ProcessPoolExecutor(max_workers=workers - 1 if two else workers,
                                             initializer=_ignore_stop_signals))
            futures = [submit(pools[0], i, compiled and plan is None) for i in range(first)]
        if two and first < n_tasks:
            _warm_screened(hsv, max_candidates)
            with _stop_signals_blocked():
                pools.append(ProcessPoolExecutor(max_workers=workers,
                                                 initializer=_ignore_stop_signals))
                # the first pool's tasks not started yet go to the compiled one, first: only
                # what its workers took while numba loaded is detected the slower way
                for i in range(first):
                    if futures[i].cancel():
                        futures[i] = submit(pools[1], i, True)
                futures += [submit(pools[1], i, True) for i in range(first, n_tasks)]
            pools[0].shutdown(wait=False)  # its workers end once their tasks are done
        if plan is None:
            yield (_rows(_told(fut.result()), row_of) for fut in futures), frozenset(), None
        else:
            task_of = {offset: i for i, task in enumerate(plan.tasks)
                       for _rank, offset, _length in task}

            def layout_of(offset: int):
                i = task_of.get(offset)
                return None if i is None else futures[i].result().layouts.get(offset)

            yield (_in_order((fut.result() for fut in futures), row_of), _offsets(plan),
                   layout_of)
    except BrokenProcessPool:
        # the pool's own clean-up stops the other workers with SIGTERM, which they ignore,
        # and waits for them: one busy with a task, or blocked on a queue the dead one left
        # locked, would never end (the command hung)
        _kill_workers(pools)
        raise PslogError(f"re-detecting {src}: a worker process died (killed, or out of "
                         f"memory); try fewer --workers") from None
    finally:
        for pool in reversed(pools):
            pool.shutdown(wait=True, cancel_futures=True)


def _warm_screened(hsv: HsvRange, max_candidates: int) -> None:
    """Load (or compile, once per install) the compiled screen and the screened decoder's
    kernels here, and make the decoder's colour table, so that the workers forked next
    inherit them."""
    import cv2

    from ._jpeg import ScreenedDecoder
    from .record import jpeg_params

    detector = BallDetector(hsv, max_candidates, compiled=True)
    frame = detector.warm(64, 48)
    ok, blob = cv2.imencode(".jpg", frame, jpeg_params(90))
    if ok:
        ScreenedDecoder(detector).detect(blob.tobytes())


def _kill_workers(pools: list[ProcessPoolExecutor]) -> None:
    """SIGKILL every worker process still alive in ``pools`` (after one died: their results
    are lost with the pool anyway)."""
    for pool in pools:
        # ProcessPoolExecutor keeps its processes in ``_processes`` (pid -> Process); there
        # is no public way to stop a busy worker
        for process in list((getattr(pool, "_processes", None) or {}).values()):
            with contextlib.suppress(Exception):
                process.kill()


def _offsets(plan: _Plan) -> frozenset[int]:
    """The offsets of the chunks of ``plan``: each is checked (CRC included) as it is read
    for detection, so the copy of the session need not compute their CRC again."""
    return frozenset(offset for task in plan.tasks for _rank, offset, _length in task)


def _guided(chunks: list, n_images: int, workers: int, head: int) -> list[list]:
    """``chunks`` in consecutive runs for ``workers`` processes: ``head`` images' worth per
    run for the first :data:`_HEAD_TASKS` runs when ``head`` (the first pool's, see
    :func:`_detecting`), then runs of a fraction of what is left, each ``1 / (2 workers)``
    of it ("factoring", Hummel, Schonberg & Flynn 1992, CACM 35(8)), down to about
    :data:`_TAIL` images: the first runs are long (few tasks) and the last ones short, so
    that every worker finishes within about one short run of the others."""
    per_chunk = max(n_images, 1) / max(len(chunks), 1)  # images per chunk, on average
    smallest = max(1, round(_TAIL / per_chunk))
    runs, at = [], 0
    if head:
        size = max(1, round(head / per_chunk))
        for _ in range(_HEAD_TASKS):
            if at < len(chunks):
                runs.append(chunks[at:at + size])
                at += size
    while at < len(chunks):
        size = max(smallest, -(-(len(chunks) - at) // (2 * workers)))
        runs.append(chunks[at:at + size])
        at += size
    return runs


_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


@contextlib.contextmanager
def _stop_signals_blocked() -> Iterator[None]:
    """Block Ctrl-C and SIGTERM in this thread for the block (the main thread: a process
    forked meanwhile starts with them blocked); one that came is delivered at its end."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _ignore_stop_signals() -> None:
    """A worker's first act: ignore Ctrl-C and SIGTERM (the main process handles them and
    shuts the pool down; a worker ends when its task queue closes), then unblock them."""
    for sig in _STOP_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


def _serial(src, row_of: dict, detector: _Redetector) -> Iterator[tuple[list, list]]:
    from pslog import progress

    images = iter(_images(src, None, None))
    while batch := list(itertools.islice(images, _BATCH)):
        progress.update(advance=len(batch))
        yield _rows(_detect_images(detector, batch), row_of)


@dataclass(frozen=True)
class _Plan:
    """Where a session's images are: ``tasks``, runs of image chunks as ``(rank, offset,
    length)`` (rank: the chunk's place in the order of first message times, then offsets;
    offset and length of its Chunk record, bytes); ``cameras``, image channel id ->
    (camera index, the channel's place in the summary)."""

    tasks: list[list[tuple[int, int, int]]]
    cameras: dict[int, tuple[int, int]]


def _plan(src, rig_names, n_images: int, per_task: int) -> _Plan | None:
    """The image chunks of ``src`` (those whose indexes list an image channel, and any
    chunk without indexes) in runs of about ``per_task`` images, as :func:`pslog.log.
    iter_images` chooses them, from the summary section (pslog's own parse: a worker then
    needs no summary, which ``mcap``'s parser reads at about 0.1 ms a chunk). None when the
    file has no usable summary or no chunks: the images are then read by
    :func:`pslog.log.iter_images` (which reports what is wrong with the file)."""
    import mmap

    from pslog.log import _mcapio as io
    from pslog.log import _schemas as S

    topics = {S.image_topic(name): c for c, name in enumerate(rig_names)}
    try:
        with open(src, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as buf:
            summary = io.read_summary(buf)
    except (OSError, ValueError):
        return None
    if summary is None or not summary.chunks:
        return None
    # the topics the statistics name (as the reader counts them), their channels in the
    # summary's order
    counted = {summary.channels[c].topic for c in summary.channel_counts
               if c in summary.channels}
    cameras = {cid: (topics[ch.topic], rank) for rank, (cid, ch) in enumerate(
        (cid, ch) for cid, ch in summary.channels.items()
        if ch.topic in topics and ch.topic in counted)}
    chunks = sorted((c for c in summary.chunks
                     if cameras.keys() & c.message_index_offsets.keys()
                     or not c.message_index_offsets),
                    key=lambda c: (c.start_ns, c.offset))
    located = [(rank, c.offset, c.length) for rank, c in enumerate(chunks)]
    step = max(1, round(per_task * len(located) / max(n_images, 1)))  # chunks per task
    return _Plan([located[i:i + step] for i in range(0, len(located), step)], cameras)


def _images(src, lo: int | None, hi: int | None) -> Iterator:
    from pslog.log import iter_images

    return iter_images(src, start_ns=lo, end_ns=hi)


def _detect_window(src: str, lo: int | None, hi: int | None, hsv: HsvRange,
                   max_candidates: int, compiled: bool, fast: bool = False
                   ) -> tuple[np.ndarray, np.ndarray, list]:
    """In a worker: read the images of ``[lo, hi)`` from ``src``, decode and detect (a file
    without a usable summary: see :func:`_plan`)."""
    import cv2

    cv2.setNumThreads(1)
    _keep_freed_memory()
    return _detect_images(_Redetector(hsv, max_candidates, compiled, fast),
                          _images(src, lo, hi))


def _detect_chunks(src: str, chunks: list[tuple[int, int, int]], cameras: dict,
                   hsv: HsvRange, max_candidates: int, compiled: bool,
                   fast: bool = False) -> _Found:
    """In a worker: decode and detect the images of ``chunks`` (see :class:`_Plan`)."""
    import cv2

    cv2.setNumThreads(1)
    _keep_freed_memory()
    return _read_and_detect(src, chunks, cameras,
                            _Redetector(hsv, max_candidates, compiled, fast))


@dataclass
class _Found:
    """The images of some chunks and their candidates: ``camera``, ``index`` (frame index),
    ``key`` ((n, 4) int64: log time, chunk rank, channel rank, byte offset in the chunk:
    sorted, the order in which :func:`pslog.log.iter_images` gives them) and ``found``,
    ``[(uv, radius, score)] * n``."""

    camera: np.ndarray
    index: np.ndarray
    key: np.ndarray
    found: list
    #: chunk offset -> the layout of its records (:func:`pslog.log.copy.record_layout`): the
    #: copy writes a chunk whose indexes state it without decompressing it again
    layouts: dict = field(default_factory=dict)


def _read_and_detect(src, chunks: list[tuple[int, int, int]], cameras: dict,
                     detector: _Redetector) -> _Found:
    """Read each chunk of ``chunks`` (one read into a buffer reused for every chunk,
    decompressed and checked as every reader checks it), and decode and detect each image
    in it where it lies in the decompressed records (no copy of its bytes)."""
    from pslog.log import _mcapio as io
    from pslog.log.reader import image_data

    path = Path(src)
    from pslog.log.copy import record_layout

    camera, index, key, found, layouts = [], [], [], [], {}
    buffer = bytearray(max((length for _r, _o, length in chunks), default=0))
    with open(path, "rb") as f:
        for rank, offset, length in chunks:
            view = memoryview(buffer)[:length]
            try:
                f.seek(offset)
                got = f.readinto(view)
                if got != length or view[0] != io.OP_CHUNK or \
                        int.from_bytes(view[1:9], "little") != length - 9:
                    raise LogFormatError("chunk record does not match the summary's index")
                records = io.chunk_payload(view[9:])
            except LogFormatError as exc:
                raise io.damaged_error(path, offset, str(exc)) from None
            layouts[offset] = record_layout(records)
            for cid, seq, t, a, b in io.message_spans(records, cameras):
                data = image_data(records, a, b, path)
                camera.append(cameras[cid][0])
                index.append(seq)
                key.append((t, rank, cameras[cid][1], a))
                found.append(detector(data))
            del records  # freed before the next chunk is read
    return _Found(np.array(camera, dtype=np.int64), np.array(index, dtype=np.int64),
                  np.array(key, dtype=np.int64).reshape(-1, 4), found, layouts)


def _told(detected: tuple[np.ndarray, np.ndarray, list]) -> tuple[np.ndarray, np.ndarray,
                                                                   list]:
    from pslog import progress

    progress.update(advance=len(detected[2]))
    return detected


def _in_order(parts, row_of: dict) -> Iterator[tuple[list, list]]:
    """The frame rows and candidates of the images of every :class:`_Found` of ``parts``,
    in the order of their keys (one batch at the end: the progress is told per part)."""
    from pslog import progress

    collected = []
    for part in parts:
        progress.update(advance=len(part.found))  # each part as it comes
        collected.append(part)
    parts = collected
    camera = np.concatenate([p.camera for p in parts]) if parts else np.zeros(0, np.int64)
    index = np.concatenate([p.index for p in parts]) if parts else np.zeros(0, np.int64)
    key = np.concatenate([p.key for p in parts]) if parts else np.zeros((0, 4), np.int64)
    found = list(itertools.chain.from_iterable(p.found for p in parts))
    order = np.lexsort(key.T[::-1])
    yield _rows((camera[order], index[order], [found[i] for i in order.tolist()]), row_of)


@functools.cache
def _keep_freed_memory() -> None:
    """In a worker or the ``pslog redetect`` process (glibc only): keep freed memory for
    reuse instead of returning it to the system. Every frame allocates a few MB (the chunk
    read, the decoded image, the copied chunk); by default glibc maps such blocks afresh
    and unmaps them when freed, so each frame page-faults its buffers in again: about
    0.25 ms of system time per 1280 x 720 frame in a worker, 5 % of the frame's cost, and
    as much again in the process copying the session (``benchmarks/bench_redetect.py``).
    Only this process's memory use is affected (its largest working set stays mapped)."""
    import ctypes
    import platform

    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return
    try:
        libc = ctypes.CDLL(None)
        libc.mallopt(-3, 256 << 20)  # M_MMAP_THRESHOLD: blocks up to 256 MB from the heap
        libc.mallopt(-1, 1 << 30)  # M_TRIM_THRESHOLD: don't give the heap's top back
    except (OSError, AttributeError):
        pass  # no mallopt: only slower


def _detect_images(detector: _Redetector, images) -> tuple[np.ndarray, np.ndarray, list]:
    """(camera (n,), frame index (n,), [(uv, radius, score)] * n) of ``images`` in order."""
    cameras, indices, found = [], [], []
    for image in images:
        cameras.append(image.camera)
        indices.append(image.frame_index)
        found.append(detector(image.data))
    return np.array(cameras, dtype=np.int64), np.array(indices, dtype=np.int64), found


def _rows(detected: tuple[np.ndarray, np.ndarray, list], row_of: dict) -> tuple[list, list]:
    """The frame rows of detected images and their candidates; an image without a frame
    record is dropped (nothing to attach it to)."""
    rows, results = [], []
    for camera, index, found in zip(*detected, strict=True):
        row = row_of.get((int(camera), int(index)))
        if row is not None:
            rows.append(row)
            results.append(found)
    return rows, results


class _HalfSizeDetector(BallDetector):
    """:class:`BallDetector` for a frame decoded at half its width and height (``fast``
    of :class:`_Redetector`): the coarse pass screens every half-size pixel (``downscale =
    1``: balls of radius >= 1.5 full-size px still leave a pixel), and each region of the
    fine pass is brought back to full size before it is thresholded, by bilinear
    interpolation on the half-size pixels' centres (half-size pixel i covers full-size
    pixels 2i and 2i + 1: its centre is at 2i + 1/2), so the candidates (centroid, area,
    roundness, score) are in full-size pixels and the mask's edge falls between the
    half-size pixels, as the full-size frame's does: centroids about 0.25 px RMS from the
    truth on 1280 x 720 frames against 0.37 when thresholded at half size (the exact
    re-detection: 0.17)."""

    #: half-size pixel (x, y) -> full-size pixel: (2 x + 1/2, 2 y + 1/2)
    _UP = np.array([[2.0, 0.0, 0.5], [0.0, 2.0, 0.5]])

    def __init__(self, hsv: HsvRange, max_candidates: int, compiled: bool) -> None:
        super().__init__(hsv, max_candidates, downscale=1, compiled=compiled)

    def _fine(self, frame_bgr: np.ndarray, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        import cv2

        roi = cv2.warpAffine(frame_bgr[y0:y1, x0:x1], self._UP, (2 * (x1 - x0), 2 * (y1 - y0)),
                             flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return self._components(roi, 2 * x0, 2 * y0)


class _Redetector:
    """Decodes a stored JPEG frame and detects the ball in it: ``(uv (k, 2), radius (k,),
    score (k,))`` in full-resolution pixels, or None for a frame that does not decode (no
    bytes, truncated, damaged, not a JPEG: the frame keeps its old candidates, as one
    without a stored image does).

    Exact (default): the whole frame decoded by ``cv2.imdecode`` and given to
    :class:`BallDetector`: the candidates of the frame the recorder saw; with ``compiled``,
    the same candidates from the blocks that may hold the ball's colour only
    (:class:`recorders._jpeg.ScreenedDecoder`; a frame it does not take is decoded whole).

    ``fast``: the frame decoded at half its width and height by libjpeg's DCT scaling
    (``cv2.IMREAD_REDUCED_COLOR_2``: the 4 x 4 inverse DCT of each block's lowest
    frequencies, no full-size image made; the entropy decoding of every coefficient, most
    of a decode's cost, stays) and detected by :class:`_HalfSizeDetector`: 10-20 % less
    CPU per 1280 x 720 frame (1.11-1.24x paired, ``benchmarks/bench_redetect.py``); not
    the exact candidates (``bench_redetect.py --accuracy``, five synthetic sessions of two
    rigs, ball sizes and motion blur: centroids 0.14-0.27 px RMS from the exact ones, no
    bias; 0 to 0.09 px RMS further from the truth; radii 0.1-0.3 px smaller; one frame of
    1,125 had one candidate fewer).
    """

    def __init__(self, hsv: HsvRange, max_candidates: int, compiled: bool,
                 fast: bool = False) -> None:
        import cv2

        self.detector = (_HalfSizeDetector(hsv, max_candidates, compiled) if fast else
                         BallDetector(hsv, max_candidates, compiled=compiled))
        self.flag = cv2.IMREAD_REDUCED_COLOR_2 if fast else cv2.IMREAD_COLOR
        self.screened = None
        if compiled and not fast:
            from ._jpeg import ScreenedDecoder

            self.screened = ScreenedDecoder(self.detector)

    def __call__(self, blob: bytes | memoryview
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        import cv2

        if len(blob) == 0:
            return None  # (cv2.imdecode raises on no bytes)
        if self.screened is not None:
            found = self.screened.detect(blob)
            if found is not None:
                return found.uv, found.radius, found.score
        try:
            frame = cv2.imdecode(np.frombuffer(blob, dtype=np.uint8), self.flag)
        except cv2.error:
            frame = None
        if frame is None:
            return None  # undecodable (truncated, damaged, not a JPEG): as if not stored
        found = self.detector.detect(frame)
        return found.uv, found.radius, found.score
