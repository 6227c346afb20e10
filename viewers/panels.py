"""Panels that explain a session at a glance: the ball's zoomed crop beside each camera's
frame, and the summary text (each camera's estimated timing, each method's accuracy).

Entity paths::

    crops/<cam>              EncodedImage (JPEG), a CROP_PX x CROP_PX cut of the frame
                             centred on the frame's detection (the latest one before it when
                             the frame has none); shown large in its own 2D view
    crops/<cam>/detection    a box around the frame's detection inside the crop, Boxes2D
                             (none when the crop follows an earlier frame's detection)
    summary                  TextDocument (markdown): accuracy, colours, camera clocks
"""

from __future__ import annotations

import contextlib

import cv2
import numpy as np
import rerun as rr

from pslog.errors import InputError
from pslog.evaluation import NOT_SCORED_TEXT, evaluate, unscored_counts
from pslog.log import Image

from . import _columns as C
from .data import ViewData

#: Side of a crop in source pixels: beside a 640 px frame in a view half as wide, about
#: 6x the frame's scale, so a ball a few pixels wide shows as a disc with its surroundings.
CROP_PX = 56
#: Half side of the box drawn around the detection in the crop, pixels: around the ball,
#: not over it.
_BOX_HALF_PX = 7.0
#: Crops are cut from at most this many frames per camera (each needs the JPEG decoded and
#: a crop encoded, ~1.5 ms for 640 x 480): beyond, from every k-th frame, so a long
#: session's view is not held up by it (6000 per camera: about 9 s per camera at most).
MAX_CROPS_PER_CAMERA = 6000
_JPEG_QUALITY = 90


def crop_path(camera: str) -> str:
    return f"crops/{camera}"


class CropLogger:
    """Cuts the crop around the ball out of each recorded frame given to :meth:`add` and
    sends them in batches (:meth:`flush`).

    Parameters
    ----------
    rec : the recording stream
    data : the view's data (its observations give each frame's detection, OpenCV pixels)
    clock : the recording's time columns
    n_images : frames per camera about to be given (to thin beyond MAX_CROPS_PER_CAMERA)
    """

    def __init__(self, rec, data: ViewData, clock: C.Clock, n_images: int) -> None:
        self.rec, self.clock = rec, clock
        self.names = data.session.rig.names
        obs = data.observations
        self._uv: dict[tuple[int, int], np.ndarray] = {
            (c, f): uv for c, f, uv in zip(obs.camera.tolist(), obs.frame_index.tolist(),
                                           obs.uv, strict=True)}
        self._last: dict[int, np.ndarray] = {}
        self.every = max(1, -(-int(n_images) // MAX_CROPS_PER_CAMERA))
        self._pending: dict[int, list[tuple[int, int, bytes, np.ndarray, bool]]] = {}
        for name in self.names:
            rec.log(f"{crop_path(name)}/detection", rr.Boxes2D.from_fields(
                colors=[(255, 255, 255)], radii=[-1.0]), static=True)

    def add(self, image: Image) -> None:
        """Crop ``image`` around its frame's detection (or the camera's latest one)."""
        uv = self._uv.get((image.camera, image.frame_index))
        detected = uv is not None
        if uv is None:
            uv = self._last.get(image.camera)
        else:
            self._last[image.camera] = uv
        if uv is None or image.frame_index % self.every:
            return
        frame = None
        if len(image.data):  # (OpenCV raises on no bytes)
            with contextlib.suppress(cv2.error):
                frame = cv2.imdecode(np.frombuffer(image.data, np.uint8), cv2.IMREAD_COLOR)
        if frame is None:
            return  # undecodable (empty, truncated, damaged): as if not stored
        crop, inside = cut(frame, uv, CROP_PX)
        ok, jpeg = cv2.imencode(".jpg", crop, [cv2.IMWRITE_JPEG_QUALITY, _JPEG_QUALITY])
        if ok:
            self._pending.setdefault(image.camera, []).append(
                (image.time_ns, image.frame_index, jpeg.tobytes(), inside, detected))

    def flush(self) -> int:
        """Send the pending crops; returns how many."""
        n = 0
        for cam, items in self._pending.items():
            t = np.array([i[0] for i in items], dtype=np.int64)
            f = np.array([i[1] for i in items], dtype=np.int64)
            path = crop_path(self.names[cam])
            n += C.send(self.rec, path, self.clock, t, f, rr.EncodedImage.columns(
                blob=[i[2] for i in items], media_type=["image/jpeg"] * len(items)))
            # a box only where the frame has its own detection (an empty row clears it)
            boxed = np.array([i[4] for i in items], dtype=bool)
            centers = C.image_space(np.array([i[3] for i in items if i[4]]).reshape(-1, 2))
            C.send(self.rec, f"{path}/detection", self.clock, t, f, rr.Boxes2D.columns(
                centers=centers, half_sizes=np.full_like(centers, _BOX_HALF_PX))
                .partition(boxed.astype(np.int64)))
        self._pending.clear()
        return n


def cut(frame: np.ndarray, uv: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """A ``size`` x ``size`` cut of ``frame`` (h, w, 3) centred on the pixel ``uv`` (2,)
    (OpenCV pixels), padded with black where it leaves the frame.

    Returns the crop (size, size, 3) uint8 and ``uv`` in the crop's pixels (2,) float64.
    """
    half = size // 2
    u0 = int(np.floor(uv[0] + 0.5)) - half
    v0 = int(np.floor(uv[1] + 0.5)) - half
    h, w = frame.shape[:2]
    crop = np.zeros((size, size, frame.shape[2]), dtype=frame.dtype)
    a, b = max(u0, 0), min(u0 + size, w)
    c, d = max(v0, 0), min(v0 + size, h)
    if a < b and c < d:
        crop[c - v0:d - v0, a - u0:b - u0] = frame[c:d, a:b]
    return crop, np.array([uv[0] - u0, uv[1] - v0], dtype=np.float64)


def accuracy_text(data: ViewData) -> str:
    """Markdown: each shown method's 3D error against the session's truth (``pslog eval``'s
    statistics over the shown window), or why there is none."""
    truth = data.session.truth
    if truth is None or len(truth) == 0:
        return "**Accuracy**: no ground truth in this session."
    if not data.tracks:
        return "**Accuracy**: no track shown."
    lines = ["**Accuracy** against the ground truth (3D error, mm)", "",
             "| method | points | rate Hz | median | p95 | RMS | max |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    notes: list[str] = []
    reasons: dict[str, None] = {}
    for method, track in data.tracks.items():
        track = track.select(data.in_window(track.time_ns))
        # (as pslog eval: the points the truth cannot score named, so the counts add up)
        unscored = unscored_counts(track, truth)
        if unscored:
            notes.append(f"{method} " + ", ".join(f"{r} {n}" for r, n in unscored.items())
                         + f" of {len(track)}")
            reasons.update(dict.fromkeys(unscored))
        try:
            a = evaluate(track, truth)
        except InputError:
            lines.append(f"| {method} | 0 | | | | | |")
            continue
        lines.append(f"| {method} | {a.n_points} | {a.rate_hz:.1f} | {a.median_mm:.1f} | "
                     f"{a.p95_mm:.1f} | {a.rms_mm:.1f} | {a.max_mm:.1f} |")
    # the points each method made but left out (invalid or untrustworthy: e.g. doubt, the
    # gate's choice in doubt, the start's unmoved one among them), over the whole session,
    # as pslog fuse says and pslog eval lists them
    left = [f"{m} " + ", ".join(f"{r} {n}" for r, n in sorted(t.dropped.items()) if n)
            for m, t in data.tracks.items() if any(t.dropped.values())]
    if left:
        lines += ["", "left out over the whole session (as `pslog fuse` and `pslog eval` "
                  "count them; `pslog eval` says why): " + "; ".join(left)]
    if notes:
        lines += ["", "points: those scored; not scored (as `pslog eval` counts them): "
                  + "; ".join(notes) + " (" + "; ".join(f"{r}: {NOT_SCORED_TEXT[r]}"
                                                        for r in reasons) + ")"]
    return "\n".join(lines)


def summary_text(data: ViewData, timing: str, legend: str = "") -> str:
    """The summary panel (markdown): the accuracy, the colours (``legend``), then the camera
    clocks (``timing``)."""
    return "\n\n".join(p for p in (accuracy_text(data), legend, timing) if p)


def log_summary(rec, data: ViewData, timing: str, legend: str = "") -> None:
    rec.log("summary", rr.TextDocument(summary_text(data, timing, legend),
                                       media_type="text/markdown"), static=True)
