"""The break test's gains (pslog/estimation/_breaks.py ``_gains``) with their per-trial terms
compiled (``trial_splines``, ``gains_data``, ``trial_gather``, ``trial_gains``): the numpy
form they replaced (written out here, as it was, with its data-term loop in pure Python), on
real break-scan windows, to rounding (``trial_gains`` sums the Schur product in loop order and
solves by its own elimination, not BLAS's and LAPACK's: the gains, a difference of nearly
equal terms, move by ~1e-9 relative); each kernel against its Python original, and
``trial_gains`` by hand."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from pslog.estimation import _breaks, _kernels
from pslog.estimation._breaks import _ACCEL, _GAUSS, _horner, _new_splines
from pslog.estimation.bspline import basis
from pslog.estimation.trajectory import MotionPrior


def _gains_data_python(s_sorted: np.ndarray, first: np.ndarray, N: np.ndarray, M: np.ndarray,
               u: np.ndarray, which: np.ndarray, j: np.ndarray, q0: np.ndarray,
               lo: np.ndarray, hi: np.ndarray, coef: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(reference) The data terms of the break test (:func:`pslog.estimation._breaks._gains`) of B
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
    f = np.zeros(3)
    old = np.zeros(6)
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
        for w in range(lo_col, hi_col):
            x = s_sorted[wb, w] - jb
            for e in range(3):
                f[e] = 0.0
                for k in range(2):
                    if x >= lo[b, e, k] and x < hi[b, e, k]:
                        c = coef[b, e, k]
                        f[e] = ((c[3] * 1.0 * x + c[2]) * x + c[1]) * x + c[0]
            for c6 in range(6):
                a = q0[b] + c6 - first[wb, w]
                old[c6] = N[wb, w, a] if 0 <= a <= 3 else 0.0
            for e in range(3):
                for i in range(3):
                    g[b, e, i] += f[e] * u[wb, w, i]
                for i in range(3):
                    for k in range(3):
                        mik = M[wb, w, i, k]
                        for e2 in range(3):
                            Hyy[b, 3 * e + i, 3 * e2 + k] += (f[e] * f[e2]) * mik
                        for c6 in range(6):
                            Hxy[b, 3 * c6 + i, 3 * e + k] += (old[c6] * f[e]) * mik
    return Hyy, Hxy, g


def _gains_numpy(base, which: np.ndarray, tau: np.ndarray, centre: np.ndarray, prior
           ) -> np.ndarray:
    """Cost decrease (B,) of a triple knot at ``tau`` (B,) in window ``which`` (B,) of
    ``base``, whose uniform knots are ``centre + k·h`` (module docstring)."""
    local, h = base.local, base.spacing
    K = local.K
    B = len(tau)
    s = (tau - centre[which]) / h
    j = np.floor(s)
    jm, jp = j - 1, j + 1
    pieces = _new_splines(s - j)  # in spacings from u_j
    q0 = (j + K - 1).astype(np.int64)  # the six base control points over spans j-1..j+1

    def spread(first, N):
        """(B, P, 4) basis values at control points first..first+3 onto q0..q0+5."""
        pos = np.clip(first - q0[:, None], 0, 2)
        out = np.zeros((*N.shape[:2], 6))
        flat = (6 * np.arange(pos.size).reshape(pos.shape) + pos)[..., None] + np.arange(4)
        out.reshape(-1)[flat.reshape(-1)] = N.reshape(-1)
        return out

    # data: the window's detections on the three spans [j-1, j+2) the new B-splines live on:
    # Σ_w (f fᵀ) ⊗ M_w, Σ_w (old fᵀ) ⊗ M_w (old: the base's B-splines q0..q0+5) and Σ_w f uᵀ,
    # one compiled pass over each window's detections
    lo = np.empty((B, 3, 2))
    hi = np.empty((B, 3, 2))
    coef = np.empty((B, 3, 2, 4))
    for e, spline in enumerate(pieces):
        for k, (a, b, c) in enumerate(spline):
            lo[:, e, k], hi[:, e, k] = a, b
            for d in range(4):
                coef[:, e, k, d] = c[d]
    Hyy, Hxy, g = _gains_data_python(base.s_sorted, base.first, base.N, base.M, base.u,
                             np.ascontiguousarray(which, dtype=np.int64), j, q0, lo, hi, coef)
    m = local.m

    # prior: four sub-spans [j-1, j], [j, τ], [τ, j+1], [j+1, j+2]
    lo = np.stack([jm, j, s, jp], 1)
    hi = np.stack([j, s, jp, jp + 1], 1)
    half, mid = (hi - lo) / 2, (hi + lo) / 2  # (B, 4), spacings
    nodes = np.concatenate([mid - _GAUSS * half, mid + _GAUSS * half, mid], axis=1)  # (B, 12)
    # each new B-spline is one polynomial piece on each of its two sub-spans
    fn = np.zeros((B, 3, 12))
    xn = nodes - j[:, None]
    for e, spline in enumerate(pieces):
        for k, (_, _, c) in enumerate(spline):
            sub = np.array([0, 4, 8]) + e + k  # the sub-span's two Gauss nodes and midpoint
            fn[:, e, sub[:2]] = _horner(c, xn[:, sub[:2]], 2) / h**2
            fn[:, e, sub[2:]] = _horner(c, xn[:, sub[2:]], 3) / h**3
    # the base's B-splines at the nodes: uniform ones (closed form), but near the clamped ends
    span = np.floor(nodes)
    u = nodes - span
    first = (span + K).astype(np.int64)  # (B, 12)
    Nd = np.empty((B, 12, 4))  # (B, 12, 4), per second^d
    ua = u[:, :8]
    Nd[:, :8] = np.stack([1 - ua, 3 * ua - 2, 1 - 3 * ua, ua], axis=-1) / h**2
    Nd[:, 8:] = np.array([-1.0, 3.0, -3.0, 1.0]) / h**3
    clamped = (first < 3) | (first > 2 * K - 4)
    if np.any(clamped):
        f_c, N_c = basis(local.knots, nodes[clamped], 3)
        first[clamped] = f_c
        Nd[clamped] = np.where(_ACCEL[np.nonzero(clamped)[1]][:, None], N_c[:, 2] / h**2,
                               N_c[:, 3] / h**3)
    # the nodes' B-splines on the six base control points q0..q0+5 of the three spans
    Nd6 = spread(first, Nd)  # (B, 12, 6)
    x0 = np.take(base.x0.reshape(-1, 3), (which * m + q0)[:, None] + np.arange(6), axis=0)
    p0 = Nd6 @ x0  # p'' or jerk, (B, 12, 3)
    p0[:, :8] -= np.asarray(prior.gravity, dtype=np.float64)  # deviation from gravity
    wq = h * np.concatenate([half / prior.q_accel, half / prior.q_accel,
                             2 * half / prior.q_jerk], axis=1)  # (B, 12)
    fw = fn * wq[:, None, :]
    pyy = fw @ np.swapaxes(fn, 1, 2)  # (B, 3, 3)
    pxy = np.swapaxes(Nd6, 1, 2) @ np.swapaxes(fw, 1, 2)  # (B, 6, 3)
    H5 = Hyy.reshape(B, 3, 3, 3, 3)
    X5 = Hxy.reshape(B, 6, 3, 3, 3)
    for i in range(3):  # ⊗ I₃
        H5[:, :, i, :, i] += pyy
        X5[:, :, i, :, i] += pxy
    g -= fw @ p0

    # the 18 x 18 diagonal blocks of each window's inverse, as a view of its columns
    col0 = base.col0
    cols = base.cov[:, col0:]
    s0, s1, s2 = cols.strides
    blocks = np.lib.stride_tricks.as_strided(cols, (len(cols), cols.shape[2] - 17, 18, 18),
                                             (s0, s1 + s2, s1, s2), writeable=False)
    k = 3 * q0 - col0
    if np.any((k < 0) | (k > cols.shape[2] - 18)):
        raise AssertionError("trial instant outside the spans its base was solved for")
    cov = blocks[which, k]  # (B, 18, 18)
    S = Hyy - np.swapaxes(Hxy, 1, 2) @ cov @ Hxy
    S = (S + np.swapaxes(S, 1, 2)) / 2
    g = g.reshape(B, 9)
    load = 1e-12 * np.max(np.abs(np.diagonal(S, axis1=1, axis2=2)), axis=1) + 1e-300
    S[:, np.arange(9), np.arange(9)] += load[:, None]
    gain = np.einsum("bk,bk->b", g, np.linalg.solve(S, g[..., None])[..., 0])
    return gain



def _scan_windows(seed, K_extra=0):
    """Two bases of break-test windows (centred and shifted by h/2), as _scan_block builds
    them, on random linearised detections."""
    rng = np.random.default_rng(seed)
    h = 0.011
    n = 400
    t = np.sort(rng.uniform(0.0, 1.2, n))
    J = rng.normal(size=(n, 2, 3)) * 300
    z = rng.normal(size=(n, 2)) * 3
    w = rng.uniform(0.2, 4.0, n)
    prior = MotionPrior(sigma_accel=4.0 * (1 + 9 * (seed % 2)))
    centers = np.sort(rng.uniform(0.15, 1.05, 9))
    lo, hi = centers - 5 * h, centers + 5 * h
    i0, i1 = np.searchsorted(t, lo), np.searchsorted(t, hi, side="right")
    W = int(np.max(i1 - i0))
    index = np.minimum(i0[:, None] + np.arange(W), n - 1)
    valid = i0[:, None] + np.arange(W) < i1[:, None]
    K = 6 + K_extra
    local = _breaks._local(K, h, prior, 1)
    both = np.r_[centers, centers + h / 2]
    spans = (-3, 1)
    base = _breaks._Base(local, t, J, z, w, np.r_[index, index], np.r_[valid, valid], both, h,
                         spans)
    return base, both, centers, prior, h, rng


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_the_compiled_gains_are_the_numpy_form(seed):
    base, both, centers, prior, h, rng = _scan_windows(seed, K_extra=seed % 2)
    C = len(centers)
    # trial instants over the spans a scan tests, on either base, some at a span's ends
    which = rng.integers(0, 2 * C, 60)
    # a trial is tested on the base whose knots are at least h/4 from it
    frac = rng.integers(-3, 2, 60) + rng.uniform(0.25, 0.75, 60)
    frac[:4] = [-2.75, 0.25, 1.75, 0.5]
    tau = both[which] + frac * h
    new = _breaks._gains(base, which, tau, both, prior)
    ref = _gains_numpy(base, which, tau, both, prior)
    assert np.all(np.isfinite(ref)) and np.any(ref > 0)
    # the Schur product and the 9 x 9 solve compiled (trial_gains): rounding only
    np.testing.assert_allclose(new, ref, rtol=1e-7, atol=0)


def test_trial_splines_are_new_splines_and_its_python_original():
    rng = np.random.default_rng(5)
    a = np.r_[rng.uniform(0, 1, 40), 0.25, 0.5, 0.75, 1e-9, 1 - 1e-9]
    j = np.floor(rng.uniform(-3, 2, len(a)))
    s = j + a
    both = np.stack([a, 1 - a])
    h = 0.0137
    args = (a, both**3, both**-3, s, j, 6, h, h**2, h**3, _GAUSS, 1.3, 2.9)
    out = _kernels.trial_splines(*args)
    for got, want in zip(out, _kernels.trial_splines.py_func(*args), strict=True):
        assert_array_equal(got, want)
    lo, hi, coef = out[:3]
    for e, spline in enumerate(_new_splines(a)):
        for k, (bound_lo, bound_hi, c) in enumerate(spline):
            assert_array_equal(lo[:, e, k], np.broadcast_to(bound_lo, a.shape))
            assert_array_equal(hi[:, e, k], np.broadcast_to(bound_hi, a.shape))
            assert_array_equal(coef[:, e, k], np.stack(c, axis=1))
    # p'' at a Gauss node by hand (Horner on the power basis), per s²
    nodes, fn = out[3], out[4]
    c = coef[:, 0, 1]
    x = nodes[:, 5] - j  # sub-span 1 (the right piece of spline 0), its second Gauss node
    by_hand = (6 * c[:, 3] * x + 2 * c[:, 2]) / h**2
    np.testing.assert_allclose(fn[:, 0, 5], by_hand, rtol=1e-12, atol=1e-9)


def test_trial_gather_and_gains_are_their_python_originals():
    base, *_, rng = _scan_windows(7)
    B = 30
    first = rng.integers(0, 12, (B, 12))
    Nd = rng.normal(size=(B, 12, 4))
    q0 = rng.integers(0, 8, B)
    rows = rng.integers(0, base.x0.shape[0], B) * base.x0.shape[1] + q0
    x0 = base.x0.reshape(-1, 3)
    for got, want in zip(_kernels.trial_gather(first, Nd, q0, x0, rows),
                         _kernels.trial_gather.py_func(first, Nd, q0, x0, rows), strict=True):
        assert_array_equal(got, want)
    # symmetric positive definite S as in a scan: Hyy = A Aᵀ + 10 I, the prior's pyy
    # symmetric, and a diagonal 18 x 18 block of a window's inverse
    A = rng.normal(size=(B, 9, 9))
    Hyy, Hxy = A @ np.swapaxes(A, 1, 2) + 10 * np.eye(9), rng.normal(size=(B, 18, 9)) * 1e-2
    p = rng.normal(size=(B, 3, 3))
    pyy, pxy = p @ np.swapaxes(p, 1, 2), rng.normal(size=(B, 6, 3))
    g = rng.normal(size=(B, 9))
    which = rng.integers(0, len(base.cov), B)
    col = rng.integers(0, base.cov.shape[2] - 17, B)
    row0 = col + base.col0
    H1, X1, H2, X2 = Hyy.copy(), Hxy.copy(), Hyy.copy(), Hxy.copy()
    got = _kernels.trial_gains(H1, X1, pyy, pxy, base.cov, which, row0, col, g)
    assert_array_equal(got, _kernels.trial_gains.py_func(H2, X2, pyy, pxy, base.cov, which,
                                                         row0, col, g))
    assert_array_equal(H1, H2)
    assert_array_equal(X1, X2)
    # the prior's terms ⊗ I₃, by hand
    assert_array_equal(H1, Hyy + np.einsum("bef,ik->beifk", pyy, np.eye(3)).reshape(B, 9, 9))
    assert_array_equal(X1, Hxy + np.einsum("bce,ik->bciek", pxy, np.eye(3)).reshape(B, 18, 9))
    # and the numpy steps it replaced (the 18 x 18 block, the Schur complement made
    # symmetric, its diagonal loaded, LAPACK's solve), to rounding
    cov = np.stack([base.cov[w, r:r + 18, c:c + 18]
                    for w, r, c in zip(which, row0, col, strict=True)])
    S = H1 - np.swapaxes(X1, 1, 2) @ cov @ X1
    S = (S + np.swapaxes(S, 1, 2)) / 2
    S[:, np.arange(9), np.arange(9)] += (1e-12 * np.max(np.abs(np.diagonal(
        S, axis1=1, axis2=2)), axis=1) + 1e-300)[:, None]
    want = np.einsum("bk,bk->b", g, np.linalg.solve(S, g[..., None])[..., 0])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * np.max(np.abs(want)))


def _gains_by_hand(Hyy, Hxy, cov, g, pyy=None, pxy=None):
    """trial_gains of one trial, the 18 x 18 block ``cov`` at row and column 0."""
    pyy = np.zeros((1, 3, 3)) if pyy is None else pyy
    pxy = np.zeros((1, 6, 3)) if pxy is None else pxy
    zero = np.zeros(1, np.int64)
    return _kernels.trial_gains(Hyy[None].copy(), Hxy[None].copy(), pyy, pxy, cov[None],
                                zero, zero, zero, g[None])[0]


def test_trial_gains_by_hand():
    """gᵀ S⁻¹ g with S = Hyy - H_xyᵀ Σ H_xy: worked out by hand on small cases."""
    g = np.arange(1.0, 10.0)
    # no coupling to the base: S = Hyy = 2 I, the gain Σ g² / 2 (the load, 2e-12, aside)
    Hyy, Hxy, cov = 2 * np.eye(9), np.zeros((18, 9)), np.eye(18)
    assert _gains_by_hand(Hyy, Hxy, cov, g) == pytest.approx(np.sum(g**2) / 2, rel=1e-10)
    # new unknown 0 coupled to base unknown 0 by 1, whose variance is 1: S[0, 0] = 2 - 1 = 1
    # (a sign error would give 3); unknown 4 to base unknown 7 by 2, whose variance is 1/8:
    # S[4, 4] = 2 - 4/8 = 1.5, and base unknowns 7 and 9 correlated by 1/16 with unknown 4
    # coupled to 9 by 1 as well: S[4, 4] = 2 - (4/8 + 2·2·1/16 + 1/8) = 1.125
    Hxy[0, 0] = 1.0
    cov[7, 7] = 1 / 8
    Hxy[7, 4] = 2.0
    want = np.sum(g**2) / 2 + g[0] ** 2 / 1 - g[0] ** 2 / 2 + g[4] ** 2 / 1.5 - g[4] ** 2 / 2
    assert _gains_by_hand(Hyy, Hxy, cov, g) == pytest.approx(want, rel=1e-10)
    Hxy[9, 4] = 1.0
    cov[9, 9] = 1 / 8
    cov[7, 9] = cov[9, 7] = 1 / 16
    want = np.sum(g**2) / 2 + g[0] ** 2 / 1 - g[0] ** 2 / 2 + g[4] ** 2 / 1.125 - g[4] ** 2 / 2
    assert _gains_by_hand(Hyy, Hxy, cov, g) == pytest.approx(want, rel=1e-10)
    # the prior's pyy ⊗ I₃: pyy[1, 1] = 2 adds 2 to S at (3 + i, 3 + i), i = 0..2
    pyy = np.zeros((1, 3, 3))
    pyy[0, 1, 1] = 2.0
    got = _gains_by_hand(Hyy, Hxy, cov, g, pyy=pyy)
    want -= (g[3] ** 2 + g[5] ** 2) / 2 - (g[3] ** 2 + g[5] ** 2) / 4
    want -= g[4] ** 2 / 1.125 - g[4] ** 2 / 3.125
    assert got == pytest.approx(want, rel=1e-10)
    # a zero pivot: S = [[0, 1], [1, 0]] ⊕ I₇ needs a row exchange; S⁻¹ = S there, so the
    # gain is 2 g₀ g₁ + Σ_{i>1} g_i² (the load, 1e-12, aside)
    S = np.eye(9)
    S[:2, :2] = [[0.0, 1.0], [1.0, 0.0]]
    got = _gains_by_hand(S, np.zeros((18, 9)), np.eye(18), g)
    assert got == pytest.approx(2 * g[0] * g[1] + np.sum(g[2:] ** 2), rel=1e-9)
    # a NaN (a failed window) gives NaN: no gain
    bad = np.eye(9)
    bad[2, 2] = np.nan
    assert np.isnan(_gains_by_hand(bad, np.zeros((18, 9)), np.eye(18), g))
