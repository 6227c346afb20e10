"""The deletion test's terms in one compiled pass (``pslog.estimation._deletion``, session
44): the bits of the two einsums and eight elementwise passes it replaced
(``deletion_numpy``), on a real fit's arguments and on terms with signed zeros,
infinities and NaNs; ``deletion_gain`` takes the pass where the probe finds those bits and
the arguments have the layout it was checked on, numpy's passes otherwise."""

from __future__ import annotations

import numpy as np
import pytest
from _rally import dirty_rally
from _stages import first_arguments
from numpy.testing import assert_array_equal

from pslog import apply_timing, builtin_rig
from pslog.estimation import _deletion
from pslog.estimation.trajectory import deletion_gain
from pslog.simulation import SimulationOptions, simulate

SEED = 77044


def _same_bits(a, b):
    assert_array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))


@pytest.fixture(scope="module")
def fit_arguments():
    """What ``fit_trajectory`` gives ``deletion_gain`` on a 6-second rally of ``paper3``
    with misses: (J, cov, r, w, sigma, scale)."""
    rig = apply_timing(builtin_rig("paper3"), "typeA")
    motion, _ = dirty_rally(SEED)
    detections, _ = simulate(rig, motion, 6.0, SimulationOptions(
        noise_px=0.5, seed=SEED, miss_rate=0.1))
    return first_arguments("deletion_gain", detections.best(), rig)


def test_the_pass_is_the_numpy_form_bit_for_bit_on_a_real_fit(fit_arguments):
    J, cov, r, w, sigma, fit_scale = fit_arguments
    assert len(J) > 400 and _deletion.usable(J, cov, r, w)
    for scale in (fit_scale, 1.37):  # (the fit's variance factor, here 1: at its floor)
        want = _deletion.deletion_numpy(J, cov, r, w, sigma, scale)
        for fn in (_deletion.deletion_terms, _deletion.deletion_terms.py_func):
            _same_bits(fn(J, cov, r, w, scale * sigma**2, sigma**2), want)
        _same_bits(deletion_gain(J, cov, r, w, sigma, scale), want)


def test_the_pass_is_the_numpy_form_with_zeros_infinities_and_nans():
    """Signed zeros (einsum's sums start from +0: a sum of -0 products is +0), an infinite
    covariance entry, NaN residuals, zero weights; its Python original the same."""
    rng = np.random.default_rng(SEED)
    n = 400
    J = rng.normal(size=(n, 2, 3)) * 10.0 ** rng.integers(-3, 4, (n, 1, 1))
    C = rng.normal(size=(n, 3, 3))
    C = np.ascontiguousarray(C @ np.swapaxes(C, 1, 2) * 1e-6)
    r = rng.normal(size=(n, 2))
    w = rng.uniform(0.0, 1.0, n)
    J[::5] = -0.0
    J[1::7, 1] = 0.0
    C[2::6] = -0.0
    C[5::8, 1, 2] = np.inf
    r[6::8, 0] = np.nan
    r[3::9] = 0.0
    w[4::9] = 0.0
    with np.errstate(all="ignore"):
        want = _deletion.deletion_numpy(J, C, r, w, 0.41, 1.7)
    assert np.any(np.isnan(want)) and np.any(want == 0.0)
    for fn in (_deletion.deletion_terms, _deletion.deletion_terms.py_func):
        _same_bits(fn(J, C, r, w, 1.7 * 0.41**2, 0.41**2), want)


def test_deletion_gain_takes_numpys_passes_where_the_layout_is_another():
    """A covariance broadcast from one matrix (not contiguous) or Jacobians of another
    width: numpy's passes (the same values the pass would give on a contiguous copy)."""
    rng = np.random.default_rng(SEED + 1)
    n = 50
    J = rng.normal(size=(n, 2, 3))
    cov = np.broadcast_to(np.diag([1e-4, 2e-4, 3e-4]), (n, 3, 3))
    r = rng.normal(size=(n, 2))
    w = rng.uniform(0.2, 1.0, n)
    assert not _deletion.usable(J, cov, r, w)
    _same_bits(deletion_gain(J, cov, r, w, 0.7, 1.2),
               _deletion.deletion_numpy(J, cov, r, w, 0.7, 1.2))
    _same_bits(deletion_gain(J, np.ascontiguousarray(cov), r, w, 0.7, 1.2),
               deletion_gain(J, cov, r, w, 0.7, 1.2))
    J4 = rng.normal(size=(n, 2, 4))
    cov4 = np.ascontiguousarray(np.broadcast_to(np.eye(4) * 1e-4, (n, 4, 4)))
    assert not _deletion.usable(J4, cov4, r, w)
    _same_bits(deletion_gain(J4, cov4, r, w, 0.7), _deletion.deletion_numpy(J4, cov4, r, w, 0.7))
