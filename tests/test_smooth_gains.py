"""The break test's gains (pslog/estimation/_breaks.py ``_gains``) with their per-trial terms
compiled (``trial_splines``, ``gains_data``, ``trial_gather``, ``trial_blocks``): the same bits
as the numpy form they replaced (written out here, as it was, with its data-term loop in pure
Python), on real break-scan windows; and each kernel against its Python original."""

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
def test_the_compiled_gains_are_the_numpy_form_bit_for_bit(seed):
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
    assert_array_equal(new, ref)


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


def test_trial_gather_and_blocks_are_their_python_originals():
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
    Hyy, Hxy = rng.normal(size=(B, 9, 9)), rng.normal(size=(B, 18, 9))
    pyy, pxy = rng.normal(size=(B, 3, 3)), rng.normal(size=(B, 6, 3))
    which = rng.integers(0, len(base.cov), B)
    col = rng.integers(0, base.cov.shape[2] - 17, B)
    row0 = rng.integers(0, base.cov.shape[1] - 17, B)
    H1, X1, H2, X2 = Hyy.copy(), Hxy.copy(), Hyy.copy(), Hxy.copy()
    cov = _kernels.trial_blocks(H1, X1, pyy, pxy, base.cov, which, row0, col)
    assert_array_equal(cov, _kernels.trial_blocks.py_func(H2, X2, pyy, pxy, base.cov, which,
                                                          row0, col))
    assert_array_equal(H1, H2)
    assert_array_equal(X1, X2)
    # ⊗ I₃ by hand
    assert_array_equal(H1, Hyy + np.einsum("bef,ik->beifk", pyy, np.eye(3)).reshape(B, 9, 9))
    assert_array_equal(X1, Hxy + np.einsum("bce,ik->bciek", pxy, np.eye(3)).reshape(B, 18, 9))
    assert_array_equal(cov[3], base.cov[which[3], row0[3]:row0[3] + 18, col[3]:col[3] + 18])


def test_trial_schur_is_the_numpy_steps_and_its_python_original():
    """S = Hyy - P, symmetric, the diagonal loaded by 1e-12 of its largest |entry|: the
    numpy steps bit for bit (a NaN diagonal propagates as np.max does), and by hand."""
    rng = np.random.default_rng(17)
    B = 40
    Hyy = rng.normal(size=(B, 9, 9)) * 10.0 ** rng.uniform(-4, 6, (B, 1, 1))
    P = rng.normal(size=(B, 9, 9)) * 10.0 ** rng.uniform(-4, 6, (B, 1, 1))
    Hyy[3, 4, 4] = np.nan
    Hyy[5] = P[5]  # S = 0: the load alone
    S = Hyy - P
    S = (S + np.swapaxes(S, 1, 2)) / 2
    load = 1e-12 * np.max(np.abs(np.diagonal(S, axis1=1, axis2=2)), axis=1) + 1e-300
    S[:, np.arange(9), np.arange(9)] += load[:, None]
    got = _kernels.trial_schur(Hyy, P)
    assert_array_equal(got, S)
    assert_array_equal(_kernels.trial_schur.py_func(Hyy, P), S)
    assert np.all(np.isnan(np.diagonal(got[3])))
    assert_array_equal(got[5], 1e-300 * np.eye(9))
    # by hand: [[4, 1], [3, -8]] in the corner -> off-diagonal 2, diagonal + 8e-12
    H = np.zeros((1, 9, 9))
    H[0, :2, :2] = [[4.0, 1.0], [3.0, -8.0]]
    one = _kernels.trial_schur(H, np.zeros((1, 9, 9)))[0]
    assert one[0, 1] == one[1, 0] == 2.0
    assert one[0, 0] == 4.0 + (8e-12 + 1e-300) and one[1, 1] == -8.0 + (8e-12 + 1e-300)
