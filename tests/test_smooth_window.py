"""The break test's window gathers in one compiled pass (``pslog.estimation._window``):
against the numpy fancy indexing, masks and einsum they replaced, bit for bit, padding
included."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from pslog.estimation import _breaks, _window


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _numpy_form(index, inside, at, wJ_all, M_all, z, w):
    """``_Base``'s numpy lines (session 18)."""
    wi = np.where(inside, w[index], 0.0)
    rows = at[index]
    zi = z[index]
    wJ = np.where(inside[..., None, None], wJ_all[rows], 0.0)
    M = np.where(inside[..., None, None], M_all[rows], 0.0)
    v = np.einsum("bwai,bwa->bwi", wJ, zi)
    wz = wi * np.sum(zi * zi, axis=2)
    return M, v, wz


@pytest.mark.parametrize("compiled", [True, False])
def test_window_terms_are_the_numpy_form_bit_for_bit(compiled):
    """Windows of a random scan (detections held by some windows only, so ``at`` maps a
    subset; windows of several lengths padded with their last detection; negative targets,
    whose masked products are -0, summed from +0 as einsum sums): every entry has the numpy
    form's bits."""
    rng = np.random.default_rng(9)
    n, B, W = 400, 37, 12
    J = rng.normal(size=(n, 2, 3)) * 300
    w = rng.uniform(0.01, 3, n)
    z = rng.normal(size=(n, 2)) * 50
    i0 = np.sort(rng.integers(50, 380, B))
    i1 = np.minimum(i0 + rng.integers(1, W + 1, B), n)
    at, wJ_all, M_all = _breaks.detection_terms(J, w, i0, i1)
    index = i0[:, None] + np.arange(W)
    valid = index < i1[:, None]
    index = np.minimum(index, n - 1)
    inside = valid & (rng.uniform(size=(B, W)) < 0.9)
    fn = _window.window_terms if compiled else _window.window_terms.py_func
    got = fn(index, inside, at, wJ_all, M_all, z, w)
    for a, b in zip(got, _numpy_form(index, inside, at, wJ_all, M_all, z, w), strict=True):
        assert_array_equal(_bits(a), _bits(b))
    assert not np.all(inside)  # padding tested


def test_window_terms_of_a_hand_case():
    """One window, one detection inside (w = 2, J = [[1, 0, 0], [0, 1, 0]], z = (-3, -4))
    and one padding slot: w JᵀJ = diag(2, 2, 0), w Jᵀ z = (-6, -8, +0) (the third a sum of
    -0 products, from +0 as einsum sums), w ‖z‖² = 50."""
    J = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])
    w = np.array([2.0])
    z = np.array([[-3.0, -4.0]])
    at, wJ_all, M_all = _breaks.detection_terms(J, w, np.zeros(0, np.int64),
                                                np.zeros(0, np.int64))
    M, v, wz = _window.window_terms(np.zeros((1, 2), np.int64), np.array([[True, False]]),
                                    at, wJ_all, M_all, z, w)
    assert_array_equal(M[0, 0], np.diag([2.0, 2.0, 0.0]))
    assert_array_equal(_bits(v[0, 0]), _bits(np.array([-6.0, -8.0, 0.0])))
    assert wz[0, 0] == 50.0
    assert_array_equal(M[0, 1], 0.0)
    assert wz[0, 1] == 0.0
