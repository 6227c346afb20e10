"""Accuracy of fused tracks against ground truth."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .errors import InputError
from .records import NS, Track, Truth


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
    instants = len(np.unique(time_ns))
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
        method=track.method, n_points=len(err), rate_hz=output_rate_hz(track.time_ns),
        mean_mm=float(err.mean()), median_mm=float(np.median(err)),
        p95_mm=float(np.percentile(err, 95)), max_mm=float(err.max()),
        rms_mm=float(np.sqrt(np.mean(err**2))),
    )


def format_accuracy_table(rows: list[Accuracy]) -> str:
    """A fixed-width table of accuracies (millimetres, hertz), one line per method."""
    header = (f"{'method':<9} {'points':>7} {'rate Hz':>8} {'mean mm':>9} {'median mm':>10} "
              f"{'p95 mm':>9} {'max mm':>9}")
    lines = [header, "-" * len(header)]
    for a in rows:
        lines.append(f"{a.method:<9} {a.n_points:>7d} {a.rate_hz:>8.1f} {a.mean_mm:>9.3f} "
                     f"{a.median_mm:>10.3f} {a.p95_mm:>9.3f} {a.max_mm:>9.3f}")
    return "\n".join(lines)
