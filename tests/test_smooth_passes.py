"""smooth's passes that do less work for the same bits: the normal equations written onto
the prior's band in one pass (``points_normal_onto``), each detection's ``w J`` and
``w JᵀJ`` formed once per break scan (``_breaks.detection_terms``), and the break test's
small prior products in one compiled pass (``trial_prior_terms``) — each against the form
it replaced, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from test_smooth_kernels import _points_case, _reference_normal, _sparse_points, _window_case

from pslog.estimation import _breaks, _kernels, _normal


def _blas_like_here() -> bool:
    """Whether numpy's BLAS sums a (B, 12, 6) @ (B, 6, 3) product in the order that
    ``trial_prior_terms`` reproduces (k ascending, fused multiply-adds: this build
    machine's OpenBLAS kernels, on which smooth's outputs were compared bit for bit).
    Another BLAS may round differently; then only the few-ulp half of the test applies."""
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(64, 12, 6)), rng.normal(size=(64, 6, 3))
    zeros = np.zeros((64, 3, 12))
    p0, *_ = _kernels.trial_prior_terms(a, b, zeros, zeros, np.zeros(3),
                                        np.zeros((64, 3, 3)))
    return bool(np.array_equal(_bits(p0), _bits(a @ b)))


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


@pytest.mark.parametrize("order", ["sorted", "shuffled", "gaps", "none"])
def test_normal_onto_is_the_base_copied_then_added_to(order):
    """Every entry of the band (those no pair of control points reaches too: points 4 apart,
    the corner before the first columns) and of the rhs is the base's plus the sums, as a
    copy of the base given to ``normal``; the base is left as it was."""
    first, N, M, v, m = _points_case(21, r=300, m=60)
    if order == "shuffled":
        perm = np.random.default_rng(22).permutation(len(first))
        first, N, M, v = first[perm], N[perm], M[perm], v[perm]
    elif order == "gaps":  # control points no term touches (more than the ring's 8 in a row)
        keep = (first < 20) | (first > 40)
        first, N, M, v = first[keep], N[keep], M[keep], v[keep]
    elif order == "none":
        first, N, M, v = first[:0], N[:0], M[:0], v[:0]
    G, B = _sparse_points(first, N, m)
    _, ab0, rhs0, ref_ab, ref_rhs = _reference_normal(G, B, M, v, m)
    keep_ab, keep_rhs = ab0.copy(), rhs0.copy()
    points = _normal.Points(first, N, m)
    for _ in range(3):  # fresh arrays from reused memory each time: no entry left unset
        ab, rhs = points.normal_onto(M, v, ab0, rhs0)
        assert_array_equal(_bits(ab), _bits(ref_ab))
        assert_array_equal(_bits(rhs), _bits(ref_rhs))
        copied = points.normal(M, v, ab0.copy(), rhs0.copy())
        assert_array_equal(_bits(ab), _bits(copied[0]))
        assert_array_equal(_bits(rhs), _bits(copied[1]))
        del ab, rhs, copied
    assert_array_equal(ab0, keep_ab)
    assert_array_equal(rhs0, keep_rhs)


def test_base_of_shared_detection_terms_is_the_per_window_one():
    """A scan's windows read each detection's ``w J``, ``w JᵀJ`` from one table: the same
    local problems, bit for bit, as each window forming them from its own gather."""
    local, t, J, z, w, index, valid, centre, h, _ = _window_case(4)
    both = np.r_[centre, centre + h / 2]
    idx, ok = np.r_[index, index], np.r_[valid, valid]
    i0 = index[:, 0]
    i1 = i0 + valid.sum(axis=1)
    terms = _breaks.detection_terms(J, w, i0, i1)
    assert len(terms[1]) < len(t)  # only the detections some window holds
    shared = _breaks._Base(local, t, J, z, w, idx, ok, both, h, terms=terms)
    alone = _breaks._Base(local, t, J, z, w, idx, ok, both, h)
    for name in ("M", "u", "x0", "cov", "cost", "first", "N", "s_sorted"):
        assert_array_equal(getattr(shared, name), getattr(alone, name), err_msg=name)
    # and the products as each window formed them before: w[index] J[index], then wJᵀ J
    inside = shared.s_sorted < 1e5
    wi = np.where(inside, w[idx], 0.0)
    wJ = wi[..., None, None] * J[idx]
    before = np.swapaxes(wJ, 2, 3) @ J[idx]
    assert_array_equal(_bits(shared.M[inside]), _bits(before[inside]))


def test_trial_prior_terms_are_the_matmuls():
    """p0 = Nd6 @ x0 less gravity at the Gauss nodes, pyy = fw fnᵀ, pxy = Nd6ᵀ fwᵀ and
    g -= fw @ p0: numpy's products (OpenBLAS), bit for bit, on real break trials' terms and
    on random ones."""
    local, t, J, z, w, index, valid, centre, h, prior = _window_case(5)
    both = np.r_[centre, centre + h / 2]
    base = _breaks._Base(local, t, J, z, w, np.r_[index, index], np.r_[valid, valid], both, h)
    rng = np.random.default_rng(6)
    which = rng.integers(0, len(both), 400)
    tau = both[which] + rng.uniform(-1.4, 1.4, 400) * h
    s = (tau - both[which]) / h
    j = np.floor(s)
    a = s - j
    K = local.K
    q0 = (j + K - 1).astype(np.int64)
    stack = np.stack([a, 1 - a])
    *_, fn, fw, first, Nd = _kernels.trial_splines(
        a, stack**3, stack**-3, s, j, K, h, h**2, h**3, 1 / np.sqrt(3.0), prior.q_accel,
        prior.q_jerk)
    first = np.clip(first, 0, local.m - 4)
    Nd6, x0 = _kernels.trial_gather(first, Nd, q0, base.x0.reshape(-1, 3),
                                    which * local.m + q0)
    gravity = np.asarray(prior.gravity, dtype=np.float64)
    cases = [(Nd6, x0, fw, fn)]
    B = 3000  # random terms of the same shapes, over several magnitudes
    cases.append((rng.normal(size=(B, 12, 6)) * 10.0 ** rng.integers(-3, 6, (B, 1, 1)),
                  rng.normal(size=(B, 6, 3)), rng.normal(size=(B, 3, 12)),
                  rng.normal(size=(B, 3, 12)) * 1e4))
    blas_like_here = _blas_like_here()
    for Nd6, x0, fw, fn in cases:
        g0 = rng.normal(size=(len(Nd6), 3, 3))
        p0 = Nd6 @ x0
        p0[:, :8] -= gravity
        pyy = fw @ np.swapaxes(fn, 1, 2)
        pxy = np.swapaxes(Nd6, 1, 2) @ np.swapaxes(fw, 1, 2)
        g_ref = g0.copy()
        g_ref -= fw @ p0
        g = g0.copy()
        q0_, qyy, qxy = _kernels.trial_prior_terms(Nd6, x0, np.ascontiguousarray(fw),
                                                   np.ascontiguousarray(fn), gravity, g)
        # Bit for bit where numpy's BLAS sums as this machine's OpenBLAS (Haswell/Zen
        # kernels, fused multiply-adds: what smooth's outputs were compared on); any other
        # BLAS order may differ by rounding, so the products are held to a few ulps of
        # their terms' magnitudes (|A| |B|), which a wrong index or term still breaks.
        bound = 8 * np.finfo(float).eps
        for got, ref, scale in (
                (q0_, p0, np.abs(Nd6) @ np.abs(x0) + np.abs(gravity)),
                (qyy, pyy, np.abs(fw) @ np.swapaxes(np.abs(fn), 1, 2)),
                (qxy, pxy, np.swapaxes(np.abs(Nd6), 1, 2) @ np.swapaxes(np.abs(fw), 1, 2)),
                (g, g_ref, np.abs(g0) + np.abs(fw) @ (np.abs(Nd6) @ np.abs(x0)
                                                       + np.abs(gravity)))):
            assert np.all(np.abs(got - ref) <= bound * scale)
        if not blas_like_here:
            continue
        assert_array_equal(_bits(q0_), _bits(p0))
        assert_array_equal(_bits(qyy), _bits(pyy))
        assert_array_equal(_bits(qxy), _bits(pxy))
        assert_array_equal(_bits(g), _bits(g_ref))


@pytest.mark.parametrize("shuffled", [False, True])
def test_isotropic_band_is_points_normal_of_w_identity(shuffled):
    """The prior's band from terms ``w I₃``: each pair's sum once, the band the general pass
    forms from the upper triangles (w, 0, 0, w, 0, w) bit for bit (zeros off the diagonal
    of each block included)."""
    first, N, _, _, m = _points_case(31, r=500, m=70)
    N = N - 0.5  # second derivatives of B-splines change sign
    w = np.random.default_rng(32).uniform(0.001, 0.02, len(first))
    if shuffled:  # the prior's Gauss nodes come two per span, not in order
        perm = np.random.default_rng(33).permutation(len(first))
        first, N, w = first[perm], N[perm], w[perm]
    upper = np.zeros((len(w), 6))
    upper[:, 0] = upper[:, 3] = upper[:, 5] = w
    ref, _ = _normal.accumulate_points(first, N, upper, np.zeros((len(w), 3)), m)
    ab = _kernels.points_normal_isotropic(first, N, w, m)
    assert_array_equal(_bits(ab), _bits(ref))


@pytest.mark.parametrize("m", [1, 2, 5, 70])
def test_prior_band_from_compact_sums_is_the_bands_prior_band(m):
    """The prior's band from the compact sums (4 per control point) bit for bit the one
    ``prior_band`` forms from the two isotropic bands (every row, the zero rows and the first
    columns no pair reaches included), and those bands' entries are the sums: the fit keeps
    the sums (session 20) where it kept two whole bands."""
    rng = np.random.default_rng(34)
    r = 7 * m
    first = np.sort(rng.integers(0, m, r))
    Na, Nj = rng.normal(size=(r, 4)), rng.normal(size=(r, 4))
    wa, wj = rng.uniform(0.001, 0.02, r), rng.uniform(0.001, 0.02, r)
    q_a, q_j = 0.37, 3.1e3
    sa, sj = _kernels.prior_sums(first, Na, wa, m), _kernels.prior_sums(first, Nj, wj, m)
    assert sa.shape == (m + 3, 4)
    want = _kernels.prior_band(_kernels.points_normal_isotropic(first, Na, wa, m),
                               _kernels.points_normal_isotropic(first, Nj, wj, m), q_a, q_j)
    got, values = _kernels.prior_band_sums(sa, sj, m, q_a, q_j)
    assert_array_equal(_bits(got), _bits(want))
    # by hand: control point p's sum with p + k sits on row 11 - 3k, columns 3(p + k) + d
    p, k = 0, min(1, m - 1)
    assert got[11 - 3 * k, 3 * (p + k) + 2] == sa[p, k] / q_a + sj[p, k] / q_j
    assert values[p, k] == got[11 - 3 * k, 3 * (p + k)]
    assert np.count_nonzero(got[[0, 1, 3, 4, 6, 7, 9, 10]]) == 0
    # A x from the distinct entries: band_matvec's value (its +0 terms left out), and the
    # dense product's to rounding
    x = np.random.default_rng(35).normal(size=3 * m)
    Ax = _kernels.prior_matvec(values, x)
    assert_array_equal(_bits(Ax), _bits(_kernels.band_matvec(got, x)))
    A = np.zeros((3 * m, 3 * m))
    for d in range(12):
        i = np.arange(3 * m - d)
        A[i, i + d] = A[i + d, i] = got[11 - d, d:]
    assert_allclose(Ax, A @ x, rtol=1e-12, atol=1e-12 * np.abs(A @ x).max())


def test_the_prior_terms_probe_takes_the_kernel_only_where_it_gives_numpys_bits():
    # here the kernel repeats OpenBLAS's order (the probe passes); a kernel whose products
    # are rounded before each sum (no fused multiply-add) must fail it: numpy's matmuls then
    import numba

    assert _breaks.prior_terms_compiled() == _blas_like_here()
    assert _breaks._prior_terms_probe(_kernels.trial_prior_terms) == _blas_like_here()

    @numba.njit
    def rounded_p0(Nd6, x0, gravity):
        p0 = np.empty((Nd6.shape[0], 12, 3))
        for b in range(Nd6.shape[0]):
            for p in range(12):
                for d in range(3):
                    acc = 0.0
                    for c in range(6):
                        acc = acc + Nd6[b, p, c] * x0[b, c, d]  # no contract: rounded
                    p0[b, p, d] = acc - gravity[d] if p < 8 else acc
        return p0

    def rounded(Nd6, x0, fw, fn, gravity, g):
        _, pyy, pxy = _breaks.prior_terms_numpy(Nd6, x0, fw, fn, gravity, g.copy())
        p0 = rounded_p0(Nd6, x0, gravity)
        g -= fw @ p0
        return p0, pyy, pxy

    assert not _breaks._prior_terms_probe(rounded)
