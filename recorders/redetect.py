"""Offline re-detection: run the ball detector again over a session's stored frames.

The new session is a stream copy of the old one (frames, calibration, poses, truth, events,
tracks and metadata kept as stored) with every frame's detections replaced, so it fuses like
any session.

Where the time goes (1280 x 720 JPEGs of quality 90, ``benchmarks/bench_redetect.py``): decoding
a frame with ``cv2.imdecode`` costs about 3.4 ms of CPU, most of it entropy decoding
that no reduced-size decode (``IMREAD_REDUCED_COLOR_2``: 2.7 ms) avoids; detection about
0.8 ms; reading the session, handing the JPEGs to the workers and writing the new session
about 1 ms more per frame in the main process. OpenCV cannot decode only a region of a JPEG,
and the detector's fine pass needs the full-resolution pixels around the ball, so every frame
is decoded whole: the decode alone bounds two cores to about 590 frames/s.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pslog.errors import InputError
from pslog.outputs import check_output_path
from pslog.records import Detections

from .detect import BallDetector, HsvRange, _bgr_box

_BATCH = 64  # images per task when several processes decode and detect
_PARALLEL_FROM = 400  # images; below this one process is faster than starting a pool
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
    """

    output: Path
    frames: int
    images: int
    kept: int
    before: int
    after: int

    def text(self) -> str:
        line = (f"re-detected {self.images} frames: {self.before} -> {self.after} frames with "
                f"a ball candidate; written {self.output}")
        if self.kept:
            line += f"\n{self.kept} frames have no stored image and keep their old detections"
        return line


def redetect_session(src: str | Path, dst: str | Path, hsv: HsvRange | None = None, *,
                     max_candidates: int = 5, force: bool = False,
                     workers: int | None = None) -> RedetectSummary:
    """Write ``dst``: session ``src`` with detections recomputed from its stored frames.

    Parameters
    ----------
    hsv : colour range (default :class:`HsvRange`'s orange ball)
    max_candidates : K, candidates kept per frame
    force : overwrite ``dst``
    workers : processes decoding and detecting (default: all cores for large sessions)
    """
    from pslog.log import copy_session, iter_images, read_session

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
                         f"--synthetic --rig paper3 --fast -o s.mcap', or use samples/throw.mcap")
    old = session.detections
    hsv = hsv or HsvRange()
    row_of = {(int(c), int(i)): r for r, (c, i) in
              enumerate(zip(old.frame_camera, old.frame_index, strict=True))}

    from pslog import progress

    progress.update(0, total=session.n_images, unit="frames", what="detecting")
    rows, results = [], []
    for batch_rows, batch_results in _detect_all(iter_images(src), row_of, hsv,
                                                 max_candidates, workers, session.n_images):
        rows.extend(batch_rows)
        results.extend(batch_results)
        progress.update(advance=len(batch_rows))
    redone = np.zeros(old.n_frames, dtype=bool)
    redone[rows] = True

    # candidates: the new ones for re-detected frames, the old ones for the others
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
    copy_session(src, dst, detections=new, metadata={"detector_hsv": hsv.text()}, force=force)
    return RedetectSummary(dst, old.n_frames, int(redone.sum()), int((~redone).sum()),
                           int(np.count_nonzero(old.candidates_per_frame())),
                           int(np.count_nonzero(new.candidates_per_frame())))


def _detect_all(images, row_of: dict, hsv: HsvRange, max_candidates: int,
                workers: int | None, n_images: int) -> Iterator[tuple[list, list]]:
    """Yield (rows, [(uv, radius, score), ...]) batches for every stored image with a frame
    record."""
    import cv2

    # one OpenCV thread in this process too, before any worker is forked: a worker inherits
    # OpenCV's thread pool if this process had started one (a large conversion, e.g. by
    # _bgr_box), without its threads, and hangs in its first call into OpenCV
    cv2.setNumThreads(1)
    workers = workers or (os.cpu_count() or 1)
    batches = _batches(images, row_of)
    if workers <= 1 or n_images < _PARALLEL_FROM:
        detector = BallDetector(hsv, max_candidates)
        for rows, blobs in batches:
            yield rows, [_detect_blob(detector, b) for b in blobs]
        return
    _bgr_box(hsv)  # computed once here and inherited by the forked workers
    with ProcessPoolExecutor(max_workers=workers) as pool:
        pending = []
        for rows, blobs in batches:
            pending.append((rows, pool.submit(_detect_batch, blobs, hsv, max_candidates)))
            if len(pending) > 2 * workers:  # bound the memory held in flight
                r, fut = pending.pop(0)
                yield r, fut.result()
        for r, fut in pending:
            yield r, fut.result()


def _batches(images, row_of: dict) -> Iterator[tuple[list, list]]:
    rows, blobs = [], []
    for image in images:
        row = row_of.get((image.camera, image.frame_index))
        if row is None:
            continue  # an image without a frame record: nothing to attach it to
        rows.append(row)
        blobs.append(image.data)
        if len(rows) == _BATCH:
            yield rows, blobs
            rows, blobs = [], []
    if rows:
        yield rows, blobs


def _detect_batch(blobs: list[bytes], hsv: HsvRange, max_candidates: int) -> list:
    import cv2

    cv2.setNumThreads(1)
    detector = BallDetector(hsv, max_candidates)
    return [_detect_blob(detector, b) for b in blobs]


def _detect_blob(detector: BallDetector, blob: bytes) -> tuple[np.ndarray, np.ndarray,
                                                                 np.ndarray]:
    import cv2

    frame = cv2.imdecode(np.frombuffer(blob, dtype=np.uint8), cv2.IMREAD_COLOR)
    if frame is None:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)  # undecodable: no candidate
    found = detector.detect(frame)
    return found.uv, found.radius, found.score
