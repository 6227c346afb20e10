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
    return _norms(_offsets(track, truth))


def _offsets(track: Track, truth: Truth) -> np.ndarray:
    """Each point's position minus the truth at its time (n, 3), metres; NaN outside the
    truth's span. Made once per track by :func:`assess` (accuracy and quality share it)."""
    return track.position_world - truth.at(track.time_ns)


def _norms(offsets: np.ndarray) -> np.ndarray:
    return np.linalg.norm(offsets, axis=1)


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
    return _accuracy(track, errors_m(track, truth))


def _accuracy(track: Track, err: np.ndarray) -> Accuracy:
    """:func:`evaluate` of ``track`` given its points' errors (:func:`errors_m`)."""
    err = err[np.isfinite(err)] * 1e3
    if len(err) == 0:
        # (NaN errors: outside the truth's span, or in its gaps: "no point inside the span"
        # was said of a track whose every point lay inside it, in gaps)
        raise InputError(f"track {track.method!r} has no point the ground truth scores (none "
                         f"inside its span, or each in a gap of it: rows without a position)")
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


#: the upper triangle of a 3 x 3 covariance, as :func:`covariance_columns` gives it
_TRIANGLE = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def covariance_columns(track: Track) -> tuple[np.ndarray, ...] | None:
    """The position covariances of ``track`` as six (n,) columns, m²: ``xx, yy, zz, xy, xz,
    yz`` (full, ``cov_*_m2``; or diagonal from per-axis standard deviations, the others
    zero); None if it has neither."""
    q = track.quality
    if all(f"cov_{a}_m2" in q for a in ("xx", "yy", "zz", "xy", "xz", "yz")):
        return tuple(q[f"cov_{a}_m2"] for a in ("xx", "yy", "zz", "xy", "xz", "yz"))
    if all(f"std_{a}_m" in q for a in "xyz"):
        zero = np.zeros(len(track))
        return (*(q[f"std_{a}_m"] ** 2 for a in "xyz"), zero, zero, zero)
    return None


def covariances(track: Track) -> np.ndarray | None:
    """(n, 3, 3) position covariances of ``track`` from its quality columns (full, or diagonal
    from per-axis standard deviations), m²; None if it has neither."""
    columns = covariance_columns(track)
    return None if columns is None else np.ascontiguousarray(_matrices(columns))


def _matrices(columns: tuple[np.ndarray, ...]) -> np.ndarray:
    """The (n, 3, 3) matrices of the six columns: a view of a (3, 3, n) array (each entry
    a contiguous row, written at memory speed; numpy's linalg reads any strides)."""
    cov = np.empty((3, 3, len(columns[0])))
    for column, (i, j) in zip(columns, _TRIANGLE, strict=True):
        cov[i, j] = cov[j, i] = column
    return cov.transpose(2, 0, 1)


def mahalanobis_sq(track: Track, truth: Truth) -> np.ndarray | None:
    """``eᵀ Σ⁻¹ e`` of every point (n,) (NaN outside the truth's span; inf where the
    covariance is singular or missing); None if the track has no covariance."""
    return _mahalanobis_sq(track, _offsets(track, truth))


def _mahalanobis_sq(track: Track, err: np.ndarray) -> np.ndarray | None:
    """:func:`mahalanobis_sq` given the points' offsets from the truth (:func:`_offsets`):
    ``np.linalg.solve`` of each covariance whose determinant is positive."""
    columns = covariance_columns(track)
    if columns is None:
        return None
    out = np.full(len(track), np.inf)
    inside = np.all(np.isfinite(err), axis=1)
    ok = inside.copy()
    for column in columns:
        ok &= np.isfinite(column)
    good = ok & _positive_det(columns)
    rows = np.flatnonzero(good)
    every = len(rows) == len(track)  # (every point: no gather)
    # in blocks: the stacks of a block stay in the cache and their memory is reused, not
    # a match's hundreds of MB taken from the system and zeroed (each matrix's solve is
    # its own: the same bits in any block)
    for start in range(0, len(rows), _BLOCK):
        block = slice(start, start + _BLOCK) if every else rows[start:start + _BLOCK]
        e = err[block]
        sol = np.linalg.solve(_matrices(tuple(c[block] for c in columns)),
                              e[..., None])[..., 0]
        out[block] = np.einsum("ni,ni->n", e, sol)
    out[~inside] = np.nan
    return out


#: rows per block of :func:`_mahalanobis_sq` (its stacks: about 1.5 MB)
_BLOCK = 16384


def _positive_det(columns: tuple[np.ndarray, ...]) -> np.ndarray:
    """Whether ``np.linalg.det`` of each covariance (:func:`covariance_columns`; where all
    six are finite) is positive, its LU (which cost more than the solve it guards) made only
    where the sign is in doubt.

    With ``s`` the largest magnitude of a matrix's entries, the cofactor expansion is within
    about 1e-14 s³ of the true determinant, and LAPACK's (LU with partial pivoting, growth
    at most 4 at n = 3: a backward error of about 1e-14 s per entry, Higham, *Accuracy and
    Stability of Numerical Algorithms*, 2nd ed., sections 9.3 and 14.6) within about
    1e-13 s³: where the expansion exceeds 1e-9 s³ in magnitude, both have the true sign.
    The others (near-singular, entries of very different scales, s³ outside the normal
    range, a non-finite entry) are decided by ``np.linalg.det`` itself, as before."""
    xx, yy, zz, xy, xz, yz = columns
    with np.errstate(invalid="ignore", over="ignore", under="ignore"):
        det = xx * (yy * zz - yz * yz) - xy * (xy * zz - yz * xz) + xz * (xy * yz - yy * xz)
        scale = np.abs(xx)
        for column in columns[1:]:
            scale = np.maximum(scale, np.abs(column))
        sure = ((np.abs(det) > 1e-9 * scale * scale * scale) & (scale > 1e-90)
                & (scale < 1e90))
    positive = det > 0
    unsure = np.flatnonzero(~sure)
    if len(unsure):
        cov = _matrices(tuple(c[unsure] for c in columns))
        finite = np.all(np.isfinite(cov), axis=(1, 2))
        positive[unsure] = False
        positive[unsure[finite]] = np.linalg.det(cov[finite]) > 0
    return positive


def summarise_quality(track: Track, truth: Truth | None) -> QualitySummary:
    """:class:`QualitySummary` of ``track``'s points inside the truth's span; without truth
    (a real session) of every point, ``within_2sigma`` and ``nees`` NaN."""
    return _quality(track, None if truth is None else _offsets(track, truth))


def assess(track: Track, truth: Truth | None) -> tuple[Accuracy | None, QualitySummary]:
    """``(evaluate(track, truth), summarise_quality(track, truth))`` (the accuracy None
    without truth), the truth interpolated at the track's times once for both."""
    if truth is None:
        return None, _quality(track, None)
    offsets = _offsets(track, truth)
    err = _norms(offsets)
    return _accuracy(track, err), _quality(track, offsets, err)


def _quality(track: Track, offsets: np.ndarray | None,
             err: np.ndarray | None = None) -> QualitySummary:
    """:func:`summarise_quality` given the points' offsets from the truth (None: no truth)
    and, if made, their lengths (:func:`errors_m`)."""
    if offsets is not None and err is None:
        err = _norms(offsets)
    inside = None if err is None else np.isfinite(err)
    if inside is not None and inside.all():
        inside = None  # (every point: the columns as they are, not copies)
    nan = float("nan")

    def column(name):
        values = track.quality.get(name)
        return values if values is None or inside is None else values[inside]

    def stat(values, fn):
        values = values[np.isfinite(values)] if values is not None else np.zeros(0)
        return float(fn(values)) if len(values) else nan

    residual = column("residual_max_px" if "residual_max_px" in track.quality
                      else "residual_px")
    d2 = None if offsets is None else _mahalanobis_sq(track, offsets)
    if d2 is not None and inside is not None:
        d2 = d2[inside]
    q = {"gap_s": column("gap_s"), "std_m": column("std_m")}
    return QualitySummary(
        method=track.method, n_points=len(track) if inside is None else int(inside.sum()),
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
        note=f"resid, p95: median and 95th percentile of each point's largest reprojection "
             f"error; gap: the longest time span a point bridged; std: the median point's "
             f"position standard deviation (std_m); in 2σ: share of "
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
    if abs(value) >= 1e7:  # (a near-zero covariance's NEES: 2.6e+40, not 41 digits)
        return f"{value:.2e}{unit}"
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
    if 4 * len(of) < len(keys):
        # few to look for (a method's rejections): only the keys whose frame index (the
        # second int64 of a key) one of them has can be among them, found by an integer
        # test; the byte keys of those alone are searched
        frames = keys.view(np.int64).reshape(len(keys), -1)[:, 1]
        wanted = np.unique(of.view(np.int64).reshape(len(of), -1)[:, 1])
        maybe = np.flatnonzero(np.isin(frames, wanted))
        out = np.zeros(len(keys), dtype=bool)
        out[maybe] = _search(keys[maybe], of)
        return out
    return _search(keys, of)


def _search(keys: np.ndarray, of: np.ndarray) -> np.ndarray:
    """:func:`_member` by a sorted search of every key."""
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
    return all_rejection_counts({method: rejections}, detections, ball)[method]


def all_rejection_counts(rejections: Mapping, detections, ball=None
                         ) -> dict[str, RejectionCounts]:
    """:func:`rejection_counts` of every method's ``rejections`` (method -> Rejections) of
    one session, its candidates' keys and ball labels made once for all."""
    cand = _keys(detections.frame_camera[detections.cand_frame],
                 detections.frame_index[detections.cand_frame], detections.cand_uv)
    had = detections.candidates_per_frame() > 0
    is_ball = None if ball is None else _member(cand, _keys(
        ball.frame_camera[ball.cand_frame], ball.frame_index[ball.cand_frame], ball.cand_uv))
    out = {}
    for method, rej in rejections.items():
        rejected = _member(cand, _keys(rej.camera, rej.frame_index, rej.uv))
        kept_frame = np.zeros(detections.n_frames, dtype=bool)
        kept_frame[detections.cand_frame[~rejected]] = True
        counts = RejectionCounts(method, detections.n_candidates, len(rej),
                                 int(np.count_nonzero(had & ~kept_frame)), rej.counts())
        if is_ball is not None:
            counts = RejectionCounts(
                method, counts.candidates, counts.rejected, counts.rejected_detections,
                counts.by_reason, correct=int(np.count_nonzero(rejected & ~is_ball)),
                wrong=int(np.count_nonzero(rejected & is_ball)),
                kept_false=int(np.count_nonzero(~rejected & ~is_ball)),
                false_candidates=int(np.count_nonzero(~is_ball)))
        out[method] = counts
    return out


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


#: What each reason a method leaves a point out for means (``Track.dropped``'s keys; ``pslog
#: eval`` prints the ones a session has; docs/methods.md and docs/paper.md tell each in full)
LEFT_OUT_TEXT = {
    "behind_camera": "the point lies behind a camera that made it",
    "outside_view": "outside the view of a camera the rig says saw it",
    "parallel_rays": "its rays nearly parallel: its depth undetermined",
    "residual_failed": "a detection's residual its noise cannot explain (a false one "
                       "paired with the ball)",
    "prediction_failed": "the prediction far from the newest ray (the innovation test)",
    "kink": "typeA: the motion bends between the points it extrapolates (a bounce or kick)",
    "contradicted": "typeA: another camera's detections place the ball elsewhere (--confirm-gaps "
                    "jumps, the default, and kicks: that camera's track around it, on its side "
                    "of a kick the track shows; all, on: the next camera's detection)",
    "break": "typeA (--confirm-gaps jumps, the default, or breaks): its construction spans a "
             "kick the cameras' images show (breaks: a velocity break of smooth's fit), and "
             "type A's point from the detections after it spans one too or was not made (its own "
             "tests left it out, or too few detections follow: near the session's end)",
    "unconfirmed": "not confirmed in time (typeA: no next camera's detection; filter: after "
                   "a jump or a surprise, two more updates, one from another camera)",
    "held": "filter: held for the next camera, whose detection placed a jump before it",
    "uncertain": "its std_m above the bound (filter: 25.5 mm, 5 cm at 95 %; typeA: "
                 "--type-a-max-std-mm)",
    "doubt": "rests on a candidate the gate chose in doubt: one it could not tell from "
             "another (rejected candidates beside it, another camera denying it, or, at a "
             "session's start, before its camera can judge stillness, a candidate that has "
             "not moved beside one that has, or beside another still one a second camera "
             "sees too: a static object or the ball at rest; docs/methods.md, \"A choice in "
             "doubt\", \"An unmoved choice at the start\")",
    "underdetermined_end": "smooth: an end beyond a kick that too few detections hold",
    "contradicted_run": "smooth: consecutive detections of two or more cameras that the fit "
                        "rejected: the ball was not where the fit puts it (a kick or bounce "
                        "it did not find)",
}

#: Why ``pslog eval`` could not score a point a method wrote (:func:`unscored_counts`'s
#: keys): its accuracy table counts the points it scored, these account for the rest
NOT_SCORED_TEXT = {
    "outside_truth": "outside the truth's time span: no truth to interpolate at its time "
                     "(e.g. a time 'pslog sync' has not corrected: a rolling shutter reads "
                     "the ball's row after its frame's time)",
    "truth_gap": "the truth not finite at its time (a gap in it)",
    "not_finite": "its position not finite",
}


def unscored_counts(track: Track, truth: Truth | None) -> dict[str, int]:
    """``{reason: count}`` of the points of ``track`` that cannot be scored against
    ``truth`` (:data:`NOT_SCORED_TEXT`'s reasons, only those with a count); empty without
    truth. With :func:`evaluate`'s ``n_points`` they sum to ``len(track)``.

    Parameters
    ----------
    track : Track, n points
    truth : Truth or None
    """
    if truth is None or len(track) == 0:
        return {}
    if len(truth) == 0:
        return {"outside_truth": len(track)}
    t = track.time_ns
    outside = (t < truth.time_ns[0]) | (t > truth.time_ns[-1])
    inside = ~outside
    gap = np.zeros(len(track), bool)
    gap[inside] = ~np.isfinite(truth.at(t[inside])).all(axis=1)
    bad = ~np.isfinite(track.position_world).all(axis=1) & inside & ~gap
    counts = {"outside_truth": int(outside.sum()), "truth_gap": int(gap.sum()),
              "not_finite": int(bad.sum())}
    return {k: n for k, n in counts.items() if n}


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
