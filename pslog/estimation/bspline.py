"""Cubic B-spline bases with derivatives, for trajectories ``p(t) = Σ_k N_k(t) c_k``.

A knot vector is clamped at both ends (each end knot repeated ``DEGREE + 1`` times) and may
hold interior knots of multiplicity 3: a cubic spline is then only C⁰ there — position
continuous, velocity free to jump — which is how a bounce or a kick is represented.

Every point ``t`` lies in one non-empty knot span ``[τ_j, τ_{j+1})`` and only the
``DEGREE + 1`` consecutive functions ``N_{j-3} … N_j`` are non-zero there, so every residual
of a trajectory touches 4 consecutive control points: the normal equations are banded.
"""

from __future__ import annotations

import numpy as np

DEGREE = 3


def clamped_knots(breaks: np.ndarray, multiplicity: np.ndarray | None = None) -> np.ndarray:
    """Knot vector of a clamped cubic spline with the given strictly increasing breakpoints.

    Parameters
    ----------
    breaks : (m,) float64, seconds, ``m >= 2``; the first and last are the spline's ends
    multiplicity : (m - 2,) int, multiplicity of each interior breakpoint (1: C², 3: C⁰);
        default 1

    Returns
    -------
    knots : (m + 2·DEGREE + Σ(multiplicity - 1),) float64; the spline has
    ``len(knots) - DEGREE - 1`` control points
    """
    breaks = np.asarray(breaks, dtype=np.float64)
    inner = breaks[1:-1]
    mult = np.ones(len(inner), dtype=np.int64) if multiplicity is None else np.asarray(
        multiplicity, dtype=np.int64)
    return np.concatenate([np.full(DEGREE + 1, breaks[0]), np.repeat(inner, mult),
                           np.full(DEGREE + 1, breaks[-1])])


def n_control(knots: np.ndarray) -> int:
    """Number of control points of a cubic spline on ``knots``."""
    return len(knots) - DEGREE - 1


def span_index(knots: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index ``j`` of the non-empty span ``[τ_j, τ_{j+1})`` holding each ``t`` (n,); the last
    span is closed on the right. Points outside the knot range take the nearest end span."""
    j = search_right(knots, t) - 1
    return np.clip(j, DEGREE, n_control(knots) - 1)


def search_right(knots: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``np.searchsorted(knots, t, side="right")``: for many times a compiled galloping
    search from the previous answer (:func:`pslog.estimation._kernels.search_right`, the
    same integers; a fit's times come in increasing runs: ~4 against ~15 ms for 486,000
    times in 162,000 knots, session 44), numpy's binary search otherwise."""
    t = np.asarray(t)
    knots = np.asarray(knots)
    if (len(t) < 64 or t.dtype != np.float64 or knots.dtype != np.float64 or t.ndim != 1
            or knots.ndim != 1 or np.isnan(knots).any()):
        return np.searchsorted(knots, t, side="right")
    from ._kernels import search_right as kernel

    return kernel(np.ascontiguousarray(knots), np.ascontiguousarray(t))


def basis(knots: np.ndarray, t: np.ndarray, n_derivatives: int = 2
          ) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives of the non-zero cubic B-spline functions at each ``t``.

    Piegl & Tiller, *The NURBS Book* (2nd ed. 1997), algorithm A2.3 (``DersBasisFuns``),
    vectorized over points.

    Parameters
    ----------
    knots : (K,) float64, a knot vector from :func:`clamped_knots`
    t : (n,) float64, seconds
    n_derivatives : int in 0..3

    Returns
    -------
    first : (n,) int64, index of the first of the 4 non-zero functions (``j - 3``)
    values : (n, n_derivatives + 1, 4) float64; ``values[i, d, a]`` is the d-th derivative
        (per second^d) of ``N_{first[i] + a}`` at ``t[i]``
    """
    t = np.asarray(t, dtype=np.float64)
    j = span_index(knots, t)
    return j - DEGREE, _basis_in_span(knots, j, t, n_derivatives)


def basis_derivative(knots: np.ndarray, t: np.ndarray, derivative: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """One derivative of the non-zero cubic B-splines at each ``t`` (n,): ``values[i]`` is
    ``basis(knots, t, 3)[1][i, derivative[i]]`` (the same bits), without every derivative.

    Returns
    -------
    first : (n,) int64; values : (n, 4) float64, per second^derivative
    """
    from ._kernels import basis_derivative_in_span

    t = np.asarray(t, dtype=np.float64)
    j = span_index(knots, t)
    return j - DEGREE, basis_derivative_in_span(
        np.ascontiguousarray(knots, dtype=np.float64), np.ascontiguousarray(j, dtype=np.int64),
        t, np.ascontiguousarray(derivative, dtype=np.int64))


def basis_pieces(knots: list[np.ndarray], piece: np.ndarray, t: np.ndarray,
                 n_derivatives: int = 2, only: int | None = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`basis` of several splines at once: point ``i`` on spline ``piece[i]``.

    The knot vectors are laid end to end: a clamped vector's repeated end knots keep every
    point's recurrence inside its own vector, so one pass serves all.

    ``only``: that derivative alone, ``values`` (n, 4) (the same bits as its row of every
    derivative's, :func:`pslog.estimation._kernels.basis_derivative_in_span`).

    Returns
    -------
    first : (n,) int64, index of the first non-zero function, counted over the splines'
        control points laid end to end
    values : (n, n_derivatives + 1, 4) float64 (``only``: (n, 4))
    """
    t = np.asarray(t, dtype=np.float64)
    lengths = np.array([len(k) for k in knots])
    start = np.zeros(len(knots), dtype=np.int64)  # each vector's first knot
    np.cumsum(lengths[:-1], out=start[1:])
    offset = np.zeros(len(knots), dtype=np.int64)  # each spline's first control point
    np.cumsum(lengths[:-1] - DEGREE - 1, out=offset[1:])
    cat = np.concatenate(knots)
    lo = start[piece] + DEGREE
    hi = start[piece] + lengths[piece] - DEGREE - 2  # the last non-empty span (n_control - 1)
    # the span in the point's own vector: searchsorted on it alone (the vectors need not be
    # sorted end to end), the points grouped by piece (they usually are already)
    j = np.empty(len(t), dtype=np.int64)
    order = None if np.all(piece[1:] >= piece[:-1]) else np.argsort(piece, kind="stable")
    grouped = piece if order is None else piece[order]
    bounds = np.searchsorted(grouped, np.arange(len(knots) + 1))
    for p in np.flatnonzero(bounds[1:] > bounds[:-1]):
        rows = slice(bounds[p], bounds[p + 1]) if order is None else order[
            bounds[p]:bounds[p + 1]]
        j[rows] = search_right(knots[p], t[rows]) - 1 + start[p]
    j = np.clip(j, lo, hi)
    if only is not None:
        from ._kernels import basis_derivative_in_span

        values = basis_derivative_in_span(np.ascontiguousarray(cat, dtype=np.float64),
                                          np.ascontiguousarray(j, dtype=np.int64),
                                          np.ascontiguousarray(t),
                                          np.full(len(t), only, dtype=np.int64))
    else:
        values = _basis_in_span(cat, j, t, n_derivatives)
    return j - start[piece] - DEGREE + offset[piece], values


def _basis_in_span(knots: np.ndarray, j: np.ndarray, t: np.ndarray, n_derivatives: int
                   ) -> np.ndarray:
    """The recurrence of :func:`basis` at points ``t`` in spans ``j`` of ``knots``: the
    compiled per-point kernel :func:`pslog.estimation._kernels.basis_in_span`."""
    from ._kernels import basis_in_span

    return basis_in_span(np.ascontiguousarray(knots, dtype=np.float64),
                         np.ascontiguousarray(j, dtype=np.int64),
                         np.ascontiguousarray(t, dtype=np.float64), int(n_derivatives))


def evaluate(knots: np.ndarray, control: np.ndarray, t: np.ndarray, derivative: int = 0
             ) -> np.ndarray:
    """The spline (or its ``derivative``-th derivative) at ``t`` (n,): shape (n, 3)."""
    first, values = basis(knots, t, derivative)
    index = first[:, None] + np.arange(DEGREE + 1)
    return np.einsum("na,nad->nd", values[:, derivative, :], control[index])
