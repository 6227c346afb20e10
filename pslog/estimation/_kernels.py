"""The compiled per-point kernels of the trajectory estimator (:mod:`pslog._jit`).

Each kernel is the loop its numpy caller ran over arrays of points, written once per point
with the same floating-point operations in the same order, so it returns the same bits
(no fastmath: no reassociation, no fused multiply-add — but in ``trial_prior_terms``,
which repeats OpenBLAS's products and so fuses as they do). Imported by the estimator's functions
when they run, never at import time (``pslog --help`` does not load numba).
"""

from __future__ import annotations

import numpy as np

from .._jit import kernel

_P = 3  # cubic


@kernel
def basis_in_span(knots: np.ndarray, j: np.ndarray, t: np.ndarray, n_derivatives: int
                  ) -> np.ndarray:
    """Values and derivatives (n, n_derivatives + 1, 4) of the four non-zero cubic B-splines
    at points ``t`` (n,) in spans ``j`` (n,) of ``knots``: Piegl & Tiller, *The NURBS Book*
    (2nd ed. 1997), algorithm A2.3 (``DersBasisFuns``), one point at a time
    (:func:`pslog.estimation.bspline._basis_in_span`)."""
    p = _P
    n = len(t)
    out = np.zeros((n, n_derivatives + 1, p + 1))
    ndu = np.zeros((p + 1, p + 1))
    left = np.zeros(p + 1)
    right = np.zeros(p + 1)
    a = np.zeros((2, p + 1))
    for i in range(n):
        _ders_basis(knots, j[i], t[i], n_derivatives, ndu, left, right, a, out, i)
    return out


@kernel
def basis_derivative_in_span(knots: np.ndarray, j: np.ndarray, t: np.ndarray,
                             derivative: np.ndarray) -> np.ndarray:
    """Row ``derivative[i]`` of :func:`basis_in_span` at each point (n, 4): the same
    recurrence up to that derivative (the same bits), without the (n, 4, 4) array of every
    derivative (the prior's nodes of a 90-minute session: 72 MB written, faulted in page by
    page, and mostly thrown away)."""
    p = _P
    n = len(t)
    out = np.zeros((n, p + 1))
    ders = np.zeros((1, 4, p + 1))
    ndu = np.zeros((p + 1, p + 1))
    left = np.zeros(p + 1)
    right = np.zeros(p + 1)
    a = np.zeros((2, p + 1))
    for i in range(n):
        d = derivative[i]
        ders[0, :d + 1] = 0.0
        _ders_basis(knots, j[i], t[i], d, ndu, left, right, a, ders, 0)
        for r in range(p + 1):
            out[i, r] = ders[0, d, r]
    return out


@kernel(inline=True)
def _ders_basis(knots: np.ndarray, ji: int, ti: float, n_derivatives: int, ndu: np.ndarray,
                left: np.ndarray, right: np.ndarray, a: np.ndarray, out: np.ndarray, i: int
                ) -> None:
    """One point of :func:`basis_in_span` into ``out[i]`` (>= n_derivatives + 1, 4), zero on
    entry (``ndu``, ``left``, ``right``, ``a``: scratch). Inlined into its callers, ``out``
    indexed in place: a compiled call (and a view ``out[i]``) took and released a reference
    to each of its arrays, two atomic operations each, at every point."""
    p = _P
    ndu[:] = 0.0
    ndu[0, 0] = 1.0
    for r in range(1, p + 1):
        left[r] = ti - knots[ji + 1 - r]
        right[r] = knots[ji + r] - ti
        saved = 0.0
        for s in range(r):
            ndu[r, s] = right[s + 1] + left[r - s]  # a knot difference, > 0
            temp = ndu[s, r - 1] / ndu[r, s]
            ndu[s, r] = saved + right[s + 1] * temp
            saved = left[r - s] * temp
        ndu[r, r] = saved
    for r in range(p + 1):
        out[i, 0, r] = ndu[r, p]
    for r in range(p + 1):
        s1, s2 = 0, 1
        a[:] = 0.0
        a[0, 0] = 1.0
        for k in range(1, n_derivatives + 1):
            d = 0.0
            rk, pk = r - k, p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d = a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for jj in range(j1, j2 + 1):
                a[s2, jj] = (a[s1, jj] - a[s1, jj - 1]) / ndu[pk + 1, rk + jj]
                d = d + a[s2, jj] * ndu[rk + jj, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d = d + a[s2, k] * ndu[r, pk]
            out[i, k, r] = d
            s1, s2 = s2, s1
    factor = 1.0
    for k in range(1, n_derivatives + 1):
        factor *= p - k + 1
        for r in range(p + 1):
            out[i, k, r] *= factor


@kernel
def window_normal(P: np.ndarray, prior_rhs: np.ndarray, first: np.ndarray, N: np.ndarray,
                  M: np.ndarray, v: np.ndarray, inside: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Dense normal equations of a batch of local windows (:class:`pslog.estimation._breaks.
    _Base`): ``H_b = P + Σ_w (N_w N_wᵀ) ⊗ M_w`` and ``rhs_b = prior_rhs + Σ_w N_w ⊗ v_w``, each
    detection's 12 x 12 block added at control points ``first .. first + 3`` (the sums the
    dense products of the basis matrix formed, one detection at a time, the prior first).

    Parameters
    ----------
    P : (n, n) float64, the prior's normal matrix (n = 3m); prior_rhs : (n,)
    first : (B, W) int64; N : (B, W, 4) float64, each detection's basis
    M : (B, W, 3, 3) float64, ``w JᵀJ``; v : (B, W, 3), ``w Jᵀ z``
    inside : (B, W) bool, the detections in each window (the rest add nothing)

    Returns
    -------
    H : (B, n, n); rhs : (B, n)
    """
    B, W = first.shape
    n = P.shape[0]
    H = np.empty((B, n, n))
    rhs = np.empty((B, n))
    for b in range(B):
        Hb = H[b]
        Hb[:, :] = P
        rb = rhs[b]
        rb[:] = 0.0
        for w in range(W):
            if not inside[b, w]:
                continue
            f3 = 3 * first[b, w]
            for a in range(4):
                na = N[b, w, a]
                for i in range(3):
                    rb[f3 + 3 * a + i] += na * v[b, w, i]
                for c in range(4):
                    nc = N[b, w, c]
                    for i in range(3):
                        for k in range(3):
                            # the upper triangle of M (w JᵀJ is symmetric only up to rounding)
                            mik = M[b, w, i, k] if i <= k else M[b, w, k, i]
                            Hb[f3 + 3 * a + i, f3 + 3 * c + k] += na * (mik * nc)
        for r in range(n):
            rb[r] += prior_rhs[r]
    return H, rhs


# control-point pairs (a, b), b >= a, in the order of the rows 4(first + a) + (b - a) they
# fill (:class:`pslog.estimation._normal.Points`): ascending, so that each sum below adds
# its terms in the order the sparse products did
_PA = np.array([0, 0, 0, 0, 1, 1, 1, 2, 2, 3])
_PB = np.array([0, 1, 2, 3, 1, 2, 3, 2, 3, 3])
#: 3 x 3 symmetric from its upper triangle (00, 01, 02, 11, 12, 22)
_SYM = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])


@kernel
def points_positions(first: np.ndarray, N: np.ndarray, control: np.ndarray) -> np.ndarray:
    """``p_i = Σ_a N[i, a] c[first_i + a]`` (r, 3) for control points (m, 3)."""
    r = len(first)
    out = np.zeros((r, 3))
    for i in range(r):
        f = first[i]
        for d in range(3):
            acc = 0.0
            for a in range(4):
                acc += N[i, a] * control[f + a, d]
            out[i, d] = acc
    return out


@kernel
def points_normal(first: np.ndarray, N: np.ndarray, upper: np.ndarray, v: np.ndarray, m: int,
                  ab: np.ndarray, rhs: np.ndarray) -> None:
    """Add ``Σ_i p_iᵀ M_i p_i - 2 v_iᵀ p_i`` to banded normal equations in place: each
    term's block ``(N_i N_iᵀ) ⊗ M_i`` (``upper`` (r, 6) the upper triangle of ``M_i``)
    summed per control-point pair over the terms in order, then added to ``ab`` (12, 3m)
    (upper banded storage); ``N_i ⊗ v_i`` to ``rhs`` (3m,).

    Each control point's sums start at 0 and take its terms in order, then are added to
    ``ab`` once. With ``first`` non-decreasing (a piece's detections in time order) a control
    point below the current term's ``first`` takes no more terms: its sums are added then,
    and a ring of 8 control points' sums is all the memory used (a whole session's, 36 MB at
    90 minutes, cost a page fault every 4 kB at every call); otherwise every control point's
    sums are kept to the end. The same sums, the same bits."""
    _points_normal_into(first, N, upper, v, m, ab, rhs, ab, rhs)


@kernel
def points_normal_onto(first: np.ndarray, N: np.ndarray, upper: np.ndarray, v: np.ndarray,
                       m: int, base_ab: np.ndarray, base_rhs: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`points_normal` added to ``base_ab`` (12, 3m) and ``base_rhs`` (3m,) (the
    prior's, left as they are) into new arrays, in one pass: each entry of the band is
    reached by exactly one control point's sums (entry ``(11 - off, 3q + e)``: the pair of
    control points ``q - k`` and ``q`` with ``3k + e - d = off``, one ``k`` for each ``off``),
    so it is written once as ``base + sums`` — the value a copy of the base then
    :func:`points_normal` gave, without the copy (47 MB read and written at every
    Gauss–Newton step of a 90-minute session). The entries no control point reaches (the
    band's corner before the first columns) are the base's."""
    ab = np.empty_like(base_ab)
    rhs = np.empty_like(base_rhs)
    # the band's corner (rows above the first columns: no pair of control points there)
    for i in range(ab.shape[0]):
        for j in range(min(12, ab.shape[1])):
            ab[i, j] = base_ab[i, j]
    if len(first) == 0:
        ab[:, :] = base_ab
        rhs[:] = base_rhs
        return ab, rhs
    _points_normal_into(first, N, upper, v, m, base_ab, base_rhs, ab, rhs)
    return ab, rhs


@kernel(inline=True)
def _ring(first: np.ndarray, m: int) -> tuple[bool, int, np.ndarray, np.ndarray]:
    """The sums per control point of :func:`_points_normal_into` and
    :func:`pslog.estimation._gauss_newton.linearised_normal_onto`, zero: (ordered, mask,
    blocks (size, 4, 6), rv (size, 3)). Where ``first`` is non-decreasing a ring of 8
    control points (a control point's slot: its index masked by 7 — a division per term cost
    more than the sums — folded into the band as the detections move past it), every
    control point's (m + 3, mask -1: the index itself) otherwise."""
    ordered = True
    for i in range(1, len(first)):
        if first[i] < first[i - 1]:
            ordered = False
            break
    size = 8 if ordered else m + 3
    mask = 7 if ordered else -1
    return ordered, mask, np.zeros((size, 4, 6)), np.zeros((size, 3))


@kernel(inline=True)
def _add_point(blocks: np.ndarray, rv: np.ndarray, f: int, mask: int, n0: float, n1: float,
               n2: float, n3: float, u0: float, u1: float, u2: float, u3: float, u4: float,
               u5: float, v0: float, v1: float, v2: float) -> None:
    """One detection's terms added to the sums of :func:`_ring`: its basis values ``n0..n3``
    (control points ``f..f+3``), the upper triangle ``u0..u5`` of its quadratic form and its
    ``v0..v2``: ``blocks[f+a][k] += n_a n_{a+k} u``, ``rv[f+a] += n_a v``."""
    for a in range(4):
        na = n0 if a == 0 else (n1 if a == 1 else (n2 if a == 2 else n3))
        row = blocks[(f + a) & mask]
        for k in range(4 - a):
            c = a + k
            nn = na * (n0 if c == 0 else (n1 if c == 1 else (n2 if c == 2 else n3)))
            blk = row[k]
            blk[0] += nn * u0
            blk[1] += nn * u1
            blk[2] += nn * u2
            blk[3] += nn * u3
            blk[4] += nn * u4
            blk[5] += nn * u5
    for a in range(4):
        na = n0 if a == 0 else (n1 if a == 1 else (n2 if a == 2 else n3))
        rr = rv[(f + a) & mask]
        rr[0] += na * v0
        rr[1] += na * v1
        rr[2] += na * v2


@kernel(inline=True)
def _points_normal_into(first: np.ndarray, N: np.ndarray, upper: np.ndarray, v: np.ndarray,
                        m: int, base_ab: np.ndarray, base_rhs: np.ndarray, ab: np.ndarray,
                        rhs: np.ndarray) -> None:
    """:func:`points_normal` with each band entry and rhs entry written as the base's plus
    its sums (``base_ab`` may be ``ab``: in place)."""
    r = len(first)
    ordered, mask, blocks, rv = _ring(first, m)
    done = 0  # control points below this one are in ab and rhs
    for i in range(r):
        f = first[i]
        if ordered:
            while done < f:
                _fold_row(blocks, rv, done, done & mask, m, base_ab, base_rhs, ab, rhs)
                done += 1
        _add_point(blocks, rv, f, mask, N[i, 0], N[i, 1], N[i, 2], N[i, 3],
                   upper[i, 0], upper[i, 1], upper[i, 2], upper[i, 3], upper[i, 4],
                   upper[i, 5], v[i, 0], v[i, 1], v[i, 2])
    while done < m:
        _fold_row(blocks, rv, done, done & mask, m, base_ab, base_rhs, ab, rhs)
        done += 1


@kernel(inline=True)
def _fold_row(blocks: np.ndarray, rv: np.ndarray, p: int, slot: int, m: int,
              base_ab: np.ndarray, base_rhs: np.ndarray, ab: np.ndarray,
              rhs: np.ndarray) -> None:
    """Write control point ``p``'s sums (``blocks[slot]`` (4, 6): its pairs with points
    ``p..p+3``, upper triangles; ``rv[slot]`` (3,)) added to ``base_ab`` and ``base_rhs``
    into ``ab`` and ``rhs`` (the same arrays: added in place), and zero them
    (:func:`points_normal`)."""
    for k in range(4):
        if p + k >= m:
            break
        for d in range(3):
            for e in range(3):
                off = 3 * k + e - d  # column minus row
                if off < 0:
                    continue
                ab[11 - off, 3 * (p + k) + e] = (base_ab[11 - off, 3 * (p + k) + e]
                                                 + blocks[slot, k, _SYM[d, e]])
    # the entries of point p's columns that no pair reaches (a pair 4 points apart: off 10
    # and 11 of coordinate 0, off 11 of coordinate 1): the base's
    ab[0, 3 * p] = base_ab[0, 3 * p]
    ab[1, 3 * p] = base_ab[1, 3 * p]
    ab[0, 3 * p + 1] = base_ab[0, 3 * p + 1]
    for d in range(3):
        rhs[3 * p + d] = base_rhs[3 * p + d] + rv[slot, d]
    blocks[slot] = 0.0
    rv[slot] = 0.0


@kernel
def prior_sums(first: np.ndarray, N: np.ndarray, w: np.ndarray, m: int) -> np.ndarray:
    """The motion prior's band in compact form: ``sums[p, k] = Σ N_a N_(a+k) w`` (m + 3, 4)
    over the terms ``w_i I₃`` with ``first_i + a = p``, each control point's sums taking its
    terms in order (ordered or not). The band of :func:`points_normal_isotropic` holds
    ``0.0 + sums[p, k]`` on row ``11 - 3k`` at columns ``3(p + k) + d`` (``d`` = 0, 1, 2) and
    zero elsewhere: 4 numbers per control point, not 36 (a 90-minute session's two bands
    were 2 x 52 MB, zeroed and written at every knot change and read whole by
    :func:`prior_band`; :func:`prior_band_sums` forms the prior's band from these)."""
    r = len(first)
    sums = np.zeros((m + 3, 4))  # sums[p, k]: Σ N_a N_(a+k) w over terms with first + a = p
    for i in range(r):
        f = first[i]
        wi = w[i]
        for a in range(4):
            na = N[i, a]
            for k in range(4 - a):
                sums[f + a, k] += (na * N[i, a + k]) * wi
    return sums


@kernel
def points_normal_isotropic(first: np.ndarray, N: np.ndarray, w: np.ndarray, m: int
                            ) -> np.ndarray:
    """The band (12, 3m) :func:`points_normal` forms from zero for terms ``w_i I₃`` (the
    motion prior's: ``upper`` = (w, 0, 0, w, 0, w), ``v`` = 0), each pair's sum formed once:
    the three diagonal entries of a block take the same products in the same order (the
    same bits), the off-diagonal ones only ``±0`` products, which leave ``+0`` (IEEE:
    ``0 + -0 = +0``). Ordered or not, each control point's sums take its terms in order.
    (The fit keeps the compact :func:`prior_sums`; this band is the tests' bridge to
    :func:`points_normal`.)"""
    sums = prior_sums(first, N, w, m)
    ab = np.zeros((12, 3 * m))
    for p in range(m):
        for k in range(4):
            if p + k >= m:
                break
            for d in range(3):
                ab[11 - 3 * k, 3 * (p + k) + d] = 0.0 + sums[p, k]
    return ab


@kernel
def points_marginal(first: np.ndarray, N: np.ndarray, band: np.ndarray) -> np.ndarray:
    """``Σ_ab N_a N_b Σ_{first+a, first+b}`` (r, 3, 3) from the covariance band (m, 4, 3, 3)
    (an off-diagonal pair stands for both orders: its block plus its transpose)."""
    r = len(first)
    out = np.zeros((r, 3, 3))
    for i in range(r):
        f = first[i]
        for q in range(10):
            a, b = _PA[q], _PB[q]
            nn = N[i, a] * N[i, b]
            k = b - a
            for d in range(3):
                for e in range(3):
                    s = band[f + a, k, d, e]
                    if k > 0:
                        s = s + band[f + a, k, e, d]
                    out[i, d, e] += nn * s
    return out


@kernel
def gains_data(s_sorted: np.ndarray, first: np.ndarray, N: np.ndarray, M: np.ndarray,
               u: np.ndarray, which: np.ndarray, j: np.ndarray, q0: np.ndarray,
               lo: np.ndarray, hi: np.ndarray, coef: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The data terms of the break test (:func:`pslog.estimation._breaks._gains`) of B
    trial instants, each on window ``which[b]`` of a base: over the window's detections on
    the three spans ``[j-1, j+2)`` (in spacings from the centre) the three new B-splines
    ``f_e`` live on,

    ``Hyy[3e+i, 3f+k] = Σ_w f_e f_f M_w[i, k]``, ``Hxy[3c+i, 3e+k] = Σ_w b_c f_e M_w[i, k]``
    (``b_c`` the base's B-spline ``q0 + c``) and ``g[e, d] = Σ_w f_e u_w[d]``.

    Parameters
    ----------
    s_sorted : (Bb, Wb) float64, each base window's detection times in spacings from its
        centre, increasing (padding 1e6); first (Bb, Wb) int64, N (Bb, Wb, 4): their basis;
        M (Bb, Wb, 3, 3): ``w JᵀJ``; u (Bb, Wb, 3): the weighted residual at the minimum
    which, q0 : (B,) int64; j : (B,) float64, the trial instant's span
    lo, hi : (B, 3, 2) float64, the two polynomial pieces of each new B-spline (spacings
        from ``u_j``); coef : (B, 3, 2, 4), their power-basis coefficients

    Returns
    -------
    Hyy : (B, 9, 9); Hxy : (B, 18, 9); g : (B, 3, 3)
    """
    B = len(which)
    Wb = s_sorted.shape[1]
    Hyy = np.zeros((B, 9, 9))
    Hxy = np.zeros((B, 18, 9))
    g = np.zeros((B, 3, 3))
    # per detection of the trial's three spans: f_e, f_e f_f and b_c f_e (each product
    # formed once), then the entries' sums over the detections (each from 0, the detections
    # in order), nine side by side in registers — a row of a 3 x 3 block: the detection's
    # coefficient times a row of its M — so nine independent chains overlap instead of one
    # waiting on its previous addition (the same terms in the same order: the same bits)
    F = np.zeros((Wb, 3))
    FF = np.zeros((Wb, 3, 3))
    OF = np.zeros((Wb, 6, 3))
    for b in range(B):
        wb = which[b]
        jb = j[b]
        lo_col = 0
        hi_col = 0
        for w in range(Wb):  # the same counts as the detections before each bound
            if s_sorted[wb, w] < jb - 1:
                lo_col += 1
            if s_sorted[wb, w] < jb + 1 + 1:
                hi_col += 1
        nw = hi_col - lo_col
        for n in range(nw):
            w = lo_col + n
            x = s_sorted[wb, w] - jb
            for e in range(3):
                fe = 0.0
                for k in range(2):
                    if x >= lo[b, e, k] and x < hi[b, e, k]:
                        c = coef[b, e, k]
                        fe = ((c[3] * 1.0 * x + c[2]) * x + c[1]) * x + c[0]
                F[n, e] = fe
            for e in range(3):
                for e2 in range(3):
                    FF[n, e, e2] = F[n, e] * F[n, e2]
            for c6 in range(6):
                a = q0[b] + c6 - first[wb, w]
                oc = N[wb, w, a] if 0 <= a <= 3 else 0.0
                for e in range(3):
                    OF[n, c6, e] = oc * F[n, e]
        Mb = M[wb, lo_col:hi_col]
        Ub = u[wb, lo_col:hi_col]
        for e in range(3):
            g0 = 0.0
            g1 = 0.0
            g2 = 0.0
            for n in range(nw):
                fe = F[n, e]
                g0 += fe * Ub[n, 0]
                g1 += fe * Ub[n, 1]
                g2 += fe * Ub[n, 2]
            g[b, e, 0] = g0
            g[b, e, 1] = g1
            g[b, e, 2] = g2
        for e in range(3):
            for i in range(3):
                _block_row(FF[:nw, e], Mb[:, i], Hyy[b, 3 * e + i])
        for c6 in range(6):
            for i in range(3):
                _block_row(OF[:nw, c6], Mb[:, i], Hxy[b, 3 * c6 + i])
    return Hyy, Hxy, g


@kernel(inline=True)
def _block_row(f: np.ndarray, m: np.ndarray, out: np.ndarray) -> None:
    """``out[3e + k] = Σ_n f[n, e] m[n, k]`` (f, m (nw, 3); out (9,)): each sum from 0 over
    ``n`` in order (:func:`gains_data`), the nine in registers side by side."""
    a00 = 0.0
    a01 = 0.0
    a02 = 0.0
    a10 = 0.0
    a11 = 0.0
    a12 = 0.0
    a20 = 0.0
    a21 = 0.0
    a22 = 0.0
    for n in range(f.shape[0]):
        f0 = f[n, 0]
        f1 = f[n, 1]
        f2 = f[n, 2]
        m0 = m[n, 0]
        m1 = m[n, 1]
        m2 = m[n, 2]
        a00 += f0 * m0
        a01 += f0 * m1
        a02 += f0 * m2
        a10 += f1 * m0
        a11 += f1 * m1
        a12 += f1 * m2
        a20 += f2 * m0
        a21 += f2 * m1
        a22 += f2 * m2
    out[0] = a00
    out[1] = a01
    out[2] = a02
    out[3] = a10
    out[4] = a11
    out[5] = a12
    out[6] = a20
    out[7] = a21
    out[8] = a22


@kernel
def takahashi_rows(diag: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Rows ``rows[r, j] = Σ_{r, r+j}`` (n + 12, 12) of ``A⁻¹`` within the band, for
    ``A = Uᵀ U`` with ``U`` upper banded: ``diag`` (n,) its diagonal, ``right`` (n, 11) row
    ``r``'s entries ``U[r, r+1..r+11]``. The Takahashi, Fagan & Chen (1973) recurrence one
    unknown at a time from the last (:func:`pslog.estimation._normal.covariance_band`):
    ``Σ_rj = -Σ_k U_rk Σ_kj / U_rr`` (``j > r``), ``Σ_rr = 1/U_rr² - Σ_k U_rk Σ_kr / U_rr``."""
    n = len(diag)
    rows = np.zeros((n + 12, 12))
    # the window of unknowns r+1..r+11 is read from the rows already computed (symmetric:
    # Σ_{r+k, r+j} = rows[r+k, j-k] for k <= j, rows[r+j, k-j] otherwise)
    for r in range(n - 1, -1, -1):
        dr = diag[r]
        for j in range(1, 12):
            acc = 0.0
            for k in range(1, 12):
                if k <= j:
                    s = rows[r + k, j - k]
                else:
                    s = rows[r + j, k - j]
                acc += right[r, k - 1] * s
            rows[r, j] = -acc / dr
        acc = 0.0
        for k in range(1, 12):
            acc += right[r, k - 1] * rows[r, k]
        rows[r, 0] = 1 / dr**2 - acc / dr
    return rows


@kernel
def takahashi_band(U: np.ndarray, m: int) -> np.ndarray:
    """The (m, 4, 3, 3) block band of ``A⁻¹`` for ``A = Uᵀ U`` (``U`` (12, 3m) upper banded
    storage, from :func:`band_cholesky`): :func:`takahashi_rows` and :func:`band_from_rows`
    in one pass, the same operations in the same order (the same bits). The recurrence
    reads only the 11 rows after the current one, so 12 rows in a ring stand for the
    (3m + 12, 12) array (zero rows beyond the last unknown, as there); control point ``i``'s
    blocks are read out as soon as its three rows are done. Row ``r``'s entries
    ``U[r, r+1..r+11]`` are read from the band itself (zero beyond the last unknown, as
    ``covariance_band`` built them), not from a copy of them."""
    n = U.shape[1]
    ring = np.zeros((12, 12))  # ring[r % 12] = row r of Σ within the band
    right = np.zeros(11)
    band = np.zeros((m, 4, 3, 3))
    for r in range(n - 1, -1, -1):
        dr = U[11, r]
        for d in range(1, 12):
            right[d - 1] = U[11 - d, r + d] if r + d < n else 0.0
        row = ring[r % 12]
        for j in range(1, 12):
            acc = 0.0
            for k in range(1, 12):
                if k <= j:
                    s = ring[(r + k) % 12, j - k]
                else:
                    s = ring[(r + j) % 12, k - j]
                acc += right[k - 1] * s
            row[j] = -acc / dr
        acc = 0.0
        for k in range(1, 12):
            acc += right[k - 1] * row[k]
        row[0] = 1 / dr**2 - acc / dr
        if r % 3 == 0 and r // 3 < m:  # rows 3i..3i+2 done: control point i's blocks
            i = r // 3
            for k in range(4):
                for a in range(3):
                    for b in range(3):
                        jj = 3 * k + b - a
                        if jj >= 0:
                            band[i, k, a, b] = ring[(r + a) % 12, jj]
                        else:
                            band[i, k, a, b] = ring[(r + b) % 12, -jj]
    return band


@kernel
def window_solve(H: np.ndarray, rhs: np.ndarray, lo: int, hi: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Solve a batch of the break test's local normal equations (B, n, n), symmetric
    positive definite and banded (every term touches 4 consecutive control points: 11
    super-diagonals): the minimum ``H⁻¹ rhs`` (B, n) and the rows and columns ``lo..hi-1``
    of ``H⁻¹`` (B, n, hi - lo; rows before ``lo`` are 0: the break test reads none), by a
    banded Cholesky factorisation ``H = L Lᵀ`` (left-looking, from the lower triangle of
    ``H``) and substitutions that start at each unit column's first non-zero (Golub & Van
    Loan, *Matrix Computations*, 4th ed., §4.3.5-4.3.6).

    Every entry is the sum of the same terms in the same order as a column-at-a-time form
    (``L[i, j] = (H[i, j] - Σ_k L[i, k] L[j, k]) / L[j, j]`` over ascending ``k``; each
    substitution likewise), the same bits; the loops run ``k`` outside and the independent
    rows or columns inside, so those chains overlap (and vectorise) instead of each waiting
    on its previous term. ``U = Lᵀ`` is stored: the factorisation's inner loop then reads
    a row.

    Returns
    -------
    x : (B, n); cov : (B, n, hi - lo); ok : (B,) bool, False where a pivot was not positive
    (that window's outputs are not set: solve it otherwise)
    """
    B, n, _ = H.shape
    bw = 11
    x = np.zeros((B, n))
    cov = np.zeros((B, n, hi - lo))
    ok = np.ones(B, dtype=np.bool_)
    U = np.zeros((n, n))  # U[k, i] = L[i, k]
    ncol = hi - lo + 1
    Y = np.zeros((n, ncol))
    Z = np.zeros((n, ncol))
    T = np.zeros(max(ncol, bw + 1))
    for b in range(B):
        ok[b] = _solve_window(H[b], rhs[b], lo, hi, U, Y, Z, T, x[b], cov[b])
    return x, cov, ok


@kernel(inline=True)
def _solve_window(Hb: np.ndarray, rb: np.ndarray, lo: int, hi: int, U: np.ndarray,
                  Y: np.ndarray, Z: np.ndarray, T: np.ndarray, xb: np.ndarray,
                  covb: np.ndarray) -> bool:
    """:func:`window_solve` of one window (``Hb`` (n, n), of which the lower band is read;
    ``rb`` (n,)) into ``xb`` (n,) and ``covb`` (n, hi - lo), with the work arrays ``U``
    (n, n), ``Y``, ``Z`` (n, hi - lo + 1) and ``T``; False (and nothing written) where a
    pivot is not positive."""
    n = Hb.shape[0]
    bw = 11
    ncol = hi - lo + 1
    for j in range(n):
        s = Hb[j, j]
        for k in range(max(0, j - bw), j):
            s -= U[k, j] * U[k, j]
        if not s > 0.0:
            return False
        d = np.sqrt(s)
        U[j, j] = d
        iend = min(n, j + bw + 1)
        for i in range(j + 1, iend):
            T[i - j] = Hb[i, j]
        # L[i, j] for the rows below: each over k >= i - bw, ascending
        for k in range(max(0, j + 1 - bw), j):
            ukj = U[k, j]
            for i in range(j + 1, min(iend, k + bw + 1)):
                T[i - j] -= U[k, i] * ukj
        for i in range(j + 1, iend):
            U[j, i] = T[i - j] / d
    # forward: the right-hand side (column 0) and the unit columns lo..hi-1 (columns
    # 1.., column c's first non-zero at row lo + c - 1) side by side; row k adds to the
    # columns that have started by row k
    for i in range(n):
        T[0] = rb[i]
        for col in range(1, ncol):
            T[col] = 1.0 if i == lo + col - 1 else 0.0
        for k in range(max(0, i - bw), i):
            lik = U[k, i]
            for col in range(min(ncol, max(1, k - lo + 2))):
                T[col] -= lik * Y[k, col]
        lii = U[i, i]
        for col in range(ncol):
            Y[i, col] = T[col] / lii if col == 0 or i >= lo + col - 1 else 0.0
    # back: the minimum in full; a unit column down to row lo only (the gains read the
    # rows lo..hi-1 of these columns: the rows below them are left 0)
    for i in range(n - 1, -1, -1):
        nc = ncol if i >= lo else 1
        for col in range(nc):
            T[col] = Y[i, col]
        for k in range(i + 1, min(n, i + bw + 1)):
            lki = U[i, k]
            for col in range(nc):
                T[col] -= lki * Z[k, col]
        lii = U[i, i]
        for col in range(nc):
            Z[i, col] = T[col] / lii
    for i in range(n):
        xb[i] = Z[i, 0]
    for i in range(lo, n):
        for col in range(1, ncol):
            covb[i, col - 1] = Z[i, col]
    return True


@kernel
def window_normal_solve(P: np.ndarray, prior_rhs: np.ndarray, first: np.ndarray,
                        N: np.ndarray, M: np.ndarray, v: np.ndarray, inside: np.ndarray,
                        lo: int, hi: int
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`window_normal`, the diagonal times ``1 + 1e-12``, then :func:`window_solve`,
    one window at a time: its normal matrix built in a work array that stays in cache (a
    batch's (B, n, n) matrices, 4 MB for a block of the scan, were written out and read
    back) and only its lower band, the part the factorisation reads (each entry the same
    terms in the same order: the same bits).

    Returns
    -------
    x : (B, n); cov : (B, n, hi - lo); ok : (B,) bool (False: a pivot not positive, that
    window's outputs not set); rhs : (B, n), :func:`window_normal`'s
    """
    B, W = first.shape
    n = P.shape[0]
    bw = 11
    x = np.zeros((B, n))
    cov = np.zeros((B, n, hi - lo))
    ok = np.ones(B, dtype=np.bool_)
    rhs = np.empty((B, n))
    Hb = np.zeros((n, n))
    U = np.zeros((n, n))  # U[k, i] = L[i, k]
    ncol = hi - lo + 1
    Y = np.zeros((n, ncol))
    Z = np.zeros((n, ncol))
    T = np.zeros(max(ncol, bw + 1))
    for b in range(B):
        for j in range(n):
            for i in range(j, min(n, j + bw + 1)):
                Hb[i, j] = P[i, j]
        rb = rhs[b]
        rb[:] = 0.0
        for w in range(W):
            if not inside[b, w]:
                continue
            f3 = 3 * first[b, w]
            for a in range(4):
                na = N[b, w, a]
                for i in range(3):
                    rb[f3 + 3 * a + i] += na * v[b, w, i]
                for c in range(a + 1):  # the blocks on and below the diagonal
                    nc = N[b, w, c]
                    for i in range(3):
                        for k in range(3 if c < a else i + 1):
                            mik = M[b, w, i, k] if i <= k else M[b, w, k, i]
                            Hb[f3 + 3 * a + i, f3 + 3 * c + k] += na * (mik * nc)
        for r in range(n):
            rb[r] += prior_rhs[r]
        for r in range(n):
            Hb[r, r] *= 1 + 1e-12
        ok[b] = _solve_window(Hb, rb, lo, hi, U, Y, Z, T, x[b], cov[b])
    return x, cov, ok, rhs


@kernel
def project_residuals(camera: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray,
                      dist: np.ndarray, X: np.ndarray, uv: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reprojection residuals and Jacobians of world points, each seen by one camera: the
    formulas of :func:`pslog.estimation.projection.project_with_jacobian` (OpenCV pinhole +
    plumb_bob, analytic chain rule), one point at a time, in the same operations and order
    as :func:`~pslog.estimation.projection.project_stacked` (so the same bits).

    Parameters
    ----------
    camera : (n,) int64, each point's camera
    R : (C, 3, 3), t : (C, 3), the cameras' poses (world to camera, metres)
    K : (C, 5), ``fx, s, cx, fy, cy`` (pixels); dist : (C, 5), ``k1, k2, p1, p2, k3``
    X : (n, 3) float64, metres; uv : (n, 2) float64, the detections, pixels

    Returns
    -------
    r : (n, 2), projection minus detection, pixels; J : (n, 2, 3), ``∂uv/∂X``, pixels per
    metre; invalid : (n,) bool, a point at or behind its camera plane (or any non-finite
    value): its ``r`` and ``J`` are set to 0 (it adds nothing to the normal equations)
    """
    n = len(camera)
    r = np.empty((n, 2))
    J = np.empty((n, 2, 3))
    invalid = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        c = camera[i]
        X0, X1, X2 = X[i, 0], X[i, 1], X[i, 2]
        # R X + t, summed as numpy's einsum ("nij,nj->ni") does: its two SIMD lanes hold
        # j = 0 and 2, and j = 1, then add up (the bits of project_stacked)
        pc0 = ((R[c, 0, 0] * X0 + R[c, 0, 2] * X2) + R[c, 0, 1] * X1) + t[c, 0]
        pc1 = ((R[c, 1, 0] * X0 + R[c, 1, 2] * X2) + R[c, 1, 1] * X1) + t[c, 1]
        pc2 = ((R[c, 2, 0] * X0 + R[c, 2, 2] * X2) + R[c, 2, 1] * X1) + t[c, 2]
        inv_z = 1.0 / pc2 if pc2 > 1e-12 else np.nan
        x = pc0 * inv_z
        y = pc1 * inv_z
        k1, k2, p1, p2, k3 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3], dist[c, 4]
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        d_radial = k1 + r2 * (2 * k2 + 3 * k3 * r2)
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        fx, s, cx, fy, cy = K[c, 0], K[c, 1], K[c, 2], K[c, 3], K[c, 4]
        r0 = (fx * xd + s * yd + cx) - uv[i, 0]
        r1 = (fy * yd + cy) - uv[i, 1]
        d00 = radial + 2 * x * x * d_radial + 2 * p1 * y + 6 * p2 * x
        d01 = 2 * x * y * d_radial + 2 * p1 * x + 2 * p2 * y
        d11 = radial + 2 * y * y * d_radial + 6 * p1 * y + 2 * p2 * x
        a00 = fx * d00 + s * d01
        a01 = fx * d01 + s * d11
        a10 = fy * d01
        a11 = fy * d11
        total = r0 + r1
        jsum = 0.0
        for k in range(3):
            px = inv_z * (R[c, 0, k] - x * R[c, 2, k])
            py = inv_z * (R[c, 1, k] - y * R[c, 2, k])
            J[i, 0, k] = a00 * px + a01 * py
            J[i, 1, k] = a10 * px + a11 * py
        for a in range(2):
            for k in range(3):
                jsum += J[i, a, k]
        if np.isfinite(total + jsum):
            r[i, 0] = r0
            r[i, 1] = r1
        else:
            invalid[i] = True
            r[i, 0] = 0.0
            r[i, 1] = 0.0
            for a in range(2):
                for k in range(3):
                    J[i, a, k] = 0.0
    return r, J, invalid


@kernel
def data_terms(J: np.ndarray, target: np.ndarray, w: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Each detection's quadratic form ``w ‖J p - z‖²`` as a point term of
    :func:`points_normal`: ``upper`` (n, 6) the upper triangle of ``w JᵀJ`` (00, 01, 02, 11,
    12, 22) and ``v = Jᵀ (w z)`` (n, 3); J (n, 2, 3), target z (n, 2), w (n,)."""
    n = len(w)
    upper = np.empty((n, 6))
    v = np.empty((n, 3))
    for i in range(n):
        wi = w[i]
        q = 0
        for a in range(3):
            for b in range(a, 3):
                upper[i, q] = wi * (J[i, 0, a] * J[i, 0, b] + J[i, 1, a] * J[i, 1, b])
                q += 1
        v0 = wi * target[i, 0]
        v1 = wi * target[i, 1]
        for d in range(3):
            v[i, d] = J[i, 0, d] * v0 + J[i, 1, d] * v1
    return upper, v


@kernel
def band_from_rows(rows: np.ndarray, m: int) -> np.ndarray:
    """The (m, 4, 3, 3) block band of a covariance from ``rows[r, j] = Σ_{r, r+j}``
    (:func:`takahashi_rows`): block (i, i+k), entry (a, b) = ``rows[3i+a, 3k+b-a]`` (by
    symmetry ``rows[3i+b, a-b]`` below a diagonal block's diagonal)."""
    band = np.zeros((m, 4, 3, 3))
    for i in range(m):
        for k in range(4):
            for a in range(3):
                for b in range(3):
                    j = 3 * k + b - a
                    if j >= 0:
                        band[i, k, a, b] = rows[3 * i + a, j]
                    else:
                        band[i, k, a, b] = rows[3 * i + b, -j]
    return band


@kernel
def window_positions(first: np.ndarray, N: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Each window's spline at its detections, ``X[b, w] = Σ_a N[b, w, a] x[b, first + a]``
    (B, W, 3), for control points ``x`` (B, m, 3) (summed over ``a`` in order, as numpy's
    einsum does: the same bits)."""
    B, W = first.shape
    out = np.empty((B, W, 3))
    for b in range(B):
        for w in range(W):
            f = first[b, w]
            for d in range(3):
                acc = 0.0
                for a in range(4):
                    acc += N[b, w, a] * x[b, f + a, d]
                out[b, w, d] = acc
    return out


@kernel
def band_cholesky(ab: np.ndarray) -> int:
    """Upper banded Cholesky factor ``U`` (``A = Uᵀ U``) of ``ab`` (kd + 1, n) in place
    (upper banded storage, ``ab[kd + i - j, j] = A[i, j]``): LAPACK's ``dpbtf2`` (the
    unblocked form ``dpbtrf`` runs for a band this narrow), step for step — the row's
    entries beyond the diagonal scaled by the pivot's reciprocal (``dscal``), then the
    rank-one update of the trailing block (``dsyr``: each entry ``a + (-x_c) x_r``, no
    fused multiply-add), so the same bits as scipy's ``cholesky_banded``. Golub & Van Loan,
    *Matrix Computations*, 4th ed., §4.3.5.

    A step updates each entry of its trailing block once, so the order of the updates
    within a step does not change a bit: they run by diagonal of the band (one stored row,
    contiguous columns), with fixed trip counts where the whole band of 11 superdiagonals
    is inside the matrix (every column but the last 11 of a spline problem): 1.4x less
    time than ``dsyr``'s column order at 90 minutes, the same bits.

    Returns
    -------
    info : int, 0, or ``j + 1`` where pivot ``j`` was not positive (``ab`` then holds the
    partial factor, as LAPACK's)
    """
    kd = ab.shape[0] - 1
    n = ab.shape[1]
    x = np.zeros(max(kd, 1))
    nx = np.zeros(max(kd, 1))  # -x, as dsyr's alpha times x_c
    for j in range(n):
        ajj = ab[kd, j]
        if not ajj > 0.0:
            return j + 1
        ajj = np.sqrt(ajj)
        ab[kd, j] = ajj
        kn = min(kd, n - j - 1)
        inv = 1.0 / ajj
        if kd == 11 and kn == 11:  # the spline problems' band, whole: fixed trip counts
            for p in range(11):
                v = ab[10 - p, j + 1 + p] * inv
                ab[10 - p, j + 1 + p] = v
                x[p] = v
                nx[p] = -1.0 * v
            # entry (kd + r - c, j + 1 + c), r <= c, on diagonal d = c - r: row kd - d
            for d in range(11):
                row = ab[11 - d]
                c0 = j + 1 + d
                for r in range(11 - d):
                    row[c0 + r] = row[c0 + r] + nx[r + d] * x[r]
        else:
            for p in range(kn):
                v = ab[kd - 1 - p, j + 1 + p] * inv
                ab[kd - 1 - p, j + 1 + p] = v
                x[p] = v
                nx[p] = -1.0 * v
            for d in range(kn):
                row = ab[kd - d]
                c0 = j + 1 + d
                for r in range(kn - d):
                    row[c0 + r] = row[c0 + r] + nx[r + d] * x[r]
    return 0


@kernel
def band_solve(U: np.ndarray, b: np.ndarray) -> None:
    """Solve ``Uᵀ U x = b`` in place for each row of ``b`` (r, n) (a right-hand side per
    row), ``U`` (kd + 1, n) from :func:`band_cholesky`: LAPACK's ``dpbtrs`` with OpenBLAS's
    ``dtbsv``, step for step — the forward solve ``Uᵀ y = b`` subtracts each row's dot
    product (summed from 0 in order) and divides by the pivot; the back solve ``U x = y``
    divides by the pivot, then subtracts ``x_i`` times column ``i`` from the rows above
    (``daxpy``): the same bits as scipy's ``cho_solve_banded``. Rows with the whole band
    of 11 superdiagonals take fixed trip counts (the same operations in the same order:
    1.7x less time at 90 minutes)."""
    kd = U.shape[0] - 1
    n = U.shape[1]
    for q in range(b.shape[0]):
        x = b[q]
        for i in range(n):
            length = min(i, kd)
            if kd == 11 and length == 11:
                dot = 0.0
                for p in range(11):
                    dot += x[i - 11 + p] * U[p, i]
                x[i] -= dot
            elif length > 0:
                dot = 0.0
                for p in range(length):
                    dot += x[i - length + p] * U[kd - length + p, i]
                x[i] -= dot
            x[i] /= U[kd, i]
        for i in range(n - 1, -1, -1):
            x[i] /= U[kd, i]
            da = -x[i]
            length = min(i, kd)
            if kd == 11 and length == 11:
                for p in range(11):
                    x[i - 11 + p] += da * U[p, i]
            else:
                for p in range(length):
                    x[i - length + p] += da * U[kd - length + p, i]


@kernel
def trial_splines(a: np.ndarray, both3: np.ndarray, cube: np.ndarray, s: np.ndarray,
                  j: np.ndarray, K: int, h: float, h2: float, h3: float, gauss: float,
                  q_accel: float, q_jerk: float):
    """The per-trial terms of the break test (:func:`pslog.estimation._breaks._gains`) for B
    trial instants ``s = j + a`` (spacings from the window's centre): the three new
    B-splines' polynomial pieces (:func:`pslog.estimation._breaks._new_splines`, whose
    operations this repeats in order: the same bits), their p'' and jerk at the prior's 12
    nodes of the four sub-spans around the instant, weighted, and the base's uniform
    B-splines there.

    Parameters
    ----------
    a : (B,) float64, the instant's fraction of its span; both3, cube : (2, B), ``b**3`` and
        ``b**-3`` of ``b = (a, 1 - a)`` (numpy's power, passed in: its SIMD ``pow`` is not
        libm's); s, j : (B,) the instant and its span, in spacings; K : the window's half
        width in spacings; h, h2, h3 : the spacing (s) and its square and cube (as numpy
        computed them); gauss : ``1/√3``; q_accel, q_jerk : the prior's spectral densities

    Returns
    -------
    lo, hi : (B, 3, 2) each new B-spline's two pieces' bounds; coef : (B, 3, 2, 4) their
    power-basis coefficients; nodes : (B, 12) the prior's nodes (two Gauss nodes of each
    sub-span, then its midpoint); fn : (B, 3, 12) the new B-splines' p'' (Gauss nodes,
    per s²) and jerk (midpoints, per s³); fw : (B, 3, 12) ``fn`` times each node's
    quadrature weight over its prior density; first : (B, 12) int64, Nd : (B, 12, 4) the
    base's uniform B-splines there (the clamped ones near the window's ends are not
    corrected here)
    """
    B = len(a)
    lo = np.empty((B, 3, 2))
    hi = np.empty((B, 3, 2))
    coef = np.empty((B, 3, 2, 4))
    nodes = np.empty((B, 12))
    fn = np.zeros((B, 3, 12))
    fw = np.empty((B, 3, 12))
    first = np.empty((B, 12), dtype=np.int64)
    Nd = np.empty((B, 12, 4))
    left = np.empty((2, 4))
    right = np.empty((2, 4))
    half = np.empty(4)
    mid = np.empty(4)
    for b in range(B):
        for row in range(2):
            av = a[b] if row == 0 else 1 - a[b]
            ap1 = av + 1
            sq = ap1 * ap1
            # (x + 1)³ / (a + 1)²
            left[row, 0] = 1.0 / sq
            left[row, 1] = 3.0 / sq
            left[row, 2] = 3.0 / sq
            left[row, 3] = 1.0 / sq
            # the power-basis products of _new_splines' _mul, term by term from 0.0
            p0 = 0.0 + 1.0 * av
            p1 = (0.0 + 1.0 * -1.0) + 2.0 * av
            p2 = (0.0 + 2.0 * -1.0) + 1.0 * av
            p3 = 0.0 + 1.0 * -1.0
            ud0 = 0.0 + 1.0 * av
            ud1 = (0.0 + 1.0 * -1.0) + 1.0 * av
            ud2 = 0.0 + 1.0 * -1.0
            q0 = 0.0 + ud0 * 0.0
            q1 = (0.0 + ud0 * 1.0) + ud1 * 0.0
            q2 = (0.0 + ud1 * 1.0) + ud2 * 0.0
            q3 = 0.0 + ud2 * 1.0
            xx0 = 0.0 + 0.0 * 0.0
            xx1 = (0.0 + 0.0 * 1.0) + 1.0 * 0.0
            xx2 = 0.0 + 1.0 * 1.0
            r0 = 0.0 + av * xx0
            r1 = (0.0 + av * xx1) + -1.0 * xx0
            r2 = (0.0 + av * xx2) + -1.0 * xx1
            r3 = 0.0 + -1.0 * xx2
            d1 = sq * av
            d2 = ap1 * (av * av)
            d3 = both3[row, b]
            right[row, 0] = p0 / d1 + q0 / d2 + r0 / d3
            right[row, 1] = p1 / d1 + q1 / d2 + r1 / d3
            right[row, 2] = p2 / d1 + q2 / d2 + r2 / d3
            right[row, 3] = p3 / d1 + q3 / d2 + r3 / d3
        ab = a[b]
        # spline 0: (-1, 0) the left piece, (0, a) the right one
        lo[b, 0, 0], hi[b, 0, 0] = -1.0, 0.0
        lo[b, 0, 1], hi[b, 0, 1] = 0.0, ab
        for d in range(4):
            coef[b, 0, 0, d] = left[0, d]
            coef[b, 0, 1, d] = right[0, d]
        # spline 1: (x / a)³ on (0, a), ((1 - x) / (1 - a))³ on (a, 1)
        lo[b, 1, 0], hi[b, 1, 0] = 0.0, ab
        lo[b, 1, 1], hi[b, 1, 1] = ab, 1.0
        coef[b, 1, 0, 0] = 0.0
        coef[b, 1, 0, 1] = 0.0
        coef[b, 1, 0, 2] = 0.0
        coef[b, 1, 0, 3] = cube[0, b]
        _reflect_into(0.0, 0.0, 0.0, cube[1, b], coef[b, 1, 1])
        # spline 2: spline 0 mirrored (x -> 1 - x, a -> 1 - a)
        lo[b, 2, 0], hi[b, 2, 0] = ab, 1.0
        lo[b, 2, 1], hi[b, 2, 1] = 1.0, 2.0
        _reflect_into(right[1, 0], right[1, 1], right[1, 2], right[1, 3], coef[b, 2, 0])
        _reflect_into(left[1, 0], left[1, 1], left[1, 2], left[1, 3], coef[b, 2, 1])
        # the prior's four sub-spans [j-1, j], [j, s], [s, j+1], [j+1, j+2]
        jb = j[b]
        jm = jb - 1
        jp = jb + 1
        l0, l1, l2, l3 = jm, jb, s[b], jp
        h0, h1, h2_, h3_ = jb, s[b], jp, jp + 1
        half[0], mid[0] = (h0 - l0) / 2, (h0 + l0) / 2
        half[1], mid[1] = (h1 - l1) / 2, (h1 + l1) / 2
        half[2], mid[2] = (h2_ - l2) / 2, (h2_ + l2) / 2
        half[3], mid[3] = (h3_ - l3) / 2, (h3_ + l3) / 2
        for p in range(4):
            nodes[b, p] = mid[p] - gauss * half[p]
            nodes[b, 4 + p] = mid[p] + gauss * half[p]
            nodes[b, 8 + p] = mid[p]
        # each new B-spline is one polynomial piece on each of its two sub-spans: p'' at the
        # sub-span's Gauss nodes, the jerk at its midpoint (_horner's operations)
        for e in range(3):
            for k in range(2):
                c = coef[b, e, k]
                sub = e + k
                dd0 = 1.0 * (2.0 * c[2])
                dd1 = 2.0 * (3.0 * c[3])
                for node in (sub, 4 + sub):
                    x = nodes[b, node] - jb
                    fn[b, e, node] = ((dd1 * 1.0) * x + dd0) / h2
                fn[b, e, 8 + sub] = ((1.0 * dd1) * 1.0) / h3
        for p in range(12):
            wq = h * (half[p % 4] / q_accel) if p < 8 else h * (2 * half[p - 8] / q_jerk)
            for e in range(3):
                fw[b, e, p] = fn[b, e, p] * wq
        # the base's uniform cubic B-splines at the nodes: p'' (Gauss nodes), jerk (mids)
        for p in range(12):
            span = np.floor(nodes[b, p])
            u = nodes[b, p] - span
            first[b, p] = int(span + K)
            if p < 8:
                Nd[b, p, 0] = (1 - u) / h2
                Nd[b, p, 1] = (3 * u - 2) / h2
                Nd[b, p, 2] = (1 - 3 * u) / h2
                Nd[b, p, 3] = u / h2
            else:
                Nd[b, p, 0] = -1.0 / h3
                Nd[b, p, 1] = 3.0 / h3
                Nd[b, p, 2] = -3.0 / h3
                Nd[b, p, 3] = 1.0 / h3
    return lo, hi, coef, nodes, fn, fw, first, Nd


@kernel(inline=True)
def _reflect_into(c0: float, c1: float, c2: float, c3: float, out: np.ndarray) -> None:
    """Coefficients of ``p(1 - x)`` from those of a cubic ``p(x)`` into ``out`` (4,)
    (:func:`pslog.estimation._breaks._reflect`'s operations)."""
    out[0] = c0 + c1 + c2 + c3
    out[1] = -c1 - 2 * c2 - 3 * c3
    out[2] = c2 + 3 * c3
    out[3] = -c3


@kernel
def trial_gather(first: np.ndarray, Nd: np.ndarray, q0: np.ndarray, x0: np.ndarray,
                 base_row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The nodes' base B-splines spread onto the six control points ``q0..q0+5`` of each
    trial (B, 12, 6) (a function ``first + a`` outside them lands on the nearest, as the
    clipped scatter did), and those control points (B, 6, 3) of its window: ``x0`` (rows,
    3) the bases' control points laid end to end, ``base_row`` (B,) the trial's window's
    first row plus ``q0``."""
    B = len(q0)
    Nd6 = np.zeros((B, 12, 6))
    x6 = np.empty((B, 6, 3))
    for b in range(B):
        for p in range(12):
            pos = first[b, p] - q0[b]
            pos = 0 if pos < 0 else (2 if pos > 2 else pos)
            for a in range(4):
                Nd6[b, p, pos + a] = Nd[b, p, a]
        for c in range(6):
            for d in range(3):
                x6[b, c, d] = x0[base_row[b] + c, d]
    return Nd6, x6


@kernel(contract=True)
def trial_prior_terms(Nd6: np.ndarray, x0: np.ndarray, fw: np.ndarray, fn: np.ndarray,
                      gravity: np.ndarray, g: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The break test's small prior products (:func:`pslog.estimation._breaks._gains`), one
    pass over B trials: ``p0 = Nd6 @ x0`` (B, 12, 3) less ``gravity`` at the 8 Gauss nodes,
    ``pyy = fw @ fnᵀ`` (B, 3, 3), ``pxy = Nd6ᵀ @ fwᵀ`` (B, 6, 3), and ``g -= fw @ p0`` in
    place (g (B, 3, 3)). Each product entry summed as numpy's matmul gets it from OpenBLAS
    for these shapes (k = 6 or 12, at most 12 rows, 3 columns): ``k`` in order from 0, each
    term a fused multiply-add (``contract``: where the CPU has none, neither has the BLAS
    kernel), then the subtraction — the same bits (tests/test_smooth_passes.py compares with
    the matmuls). Every trial's products were separate BLAS calls of a few dozen flops.

    Returns
    -------
    p0, pyy, pxy
    """
    B = Nd6.shape[0]
    p0 = np.empty((B, 12, 3))
    pyy = np.empty((B, 3, 3))
    pxy = np.empty((B, 6, 3))
    for b in range(B):
        for p in range(12):
            for d in range(3):
                acc = 0.0
                for c in range(6):
                    acc = acc + Nd6[b, p, c] * x0[b, c, d]
                p0[b, p, d] = acc - gravity[d] if p < 8 else acc
        for e in range(3):
            for f in range(3):
                acc = 0.0
                for p in range(12):
                    acc = acc + fw[b, e, p] * fn[b, f, p]
                pyy[b, e, f] = acc
        for c in range(6):
            for e in range(3):
                acc = 0.0
                for p in range(12):
                    acc = acc + Nd6[b, p, c] * fw[b, e, p]
                pxy[b, c, e] = acc
        for e in range(3):
            for d in range(3):
                acc = 0.0
                for p in range(12):
                    acc = acc + fw[b, e, p] * p0[b, p, d]
                g[b, e, d] = g[b, e, d] - acc
    return p0, pyy, pxy


@kernel
def trial_gains(Hyy: np.ndarray, Hxy: np.ndarray, pyy: np.ndarray, pxy: np.ndarray,
                cov: np.ndarray, which: np.ndarray, row0: np.ndarray, col: np.ndarray,
                g: np.ndarray) -> np.ndarray:
    """The break test's gains ``gᵀ S⁻¹ g`` (B,) in one pass per trial: the prior's terms
    ``pyy ⊗ I₃`` and ``pxy ⊗ I₃`` added to ``Hyy`` (B, 9, 9) and ``Hxy`` (B, 18, 9) (in
    place), ``S = Hyy - H_xyᵀ Σ H_xy`` with ``Σ`` the 18 x 18 block
    ``cov[which, row0 + r, col + c]`` of the trial's window's inverse information (read in
    place, symmetric: the upper triangle of the product is formed), ``(S + Sᵀ) / 2``, its
    diagonal loaded by ``1e-12 · max |diag S| + 1e-300`` (NaN if a diagonal entry is),
    then ``S y = g`` (g (B, 9)) by Gaussian elimination with partial pivoting (LAPACK
    ``dgesv``'s choice of pivots) and ``gᵀ y``. The products summed in loop order, not
    BLAS's: the gains equal numpy's form to rounding (~1e-9 relative: ``S`` is a difference
    of nearly equal terms), two numpy products, a batched LAPACK call and three passes
    fewer. NaN where ``S`` has a NaN or a zero pivot (no gain).

    Session 24 (the same bits as :func:`_trial_gains_dense`, the form before): each entry of
    ``T = Σ H_xy`` and of ``H_xyᵀ T`` is still the sum of its terms from 0 in order, but
    nine entries are summed side by side in registers (a row of ``T``, or of the product)
    where each used to wait on its previous addition through memory; and the terms that
    are exact zeros are not added. ``H_xy``'s blocks (q0, the second and third new
    B-spline) and (q0 + 5, the first and second) are zero — control point q0's B-spline
    lives on span j - 1 only and q0 + 5's on span j + 1 only, where those new B-splines
    vanish, and so do the prior's terms there — so ``s · 0`` and ``0 · t`` are ``±0``, and
    adding ``±0`` to a sum started at ``+0`` changes no bit (a sum of such terms is never
    ``-0``). That holds for finite ``s`` and ``t``: a trial whose blocks are not exactly
    zero, whose ``T`` is not finite, or whose skipped ``Σ`` entries are not finite takes
    the dense form (``_trial_gains_dense``' loops) instead. Only ``S``'s upper triangle is
    formed (rows ``i`` of the product against columns ``k >= i`` of the blocks)."""
    B = len(which)
    out = np.empty(B)
    T = np.empty((18, 9))
    S = np.empty((9, 9))
    Q = np.empty((9, 9))  # Q[i, k] = Σ_r H_xy[r, i] T[r, k], k >= i
    y = np.empty(9)
    for b in range(B):
        Hyb = Hyy[b]
        Hxb = Hxy[b]
        for i in range(3):
            for e in range(3):
                for e2 in range(3):
                    Hyb[3 * e + i, 3 * e2 + i] += pyy[b, e, e2]
                for c in range(6):
                    Hxb[3 * c + i, 3 * e + i] += pxy[b, c, e]
        w, r0, c0 = which[b], row0[b], col[b]
        sparse = True
        for r in range(3):
            for k in range(3, 9):
                if Hxb[r, k] != 0.0 or Hxb[15 + r, k - 3] != 0.0:
                    sparse = False
        if sparse:
            sparse = _sparse_products(Hxb, cov[w], r0, c0, T, Q)
        if not sparse:
            _dense_products(Hxb, cov[w], r0, c0, T, Q)
        out[b] = _schur_gain(Hyb, Q, g[b], S, y)
    return out


@kernel(inline=True)
def _sparse_products(Hxb: np.ndarray, cw: np.ndarray, r0: int, c0: int, T: np.ndarray,
                     Q: np.ndarray) -> bool:
    """:func:`trial_gains`' ``T = Σ H_xy`` and ``Q = H_xyᵀ T`` (its upper triangle) without
    the zero blocks' terms, nine sums side by side; False (T, Q unusable) where ``T`` or a
    skipped entry of ``Σ`` (``cw`` the window's inverse, rows ``r0..``, columns ``c0..``)
    is not finite."""
    total = 0.0
    for r in range(18):
        cr = cw[r0 + r]
        s0 = cr[c0]
        s1 = cr[c0 + 1]
        s2 = cr[c0 + 2]
        # columns of the first new B-spline: rows 0-14 of H_xy; of the second: 3-14; of
        # the third: 3-17
        t0 = 0.0 + s0 * Hxb[0, 0]
        t1 = 0.0 + s0 * Hxb[0, 1]
        t2 = 0.0 + s0 * Hxb[0, 2]
        t0 += s1 * Hxb[1, 0]
        t1 += s1 * Hxb[1, 1]
        t2 += s1 * Hxb[1, 2]
        t0 += s2 * Hxb[2, 0]
        t1 += s2 * Hxb[2, 1]
        t2 += s2 * Hxb[2, 2]
        t3 = 0.0
        t4 = 0.0
        t5 = 0.0
        t6 = 0.0
        t7 = 0.0
        t8 = 0.0
        for c in range(3, 15):
            s = cr[c0 + c]
            t0 += s * Hxb[c, 0]
            t1 += s * Hxb[c, 1]
            t2 += s * Hxb[c, 2]
            t3 += s * Hxb[c, 3]
            t4 += s * Hxb[c, 4]
            t5 += s * Hxb[c, 5]
            t6 += s * Hxb[c, 6]
            t7 += s * Hxb[c, 7]
            t8 += s * Hxb[c, 8]
        s15 = cr[c0 + 15]
        s16 = cr[c0 + 16]
        s17 = cr[c0 + 17]
        t6 += s15 * Hxb[15, 6]
        t7 += s15 * Hxb[15, 7]
        t8 += s15 * Hxb[15, 8]
        t6 += s16 * Hxb[16, 6]
        t7 += s16 * Hxb[16, 7]
        t8 += s16 * Hxb[16, 8]
        t6 += s17 * Hxb[17, 6]
        t7 += s17 * Hxb[17, 7]
        t8 += s17 * Hxb[17, 8]
        T[r, 0] = t0
        T[r, 1] = t1
        T[r, 2] = t2
        T[r, 3] = t3
        T[r, 4] = t4
        T[r, 5] = t5
        T[r, 6] = t6
        T[r, 7] = t7
        T[r, 8] = t8
        # not finite if any of these is (a sum's overflow only sends a trial to the dense
        # form)
        total += (((t0 + t1) + (t2 + t3)) + ((t4 + t5) + (t6 + t7))
                  + ((t8 + s0) + (s1 + s2)) + ((s15 + s16) + s17))
    if not abs(total) < np.inf:
        return False
    for i in range(3):  # rows 0-14 of H_xy's first three columns, against every column
        a0 = 0.0
        a1 = 0.0
        a2 = 0.0
        a3 = 0.0
        a4 = 0.0
        a5 = 0.0
        a6 = 0.0
        a7 = 0.0
        a8 = 0.0
        for r in range(15):
            h = Hxb[r, i]
            a0 += h * T[r, 0]
            a1 += h * T[r, 1]
            a2 += h * T[r, 2]
            a3 += h * T[r, 3]
            a4 += h * T[r, 4]
            a5 += h * T[r, 5]
            a6 += h * T[r, 6]
            a7 += h * T[r, 7]
            a8 += h * T[r, 8]
        Q[i, 0] = a0
        Q[i, 1] = a1
        Q[i, 2] = a2
        Q[i, 3] = a3
        Q[i, 4] = a4
        Q[i, 5] = a5
        Q[i, 6] = a6
        Q[i, 7] = a7
        Q[i, 8] = a8
    for i in range(3, 6):  # rows 3-14, against columns 3-8
        a3 = 0.0
        a4 = 0.0
        a5 = 0.0
        a6 = 0.0
        a7 = 0.0
        a8 = 0.0
        for r in range(3, 15):
            h = Hxb[r, i]
            a3 += h * T[r, 3]
            a4 += h * T[r, 4]
            a5 += h * T[r, 5]
            a6 += h * T[r, 6]
            a7 += h * T[r, 7]
            a8 += h * T[r, 8]
        Q[i, 3] = a3
        Q[i, 4] = a4
        Q[i, 5] = a5
        Q[i, 6] = a6
        Q[i, 7] = a7
        Q[i, 8] = a8
    for i in range(6, 9):  # rows 3-17, against columns 6-8
        a6 = 0.0
        a7 = 0.0
        a8 = 0.0
        for r in range(3, 18):
            h = Hxb[r, i]
            a6 += h * T[r, 6]
            a7 += h * T[r, 7]
            a8 += h * T[r, 8]
        Q[i, 6] = a6
        Q[i, 7] = a7
        Q[i, 8] = a8
    return True


@kernel(inline=True)
def _dense_products(Hxb: np.ndarray, cw: np.ndarray, r0: int, c0: int, T: np.ndarray,
                    Q: np.ndarray) -> None:
    """:func:`trial_gains`' ``T`` and ``Q`` with every term (the form before session 24)."""
    for r in range(18):
        for k in range(9):
            T[r, k] = 0.0
        for c in range(18):
            s_rc = cw[r0 + r, c0 + c]
            for k in range(9):
                T[r, k] += s_rc * Hxb[c, k]
    for i in range(9):
        for k in range(i, 9):
            acc = 0.0
            for r in range(18):
                acc += Hxb[r, i] * T[r, k]
            Q[i, k] = acc


@kernel(inline=True)
def _schur_gain(Hyb: np.ndarray, Q: np.ndarray, gb: np.ndarray, S: np.ndarray,
                y: np.ndarray) -> float:
    """``S = Hyy - Q`` symmetrised, its diagonal loaded, ``S y = g`` and ``gᵀ y``
    (:func:`trial_gains`); NaN where ``S`` has a NaN or a zero pivot."""
    for i in range(9):
        for k in range(i, 9):
            acc = Q[i, k]
            v = (Hyb[i, k] - acc + Hyb[k, i] - acc) / 2 if k > i else Hyb[i, i] - acc
            S[i, k] = v
            S[k, i] = v
    big = 0.0
    nan = False
    for i in range(9):
        a = abs(S[i, i])
        if a != a:
            nan = True
        elif a > big:
            big = a
    load = (np.nan if nan else 1e-12 * big) + 1e-300
    for i in range(9):
        S[i, i] += load
        y[i] = gb[i]
    # elimination with partial pivoting, then back substitution
    if nan:
        return np.nan
    for k in range(9):
        p = k
        best = abs(S[k, k])
        for i in range(k + 1, 9):
            if abs(S[i, k]) > best:
                best = abs(S[i, k])
                p = i
        if not best > 0.0:
            return np.nan
        if p != k:
            for c in range(9):
                S[k, c], S[p, c] = S[p, c], S[k, c]
            y[k], y[p] = y[p], y[k]
        for i in range(k + 1, 9):
            f = S[i, k] / S[k, k]
            for c in range(k + 1, 9):
                S[i, c] -= f * S[k, c]
            y[i] -= f * y[k]
    for i in range(8, -1, -1):
        acc = y[i]
        for c in range(i + 1, 9):
            acc -= S[i, c] * y[c]
        y[i] = acc / S[i, i]
    gain = 0.0
    for i in range(9):
        gain += gb[i] * y[i]
    return gain


@kernel
def _trial_gains_dense(Hyy: np.ndarray, Hxy: np.ndarray, pyy: np.ndarray, pxy: np.ndarray,
                       cov: np.ndarray, which: np.ndarray, row0: np.ndarray, col: np.ndarray,
                       g: np.ndarray) -> np.ndarray:
    """:func:`trial_gains` with every term of every product (its form before session 24;
    the reference its tests compare with, bit for bit)."""
    B = len(which)
    out = np.empty(B)
    T = np.empty((18, 9))
    S = np.empty((9, 9))
    Q = np.empty((9, 9))
    y = np.empty(9)
    for b in range(B):
        Hyb = Hyy[b]
        Hxb = Hxy[b]
        for i in range(3):
            for e in range(3):
                for e2 in range(3):
                    Hyb[3 * e + i, 3 * e2 + i] += pyy[b, e, e2]
                for c in range(6):
                    Hxb[3 * c + i, 3 * e + i] += pxy[b, c, e]
        _dense_products(Hxb, cov[which[b]], row0[b], col[b], T, Q)
        out[b] = _schur_gain(Hyb, Q, g[b], S, y)
    return out


@kernel
def prior_band(ab_accel: np.ndarray, ab_jerk: np.ndarray, q_accel: float, q_jerk: float
               ) -> np.ndarray:
    """The motion prior's band ``ab_accel / q_accel + ab_jerk / q_jerk`` (12, n), in one pass
    (the numpy form's two temporaries of a whole session's band)."""
    rows, n = ab_accel.shape
    out = np.empty((rows, n))
    for r in range(rows):
        for i in range(n):
            out[r, i] = ab_accel[r, i] / q_accel + ab_jerk[r, i] / q_jerk
    return out


@kernel
def prior_band_sums(sums_accel: np.ndarray, sums_jerk: np.ndarray, m: int, q_accel: float,
                    q_jerk: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`prior_band` of the bands :func:`points_normal_isotropic` forms, from their
    compact :func:`prior_sums` (m + 3, 4) each: every entry the same expression on the same
    values (``(0.0 + s_a) / q_accel + (0.0 + s_j) / q_jerk`` where a pair of control points
    reaches it, ``0.0 / q_accel + 0.0 / q_jerk`` elsewhere), so the same bits, reading
    2 x 4 numbers per control point instead of 2 x 36.

    Returns
    -------
    band : (12, 3m); values : (m, 4) the band's distinct entries, ``values[p, k]`` the one of
    control points ``p`` and ``p + k`` (zero where ``p + k >= m``), for :func:`prior_matvec`
    """
    n = 3 * m
    out = np.empty((12, n))
    values = np.zeros((m, 4))
    zero = 0.0 / q_accel + 0.0 / q_jerk
    for r in range(12):
        if r % 3 != 2:  # rows 11 - 3k alone hold sums
            for i in range(n):
                out[r, i] = zero
    for k in range(4):
        row = 11 - 3 * k
        for i in range(min(3 * k, n)):  # the columns of control points below k: no pair
            out[row, i] = zero
        for p in range(m - k):
            value = (0.0 + sums_accel[p, k]) / q_accel + (0.0 + sums_jerk[p, k]) / q_jerk
            values[p, k] = value
            c = 3 * (p + k)
            out[row, c] = value
            out[row, c + 1] = value
            out[row, c + 2] = value
    return out, values


@kernel
def prior_matvec(values: np.ndarray, x: np.ndarray) -> np.ndarray:
    """:func:`band_matvec` of the prior's band from its distinct entries ``values`` (m, 4)
    (:func:`prior_band_sums`), ``x`` (3m,): the band is zero but on its diagonals ``3k``
    (entry ``values[p, k]`` at rows ``3p + d``, columns ``3(p + k) + d``), so each entry of
    ``A x`` is the diagonal's term, then per ``k = 1, 2, 3`` the term above and the term below
    — :func:`band_matvec`'s nonzero terms in its order, without its ``+0`` products
    (``s + 0·x`` is ``s`` for a finite ``x``, but for the sign of a zero ``s``), reading
    4 numbers per control point instead of 12 x 3."""
    n = len(x)
    out = np.empty(n)
    for i in range(n):
        p = i // 3
        acc = values[p, 0] * x[i]
        for k in range(1, 4):
            d = 3 * k
            if i + d < n:
                acc += values[p, k] * x[i + d]
            if i - d >= 0:
                acc += values[p - k, k] * x[i - d]
        out[i] = acc
    return out


@kernel
def prior_pull(first: np.ndarray, w: np.ndarray, N: np.ndarray, m: int) -> np.ndarray:
    """``Σ_i w_i N_i,a`` added to control point ``first_i + a`` (m + 3,), for ``a`` = 0..3
    and then the terms in order (the order ``np.add.at`` added them in: the same bits)."""
    pull = np.zeros(m + 3)
    for a in range(4):
        for i in range(len(first)):
            pull[first[i] + a] += w[i] * N[i, a]
    return pull


@kernel
def search_right(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``np.searchsorted(a, v, side="right")`` (n,) int64 for ``a`` sorted without NaN:
    each ``v`` the count of ``a``'s entries at most it (a NaN: all of them), found by a
    galloping search from the previous answer (Bentley & Yao, IPL 5(3), 1976) — a knot
    vector searched for times in runs of increasing ones (a fit's detections, the prior's
    nodes) takes one or two steps a time where a binary search over the rest takes ~17
    (session 44). The same integers: the first index whose entry exceeds ``v``."""
    n = len(a)
    out = np.empty(len(v), dtype=np.int64)
    j = 0
    for i in range(len(v)):
        x = v[i]
        # pred(k): k == n or a[k] > x, False then True over k = 0..n; the answer is the
        # first k where it holds
        if j == n or a[j] > x:
            hi = j
            lo = j - 1
            step = 1
            while lo >= 0 and a[lo] > x:
                hi = lo
                step *= 2
                lo = hi - step
            if lo < -1:
                lo = -1
        else:
            lo = j
            hi = j + 1
            step = 1
            while hi < n and not a[hi] > x:
                lo = hi
                step *= 2
                hi = lo + step
            if hi > n:
                hi = n
        while hi - lo > 1:  # pred(lo) False (or lo = -1), pred(hi) True
            mid = (lo + hi) // 2
            if mid == n or a[mid] > x:
                hi = mid
            else:
                lo = mid
        out[i] = hi
        j = hi
    return out


@kernel
def abs_median_finite_rows(r: np.ndarray) -> tuple[float, int]:
    """``np.median(np.abs(r[rows with every entry finite]))`` of ``r`` (n, d) and the number
    of those rows, in one pass and a selection (no masked copy, absolute copy and
    partition's copy of a whole session's residuals): the order statistics are the same
    values, and the middle two are averaged as ``np.median`` does (``(a + b) / 2``).
    The median is NaN when no row is finite."""
    n, d = r.shape
    buf = np.empty(n * d)
    size = 0
    rows = 0
    for i in range(n):
        ok = True
        for k in range(d):
            if not np.isfinite(r[i, k]):
                ok = False
        if ok:
            for k in range(d):
                buf[size] = abs(r[i, k])
                size += 1
            rows += 1
    if size == 0:
        return np.nan, 0
    half = size // 2
    # a large set: the two middle order statistics from the values between two of an
    # evenly spaced sample's order statistics that bracket them (Floyd & Rivest, CACM 18(3),
    # 1975: the same values as a selection over all, in one pass over them and a selection
    # over a fraction). The sample ~1,024 values (from 65,536 values on, ~16,384: the
    # bracket, 6 standard deviations of the median's rank in the sample either side, then
    # holds ~5 % of the values where ~1,024's held ~19 %; session 44: 12 -> ~8 ms a call at
    # 90 minutes)
    if size >= 4096:
        big = size >= 65536
        step = size // (16384 if big else 1024)
        reach = 384 if big else 96
        sample = np.sort(buf[:size:step])
        ns = len(sample)
        at = (half * ns) // size
        below_v = sample[max(at - reach, 0)]
        above_v = sample[min(at + reach, ns - 1)]
        below = 0
        inner = np.empty(size)
        count = 0
        for i in range(size):
            # (no branch on the value: each is stored at the next free place, which moves
            # on only for a value inside the bracket; the same values in the same order)
            v = buf[i]
            below += v < below_v
            inner[count] = v
            count += (v >= below_v) & (v <= above_v)
        lo_rank = half - 1 if size % 2 == 0 else half
        if below <= lo_rank and below + count > half:
            upper = _select(inner, count, half - below)
            if size % 2 == 1:
                return upper, rows
            lower = inner[0]
            for i in range(1, half - below):
                if inner[i] > lower:
                    lower = inner[i]
            return (lower + upper) / 2, rows
    upper = _select(buf, size, half)
    if size % 2 == 1:
        return upper, rows
    # the largest of the lower half (all at most the selected one after the selection)
    lower = buf[0]
    for i in range(1, half):
        if buf[i] > lower:
            lower = buf[i]
    return (lower + upper) / 2, rows


@kernel
def _select(buf: np.ndarray, size: int, k: int) -> float:
    """The ``k``-th smallest of ``buf[:size]`` (0-based, finite values), by quickselect
    with a median-of-three pivot and a three-way partition (Dijkstra's Dutch national flag:
    values equal to the pivot are settled at once, so many equal values — zero residuals —
    take linear time, not quadratic); ``buf`` is reordered so that ``buf[:k]`` holds values
    at most it and ``buf[k+1:size]`` values at least it."""
    lo, hi = 0, size - 1
    while hi > lo:
        mid = (lo + hi) // 2
        # median of three to buf[hi]
        if buf[mid] < buf[lo]:
            buf[mid], buf[lo] = buf[lo], buf[mid]
        if buf[hi] < buf[lo]:
            buf[hi], buf[lo] = buf[lo], buf[hi]
        if buf[mid] < buf[hi]:
            buf[mid], buf[hi] = buf[hi], buf[mid]
        pivot = buf[hi]
        # buf[lo:lt] < pivot, buf[lt:i] == pivot, buf[gt+1:hi+1] > pivot
        lt, i, gt = lo, lo, hi
        while i <= gt:
            v = buf[i]
            if v < pivot:
                buf[lt], buf[i] = buf[i], buf[lt]
                lt += 1
                i += 1
            elif v > pivot:
                buf[gt], buf[i] = buf[i], buf[gt]
                gt -= 1
            else:
                i += 1
        if k < lt:
            hi = lt - 1
        elif k > gt:
            lo = gt + 1
        else:
            return pivot
    return buf[k]


@kernel
def scaled_norms(r: np.ndarray, sigma2: float) -> np.ndarray:
    """``np.sum(r * r, axis=1) / sigma2`` (n,) of ``r`` (n, 2), one pass (numpy's sum of
    two: ``r0² + r1²``; the same bits)."""
    n = r.shape[0]
    out = np.empty(n)
    for i in range(n):
        out[i] = (r[i, 0] * r[i, 0] + r[i, 1] * r[i, 1]) / sigma2
    return out


@kernel
def linear_target(J: np.ndarray, X: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``einsum("naj,nj->na", J, X) - r`` (n, 2): the linearised measurements ``J X - r``,
    one pass. The three products are added as numpy's einsum adds them here (its
    sum-of-products loop: ``(p0 + p2) + p1``; the same bits, measured on whole sessions)."""
    n = r.shape[0]
    out = np.empty((n, 2))
    for i in range(n):
        for a in range(2):
            out[i, a] = ((J[i, a, 0] * X[i, 0] + J[i, a, 2] * X[i, 2])
                         + J[i, a, 1] * X[i, 1]) - r[i, a]
    return out


@kernel
def band_matvec(ab: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A x`` (n,) of the symmetric band ``ab`` (12, n) (upper storage,
    :mod:`pslog.estimation._normal`): each entry the diagonal's term, then per
    super-diagonal ``d = 1..11`` the term above and the term below (the order of
    :func:`pslog.estimation.trajectory._prior_cost`'s numpy passes: the same bits)."""
    rows, n = ab.shape
    u = rows - 1
    out = np.empty(n)
    # inside, every term is there: four entries at a time, each its own running sum of the
    # same terms in the same order (four chains overlap instead of one waiting on its
    # previous addition); the ends test each term
    i = 0
    while i < n:
        if u <= i and i + 3 < n - u:
            a0 = ab[u, i] * x[i]
            a1 = ab[u, i + 1] * x[i + 1]
            a2 = ab[u, i + 2] * x[i + 2]
            a3 = ab[u, i + 3] * x[i + 3]
            for d in range(1, rows):
                row = u - d
                a0 += ab[row, i + d] * x[i + d]
                a0 += ab[row, i] * x[i - d]
                a1 += ab[row, i + 1 + d] * x[i + 1 + d]
                a1 += ab[row, i + 1] * x[i + 1 - d]
                a2 += ab[row, i + 2 + d] * x[i + 2 + d]
                a2 += ab[row, i + 2] * x[i + 2 - d]
                a3 += ab[row, i + 3 + d] * x[i + 3 + d]
                a3 += ab[row, i + 3] * x[i + 3 - d]
            out[i] = a0
            out[i + 1] = a1
            out[i + 2] = a2
            out[i + 3] = a3
            i += 4
            continue
        acc = ab[u, i] * x[i]
        for d in range(1, rows):
            if i + d < n:
                acc += ab[u - d, i + d] * x[i + d]
            if i - d >= 0:
                acc += ab[u - d, i] * x[i - d]
        out[i] = acc
        i += 1
    return out


@kernel
def hat_diagonal(J: np.ndarray, cov: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``w_n tr(J_n Σ_n J_nᵀ)`` (n,) of Jacobians (n, 2, 3), marginal covariances (n, 3, 3)
    and weights (n,) (``w * np.einsum("naj,njk,nak->n", J, cov, J)``), one pass: per row
    the sum over ``a, j, k`` in that order."""
    n = J.shape[0]
    out = np.empty(n)
    for i in range(n):
        acc = 0.0
        for a in range(2):
            for j in range(3):
                for k in range(3):
                    acc += J[i, a, j] * cov[i, j, k] * J[i, a, k]
        out[i] = w[i] * acc
    return out
