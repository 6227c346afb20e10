"""``pslog eval``'s calibration figures by hand: the Mahalanobis distance of each point's error,
the share inside the 2σ ellipsoid and the NEES (docs/paper.md, "what each point says about
itself"; :func:`pslog.evaluation.summarise_quality`), and the χ²₃ share they are compared
with."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import stats

from pslog.evaluation import CHI2_3D_2SIGMA, mahalanobis_sq, summarise_quality
from pslog.records import Track, Truth

MM = 1e-3


def _track(errors_mm, quality) -> tuple[Track, Truth]:
    """A track whose points are ``errors_mm`` (n, 3) off a truth sampled at its times."""
    n = len(errors_mm)
    time_ns = np.arange(1, n + 1) * 10_000_000
    truth_xyz = np.column_stack([np.linspace(0.5, 1.5, n), np.full(n, 1.0), np.full(n, 0.8)])
    track = Track("hand", time_ns, truth_xyz + np.asarray(errors_mm) * MM,
                  np.zeros(n, np.int32), quality)
    return track, Truth(time_ns, truth_xyz)


def test_mahalanobis_share_and_nees_of_full_covariances_by_hand():
    # point 0: Σ = diag(1, 4, 9) mm², e = (1, 2, 3) mm: d² = 1 + 1 + 1 = 3 (inside 2σ)
    # point 1: Σ = [[4, 2, 0], [2, 2, 0], [0, 0, 1]] mm², e = (2, 0, 3) mm:
    #          the xy block's inverse is [[2, -2], [-2, 4]] / 4, so d² = 2·2·2/4 + 9 = 11
    # point 2: Σ = I mm², e = 0: d² = 0
    # point 3: Σ = diag(4, 4, 4) mm², e = (2, 2, 2) mm: d² = 3 · 4/4 = 3
    cov = {"cov_xx_m2": [1, 4, 1, 4], "cov_yy_m2": [4, 2, 1, 4], "cov_zz_m2": [9, 1, 1, 4],
           "cov_xy_m2": [0, 2, 0, 0], "cov_xz_m2": [0, 0, 0, 0], "cov_yz_m2": [0, 0, 0, 0]}
    quality = {k: np.array(v, dtype=np.float64) * MM**2 for k, v in cov.items()}
    track, truth = _track([[1, 2, 3], [2, 0, 3], [0, 0, 0], [2, 2, 2]], quality)
    assert_allclose(mahalanobis_sq(track, truth), [3.0, 11.0, 0.0, 3.0], rtol=1e-9, atol=1e-12)
    q = summarise_quality(track, truth)
    assert q.within_2sigma == 0.75  # d² <= 4 for three of the four
    assert q.nees == pytest.approx((3 + 11 + 0 + 3) / 4 / 3, rel=1e-9)  # mean d² / 3


def test_per_axis_deviations_give_the_diagonal_covariance():
    # filter's columns: std_x_m, std_y_m, std_z_m; e = (3, -4, 0) mm with σ = (3, 2, 5) mm:
    # d² = 1 + 4 + 0 = 5 (outside 2σ); e = (0, 1, -5) mm: d² = 0 + 1/4 + 1 = 1.25 (inside)
    quality = {"std_x_m": np.array([3.0, 3.0]) * MM, "std_y_m": np.array([2.0, 2.0]) * MM,
               "std_z_m": np.array([5.0, 5.0]) * MM}
    track, truth = _track([[3, -4, 0], [0, 1, -5]], quality)
    assert_allclose(mahalanobis_sq(track, truth), [5.0, 1.25], rtol=1e-9)
    q = summarise_quality(track, truth)
    assert q.within_2sigma == 0.5
    assert q.nees == pytest.approx((5 + 1.25) / 2 / 3, rel=1e-9)


def test_the_two_sigma_share_of_honest_gaussian_errors_is_chi2_3_at_4():
    # P(χ²₃ <= 4) = erf(√2) − √(8/π) e⁻² (the χ distribution of 3 dof at r = 2)
    assert CHI2_3D_2SIGMA == pytest.approx(stats.chi2.cdf(4.0, 3), rel=1e-14)
    assert CHI2_3D_2SIGMA == pytest.approx(
        math.erf(math.sqrt(2)) - math.sqrt(8 / math.pi) * math.exp(-2), rel=1e-15)
