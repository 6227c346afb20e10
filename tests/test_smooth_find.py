"""The break find's cheaper passes (session 24), each the same bits as the form it replaced:
``trial_gains`` without the Schur products' exact-zero terms (against every term,
``_trial_gains_dense``), the greedy choice of breaks that loops only over candidates with a
rival nearby (against the loop over all of them), the acceleration at every span's
midpoint from the second derivative's basis alone (against every derivative's and
numpy's einsum), and the windows' ``M X₀`` compiled (against numpy's matmul)."""

from __future__ import annotations

import bisect

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from test_smooth_gains import _scan_windows

from pslog.estimation import _breaks, _kernels, _window
from pslog.estimation.bspline import DEGREE, basis_pieces, clamped_knots
from pslog.estimation.trajectory import _greedy_breaks


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _real_trials(seed: int, count: int = 80):
    """``trial_gains``' arguments for trials on real break-test windows (both bases, trial
    instants over the spans a scan tests, a few at a span's ends)."""
    base, both, centers, prior, h, rng = _scan_windows(seed, K_extra=seed % 2)
    C = len(centers)
    which = rng.integers(0, 2 * C, count)
    frac = rng.integers(-3, 2, count) + rng.uniform(0.25, 0.75, count)
    frac[:4] = [-2.75, 0.25, 1.75, 0.5]
    tau = both[which] + frac * h
    return _breaks._trial_terms(base, which, tau, both, prior)


def _copied(args: tuple) -> list:
    return [a.copy() if isinstance(a, np.ndarray) else a for a in args]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_trial_gains_without_the_zero_terms_are_every_terms_bits(seed):
    """On real windows the blocks of H_xy that no detection or prior node reaches are exact
    zeros (so the kernel skips their terms), and the gains are those of every term, to the
    last bit (compiled and its Python original; ``Hyy``, ``Hxy`` updated alike)."""
    args = _real_trials(seed)
    dense = _copied(args)
    want = _kernels._trial_gains_dense(*dense)
    for kernel in (_kernels.trial_gains, _kernels.trial_gains.py_func):
        got_args = _copied(args)
        got = kernel(*got_args)
        assert_array_equal(_bits(got), _bits(want))
        assert_array_equal(got_args[0], dense[0])
        assert_array_equal(got_args[1], dense[1])
    Hxy = dense[1]  # with the prior's terms added
    assert np.all(Hxy[:, 0:3, 3:9] == 0.0) and np.all(Hxy[:, 15:18, 0:6] == 0.0)
    assert np.all(np.isfinite(want)) and np.any(want > 25)


def test_trial_gains_take_every_term_where_a_skipped_one_would_not_be_nil():
    """A block that is not exactly zero, a skipped entry of the window's inverse that is
    not finite (inf · 0 is NaN in every term's sum): those trials take the dense form
    (NaN gains where it gives NaN), the others are unchanged."""
    args = list(_real_trials(5, 12))
    Hxy, cov, which, row0, col = args[1], args[4], args[5], args[6], args[7]
    Hxy[1, 1, 4] = 1e-3  # the zero block of q0 and the second new B-spline
    Hxy[2, 16, 0] = -2e-3  # of q0 + 5 and the first
    cov = cov.copy()
    w3 = which[3]
    others = np.flatnonzero(which != w3)
    cov[w3, row0[3] + 4, col[3] + 1] = np.inf  # column 1: skipped for columns 3-8 of T
    args[4] = cov
    dense = _copied(args)
    want = _kernels._trial_gains_dense(*dense)
    got = _kernels.trial_gains(*_copied(args))
    assert_array_equal(_bits(got), _bits(want))
    assert np.isnan(want[3])
    assert np.all(np.isfinite(want[others]))
    # a row of T that only skipped terms read (row 15: q0 + 5's, against the first two
    # new B-splines) not finite: every term's sum is NaN (0 · inf), so must the gain be
    args2 = list(_real_trials(6, 12))
    cov2 = args2[4].copy()
    w = args2[5][0]
    cov2[w, args2[6][0] + 15, args2[7][0]] = np.inf
    args2[4] = cov2
    want2 = _kernels._trial_gains_dense(*_copied(args2))
    assert_array_equal(_bits(_kernels.trial_gains(*_copied(args2))), _bits(want2))
    assert np.isnan(want2[0])


def _greedy_loop(tau, gain, free, threshold, apart):
    """(reference) The loop over every candidate, as ``_find_breaks`` wrote it before."""
    found: list[float] = []
    for i in np.argsort(-gain):
        if gain[i] <= threshold:
            break
        k = bisect.bisect_left(found, tau[i])
        if free[i] and (k == len(found) or abs(tau[i] - found[k]) > apart) and (
                k == 0 or abs(tau[i] - found[k - 1]) > apart):
            found.insert(k, float(tau[i]))
    return np.sort(np.array(found))


@pytest.mark.parametrize("seed", range(6))
def test_greedy_breaks_are_the_loop_over_every_candidate(seed):
    """Candidates mostly alone and some in clusters (rivals within 1.5 spacings, pairs at
    exactly that distance, equal instants, gains tied and at the threshold, not free):
    the same breaks as the greedy loop over all of them."""
    rng = np.random.default_rng(seed)
    h = 2.0**-5  # instants on a 2**-10 s grid: differences exact, some exactly 1.5 h
    apart = 1.5 * h
    alone = np.round(np.cumsum(rng.uniform(2.0, 4.0, 300)) * h * 1024) / 1024
    cluster = alone[rng.choice(300, 60, replace=False)] + rng.uniform(-1.6, 1.6, 60) * h
    tau = np.r_[alone, cluster, alone[20:26] + apart, alone[30:32]]
    gain = rng.exponential(60.0, len(tau))
    gain[:10] = 25.0  # at the threshold: not kept
    gain[10:14] = gain[14]  # ties
    free = rng.uniform(size=len(tau)) > 0.1
    want = _greedy_loop(tau, gain, free, 25.0, apart)
    got = _greedy_breaks(tau, gain, free, 25.0, apart)
    assert_array_equal(_bits(got), _bits(want))
    assert 150 < len(want) < len(tau)
    # and with a NaN gain (the loop's own reading of it)
    gain[20] = np.nan
    assert_array_equal(_bits(_greedy_breaks(tau, gain, free, 25.0, apart)),
                       _bits(_greedy_loop(tau, gain, free, 25.0, apart)))
    empty = np.zeros(0)
    assert _greedy_breaks(empty, empty, np.zeros(0, bool), 25.0, apart).shape == (0,)


def test_midpoint_acceleration_is_every_derivatives_row_and_einsums_sum():
    """``basis_pieces(..., only=2)`` is row 2 of every derivative's basis, and the compiled
    sum of its four control points numpy's einsum over them, bit for bit (pieces with
    triple knots, as after breaks)."""
    rng = np.random.default_rng(4)
    knots = []
    for p in range(3):
        breaks = np.sort(np.r_[np.arange(0.0, 2.0, 0.0333) + p * 3, p * 3 + 0.71])
        mult = np.ones(len(breaks) - 2, dtype=np.int64)
        mult[20] = 3
        knots.append(clamped_knots(breaks, mult))
    mids = [((k[:-1] + k[1:]) / 2)[k[1:] > k[:-1]] for k in knots]
    piece = np.repeat(np.arange(len(mids)), [len(x) for x in mids])
    t = np.concatenate(mids)
    m = sum(len(k) - DEGREE - 1 for k in knots)
    control = rng.normal(size=(m, 3)) * 10.0 ** rng.integers(-2, 3, (m, 1))
    first, N = basis_pieces(knots, piece, t, 2)
    first2, N2 = basis_pieces(knots, piece, t, only=2)
    assert_array_equal(first2, first)
    assert_array_equal(_bits(N2), _bits(N[:, 2]))
    want = np.einsum("na,nad->nd", N[:, 2], control[first[:, None] + np.arange(DEGREE + 1)])
    got = _kernels.points_positions(first2, N2, control)
    assert_array_equal(_bits(got), _bits(want))


def test_window_products_are_numpys_matmul_on_real_windows():
    """The break windows' ``M X₀`` (padding included) compiled: numpy's matmul's bits where
    the probe says so (this build machine: it must), and the base's residuals ``u`` are
    ``v - M X₀`` either way."""
    base, *_ = _scan_windows(9)
    X0 = _kernels.window_positions(base.first, base.N, np.ascontiguousarray(base.x0))
    want = (base.M @ X0[..., None])[..., 0]
    got = _window.window_products(base.M, X0)
    assert _window.products_compiled()
    assert_array_equal(_bits(got), _bits(want))
    assert np.any(base.M == 0.0) and np.any(base.u != 0.0)
