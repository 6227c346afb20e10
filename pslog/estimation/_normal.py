"""Banded normal equations of least-squares problems whose residual rows each touch 12
consecutive unknowns (4 consecutive control points × 3 coordinates), and the band of the
inverse (the marginal covariances) of their information matrix."""

from __future__ import annotations

import numpy as np

from ..errors import FusionError

WIDTH = 12  # unknowns a row touches: 4 control points x 3 coordinates
_U = WIDTH - 1  # super-diagonals of the information matrix


def accumulate(start: np.ndarray, E: np.ndarray, b: np.ndarray, w: np.ndarray, n: int,
               ab: np.ndarray | None = None, rhs: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Add ``Σ w (E x[start:start+12] - b)²`` to normal equations ``A x = rhs``.

    Parameters
    ----------
    start : (m,) int64, first unknown of each row
    E : (m, 12) float64, the row's coefficients on ``x[start:start+12]``
    b : (m,) float64, the row's target
    w : (m,) float64, the row's weight
    n : int, number of unknowns
    ab, rhs : normal equations to add to (upper banded storage ``ab[11 + i - j, j] = A[i, j]``,
        shape (12, n); and (n,)), or None for new ones

    Returns
    -------
    ab, rhs
    """
    ab = np.zeros((WIDTH, n)) if ab is None else ab
    rhs = np.zeros(n) if rhs is None else rhs
    wE = w[:, None] * E
    for d in range(WIDTH):  # one bincount per diagonal
        cols = start[:, None] + np.arange(d, WIDTH)
        ab[_U - d] += np.bincount(cols.ravel(), (wE[:, :WIDTH - d] * E[:, d:]).ravel(),
                                  minlength=n)
    cols = start[:, None] + np.arange(WIDTH)
    rhs += np.bincount(cols.ravel(), (wE * b[:, None]).ravel(), minlength=n)
    return ab, rhs


_UPPER9 = np.array([0, 1, 2, 4, 5, 8])  # the upper triangle of a flattened 3 x 3


def accumulate_points(first: np.ndarray, N: np.ndarray, M: np.ndarray, v: np.ndarray, m: int,
                      ab: np.ndarray | None = None, rhs: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Add the terms of points ``p_i = Σ_a N[i, a] c[first_i + a]`` to normal equations.

    Each term is a quadratic form ``p_iᵀ M_i p_i - 2 v_iᵀ p_i`` of a point on the spline
    (a detection: ``M = w JᵀJ``, ``v = w Jᵀ z``; the prior: ``M = w I``, ``v = w g``); its
    contribution to the normal matrix is the 12 x 12 block ``(N_i N_iᵀ) ⊗ M_i`` at control
    points ``first_i .. first_i + 3``, and ``N_i ⊗ v_i`` to the right-hand side — the same
    sums :func:`accumulate` forms row by row (:class:`Points` does it).

    Parameters
    ----------
    first : (r,) int64, first control point of each term
    N : (r, 4) float64, basis values
    M : (r, 3, 3) float64, symmetric
    v : (r, 3) float64
    m : int, number of control points (``3m`` unknowns)
    ab, rhs : as :func:`accumulate`

    Returns
    -------
    ab, rhs
    """
    return Points(first, N, m).normal(M, v, ab, rhs)


class Points:
    """Points ``p_i = Σ_a N[i, a] c[first_i + a]`` on a spline of ``m`` control points: their
    positions, the normal equations of quadratic forms of them, and their marginal
    covariances, each one compiled pass over the points
    (:mod:`pslog.estimation._kernels`: the sums a basis matrix ``B`` (r x m, ``p = B c``) and
    a matrix ``G`` (4(m+3) x r, row ``4p + k`` holding ``N_ia N_i(a+k)`` for every term with
    ``first_i + a = p``) form in sparse products, added in the same order).

    Parameters
    ----------
    first : (r,) int64; N : (r, 4) float64; m : int
    """

    def __init__(self, first: np.ndarray, N: np.ndarray, m: int):
        self.first = np.ascontiguousarray(first, dtype=np.int64)
        self.N = np.ascontiguousarray(N, dtype=np.float64)
        self.m, self.r = m, len(self.first)

    def positions(self, control: np.ndarray) -> np.ndarray:
        """``Σ_a N_a c[first + a]`` (r, 3) for control points (m, 3)."""
        from ._kernels import points_positions

        return points_positions(self.first, self.N,
                                np.ascontiguousarray(control, dtype=np.float64))

    def marginal(self, band: np.ndarray) -> np.ndarray:
        """:func:`marginal` at the points: ``Σ_ab N_a N_b Σ_{first+a, first+b}`` (r, 3, 3)
        from the covariance band (m, 4, 3, 3) (the off-diagonal blocks with their
        transposes: each pair (a, b), a < b, stands for both orders)."""
        from ._kernels import points_marginal

        return points_marginal(self.first, self.N, np.ascontiguousarray(band))

    def normal(self, M: np.ndarray, v: np.ndarray, ab: np.ndarray | None = None,
               rhs: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Add ``Σ_i p_iᵀ M_i p_i - 2 v_iᵀ p_i`` (M (r, 3, 3) symmetric, or its upper triangle
        (r, 6) in the order 00, 01, 02, 11, 12, 22; v (r, 3)) to normal equations (as
        :func:`accumulate`)."""
        from ._kernels import points_normal

        m, r = self.m, self.r
        n = 3 * m
        ab = np.zeros((WIDTH, n)) if ab is None else ab
        rhs = np.zeros(n) if rhs is None else rhs
        if r == 0:
            return ab, rhs
        # the upper triangle (r, 6): given, or taken from the full matrices
        upper = M if M.ndim == 2 else np.take(M.reshape(r, 9), _UPPER9, axis=1)
        points_normal(self.first, self.N, np.ascontiguousarray(upper, dtype=np.float64),
                      np.ascontiguousarray(v, dtype=np.float64), m, ab, rhs)
        return ab, rhs

    def normal_onto(self, M: np.ndarray, v: np.ndarray, base_ab: np.ndarray,
                    base_rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`normal` added to normal equations ``base_ab``, ``base_rhs`` (left as they
        are: e.g. the prior's) into new arrays, in one pass (the values ``normal(M, v,
        base_ab.copy(), base_rhs.copy())`` gives, without the copy:
        :func:`pslog.estimation._kernels.points_normal_onto`)."""
        from ._kernels import points_normal_onto

        upper = M if M.ndim == 2 else np.take(M.reshape(self.r, 9), _UPPER9, axis=1)
        return points_normal_onto(self.first, self.N,
                                  np.ascontiguousarray(upper, dtype=np.float64),
                                  np.ascontiguousarray(v, dtype=np.float64), self.m,
                                  np.ascontiguousarray(base_ab, dtype=np.float64),
                                  np.ascontiguousarray(base_rhs, dtype=np.float64))


def factor(ab: np.ndarray, rebuild=None, loads: list[float] | None = None) -> np.ndarray:
    """Upper banded Cholesky factor ``U`` (``A = Uᵀ U``) of an information matrix (LAPACK's
    ``dpbtrf`` step for step, the same bits as scipy's ``cholesky_banded``:
    :func:`pslog.estimation._kernels.band_cholesky`); a :class:`FusionError` if it is not
    positive definite (a trajectory the detections and the motion prior leave undetermined).

    ``rebuild``: None, a new array (``ab`` is left as it is); or a function returning ``ab``
    anew (the same values), and ``ab`` (C-contiguous float64) is factored in place — no copy
    of a 90-minute session's 47 MB band at every Gauss–Newton step — and only a pivot that
    is not positive (``ab`` then half factored) calls it for the original again.
    ``loads``: a list, to which the diagonal load is appended when one was needed (the
    factor is then of ``A + λ I``; :func:`pslog.estimation._hat.hat_trace` takes it out).
    """
    from ._kernels import band_cholesky

    if rebuild is not None and ab.dtype == np.float64 and ab.flags.c_contiguous:
        if band_cholesky(ab) == 0:
            return ab
        ab = rebuild()
    U = np.array(ab, dtype=np.float64, order="C")
    if band_cholesky(U) == 0:
        return U
    # a direction no detection reaches (a wild iterate put a short segment's only detection
    # behind its camera): a Levenberg-Marquardt-like load on the diagonal keeps the step
    # defined; the covariance then says that direction is unknown
    U[:] = ab
    load = 1e-9 * np.max(np.abs(ab[_U]), initial=0.0) + 1e-12
    U[_U] += load
    if band_cholesky(U) == 0:
        if loads is not None:
            loads.append(float(load))
        return U
    raise FusionError("the detections leave the trajectory undetermined "
                      "(information matrix not positive definite)")


def solve(U: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``A⁻¹ rhs`` (n,) or (n, r) from the factor of :func:`factor` (LAPACK's ``dpbtrs`` step
    for step, the same bits as scipy's ``cho_solve_banded``:
    :func:`pslog.estimation._kernels.band_solve`; (n, r) comes back in Fortran order, as
    scipy's)."""
    from ._kernels import band_solve

    U = np.ascontiguousarray(U, dtype=np.float64)
    if np.ndim(rhs) == 1:
        x = np.array(rhs, dtype=np.float64)
        band_solve(U, x.reshape(1, -1))
        return x
    xt = np.array(np.transpose(rhs), dtype=np.float64, order="C")  # a right-hand side a row
    band_solve(U, xt)
    return xt.T


def covariance_band(U: np.ndarray) -> np.ndarray:
    """The band of ``A⁻¹`` for ``A = Uᵀ U``, by control-point blocks.

    Takahashi, Fagan & Chen (1973) recurrence on the banded Cholesky factor, one unknown at a
    time from the last: with ``Σ = U⁻¹ U⁻ᵀ`` and ``k`` over the band of row ``r``,
    ``Σ_rj = -Σ_k U_rk Σ_kj / U_rr`` (``j > r``) and ``Σ_rr = 1/U_rr² - Σ_k U_rk Σ_kr / U_rr``.
    Only entries inside the band are ever needed, so the cost is linear in the number of
    unknowns: a compiled loop (:func:`pslog.estimation._kernels.takahashi_band`: the
    recurrence of :func:`pslog.estimation._kernels.takahashi_rows` on a ring of 12 rows,
    each control point's blocks read out as its rows are done — the same bits, without the
    (n + 12, 12) rows and (n, 11) copy of ``U`` a 90-minute session's fit allocated twice,
    47 and 43 MB faulted in page by page). (The same recurrence grouped by 3 x 3 blocks is
    algebraically identical but numerically unstable on these spline problems: errors grew
    ~6x per control point.)

    Returns
    -------
    band : (m, 4, 3, 3), ``band[i, k] = Σ_{i, i+k}`` (zero beyond the last control point)
    """
    from ._kernels import takahashi_band

    if U.ndim != 2 or U.shape[0] != WIDTH or U.shape[1] % 3:
        raise ValueError(f"U must be (12, 3m), got {U.shape}")
    return takahashi_band(np.ascontiguousarray(U, dtype=np.float64), U.shape[1] // 3)


def covariance_band_rows(U: np.ndarray) -> np.ndarray:
    """:func:`covariance_band` through the whole rows array (:func:`pslog.estimation.
    _kernels.takahashi_rows`, then :func:`_band_from_rows`): the reference the tests
    compare the one-pass kernel with."""
    from ._kernels import takahashi_rows

    n = U.shape[1]
    right = np.zeros((n, _U))  # row r of U: columns r+1..r+11 (zero beyond n)
    for d in range(1, WIDTH):
        right[: n - d, d - 1] = U[_U - d, d:]
    rows = takahashi_rows(np.ascontiguousarray(U[_U], dtype=np.float64), right)
    return _band_from_rows(rows, n // 3)


def covariance_band_sequential(U: np.ndarray) -> np.ndarray:
    """:func:`covariance_band` one unknown at a time (the reference the tests compare with)."""
    n = U.shape[1]
    m = n // 3
    # upper rows of U: row r, columns r+1..r+11 (zero beyond n)
    diag = U[_U]
    right = np.zeros((n, _U))
    for d in range(1, WIDTH):
        right[: n - d, d - 1] = U[_U - d, d:]
    rows = np.zeros((n + WIDTH, WIDTH))  # rows[r, j] = Σ_{r, r+j}
    window = np.zeros((WIDTH, WIDTH))  # Σ of unknowns r..r+11
    for r in range(n - 1, -1, -1):
        s_next = window[:_U, :_U]
        row = -(right[r] @ s_next) / diag[r]
        new = np.empty((WIDTH, WIDTH))
        new[0, 0] = 1 / diag[r] ** 2 - (right[r] @ row) / diag[r]
        new[0, 1:] = row
        new[1:, 0] = row
        new[1:, 1:] = s_next
        window = new
        rows[r] = new[0]
    return _band_from_rows(rows, m)


def _band_from_rows(rows: np.ndarray, m: int) -> np.ndarray:
    """The (m, 4, 3, 3) block band from ``rows[r, j] = Σ_{r, r+j}`` (n + 12, 12): block
    (i, i+k), entry (a, b) = Σ_{3i+a, 3i+3k+b} = rows[3i+a, 3k+b-a] (b >= a if k = 0)."""
    from ._kernels import band_from_rows

    # the kernel reads rows[3i+a, j] for i < m, j < 12 unchecked (numba checks no bounds)
    if rows.ndim != 2 or rows.shape[1] != 12 or rows.shape[0] < 3 * m:
        raise ValueError(f"rows must be (>= {3 * m}, 12), got {rows.shape}")
    return band_from_rows(np.ascontiguousarray(rows, dtype=np.float64), int(m))


def marginal(band: np.ndarray, first: np.ndarray, N: np.ndarray) -> np.ndarray:
    """Covariance (n, 3, 3) of ``Σ_a N[:, a] c[first + a]`` from the covariance band."""
    out = np.zeros((len(first), 3, 3))
    for a in range(4):
        for b in range(a, 4):
            block = band[first + a, b - a]  # Σ_{first+a, first+b}
            coef = (N[:, a] * N[:, b])[:, None, None]
            out += coef * block
            if b != a:
                out += coef * np.swapaxes(block, 1, 2)
    return out
