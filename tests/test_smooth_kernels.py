"""The compiled kernels of the smooth trajectory estimator (pslog/estimation/_kernels.py):
each against its pure-Python original (``kernel.py_func``) and against the numpy form it
replaced (the dense or sparse products, written out here), bit for bit where the sums run in
the same order."""

from __future__ import annotations

import numpy as np
import pytest
from _bits import assert_blas_bits
from numpy.testing import assert_allclose, assert_array_equal
from scipy.interpolate import BSpline
from scipy.sparse import csr_matrix

from pslog.estimation import _breaks, _kernels, _normal
from pslog.estimation import trajectory as T
from pslog.estimation.bspline import basis, basis_derivative, clamped_knots, n_control, span_index


def _knots():
    return clamped_knots(np.array([0.0, 0.1, 0.25, 0.3, 0.45, 0.6, 0.62, 0.8]),
                         np.array([1, 3, 1, 1, 3, 1]))


@pytest.mark.parametrize("nd", [0, 1, 2, 3])
def test_basis_kernel_is_its_python_original_and_scipy(nd):
    knots = _knots()
    t = np.r_[np.linspace(0.0, 0.8, 301), 0.25, 0.6, 0.8]
    j = span_index(knots, t)
    compiled = _kernels.basis_in_span(knots, j, t, nd)
    assert_array_equal(compiled, _kernels.basis_in_span.py_func(knots, j, t, nd))
    control = np.random.default_rng(nd).normal(size=(n_control(knots), 3))
    first, values = basis(knots, t, nd)
    index = first[:, None] + np.arange(4)
    for d in range(nd + 1):
        ours = np.einsum("na,nad->nd", values[:, d], control[index])
        ref = BSpline(knots, control, 3)(t, nu=d)
        assert_allclose(ours, ref, rtol=1e-10, atol=1e-9 * np.abs(ref).max())


def test_basis_derivative_is_that_row_of_the_whole_basis():
    """One derivative per point (the prior's nodes): the same bits as the row of every
    derivative's basis, compiled and its Python original; a wrong row is caught."""
    knots = _knots()
    t = np.r_[np.linspace(0.0, 0.8, 97), 0.25, 0.6, 0.8]
    which = np.arange(len(t)) % 4
    first, values = basis(knots, t, 3)
    f1, one = basis_derivative(knots, t, which)
    assert_array_equal(f1, first)
    assert_array_equal(one, values[np.arange(len(t)), which])
    j = span_index(knots, t)
    assert_array_equal(_kernels.basis_derivative_in_span.py_func(knots, j, t, which), one)
    # by hand: a uniform cubic's second derivative at a knot is (1, -2, 1, 0) / h²
    u = clamped_knots(np.arange(9.0) * 0.5)
    _, d2 = basis_derivative(u, np.array([2.0]), np.array([2]))
    assert_allclose(d2[0], np.array([1.0, -2.0, 1.0, 0.0]) / 0.25, atol=1e-12)


def _sparse_points(first, N, m):
    """The sparse matrices ``Points`` used before its compiled passes (the reference)."""
    pairs = [(a, b) for a in range(4) for b in range(a, 4)]
    PA, PB = np.array([a for a, _ in pairs]), np.array([b for _, b in pairs])
    r = len(first)
    G = csr_matrix(((np.take(N, PA, axis=1) * np.take(N, PB, axis=1)).ravel(),
                    ((4 * (first[:, None] + PA) + (PB - PA)).ravel(), np.repeat(np.arange(r), 10))),
                   shape=(4 * (m + 3), r))
    B = csr_matrix((N.ravel(), (first[:, None] + np.arange(4)).ravel(),
                    np.arange(0, 4 * r + 1, 4)), shape=(r, m))
    return G, B


def _points_case(seed=0, r=400, m=40):
    rng = np.random.default_rng(seed)
    first = np.sort(rng.integers(0, m - 3, r))
    N = rng.random((r, 4))
    A = rng.normal(size=(r, 3, 3))
    M = A @ np.swapaxes(A, 1, 2)
    v = rng.normal(size=(r, 3))
    return first, N, M, v, m


def _reference_normal(G, B, M, v, m):
    """The points' normal equations from the sparse products, laid into a random band and
    right-hand side: ``(upper, ab0, rhs0, ab, rhs)`` (``upper``: M's 6 distinct entries;
    ``ab0``, ``rhs0``: the band and vector before; ``ab``, ``rhs``: after)."""
    upper = np.take(M.reshape(-1, 9), [0, 1, 2, 4, 5, 8], axis=1)
    # G @ upper, expanded to 3 x 3 blocks and laid into the band
    blocks = np.take(G @ upper, [0, 1, 2, 1, 3, 4, 2, 4, 5], axis=1).reshape(m + 3, 4, 3, 3)
    ab0 = np.random.default_rng(2).normal(size=(12, 3 * m))
    rhs0 = np.random.default_rng(3).normal(size=3 * m)
    ab = ab0.copy()
    for k in range(4):
        for d in range(3):
            for e in range(3):
                off = 3 * k + e - d
                if off >= 0:
                    ab[11 - off, 3 * k + e::3][:m - k] += blocks[:m - k, k, d, e]
    return upper, ab0, rhs0, ab, rhs0 + (B.T.tocsr() @ v).reshape(-1)


def test_points_passes_are_the_sparse_products_bit_for_bit():
    first, N, M, v, m = _points_case()
    G, B = _sparse_points(first, N, m)
    points = _normal.Points(first, N, m)
    control = np.random.default_rng(1).normal(size=(m, 3))
    assert_array_equal(points.positions(control), B @ control)
    _, ab0, rhs0, ref_ab, ref_rhs = _reference_normal(G, B, M, v, m)
    ab, rhs = points.normal(M, v, ab0.copy(), rhs0.copy())
    assert_array_equal(ab, ref_ab)
    assert_array_equal(rhs, ref_rhs)
    # marginals: Gᵀ times the band with the off-diagonal blocks' transposes added
    band = np.random.default_rng(4).normal(size=(m, 4, 3, 3))
    both = np.zeros((m + 3, 4, 3, 3))
    both[:m] = band
    both[:, 1:] += np.swapaxes(both[:, 1:], 2, 3)
    ref = (G.T @ both.reshape(-1, 9)).reshape(-1, 3, 3)
    assert_array_equal(points.marginal(band), ref)
    assert_allclose(points.marginal(band), _normal.marginal(band, first, N), rtol=1e-12,
                    atol=1e-12)


def test_points_kernels_are_their_python_originals():
    first, N, M, v, m = _points_case(5, r=60, m=12)
    upper = np.take(M.reshape(-1, 9), [0, 1, 2, 4, 5, 8], axis=1)
    a1, r1 = np.zeros((12, 3 * m)), np.zeros(3 * m)
    a2, r2 = np.zeros((12, 3 * m)), np.zeros(3 * m)
    _kernels.points_normal(first, N, upper, v, m, a1, r1)
    _kernels.points_normal.py_func(first, N, upper, v, m, a2, r2)
    assert_array_equal(a1, a2)
    assert_array_equal(r1, r2)
    control = np.random.default_rng(6).normal(size=(m, 3))
    assert_array_equal(_kernels.points_positions(first, N, control),
                       _kernels.points_positions.py_func(first, N, control))
    band = np.random.default_rng(7).normal(size=(m, 4, 3, 3))
    assert_array_equal(_kernels.points_marginal(first, N, band),
                       _kernels.points_marginal.py_func(first, N, band))


def _window_case(seed=0):
    """A batch of break-test windows as :func:`_breaks.scan` builds them."""
    rng = np.random.default_rng(seed)
    h = 0.011
    t = np.sort(rng.uniform(0.0, 0.4, 90))
    J = rng.normal(size=(90, 2, 3)) * 300
    z = rng.normal(size=(90, 2))
    w = rng.uniform(0.5, 4.0, 90)
    centers = np.array([0.1, 0.2, 0.27])
    from pslog.estimation.trajectory import MotionPrior

    prior = MotionPrior()
    K = 6
    local = _breaks._local(K, h, prior, 1)
    lo, hi = centers - 5 * h, centers + 5 * h
    i0, i1 = np.searchsorted(t, lo), np.searchsorted(t, hi, side="right")
    W = int(np.max(i1 - i0))
    index = np.minimum(i0[:, None] + np.arange(W), len(t) - 1)
    valid = i0[:, None] + np.arange(W) < i1[:, None]
    return local, t, J, z, w, index, valid, centers, h, prior


def test_window_normal_is_the_dense_basis_product():
    local, t, J, z, w, index, valid, centre, h, _ = _window_case()
    base = _breaks._Base(local, t, J, z, w, index, valid, centre, h)
    B, W = index.shape
    m = local.m
    # the dense form it replaced: H = P + Bᵀ (M ⊗) B with the basis as a (B, W, m) matrix
    basis_w = np.zeros((B, W, m))
    for b in range(B):
        for k in range(W):
            basis_w[b, k, base.first[b, k]:base.first[b, k] + 4] = base.N[b, k]
    inside = base.s_sorted < 1e5
    Mi = np.where(inside[..., None, None], base.M, 0.0)
    H = local.P + np.einsum("bwp,bwik,bwq->bpiqk", basis_w, Mi, basis_w).reshape(B, 3 * m, 3 * m)
    v = np.einsum("bwai,bwa,bw->bwi", J[index], z[index], np.where(inside, w[index], 0.0))
    rhs = np.einsum("bwp,bwi->bpi", basis_w, v).reshape(B, -1) + local.rhs
    Hk, rk = _kernels.window_normal(local.P, local.rhs, base.first, base.N, base.M,
                                    np.ascontiguousarray(v), inside)
    assert_allclose(Hk, H, rtol=1e-12, atol=1e-9 * np.abs(H).max())
    assert_allclose(rk, rhs, rtol=1e-12, atol=1e-9 * np.abs(rhs).max())
    Hp, rp = _kernels.window_normal.py_func(local.P, local.rhs, base.first, base.N, base.M,
                                            np.ascontiguousarray(v), inside)
    assert_array_equal(Hk, Hp)
    assert_array_equal(rk, rp)
    # the base's minimum solves them: X0 = basis x0 at the detections
    x = np.linalg.solve(H, rhs[..., None])[..., 0].reshape(B, -1, 3)
    assert_allclose(base.x0, x, rtol=1e-6, atol=1e-9 * np.abs(x).max())


def test_gains_data_is_the_sum_over_the_window_and_its_python_original():
    local, t, J, z, w, index, valid, centre, h, _ = _window_case(3)
    both = np.r_[centre, centre + h / 2]
    base = _breaks._Base(local, t, J, z, w, np.r_[index, index], np.r_[valid, valid], both, h)
    which = np.array([0, 1, 2, 3, 4, 5, 1])
    tau = both[which] + np.array([0.3, -1.2, 0.7, 0.45, -0.2, 1.3, 0.05]) * h
    s = (tau - both[which]) / h
    j = np.floor(s)
    q0 = (j + local.K - 1).astype(np.int64)
    pieces = _breaks._new_splines(s - j)
    lo, hi, coef = np.empty((7, 3, 2)), np.empty((7, 3, 2)), np.empty((7, 3, 2, 4))
    for e, spline in enumerate(pieces):
        for k, (a, b, c) in enumerate(spline):
            lo[:, e, k], hi[:, e, k] = a, b
            coef[:, e, k] = np.stack(c, axis=1)
    args = (base.s_sorted, base.first, base.N, base.M, base.u, which, j, q0, lo, hi, coef)
    Hyy, Hxy, g = _kernels.gains_data(*args)
    for got, ref in zip((Hyy, Hxy, g), _kernels.gains_data.py_func(*args), strict=True):
        assert_array_equal(got, ref)
    # by hand: every detection of the window on spans j-1..j+1, the new B-splines by Horner
    for b in range(7):
        ref_yy, ref_xy, ref_g = np.zeros((9, 9)), np.zeros((18, 9)), np.zeros((3, 3))
        for k in range(base.s_sorted.shape[1]):
            x = base.s_sorted[which[b], k] - j[b]
            if not -1 <= x < 2:
                continue
            f = np.zeros(3)
            for e in range(3):
                for p in range(2):
                    if lo[b, e, p] <= x < hi[b, e, p]:
                        f[e] = np.polyval(coef[b, e, p][::-1], x)
            old = np.zeros(6)
            for a in range(4):
                c = base.first[which[b], k] + a - q0[b]
                if 0 <= c < 6:
                    old[c] = base.N[which[b], k, a]
            Mw = base.M[which[b], k]
            ref_yy += np.kron(np.outer(f, f), Mw)
            ref_xy += np.kron(np.outer(old, f), Mw)
            ref_g += np.outer(f, base.u[which[b], k])
        assert np.abs(ref_yy).max() > 0
        assert_allclose(Hyy[b], ref_yy, rtol=1e-10, atol=1e-10 * np.abs(ref_yy).max())
        assert_allclose(Hxy[b], ref_xy, rtol=1e-10, atol=1e-10 * np.abs(ref_xy).max())
        assert_allclose(g[b], ref_g, rtol=1e-10, atol=1e-10 * np.abs(ref_g).max())


def test_nearest_distance_is_the_minimum_over_every_pair():
    rng = np.random.default_rng(9)
    x = rng.uniform(-1, 11, 500)
    known = rng.uniform(0, 10, 37)
    brute = np.min(np.abs(x[:, None] - known[None, :]), axis=1)
    assert_array_equal(T._nearest_distance(x, known), brute)
    assert_array_equal(T._nearest_distance(x, known[::-1]), brute)  # unsorted input
    assert np.all(np.isinf(T._nearest_distance(x, np.zeros(0))))


def test_takahashi_kernel_is_its_python_original_and_the_dense_inverse():
    rng = np.random.default_rng(11)
    m, r = 30, 240
    first = rng.integers(0, m - 3, r)
    J = rng.normal(size=(r, 2, 3))
    ab, _ = _normal.accumulate_points(first, rng.random((r, 4)),
                                      np.einsum("nai,naj->nij", J, J), np.zeros((r, 3)), m)
    ab[11] += 1e-3
    U = _normal.factor(ab)
    n = 3 * m
    right = np.zeros((n, 11))
    for d in range(1, 12):
        right[: n - d, d - 1] = U[11 - d, d:]
    rows = _kernels.takahashi_rows(np.ascontiguousarray(U[11]), right)
    assert_array_equal(rows, _kernels.takahashi_rows.py_func(np.ascontiguousarray(U[11]),
                                                             right))
    dense = np.zeros((n, n))
    for d in range(12):
        i = np.arange(n - d)
        dense[i, i + d] = dense[i + d, i] = ab[11 - d, d:]
    cov = np.linalg.inv(dense)
    scale = np.abs(cov).max()
    for j in range(12):
        i = np.arange(n - j)
        assert_allclose(rows[i, j], cov[i, i + j], rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("m, seed", [(4, 0), (5, 1), (30, 2), (400, 3)])
def test_takahashi_band_is_the_rows_recurrence_and_the_dense_inverse(m, seed):
    """The one-pass covariance band (a ring of 12 rows, blocks read out as their rows are
    done) is the whole-rows recurrence and its read-out to the last bit, and the dense
    inverse's band; its Python original is the Python originals' chain."""
    rng = np.random.default_rng(seed)
    r = 8 * m
    first = np.sort(rng.integers(0, m - 3, r))
    J = rng.normal(size=(r, 2, 3)) * 10.0 ** rng.uniform(-2, 3, (r, 1, 1))
    ab, _ = _normal.accumulate_points(first, rng.random((r, 4)),
                                      np.einsum("nai,naj->nij", J, J), np.zeros((r, 3)), m)
    ab[11] += 1e-3
    U = _normal.factor(ab)
    band = _normal.covariance_band(U)
    assert_array_equal(band, _normal.covariance_band_rows(U))
    n = 3 * m
    right = np.zeros((n, 11))
    for d in range(1, min(12, n)):
        right[: n - d, d - 1] = U[11 - d, d:]
    rows = _kernels.takahashi_rows.py_func(np.ascontiguousarray(U[11]), right)
    assert_array_equal(_kernels.takahashi_band.py_func(U, m),
                       _kernels.band_from_rows.py_func(rows, m))
    dense = np.zeros((n, n))
    for d in range(12):
        i = np.arange(n - d)
        dense[i, i + d] = dense[i + d, i] = ab[11 - d, d:]
    cov = np.linalg.inv(dense)
    scale = np.abs(cov).max()  # (once: the loop's 1,600 asserts took 3 s recomputing it)
    for i in range(m):
        for k in range(4):
            want = (cov[3 * i:3 * i + 3, 3 * (i + k):3 * (i + k) + 3] if i + k < m
                    else np.zeros((3, 3)))
            assert_allclose(band[i, k], want, rtol=0, atol=1e-9 * scale)


def test_window_solve_is_the_dense_solve_and_refuses_a_non_positive_pivot():
    local, t, J, z, w, index, valid, centre, h, _ = _window_case(4)
    base = _breaks._Base(local, t, J, z, w, index, valid, centre, h)
    B = len(index)
    v = np.ascontiguousarray(np.einsum("bwai,bwa,bw->bwi", J[index], z[index],
                                       np.where(base.s_sorted < 1e5, w[index], 0.0)))
    H, rhs = _kernels.window_normal(local.P, local.rhs, base.first, base.N, base.M, v,
                                    base.s_sorted < 1e5)
    n = H.shape[1]
    lo, hi = 9, 36
    x, cov, ok = _kernels.window_solve(H, rhs, lo, hi)
    assert ok.all()
    inverse = np.linalg.inv(H)
    # the rows and columns lo..hi-1 of the inverse (the rows before lo are not computed)
    assert_allclose(cov[:, lo:], inverse[:, lo:, lo:hi], rtol=1e-8,
                    atol=1e-10 * np.abs(inverse).max())
    assert_array_equal(cov[:, :lo], 0.0)
    ref = np.linalg.solve(H, rhs[..., None])[..., 0]
    assert_allclose(x, ref, rtol=1e-8, atol=1e-10 * np.abs(ref).max())
    for got, want in zip((x, cov, ok), _kernels.window_solve.py_func(H, rhs, lo, hi),
                         strict=True):
        assert_array_equal(got, want)
    # the base solved its windows this way (its diagonal loaded by 1e-12): the dense minimum
    loaded = H.copy()
    loaded[:, np.arange(n), np.arange(n)] *= 1 + 1e-12
    ref = np.linalg.solve(loaded, rhs[..., None])[..., 0]
    assert_allclose(base.x0.reshape(B, -1), ref, rtol=1e-8, atol=1e-10 * np.abs(ref).max())
    bad = H.copy()
    bad[1, n // 2, n // 2] = -1.0  # not positive definite
    _, _, ok = _kernels.window_solve(bad, rhs, lo, hi)
    assert_array_equal(ok, [True, False, True])



def test_window_normal_solve_is_the_normal_then_the_solve_bit_for_bit():
    """The fused pass (a window's normal matrix built in a work array, its lower band only,
    then solved) gives the bits of window_normal, the diagonal times 1 + 1e-12 and
    window_solve; a window whose matrix is not positive definite is flagged, not solved, and
    the base solves it by LU on the matrix window_normal builds (the dense minimum)."""
    local, t, J, z, w, index, valid, centre, h, _ = _window_case(5)
    w = w.copy()
    # window 1's detections weighed negatively: its normal matrix is not positive definite
    inside1 = np.zeros(len(t), bool)
    inside1[index[1][valid[1]]] = True
    inside1[index[0][valid[0]]] = False
    inside1[index[2][valid[2]]] = False
    w[inside1] = -1e6
    base = _breaks._Base(local, t, J, z, w, index, valid, centre, h)
    inside = base.s_sorted < 1e5
    # w Jᵀ z as the base forms it
    wJ = np.where(inside, w[index], 0.0)[..., None, None] * J[index]
    v = np.ascontiguousarray(np.einsum("bwai,bwa->bwi", wJ, z[index]))
    args = (local.P, local.rhs, base.first, base.N, base.M, v, inside)
    H, rhs = _kernels.window_normal(*args)
    n = H.shape[1]
    H[:, np.arange(n), np.arange(n)] *= 1 + 1e-12
    lo, hi = 9, 36
    want = (*_kernels.window_solve(H, rhs, lo, hi), rhs)
    assert_array_equal(want[2], [True, False, True])
    for fused in (_kernels.window_normal_solve, _kernels.window_normal_solve.py_func):
        got = fused(*args, lo, hi)
        for a, b in zip(got, want, strict=True):
            assert_array_equal(a, b)
            assert_array_equal(np.signbit(a), np.signbit(b))
    # the base: the good windows solved by the pass, the bad one by LU on its whole matrix
    ref = np.linalg.solve(H, rhs[..., None])[..., 0]
    assert_array_equal(base.x0.reshape(3, -1)[[0, 2]], want[0][[0, 2]])
    assert_allclose(base.x0.reshape(3, -1)[1], ref[1], rtol=1e-8,
                    atol=1e-10 * np.abs(ref[1]).max())
    assert np.all(np.isfinite(base.cov[1]))


def test_search_right_is_numpys_searchsorted():
    """The galloping search (session 44): numpy's ``searchsorted(side="right")`` for knot
    vectors with repeated knots (clamped ends), times sorted, in runs and shuffled, with
    ties, -0, ±inf and NaN (counted beyond every knot), outside the knots and none; its
    Python original the same; and ``bspline.search_right`` the same on every path (the
    kernel from 64 times on, numpy's below and where a knot is NaN)."""
    from pslog.estimation.bspline import search_right

    rng = np.random.default_rng(77046)
    for trial in range(600):
        n, m = int(rng.integers(0, 40)), int(rng.integers(0, 200))
        a = np.sort(np.round(rng.normal(size=n), 1))
        if trial % 3 == 0 and n:
            a = np.r_[np.full(3, a[0]), a, np.full(3, a[-1])]
        v = np.round(rng.normal(size=m) * 1.5, 1)
        if trial % 4 == 1:
            v = np.sort(v)
        if trial % 4 == 2:  # runs of increasing times (a prior's node sets)
            v = np.concatenate([np.sort(part) for part in np.array_split(v, 3)])
        if m:
            v[rng.integers(0, m, 3)] = [np.nan, -0.0, np.inf][trial % 3]
            if trial % 5 == 0:
                v[rng.integers(0, m)] = -np.inf
        want = np.searchsorted(a, v, side="right")
        for fn in (_kernels.search_right, _kernels.search_right.py_func):
            assert_array_equal(fn(a, v), want)
        assert_array_equal(search_right(a, v), want)
    a = np.array([0.0, 1.0, np.nan])
    v = np.linspace(-1.0, 2.0, 100)
    assert_array_equal(search_right(a, v), np.searchsorted(a, v, side="right"))


def _lens_rig():
    from pslog.camera import Camera, look_at
    from pslog.rig import Rig

    cams = []
    for i in range(3):
        angle = 2 * np.pi * i / 3 + 0.4
        R, t = look_at((1.5 + 4.2 * np.cos(angle), 1.0 + 3.6 * np.sin(angle), 2.2 + 0.3 * i),
                       (1.5, 1.0, 0.8))
        cams.append(Camera(f"c{i + 1}", 800, 600, [[700.0 + 20 * i, 0.3, 401.0],
                                                   [0, 702.0 + 20 * i, 298.0], [0, 0, 1]],
                           np.array([-0.21, 0.08, 4e-4, -6e-4, -0.01]), R, t, 30.0))
    return Rig(tuple(cams))


def test_project_residuals_is_the_stacked_projection_bit_for_bit_and_flags_points_behind():
    from pslog.estimation.projection import project_stacked, stack_cameras

    rig = _lens_rig()
    rng = np.random.default_rng(21)
    n = 400
    X = rng.uniform([0.3, 0.2, 0.1], [2.7, 1.8, 1.9], (n, 3))
    X[7] = rig.cameras[0].center_world  # on its camera's plane: no projection
    camera = rng.integers(0, 3, n)
    camera[7] = 0
    uv_obs = rng.uniform(0, 800, (n, 2))
    params = [np.array([c.R for c in rig.cameras]), np.array([c.t for c in rig.cameras]),
              np.array([[c.K[0, 0], c.K[0, 1], c.K[0, 2], c.K[1, 1], c.K[1, 2]]
                        for c in rig.cameras]), np.array([c.dist for c in rig.cameras])]
    r, J, invalid = _kernels.project_residuals(camera, *params, X, uv_obs)
    for got, want in zip((r, J, invalid),
                         _kernels.project_residuals.py_func(camera, *params, X, uv_obs),
                         strict=True):
        assert_array_equal(got, want)
    uv, J_ref = project_stacked(stack_cameras(rig.cameras, camera), X)
    ok = np.ones(n, bool)
    ok[7] = False
    assert_array_equal(invalid, ~ok)
    # the same bits on this machine (the kernel sums in numpy einsum's order); einsum's
    # SIMD lanes may sum otherwise on another CPU or numpy, hence last-bit tolerance here
    assert_allclose(r[ok], (uv - uv_obs)[ok], rtol=4e-16, atol=1e-12)
    assert_allclose(J[ok], J_ref[ok], rtol=4e-16, atol=1e-9)
    assert_array_equal(r[7], 0.0)
    assert_array_equal(J[7], 0.0)
    # and the single-camera projection with its hand-written chain rule
    for i, cam in enumerate(rig.cameras):
        sel = ok & (camera == i)
        uv_i, J_i = project_with_jacobian_of(cam, X[sel])
        assert_allclose(r[sel] + uv_obs[sel], uv_i, rtol=1e-14, atol=1e-9)
        assert_allclose(J[sel], J_i, rtol=1e-12, atol=1e-9)


def project_with_jacobian_of(cam, X):
    from pslog.estimation.projection import project_with_jacobian

    return project_with_jacobian(cam, X)


def test_data_terms_are_the_detections_quadratic_forms():
    rng = np.random.default_rng(22)
    n = 120
    J = rng.normal(size=(n, 2, 3)) * 300
    z = rng.normal(size=(n, 2)) * 20
    w = rng.uniform(0.1, 2.0, n)
    upper, v = _kernels.data_terms(J, z, w)
    for got, want in zip((upper, v), _kernels.data_terms.py_func(J, z, w), strict=True):
        assert_array_equal(got, want)
    M = np.einsum("n,nai,nak->nik", w, J, J)  # w JᵀJ
    assert_allclose(upper, M.reshape(n, 9)[:, [0, 1, 2, 4, 5, 8]], rtol=1e-13)
    assert_allclose(v, np.einsum("nai,na->ni", J, w[:, None] * z), rtol=1e-12, atol=1e-9)


def test_band_from_rows_reads_the_symmetric_band():
    rng = np.random.default_rng(23)
    m = 6
    n = 3 * m
    A = rng.normal(size=(n, n))
    S = A @ A.T  # a symmetric "covariance"
    rows = np.zeros((n + 12, 12))
    for j in range(12):
        i = np.arange(n - j)
        rows[i, j] = S[i, i + j]
    band = _kernels.band_from_rows(rows, m)
    assert_array_equal(band, _kernels.band_from_rows.py_func(rows, m))
    for i in range(m):
        for k in range(4):
            if i + k < m:
                assert_array_equal(band[i, k], S[3 * i:3 * i + 3, 3 * (i + k):3 * (i + k) + 3])
            else:  # beyond the last control point: zero
                assert_array_equal(band[i, k], 0.0)


def test_window_positions_are_the_basis_sums_of_the_numpy_form_bit_for_bit():
    local, t, J, z, w, index, valid, centre, h, _ = _window_case(6)
    base = _breaks._Base(local, t, J, z, w, index, valid, centre, h)
    X = _kernels.window_positions(base.first, base.N, np.ascontiguousarray(base.x0))
    assert_array_equal(X, _kernels.window_positions.py_func(base.first, base.N,
                                                            np.ascontiguousarray(base.x0)))
    B, W = base.first.shape
    gathered = np.take_along_axis(base.x0, (base.first[..., None] + np.arange(4)).reshape(
        B, -1)[..., None], axis=1).reshape(B, W, 4, 3)
    assert_array_equal(X, np.einsum("bwa,bwad->bwd", base.N, gathered))
    # by hand, one detection
    f = base.first[1, 2]
    assert_allclose(X[1, 2], sum(base.N[1, 2, a] * base.x0[1, f + a] for a in range(4)),
                    rtol=1e-15, atol=0)


@pytest.mark.parametrize("order", ["sorted", "shuffled", "gaps", "one step back"])
def test_points_normal_streamed_or_kept_is_the_sparse_product(order):
    """points_normal adds a control point's sums as soon as the (sorted) terms pass it, or
    keeps them all when the terms are not in order (a prior's Gauss nodes, moved times):
    either way the sums of the sparse products, bit for bit, added once to ab and rhs."""
    first, N, M, v, m = _points_case(11, r=300, m=60)
    if order == "shuffled":
        perm = np.random.default_rng(12).permutation(len(first))
        first, N, M, v = first[perm], N[perm], M[perm], v[perm]
    elif order == "one step back":  # sorted but for one term a control point back
        i = int(np.flatnonzero(np.diff(first) == 1)[len(first) // 40])
        perm = np.arange(len(first))
        perm[[i, i + 1]] = i + 1, i
        first, N, M, v = first[perm], N[perm], M[perm], v[perm]
    elif order == "gaps":  # control points no term touches (more than the ring's 8 in a row)
        keep = (first < 20) | (first > 40)
        first, N, M, v = first[keep], N[keep], M[keep], v[keep]
    G, B = _sparse_points(first, N, m)
    upper, ab0, rhs0, ref_ab, ref_rhs = _reference_normal(G, B, M, v, m)
    for fn in (_kernels.points_normal, _kernels.points_normal.py_func):
        ab, rhs = ab0.copy(), rhs0.copy()
        fn(first, N, upper, v, m, ab, rhs)
        assert_array_equal(ab, ref_ab)
        assert_array_equal(rhs, ref_rhs)


def _window_solve_by_columns(H, rhs, lo, hi):
    """The break windows' solve one entry at a time (the form window_solve replaced: each
    entry's own chain over ascending k; the reference its loop order must match bit for
    bit)."""
    B, n, _ = H.shape
    bw = 11
    x, cov, ok = np.zeros((B, n)), np.zeros((B, n, hi - lo)), np.ones(B, dtype=bool)
    ncol = hi - lo + 1
    for b in range(B):
        L = np.zeros((n, n))
        Y, Z = np.zeros((n, ncol)), np.zeros((n, ncol))
        good = True
        for j in range(n):
            s = H[b, j, j]
            for k in range(max(0, j - bw), j):
                s -= L[j, k] * L[j, k]
            if not s > 0.0:
                good = False
                break
            d = np.sqrt(s)
            L[j, j] = d
            for i in range(j + 1, min(n, j + bw + 1)):
                t = H[b, i, j]
                for k in range(max(0, i - bw), j):
                    t -= L[i, k] * L[j, k]
                L[i, j] = t / d
        if not good:
            ok[b] = False
            continue
        for col in range(ncol):
            start = 0 if col == 0 else lo + col - 1
            for i in range(start, n):
                t = rhs[b, i] if col == 0 else (1.0 if i == start else 0.0)
                for k in range(max(start, i - bw), i):
                    t -= L[i, k] * Y[k, col]
                Y[i, col] = t / L[i, i]
            for i in range(n - 1, (-1 if col == 0 else lo - 1), -1):
                t = Y[i, col]
                for k in range(i + 1, min(n, i + bw + 1)):
                    t -= L[k, i] * Z[k, col]
                Z[i, col] = t / L[i, i]
        x[b] = Z[:, 0]
        cov[b, lo:] = Z[lo:, 1:]
    return x, cov, ok


@pytest.mark.parametrize("lo, hi", [(0, 45), (9, 36), (21, 39), (27, 45)])
def test_window_solve_is_the_column_at_a_time_solve_bit_for_bit(lo, hi):
    """window_solve runs k outside and the rows (factor) or columns (substitutions) inside:
    every entry still sums the same terms in the same order as one entry at a time."""
    local, t, J, z, w, index, valid, centre, h, _ = _window_case(8)
    base = _breaks._Base(local, t, J, z, w, index, valid, centre, h)
    v = np.ascontiguousarray(np.einsum("bwai,bwa,bw->bwi", J[index], z[index],
                                       np.where(base.s_sorted < 1e5, w[index], 0.0)))
    H, rhs = _kernels.window_normal(local.P, local.rhs, base.first, base.N, base.M, v,
                                    base.s_sorted < 1e5)
    # a random symmetric positive definite banded batch too (not a spline's pattern)
    rng = np.random.default_rng(lo + hi)
    n = H.shape[1]
    A = rng.normal(size=(4, n, n)) * (np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
                                      <= 5)
    R = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(n)
    R[:, np.arange(n - 1), np.arange(1, n)] *= 1 + 1e-9  # not exactly symmetric: the lower
    H = np.concatenate([H, R])                            # triangle is the one read
    rhs = np.concatenate([rhs, rng.normal(size=(4, n))])
    H[2, n // 3, n // 3] = -1.0  # a window that fails
    for got, want in zip(_kernels.window_solve(H, rhs, lo, hi),
                         _window_solve_by_columns(H, rhs, lo, hi), strict=True):
        assert_array_equal(got, want)
    assert not _kernels.window_solve(H, rhs, lo, hi)[2][2]


def _band_case(n, seed, width=4):
    """A symmetric positive definite matrix of bandwidth ``width`` in upper banded storage
    (12, n), scaled like a spline problem (entries over many orders of magnitude)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n)) * (np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
                                   <= width)
    A = A @ A.T * 10.0 ** rng.uniform(-3, 6) + 1e-3 * np.eye(n)
    ab = np.zeros((12, n))
    for d in range(12):
        i = np.arange(n - d)
        ab[11 - d, d:] = A[i, i + d]
    return ab


@pytest.mark.parametrize("n, seed", [(1, 0), (5, 1), (12, 2), (13, 3), (60, 4), (2000, 5)])
def test_band_cholesky_and_solve_are_lapacks_bit_for_bit(n, seed):
    """The compiled banded Cholesky factor and solve are LAPACK's dpbtrf / dpbtrs (through
    scipy) to the last bit, one right-hand side or several; and their Python originals."""
    from scipy.linalg import cho_solve_banded, cholesky_banded

    ab = _band_case(n, seed, width=5 if n > 12 else 3)
    ref = cholesky_banded(ab, lower=False)
    U = _normal.factor(ab)
    assert_blas_bits(U, ref)  # bit for bit where this machine's LAPACK sums unfused (_bits)
    py = ab.copy()
    assert _kernels.band_cholesky.py_func(py) == 0
    assert_array_equal(py, U)
    rng = np.random.default_rng(seed + 100)
    b, B = rng.normal(size=n) * 1e3, rng.normal(size=(n, 3))
    assert_blas_bits(_normal.solve(U, b), cho_solve_banded((U, False), b))
    solved = _normal.solve(U, B)
    assert_blas_bits(solved, cho_solve_banded((U, False), B))
    assert solved.flags.f_contiguous  # as scipy's (later sums over it keep their order)
    rows = np.ascontiguousarray(B.T)
    _kernels.band_solve.py_func(U, rows)
    assert_array_equal(rows.T, solved)
    # and it solves: A x = b
    A = np.zeros((n, n))
    for d in range(12):
        i = np.arange(n - d)
        A[i, i + d] = A[i + d, i] = ab[11 - d, d:]
    assert_allclose(A @ _normal.solve(U, b), b, rtol=1e-6, atol=1e-6 * np.abs(b).max())


def test_band_cholesky_reports_the_first_non_positive_pivot_and_factor_loads_it():
    ab = _band_case(30, 7)
    bad = ab.copy()
    bad[11, 17] = -1.0
    assert _kernels.band_cholesky(bad.copy()) == 18
    assert _kernels.band_cholesky.py_func(bad.copy()) == 18
    # a direction nothing reaches (a zero row and column): the diagonal load makes it solvable
    empty = ab.copy()
    empty[:, 17] = 0.0
    for d in range(1, 12):
        if 17 + d < 30:
            empty[11 - d, 17 + d] = 0.0
    U = _normal.factor(empty)
    assert np.all(np.isfinite(U)) and U[11, 17] > 0
    from pslog.errors import FusionError

    with pytest.raises(FusionError, match="undetermined"):
        _normal.factor(bad)


@pytest.mark.parametrize("n, pivot", [(5, 3), (12, 0), (13, 12), (40, 17), (40, 39), (300, 150)])
def test_band_cholesky_leaves_lapacks_partial_factor_where_a_pivot_fails(n, pivot):
    """A pivot that is not positive: the same ``info`` and the same half-factored band as
    LAPACK's dpbtrf (its docstring's promise; a kernel that worked on a copy of the
    columns would have to write them back), compiled and in Python."""
    from scipy.linalg import lapack

    ab = _band_case(n, pivot + 11, width=5 if n > 12 else 3)
    ab[11, pivot] = -abs(ab[11, pivot]) - 1.0
    want, info = lapack.dpbtrf(ab.copy())
    for kernel in (_kernels.band_cholesky, _kernels.band_cholesky.py_func):
        got = ab.copy()
        assert kernel(got) == info == pivot + 1
        assert_blas_bits(got, want)


@pytest.mark.parametrize("n", [1, 2, 3, 8, 101, 4000])
def test_abs_median_of_finite_rows_is_numpys_median(n):
    """The noise scale's median: the value np.median gives on the finite rows' absolute
    residuals (ties, heavy tails, non-finite rows, odd and even counts), and the rows
    counted; its Python original the same."""
    rng = np.random.default_rng(n)
    for trial in range(6):
        r = rng.standard_cauchy((n, 2)) if trial % 2 else np.round(rng.normal(size=(n, 2)), 1)
        if trial >= 3 and n > 3:
            r[rng.integers(0, n, 3), rng.integers(0, 2, 3)] = [np.nan, np.inf, -np.inf]
        finite = r[np.all(np.isfinite(r), axis=1)]
        for fn in (_kernels.abs_median_finite_rows, _kernels.abs_median_finite_rows.py_func):
            median, rows = fn(r)
            assert rows == len(finite)
            assert median == np.median(np.abs(finite))
    assert np.isnan(_kernels.abs_median_finite_rows(np.full((3, 2), np.nan))[0])
    # by hand: |-3|, 1, 2, |-0.5| -> (1 + 2) / 2
    assert _kernels.abs_median_finite_rows(np.array([[-3.0, 1.0], [2.0, -0.5]]))[0] == 1.5


def test_factor_in_place_is_the_copy_and_rebuilds_the_original_on_a_failed_pivot():
    """With ``rebuild`` the band is factored in place (the same bits as the copy); a pivot
    that is not positive calls ``rebuild`` for the original (the half-factored band is no
    start for the diagonal load) and gives what the copying factor gives."""
    ab = _band_case(40, 9)
    ref = _normal.factor(ab)
    work = ab.copy()
    calls = []
    U = _normal.factor(work, rebuild=lambda: calls.append(1) or ab.copy())
    assert U is work and not calls
    assert_array_equal(U, ref)
    empty = ab.copy()  # a direction nothing reaches: the loaded factor
    empty[:, 17] = 0.0
    for d in range(1, 12):
        empty[11 - d, 17 + d] = 0.0
    loaded = _normal.factor(empty)
    got = _normal.factor(empty.copy(), rebuild=lambda: calls.append(1) or empty.copy())
    assert calls == [1]
    assert_array_equal(got, loaded)


@pytest.mark.parametrize("n", [2048, 2049, 5000, 30001, 32768, 40001])
def test_abs_median_of_many_rows_from_a_sample_bracket_is_numpys_median(n):
    """From 4096 values on, the middle order statistics come from the values a sample's
    order statistics bracket (~1,024 sampled, from 65,536 values on ~16,384): the same
    value as np.median with ties (a coarse rounding), heavy tails, non-finite rows and a
    sample that misses the middle (every sampled value huge: the selection over all then),
    compiled and its Python original."""
    rng = np.random.default_rng(n)
    for trial in range(4):
        r = rng.standard_cauchy((n, 2)) if trial % 2 else np.round(rng.normal(size=(n, 2)), 1)
        if trial == 2:
            r[rng.integers(0, n, 5), rng.integers(0, 2, 5)] = np.nan
            r[rng.integers(0, n, 5), rng.integers(0, 2, 5)] = np.inf
        if trial == 3:  # the sampled positions (every step-th value) all far out
            r.reshape(-1)[:: max(2 * n // (16384 if 2 * n >= 65536 else 1024), 1)] = 1e9
        finite = r[np.all(np.isfinite(r), axis=1)]
        for fn in (_kernels.abs_median_finite_rows, _kernels.abs_median_finite_rows.py_func):
            median, rows = fn(r)
            assert rows == len(finite)
            assert median == np.median(np.abs(finite))


def test_the_gauss_newton_passes_are_the_numpy_forms_bit_for_bit():
    """‖r‖²/σ², the linearised targets J X - r, the prior's band times a vector and the hat
    matrix's diagonal w tr(J Σ Jᵀ): compiled, the same bits as the numpy forms they replaced
    (the einsum adds a row's three products as (p0 + p2) + p1) and as their Python
    originals."""
    rng = np.random.default_rng(3)
    n = 3001
    r = rng.normal(size=(n, 2)) * 10.0 ** rng.uniform(-3, 2, (n, 1))
    J = rng.normal(size=(n, 2, 3)) * 400
    X = rng.normal(size=(n, 3)) + np.array([1.5, 1.0, 0.5])
    sigma = 0.37
    for fn in (_kernels.scaled_norms, _kernels.scaled_norms.py_func):
        assert_array_equal(fn(r, sigma**2), np.sum(r * r, axis=1) / sigma**2)
    for fn in (_kernels.linear_target, _kernels.linear_target.py_func):
        assert_array_equal(fn(J, X, r), np.einsum("naj,nj->na", J, X) - r)
    ab = _band_case(60, 4)
    x = rng.normal(size=ab.shape[1])
    Ax = ab[-1] * x
    for d in range(1, 12):
        Ax[:-d] += ab[-1 - d, d:] * x[d:]
        Ax[d:] += ab[-1 - d, d:] * x[:-d]
    for fn in (_kernels.band_matvec, _kernels.band_matvec.py_func):
        assert_array_equal(fn(ab, x), Ax)
    # and the dense product of the symmetric matrix the band stands for
    A = np.zeros((ab.shape[1], ab.shape[1]))
    for d in range(12):
        i = np.arange(ab.shape[1] - d)
        A[i, i + d] = A[i + d, i] = ab[11 - d, d:]
    assert_allclose(_kernels.band_matvec(ab, x), A @ x, rtol=1e-12, atol=1e-12)
    L = rng.normal(size=(n, 3, 3))
    cov = L @ np.swapaxes(L, 1, 2)
    w = rng.uniform(0, 1, n)
    for fn in (_kernels.hat_diagonal, _kernels.hat_diagonal.py_func):
        assert_array_equal(fn(J, cov, w), w * np.einsum("naj,njk,nak->n", J, cov, J))
    # by hand: J = [[1, 0, 0], [0, 2, 0]], Σ = diag(3, 5, 7), w = 0.5 -> 0.5 (3 + 4·5)
    one = np.array([[[1.0, 0, 0], [0, 2.0, 0]]])
    assert _kernels.hat_diagonal(one, np.diag([3.0, 5.0, 7.0])[None], np.array([0.5]))[0] \
        == 11.5


@pytest.mark.parametrize("n", [5, 4096, 60001])
def test_abs_median_of_many_equal_values(n):
    """Zero residuals (a noiseless simulation) and two-valued ones: np.median's value. (The
    selection's three-way partition settles equal values at once: 80,000 zeros took 8.9 s
    with a two-way partition, quadratic; measured, not asserted.)"""
    cases = [np.zeros((n, 2)), np.tile([[0.0, 1.0]], (n, 1)),
             np.where(np.arange(2 * n).reshape(n, 2) % 7 == 0, 2.0, -0.5)]
    for r in cases:
        fns = [_kernels.abs_median_finite_rows]
        if n < 5000:
            fns.append(_kernels.abs_median_finite_rows.py_func)
        for fn in fns:
            median, rows = fn(r)
            assert rows == n and median == np.median(np.abs(r))


@pytest.mark.parametrize("core, plain", [("Haswell", True), ("Nehalem", False)])
def test_the_exact_comparisons_are_on_where_openblas_runs_the_kernels_they_follow(core, plain):
    """tests/_bits.py reads the cores numpy's and scipy's OpenBLAS chose (forced here by
    OPENBLAS_CORETYPE, as OpenBLAS allows): exact comparisons on Haswell's kernels, within
    rounding on Nehalem's; a probe that could not read them would leave every comparison
    within rounding on every machine."""
    import os
    import subprocess
    import sys

    code = ("import sys; sys.path.insert(0, 'tests'); import _bits; "
            "print(sorted(_bits.openblas_cores()), _bits.blas_is_plain())")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "OPENBLAS_CORETYPE": core}, timeout=120,
                         cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == [f"['{core}']", str(plain)]
