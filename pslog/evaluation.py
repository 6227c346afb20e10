"""Accuracy of fused tracks against ground truth, and what their per-point quality says."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np

from .errors import InputError
from .records import NS, Track, Truth
from .tables import format_table


@dataclass(frozen=True)
class Accuracy:
    """Error statistics of one track, millimetres (human-facing), and its output rate.

    Attributes
    ----------
    method : str
    n_points : int, points compared (those inside the truth's time span)
    rate_hz : float, output rate: (distinct instants - 1) / (last time - first time)
    mean_mm, median_mm, p95_mm, max_mm, rms_mm : float, Euclidean 3D error, millimetres
    """

    method: str
    n_points: int
    rate_hz: float
    mean_mm: float
    median_mm: float
    p95_mm: float
    max_mm: float
    rms_mm: float

    def as_dict(self) -> dict:
        return asdict(self)


def errors_m(track: Track, truth: Truth) -> np.ndarray:
    """3D error of every point of ``track``, metres (n,); NaN outside the truth's span."""
    return np.linalg.norm(track.position_world - truth.at(track.time_ns), axis=1)


def output_rate_hz(time_ns: np.ndarray) -> float:
    """Distinct instants per second over the span of ``time_ns`` (sorted); 0 for fewer than
    two. Points at the same instant (several cameras firing together) count once."""
    time_ns = np.asarray(time_ns)
    step = np.diff(time_ns)
    # sorted (as tracks are): the distinct instants are where the time changes, no hashing
    instants = (1 + int(np.count_nonzero(step)) if len(time_ns) and np.all(step >= 0)
                else len(np.unique(time_ns)))
    if instants < 2:
        return 0.0
    return (instants - 1) / ((time_ns[-1] - time_ns[0]) / NS)


def evaluate(track: Track, truth: Truth) -> Accuracy:
    """Error statistics of ``track`` against ``truth``."""
    err = errors_m(track, truth)
    err = err[np.isfinite(err)] * 1e3
    if len(err) == 0:
        raise InputError(f"track {track.method!r} has no point inside the ground truth's span")
    return Accuracy(
        method=track.method, n_points=len(err), rate_hz=float(output_rate_hz(track.time_ns)),
        mean_mm=float(err.mean()), median_mm=float(np.median(err)),
        p95_mm=float(np.percentile(err, 95)), max_mm=float(err.max()),
        rms_mm=float(np.sqrt(np.mean(err**2))),
    )


def format_accuracy_table(rows: list[Accuracy]) -> str:
    """A table of accuracies (millimetres, hertz), one line per method."""
    return format_table(
        ("method", "points", "rate Hz", "mean mm", "median mm", "p95 mm", "max mm"),
        [(a.method, f"{a.n_points:d}", f"{a.rate_hz:.1f}", f"{a.mean_mm:.3f}",
          f"{a.median_mm:.3f}", f"{a.p95_mm:.3f}", f"{a.max_mm:.3f}") for a in rows])


#: P(χ²₃ <= 4): the share of 3-D Gaussian errors inside the covariance's 2σ ellipsoid
#: (Mahalanobis distance 2); ``erf(√2) - √(8/π) e⁻²``.
CHI2_3D_2SIGMA = 0.7385358700508894


@dataclass(frozen=True)
class QualitySummary:
    """What one track's per-point quality columns say, and whether its uncertainty is honest.

    Attributes
    ----------
    method : str
    n_points : int, points inside the truth's span
    residual_median_px, residual_p95_px : float, of each point's largest reprojection error
        of a contributing detection (``residual_max_px``; smooth: ``residual_px``), pixels;
        NaN if the track has none
    gap_max_ms : float, largest time span a point bridged (``gap_s``), milliseconds
    std_median_mm : float, median position standard deviation (``std_m``), millimetres
    within_2sigma : float, share of points whose truth lies inside the 2σ ellipsoid of their
        covariance: Mahalanobis ``d² = eᵀ Σ⁻¹ e <= 4`` with the full covariance
        (``cov_*_m2``: every method but filter), or the diagonal one from ``std_x_m, std_y_m,
        std_z_m`` (filter); NaN
        without either. Honest, Gaussian errors give :data:`CHI2_3D_2SIGMA` (0.739)
    nees : float, mean ``d² / 3`` (normalised estimation error squared): 1 when the covariance
        is honest, above 1 when it is over-confident
    """

    method: str
    n_points: int
    residual_median_px: float
    residual_p95_px: float
    gap_max_ms: float
    std_median_mm: float
    within_2sigma: float
    nees: float
    expected_2sigma: float = CHI2_3D_2SIGMA

    def as_dict(self) -> dict:
        return asdict(self)


def covariances(track: Track) -> np.ndarray | None:
    """(n, 3, 3) position covariances of ``track`` from its quality columns (full, or diagonal
    from per-axis standard deviations), m²; None if it has neither."""
    q = track.quality
    n = len(track)
    if all(f"cov_{a}_m2" in q for a in ("xx", "yy", "zz", "xy", "xz", "yz")):
        cov = np.empty((n, 3, 3))
        for name, (i, j) in (("xx", (0, 0)), ("yy", (1, 1)), ("zz", (2, 2)), ("xy", (0, 1)),
                             ("xz", (0, 2)), ("yz", (1, 2))):
            cov[:, i, j] = cov[:, j, i] = q[f"cov_{name}_m2"]
        return cov
    if all(f"std_{a}_m" in q for a in "xyz"):
        cov = np.zeros((n, 3, 3))
        for i, a in enumerate("xyz"):
            cov[:, i, i] = q[f"std_{a}_m"] ** 2
        return cov
    return None


def mahalanobis_sq(track: Track, truth: Truth) -> np.ndarray | None:
    """``eᵀ Σ⁻¹ e`` of every point (n,) (NaN outside the truth's span; inf where the
    covariance is singular or missing); None if the track has no covariance."""
    cov = covariances(track)
    if cov is None:
        return None
    err = track.position_world - truth.at(track.time_ns)
    out = np.full(len(track), np.inf)
    ok = np.all(np.isfinite(cov), axis=(1, 2)) & np.all(np.isfinite(err), axis=1)
    if np.any(ok):
        det = np.linalg.det(cov[ok])
        good = det > 0
        rows = np.flatnonzero(ok)[good]
        sol = np.linalg.solve(cov[rows], err[rows][..., None])[..., 0]
        out[rows] = np.einsum("ni,ni->n", err[rows], sol)
    out[~np.all(np.isfinite(err), axis=1)] = np.nan
    return out


def summarise_quality(track: Track, truth: Truth | None) -> QualitySummary:
    """:class:`QualitySummary` of ``track``'s points inside the truth's span; without truth
    (a real session) of every point, ``within_2sigma`` and ``nees`` NaN."""
    inside = (np.ones(len(track), dtype=bool) if truth is None
              else np.isfinite(errors_m(track, truth)))
    q = {k: v[inside] for k, v in track.quality.items()}
    nan = float("nan")

    def stat(values, fn):
        values = values[np.isfinite(values)] if values is not None else np.zeros(0)
        return float(fn(values)) if len(values) else nan

    residual = q.get("residual_max_px", q.get("residual_px"))
    d2 = None if truth is None else mahalanobis_sq(track, truth)
    if d2 is not None:
        d2 = d2[inside]
    return QualitySummary(
        method=track.method, n_points=int(inside.sum()),
        residual_median_px=stat(residual, np.median),
        residual_p95_px=stat(residual, lambda v: np.percentile(v, 95)),
        gap_max_ms=stat(q.get("gap_s"), np.max) * 1e3,
        std_median_mm=stat(q.get("std_m"), np.median) * 1e3,
        within_2sigma=float(np.mean(d2 <= 4.0)) if d2 is not None and len(d2) else nan,
        nees=float(np.mean(d2) / 3) if d2 is not None and len(d2) else nan,
    )


def format_quality_table(rows: list[QualitySummary]) -> str:
    """A table of quality summaries, one line per method, and what its columns mean."""
    return format_table(
        ("method", "resid px", "p95 px", "gap ms", "std mm", "in 2σ", "NEES"),
        [(r.method, _cell(r.residual_median_px, ".3f"), _cell(r.residual_p95_px, ".3f"),
          _cell(r.gap_max_ms, ".1f"), _cell(r.std_median_mm, ".3f"),
          _cell(r.within_2sigma * 100, ".1f", "%"), _cell(r.nees, ".2f")) for r in rows],
        note=f"resid: median of each point's largest reprojection error; in 2σ: share of "
             f"truth inside the covariance's 2σ ellipsoid ({CHI2_3D_2SIGMA * 100:.1f}% if "
             f"honest); NEES: mean d²/3 (1 if honest); -: no figure (in 2σ and NEES need "
             f"ground truth); σ 0: a zero covariance (NEES unbounded)")


def _cell(value: float, spec: str, unit: str = "") -> str:
    """A table cell: ``-`` for NaN (no figure, e.g. no truth), ``σ 0`` for an infinite
    value (a zero covariance), else the number."""
    if value != value:
        return "-"
    if np.isinf(value):
        return "σ 0"
    return f"{value:{spec}}{unit}"


@dataclass(frozen=True)
class RejectionCounts:
    """What the gating stage rejected for one track, against the truth's ball labels.

    Attributes
    ----------
    method : str
    candidates : int, candidates in the session
    rejected : int, candidates rejected (:class:`pslog.fusion.gating.Rejections`)
    rejected_detections : int, frames with candidates of which none was kept
    by_reason : dict reason -> rejected candidates
    correct : int or None, rejected candidates that are not the ball (None: no labels)
    wrong : int or None, rejected candidates that are the ball
    kept_false : int or None, kept candidates that are not the ball
    false_candidates : int or None, candidates that are not the ball
    """

    method: str
    candidates: int
    rejected: int
    rejected_detections: int
    by_reason: dict
    correct: int | None = None
    wrong: int | None = None
    kept_false: int | None = None
    false_candidates: int | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def _keys(camera, frame_index, uv) -> np.ndarray:
    """One fixed-width byte key per candidate (camera, frame index, pixel), comparable by
    value: -0.0 is made 0.0 (equal as numbers); a NaN pixel gets a key of its own (a NaN
    equals nothing)."""
    n = len(camera)
    table = np.zeros(n, dtype=[("camera", "<i8"), ("frame", "<i8"), ("u", "<f8"), ("v", "<f8"),
                               ("nan", "<i8")])
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    table["camera"] = np.asarray(camera)
    table["frame"] = np.asarray(frame_index)
    table["u"] = uv[:, 0] + 0.0
    table["v"] = uv[:, 1] + 0.0
    nan = np.isnan(uv).any(axis=1)
    table["nan"][nan] = -1 - np.arange(np.count_nonzero(nan))  # unique: never matched
    return table.view(f"V{table.dtype.itemsize}")


def _member(keys: np.ndarray, of: np.ndarray) -> np.ndarray:
    """Whether each of ``keys`` is among ``of`` (both from :func:`_keys`): sorted search, linear
    in the candidates (a Python set of tuples cost seconds on a match)."""
    if len(of) == 0 or len(keys) == 0:
        return np.zeros(len(keys), dtype=bool)
    of = np.sort(of)
    at = np.minimum(np.searchsorted(of, keys), len(of) - 1)
    found = of[at] == keys
    # a NaN key (last field non-zero) matches nothing, not even itself
    nan = keys.view(np.uint8).reshape(len(keys), -1)[:, -8:].any(axis=1)
    return found & ~nan


def rejection_counts(method: str, rejections, detections, ball=None) -> RejectionCounts:
    """Count ``rejections`` (:class:`pslog.fusion.gating.Rejections`) of ``detections``'
    candidates and, with ``ball`` (the session's ball labels, a Detections of the ball's
    candidates), how many were right. Candidates are matched by camera, frame index and
    pixel."""
    cand = _keys(detections.frame_camera[detections.cand_frame],
                 detections.frame_index[detections.cand_frame], detections.cand_uv)
    rejected = _member(cand, _keys(rejections.camera, rejections.frame_index, rejections.uv))
    had = detections.candidates_per_frame() > 0
    kept_frame = np.zeros(detections.n_frames, dtype=bool)
    kept_frame[detections.cand_frame[~rejected]] = True
    counts = RejectionCounts(method, detections.n_candidates, len(rejections),
                             int(np.count_nonzero(had & ~kept_frame)), rejections.counts())
    if ball is None:
        return counts
    is_ball = _member(cand, _keys(ball.frame_camera[ball.cand_frame],
                                  ball.frame_index[ball.cand_frame], ball.cand_uv))
    return RejectionCounts(
        method, counts.candidates, counts.rejected, counts.rejected_detections,
        counts.by_reason, correct=int(np.count_nonzero(rejected & ~is_ball)),
        wrong=int(np.count_nonzero(rejected & is_ball)),
        kept_false=int(np.count_nonzero(~rejected & ~is_ball)),
        false_candidates=int(np.count_nonzero(~is_ball)))


def format_rejection_table(rows: list[RejectionCounts]) -> str:
    """A table of the gating's rejections, one line per method; the last three
    columns only when the session labels the ball's candidates."""
    labelled = any(r.correct is not None for r in rows)
    header = ["method", "candidates", "rejected", "detections"]
    if labelled:
        header += ["correct", "ball lost", "false kept"]
    header.append("by reason")
    cells = []
    for r in rows:
        row = [r.method, f"{r.candidates:d}", f"{r.rejected:d}", f"{r.rejected_detections:d}"]
        if labelled:
            row += ([f"{r.correct:d}", f"{r.wrong:d}", f"{r.kept_false:d}"]
                    if r.correct is not None else ["-", "-", "-"])
        row.append(", ".join(f"{k} {v}" for k, v in r.by_reason.items() if v))
        cells.append(row)
    return format_table(header, cells, left={0, len(header) - 1})


#: Where ``pslog fuse`` keeps the points each method left out, by reason (``Track.dropped``):
#: the metadata key of each track's channel; files fused before kept every method's counts
#: under this key of the session metadata (:attr:`pslog.log.Session.left_out` reads both).
LEFT_OUT_KEY = "left_out_points"


def left_out_counts(metadata: Mapping[str, str]) -> dict[str, dict[str, int]]:
    """``{method: {reason: count}}`` of the points the methods of a session fused before the
    counts went with each track left out (invalid or untrustworthy: behind a camera,
    outside its view, near-parallel rays, an underdetermined end, unconfirmed after a
    jump, ...), from its session ``metadata``; empty when not recorded or unreadable. A
    session read with :func:`pslog.log.read_session` has them in ``Session.left_out``,
    whichever way the file holds them."""
    from .log.reader import old_left_out_counts

    return old_left_out_counts(metadata)
